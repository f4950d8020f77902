//! An independent, naive reference of the lease and undo rules, replayed over a peer's final
//! linear order and compared with the peer's own verdicts.
//!
//! The core evaluates the rules incrementally (checkpoints, refolds when a late op lands in
//! the middle) through [`replication::Payload::effect`]. This reference reads the
//! [`ShapePayload`] variants itself and walks the final order once from the start with plain
//! maps, as the rules are written in `ARCHITECTURE.md`:
//!
//! - every op is judged on its own causal past alone (what its author had): the lease of its
//!   object is the fold of these rules over the lease ops of that object in its causal past,
//!   in linear order, from scratch (a lease binds only ops that saw it);
//! - an edit of an object is effective unless another peer holds a lease on it that has not
//!   expired at the edit's timestamp;
//! - a weak acquire takes over another peer's live weak lease but not a strong one; a strong
//!   acquire needs the object free, expired or its own; an effective acquire sets the lease
//!   to expire `ttl` after its timestamp;
//! - an acquire counts only once an effective op creating its object is in its causal past
//!   ([`RejectReason::UnknownObject`]), and only while its author's own effective acquires, not
//!   released by it, hold fewer than `MAX_LIVE_LEASES_PER_AUTHOR` live leases on other objects
//!   ([`RejectReason::TooManyLeases`]); an acquire refused so counts in nobody's lease;
//! - a release is effective only by the live holder;
//! - an undo (redo) is effective only on an earlier, own, effective edit that is not (is)
//!   undone, and only if the edit's object is free for the author; an edit is active when it
//!   is effective and not undone at the end, and no effective delete of its object that is not
//!   undone has it in its causal past (a delete removes only what it saw);
//! - in a session with a founder, membership is read from each op's causal past: a member is
//!   expelled there when an expel of it by the founder (a membership op whose nonce proves its
//!   author the founder, naming another member) is in it and no readmit there saw that expel.
//!   An op whose author is expelled in its past is rejected as [`RejectReason::Expelled`], and
//!   a lease whose holder is expelled in an op's past does not bind that op;
//! - an expel that no readmit saw makes the member's ops it did not see void: they keep their
//!   verdicts but are inactive (a void delete hides nothing);
//! - an author with two held ops of one seq forked: its ops at the lowest such seq and after
//!   are rejected as [`RejectReason::Forked`] and count in nobody's lease, and past that seq
//!   an op's causal past runs through its deps alone.

use std::collections::{BTreeMap, BTreeSet};

use replication::lease::{MAX_LEASE_TTL_MICROS, MAX_LIVE_LEASES_PER_AUTHOR};
use replication::payload::LeaseAction;
use replication::shape::ShapePayload;
use replication::{Log, Mark, OpId, Payload, PeerId, RejectReason};

/// Group ids share lease space with objects under this bit (as `replication::shape` does).
const GROUP_LEASE_BIT: u64 = 1 << 63;

/// What the reference found on one log.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LeaseCheck {
    /// Ops whose verdict was compared.
    pub n_checked: usize,
    /// Ops the rules reject.
    pub n_rejected: usize,
    /// Ops whose verdict or activity differs from the reference (the first few, described).
    pub mismatches: Vec<String>,
    /// Number of mismatches in all.
    pub n_mismatches: usize,
}

/// Most mismatches described per log.
const MAX_DESCRIBED: usize = 5;

#[derive(Clone, Copy)]
struct Lease {
    holder: PeerId,
    strong: bool,
    expires_micros: u64,
}

#[derive(Clone, Copy)]
struct Seen {
    author: PeerId,
    edit_of: Option<u64>,
    effective: bool,
}

#[derive(Default)]
struct Rules {
    leases: BTreeMap<u64, Lease>,
    undone: BTreeSet<OpId>,
    earlier: BTreeMap<OpId, Seen>,
}

enum Kind {
    Edit(u64),
    Acquire { object: u64, strong: bool, ttl: u64 },
    Release(u64),
    Undo(OpId),
    Redo(OpId),
    Independent,
}

