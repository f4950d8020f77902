//! The canonical binary form of objects and edits: one version byte, then the value in
//! `postcard` (varint integers, little-endian floats, fields in declaration order, no maps
//! with unordered keys), so equal values encode to equal bytes on every peer.
//!
//! Decoding takes untrusted bytes: their length is bounded by [`MAX_ENCODED_BYTES`], every
//! sequence allocates at most what the remaining input can hold, trailing bytes are an error,
//! and the result is validated (formulas compiled, numbers checked) before it is returned.

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::edit::{CompiledEdit, Edit};
use super::{Object, ObjectData, ObjectError};
use crate::limits::MAX_ENCODED_BYTES;

/// The encoding's version; decoders refuse others.
pub const VERSION: u8 = 1;

/// An object as encoded: its description and its edits with their activity.
#[derive(serde::Serialize, serde::Deserialize)]
struct ObjectRecord {
    data: ObjectData,
    edits: Vec<(Edit, bool)>,
}

/// Encodes any serialisable value of the object model, version byte first.
pub fn encode<T: Serialize>(value: &T) -> Vec<u8> {
    let out = vec![VERSION];
    // Serialising plain data into a Vec cannot fail: no maps with non-string keys, no
    // sequences of unknown length.
    match postcard::to_extend(value, out) {
        Ok(v) => v,
        Err(e) => unreachable!("the object model always serialises: {e}"),
    }
}

/// Decodes a value encoded by [`encode`] (no validation beyond the encoding).
pub fn decode<T: DeserializeOwned>(what: &'static str, bytes: &[u8]) -> Result<T, ObjectError> {
    let fail = |reason: String| ObjectError::Decode { what, reason };
    if bytes.len() > MAX_ENCODED_BYTES {
        return Err(fail(format!(
            "{} bytes is more than the limit of {MAX_ENCODED_BYTES}",
            bytes.len()
        )));
    }
    match bytes.first() {
        None => return Err(fail("no bytes".into())),
        Some(&VERSION) => {}
        Some(&v) => {
            return Err(fail(format!(
                "version {v} is not supported (this is {VERSION})"
            )));
        }
    }
    let (value, rest) = postcard::take_from_bytes::<T>(&bytes[1..])
        .map_err(|e| fail(format!("{e} (within {} bytes)", bytes.len())))?;
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
    let record: ObjectRecord = decode("object", bytes)?;
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
    CompiledEdit::new(decode("edit", bytes)?)
}
