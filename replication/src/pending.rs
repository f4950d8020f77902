//! The bounded buffer of ops that arrived before their dependencies.
//!
//! Limits are named constants; when one is exceeded an op is evicted and reported, never
//! silently dropped. Eviction picks the source holding the most pending ops, so a peer flooding
//! the buffer with ops whose dependencies never come evicts its own ops first; of that source's
//! ops by the author it sent last, the one furthest along the author's chain goes, so a buffer
//! full of one author's later ops keeps room for the ops that come next in that chain.

use std::collections::{BTreeMap, BTreeSet};

use crate::identity::{OpId, PeerId};
use crate::op::Op;
use crate::time::Timestamp;

/// Most ops waiting for dependencies at once.
pub const MAX_PENDING_OPS: usize = 4096;
/// Most encoded bytes waiting for dependencies at once.
pub const MAX_PENDING_BYTES: usize = 8 * 1024 * 1024;
/// How long an op may wait for its dependencies before it is evicted (5 minutes).
pub const PENDING_TTL_MICROS: u64 = 5 * 60 * 1_000_000;

/// Where an op came from: the local peer, the store, or one remote connection.
///
/// Chosen by the caller; it is used for fair eviction and to attribute rejections.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Origin(pub u64);

/// Something a pending op waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum DepKey {
    /// A named dependency.
    Op(OpId),
    /// The author's previous op (per-author sequence numbers have no gaps).
    Seq(PeerId, u64),
    /// The receiver's wall clock reaching this time: the op's timestamp runs ahead of it by
    /// more than [`crate::time::MAX_CLOCK_SKEW_MICROS`] until then.
    Clock(Timestamp),
}

/// Why a pending op was evicted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvictReason {
    /// The buffer was over [`MAX_PENDING_OPS`] or [`MAX_PENDING_BYTES`].
    Full,
    /// It waited longer than [`PENDING_TTL_MICROS`].
    Expired,
}

/// A pending op that was dropped; its sender will offer it again on the next sync.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Evicted {
    /// The op.
    pub id: OpId,
    /// Where it came from.
    pub origin: Origin,
    /// Why it was dropped.
    pub reason: EvictReason,
}

/// The pending buffer's limits; [`PendingLimits::default`] uses the named constants.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PendingLimits {
    /// Most ops waiting at once.
    pub max_ops: usize,
    /// Most encoded bytes waiting at once.
    pub max_bytes: usize,
    /// How long an op may wait, in microseconds.
    pub ttl_micros: u64,
}

impl Default for PendingLimits {
    fn default() -> Self {
        Self {
            max_ops: MAX_PENDING_OPS,
            max_bytes: MAX_PENDING_BYTES,
            ttl_micros: PENDING_TTL_MICROS,
        }
    }
}

#[derive(Clone, Debug)]
struct Entry<P> {
    op: Op<P>,
    origin: Origin,
    arrived: Timestamp,
    arrival_no: u64,
    missing: BTreeSet<DepKey>,
}

/// Ops waiting on dependencies, indexed by what they wait for.
#[derive(Clone, Debug)]
pub struct Pending<P> {
    entries: BTreeMap<OpId, Entry<P>>,
    waiters: BTreeMap<DepKey, BTreeSet<OpId>>,
    per_origin: BTreeMap<Origin, BTreeSet<(u64, OpId)>>,
    /// Entries by origin and author, in their author's order (seq, then id).
    per_author: BTreeMap<(Origin, PeerId), BTreeSet<(u64, OpId)>>,
    /// Entries by arrival time, so expiry is found and done without a scan (every connection
    /// asks on every poll).
    by_arrival: BTreeSet<(Timestamp, u64, OpId)>,
    n_bytes: usize,
    next_arrival_no: u64,
    limits: PendingLimits,
}

impl<P> Default for Pending<P> {
    fn default() -> Self {
        Self {
            entries: BTreeMap::new(),
            waiters: BTreeMap::new(),
            per_origin: BTreeMap::new(),
            per_author: BTreeMap::new(),
            by_arrival: BTreeSet::new(),
            n_bytes: 0,
            next_arrival_no: 0,
            limits: PendingLimits::default(),
        }
    }
}

