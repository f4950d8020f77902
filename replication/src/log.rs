//! The replicated op log: causal delivery through the pending buffer, the deterministic
//! linear order (Lamport time, then author, then seq), and the lease/undo marks of every op,
//! re-evaluated incrementally from checkpoints when a late op lands in the middle.

use std::collections::{BTreeMap, BTreeSet};

use smallvec::SmallVec;

use crate::causal::{Frontier, Reach, VersionVector};
use crate::fork::Forks;
use crate::identity::{Keypair, OpId, PeerId, SessionId};
use crate::lease::{FoldState, Lease, Mark, RejectReason, TargetInfo};
use crate::membership::{FounderCommitment, Membership};
use crate::op::{
    BuildError, MAX_DEPS, MAX_LOG_OPS, Op, OpFields, OpSlab, UNNAMED_SESSION, VerifiedOp,
};
use crate::payload::{Effect, ObjectId, Payload};
use crate::pending::{DepKey, Evicted, Origin, Pending, PendingLimits};
use crate::time::{HybridClock, MAX_CLOCK_SKEW_MICROS, Timestamp};

mod marks;
mod object_keys;
mod seen;

pub use object_keys::ObjectKeys;
pub use seen::MAX_UNSEEN_LEASE_OPS;

/// The fold state is checkpointed every this many positions of the linear order, so a late
/// op re-evaluates from the nearest checkpoint instead of from the start.
pub const CHECKPOINT_INTERVAL: usize = 256;
/// Most bytes of encoded ops one log holds (3.5 GiB): below the store's limit with room for
/// every record's framing, so a store never fills with ops its log accepted.
pub const MAX_LOG_BYTES: u64 = 7 * 512 * 1024 * 1024;
/// Most bytes of encoded ops one author may have in a log (256 MiB, about 10^6 ordinary
/// edits). Judged along the author's own chain of ops, so every full log refuses the same op,
/// and one member cannot fill every peer's memory and store on its own.
pub const MAX_AUTHOR_BYTES: u64 = 256 * 1024 * 1024;
/// Most an op's Lamport time may exceed the highest of its dependencies' and its author's
/// previous op's (2^32). Honest ops exceed it by one, and `u64::MAX / MAX_LAMPORT_JUMP` is far
/// above [`MAX_LOG_OPS`], so no member can exhaust the Lamport clock before the log fills.
pub const MAX_LAMPORT_JUMP: u64 = 1 << 32;
/// Most entries a remote op's refold may re-evaluate without being charged for it: positions
/// of the linear order from the checkpoint before it, plus the edits of each object the scene
/// folds again from its start. An op landing near the end of a small object's history (an
/// honest concurrent edit) is delivered at once, whatever the budget below.
pub const MAX_FREE_REFOLD_ENTRIES: usize = 2 * CHECKPOINT_INTERVAL;
/// Most ops a log keeps that were refused for sorting below their author's previous op as it
/// holds it, while their own deps allowed them (delivered when the fork is learnt); past this
/// the oldest is dropped (a peer asks for it again, as for any op it lacks).
pub const MAX_FORK_CANDIDATE_OPS: usize = 64;
/// Most entries per second that refolds caused by remote ops may re-evaluate, on average,
/// counting only refolds over [`MAX_FREE_REFOLD_ENTRIES`]. A remote op whose refold would be
/// over that while the budget is spent waits in the pending buffer until it is earned back;
/// every op that waited is then delivered in one batch, one refold. So a member sending
/// backdated ops costs a receiver at most this many entries a second, however many it sends,
/// and an op lands in the same place whenever it is delivered.
pub const MAX_REFOLD_ENTRIES_PER_SECOND: u64 = 200_000;
/// How far the refold budget may be overspent before remote ops wait: one second of
/// [`MAX_REFOLD_ENTRIES_PER_SECOND`], so a single late op on a history up to this long is
/// never held.
pub const MAX_REFOLD_BURST_ENTRIES: u64 = MAX_REFOLD_ENTRIES_PER_SECOND;

/// What refolds remote ops cause may cost; [`RefoldBudget::default`] uses the named limits.
/// A peer lowers it only to exercise held deliveries on small logs (the simulator).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RefoldBudget {
    /// Entries a refold may re-evaluate without being charged ([`MAX_FREE_REFOLD_ENTRIES`]).
    pub free_entries: usize,
    /// Entries a second charged refolds may re-evaluate ([`MAX_REFOLD_ENTRIES_PER_SECOND`]).
    pub entries_per_second: u64,
    /// How far the budget may be overspent before ops wait ([`MAX_REFOLD_BURST_ENTRIES`]).
    pub burst_entries: u64,
}

impl Default for RefoldBudget {
    fn default() -> Self {
        Self {
            free_entries: MAX_FREE_REFOLD_ENTRIES,
            entries_per_second: MAX_REFOLD_ENTRIES_PER_SECOND,
            burst_entries: MAX_REFOLD_BURST_ENTRIES,
        }
    }
}

impl RefoldBudget {
    /// Microseconds the budget takes to earn back `entries`.
    fn micros(&self, entries: u64) -> u64 {
        let per_second = self.entries_per_second.max(1);
        entries.saturating_mul(1_000_000) / per_second
    }
}

/// An honest admitter grants a newcomer this share of its remaining budget (a quarter), at
/// most [`MAX_AUTHOR_BYTES`] ([`Log::default_grant`]).
pub const GRANT_SHARE_OF_REMAINING: u64 = 4;

/// The [`Origin`] of ops this peer authors or loads from its own store.
pub const LOCAL_ORIGIN: Origin = Origin(0);

/// Why [`Log::set_founder`] or [`Log::bind_authors`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FounderError {
    /// The log already holds or waits for ops, judged without a founder.
    #[error("the founder must be named before the log holds any op")]
    NotEmpty,
    /// Authors are bound to their admissions, whose root is the founder: name it first.
    #[error("a session binds its authors only once it names its founder")]
    NoFounder,
}

/// Why an op was refused outright (it is not stored, not even as rejected).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InsertError {
    /// The Lamport time is not above every dependency's and the author's previous op's.
    #[error("lamport time {lamport} is not above its causal past ({floor})")]
    BadLamport {
        /// The op's Lamport time.
        lamport: u64,
        /// The highest Lamport time in its immediate past.
        floor: u64,
    },
    /// The Lamport time leaps more than [`MAX_LAMPORT_JUMP`] past its causal past: honest
    /// peers step by one, and a member leaping to near `u64::MAX` would leave nobody able to
    /// author again.
    #[error(
        "lamport time {lamport} leaps past its causal past ({floor}) by over {MAX_LAMPORT_JUMP}"
    )]
    LamportJump {
        /// The op's Lamport time.
        lamport: u64,
        /// The highest Lamport time in its immediate past.
        floor: u64,
    },
    /// The timestamp is earlier than one in its causal past (a dependency's or the author's
    /// previous op's): honest clocks observe every op they depend on, so only a member
    /// backdating an op writes this.
    #[error("timestamp {timestamp} is before its causal past ({floor})")]
    BadTimestamp {
        /// The op's timestamp, in microseconds.
        timestamp: u64,
        /// The latest timestamp in its immediate past.
        floor: u64,
    },
    /// The log is at [`MAX_LOG_OPS`] ops or [`MAX_LOG_BYTES`] bytes.
    #[error("log is full ({MAX_LOG_OPS} ops or {MAX_LOG_BYTES} bytes)")]
    Full,
    /// The op would take its author past its quota ([`MAX_AUTHOR_BYTES`] of encoded ops).
    #[error("author {author} is over its quota of {limit} bytes of ops")]
    AuthorQuota {
        /// The author.
        author: PeerId,
        /// The quota.
        limit: u64,
    },
    /// The session binds its authors ([`Log::bind_authors`]) and the author has no op here
    /// yet, yet this op names no admission of its key among its deps (nor is it the founder's
    /// admission of itself): a key nobody admitted writes nothing.
    #[error("author {author} was not admitted: its first op names no admission of its key")]
    NotAdmitted {
        /// The author.
        author: PeerId,
    },
    /// The session binds its authors, and the op was signed in the layout from before ops
    /// named their session ([`crate::op::OP_FORMAT_VERSION_1`]).
    #[error("an op signed without its session, refused in a session that binds its authors")]
    OldLayout,
}

/// Why a local op could not be authored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AuthorError {
    /// The op could not be built.
    #[error(transparent)]
    Build(#[from] BuildError),
    /// The op could not be inserted.
    #[error(transparent)]
    Insert(#[from] InsertError),
    /// The session binds its authors and holds no admission of this peer's key yet.
    #[error("waiting for a member to admit this peer")]
    NotAdmitted,
}

/// What inserting one op did. Drain it: it is the only report of these facts.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Insertion {
    /// Ops newly delivered, in delivery order (the op itself and any pending ops it freed);
    /// one is held inline.
    pub delivered: SmallVec<[OpId; 1]>,
    /// True if the op was already known (delivered or pending): nothing changed.
    pub duplicate: bool,
    /// True if the op waits in the pending buffer for dependencies.
    pub parked: bool,
    /// Pending ops dropped to stay within limits.
    pub evicted: Vec<Evicted>,
    /// Freed pending ops that were refused when their turn came.
    pub refused: Vec<(OpId, Origin, InsertError)>,
    /// What the scene fold must redo, if anything changed.
    pub refold: Option<Refold>,
}

/// An op's place in the linear order: Lamport time, then author, then seq. Stable: unlike a
/// position, it does not shift when a late op lands before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct OrderKey {
    /// Lamport time.
    pub lamport: u64,
    /// Author.
    pub author: PeerId,
    /// Per-author sequence number.
    pub seq: u64,
}

impl OrderKey {
    /// The key of `op`.
    pub fn of<P>(op: &Op<P>) -> Self {
        Self {
            lamport: op.lamport(),
            author: op.author(),
            seq: op.seq(),
        }
    }
}

/// Where the scene fold must restart after a change to the log.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Refold {
    /// First position of the linear order whose op, mark or activity changed (an undo's
    /// target position counts too).
    pub from: usize,
    /// For each object touched, the first entry from which its own fold must be redone (an
    /// undo's target counts for the target's object), as an order key: positions shift when
    /// later ops land before them and keys do not, so a driver that applies an insertion after
    /// later ones were inserted (events drained in a batch) still finds it.
    pub object_keys: ObjectKeys,
    /// Authors whose ops from this seq on turned void or counted again (an expel or a readmit,
    /// [`crate::membership`]), or were rejected by a fork ([`crate::fork`]): their independent
    /// entries from there must be applied again.
    pub void_from: BTreeMap<PeerId, u64>,
}

