//! What the replication core needs to know about an op's payload, without knowing the
//! object model: the [`Payload`] trait and the [`Effect`] an op has on leases and undo.

use std::fmt;

use crate::codec::DecodeError;
use crate::identity::{OpId, PeerId};
use crate::membership::{Admission, Membership};

/// Largest encoded payload accepted in an op, in bytes (typical ops are well under 1 KiB).
pub const MAX_PAYLOAD_BYTES: usize = 16 * 1024;

/// A shared object's id, chosen by the payload's object model (for example derived from the
/// id of the op that created it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ObjectId(pub u64);

/// How strongly a lease is held.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LeaseStrength {
    /// Another peer may take the object over; the former holder loses it.
    Weak,
    /// Only granted when the object is free, expired or already the acquirer's.
    Strong,
}

/// The lease vocabulary every payload shares: a lease taken on an object or given back. A
/// payload holds one as a variant of its own (`Lease`) and encodes it in its own format; the
/// core reads it through [`LeaseAction::effect`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeaseAction {
    /// Takes the object's lease.
    Acquire {
        /// The object, in the payload's own ids.
        object: u64,
        /// Strong (only when free, expired or own) or weak (takes over).
        strong: bool,
        /// Time to live in microseconds from the op's timestamp.
        ttl_micros: u64,
    },
    /// Gives the author's lease on the object back.
    Release {
        /// The object, in the payload's own ids.
        object: u64,
    },
}

impl LeaseAction {
    /// What it means to the core; `lease_object` maps the payload's object id to the object
    /// whose lease it is.
    pub fn effect(self, lease_object: impl FnOnce(u64) -> ObjectId) -> Effect {
        match self {
            LeaseAction::Acquire {
                object,
                strong,
                ttl_micros,
            } => Effect::Acquire {
                object: lease_object(object),
                strength: if strong {
                    LeaseStrength::Strong
                } else {
                    LeaseStrength::Weak
                },
                ttl_micros,
            },
            LeaseAction::Release { object } => Effect::Release {
                object: lease_object(object),
            },
        }
    }
}

/// What an op means to the core: which object it touches and which lease or undo rule
/// applies to it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Effect {
    /// Needs no lease and touches no object's lease state (chat, for example): always effective.
    Independent,
    /// Changes `object` (create, set a property, tool edit, transform): effective only if the
    /// author holds the object's lease, or it is free or expired, at this point of the order.
    Edit {
        /// The object changed.
        object: ObjectId,
    },
    /// Acquires the lease on `object` until `ttl_micros` after the op's timestamp.
    Acquire {
        /// The object whose lease is acquired.
        object: ObjectId,
        /// Weak (takes over) or strong (only when free, expired or own).
        strength: LeaseStrength,
        /// Time to live in microseconds from the op's timestamp.
        ttl_micros: u64,
    },
    /// Releases the author's lease on `object`.
    Release {
        /// The object whose lease is released.
        object: ObjectId,
    },
    /// Undoes the author's own earlier effective edit `target`.
    Undo {
        /// The edit undone.
        target: OpId,
    },
    /// Redoes the author's own earlier edit `target` that is currently undone.
    Redo {
        /// The edit redone.
        target: OpId,
    },
}

/// Whether [`Payload::encode`] writes exactly `bytes` for `payload`.
pub fn encodes_to<P: Payload>(payload: &P, bytes: &[u8]) -> bool {
    let mut canonical = Vec::with_capacity(bytes.len());
    payload.encode(&mut canonical);
    canonical == bytes
}

/// An op's payload: the object model's edits, encoded canonically.
///
/// The core is generic over it; `fdsl`'s edits implement it, tests use a small payload.
pub trait Payload: Clone + fmt::Debug + PartialEq + Eq {
    /// Appends the canonical encoding. It must be at most [`MAX_PAYLOAD_BYTES`] long and
    /// `decode(encode(p)) == p`.
    fn encode(&self, out: &mut Vec<u8>);

    /// Decodes a payload from untrusted bytes (at most [`MAX_PAYLOAD_BYTES`] long), never
    /// panicking; error offsets are relative to the start of `bytes`.
    fn decode(bytes: &[u8]) -> Result<Self, DecodeError>;

