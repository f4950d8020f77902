//! Equivocation: an author that signed two different ops with one seq (a fork of its history).
//!
//! A hostile member forks on purpose, often giving each side to a different peer; an honest
//! identity forks too when it runs as two copies, or when its store is restored from an old
//! backup. Whatever the cause, a log accepts both sides: an op whose author's slot is taken is
//! held beside the first (a *sibling*), ordered by its key and then its id, so the honest ops
//! built on either side are delivered and every peer holds the same history.
//!
//! The verdict is deterministic and does not depend on which side came first: once a log holds
//! two ops of an author with one seq, every op of that author at the lowest such seq or after is
//! rejected as [`crate::RejectReason::Forked`], on both sides. Neither side can be preferred on
//! merit, and an op of a side nobody built on may never reach every peer (version vectors count
//! seqs, not sides), so no peer may let it count. The author's ops before the fork stand. Past
//! the fork an author's ops reach their causal past through their deps only (no implicit
//! previous op: which op that is depends on the side).
//!
//! [`Forks`] notes, per author, the lowest forked seq and two ops that prove it. Sync passes the
//! two ops to every connection whose remote holds the author (`Message::Forked`); the receiver
//! inserts them like any other ops, so it holds both sides of the proof and reaches the same
//! verdict.

use std::collections::BTreeMap;

use crate::identity::{OpId, PeerId};

/// The lowest seq an author signed twice, with two held ops of that seq.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fork {
    /// The seq signed twice.
    pub seq: u64,
    /// Two different held ops of the author with that seq, in id order.
    pub ids: [OpId; 2],
    /// When this entry last changed, on [`Forks::generation`]'s count.
    generation: u64,
}

/// The forks a log holds, one entry per forked author (so no more entries than authors held).
#[derive(Debug, Clone, Default)]
pub struct Forks {
    by_author: BTreeMap<PeerId, Fork>,
    generation: u64,
}

impl Forks {
    /// Notes that `author` signed `a` and `b` (different held ops) with `seq`; true if this is
    /// the author's first fork or a lower seq than the one noted.
    pub(crate) fn record(&mut self, author: PeerId, seq: u64, a: OpId, b: OpId) -> bool {
        debug_assert!(a != b, "a fork is two different ops");
        if self.covers(&author, seq) {
            return false;
        }
        self.generation += 1;
        let ids = if a < b { [a, b] } else { [b, a] };
        let generation = self.generation;
        self.by_author.insert(
            author,
            Fork {
                seq,
                ids,
                generation,
            },
        );
        true
    }

    /// `author`'s fork, if it forked.
    pub fn get(&self, author: &PeerId) -> Option<&Fork> {
        self.by_author.get(author)
    }

    /// The lowest seq `author` signed twice, if it forked.
    pub fn seq_of(&self, author: &PeerId) -> Option<u64> {
        self.get(author).map(|f| f.seq)
    }

    /// True if `author` forked at `seq` or before: its ops at `seq` are rejected.
    pub fn covers(&self, author: &PeerId, seq: u64) -> bool {
        self.seq_of(author).is_some_and(|f| f <= seq)
    }

    /// True if `author` forked.
    pub fn contains(&self, author: &PeerId) -> bool {
        self.by_author.contains_key(author)
    }

    /// The forked authors in id order, each with its fork.
    pub fn iter(&self) -> impl Iterator<Item = (&PeerId, &Fork)> {
        self.by_author.iter()
    }

    /// The forked authors, each with the lowest seq it signed twice.
    pub fn authors(&self) -> impl Iterator<Item = (PeerId, u64)> + '_ {
        self.by_author.iter().map(|(a, f)| (*a, f.seq))
    }

    /// Number of forked authors.
    pub fn len(&self) -> usize {
        self.by_author.len()
    }

    /// True if no author forked.
    pub fn is_empty(&self) -> bool {
        self.by_author.is_empty()
    }

    /// A count that grows with every change: compare two readings to learn whether a fork was
    /// found or lowered between them.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// The authors whose fork was found or lowered after `generation`, with its seq now.
    pub fn changed_since(&self, generation: u64) -> impl Iterator<Item = (PeerId, u64)> + '_ {
        (self.by_author.iter())
            .filter(move |(_, f)| f.generation > generation)
            .map(|(a, f)| (*a, f.seq))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(byte: u8) -> OpId {
        OpId([byte; 32])
    }

    #[test]
    fn a_fork_is_noted_once_per_author_at_its_lowest_seq() {
        let mut forks = Forks::default();
        let (x, y) = (PeerId([1; 32]), PeerId([2; 32]));
        assert!(forks.record(x, 5, id(9), id(3)));
        assert_eq!(
            forks.iter().next().map(|(_, f)| f.ids),
            Some([id(3), id(9)])
        );
        let g = forks.generation();
        assert!(
            !forks.record(x, 7, id(4), id(5)),
            "a higher seq adds nothing"
        );
        assert!(!forks.record(x, 5, id(4), id(5)), "nor does the same seq");
        assert_eq!(forks.changed_since(g).count(), 0);
        assert!(forks.record(x, 2, id(4), id(5)), "a lower seq replaces it");
        assert!(forks.record(y, 1, id(6), id(7)));
        assert_eq!(forks.seq_of(&x), Some(2));
        assert_eq!(
            forks.changed_since(g).collect::<Vec<_>>(),
            vec![(x, 2), (y, 1)]
        );
        assert_eq!(forks.len(), 2);
    }
}
