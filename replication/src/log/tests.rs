//! Tests of the op log: causal delivery, linear order, lease marks, undo/redo, late ops,
//! delivery-order independence and merge laws.

use super::*;
use crate::payload::test_payload::TestPayload;
use proptest::prelude::*;
use rand_chacha::ChaCha20Rng;
use rand_core::{RngCore, SeedableRng};

pub(crate) type TLog = Log<TestPayload>;

pub(crate) fn key(i: u8) -> Keypair {
    Keypair::from_seed([i + 1; 32])
}

pub(crate) fn set(object: u64, value: &str) -> TestPayload {
    TestPayload::Set {
        object,
        value: value.into(),
    }
}

pub(crate) fn weak(object: u64, ttl_micros: u64) -> TestPayload {
    TestPayload::Acquire {
        object,
        strong: false,
        ttl_micros,
    }
}

/// The observable outcome of a log: linear order, marks and active flags.
fn observe(log: &TLog) -> Vec<(OpId, Mark, bool)> {
    log.entries()
        .map(|e| (e.op.id(), e.mark, e.active))
        .collect()
}

/// A random workload by `n_authors` replicas that author ops and merge each other at random,
/// so ops are concurrent in many ways. Returns every op, each author's in seq order.
pub(crate) fn workload(seed: u64, n_authors: u8, n_steps: usize) -> Vec<VerifiedOp<TestPayload>> {
    let mut rng = ChaCha20Rng::seed_from_u64(seed);
    let keys: Vec<Keypair> = (0..n_authors).map(key).collect();
    let mut replicas: Vec<TLog> = (0..n_authors).map(|_| TLog::default()).collect();
    let mut all = Vec::new();
    for step in 0..n_steps {
        let now = Timestamp(step as u64 * 1000);
        let a = (rng.next_u32() % u32::from(n_authors)) as usize;
        if rng.next_u32() % 3 == 0 {
            let b = (rng.next_u32() % u32::from(n_authors)) as usize;
            if a != b {
                let other = replicas[b].clone();
                replicas[a].merge(now, &other).unwrap();
            }
        }
        let object = u64::from(rng.next_u32() % 2);
        let own_edits: Vec<OpId> = replicas[a]
            .entries()
            .filter(|e| e.op.author() == keys[a].peer_id())
            .filter(|e| matches!(e.op.payload(), TestPayload::Set { .. }))
            .map(|e| e.op.id())
            .collect();
        let pick = |rng: &mut ChaCha20Rng| own_edits[(rng.next_u32() as usize) % own_edits.len()];
        let payload = match rng.next_u32() % 8 {
            0 => weak(object, 5000),
            1 => TestPayload::Acquire {
                object,
                strong: true,
                ttl_micros: 3000,
            },
            2 => TestPayload::Release { object },
            3 if !own_edits.is_empty() => TestPayload::Undo(pick(&mut rng)),
            4 if !own_edits.is_empty() => TestPayload::Redo(pick(&mut rng)),
            5 => TestPayload::Chat(format!("hi {step}")),
            _ => set(object, &format!("v{step}")),
        };
        let (op, _) = replicas[a].author(&keys[a], now, payload).unwrap();
        all.push(op);
    }
    all
}

pub(crate) fn deliver_all(ops: &[VerifiedOp<TestPayload>]) -> TLog {
    let mut log = TLog::default();
    for op in ops {
        log.insert(Timestamp(0), op.clone(), Origin(1)).unwrap();
    }
    log
}

pub(crate) fn shuffled(ops: &[VerifiedOp<TestPayload>], seed: u64) -> Vec<VerifiedOp<TestPayload>> {
    let mut rng = ChaCha20Rng::seed_from_u64(seed);
    let mut v = ops.to_vec();
    for i in (1..v.len()).rev() {
        let j = (rng.next_u32() as usize) % (i + 1);
        v.swap(i, j);
    }
    v
}

#[test]
fn out_of_order_ops_wait_for_their_past() {
    let ops = workload(1, 2, 12);
    let mut log = TLog::default();
    let last = ops.last().unwrap().clone();
    let ins = log.insert(Timestamp(0), last.clone(), Origin(1)).unwrap();
    assert!(ins.parked && ins.delivered.is_empty());
    assert_eq!(log.n_pending(), 1);
    for op in &ops[..ops.len() - 1] {
        log.insert(Timestamp(0), op.clone(), Origin(1)).unwrap();
    }
    assert_eq!(log.len(), ops.len());
    assert_eq!(log.n_pending(), 0);
    assert!(log.contains(&last.id()));
    // Duplicates change nothing.
    assert!(log.insert(Timestamp(0), last, Origin(2)).unwrap().duplicate);
}

