//! Tests of the op log: causal delivery, linear order, lease marks, undo/redo, late ops,
//! delivery-order independence and merge laws.

use super::*;
use crate::membership::{FounderCommitment, Membership};
use crate::payload::LeaseAction;
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
    TestPayload::Lease(LeaseAction::Acquire {
        object,
        strong: false,
        ttl_micros,
    })
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
    workload_with_marks(seed, n_authors, n_steps).0
}

/// [`workload`], with each op's mark at its author's replica right after it was authored.
pub(crate) fn workload_with_marks(
    seed: u64,
    n_authors: u8,
    n_steps: usize,
) -> (Vec<VerifiedOp<TestPayload>>, BTreeMap<OpId, Mark>) {
    workload_in(seed, n_authors, n_steps, None)
}

/// The nonce of author 0's founder commitment in [`founded_workload`].
const FOUNDER_NONCE: [u8; 32] = [0xf0; 32];

/// A log of a session founded by author 0 ([`key`]`(0)` with [`FOUNDER_NONCE`]).
pub(crate) fn founded_log() -> TLog {
    let mut log = TLog::default();
    log.set_founder(FounderCommitment::of(&key(0).peer_id(), &FOUNDER_NONCE))
        .unwrap();
    log
}

/// [`workload`] in a session founded by author 0, who now and then expels or readmits
/// another author; the others send membership ops too, which must count for nothing.
pub(crate) fn founded_workload(
    seed: u64,
    n_authors: u8,
    n_steps: usize,
) -> Vec<VerifiedOp<TestPayload>> {
    workload_in(seed, n_authors, n_steps, Some(FOUNDER_NONCE)).0
}

/// [`workload`] where the last replica runs as a second copy of author 0 (one identity on
/// two machines): wherever the copies author without having merged each other, they fork.
pub(crate) fn twin_workload(
    seed: u64,
    n_authors: u8,
    n_steps: usize,
) -> Vec<VerifiedOp<TestPayload>> {
    workload_keys(seed, n_authors, n_steps, None, true).0
}

fn workload_in(
    seed: u64,
    n_authors: u8,
    n_steps: usize,
    founder_nonce: Option<[u8; 32]>,
) -> (Vec<VerifiedOp<TestPayload>>, BTreeMap<OpId, Mark>) {
    workload_keys(seed, n_authors, n_steps, founder_nonce, false)
}

fn workload_keys(
    seed: u64,
    n_authors: u8,
    n_steps: usize,
    founder_nonce: Option<[u8; 32]>,
    twin: bool,
) -> (Vec<VerifiedOp<TestPayload>>, BTreeMap<OpId, Mark>) {
    let mut rng = ChaCha20Rng::seed_from_u64(seed);
    let twin_of = |i: u8| if twin && i + 1 == n_authors { 0 } else { i };
    let keys: Vec<Keypair> = (0..n_authors).map(|i| key(twin_of(i))).collect();
    let new_replica = || match founder_nonce {
        Some(_) => founded_log(),
        None => TLog::default(),
    };
    let mut replicas: Vec<TLog> = (0..n_authors).map(|_| new_replica()).collect();
    let mut all = Vec::new();
    let mut marks = BTreeMap::new();
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
        let n_kinds = if founder_nonce.is_some() { 9 } else { 8 };
        let payload = match rng.next_u32() % n_kinds {
            8 => TestPayload::Member(Membership {
                member: keys[1 + (rng.next_u32() % u32::from(n_authors - 1)) as usize].peer_id(),
                expel: rng.next_u32() % 3 != 0,
                nonce: founder_nonce.unwrap_or_default(),
            }),
            0 => weak(object, 5000),
            1 => TestPayload::Lease(LeaseAction::Acquire {
                object,
                strong: true,
                ttl_micros: 3000,
            }),
            2 => TestPayload::Lease(LeaseAction::Release { object }),
            3 if !own_edits.is_empty() => TestPayload::Undo(pick(&mut rng)),
            4 if !own_edits.is_empty() => TestPayload::Redo(pick(&mut rng)),
            5 => TestPayload::Chat(format!("hi {step}")),
            6 if rng.next_u32() % 3 == 0 => TestPayload::Delete { object },
            _ => set(object, &format!("v{step}")),
        };
        let (op, _) = replicas[a].author(&keys[a], now, payload).unwrap();
        marks.insert(op.id(), replicas[a].mark(&op.id()).unwrap());
        all.push(op);
    }
    (all, marks)
}

pub(crate) fn deliver_all(ops: &[VerifiedOp<TestPayload>]) -> TLog {
    deliver_all_into(TLog::default(), ops)
}

