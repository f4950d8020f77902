//! The simulated disk of one peer: when ops become durable, and what a crash leaves behind.
//!
//! The driver appends every delivered op (local or remote) to its store in delivery order and
//! sends nothing while an appended op is not yet synced (the rule of [`replication`]'s crate
//! docs: a peer must never send, or acknowledge, an op it could lose in a crash). Appends are
//! group-committed: an fsync started at `t` covers what was appended before `t` and completes
//! after a simulated delay.
//!
//! A crash keeps the durable records, a random prefix of the records written but not synced
//! (the page cache may have flushed them), and possibly a torn part of the next record. That
//! image is written to a temporary file through the real [`OpStore`] and cut with `set_len`,
//! then reopened with the real [`OpStore::open_into`], whose recovery must cut the torn tail
//! and return exactly the complete records. So recovery runs the store's own code; the only
//! file IO of the simulator happens here, once per crash, and its content is a function of
//! the seed.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use replication::identity::SessionId;
use replication::log::Log;
use replication::membership::FounderCommitment;
use replication::shape::{ShapePayload, ShapeScene};
use replication::snapshot::Snapshot;
use replication::store::OpStore;
use replication::store::record::CHECKSUM_BYTES;
use replication::{Op, OpId, Timestamp};

use crate::rng::SimRng;

/// Bytes of record head before each body (`[u32 len][checksum]`).
const RECORD_HEAD_BYTES: usize = 4 + CHECKSUM_BYTES;

/// Temporary store files made so far in this process (makes names unique).
static N_FILES: AtomicU64 = AtomicU64::new(0);

/// One peer's store as the simulation sees it.
#[derive(Debug, Clone, Default)]
pub struct Disk {
    /// Ops appended since the peer (re)started from its store, in append order; the first
    /// `n_durable` are synced.
    appended: Vec<OpId>,
    n_durable: usize,
    /// The running fsync: when it completes and how many appended ops it covers.
    syncing: Option<(u64, usize)>,
    /// Bumped at every crash, so a completion scheduled before it is ignored.
    pub generation: u64,
    /// The snapshot the peer joined from (kept beside the store).
    pub snapshot: Option<Vec<u8>>,
}

/// What a crash and the store's recovery left.
#[derive(Debug)]
pub struct Recovered {
    /// The log reloaded by [`OpStore::open_into`] (on top of the snapshot, if any).
    pub log: Log<ShapePayload>,
    /// Ops appended but lost (neither synced nor surviving as complete records).
    pub lost: Vec<OpId>,
    /// Bytes of torn record the recovery cut (as it reported).
    pub n_truncated_bytes: u64,
}

impl Disk {
    /// Appends delivered ops (not yet durable).
    pub fn append(&mut self, ids: &[OpId]) {
        self.appended.extend_from_slice(ids);
    }

    /// Appended ops not yet synced.
    pub fn n_unsynced(&self) -> usize {
        self.appended.len() - self.n_durable
    }

    /// Ops synced.
    pub fn n_durable(&self) -> usize {
        self.n_durable
    }

    /// Starts an fsync lasting `delay_micros` if there is something to sync and none runs;
    /// returns when it completes.
    pub fn start_sync(&mut self, now: u64, delay_micros: u64) -> Option<u64> {
        if self.syncing.is_some() || self.n_unsynced() == 0 {
            return None;
        }
        let done = now + delay_micros;
        self.syncing = Some((done, self.appended.len()));
        Some(done)
    }

    /// Completes the running fsync; returns the ops it made durable.
    pub fn complete_sync(&mut self) -> &[OpId] {
        let Some((_, covered)) = self.syncing.take() else {
            return &[];
        };
        let from = self.n_durable;
        self.n_durable = covered.max(from);
        &self.appended[from..self.n_durable]
    }

    /// Crashes: builds the file image the crash leaves (durable records, a random prefix of
    /// the unsynced ones, maybe a torn record), then reopens it with the real store. `old` is
    /// the log before the crash (it holds every appended op).
    pub fn crash(
        &mut self,
        old: &Log<ShapePayload>,
        rng: &mut SimRng,
        now: Timestamp,
    ) -> Result<Recovered, String> {
        let n_unsynced = self.n_unsynced();
        let n_survivors = rng.index(n_unsynced + 1);
        let torn = n_survivors < n_unsynced && rng.chance(700);
        let n_written = self.n_durable + n_survivors + usize::from(torn);
        let ops: Vec<&Op<ShapePayload>> = self.appended[..n_written]
            .iter()
            .map(|id| {
                old.get(id)
                    .ok_or(format!("appended op {id} not in the log"))
            })
            .collect::<Result<_, _>>()?;
        // Keep 1..len-1 bytes of the torn record.
        let torn_keep = ops
            .last()
            .filter(|_| torn)
            .map(|op| 1 + rng.index(RECORD_HEAD_BYTES + op.encoded().len() - 1));
        let dir = temp_dir();
        let result = std::fs::create_dir_all(&dir)
            .map_err(|e| format!("store directory: {e}"))
            .and_then(|()| {
                let path = dir.join("ops.sculpt");
                let snapshot = self.snapshot.as_deref();
                let session = (old.session_id(), old.founder(), old.founder_budget());
                write_and_recover(&path, &ops, torn_keep, snapshot, session, now)
            });
        // The store's lock file and any torn tail it set aside go with the directory.
        let _ = std::fs::remove_dir_all(&dir);
        let (log, n_records, n_truncated_bytes) = result?;
        let n_expected = self.n_durable + n_survivors;
        if n_records != n_expected || n_truncated_bytes != torn_keep.unwrap_or(0) as u64 {
            return Err(format!(
                "store recovery kept {n_records} records and cut {n_truncated_bytes} bytes; \
                 expected {n_expected} records and a cut of {} bytes",
                torn_keep.unwrap_or(0)
            ));
        }
        let lost = self.appended.split_off(n_expected);
        self.n_durable = self.appended.len();
        self.syncing = None;
        self.generation += 1;
        Ok(Recovered {
            log,
            lost,
            n_truncated_bytes,
        })
    }
}