#[test]
fn linear_order_respects_causality() {
    let ops = workload(2, 3, 40);
    let log = deliver_all(&shuffled(&ops, 9));
    let pos: BTreeMap<OpId, usize> = log
        .linear_ids()
        .enumerate()
        .map(|(i, id)| (id, i))
        .collect();
    for op in &ops {
        for dep in op.deps() {
            assert!(pos[dep] < pos[&op.id()], "dep after op");
        }
        if let Some(prev) = log.by_seq(&op.author(), op.seq() - 1) {
            assert!(pos[&prev.id()] < pos[&op.id()], "own previous op after op");
        }
    }
}

#[test]
fn edits_need_the_lease_and_rejections_are_queryable() {
    let (a, b) = (key(0), key(1));
    let mut log = TLog::default();
    log.author(&a, Timestamp(10), weak(1, 1_000)).unwrap();
    let (ok, _) = log.author(&a, Timestamp(20), set(1, "x")).unwrap();
    let (blocked, _) = log.author(&b, Timestamp(30), set(1, "y")).unwrap();
    let (other_obj, _) = log.author(&b, Timestamp(40), set(2, "z")).unwrap();
    let (late, _) = log.author(&b, Timestamp(2_000), set(1, "w")).unwrap();
    assert!(log.is_active(&ok.id()));
    assert_eq!(
        log.mark(&blocked.id()),
        Some(Mark::Rejected(RejectReason::LeaseHeld {
            holder: a.peer_id()
        }))
    );
    assert!(log.is_active(&other_obj.id()));
    assert!(log.is_active(&late.id()), "the lease expired by then");
    assert_eq!(
        log.rejected_by(&b.peer_id()),
        vec![(
            blocked.id(),
            RejectReason::LeaseHeld {
                holder: a.peer_id()
            }
        )]
    );
    assert!(log.rejected_by(&a.peer_id()).is_empty());
    assert_eq!(
        log.lease(ObjectId(1), Timestamp(500)).map(|l| l.holder),
        Some(a.peer_id())
    );
    assert_eq!(log.lease(ObjectId(1), Timestamp(5_000)), None);
}

#[test]
fn late_op_refolds_from_its_position_and_flips_marks() {
    let (a, b) = (key(0), key(1));
    // B works offline: acquires object 1 at lamport 1.
    let mut offline = TLog::default();
    let (b_acquire, _) = offline
        .author(&b, Timestamp(5), weak(1, 1_000_000))
        .unwrap();
    // A, not knowing, edits object 1 three times.
    let mut log = TLog::default();
    let mut a_ops = Vec::new();
    for i in 0..3 {
        a_ops.push(
            log.author(&a, Timestamp(10 + i), set(1, &format!("{i}")))
                .unwrap()
                .0,
        );
    }
    assert!(a_ops.iter().all(|op| log.is_active(&op.id())));
    // B's acquire arrives late. Lamport 1 and B's key: its place in the order decides.
    let ins = log
        .insert(Timestamp(100), b_acquire.clone(), Origin(1))
        .unwrap();
    let refold = ins.refold.unwrap();
    let b_pos = log
        .linear_ids()
        .position(|id| id == b_acquire.id())
        .unwrap();
    assert_eq!(refold.from, b_pos);
    assert_eq!(refold.objects.get(&ObjectId(1)), Some(&b_pos));
    for op in &a_ops {
        let pos = log.linear_ids().position(|id| id == op.id()).unwrap();
        let expected_active = pos < b_pos;
        assert_eq!(
            log.is_active(&op.id()),
            expected_active,
            "op at {pos}, acquire at {b_pos}"
        );
    }
}

