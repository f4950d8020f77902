//! A checksummed append-only record file with `fsync`: the storage primitive under
//! [`super::OpStore`].
//!
//! Layout: the header `SCULPTOPS` + format version byte, then records, each
//! `[u32 LE body length][16-byte blake3 checksum of length and body][body]`.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::lock::StoreLock;
use super::{OpenError, sibling};
use crate::op::MAX_OP_BYTES;

/// Magic bytes that open the file.
pub const MAGIC: &[u8; 9] = b"SCULPTOPS";
/// The record file format version.
pub const RECORD_FORMAT_VERSION: u8 = 1;
/// Largest record body accepted.
pub const MAX_RECORD_BYTES: usize = MAX_OP_BYTES;
/// Largest store file: appends that would pass it are refused ([`RecordError::Full`]), so a
/// store always opens at every size it accepted (4 GiB).
pub const MAX_STORE_BYTES: u64 = 4 * 1024 * 1024 * 1024;
/// Bytes of checksum per record.
pub const CHECKSUM_BYTES: usize = 16;
/// Bytes of the cut bytes' blake3 hash, in hex, in a torn-tail file's name.
const TORN_NAME_HASH_BYTES: usize = 8;

const HEADER_BYTES: usize = MAGIC.len() + 1;
const RECORD_HEAD_BYTES: usize = 4 + CHECKSUM_BYTES;

// Every op a log accepts fits in a store: a log's bytes and one record head per op.
const _: () = assert!(
    crate::log::MAX_LOG_BYTES
        + crate::op::MAX_LOG_OPS as u64 * RECORD_HEAD_BYTES as u64
        + HEADER_BYTES as u64
        <= MAX_STORE_BYTES
);

/// Why the record file failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// An IO error, with the path.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file does not start with the header (not a store, or another version).
    #[error("{0}: not a sculpt op store of format {RECORD_FORMAT_VERSION}")]
    BadHeader(PathBuf),
    /// The file is larger than its limit ([`MAX_STORE_BYTES`]): not a file this store wrote.
    #[error("{0}: larger than the store's limit")]
    TooLarge(PathBuf),
    /// Appending would take the file past its limit ([`MAX_STORE_BYTES`]); nothing was
    /// written, and everything stored before is kept.
    #[error(
        "{}: the store is full ({size} bytes; {needed} more would pass its limit of {limit})",
        .path.display()
    )]
    Full {
        /// The file.
        path: PathBuf,
        /// Its size now.
        size: u64,
        /// The bytes the refused append needed.
        needed: u64,
        /// The store's limit.
        limit: u64,
    },
    /// A record to append is larger than [`MAX_RECORD_BYTES`].
    #[error("record of {0} bytes, over the limit {MAX_RECORD_BYTES}")]
    RecordTooLarge(usize),
}

/// What opening found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Recovery {
    /// Records accepted.
    pub n_records: usize,
    /// Bytes of torn tail cut off (0 after a clean shutdown).
    pub n_truncated_bytes: u64,
    /// The file that holds the cut bytes, byte for byte (written and synced before the cut):
    /// `<ops file>.torn-<offset>-<hash>`, where `offset` is where the file was cut and `hash`
    /// starts the cut bytes' blake3 hash. `None` when nothing was cut, or only a partial
    /// header (a prefix of [`MAGIC`], which holds nothing to keep). Usually at most one record;
    /// more when a multi-record append was torn.
    pub torn_tail: Option<PathBuf>,
}

/// An open record file, positioned at its end, and its lock.
#[derive(Debug)]
pub struct RecordFile {
    file: File,
    path: PathBuf,
    /// End of the last durable record.
    end: u64,
    /// The largest size the file may reach (at most [`MAX_STORE_BYTES`]).
    max_bytes: u64,
    /// Appends synced since the file was opened.
    n_syncs: u64,
    /// Held while the file is open; declared last so that it is released after the file is
    /// closed.
    _lock: StoreLock,
}

