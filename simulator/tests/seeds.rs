//! Fixed seeds under each fault mix converge and pass every checker; a seed replays to the same
//! trace; planted bugs are caught by the checkers and shrink to small reproducers.
//!
//! The convergence runs are 8 peers and 500 actions plus a hostile peer (a few seconds each in
//! a debug build); the CLI runs larger ones and campaigns. The counting allocator is installed
//! here, so memory per peer is measured and its bound checked.

use simulator::config::{Config, FaultKind, FaultSet, Faults, Sabotage};
use simulator::memory::CountingAlloc;
use simulator::report::Report;
use simulator::shrink::{MAX_SHRINK_RUNS, shrink};
use simulator::sim::run;

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

fn faults(name: &str) -> Faults {
    Faults::named(name).expect("a preset")
}

fn checked(config: Config) -> Report {
    run(config).expect("a valid config")
}

/// One fixed seed under `name`: every checker passes and the faults really happened.
fn converges(seed: u64, name: &str) -> Report {
    let report = checked(Config::new(seed, 8, 500, faults(name)));
    let s = &report.stats;
    assert!(report.passed(), "{report}");
    // Every action authored (or its peer had not joined yet), plus the hot object.
    assert_eq!(
        s.n_ops_authored + s.n_actions_skipped + s.n_author_errors,
        501,
        "{report}"
    );
    assert_eq!(
        report.n_log_ops as u64,
        s.n_ops_authored - report.n_lost_own_ops as u64 + report.n_hostile_ops_accepted as u64,
        "{report}"
    );
    assert!(s.n_hostile_rejects > 0 && s.n_forged_ops > 0, "{report}");
    assert!(
        s.hostile_rejects.get("BadSignature").copied().unwrap_or(0) > 0,
        "{report}"
    );
    assert!(report.n_hostile_ops_accepted > 0, "{report}");
    // The flood went three times over the burst; exactly a burst's worth got through.
    assert_eq!(report.n_flood_accepted_max, 512, "{report}");
    assert!(
        report.n_lease_verdicts_checked > 500 && report.n_lease_rejected > 0,
        "{report}"
    );
    let memory = report.memory.expect("the counting allocator is installed");
    assert!(memory.peak_bytes_max > 100_000, "{report}");
    if name != "lan" {
        assert!(s.n_lost > 0 && s.n_partition_drops > 0, "{report}");
        assert!(s.n_late_joins + s.n_snapshot_joins > 0, "{report}");
    }
    report
}

#[test]
fn a_fixed_seed_converges_on_a_lan() {
    converges(11, "lan");
}

#[test]
fn a_fixed_seed_converges_over_a_wan_with_partitions_and_late_joins() {
    converges(12, "wan");
}

#[test]
fn a_fixed_seed_converges_under_chaos_with_crashes() {
    let report = converges(13, "chaos");
    let s = &report.stats;
    assert!(s.n_crashes > 0 && s.n_stale_drops > 0, "{report}");
    assert_eq!(
        s.n_resumed_rounds, 0,
        "datagrams have no connection to dial"
    );
    // The catch-up accounting: every op a peer lacked at healing is delivered after it, and
    // the slowest peer's last delivery is the convergence time.
    let first = report.catch_up[0];
    assert_eq!(
        first.n_held_at_heal + first.n_delivered,
        report.n_log_ops,
        "{report}"
    );
    let last = (report.catch_up.iter())
        .filter(|c| c.n_insertions > 0)
        .map(|c| c.last_micros)
        .max();
    assert_eq!(last, Some(report.convergence_micros), "{report}");
    // The mean over peers lies between the fastest peer's catch-up and the slowest's.
    let mean = report.mean_catch_up_round_trips();
    let rtt = report.mean_rtt_micros as f64;
    let fastest = (report.catch_up.iter())
        .map(|c| if c.n_insertions > 0 { c.last_micros } else { 0 })
        .min()
        .unwrap();
    assert!(fastest as f64 / rtt <= mean, "{report}");
    assert!(mean < report.convergence_round_trips(), "{report}");
    assert!(report.to_string().contains(&format!(
        "a peer caught up after {mean:.2} round trips on average"
    )));
    assert!(
        report
            .to_string()
            .contains("slowest to catch up after healing: peer ")
    );
}

/// Runs `n` consecutive seeds from `first`; every one must pass.
fn passing_runs(first: u64, n: u64, config: Config) -> Vec<Report> {
    (first..first + n)
        .map(|seed| {
            let report = checked(Config {
                seed,
                ..config.clone()
            });
            assert!(report.passed(), "{report}");
            report
        })
        .collect()
}

#[test]
fn crashes_lose_only_unsynced_ops_and_recovery_cuts_torn_tails() {
    let reports = passing_runs(100, 8, Config::new(0, 4, 300, faults("chaos")));
    let sum = |f: fn(&Report) -> u64| reports.iter().map(f).sum::<u64>();
    assert!(sum(|r| r.stats.n_crashes) > 0);
    assert!(
        sum(|r| r.stats.n_lost_unsynced) > 0,
        "no crash lost an unsynced op"
    );
    assert!(sum(|r| r.stats.n_torn_tails) > 0, "no crash tore a record");
}