#[test]
fn refused_ops_are_counted() {
    let a = key(0);
    let mut log = TLog::default();
    let (op1, _) = log.author(&a, Timestamp(1), set(1, "x")).unwrap();
    // Same author, same seq, different content: equivocation.
    let fork = Op::sign(
        &a,
        OpFields {
            seq: 1,
            lamport: 1,
            timestamp: Timestamp(2),
            deps: vec![],
            payload: set(1, "y"),
        },
    )
    .unwrap();
    assert_eq!(
        log.insert(Timestamp(0), fork, Origin(1)),
        Err(InsertError::Equivocation {
            author: a.peer_id(),
            seq: 1
        })
    );
    // Lamport time not above its dependency.
    let bad = Op::sign(
        &key(1),
        OpFields {
            seq: 1,
            lamport: 1,
            timestamp: Timestamp(2),
            deps: vec![op1.id()],
            payload: set(2, "z"),
        },
    )
    .unwrap();
    assert!(matches!(
        log.insert(Timestamp(0), bad, Origin(1)),
        Err(InsertError::BadLamport { .. })
    ));
    // Forged author: decode a tampered encoding.
    let mut bytes = op1.encoded().to_vec();
    bytes[1..33].copy_from_slice(&key(2).peer_id().0);
    let forged = Op::<TestPayload>::decode(&bytes).unwrap();
    assert!(
        forged.into_verified().is_err(),
        "a forged op never reaches the log"
    );
    assert_eq!(log.stats().n_refused, 2);
    assert_eq!(log.len(), 1);
}

#[test]
fn many_ops_cross_checkpoints_consistently() {
    // Enough ops to cross several checkpoints; a late op at the start must give the same
    // result as a log built in order.
    let ops = workload(3, 3, CHECKPOINT_INTERVAL * 2 + 40);
    let in_order = deliver_all(&ops);
    let mut late_first = ops.clone();
    let first_b = late_first
        .iter()
        .position(|op| op.author() == key(1).peer_id())
        .unwrap();
    let moved = late_first.remove(first_b);
    late_first.push(moved);
    assert_eq!(observe(&deliver_all(&late_first)), observe(&in_order));
}

proptest! {
    #![proptest_config(crate::test_config(32))]

    #[test]
    fn delivery_order_does_not_matter(seed in any::<u64>(), perm in any::<u64>()) {
        let ops = workload(seed, 3, 30);
        let a = deliver_all(&ops);
        let b = deliver_all(&shuffled(&ops, perm));
        prop_assert_eq!(a.len(), ops.len());
        prop_assert_eq!(observe(&a), observe(&b));
        prop_assert_eq!(a.version_vector(), b.version_vector());
        prop_assert_eq!(a.heads().collect::<Vec<_>>(), b.heads().collect::<Vec<_>>());
    }

    #[test]
    fn merge_is_commutative_associative_idempotent(seed in any::<u64>(), cuts in any::<[u64; 3]>()) {
        let ops = workload(seed, 3, 24);
        // Three replicas each holding a random subset (possibly not causally closed).
        let subset = |salt: u64| -> TLog {
            let picked: Vec<_> = shuffled(&ops, salt).into_iter().take((salt % 24) as usize).collect();
            deliver_all(&picked)
        };
        let (x, y, z) = (subset(cuts[0]), subset(cuts[1]), subset(cuts[2]));
        let merged = |parts: &[&TLog]| -> TLog {
            let mut out = TLog::default();
            for p in parts { out.merge(Timestamp(0), p).unwrap(); }
            out
        };
        prop_assert_eq!(observe(&merged(&[&x, &y])), observe(&merged(&[&y, &x])));
        let xy = merged(&[&x, &y]);
        let yz = merged(&[&y, &z]);
        prop_assert_eq!(observe(&merged(&[&xy, &z])), observe(&merged(&[&x, &yz])));
        prop_assert_eq!(observe(&merged(&[&x, &x])), observe(&x));
        let mut again = xy.clone();
        again.merge(Timestamp(0), &xy).unwrap();
        prop_assert_eq!(observe(&again), observe(&xy));
    }

    #[test]
    fn undo_n_then_redo_n_restores_state(n_edits in 1usize..8, n_undo in 0usize..8) {
        let a = key(0);
        let mut log = TLog::default();
        let mut t = 0;
        let mut edits = Vec::new();
        for i in 0..n_edits {
            t += 1;
            edits.push(log.author(&a, Timestamp(t), set(i as u64 % 2, &format!("{i}"))).unwrap().0.id());
        }
        let active_before: Vec<bool> = edits.iter().map(|id| log.is_active(id)).collect();
        let n = n_undo.min(n_edits);
        for id in edits.iter().rev().take(n) {
            t += 1;
            let (u, _) = log.author(&a, Timestamp(t), TestPayload::Undo(*id)).unwrap();
            prop_assert_eq!(log.mark(&u.id()), Some(Mark::Effective));
            prop_assert!(!log.is_active(id));
        }
        for id in edits.iter().rev().take(n).collect::<Vec<_>>().into_iter().rev() {
            t += 1;
            let (r, _) = log.author(&a, Timestamp(t), TestPayload::Redo(*id)).unwrap();
            prop_assert_eq!(log.mark(&r.id()), Some(Mark::Effective));
        }
        let active_after: Vec<bool> = edits.iter().map(|id| log.is_active(id)).collect();
        prop_assert_eq!(active_before, active_after);
    }
}

