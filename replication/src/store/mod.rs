//! The crash-safe on-disk op store: an IO adapter around the core. The core never imports it.
//!
//! Ops are kept in a checksummed append-only file ([`record::RecordFile`]); an op is
//! acknowledged once [`OpStore::append`] returns, after `fsync`. On open, a torn or corrupt
//! tail (from a crash mid-write) is detected by length and checksum and cut off, so a
//! restarted peer loses no acknowledged op and accepts no torn one.

pub mod record;

use std::marker::PhantomData;
use std::path::Path;

use crate::codec::DecodeError;
use crate::log::{InsertError, LOCAL_ORIGIN, Log};
use crate::op::{Op, VerifiedOp};
use crate::payload::Payload;
use crate::time::Timestamp;
use record::{RecordError, RecordFile, Recovery};

/// Why the store could not be opened or loaded.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The record file could not be read.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// A record passed its checksum but is not an op this build can decode.
    #[error("record {record_idx} is not a valid op: {error}")]
    Decode {
        /// Index of the record in the file.
        record_idx: usize,
        /// The decode error.
        error: DecodeError,
    },
    /// A stored op's signature does not verify.
    #[error("record {record_idx} has a bad signature")]
    BadSignature {
        /// Index of the record in the file.
        record_idx: usize,
    },
    /// The log refused a stored op.
    #[error("record {record_idx} refused by the log: {error}")]
    Refused {
        /// Index of the record in the file.
        record_idx: usize,
        /// Why.
        error: InsertError,
    },
}

/// An append-only store of encoded ops.
#[derive(Debug)]
pub struct OpStore<P> {
    file: RecordFile,
    payload: PhantomData<P>,
}

impl<P: Payload> OpStore<P> {
    /// Opens (or creates) the store at `path`, cutting off a torn tail; returns the stored ops
    /// in append order (not yet signature-checked) and what recovery did.
    pub fn open(path: &Path) -> Result<(Self, Vec<Op<P>>, Recovery), OpenError> {
        let (file, records, recovery) = RecordFile::open(path)?;
        let ops = records
            .iter()
            .enumerate()
            .map(|(record_idx, bytes)| {
                Op::decode(bytes).map_err(|error| OpenError::Decode { record_idx, error })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok((
            Self {
                file,
                payload: PhantomData,
            },
            ops,
            recovery,
        ))
    }

    /// Opens the store and inserts every stored op into `log`, checking signatures.
    pub fn open_into(
        path: &Path,
        now: Timestamp,
        log: &mut Log<P>,
    ) -> Result<(Self, Recovery), OpenError> {
        let (store, ops, recovery) = Self::open(path)?;
        for (record_idx, op) in ops.into_iter().enumerate() {
            let op = op
                .into_verified()
                .map_err(|_| OpenError::BadSignature { record_idx })?;
            log.insert(now, op, LOCAL_ORIGIN)
                .map_err(|error| OpenError::Refused { record_idx, error })?;
        }
        Ok((store, recovery))
    }

    /// Like [`OpStore::open_into`], but without checking signatures again: for a store that
    /// only this peer wrote, where every op was verified before it was appended. Record
    /// checksums still catch corruption; a file someone else could write needs
    /// [`OpStore::open_into`] (about 50 µs per op more on this project's machines).
    pub fn open_into_trusted(
        path: &Path,
        now: Timestamp,
        log: &mut Log<P>,
    ) -> Result<(Self, Recovery), OpenError> {
        let (store, ops, recovery) = Self::open(path)?;
        for (record_idx, op) in ops.into_iter().enumerate() {
            log.insert(now, VerifiedOp::trusted(op), LOCAL_ORIGIN)
                .map_err(|error| OpenError::Refused { record_idx, error })?;
        }
        Ok((store, recovery))
    }

    /// Appends ops and syncs them to disk; they are acknowledged when this returns `Ok`.
    pub fn append(&mut self, ops: &[&Op<P>]) -> Result<(), RecordError> {
        let records: Vec<&[u8]> = ops.iter().map(|op| op.encoded()).collect();
        self.file.append(&records)
    }

    /// Appends with `mid` called part-way through the write, so a test's kill lands
    /// mid-record.
    #[cfg(test)]
    pub(crate) fn append_split(
        &mut self,
        ops: &[&Op<P>],
        split_at: usize,
        mid: &mut dyn FnMut(),
    ) -> Result<(), RecordError> {
        let records: Vec<&[u8]> = ops.iter().map(|op| op.encoded()).collect();
        self.file.append_split(&records, split_at, mid)
    }
}

#[cfg(test)]
mod tests;
