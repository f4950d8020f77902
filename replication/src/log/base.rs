//! The base of a log joined from a snapshot: what it keeps of the ops before the cut (ids for
//! causal checks, the lease/undo state at the cut, and the effective edits whole, because a
//! later undo or redo may still toggle them), and how a full log computes a base at a cut.
//!
//! A cut at Lamport time `L` holds exactly the ops with Lamport time `L` or less. It is
//! *stable* when no op outside it can ever sort before it: see [`Log::stable_lamport`].

use std::collections::{BTreeMap, BTreeSet};

use super::{CHECKPOINT_INTERVAL, Log, OrderKey};
use crate::causal::{Frontier, VersionVector};
use crate::identity::{OpId, PeerId};
use crate::lease::{FoldState, Mark, RejectReason, TargetInfo};
use crate::op::Op;
use crate::payload::{Effect, ObjectId, Payload};
use crate::pending::{Pending, PendingLimits};
use crate::time::Timestamp;

/// What the base knows of one op before the cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BaseKind {
    /// Not an edit (lease, undo, redo, independent).
    Other,
    /// An edit that was rejected: it can never become active.
    RejectedEdit,
    /// An effective edit (active, or undone at the cut); kept whole in [`Base::edits`].
    EffectiveEdit,
}

/// One op before the cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct BaseOp {
    pub(crate) id: OpId,
    /// Index into [`Base::authors`].
    pub(crate) author_idx: u32,
    pub(crate) kind: BaseKind,
}

/// Per author: the last seq and the Lamport time of that op, inside the base.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct BaseAuthor {
    pub(crate) author: PeerId,
    pub(crate) seq: u64,
    pub(crate) lamport: u64,
}

/// What a log keeps of the ops at or before its cut.
#[derive(Clone, Debug)]
pub(crate) struct Base<P> {
    /// The cut: every op with this Lamport time or less is in the base, and no other.
    pub(crate) lamport: u64,
    /// Sorted by author.
    pub(crate) authors: Vec<BaseAuthor>,
    /// Every op of the base, sorted by id.
    pub(crate) ops: Vec<BaseOp>,
    /// The effective edits, whole (a later undo or redo may toggle them).
    pub(crate) edits: BTreeMap<OpId, Op<P>>,
    /// The effective edits of each object in linear order.
    pub(crate) edits_by_object: BTreeMap<ObjectId, Vec<(OrderKey, OpId)>>,
    /// The DAG's heads at the cut.
    pub(crate) heads: Vec<OpId>,
    /// The latest op timestamp in the base.
    pub(crate) max_timestamp: Timestamp,
    /// The lease and undo state at the cut.
    pub(crate) state: FoldState,
    /// The scene at the cut, in the scene's own snapshot encoding.
    pub(crate) scene: Vec<u8>,
}

/// Why a base could not be cut at a Lamport time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CutError {
    /// Ops at or before the cut may still arrive: it is above [`Log::stable_lamport`].
    #[error("cut {cut} is above the stable Lamport time {stable}")]
    NotStable {
        /// The cut asked for.
        cut: u64,
        /// The highest stable cut.
        stable: u64,
    },
    /// The log holds a founder's expel or readmit: a base keeps no membership, so the cut
    /// would forget it (join such a session from full history).
    #[error("the log holds membership ops, which a snapshot cannot keep")]
    Membership,
    /// The session binds its authors ([`Log::bind_authors`]): a base keeps neither the
    /// admissions nor the budgets, so a joined log could not judge the ops after the cut
    /// (join such a session from full history).
    #[error("the session binds its authors, whose admissions and budgets a snapshot cannot keep")]
    Bound,
    /// The log holds a fork ([`crate::fork`]): a base keeps one op per author and seq, so the
    /// cut would forget a side (join such a session from full history).
    #[error("the log holds a forked author's two sides, which a snapshot cannot keep")]
    Forked,
    /// The cut is below the log's own base cut.
    #[error("cut {cut} is below the log's base cut {base}")]
    BelowBase {
        /// The cut asked for.
        cut: u64,
        /// The base's cut.
        base: u64,
    },
}

impl<P> Base<P> {
    fn find(&self, id: &OpId) -> Option<&BaseOp> {
        self.ops
            .binary_search_by(|o| o.id.cmp(id))
            .ok()
            .map(|i| &self.ops[i])
    }

