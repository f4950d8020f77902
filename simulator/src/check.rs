//! The checkers, run once the network is quiet: every honest peer against the rules, against
//! its own history and against peer 0 (the reference, which never joins late).

use replication::Log;
use replication::log::OrderKey;
use replication::materialize::{FoldEntry, Materialize, SceneHash};
use replication::shape::{ShapePayload, ShapeScene};
use replication::sync::state::MAX_MESSAGE_BURST;
use std::collections::{BTreeMap, BTreeSet};

use replication::{Mark, Op, OpId, Payload, PeerId, RejectReason};

use crate::config::{Config, Faults, Sabotage};
use crate::honest::{Honest, Scene};
use crate::hostile::Hostile;
use crate::memory;
use crate::reference;
use crate::report::{Memory, OpKindBytes, Report, Sample, Stats, short_hash};

/// Heap bytes a peer may hold besides its ops: twice the pending buffer's byte limit (its
/// encoded ops plus their decoded form), plus room for connections and an empty scene.
pub const MAX_MEMORY_FIXED_BYTES: i64 = 2 * replication::pending::MAX_PENDING_BYTES as i64;
/// Heap bytes a peer may hold per op in its log (op, order, marks, indexes, its share of the
/// scene), at its peak. Campaigns measure about 2.3 KiB; this leaves a factor of 7.
pub const MAX_MEMORY_BYTES_PER_OP: i64 = 16 * 1024;

/// How long after healing the network may take to go quiet before the run counts as stuck.
pub const QUIESCENCE_LIMIT_MICROS: u64 = 600_000_000;

/// What a run ended with, which the checkers judge.
pub(crate) struct Ended {
    pub(crate) config: Config,
    pub(crate) faults: Faults,
    pub(crate) honest: Vec<Honest>,
    pub(crate) hostile: Option<Hostile>,
    pub(crate) stats: Stats,
    pub(crate) trace_hash: u64,
    /// One-way base latency per directed link, `[from][to]`.
    pub(crate) latency_micros: Vec<Vec<u64>>,
    /// Virtual time of healing, since the start.
    pub(crate) heal_micros: u64,
    /// Virtual time of the last op delivered anywhere, since the start.
    pub(crate) last_delivery_micros: u64,
    /// Virtual time the run ended, since the start.
    pub(crate) end_micros: u64,
    /// The network did not go quiet within [`QUIESCENCE_LIMIT_MICROS`] of healing (or the
    /// run handled too many events).
    pub(crate) timed_out: bool,
    /// What went wrong at restarts and joins.
    pub(crate) restart_failures: Vec<String>,
    /// Ops some peer synced to disk (acknowledged as durable).
    pub(crate) durable: BTreeSet<OpId>,
    /// Own ops a crash lost before they were synced.
    pub(crate) lost_own: BTreeSet<OpId>,
    /// Per flood: (messages delivered, messages accepted).
    pub(crate) floods: Vec<(u64, u64)>,
    pub(crate) samples: Vec<Sample>,
}

/// Runs every checker and builds the report.
pub(crate) fn finish(end: Ended) -> Report {
    let mut failures = Vec::new();
    if end.timed_out {
        failures.push(format!(
            "no quiescence within {} s of virtual time after healing",
            QUIESCENCE_LIMIT_MICROS / 1_000_000
        ));
    }
    failures.extend(end.restart_failures.iter().cloned());
    if end.stats.n_author_errors > 0 {
        // A user's edit the core would not author is an edit lost.
        failures.push(format!(
            "the core refused {} user ops: {:?}",
            end.stats.n_author_errors, end.stats.author_errors
        ));
    }
    let (reference_hash, n_lease_checked) = check_peers(&end, &mut failures);
    check_floods(&end, &mut failures);
    if end.hostile.as_ref().is_some_and(|h| h.byzantine.is_some()) {
        check_erasure(&end, &mut failures);
        check_stolen_ids(&end, &mut failures);
        check_creations(&end, &mut failures);
    }
    check_cap(&end, &mut failures);
    if end.faults.expel {
        check_expels(&end, &mut failures);
    }
    check_forks(&end, &mut failures);
    let memory = memory_figures(&end, &mut failures);
    build_report(end, failures, reference_hash, memory, n_lease_checked)
}

