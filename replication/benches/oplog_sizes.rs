//! Sizes per op, printed as a table (not timed): bytes on the wire during a catch-up, on disk
//! in the store, in a snapshot, and live memory of a log plus its scene, counted by a global
//! allocator that tracks live bytes.

mod common;

use testkit::alloc::{CountingAlloc, live_bytes};

use common::{N_HISTORY, Side, TLog, TScene, build, catch_up, history};
use replication::Timestamp;
use replication::materialize::test_scene::TestScene;
use replication::payload::test_payload::TestPayload;
use replication::snapshot::Snapshot;
use replication::store::OpStore;
use replication::{Op, VerifiedOp};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

fn live() -> usize {
    live_bytes()
}

fn per_op(bytes: usize, n: usize) -> f64 {
    bytes as f64 / n as f64
}

fn main() {
    let n = N_HISTORY;
    let ops = history(n);
    let encoded: usize = ops.iter().map(|op| op.encoded().len()).sum();
    println!("| measure ({n} TestPayload ops) | bytes per op |");
    println!("|---|---|");
    println!("| encoded op | {:.1} |", per_op(encoded, n));

    // Memory: a log and scene built from ops moved in (the ops' own memory counted).
    let before = live();
    let (log, scene) = {
        let moved: Vec<VerifiedOp<TestPayload>> = ops.clone();
        let built = build(&moved);
        drop(moved);
        built
    };
    println!(
        "| memory: log + scene, live | {:.1} |",
        per_op(live() - before, n)
    );

    // Disk.
    let dir = std::env::temp_dir().join(format!("sculpt-bench-sizes-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temp dir");
    let path = dir.join("ops.log");
    {
        let (mut store, _, _) = OpStore::<TestPayload>::open(&path).expect("a new store");
        for chunk in ops.chunks(1024) {
            let refs: Vec<&Op<TestPayload>> = chunk.iter().map(VerifiedOp::op).collect();
            store.append(&refs).expect("append");
        }
    }
    let disk = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0) as usize;
    println!("| disk: store file | {:.1} |", per_op(disk, n));
    let _ = std::fs::remove_dir_all(&dir);

    // Wire: a new peer catching up on everything.
    let mut a = Side::new(log.clone(), scene.clone(), 11, 1);
    let mut b = Side::new(TLog::default(), TScene::fold(&TLog::default()), 12, 2);
    let wire = catch_up(&mut a, &mut b) as usize;
    assert_eq!(b.scene.scene_hash(), scene.scene_hash());
    println!(
        "| wire: catch-up, both directions | {:.1} |",
        per_op(wire, n)
    );
    drop((a, b));

    // The snapshot, and the memory of a log joined from it.
    let snapshot = Snapshot::capture(&log, &scene);
    let bytes = snapshot.encode().expect("encodes");
    println!(
        "| snapshot ({} ops, the scene) | {:.1} |",
        snapshot.n_ops(),
        per_op(bytes.len(), n)
    );
    drop(snapshot);
    let before = live();
    let joined = Snapshot::<TestPayload>::decode(&bytes)
        .expect("decodes")
        .join::<TestScene>(TLog::default(), Timestamp(0))
        .expect("joins");
    println!(
        "| memory: joined log + scene, live | {:.1} |",
        per_op(live() - before, n)
    );
    // The joined peer holds everything: sync only says so.
    let mut a = Side::new(log, scene.clone(), 11, 1);
    let mut b = Side::new(joined.0, joined.1, 12, 2);
    let wire = catch_up(&mut a, &mut b);
    println!("| wire: joined peer syncing with its producer (total bytes) | {wire} |");
    assert_eq!(b.scene.scene_hash(), scene.scene_hash());
}