#[test]
fn late_peers_join_from_snapshots_and_converge() {
    // Issue 50: a joined log kept no deps for the ops before its cut, and about one run in
    // ten of this size ended with a joined peer judging a lease differently from the rest.
    let config = Config::new(0, 6, 400, faults("wan"));
    let reports = passing_runs(16, 6, config);
    let n_snapshot_joins: u64 = reports.iter().map(|r| r.stats.n_snapshot_joins).sum();
    assert!(n_snapshot_joins > 0, "no run joined from a snapshot");
    // The hostile member's snapshots (a scene that is not their ops' fold) were refused by
    // the joiners' check, who then synced op by op and converged with the rest.
    let n_refused: u64 = reports.iter().map(|r| r.stats.n_snapshots_refused).sum();
    assert!(n_refused > 0, "no planted snapshot was handed out");
}

/// Issue 53: the product's sync runs over QUIC streams, which lose no message inside a
/// connection. Under `quic`, a loss is a retransmission of that message alone and a partition
/// a stall: nothing is lost or duplicated, stalled connections are replaced, closed ones are
/// dialed again, and the runs converge.
#[test]
fn the_quic_preset_turns_losses_into_delays_and_partitions_into_stalls() {
    let reports = passing_runs(0, 6, Config::new(0, 5, 300, faults("quic-backlog")));
    let sum = |f: fn(&Report) -> u64| reports.iter().map(f).sum::<u64>();
    assert_eq!(sum(|r| r.stats.n_lost + r.stats.n_duplicated), 0);
    assert_eq!(sum(|r| r.stats.n_partition_drops), 0);
    assert!(
        sum(|r| r.stats.n_retransmitted) > 0,
        "no loss was made good"
    );
    // Each message is a stream of its own, as the node sends it: a loss holds up only its
    // message, and later ones on the connection go past it.
    assert!(
        sum(|r| r.stats.n_overtaking) > 0,
        "no message went past a lost one"
    );
    assert!(
        sum(|r| r.stats.n_stalled) > 0,
        "no partition stalled a connection"
    );
    // The smaller id of a stalled connection dials again, as the node does, and the new
    // connection replaces it once the partition is over.
    assert!(sum(|r| r.stats.n_stalls_replaced) > 0, "no stall redialed");
    assert!(sum(|r| r.stats.n_stall_redials) >= sum(|r| r.stats.n_stalls_replaced));
    // A closed connection (an outage, a restart, a late join, the long partition past the
    // idle timeout) comes back only through a dial on a LAN finder's round, admitted two
    // round trips later.
    assert!(
        sum(|r| r.stats.n_dials) > 0,
        "no closed connection was dialed"
    );
    // A peer that hears a remote after a silence, or whose dial waited out a stall, dials at
    // once the peers it has no connection to, as the node tells its finders.
    assert!(
        sum(|r| r.stats.n_resumed_rounds) > 0,
        "no sign of the network's return brought dials forward"
    );
    // Partitions left peers lacking ops at healing: the bandwidth bound counts them.
    assert!(
        (reports.iter()).all(|r| r.convergence_over_goal().is_some_and(f64::is_finite)),
        "chaos's links have a rate"
    );
    assert!(
        sum(|r| r
            .catch_up
            .iter()
            .map(|c| c.n_bytes_lacked)
            .max()
            .unwrap_or(0))
            > 0
    );
}

/// Issue 53's bandwidth-bound goal needs a large backlog at healing, which no other preset
/// leaves: under `quic-backlog` the two halves of the peers are apart for the last third of
/// the work, so every honest peer lacks the other half's ops then, and the runs converge.
/// Without the other faults that leave peers behind (random partitions, peers offline,
/// crashes, late joins), `quic` leaves less than half as much lacked, so the backlog is the
/// split's.
#[test]
fn the_backlog_preset_leaves_every_peer_lacking_the_other_halfs_work_at_healing() {
    let quiet = [
        FaultKind::Partitions,
        FaultKind::Offline,
        FaultKind::Crashes,
        FaultKind::LateJoins,
    ];
    let without = quiet.into_iter().fold(FaultSet::default(), FaultSet::with);
    let lacked = |name| {
        let config = Config {
            without,
            ..Config::new(0, 6, 600, faults(name))
        };
        let reports = passing_runs(0, 3, config);
        let lacked = |r: &Report| r.catch_up.iter().map(|c| c.n_bytes_lacked).collect();
        reports.iter().map(lacked).collect::<Vec<Vec<u64>>>()
    };
    let (split, plain) = (lacked("quic-backlog"), lacked("quic"));
    for (split, plain) in split.iter().zip(&plain) {
        let (least, most) = (split.iter().min(), plain.iter().max());
        assert!(
            least
                .zip(most)
                .is_some_and(|(l, m)| *l >= 10_000 && *l > 2 * m),
            "lacked at healing: {split:?} split, {plain:?} not"
        );
    }
}