/// Checks every honest peer on its own (history, refused ops, lease verdicts, fresh fold) and
/// against the first one checked; returns that one's scene hash and the verdicts checked.
fn check_peers(end: &Ended, failures: &mut Vec<String>) -> (Option<SceneHash>, usize) {
    let all_authored: Vec<OpId> = end
        .honest
        .iter()
        .flat_map(|h| h.authored.iter().copied())
        .collect();
    let forged: Vec<OpId> = end
        .hostile
        .as_ref()
        .map_or(Vec::new(), |h| h.forged.clone());
    let must_refuse: Vec<OpId> = end
        .hostile
        .as_ref()
        .and_then(|h| h.byzantine.as_ref())
        .map_or(Vec::new(), |b| b.must_refuse.clone());
    let mut reference_hash = None;
    let mut n_lease_checked = 0;
    for (i, h) in end.honest.iter().enumerate() {
        if let Some(p) = &h.panicked {
            failures.push(format!("peer {i} panicked: {p}"));
            continue;
        }
        check_history(end, i, h, &all_authored, &forged, failures);
        let refused = must_refuse.iter().filter(|id| h.peer.log().contains(id));
        let n_refused = refused.count();
        if n_refused > 0 {
            failures.push(format!(
                "peer {i}: {n_refused} hostile ops accepted that are stamped before their \
                 causal past or signed for another session"
            ));
        }
        let flip = end.config.sabotage == Sabotage::FlipLeaseVerdict && i == 0;
        let lease = reference::check(h.peer.log(), flip);
        n_lease_checked += lease.n_checked;
        if lease.n_mismatches > 0 {
            failures.push(format!(
                "peer {i}: {} lease/undo verdicts differ from the reference rules: {}",
                lease.n_mismatches,
                lease.mismatches.join("; ")
            ));
        }
        let fresh = fresh_hash(end, i, h, failures);
        match reference_hash {
            None => reference_hash = Some((i, fresh)),
            Some((r, hash)) => {
                compare(&end.honest[r], r, h, i, failures);
                if hash != fresh {
                    failures.push(format!(
                        "peer {i}: scene hash {} differs from peer {r}'s {}",
                        short_hash(&fresh),
                        short_hash(&hash)
                    ));
                }
            }
        }
    }
    (reference_hash.map(|(_, h)| h), n_lease_checked)
}

/// Only the founder's expels counted: no honest peer is expelled anywhere, and every member
/// peer 0 holds as expelled is expelled on every honest peer, up to the same seq, with every op
/// of it after that seq void and inactive (the reference checks the verdicts).
fn check_expels(end: &Ended, failures: &mut Vec<String>) {
    let honest: BTreeSet<PeerId> = end.honest.iter().map(|h| h.peer.peer_id()).collect();
    let founders = end.honest[0].peer.log().expelled();
    for (i, h) in end.honest.iter().enumerate() {
        if h.panicked.is_some() {
            continue;
        }
        let log = h.peer.log();
        let wrongly: Vec<String> = (log.expelled().keys())
            .filter(|p| honest.contains(p))
            .map(PeerId::short)
            .collect();
        if !wrongly.is_empty() {
            failures.push(format!("peer {i}: honest peers {wrongly:?} expelled"));
        }
        if log.expelled() != founders {
            failures.push(format!(
                "peer {i}: expelled {:?}, peer 0 {:?}",
                log.expelled(),
                founders
            ));
        }
        let counted = log
            .entries()
            .filter(|e| {
                founders
                    .get(&e.op.author())
                    .is_some_and(|last| e.op.seq() > *last)
            })
            .filter(|e| e.active || !log.is_void(&e.op.id()))
            .count();
        if counted > 0 {
            failures.push(format!(
                "peer {i}: {counted} ops of expelled members not void"
            ));
        }
    }
}

