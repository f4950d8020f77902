//! Lease and undo rules, evaluated in the fold: given the state before an op in the linear
//! order, decide whether the op is effective or rejected (and why), and update the state.
//!
//! A lease binds only ops that saw it. The fold carries the lease state of the whole prefix
//! (what an op that saw every earlier op faces); an op that missed some earlier lease ops of
//! its object is judged against the lease its own causal past gives instead, which the log
//! works out ([`crate::log`]) and hands to [`FoldState::apply`] as `seen`.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

use crate::codec::{DecodeError, Reader, put_varint};
use crate::identity::{OpId, PeerId};
use crate::op::MAX_LOG_OPS;
use crate::payload::{Effect, LeaseStrength, ObjectId};
use crate::time::Timestamp;

/// Longest a lease may hold (one hour). An acquire asking for more is clamped to it in the
/// fold, on every peer alike, so a lease taken with `ttl u64::MAX` still ends.
pub const MAX_LEASE_TTL_MICROS: u64 = 60 * 60 * 1_000_000;
/// Most live leases one author may hold: an acquire of another object by an author whose own
/// effective acquires, not released by it, already hold this many unexpired leases is
/// rejected ([`RejectReason::TooManyLeases`]). Counted along the author's own chain (its
/// acquires and releases, with their own verdicts), so the count is a function of the op's
/// causal past, and one member cannot hold every object of a session at once.
pub const MAX_LIVE_LEASES_PER_AUTHOR: usize = 32;

/// A lease on one object, as of some point in the linear order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lease {
    /// Who holds it.
    pub holder: PeerId,
    /// Weak or strong.
    pub strength: LeaseStrength,
    /// First timestamp at which it no longer holds.
    pub expires_at: Timestamp,
}

impl Lease {
    /// True if the lease still holds at `at`.
    pub fn holds_at(&self, at: Timestamp) -> bool {
        at < self.expires_at
    }
}

/// Why an op was not effective. Rejected ops stay in history with their reason.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RejectReason {
    /// Another peer held the object's lease.
    LeaseHeld {
        /// The holder at that point of the order.
        holder: PeerId,
    },
    /// A weak acquire met another peer's strong lease.
    StrongLeaseHeld {
        /// The holder at that point of the order.
        holder: PeerId,
    },
    /// A release by a peer that did not hold the lease.
    NotHolder,
    /// An undo or redo of an op that is not earlier in the order.
    UnknownTarget,
    /// An undo or redo of another author's op.
    NotOwnTarget,
    /// An undo or redo of an op that is not an edit.
    TargetNotEdit,
    /// An undo or redo of an edit that was itself rejected.
    TargetNotEffective,
    /// An undo of an edit that is already undone.
    AlreadyUndone,
    /// A redo of an edit that is not undone.
    NotUndone,
    /// An op of a member the session's founder expelled, not in the expel's causal past: it
    /// is void (see [`crate::membership`]).
    Expelled,
    /// An op of an author that signed two different ops with one seq, at that seq or after:
    /// both sides are held, neither counts (see [`crate::fork`]).
    Forked,
    /// An acquire of an object whose creation is not in its causal past
    /// ([`crate::Payload::creates`]): nobody can lease an id before its creator makes it.
    UnknownObject,
    /// An acquire by an author already holding [`MAX_LIVE_LEASES_PER_AUTHOR`] live leases on
    /// other objects.
    TooManyLeases,
}

impl RejectReason {
    /// True if the reason is the acquire's own, whatever lease its object has: such an
    /// acquire counts in nobody's view of the lease, as if it were not there.
    pub fn voids_lease_op(&self) -> bool {
        matches!(self, Self::UnknownObject | Self::TooManyLeases)
    }
}

