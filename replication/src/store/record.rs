//! A checksummed append-only record file with `fsync`: the storage primitive under
//! [`super::OpStore`].
//!
//! Layout: the header `SCULPTOPS` + format version byte, then records, each
//! `[u32 LE body length][16-byte blake3 checksum of length and body][body]`.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::op::MAX_OP_BYTES;

/// Magic bytes that open the file.
pub const MAGIC: &[u8; 9] = b"SCULPTOPS";
/// The record file format version.
pub const RECORD_FORMAT_VERSION: u8 = 1;
/// Largest record body accepted.
pub const MAX_RECORD_BYTES: usize = MAX_OP_BYTES;
/// Largest store file read on open (4 GiB).
pub const MAX_STORE_BYTES: u64 = 4 * 1024 * 1024 * 1024;
/// Bytes of checksum per record.
pub const CHECKSUM_BYTES: usize = 16;

const HEADER_BYTES: usize = MAGIC.len() + 1;
const RECORD_HEAD_BYTES: usize = 4 + CHECKSUM_BYTES;

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
    /// The file is larger than [`MAX_STORE_BYTES`].
    #[error("{0}: larger than {MAX_STORE_BYTES} bytes")]
    TooLarge(PathBuf),
    /// A record to append is larger than [`MAX_RECORD_BYTES`].
    #[error("record of {0} bytes, over the limit {MAX_RECORD_BYTES}")]
    RecordTooLarge(usize),
}

/// What opening found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Recovery {
    /// Records accepted.
    pub n_records: usize,
    /// Bytes of torn or corrupt tail cut off (0 after a clean shutdown).
    pub n_truncated_bytes: u64,
}

/// An open record file, positioned at its end.
#[derive(Debug)]
pub struct RecordFile {
    file: File,
    path: PathBuf,
    /// End of the last durable record.
    end: u64,
}

fn checksum(body: &[u8]) -> [u8; CHECKSUM_BYTES] {
    let mut hasher = blake3::Hasher::new();
    hasher.update(&(body.len() as u32).to_le_bytes());
    hasher.update(body);
    let mut out = [0u8; CHECKSUM_BYTES];
    out.copy_from_slice(&hasher.finalize().as_bytes()[..CHECKSUM_BYTES]);
    out
}

/// Splits `bytes` (after the header) into valid records; returns them and where the valid
/// prefix ends. Parsing stops at the first short, oversized or mismatching record.
fn parse(bytes: &[u8]) -> (Vec<Vec<u8>>, usize) {
    let mut records = Vec::new();
    let mut at = 0;
    while let Some(head) = bytes.get(at..at + RECORD_HEAD_BYTES) {
        let mut len_bytes = [0u8; 4];
        len_bytes.copy_from_slice(&head[..4]);
        let len = u32::from_le_bytes(len_bytes) as usize;
        if len > MAX_RECORD_BYTES {
            break;
        }
        let Some(body) = bytes.get(at + RECORD_HEAD_BYTES..at + RECORD_HEAD_BYTES + len) else {
            break;
        };
        if head[4..] != checksum(body) {
            break;
        }
        records.push(body.to_vec());
        at += RECORD_HEAD_BYTES + len;
    }
    (records, at)
}

impl RecordFile {
    /// Opens or creates the file, cuts off any torn tail (and syncs the cut), and returns the
    /// valid records.
    pub fn open(path: &Path) -> Result<(Self, Vec<Vec<u8>>, Recovery), RecordError> {
        let io = |source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        if len > MAX_STORE_BYTES {
            return Err(RecordError::TooLarge(path.to_path_buf()));
        }
        let mut store = Self {
            file,
            path: path.to_path_buf(),
            end: HEADER_BYTES as u64,
        };
        if len < HEADER_BYTES as u64 {
            // New, or a crash while writing the header: nothing was ever acknowledged.
            store.write_header()?;
            return Ok((
                store,
                Vec::new(),
                Recovery {
                    n_records: 0,
                    n_truncated_bytes: len,
                },
            ));
        }
        let mut bytes = Vec::new();
        store.file.read_to_end(&mut bytes).map_err(io)?;
        if bytes[..MAGIC.len()] != MAGIC[..] || bytes[MAGIC.len()] != RECORD_FORMAT_VERSION {
            return Err(RecordError::BadHeader(path.to_path_buf()));
        }
        let (records, valid) = parse(&bytes[HEADER_BYTES..]);
        let end = (HEADER_BYTES + valid) as u64;
        let recovery = Recovery {
            n_records: records.len(),
            n_truncated_bytes: len - end,
        };
        if end < len {
            store.file.set_len(end).map_err(io)?;
            store.file.sync_all().map_err(io)?;
        }
        store.file.seek(SeekFrom::Start(end)).map_err(io)?;
        store.end = end;
        Ok((store, records, recovery))
    }

    fn write_header(&mut self) -> Result<(), RecordError> {
        let io = |source| RecordError::Io {
            path: self.path.clone(),
            source,
        };
        self.file.set_len(0).map_err(io)?;
        self.file.seek(SeekFrom::Start(0)).map_err(io)?;
        let mut header = MAGIC.to_vec();
        header.push(RECORD_FORMAT_VERSION);
        self.file.write_all(&header).map_err(io)?;
        self.file.sync_all().map_err(io)?;
        // Make the new file's directory entry durable too.
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            File::open(dir).and_then(|d| d.sync_all()).map_err(io)?;
        }
        Ok(())
    }

    /// Appends records in one write and syncs; they are durable when this returns `Ok`.
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