/// Every fork the byzantine member made that honest peers built on both sides of is known to
/// every honest peer holding an op of its key (the holder of one side got the other, by a
/// have's tip or by asking for it by id, and passed both on). `compare` requires the same
/// forks everywhere besides.
fn check_forks(end: &Ended, failures: &mut Vec<String>) {
    let forks = (end.hostile.as_ref())
        .and_then(|h| h.byzantine.as_ref())
        .map_or(&[][..], |b| &b.forks[..]);
    for (a, b) in forks {
        let author = (end.honest.iter())
            .find_map(|h| h.peer.log().get(a).or_else(|| h.peer.log().get(b)))
            .map(replication::Op::author);
        let Some(author) = author else {
            continue;
        };
        // Only when honest peers built on both sides does anyone need the other side (an
        // honest op waits for it, and is asked for it by id); else nobody sees both.
        let built_on = |side: &OpId| {
            end.honest.iter().any(|h| {
                let me = h.peer.peer_id();
                (h.peer.log().entries()).any(|e| e.op.author() == me && e.op.deps().contains(side))
            })
        };
        if !(built_on(a) && built_on(b)) {
            continue;
        }
        for (i, h) in end.honest.iter().enumerate() {
            let log = h.peer.log();
            if log.version_vector().get(&author) > 0 && !log.forks().contains(&author) {
                failures.push(format!(
                    "peer {i}: holds ops of {}, which forked, and no proof of it",
                    author.short()
                ));
            }
        }
    }
}

/// No honest scene holds an object the byzantine member created under an honest peer's id.
fn check_stolen_ids(end: &Ended, failures: &mut Vec<String>) {
    for (i, h) in end.honest.iter().enumerate() {
        let stolen = (h.scene.scene().scene().objects())
            .filter(|(_, o)| o.object.data().name == crate::byzantine::STOLEN_NAME)
            .count();
        if stolen > 0 {
            failures.push(format!(
                "peer {i}: {stolen} objects created by a member under another peer's id"
            ));
        }
    }
}

/// No honest creation of an object under its own id is refused: nobody's lease counts on an
/// object before its creation (the byzantine member strongly acquires the ids honest users
/// take next).
fn check_creations(end: &Ended, failures: &mut Vec<String>) {
    let honest: BTreeSet<PeerId> = end.honest.iter().map(|h| h.peer.peer_id()).collect();
    for (i, h) in end.honest.iter().enumerate() {
        let refused = (h.peer.log().entries())
            .filter(|e| honest.contains(&e.op.author()) && e.mark != Mark::Effective)
            .filter(|e| {
                matches!(
                    e.op.payload(),
                    ShapePayload::Create {
                        counter: Some(_),
                        ..
                    }
                )
            })
            .count();
        if refused > 0 {
            failures.push(format!(
                "peer {i}: {refused} honest creations of their own ids refused"
            ));
        }
    }
}

/// In a session that binds its authors, no honest log holds more bytes of ops than the
/// session's cap, whatever the members and their Sybil keys write.
fn check_cap(end: &Ended, failures: &mut Vec<String>) {
    for (i, h) in end.honest.iter().enumerate() {
        let log = h.peer.log();
        if let Some(cap) = log.founder_budget()
            && log.n_bytes() > cap
        {
            failures.push(format!(
                "peer {i}: {} bytes of ops, over the session's cap of {cap}",
                log.n_bytes()
            ));
        }
    }
}

/// Per-peer history: panics, causal order, pending, authored and durable ops present, ops
/// lost before they were synced and forged ops absent.
fn check_history(
    end: &Ended,
    i: usize,
    h: &Honest,
    all_authored: &[OpId],
    forged: &[OpId],
    failures: &mut Vec<String>,
) {
    if h.n_causal_violations > 0 {
        failures.push(format!(
            "peer {i}: {} ops delivered before their dependencies",
            h.n_causal_violations
        ));
    }
    let log = h.peer.log();
    if log.n_pending() > 0 {
        failures.push(format!("peer {i}: {} ops still pending", log.n_pending()));
    }
    let count = |ids: &mut dyn Iterator<Item = &OpId>, present: bool| {
        ids.filter(|id| log.contains(id) == present).count()
    };
    let checks = [
        (
            count(&mut all_authored.iter(), false),
            "authored ops missing",
        ),
        (
            // Past its author's fork an op counts for nothing, and a side nobody built on need
            // not reach every peer.
            count(
                &mut end.durable.iter().filter(|id| !past_fork(end, log, id)),
                false,
            ),
            "ops missing that a peer had synced to disk",
        ),
        (
            count(&mut end.lost_own.iter(), true),
            "ops present that their author lost unsynced in a crash (sent before durable)",
        ),
        (count(&mut forged.iter(), true), "forged ops accepted"),
    ];
    for (n, what) in checks {
        if n > 0 {
            failures.push(format!("peer {i}: {n} {what}"));
        }
    }
}

