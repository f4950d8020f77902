//! Tests of materialisation: delivery-order independence of the scene hash, incremental
//! refold against a fold from scratch, merge laws on scenes, undo/redo with concurrent
//! authors, and the lease rules checked against a naive reference fold.

use super::test_scene::TestScene;
use super::*;
use crate::identity::PeerId;
use crate::lease::{Mark, RejectReason};
use crate::log::tests::{
    TLog, causal_past, deliver_all, founded_log, founded_workload, key, set, shuffled, weak,
    workload,
};
use crate::op::VerifiedOp;
use crate::payload::LeaseAction;
use crate::payload::test_payload::TestPayload;
use crate::pending::Origin;
use crate::time::Timestamp;
use proptest::prelude::*;

type TScene = Materialized<TestPayload, TestScene>;

fn from_scratch(log: &TLog) -> TScene {
    TScene::fold(log)
}

/// Delivers `ops` one by one, keeping a scene in step with every insertion.
fn deliver_incrementally(ops: &[VerifiedOp<TestPayload>]) -> (TLog, TScene) {
    let mut log = TLog::default();
    let mut scene = from_scratch(&log);
    for op in ops {
        let ins = log.insert(Timestamp(0), op.clone(), Origin(1)).unwrap();
        scene.apply_insertion(&log, &ins);
    }
    (log, scene)
}

/// Inserts `ops` into `log` one by one: the scene kept in step equals the fold from scratch
/// after each, and the naive fold at the end.
fn incremental_equals_fold_from_scratch(
    mut log: TLog,
    ops: Vec<VerifiedOp<TestPayload>>,
) -> Result<(), TestCaseError> {
    let mut scene = from_scratch(&log);
    for op in ops {
        let ins = log.insert(Timestamp(0), op, Origin(1)).unwrap();
        scene.apply_insertion(&log, &ins);
        prop_assert_eq!(scene.scene().clone(), from_scratch(&log).scene().clone());
    }
    prop_assert_eq!(scene.scene(), &naive_scene(&log));
    Ok(())
}

/// The scene a naive fold gives: each object's last active `Set`, chat in order.
fn naive_scene(log: &TLog) -> TestScene {
    let mut scene = TestScene::default();
    for e in log.entries().filter(|e| e.active) {
        match e.op.payload() {
            TestPayload::Set { object, value } => {
                scene.objects.insert(*object, value.clone());
            }
            TestPayload::Chat(text) => scene.chat.push((OrderKey::of(e.op), text.clone())),
            _ => {}
        }
    }
    scene
}

#[test]
fn late_op_refolds_only_the_objects_it_affects() {
    let (a, b) = (key(0), key(1));
    // B, offline, takes object 1 at Lamport time 1.
    let mut offline = TLog::default();
    let (b_acquire, _) = offline
        .author(&b, Timestamp(5), weak(1, 1_000_000))
        .unwrap();
    let mut log = TLog::default();
    let mut scene = from_scratch(&log);
    for i in 0..50 {
        let (_, ins) = log
            .author(&a, Timestamp(10 + i), set(i % 5, &format!("{i}")))
            .unwrap();
        scene.apply_insertion(&log, &ins);
    }
    let before = scene.stats();
    assert_eq!(before.n_object_refolds, 0, "in-order ops only append");
    let ins = log.insert(Timestamp(100), b_acquire, Origin(1)).unwrap();
    scene.apply_insertion(&log, &ins);
    let after = scene.stats();
    assert_eq!(after.n_object_refolds - before.n_object_refolds, 1);
    // Object 1's ten edits are re-examined; none saw B's lease, so all of them stand.
    assert!(after.n_applied - before.n_applied <= 10);
    assert_eq!(scene.scene(), from_scratch(&log).scene());
    assert_eq!(
        scene.scene().objects.get(&1).map(String::as_str),
        Some("46")
    );
}

