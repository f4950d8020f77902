//! Op log throughput: applying ops live in order (log and scene, signatures apart), decoding
//! and verifying one op, opening a 10^5-op store and folding the history loaded from it, a
//! late op's refold, catching up on 10^4 and 10^5 missing ops through two `SyncState`s in
//! memory, and joining from a snapshot instead.
//!
//! Goals (from the issue): at least 10^6 ops/s applied, and a 10^5-op join in under 1 s.
//! Context: Loro applies 260k text ops in 235 ms, diamond-types in 33 ms (their figures, not
//! run here). Sizes and memory per op are in the `oplog_sizes` bench.

mod common;

use std::path::PathBuf;
use std::sync::LazyLock;

use common::{N_HISTORY, NOW, Side, TLog, TScene, build, catch_up, history};
use divan::Bencher;
use divan::counter::ItemsCount;
use replication::materialize::test_scene::TestScene;
use replication::payload::LeaseAction;
use replication::payload::test_payload::TestPayload;
use replication::pending::Origin;
use replication::snapshot::Snapshot;
use replication::store::OpStore;
use replication::{Keypair, Op, Timestamp, VerifiedOp};

static HISTORY: LazyLock<Vec<VerifiedOp<TestPayload>>> = LazyLock::new(|| history(N_HISTORY));
static FULL: LazyLock<(TLog, TScene)> = LazyLock::new(|| build(&HISTORY));