/// True if `id`, held by some honest peer, is at or past its author's fork as `log` knows it.
fn past_fork(end: &Ended, log: &Log<ShapePayload>, id: &OpId) -> bool {
    let op = end.honest.iter().find_map(|h| h.peer.log().get(id));
    op.is_some_and(|op| log.forks().covers(&op.author(), op.seq()))
}

/// A fresh fold of the peer's log, compared with its incremental scene.
fn fresh_hash(end: &Ended, i: usize, h: &Honest, failures: &mut Vec<String>) -> SceneHash {
    let log = h.peer.log();
    let fresh = if end.config.sabotage == Sabotage::ReverseFold && i == 1 {
        reversed_fold_hash(log)
    } else {
        memory::with_slot(0, || Scene::fold(log).scene_hash())
    };
    if h.scene.scene_hash() != fresh {
        failures.push(format!(
            "peer {i}: incremental scene {} differs from a fresh fold {}",
            short_hash(&h.scene.scene_hash()),
            short_hash(&fresh)
        ));
    }
    fresh
}

/// Peer `i` against the reference `r`: version vectors, linear order and activity.
fn compare(reference: &Honest, r: usize, h: &Honest, i: usize, failures: &mut Vec<String>) {
    let (rlog, log) = (reference.peer.log(), h.peer.log());
    if rlog.version_vector() != log.version_vector() {
        failures.push(format!(
            "peer {i}: version vector ({} ops) differs from peer {r}'s ({} ops)",
            log.version_vector().n_ops(),
            rlog.version_vector().n_ops()
        ));
        return;
    }
    let forks = |l: &Log<ShapePayload>| l.forks().authors().collect::<Vec<_>>();
    if forks(rlog) != forks(log) {
        failures.push(format!("peer {i}: forks differ from peer {r}'s"));
        return;
    }
    // Of a forked author's ops past its fork (all rejected), a peer may hold a side nobody
    // built on that another lacks: they are left out.
    let counts = |e: &replication::log::Entry<'_, ShapePayload>| {
        e.mark != Mark::Rejected(RejectReason::Forked)
    };
    let expected = rlog.entries().filter(counts).map(|e| (e.op.id(), e.active));
    let actual = log.entries().filter(counts).map(|e| (e.op.id(), e.active));
    let (expected, actual): (Vec<_>, Vec<_>) = (expected.collect(), actual.collect());
    let ids = |v: &[(OpId, bool)]| v.iter().map(|x| x.0).collect::<Vec<_>>();
    if ids(&expected) != ids(&actual) {
        failures.push(format!("peer {i}: linear order differs from peer {r}'s"));
    } else if expected != actual {
        failures.push(format!(
            "peer {i}: lease/undo verdicts differ from peer {r}'s"
        ));
    }
}

/// Who erased an honest op.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
enum Culprit {
    /// A lease of a hostile member's key.
    HostileLease,
    /// A delete by a hostile member's key.
    HostileDelete,
    /// A concurrent lease of an honest peer.
    HonestLease,
    /// A concurrent delete by an honest peer.
    HonestDelete,
    /// Any other verdict (a release after a takeover, an undo made void, an op inactive
    /// without its own undo).
    Other,
}

impl Culprit {
    fn by_hostile(self) -> bool {
        matches!(self, Culprit::HostileLease | Culprit::HostileDelete)
    }
}

/// No honest op that was effective at its author's peer is, at the end on any honest peer,
/// rejected, inactive or deleted by an op that did not have it in its causal past: it may be
/// inactive only through its author's undo or a delete of its object, either having it in its
/// causal past. A verdict
/// depends only on the ops before it in the linear order, and those never have it in their
/// causal past (Lamport times grow along it), so an effective op must stay effective, may be
/// inactive only through an undo that has it in its causal past (its author's), and its object
/// may be deleted only by a delete that has its creation in its causal past.
fn check_erasure(end: &Ended, failures: &mut Vec<String>) {
    let honest_ids: BTreeSet<PeerId> = end.honest.iter().map(|h| h.peer.peer_id()).collect();
    let checked: Vec<OpId> = end
        .honest
        .iter()
        .flat_map(|h| h.effective_at_author.iter().copied())
        .filter(|id| !end.lost_own.contains(id))
        .collect();
    for (i, h) in end.honest.iter().enumerate() {
        if h.panicked.is_some() {
            continue;
        }
        let log = h.peer.log();
        let (deletes, position) = standing_deletes(log);
        let mut found: Vec<(Culprit, String)> = Vec::new();
        for id in &checked {
            let (Some(mark), Some(op)) = (log.mark(id), log.get(id)) else {
                continue;
            };
            let at = position.get(id).copied().unwrap_or(0);
            if let Some(culprit) = culprit(log, op, mark, at, &deletes, &honest_ids) {
                found.push((culprit, format!("op {id} by {}: {mark:?}", op.author())));
            }
        }
        note_erasures(i, &found, failures);
    }
}

