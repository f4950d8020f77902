//! What an op arriving in order costs the allocator: the profile of in-order apply (issue 18's
//! 10^6 ops/s goal) was led by allocations per op, most of them for work that found nothing.

#[path = "../benches/common/mod.rs"]
mod common;

use common::{NOW, TLog, TScene, history};
use replication::pending::Origin;
use testkit::alloc::{CountingAlloc, allocations_in};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

/// Allocator calls (allocations, frees and reallocations) per op, over the first 4,000 ops of
/// the benches' in-order workload: 6.42 for the log until an insertion's delivered ops and its
/// refold's one object were held inline and the paths that find nothing stopped allocating;
/// then 0.47, until ops answered from their horizon stopped growing the reach memo; 0.14 on
/// 2026-11-28 (what remains is the log's indexes growing).
const MAX_LOG_CALLS_PER_OP: f64 = 0.3;

#[test]
fn an_op_arriving_in_order_costs_the_log_few_allocator_calls() {
    let ops = history(4000);
    let n = ops.len() as f64;
    let mut log = TLog::default();
    let mut scene = TScene::fold(&log);
    let (mut n_log, mut n_scene) = (0, 0);
    for op in ops {
        let mut insertion = None;
        n_log += allocations_in(|| {
            insertion = Some(log.insert(NOW, op, Origin(1)).expect("in order"));
        });
        let insertion = insertion.expect("inserted");
        assert!(insertion.refold.is_some(), "every op changes the log");
        n_scene += allocations_in(|| scene.apply_insertion(&log, &insertion));
        n_log += allocations_in(|| drop(insertion));
    }
    let (log_per_op, scene_per_op) = (n_log as f64 / n, n_scene as f64 / n);
    eprintln!("allocator calls per op: log {log_per_op:.2}, scene {scene_per_op:.2}");
    assert!(
        log_per_op <= MAX_LOG_CALLS_PER_OP,
        "the log made {log_per_op:.2} allocator calls per op"
    );
    // The test scene copies each value into a string it already holds.
    assert!(
        scene_per_op <= 0.1,
        "the scene made {scene_per_op:.2} per op"
    );
}
