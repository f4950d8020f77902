//! Joining a session of 10^4 and of 10^5 ops, op by op against a snapshot, in one run: the
//! time and bytes of each, and the check a peer joined from a snapshot runs afterwards.
//!
//! Op by op: two `SyncState`s in memory (decode, verify in batches, insert, fold, acks).
//! Snapshot: the producer captures and encodes; the joiner decodes, inserts every op without
//! its signature, adopts the scene, then syncs with the producer (which finds nothing to
//! send). Then `snapshot::verify`: every signature and a fold from scratch.
//! Workload: `common::history` (signed `TestPayload` ops by four authors).

mod common;

use std::time::{Duration, Instant};

use common::{NOW, Side, TLog, TScene, build, catch_up, history};
use replication::materialize::test_scene::TestScene;
use replication::op::UNNAMED_SESSION;
use replication::payload::test_payload::TestPayload;
use replication::snapshot::{Snapshot, verify};

/// Runs of each measurement; the median is printed.
const RUNS: usize = 3;

fn main() {
    println!("| ops | way | time (median of {RUNS}) | bytes | bytes per op |");
    println!("|---|---|---|---|---|");
    for n in [10_000, 100_000] {
        let (log, scene) = build(&history(n));
        let (time, bytes) = median(|| {
            let mut a = Side::new(log.clone(), scene.clone(), 11, 1);
            let mut b = Side::new(TLog::default(), TScene::fold(&TLog::default()), 12, 2);
            let start = clock();
            let wire = catch_up(&mut a, &mut b);
            (start.elapsed(), wire as usize)
        });
        row(n, "op by op (catch-up, both directions)", time, bytes);

        let (time, bytes) = median(|| {
            let start = clock();
            let encoded = Snapshot::capture(&log, &scene).and_then(|s| s.encode());
            (start.elapsed(), encoded.expect("a snapshot").len())
        });
        row(n, "snapshot: capture and encode (producer)", time, bytes);
        let encoded = (Snapshot::capture(&log, &scene).and_then(|s| s.encode())).expect("encodes");
        let (time, bytes) = median(|| {
            let mut a = Side::new(log.clone(), scene.clone(), 11, 1);
            let start = clock();
            let (joined, joined_scene) = Snapshot::<TestPayload>::decode(&encoded)
                .expect("decodes")
                .join::<TestScene>(TLog::default(), NOW)
                .expect("joins");
            let mut b = Side::new(joined, joined_scene, 12, 2);
            let wire = catch_up(&mut a, &mut b);
            assert_eq!(b.scene.scene_hash(), scene.scene_hash());
            (start.elapsed(), encoded.len() + wire as usize)
        });
        row(n, "snapshot: decode, join, sync (joiner)", time, bytes);
        let decoded = Snapshot::<TestPayload>::decode(&encoded).expect("decodes");
        let (joined, joined_scene) =
            (decoded.join::<TestScene>(TLog::default(), NOW)).expect("joins");
        let (time, _) = median(|| {
            let start = clock();
            verify(&joined, &joined_scene, &UNNAMED_SESSION, |_| {}).expect("verifies");
            (start.elapsed(), 0)
        });
        row(n, "snapshot: verify afterwards (signatures, fold)", time, 0);
    }
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

fn row(n: usize, way: &str, time: Duration, bytes: usize) {
    let per_op = bytes as f64 / n as f64;
    let ms = time.as_secs_f64() * 1e3;
    println!("| {n} | {way} | {ms:.1} ms | {bytes} | {per_op:.1} |");
}
