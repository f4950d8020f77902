//! How a [`ShapePayload`] is encoded: one layout ([`Wire`]) for every version of the object
//! encoding, generic over how a `Create` holds its description.
//!
//! Version 2 (written today) holds today's [`ObjectData`]; version 1 (before objects held
//! grids, still read for ops signed then) holds [`object_codec::v1::ObjectData`] and has only
//! the variants up to `Chat`. A payload decoded from version 1 is canonical when version 1's
//! encoding of it is the bytes it came from, so those ops keep their ids and signatures.

use std::borrow::Cow;
use std::sync::Arc;

use model::object::codec::{self as object_codec, v1};
use model::object::{CompiledEdit, Field, ObjectData, ObjectError};
use model::scene::Group;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::ShapePayload;
use crate::identity::{OpId, PeerId};
use crate::membership::{Admission, Membership};
use crate::payload::LeaseAction;

/// [`ShapePayload`] as encoded: its variants in their order, `Create` in its layout from
/// before ids were derived, and then `CreateOwned`, a `Create` with its counter, so ops signed
/// before read as they did. A `Create`'s description is a `D`: today's, or version 1's.
/// Serializing borrows; deserializing moves.
#[derive(Serialize, Deserialize)]
enum Wire<'a, D> {
    Create {
        object: u64,
        data: D,
        group: Option<u64>,
    },
    Delete {
        object: u64,
    },
    Set {
        object: u64,
        field: Cow<'a, Box<Field>>,
    },
    Edit {
        object: u64,
        edit: Cow<'a, Arc<CompiledEdit>>,
    },
    SetGroup {
        group: u64,
        value: Cow<'a, Option<Box<Group>>>,
    },
    Move {
        object: u64,
        group: Option<u64>,
    },
    Acquire {
        object: u64,
        strong: bool,
        ttl_micros: u64,
    },
    Release {
        object: u64,
    },
    Undo(#[serde(with = "op_id")] OpId),
    Redo(#[serde(with = "op_id")] OpId),
    Chat(Cow<'a, str>),
    Part {
        object: u64,
        bytes: Cow<'a, [u8]>,
    },
    Assemble {
        object: u64,
        parts: Cow<'a, [[u8; 32]]>,
    },
    CreateOwned {
        object: u64,
        counter: u32,
        data: D,
        group: Option<u64>,
    },
    Member {
        member: [u8; 32],
        expel: bool,
        nonce: [u8; 32],
    },
    Admit {
        key: [u8; 32],
        grant_bytes: u64,
        nonce: Option<[u8; 32]>,
    },
}

/// Today's description of a `Create`, borrowed when encoding.
type Data<'a> = Cow<'a, Arc<ObjectData>>;

/// Version 1's description of a `Create` (without grids).
type DataV1 = Box<v1::ObjectData>;

impl<'a, D> Wire<'a, D> {
    /// `p` in this layout, a `Create`'s description through `data`; `None` where `data` has
    /// none for it.
    // tidy:table: one arm per payload variant.
    fn of(
        p: &'a ShapePayload,
        data: impl FnOnce(&'a Arc<ObjectData>) -> Option<D>,
    ) -> Option<Wire<'a, D>> {
        Some(match p {
            ShapePayload::Create {
                object,
                counter: None,
                data: d,
                group,
            } => Wire::Create {
                object: *object,
                data: data(d)?,
                group: *group,
            },
            ShapePayload::Create {
                object,
                counter: Some(counter),
                data: d,
                group,
            } => Wire::CreateOwned {
                object: *object,
                counter: *counter,
                data: data(d)?,
                group: *group,
            },
            ShapePayload::Delete { object } => Wire::Delete { object: *object },
            ShapePayload::Set { object, field } => Wire::Set {
                object: *object,
                field: Cow::Borrowed(field),
            },
            ShapePayload::Edit { object, edit } => Wire::Edit {
                object: *object,
                edit: Cow::Borrowed(edit),
            },
            ShapePayload::SetGroup { group, value } => Wire::SetGroup {
                group: *group,
                value: Cow::Borrowed(value),
            },
            ShapePayload::Move { object, group } => Wire::Move {
                object: *object,
                group: *group,
            },
            ShapePayload::Lease(LeaseAction::Acquire {
                object,
                strong,
                ttl_micros,
            }) => Wire::Acquire {
                object: *object,
                strong: *strong,
                ttl_micros: *ttl_micros,
            },
            ShapePayload::Lease(LeaseAction::Release { object }) => {
                Wire::Release { object: *object }
            }
            ShapePayload::Undo(id) => Wire::Undo(*id),
            ShapePayload::Redo(id) => Wire::Redo(*id),
            ShapePayload::Chat(text) => Wire::Chat(Cow::Borrowed(text)),
            ShapePayload::Part { object, bytes } => Wire::Part {
                object: *object,
                bytes: Cow::Borrowed(bytes),
            },
            ShapePayload::Assemble { object, parts } => Wire::Assemble {
                object: *object,
                parts: Cow::Borrowed(parts),
            },
            ShapePayload::Member(m) => Wire::Member {
                member: m.member.0,
                expel: m.expel,
                nonce: m.nonce,
            },
            ShapePayload::Admit(a) => Wire::Admit {
                key: a.key.0,
                grant_bytes: a.grant_bytes,
                nonce: a.nonce,
            },
        })
    }

    /// The payload this encodes, a `Create`'s description through `data`.
    // tidy:table: one arm per wire variant.
    fn into_payload(self, data: impl FnOnce(D) -> Arc<ObjectData>) -> ShapePayload {
        match self {
            Wire::Create {
                object,
                data: d,
                group,
            } => ShapePayload::Create {
                object,
                counter: None,
                data: data(d),
                group,
            },
            Wire::CreateOwned {
                object,
                counter,
                data: d,
                group,
            } => ShapePayload::Create {
                object,
                counter: Some(counter),
                data: data(d),
                group,
            },
            Wire::Delete { object } => ShapePayload::Delete { object },
            Wire::Set { object, field } => ShapePayload::Set {
                object,
                field: field.into_owned(),
            },
            Wire::Edit { object, edit } => ShapePayload::Edit {
                object,
                edit: edit.into_owned(),
            },
            Wire::SetGroup { group, value } => ShapePayload::SetGroup {
                group,
                value: value.into_owned(),
            },
            Wire::Move { object, group } => ShapePayload::Move { object, group },
            Wire::Acquire {
                object,
                strong,
                ttl_micros,
            } => ShapePayload::Lease(LeaseAction::Acquire {
                object,
                strong,
                ttl_micros,
            }),
            Wire::Release { object } => ShapePayload::Lease(LeaseAction::Release { object }),
            Wire::Undo(id) => ShapePayload::Undo(id),
            Wire::Redo(id) => ShapePayload::Redo(id),
            Wire::Chat(text) => ShapePayload::Chat(text.into_owned()),
            Wire::Part { object, bytes } => ShapePayload::Part {
                object,
                bytes: bytes.into_owned(),
            },
            Wire::Assemble { object, parts } => ShapePayload::Assemble {
                object,
                parts: parts.into_owned(),
            },
            Wire::Member {
                member,
                expel,
                nonce,
            } => ShapePayload::Member(Box::new(Membership {
                member: PeerId(member),
                expel,
                nonce,
            })),
            Wire::Admit {
                key,
                grant_bytes,
                nonce,
            } => ShapePayload::Admit(Box::new(Admission {
                key: PeerId(key),
                grant_bytes,
                nonce,
            })),
        }
    }

    /// Whether version 1 has this variant: it ends at `Chat`.
    fn in_version_1(&self) -> bool {
        !matches!(
            self,
            Wire::Part { .. }
                | Wire::Assemble { .. }
                | Wire::CreateOwned { .. }
                | Wire::Member { .. }
                | Wire::Admit { .. }
        )
    }
}

impl<'a> Wire<'a, DataV1> {
    /// `p` in version 1's layout; `None` when it holds what version 1 cannot say (grids, or a
    /// variant that came later).
    fn version_1(p: &'a ShapePayload) -> Option<Wire<'a, DataV1>> {
        if let ShapePayload::Set { field, .. } = p
            && matches!(**field, Field::Grids(_))
        {
            return None;
        }
        let data = |d: &Arc<ObjectData>| v1::ObjectData::of(ObjectData::clone(d)).map(Box::new);
        Wire::of(p, data).filter(Wire::in_version_1)
    }
}

impl Serialize for ShapePayload {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let data = |d| Some(Data::Borrowed(d));
        let wire = Wire::of(self, data).expect("today's layout holds every payload");
        wire.serialize(s)
    }
}

impl<'de> Deserialize<'de> for ShapePayload {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<ShapePayload, D::Error> {
        let wire = Wire::<Data<'static>>::deserialize(d)?;
        Ok(wire.into_payload(Cow::into_owned))
    }
}

/// [`Wire`] as version 1 encoded it: decoding refuses the variants version 1 did not have.
struct WireV1(Wire<'static, DataV1>);

impl<'de> Deserialize<'de> for WireV1 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<WireV1, D::Error> {
        let wire = Wire::deserialize(d)?;
        if !wire.in_version_1() {
            return Err(serde::de::Error::custom(
                "a variant version 1 does not have",
            ));
        }
        Ok(WireV1(wire))
    }
}

impl From<WireV1> for ShapePayload {
    fn from(w: WireV1) -> ShapePayload {
        w.0.into_payload(|d| Arc::new((*d).into()))
    }
}

/// Decodes a payload in today's version or in version 1 (no validation beyond the encoding).
pub(super) fn decode(what: &'static str, bytes: &[u8]) -> Result<ShapePayload, ObjectError> {
    object_codec::decode_versioned::<_, WireV1>(what, bytes)
}

/// Whether `bytes`, which decoded to `p`, are its canonical encoding: today's, or version 1's
/// when they are in version 1.
pub(super) fn is_canonical(p: &ShapePayload, bytes: &[u8]) -> bool {
    if bytes.first() == Some(&object_codec::VERSION_1) {
        return Wire::version_1(p).is_some_and(|v1| object_codec::encode_version_1(&v1) == bytes);
    }
    crate::payload::encodes_to(p, bytes)
}

mod op_id {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::identity::OpId;

    pub fn serialize<S: Serializer>(id: &OpId, s: S) -> Result<S::Ok, S::Error> {
        id.0.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<OpId, D::Error> {
        <[u8; 32]>::deserialize(d).map(OpId)
    }
}
