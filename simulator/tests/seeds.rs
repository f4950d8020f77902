//! Fixed seeds under each fault mix converge and pass every checker; a seed replays to the same
//! trace; planted bugs in the merge path are caught by the checkers.
//!
//! Each run is 8 peers and 500 ops plus a hostile peer (a few seconds in a debug build); the CLI
//! runs larger ones.

use simulator::config::{Config, Faults, Sabotage};
use simulator::sim::run;

fn faults(name: &str) -> Faults {
    Faults::named(name).expect("a preset")
}

fn checked(config: Config) -> simulator::report::Report {
    run(config).expect("a valid config")
}

/// One fixed seed under `name`: every checker passes and the faults really happened.
fn converges(seed: u64, name: &str) {
    let report = checked(Config::new(seed, 8, 500, faults(name)));
    assert!(report.passed(), "{report}");
    assert_eq!(report.stats.n_ops_authored, 501, "{report}");
    assert_eq!(report.n_log_ops, 501, "{report}");
    assert!(report.stats.n_hostile_messages > 0, "{report}");
    assert!(report.stats.n_hostile_rejects > 0, "{report}");
    if name != "lan" {
        assert!(report.stats.n_lost > 0, "{report}");
        assert!(report.stats.n_partition_drops > 0, "{report}");
    }
    if name == "chaos" {
        assert!(report.stats.n_crashes > 0, "{report}");
        assert!(report.stats.n_stale_drops > 0, "{report}");
    }
}

#[test]
fn a_fixed_seed_converges_on_a_lan() {
    converges(11, "lan");
}

#[test]
fn a_fixed_seed_converges_over_a_wan_with_partitions() {
    converges(12, "wan");
}

#[test]
fn a_fixed_seed_converges_under_chaos_with_peers_offline() {
    converges(13, "chaos");
}

#[test]
fn a_seed_replays_to_the_same_trace_and_another_seed_does_not() {
    let config = Config::new(21, 4, 80, faults("chaos"));
    let (a, b) = (checked(config), checked(config));
    assert!(a.passed(), "{a}");
    assert_eq!(a.trace_hash, b.trace_hash);
    assert_eq!(a.scene_hash, b.scene_hash);
    assert_eq!(a.stats.n_bytes, b.stats.n_bytes);
    let other = checked(Config { seed: 22, ..config });
    assert_ne!(a.trace_hash, other.trace_hash);
}

#[test]
fn dropping_every_tenth_received_insertion_is_caught() {
    let config = Config {
        sabotage: Sabotage::DropEveryTenthInsertion,
        ..Config::new(31, 4, 120, faults("lan"))
    };
    let report = checked(config);
    assert!(!report.passed(), "the planted bug went unnoticed: {report}");
    assert!(
        report.failures.iter().any(|f| f.starts_with("peer 0:")),
        "{report}"
    );
    let text = report.to_string();
    assert!(
        text.contains("--seed 31 --peers 4 --ops 120 --faults lan --sabotage drop-insertions"),
        "{text}"
    );
}

#[test]
fn a_fold_in_reverse_order_is_caught() {
    let config = Config {
        sabotage: Sabotage::ReverseFold,
        ..Config::new(41, 3, 80, faults("wan"))
    };
    let report = checked(config);
    assert!(!report.passed(), "the planted bug went unnoticed: {report}");
    assert!(
        report.failures.iter().any(|f| f.starts_with("peer 1:")),
        "{report}"
    );
}

#[test]
fn out_of_range_configs_are_refused() {
    assert!(run(Config::new(1, 1, 10, faults("none"))).is_err());
    assert!(run(Config::new(1, 64, 10, faults("none"))).is_err());
}