    /// Whether `bytes`, which decoded to `self`, are its canonical encoding. By default: what
    /// [`Payload::encode`] writes; a payload whose format gained a version may also accept its
    /// canonical encoding in an older version it still reads (ops signed then).
    fn is_canonical(&self, bytes: &[u8]) -> bool {
        encodes_to(self, bytes)
    }

    /// What the core must know about this payload.
    fn effect(&self) -> Effect;

    /// True if this op deletes the object of its [`Effect::Edit`]. A delete removes only what
    /// it saw: while it is effective and not undone, the edits of its object in its causal
    /// past are inactive; edits it did not see (concurrent ones, or later ones) stay active.
    /// The scene does not apply a delete itself: it acts only through which edits are active.
    fn is_delete(&self) -> bool {
        false
    }

    /// True if this op, authored by `author`, makes the object of its [`Effect::Edit`] exist
    /// (by the payload's own rules on who may make which object). A lease counts only once an
    /// effective op that creates its object is in the acquire's causal past, so a member cannot
    /// lease an id before its creator makes it. By default no op creates anything, and no lease
    /// counts.
    fn creates(&self, author: &PeerId) -> bool {
        let _ = author;
        false
    }

    /// The expel or readmit this op asks for, if it is a membership op (its [`Effect`] is
    /// [`Effect::Independent`]). The log alone decides whether it counts: see
    /// [`crate::membership`].
    fn membership(&self) -> Option<Membership> {
        None
    }

    /// The admission this op makes, if it is an admission op (its [`Effect`] is
    /// [`Effect::Independent`]): a session that binds its authors accepts a key's ops only once
    /// its first op names one of it ([`crate::membership`]).
    fn admission(&self) -> Option<Admission> {
        None
    }

    /// The payload of an admission op making `admission`, for a node that admits the keys it
    /// meets; `None` for a payload that cannot admit anyone.
    fn admitting(admission: Admission) -> Option<Self>
    where
        Self: Sized,
    {
        let _ = admission;
        None
    }
}

/// A small payload for tests, examples and the simulator.
pub mod test_payload {
    use super::*;
    use crate::codec::{Reader, put_bytes, put_varint};

    /// Largest note in a [`TestPayload::Chat`] or [`TestPayload::Set`].
    pub const MAX_TEST_TEXT_BYTES: usize = 256;

    /// A toy object model: set a property string, lease ops, undo/redo, chat.
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub enum TestPayload {
        /// A chat line (independent of leases).
        Chat(String),
        /// Sets object `object`'s value (an edit needing the lease); it also makes the object
        /// exist, for every author ([`Payload::creates`]).
        Set {
            /// The object.
            object: u64,
            /// The new value.
            value: String,
        },
        /// Acquires or releases a lease.
        Lease(LeaseAction),
        /// Undoes an earlier edit.
        Undo(OpId),
        /// Redoes an undone edit.
        Redo(OpId),
        /// Deletes an object: hides the edits of it that it saw (an edit needing the lease).
        Delete {
            /// The object.
            object: u64,
        },
        /// Expels or readmits a member (counts only from the session's founder).
        Member(Membership),
        /// Admits a key ([`crate::membership::Admission`]).
        Admit(Admission),
    }

    impl TestPayload {
        /// The `k`th op of a backlog the peer of key `seed` authored while apart: a third chat
        /// lines, the rest sets of 16 objects of its own (the backlog tests and bench).
        pub fn backlog(seed: u8, k: usize) -> Self {
            if k.is_multiple_of(3) {
                Self::Chat(format!("{k}"))
            } else {
                Self::Set {
                    object: u64::from(seed) * 100 + (k % 16) as u64,
                    value: format!("x - {k}"),
                }
            }
        }
    }