impl<P: Clone> Pending<P> {
    /// An empty buffer with the given limits.
    pub fn with_limits(limits: PendingLimits) -> Self {
        Self {
            limits,
            ..Self::default()
        }
    }

    /// Number of ops waiting.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True if nothing waits.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Encoded bytes waiting.
    pub fn n_bytes(&self) -> usize {
        self.n_bytes
    }

    /// True if `id` is waiting.
    pub fn contains(&self, id: &OpId) -> bool {
        self.entries.contains_key(id)
    }

    /// Number of ops waiting that came from `origin`.
    pub fn n_from(&self, origin: Origin) -> usize {
        self.per_origin.get(&origin).map_or(0, BTreeSet::len)
    }

    /// The dependencies, by id, that ops from `origin` which arrived at or before `before`
    /// still wait for and that are not waiting here themselves: at most `max`, sorted. An
    /// honest sender holds the dependencies of every op it sends, so one that waited this
    /// long and did not come by the version vectors is worth asking for by id (the other op
    /// of a fork, which version vectors cannot tell apart, is one).
    pub fn stuck_deps(&self, origin: Origin, before: Timestamp, max: usize) -> Vec<OpId> {
        let mut stuck = BTreeSet::new();
        let ids = self.per_origin.get(&origin).into_iter().flatten();
        for (_, id) in ids {
            let Some(entry) = self.entries.get(id) else {
                continue;
            };
            if entry.arrived > before {
                // In arrival order: every later one arrived later.
                break;
            }
            for key in &entry.missing {
                if let DepKey::Op(dep) = key
                    && !self.entries.contains_key(dep)
                {
                    stuck.insert(*dep);
                    if stuck.len() == max {
                        return stuck.into_iter().collect();
                    }
                }
            }
        }
        stuck.into_iter().collect()
    }

    /// True if the op `id` of `author` at `seq` from `origin`, parked now, would be the op its
    /// own insertion evicts ([`Pending::insert`]): the buffer holds its most ops, `origin`
    /// would then hold more than any other source, and every op of `author` from it waits at
    /// a lower seq (or at `seq` with a lower id, a fork). A receiver skips such an op before
    /// checking its signature.
    pub fn drops_on_arrival(&self, origin: Origin, author: &PeerId, seq: u64, id: OpId) -> bool {
        if self.entries.len() < self.limits.max_ops {
            return false;
        }
        let this = (self.n_from(origin) + 1, origin);
        let others = (self.per_origin.iter())
            .filter(|(o, _)| **o != origin)
            .map(|(o, ids)| (ids.len(), *o));
        if others.max().is_some_and(|most| most > this) {
            return false;
        }
        (self.per_author.get(&(origin, *author)))
            .and_then(BTreeSet::last)
            .is_none_or(|&top| top < (seq, id))
    }

    /// Parks `op` until every key in `missing` is satisfied; returns what had to be evicted
    /// to stay within limits (possibly `op` itself).
    pub fn insert(
        &mut self,
        now: Timestamp,
        op: Op<P>,
        origin: Origin,
        missing: BTreeSet<DepKey>,
    ) -> Vec<Evicted> {
        assert!(
            !missing.is_empty(),
            "a pending op must be missing something"
        );
        let id = op.id();
        if self.entries.contains_key(&id) {
            return Vec::new();
        }
        for key in &missing {
            self.waiters.entry(*key).or_default().insert(id);
        }
        let arrival_no = self.next_arrival_no;
        self.next_arrival_no += 1;
        self.per_origin
            .entry(origin)
            .or_default()
            .insert((arrival_no, id));
        self.per_author
            .entry((origin, op.author()))
            .or_default()
            .insert((op.seq(), id));
        self.by_arrival.insert((now, arrival_no, id));
        self.n_bytes += op.encoded().len();
        self.entries.insert(
            id,
            Entry {
                op,
                origin,
                arrived: now,
                arrival_no,
                missing,
            },
        );
        let mut evicted = Vec::new();
        while self.entries.len() > self.limits.max_ops || self.n_bytes > self.limits.max_bytes {
            match self.evict_one() {
                Some(e) => evicted.push(e),
                None => break,
            }
        }
        evicted
    }