impl RejectReason {
    /// What the op's author can do about it, in a few words for a tooltip.
    pub fn remedy(&self) -> &'static str {
        match self {
            Self::LeaseHeld { .. } => {
                "it stays in the history, marked rejected; take the lease and redo it"
            }
            Self::StrongLeaseHeld { .. } => {
                "it stays in the history, marked rejected; a strong lease cannot be taken over: \
                 redo it once its holder releases it or the lease runs out"
            }
            Self::NotHolder => "nothing to give back: the lease was not yours at that point",
            Self::UnknownTarget
            | Self::NotOwnTarget
            | Self::TargetNotEdit
            | Self::TargetNotEffective
            | Self::AlreadyUndone
            | Self::NotUndone => "nothing changed; undo and redo apply to your own effective edits",
            Self::Forked => {
                "two copies of your identity signed different edits; from the fork on, its edits \
                 count for nothing on every peer: join again with a new identity"
            }
            Self::Expelled => {
                "the session's founder expelled this identity; its edits count for nothing"
            }
            Self::UnknownObject => {
                "nothing to lease yet: take the lease once the object's creation has arrived"
            }
            Self::TooManyLeases => "release some of the leases you hold, then take this one",
        }
    }
}

impl fmt::Display for RejectReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LeaseHeld { holder } => write!(f, "{holder} held the lease"),
            Self::StrongLeaseHeld { holder } => write!(f, "{holder} held a strong lease"),
            Self::NotHolder => f.write_str("released a lease it did not hold"),
            Self::UnknownTarget => f.write_str("undo/redo of an unknown op"),
            Self::NotOwnTarget => f.write_str("undo/redo of another author's op"),
            Self::TargetNotEdit => f.write_str("undo/redo of an op that is not an edit"),
            Self::TargetNotEffective => f.write_str("undo/redo of a rejected edit"),
            Self::AlreadyUndone => f.write_str("already undone"),
            Self::NotUndone => f.write_str("redo of an edit that is not undone"),
            Self::Forked => f.write_str("its author forked its history at or before it"),
            Self::Expelled => f.write_str("its author was expelled"),
            Self::UnknownObject => f.write_str("acquire of an object it never saw created"),
            Self::TooManyLeases => write!(
                f,
                "its author already held {MAX_LIVE_LEASES_PER_AUTHOR} live leases"
            ),
        }
    }
}

/// The verdict on one op at its point of the linear order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Mark {
    /// The op took effect.
    Effective,
    /// The op stays in history but had no effect.
    Rejected(RejectReason),
}

/// What the fold knows about an undo/redo target that precedes the op in the order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TargetInfo {
    /// The target's author.
    pub author: PeerId,
    /// The target's effect.
    pub effect: Effect,
    /// The target's mark.
    pub mark: Mark,
}

/// The state the lease/undo fold carries from op to op: small, cloned into checkpoints.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FoldState {
    leases: BTreeMap<ObjectId, Lease>,
    undone: BTreeSet<OpId>,
    /// Per author and object, when the lease its own last effective acquire took expires,
    /// until its own effective release: what [`MAX_LIVE_LEASES_PER_AUTHOR`] counts. Only the
    /// author's ops change its entries, so they follow its chain, not the order's other ops
    /// (a lease another peer took over still counts until it expires or is released).
    claims: BTreeMap<(PeerId, ObjectId), Timestamp>,
}

impl FoldState {
    /// The lease on `object` as recorded (it may have expired).
    pub fn lease(&self, object: ObjectId) -> Option<Lease> {
        self.leases.get(&object).copied()
    }

    /// True if edit `id` is currently undone.
    pub fn is_undone(&self, id: &OpId) -> bool {
        self.undone.contains(id)
    }

    /// Most leases or undone edits a decoded state may hold.
    pub const MAX_DECODED_ENTRIES: usize = MAX_LOG_OPS;