#[test]
fn insertions_applied_after_later_ones_still_converge() {
    // A sync batch reports one insertion per op; the app drains them together.
    let ops = workload(11, 3, 120);
    let mut log = TLog::default();
    let mut scene = from_scratch(&log);
    let mut queued = Vec::new();
    for (i, op) in shuffled(&ops, 3).into_iter().enumerate() {
        queued.push(log.insert(Timestamp(0), op, Origin(1)).unwrap());
        if i % 7 == 6 {
            for ins in queued.drain(..) {
                scene.apply_insertion(&log, &ins);
            }
        }
    }
    for ins in queued.drain(..) {
        scene.apply_insertion(&log, &ins);
    }
    assert_eq!(scene.scene(), from_scratch(&log).scene());
}

#[test]
fn insertions_drained_together_fold_each_object_once_and_equal_the_fold_from_scratch() {
    for order in [0, 3, 9] {
        let ops = workload(12, 3, 200);
        let ops = if order == 0 {
            ops
        } else {
            shuffled(&ops, order)
        };
        let mut log = TLog::default();
        let mut one_by_one = from_scratch(&log);
        let mut together = from_scratch(&log);
        let mut queued = Vec::new();
        for (i, op) in ops.into_iter().enumerate() {
            queued.push(log.insert(Timestamp(0), op, Origin(1)).unwrap());
            if i % 16 == 15 {
                for ins in &queued {
                    one_by_one.apply_insertion(&log, ins);
                }
                together.apply_insertions(&log, &queued);
                queued.clear();
            }
        }
        for ins in &queued {
            one_by_one.apply_insertion(&log, ins);
        }
        together.apply_insertions(&log, &queued);
        let expected = from_scratch(&log);
        assert_eq!(together.scene(), expected.scene(), "order {order}");
        assert_eq!(one_by_one.scene(), expected.scene(), "order {order}");
        let (merged, single) = (together.stats(), one_by_one.stats());
        assert!(
            merged.n_applied < single.n_applied
                && merged.n_object_refolds <= single.n_object_refolds,
            "order {order}: {merged:?} against {single:?}"
        );
    }
}

/// Authors A and B: A edits objects 0 and 1 under a lease and undoes and redoes its last `n`
/// edits, while B edits objects 1 and 2 and chats, concurrently, without leases.
fn undo_redo_ops(
    n_edits: usize,
    n_undo: usize,
    seed: u64,
) -> (Vec<VerifiedOp<TestPayload>>, Vec<OpId>) {
    let (a, b) = (key(0), key(1));
    let mut la = TLog::default();
    let mut lb = TLog::default();
    let mut undo_redo = Vec::new();
    let mut t = 0;
    let mut tick = || {
        t += 10;
        Timestamp(t)
    };
    la.author(&a, tick(), weak(0, 1_000_000_000)).unwrap();
    let mut edits = Vec::new();
    for i in 0..n_edits {
        let (op, _) = la
            .author(&a, tick(), set(i as u64 % 2, &format!("a{i}")))
            .unwrap();
        edits.push(op.id());
        let (bop, _) = lb
            .author(&b, tick(), set(1 + (i as u64 % 2), &format!("b{i}")))
            .unwrap();
        let _ = bop;
        if (seed >> i) & 1 == 1 {
            lb.merge(tick(), &la).unwrap();
        }
    }
    let n = n_undo.min(n_edits);
    for id in edits.iter().rev().take(n) {
        undo_redo.push(
            la.author(&a, tick(), TestPayload::Undo(*id))
                .unwrap()
                .0
                .id(),
        );
        lb.author(&b, tick(), TestPayload::Chat("meanwhile".into()))
            .unwrap();
    }
    for id in edits
        .iter()
        .rev()
        .take(n)
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
    {
        undo_redo.push(
            la.author(&a, tick(), TestPayload::Redo(*id))
                .unwrap()
                .0
                .id(),
        );
        lb.author(&b, tick(), set(2, "late")).unwrap();
    }
    let mut all = la.clone();
    all.merge(tick(), &lb).unwrap();
    let ops = all
        .linear_ids()
        .filter_map(|id| all.get(&id))
        .map(|op| VerifiedOp::trusted(op.clone()))
        .collect();
    (ops, undo_redo)
}

