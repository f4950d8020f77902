//! The `byzantine` presets: a hostile member that holds the invite, runs the real core and
//! crafts attacks (issue 17). A few small seeds here; campaigns run thousands from the CLI.
//!
//! Every checker must hold, the causal-erasure one included, equivocation (`byzantine-forks`)
//! too: both sides of a fork are held, the member's ops from the fork on count for nothing, and
//! every honest peer learns who forked.

use simulator::config::{Config, FaultKind, FaultSet, Faults};
use simulator::memory::CountingAlloc;
use simulator::report::Report;
use simulator::sim::run;

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

/// What the causal-erasure checker writes.
const ERASED: &str = "honest ops effective at their authors erased by";

fn runs(name: &str, without: FaultSet, seeds: std::ops::Range<u64>) -> Vec<Report> {
    let faults = Faults::named(name).expect("a preset");
    seeds
        .map(|seed| {
            let config = Config {
                without,
                ..Config::new(seed, 4, 150, faults)
            };
            run(config).expect("a valid config")
        })
        .collect()
}

#[test]
fn crafted_attacks_crash_split_and_corrupt_nothing() {
    // The attacks alone: expels close the member's connection late in the run, which a test
    // of their own covers below.
    let reports = runs(
        "byzantine",
        FaultSet::default().with(FaultKind::Expel),
        1..4,
    );
    let mut sent = std::collections::BTreeMap::new();
    for report in &reports {
        // No panic, convergence, nothing pending, no ops stamped before their causal past
        // accepted, no forged op, memory within its bound, lease verdicts as the reference,
        // and no honest op erased by one that never saw it.
        assert!(report.failures.is_empty(), "{report}");
        for (attack, n) in &report.stats.byzantine {
            *sent.entry(*attack).or_insert(0) += n;
        }
    }
    // The ops stamped before their causal past were refused (and, above, found nowhere).
    let refused = |r: &Report| r.stats.hostile_rejects.contains_key("RefusedOp");
    assert!(reports.iter().any(refused), "{}", reports[0]);
    for attack in [
        "backdated",
        "backdated-lease",
        "hoard",
        "far-future",
        "far-past",
        "sybil",
        "giant-vv",
        "oversized-batch",
        "cost-bomb",
        "take-id",
        "refold-flood",
        "hello-flood",
        "wrong-id-hello",
        "byte-flood",
    ] {
        assert!(
            sent.get(attack).is_some_and(|n| *n > 0),
            "{attack}: {sent:?}"
        );
    }
    assert!(!sent.contains_key("fork"), "{sent:?}");
    // Hellos over the allowance were counted, and so were hellos naming another peer than
    // the admitted member (each closed the connection, and the member dialed again).
    for kind in ["RepeatedHello", "WrongPeer"] {
        let counted = |r: &Report| r.stats.hostile_rejects.contains_key(kind);
        assert!(reports.iter().any(counted), "{kind}: {}", reports[0]);
    }
    // The refold floods made honest peers hold ops for their budget, and still every checker
    // passed: held ops are delivered, in place, and relayed.
    let held: u64 = reports.iter().map(|r| r.n_refold_holds).sum();
    assert!(held > 0, "{}", reports[0]);
}

#[test]
fn the_founder_expels_the_member_and_forged_expels_count_for_nothing() {
    // Peer 0 founds the session and expels the lease hoarder's key, then the key the member
    // connects with; the member forges expels of honest peers. Every checker passes: honest
    // peers agree on who is expelled (never one of them), the hoarder's ops its expel did not
    // see are void everywhere, verdicts match the reference's membership rules, and no honest
    // op is erased.
    // Whether the hoarder authors an op its expel does not see depends on the run's timing:
    // about one seed in two, so six seeds (each seed's figures differ between versions of
    // the sync's timers; the test asks for the case, not a seed's).
    let reports = runs("byzantine", FaultSet::default(), 0..6);
    let (mut expels, mut closes, mut void) = (0, 0, 0);
    let mut forged = 0;
    for report in &reports {
        assert!(report.failures.is_empty(), "{report}");
        expels += report.stats.n_expels;
        closes += report.stats.n_expel_closes;
        void += report.n_void_ops;
        forged += report
            .stats
            .byzantine
            .get("forge-expel")
            .copied()
            .unwrap_or(0);
    }
    assert!(expels >= 2 && closes > 0 && forged > 0, "{}", reports[0]);
    assert!(
        void > 0,
        "an expel voided some of the member's ops: {}",
        reports[0]
    );
    // Switched off, nobody expels and nothing is void.
    for report in runs(
        "byzantine",
        FaultSet::default().with(FaultKind::Expel),
        1..2,
    ) {
        assert!(report.failures.is_empty(), "{report}");
        assert_eq!((report.stats.n_expels, report.n_void_ops), (0, 0));
    }
}