#[test]
fn a_seed_replays_to_the_same_trace_and_another_seed_does_not() {
    let config = Config::new(21, 4, 80, faults("chaos"));
    let (a, b) = (checked(config.clone()), checked(config.clone()));
    assert!(a.passed(), "{a}");
    assert_eq!(a.trace_hash, b.trace_hash);
    assert_eq!(a.scene_hash, b.scene_hash);
    assert_eq!(a.stats.n_bytes, b.stats.n_bytes);
    let other = checked(Config { seed: 22, ..config });
    assert_ne!(a.trace_hash, other.trace_hash);
}

/// `config` fails with a failure starting `what`; it shrinks to a reproducer that still fails
/// the same way, with at most 3 peers, no hostile peer and at most `max_actions` actions.
fn caught_and_shrunk(config: Config, what: &str, max_actions: usize) {
    let report = checked(config.clone());
    assert!(!report.passed(), "the planted bug went unnoticed: {report}");
    assert!(
        report.failures.iter().any(|f| f.starts_with(what)),
        "{report}"
    );
    let shrunk = shrink(&config, MAX_SHRINK_RUNS)
        .expect("a valid config")
        .expect("it fails");
    let text = format!("{}", shrunk.report);
    assert!(!shrunk.report.passed(), "{text}");
    assert!(
        shrunk.report.failures.iter().any(|f| f.starts_with(what)),
        "{text}"
    );
    // Two peers when the bug shows between two; a dropped insertion may need a third peer's
    // ops to land in a dropped slot, depending on how the sync batches them.
    assert!(shrunk.config.n_peers <= 3, "{text}");
    assert!(!shrunk.config.hostile, "{text}");
    assert!(shrunk.config.n_actions() <= max_actions, "{text}");
    assert!(shrunk.config.n_actions() * 4 < config.n_ops, "{text}");
    // The printed command replays it: same config, same failure, same trace.
    assert!(text.contains("--actions"), "{text}");
    let again = checked(shrunk.config.clone());
    assert_eq!(again.trace_hash, shrunk.report.trace_hash);
    assert_eq!(again.failures, shrunk.report.failures);
}

/// The first seed from `first` (of `n`) whose run of `config` fails.
fn first_failing(first: u64, n: u64, config: &Config) -> Config {
    (first..first + n)
        .map(|seed| Config {
            seed,
            ..config.clone()
        })
        .find(|c| !checked(c.clone()).passed())
        .expect("the planted bug went unnoticed on every seed tried")
}

#[test]
fn dropping_every_tenth_received_insertion_is_caught_and_shrunk() {
    let config = Config {
        sabotage: Sabotage::DropEveryTenthInsertion,
        ..Config::new(31, 4, 120, faults("lan"))
    };
    let failing = first_failing(31, 10, &config);
    let text = checked(failing.clone()).to_string();
    let replay = format!(
        "--seed {} --peers 4 --ops 120 --faults lan --sabotage drop-insertions",
        failing.seed
    );
    assert!(text.contains(&replay), "{text}");
    caught_and_shrunk(failing, "peer 0:", 25);
}

#[test]
fn a_fold_in_reverse_order_is_caught_and_shrunk() {
    let config = Config {
        sabotage: Sabotage::ReverseFold,
        ..Config::new(41, 3, 80, faults("wan"))
    };
    caught_and_shrunk(config, "peer 1:", 3);
}

#[test]
fn a_wrong_lease_verdict_is_caught_by_the_reference_rules_and_shrunk() {
    let config = Config {
        sabotage: Sabotage::FlipLeaseVerdict,
        ..Config::new(51, 4, 120, faults("wan"))
    };
    caught_and_shrunk(config, "peer 0: 1 lease/undo verdicts differ", 4);
}

#[test]
fn sending_before_the_store_synced_is_caught() {
    let config = Config {
        sabotage: Sabotage::SendUnsynced,
        ..Config::new(1, 4, 200, faults("chaos"))
    };
    // The bug shows only when an author crashes before its sync and then authors again
    // before the others hand its lost op back: the quicker the sync repairs, the rarer that
    // is (one seed in eleven to fifteen of these).
    let failing = first_failing(1, 40, &config);
    let clean = checked(Config {
        sabotage: Sabotage::None,
        ..failing
    });
    assert!(clean.passed(), "{clean}");
}

#[test]
fn a_passing_run_does_not_shrink() {
    let config = Config::new(5, 2, 20, faults("lan"));
    assert!(shrink(&config, 10).expect("a valid config").is_none());
}

#[test]
fn out_of_range_configs_are_refused() {
    assert!(run(Config::new(1, 1, 10, faults("none"))).is_err());
    assert!(run(Config::new(1, 64, 10, faults("none"))).is_err());
    let bad_actions = Config {
        actions: Some(vec![3, 2]),
        ..Config::new(1, 2, 10, faults("none"))
    };
    assert!(run(bad_actions).is_err());
}
