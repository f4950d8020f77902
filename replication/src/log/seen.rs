//! What an op saw: causal reachability over the held DAG, the lease an op's own causal past
//! gives its object, and the edits each delete saw.
//!
//! A lease binds only ops that have its acquire in their causal past, and a delete hides only
//! the edits in its causal past. Both are decided from the log's content alone (deps and each
//! author's chain of seqs), so every peer holding the same ops gets the same verdicts whatever
//! the delivery order.

use std::collections::BTreeMap;

use super::OrderKey;
use crate::causal::Reach;
use crate::identity::{OpId, PeerId};
use crate::lease::{Lease, Mark, lease_step};
use crate::op::Op;
use crate::payload::{ObjectId, Payload};

/// Most lease ops of an object, sorted before a lease op but missing from its causal past, that
/// the op remembers. An op that saw a lease op remembering its misses stops scanning there;
/// past this many it scans on (the cost grows, the verdict does not change).
pub const MAX_UNSEEN_LEASE_OPS: usize = 16;

/// One lease op (acquire or release) of an object, and what the fold learnt of it.
#[derive(Clone, Debug)]
pub(crate) struct LeaseOp {
    /// The op's order key (kept here: a refold compares it for every lease op it judges).
    pub(crate) key: OrderKey,
    /// The op's position in the log's slab (its id is read from it).
    pub(crate) at: u32,
    /// The object's lease in the fold of the whole prefix just before this op.
    pub(crate) before: Option<Lease>,
    /// The object's lease ops sorted before this one that are not in its causal past, in
    /// order, as slab positions; `None` when more than [`MAX_UNSEEN_LEASE_OPS`]. Positions
    /// alone (keys and ids are their ops'), since every lease op of a session keeps this list.
    pub(crate) unseen: Option<Box<[u32]>>,
}

/// Alternative lease folds computed during one refold, keyed by object and the lease ops
/// skipped: how far each got (an index into the object's lease ops) and the lease there.
pub(crate) type AltFolds = BTreeMap<(ObjectId, Vec<OrderKey>), (usize, Option<Lease>)>;

/// The held part of the op DAG, as reachability walks it.
pub(crate) struct Dag<'a, P> {
    pub(crate) ops: &'a crate::op::OpSlab<P>,
    /// Per held op, by slab position: every op held before this position is in its causal
    /// past, through deps alone. An op whose deps named every head of the frontier has its own
    /// position; otherwise the furthest its deps reach, one past a dep whose horizon is its
    /// own. Deps never change, so neither do horizons; prev links are left out because a fork
    /// found later cuts them.
    pub(crate) horizons: &'a [u32],
    /// What is held of each author: its chain of held ops in seq order, as positions in `ops`.
    pub(crate) authors: &'a BTreeMap<PeerId, super::Authored>,
    /// The forked authors: past its fork, an author's ops reach their past through their deps
    /// alone, and no memo or seq shortcut speaks for them.
    pub(crate) forks: &'a crate::fork::Forks,
    /// Per member, the membership ops that count, with whether each expels.
    pub(crate) members: &'a BTreeMap<PeerId, Vec<(OpId, bool)>>,
    /// The verdict on each held op, by slab position.
    pub(crate) marks: &'a super::marks::Marks,
}

