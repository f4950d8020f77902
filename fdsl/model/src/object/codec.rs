//! The canonical binary form of objects and edits: one version byte, then the value in
//! `postcard` (varint integers, little-endian floats, fields in declaration order, no maps
//! with unordered keys), so equal values encode to equal bytes on every peer.
//!
//! Version 2 added [`ObjectData::grids`]; version 1 is still read (stores and files written
//! before it), through [`decode_versioned`] and the layouts in [`v1`], and never written.
//!
//! Decoding takes untrusted bytes: their length is bounded by [`MAX_ENCODED_BYTES`], every
//! sequence allocates at most what the remaining input can hold, trailing bytes are an error,
//! and the result is validated (formulas compiled, numbers checked) before it is returned.

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::edit::{CompiledEdit, Edit};
use super::{Object, ObjectData, ObjectError};
use crate::limits::MAX_ENCODED_BYTES;

/// The encoding's version, which encoders write; decoders read it and [`VERSION_1`].
pub const VERSION: u8 = 2;
/// The first version, before objects held grids.
pub const VERSION_1: u8 = 1;

/// An object as encoded: its description and its edits with their activity.
#[derive(serde::Serialize, serde::Deserialize)]
struct ObjectRecord {
    data: ObjectData,
    edits: Vec<(Edit, bool)>,
}

/// Layouts of version 1 that differ from today's: read into today's types.
pub mod v1 {
    use serde::{Deserialize, Serialize};

    use super::super::{Appearance, Edit, Geometry, Motion, Physics, Shared, Transform};

    /// [`super::ObjectData`] without grids.
    #[derive(Serialize, Deserialize)]
    pub struct ObjectData {
        name: String,
        geometry: Option<Geometry>,
        appearance: Shared<Appearance>,
        physics: Shared<Physics>,
        transform: Transform,
        motion: Option<Motion>,
    }

    impl ObjectData {
        /// `d` in version 1's layout; `None` when it holds grids, which version 1 cannot say.
        pub fn of(d: super::ObjectData) -> Option<ObjectData> {
            d.grids.is_empty().then_some(ObjectData {
                name: d.name,
                geometry: d.geometry,
                appearance: d.appearance,
                physics: d.physics,
                transform: d.transform,
                motion: d.motion,
            })
        }
    }

    impl From<ObjectData> for super::ObjectData {
        fn from(d: ObjectData) -> super::ObjectData {
            super::ObjectData {
                name: d.name,
                geometry: d.geometry,
                appearance: d.appearance,
                physics: d.physics,
                transform: d.transform,
                motion: d.motion,
                grids: Default::default(),
            }
        }
    }

    #[derive(Deserialize)]
    pub(super) struct ObjectRecord {
        data: ObjectData,
        edits: Vec<(Edit, bool)>,
    }

    impl From<ObjectRecord> for super::ObjectRecord {
        fn from(r: ObjectRecord) -> super::ObjectRecord {
            super::ObjectRecord {
                data: r.data.into(),
                edits: r.edits,
            }
        }
    }
}

/// Encodes any serialisable value of the object model, version byte first.
pub fn encode<T: Serialize>(value: &T) -> Vec<u8> {
    encode_as(VERSION, value)
}

fn encode_as<T: Serialize>(version: u8, value: &T) -> Vec<u8> {
    // Serialising plain data into a Vec cannot fail: no maps with non-string keys, no
    // sequences of unknown length.
    match postcard::to_extend(value, vec![version]) {
        Ok(v) => v,
        Err(e) => unreachable!("the object model always serialises: {e}"),
    }
}

/// Encodes a value in [`VERSION_1`] (a layout from [`v1`], or a type that did not change):
/// what checks that bytes written then are canonical.
pub fn encode_version_1<T: Serialize>(value: &T) -> Vec<u8> {
    encode_as(VERSION_1, value)
}

/// Decodes a value encoded by [`encode`] (no validation beyond the encoding), of a type whose
/// layout is the same in every version (one holding no [`ObjectData`]).
pub fn decode<T: DeserializeOwned>(what: &'static str, bytes: &[u8]) -> Result<T, ObjectError> {
    decode_versioned::<T, T>(what, bytes)
}

/// Decodes a value encoded by [`encode`] in the current version, or in [`VERSION_1`] as
/// `V1` (its layout then) converted.
pub fn decode_versioned<T: DeserializeOwned, V1: DeserializeOwned + Into<T>>(
    what: &'static str,
    bytes: &[u8],
) -> Result<T, ObjectError> {
    let fail = |reason: String| ObjectError::Decode { what, reason };
    if bytes.len() > MAX_ENCODED_BYTES {
        return Err(fail(format!(
            "{} bytes is more than the limit of {MAX_ENCODED_BYTES}",
            bytes.len()
        )));
    }
    let body = &bytes[1.min(bytes.len())..];
    let within = |e: postcard::Error| fail(format!("{e} (within {} bytes)", bytes.len()));
    let (value, rest) = match bytes.first() {
        None => return Err(fail("no bytes".into())),
        Some(&VERSION) => postcard::take_from_bytes::<T>(body).map_err(within)?,
        Some(&VERSION_1) => {
            let (old, rest) = postcard::take_from_bytes::<V1>(body).map_err(within)?;
            (old.into(), rest)
        }
        Some(&v) => {
            return Err(fail(format!(
                "version {v} is not supported (this reads {VERSION_1} and {VERSION})"
            )));
        }
    };
    if !rest.is_empty() {
        return Err(fail(format!(
            "{} bytes left over at offset {}",
            rest.len(),
            bytes.len() - rest.len()
        )));
    }
    Ok(value)
}

/// Encodes an object with its whole history.
pub fn encode_object(object: &Object) -> Vec<u8> {
    let record = ObjectRecord {
        data: object.data().clone(),
        edits: object
            .history()
            .entries()
            .iter()
            .map(|e| (e.edit.edit().clone(), e.active))
            .collect(),
    };
    encode(&record)
}

/// Decodes and validates an object.
pub fn decode_object(bytes: &[u8]) -> Result<Object, ObjectError> {
    let record: ObjectRecord = decode_versioned::<_, v1::ObjectRecord>("object", bytes)?;
    let mut object = Object::new(record.data)?;
    for (edit, active) in record.edits {
        let idx = object.apply(edit)?;
        if !active {
            object.undo(idx);
        }
    }
    object.prepare();
    Ok(object)
}

/// Encodes one edit.
pub fn encode_edit(edit: &Edit) -> Vec<u8> {
    encode(edit)
}

/// Decodes and validates one edit.
pub fn decode_edit(bytes: &[u8]) -> Result<CompiledEdit, ObjectError> {
    CompiledEdit::new(decode::<Edit>("edit", bytes)?)
}
