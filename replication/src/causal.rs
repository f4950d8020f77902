//! Causal bookkeeping: version vectors (what a peer has), the DAG's frontier (heads), and the
//! memo of which ops have a given op in their causal past ([`Reach`]).

use std::collections::BTreeMap;
use std::collections::BTreeSet;

use crate::identity::{OpId, PeerId};

/// Most authors one version vector on the wire may name. A longer one (a log may hold any
/// number of authors) goes out as several messages: see [`VersionVector::split`].
pub const MAX_VV_AUTHORS: usize = 4096;

/// For each author, the highest sequence number such that all of that author's ops up to it
/// are held. Because delivery is causal and per-author gapless, this names a set of ops
/// exactly.
#[derive(Clone, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct VersionVector {
    seqs: BTreeMap<PeerId, u64>,
}

impl VersionVector {
    /// An empty version vector.
    pub fn new() -> Self {
        Self::default()
    }

    /// The highest contiguous sequence number held for `author` (0 if none).
    pub fn get(&self, author: &PeerId) -> u64 {
        self.seqs.get(author).copied().unwrap_or(0)
    }

    /// Raises `author`'s entry to at least `seq`.
    pub fn raise(&mut self, author: PeerId, seq: u64) {
        if seq == 0 {
            return;
        }
        // Held authors are the usual case: `get_mut` searches without taking the key.
        match self.seqs.get_mut(&author) {
            Some(entry) => *entry = (*entry).max(seq),
            None => {
                self.seqs.insert(author, seq);
            }
        }
    }

    /// Sets `author`'s entry to exactly `seq` (0 removes it), lowering it if need be.
    pub fn set(&mut self, author: PeerId, seq: u64) {
        if seq == 0 {
            self.seqs.remove(&author);
        } else {
            self.seqs.insert(author, seq);
        }
    }

    /// Pointwise maximum with `other`.
    pub fn join(&mut self, other: &VersionVector) {
        for (author, seq) in &other.seqs {
            self.raise(*author, *seq);
        }
    }

    /// True if `self` includes everything `other` names.
    pub fn dominates(&self, other: &VersionVector) -> bool {
        other.seqs.iter().all(|(a, s)| self.get(a) >= *s)
    }

    /// Entries in author order.
    pub fn iter(&self) -> impl Iterator<Item = (&PeerId, &u64)> {
        self.seqs.iter()
    }

    /// Number of authors named.
    pub fn len(&self) -> usize {
        self.seqs.len()
    }

    /// True if no author is named.
    pub fn is_empty(&self) -> bool {
        self.seqs.is_empty()
    }

    /// The entries in author order as version vectors of at most `max_authors` entries each,
    /// whose join is `self`; always at least one (empty if `self` is).
    pub fn split(&self, max_authors: usize) -> Vec<VersionVector> {
        assert!(max_authors > 0, "a version vector split into empty parts");
        let mut parts = vec![VersionVector::new()];
        for (author, seq) in &self.seqs {
            if parts.last().is_some_and(|p| p.len() == max_authors) {
                parts.push(VersionVector::new());
            }
            if let Some(part) = parts.last_mut() {
                part.seqs.insert(*author, *seq);
            }
        }
        parts
    }

    /// Total number of ops named.
    pub fn n_ops(&self) -> u64 {
        self.seqs
            .values()
            .fold(0u64, |acc, s| acc.saturating_add(*s))
    }
}

/// The frontier of the op DAG: delivered ops that no delivered op depends on yet.
///
/// New local ops depend on exactly these. Two frontiers are equal when their heads are.
#[derive(Clone, Debug)]
pub struct Frontier {
    heads: Heads,
}

/// Most heads a frontier keeps in a sorted vector; past this it keeps a tree, and returns to
/// the vector below half of it.
const MAX_FEW_HEADS: usize = 32;