/// Checks every verdict against a naive lease model: an effective edit's author held the
/// object's lease or nobody else held it unexpired; a `LeaseHeld` rejection names a holder
/// that did hold it.
fn check_lease_rules(log: &TLog) {
    // A naive reference: each op judged on its own causal past alone, by the lease rules
    // folded from scratch over the lease ops of its object found there, in linear order.
    let entries: Vec<_> = log.entries().collect();
    for e in &entries {
        let (author, at) = (e.op.author(), e.op.timestamp().0);
        let past = causal_past(log, &e.op.id());
        let object = match e.op.payload() {
            TestPayload::Set { object, .. }
            | TestPayload::Delete { object }
            | TestPayload::Lease(LeaseAction::Acquire { object, .. })
            | TestPayload::Lease(LeaseAction::Release { object }) => *object,
            _ => continue,
        };
        // An acquire counts only once an effective creation of its object is in its past.
        let created = |id: &OpId| {
            let past = causal_past(log, id);
            entries.iter().any(|c| {
                matches!(c.op.payload(), TestPayload::Set { object: o, .. } if *o == object)
                    && c.mark == Mark::Effective
                    && c.op.id() != *id
                    && past.contains(&c.op.id())
            })
        };
        let mut held: Option<(PeerId, bool, u64)> = None;
        for l in entries.iter().filter(|l| past.contains(&l.op.id())) {
            let (h_author, h_at) = (l.op.author(), l.op.timestamp().0);
            let blocked = held.filter(|(h, _, until)| *h != h_author && h_at < *until);
            match l.op.payload() {
                TestPayload::Lease(LeaseAction::Acquire {
                    object: o,
                    strong,
                    ttl_micros,
                }) if *o == object
                    && blocked.is_none_or(|(_, s, _)| !*strong && !s)
                    && created(&l.op.id()) =>
                {
                    let ttl = (*ttl_micros).min(crate::lease::MAX_LEASE_TTL_MICROS);
                    held = Some((h_author, *strong, h_at.saturating_add(ttl)));
                }
                TestPayload::Lease(LeaseAction::Release { object: o })
                    if *o == object
                        && held.is_some_and(|(h, _, until)| h == h_author && h_at < until) =>
                {
                    held = None;
                }
                _ => {}
            }
        }
        let blocker = held.filter(|(h, _, until)| *h != author && at < *until);
        match e.op.payload() {
            TestPayload::Set { .. } | TestPayload::Delete { .. } => match e.mark {
                Mark::Effective => assert!(blocker.is_none(), "edit under a lease it saw"),
                Mark::Rejected(RejectReason::LeaseHeld { holder }) => {
                    assert_eq!(blocker.map(|b| b.0), Some(holder));
                }
                Mark::Rejected(other) => panic!("edit rejected for {other:?}"),
            },
            TestPayload::Lease(LeaseAction::Acquire { .. }) if !created(&e.op.id()) => {
                let unknown = Mark::Rejected(RejectReason::UnknownObject);
                assert_eq!(e.mark, unknown, "acquire of an object it never saw made");
            }
            TestPayload::Lease(LeaseAction::Acquire { strong, .. }) => {
                let ok = blocker.is_none_or(|(_, s, _)| !*strong && !s);
                assert_eq!(e.mark == Mark::Effective, ok, "acquire verdict");
            }
            TestPayload::Lease(LeaseAction::Release { .. }) => {
                let ok = held.is_some_and(|(h, _, until)| h == author && at < until);
                assert_eq!(e.mark == Mark::Effective, ok, "release verdict");
            }
            _ => {}
        }
        // Hidden exactly when an effective delete of its object, not undone, saw it.
        if let TestPayload::Set { .. } | TestPayload::Delete { .. } = e.op.payload() {
            let hidden = entries.iter().any(|d| {
                matches!(d.op.payload(), TestPayload::Delete { object: o } if *o == object)
                    && d.mark == Mark::Effective
                    && !log.fold_state().is_undone(&d.op.id())
                    && causal_past(log, &d.op.id()).contains(&e.op.id())
            });
            assert_eq!(
                log.is_hidden(&e.op.id()),
                hidden,
                "hidden by a delete that saw it"
            );
        }
    }
}