    pub(crate) fn contains(&self, id: &OpId) -> bool {
        self.find(id).is_some()
    }

    /// The Lamport time of the author's last op inside the base (0 if none).
    pub(crate) fn lamport_of(&self, author: &PeerId) -> u64 {
        self.authors
            .binary_search_by(|a| a.author.cmp(author))
            .map_or(0, |i| self.authors[i].lamport)
    }

    pub(crate) fn seq(&self, author: &PeerId) -> u64 {
        self.authors
            .binary_search_by(|a| a.author.cmp(author))
            .map_or(0, |i| self.authors[i].seq)
    }

    /// What the undo/redo fold needs to know of a target inside the base.
    pub(crate) fn target_info(&self, id: &OpId) -> Option<TargetInfo>
    where
        P: Payload,
    {
        let op = self.find(id)?;
        let author = self.authors.get(op.author_idx as usize)?.author;
        let (effect, mark) = match op.kind {
            BaseKind::Other => (Effect::Independent, Mark::Effective),
            // The fold reads only "not effective" from a rejected target; its object and the
            // reason are not kept.
            BaseKind::RejectedEdit => (
                Effect::Edit {
                    object: ObjectId(0),
                },
                Mark::Rejected(RejectReason::TargetNotEffective),
            ),
            BaseKind::EffectiveEdit => (self.edits.get(id)?.payload().effect(), Mark::Effective),
        };
        Some(TargetInfo {
            author,
            effect,
            mark,
        })
    }

    /// The object of an effective edit inside the base.
    pub(crate) fn edit_object(&self, id: &OpId) -> Option<ObjectId>
    where
        P: Payload,
    {
        match self.edits.get(id)?.payload().effect() {
            Effect::Edit { object } => Some(object),
            _ => None,
        }
    }

    pub(crate) fn max_lamport(&self) -> u64 {
        self.authors
            .iter()
            .map(|a| a.lamport)
            .max()
            .unwrap_or(0)
            .max(self.lamport)
    }
}

impl<P: Payload> Base<P> {
    /// The base's deletes, per object, which hide the base edits of their object sorted
    /// before them.
    fn deletes(&self) -> BTreeMap<ObjectId, Vec<(OrderKey, OpId)>> {
        let mut deletes: BTreeMap<ObjectId, Vec<(OrderKey, OpId)>> = BTreeMap::new();
        for (object, edits) in &self.edits_by_object {
            for (key, id) in edits {
                if self
                    .edits
                    .get(id)
                    .is_some_and(|op| op.payload().is_delete())
                {
                    deletes.entry(*object).or_default().push((*key, *id));
                }
            }
        }
        deletes
    }

    /// The objects an effective creation in the base made: every held op sorts after the
    /// base, so all saw it.
    fn created(&self) -> BTreeSet<ObjectId> {
        (self.edits.values())
            .filter(|op| op.payload().creates(&op.author()))
            .filter_map(|op| match op.payload().effect() {
                Effect::Edit { object } => Some(object),
                _ => None,
            })
            .collect()
    }
}