/// The history written to a store file once per run.
static STORE: LazyLock<PathBuf> = LazyLock::new(|| {
    let dir = std::env::temp_dir().join(format!("sculpt-bench-store-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temp dir");
    let path = dir.join("ops.log");
    let (mut store, _, _) = OpStore::<TestPayload>::open(&path).expect("a new store");
    for chunk in HISTORY.chunks(1024) {
        let ops: Vec<&Op<TestPayload>> = chunk.iter().map(VerifiedOp::op).collect();
        store.append(&ops).expect("append");
    }
    path
});

/// The full history's snapshot, encoded.
static SNAPSHOT: LazyLock<Vec<u8>> = LazyLock::new(|| {
    Snapshot::capture(&FULL.0, &FULL.1)
        .encode()
        .expect("a snapshot")
});

fn main() {
    divan::main();
}

/// Ops applied live, in order, to the log and the scene (ops arrive already verified).
#[divan::bench(args = [10_000, 100_000], sample_count = 10)]
fn apply_in_order(bencher: Bencher, n: usize) {
    bencher
        .counter(ItemsCount::new(n))
        .with_inputs(|| HISTORY[..n].to_vec())
        .bench_values(|ops| {
            let mut log = TLog::default();
            let mut scene = TScene::fold(&log);
            for op in ops {
                let ins = log.insert(NOW, op, Origin(1)).expect("in order");
                scene.apply_insertion(&log, &ins);
            }
            (log, scene)
        });
}

/// The same, log only (lease fold, order, causal checks): the scene's share is the difference.
#[divan::bench(args = [100_000], sample_count = 10)]
fn apply_in_order_log_only(bencher: Bencher, n: usize) {
    bencher
        .counter(ItemsCount::new(n))
        .with_inputs(|| HISTORY[..n].to_vec())
        .bench_values(|ops| {
            let mut log = TLog::default();
            for op in ops {
                log.insert(NOW, op, Origin(1)).expect("in order");
            }
            log
        });
}

/// Decoding one op from the wire (canonical checks, blake3 id), no signature check.
#[divan::bench]
fn decode_op(bencher: Bencher) {
    let bytes = HISTORY[1234].encoded().to_vec();
    bencher.bench(|| Op::<TestPayload>::decode(divan::black_box(&bytes)).expect("decodes"));
}

/// Decoding and verifying one op's ed25519 signature (strict), as sync does per new op.
#[divan::bench]
fn decode_and_verify_op(bencher: Bencher) {
    let bytes = HISTORY[1234].encoded().to_vec();
    bencher.bench(|| {
        Op::<TestPayload>::decode(divan::black_box(&bytes))
            .expect("decodes")
            .into_verified(&replication::op::UNNAMED_SESSION)
            .expect("verifies")
    });
}

/// Opening the 10^5-op store alone: lock, read, check every record's checksum, decode every
/// op (no log, no scene). The file is never copied, so this is the whole cost of opening.
#[divan::bench(sample_count = 10)]
fn open_store_100k(bencher: Bencher) {
    let path = &*STORE;
    bencher.counter(ItemsCount::new(N_HISTORY)).bench(|| {
        let (_store, ops, _) = OpStore::<TestPayload>::open(path).expect("opens");
        ops
    });
}

/// Opening the store, inserting every op (own store: no signature check) and folding the
/// scene, for the 10^5-op history.
#[divan::bench(sample_count = 5)]
fn load_store_100k(bencher: Bencher) {
    let path = &*STORE;
    bencher.counter(ItemsCount::new(N_HISTORY)).bench(|| {
        let mut log = TLog::default();
        OpStore::open_into_trusted(path, Timestamp(0), &mut log).expect("loads");
        let scene = TScene::fold(&log);
        (log, scene)
    });
}

/// The same, checking every signature again (`OpStore::open_into`).
#[divan::bench(sample_count = 1)]
fn load_store_verified_100k(bencher: Bencher) {
    let path = &*STORE;
    bencher.counter(ItemsCount::new(N_HISTORY)).bench(|| {
        let mut log = TLog::default();
        OpStore::open_into(path, Timestamp(0), &mut log).expect("loads");
        let scene = TScene::fold(&log);
        (log, scene)
    });
}

/// A late weak acquire from a new author at Lamport time 1 lands near the start of a
/// 10^5-op log: marks are re-evaluated from the first checkpoint, and the one object it takes
/// over is re-folded.
#[divan::bench(sample_count = 5)]
fn late_acquire_refold_100k(bencher: Bencher) {
    let late = Log1::late(TestPayload::Lease(LeaseAction::Acquire {
        object: 3,
        strong: false,
        ttl_micros: u64::MAX / 2,
    }));
    bencher
        .with_inputs(|| (FULL.0.clone(), FULL.1.clone()))
        .bench_values(|(mut log, mut scene)| {
            let ins = log.insert(NOW, late.clone(), Origin(2)).expect("accepted");
            scene.apply_insertion(&log, &ins);
            (log, scene)
        });
}

/// A late chat line near the start: marks are re-evaluated, no object is re-folded.
#[divan::bench(sample_count = 5)]
fn late_chat_refold_100k(bencher: Bencher) {
    let late = Log1::late(TestPayload::Chat("late".into()));
    bencher
        .with_inputs(|| (FULL.0.clone(), FULL.1.clone()))
        .bench_values(|(mut log, mut scene)| {
            let ins = log.insert(NOW, late.clone(), Origin(2)).expect("accepted");
            scene.apply_insertion(&log, &ins);
            (log, scene)
        });
}

/// One op authored alone by a new author (Lamport time 1).
struct Log1;

impl Log1 {
    fn late(payload: TestPayload) -> VerifiedOp<TestPayload> {
        let mut log = TLog::default();
        let (op, _) = log
            .author(&Keypair::from_seed([99; 32]), Timestamp(1), payload)
            .expect("an op");
        op
    }
}

fn catch_up_bench(bencher: Bencher, n: usize) {
    bencher
        .counter(ItemsCount::new(n))
        .with_inputs(|| {
            let (log, scene) = if n == N_HISTORY {
                FULL.clone()
            } else {
                build(&HISTORY[..n])
            };
            let a = Side::new(log, scene, 11, 1);
            let b = Side::new(TLog::default(), TScene::fold(&TLog::default()), 12, 2);
            (a, b)
        })
        .bench_values(|(mut a, mut b)| {
            catch_up(&mut a, &mut b);
            (a, b)
        });
}

/// A new peer catches up on 10^4 ops: decode, verify, insert, fold, ack.
#[divan::bench(sample_count = 3)]
fn catch_up_10k(bencher: Bencher) {
    catch_up_bench(bencher, 10_000);
}

/// A new peer catches up on 10^5 ops.
#[divan::bench(sample_count = 1)]
fn catch_up_100k(bencher: Bencher) {
    catch_up_bench(bencher, N_HISTORY);
}

/// A new peer joins a 10^5-op session from a snapshot (decode, insert every op without its
/// signature, check the cut, decode the scene), then syncs with its producer.
#[divan::bench(sample_count = 5)]
fn join_snapshot_100k(bencher: Bencher) {
    let bytes = &*SNAPSHOT;
    bencher
        .counter(ItemsCount::new(N_HISTORY))
        .with_inputs(|| Side::new(FULL.0.clone(), FULL.1.clone(), 11, 1))
        .bench_values(|mut a| {
            let (log, scene) = Snapshot::<TestPayload>::decode(bytes)
                .expect("decodes")
                .join::<TestScene>(TLog::default(), NOW)
                .expect("joins");
            let mut b = Side::new(log, scene, 12, 2);
            catch_up(&mut a, &mut b);
            (a, b)
        });
}