    /// Evicts an op of the origin holding the most pending ops: of its ops by the author of
    /// the one it sent last, the furthest along that author's chain (the highest seq). A
    /// sender streams an author's ops in order and sends again what was dropped, so a buffer
    /// full of ops far ahead of what the log holds drops those, not the next op in line
    /// (evicting the newest instead let a backlog's far end hold the buffer while every op
    /// that could be delivered was dropped on arrival).
    fn evict_one(&mut self) -> Option<Evicted> {
        let (&origin, ids) = self
            .per_origin
            .iter()
            .max_by_key(|(o, ids)| (ids.len(), *o))?;
        let &(_, newest) = ids.iter().next_back()?;
        let author = self.entries.get(&newest)?.op.author();
        let &(_, id) = self.per_author.get(&(origin, author))?.iter().next_back()?;
        self.remove(&id).map(|entry| Evicted {
            id,
            origin: entry.origin,
            reason: EvictReason::Full,
        })
    }

    fn remove(&mut self, id: &OpId) -> Option<Entry<P>> {
        let entry = self.entries.remove(id)?;
        for key in &entry.missing {
            if let Some(set) = self.waiters.get_mut(key) {
                set.remove(id);
                if set.is_empty() {
                    self.waiters.remove(key);
                }
            }
        }
        if let Some(set) = self.per_origin.get_mut(&entry.origin) {
            set.remove(&(entry.arrival_no, *id));
            if set.is_empty() {
                self.per_origin.remove(&entry.origin);
            }
        }
        let key = (entry.origin, entry.op.author());
        if let Some(set) = self.per_author.get_mut(&key) {
            set.remove(&(entry.op.seq(), *id));
            if set.is_empty() {
                self.per_author.remove(&key);
            }
        }
        self.by_arrival
            .remove(&(entry.arrived, entry.arrival_no, *id));
        self.n_bytes -= entry.op.encoded().len();
        Some(entry)
    }

    /// Marks `key` as satisfied; returns the ops that now miss nothing, removed from the
    /// buffer, with their origins, in arrival order.
    pub fn satisfy(&mut self, key: DepKey) -> Vec<(Op<P>, Origin)> {
        let Some(ids) = self.waiters.remove(&key) else {
            return Vec::new();
        };
        let mut ready = Vec::new();
        for id in ids {
            let now_ready = match self.entries.get_mut(&id) {
                Some(entry) => {
                    entry.missing.remove(&key);
                    entry.missing.is_empty()
                }
                None => false,
            };
            if now_ready && let Some(entry) = self.remove(&id) {
                ready.push((entry.arrival_no, entry.op, entry.origin));
            }
        }
        ready.sort_by_key(|(n, _, _)| *n);
        ready
            .into_iter()
            .map(|(_, op, origin)| (op, origin))
            .collect()
    }

    /// Marks every clock wait due at `now` as satisfied; returns the ops that now miss nothing,
    /// removed from the buffer, with their origins, in order of due time then arrival.
    pub fn due(&mut self, now: Timestamp) -> Vec<(Op<P>, Origin)> {
        let keys: Vec<DepKey> = self
            .waiters
            .range(DepKey::Clock(Timestamp(0))..=DepKey::Clock(now))
            .map(|(key, _)| *key)
            .collect();
        keys.into_iter().flat_map(|key| self.satisfy(key)).collect()
    }

    /// The earliest time at which an op waiting for the clock is due, if any waits.
    pub fn next_due(&self) -> Option<Timestamp> {
        self.waiters
            .range(DepKey::Clock(Timestamp(0))..)
            .next()
            .and_then(|(key, _)| match key {
                DepKey::Clock(at) => Some(*at),
                _ => None,
            })
    }