/// Effective deletes not undone, per object, with their positions in the linear order.
type Deletes<'a> = BTreeMap<u64, Vec<(usize, &'a Op<ShapePayload>)>>;

/// The standing deletes of `log`, and the position of every op in its linear order.
fn standing_deletes(log: &Log<ShapePayload>) -> (Deletes<'_>, BTreeMap<OpId, usize>) {
    let mut deletes: Deletes<'_> = BTreeMap::new();
    let mut position = BTreeMap::new();
    for (pos, e) in log.entries().enumerate() {
        position.insert(e.op.id(), pos);
        if let ShapePayload::Delete { object } = e.op.payload()
            && e.mark == Mark::Effective
            && !log.fold_state().is_undone(&e.op.id())
        {
            deletes.entry(*object).or_default().push((pos, e.op));
        }
    }
    (deletes, position)
}

/// What erased `op` (marked `mark`, at position `at` of `log`'s order), effective at its
/// author's peer, if something did.
fn culprit(
    log: &Log<ShapePayload>,
    op: &Op<ShapePayload>,
    mark: Mark,
    at: usize,
    deletes: &Deletes<'_>,
    honest_ids: &BTreeSet<PeerId>,
) -> Option<Culprit> {
    let honest = |author: &PeerId| honest_ids.contains(author);
    let verdict = match mark {
        Mark::Rejected(
            RejectReason::LeaseHeld { holder } | RejectReason::StrongLeaseHeld { holder },
        ) => Some(if honest(&holder) {
            Culprit::HonestLease
        } else {
            Culprit::HostileLease
        }),
        Mark::Rejected(_) => Some(Culprit::Other),
        Mark::Effective
            if !log.is_active(&op.id())
                && !undone_by_successor(log, op)
                && !deleted_by_successor(log, op) =>
        {
            Some(Culprit::Other)
        }
        Mark::Effective => None,
    };
    // An inactive edit with a delete of its object after it that never saw it: blame that
    // delete.
    let object = edited_object(op.payload());
    let erasing = deletes
        .get(&object.unwrap_or(u64::MAX))
        .into_iter()
        .flatten()
        .find(|(pos, d)| *pos > at && !in_causal_past(log, d, op));
    match (verdict, erasing) {
        (Some(Culprit::Other), Some((_, d))) if honest(&d.author()) => Some(Culprit::HonestDelete),
        (Some(Culprit::Other), Some(_)) => Some(Culprit::HostileDelete),
        (verdict, _) => verdict,
    }
}

/// Reports the erasures `found` on peer `i`, by hostile members and by honest peers.
fn note_erasures(i: usize, found: &[(Culprit, String)], failures: &mut Vec<String>) {
    for hostile in [true, false] {
        let mine: Vec<&(Culprit, String)> = found
            .iter()
            .filter(|(c, _)| c.by_hostile() == hostile)
            .collect();
        let Some((_, first)) = mine.first() else {
            continue;
        };
        let mut kinds: BTreeMap<Culprit, usize> = BTreeMap::new();
        for (c, _) in &mine {
            *kinds.entry(*c).or_default() += 1;
        }
        let by = if hostile {
            "hostile members' ops"
        } else {
            "honest peers' concurrent ops (or other verdicts)"
        };
        failures.push(format!(
            "peer {i}: {} honest ops effective at their authors erased by {by} without them \
             in their causal past {kinds:?}; first: {first}",
            mine.len()
        ));
    }
}

/// The object an edit changes (`None` for other ops).
fn edited_object(payload: &ShapePayload) -> Option<u64> {
    match payload {
        ShapePayload::Create { object, .. }
        | ShapePayload::Delete { object }
        | ShapePayload::Set { object, .. }
        | ShapePayload::Edit { object, .. }
        | ShapePayload::Move { object, .. } => Some(*object),
        _ => None,
    }
}

