//! Snapshot tests: a join at every point of workloads with leases, deletes, undo, forks,
//! membership and late ops judges every later op as a full peer does; a joined peer syncs and
//! is snapshotted again; corrupt and hostile snapshots (a planted scene hash among them) are
//! refused, and [`verify`] finds a forged op.

use super::*;
use crate::identity::Keypair;
use crate::lease::Mark;
use crate::log::tests::{
    TLog, deliver_all, founded_log, founded_workload, key, set, shuffled, twin_workload, workload,
};
use crate::materialize::test_scene::TestScene;
use crate::op::UNNAMED_SESSION;
use crate::payload::test_payload::TestPayload;
use crate::pending::Origin;
use crate::sync::state::{Event, SyncConfig, SyncState};
use testkit::stack::on_small_stack;

type TScene = Materialized<TestPayload, TestScene>;
type TSnapshot = Snapshot<TestPayload>;

/// The encoded snapshot of `log` and its scene folded from scratch.
fn snapshot_bytes(log: &TLog) -> Vec<u8> {
    let scene = TScene::fold(log);
    TSnapshot::capture(log, &scene).encode().unwrap()
}

/// A log joined into `fresh` from the encoded snapshot of `log`.
fn joined(log: &TLog, fresh: TLog) -> (TLog, TScene) {
    let bytes = snapshot_bytes(log);
    let decoded = on_small_stack(|| TSnapshot::decode(&bytes)).unwrap();
    decoded.join::<TestScene>(fresh, Timestamp(0)).unwrap()
}

/// Every delivered op's id, verdict and activity, in the linear order.
fn verdicts(log: &TLog) -> Vec<(OpId, Mark, bool)> {
    log.entries()
        .map(|e| (e.op.id(), e.mark, e.active))
        .collect()
}