    /// Evicts every op that has waited its time to live or longer at `now`.
    pub fn expire(&mut self, now: Timestamp) -> Vec<Evicted> {
        let ttl = self.limits.ttl_micros;
        let old: Vec<OpId> = self
            .by_arrival
            .iter()
            .take_while(|(arrived, _, _)| arrived.saturating_add_micros(ttl) <= now)
            .map(|(_, _, id)| *id)
            .collect();
        old.iter()
            .filter_map(|id| {
                self.remove(id).map(|e| Evicted {
                    id: *id,
                    origin: e.origin,
                    reason: EvictReason::Expired,
                })
            })
            .collect()
    }

    /// When the oldest pending op expires, if any waits.
    pub fn next_expiry(&self) -> Option<Timestamp> {
        let ttl = self.limits.ttl_micros;
        self.by_arrival
            .first()
            .map(|(arrived, _, _)| arrived.saturating_add_micros(ttl))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identity::Keypair;
    use crate::op::OpFields;
    use crate::payload::test_payload::TestPayload;

    fn op(seed: u8, seq: u64) -> Op<TestPayload> {
        let fields = OpFields {
            seq,
            lamport: seq,
            timestamp: Timestamp(0),
            deps: vec![],
            payload: TestPayload::Chat(format!("{seq}")),
        };
        Op::sign(
            &Keypair::from_seed([seed; 32]),
            &crate::op::UNNAMED_SESSION,
            fields,
        )
        .unwrap()
        .into_op()
    }

    /// The other side of a fork of [`op`]: the same author and seq, another id.
    fn forked(seed: u8, seq: u64) -> Op<TestPayload> {
        let fields = OpFields {
            seq,
            lamport: seq,
            timestamp: Timestamp(1),
            deps: vec![],
            payload: TestPayload::Chat(format!("{seq}, forked")),
        };
        let key = Keypair::from_seed([seed; 32]);
        (Op::sign(&key, &crate::op::UNNAMED_SESSION, fields).unwrap()).into_op()
    }

    #[test]
    fn satisfied_ops_come_out_once_all_keys_arrive() {
        let mut p = Pending::default();
        let a = OpId([1; 32]);
        let b = OpId([2; 32]);
        let o = op(1, 1);
        let missing = [DepKey::Op(a), DepKey::Op(b)].into_iter().collect();
        assert!(
            p.insert(Timestamp(0), o.clone(), Origin(1), missing)
                .is_empty()
        );
        assert!(p.satisfy(DepKey::Op(a)).is_empty());
        assert_eq!(p.len(), 1);
        let ready = p.satisfy(DepKey::Op(b));
        assert_eq!(ready, vec![(o, Origin(1))]);
        assert!(p.is_empty());
        assert_eq!(p.n_bytes(), 0);
    }

    #[test]
    fn flooding_origin_is_evicted_first() {
        let limits = PendingLimits {
            max_ops: 20,
            ..PendingLimits::default()
        };
        let mut p = Pending::with_limits(limits);
        let missing: BTreeSet<DepKey> = [DepKey::Op(OpId([9; 32]))].into_iter().collect();
        let honest = op(1, 1);
        assert!(
            p.insert(Timestamp(0), honest.clone(), Origin(1), missing.clone())
                .is_empty()
        );
        let mut evicted = Vec::new();
        for seq in 1..=(limits.max_ops as u64 + 10) {
            evicted.extend(p.insert(Timestamp(0), op(2, seq), Origin(2), missing.clone()));
        }
        assert_eq!(evicted.len(), 11);
        assert!(
            evicted
                .iter()
                .all(|e| e.origin == Origin(2) && e.reason == EvictReason::Full)
        );
        assert!(p.contains(&honest.id()));
        assert_eq!(p.len(), limits.max_ops);
    }

    /// A buffer full of an author's ops far ahead of the log keeps the ops that come next in
    /// that chain as they arrive, dropping the far end, from whichever source: each would
    /// otherwise be dropped on arrival until the far ones expired.
    #[test]
    fn a_full_buffer_drops_the_far_end_of_an_authors_chain() {
        let limits = PendingLimits {
            max_ops: 8,
            ..PendingLimits::default()
        };
        let mut p = Pending::with_limits(limits);
        let waits =
            |seq: u64| BTreeSet::from([DepKey::Seq(Keypair::from_seed([1; 32]).peer_id(), seq)]);
        for seq in 101..=108 {
            assert!(
                p.insert(Timestamp(0), op(1, seq), Origin(1), waits(seq - 1))
                    .is_empty()
            );
        }
        // Another author's op, from the same source, goes itself (the far end of its chain).
        let other = p.insert(Timestamp(1), op(2, 5), Origin(1), waits(1));
        assert_eq!(
            other.iter().map(|e| e.id).collect::<Vec<_>>(),
            [op(2, 5).id()]
        );
        // Ops 2 to 9 come again, from this source and another.
        for seq in 2..=9 {
            let origin = Origin(1 + seq % 2);
            let evicted = p.insert(Timestamp(2), op(1, seq), origin, waits(seq - 1));
            assert_eq!(evicted.len(), 1);
            assert_eq!(evicted[0].id, op(1, 110 - seq).id(), "{seq}");
            assert_eq!(evicted[0].origin, Origin(1));
        }
        assert!((2..=9).all(|seq| p.contains(&op(1, seq).id())));
        assert_eq!(p.len(), limits.max_ops);
    }

    /// `drops_on_arrival` says exactly when an insertion evicts the op it parks, over random
    /// arrivals from three sources of two authors' ops, forks among them, into a small full
    /// buffer.
    #[test]
    fn drops_on_arrival_foretells_the_eviction() {
        let limits = PendingLimits {
            max_ops: 6,
            ..PendingLimits::default()
        };
        let mut p = Pending::with_limits(limits);
        let missing: BTreeSet<DepKey> = [DepKey::Op(OpId([9; 32]))].into_iter().collect();
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let (mut n_dropped, mut n_kept) = (0, 0);
        for _ in 0..2_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let (origin, seed, seq) = (
                Origin(state % 3),
                1 + (state >> 8) % 2,
                1 + (state >> 16) % 24,
            );
            // A third of the ops fork their author's chain.
            let op = if (state >> 32).is_multiple_of(3) {
                forked(seed as u8, seq)
            } else {
                op(seed as u8, seq)
            };
            if p.contains(&op.id()) {
                continue;
            }
            let foretold = p.drops_on_arrival(origin, &op.author(), seq, op.id());
            let evicted = p.insert(Timestamp(0), op.clone(), origin, missing.clone());
            let dropped = evicted.iter().any(|e| e.id == op.id());
            assert_eq!(foretold, dropped, "{origin:?} {seed} {seq}");
            n_dropped += usize::from(dropped);
            n_kept += usize::from(!dropped && !evicted.is_empty());
        }
        assert!(n_dropped > 100 && n_kept > 10, "{n_dropped} {n_kept}");
    }

    #[test]
    fn old_ops_expire() {
        let mut p = Pending::default();
        let missing: BTreeSet<DepKey> = [DepKey::Op(OpId([9; 32]))].into_iter().collect();
        p.insert(Timestamp(10), op(1, 1), Origin(1), missing.clone());
        p.insert(Timestamp(20), op(1, 2), Origin(1), missing);
        assert_eq!(p.next_expiry(), Some(Timestamp(10 + PENDING_TTL_MICROS)));
        assert!(p.expire(Timestamp(10 + PENDING_TTL_MICROS - 1)).is_empty());
        let gone = p.expire(Timestamp(15 + PENDING_TTL_MICROS));
        assert_eq!(gone.len(), 1);
        assert_eq!(gone[0].reason, EvictReason::Expired);
        assert_eq!(p.len(), 1);
        assert!(p.satisfy(DepKey::Op(OpId([9; 32]))).len() == 1);
    }
}