fn deliver_all_into(mut log: TLog, ops: &[VerifiedOp<TestPayload>]) -> TLog {
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
    log.author(&a, Timestamp(5), set(1, "made")).unwrap();
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
fn a_late_acquire_does_not_bind_edits_that_never_saw_it() {
    let (a, b) = (key(0), key(1));
    // A makes object 1; B, having seen that, works offline: acquires object 1 at lamport 2.
    let mut log = TLog::default();
    log.author(&a, Timestamp(1), set(1, "made")).unwrap();
    let mut offline = TLog::default();
    offline.merge(Timestamp(1), &log).unwrap();
    let (b_acquire, _) = offline
        .author(&b, Timestamp(5), weak(1, 1_000_000))
        .unwrap();
    // A, not knowing, edits object 1 three times.
    let mut a_ops = Vec::new();
    for i in 0..3 {
        a_ops.push(
            log.author(&a, Timestamp(10 + i), set(1, &format!("{i}")))
                .unwrap()
                .0,
        );
    }
    assert!(a_ops.iter().all(|op| log.is_active(&op.id())));
    // B's acquire arrives late and sorts before A's edits, which never saw it: they stand.
    let ins = log
        .insert(Timestamp(100), b_acquire.clone(), Origin(1))
        .unwrap();
    let refold = ins.refold.unwrap();
    let b_pos = log
        .linear_ids()
        .position(|id| id == b_acquire.id())
        .unwrap();
    assert_eq!(refold.from, b_pos);
    assert_eq!(
        refold.object_keys.get(&ObjectId(1)),
        Some(&OrderKey::of(b_acquire.op()))
    );
    assert!(a_ops.iter().all(|op| log.is_active(&op.id())));
    // A's next edit saw it, and is bound by it.
    let (after, _) = log.author(&a, Timestamp(200), set(1, "after")).unwrap();
    assert_eq!(
        log.mark(&after.id()),
        Some(Mark::Rejected(RejectReason::LeaseHeld {
            holder: b.peer_id()
        }))
    );
}

#[test]
fn a_backdated_strong_acquire_binds_only_the_ops_that_saw_it() {
    let (a, c, mallory) = (key(0), key(2), key(9));
    let hoard = TestPayload::Lease(LeaseAction::Acquire {
        object: 1,
        strong: true,
        ttl_micros: u64::MAX,
    });
    let mut log = TLog::default();
    let (made, _) = log.author(&a, Timestamp(500), set(1, "made")).unwrap();
    // A fresh key: Lamport 2, stamped as early as its past allows, depending on the object's
    // creation alone, asking for the lease forever.
    let backdated = signed(&mallory, 1, 2, 500, vec![made.id()], hoard);
    let honest = signed(&a, 2, 5, 1_000, vec![made.id()], set(1, "mine"));
    log.insert(Timestamp(1_000), honest.clone(), LOCAL_ORIGIN)
        .unwrap();
    let mut other = TLog::default();
    other.merge(Timestamp(1_000), &log).unwrap();
    let concurrent = signed(&c, 1, 6, 2_000, vec![honest.id()], set(1, "theirs"));
    log.insert(Timestamp(3_000), backdated.clone(), Origin(1))
        .unwrap();
    log.insert(Timestamp(3_000), concurrent.clone(), Origin(2))
        .unwrap();
    // Both honest edits sort after the hoard and are stamped within its hour; neither saw it.
    assert!(log.is_active(&honest.id()));
    assert!(log.is_active(&concurrent.id()));
    // An edit that did see it is refused, as it would be everywhere.
    let (saw, _) = log.author(&a, Timestamp(4_000), set(1, "late")).unwrap();
    assert!(saw.deps().contains(&backdated.id()));
    assert_eq!(
        log.mark(&saw.id()),
        Some(Mark::Rejected(RejectReason::LeaseHeld {
            holder: mallory.peer_id()
        }))
    );
    // The same verdicts in any delivery order.
    let all = [made, honest, concurrent, backdated, saw];
    for seed in 0..8 {
        let shuffled_log = deliver_all_causally(&shuffled(&all, seed));
        assert_eq!(observe(&shuffled_log), observe(&log), "order {seed}");
    }
}

#[test]
fn a_delete_hides_only_the_edits_it_saw() {
    let (a, b, mallory) = (key(0), key(1), key(9));
    let mut log = TLog::default();
    let (create, _) = log.author(&a, Timestamp(1_000), set(1, "made")).unwrap();
    // A backdated delete by a fresh key, which never saw the object: it hides nothing.
    let backdated = signed(&mallory, 1, 1, 0, vec![], TestPayload::Delete { object: 1 });
    log.insert(Timestamp(2_000), backdated, Origin(1)).unwrap();
    let (edit, _) = log.author(&a, Timestamp(3_000), set(1, "edited")).unwrap();
    assert!(log.is_active(&create.id()) && log.is_active(&edit.id()));
    // B deletes what it saw (both edits); A edits concurrently.
    let mut b_log = TLog::default();
    b_log.merge(Timestamp(3_000), &log).unwrap();
    let (delete, _) = b_log
        .author(&b, Timestamp(4_000), TestPayload::Delete { object: 1 })
        .unwrap();
    let (concurrent, _) = log.author(&a, Timestamp(4_000), set(1, "again")).unwrap();
    log.insert(Timestamp(5_000), delete.clone(), Origin(2))
        .unwrap();
    assert!(log.is_hidden(&create.id()) && log.is_hidden(&edit.id()));
    assert!(!log.is_active(&create.id()));
    assert!(
        log.is_active(&concurrent.id()),
        "a concurrent edit is not erased"
    );
    // An undo of the delete brings back what it hid.
    let (undo, _) = log
        .author(&b, Timestamp(6_000), TestPayload::Undo(delete.id()))
        .unwrap();
    assert_eq!(log.mark(&undo.id()), Some(Mark::Effective));
    assert!(log.is_active(&create.id()) && log.is_active(&edit.id()));
}

/// Inserts `ops` in the given order, parking those whose past is missing.
fn deliver_all_causally(ops: &[VerifiedOp<TestPayload>]) -> TLog {
    let mut log = TLog::default();
    for op in ops {
        log.insert(Timestamp(0), op.clone(), Origin(1)).unwrap();
    }
    assert_eq!(log.n_pending(), 0);
    log
}

/// The causal past of `id` in `log`: reachable through deps and each author's previous op.
pub(crate) fn causal_past(log: &TLog, id: &OpId) -> BTreeSet<OpId> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![*id];
    while let Some(id) = stack.pop() {
        let Some(op) = log.get(&id) else { continue };
        let prev = op
            .seq()
            .checked_sub(1)
            .and_then(|s| log.by_seq(&op.author(), s))
            .map(Op::id);
        for p in op.deps().iter().copied().chain(prev) {
            if seen.insert(p) {
                stack.push(p);
            }
        }
    }
    seen
}

/// The ops reachable from `id` through deps alone (no author's previous op).
fn deps_past(log: &TLog, id: &OpId) -> BTreeSet<OpId> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![*id];
    while let Some(id) = stack.pop() {
        let Some(op) = log.get(&id) else { continue };
        for p in op.deps() {
            if seen.insert(*p) {
                stack.push(*p);
            }
        }
    }
    seen
}