impl Refold {
    /// Adds a later insertion's refold to this one: each object from the earlier of its two
    /// first changed entries. Folding the merged refold once, after both insertions, gives
    /// what folding each after its own insertion gives (a driver that drains a step's events
    /// together folds each object once, not once per insertion).
    pub fn merge(&mut self, later: &Refold) {
        for (object, key) in &later.object_keys {
            self.object_keys.lower(*object, *key);
        }
        self.from = self.from.min(later.from);
        for (author, seq) in &later.void_from {
            let earliest = self.void_from.entry(*author).or_insert(*seq);
            *earliest = (*earliest).min(*seq);
        }
    }
}

/// Insertions drained together, not folded yet: their delivered ops in order and their
/// refolds merged ([`Refold::merge`]), so a driver folds each object once per step.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Drained {
    /// The delivered ops of every insertion added that changed the log, in order.
    pub delivered: Vec<OpId>,
    /// Their merged refold; `None` while nothing changed.
    pub refold: Option<Refold>,
}

impl Drained {
    /// Adds the next insertion (one that changed nothing adds nothing).
    pub fn add(&mut self, insertion: &Insertion) {
        let Some(refold) = &insertion.refold else {
            return;
        };
        self.delivered.extend_from_slice(&insertion.delivered);
        match &mut self.refold {
            Some(merged) => merged.merge(refold),
            None => self.refold = Some(refold.clone()),
        }
    }
}

/// What a log holds of one author.
#[derive(Clone, Debug, Default)]
pub(crate) struct Authored {
    /// The author's held ops in seq order, as positions in the
    /// slab: its chain, without the siblings of a fork.
    pub(crate) chain: Vec<u32>,
    /// Bytes of the author's encoded ops held, siblings included ([`MAX_AUTHOR_BYTES`]).
    pub(crate) bytes: u64,
    /// Bytes its held admissions granted other keys ([`crate::membership::Admission`]).
    pub(crate) granted: u64,
    /// What its ops and grants may spend in all: the grants of the admissions its first op
    /// named, the session's cap for the founder, or unbounded where authors are not bound
    /// (only [`MAX_AUTHOR_BYTES`] then holds).
    pub(crate) budget: u64,
}

impl Authored {
    /// Where the chain's op with sequence number `seq` is held (`None` past the chain).
    pub(crate) fn at_seq(&self, seq: u64) -> Option<u32> {
        let i = usize::try_from(seq.checked_sub(1)?).ok()?;
        self.chain.get(i).copied()
    }
}

/// What a refold carries to judge ops against the leases they saw: the reach memo, taken out
/// of the log for its duration, and what judging the last lease op learnt of it.
struct LeaseCx {
    reach: Reach,
    /// What judging the last lease op learnt of it, for the log to record once it is done.
    learnt: Option<Learnt>,
    /// Folds of ops that missed lease ops, kept from one op to the next ([`seen::lease_seen`]);
    /// made when first needed.
    alt: Option<seen::AltFolds>,
}

/// What judging a lease op learnt of it ([`seen::LeaseOp::before`] and
/// [`seen::LeaseOp::unseen`]), and where the log keeps it.
struct Learnt {
    object: ObjectId,
    /// The op's index among its object's lease ops.
    index: usize,
    before: Option<Lease>,
    unseen: Option<Box<[u32]>>,
}

/// What an op's deps show of its causal past ([`Log::deps_seen`]).
#[derive(Clone, Copy)]
struct DepsSeen {
    /// The highest Lamport time among the held deps (0 when none is held).
    lamport: u64,
    /// The latest timestamp among the held deps.
    timestamp: Timestamp,
    /// Every op held before this slab position is a dep or in a dep's causal past.
    horizon: u32,
    /// True if every dep is delivered.
    all_delivered: bool,
}

/// An author's chain of held ops, as delivery reads it: the slab, the author's record (none
/// before its first op).
struct Chain<'a, P> {
    ops: &'a OpSlab<P>,
    authored: Option<&'a Authored>,
}

impl<'a, P> Chain<'a, P> {
    /// How many of the author's ops are held.
    fn held(&self) -> u64 {
        self.authored.map_or(0, |a| a.chain.len() as u64)
    }

    /// The op on the chain at `seq` (`None` past the chain).
    fn at_seq(&self, seq: u64) -> Option<&'a Op<P>> {
        Some(self.ops.at(self.authored?.at_seq(seq)?))
    }

    /// The op held at `op`'s seq, if there is one (`op` is then a fork's second side); `op`
    /// extends the chain otherwise.
    fn twin(&self, op: &Op<P>) -> Option<OpId> {
        let held = self.held();
        assert!(
            op.seq() <= held + 1,
            "delivery waits for the author's previous op"
        );
        // The chain holds an op at every seq up to `held`.
        self.at_seq(op.seq()).map(Op::id)
    }

    /// True if `op`, refused by [`Chain::check_floors`], clears what its deps set and sorts
    /// below its author's previous op as held here only: where the author forked, that op may
    /// be the other side's, and `op` fits once the fork is known.
    fn below_previous_only(&self, forks: &Forks, op: &Op<P>, deps: DepsSeen) -> bool {
        let past_fork = forks.covers(&op.author(), op.seq().saturating_sub(1));
        !past_fork && op.seq() > 1 && clears(op, deps.lamport, deps.timestamp).is_ok()
    }

    /// Checks that `op`'s Lamport time and timestamp clear what its causal past sets (its
    /// held deps, `deps`, and its author's previous op); returns its horizon.
    fn check_floors(&self, forks: &Forks, op: &Op<P>, deps: DepsSeen) -> Result<u32, InsertError> {
        // The author's previous op is part of the causal past only up to its first fork,
        // where there is one previous op whichever side an op is on.
        let past_fork = forks.covers(&op.author(), op.seq().saturating_sub(1));
        let prev = (!past_fork)
            .then(|| self.at_seq(op.seq().checked_sub(1)?))
            .flatten();
        let DepsSeen {
            lamport: mut floor,
            timestamp: mut floor_ts,
            horizon,
            ..
        } = deps;
        if let Some(p) = prev {
            (floor, floor_ts) = (floor.max(p.lamport()), floor_ts.max(p.timestamp()));
        }
        clears(op, floor, floor_ts)?;
        Ok(horizon)
    }
}

/// Checks that `op`'s Lamport time is above `floor`, by at most [`MAX_LAMPORT_JUMP`], and its
/// timestamp at or above `floor_ts`.
fn clears<P>(op: &Op<P>, floor: u64, floor_ts: Timestamp) -> Result<(), InsertError> {
    if op.lamport() <= floor {
        return Err(InsertError::BadLamport {
            lamport: op.lamport(),
            floor,
        });
    }
    if op.lamport() - floor > MAX_LAMPORT_JUMP {
        return Err(InsertError::LamportJump {
            lamport: op.lamport(),
            floor,
        });
    }
    if op.timestamp() < floor_ts {
        return Err(InsertError::BadTimestamp {
            timestamp: op.timestamp().0,
            floor: floor_ts.0,
        });
    }
    Ok(())
}

/// Keeps `op` (from `origin`) among the fork candidates, once, dropping the oldest past
/// [`MAX_FORK_CANDIDATE_OPS`].
fn keep_fork_candidate<P>(
    candidates: &mut std::collections::VecDeque<(Op<P>, Origin)>,
    op: Op<P>,
    origin: Origin,
) {
    if candidates.iter().any(|(c, _)| c.id_ref() == op.id_ref()) {
        return;
    }
    if candidates.len() == MAX_FORK_CANDIDATE_OPS {
        candidates.pop_front();
    }
    candidates.push_back((op, origin));
}

/// What holding an op charges its author: its bytes and grants, within the author's quota
/// and budget.
struct Charge {
    /// The op's encoded bytes.
    n_bytes: u64,
    /// The author's bytes of held ops with it.
    author_bytes: u64,
    /// The author's grants with its own.
    granted: u64,
    /// What the author's ops and grants may spend in all.
    budget: u64,
}

impl Charge {
    /// The charge for `op` on its author's record `authored` (none before its first op, whose
    /// budget is `first_budget` where authors are bound), refused over `quota` bytes or the
    /// budget.
    fn of<P: Payload>(
        authored: Option<&Authored>,
        quota: u64,
        first_budget: Option<u64>,
        op: &Op<P>,
    ) -> Result<Charge, InsertError> {
        let n_bytes = op.encoded().len() as u64;
        let author_bytes = authored.map_or(0, |a| a.bytes) + n_bytes;
        if author_bytes > quota {
            return Err(InsertError::AuthorQuota {
                author: op.author(),
                limit: quota,
            });
        }
        // Its ops and grants along its chain within its budget, on every peer alike.
        let grant = Log::<P>::grant_of(op);
        let granted = authored.map_or(0, |a| a.granted).saturating_add(grant);
        let budget = (first_budget.or(authored.map(|a| a.budget))).unwrap_or(u64::MAX);
        if author_bytes.saturating_add(granted) > budget {
            return Err(InsertError::AuthorQuota {
                author: op.author(),
                limit: budget,
            });
        }
        Ok(Charge {
            n_bytes,
            author_bytes,
            granted,
            budget,
        })
    }

    /// Writes the charge into the author's record; `chain_at` is the op's slab position, or
    /// none for a fork's second side, which is not on the chain.
    fn record(&self, authored: &mut Authored, chain_at: Option<u32>) {
        authored.chain.extend(chain_at);
        authored.bytes = self.author_bytes;
        authored.granted = self.granted;
        authored.budget = self.budget;
    }
}

/// One op in the linear order with its verdict.
#[derive(Debug, Clone, Copy)]
pub struct Entry<'a, P> {
    /// The op.
    pub op: &'a Op<P>,
    /// Effective or rejected (with the reason), at its point of the order.
    pub mark: Mark,
    /// True if the op is effective and not undone by a later op: the scene folds these.
    pub active: bool,
}

/// Counters of what the log refused, dropped, re-evaluated and held back.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LogStats {
    /// Ops refused (equivocation, bad Lamport time, full).
    pub n_refused: u64,
    /// Pending ops evicted.
    pub n_evicted: u64,
    /// Positions of the linear order re-evaluated by refolds (the cost of late ops).
    pub n_refolded: u64,
    /// Entries charged to the refold budget ([`MAX_REFOLD_ENTRIES_PER_SECOND`]).
    pub n_refold_charged: u64,
    /// Remote ops held back because the refold budget was spent.
    pub n_held_for_refold: u64,
}