#[test]
fn backdated_and_hoarded_leases_and_deletes_erase_no_honest_op() {
    // Backdated strong acquires asking for ever, a hoarding key and backdated deletes: none
    // erases an honest op effective at its author, on any honest peer.
    let with = runs("byzantine", FaultSet::default(), 1..4);
    let mut sent = std::collections::BTreeMap::new();
    for report in &with {
        assert!(
            !report.failures.iter().any(|f| f.contains(ERASED)),
            "{report}"
        );
        for (attack, n) in &report.stats.byzantine {
            *sent.entry(*attack).or_insert(0) += n;
        }
    }
    for attack in ["backdated", "backdated-lease", "hoard"] {
        assert!(
            sent.get(attack).is_some_and(|n| *n > 0),
            "{attack}: {sent:?}"
        );
    }
}

#[test]
fn forks_are_held_on_both_sides_and_every_checker_holds() {
    // Forks alone, then with every other attack and fault.
    let mut without = FaultSet::default();
    for kind in [
        FaultKind::Byzantine,
        FaultKind::LeaseAttacks,
        FaultKind::Crashes,
        FaultKind::LateJoins,
        FaultKind::Partitions,
        FaultKind::Offline,
        FaultKind::Flood,
        FaultKind::Expel,
    ] {
        without = without.with(kind);
    }
    let quiet = Config {
        without,
        ..Config::new(
            3,
            4,
            80,
            Faults::named("byzantine-forks").expect("a preset"),
        )
    };
    let mut reports = vec![run(quiet).expect("a valid config")];
    assert_eq!(reports[0].stats.byzantine.len(), 1, "{}", reports[0]);
    reports.extend(runs("byzantine-forks", FaultSet::default(), 1..4));
    for report in &reports {
        // Converged (the same forks known everywhere, nothing pending), the same verdicts
        // as the reference, which rejects a forked author's ops from its fork on.
        assert!(report.failures.is_empty(), "{report}");
    }
    let forked = |r: &&Report| r.stats.byzantine.get("fork").is_some_and(|n| *n > 0);
    assert!(forked(&&reports[0]), "{}", reports[0]);
    assert!(reports.iter().filter(forked).count() >= 2);
    // Each fork reached every honest peer holding its author: by the other side's ops
    // (built on, and asked for by id, or named by a have's tip) and by `Forked`.
    let learnt: u64 = reports.iter().map(|r| r.stats.n_forks_learnt).sum();
    assert!(learnt >= 8, "{learnt}");
}

#[test]
fn a_session_binding_its_authors_refuses_unadmitted_keys_and_stays_under_its_cap() {
    // Even seeds bind the authors of a founded session (every session the app makes now), odd
    // seeds keep the old rules. In both, the member admits Sybil keys of its own past their
    // grant, admits a fresh key to itself, fills what it may, and strongly acquires the ids
    // honest users take next and every object; every checker passes (no honest creation
    // refused, lease verdicts as the reference with its cap, the cap held).
    let reports = runs("byzantine", FaultSet::default(), 2..6);
    let mut sent = std::collections::BTreeMap::new();
    for report in &reports {
        assert!(report.failures.is_empty(), "{report}");
        for (attack, n) in &report.stats.byzantine {
            *sent.entry(*attack).or_insert(0) += n;
        }
        let bound = report.config.seed % 2 == 0;
        match report.session_bytes {
            Some((cap, n_bytes)) => {
                assert!(bound && cap == simulator::session::SESSION_CAP_BYTES && n_bytes <= cap);
                // The member's crafted ops under fresh keys were refused at the door.
                assert!(
                    report.stats.hostile_rejects.contains_key("RefusedOp"),
                    "{report}"
                );
            }
            None => assert!(!bound, "{report}"),
        }
    }
    for attack in [
        "admitted-sybil",
        "self-admitted",
        "cap-fill",
        "lease-predicted",
        "lease-all",
        "other-session",
    ] {
        assert!(
            sent.get(attack).is_some_and(|n| *n > 0),
            "{attack}: {sent:?}"
        );
    }
}