impl<P: Payload> Log<P> {
    /// A log that starts from `base` (a decoded snapshot) instead of from nothing.
    pub(crate) fn from_base(base: Base<P>, limits: PendingLimits) -> Self {
        let mut frontier = Frontier::default();
        for head in &base.heads {
            frontier.deliver(*head, &[]);
        }
        let mut vv = VersionVector::new();
        for a in &base.authors {
            vv.raise(a.author, a.seq);
        }
        // The clock observes the base's latest timestamp when this log authors (`Log::author`),
        // bounded by the wall clock then.
        let clock = crate::time::HybridClock::default();
        let deletes = base.deletes();
        let base_created = base.created();
        let mut log = Self {
            ops: crate::op::OpSlab::default(),
            order: Vec::new(),
            marks: super::marks::Marks::default(),
            horizons: Vec::new(),
            checkpoints: vec![base.state.clone()],
            state: base.state.clone(),
            n_folded: 0,
            authors: BTreeMap::new(),
            by_object: BTreeMap::new(),
            lease_ops: BTreeMap::new(),
            creates: BTreeMap::new(),
            base_created,
            deletes,
            delete_hides: BTreeMap::new(),
            hidden: BTreeMap::new(),
            reach: crate::causal::Reach::default(),
            // A bound session's log is never cut (`CutError::Bound`).
            binding: None,
            admissions: BTreeMap::new(),
            frontier,
            vv,
            // New local ops must land after the cut.
            max_lamport: base.max_lamport(),
            clock,
            pending: Pending::with_limits(limits),
            stats: super::LogStats::default(),
            base: Some(Box::new(base)),
            // Ops inside the base are not counted: a joined log judges quotas on the ops
            // after its cut only (a non-guarantee, as for timestamps).
            n_bytes: 0,
            author_quota: super::MAX_AUTHOR_BYTES,
            refold_paid_until: Timestamp(0),
            refold_budget: super::RefoldBudget::default(),
            session_id: crate::op::UNNAMED_SESSION,
            // A snapshot keeps no membership (a log holding any cannot be cut).
            founder: None,
            membership_ops: BTreeMap::new(),
            expelled: BTreeMap::new(),
            members_changed: Default::default(),
            void_changed: BTreeMap::new(),
            forks: crate::fork::Forks::default(),
            siblings: BTreeMap::new(),
            forks_changed: Default::default(),
            hides_changed: Vec::new(),
        };
        let objects: Vec<ObjectId> = log.deletes.keys().copied().collect();
        for object in objects {
            let hidden = log.hidden_of(object);
            if !hidden.is_empty() {
                log.hidden.insert(object, hidden);
            }
        }
        log
    }

    pub(crate) fn base(&self) -> Option<&Base<P>> {
        self.base.as_deref()
    }

    /// The Lamport time of the base's cut, for a log joined from a snapshot.
    pub fn base_lamport(&self) -> Option<u64> {
        self.base.as_ref().map(|b| b.lamport)
    }

    /// Number of ops inside the base (0 without one); [`Log::len`] counts them too.
    pub fn n_base(&self) -> usize {
        self.base.as_ref().map_or(0, |b| b.ops.len())
    }

    /// Number of ops held whole in the linear order (those after the base's cut).
    pub fn n_held(&self) -> usize {
        self.ops.len()
    }

    /// The highest Lamport time `L` such that every op with Lamport time `L` or less by an
    /// author this log knows is already here.
    ///
    /// An author's ops have growing Lamport times, so once the log holds an op of every known
    /// author at `L` or later, none of their missing ops can sort at or before `L`. An author
    /// never heard of, who worked offline before ever syncing, can still break it: a log
    /// joined at such a cut refuses that author's early ops with [`InsertError::BeforeBase`].
    ///
    /// [`InsertError::BeforeBase`]: super::InsertError::BeforeBase
    pub fn stable_lamport(&self) -> u64 {
        let base_floor = self.base.as_ref().map_or(0, |b| b.lamport);
        self.vv
            .iter()
            .map(|(author, _)| self.last_lamport(author))
            .min()
            .unwrap_or(0)
            .max(base_floor)
    }

    /// The Lamport time of the author's latest op here (0 if none).
    fn last_lamport(&self, author: &PeerId) -> u64 {
        if let Some(op) = self.chain(author).last().map(|&at| self.ops.at(at)) {
            return op.lamport();
        }
        self.base.as_ref().map_or(0, |b| b.lamport_of(author))
    }

    /// The number of held positions at or before Lamport time `cut`.
    pub(crate) fn prefix_len(&self, cut: u64) -> usize {
        (self.order).partition_point(|&at| self.ops.at(at).lamport() <= cut)
    }

    /// The lease/undo state after the first `n` positions.
    pub(crate) fn state_at(&self, n: usize) -> FoldState {
        if n >= self.n_folded {
            return self.state.clone();
        }
        let k = (n / CHECKPOINT_INTERVAL).min(self.checkpoints.len() - 1);
        let mut state = self.checkpoints[k].clone();
        // Judging again learns of each lease op what the log holds already: nothing is
        // recorded.
        let mut cx = super::LeaseCx {
            reach: self.reach.clone(),
            learnt: None,
            alt: None,
        };
        for pos in k * CHECKPOINT_INTERVAL..n {
            self.judge(&mut cx, &mut state, pos);
        }
        state
    }