    /// Appends the canonical encoding: `[n][object][holder 32][strong 0/1][expires]*`
    /// `[n][undone id 32]*` `[n][author 32][object][expires]*`, each sorted.
    pub fn encode(&self, out: &mut Vec<u8>) {
        put_varint(out, self.leases.len() as u64);
        for (object, lease) in &self.leases {
            put_varint(out, object.0);
            out.extend_from_slice(&lease.holder.0);
            out.push(u8::from(lease.strength == LeaseStrength::Strong));
            put_varint(out, lease.expires_at.0);
        }
        put_varint(out, self.undone.len() as u64);
        for id in &self.undone {
            out.extend_from_slice(&id.0);
        }
        put_varint(out, self.claims.len() as u64);
        for ((author, object), expires_at) in &self.claims {
            out.extend_from_slice(&author.0);
            put_varint(out, object.0);
            put_varint(out, expires_at.0);
        }
    }

    /// Decodes [`FoldState::encode`]'s output from untrusted bytes (sorted, bounded); with
    /// `with_claims` false, the layout from before live leases were counted (no claims: a log
    /// joined from it counts only the leases taken after its cut).
    pub fn decode(r: &mut Reader<'_>, with_claims: bool) -> Result<Self, DecodeError> {
        // Each lease takes at least 35 bytes and each id 32: bound counts by what is left.
        let limit = |r: &Reader<'_>, each: usize| {
            (r.remaining() / each).min(Self::MAX_DECODED_ENTRIES) as u64
        };
        let n_leases = r.bounded("lease count", limit(r, 35))?;
        let mut leases = BTreeMap::new();
        for _ in 0..n_leases {
            let offset = r.offset();
            let object = ObjectId(r.varint()?);
            if leases.last_key_value().is_some_and(|(o, _)| *o >= object) {
                return Err(DecodeError::Invalid {
                    offset,
                    what: "unsorted leases",
                });
            }
            let holder = PeerId(r.array()?);
            let strength = if r.flag()? {
                LeaseStrength::Strong
            } else {
                LeaseStrength::Weak
            };
            let expires_at = Timestamp(r.varint()?);
            leases.insert(
                object,
                Lease {
                    holder,
                    strength,
                    expires_at,
                },
            );
        }
        let n_undone = r.bounded("undone count", limit(r, 32))?;
        let mut undone = BTreeSet::new();
        for _ in 0..n_undone {
            let offset = r.offset();
            let id = OpId(r.array()?);
            if undone.last().is_some_and(|last| *last >= id) {
                return Err(DecodeError::Invalid {
                    offset,
                    what: "unsorted undone ids",
                });
            }
            undone.insert(id);
        }
        let mut claims = BTreeMap::new();
        if with_claims {
            // Each claim takes at least 34 bytes.
            let n_claims = r.bounded("claim count", limit(r, 34))?;
            for _ in 0..n_claims {
                let offset = r.offset();
                let key = (PeerId(r.array()?), ObjectId(r.varint()?));
                if claims.last_key_value().is_some_and(|(k, _)| *k >= key) {
                    return Err(DecodeError::Invalid {
                        offset,
                        what: "unsorted claims",
                    });
                }
                claims.insert(key, Timestamp(r.varint()?));
            }
        }
        Ok(Self {
            leases,
            undone,
            claims,
        })
    }

    /// True if `author`, acquiring `object` at `at`, already holds
    /// [`MAX_LIVE_LEASES_PER_AUTHOR`] live leases on other objects by its own acquires. Drops
    /// the author's claims that expired by `at` (its later ops are stamped no earlier).
    fn over_lease_cap(&mut self, author: PeerId, object: ObjectId, at: Timestamp) -> bool {
        let range = (author, ObjectId(0))..=(author, ObjectId(u64::MAX));
        let expired: Vec<(PeerId, ObjectId)> = (self.claims.range(range.clone()))
            .filter(|(_, until)| **until <= at)
            .map(|(k, _)| *k)
            .collect();
        for key in expired {
            self.claims.remove(&key);
        }
        let others = self.claims.range(range).filter(|((_, o), _)| *o != object);
        others.count() >= MAX_LIVE_LEASES_PER_AUTHOR
    }

    /// Evaluates one op and updates the state. `target` describes an undo/redo's target if it
    /// precedes this op in the order. `seen` is `None` when every earlier lease op of the op's
    /// object is in its causal past; otherwise it is the object's lease as the op's causal
    /// past gives it (see [`lease_step`]), and the op is judged against that, while the state
    /// still follows the whole prefix.
    pub fn apply(
        &mut self,
        author: PeerId,
        at: Timestamp,
        effect: Effect,
        target: Option<TargetInfo>,
        seen: Option<Option<Lease>>,
    ) -> Mark {
        self.apply_exempting(author, at, effect, target, seen, &mut |_| false)
    }

    /// [`FoldState::apply`], where a lease held by a peer for which `exempt` is true does not
    /// bind the op (the founder expelled its holder, as the op's causal past has it: see
    /// [`crate::membership`]). Only acquires and releases change the state; an acquire judged
    /// free that way takes the lease over in it.
    pub fn apply_exempting(
        &mut self,
        author: PeerId,
        at: Timestamp,
        effect: Effect,
        target: Option<TargetInfo>,
        seen: Option<Option<Lease>>,
        exempt: &mut impl FnMut(&PeerId) -> bool,
    ) -> Mark {
        let mut binding = |lease: Option<Lease>| lease.filter(|l| !exempt(&l.holder));
        if let Effect::Acquire { object, .. } = effect
            && self.over_lease_cap(author, object, at)
        {
            return Mark::Rejected(RejectReason::TooManyLeases);
        }
        let verdict = match effect {
            Effect::Independent => Ok(()),
            Effect::Edit { object }
            | Effect::Acquire { object, .. }
            | Effect::Release { object } => {
                let global = self.leases.get(&object).copied();
                let judged = lease_step(binding(seen.unwrap_or(global)), author, at, effect);
                match (effect, judged) {
                    (Effect::Acquire { .. }, Ok(Some(lease))) => {
                        self.claims.insert((author, object), lease.expires_at);
                    }
                    (Effect::Release { .. }, Ok(_)) => {
                        self.claims.remove(&(author, object));
                    }
                    _ => {}
                }
                if matches!(effect, Effect::Acquire { .. } | Effect::Release { .. }) {
                    let whole = match seen {
                        None => judged,
                        Some(_) => lease_step(binding(global), author, at, effect),
                    };
                    if let Ok(lease) = whole {
                        match lease {
                            Some(l) => self.leases.insert(object, l),
                            None => self.leases.remove(&object),
                        };
                    }
                }
                judged.map(|_| ())
            }
            Effect::Undo { .. } | Effect::Redo { .. } => {
                self.undo_redo(author, at, effect, target, seen, &mut binding)
            }
        };
        match verdict {
            Ok(()) => Mark::Effective,
            Err(reason) => Mark::Rejected(reason),
        }
    }

    /// An undo or redo (`effect`) of `target`.
    fn undo_redo(
        &mut self,
        author: PeerId,
        at: Timestamp,
        effect: Effect,
        target: Option<TargetInfo>,
        seen: Option<Option<Lease>>,
        binding: &mut dyn FnMut(Option<Lease>) -> Option<Lease>,
    ) -> Result<(), RejectReason> {
        let (id, undo) = match effect {
            Effect::Undo { target } => (target, true),
            Effect::Redo { target } => (target, false),
            _ => return Err(RejectReason::TargetNotEdit),
        };
        let t = target.ok_or(RejectReason::UnknownTarget)?;
        if t.author != author {
            return Err(RejectReason::NotOwnTarget);
        }
        let Effect::Edit { object } = t.effect else {
            return Err(RejectReason::TargetNotEdit);
        };
        if t.mark != Mark::Effective {
            return Err(RejectReason::TargetNotEffective);
        }
        match (undo, self.undone.contains(&id)) {
            (true, true) => return Err(RejectReason::AlreadyUndone),
            (false, false) => return Err(RejectReason::NotUndone),
            _ => {}
        }
        let lease = binding(seen.unwrap_or_else(|| self.leases.get(&object).copied()));
        lease_step(lease, author, at, Effect::Edit { object })?;
        if undo {
            self.undone.insert(id);
        } else {
            self.undone.remove(&id);
        }
        Ok(())
    }
}