/// True if an effective delete of `target`'s object, not undone, has it in its causal past
/// (a delete removes what it saw, and only that).
fn deleted_by_successor(log: &Log<ShapePayload>, target: &Op<ShapePayload>) -> bool {
    let Some(object) = edited_object(target.payload()) else {
        return false;
    };
    log.entries().any(|e| {
        e.mark == Mark::Effective
            && matches!(e.op.payload(), ShapePayload::Delete { object: o } if *o == object)
            && !log.fold_state().is_undone(&e.op.id())
            && in_causal_past(log, e.op, target)
    })
}

/// True if an effective undo of `target` in `log` has it in its causal past.
fn undone_by_successor(log: &Log<ShapePayload>, target: &Op<ShapePayload>) -> bool {
    log.entries().any(|e| {
        e.mark == Mark::Effective
            && matches!(e.op.payload(), ShapePayload::Undo(t) if *t == target.id())
            && in_causal_past(log, e.op, target)
    })
}

/// True if `target` is in `op`'s causal past: reachable through dependencies and each
/// author's previous op (sequence numbers chain an author's ops).
fn in_causal_past(
    log: &Log<ShapePayload>,
    op: &Op<ShapePayload>,
    target: &Op<ShapePayload>,
) -> bool {
    let parents = |op: &Op<ShapePayload>| {
        let prev = op
            .seq()
            .checked_sub(1)
            .and_then(|s| log.by_seq(&op.author(), s))
            .map(Op::id);
        op.deps().iter().copied().chain(prev).collect::<Vec<_>>()
    };
    let mut seen = BTreeSet::new();
    let mut stack = parents(op);
    while let Some(id) = stack.pop() {
        if id == target.id() {
            return true;
        }
        if !seen.insert(id) {
            continue;
        }
        // Ancestors have lower Lamport times: below the target's, it cannot be reached.
        if let Some(p) = log.get(&id)
            && p.lamport() > target.lamport()
        {
            stack.extend(parents(p));
        }
    }
    false
}

/// The rate limit held: no flood got more than a burst's worth of messages accepted.
fn check_floods(end: &Ended, failures: &mut Vec<String>) {
    for (f, (delivered, accepted)) in end.floods.iter().enumerate() {
        if *accepted > MAX_MESSAGE_BURST {
            failures.push(format!(
                "flood {f}: {accepted} of {delivered} messages accepted at one instant, over \
                 the burst limit {MAX_MESSAGE_BURST}"
            ));
        }
    }
}

/// Memory per peer, checked against the named bounds (only with the counting allocator).
fn memory_figures(end: &Ended, failures: &mut Vec<String>) -> Option<Memory> {
    if !memory::installed() || end.honest.is_empty() {
        return None;
    }
    let n = end.honest.len() as f64;
    let mut m = Memory {
        peak_bytes_max: 0,
        peak_bytes_mean: 0.0,
        final_bytes_mean: 0.0,
        peak_bytes_per_op_max: 0.0,
        final_bytes_per_op_mean: 0.0,
    };
    for (i, h) in end.honest.iter().enumerate() {
        let n_ops = h.peer.log().len().max(1) as i64;
        let (peak, last) = (h.peak_live_bytes, h.live_bytes());
        m.peak_bytes_max = m.peak_bytes_max.max(peak);
        m.peak_bytes_mean += peak as f64 / n;
        m.final_bytes_mean += last as f64 / n;
        m.peak_bytes_per_op_max = m.peak_bytes_per_op_max.max(peak as f64 / n_ops as f64);
        m.final_bytes_per_op_mean += last as f64 / n_ops as f64 / n;
        let bound = MAX_MEMORY_FIXED_BYTES + MAX_MEMORY_BYTES_PER_OP * n_ops;
        if peak > bound {
            failures.push(format!(
                "peer {i}: held {peak} heap bytes at its peak, over the bound {bound} \
                 ({MAX_MEMORY_FIXED_BYTES} + {MAX_MEMORY_BYTES_PER_OP} per op for {n_ops} ops)"
            ));
        }
    }
    Some(m)
}