fn checksum(body: &[u8]) -> [u8; CHECKSUM_BYTES] {
    let mut hasher = blake3::Hasher::new();
    hasher.update(&(body.len() as u32).to_le_bytes());
    hasher.update(body);
    let mut out = [0u8; CHECKSUM_BYTES];
    out.copy_from_slice(&hasher.finalize().as_bytes()[..CHECKSUM_BYTES]);
    out
}

fn header() -> [u8; HEADER_BYTES] {
    let mut header = [0u8; HEADER_BYTES];
    header[..MAGIC.len()].copy_from_slice(MAGIC);
    header[MAGIC.len()] = RECORD_FORMAT_VERSION;
    header
}

/// The body of the record starting at `at` in `bytes`, if one is there: its length is at most
/// [`MAX_RECORD_BYTES`], its body fits in `bytes`, and its checksum matches.
fn record_at(bytes: &[u8], at: usize) -> Option<&[u8]> {
    let head = bytes.get(at..at.checked_add(RECORD_HEAD_BYTES)?)?;
    let mut len_bytes = [0u8; 4];
    len_bytes.copy_from_slice(&head[..4]);
    let len = u32::from_le_bytes(len_bytes) as usize;
    if len > MAX_RECORD_BYTES {
        return None;
    }
    let start = at + RECORD_HEAD_BYTES;
    let body = bytes.get(start..start + len)?;
    (head[4..] == checksum(body)).then_some(body)
}

/// Splits the whole file's `bytes` (header included) into the valid records after the header;
/// returns them and where the valid prefix ends. Parsing stops at the first short, oversized
/// or mismatching record.
fn parse(bytes: &[u8]) -> (Vec<Vec<u8>>, usize) {
    let mut records = Vec::new();
    let mut at = HEADER_BYTES;
    while let Some(body) = record_at(bytes, at) {
        records.push(body.to_vec());
        at += RECORD_HEAD_BYTES + body.len();
    }
    (records, at)
}

/// The first position after `bad` where a valid record starts, if any. Every position up to
/// the end of the file is tried (the scan is bounded by the file's length): a position costs
/// O(1) unless its length field is possible, and then one checksum of at most
/// [`MAX_RECORD_BYTES`], so the scan is O(bytes after `bad`). After a torn append that is at
/// most a record or a batch; in the middle of a file the next valid record is usually within
/// a record or two.
fn first_record_after(bytes: &[u8], bad: usize) -> Option<usize> {
    let last_start = bytes.len().checked_sub(RECORD_HEAD_BYTES)?;
    (bad + 1..=last_start).find(|&at| record_at(bytes, at).is_some())
}

/// Makes `path`'s directory entry durable by syncing its directory.
fn sync_parent_dir(path: &Path) -> std::io::Result<()> {
    match path.parent().filter(|dir| !dir.as_os_str().is_empty()) {
        Some(dir) => File::open(dir)?.sync_all(),
        None => File::open(".")?.sync_all(),
    }
}

/// Writes `tail`, the bytes of the store at `path` from `offset` on, to
/// `<ops file>.torn-<offset>-<hash>` and makes it durable (file and directory entry); returns
/// its path. The bytes go to a `.partial` file first and are renamed into place once synced,
/// so a file of the final name is always whole; since the name carries the bytes' hash, one
/// left by an earlier open that crashed before it cut the tail holds the same bytes and is
/// replaced by an equal copy.
fn set_tail_aside(path: &Path, offset: usize, tail: &[u8]) -> Result<PathBuf, RecordError> {
    let hash = blake3::hash(tail);
    let hash_hex = crate::identity::hex(&hash.as_bytes()[..TORN_NAME_HASH_BYTES]);
    let torn = sibling(path, &format!(".torn-{offset}-{hash_hex}"));
    let partial = sibling(&torn, ".partial");
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| RecordError::Io { path, source }
    };
    let mut file = OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .open(&partial)
        .map_err(io(&partial))?;
    file.write_all(tail)
        .and_then(|()| file.sync_all())
        .map_err(io(&partial))?;
    drop(file);
    std::fs::rename(&partial, &torn).map_err(io(&torn))?;
    sync_parent_dir(&torn).map_err(io(&torn))?;
    Ok(torn)
}

