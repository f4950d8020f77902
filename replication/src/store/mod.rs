//! The crash-safe on-disk op store: an IO adapter around the core. The core never imports it.
//!
//! Ops are kept in a checksummed append-only file ([`record::RecordFile`]); an op is
//! acknowledged once [`OpStore::append`] returns, after `fsync`. Opening:
//!
//! - locks the store ([`lock`]): a second opener, in this process or another, gets
//!   [`OpenError::Locked`] naming the holder, and nothing is read or written;
//! - reads and checks every record (time in proportion to the file; it is never copied);
//! - refuses, with [`OpenError::Corrupt`] and without modifying the file, a damaged record
//!   that a valid record follows: that is damage, not a crash;
//! - sets a torn tail (a damaged last record, which a crash during an append leaves) aside in
//!   `<ops file>.torn-<offset>-<checksum>`, durably, and only then cuts it off; its path is in
//!   [`Recovery::torn_tail`].
//!
//! So a restarted peer loses no acknowledged op, accepts no torn one, and no byte that
//! opening removes from the file is lost.

pub mod lock;
pub mod record;

use std::ffi::OsString;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use crate::codec::DecodeError;
use crate::log::{InsertError, LOCAL_ORIGIN, Log};
use crate::op::{Op, VerifiedOp};
use crate::payload::Payload;
use crate::time::Timestamp;
use record::{RecordError, RecordFile, Recovery};

/// Why the store could not be opened or loaded.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The record file could not be read, or the lock or torn-tail file not written.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// Another open store (in this process or another) holds the store's lock. Nothing was
    /// read or written.
    #[error(
        "the store {} is in use by another sculpt process{}; close it first",
        .path.display(),
        in_parentheses(.holder)
    )]
    Locked {
        /// The store's op file.
        path: PathBuf,
        /// The holder as its lock file names it (`pid 1234, /path/to/exe`), if it could be read.
        holder: Option<String>,
    },
    /// A record before the end of the file is damaged (bad checksum or impossible length)
    /// while a valid record follows it: damage, not the torn tail of an interrupted append.
    /// The file was left exactly as it was.
    #[error(
        "the store {} is damaged: the record at byte {offset} fails its check, but a valid \
         record follows at byte {next_valid_offset}, so this is not an interrupted write; the \
         file was left as it was. Keep it, and restore the store from a backup or rejoin the \
         session with a new store",
        .path.display()
    )]
    Corrupt {
        /// The store's op file.
        path: PathBuf,
        /// Byte offset in the file of the first damaged record.
        offset: u64,
        /// Byte offset of the first valid record after it.
        next_valid_offset: u64,
    },
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

/// ` (holder)`, or nothing.
fn in_parentheses(holder: &Option<String>) -> String {
    holder
        .as_ref()
        .map_or_else(String::new, |holder| format!(" ({holder})"))
}

/// `path` with `suffix` appended to its file name: a sibling file of the store.
fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let mut name = OsString::from(path.as_os_str());
    name.push(suffix);
    PathBuf::from(name)
}

/// An append-only store of encoded ops, locked for as long as it lives.
#[derive(Debug)]
pub struct OpStore<P> {
    file: RecordFile,
    payload: PhantomData<P>,
}

impl<P: Payload> OpStore<P> {
    /// Opens (or creates) the store at `path`, locking it and setting a torn tail aside before
    /// cutting it off (see the [module docs](self)); returns the stored ops in append order
    /// (not yet signature-checked) and what recovery did.
    ///
    /// # Errors
    ///
    /// [`OpenError::Locked`] while another [`OpStore`] has it open; [`OpenError::Corrupt`] for
    /// a damaged record in the middle (the file is not modified); [`OpenError::Record`] for IO
    /// errors and files that are not stores; [`OpenError::Decode`] for a record that is not an
    /// op.
    pub fn open(path: &Path) -> Result<(Self, Vec<Op<P>>, Recovery), OpenError> {
        Self::open_with_limit(path, record::MAX_STORE_BYTES)
    }

    /// [`OpStore::open`] for a store that may grow to `max_bytes` (at most
    /// [`record::MAX_STORE_BYTES`]; a small device may want less).
    pub fn open_with_limit(
        path: &Path,
        max_bytes: u64,
    ) -> Result<(Self, Vec<Op<P>>, Recovery), OpenError> {
        let (file, records, recovery) = RecordFile::open_with_limit(path, max_bytes)?;
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

    /// Opens the store and inserts every stored op into `log`, checking signatures for the
    /// log's session (in batches; [`OpenError::BadSignature`] names the first record that
    /// fails).
    pub fn open_into(
        path: &Path,
        now: Timestamp,
        log: &mut Log<P>,
    ) -> Result<(Self, Recovery), OpenError> {
        let (store, ops, recovery) = Self::open(path)?;
        if let Some(record_idx) = Op::first_unsigned(&ops, &log.session_id()) {
            return Err(OpenError::BadSignature { record_idx });
        }
        for (record_idx, op) in ops.into_iter().enumerate() {
            log.insert(now, VerifiedOp::trusted(op), LOCAL_ORIGIN)
                .map_err(|error| OpenError::Refused { record_idx, error })?;
        }
        Ok((store, recovery))
    }

    /// Like [`OpStore::open_into`], but without checking signatures again: for a store that
    /// only this peer wrote, where every op was verified before it was appended. Record
    /// checksums still catch corruption; a file someone else could write needs
    /// [`OpStore::open_into`] (about 11 µs per op more on this project's machines, with signatures
    /// checked in batches).
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

    /// Appends synced since the store was opened (one `fsync` each).
    pub fn n_syncs(&self) -> u64 {
        self.file.n_syncs()
    }

    /// Bytes in the store's file.
    pub fn len_bytes(&self) -> u64 {
        self.file.len_bytes()
    }

    /// Appends ops in one write and syncs them to disk (one `fsync` for the lot); they are
    /// acknowledged when this returns `Ok`. A store that would pass its limit refuses the
    /// whole append ([`RecordError::Full`]) and keeps everything it held.
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