/// The lease rules on one object: the verdict on `effect` by `author` at `at` against the
/// object's `lease` (as recorded: it may have expired), and the object's lease after it.
///
/// An edit (or undo/redo) needs the object free, expired or the author's own; a weak acquire
/// takes a weak lease over, a strong one needs the object free, expired or its own, and either
/// lasts its TTL clamped to [`MAX_LEASE_TTL_MICROS`]; a release needs the live holder.
pub fn lease_step(
    lease: Option<Lease>,
    author: PeerId,
    at: Timestamp,
    effect: Effect,
) -> Result<Option<Lease>, RejectReason> {
    let blocker = lease.filter(|l| l.holds_at(at) && l.holder != author);
    match effect {
        Effect::Independent => Ok(lease),
        Effect::Edit { .. } | Effect::Undo { .. } | Effect::Redo { .. } => match blocker {
            Some(l) => Err(RejectReason::LeaseHeld { holder: l.holder }),
            None => Ok(lease),
        },
        Effect::Acquire {
            strength,
            ttl_micros,
            ..
        } => {
            if let Some(l) = blocker {
                match (strength, l.strength) {
                    // A weak acquire takes a weak lease over; the former holder loses it.
                    (LeaseStrength::Weak, LeaseStrength::Weak) => {}
                    (LeaseStrength::Weak, LeaseStrength::Strong) => {
                        return Err(RejectReason::StrongLeaseHeld { holder: l.holder });
                    }
                    (LeaseStrength::Strong, _) => {
                        return Err(RejectReason::LeaseHeld { holder: l.holder });
                    }
                }
            }
            let expires_at = at.saturating_add_micros(ttl_micros.min(MAX_LEASE_TTL_MICROS));
            Ok(Some(Lease {
                holder: author,
                strength,
                expires_at,
            }))
        }
        Effect::Release { .. } => match lease {
            Some(l) if l.holder == author && l.holds_at(at) => Ok(None),
            _ => Err(RejectReason::NotHolder),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: PeerId = PeerId([1; 32]);
    const B: PeerId = PeerId([2; 32]);

    #[test]
    fn the_advice_on_a_rejected_edit_follows_its_reason() {
        // Only a weak lease can be taken over: the advice to take it is for that alone.
        let weak = RejectReason::LeaseHeld { holder: B }.remedy();
        assert!(weak.contains("take the lease"), "{weak}");
        let strong = RejectReason::StrongLeaseHeld { holder: B }.remedy();
        assert!(!strong.contains("take the lease"), "{strong}");
        assert!(
            strong.contains("releases it or the lease runs out"),
            "{strong}"
        );
        for other in [
            RejectReason::Forked,
            RejectReason::Expelled,
            RejectReason::UnknownObject,
            RejectReason::TooManyLeases,
            RejectReason::NotHolder,
            RejectReason::AlreadyUndone,
        ] {
            assert!(!other.remedy().contains("take the lease and"), "{other}");
        }
    }
    const OBJ: ObjectId = ObjectId(7);

    fn acquire(strength: LeaseStrength, ttl_micros: u64) -> Effect {
        Effect::Acquire {
            object: OBJ,
            strength,
            ttl_micros,
        }
    }

    #[test]
    fn weak_takes_over_strong_does_not() {
        let mut s = FoldState::default();
        let edit = Effect::Edit { object: OBJ };
        assert_eq!(
            s.apply(B, Timestamp(0), edit, None, None),
            Mark::Effective,
            "free object"
        );
        assert_eq!(
            s.apply(
                A,
                Timestamp(1),
                acquire(LeaseStrength::Weak, 100),
                None,
                None
            ),
            Mark::Effective
        );
        assert_eq!(
            s.apply(B, Timestamp(2), edit, None, None),
            Mark::Rejected(RejectReason::LeaseHeld { holder: A })
        );
        assert_eq!(
            s.apply(
                B,
                Timestamp(3),
                acquire(LeaseStrength::Weak, 100),
                None,
                None
            ),
            Mark::Effective
        );
        assert_eq!(
            s.apply(A, Timestamp(4), edit, None, None),
            Mark::Rejected(RejectReason::LeaseHeld { holder: B })
        );
        assert_eq!(
            s.apply(
                A,
                Timestamp(5),
                acquire(LeaseStrength::Strong, 100),
                None,
                None
            ),
            Mark::Rejected(RejectReason::LeaseHeld { holder: B })
        );
        assert_eq!(
            s.apply(
                B,
                Timestamp(6),
                acquire(LeaseStrength::Strong, 10),
                None,
                None
            ),
            Mark::Effective
        );
        assert_eq!(
            s.apply(
                A,
                Timestamp(7),
                acquire(LeaseStrength::Weak, 10),
                None,
                None
            ),
            Mark::Rejected(RejectReason::StrongLeaseHeld { holder: B })
        );
        // The strong lease expires at 16.
        assert_eq!(s.apply(A, Timestamp(16), edit, None, None), Mark::Effective);
        assert_eq!(
            s.apply(
                B,
                Timestamp(17),
                Effect::Release { object: OBJ },
                None,
                None
            ),
            Mark::Rejected(RejectReason::NotHolder)
        );
    }

    #[test]
    fn release_frees_the_object() {
        let mut s = FoldState::default();
        s.apply(
            A,
            Timestamp(1),
            acquire(LeaseStrength::Strong, 1000),
            None,
            None,
        );
        assert_eq!(
            s.apply(A, Timestamp(2), Effect::Release { object: OBJ }, None, None),
            Mark::Effective
        );
        assert_eq!(
            s.apply(B, Timestamp(3), Effect::Edit { object: OBJ }, None, None),
            Mark::Effective
        );
        assert_eq!(s.lease(OBJ), None);
    }

    #[test]
    fn undo_rules() {
        let mut s = FoldState::default();
        let id = OpId([5; 32]);
        let info = TargetInfo {
            author: A,
            effect: Effect::Edit { object: OBJ },
            mark: Mark::Effective,
        };
        let undo = Effect::Undo { target: id };
        let redo = Effect::Redo { target: id };
        assert_eq!(
            s.apply(A, Timestamp(1), redo, Some(info), None),
            Mark::Rejected(RejectReason::NotUndone)
        );
        assert_eq!(
            s.apply(B, Timestamp(1), undo, Some(info), None),
            Mark::Rejected(RejectReason::NotOwnTarget)
        );
        assert_eq!(
            s.apply(A, Timestamp(1), undo, None, None),
            Mark::Rejected(RejectReason::UnknownTarget)
        );
        assert_eq!(
            s.apply(A, Timestamp(1), undo, Some(info), None),
            Mark::Effective
        );
        assert!(s.is_undone(&id));
        assert_eq!(
            s.apply(A, Timestamp(2), undo, Some(info), None),
            Mark::Rejected(RejectReason::AlreadyUndone)
        );
        s.apply(
            B,
            Timestamp(3),
            acquire(LeaseStrength::Weak, 100),
            None,
            None,
        );
        assert_eq!(
            s.apply(A, Timestamp(4), redo, Some(info), None),
            Mark::Rejected(RejectReason::LeaseHeld { holder: B })
        );
        assert_eq!(
            s.apply(A, Timestamp(200), redo, Some(info), None),
            Mark::Effective
        );
        assert!(!s.is_undone(&id));
        let rejected = TargetInfo {
            mark: Mark::Rejected(RejectReason::NotHolder),
            ..info
        };
        assert_eq!(
            s.apply(A, Timestamp(201), undo, Some(rejected), None),
            Mark::Rejected(RejectReason::TargetNotEffective)
        );
    }
}
