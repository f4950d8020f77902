//! The bar: 32 honest peers and 10^4 ops under the chaos mix (loss, duplication,
//! reordering by jitter, partitions, peers offline, crashes and restarts) plus a hostile peer
//! converge on every seed of the CI set, and every checker passes.
//!
//! One test per seed, so the test runner spreads them over the cores. `replication` and
//! `simulator` are optimised in the dev profile (root Cargo.toml), so each takes about as long
//! as a release run. The same runs from the command line:
//! `cargo run -p simulator --release -- --seed 1 --peers 32 --ops 10000 --faults chaos`.

use simulator::config::{Config, Faults};
use simulator::sim::run;

const N_PEERS: usize = 32;
const N_OPS: usize = 10_000;

fn thirty_two_peers_converge(seed: u64) {
    let faults = Faults::named("chaos").expect("the chaos preset");
    let report = run(Config::new(seed, N_PEERS, N_OPS, faults)).expect("a valid config");
    assert!(report.passed(), "{report}");
    let stats = &report.stats;
    // Every action of the workload (plus the session's opening op) was authored, or skipped
    // by a peer that had not joined yet; none was refused by the core.
    assert_eq!(stats.n_author_errors, 0, "{report}");
    assert_eq!(
        stats.n_ops_authored + stats.n_actions_skipped,
        N_OPS as u64 + 1,
        "{report}"
    );
    // Everywhere: what was authored, less what crashes lost before it was synced, plus the
    // hostile member's own ops.
    assert_eq!(
        report.n_log_ops as u64,
        stats.n_ops_authored - report.n_lost_own_ops as u64 + report.n_hostile_ops_accepted as u64,
        "{report}"
    );
    // Every fault of the mix really happened.
    assert!(stats.n_lost > 0, "{report}");
    assert!(stats.n_duplicated > 0, "{report}");
    assert!(stats.n_partition_drops > 0, "{report}");
    assert!(stats.n_crashes > 0, "{report}");
    assert!(stats.n_hostile_messages > 0, "{report}");
    assert!(stats.n_hostile_rejects > 0, "{report}");
    println!("{report}");
}

#[test]
fn thirty_two_peers_ten_thousand_ops_under_chaos_seed_1() {
    thirty_two_peers_converge(1);
}

#[test]
fn thirty_two_peers_ten_thousand_ops_under_chaos_seed_2() {
    thirty_two_peers_converge(2);
}