/// A frontier's heads in id order. A session has about one head per concurrent author, so
/// most deliveries replace one head in a short vector; a tree keeps a member that makes
/// thousands of heads (ops that name no deps) from costing a shift of all of them per op.
/// Between half of [`MAX_FEW_HEADS`] and it, the same heads may be held in either form.
#[derive(Clone, Debug)]
enum Heads {
    Few(Vec<OpId>),
    Many(BTreeSet<OpId>),
}

impl PartialEq for Frontier {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.heads().eq(other.heads())
    }
}

impl Eq for Frontier {}

impl Default for Frontier {
    fn default() -> Self {
        Self {
            heads: Heads::Few(Vec::new()),
        }
    }
}

impl Frontier {
    /// Records a delivered op. Causal delivery guarantees its dependencies were delivered
    /// before it and that nothing delivered depends on it yet.
    pub fn deliver(&mut self, id: OpId, deps: &[OpId]) {
        match &mut self.heads {
            Heads::Few(heads) => {
                if let [only] = heads.as_mut_slice()
                    && deps.contains(only)
                {
                    // The usual op, which saw the only head: it replaces it.
                    *only = id;
                    return;
                }
                heads.retain(|h| !deps.contains(h));
                let at = heads.partition_point(|h| *h < id);
                heads.insert(at, id);
                if heads.len() > MAX_FEW_HEADS {
                    self.heads = Heads::Many(heads.drain(..).collect());
                }
            }
            Heads::Many(heads) => {
                for dep in deps {
                    heads.remove(dep);
                }
                heads.insert(id);
                if heads.len() < MAX_FEW_HEADS / 2 {
                    self.heads = Heads::Few(std::mem::take(heads).into_iter().collect());
                }
            }
        }
    }

    /// The heads in id order.
    pub fn heads(&self) -> impl Iterator<Item = &OpId> {
        let (few, many) = match &self.heads {
            Heads::Few(heads) => (Some(heads.iter()), None),
            Heads::Many(heads) => (None, Some(heads.iter())),
        };
        few.into_iter().flatten().chain(many.into_iter().flatten())
    }

    /// Number of heads.
    pub fn len(&self) -> usize {
        match &self.heads {
            Heads::Few(heads) => heads.len(),
            Heads::Many(heads) => heads.len(),
        }
    }

    /// True before any op is delivered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Most (target, author) slots a [`Reach`] memo holds; past it the memo starts afresh, which
/// changes no answer, only what the next ones cost.
pub const MAX_REACH_MEMO_ENTRIES: usize = 1 << 20;

/// A memo of causal reachability: for a target op, per author, the sequence numbers of that
/// author's ops known *not* to have the target in their causal past (`..=unseen_to`) and known
/// to have it (`seen_from..`). Each op of an author has the author's previous op in its past,
/// so both are ranges of the author's chain; an op's past never changes once it is delivered,
/// so an entry never goes stale.
///
/// Targets are named by their position in the log's slab ([`crate::op`]), which never changes
/// while the log holds the op. Targets and authors are numbered in order of first use, and
/// each target has a row of 8-byte slots indexed by author number: a session's few authors are
/// asked about most targets, so the rows are nearly full. A hash table of pairs took 16 bytes
/// an entry and doubled as it grew (about 150 bytes per op held at 32 peers); nested trees of
/// ids, before it, about 100 bytes an entry.
///
/// An empty memo holds nothing on the heap and costs nothing to drop: a log lends its memo
/// out for each refold and takes it back, leaving an empty one in its place meanwhile.
#[derive(Clone, Debug, Default)]
pub struct Reach {
    tables: Option<Box<ReachTables>>,
}

/// What a [`Reach`] memo holds once something is recorded.
#[derive(Clone, Debug, Default)]
struct ReachTables {
    targets: BTreeMap<u32, u32>,
    authors: BTreeMap<PeerId, u32>,
    /// Per target number, per author number: `(unseen_to, seen_from)`, [`UNKNOWN`] until an
    /// answer is recorded. Sequence numbers from `u32::MAX` on are not memoised.
    rows: Vec<Vec<(u32, u32)>>,
    /// Slots in all rows (what [`MAX_REACH_MEMO_ENTRIES`] bounds; rows reserve at most an
    /// eighth more).
    n_slots: usize,
    /// Slots holding an answer.
    n_entries: usize,
}

/// A slot with nothing recorded: no seq is known either way.
const UNKNOWN: (u32, u32) = (0, u32::MAX);

impl Reach {
    fn slot(&self, target: u32, author: &PeerId) -> Option<(u32, u32)> {
        let t = self.tables.as_deref()?;
        let row = t.rows.get(*t.targets.get(&target)? as usize)?;
        row.get(*t.authors.get(author)? as usize).copied()
    }