fn kind(p: &ShapePayload) -> Kind {
    let obj = |o: u64| o & !GROUP_LEASE_BIT;
    match p {
        ShapePayload::Create { object, .. }
        | ShapePayload::Delete { object }
        | ShapePayload::Set { object, .. }
        | ShapePayload::Edit { object, .. }
        | ShapePayload::Move { object, .. }
        | ShapePayload::Part { object, .. }
        | ShapePayload::Assemble { object, .. } => Kind::Edit(obj(*object)),
        ShapePayload::SetGroup { group, .. } => Kind::Edit(group | GROUP_LEASE_BIT),
        ShapePayload::Lease(LeaseAction::Acquire {
            object,
            strong,
            ttl_micros,
        }) => Kind::Acquire {
            object: obj(*object),
            strong: *strong,
            ttl: *ttl_micros,
        },
        ShapePayload::Lease(LeaseAction::Release { object }) => Kind::Release(obj(*object)),
        ShapePayload::Undo(t) => Kind::Undo(*t),
        ShapePayload::Redo(t) => Kind::Redo(*t),
        ShapePayload::Chat(_) | ShapePayload::Member(_) | ShapePayload::Admit(_) => {
            Kind::Independent
        }
    }
}

impl Rules {
    /// The live lease of another peer on `object` at `at`.
    fn blocker(
        &self,
        author: PeerId,
        object: u64,
        at: u64,
        exempt: &dyn Fn(&PeerId) -> bool,
    ) -> Option<Lease> {
        self.leases
            .get(&object)
            .filter(|l| at < l.expires_micros && l.holder != author && !exempt(&l.holder))
            .copied()
    }

    /// The verdict on an op; a lease held by a peer `exempt` names does not bind it.
    fn verdict(
        &mut self,
        author: PeerId,
        at: u64,
        k: &Kind,
        exempt: &dyn Fn(&PeerId) -> bool,
    ) -> Result<(), RejectReason> {
        match *k {
            Kind::Independent => Ok(()),
            Kind::Edit(object) => match self.blocker(author, object, at, exempt) {
                Some(l) => Err(RejectReason::LeaseHeld { holder: l.holder }),
                None => Ok(()),
            },
            Kind::Acquire {
                object,
                strong,
                ttl,
            } => {
                if let Some(l) = self.blocker(author, object, at, exempt) {
                    if strong {
                        return Err(RejectReason::LeaseHeld { holder: l.holder });
                    }
                    if l.strong {
                        return Err(RejectReason::StrongLeaseHeld { holder: l.holder });
                    }
                }
                let lease = Lease {
                    holder: author,
                    strong,
                    expires_micros: at.saturating_add(ttl.min(MAX_LEASE_TTL_MICROS)),
                };
                self.leases.insert(object, lease);
                Ok(())
            }
            Kind::Release(object) => match self.leases.get(&object) {
                Some(l) if l.holder == author && at < l.expires_micros => {
                    self.leases.remove(&object);
                    Ok(())
                }
                _ => Err(RejectReason::NotHolder),
            },
            Kind::Undo(target) => self.toggle(author, at, target, true, exempt),
            Kind::Redo(target) => self.toggle(author, at, target, false, exempt),
        }
    }

    fn toggle(
        &mut self,
        author: PeerId,
        at: u64,
        target: OpId,
        undo: bool,
        exempt: &dyn Fn(&PeerId) -> bool,
    ) -> Result<(), RejectReason> {
        let seen = self
            .earlier
            .get(&target)
            .copied()
            .ok_or(RejectReason::UnknownTarget)?;
        if seen.author != author {
            return Err(RejectReason::NotOwnTarget);
        }
        let object = seen.edit_of.ok_or(RejectReason::TargetNotEdit)?;
        if !seen.effective {
            return Err(RejectReason::TargetNotEffective);
        }
        let undone = self.undone.contains(&target);
        if undo && undone {
            return Err(RejectReason::AlreadyUndone);
        }
        if !undo && !undone {
            return Err(RejectReason::NotUndone);
        }
        if let Some(l) = self.blocker(author, object, at, exempt) {
            return Err(RejectReason::LeaseHeld { holder: l.holder });
        }
        if undo {
            self.undone.insert(target);
        } else {
            self.undone.remove(&target);
        }
        Ok(())
    }
}