impl RecordFile {
    /// Opens or creates the file after taking its lock ([`super::lock`]); if its last record
    /// is torn, sets it aside and cuts it off (and syncs the cut); returns the valid records.
    ///
    /// # Errors
    ///
    /// [`OpenError::Locked`] if the store is open elsewhere, [`OpenError::Corrupt`] if a
    /// damaged record has a valid one after it (the file is then not modified), and
    /// [`OpenError::Record`] for IO errors, files over [`MAX_STORE_BYTES`] and files that do
    /// not start with the header (or a prefix of it).
    pub fn open(path: &Path) -> Result<(Self, Vec<Vec<u8>>, Recovery), OpenError> {
        Self::open_with_limit(path, MAX_STORE_BYTES)
    }

    /// [`RecordFile::open`] for a file that may grow to `max_bytes` (at most
    /// [`MAX_STORE_BYTES`]): a file over it is refused, an append that would pass it is too.
    pub fn open_with_limit(
        path: &Path,
        max_bytes: u64,
    ) -> Result<(Self, Vec<Vec<u8>>, Recovery), OpenError> {
        let max_bytes = max_bytes.min(MAX_STORE_BYTES);
        let lock = StoreLock::acquire(path)?;
        let io = |source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(io)?;
        let mut bytes = Vec::new();
        (&mut file)
            .take(max_bytes + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        if bytes.len() as u64 > max_bytes {
            return Err(RecordError::TooLarge(path.to_path_buf()).into());
        }
        let mut store = Self {
            file,
            path: path.to_path_buf(),
            end: HEADER_BYTES as u64,
            max_bytes,
            n_syncs: 0,
            _lock: lock,
        };
        if bytes.len() < HEADER_BYTES {
            return store.start_after_partial_header(&bytes);
        }
        if bytes[..HEADER_BYTES] != header() {
            return Err(RecordError::BadHeader(path.to_path_buf()).into());
        }
        let (records, end) = parse(&bytes);
        let torn_tail = if end < bytes.len() {
            Some(store.cut_torn_tail(&bytes, end)?)
        } else {
            None
        };
        store.file.seek(SeekFrom::Start(end as u64)).map_err(io)?;
        store.end = end as u64;
        let recovery = Recovery {
            n_records: records.len(),
            n_truncated_bytes: (bytes.len() - end) as u64,
            torn_tail,
        };
        Ok((store, records, recovery))
    }

    /// Handles a file shorter than the header: new, or a crash while writing the header, when
    /// nothing was ever acknowledged; anything else is not a store and is left alone.
    fn start_after_partial_header(
        mut self,
        bytes: &[u8],
    ) -> Result<(Self, Vec<Vec<u8>>, Recovery), OpenError> {
        if bytes[..] != header()[..bytes.len()] {
            return Err(RecordError::BadHeader(self.path.clone()).into());
        }
        self.write_header()?;
        let recovery = Recovery {
            n_records: 0,
            n_truncated_bytes: bytes.len() as u64,
            torn_tail: None,
        };
        Ok((self, Vec::new(), recovery))
    }

    /// Given the whole file's `bytes`, whose valid records end at `end`: refuses a damaged
    /// record that a valid one follows; otherwise the damage is a torn tail, which is set
    /// aside, then cut off and synced. Returns the set-aside file.
    fn cut_torn_tail(&mut self, bytes: &[u8], end: usize) -> Result<PathBuf, OpenError> {
        assert!(
            end < bytes.len(),
            "a torn tail needs bytes after the valid records"
        );
        if let Some(next) = first_record_after(bytes, end) {
            return Err(OpenError::Corrupt {
                path: self.path.clone(),
                offset: end as u64,
                next_valid_offset: next as u64,
            });
        }
        let torn = set_tail_aside(&self.path, end, &bytes[end..])?;
        let io = |source| RecordError::Io {
            path: self.path.clone(),
            source,
        };
        self.file.set_len(end as u64).map_err(io)?;
        self.file.sync_all().map_err(io)?;
        Ok(torn)
    }

    fn write_header(&mut self) -> Result<(), RecordError> {
        let io = |source| RecordError::Io {
            path: self.path.clone(),
            source,
        };
        self.file.set_len(0).map_err(io)?;
        self.file.seek(SeekFrom::Start(0)).map_err(io)?;
        self.file.write_all(&header()).map_err(io)?;
        self.file.sync_all().map_err(io)?;
        // Make the new file's directory entry durable too.
        sync_parent_dir(&self.path).map_err(io)?;
        Ok(())
    }

    /// Appends synced since the file was opened: one per successful [`RecordFile::append`].
    pub fn n_syncs(&self) -> u64 {
        self.n_syncs
    }

    /// Bytes in the file: the header and every durable record.
    pub fn len_bytes(&self) -> u64 {
        self.end
    }

    /// Appends records in one write and syncs; they are durable when this returns `Ok`.
    /// Appending nothing writes and syncs nothing. An append that would take the file past
    /// its limit is refused whole ([`RecordError::Full`]) and writes nothing.
    pub fn append(&mut self, bodies: &[&[u8]]) -> Result<(), RecordError> {
        let buf = encode_records(bodies)?;
        self.write_durably(&buf, buf.len(), &mut || {})
    }

    /// Like [`RecordFile::append`], but calls `mid` after writing the first `split_at` bytes,
    /// so a test can have the writer killed inside a record.
    #[cfg(test)]
    pub(crate) fn append_split(
        &mut self,
        bodies: &[&[u8]],
        split_at: usize,
        mid: &mut dyn FnMut(),
    ) -> Result<(), RecordError> {
        let buf = encode_records(bodies)?;
        self.write_durably(&buf, split_at.min(buf.len()), mid)
    }

    fn write_durably(
        &mut self,
        buf: &[u8],
        split_at: usize,
        mid: &mut dyn FnMut(),
    ) -> Result<(), RecordError> {
        if buf.is_empty() {
            return Ok(());
        }
        if self.end + buf.len() as u64 > self.max_bytes {
            return Err(RecordError::Full {
                path: self.path.clone(),
                size: self.end,
                needed: buf.len() as u64,
                limit: self.max_bytes,
            });
        }
        let io = |source| RecordError::Io {
            path: self.path.clone(),
            source,
        };
        let (head, tail) = buf.split_at(split_at);
        let written = self
            .file
            .write_all(head)
            .map(|()| mid())
            .and_then(|()| self.file.write_all(tail))
            .and_then(|()| self.file.sync_data());
        if let Err(source) = written {
            // Cut a partial write off so later appends never land behind a torn record.
            let _ = self
                .file
                .set_len(self.end)
                .and_then(|()| self.file.seek(SeekFrom::Start(self.end)));
            return Err(io(source));
        }
        self.end += buf.len() as u64;
        self.n_syncs += 1;
        Ok(())
    }
}

fn encode_records(bodies: &[&[u8]]) -> Result<Vec<u8>, RecordError> {
    let mut buf = Vec::new();
    for body in bodies {
        if body.len() > MAX_RECORD_BYTES {
            return Err(RecordError::RecordTooLarge(body.len()));
        }
        buf.extend_from_slice(&(body.len() as u32).to_le_bytes());
        buf.extend_from_slice(&checksum(body));
        buf.extend_from_slice(body);
    }
    Ok(buf)
}