/// Issue 50: a peer joined from a snapshot judged a later op concurrent with a lease op or an
/// edit of the snapshot differently from a full peer. Joined at every tenth point of three
/// workloads delivered out of order (later ops sorting before held ones), the joined peer
/// gives every later op, and every op it holds, the verdict, activity and scene of the peer
/// that received everything op by op.
#[test]
fn a_join_at_any_point_judges_every_later_op_as_a_full_peer_does() {
    type Run = (&'static str, Vec<VerifiedOp<TestPayload>>, fn() -> TLog);
    let runs: [Run; 3] = [
        ("leases, deletes, undo", workload(3, 4, 150), TLog::default),
        ("forks", twin_workload(5, 4, 150), TLog::default),
        ("membership", founded_workload(7, 4, 150), founded_log),
    ];
    for (name, ops, fresh) in runs {
        let order = shuffled(&ops, 11);
        let mut prefix = fresh();
        for k in 0..=order.len() {
            if k % 10 == 0 {
                check_join_at(name, &order, k, &prefix, fresh);
            }
            if let Some(op) = order.get(k) {
                prefix.insert(Timestamp(0), op.clone(), Origin(1)).unwrap();
            }
        }
        assert_eq!(prefix.n_pending(), 0, "{name}");
        if name == "forks" {
            assert!(!prefix.forks().is_empty(), "the twin workload forked");
        }
    }
}

/// Joins from `prefix` (the first `k` ops of `order` inserted), then gives the joined log and
/// a copy of `prefix` the same ops, comparing verdicts after each.
fn check_join_at(
    name: &str,
    order: &[VerifiedOp<TestPayload>],
    k: usize,
    prefix: &TLog,
    fresh: fn() -> TLog,
) {
    let (mut joined, mut joined_scene) = joined(prefix, fresh());
    let mut full = prefix.clone();
    let mut full_scene = TScene::fold(&full);
    assert_eq!(joined_scene.scene_hash(), full_scene.scene_hash());
    assert_eq!(verdicts(&joined), verdicts(&full), "{name}: at {k}");
    // What the prefix parked (its deps later in the order) is not in the snapshot: the
    // joined peer gets it again, as sync would send it.
    let parked = order[..k].iter().filter(|op| !prefix.contains(&op.id()));
    for op in parked.chain(&order[k..]) {
        let a = full.insert(Timestamp(0), op.clone(), Origin(1));
        let b = joined.insert(Timestamp(0), op.clone(), Origin(1));
        if let (Ok(a), Ok(b)) = (&a, &b) {
            full_scene.apply_insertion(&full, a);
            joined_scene.apply_insertion(&joined, b);
        }
        assert_eq!(a.is_ok(), b.is_ok(), "{name}: joined at {k}");
        assert_eq!(verdicts(&joined), verdicts(&full), "{name}: joined at {k}");
    }
    assert_eq!(joined_scene.scene_hash(), full_scene.scene_hash(), "{name}");
    assert_eq!(TScene::fold(&joined).scene_hash(), full_scene.scene_hash());
}

/// One side of an in-memory connection, with its scene kept in step by sync events.
struct Side {
    log: TLog,
    scene: TScene,
    sync: SyncState<TestPayload>,
    /// What was last asked of the remote.
    wanted: Option<crate::causal::VersionVector>,
}

impl Side {
    fn new(log: TLog, scene: TScene, me: &Keypair, origin: u64) -> Self {
        let config = SyncConfig {
            session_id: [4; 16],
            local: me.peer_id(),
            origin: Origin(origin),
        };
        Self {
            sync: SyncState::new(Timestamp(0), config),
            wanted: None,
            log,
            scene,
        }
    }

    fn drain(&mut self) {
        while let Some(event) = self.sync.poll_event() {
            if let Event::Delivered(ins) = event {
                self.scene.apply_insertion(&self.log, &ins);
            }
        }
    }

    fn author(&mut self, key: &Keypair, now: u64, payload: TestPayload) -> OpId {
        let (op, ins) = self.log.author(key, Timestamp(now), payload).unwrap();
        self.scene.apply_insertion(&self.log, &ins);
        op.id()
    }
}

/// Moves messages both ways, advancing virtual time 1 ms a round, until nothing moves.
fn pump(a: &mut Side, b: &mut Side, now: &mut u64) {
    for _ in 0..100_000 {
        let mut moved = false;
        while let Some(bytes) = a.sync.poll_transmit(Timestamp(*now), &a.log) {
            b.sync.handle_input(Timestamp(*now), &bytes, &mut b.log);
            moved = true;
        }
        while let Some(bytes) = b.sync.poll_transmit(Timestamp(*now), &b.log) {
            a.sync.handle_input(Timestamp(*now), &bytes, &mut a.log);
            moved = true;
        }
        a.drain();
        b.drain();
        // A lone connection asks its remote for everything it lacks (a `Peer` would choose
        // among its connections).
        for side in [&mut *a, &mut *b] {
            let lacking = side.sync.lacking(&side.log);
            if !lacking.is_empty() && side.wanted.as_ref() != Some(&lacking) {
                side.sync.want(lacking.clone(), &side.log);
                side.wanted = Some(lacking);
                moved = true;
            }
        }
        *now += 1000;
        let done = a.log.version_vector() == b.log.version_vector();
        if !moved && done {
            return;
        }
    }
    panic!("sync did not quiesce");
}

#[test]
fn a_joined_peer_syncs_undoes_old_edits_and_is_snapshotted_again() {
    let a_log = deliver_all(&workload(21, 3, 400));
    let bytes = snapshot_bytes(&a_log);
    let decoded = TSnapshot::decode(&bytes).unwrap();
    assert_eq!(decoded.encode().unwrap(), bytes, "canonical encoding");
    assert_eq!(decoded.cut(), SceneCut::of(&a_log));
    let (b_log, b_scene) = decoded
        .join::<TestScene>(TLog::default(), Timestamp(0))
        .unwrap();
    assert_eq!(verdicts(&b_log), verdicts(&a_log));
    verify(&b_log, &UNNAMED_SESSION, |_| {}).unwrap();

    // The author of the oldest active edit undoes it, then redoes it.
    let (oldest, author) = (a_log.entries())
        .find(|e| e.active && matches!(e.op.payload(), TestPayload::Set { .. }))
        .map(|e| (e.op.id(), e.op.author()))
        .expect("an active edit");
    let ka = (0..3).map(key).find(|k| k.peer_id() == author).unwrap();
    let kb = Keypair::from_seed([77; 32]);
    let a_scene = TScene::fold(&a_log);
    let mut a = Side::new(a_log, a_scene, &ka, 1);
    let mut b = Side::new(b_log, b_scene, &kb, 2);
    let mut now = 2_000_000;
    a.author(&ka, now, TestPayload::Undo(oldest));
    b.author(&kb, now, set(9, "from b"));
    pump(&mut a, &mut b, &mut now);
    assert!(!b.log.is_active(&oldest));
    assert_eq!(b.scene.scene_hash(), a.scene.scene_hash());
    a.author(&ka, now, TestPayload::Redo(oldest));
    pump(&mut a, &mut b, &mut now);
    assert!(b.log.is_active(&oldest));
    assert_eq!(b.scene.scene_hash(), a.scene.scene_hash());
    assert_eq!(TScene::fold(&b.log).scene_hash(), b.scene.scene_hash());

    // A third peer joins from the joined peer.
    let (c_log, c_scene) = joined(&b.log, TLog::default());
    assert_eq!(c_scene.scene_hash(), a.scene.scene_hash());
    assert_eq!(verdicts(&c_log), verdicts(&a.log));
}

#[test]
fn corrupt_truncated_or_inconsistent_snapshots_are_refused() {
    let log = deliver_all(&workload(6, 3, 80));
    let bytes = snapshot_bytes(&log);
    for i in (0..bytes.len()).step_by(7) {
        let mut bad = bytes.clone();
        bad[i] ^= 0x40;
        assert!(TSnapshot::decode(&bad).is_err(), "flip at {i}");
    }
    for cut in (0..bytes.len()).step_by(5) {
        assert!(TSnapshot::decode(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    assert!(TSnapshot::decode(&vec![0; MAX_SNAPSHOT_BYTES + 1]).is_err());

    let good = TSnapshot::decode(&bytes).unwrap();
    let join = |s: TSnapshot| {
        s.join::<TestScene>(TLog::default(), Timestamp(0))
            .map(|_| ())
    };
    // Well-formed, checksummed, and wrong.
    let mut swapped = good.clone();
    swapped.ops.swap(0, 40);
    assert!(matches!(
        join(swapped),
        Err(JoinError::OutOfOrder { .. } | JoinError::Refused { .. })
    ));
    let mut short = good.clone();
    short.ops.pop();
    assert!(matches!(join(short), Err(JoinError::Cut { .. })));
    let mut planted = good.clone();
    planted.scene_hash = SceneHash([7; SCENE_HASH_BYTES]);
    assert_eq!(join(planted), Err(JoinError::SceneHash));
    // The honest ops under another log's scene hash: the join's fold tells.
    let mut planted = good.clone();
    planted.scene_hash = TScene::fold(&deliver_all(&workload(9, 3, 60))).scene_hash();
    assert_eq!(join(planted), Err(JoinError::SceneHash));
    let busy = deliver_all(&workload(1, 1, 3));
    assert!(matches!(
        good.join::<TestScene>(busy, Timestamp(0)),
        Err(JoinError::NotEmpty(3))
    ));

    // A count of ops the bytes cannot hold is refused before anything is allocated.
    let mut body = SNAPSHOT_MAGIC.to_vec();
    body.push(SNAPSHOT_FORMAT_VERSION);
    put_varint(&mut body, MAX_LOG_OPS as u64);
    body.extend_from_slice(blake3::hash(&body).as_bytes());
    assert!(matches!(
        TSnapshot::decode(&body),
        Err(DecodeError::OverLimit {
            what: "snapshot op count",
            limit: 0,
            ..
        })
    ));
    // The versions that kept ids without ops, or the producer's scene, are refused by name.
    for version in [2, 3] {
        let mut old = bytes.clone();
        old[SNAPSHOT_MAGIC.len()] = version;
        assert_eq!(
            TSnapshot::decode(&old).map(|_| ()),
            Err(DecodeError::UnknownVersion {
                offset: SNAPSHOT_MAGIC.len(),
                version
            })
        );
    }
}

/// A hostile producer's snapshot with a forged op joins (nothing cheap can tell), and
/// [`verify`] and [`verify_encoded`] find it.
#[test]
fn verify_finds_a_forged_op() {
    let honest = deliver_all(&workload(8, 3, 60));
    let (log, _) = joined(&honest, TLog::default());
    let mut seen = 0;
    verify(&log, &UNNAMED_SESSION, |n| seen = n).unwrap();
    assert_eq!(seen, log.len());
    verify_encoded::<TestPayload>(&snapshot_bytes(&honest), &UNNAMED_SESSION, |_| {}).unwrap();
    // Signed for another session: every signature fails here.
    assert!(matches!(
        verify(&log, &[9; 16], |_| {}),
        Err(VerifyError::Unsigned(_))
    ));

    // A new op whose text is changed after signing: it decodes, and no signature covers it.
    let mut lying = honest.clone();
    let (signed, _) = lying
        .clone()
        .author(&key(0), Timestamp(1), TestPayload::Chat("hello".into()))
        .unwrap();
    let mut bytes = signed.encoded().to_vec();
    let at = bytes.windows(5).position(|w| w == b"hello").unwrap();
    bytes[at] = b'j';
    let forged = Op::<TestPayload>::decode(&bytes).unwrap();
    lying
        .insert(Timestamp(0), VerifiedOp::trusted(forged.clone()), Origin(1))
        .unwrap();
    let (log, _) = joined(&lying, TLog::default());
    assert_eq!(
        verify(&log, &UNNAMED_SESSION, |_| {}),
        Err(VerifyError::Unsigned(forged.id()))
    );
    let encoded = snapshot_bytes(&lying);
    assert_eq!(
        verify_encoded::<TestPayload>(&encoded, &UNNAMED_SESSION, |_| {}),
        Err(VerifyError::Unsigned(forged.id()))
    );
    assert!(matches!(
        verify_encoded::<TestPayload>(&encoded[1..], &UNNAMED_SESSION, |_| {}),
        Err(VerifyError::Decode(_))
    ));
}

/// Issue 17: a snapshot could name at most 4,096 authors; one of 5,000 authors round-trips.
#[test]
fn a_snapshot_holds_more_authors_than_a_version_vector_message_names() {
    let log = crate::sync::state::tests::log_of_many_authors(5_000);
    let bytes = snapshot_bytes(&log);
    let decoded = TSnapshot::decode(&bytes).unwrap();
    assert_eq!(decoded.n_ops(), 5_000);
    assert_eq!(decoded.encode().unwrap(), bytes, "canonical encoding");
    let (joined, _) = decoded
        .join::<TestScene>(TLog::default(), Timestamp(0))
        .unwrap();
    assert_eq!(joined.version_vector(), log.version_vector());
}