/// The replicated log of one peer, generic over the payload.
#[derive(Debug, Clone)]
pub struct Log<P> {
    ops: OpSlab<P>,
    /// The linear order, as positions in `ops`: sorted by each op's key, then id (siblings
    /// of a fork share a key); a topological order because Lamport times grow along every
    /// dependency. Keys and ids are read from the ops: an entry is 4 bytes, not 80.
    order: Vec<u32>,
    /// The verdict on each held op, by slab position.
    marks: marks::Marks,
    /// Per held op, by slab position, how much of the delivery order its deps alone show it
    /// saw: every op held before that position is in its causal past ([`seen::Dag`]).
    horizons: Vec<u32>,
    /// `checkpoints[k]` is the fold state before position `k * CHECKPOINT_INTERVAL`.
    checkpoints: Vec<FoldState>,
    /// The fold state after the first `n_folded` positions (all of them between calls).
    state: FoldState,
    n_folded: usize,
    /// What is held of each author: one record, so that an op's delivery looks its author up
    /// twice (to check, then to record), not once per fact.
    authors: BTreeMap<PeerId, Authored>,
    /// Each object's held edits (ops whose effect is [`Effect::Edit`]) in linear order, as
    /// positions in `ops`.
    by_object: BTreeMap<ObjectId, Vec<u32>>,
    /// Each object's held lease ops (acquires and releases) in linear order, with what the
    /// fold learnt of each: a lease binds only ops that saw it.
    lease_ops: BTreeMap<ObjectId, Vec<seen::LeaseOp>>,
    /// Each object's held ops that create it ([`Payload::creates`]) in linear order, as
    /// positions in `ops`: an acquire counts only once an effective one is in its past.
    creates: BTreeMap<ObjectId, Vec<u32>>,
    /// Each object's deletes in linear order.
    deletes: BTreeMap<ObjectId, Vec<(OrderKey, OpId)>>,
    /// For each held delete, the held edits of its object in its causal past.
    delete_hides: BTreeMap<OpId, Vec<OpId>>,
    /// Per object, the edits hidden by an effective delete that is not undone and saw them.
    hidden: BTreeMap<ObjectId, BTreeSet<OpId>>,
    /// Memo of causal reachability (a cache: it changes no verdict).
    reach: Reach,
    /// The founder's budget, the session's cap on bytes of ops, when the session binds its
    /// authors to their admissions ([`Log::bind_authors`]).
    binding: Option<u64>,
    /// Per key, the held ops that admit it, in delivery order.
    admissions: BTreeMap<PeerId, Vec<OpId>>,
    frontier: Frontier,
    vv: VersionVector,
    max_lamport: u64,
    clock: HybridClock,
    pending: Pending<P>,
    /// Ops refused only for sorting below their author's previous op held here, with their
    /// origins, oldest first (at most [`MAX_FORK_CANDIDATE_OPS`]): if the author turns out to
    /// have forked, that op was the other side's, and they are delivered at once.
    fork_candidates: std::collections::VecDeque<(Op<P>, Origin)>,
    stats: LogStats,
    /// Bytes of encoded ops held, in all (per author in [`Authored::bytes`]).
    n_bytes: u64,
    /// [`MAX_AUTHOR_BYTES`], lowered by tests only.
    author_quota: u64,
    /// When the refold budget is earned back: each charged refold pushes it on by its cost
    /// at the budget's rate (a virtual scheduling time, as in GCRA).
    refold_paid_until: Timestamp,
    refold_budget: RefoldBudget,
    /// The session whose id this log's own ops are signed for ([`Log::set_session_id`]).
    session_id: SessionId,
    /// What the session's invite commits to, when it names a founder
    /// ([`crate::membership`]): only membership ops it proves count.
    founder: Option<FounderCommitment>,
    /// Per member, the held membership ops that count (by the founder, of another member),
    /// in delivery order, with whether each expels.
    membership_ops: BTreeMap<PeerId, Vec<(OpId, bool)>>,
    /// Per expelled member, the last seq of its ops that are not void (those in the causal
    /// past of every expel of it that counts and no readmit cancelled).
    expelled: BTreeMap<PeerId, u64>,
    /// Members whose membership ops changed since the last refold.
    members_changed: BTreeSet<PeerId>,
    /// Members whose ops from this seq on changed sides since the last refold.
    void_changed: BTreeMap<PeerId, u64>,
    /// Authors that signed two held ops with one seq ([`crate::fork`]): their ops from that
    /// seq on are rejected as [`RejectReason::Forked`].
    forks: Forks,
    /// Per forked author, its held ops that are not on its chain (`authors`): the second and
    /// later ops of a seq, in delivery order.
    siblings: BTreeMap<PeerId, Vec<OpId>>,
    /// Authors whose fork was found or lowered since the last refold.
    forks_changed: BTreeSet<PeerId>,
    /// Objects whose deletes learnt again what they saw (after a fork), with the delete's
    /// position: their hidden edits are recomputed by the next refold.
    hides_changed: Vec<(ObjectId, usize)>,
}

impl<P: Payload> Default for Log<P> {
    fn default() -> Self {
        Self::with_pending_limits(PendingLimits::default())
    }
}

impl<P: Payload> Log<P> {
    /// An empty log whose pending buffer has the given limits.
    pub fn with_pending_limits(limits: PendingLimits) -> Self {
        Self {
            ops: OpSlab::default(),
            order: Vec::new(),
            marks: marks::Marks::default(),
            horizons: Vec::new(),
            checkpoints: vec![FoldState::default()],
            state: FoldState::default(),
            n_folded: 0,
            authors: BTreeMap::new(),
            by_object: BTreeMap::new(),
            lease_ops: BTreeMap::new(),
            creates: BTreeMap::new(),
            deletes: BTreeMap::new(),
            delete_hides: BTreeMap::new(),
            hidden: BTreeMap::new(),
            reach: Reach::default(),
            binding: None,
            admissions: BTreeMap::new(),
            frontier: Frontier::default(),
            vv: VersionVector::new(),
            max_lamport: 0,
            clock: HybridClock::default(),
            pending: Pending::with_limits(limits),
            fork_candidates: std::collections::VecDeque::new(),
            stats: LogStats::default(),
            n_bytes: 0,
            author_quota: MAX_AUTHOR_BYTES,
            refold_paid_until: Timestamp(0),
            refold_budget: RefoldBudget::default(),
            session_id: UNNAMED_SESSION,
            founder: None,
            membership_ops: BTreeMap::new(),
            expelled: BTreeMap::new(),
            members_changed: BTreeSet::new(),
            void_changed: BTreeMap::new(),
            forks: Forks::default(),
            siblings: BTreeMap::new(),
            forks_changed: BTreeSet::new(),
            hides_changed: Vec::new(),
        }
    }

    /// Names what the session's invite commits to, so that its founder's membership ops count
    /// ([`crate::membership`]). Every peer of a session must set the same one before its first
    /// op is inserted (a log joined from a snapshot: before its first op after the cut), or
    /// their verdicts on expelled members differ.
    pub fn set_founder(&mut self, commitment: FounderCommitment) -> Result<(), FounderError> {
        if self.ops.len() > 0 || !self.pending.is_empty() {
            return Err(FounderError::NotEmpty);
        }
        self.founder = Some(commitment);
        Ok(())
    }

    /// Names the session this log is of: its own ops are signed for it ([`Op::sign`]), and
    /// what it receives is checked against it ([`crate::sync`]). A log starts with
    /// [`UNNAMED_SESSION`]; [`crate::Peer::new`] names its session.
    pub fn set_session_id(&mut self, session_id: SessionId) {
        self.session_id = session_id;
    }

    /// The session this log is of ([`Log::set_session_id`]).
    pub fn session_id(&self) -> SessionId {
        self.session_id
    }

    /// What the session's invite commits to, if set.
    pub fn founder(&self) -> Option<FounderCommitment> {
        self.founder
    }

    /// Binds the session's authors to their admissions ([`crate::membership`]): from its first
    /// op, the log accepts a key's ops only if its first op names an admission of it among its
    /// deps (or is the founder's admission of itself, showing the nonce), and holds each
    /// author's spending (its ops' bytes and the grants it gave) within its budget, the
    /// founder's being `founder_budget` bytes (at most [`MAX_LOG_BYTES`]: the app passes that;
    /// every peer of a session must pass the same). Ops signed without their session are
    /// refused. Every peer of a session must bind, or not, before its first op, as for
    /// [`Log::set_founder`], which must come first.
    pub fn bind_authors(&mut self, founder_budget: u64) -> Result<(), FounderError> {
        if self.ops.len() > 0 || !self.pending.is_empty() {
            return Err(FounderError::NotEmpty);
        }
        if self.founder.is_none() {
            return Err(FounderError::NoFounder);
        }
        self.binding = Some(founder_budget.min(MAX_LOG_BYTES));
        Ok(())
    }

    /// True if the session binds its authors to their admissions ([`Log::bind_authors`]).
    pub fn binds_authors(&self) -> bool {
        self.binding.is_some()
    }

    /// The founder's budget, when the session binds its authors ([`Log::bind_authors`]).
    pub fn founder_budget(&self) -> Option<u64> {
        self.binding
    }

    /// True if `key` may write here: authors are not bound, or the log holds an op of it or
    /// an admission of it.
    pub fn is_admitted(&self, key: &PeerId) -> bool {
        self.binding.is_none()
            || self.authors.contains_key(key)
            || self.admissions.contains_key(key)
    }

    /// Bytes `author` may still spend on ops and grants, where authors are bound and it has
    /// written (`None` otherwise).
    pub fn remaining_budget(&self, author: &PeerId) -> Option<u64> {
        self.binding?;
        let a = self.authors.get(author)?;
        Some(a.budget.saturating_sub(a.bytes + a.granted))
    }

    /// What an honest `admitter` grants a newcomer: [`GRANT_SHARE_OF_REMAINING`] of its
    /// remaining budget, at most [`MAX_AUTHOR_BYTES`]. An admitter with no op yet (it waits for
    /// its own admission's grant to be known here) grants a share of [`MAX_AUTHOR_BYTES`].
    pub fn default_grant(&self, admitter: &PeerId) -> u64 {
        let remaining = self.remaining_budget(admitter).unwrap_or(MAX_AUTHOR_BYTES);
        (remaining / GRANT_SHARE_OF_REMAINING).min(MAX_AUTHOR_BYTES)
    }

    /// The expelled members, each with the last seq of its ops that still count (its later
    /// ops are void).
    pub fn expelled(&self) -> &BTreeMap<PeerId, u64> {
        &self.expelled
    }

    /// True if the founder expelled `member` (and has not readmitted it).
    pub fn is_expelled(&self, member: &PeerId) -> bool {
        self.expelled.contains_key(member)
    }

    /// Sets what refolds remote ops cause may cost ([`RefoldBudget`]).
    pub fn set_refold_budget(&mut self, budget: RefoldBudget) {
        self.refold_budget = budget;
    }

    /// An empty log whose authors' quota is `quota` bytes instead of [`MAX_AUTHOR_BYTES`].
    #[cfg(test)]
    pub(crate) fn with_author_quota(quota: u64) -> Self {
        Self {
            author_quota: quota,
            ..Self::default()
        }
    }

    /// Bytes of encoded ops held.
    pub fn n_bytes(&self) -> u64 {
        self.n_bytes
    }

