//! The store's lock: an exclusive OS lock on the sibling file `<ops file>.lock`, so that two
//! processes never open one store at once (both would append, and either could cut what the
//! other is writing as a "torn tail").
//!
//! The lock is taken with [`File::try_lock`] (`flock` on Linux), which the kernel releases
//! when the holder's file is closed: on drop, and also when the process is killed, so a crash
//! never leaves a stale lock behind. `flock` locks belong to an open file description, so a
//! second open in the same process is refused too.
//!
//! After locking, the holder writes its pid and executable into the lock file, only so that a
//! refused opener can name it; that content is a hint for the message, never trusted. The
//! lock file is never deleted: deleting it while another process has it open would let a
//! third process lock a new file of the same name, and two holders in.
//!
//! Not guaranteed: on network file systems `flock` may lock against this machine's processes
//! only, or not at all. A child process forked while a store is open shares its lock file
//! until the child execs or exits (std's `Command` execs at once, but the window is real): a
//! store dropped and reopened in that window is refused as [`OpenError::Locked`], naming this
//! very process. Opening never waits; the caller may retry.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use super::OpenError;
use super::record::RecordError;
use super::sibling;

/// Most bytes of a lock file read to name its holder.
pub const MAX_HOLDER_BYTES: usize = 512;

/// The lock file of the store at `ops_path`: `<ops file>.lock`.
pub fn lock_path(ops_path: &Path) -> PathBuf {
    sibling(ops_path, ".lock")
}

/// A held lock on a store; released when dropped (or when the process ends).
#[derive(Debug)]
pub(super) struct StoreLock {
    /// The open lock file: closing it releases the lock.
    _file: File,
}

impl StoreLock {
    /// Takes the lock of the store at `ops_path` without waiting, creating the lock file if
    /// needed, and writes this process's pid and executable into it.
    ///
    /// # Errors
    ///
    /// [`OpenError::Locked`] if another open file (of this or another process) holds the
    /// lock; [`OpenError::Record`] if the lock file cannot be opened, locked or written.
    pub(super) fn acquire(ops_path: &Path) -> Result<Self, OpenError> {
        let path = lock_path(ops_path);
        let io = |source| {
            OpenError::Record(RecordError::Io {
                path: path.clone(),
                source,
            })
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                return Err(OpenError::Locked {
                    path: ops_path.to_path_buf(),
                    holder: read_holder(&mut file),
                });
            }
            Err(TryLockError::Error(source)) => return Err(io(source)),
        }
        // Overwrite in place, then cut: a concurrent reader never sees an empty file while a
        // holder is in place. No fsync: after a crash the lock is free and the text moot.
        let holder = format!("{}\n", this_process());
        file.rewind()
            .and_then(|()| file.write_all(holder.as_bytes()))
            .and_then(|()| file.set_len(holder.len() as u64))
            .map_err(io)?;
        Ok(Self { _file: file })
    }
}

/// This process, as the lock file names it: `pid 1234, /path/to/exe`.
fn this_process() -> String {
    let pid = std::process::id();
    let exe = std::env::current_exe()
        .ok()
        .map(PathBuf::into_os_string)
        .or_else(|| std::env::args_os().next());
    match exe {
        Some(exe) => format!("pid {pid}, {}", exe.to_string_lossy()),
        None => format!("pid {pid}"),
    }
}

/// The holder named in a lock file, read from its start: at most [`MAX_HOLDER_BYTES`], on one
/// line, with control characters dropped; `None` if it is empty or unreadable (for example
/// when the holder has locked the file but not yet written it).
fn read_holder(file: &mut File) -> Option<String> {
    file.rewind().ok()?;
    let mut bytes = Vec::new();
    file.take(MAX_HOLDER_BYTES as u64)
        .read_to_end(&mut bytes)
        .ok()?;
    let text: String = String::from_utf8_lossy(&bytes)
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect();
    let text = text.trim();
    (!text.is_empty()).then(|| text.to_string())
}