/// The object an op's verdict matters to, as the scene fold sees it.
fn fold_object(log: &TLog, op: &Op<TestPayload>) -> Option<ObjectId> {
    match op.payload().effect() {
        Effect::Independent => None,
        Effect::Edit { object } | Effect::Acquire { object, .. } | Effect::Release { object } => {
            Some(object)
        }
        Effect::Undo { target } | Effect::Redo { target } => {
            match log.get(&target)?.payload().effect() {
                Effect::Edit { object } => Some(object),
                _ => None,
            }
        }
    }
}

proptest! {
    #![proptest_config(crate::test_config(24))]

    /// Every op whose verdict or activity an insertion changed lies at or after the refold
    /// position reported for its object, so a per-object refold from there is complete.
    #[test]
    fn refold_report_covers_every_change(seed in any::<u64>(), perm in any::<u64>()) {
        let ops = workload(seed, 3, 30);
        let mut log = TLog::default();
        for op in shuffled(&ops, perm) {
            let before: BTreeMap<OpId, (Mark, bool)> =
                log.entries().map(|e| (e.op.id(), (e.mark, e.active))).collect();
            let ins = log.insert(Timestamp(0), op, Origin(1)).unwrap();
            let Some(refold) = ins.refold else {
                prop_assert!(ins.delivered.is_empty());
                continue;
            };
            for (pos, e) in log.entries().enumerate() {
                let now = (e.mark, e.active);
                if before.get(&e.op.id()) == Some(&now) {
                    continue;
                }
                prop_assert!(refold.from <= pos);
                if let Some(object) = fold_object(&log, e.op) {
                    let from = refold.objects.get(&object).copied();
                    prop_assert!(from.is_some_and(|f| f <= pos), "{object:?} changed at {pos}, refold {from:?}");
                }
            }
        }
    }
}

#[test]
fn more_concurrent_heads_than_max_deps_still_author() {
    // 40 peers write at once; a 41st has seen all their ops, so its frontier has 40 heads.
    let mut log = TLog::default();
    for i in 0..40 {
        let mut theirs = TLog::default();
        let (op, _) = theirs
            .author(&key(i), Timestamp(1), set(u64::from(i), "x"))
            .unwrap();
        log.insert(Timestamp(1), op, Origin(1)).unwrap();
    }
    assert_eq!(log.heads().count(), 40);
    let (first, _) = log
        .author(&key(200), Timestamp(2), set(0, "after all"))
        .unwrap();
    assert_eq!(first.deps().len(), MAX_DEPS);
    assert_eq!(first.lamport(), 2, "it still follows everything seen");
    // The heads left out stay heads, and the next op names them.
    assert_eq!(log.heads().count(), 40 - MAX_DEPS + 1);
    let (second, _) = log
        .author(&key(200), Timestamp(3), set(0, "and the rest"))
        .unwrap();
    assert_eq!(second.deps().len(), 40 - MAX_DEPS + 1);
    assert_eq!(log.heads().count(), 1);
}

#[test]
fn a_lamport_leap_towards_exhaustion_is_refused() {
    let mut log = TLog::default();
    let (first, _) = log.author(&key(1), Timestamp(1), set(1, "x")).unwrap();
    let leap = |lamport| {
        Op::sign(
            &key(2),
            OpFields {
                seq: 1,
                lamport,
                timestamp: Timestamp(2),
                deps: vec![first.id()],
                payload: set(2, "y"),
            },
        )
        .unwrap()
    };
    let far = first.lamport() + MAX_LAMPORT_JUMP + 1;
    assert!(matches!(
        log.insert(Timestamp(2), leap(far), Origin(1)),
        Err(InsertError::LamportJump { .. })
    ));
    assert!(matches!(
        log.insert(Timestamp(2), leap(u64::MAX), Origin(1)),
        Err(InsertError::LamportJump { .. })
    ));
    // The largest leap allowed is accepted, and authoring goes on after it.
    log.insert(Timestamp(2), leap(far - 1), Origin(1)).unwrap();
    log.author(&key(1), Timestamp(3), set(1, "z")).unwrap();
}