    /// Bytes of encoded ops held by `author` (of the ops after a snapshot's cut, in a joined
    /// log).
    pub fn author_bytes(&self, author: &PeerId) -> u64 {
        self.authors.get(author).map_or(0, |a| a.bytes)
    }

    /// The author's held ops on its chain in seq order, as slab positions.
    fn chain(&self, author: &PeerId) -> &[u32] {
        self.authors.get(author).map_or(&[], |a| &a.chain)
    }

    /// Authors, signs and inserts a new op by `keypair` that depends on the current heads.
    pub fn author(
        &mut self,
        keypair: &Keypair,
        now: Timestamp,
        payload: P,
    ) -> Result<(VerifiedOp<P>, Insertion), AuthorError> {
        let me = keypair.peer_id();
        let own_admissions = self.own_admissions(&me, &payload)?;
        let seq = self.vv.get(&me).checked_add(1).ok_or(InsertError::Full)?;
        let lamport = self.max_lamport.checked_add(1).ok_or(InsertError::Full)?;
        let timestamp = self.clock.tick(now);
        let mut deps = self.author_deps(timestamp);
        if let Some(admission) = own_admissions
            && !deps.contains(&admission)
        {
            // Left-out heads stay heads: the next op names them.
            deps.truncate(MAX_DEPS - 1);
            deps.push(admission);
        }
        let fields = OpFields {
            seq,
            lamport,
            timestamp,
            deps,
            payload,
        };
        let op = Op::sign(keypair, &self.session_id, fields)?;
        let insertion = self.insert_from(now, op.clone(), LOCAL_ORIGIN, false)?;
        assert!(
            insertion.delivered.first() == Some(&op.id()),
            "a local op is delivered at once"
        );
        Ok((op, insertion))
    }

    /// The admissions of `me` its next op must name ([`Log::bind_authors`]): one, when authors
    /// are bound and `me` has no op yet, unless `payload` is the founder's admission of itself.
    fn own_admissions(&self, me: &PeerId, payload: &P) -> Result<Option<OpId>, AuthorError> {
        if self.binding.is_none() || self.vv.get(me) > 0 || self.is_founding(me, payload) {
            return Ok(None);
        }
        let first = self.admissions.get(me).and_then(|ids| ids.first());
        first.copied().map(Some).ok_or(AuthorError::NotAdmitted)
    }

    /// True if `payload`, by `author`, is the founder's admission of itself.
    fn is_founding(&self, author: &PeerId, payload: &P) -> bool {
        let nonce = payload
            .admission()
            .filter(|a| a.key == *author)
            .and_then(|a| a.nonce);
        (self.founder.as_ref()).is_some_and(|f| nonce.is_some_and(|n| f.is_founder(author, &n)))
    }

    /// The budget of `op`'s author, whose first op here it is, where authors are bound
    /// ([`Authored::budget`]): the session's cap `cap` for the founder's admission of itself,
    /// the grants of the admissions of its key it names among its deps (by other keys)
    /// otherwise. Every dep is delivered, so every peer finds the same.
    fn first_budget(&self, op: &Op<P>, cap: u64) -> Result<u64, InsertError> {
        let author = op.author();
        if self.is_founding(&author, op.payload()) {
            return Ok(cap);
        }
        let grants = (op.deps().iter())
            .filter_map(|d| self.ops.get(d))
            .filter(|d| d.author() != author)
            .filter_map(|d| d.payload().admission().filter(|a| a.key == author))
            .map(|a| a.grant_bytes);
        let mut budget = None;
        for grant in grants {
            budget = Some(budget.unwrap_or(0u64).saturating_add(grant));
        }
        budget.ok_or(InsertError::NotAdmitted { author })
    }

    /// Bytes `op` grants another key (its admission's grant; 0 for any other op, and for an
    /// admission of its own author).
    fn grant_of(op: &Op<P>) -> u64 {
        (op.payload().admission())
            .filter(|a| a.key != op.author())
            .map_or(0, |a| a.grant_bytes)
    }

    /// The heads a new op depends on: all of them, or when more than [`MAX_DEPS`] peers wrote
    /// concurrently, the [`MAX_DEPS`] latest by Lamport time. Leaving older heads out only
    /// weakens the op's causal claim (its Lamport time still follows everything seen); the
    /// heads left out stay heads, and the next op names them. Heads stamped after `timestamp`
    /// (ops from a store that arrived before the clock bound existed) are left out the same way
    /// until the clock passes them, so this peer's op is never before its causal past.
    fn author_deps(&self, timestamp: Timestamp) -> Vec<OpId> {
        let mut heads: Vec<OpId> = self
            .frontier
            .heads()
            .filter(|id| {
                self.ops
                    .get(id)
                    .is_none_or(|op| op.timestamp() <= timestamp)
            })
            .copied()
            .collect();
        if heads.len() > MAX_DEPS {
            heads.sort_by_key(|id| std::cmp::Reverse((self.get(id).map_or(0, Op::lamport), *id)));
            heads.truncate(MAX_DEPS);
            heads.sort();
        }
        heads
    }

    /// Inserts a verified op from `origin`: delivers it if its causal past is here (and then
    /// every pending op it frees), or parks it until then. An op from a remote origin whose
    /// timestamp runs more than [`MAX_CLOCK_SKEW_MICROS`] ahead of `now` also waits, until the
    /// clock catches up ([`Log::release_due`]); where it lands in the order does not depend on
    /// when. Pending ops whose time came are delivered along the way.
    pub fn insert(
        &mut self,
        now: Timestamp,
        op: VerifiedOp<P>,
        origin: Origin,
    ) -> Result<Insertion, InsertError> {
        self.insert_from(now, op, origin, true)
    }

    /// [`Log::insert`]; `clocked` is false only for an op this log's author just stamped
    /// (several in one microsecond may step a little past the skew bound). Ops from
    /// [`LOCAL_ORIGIN`] (this peer's store) never wait for the clock either.
    fn insert_from(
        &mut self,
        now: Timestamp,
        op: VerifiedOp<P>,
        origin: Origin,
        clocked: bool,
    ) -> Result<Insertion, InsertError> {
        let op = op.into_op();
        let mut out = Insertion::default();
        if self.contains_arriving(&op.id()) || self.pending.contains(&op.id()) {
            out.duplicate = true;
            self.deliver_queue(now, std::collections::VecDeque::new(), None, &mut out);
            return Ok(out);
        }
        let deps = self.deps_seen(&op);
        let missing = self.missing(&op, now, &deps).and_then(|mut keys| {
            if !clocked || origin == LOCAL_ORIGIN {
                keys.retain(|key| !matches!(key, DepKey::Clock(_)));
            }
            (!keys.is_empty()).then_some(keys)
        });
        if let Some(missing) = missing {
            out.parked = true;
            out.evicted = self.pending.insert(now, op, origin, missing);
            self.deliver_queue(now, std::collections::VecDeque::new(), None, &mut out);
            return Ok(out);
        }
        let remote = clocked && origin != LOCAL_ORIGIN;
        if remote && let Some(until) = self.refold_hold(&op, now) {
            out.parked = true;
            self.hold_for_refold(now, op, origin, until, &mut out);
            self.deliver_queue(now, std::collections::VecDeque::new(), None, &mut out);
            return Ok(out);
        }
        let first_id = op.id();
        let first_pos = self
            .deliver(op, origin, now, deps)
            .inspect_err(|_| self.stats.n_refused += 1)?;
        let mut queue = std::collections::VecDeque::new();
        self.free_waiters(first_id, &mut queue);
        out.delivered.push(first_id);
        self.deliver_queue(now, queue, Some((first_pos, remote)), &mut out);
        Ok(out)
    }

    /// Delivers the pending ops whose timestamps the clock `now` has caught up with (and every
    /// op they free). Drivers call it when [`Log::next_due`] has passed.
    pub fn release_due(&mut self, now: Timestamp) -> Insertion {
        let mut out = Insertion::default();
        self.deliver_queue(now, std::collections::VecDeque::new(), None, &mut out);
        out
    }

    /// When the earliest op waiting for the clock may be delivered, if any waits.
    pub fn next_due(&self) -> Option<Timestamp> {
        self.pending.next_due()
    }

    /// Delivers `queue` (freed ops), then the pending ops due at `now`, and everything they
    /// free; records it all in `out` with the refold from the first changed position.
    /// `first` is the position of an op delivered just before, and whether it came from a
    /// remote origin: a refold a remote op caused is charged to the refold budget.
    fn deliver_queue(
        &mut self,
        now: Timestamp,
        mut queue: std::collections::VecDeque<(Op<P>, Origin)>,
        first: Option<(usize, bool)>,
        out: &mut Insertion,
    ) {
        let mut first_pos = first.map(|(pos, _)| pos);
        let mut charged = first.is_some_and(|(_, remote)| remote);
        if !self.pending.is_empty() {
            queue.extend(self.pending.due(now));
        }
        loop {
            let Some((ready, ready_origin)) = queue.pop_front() else {
                // A fork this insertion revealed may let a refused op in.
                queue = self.retry_fork_candidates();
                if queue.is_empty() {
                    break;
                }
                continue;
            };
            let id = ready.id();
            let deps = self.deps_seen(&ready);
            if let Some(missing) = self.missing(&ready, now, &deps) {
                // Freed by one key but another (e.g. the previous seq) is still missing.
                out.evicted
                    .extend(self.pending.insert(now, ready, ready_origin, missing));
                continue;
            }
            let remote = ready_origin != LOCAL_ORIGIN;
            if remote && let Some(until) = self.refold_hold(&ready, now) {
                self.hold_for_refold(now, ready, ready_origin, until, out);
                continue;
            }
            match self.deliver(ready, ready_origin, now, deps) {
                Ok(pos) => {
                    first_pos = Some(first_pos.map_or(pos, |f| f.min(pos)));
                    charged |= remote;
                    out.delivered.push(id);
                    self.free_waiters(id, &mut queue);
                }
                Err(e) => {
                    self.stats.n_refused += 1;
                    out.refused.push((id, ready_origin, e));
                }
            }
        }
        self.close_insertion(now, first_pos, charged, out);
    }

    /// The fork candidates whose author is now known to have forked before their seq: their
    /// previous op is no longer read from the chain, so they may be delivered. Nothing unless
    /// this insertion found a fork.
    fn retry_fork_candidates(&mut self) -> std::collections::VecDeque<(Op<P>, Origin)> {
        if self.forks_changed.is_empty() || self.fork_candidates.is_empty() {
            return std::collections::VecDeque::new();
        }
        let forks = &self.forks;
        let (retry, keep) = std::mem::take(&mut self.fork_candidates)
            .into_iter()
            .partition(|(op, _)| forks.covers(&op.author(), op.seq() - 1));
        self.fork_candidates = keep;
        retry
    }