    impl Payload for TestPayload {
        fn encode(&self, out: &mut Vec<u8>) {
            match self {
                Self::Chat(text) => {
                    out.push(0);
                    put_bytes(out, text.as_bytes());
                }
                Self::Set { object, value } => {
                    out.push(1);
                    put_varint(out, *object);
                    put_bytes(out, value.as_bytes());
                }
                Self::Lease(LeaseAction::Acquire {
                    object,
                    strong,
                    ttl_micros,
                }) => {
                    out.push(2);
                    put_varint(out, *object);
                    out.push(u8::from(*strong));
                    put_varint(out, *ttl_micros);
                }
                Self::Lease(LeaseAction::Release { object }) => {
                    out.push(3);
                    put_varint(out, *object);
                }
                Self::Undo(id) => {
                    out.push(4);
                    out.extend_from_slice(&id.0);
                }
                Self::Redo(id) => {
                    out.push(5);
                    out.extend_from_slice(&id.0);
                }
                Self::Delete { object } => {
                    out.push(6);
                    put_varint(out, *object);
                }
                Self::Member(m) => {
                    out.push(7);
                    out.extend_from_slice(&m.member.0);
                    out.push(u8::from(m.expel));
                    out.extend_from_slice(&m.nonce);
                }
                Self::Admit(a) => {
                    out.push(8);
                    out.extend_from_slice(&a.key.0);
                    put_varint(out, a.grant_bytes);
                    out.push(u8::from(a.nonce.is_some()));
                    if let Some(nonce) = &a.nonce {
                        out.extend_from_slice(nonce);
                    }
                }
            }
        }

        fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
            let mut r = Reader::new(bytes);
            let tag_offset = r.offset();
            let payload = match r.u8()? {
                0 => Self::Chat(text(&mut r)?),
                1 => Self::Set {
                    object: r.varint()?,
                    value: text(&mut r)?,
                },
                2 => {
                    let object = r.varint()?;
                    let strong = r.flag()?;
                    Self::Lease(LeaseAction::Acquire {
                        object,
                        strong,
                        ttl_micros: r.varint()?,
                    })
                }
                3 => Self::Lease(LeaseAction::Release {
                    object: r.varint()?,
                }),
                4 => Self::Undo(OpId(r.array()?)),
                5 => Self::Redo(OpId(r.array()?)),
                6 => Self::Delete {
                    object: r.varint()?,
                },
                7 => Self::Member(Membership {
                    member: crate::identity::PeerId(r.array()?),
                    expel: r.flag()?,
                    nonce: r.array()?,
                }),
                8 => {
                    let key = PeerId(r.array()?);
                    let grant_bytes = r.varint()?;
                    let nonce = if r.flag()? { Some(r.array()?) } else { None };
                    Self::Admit(Admission {
                        key,
                        grant_bytes,
                        nonce,
                    })
                }
                _ => {
                    return Err(DecodeError::Invalid {
                        offset: tag_offset,
                        what: "payload tag",
                    });
                }
            };
            r.finish()?;
            Ok(payload)
        }

        fn effect(&self) -> Effect {
            match self {
                Self::Chat(_) | Self::Member(_) | Self::Admit(_) => Effect::Independent,
                Self::Set { object, .. } | Self::Delete { object } => Effect::Edit {
                    object: ObjectId(*object),
                },
                Self::Lease(lease) => lease.effect(ObjectId),
                Self::Undo(target) => Effect::Undo { target: *target },
                Self::Redo(target) => Effect::Redo { target: *target },
            }
        }

        fn is_delete(&self) -> bool {
            matches!(self, Self::Delete { .. })
        }

        fn creates(&self, _author: &PeerId) -> bool {
            matches!(self, Self::Set { .. })
        }

        fn membership(&self) -> Option<Membership> {
            match self {
                Self::Member(m) => Some(*m),
                _ => None,
            }
        }

        fn admission(&self) -> Option<Admission> {
            match self {
                Self::Admit(a) => Some(*a),
                _ => None,
            }
        }

        fn admitting(admission: Admission) -> Option<Self> {
            Some(Self::Admit(admission))
        }
    }

    fn text(r: &mut Reader<'_>) -> Result<String, DecodeError> {
        let offset = r.offset();
        let bytes = r.bytes("text length", MAX_TEST_TEXT_BYTES as u64)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| DecodeError::Invalid {
            offset,
            what: "utf-8",
        })
    }
}