    /// The base of this log at Lamport time `cut` (without the scene, which the caller folds):
    /// every held op at or before the cut joins the existing base, if any.
    pub(crate) fn base_at(&self, cut: u64) -> Result<(Base<P>, usize), CutError> {
        self.check_cut(cut)?;
        let old = self.base.as_deref();
        let n = self.prefix_len(cut);
        let mut frontier = Frontier::default();
        let mut authors: BTreeMap<PeerId, (u64, u64)> = BTreeMap::new();
        let mut max_timestamp = Timestamp::default();
        let mut edits = BTreeMap::new();
        let mut edits_by_object: BTreeMap<ObjectId, Vec<(OrderKey, OpId)>> = BTreeMap::new();
        let mut kinds: Vec<(OpId, PeerId, BaseKind)> = Vec::new();
        if let Some(b) = old {
            for head in &b.heads {
                frontier.deliver(*head, &[]);
            }
            for a in &b.authors {
                authors.insert(a.author, (a.seq, a.lamport));
            }
            max_timestamp = b.max_timestamp;
            edits = b.edits.clone();
            edits_by_object = b.edits_by_object.clone();
            kinds.extend(b.ops.iter().filter_map(|o| {
                Some((o.id, b.authors.get(o.author_idx as usize)?.author, o.kind))
            }));
        }
        for pos in 0..n {
            let op = self.op_at(pos);
            let (key, id) = (OrderKey::of(op), op.id());
            frontier.deliver(id, op.deps());
            authors.insert(key.author, (key.seq, key.lamport));
            max_timestamp = max_timestamp.max(op.timestamp());
            let kind = match (op.payload().effect(), self.mark_at(pos)) {
                (Effect::Edit { object }, Mark::Effective) => {
                    edits.insert(id, op.clone());
                    edits_by_object.entry(object).or_default().push((key, id));
                    BaseKind::EffectiveEdit
                }
                (Effect::Edit { .. }, Mark::Rejected(_)) => BaseKind::RejectedEdit,
                _ => BaseKind::Other,
            };
            kinds.push((id, key.author, kind));
        }
        let (authors, ops) = base_ops(authors, kinds);
        let base = Base {
            lamport: cut,
            authors,
            ops,
            edits,
            edits_by_object,
            heads: frontier.heads().copied().collect(),
            max_timestamp,
            state: self.state_at(n),
            scene: Vec::new(),
        };
        Ok((base, n))
    }

    /// Whether this log may be cut at Lamport time `cut`: it holds no membership ops, binds
    /// no authors and holds no fork, and the cut is stable and not below its base's.
    fn check_cut(&self, cut: u64) -> Result<(), CutError> {
        if self.has_membership_ops() {
            return Err(CutError::Membership);
        }
        if self.binds_authors() {
            return Err(CutError::Bound);
        }
        if !self.forks.is_empty() {
            return Err(CutError::Forked);
        }
        let stable = self.stable_lamport();
        if cut > stable {
            return Err(CutError::NotStable { cut, stable });
        }
        if let Some(b) = self.base.as_deref()
            && cut < b.lamport
        {
            return Err(CutError::BelowBase {
                cut,
                base: b.lamport,
            });
        }
        Ok(())
    }
}

/// A base's authors (from each author's last seq and Lamport time at the cut) and its ops
/// (from each op's id, author and kind), the ops sorted by id.
fn base_ops(
    authors: BTreeMap<PeerId, (u64, u64)>,
    kinds: Vec<(OpId, PeerId, BaseKind)>,
) -> (Vec<BaseAuthor>, Vec<BaseOp>) {
    let authors: Vec<BaseAuthor> = authors
        .into_iter()
        .map(|(author, (seq, lamport))| BaseAuthor {
            author,
            seq,
            lamport,
        })
        .collect();
    let mut ops: Vec<BaseOp> = kinds
        .into_iter()
        .map(|(id, author, kind)| BaseOp {
            id,
            author_idx: authors
                .binary_search_by(|a| a.author.cmp(&author))
                .map_or(u32::MAX, |i| i as u32),
            kind,
        })
        .collect();
    ops.sort_unstable_by_key(|o| o.id);
    (authors, ops)
}