    /// Ends an insertion that delivered from `first_pos` on (`None`: nothing moved): notes the
    /// forks and expels it brought, and records in `out` the refold from the first changed
    /// position, charged to the refold budget if a remote op caused it (`charged`).
    fn close_insertion(
        &mut self,
        now: Timestamp,
        mut first_pos: Option<usize>,
        charged: bool,
        out: &mut Insertion,
    ) {
        self.stats.n_evicted += out.evicted.len() as u64;
        if !self.forks_changed.is_empty()
            && let Some(pos) = self.note_forks()
        {
            first_pos = Some(first_pos.map_or(pos, |f| f.min(pos)));
        }
        if !self.members_changed.is_empty() {
            // A membership op was delivered, so `first_pos` is set and the refold reports
            // the activity this changes.
            self.update_expelled();
        }
        if let Some(first_pos) = first_pos {
            let positions = self.refold_positions(first_pos);
            // Held ops never move nor go, and every op this insertion held is in `delivered`:
            // they are the slab's last ones.
            let first_new = self.ops.len().saturating_sub(out.delivered.len());
            debug_assert!(
                (out.delivered.last()).is_none_or(|id| {
                    let at = self.ops.position(id).map(|at| at as usize);
                    at == self.ops.len().checked_sub(1)
                }),
                "the ops an insertion delivered are the last held"
            );
            let refold = self.refold_from(first_pos, first_new);
            if charged {
                let objects = refold.object_keys.iter();
                let entries = positions
                    + objects
                        .map(|(object, from)| self.scene_refold_entries(*object, from))
                        .sum::<usize>();
                self.charge_refold(now, entries);
            }
            out.refold = Some(refold);
        }
    }

    /// Positions a refold from `from` re-evaluates: from the checkpoint at or before it, or
    /// none when `from` lies after everything folded (ops arriving in order).
    fn refold_positions(&self, from: usize) -> usize {
        if from >= self.n_folded {
            0
        } else {
            self.order.len() - self.refold_start(from)
        }
    }

    /// The checkpointed position a refold from `from` (before what was folded) starts at.
    fn refold_start(&self, from: usize) -> usize {
        (from / CHECKPOINT_INTERVAL).min(self.checkpoints.len() - 1) * CHECKPOINT_INTERVAL
    }

    /// Edits a scene folds again when `object` changes from `from` on: all of them (it folds
    /// the object from its start) unless the change is at or after its last held edit.
    fn scene_refold_entries(&self, object: ObjectId, from: &OrderKey) -> usize {
        // A change at or after the order's last op lies after every held edit (an op arriving
        // in order): no need to look the object up.
        if (self.order.last()).is_none_or(|&last| self.slot_cmp(last, from).is_le()) {
            return 0;
        }
        let held = self.held_edits(object);
        if held
            .last()
            .is_none_or(|&last| self.slot_cmp(last, from).is_le())
        {
            return 0;
        }
        held.len()
    }

    /// Charges `entries` re-evaluated by a refold remote ops caused to the refold budget.
    fn charge_refold(&mut self, now: Timestamp, entries: usize) {
        if entries <= self.refold_budget.free_entries {
            return;
        }
        self.stats.n_refold_charged += entries as u64;
        let micros = self.refold_budget.micros(entries as u64);
        self.refold_paid_until = self
            .refold_paid_until
            .max(now)
            .saturating_add_micros(micros);
    }

    /// When a remote op must wait for the refold budget: its refold would re-evaluate more
    /// than the free entries while the budget is overspent by more than its burst. `None` to
    /// deliver it now.
    fn refold_hold(&self, op: &Op<P>, now: Timestamp) -> Option<Timestamp> {
        let burst = self.refold_budget.micros(self.refold_budget.burst_entries);
        let until = Timestamp(self.refold_paid_until.0.checked_sub(burst)?);
        if until <= now {
            return None;
        }
        let key = OrderKey::of(op);
        let pos = point_near_end(&self.order, |&at| self.slot_cmp(at, &key).is_lt());
        // The object the scene folds again, from the op itself or from an undone edit.
        let object = match op.payload().effect() {
            Effect::Edit { object }
            | Effect::Acquire { object, .. }
            | Effect::Release { object } => Some((object, key)),
            Effect::Undo { target } | Effect::Redo { target } => self
                .target_object(&target)
                .map(|(object, at)| (object, self.order_key(at).min(key))),
            Effect::Independent => None,
        };
        let scene = object.map_or(0, |(o, from)| self.scene_refold_entries(o, &from));
        (self.refold_positions(pos) + scene > self.refold_budget.free_entries).then_some(until)
    }

    /// Parks `op` until `until`, when the refold budget is earned back
    /// ([`Log::refold_hold`]); it is then delivered with every op that waited beside it.
    fn hold_for_refold(
        &mut self,
        now: Timestamp,
        op: Op<P>,
        origin: Origin,
        until: Timestamp,
        out: &mut Insertion,
    ) {
        self.stats.n_held_for_refold += 1;
        let wait = BTreeSet::from([DepKey::Clock(until)]);
        out.evicted
            .extend(self.pending.insert(now, op, origin, wait));
    }

    /// True if the op `id` of `author` at `seq` from `origin` would wait for its author's
    /// previous op and be dropped at once by the full pending buffer
    /// ([`Pending::drops_on_arrival`]): a receiver skips it unread, since checking its
    /// signature would buy nothing.
    pub fn pending_drops(&self, origin: Origin, author: &PeerId, seq: u64, id: OpId) -> bool {
        let held = self.version_vector().get(author);
        seq > held.saturating_add(1) && self.pending.drops_on_arrival(origin, author, seq, id)
    }

    /// Drops pending ops that waited too long; their senders offer them again on next sync.
    pub fn expire_pending(&mut self, now: Timestamp) -> Vec<Evicted> {
        let evicted = self.pending.expire(now);
        self.stats.n_evicted += evicted.len() as u64;
        evicted
    }

    /// When the next pending op expires, if any waits.
    pub fn next_pending_expiry(&self) -> Option<Timestamp> {
        self.pending.next_expiry()
    }

    /// Inserts every op of `other` (in its linear order, so causally).
    pub fn merge(&mut self, now: Timestamp, other: &Log<P>) -> Result<(), InsertError> {
        for &at in &other.order {
            let op = other.ops.at(at).clone();
            self.insert(now, VerifiedOp::trusted(op), LOCAL_ORIGIN)?;
        }
        Ok(())
    }

    /// What `op`'s deps show of its causal past, looked up once for [`Log::missing`] and
    /// [`Log::deliver`].
    fn deps_seen(&self, op: &Op<P>) -> DepsSeen {
        let mut seen = DepsSeen {
            lamport: 0,
            timestamp: Timestamp::default(),
            horizon: 0,
            all_delivered: true,
        };
        for d in op.deps() {
            let Some(d_at) = self.ops.position(d) else {
                seen.all_delivered = false;
                continue;
            };
            let dep = self.ops.at(d_at);
            seen.lamport = seen.lamport.max(dep.lamport());
            seen.timestamp = seen.timestamp.max(dep.timestamp());
            // The dep itself and every op before its own horizon: one prefix when they meet.
            let h = self.horizons[d_at as usize];
            seen.horizon = seen.horizon.max(if h == d_at { d_at + 1 } else { h });
        }
        seen
    }

    /// What `op`, whose deps show `deps` ([`Log::deps_seen`]), waits for before it can be
    /// delivered: `None` when nothing.
    fn missing(&self, op: &Op<P>, now: Timestamp, deps: &DepsSeen) -> Option<BTreeSet<DepKey>> {
        let seq_ready = op.seq() == 1 || self.vv.get(&op.author()) >= op.seq() - 1;
        let on_time = op.timestamp() <= now.saturating_add_micros(MAX_CLOCK_SKEW_MICROS);
        if seq_ready && on_time && deps.all_delivered {
            // The usual case: nothing to collect (nor to drop).
            return None;
        }
        let mut missing: BTreeSet<DepKey> = op
            .deps()
            .iter()
            .filter(|d| !self.contains(d))
            .map(|d| DepKey::Op(*d))
            .collect();
        if !seq_ready {
            missing.insert(DepKey::Seq(op.author(), op.seq() - 1));
        }
        // Ops from this peer's store are not held back (an insertion from `LOCAL_ORIGIN` drops
        // this key): the store has them because they were delivered before. One stored before
        // this bound existed cannot pin the clock (`HybridClock::observe` is bounded) nor make
        // a local op precede it (`Log::author_deps` leaves it out until the clock passes it).
        if !on_time {
            missing.insert(DepKey::Clock(Timestamp(
                op.timestamp().0 - MAX_CLOCK_SKEW_MICROS,
            )));
        }
        Some(missing)
    }

    fn free_waiters(&mut self, id: OpId, queue: &mut std::collections::VecDeque<(Op<P>, Origin)>) {
        if self.pending.is_empty() {
            return;
        }
        let Some(op) = self.ops.get(&id) else { return };
        let keys = [DepKey::Op(id), DepKey::Seq(op.author(), op.seq())];
        for key in keys {
            queue.extend(self.pending.satisfy(key));
        }
    }

    /// Adds an op whose causal past is delivered; returns its position in the order. An op
    /// whose author's slot is taken is held beside the first as a sibling ([`crate::fork`]).
    fn deliver(
        &mut self,
        op: Op<P>,
        origin: Origin,
        now: Timestamp,
        deps: DepsSeen,
    ) -> Result<usize, InsertError> {
        let author = op.author();
        if self.binding.is_some() && op.version() != crate::op::OP_FORMAT_VERSION {
            return Err(InsertError::OldLayout);
        }
        // Where authors are bound, a new author's budget, from its first op (an old one's is
        // in its record); an unbound log looks nothing up.
        let first_budget = match self.binding {
            Some(cap) if !self.authors.contains_key(&author) => Some(self.first_budget(&op, cap)?),
            _ => None,
        };
        // The author's record, looked up once: read to check the op, then written to hold it.
        let authored = self.authors.get_mut(&author);
        let chain = Chain {
            ops: &self.ops,
            authored: authored.as_deref(),
        };
        debug_assert_eq!(
            chain.held(),
            self.vv.get(&author),
            "the chain is what is held"
        );
        let twin = chain.twin(&op);
        if self.ops.len() >= MAX_LOG_OPS {
            return Err(InsertError::Full);
        }
        let horizon = match chain.check_floors(&self.forks, &op, deps) {
            Ok(horizon) => horizon,
            Err(e) => {
                if chain.below_previous_only(&self.forks, &op, deps) {
                    keep_fork_candidate(&mut self.fork_candidates, op, origin);
                }
                return Err(e);
            }
        };
        let charge = Charge::of(authored.as_deref(), self.author_quota, first_budget, &op)?;
        if self.n_bytes + charge.n_bytes > MAX_LOG_BYTES {
            return Err(InsertError::Full);
        }
        // Where the slab will hold it: every path from here holds it.
        let at = u32::try_from(self.ops.len()).expect("a log holds fewer than 2^32 ops");
        // A sibling of a fork is not on its author's chain.
        let chain_at = twin.is_none().then_some(at);
        match authored {
            Some(a) => charge.record(a, chain_at),
            // A new author: its chain grows from empty, as every chain does.
            None => charge.record(self.authors.entry(author).or_default(), chain_at),
        }
        Ok(self.hold(op, now, at, twin, horizon, charge.n_bytes))
    }

