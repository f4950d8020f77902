//! Changes too large for one op, authored in parts.
//!
//! [`split`] turns a `Create` or `Set` whose encoding is longer than [`MAX_PAYLOAD_BYTES`]
//! into `Part` ops of at most [`MAX_PART_BYTES`] each and one `Assemble` that names them by
//! blake3 hash, in order. The author authors them in that order, so the parts are in the
//! `Assemble`'s causal past and every peer folds them first.
//!
//! The fold (`HeldParts`) keeps each object's parts by hash until an `Assemble` of that
//! object consumes them. An `Assemble` changes nothing when a part it names is not held (never
//! sent, undone, hidden by a delete, or already consumed), or when the bytes are not the
//! canonical encoding of a valid `Create` or `Set` of its own object. Since a part is consumed
//! by the first `Assemble` that names it, a small `Assemble` op cannot make every peer decode
//! the same megabytes again and again: what a fold decodes is bounded by the part bytes it
//! holds. A refold of the object decodes again only when the change has left the small cache
//! of recent assemblies ([`MAX_CACHED_ASSEMBLIES`]).

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use model::object::codec as object_codec;

use super::{ShapePayload, wire};
use crate::identity::OpId;
use crate::payload::{MAX_PAYLOAD_BYTES, Payload};

/// Longest change authored in parts, in bytes of its encoding (a mesh of about 170 000
/// triangles, or eight grids of 64³ samples).
pub const MAX_ASSEMBLED_BYTES: usize = 4 << 20;
/// Most bytes of a change one `Part` carries (the rest of its op is the object id and the
/// encoding's framing).
pub const MAX_PART_BYTES: usize = MAX_PAYLOAD_BYTES - 32;
/// Most parts one `Assemble` names.
pub const MAX_PARTS: usize = MAX_ASSEMBLED_BYTES.div_ceil(MAX_PART_BYTES);
/// Recently assembled changes kept per scene, so that refolding an object does not decode its
/// large change again.
pub const MAX_CACHED_ASSEMBLIES: usize = 8;

const _: () = assert!(MAX_PARTS * 32 + 32 <= MAX_PAYLOAD_BYTES);

/// A part's blake3 hash.
pub type PartHash = [u8; 32];

/// Why a change cannot be authored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SplitError {
    /// Longer than [`MAX_ASSEMBLED_BYTES`].
    #[error(
        "the change takes {n_bytes} bytes, more than the {MAX_ASSEMBLED_BYTES} a change \
         authored in parts may take"
    )]
    TooLarge {
        /// Its encoded length.
        n_bytes: usize,
    },
    /// Longer than one op and not a `Create` or `Set`.
    #[error(
        "a {kind} of {n_bytes} bytes does not fit in one op, and only creations and property changes are authored in parts"
    )]
    NotSplittable {
        /// What it is.
        kind: &'static str,
        /// Its encoded length.
        n_bytes: usize,
    },
}

/// The ops that author `change`: itself when it fits in one op, else its `Part`s and the
/// `Assemble` that names them, to be authored in this order.
pub fn split(change: ShapePayload) -> Result<Vec<ShapePayload>, SplitError> {
    let mut bytes = Vec::new();
    change.encode(&mut bytes);
    if bytes.len() <= MAX_PAYLOAD_BYTES {
        return Ok(vec![change]);
    }
    let n_bytes = bytes.len();
    let object = match &change {
        ShapePayload::Create { object, .. } | ShapePayload::Set { object, .. } => *object,
        other => {
            return Err(SplitError::NotSplittable {
                kind: kind(other),
                n_bytes,
            });
        }
    };
    if n_bytes > MAX_ASSEMBLED_BYTES {
        return Err(SplitError::TooLarge { n_bytes });
    }
    let mut ops = Vec::with_capacity(n_bytes.div_ceil(MAX_PART_BYTES) + 1);
    let mut hashes = Vec::with_capacity(ops.capacity());
    for piece in bytes.chunks(MAX_PART_BYTES) {
        hashes.push(part_hash(piece));
        ops.push(ShapePayload::Part {
            object,
            bytes: piece.to_vec(),
        });
    }
    ops.push(ShapePayload::Assemble {
        object,
        parts: hashes,
    });
    Ok(ops)
}

/// A payload's kind in words.
fn kind(p: &ShapePayload) -> &'static str {
    match p {
        ShapePayload::Create { .. } => "creation",
        ShapePayload::Set { .. } => "property change",
        ShapePayload::Edit { .. } => "sculpting edit",
        ShapePayload::Chat(_) => "chat message",
        _ => "change",
    }
}

/// The hash by which an `Assemble` names a part of these bytes.
pub fn part_hash(bytes: &[u8]) -> PartHash {
    *blake3::hash(bytes).as_bytes()
}

/// What decoding checks of a `Part`: it holds some bytes, at most [`MAX_PART_BYTES`].
pub(super) fn check_part(bytes: &[u8]) -> Result<(), String> {
    if bytes.is_empty() || bytes.len() > MAX_PART_BYTES {
        return Err(format!(
            "a part holds {} bytes; it must hold 1 to {MAX_PART_BYTES}",
            bytes.len()
        ));
    }
    Ok(())
}

