//! Shared workload for the replication benches: an in-order history of signed `TestPayload`
//! ops by four authors taking turns (edits of 64 objects, some lease traffic, chat), and an
//! in-memory sync pump between two `SyncState`s.

#![allow(dead_code, reason = "each bench binary uses part of this module")]

use model::object::{Edit, EditOp, Formula, Geometry, ObjectData, Pose, ToolShape};
use replication::Payload;
use replication::materialize::test_scene::TestScene;
use replication::materialize::{Materialize, Materialized};
use replication::payload::LeaseAction;
use replication::payload::test_payload::TestPayload;
use replication::pending::Origin;
use replication::shape::{IdSource, ShapePayload};
use replication::sync::state::Event;
use replication::{Keypair, Log, SyncConfig, SyncState, Timestamp, VerifiedOp};

pub type TLog = Log<TestPayload>;
pub type TScene = Materialized<TestPayload, TestScene>;

/// The largest history the benches use.
pub const N_HISTORY: usize = 100_000;
/// Microseconds between the history's ops.
pub const HISTORY_STEP_MICROS: u64 = 1000;
/// The receivers' clock: after the whole history's timestamps. A receiver whose clock is
/// behind an op's timestamp by more than the skew bound parks the op until then, so a bench
/// run at time 0 would apply only the first minute of the history and park the rest.
pub const NOW: Timestamp = Timestamp(N_HISTORY as u64 * HISTORY_STEP_MICROS + 1);

/// The four authors.
pub fn keys() -> Vec<Keypair> {
    (1..=4).map(|i| Keypair::from_seed([i; 32])).collect()
}

/// An in-order history of `n` ops, each depending on the one before.
pub fn history(n: usize) -> Vec<VerifiedOp<TestPayload>> {
    let keys = keys();
    let mut log = TLog::default();
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let object = (i % 64) as u64;
        let payload = match i % 50 {
            0 => TestPayload::Chat(format!("line {i}")),
            1 => TestPayload::Lease(LeaseAction::Acquire {
                object,
                strong: false,
                ttl_micros: 20_000,
            }),
            2 => TestPayload::Lease(LeaseAction::Release { object: 1 }),
            _ => TestPayload::Set {
                object,
                value: format!("x*x+y*y-{i}"),
            },
        };
        let (op, _) = log
            .author(
                &keys[i % keys.len()],
                Timestamp(i as u64 * HISTORY_STEP_MICROS),
                payload,
            )
            .expect("a valid op");
        out.push(op);
    }
    out
}

/// A log holding `ops`, delivered in order, and its scene.
pub fn build(ops: &[VerifiedOp<TestPayload>]) -> (TLog, TScene) {
    build_of(ops)
}

/// An in-order history of `n` sculpting edits by one author: a ball made, then carved with
/// small spheres spread over its surface (the object model's payload, whose ops decode by
/// compiling their edits).
pub fn carved(n: usize) -> Vec<VerifiedOp<ShapePayload>> {
    let key = Keypair::from_seed([1; 32]);
    let mut log = Log::<ShapePayload>::default();
    let ball = IdSource::first(key.peer_id());
    let data = ObjectData {
        name: "ball".into(),
        geometry: Some(Geometry::implicit(
            Formula::new("0.8 - sqrt(x^2 + y^2 + z^2)").expect("a formula"),
        )),
        ..ObjectData::default()
    };
    let mut payloads = vec![ball.create(data, None)];
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 1..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let (r, a) = ((1.0 - z * z).sqrt(), golden * i as f64);
        let at = glam::DVec3::new(r * a.cos(), r * a.sin(), z) * 0.8;
        let stamp = Edit::stamp(
            EditOp::Subtract,
            ToolShape::Sphere { radius: 0.03 },
            Pose::at(at),
        );
        payloads.push(ShapePayload::edit(ball.id(), stamp).expect("a valid edit"));
    }
    (payloads.into_iter().enumerate())
        .map(|(i, p)| {
            let at = Timestamp(i as u64 * HISTORY_STEP_MICROS);
            log.author(&key, at, p).expect("a valid op").0
        })
        .collect()
}

/// [`build`] for any payload and scene.
pub fn build_of<P: Payload, M: Materialize<P> + Default>(
    ops: &[VerifiedOp<P>],
) -> (Log<P>, Materialized<P, M>) {
    let mut log = Log::default();
    let mut scene = Materialized::fold(&log);
    for op in ops {
        let ins = log
            .insert(NOW, op.clone(), Origin(1))
            .expect("in-order ops are accepted");
        scene.apply_insertion(&log, &ins);
    }
    assert_eq!(log.len(), ops.len(), "every op of the history is delivered");
    (log, scene)
}

/// One end of an in-memory connection.
pub struct Side<P: Payload = TestPayload, M = TestScene> {
    pub log: Log<P>,
    pub scene: Materialized<P, M>,
    pub sync: SyncState<P>,
}

impl<P: Payload, M: Materialize<P>> Side<P, M> {
    pub fn new(log: Log<P>, scene: Materialized<P, M>, seed: u8, origin: u64) -> Self {
        let config = SyncConfig {
            session_id: [1; 16],
            local: Keypair::from_seed([seed; 32]).peer_id(),
            origin: Origin(origin),
        };
        Self {
            sync: SyncState::new(NOW, config),
            log,
            scene,
        }
    }

    /// Folds the round's deliveries together, as a node folds each settled step.
    fn drain(&mut self) {
        let mut delivered = Vec::new();
        while let Some(event) = self.sync.poll_event() {
            if let Event::Delivered(ins) = event {
                delivered.push(ins);
            }
        }
        self.scene.apply_insertions(&self.log, &delivered);
    }
}

/// Exchanges messages until `b` holds what `a` holds, advancing virtual time 1 ms a round
/// (the send pacing allows 1,000 messages a second); returns the bytes sent both ways.
pub fn catch_up<P: Payload, M: Materialize<P>>(a: &mut Side<P, M>, b: &mut Side<P, M>) -> u64 {
    let mut now = NOW.0;
    // A lone connection asks for every author's ops it lacks, as `Peer` would of its only
    // holder.
    let mut wanted = None;
    for _ in 0..10_000_000 {
        let lacking = b.sync.lacking(&b.log);
        if !lacking.is_empty() && wanted.as_ref() != Some(&lacking) {
            b.sync.want(lacking.clone(), &b.log);
            wanted = Some(lacking);
        }
        while let Some(bytes) = a.sync.poll_transmit(Timestamp(now), &a.log) {
            b.sync.handle_input(Timestamp(now), &bytes, &mut b.log);
        }
        while let Some(bytes) = b.sync.poll_transmit(Timestamp(now), &b.log) {
            a.sync.handle_input(Timestamp(now), &bytes, &mut a.log);
        }
        a.drain();
        b.drain();
        if b.log.version_vector() == a.log.version_vector() {
            assert_eq!(b.log.len(), a.log.len(), "nothing is left pending");
            return a.sync.stats().n_bytes_out + b.sync.stats().n_bytes_out;
        }
        now += 1000;
    }
    panic!("the catch-up did not finish");
}