    /// Holds `op`, checked, at slab position `at`: places it in the order and the indexes
    /// (a fork's second side, whose first is `twin`, only in the fork's); returns its
    /// position in the order. Inlined, so that the op moves from its caller into its slot
    /// once, not through this call's argument as well.
    #[inline(always)]
    fn hold(
        &mut self,
        op: Op<P>,
        now: Timestamp,
        at: u32,
        twin: Option<OpId>,
        horizon: u32,
        n_bytes: u64,
    ) -> usize {
        let (author, key, id) = (op.author(), OrderKey::of(&op), op.id());
        // Most ops arrive in order: append without searching. Siblings share a key: the id
        // breaks the tie.
        let pos = point_near_end(&self.order, |&at| {
            let op = self.ops.at(at);
            cmp_key(op, &key).then_with(|| op.id_ref().cmp(&id)).is_lt()
        });
        self.order.insert(pos, at);
        // A placeholder: the refold that follows judges it.
        self.marks.push();
        if let Some(twin) = twin {
            self.hold_sibling(op, at, twin, horizon, n_bytes);
            return pos;
        }
        self.index_effect(&op, at, key);
        let delete_of = match op.payload().effect() {
            Effect::Edit { object } if op.payload().is_delete() => Some(object),
            _ => None,
        };
        self.vv.raise(author, op.seq());
        self.frontier.deliver(id, op.deps());
        self.horizons.push(self.horizon_of(at, horizon));
        self.max_lamport = self.max_lamport.max(op.lamport());
        self.clock.observe(op.timestamp(), now);
        let membership = op.payload().membership();
        if let Some(admission) = op.payload().admission() {
            self.admissions.entry(admission.key).or_default().push(id);
        }
        let held = self.ops.insert(id, op);
        debug_assert_eq!(held, at, "held where the order says");
        self.n_bytes += n_bytes;
        if let Some(object) = delete_of {
            self.note_delete(object, id, key);
        }
        if let Some(membership) = membership {
            self.note_membership(author, id, membership);
        }
        pos
    }

    /// Holds `op`, the second side of a fork whose first is `twin`, at slab position `at`
    /// (placed in the order already): rejected whatever it does, so no object, lease or delete
    /// index names it, only the fork's.
    #[inline]
    fn hold_sibling(&mut self, op: Op<P>, at: u32, twin: OpId, horizon: u32, n_bytes: u64) {
        let (author, id) = (op.author(), op.id());
        self.siblings.entry(author).or_default().push(id);
        if self.forks.record(author, op.seq(), twin, id) {
            self.forks_changed.insert(author);
        }
        self.frontier.deliver(id, op.deps());
        self.horizons.push(self.horizon_of(at, horizon));
        self.max_lamport = self.max_lamport.max(op.lamport());
        let held = self.ops.insert(id, op);
        debug_assert_eq!(held, at, "held where the order says");
        self.n_bytes += n_bytes;
    }

    /// Names `op`, at slab position `at` and sorting by `key`, in the index of what its
    /// effect touches: its object's edits (and creations and deletes), or its object's lease
    /// ops.
    fn index_effect(&mut self, op: &Op<P>, at: u32, key: OrderKey) {
        match op.payload().effect() {
            Effect::Edit { object } => {
                let ops = &self.ops;
                let before = |&a: &u32| cmp_key(ops.at(a), &key).is_lt();
                insert_in_list(&mut self.by_object, object, at, before);
                if op.payload().creates(&op.author()) {
                    insert_in_list(&mut self.creates, object, at, before);
                }
                if op.payload().is_delete() {
                    let deletes = self.deletes.entry(object).or_default();
                    let at = deletes.partition_point(|(k, _)| *k < key);
                    deletes.insert(at, (key, op.id()));
                }
            }
            Effect::Acquire { object, .. } | Effect::Release { object } => {
                // Placeholders: the refold that follows fills them in.
                let placeholder = seen::LeaseOp {
                    key,
                    at,
                    before: None,
                    unseen: None,
                };
                insert_in_list(&mut self.lease_ops, object, placeholder, |l| l.key < key);
            }
            _ => {}
        }
    }

    /// The horizon of the op about to be held at `at`, just delivered to the frontier, whose
    /// deps' horizons give `from_deps`. When the op is the frontier's only head, its deps
    /// named every head: every held op is in its causal past.
    fn horizon_of(&self, at: u32, from_deps: u32) -> u32 {
        if self.frontier.len() == 1 {
            at
        } else {
            from_deps
        }
    }