/// A fresh directory for one crash image (the store puts its lock and torn tails beside the
/// op file).
fn temp_dir() -> PathBuf {
    let n = N_FILES.fetch_add(1, Ordering::Relaxed);
    std::env::temp_dir().join(format!("sculpt-sim-{}-{n}", std::process::id()))
}

/// Writes `ops` through the real store, cuts the last record to `torn_keep` bytes if given,
/// and reopens the file into a log (joined from `snapshot`, if any) of the session: its id,
/// the founder it names, if any, and the founder's budget, if it binds its authors.
fn write_and_recover(
    path: &std::path::Path,
    ops: &[&Op<ShapePayload>],
    torn_keep: Option<usize>,
    snapshot: Option<&[u8]>,
    (session_id, founder, binding): (SessionId, Option<FounderCommitment>, Option<u64>),
    now: Timestamp,
) -> Result<(Log<ShapePayload>, usize, u64), String> {
    let (mut store, stale, _) =
        OpStore::<ShapePayload>::open(path).map_err(|e| format!("store create: {e}"))?;
    if !stale.is_empty() {
        return Err(format!("temporary store {} was not new", path.display()));
    }
    store
        .append(ops)
        .map_err(|e| format!("store append: {e}"))?;
    drop(store);
    if let (Some(keep), Some(last)) = (torn_keep, ops.last()) {
        let record = (RECORD_HEAD_BYTES + last.encoded().len()) as u64;
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| format!("store reopen: {e}"))?;
        let len = file.metadata().map_err(|e| e.to_string())?.len();
        file.set_len(len - record + keep as u64)
            .map_err(|e| format!("store tear: {e}"))?;
    }
    let mut log = Log::default();
    if let Some(founder) = founder {
        log.set_founder(founder)
            .map_err(|e| format!("store recovery: {e}"))?;
    }
    if let Some(cap) = binding {
        log.bind_authors(cap)
            .map_err(|e| format!("store recovery: {e}"))?;
    }
    log.set_session_id(session_id);
    if let Some(bytes) = snapshot {
        // The snapshot was verified when the peer joined from it.
        let snapshot = (Snapshot::<ShapePayload>::decode(bytes))
            .map_err(|e| format!("snapshot decode: {e}"))?;
        (log, _) =
            (snapshot.join::<ShapeScene>(log, now)).map_err(|e| format!("snapshot join: {e}"))?;
    }
    let (_store, recovery) =
        OpStore::open_into(path, now, &mut log).map_err(|e| format!("store recovery: {e}"))?;
    Ok((log, recovery.n_records, recovery.n_truncated_bytes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use replication::Keypair;

    #[test]
    fn a_crash_keeps_synced_ops_and_recovery_cuts_the_torn_record() {
        let key = Keypair::from_seed([4; 32]);
        let mut log = Log::<ShapePayload>::default();
        let mut disk = Disk::default();
        for i in 0..6 {
            let (op, _) = log
                .author(
                    &key,
                    Timestamp(1000 + i),
                    ShapePayload::Chat(format!("{i}")),
                )
                .unwrap();
            disk.append(&[op.id()]);
            if i == 2 {
                assert_eq!(disk.start_sync(10, 5), Some(15));
                assert_eq!(disk.start_sync(11, 5), None, "one fsync at a time");
                assert_eq!(disk.complete_sync().len(), 3);
            }
        }
        assert_eq!((disk.n_durable(), disk.n_unsynced()), (3, 3));
        let mut n_torn = 0;
        for seed in 0..12 {
            let mut d = disk.clone();
            let r = d
                .crash(&log, &mut SimRng::new(seed), Timestamp(2000))
                .unwrap();
            assert!(r.log.len() >= 3 && r.log.len() + r.lost.len() == 6);
            assert_eq!(d.n_unsynced(), 0);
            n_torn += usize::from(r.n_truncated_bytes > 0);
        }
        assert!(n_torn > 0, "no seed tore a record");
    }
}