/// What decoding checks of an `Assemble`: it names 1 to [`MAX_PARTS`] parts.
pub(super) fn check_assemble(hashes: &[PartHash]) -> Result<(), String> {
    if hashes.is_empty() || hashes.len() > MAX_PARTS {
        return Err(format!(
            "an assembly names {} parts; it must name 1 to {MAX_PARTS}",
            hashes.len()
        ));
    }
    Ok(())
}

/// The tag of `CreateOwned` (a `Create` with its counter) in the payload's encoding: what a
/// part that starts a creation holds after the encoding's version.
const CREATE_OWNED_TAG: u64 = 13;

/// Whether a `Part` of `object` by `author` holding `bytes` starts the encoding of a `Create`
/// of `object` with a counter that makes the id `author`'s ([`super::may_create`]): the first
/// part of an object created in parts, which creates it as far as leases go
/// ([`Payload::creates`]). Only the head is read (version, tag, id and counter).
pub(super) fn starts_create(author: &crate::PeerId, object: u64, bytes: &[u8]) -> bool {
    let mut r = crate::codec::Reader::new(bytes);
    let head = (|| {
        let version = r.u8().ok()?;
        let tag = r.varint().ok()?;
        let id = r.varint().ok()?;
        let counter = u32::try_from(r.varint().ok()?).ok()?;
        (version == object_codec::VERSION && tag == CREATE_OWNED_TAG && id == object)
            .then_some(counter)
    })();
    head.is_some_and(|counter| super::may_create(*author, object, Some(counter)))
}

/// The change `bytes` encode, when they are the canonical encoding of a valid `Create` or
/// `Set` of `object`.
fn decode_change(object: u64, bytes: &[u8]) -> Option<ShapePayload> {
    if bytes.len() > MAX_ASSEMBLED_BYTES {
        return None;
    }
    let change = wire::decode("assembled change", bytes).ok()?;
    let for_object = match &change {
        ShapePayload::Create { object: o, .. } | ShapePayload::Set { object: o, .. } => {
            *o == object
        }
        _ => false,
    };
    (for_object && change.validate().is_ok() && crate::payload::encodes_to(&change, bytes))
        .then_some(change)
}

/// The parts a scene's fold holds, per object, and the changes recently assembled.
#[derive(Clone, Debug, Default)]
pub(crate) struct HeldParts {
    by_object: BTreeMap<u64, BTreeMap<PartHash, Arc<[u8]>>>,
    /// The change each recent `Assemble` op decoded to (`None`: not a valid change).
    assembled: VecDeque<(OpId, Option<Arc<ShapePayload>>)>,
}

/// The snapshot form of [`HeldParts`]: per object, its parts' bytes in hash order.
pub(crate) type EncodedParts = Vec<(u64, Vec<Vec<u8>>)>;

impl PartialEq for HeldParts {
    /// Equal when they hold the same parts (the cache is not state).
    fn eq(&self, other: &Self) -> bool {
        self.by_object == other.by_object
    }
}

impl HeldParts {
    /// Keeps a folded part of `object`.
    pub(crate) fn hold(&mut self, object: u64, bytes: &[u8]) {
        self.by_object
            .entry(object)
            .or_default()
            .entry(part_hash(bytes))
            .or_insert_with(|| bytes.into());
    }

    /// The objects that hold parts.
    pub(crate) fn objects(&self) -> impl Iterator<Item = u64> + '_ {
        self.by_object.keys().copied()
    }

    /// The parts `object` holds, in hash order.
    pub(crate) fn of_object(&self, object: u64) -> Vec<&[u8]> {
        (self.by_object.get(&object).into_iter())
            .flat_map(|parts| parts.values().map(|bytes| &bytes[..]))
            .collect()
    }

    /// Forgets the parts of `object` (its fold starts again).
    pub(crate) fn forget(&mut self, object: u64) {
        self.by_object.remove(&object);
    }

    /// The change the `Assemble` op `id` of `object` names, consuming its parts; `None`
    /// (consuming nothing) when a part is not held, and `None` (consuming them) when they do
    /// not make a valid change of `object`.
    pub(crate) fn assemble(
        &mut self,
        id: OpId,
        object: u64,
        hashes: &[PartHash],
    ) -> Option<Arc<ShapePayload>> {
        let held = self.by_object.get_mut(&object)?;
        if !hashes.iter().all(|h| held.contains_key(h)) {
            return None;
        }
        let cached = self.assembled.iter().find(|(op, _)| *op == id);
        let change = match cached {
            Some((_, change)) => change.clone(),
            None => {
                let n_bytes: usize = hashes.iter().map(|h| held[h].len()).sum();
                let change = if n_bytes <= MAX_ASSEMBLED_BYTES {
                    let mut bytes = Vec::with_capacity(n_bytes);
                    for h in hashes {
                        bytes.extend_from_slice(&held[h]);
                    }
                    decode_change(object, &bytes).map(Arc::new)
                } else {
                    None
                };
                if self.assembled.len() == MAX_CACHED_ASSEMBLIES {
                    self.assembled.pop_front();
                }
                self.assembled.push_back((id, change.clone()));
                change
            }
        };
        for h in hashes {
            held.remove(h);
        }
        if held.is_empty() {
            self.by_object.remove(&object);
        }
        change
    }

    /// The canonical form the scene hash hashes (equal holdings encode equal).
    pub(crate) fn encode(&self) -> EncodedParts {
        self.by_object
            .iter()
            .map(|(object, parts)| (*object, parts.values().map(|b| b.to_vec()).collect()))
            .collect()
    }
}