    /// The held DAG, for reachability.
    fn dag(&self) -> seen::Dag<'_, P> {
        seen::Dag {
            ops: &self.ops,
            horizons: &self.horizons,
            authors: &self.authors,
            forks: &self.forks,
            members: &self.membership_ops,
            marks: &self.marks,
        }
    }

    /// True if an effective op creating `object` ([`Payload::creates`]) is in the causal past
    /// of the op held at `at`, whose order key is `key`.
    fn created_in_past(
        &self,
        reach: &mut Reach,
        at: u32,
        key: &OrderKey,
        object: ObjectId,
    ) -> bool {
        let Some(list) = self.creates.get(&object) else {
            return false;
        };
        let n = point_near_end(list, |&c| self.slot_cmp(c, key).is_lt());
        let dag = self.dag();
        // Latest first: an honest acquire saw the creation sorted just before it, not the
        // backdated ones a member may have sorted first.
        list[..n]
            .iter()
            .rev()
            .any(|&c| self.marks.get(c) == Mark::Effective && dag.held_sees_at(reach, at, c))
    }

    /// Records the membership op `id` (asking for `m`) just delivered, if it counts: its
    /// author proves to be the founder with the nonce it shows, and it names another member.
    fn note_membership(&mut self, author: PeerId, id: OpId, m: Membership) {
        let Some(founder) = &self.founder else {
            return;
        };
        if m.member == author || !founder.is_founder(&author, &m.nonce) {
            return;
        }
        self.membership_ops
            .entry(m.member)
            .or_default()
            .push((id, m.expel));
        self.members_changed.insert(m.member);
    }

    /// Recomputes which ops of the members whose membership ops changed are void, and notes
    /// from which seq each member's changed ([`Refold::void_from`] of the next refold).
    fn update_expelled(&mut self) {
        for member in std::mem::take(&mut self.members_changed) {
            let last = self.last_counting_seq(&member);
            let old = self.expelled.get(&member).copied();
            if last == old {
                continue;
            }
            match last {
                Some(last) => self.expelled.insert(member, last),
                None => self.expelled.remove(&member),
            };
            // Ops after the lower of the two bounds changed sides.
            let from_seq = last.unwrap_or(u64::MAX).min(old.unwrap_or(u64::MAX)) + 1;
            let earliest = self.void_changed.entry(member).or_insert(from_seq);
            *earliest = (*earliest).min(from_seq);
        }
    }

    /// The last seq of `member`'s ops that still count: the fewest its expels saw, over the
    /// expels no readmit saw; `None` when no such expel is held.
    fn last_counting_seq(&mut self, member: &PeerId) -> Option<u64> {
        let ops = self.membership_ops.get(member)?;
        let mut reach = std::mem::take(&mut self.reach);
        let dag = self.dag();
        let mut chain = self.chain(member);
        if let Some(fork) = self.forks.seq_of(member) {
            // Past its fork a member's ops are rejected anyway, and its chain is no longer one
            // history: the ops that count end before it.
            let before = usize::try_from(fork.saturating_sub(1)).unwrap_or(usize::MAX);
            chain = &chain[..chain.len().min(before)];
        }
        let mut last: Option<u64> = None;
        for (expel, _) in ops.iter().filter(|(_, expel)| *expel) {
            let readmitted = ops
                .iter()
                .any(|(r, is_expel)| !is_expel && dag.sees(&mut reach, r, expel));
            if readmitted {
                continue;
            }
            let seen = dag.seen_prefix(&mut reach, expel, chain) as u64;
            last = Some(last.map_or(seen, |l| l.min(seen)));
        }
        self.reach = reach;
        last
    }

    /// Makes a fork just found or lowered hold: past it an op's causal past no longer runs
    /// through its author's previous op, so the reach memo starts afresh and the deletes from
    /// the fork's first op on learn again what they saw; a forked member's void ops are counted
    /// again, and the scene is told the author's ops changed from the fork on
    /// ([`Refold::void_from`]). Returns the position of the author's first op at or past its
    /// fork: verdicts from there on may change.
    fn note_forks(&mut self) -> Option<usize> {
        let mut first: Option<usize> = None;
        for author in std::mem::take(&mut self.forks_changed) {
            let Some(seq) = self.forks.seq_of(&author) else {
                continue;
            };
            let skip = usize::try_from(seq.saturating_sub(1)).unwrap_or(usize::MAX);
            let chain = self.chain(&author);
            let chain = chain.iter().skip(skip).map(|&at| self.ops.at(at).id_ref());
            let siblings = self.siblings.get(&author).map_or(&[][..], Vec::as_slice);
            for id in chain.chain(siblings) {
                if let Some(pos) = self.position(id) {
                    first = Some(first.map_or(pos, |f| f.min(pos)));
                }
            }
            if self.membership_ops.contains_key(&author) {
                self.members_changed.insert(author);
            }
            // Its ops the scene keeps outside objects (chat) are dropped from the fork on.
            let void_from = self.void_changed.entry(author).or_insert(seq);
            *void_from = (*void_from).min(seq);
        }
        self.reach = Reach::default();
        let from = self.order_key(first?);
        let deletes: Vec<(ObjectId, OpId, OrderKey)> = (self.deletes.iter())
            .flat_map(|(object, list)| list.iter().map(move |(k, id)| (*object, *id, *k)))
            .filter(|(_, id, k)| *k >= from && self.ops.contains_key(id))
            .collect();
        for (object, id, key) in deletes {
            let old = self.delete_hides.get(&id).cloned();
            self.note_delete(object, id, key);
            if self.delete_hides.get(&id) != old.as_ref()
                && let Some(pos) = self.position(&id)
            {
                self.hides_changed.push((object, pos));
            }
        }
        first
    }

    /// Records which held edits of `object` the delete `id` just delivered saw. Every edit in
    /// its causal past is delivered before it, so this never changes later.
    fn note_delete(&mut self, object: ObjectId, id: OpId, key: OrderKey) {
        let mut reach = std::mem::take(&mut self.reach);
        let held = self.held_edits(object);
        let before = &held[..point_near_end(held, |&a| self.slot_key(a) < key)];
        let dag = self.dag();
        let hides: Vec<OpId> = before
            .iter()
            .map(|&a| self.ops.at(a).id())
            .filter(|e| dag.sees(&mut reach, &id, e))
            .collect();
        self.reach = reach;
        self.delete_hides.insert(id, hides);
    }

    /// Re-evaluates marks from `from` to the end, starting at the nearest checkpoint (or at
    /// the current state, when everything changed lies after what was folded: the common case
    /// of ops arriving in order). The ops held at slab positions from `first_new` on are the
    /// insertion's own, reported whatever their marks.
    fn refold_from(&mut self, from: usize, first_new: usize) -> Refold {
        let (start, mut state) = if from >= self.n_folded {
            (self.n_folded, std::mem::take(&mut self.state))
        } else {
            // Checkpoints after `from` are stale (positions shifted); one may not exist yet.
            let start = self.refold_start(from);
            let k = start / CHECKPOINT_INTERVAL;
            self.checkpoints.truncate(k + 1);
            (start, self.checkpoints[k].clone())
        };
        self.stats.n_refolded += (self.order.len() - start) as u64;
        let mut refold = Refold {
            from,
            object_keys: ObjectKeys::default(),
            void_from: std::mem::take(&mut self.void_changed),
        };
        let mut cx = LeaseCx {
            reach: std::mem::take(&mut self.reach),
            learnt: None,
            alt: None,
        };
        // Marks at or after `from` were computed before the insertion (or are placeholders):
        // compare against the old verdicts to find the objects that changed.
        for pos in start..self.order.len() {
            if pos % CHECKPOINT_INTERVAL == 0 && pos / CHECKPOINT_INTERVAL == self.checkpoints.len()
            {
                self.checkpoints.push(state.clone());
            }
            // Read once for judging and reporting; from the slab's field, not through
            // `op_at`, so that the writes below may borrow the log's other fields.
            let op = self.ops.at(self.order[pos]);
            let (key, effect) = (OrderKey::of(op), op.payload().effect());
            let mark = self.judge_read(&mut cx, &mut state, pos, (op, key, effect));
            if let Some(learnt) = cx.learnt.take()
                && let Some(me) = (self.lease_ops.get_mut(&learnt.object))
                    .and_then(|list| list.get_mut(learnt.index))
            {
                (me.before, me.unseen) = (learnt.before, learnt.unseen);
            }
            if pos >= from {
                let at = self.order[pos];
                let old = self.marks.get(at);
                if old != mark || at as usize >= first_new {
                    self.report_change(&mut refold, effect, pos, key);
                }
                if old != mark {
                    self.marks.set(at, mark);
                }
            }
        }
        self.reach = cx.reach;
        self.state = state;
        self.n_folded = self.order.len();
        self.report_void_changes(&mut refold);
        for (object, pos) in std::mem::take(&mut self.hides_changed) {
            self.report_change(
                &mut refold,
                Effect::Edit { object },
                pos,
                self.order_key(pos),
            );
        }
        self.update_hidden(&mut refold);
        refold
    }

    /// Judges the op at `pos` (its order key and effect already read) against `state` (the
    /// fold of the positions before it) and advances the state past it.
    fn judge_read(
        &self,
        cx: &mut LeaseCx,
        state: &mut FoldState,
        pos: usize,
        (op, key, effect): (&Op<P>, OrderKey, Effect),
    ) -> Mark {
        let id = op.id_ref();
        if self.forks.covers(&op.author(), op.seq()) {
            // A lease op on the chain still notes the lease before it: later lease ops that
            // missed it fold from there.
            let on_chain = || {
                self.by_seq(&op.author(), op.seq())
                    .is_some_and(|o| o.id_ref() == id)
            };
            if matches!(effect, Effect::Acquire { .. } | Effect::Release { .. }) && on_chain() {
                self.lease_context(cx, state, (key, self.order[pos], effect), None);
            }
            return Mark::Rejected(RejectReason::Forked);
        }
        let target = self.target_info(effect, pos);
        let seen = self.lease_context(cx, state, (key, self.order[pos], effect), target);
        let (author, at) = (op.author(), op.timestamp());
        // Membership as this op's causal past has it: a member that saw its own expel is
        // refused, and nobody who saw an expel is bound by the expelled member's leases.
        let dag = self.dag();
        if !self.membership_ops.is_empty() && dag.expelled_in_past(&mut cx.reach, id, &author) {
            return Mark::Rejected(RejectReason::Expelled);
        }
        if let Effect::Acquire { object, .. } = effect
            && !self.created_in_past(&mut cx.reach, self.order[pos], &key, object)
        {
            return Mark::Rejected(RejectReason::UnknownObject);
        }
        if self.membership_ops.is_empty() {
            return state.apply(author, at, effect, target, seen);
        }
        let reach = &mut cx.reach;
        let mut exempt = |holder: &PeerId| dag.expelled_in_past(reach, id, holder);
        state.apply_exempting(author, at, effect, target, seen, &mut exempt)
    }

    /// Records in `refold` the objects of the ops that turned void or counted again
    /// ([`Refold::void_from`]): their activity changed, not their marks.
    fn report_void_changes(&self, refold: &mut Refold) {
        if refold.void_from.is_empty() {
            return;
        }
        for (member, from_seq) in refold.void_from.clone() {
            let member = &member;
            let skip = usize::try_from(from_seq.saturating_sub(1)).unwrap_or(usize::MAX);
            let chain = self.chain(member);
            for &at in chain.iter().skip(skip) {
                let op = self.ops.at(at);
                let Some(pos) = self.position(op.id_ref()) else {
                    continue;
                };
                refold.from = refold.from.min(pos);
                self.report_change(refold, op.payload().effect(), pos, OrderKey::of(op));
            }
        }
    }

    /// True if held op `id` is void: its author was expelled by an expel that did not see it
    /// ([`crate::membership`]). A void op keeps its mark (verdicts are judged on causal pasts,
    /// which an expel arriving later does not change) but is inactive: the scene does not fold
    /// it, and a void delete hides nothing.
    pub fn is_void(&self, id: &OpId) -> bool {
        if self.expelled.is_empty() {
            return false;
        }
        self.ops.get(id).is_some_and(|op| {
            (self.expelled.get(&op.author())).is_some_and(|last| op.seq() > *last)
        })
    }

    /// The authors that forked ([`crate::fork`]).
    pub fn forks(&self) -> &Forks {
        &self.forks
    }

    /// Records in `refold` the object whose fold the changed op at `pos` (order key `key`)
    /// affects.
    fn report_change(&self, refold: &mut Refold, effect: Effect, pos: usize, key: OrderKey) {
        let (object, at) = match effect {
            Effect::Independent => return,
            Effect::Edit { object }
            | Effect::Acquire { object, .. }
            | Effect::Release { object } => (object, pos),
            Effect::Undo { target } | Effect::Redo { target } => {
                match self.target_object(&target) {
                    Some((object, target_pos)) => (object, target_pos.min(pos)),
                    None => return,
                }
            }
        };
        // An undo or redo changes its target's activity, which may lie before `from`.
        refold.from = refold.from.min(at);
        let key = if at == pos { key } else { self.order_key(at) };
        refold.object_keys.lower(object, key);
    }

    /// The lease an op's causal past gives its object, when it missed some of the object's
    /// earlier lease ops (`None` when it saw them all: the fold's state is then its past's).
    /// Records, for a lease op, the prefix's lease before it and the lease ops it missed.
    fn lease_context(
        &self,
        cx: &mut LeaseCx,
        state: &FoldState,
        (key, at, effect): (OrderKey, u32, Effect),
        target: Option<TargetInfo>,
    ) -> Option<Option<Lease>> {
        let object = match effect {
            Effect::Edit { object }
            | Effect::Acquire { object, .. }
            | Effect::Release { object } => object,
            Effect::Undo { .. } | Effect::Redo { .. } => match target?.effect {
                Effect::Edit { object } => object,
                _ => return None,
            },
            Effect::Independent => return None,
        };
        let list = self.lease_ops.get(&object)?;
        let n = point_near_end(list, |l| l.key < key);
        let dag = self.dag();
        let unseen = seen::unseen_before(&dag, &mut cx.reach, list, n, at);
        let lease = (!unseen.is_empty()).then(|| {
            let alt = cx.alt.get_or_insert_with(seen::AltFolds::new);
            seen::lease_seen(&dag, &mut cx.reach, list, n, &unseen, alt, object)
        });
        if matches!(effect, Effect::Acquire { .. } | Effect::Release { .. }) {
            assert!(list[n].at == at, "a lease op is indexed under its object");
            let unseen = (unseen.len() <= MAX_UNSEEN_LEASE_OPS)
                .then(|| unseen.iter().map(|&(_, at)| at).collect());
            cx.learnt = Some(Learnt {
                object,
                index: n,
                before: state.lease(object),
                unseen,
            });
        }
        lease
    }

    /// Recomputes the hidden edits of every object `refold` names, and adds to it the objects
    /// whose hidden edits changed, from the first that did.
    fn update_hidden(&mut self, refold: &mut Refold) {
        if self.deletes.is_empty() && self.hidden.is_empty() {
            // No object has a delete or hidden edits: nothing to recompute.
            return;
        }
        let objects: BTreeSet<ObjectId> = refold
            .object_keys
            .keys()
            .copied()
            .filter(|o| self.deletes.contains_key(o) || self.hidden.contains_key(o))
            .collect();
        for object in objects {
            let now = self.hidden_of(object);
            let old = self.hidden.remove(&object).unwrap_or_default();
            for changed in now.symmetric_difference(&old) {
                if let Some(pos) = self.position(changed) {
                    refold.from = refold.from.min(pos);
                    refold.object_keys.lower(object, self.order_key(pos));
                }
            }
            if !now.is_empty() {
                self.hidden.insert(object, now);
            }
        }
    }

    /// The edits of `object` that an effective delete, not undone, saw.
    fn hidden_of(&self, object: ObjectId) -> BTreeSet<OpId> {
        let mut out = BTreeSet::new();
        for (_, d) in self.deletes.get(&object).into_iter().flatten() {
            if !self.is_effective(d) || self.state.is_undone(d) || self.is_void(d) {
                continue;
            }
            if let Some(hides) = self.delete_hides.get(d) {
                out.extend(hides.iter().copied());
            }
        }
        out
    }

    /// True if `id` is held and effective.
    fn is_effective(&self, id: &OpId) -> bool {
        self.mark(id) == Some(Mark::Effective)
    }

    /// True if `object` has a delete, effective or not.
    pub fn has_deletes(&self, object: ObjectId) -> bool {
        self.deletes.contains_key(&object)
    }

    /// True if an effective delete that is not undone saw edit `id` (see [`Payload::is_delete`]).
    pub fn is_hidden(&self, id: &OpId) -> bool {
        if self.hidden.is_empty() {
            return false;
        }
        let Some(Effect::Edit { object }) = self.get(id).map(|op| op.payload().effect()) else {
            return false;
        };
        self.hidden.get(&object).is_some_and(|h| h.contains(id))
    }

    fn position(&self, id: &OpId) -> Option<usize> {
        let at = self.ops.position(id)?;
        // Live ops are looked up right after they were appended.
        if self.order.last() == Some(&at) {
            return Some(self.order.len() - 1);
        }
        let entry = self.slot_entry(at);
        let pos = self.order.partition_point(|&a| self.slot_entry(a) < entry);
        (self.order.get(pos) == Some(&at)).then_some(pos)
    }

    /// The verdict on position `pos` of the linear order.
    fn mark_at(&self, pos: usize) -> Mark {
        self.marks.get(self.order[pos])
    }

    /// The op at position `pos` of the linear order.
    fn op_at(&self, pos: usize) -> &Op<P> {
        self.ops.at(self.order[pos])
    }

    /// The order key at position `pos` of the linear order.
    fn order_key(&self, pos: usize) -> OrderKey {
        OrderKey::of(self.op_at(pos))
    }

    /// The id of the op at position `pos` of the linear order.
    fn id_at(&self, pos: usize) -> OpId {
        self.op_at(pos).id()
    }

    /// The order key of the op the slab holds at `at`.
    fn slot_key(&self, at: u32) -> OrderKey {
        OrderKey::of(self.ops.at(at))
    }

    /// How the op the slab holds at `at` sorts against `key` ([`cmp_key`]).
    fn slot_cmp(&self, at: u32, key: &OrderKey) -> std::cmp::Ordering {
        cmp_key(self.ops.at(at), key)
    }

    /// What the linear order sorts the op the slab holds at `at` by.
    fn slot_entry(&self, at: u32) -> (OrderKey, OpId) {
        let op = self.ops.at(at);
        (OrderKey::of(op), op.id())
    }

    /// The position of the op with `key` on its author's chain (a sibling of a fork shares
    /// its key).
    fn position_of_key(&self, key: &OrderKey) -> Option<usize> {
        let n = self.order.len();
        if n > 0 && self.order_key(n - 1) == *key && (n < 2 || self.order_key(n - 2) != *key) {
            return Some(n - 1);
        }
        let at = self.order.partition_point(|&a| self.slot_key(a) < *key);
        let same = self.order[at..]
            .iter()
            .take_while(|&&a| self.slot_key(a) == *key)
            .count();
        match same {
            0 => None,
            1 => Some(at),
            _ => {
                let chain = self.by_seq(&key.author, key.seq)?.id();
                (at..at + same).find(|p| self.id_at(*p) == chain)
            }
        }
    }

    fn target_info(&self, effect: Effect, pos: usize) -> Option<TargetInfo> {
        let (Effect::Undo { target } | Effect::Redo { target }) = effect else {
            return None;
        };
        let target_pos = self.position(&target).filter(|p| *p < pos)?;
        let op = self.ops.get(&target)?;
        Some(TargetInfo {
            author: op.author(),
            effect: op.payload().effect(),
            mark: self.mark_at(target_pos),
        })
    }

    /// The object of edit `target` and its position.
    fn target_object(&self, target: &OpId) -> Option<(ObjectId, usize)> {
        let op = self.ops.get(target)?;
        match op.payload().effect() {
            Effect::Edit { object } => Some((object, self.position(target)?)),
            _ => None,
        }
    }
}