fn build_report(
    end: Ended,
    failures: Vec<String>,
    scene_hash: Option<SceneHash>,
    memory: Option<Memory>,
    n_lease_verdicts_checked: usize,
) -> Report {
    let log0 = end.honest.first().map(|h| h.peer.log());
    let n_hostile_ops_accepted = match (&end.hostile, log0) {
        (Some(hostile), Some(log)) => hostile.own_ids.iter().filter(|id| log.contains(id)).count(),
        _ => 0,
    };
    let n_lease_rejected = log0.map_or(0, |l| reference::check(l, false).n_rejected);
    let mean_latency = mean_latency_micros(&end.latency_micros, end.config.n_peers);
    Report {
        n_log_ops: log0.map_or(0, Log::len),
        op_bytes: log0.map_or(Vec::new(), op_bytes),
        scene_hash,
        convergence_micros: end.last_delivery_micros.saturating_sub(end.heal_micros),
        mean_rtt_micros: 2 * mean_latency + end.faults.jitter_micros,
        virtual_end_micros: end.end_micros,
        heal_micros: end.heal_micros,
        trace_hash: end.trace_hash,
        memory,
        n_lease_verdicts_checked,
        n_lease_rejected,
        n_durable_ops: end.durable.len(),
        n_lost_own_ops: end.lost_own.len(),
        n_hostile_ops_accepted,
        n_flood_accepted_max: end.floods.iter().map(|f| f.1).max().unwrap_or(0),
        n_refold_holds: (end.honest.iter())
            .map(|h| h.peer.log().stats().n_held_for_refold)
            .sum(),
        n_void_ops: (end.honest[0].peer.log().entries())
            .filter(|e| end.honest[0].peer.log().is_void(&e.op.id()))
            .count(),
        session_bytes: (log0.and_then(Log::founder_budget)).zip(log0.map(Log::n_bytes)),
        catch_up: end.honest.iter().map(|h| h.catch_up).collect(),
        failures,
        samples: end.samples,
        stats: end.stats,
        config: end.config,
    }
}

/// What the user did, from the payload.
fn kind(p: &ShapePayload) -> &'static str {
    use model::object::{ColorDef, Field};
    match p {
        ShapePayload::Create { .. } => "create (geometry formula)",
        ShapePayload::Set { field, .. } => match **field {
            Field::Diffuse(Some(ColorDef::Rgb(_))) => "set colour formula",
            Field::Geometry(_) => "set geometry formula",
            _ => "set constant",
        },
        ShapePayload::Edit { .. } => "tool edit",
        ShapePayload::Undo(_) | ShapePayload::Redo(_) => "undo",
        ShapePayload::Chat(_) => "chat",
        ShapePayload::Lease(_) => "lease",
        _ => "other",
    }
}

/// Op sizes by kind in `log`.
fn op_bytes(log: &Log<ShapePayload>) -> Vec<OpKindBytes> {
    let mut out: Vec<OpKindBytes> = Vec::new();
    let mut payload = Vec::new();
    for e in log.entries() {
        let k = kind(e.op.payload());
        payload.clear();
        e.op.payload().encode(&mut payload);
        let at = match out.iter().position(|x| x.kind == k) {
            Some(at) => at,
            None => {
                out.push(OpKindBytes {
                    kind: k,
                    n_ops: 0,
                    n_op_bytes: 0,
                    n_payload_bytes: 0,
                });
                out.len() - 1
            }
        };
        out[at].n_ops += 1;
        out[at].n_op_bytes += e.op.encoded().len() as u64;
        out[at].n_payload_bytes += payload.len() as u64;
    }
    out.sort_by_key(|k| k.kind);
    out
}

/// The deliberately wrong fold of [`Sabotage::ReverseFold`]: active entries, last first.
fn reversed_fold_hash(log: &Log<ShapePayload>) -> SceneHash {
    let mut scene = ShapeScene::default();
    let entries: Vec<_> = log.entries().filter(|e| e.active).collect();
    for e in entries.iter().rev() {
        scene.apply(FoldEntry {
            key: OrderKey::of(e.op),
            op: e.op,
        });
    }
    scene.scene_hash()
}

fn mean_latency_micros(latency: &[Vec<u64>], n_honest: usize) -> u64 {
    let mut sum = 0u64;
    let mut n = 0u64;
    for (a, row) in latency.iter().enumerate().take(n_honest) {
        for (b, l) in row.iter().enumerate().take(n_honest) {
            if a != b {
                sum += l;
                n += 1;
            }
        }
    }
    sum.checked_div(n).unwrap_or(0)
}