/// Per author and object, when the lease its own last effective acquire took expires, until
/// its own effective release: the live leases `MAX_LIVE_LEASES_PER_AUTHOR` counts.
#[derive(Default)]
struct Claims(BTreeMap<(PeerId, u64), u64>);

impl Claims {
    /// True if `author` holds the most live leases on objects other than `object` at `at`.
    fn over_cap(&self, author: PeerId, object: u64, at: u64) -> bool {
        let live = (self.0.iter())
            .filter(|((a, o), until)| *a == author && *o != object && at < **until)
            .count();
        live >= MAX_LIVE_LEASES_PER_AUTHOR
    }

    /// Follows the author's acquire or release with its verdict.
    fn follow(&mut self, author: PeerId, at: u64, k: &Kind, verdict: Mark) {
        if verdict != Mark::Effective {
            return;
        }
        match k {
            Kind::Acquire { object, ttl, .. } => {
                let until = at.saturating_add((*ttl).min(MAX_LEASE_TTL_MICROS));
                self.0.insert((author, *object), until);
            }
            Kind::Release(object) => {
                self.0.remove(&(author, *object));
            }
            _ => {}
        }
    }
}

/// Replays `log`'s linear order (a log with every op since the start, not one joined from a
/// snapshot) through the reference rules and compares every verdict and activity flag. With
/// `flip_first_rejected` the peer's first lease-rejected op is read as effective (the
/// checker's planted-bug test).
pub fn check(log: &Log<ShapePayload>, flip_first_rejected: bool) -> LeaseCheck {
    let replay = Replay::new(log);
    let mut rules = Rules::default();
    let mut out = LeaseCheck::default();
    let mut observed: Vec<Observed> = Vec::new();
    let mut flipped = !flip_first_rejected;
    // Per object, the positions of its lease ops (acquires and releases).
    let mut lease_ops: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
    let mut claims = Claims::default();
    for (pos, entry) in replay.entries.iter().enumerate() {
        let op = entry.op;
        let k = kind(op.payload());
        let object = match k {
            Kind::Edit(o) | Kind::Acquire { object: o, .. } | Kind::Release(o) => Some(o),
            Kind::Undo(t) | Kind::Redo(t) => rules.earlier.get(&t).and_then(|s| s.edit_of),
            Kind::Independent => None,
        };
        if let Some(object) = object {
            let ops = lease_ops.get(&object).map_or(&[][..], Vec::as_slice);
            match replay.lease_in_past(pos, object, ops, &observed) {
                Some(lease) => rules.leases.insert(object, lease),
                None => rules.leases.remove(&object),
            };
            if matches!(k, Kind::Acquire { .. } | Kind::Release(_)) {
                lease_ops.entry(object).or_default().push(pos);
            }
        }
        let expected = replay.expected(pos, &k, &mut rules, &claims, &observed);
        claims.follow(op.author(), op.timestamp().0, &k, expected);
        let mut mark = entry.mark;
        if !flipped && matches!(mark, Mark::Rejected(RejectReason::LeaseHeld { .. })) {
            mark = Mark::Effective;
            flipped = true;
        }
        let edit_of = match k {
            Kind::Edit(object) => Some(object),
            _ => None,
        };
        let seen = Seen {
            author: op.author(),
            edit_of,
            effective: expected == Mark::Effective,
        };
        rules.earlier.insert(op.id(), seen);
        out.n_checked += 1;
        out.n_rejected += usize::from(expected != Mark::Effective);
        if mark != expected {
            out.note(format!(
                "op {} by {}: verdict {mark:?}, the rules say {expected:?}",
                op.id(),
                op.author()
            ));
        }
        observed.push((op.id(), expected, entry.active));
    }
    let hidden = replay.hidden(&observed, &rules.undone);
    for (pos, (id, expected, active)) in observed.into_iter().enumerate() {
        let should = expected == Mark::Effective
            && !rules.undone.contains(&id)
            && !hidden.contains(&id)
            && !replay.void.contains(pos);
        if active != should {
            out.note(format!("op {id}: active {active}, the rules say {should}"));
        }
    }
    out
}