impl<P: Payload> Log<P> {
    /// Number of delivered ops.
    pub fn len(&self) -> usize {
        self.ops.len()
    }

    /// True if no op is delivered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// A delivered op by id.
    pub fn get(&self, id: &OpId) -> Option<&Op<P>> {
        self.ops.get(id)
    }

    /// True if `id` is delivered.
    pub fn contains(&self, id: &OpId) -> bool {
        self.ops.contains_key(id)
    }

    /// [`Log::contains`] for an op arriving, which is usually new: the slab's table is probed
    /// without comparing the latest ops first.
    fn contains_arriving(&self, id: &OpId) -> bool {
        self.ops.indexed_position(id).is_some()
    }

    /// The author's held op with sequence number `seq`.
    pub fn by_seq(&self, author: &PeerId, seq: u64) -> Option<&Op<P>> {
        Some(self.ops.at(self.authors.get(author)?.at_seq(seq)?))
    }

    /// What this log holds, per author.
    pub fn version_vector(&self) -> &VersionVector {
        &self.vv
    }

    /// The DAG's heads: what a new local op depends on.
    pub fn heads(&self) -> impl Iterator<Item = &OpId> {
        self.frontier.heads()
    }

    /// Number of ops waiting on dependencies.
    pub fn n_pending(&self) -> usize {
        self.pending.len()
    }

    /// Number of ops waiting that came from `origin`.
    pub fn n_pending_from(&self, origin: Origin) -> usize {
        self.pending.n_from(origin)
    }

    /// Dependencies by id that ops from `origin` waiting since `before` still miss
    /// ([`Pending::stuck_deps`]), at most `max`, none of them held or waiting.
    pub fn stuck_deps(&self, origin: Origin, before: Timestamp, max: usize) -> Vec<OpId> {
        let mut stuck = self.pending.stuck_deps(origin, before, max);
        stuck.retain(|id| !self.contains(id));
        stuck
    }

    /// What was refused or evicted so far.
    pub fn stats(&self) -> LogStats {
        self.stats
    }

    /// The linear order with every op's mark and whether the scene folds it.
    pub fn entries(&self) -> impl Iterator<Item = Entry<'_, P>> {
        self.order.iter().map(|&at| self.entry_of(at))
    }

    /// The entry of the op the slab holds at `at`.
    fn entry_of(&self, at: u32) -> Entry<'_, P> {
        let op = self.ops.at(at);
        let (id, mark) = (op.id_ref(), self.marks.get(at));
        Entry {
            op,
            mark,
            active: mark == Mark::Effective
                && !self.state.is_undone(id)
                && !self.is_hidden(id)
                && !self.is_void(id),
        }
    }

    /// The order key at held position `pos`.
    pub fn key_at(&self, pos: usize) -> Option<OrderKey> {
        self.order.get(pos).map(|&at| self.slot_key(at))
    }

    /// The held entry with order key `key`.
    pub fn entry_at_key(&self, key: &OrderKey) -> Option<Entry<'_, P>> {
        let pos = self.position_of_key(key)?;
        Some(self.entry_of(self.order[pos]))
    }

    /// `object`'s held edits (ops whose effect is an edit of it) with their order keys, in
    /// linear order, active or not: all of them, or those from key `from` on.
    pub fn object_edits(
        &self,
        object: ObjectId,
        from: Option<&OrderKey>,
    ) -> impl Iterator<Item = (OrderKey, Entry<'_, P>)> {
        let held = self.held_edits(object);
        // A fold continuing after ops that arrived in order starts at or near the end.
        let start = from.map_or(0, |from| {
            point_near_end(held, |&a| self.slot_key(a) < *from)
        });
        (held[start..].iter()).map(|&at| (self.slot_key(at), self.entry_of(at)))
    }

    /// How many edits of `object` are held.
    pub fn n_object_edits(&self, object: ObjectId) -> usize {
        self.held_edits(object).len()
    }

    /// `object`'s held edits in linear order, as positions in `ops`.
    fn held_edits(&self, object: ObjectId) -> &[u32] {
        self.by_object.get(&object).map_or(&[], Vec::as_slice)
    }

    /// The lease and undo state after every delivered op.
    pub fn fold_state(&self) -> &FoldState {
        &self.state
    }

    /// Op ids in the linear order.
    pub fn linear_ids(&self) -> impl Iterator<Item = OpId> + '_ {
        self.order.iter().map(|&at| self.ops.at(at).id())
    }

    /// Ops with Lamport time `lamport` or more, in linear order; used to stream what a
    /// remote lacks.
    pub(crate) fn ops_from_lamport(&self, lamport: u64) -> impl Iterator<Item = &Op<P>> {
        let start = (self.order).partition_point(|&at| self.ops.at(at).lamport() < lamport);
        self.order[start..].iter().map(|&at| self.ops.at(at))
    }

    /// The verdict on a delivered op.
    pub fn mark(&self, id: &OpId) -> Option<Mark> {
        self.ops.position(id).map(|at| self.marks.get(at))
    }

    /// True if the op is effective, not undone and not hidden by a delete that saw it.
    pub fn is_active(&self, id: &OpId) -> bool {
        self.is_effective(id)
            && !self.state.is_undone(id)
            && !self.is_hidden(id)
            && !self.is_void(id)
    }

    /// The author's rejected ops in linear order, with reasons, so their work can be re-applied.
    pub fn rejected_by(&self, author: &PeerId) -> Vec<(OpId, RejectReason)> {
        (0..self.order.len())
            .filter(|&pos| self.op_at(pos).author() == *author)
            .filter_map(|pos| match self.mark_at(pos) {
                Mark::Rejected(reason) => Some((self.id_at(pos), reason)),
                Mark::Effective => None,
            })
            .collect()
    }

    /// The lease on `object` that holds at `now`, after every delivered op.
    pub fn lease(&self, object: ObjectId, now: Timestamp) -> Option<Lease> {
        self.state.lease(object).filter(|l| l.holds_at(now))
    }
}

/// `list.partition_point(pred)`, looking at the end first: ops mostly arrive in order, so the
/// point is usually the end, or just before the last entry (the op itself, once indexed).
fn point_near_end<T>(list: &[T], pred: impl Fn(&T) -> bool) -> usize {
    match list {
        [] => 0,
        [.., last] if pred(last) => list.len(),
        [.., before, _] if pred(before) => list.len() - 1,
        _ => list.partition_point(pred),
    }
}

/// How `op` sorts against `key` in the linear order. Lamport times differ in most
/// comparisons and decide them without the op's author, which is read from its encoding
/// (another cache line) to build its whole key.
fn cmp_key<P>(op: &Op<P>, key: &OrderKey) -> std::cmp::Ordering {
    match op.lamport().cmp(&key.lamport) {
        std::cmp::Ordering::Equal => OrderKey::of(op).cmp(key),
        unequal => unequal,
    }
}

/// Inserts `item` into the sorted list `map` holds under `key`, at the first place where
/// `before` does not hold ([`point_near_end`]). A key already there, the usual case, is found
/// by one search, without an entry (which takes the key by value and costs more).
fn insert_in_list<K: Ord, T>(
    map: &mut BTreeMap<K, Vec<T>>,
    key: K,
    item: T,
    before: impl Fn(&T) -> bool,
) {
    match map.get_mut(&key) {
        Some(list) => {
            let i = point_near_end(list, before);
            list.insert(i, item);
        }
        // Grown from empty, not made to measure: the list's next item does not reallocate.
        None => map.entry(key).or_default().push(item),
    }
}

#[cfg(test)]
pub(crate) mod tests;