    /// Whether `author`'s op `seq` has `target` in its causal past, if known.
    pub fn known(&self, target: u32, author: &PeerId, seq: u64) -> Option<bool> {
        let seq = u32::try_from(seq).ok()?;
        let (unseen_to, seen_from) = self.slot(target, author).filter(|s| *s != UNKNOWN)?;
        if seq <= unseen_to {
            Some(false)
        } else if seq >= seen_from {
            Some(true)
        } else {
            None
        }
    }

    /// Records whether `author`'s op `seq` has `target` in its causal past.
    pub fn record(&mut self, target: u32, author: PeerId, seq: u64, seen: bool) {
        let Some(seq) = u32::try_from(seq).ok().filter(|s| *s < u32::MAX) else {
            return;
        };
        if seq == 0 && !seen {
            // Says nothing: no op has seq 0.
            return;
        }
        let tables = self.tables.get_or_insert_default();
        if !tables.record(target, author, seq, seen) {
            // Full: start afresh.
            **tables = ReachTables::default();
            tables.record(target, author, seq, seen);
        }
    }

    /// Number of (target, author) pairs with an answer.
    pub fn len(&self) -> usize {
        self.tables.as_ref().map_or(0, |t| t.n_entries)
    }

    /// True if nothing is memoised.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl ReachTables {
    /// [`Reach::record`] for a seq below `u32::MAX`; false, recording nothing, when the slots
    /// it needs would pass [`MAX_REACH_MEMO_ENTRIES`].
    fn record(&mut self, target: u32, author: PeerId, seq: u32, seen: bool) -> bool {
        let next = |n: usize| u32::try_from(n).expect("at most MAX_REACH_MEMO_ENTRIES");
        let n_targets = next(self.targets.len());
        let t = *self.targets.entry(target).or_insert(n_targets) as usize;
        let n_authors = next(self.authors.len());
        let a = *self.authors.entry(author).or_insert(n_authors) as usize;
        let grow = (a + 1).saturating_sub(self.rows.get(t).map_or(0, Vec::len));
        if self.n_slots + grow > MAX_REACH_MEMO_ENTRIES {
            return false;
        }
        if t == self.rows.len() {
            self.rows.push(Vec::new());
        }
        let row = &mut self.rows[t];
        if grow > 0 {
            // A row grows by at least an eighth: one extended an author at a time (a member
            // signing with ever new keys) copies each slot a bounded number of times, not once
            // per new author, and holds at most an eighth more than its slots.
            let len = row.len();
            if a >= row.capacity() {
                row.reserve_exact((a + 1).max(len + len / 8 + 1) - len);
            }
            row.resize(a + 1, UNKNOWN);
            self.n_slots += grow;
        }
        let slot = &mut row[a];
        if *slot == UNKNOWN {
            self.n_entries += 1;
        }
        if seen {
            slot.1 = slot.1.min(seq);
        } else {
            slot.0 = slot.0.max(seq);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn vv(entries: &[(u8, u64)]) -> VersionVector {
        let mut v = VersionVector::new();
        for (a, s) in entries {
            v.raise(PeerId([*a; 32]), *s);
        }
        v
    }

    #[test]
    fn frontier_tracks_heads() {
        let mut f = Frontier::default();
        let (a, b, c) = (OpId([1; 32]), OpId([2; 32]), OpId([3; 32]));
        f.deliver(a, &[]);
        f.deliver(b, &[]);
        assert_eq!(f.len(), 2);
        f.deliver(c, &[a, b]);
        assert_eq!(f.heads().copied().collect::<Vec<_>>(), vec![c]);
    }

    #[test]
    fn a_frontier_keeps_its_heads_sorted_across_both_forms() {
        // Ops naming no deps each stay a head: the frontier outgrows its vector, then shrinks
        // back into it, and always lists its heads in id order.
        let id = |i: u32| {
            let mut bytes = [0; 32];
            bytes[..4].copy_from_slice(&i.wrapping_mul(2_654_435_761).to_be_bytes());
            bytes[4..8].copy_from_slice(&i.to_be_bytes());
            OpId(bytes)
        };
        let mut f = Frontier::default();
        let mut expected = BTreeSet::new();
        for i in 0..100 {
            f.deliver(id(i), &[]);
            expected.insert(id(i));
            assert!(f.heads().copied().eq(expected.iter().copied()), "after {i}");
        }
        // Then each new op merges one old head and the previous new one.
        for i in 0..99 {
            let deps: Vec<OpId> = std::iter::once(id(i))
                .chain((i > 0).then(|| id(1000 + i - 1)))
                .collect();
            f.deliver(id(1000 + i), &deps);
            expected.retain(|h| !deps.contains(h));
            expected.insert(id(1000 + i));
            assert!(f.heads().copied().eq(expected.iter().copied()), "after {i}");
            assert_eq!(f.len(), expected.len());
        }
        assert_eq!(f.len(), 2);
        assert!(matches!(f.heads, Heads::Few(_)));
    }

    #[test]
    fn frontiers_with_the_same_heads_are_equal_in_either_form() {
        let id = |i: u8| OpId([i; 32]);
        // One grows past the vector and shrinks back to 20 heads, still a tree; the other
        // takes the same 20 heads directly, in a vector.
        let mut grown = Frontier::default();
        for i in 0..40 {
            grown.deliver(id(i), &[]);
        }
        let merged: Vec<OpId> = (20..40).map(id).collect();
        grown.deliver(id(200), &merged);
        let mut direct = Frontier::default();
        for i in (0..20).chain([200]) {
            direct.deliver(id(i), &[]);
        }
        assert!(matches!(grown.heads, Heads::Many(_)));
        assert!(matches!(direct.heads, Heads::Few(_)));
        assert_eq!(grown, direct);
        direct.deliver(id(201), &[]);
        assert_ne!(grown, direct);
    }

    #[test]
    fn reach_memo_keeps_ranges_of_an_authors_chain() {
        let mut r = Reach::default();
        let (t, a) = (9, PeerId([1; 32]));
        assert_eq!(r.known(t, &a, 3), None);
        r.record(t, a, 3, false);
        r.record(t, a, 7, true);
        assert_eq!(r.known(t, &a, 1), Some(false));
        assert_eq!(r.known(t, &a, 3), Some(false));
        assert_eq!(r.known(t, &a, 5), None);
        assert_eq!(r.known(t, &a, 9), Some(true));
        assert_eq!(r.len(), 1);
        // Sequence numbers past 32 bits are not memoised: asked again, never answered wrong.
        r.record(t, a, u64::from(u32::MAX), true);
        r.record(t, a, 1 << 40, false);
        assert_eq!(r.known(t, &a, 1 << 40), None);
        assert_eq!(r.known(t, &a, 9), Some(true));
    }

    /// A row extended one new author at a time grows geometrically: few copies, little slack.
    #[test]
    fn a_reach_row_grown_one_author_at_a_time_is_copied_few_times() {
        let mut r = Reach::default();
        let author = |i: u32| PeerId(blake3::hash(&i.to_le_bytes()).into());
        let mut n_grown = 0;
        let capacity = |r: &Reach| r.tables.as_ref().map_or(0, |t| t.rows[0].capacity());
        for a in 0..4000 {
            let before = capacity(&r);
            r.record(9, author(a), 1, true);
            n_grown += usize::from(capacity(&r) != before);
        }
        let row = &r.tables.as_ref().unwrap().rows[0];
        assert_eq!(row.len(), 4000);
        assert!(row.capacity() <= 4000 + 4000 / 8 + 1, "{}", row.capacity());
        assert!(n_grown < 100, "{n_grown} reallocations");
        assert_eq!(r.known(9, &author(3999), 1), Some(true));
    }

    #[test]
    fn reach_memo_keeps_every_pair_apart_and_starts_afresh_at_its_limit() {
        let mut r = Reach::default();
        let target = |i: u32| i * 7 + 3;
        let author = |i: u32| PeerId(blake3::hash(&(i + 1000).to_le_bytes()).into());
        for t in 0..40 {
            for a in 0..40 {
                r.record(target(t), author(a), u64::from(t + a + 1), (t + a) % 2 == 0);
            }
        }
        assert_eq!(r.len(), 1600);
        for t in 0..40 {
            for a in 0..40 {
                let seq = u64::from(t + a + 1);
                assert_eq!(r.known(target(t), &author(a), seq), Some((t + a) % 2 == 0));
            }
        }
        assert_eq!(r.known(target(40), &author(0), 1), None);
        for i in 0..MAX_REACH_MEMO_ENTRIES as u32 - 1600 {
            r.record(target(100 + i), author(0), 1, true);
        }
        assert_eq!(r.len(), MAX_REACH_MEMO_ENTRIES);
        // An answer in a slot it holds costs nothing; a new slot past the limit starts afresh.
        r.record(target(0), author(0), 1, true);
        assert_eq!(r.len(), MAX_REACH_MEMO_ENTRIES);
        r.record(target(0), author(40), 1, true);
        assert_eq!(r.len(), 1, "the memo started afresh");
        assert_eq!(r.known(target(0), &author(40), 1), Some(true));
        assert_eq!(r.known(target(1), &author(1), 3), None);
    }

    #[test]
    fn split_parts_are_bounded_and_join_to_the_whole() {
        assert_eq!(VersionVector::new().split(2), vec![VersionVector::new()]);
        let whole = vv(&[(1, 1), (2, 5), (3, 2), (4, 9), (5, 1)]);
        let parts = whole.split(2);
        assert_eq!(
            parts.iter().map(VersionVector::len).collect::<Vec<_>>(),
            [2, 2, 1]
        );
        let mut joined = VersionVector::new();
        for part in &parts {
            joined.join(part);
        }
        assert_eq!(joined, whole);
    }

    proptest! {
        #![proptest_config(crate::test_config(64))]
        #[test]
        fn join_is_a_semilattice(
            a in proptest::collection::vec((0u8..4, 0u64..5), 0..4),
            b in proptest::collection::vec((0u8..4, 0u64..5), 0..4),
            c in proptest::collection::vec((0u8..4, 0u64..5), 0..4),
        ) {
            let (a, b, c) = (vv(&a), vv(&b), vv(&c));
            let mut ab = a.clone(); ab.join(&b);
            let mut ba = b.clone(); ba.join(&a);
            prop_assert_eq!(&ab, &ba);
            let mut ab_c = ab.clone(); ab_c.join(&c);
            let mut bc = b.clone(); bc.join(&c);
            let mut a_bc = a.clone(); a_bc.join(&bc);
            prop_assert_eq!(&ab_c, &a_bc);
            let mut aa = a.clone(); aa.join(&a);
            prop_assert_eq!(&aa, &a);
            prop_assert!(ab.dominates(&a) && ab.dominates(&b));
        }
    }
}