/// Checks every held op's horizon against its deps' reach, and every answer of `sees` against
/// the causal past found by a plain walk (held sides of a fork included).
fn check_horizons(log: &TLog) -> Result<(), TestCaseError> {
    let dag = log.dag();
    let mut memo = Reach::default();
    for at in 0..u32::try_from(log.ops.len()).unwrap() {
        let id = log.ops.at(at).id();
        let h = log.horizons[at as usize];
        prop_assert!(h <= at, "a horizon lies at or before its op");
        let past = deps_past(log, &id);
        for before in 0..h {
            prop_assert!(
                past.contains(log.ops.at(before).id_ref()),
                "op {} before {}",
                before,
                at
            );
        }
        if log.forks().is_empty() {
            let past = causal_past(log, &id);
            for target in 0..u32::try_from(log.ops.len()).unwrap() {
                let t = log.ops.at(target).id();
                let expected = t == id || past.contains(&t);
                prop_assert_eq!(
                    dag.sees(&mut memo, &id, &t),
                    expected,
                    "{} sees {}",
                    at,
                    target
                );
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(crate::test_config(32))]

    /// Every op held before an op's horizon is in its past through deps alone, in any
    /// delivery order and with forked authors; and `sees` answers as a walk does.
    #[test]
    fn an_ops_horizon_lies_inside_its_causal_past(seed in any::<u64>(), perm in any::<u64>()) {
        let ops = workload(seed, 4, 40);
        check_horizons(&deliver_all(&shuffled(&ops, perm)))?;
        let twins = twin_workload(seed, 3, 40);
        check_horizons(&deliver_all(&shuffled(&twins, perm)))?;
    }
}

/// One author writing alone names the frontier's only head each time: each op saw every op
/// held before it, and its horizon says so.
#[test]
fn a_lone_authors_ops_see_everything_before_them() {
    let a = key(0);
    let mut log = TLog::default();
    for i in 0..20 {
        log.author(&a, Timestamp(i + 1), set(i % 3, "x")).unwrap();
    }
    let at: Vec<u32> = (0..20).collect();
    assert_eq!(log.horizons, at);
}

#[test]
fn refused_ops_are_counted() {
    let a = key(0);
    let mut log = TLog::default();
    let (op1, _) = log.author(&a, Timestamp(1), set(1, "x")).unwrap();
    // Lamport time not above its dependency.
    let bad = Op::sign(
        &key(1),
        &crate::op::UNNAMED_SESSION,
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
        forged.into_verified(&crate::op::UNNAMED_SESSION).is_err(),
        "a forged op never reaches the log"
    );
    assert_eq!(log.stats().n_refused, 1);
    assert_eq!(log.len(), 1);
}

/// A forked author: both sides are held, its ops from the fork on are rejected on both sides
/// whichever side a log saw first (so its lease binds nobody), and the honest ops built on
/// either side are delivered and judged alike everywhere.
#[test]
fn both_sides_of_a_fork_are_held_and_rejected_in_every_delivery_order() {
    let (x, h1, h2) = (key(0), key(1), key(2));
    let mut left = TLog::default();
    let (x1, _) = left.author(&x, Timestamp(10), set(1, "base")).unwrap();
    let mut right = left.clone();
    // Side a: a strong lease on object 1, then an honest edit of it that the lease binds.
    let strong = TestPayload::Lease(LeaseAction::Acquire {
        object: 1,
        strong: true,
        ttl_micros: 1_000_000,
    });
    let (xa, _) = left.author(&x, Timestamp(20), strong).unwrap();
    let (ha, _) = left.author(&h1, Timestamp(30), set(1, "h1")).unwrap();
    assert!(matches!(left.mark(&ha.id()), Some(Mark::Rejected(_))));
    // Side b: two ops of the same author, a delete that saw one, and an honest op on them.
    let (xb, _) = right.author(&x, Timestamp(21), set(2, "b")).unwrap();
    let (xb2, _) = right
        .author(&x, Timestamp(22), TestPayload::Delete { object: 2 })
        .unwrap();
    let (hb, _) = right.author(&h2, Timestamp(31), set(2, "h2")).unwrap();
    let ops = [x1.clone(), xa, ha.clone(), xb, xb2, hb.clone()];
    let mut outcomes = BTreeSet::new();
    for seed in 0..24 {
        let log = deliver_all_causally(&shuffled(&ops, seed));
        assert_eq!(log.forks().seq_of(&x.peer_id()), Some(2), "seed {seed}");
        assert_eq!(log.len(), ops.len());
        for op in &ops {
            let forked = op.author() == x.peer_id() && op.seq() >= 2;
            let expected = if forked {
                Mark::Rejected(RejectReason::Forked)
            } else {
                Mark::Effective
            };
            assert_eq!(log.mark(&op.id()), Some(expected), "seed {seed}: {op:?}");
            assert_eq!(log.is_active(&op.id()), !forked, "seed {seed}: {op:?}");
        }
        outcomes.insert(observe(&log));
    }
    assert_eq!(outcomes.len(), 1, "every delivery order gives one outcome");
    // A side that lands last still turns the first side's verdicts: the lease stops binding.
    let mut log = deliver_all_causally(&ops[..3]);
    assert!(matches!(log.mark(&ha.id()), Some(Mark::Rejected(_))));
    let ins = log.insert(Timestamp(0), ops[3].clone(), Origin(2)).unwrap();
    assert_eq!(log.mark(&ha.id()), Some(Mark::Effective));
    assert!(
        ins.refold
            .is_some_and(|r| r.object_keys.contains_key(&ObjectId(1)))
    );
    assert!(
        log.is_active(&x1.id()),
        "the author's ops before its fork stand"
    );
}

/// A fork found again lower down moves the verdicts with it, and a forked log is not cut.
#[test]
fn a_lower_fork_rejects_from_the_lower_seq() {
    let x = key(0);
    let mut left = TLog::default();
    let (x1, _) = left.author(&x, Timestamp(10), set(1, "one")).unwrap();
    let mut right = TLog::default();
    let mut ops = vec![x1.clone()];
    for i in 2..5 {
        ops.push(
            left.author(&x, Timestamp(10 + i), set(1, "left"))
                .unwrap()
                .0,
        );
    }
    let (other1, _) = right.author(&x, Timestamp(11), set(1, "other")).unwrap();
    let mut log = deliver_all_causally(&ops);
    let x3b = signed(&x, 3, 3, 30, vec![ops[1].id()], set(9, "late"));
    log.insert(Timestamp(0), x3b, Origin(2)).unwrap();
    assert_eq!(log.forks().seq_of(&x.peer_id()), Some(3));
    assert_eq!(log.mark(&ops[1].id()), Some(Mark::Effective));
    log.insert(Timestamp(0), other1, Origin(2)).unwrap();
    assert_eq!(log.forks().seq_of(&x.peer_id()), Some(1));
    for op in &ops {
        assert_eq!(
            log.mark(&op.id()),
            Some(Mark::Rejected(RejectReason::Forked))
        );
    }
}

/// Issue 50: an op of a forker checked against the other side's previous op was refused, and
/// stayed out until a peer asked for it again; learning the fork now delivers it at once.
#[test]
fn an_op_refused_against_the_other_side_is_delivered_when_the_fork_is_learnt() {
    let x = key(0);
    let chat = |text: &str| TestPayload::Chat(text.into());
    let a1 = signed(&x, 1, 50, 5_000, vec![], chat("a1"));
    let b1 = signed(&x, 1, 1, 1_000, vec![], chat("b1"));
    // Its deps leave out its previous op, which a member signing its own ops may do.
    let b2 = signed(&x, 2, 2, 1_100, vec![], chat("b2"));
    let mut log = TLog::default();
    log.insert(Timestamp(0), a1, Origin(1)).unwrap();
    assert!(matches!(
        log.insert(Timestamp(0), b2.clone(), Origin(1)),
        Err(InsertError::BadLamport { .. })
    ));
    assert!(!log.contains(&b2.id()));
    let ins = log.insert(Timestamp(0), b1.clone(), Origin(1)).unwrap();
    assert_eq!(log.forks().seq_of(&x.peer_id()), Some(1));
    assert!(ins.delivered.contains(&b2.id()), "{:?}", ins.delivered);
    assert_eq!(
        log.mark(&b2.id()),
        Some(Mark::Rejected(RejectReason::Forked))
    );
    // A log that got the fork first holds the same.
    let mut other = TLog::default();
    for op in [&b2, &b1] {
        let _ = other.insert(Timestamp(0), op.clone(), Origin(1));
    }
    let a1 = signed(&x, 1, 50, 5_000, vec![], chat("a1"));
    other.insert(Timestamp(0), a1, Origin(1)).unwrap();
    let ids = |l: &TLog| l.entries().map(|e| (e.op.id(), e.mark)).collect::<Vec<_>>();
    assert_eq!(ids(&other), ids(&log));
}

/// Two copies of one identity sculpting side by side: every delivery order of the same ops
/// gives one linear order, one set of verdicts and one activity, with the identity's ops
/// rejected from its lowest fork on, and nothing left waiting.
#[test]
fn a_twin_identity_forks_and_every_delivery_order_agrees() {
    let mut n_forked = 0;
    for seed in 0..12 {
        let ops = twin_workload(seed, 4, 60);
        let reference = deliver_all(&ops);
        assert_eq!(reference.n_pending(), 0);
        let twin = key(0).peer_id();
        if let Some(fork) = reference.forks().seq_of(&twin) {
            n_forked += 1;
            for e in reference.entries() {
                let forked = e.op.author() == twin && e.op.seq() >= fork;
                assert_eq!(forked, e.mark == Mark::Rejected(RejectReason::Forked));
            }
        }
        for order in 0..4 {
            let log = deliver_all(&shuffled(&ops, seed * 100 + order));
            assert_eq!(log.n_pending(), 0, "seed {seed} order {order}");
            assert_eq!(log.forks().seq_of(&twin), reference.forks().seq_of(&twin));
            assert_eq!(
                observe(&log),
                observe(&reference),
                "seed {seed} order {order}"
            );
        }
    }
    assert!(n_forked >= 6, "only {n_forked} of 12 workloads forked");
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
    #![proptest_config(crate::test_config(256))]

    /// The in-order shortcut finds the same point as a binary search, wherever it lies.
    #[test]
    fn the_point_near_the_end_is_the_partition_point(
        mut list in proptest::collection::vec(0u8..40, 0..12),
        key in 0u8..42,
    ) {
        list.sort_unstable();
        prop_assert_eq!(
            point_near_end(&list, |x| *x < key),
            list.partition_point(|x| *x < key)
        );
    }
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

    /// A verdict depends only on the op's causal past, which its author had: every peer ends
    /// with the mark the author saw, whatever arrives later and in whatever order.
    #[test]
    fn every_mark_is_the_one_its_author_saw(seed in any::<u64>(), perm in any::<u64>()) {
        let (ops, at_author) = workload_with_marks(seed, 4, 60);
        let log = deliver_all(&shuffled(&ops, perm));
        for (id, mark) in &at_author {
            prop_assert_eq!(log.mark(id), Some(*mark), "op {}", id);
        }
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
                    let from = refold.object_keys.get(&object).copied();
                    prop_assert!(from.is_some_and(|f| f <= OrderKey::of(e.op)), "{object:?} changed at {pos}, refold {from:?}");
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
            &crate::op::UNNAMED_SESSION,
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

/// An op signed by `key` with the given fields.
pub(crate) fn signed(
    key: &Keypair,
    seq: u64,
    lamport: u64,
    timestamp: u64,
    deps: Vec<OpId>,
    payload: TestPayload,
) -> VerifiedOp<TestPayload> {
    signed_in(
        &crate::op::UNNAMED_SESSION,
        key,
        (seq, lamport, timestamp),
        deps,
        payload,
    )
}

/// [`signed`] for `session`, with seq, Lamport time and timestamp.
pub(crate) fn signed_in(
    session: &crate::identity::SessionId,
    key: &Keypair,
    (seq, lamport, timestamp): (u64, u64, u64),
    deps: Vec<OpId>,
    payload: TestPayload,
) -> VerifiedOp<TestPayload> {
    let fields = OpFields {
        seq,
        lamport,
        timestamp: Timestamp(timestamp),
        deps,
        payload,
    };
    Op::sign(key, session, fields).unwrap()
}

#[test]
fn a_lease_asking_for_more_than_the_max_ttl_ends_at_the_max() {
    let (a, b) = (key(0), key(1));
    let mut log = TLog::default();
    let strong_forever = TestPayload::Lease(LeaseAction::Acquire {
        object: 1,
        strong: true,
        ttl_micros: u64::MAX,
    });
    log.author(&b, Timestamp(500), set(1, "made")).unwrap();
    log.author(&a, Timestamp(1000), strong_forever).unwrap();
    let (held, _) = log.author(&b, Timestamp(2000), set(1, "x")).unwrap();
    assert!(matches!(log.mark(&held.id()), Some(Mark::Rejected(_))));
    let end = 1000 + crate::lease::MAX_LEASE_TTL_MICROS;
    assert_eq!(
        log.lease(ObjectId(1), Timestamp(0)).map(|l| l.expires_at),
        Some(Timestamp(end))
    );
    let (after, _) = log.author(&b, Timestamp(end), set(1, "y")).unwrap();
    assert_eq!(log.mark(&after.id()), Some(Mark::Effective));
}

#[test]
fn an_op_stamped_before_its_causal_past_is_refused() {
    let mut log = TLog::default();
    let (first, _) = log.author(&key(0), Timestamp(5000), set(1, "x")).unwrap();
    let backdated = signed(&key(1), 1, 2, 4999, vec![first.id()], set(1, "y"));
    assert_eq!(
        log.insert(Timestamp(6000), backdated, Origin(1)),
        Err(InsertError::BadTimestamp {
            timestamp: 4999,
            floor: 5000
        })
    );
    let same_time = signed(&key(1), 1, 2, 5000, vec![first.id()], set(1, "y"));
    log.insert(Timestamp(6000), same_time, Origin(1)).unwrap();
}

#[test]
fn an_op_from_the_far_future_waits_then_lands_in_the_same_place_on_two_peers() {
    use crate::time::MAX_CLOCK_SKEW_MICROS;
    let now = 1_000_000_000u64;
    let ahead = now + MAX_CLOCK_SKEW_MICROS + 5_000_000;
    let (a, b, c) = (key(0), key(1), key(2));
    let base = signed(&a, 1, 1, now, vec![], set(1, "a"));
    let future = signed(&b, 1, 2, ahead, vec![base.id()], set(1, "future"));
    // b's next op depends on the future one and waits with it.
    let after = signed(&b, 2, 3, ahead + 1, vec![future.id()], set(1, "after"));
    // c's op is concurrent and sorts after the future one.
    let concurrent = signed(&c, 1, 2, now + 10, vec![base.id()], set(1, "c"));
    let mut x = TLog::default();
    let mut y = TLog::default();
    for op in [&base, &future, &after, &concurrent] {
        x.insert(Timestamp(now), op.clone(), Origin(1)).unwrap();
    }
    for op in [&after, &concurrent, &future, &base] {
        y.insert(Timestamp(now + 1000), op.clone(), Origin(2))
            .unwrap();
    }
    for log in [&x, &y] {
        assert_eq!(log.len(), 2, "the future op and its dependent wait");
        assert_eq!(log.n_pending(), 2);
        assert!(!log.contains(&future.id()));
    }
    let due = ahead - MAX_CLOCK_SKEW_MICROS;
    assert_eq!(x.next_due(), Some(Timestamp(due)));
    assert!(x.release_due(Timestamp(due - 1)).delivered.is_empty());
    assert_eq!(x.release_due(Timestamp(due)).delivered[..], [future.id()]);
    let released = x.release_due(Timestamp(due + 1));
    assert_eq!(released.delivered[..], [after.id()]);
    assert!(released.refold.is_some());
    // y's clock passes it later, and an insertion (a duplicate here) delivers it.
    let ins = y
        .insert(Timestamp(due + 7), concurrent.clone(), Origin(2))
        .unwrap();
    assert!(ins.duplicate);
    assert_eq!(ins.delivered[..], [future.id(), after.id()]);
    assert_eq!(x.next_due(), None);
    assert_eq!(observe(&x), observe(&y));
    let ids: Vec<OpId> = x.linear_ids().collect();
    assert_eq!(
        ids[1],
        future.id(),
        "placed by its order key, not its arrival"
    );
}

#[test]
fn a_stored_far_future_op_does_not_pin_the_clock() {
    use crate::time::MAX_CLOCK_SKEW_MICROS;
    let now = 1_700_000_000_000_000u64;
    let mut log = TLog::default();
    // A store written before the bound may hold such an op: on reopening it loads, but moves
    // the clock only to the bound, and local ops leave it out of their deps meanwhile.
    let far = signed(&key(1), 1, 1, u64::MAX - 1, vec![], set(1, "far"));
    let far_id = far.id();
    let loaded = log.insert(Timestamp(now), far, LOCAL_ORIGIN).unwrap();
    assert_eq!(loaded.delivered[..], [far_id]);
    let (mine, _) = log.author(&key(0), Timestamp(now), set(2, "x")).unwrap();
    assert_eq!(mine.timestamp(), Timestamp(now + MAX_CLOCK_SKEW_MICROS + 1));
    assert!(mine.deps().is_empty());
    assert!(log.heads().any(|h| *h == far_id));
    // From a remote, the same op waits instead of moving the clock at all.
    let mut log = TLog::default();
    let far = signed(&key(1), 1, 1, u64::MAX - 1, vec![], set(1, "far"));
    assert!(log.insert(Timestamp(now), far, Origin(1)).unwrap().parked);
    let (mine, _) = log.author(&key(0), Timestamp(now), set(2, "x")).unwrap();
    assert_eq!(mine.timestamp(), Timestamp(now));
    // One just past the bound, delivered once the clock allows, moves the clock no further
    // than the bound.
    let near = now + MAX_CLOCK_SKEW_MICROS;
    let soon = signed(&key(2), 1, 3, near + 1000, vec![mine.id()], set(1, "soon"));
    assert!(log.insert(Timestamp(now), soon, Origin(1)).unwrap().parked);
    let later = Timestamp(now + 1000);
    assert_eq!(log.release_due(later).delivered.len(), 1);
    let (next, _) = log.author(&key(0), later, set(2, "y")).unwrap();
    assert_eq!(next.timestamp(), Timestamp(near + 1001));
}

#[test]
fn an_author_over_its_quota_is_refused_the_same_on_every_log_and_others_go_on() {
    let mut author_log = TLog::default();
    let mut ops = Vec::new();
    for i in 0..12u64 {
        let (op, _) = author_log
            .author(&key(2), Timestamp(10 + i), set(1, &"v".repeat(200)))
            .unwrap();
        ops.push(op);
    }
    // A quota that holds the first ten ops and half of the eleventh.
    let ten: u64 = ops[..10].iter().map(|op| op.encoded().len() as u64).sum();
    let quota = ten + ops[10].encoded().len() as u64 / 2;
    // Two logs receiving the member's ops in different orders refuse the same one: the
    // eleventh, the first past the quota along its author's chain.
    let mut outcomes = Vec::new();
    for order in [ops.clone(), ops.iter().rev().cloned().collect()] {
        let mut log = TLog::with_author_quota(quota);
        let mut refused = Vec::new();
        for op in order {
            match log.insert(Timestamp(100), op.clone(), Origin(1)) {
                Ok(insertion) => {
                    refused.extend(insertion.refused.iter().map(|(id, _, e)| (*id, e.clone())))
                }
                Err(e) => refused.push((op.id(), e)),
            }
        }
        assert_eq!(log.len(), 10);
        assert!(log.author_bytes(&key(2).peer_id()) <= quota);
        assert_eq!(log.n_bytes(), ten);
        let (first_refused, error) = refused.first().cloned().unwrap();
        assert_eq!(first_refused, ops[10].id());
        assert!(matches!(error, InsertError::AuthorQuota { .. }), "{error}");
        // Another author is not held back by the member's quota.
        log.author(&key(3), Timestamp(200), set(2, "honest"))
            .unwrap();
        outcomes.push(observe(&log));
    }
    assert_eq!(outcomes[0], outcomes[1]);
}

#[test]
fn a_local_author_over_its_quota_gets_an_error_and_the_log_is_unchanged() {
    let mut log = TLog::with_author_quota(1_000);
    let mut n = 0;
    let error = loop {
        match log.author(&key(1), Timestamp(1 + n), set(1, &"w".repeat(100))) {
            Ok(_) => n += 1,
            Err(e) => break e,
        }
    };
    assert!(matches!(
        error,
        AuthorError::Insert(InsertError::AuthorQuota { limit: 1_000, .. })
    ));
    assert_eq!(log.len() as u64, n);
    assert!(log.n_bytes() <= 1_000);
}

#[test]
fn backdated_ops_flooding_a_long_log_refold_within_the_budget_and_land_as_without_it() {
    // A history of 20,000 ops, then a member's 100 backdated edits, each sent alone at the
    // same moment: each lands near the start, so each would re-evaluate the whole order
    // (2,000,000 positions in all without the budget) and make the scene fold its object's
    // 5,000 edits again.
    let (a, c, mallory) = (key(0), key(2), key(9));
    let n = 20_000u64;
    let mut log = TLog::default();
    for i in 0..n {
        log.author(&a, Timestamp(i), set(i % 4, "x")).unwrap();
    }
    let backdated: Vec<_> = (1..=100u64)
        .map(|i| signed(&mallory, i, i, i, vec![], set(1, "mine")))
        .collect();
    let mut reference = log.clone();
    let now = Timestamp(n + 1_000_000);
    let before = log.stats().n_refolded;
    let mut held = 0;
    for op in &backdated {
        held += usize::from(log.insert(now, op.clone(), Origin(1)).unwrap().parked);
    }
    // The first held op holds the rest of the member's chain behind it.
    assert!(
        held > 0 && log.stats().n_held_for_refold >= 1,
        "the budget holds some back"
    );
    // An honest op landing at the end is not held behind them.
    let mut other = log.clone();
    let (honest, _) = other.author(&c, now, set(1, "c")).unwrap();
    let ins = log.insert(now, honest.clone(), Origin(2)).unwrap();
    assert_eq!(ins.delivered[..], [honest.id()]);
    // The held ops wait together, are delivered together and cost one refold.
    let due = log.next_due().expect("held ops wait for the budget");
    assert!(due > now && due.0 - now.0 <= 1_000_000);
    let released = log.release_due(due);
    assert_eq!(released.delivered.len(), held);
    assert_eq!(log.n_pending(), 0);
    // Within the burst, what the budget earned meanwhile, the refold that overspent it and
    // the held batch's one refold.
    let elapsed_s = (due.0 - now.0) as f64 / 1e6;
    let budget = MAX_REFOLD_BURST_ENTRIES as f64
        + MAX_REFOLD_ENTRIES_PER_SECOND as f64 * elapsed_s
        + 2.0 * (log.len() + log.n_object_edits(ObjectId(1))) as f64;
    let refolded = log.stats().n_refolded - before;
    let charged = log.stats().n_refold_charged;
    assert!(
        refolded as f64 <= budget && charged as f64 <= budget,
        "{refolded} positions re-evaluated, {charged} charged, budget {budget}"
    );
    // Where they land does not depend on when: the same as a log that took them unheld.
    for op in backdated.iter().chain([&honest]) {
        reference.insert(now, op.clone(), LOCAL_ORIGIN).unwrap();
    }
    assert_eq!(observe(&log), observe(&reference));
    assert!(backdated.iter().all(|op| log.is_active(&op.id())));
}

proptest! {
    #![proptest_config(crate::test_config(24))]

    /// Expels and readmits (and membership ops from authors who are not the founder) give
    /// the same verdicts in any delivery order, and every change they make lies where the
    /// refold reports it.
    /// An expel never changes a verdict its author saw (no honest op is erased by it): marks
    /// are judged on causal pasts, and an expel only voids the member's own ops.
    #[test]
    fn with_expels_every_mark_is_the_one_its_author_saw(seed in any::<u64>(), perm in any::<u64>()) {
        let (ops, at_author) = workload_in(seed, 4, 60, Some(FOUNDER_NONCE));
        let log = deliver_all_into(founded_log(), &shuffled(&ops, perm));
        for (id, mark) in &at_author {
            prop_assert_eq!(log.mark(id), Some(*mark), "op {}", id);
        }
    }

    #[test]
    fn expels_give_the_same_verdicts_in_any_order_and_report_their_refolds(
        seed in any::<u64>(),
        perm in any::<u64>(),
    ) {
        let ops = founded_workload(seed, 3, 40);
        let a = deliver_all_into(founded_log(), &ops);
        let b = deliver_all_into(founded_log(), &shuffled(&ops, perm));
        prop_assert_eq!(a.len(), ops.len());
        prop_assert_eq!(observe(&a), observe(&b));
        prop_assert_eq!(a.expelled(), b.expelled());
        let mut log = founded_log();
        for op in shuffled(&ops, perm) {
            let before: BTreeMap<OpId, (Mark, bool)> =
                log.entries().map(|e| (e.op.id(), (e.mark, e.active))).collect();
            let ins = log.insert(Timestamp(0), op, Origin(1)).unwrap();
            let Some(refold) = ins.refold else {
                continue;
            };
            for (pos, e) in log.entries().enumerate() {
                if before.get(&e.op.id()) == Some(&(e.mark, e.active)) {
                    continue;
                }
                prop_assert!(refold.from <= pos);
                if let Some(object) = fold_object(&log, e.op) {
                    let from = refold.object_keys.get(&object).copied();
                    prop_assert!(from.is_some_and(|f| f <= OrderKey::of(e.op)), "{object:?} changed at {pos}, refold {from:?}");
                }
            }
        }
        prop_assert_eq!(observe(&log), observe(&a));
    }
}

#[test]
fn the_founder_expels_a_member_whose_unseen_ops_turn_void_and_whose_leases_bind_nobody_who_saw_it()
{
    let (founder, honest, mallory) = (key(0), key(1), key(9));
    let hoard = TestPayload::Lease(LeaseAction::Acquire {
        object: 2,
        strong: true,
        ttl_micros: u64::MAX,
    });
    let mut log = founded_log();
    let (two, _) = log.author(&honest, Timestamp(500), set(2, "two")).unwrap();
    let (made, _) = log
        .author(&mallory, Timestamp(1_000), set(1, "mine"))
        .unwrap();
    // The founder sees Mallory's first op only; meanwhile Mallory hoards object 2 and edits
    // object 1 again, and an honest member who saw the hoard is refused by it.
    let mut founders = founded_log();
    founders.merge(Timestamp(1_000), &log).unwrap();
    let (hoarded, _) = log.author(&mallory, Timestamp(2_000), hoard).unwrap();
    let (again, _) = log
        .author(&mallory, Timestamp(2_100), set(1, "again"))
        .unwrap();
    let (refused, _) = log
        .author(&honest, Timestamp(2_200), set(2, "honest"))
        .unwrap();
    let held_by_mallory = Some(Mark::Rejected(RejectReason::LeaseHeld {
        holder: mallory.peer_id(),
    }));
    assert_eq!(log.mark(&refused.id()), held_by_mallory);
    let membership = |member: &Keypair, expel| {
        TestPayload::Member(Membership {
            member: member.peer_id(),
            expel,
            nonce: FOUNDER_NONCE,
        })
    };
    let (expelled, _) = founders
        .author(&founder, Timestamp(3_000), membership(&mallory, true))
        .unwrap();
    // Mallory, posing as the founder with the founder's nonce, expels the honest member: it
    // counts for nothing (the nonce proves the founder's key only).
    let (forged, _) = log
        .author(&mallory, Timestamp(2_300), membership(&honest, true))
        .unwrap();
    let ins = log
        .insert(Timestamp(4_000), expelled.clone(), Origin(2))
        .unwrap();
    let refold = ins.refold.expect("the expel changed what is active");
    assert!(refold.object_keys.contains_key(&ObjectId(1)));
    assert_eq!(refold.void_from.get(&mallory.peer_id()), Some(&2));
    assert!(log.is_expelled(&mallory.peer_id()) && !log.is_expelled(&honest.peer_id()));
    assert_eq!(log.expelled().get(&mallory.peer_id()), Some(&1));
    assert!(log.is_active(&made.id()), "what the founder saw stays");
    for void in [&hoarded, &again, &forged] {
        assert!(log.is_void(&void.id()) && !log.is_active(&void.id()));
    }
    // Verdicts stand as their authors saw them: the refused edit saw the hoard, not the expel.
    assert_eq!(log.mark(&refused.id()), held_by_mallory);
    assert_eq!(log.mark(&hoarded.id()), Some(Mark::Effective));
    // An edit that saw the expel is not bound by the hoard, though its lease runs on.
    let (freed, _) = log
        .author(&honest, Timestamp(5_000), set(2, "freed"))
        .unwrap();
    assert!(log.is_active(&freed.id()));
    // Mallory goes on after seeing its expel: refused outright.
    let (after, _) = log
        .author(&mallory, Timestamp(5_000), set(3, "after"))
        .unwrap();
    let refused_expelled = Some(Mark::Rejected(RejectReason::Expelled));
    assert_eq!(log.mark(&after.id()), refused_expelled);
    // Every delivery order gives the same verdicts and activity.
    let all = [
        two,
        made.clone(),
        hoarded.clone(),
        again,
        refused.clone(),
        expelled,
        forged,
        freed.clone(),
        after.clone(),
    ];
    for seed in 0..8 {
        let other = deliver_all_into(founded_log(), &shuffled(&all, seed));
        assert_eq!(observe(&other), observe(&log), "order {seed}");
    }
    // Without a founder named, the same ops expel nobody and the hoard binds.
    let unfounded = deliver_all(&all);
    assert!(unfounded.expelled().is_empty());
    assert!(unfounded.is_active(&hoarded.id()));
    assert_eq!(unfounded.mark(&freed.id()), held_by_mallory);
    // A readmit that saw the expel cancels it: Mallory's unseen ops count again, and ops that
    // see the readmit are bound by its leases again.
    let (readmit, _) = log
        .author(&founder, Timestamp(6_000), membership(&mallory, false))
        .unwrap();
    assert_eq!(log.mark(&readmit.id()), Some(Mark::Effective));
    assert!(!log.is_expelled(&mallory.peer_id()));
    assert!(log.is_active(&hoarded.id()));
    assert_eq!(log.mark(&after.id()), refused_expelled, "a verdict stands");
    let (bound, _) = log
        .author(&honest, Timestamp(7_000), set(2, "bound"))
        .unwrap();
    assert_eq!(log.mark(&bound.id()), held_by_mallory);
    // The founder cannot expel itself, and a log with ops cannot name a founder late.
    let (own, _) = log
        .author(&founder, Timestamp(8_000), membership(&founder, true))
        .unwrap();
    assert!(log.is_active(&own.id()) && log.expelled().is_empty());
    assert_eq!(
        log.set_founder(FounderCommitment::of(&founder.peer_id(), &FOUNDER_NONCE)),
        Err(FounderError::NotEmpty)
    );
}

#[test]
fn the_founded_workload_voids_ops_and_readmits() {
    let (mut voided, mut readmitted) = (false, false);
    for seed in 0..16 {
        let log = deliver_all_into(founded_log(), &founded_workload(seed, 3, 40));
        voided |= log.entries().any(|e| log.is_void(&e.op.id()));
        readmitted |= log.entries().any(|e| {
            matches!(e.op.payload(), TestPayload::Member(m) if !m.expel && e.op.author() == key(0).peer_id())
        });
    }
    assert!(
        voided && readmitted,
        "the workload exercises expels and readmits"
    );
}

#[test]
fn strong_acquires_of_a_victims_next_objects_do_not_reject_its_creations() {
    let (victim, mallory) = (key(0), key(9));
    let hoard = |object| {
        TestPayload::Lease(LeaseAction::Acquire {
            object,
            strong: true,
            ttl_micros: u64::MAX,
        })
    };
    let mut log = TLog::default();
    log.author(&victim, Timestamp(1_000), set(1, "first"))
        .unwrap();
    // Mallory sees everything and strongly takes the ids the victim will make next.
    let hoards: Vec<_> = (2..5)
        .map(|object| {
            log.author(&mallory, Timestamp(2_000), hoard(object))
                .unwrap()
                .0
        })
        .collect();
    for h in &hoards {
        assert_eq!(
            log.mark(&h.id()),
            Some(Mark::Rejected(RejectReason::UnknownObject))
        );
    }
    // The victim, who saw the hoards, makes and edits its objects all the same.
    let made: Vec<_> = (2..5)
        .flat_map(|object| {
            let create = log.author(&victim, Timestamp(3_000), set(object, "made"));
            let edit = log.author(&victim, Timestamp(3_100), set(object, "edited"));
            [create.unwrap().0, edit.unwrap().0]
        })
        .collect();
    assert!(made.iter().all(|op| log.is_active(&op.id())));
    assert_eq!(log.lease(ObjectId(2), Timestamp(3_200)), None);
    // Once Mallory has seen an object made, its lease counts, and binds the ops that see it.
    let (taken, _) = log.author(&mallory, Timestamp(4_000), hoard(2)).unwrap();
    assert_eq!(log.mark(&taken.id()), Some(Mark::Effective));
    let (bound, _) = log
        .author(&victim, Timestamp(4_100), set(2, "bound"))
        .unwrap();
    assert_eq!(
        log.mark(&bound.id()),
        Some(Mark::Rejected(RejectReason::LeaseHeld {
            holder: mallory.peer_id()
        }))
    );
    // The same verdicts in any delivery order.
    let all: Vec<_> = log
        .entries()
        .map(|e| VerifiedOp::trusted(e.op.clone()))
        .collect();
    for seed in 0..8 {
        assert_eq!(
            observe(&deliver_all_causally(&shuffled(&all, seed))),
            observe(&log),
            "order {seed}"
        );
    }
}

#[test]
fn one_member_leasing_every_object_holds_at_most_the_cap_and_the_rest_stay_free() {
    use crate::lease::MAX_LIVE_LEASES_PER_AUTHOR;
    let (honest, mallory) = (key(0), key(9));
    let n_objects = MAX_LIVE_LEASES_PER_AUTHOR as u64 + 8;
    let mut log = TLog::default();
    for object in 0..n_objects {
        log.author(&honest, Timestamp(1_000), set(object, "made"))
            .unwrap();
    }
    let hoard = |object| {
        TestPayload::Lease(LeaseAction::Acquire {
            object,
            strong: true,
            ttl_micros: u64::MAX,
        })
    };
    let marks: Vec<Mark> = (0..n_objects)
        .map(|object| {
            let (op, _) = log
                .author(&mallory, Timestamp(2_000), hoard(object))
                .unwrap();
            log.mark(&op.id()).unwrap()
        })
        .collect();
    let (held, over) = marks.split_at(MAX_LIVE_LEASES_PER_AUTHOR);
    assert!(held.iter().all(|m| *m == Mark::Effective));
    let too_many = Mark::Rejected(RejectReason::TooManyLeases);
    assert!(over.iter().all(|m| *m == too_many), "{over:?}");
    // Renewing a lease it holds is no new lease; the honest member edits past the cap.
    let (renewed, _) = log.author(&mallory, Timestamp(2_100), hoard(0)).unwrap();
    assert_eq!(log.mark(&renewed.id()), Some(Mark::Effective));
    let (free, _) = log
        .author(&honest, Timestamp(2_200), set(n_objects - 1, "free"))
        .unwrap();
    assert!(log.is_active(&free.id()));
    let (blocked, _) = log
        .author(&honest, Timestamp(2_200), set(0, "blocked"))
        .unwrap();
    assert!(!log.is_active(&blocked.id()));
    // A release gives a slot back.
    log.author(
        &mallory,
        Timestamp(2_300),
        TestPayload::Lease(LeaseAction::Release { object: 0 }),
    )
    .unwrap();
    let (next, _) = log
        .author(&mallory, Timestamp(2_400), hoard(n_objects - 1))
        .unwrap();
    assert_eq!(log.mark(&next.id()), Some(Mark::Effective));
    let (again, _) = log
        .author(&mallory, Timestamp(2_500), hoard(n_objects - 2))
        .unwrap();
    assert_eq!(log.mark(&again.id()), Some(too_many));
    // The same verdicts in any delivery order.
    let all: Vec<_> = log
        .entries()
        .map(|e| VerifiedOp::trusted(e.op.clone()))
        .collect();
    for seed in 0..4 {
        assert_eq!(
            observe(&deliver_all_causally(&shuffled(&all, seed))),
            observe(&log),
            "order {seed}"
        );
    }
}

#[test]
fn live_leases_expire_out_of_the_cap() {
    use crate::lease::MAX_LIVE_LEASES_PER_AUTHOR;
    let (honest, mallory) = (key(0), key(9));
    let n_objects = MAX_LIVE_LEASES_PER_AUTHOR as u64 + 1;
    let mut log = TLog::default();
    for object in 0..n_objects {
        log.author(&honest, Timestamp(1_000), set(object, "made"))
            .unwrap();
    }
    for object in 0..n_objects - 1 {
        log.author(&mallory, Timestamp(2_000), weak(object, 1_000))
            .unwrap();
    }
    let (late, _) = log
        .author(&mallory, Timestamp(3_000), weak(n_objects - 1, 1_000))
        .unwrap();
    assert_eq!(
        log.mark(&late.id()),
        Some(Mark::Effective),
        "the others expired"
    );
}

/// A log of a session founded by author 0 that binds its authors, with `cap` bytes in all.
fn bound_log(cap: u64) -> TLog {
    let mut log = founded_log();
    log.bind_authors(cap).unwrap();
    log
}

fn admit(key: &Keypair, grant_bytes: u64) -> TestPayload {
    TestPayload::Admit(crate::membership::Admission {
        key: key.peer_id(),
        grant_bytes,
        nonce: None,
    })
}

/// The founder's admission of itself, which roots every budget.
fn found(founder: &Keypair) -> TestPayload {
    TestPayload::Admit(crate::membership::Admission {
        key: founder.peer_id(),
        grant_bytes: 0,
        nonce: Some(FOUNDER_NONCE),
    })
}

#[test]
fn a_bound_session_takes_a_keys_ops_only_once_its_first_names_its_admission() {
    let (founder, newcomer, stranger) = (key(0), key(1), key(9));
    let mut log = bound_log(MAX_LOG_BYTES);
    // Nobody writes before the founder's admission of itself: not even the founder.
    assert_eq!(
        log.author(&founder, Timestamp(1), set(1, "x")).unwrap_err(),
        AuthorError::NotAdmitted
    );
    log.author(&founder, Timestamp(1), found(&founder)).unwrap();
    assert_eq!(
        log.remaining_budget(&founder.peer_id()),
        Some(MAX_LOG_BYTES - log.n_bytes())
    );
    let grant = log.default_grant(&founder.peer_id());
    assert_eq!(
        grant, MAX_AUTHOR_BYTES,
        "a quarter of the cap is more than an author's quota"
    );
    let (admission, _) = log
        .author(&founder, Timestamp(2), admit(&newcomer, grant))
        .unwrap();
    log.author(&founder, Timestamp(3), set(2, "later")).unwrap();
    // The newcomer's first op names its admission, though it is no longer a head.
    let (first, _) = log.author(&newcomer, Timestamp(4), set(1, "mine")).unwrap();
    assert!(first.deps().contains(&admission.id()));
    assert_eq!(
        log.remaining_budget(&newcomer.peer_id()),
        Some(grant - first.encoded().len() as u64)
    );
    // A key minted offline is refused, whatever its first op says of itself.
    let heads: Vec<OpId> = log.heads().copied().collect();
    let lamport = log.entries().map(|e| e.op.lamport()).max().unwrap() + 1;
    let unadmitted = |payload| signed(&stranger, 1, lamport, 10, heads.clone(), payload);
    let fake_founding = TestPayload::Admit(crate::membership::Admission {
        key: stranger.peer_id(),
        grant_bytes: 0,
        nonce: Some([7; 32]),
    });
    for payload in [set(1, "sybil"), admit(&stranger, 1 << 20), fake_founding] {
        assert_eq!(
            log.insert(Timestamp(10), unadmitted(payload), Origin(1)),
            Err(InsertError::NotAdmitted {
                author: stranger.peer_id()
            })
        );
    }
    assert!(!log.is_admitted(&stranger.peer_id()) && log.is_admitted(&newcomer.peer_id()));
    // An op signed without its session is refused here.
    let old = Op::sign_v1(
        &newcomer,
        OpFields {
            seq: 2,
            lamport,
            timestamp: Timestamp(10),
            deps: heads.clone(),
            payload: set(1, "old"),
        },
    )
    .unwrap();
    assert_eq!(
        log.insert(Timestamp(10), old.clone(), Origin(1)),
        Err(InsertError::OldLayout)
    );
    // Every delivery order holds the same ops: the newcomer's wait for their admission.
    let all: Vec<_> = log
        .entries()
        .map(|e| VerifiedOp::trusted(e.op.clone()))
        .collect();
    for seed in 0..8 {
        let mut other = bound_log(MAX_LOG_BYTES);
        for op in shuffled(&all, seed) {
            other.insert(Timestamp(10), op, Origin(1)).unwrap();
        }
        assert_eq!(other.n_pending(), 0);
        assert_eq!(observe(&other), observe(&log), "order {seed}");
    }
    // A session that does not bind keeps the old rules: the stranger and the old layout pass.
    let mut unbound = founded_log();
    unbound.merge(Timestamp(10), &log).unwrap();
    unbound
        .insert(Timestamp(10), unadmitted(set(1, "sybil")), Origin(1))
        .unwrap();
    unbound.insert(Timestamp(10), old, Origin(1)).unwrap();
    assert_eq!(
        TLog::default().bind_authors(1),
        Err(FounderError::NoFounder)
    );
}

#[test]
fn grants_hold_every_author_within_its_budget_and_the_log_under_the_cap_in_any_order() {
    let (founder, member) = (key(0), key(1));
    let sybils: Vec<Keypair> = (10..20).map(key).collect();
    let cap = 40_000;
    // The member's ops as it would sign them, budgets aside: authored in a session that does
    // not bind, then delivered to logs that do.
    let mut free = founded_log();
    let mut ops = vec![
        free.author(&founder, Timestamp(1), found(&founder))
            .unwrap()
            .0,
        free.author(&founder, Timestamp(2), admit(&member, 12_000))
            .unwrap()
            .0,
    ];
    for (i, sybil) in sybils.iter().enumerate() {
        let t = 10 + i as u64;
        ops.push(
            free.author(&member, Timestamp(t), admit(sybil, 3_000))
                .unwrap()
                .0,
        );
        for j in 0..20 {
            let text = "x".repeat(200);
            ops.push(
                free.author(sybil, Timestamp(t * 100 + j), set(j, &text))
                    .unwrap()
                    .0,
            );
        }
    }
    // The founder grants more than it holds: refused, as an over-budget op is.
    let too_much = free
        .author(&founder, Timestamp(3_000), admit(&key(30), cap))
        .unwrap()
        .0;
    ops.push(too_much.clone());
    let mut accepted = None;
    for seed in 0..6 {
        let mut log = bound_log(cap);
        for op in shuffled(&ops, seed) {
            match log.insert(Timestamp(5_000), op, Origin(1)) {
                Ok(_) | Err(InsertError::AuthorQuota { .. }) => {}
                Err(e) => panic!("{e}"),
            }
        }
        assert!(log.n_bytes() <= cap, "{} bytes", log.n_bytes());
        assert!(!log.contains(&too_much.id()));
        let ids: BTreeSet<OpId> = log.linear_ids().collect();
        // Some sybil ops were refused (each sybil's grant is smaller than its writes), and
        // every order refused the same ones (ops refused wait for nothing: none is pending
        // but those whose deps were refused).
        assert!(ids.len() < ops.len() - 1);
        match &accepted {
            None => accepted = Some(ids),
            Some(first) => assert_eq!(&ids, first, "order {seed}"),
        }
    }
}