impl<P: Payload> Dag<'_, P> {
    /// True if `from`'s causal past has the founder expelling `member`: an expel of it is in
    /// that past, and no readmit there saw that expel. Such an op is not bound by the member's
    /// leases, and if it is the member's own, it is rejected.
    pub(crate) fn expelled_in_past(&self, memo: &mut Reach, from: &OpId, member: &PeerId) -> bool {
        let Some(ops) = self.members.get(member) else {
            return false;
        };
        ops.iter().filter(|(_, expel)| *expel).any(|(e, _)| {
            self.sees(memo, from, e)
                && !ops
                    .iter()
                    .any(|(r, expel)| !expel && self.sees(memo, from, r) && self.sees(memo, r, e))
        })
    }

    /// How many of `chain` (an author's held ops in seq order, as positions in `ops`) are in
    /// `from`'s causal past: a prefix, since each op's previous op is in its past.
    pub(crate) fn seen_prefix(&self, memo: &mut Reach, from: &OpId, chain: &[u32]) -> usize {
        let (mut lo, mut hi) = (0, chain.len());
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.sees(memo, from, self.ops.at(chain[mid]).id_ref()) {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// True if `op` is at or past its author's fork ([`crate::fork`]): it is rejected.
    pub(crate) fn is_forked(&self, op: &Op<P>) -> bool {
        self.forks.covers(&op.author(), op.seq())
    }

    /// The author's previous held op (`None` for its first, or past the
    /// author's fork, where the previous op depends on the side).
    fn prev(&self, op: &Op<P>) -> Option<&OpId> {
        if self.forks.covers(&op.author(), op.seq().saturating_sub(1)) {
            return None;
        }
        let at = (self.authors.get(&op.author())?).at_seq(op.seq().checked_sub(1)?)?;
        Some(self.ops.at(at).id_ref())
    }

    /// The answer for `id` without walking, if there is one.
    fn quick(&self, memo: &Reach, id: &OpId, target: &Op<P>, target_at: u32) -> Option<bool> {
        if id == target.id_ref() {
            return Some(true);
        }
        // Every dep of a held op is held: an id that is not is in no held op's past.
        let Some(at) = self.ops.position(id) else {
            return Some(false);
        };
        self.quick_held(memo, at, target, target_at)
    }

    /// [`Dag::quick`] for the held op at `at`, other than the target.
    fn quick_held(&self, memo: &Reach, at: u32, target: &Op<P>, target_at: u32) -> Option<bool> {
        let op = self.ops.at(at);
        // Lamport times grow along every dependency and every author's chain.
        if op.lamport() <= target.lamport() {
            return Some(false);
        }
        if target_at < self.horizons[at as usize] {
            return Some(true);
        }
        if self.forks.covers(&op.author(), op.seq()) {
            // Two ops share this seq and may see different things: walk.
            return None;
        }
        if op.author() == target.author() && !self.forks.covers(&target.author(), target.seq()) {
            return Some(op.seq() >= target.seq());
        }
        memo.known(target_at, &op.author(), op.seq())
    }

    /// The answer for held `op` from its parents' quick answers, recorded in the memo: the walk's
    /// first step, without its stack. A live op's parents are usually answered already (its
    /// author's previous op asked the same), so most asks end here. `None` when a parent needs
    /// the walk, or for an op past its author's fork (which the memo does not keep).
    fn one_step(
        &self,
        memo: &mut Reach,
        op: &Op<P>,
        target: &Op<P>,
        target_at: u32,
    ) -> Option<bool> {
        if self.forks.covers(&op.author(), op.seq()) {
            return None;
        }
        let mut seen = false;
        for p in op.deps().iter().chain(self.prev(op)) {
            if self.quick(memo, p, target, target_at)? {
                seen = true;
                break;
            }
        }
        memo.record(target_at, op.author(), op.seq(), seen);
        Some(seen)
    }

    /// True if held op `target` is `from` or in its causal past (reachable through deps and
    /// each author's previous op). Walks each op at most once per target over the memo's life.
    pub(crate) fn sees(&self, memo: &mut Reach, from: &OpId, target_id: &OpId) -> bool {
        match self.ops.position(target_id) {
            Some(target_at) => self.sees_at(memo, from, target_at),
            // Not held: in no held op's past.
            None => false,
        }
    }

    /// [`Dag::sees`] for the target held at slab position `target_at`.
    pub(crate) fn sees_at(&self, memo: &mut Reach, from: &OpId, target_at: u32) -> bool {
        if from == self.ops.at(target_at).id_ref() {
            return true;
        }
        match self.ops.position(from) {
            Some(from_at) => self.held_sees_at(memo, from_at, target_at),
            None => false,
        }
    }

    /// [`Dag::sees_at`] for `from` held at slab position `from_at` (a caller that holds the
    /// position skips the lookup of its id).
    pub(crate) fn held_sees_at(&self, memo: &mut Reach, from_at: u32, target_at: u32) -> bool {
        if from_at == target_at {
            return true;
        }
        let target = self.ops.at(target_at);
        if let Some(known) = self.quick_held(memo, from_at, target, target_at) {
            return known;
        }
        let from_op = self.ops.at(from_at);
        let from = from_op.id_ref();
        if let Some(known) = self.one_step(memo, from_op, target, target_at) {
            return known;
        }
        // Depth-first, children before parents: an op's answer is the "or" of its parents'.
        // A parent goes back on the stack under its unanswered parents and is answered when it
        // comes up again (a memo that started afresh meanwhile only repeats some work).
        // Answers for ops past their author's fork, which the memo does not keep: this walk
        // keeps them, so each op is still answered once.
        let mut forked: BTreeMap<OpId, bool> = BTreeMap::new();
        let quick = |memo: &Reach, forked: &BTreeMap<OpId, bool>, id: &OpId| {
            (forked.get(id).copied()).or_else(|| self.quick(memo, id, target, target_at))
        };
        let mut stack = vec![*from];
        while let Some(id) = stack.pop() {
            if let Some(known) = quick(memo, &forked, &id) {
                if id == *from {
                    return known;
                }
                continue;
            }
            let Some(op) = self.ops.get(&id) else {
                continue;
            };
            let parents = || op.deps().iter().chain(self.prev(op));
            let answers = parents().map(|p| quick(memo, &forked, p));
            let mut unknown = Vec::new();
            let mut seen = false;
            for (p, answer) in parents().zip(answers) {
                match answer {
                    Some(true) => {
                        seen = true;
                        break;
                    }
                    Some(false) => {}
                    None => unknown.push(*p),
                }
            }
            if seen || unknown.is_empty() {
                if self.forks.covers(&op.author(), op.seq()) {
                    forked.insert(id, seen);
                } else {
                    memo.record(target_at, op.author(), op.seq(), seen);
                }
                if id == *from {
                    return seen;
                }
                continue;
            }
            stack.push(id);
            stack.extend(unknown);
        }
        // The walk starts from `from` and only answers it last.
        false
    }
}

/// The lease ops among `list[..n]` (an object's lease ops before `x` in the order) that are
/// not in `x`'s causal past, with their slab positions, sorted: empty when `x` saw them all.
pub(crate) fn unseen_before<P: Payload>(
    dag: &Dag<'_, P>,
    memo: &mut Reach,
    list: &[LeaseOp],
    n: usize,
    x_at: u32,
) -> Vec<(OrderKey, u32)> {
    let mut unseen = Vec::new();
    for l in list[..n].iter().rev() {
        if !dag.held_sees_at(memo, x_at, l.at) {
            unseen.push((l.key, l.at));
            continue;
        }
        // What `l` saw, `x` saw: only `l`'s own misses are left to check.
        if let Some(misses) = &l.unseen {
            for &at in misses.iter() {
                let op = dag.ops.at(at);
                if !dag.held_sees_at(memo, x_at, at) {
                    unseen.push((OrderKey::of(op), at));
                }
            }
            break;
        }
    }
    unseen.sort_unstable();
    unseen.dedup();
    unseen
}

/// The object's lease as the causal past of an op gives it: the lease rules folded, in linear
/// order, over `list[..n]` without the `unseen` lease ops. Starts from the whole prefix's lease
/// before the first unseen op (everything before it was seen), and continues a fold kept in
/// `alt` for the same object and unseen ops, so a run of ops that missed the same lease ops
/// costs one pass over the object's lease ops.
pub(crate) fn lease_seen<P: Payload>(
    dag: &Dag<'_, P>,
    memo: &mut Reach,
    list: &[LeaseOp],
    n: usize,
    unseen: &[(OrderKey, u32)],
    alt: &mut AltFolds,
    object: ObjectId,
) -> Option<Lease> {
    assert!(
        !unseen.is_empty(),
        "an op that saw every lease op uses the fold's state"
    );
    let first = list.partition_point(|l| l.key < unseen[0].0);
    let cache_key = (object, unseen.iter().map(|(k, _)| *k).collect::<Vec<_>>());
    let (mut i, mut lease) = match alt.get(&cache_key) {
        Some(&(i, lease)) if i <= n => (i, lease),
        _ => (first, list[first].before),
    };
    while i < n {
        let l = &list[i];
        let skipped = unseen.binary_search_by(|(k, _)| k.cmp(&l.key)).is_ok();
        let op = dag.ops.at(l.at);
        // An acquire refused for its own reasons (its object unseen, its author over the cap)
        // is judged so in every view: it counts in none.
        let void = matches!(dag.marks.get(l.at), Mark::Rejected(r) if r.voids_lease_op());
        if !skipped && !void && !dag.is_forked(op) {
            // Judged as the fold judged it: rejected if its author saw its own expel, and not
            // bound by a holder it saw expelled.
            let id = op.id_ref();
            if !dag.expelled_in_past(memo, id, &op.author()) {
                let binding = lease.filter(|h| !dag.expelled_in_past(memo, id, &h.holder));
                let effect = op.payload().effect();
                lease = lease_step(binding, op.author(), op.timestamp(), effect).unwrap_or(lease);
            }
        }
        i += 1;
    }
    alt.insert(cache_key, (n, lease));
    lease
}