/// An op replayed: its id, the verdict the rules give it, and whether the peer holds it active.
type Observed = (OpId, Mark, bool);

/// What the replay reads from a log before it walks the order.
struct Replay<'a> {
    /// The log's entries, in its linear order.
    entries: Vec<replication::log::Entry<'a, ShapePayload>>,
    /// Per forked author, its lowest forked seq.
    forks: BTreeMap<PeerId, u64>,
    /// Each entry's causal past.
    pasts: Vec<Positions>,
    /// Per member, the membership ops that count.
    membership: BTreeMap<PeerId, Vec<(usize, bool)>>,
    /// The void ops.
    void: Positions,
}

impl<'a> Replay<'a> {
    fn new(log: &'a Log<ShapePayload>) -> Replay<'a> {
        let entries: Vec<_> = log.entries().collect();
        let forks = forks(&entries);
        let pasts = causal_pasts(log, &entries, &forks);
        let membership = membership_ops(log, &entries);
        let void = void_ops(&entries, &pasts, &membership);
        Replay {
            entries,
            forks,
            pasts,
            membership,
            void,
        }
    }

    /// Whether `op` is at or past its author's fork.
    fn forked(&self, op: &replication::Op<ShapePayload>) -> bool {
        self.forks.get(&op.author()).is_some_and(|f| op.seq() >= *f)
    }

    /// Whether `member` is expelled in the causal past of the op at `pos` (itself included).
    fn expelled_at(&self, pos: usize, member: &PeerId) -> bool {
        let saw = |p: usize, q: usize| p == q || self.pasts[p].contains(q);
        self.membership.get(member).is_some_and(|ops| {
            ops.iter().any(|&(e, expel)| {
                expel
                    && saw(pos, e)
                    && !ops
                        .iter()
                        .any(|&(r, expel)| !expel && saw(pos, r) && saw(r, e))
            })
        })
    }

    /// The lease the causal past of the op at `pos` gives `object`, folded from scratch over
    /// the object's lease ops `lease_ops` there, but those refused for their own reasons
    /// (counted in no view).
    fn lease_in_past(
        &self,
        pos: usize,
        object: u64,
        lease_ops: &[usize],
        observed: &[Observed],
    ) -> Option<Lease> {
        let mut seen = Rules::default();
        for &p in lease_ops {
            let l = self.entries[p].op;
            let void = matches!(observed[p], (_, Mark::Rejected(r), _) if r.voids_lease_op());
            if self.pasts[pos].contains(p)
                && !void
                && !self.expelled_at(p, &l.author())
                && !self.forked(l)
            {
                let exempt = |holder: &PeerId| self.expelled_at(p, holder);
                let _ = seen.verdict(l.author(), l.timestamp().0, &kind(l.payload()), &exempt);
            }
        }
        seen.leases.get(&object).copied()
    }

    /// Whether an effective creation of `object` is in the causal past of the op at `pos`.
    fn created(&self, pos: usize, object: u64, observed: &[Observed]) -> bool {
        (0..pos).any(|p| {
            let c = self.entries[p].op;
            matches!(kind(c.payload()), Kind::Edit(o) if o == object)
                && c.payload().creates(&c.author())
                && observed[p].1 == Mark::Effective
                && self.pasts[pos].contains(p)
        })
    }

    /// The verdict the rules give the op at `pos`, of kind `k`.
    fn expected(
        &self,
        pos: usize,
        k: &Kind,
        rules: &mut Rules,
        claims: &Claims,
        observed: &[Observed],
    ) -> Mark {
        let op = self.entries[pos].op;
        let exempt = |holder: &PeerId| self.expelled_at(pos, holder);
        if self.forked(op) {
            Mark::Rejected(RejectReason::Forked)
        } else if self.expelled_at(pos, &op.author()) {
            Mark::Rejected(RejectReason::Expelled)
        } else if matches!(*k, Kind::Acquire { object, .. } if !self.created(pos, object, observed))
        {
            // An acquire counts once an effective creation of its object is in its past.
            Mark::Rejected(RejectReason::UnknownObject)
        } else if let Kind::Acquire { object, .. } = *k
            && claims.over_cap(op.author(), object, op.timestamp().0)
        {
            Mark::Rejected(RejectReason::TooManyLeases)
        } else {
            match rules.verdict(op.author(), op.timestamp().0, k, &exempt) {
                Ok(()) => Mark::Effective,
                Err(reason) => Mark::Rejected(reason),
            }
        }
    }

    /// The edits hidden by deletes that stand (effective, not undone, not void): those of
    /// their object they saw.
    fn hidden(&self, observed: &[Observed], undone: &BTreeSet<OpId>) -> BTreeSet<OpId> {
        let mut hidden = BTreeSet::new();
        for (pos, entry) in self.entries.iter().enumerate() {
            let ShapePayload::Delete { object } = entry.op.payload() else {
                continue;
            };
            let stands = observed[pos].1 == Mark::Effective
                && !undone.contains(&observed[pos].0)
                && !self.void.contains(pos);
            if !stands {
                continue;
            }
            for (p, e) in self.entries[..pos].iter().enumerate() {
                let same = matches!(kind(e.op.payload()), Kind::Edit(o) if o == *object & !GROUP_LEASE_BIT);
                if same && self.pasts[pos].contains(p) {
                    hidden.insert(e.op.id());
                }
            }
        }
        hidden
    }
}

/// Per member, the membership ops that count (by the founder the log's invite commits to,
/// naming another member), as positions with whether each expels.
fn membership_ops(
    log: &Log<ShapePayload>,
    entries: &[replication::log::Entry<'_, ShapePayload>],
) -> BTreeMap<PeerId, Vec<(usize, bool)>> {
    let mut membership: BTreeMap<PeerId, Vec<(usize, bool)>> = BTreeMap::new();
    let Some(founder) = log.founder() else {
        return membership;
    };
    for (pos, e) in entries.iter().enumerate() {
        if let ShapePayload::Member(m) = e.op.payload()
            && m.member != e.op.author()
            && founder.is_founder(&e.op.author(), &m.nonce)
        {
            membership.entry(m.member).or_default().push((pos, m.expel));
        }
    }
    membership
}

/// The positions of the void ops, by brute force over the causal pasts: per member, each
/// standing expel (seen by no readmit of that member) voids the member's ops it did not see.
fn void_ops(
    entries: &[replication::log::Entry<'_, ShapePayload>],
    pasts: &[Positions],
    membership: &BTreeMap<PeerId, Vec<(usize, bool)>>,
) -> Positions {
    let mut void = Positions(vec![0; entries.len().div_ceil(64)]);
    for (member, ops) in membership {
        let standing: Vec<usize> = ops
            .iter()
            .filter(|(e, expel)| {
                *expel
                    && !ops
                        .iter()
                        .any(|(r, is_expel)| !is_expel && pasts[*r].contains(*e))
            })
            .map(|(e, _)| *e)
            .collect();
        for (pos, entry) in entries.iter().enumerate() {
            if entry.op.author() == *member && standing.iter().any(|e| !pasts[*e].contains(pos)) {
                void.0[pos / 64] |= 1 << (pos % 64);
            }
        }
    }
    void
}

/// A set of positions of the linear order, as bits.
struct Positions(Vec<u64>);

impl Positions {
    fn contains(&self, pos: usize) -> bool {
        self.0
            .get(pos / 64)
            .is_some_and(|w| w & (1 << (pos % 64)) != 0)
    }
}

/// Per author that signed two held ops with one seq, the lowest such seq.
fn forks(entries: &[replication::log::Entry<'_, ShapePayload>]) -> BTreeMap<PeerId, u64> {
    let mut seen = BTreeSet::new();
    let mut forks: BTreeMap<PeerId, u64> = BTreeMap::new();
    for e in entries {
        if !seen.insert((e.op.author(), e.op.seq())) {
            let f = forks.entry(e.op.author()).or_insert(e.op.seq());
            *f = (*f).min(e.op.seq());
        }
    }
    forks
}

/// Each entry's causal past, as positions of the linear order (a topological order, so every
/// parent comes first): its deps and its author's previous op (up to the author's fork), and
/// theirs.
fn causal_pasts(
    log: &Log<ShapePayload>,
    entries: &[replication::log::Entry<'_, ShapePayload>],
    forks: &BTreeMap<PeerId, u64>,
) -> Vec<Positions> {
    let position: BTreeMap<OpId, usize> = entries
        .iter()
        .enumerate()
        .map(|(p, e)| (e.op.id(), p))
        .collect();
    let words = entries.len().div_ceil(64);
    let mut pasts: Vec<Positions> = Vec::with_capacity(entries.len());
    for e in entries {
        let mut past = vec![0u64; words];
        let past_fork = forks.get(&e.op.author()).is_some_and(|f| e.op.seq() > *f);
        let prev = (e.op.seq().checked_sub(1))
            .filter(|_| !past_fork)
            .and_then(|s| log.by_seq(&e.op.author(), s))
            .map(|op| op.id());
        for parent in e.op.deps().iter().copied().chain(prev) {
            let Some(&p) = position.get(&parent) else {
                continue;
            };
            for (w, theirs) in past.iter_mut().zip(&pasts[p].0) {
                *w |= theirs;
            }
            past[p / 64] |= 1 << (p % 64);
        }
        pasts.push(Positions(past));
    }
    pasts
}

impl LeaseCheck {
    fn note(&mut self, what: String) {
        self.n_mismatches += 1;
        if self.mismatches.len() < MAX_DESCRIBED {
            self.mismatches.push(what);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use replication::{Keypair, Timestamp};

    /// The creation of object 1 (anybody may make an id without the derived bit).
    fn create() -> ShapePayload {
        ShapePayload::Create {
            object: 1,
            counter: None,
            data: std::sync::Arc::new(model::object::ObjectData::default()),
            group: None,
        }
    }

    fn acquire(strong: bool) -> ShapePayload {
        ShapePayload::Lease(LeaseAction::Acquire {
            object: 1,
            strong,
            ttl_micros: 100,
        })
    }

    #[test]
    fn the_reference_agrees_with_the_core_on_a_lease_fight() {
        let (a, b) = (Keypair::from_seed([1; 32]), Keypair::from_seed([2; 32]));
        let mut log = Log::<ShapePayload>::default();
        let chat = |s: &str| ShapePayload::Chat(s.into());
        let script: Vec<(&Keypair, u64, ShapePayload)> = vec![
            (&b, 900, create()),
            (&a, 1000, acquire(false)),
            (&b, 1010, chat("x")),
            (
                &b,
                1020,
                ShapePayload::Lease(LeaseAction::Release { object: 1 }),
            ),
            (&b, 1030, acquire(false)),
            (&a, 1040, acquire(true)),
            (&b, 1050, acquire(true)),
            (&a, 1060, acquire(false)),
            (&a, 2000, acquire(true)),
            (
                &a,
                2010,
                ShapePayload::Lease(LeaseAction::Release { object: 1 }),
            ),
        ];
        for (key, at, p) in script {
            log.author(key, Timestamp(at), p).unwrap();
        }
        let report = check(&log, false);
        assert_eq!(report.n_checked, 10);
        assert!(report.n_rejected >= 3, "{report:?}");
        assert_eq!(report.n_mismatches, 0, "{report:?}");
        let flipped = check(&log, true);
        assert!(flipped.n_mismatches >= 1, "{flipped:?}");
    }

    #[test]
    fn a_lease_asked_for_forever_ends_after_the_longest_ttl_as_in_the_core() {
        let (a, b) = (Keypair::from_seed([1; 32]), Keypair::from_seed([2; 32]));
        let mut log = Log::<ShapePayload>::default();
        let hoard = ShapePayload::Lease(LeaseAction::Acquire {
            object: 1,
            strong: true,
            ttl_micros: u64::MAX,
        });
        log.author(&b, Timestamp(900), create()).unwrap();
        log.author(&a, Timestamp(1000), hoard).unwrap();
        let late = Timestamp(1000 + MAX_LEASE_TTL_MICROS + 10);
        log.author(&b, late, ShapePayload::Delete { object: 1 })
            .unwrap();
        let report = check(&log, false);
        assert_eq!((report.n_checked, report.n_rejected), (3, 0), "{report:?}");
        assert_eq!(report.n_mismatches, 0, "{report:?}");
    }

    #[test]
    fn the_reference_voids_what_the_founders_expel_did_not_see_as_the_core_does() {
        use replication::membership::{FounderCommitment, Membership};
        let (founder, mallory, c) = (
            Keypair::from_seed([1; 32]),
            Keypair::from_seed([2; 32]),
            Keypair::from_seed([3; 32]),
        );
        let nonce = [9; 32];
        let founded = || {
            let mut log = Log::<ShapePayload>::default();
            log.set_founder(FounderCommitment::of(&founder.peer_id(), &nonce))
                .unwrap();
            log
        };
        let mut log = founded();
        let mut founders = founded();
        log.author(&mallory, Timestamp(1000), acquire(true))
            .unwrap();
        founders.merge(Timestamp(1000), &log).unwrap();
        // Unseen by the founder: Mallory hoards again, and C's delete that saw it is refused.
        let hoard = ShapePayload::Lease(LeaseAction::Acquire {
            object: 1,
            strong: true,
            ttl_micros: u64::MAX,
        });
        log.author(&mallory, Timestamp(1200), hoard).unwrap();
        let expel = ShapePayload::Member(Box::new(Membership {
            member: mallory.peer_id(),
            expel: true,
            nonce,
        }));
        let (expel, _) = founders.author(&founder, Timestamp(1100), expel).unwrap();
        log.author(&c, Timestamp(2000), ShapePayload::Delete { object: 1 })
            .unwrap();
        log.insert(Timestamp(3000), expel, replication::pending::Origin(1))
            .unwrap();
        let report = check(&log, false);
        assert_eq!(report.n_checked, 4);
        assert_eq!(report.n_mismatches, 0, "{report:?}");
        let n_void = log.entries().filter(|e| log.is_void(&e.op.id())).count();
        assert_eq!(n_void, 1, "the hoard the founder never saw is void");
        // Mallory, seeing its expel, is refused; C, seeing it, is not bound by the hoard.
        log.author(&mallory, Timestamp(4000), acquire(true))
            .unwrap();
        log.author(&c, Timestamp(4100), ShapePayload::Delete { object: 1 })
            .unwrap();
        let report = check(&log, false);
        assert_eq!(report.n_checked, 6);
        assert_eq!(report.n_mismatches, 0, "{report:?}");
        let marks: Vec<Mark> = log.entries().map(|e| e.mark).collect();
        assert_eq!(marks[4], Mark::Rejected(RejectReason::Expelled));
        assert_eq!(marks[5], Mark::Effective);
        // Read without the founder (as a core without expels would judge), the same ops
        // disagree with the reference.
        let mut unfounded = Log::<ShapePayload>::default();
        unfounded.merge(Timestamp(3000), &log).unwrap();
        let mut founded_again = founded();
        founded_again.merge(Timestamp(3000), &unfounded).unwrap();
        assert_eq!(check(&founded_again, false).n_mismatches, 0);
        assert_ne!(
            unfounded.entries().map(|e| e.mark).collect::<Vec<_>>(),
            log.entries().map(|e| e.mark).collect::<Vec<_>>()
        );
    }
}