proptest! {
    #![proptest_config(crate::test_config(32))]

    #[test]
    fn any_delivery_order_gives_the_same_scene(seed in any::<u64>(), perm in any::<u64>()) {
        let ops = workload(seed, 3, 40);
        let (in_order_log, in_order) = deliver_incrementally(&ops);
        let (log, shuffled_scene) = deliver_incrementally(&shuffled(&ops, perm));
        prop_assert_eq!(shuffled_scene.scene_hash(), in_order.scene_hash());
        prop_assert_eq!(from_scratch(&log).scene_hash(), in_order.scene_hash());
        prop_assert_eq!(from_scratch(&in_order_log).scene().clone(), naive_scene(&in_order_log));
    }

    #[test]
    fn incremental_refold_equals_fold_from_scratch(seed in any::<u64>(), perm in any::<u64>()) {
        let ops = shuffled(&workload(seed, 3, 30), perm);
        incremental_equals_fold_from_scratch(TLog::default(), ops)?;
    }

    /// Expels and readmits void and bring back a member's ops, chat included: the scene kept
    /// in step equals the fold from scratch after every insertion, in any delivery order.
    #[test]
    fn expels_keep_the_incremental_scene_equal_to_the_fold_from_scratch(
        seed in any::<u64>(),
        perm in any::<u64>(),
    ) {
        let ops = shuffled(&founded_workload(seed, 3, 40), perm);
        incremental_equals_fold_from_scratch(founded_log(), ops)?;
    }

    #[test]
    fn merged_scenes_are_commutative_associative_idempotent(seed in any::<u64>(), cuts in any::<[u64; 3]>()) {
        let ops = workload(seed, 3, 24);
        let subset = |salt: u64| -> TLog {
            let picked: Vec<_> = shuffled(&ops, salt).into_iter().take((salt % 24) as usize).collect();
            deliver_all(&picked)
        };
        let (x, y, z) = (subset(cuts[0]), subset(cuts[1]), subset(cuts[2]));
        let merged = |parts: &[&TLog]| -> SceneHash {
            let mut out = TLog::default();
            for p in parts { out.merge(Timestamp(0), p).unwrap(); }
            from_scratch(&out).scene_hash()
        };
        prop_assert_eq!(merged(&[&x, &y]), merged(&[&y, &x]));
        let mut xy = TLog::default();
        xy.merge(Timestamp(0), &x).unwrap();
        xy.merge(Timestamp(0), &y).unwrap();
        let mut yz = TLog::default();
        yz.merge(Timestamp(0), &y).unwrap();
        yz.merge(Timestamp(0), &z).unwrap();
        prop_assert_eq!(merged(&[&xy, &z]), merged(&[&x, &yz]));
        prop_assert_eq!(merged(&[&x, &x]), from_scratch(&x).scene_hash());
    }

    #[test]
    fn undo_n_then_redo_n_restores_the_scene_with_concurrent_authors(
        n_edits in 1usize..8, n_undo in 0usize..8, seed in any::<u64>(), perm in any::<u64>(),
    ) {
        let (ops, undo_redo) = undo_redo_ops(n_edits, n_undo, seed);
        let (log, scene) = deliver_incrementally(&shuffled(&ops, perm));
        for id in &undo_redo {
            prop_assert_eq!(log.mark(id), Some(Mark::Effective));
        }
        let without: Vec<_> = ops.iter().filter(|op| !undo_redo.contains(&op.id())).cloned().collect();
        let (_, reference) = deliver_incrementally(&without);
        prop_assert_eq!(scene.scene_hash(), reference.scene_hash());
    }

    #[test]
    fn lease_rules_hold_in_the_fold(seed in any::<u64>(), perm in any::<u64>()) {
        let ops = workload(seed, 3, 40);
        let log = deliver_all(&shuffled(&ops, perm));
        check_lease_rules(&log);
        // The scene shows exactly the active edits: the last one of each object.
        prop_assert_eq!(from_scratch(&log).scene().clone(), naive_scene(&log));
    }
}
