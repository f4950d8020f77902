//! Joining a session of 10^4 and of 10^5 ops, op by op against a snapshot, in one run: the
//! time and bytes of each, and the check a peer joined from a snapshot runs afterwards.
//!
//! Op by op: two `SyncState`s in memory (decode, verify in batches, insert, fold, acks).
//! Snapshot: the producer captures and encodes; the joiner decodes, inserts every op without
//! its signature, folds them and checks the fold's hash, then syncs with the producer (which
//! finds nothing to send); the decode and the join are also timed alone. Then
//! `snapshot::verify`: every signature.
//! Workloads: `common::history` (signed `TestPayload` ops by four authors) and
//! `common::carved` (the object model's payload: one ball carved by one author).

mod common;

use std::time::{Duration, Instant};

use common::{NOW, Side, build_of, carved, catch_up, history};
use replication::materialize::test_scene::TestScene;
use replication::materialize::{Materialize, Materialized};
use replication::op::UNNAMED_SESSION;
use replication::shape::ShapeScene;
use replication::snapshot::{Snapshot, verify};
use replication::{Log, Payload, VerifiedOp};

/// Runs of each measurement; the median is printed.
const RUNS: usize = 3;

fn main() {
    println!("| workload | ops | way | time (median of {RUNS}) | bytes | bytes per op |");
    println!("|---|---|---|---|---|---|");
    for n in [10_000, 100_000] {
        measure::<_, TestScene>("TestPayload", &history(n));
        measure::<_, ShapeScene>("ShapePayload (carved)", &carved(n));
    }
}

fn measure<P: Payload, M: Materialize<P> + Default + Clone>(workload: &str, ops: &[VerifiedOp<P>]) {
    let n = ops.len();
    let row = |way: &str, time: Duration, bytes: usize| {
        let per_op = bytes as f64 / n as f64;
        let ms = time.as_secs_f64() * 1e3;
        println!("| {workload} | {n} | {way} | {ms:.1} ms | {bytes} | {per_op:.1} |");
    };
    let (log, scene) = build_of::<P, M>(ops);
    let empty = || {
        (
            Log::<P>::default(),
            Materialized::<P, M>::fold(&Log::default()),
        )
    };
    let (time, bytes) = median(|| {
        let mut a = Side::new(log.clone(), scene.clone(), 11, 1);
        let (l, s) = empty();
        let mut b = Side::new(l, s, 12, 2);
        let start = clock();
        let wire = catch_up(&mut a, &mut b);
        (start.elapsed(), wire as usize)
    });
    row("op by op (catch-up, both directions)", time, bytes);

    let (time, bytes) = median(|| {
        let start = clock();
        let encoded = Snapshot::capture(&log, &scene).encode();
        (start.elapsed(), encoded.expect("a snapshot").len())
    });
    row("snapshot: capture and encode (producer)", time, bytes);
    let encoded = Snapshot::capture(&log, &scene).encode().expect("encodes");
    let (time, _) = median(|| {
        let start = clock();
        let decoded = Snapshot::<P>::decode(&encoded).expect("decodes");
        let took = start.elapsed();
        drop(decoded);
        (took, 0)
    });
    row("snapshot: decode alone", time, encoded.len());
    let (time, _) = median(|| {
        let decoded = Snapshot::<P>::decode(&encoded).expect("decodes");
        let start = clock();
        let joined = decoded.join::<M>(Log::default(), NOW).expect("joins");
        let took = start.elapsed();
        drop(joined);
        (took, 0)
    });
    row(
        "snapshot: join alone (insert unverified, fold, check)",
        time,
        encoded.len(),
    );
    let (time, bytes) = median(|| {
        let mut a = Side::new(log.clone(), scene.clone(), 11, 1);
        let start = clock();
        let (joined, joined_scene) = Snapshot::<P>::decode(&encoded)
            .expect("decodes")
            .join::<M>(Log::default(), NOW)
            .expect("joins");
        let mut b = Side::new(joined, joined_scene, 12, 2);
        let wire = catch_up(&mut a, &mut b);
        assert_eq!(b.scene.scene_hash(), scene.scene_hash());
        (start.elapsed(), encoded.len() + wire as usize)
    });
    row("snapshot: decode, join, sync (joiner)", time, bytes);
    let decoded = Snapshot::<P>::decode(&encoded).expect("decodes");
    let (joined, _) = (decoded.join::<M>(Log::default(), NOW)).expect("joins");
    let (time, _) = median(|| {
        let start = clock();
        verify(&joined, &UNNAMED_SESSION, |_| {}).expect("verifies");
        (start.elapsed(), 0)
    });
    row("snapshot: verify afterwards (signatures)", time, 0);
}

#[expect(
    clippy::disallowed_methods,
    reason = "a benchmark times real work on the wall clock"
)]
fn clock() -> Instant {
    Instant::now()
}

/// The median run of `f` by time, with its bytes.
fn median(mut f: impl FnMut() -> (Duration, usize)) -> (Duration, usize) {
    let mut runs: Vec<(Duration, usize)> = (0..RUNS).map(|_| f()).collect();
    runs.sort_unstable();
    runs[RUNS / 2]
}
