//! Store tests: exact reopen, the lock, torn tails set aside and cut, damaged middle records
//! refused, and a writer child process killed with SIGKILL mid-write many times.

use super::*;
use crate::identity::{Keypair, OpId};
use crate::op::{OpFields, VerifiedOp};
use crate::payload::test_payload::TestPayload;
use rand_chacha::ChaCha20Rng;
use rand_core::{RngCore, SeedableRng};
use record::MAGIC;
use std::collections::BTreeSet;
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{PoisonError, RwLock, RwLockReadGuard};

/// Set in the child process: the store path it appends to until killed.
const CHILD_ENV: &str = "SCULPT_STORE_KILL9_CHILD";
/// Set in the child in every other round to the number of acks after which it blocks inside
/// the next record, so the kill is sure to land mid-record; otherwise the kill lands wherever
/// the child happens to be.
const CHILD_BLOCK_ENV: &str = "SCULPT_STORE_KILL9_BLOCK";
/// Kill rounds in the crash test.
const N_KILL_ROUNDS: u64 = 12;

/// Keeps child processes from being spawned while a test has stores open. A child shares the
/// parent's open files from fork until exec, a store's lock included (an `flock` belongs to the
/// open file description), so a test that drops a store and reopens it in that window would
/// find its own lock still held. Tests that open stores hold a read guard ([`no_spawn`]); the
/// kill test takes the write guard around each spawn.
static SPAWN: RwLock<()> = RwLock::new(());

/// Held for the whole of a test that opens stores in this process.
fn no_spawn() -> RwLockReadGuard<'static, ()> {
    SPAWN.read().unwrap_or_else(PoisonError::into_inner)
}

fn temp_path(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sculpt-store-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir.join("ops.log")
}

fn next_op(key: &Keypair, prev: Option<&Op<TestPayload>>, pad: usize) -> VerifiedOp<TestPayload> {
    let seq = prev.map_or(1, |p| p.seq() + 1);
    let fields = OpFields {
        seq,
        lamport: seq,
        timestamp: Timestamp(seq * 1000),
        deps: prev.map(|p| vec![p.id()]).unwrap_or_default(),
        payload: TestPayload::Set {
            object: 1,
            value: "x".repeat(pad),
        },
    };
    Op::sign(key, &crate::op::UNNAMED_SESSION, fields).unwrap()
}

#[test]
fn reopen_restores_exactly_and_loads_into_a_log() {
    let _no_spawn = no_spawn();
    let path = temp_path("reopen");
    let key = Keypair::from_seed([4; 32]);
    let mut written: Vec<VerifiedOp<TestPayload>> = Vec::new();
    {
        let (mut store, ops, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
        assert!(ops.is_empty());
        assert_eq!(recovery.n_records, 0);
        for i in 0..10 {
            let op = next_op(&key, written.last().map(|o| o.op()), i * 7);
            store.append(&[op.op()]).unwrap();
            written.push(op);
        }
    }
    let (_, ops, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!(
        recovery,
        Recovery {
            n_records: 10,
            n_truncated_bytes: 0,
            torn_tail: None,
        }
    );
    assert_eq!(
        ops,
        written.iter().map(|o| o.op().clone()).collect::<Vec<_>>()
    );
    let mut log = Log::default();
    OpStore::<TestPayload>::open_into(&path, Timestamp(0), &mut log).unwrap();
    assert_eq!(log.len(), 10);
    let mut trusted = Log::default();
    OpStore::<TestPayload>::open_into_trusted(&path, Timestamp(0), &mut trusted).unwrap();
    assert_eq!(
        trusted.linear_ids().collect::<Vec<_>>(),
        log.linear_ids().collect::<Vec<_>>()
    );
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn a_stored_op_whose_signature_fails_is_named_by_its_record() {
    let _no_spawn = no_spawn();
    let key = Keypair::from_seed([6; 32]);
    // Forged records at the start, the middle of a batch of signatures, and past the first.
    for forged_at in [0, 37, 100] {
        let path = temp_path("forged");
        {
            let (mut store, _, _) = OpStore::<TestPayload>::open(&path).unwrap();
            let mut last: Option<Op<TestPayload>> = None;
            for i in 0..130 {
                let op = next_op(&key, last.as_ref(), i).into_op();
                let stored = if i == forged_at {
                    let mut bytes = op.encoded().to_vec();
                    let at = bytes.len() - 1;
                    bytes[at] ^= 1;
                    Op::decode(&bytes).unwrap()
                } else {
                    op.clone()
                };
                store.append(&[&stored]).unwrap();
                last = Some(op);
            }
        }
        let mut log = Log::default();
        let error = OpStore::<TestPayload>::open_into(&path, Timestamp(0), &mut log)
            .map(|_| ())
            .unwrap_err();
        assert!(
            matches!(error, OpenError::BadSignature { record_idx } if record_idx == forged_at),
            "{forged_at}: {error:?}"
        );
        // The file is left as it was.
        let (_, ops, _) = OpStore::<TestPayload>::open(&path).unwrap();
        assert_eq!(ops.len(), 130);
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }
}

#[test]
fn torn_or_corrupt_tails_are_cut_and_never_accepted() {
    let _no_spawn = no_spawn();
    let path = temp_path("torn");
    let key = Keypair::from_seed([5; 32]);
    let mut ops: Vec<VerifiedOp<TestPayload>> = Vec::new();
    let mut ends = Vec::new();
    {
        let (mut store, _, _) = OpStore::<TestPayload>::open(&path).unwrap();
        for i in 0..4 {
            let op = next_op(&key, ops.last().map(|o| o.op()), 30 + i);
            store.append(&[op.op()]).unwrap();
            ops.push(op);
            ends.push(std::fs::metadata(&path).unwrap().len());
        }
    }
    let full = std::fs::read(&path).unwrap();
    let last_start = ends[2] as usize;
    // Every truncation inside the last record, and every single-byte corruption of it.
    for cut in last_start..full.len() {
        std::fs::write(&path, &full[..cut]).unwrap();
        let (_, got, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
        assert_eq!(got.len(), 3, "cut at {cut}");
        assert_eq!(recovery.n_truncated_bytes, (cut - last_start) as u64);
        assert_eq!(
            std::fs::metadata(&path).unwrap().len(),
            ends[2],
            "tail cut off on disk"
        );
    }
    for flip in last_start..full.len() {
        let mut bad = full.clone();
        bad[flip] ^= 0x10;
        std::fs::write(&path, &bad).unwrap();
        let (_, got, _) = OpStore::<TestPayload>::open(&path).unwrap();
        assert_eq!(
            got,
            ops[..3].iter().map(|o| o.op().clone()).collect::<Vec<_>>(),
            "flip at {flip}"
        );
    }
    // After a cut, appending continues cleanly behind the last good record.
    std::fs::write(&path, &full[..full.len() - 3]).unwrap();
    let (mut store, got, _) = OpStore::<TestPayload>::open(&path).unwrap();
    store.append(&[ops[3].op()]).unwrap();
    drop(store);
    let (_, got_after, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!(got.len() + 1, got_after.len());
    assert_eq!(recovery.n_truncated_bytes, 0);
    // A file that is not a store is refused, not overwritten.
    std::fs::write(&path, b"hello world, not a store").unwrap();
    assert!(matches!(
        OpStore::<TestPayload>::open(&path),
        Err(OpenError::Record(RecordError::BadHeader(_)))
    ));
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

/// Writes `n` ops (of different sizes) to a new store at `path`; returns them and the file's
/// length after each append (so record `i` spans `ends[i - 1]..ends[i]`, record 0 starts
/// after the header).
fn write_ops(path: &Path, key: &Keypair, n: usize) -> (Vec<VerifiedOp<TestPayload>>, Vec<u64>) {
    let mut ops: Vec<VerifiedOp<TestPayload>> = Vec::new();
    let mut ends = Vec::new();
    let (mut store, _, _) = OpStore::<TestPayload>::open(path).unwrap();
    for i in 0..n {
        let op = next_op(key, ops.last().map(|o| o.op()), 20 + 9 * i);
        store.append(&[op.op()]).unwrap();
        ops.push(op);
        ends.push(std::fs::metadata(path).unwrap().len());
    }
    (ops, ends)
}

/// The names of the files in `path`'s directory other than the store and its lock file.
fn other_files(path: &Path) -> Vec<String> {
    let store = path.file_name().unwrap().to_string_lossy().into_owned();
    let lock = format!("{store}.lock");
    let mut names: Vec<String> = std::fs::read_dir(path.parent().unwrap())
        .unwrap()
        .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| *name != store && *name != lock)
        .collect();
    names.sort();
    names
}

/// The lock relies on `flock` locks belonging to an open file description: a second open of
/// the same file in the same process must conflict with the first. Checked here on the OS the
/// tests run on, with std alone.
#[test]
fn two_opens_of_one_file_in_one_process_conflict_on_try_lock() {
    let _no_spawn = no_spawn();
    let path = temp_path("flock").with_extension("lock");
    let open = || {
        OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .unwrap()
    };
    let first: File = open();
    let second: File = open();
    first.try_lock().unwrap();
    assert!(matches!(second.try_lock(), Err(TryLockError::WouldBlock)));
    drop(first);
    second.try_lock().unwrap();
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn a_second_open_is_locked_out_and_names_the_holder_until_the_first_is_dropped() {
    let _no_spawn = no_spawn();
    let path = temp_path("locked");
    let key = Keypair::from_seed([7; 32]);
    let (_, ends) = write_ops(&path, &key, 2);
    let (first, ops, _) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!(ops.len(), 2);
    let pid = format!("pid {}", std::process::id());
    let Err(error) = OpStore::<TestPayload>::open(&path) else {
        panic!("a second open of a held store succeeded");
    };
    let message = error.to_string();
    let OpenError::Locked {
        path: locked,
        holder,
    } = error
    else {
        panic!("expected Locked, got {error:?}");
    };
    assert_eq!(locked, path);
    let holder = holder.expect("the holder wrote its pid into the lock file");
    assert!(
        holder.starts_with(&format!("{pid}, ")),
        "holder {holder:?} should name {pid} and the executable"
    );
    assert!(
        message.contains(&format!("is in use by another sculpt process ({pid}"))
            && message.ends_with("; close it first"),
        "{message}"
    );
    // Refused before reading or writing: the store is as it was.
    assert_eq!(std::fs::metadata(&path).unwrap().len(), ends[1]);
    let lock = std::fs::read_to_string(lock::lock_path(&path)).unwrap();
    assert!(lock.starts_with(&pid), "{lock:?}");
    drop(first);
    let (_, ops, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!((ops.len(), recovery.n_truncated_bytes), (2, 0));
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn a_damaged_record_before_a_valid_one_is_refused_and_the_file_left_alone() {
    let _no_spawn = no_spawn();
    let path = temp_path("corrupt");
    let key = Keypair::from_seed([8; 32]);
    let (_, ends) = write_ops(&path, &key, 3);
    let full = std::fs::read(&path).unwrap();
    let header_bytes = (MAGIC.len() + 1) as u64;
    let starts = [header_bytes, ends[0], ends[1]];
    // Every single-bit flip of the first and the middle record (length, checksum and body):
    // the record is damaged but the last one is still valid after it.
    for record_idx in 0..2 {
        for flip in starts[record_idx]..ends[record_idx] {
            let mut bad = full.clone();
            bad[flip as usize] ^= 0x10;
            std::fs::write(&path, &bad).unwrap();
            let error = OpStore::<TestPayload>::open(&path).unwrap_err();
            let message = error.to_string();
            let OpenError::Corrupt {
                path: damaged,
                offset,
                next_valid_offset,
            } = error
            else {
                panic!("flip at {flip}: expected Corrupt, got {error:?}");
            };
            assert_eq!(damaged, path);
            assert_eq!(offset, starts[record_idx], "flip at {flip}");
            assert_eq!(next_valid_offset, ends[record_idx], "flip at {flip}");
            assert!(
                message.contains(&format!("at byte {offset}"))
                    && message.contains("the file was left as it was"),
                "{message}"
            );
            assert!(
                std::fs::read(&path).unwrap() == bad,
                "flip at {flip}: the file was modified"
            );
        }
    }
    assert_eq!(
        other_files(&path),
        Vec::<String>::new(),
        "nothing set aside"
    );
    // The refusal held no lock: once repaired, the store opens whole.
    std::fs::write(&path, &full).unwrap();
    let (_, ops, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!((ops.len(), recovery.n_truncated_bytes), (3, 0));
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn a_torn_last_record_is_set_aside_byte_for_byte_then_cut() {
    let _no_spawn = no_spawn();
    let path = temp_path("set-aside");
    let key = Keypair::from_seed([9; 32]);
    let (ops, ends) = write_ops(&path, &key, 3);
    let full = std::fs::read(&path).unwrap();
    let cut_at = ends[1] as usize;
    let torn = &full[..full.len() - 5];
    std::fs::write(&path, torn).unwrap();
    let (mut store, got, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!(got.len(), 2);
    assert_eq!(recovery.n_truncated_bytes, (torn.len() - cut_at) as u64);
    let set_aside = recovery.torn_tail.clone().expect("the cut bytes were kept");
    let name = set_aside
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    assert!(
        name.starts_with(&format!("ops.log.torn-{cut_at}-")),
        "{name}"
    );
    assert_eq!(set_aside.parent(), path.parent());
    assert!(std::fs::read(&set_aside).unwrap() == torn[cut_at..]);
    assert_eq!(std::fs::metadata(&path).unwrap().len(), ends[1]);
    assert_eq!(
        other_files(&path),
        vec![name.clone()],
        "no partial file left"
    );
    // The cut store takes the op again and reopens clean, keeping the set-aside file.
    store.append(&[ops[2].op()]).unwrap();
    drop(store);
    let (_, got, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!(got, ops.iter().map(|o| o.op().clone()).collect::<Vec<_>>());
    assert_eq!(recovery.torn_tail, None);
    assert!(std::fs::read(&set_aside).unwrap() == torn[cut_at..]);
    // The same tail again (as after a crash between setting aside and cutting) goes to the
    // same file, with the same bytes.
    std::fs::write(&path, torn).unwrap();
    let (_, _, again) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!(again.torn_tail, Some(set_aside.clone()));
    assert!(std::fs::read(&set_aside).unwrap() == torn[cut_at..]);
    assert_eq!(other_files(&path), vec![name]);
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn a_partial_header_is_rewritten_but_a_short_other_file_is_refused() {
    let _no_spawn = no_spawn();
    let path = temp_path("short");
    std::fs::write(&path, &MAGIC[..4]).unwrap();
    let (_, ops, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
    assert!(ops.is_empty());
    assert_eq!(
        recovery,
        Recovery {
            n_records: 0,
            n_truncated_bytes: 4,
            torn_tail: None
        }
    );
    assert_eq!(
        std::fs::metadata(&path).unwrap().len(),
        MAGIC.len() as u64 + 1
    );
    std::fs::write(&path, b"notes").unwrap();
    assert!(matches!(
        OpStore::<TestPayload>::open(&path),
        Err(OpenError::Record(RecordError::BadHeader(_)))
    ));
    assert_eq!(std::fs::read(&path).unwrap(), b"notes", "not overwritten");
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

/// In the child (with [`CHILD_ENV`] set) this appends ops forever, printing `ack <id>` after
/// each durable append, until the parent kills it. Run plainly, it checks the same writer
/// loop for a few ops in-process.
#[test]
fn kill9_child_writer() {
    let _no_spawn = no_spawn();
    match std::env::var(CHILD_ENV) {
        Ok(path) => {
            let block_after = std::env::var(CHILD_BLOCK_ENV)
                .ok()
                .and_then(|v| v.parse().ok());
            child_writer(
                &PathBuf::from(path),
                u64::MAX,
                &mut std::io::stdout(),
                block_after,
            );
        }
        Err(_) => {
            let path = temp_path("writer");
            let mut out = Vec::new();
            child_writer(&path, 5, &mut out, None);
            assert_eq!(
                String::from_utf8(out)
                    .unwrap()
                    .lines()
                    .filter(|l| ack_id(l).is_some())
                    .count(),
                5
            );
            let (_, ops, _) = OpStore::<TestPayload>::open(&path).unwrap();
            assert_eq!(ops.len(), 5);
            assert!(
                ops.iter()
                    .all(|op| op.verify(&crate::op::UNNAMED_SESSION).is_ok())
            );
            let _ = std::fs::remove_dir_all(path.parent().unwrap());
        }
    }
}

fn child_writer(path: &Path, n_ops: u64, out: &mut dyn Write, block_after: Option<u64>) {
    let key = Keypair::from_seed([6; 32]);
    let (mut store, ops, _) = OpStore::<TestPayload>::open(path).unwrap();
    let mut prev = ops.last().cloned();
    let mut unacked: Option<OpId> = None;
    for i in 0..n_ops {
        let op = next_op(&key, prev.as_ref(), (i as usize * 37) % 250);
        // The previous op is durable; announce it half-way through writing this one, so the
        // parent's SIGKILL, sent on reading the ack, usually lands inside this record.
        let mut announce = || {
            if let Some(id) = unacked.take() {
                writeln!(out, "ack {}", crate::identity::hex(&id.0)).unwrap();
                out.flush().unwrap();
                if Some(i) == block_after {
                    // The parent never writes to our stdin: wait here for the kill.
                    let _ = std::io::stdin().read_line(&mut String::new());
                }
            }
        };
        store
            .append_split(&[op.op()], 20 + i as usize % 40, &mut announce)
            .unwrap();
        unacked = Some(op.id());
        prev = Some(op.into_op());
    }
    if let Some(id) = unacked {
        writeln!(out, "ack {}", crate::identity::hex(&id.0)).unwrap();
    }
}

/// The op id in an `ack <id>` line (libtest may print its own text before the first one).
fn ack_id(line: &str) -> Option<&str> {
    line.rsplit_once("ack ").map(|(_, id)| id.trim())
}

/// Kills the child on drop, so a failing assertion never leaves it running.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn kill9_never_loses_acknowledged_ops_nor_accepts_torn_ones() {
    let path = temp_path("kill9");
    let exe = std::env::current_exe().unwrap();
    let mut rng = ChaCha20Rng::seed_from_u64(99);
    let mut acked: BTreeSet<String> = BTreeSet::new();
    let mut n_torn_rounds = 0;
    for round in 0..N_KILL_ROUNDS {
        let mut command = Command::new(&exe);
        command
            .args([
                "--exact",
                "store::tests::kill9_child_writer",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_ENV, &path)
            .env_remove(CHILD_BLOCK_ENV)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null());
        let wanted = 1 + rng.next_u32() % 20;
        if round % 2 == 0 {
            command.env(CHILD_BLOCK_ENV, wanted.to_string());
        }
        let child = {
            let _spawning = SPAWN.write().unwrap_or_else(PoisonError::into_inner);
            command.spawn().unwrap()
        };
        let mut child = KillOnDrop(child);
        let stdout = child.0.stdout.take().unwrap();
        let mut lines = BufReader::new(stdout).lines();
        let mut n_seen = 0;
        while n_seen < wanted {
            let line = lines.next().expect("child ended early").unwrap();
            if let Some(id) = ack_id(&line) {
                acked.insert(id.to_string());
                n_seen += 1;
            }
        }
        // SIGKILL while the child is somewhere in its next write.
        child.0.kill().unwrap();
        child.0.wait().unwrap();
        // An ack printed before the kill landed may still be in the pipe: it counts too.
        for line in lines.map_while(Result::ok) {
            if let Some(id) = ack_id(&line) {
                acked.insert(id.to_string());
            }
        }
        let (_, ops, recovery) = OpStore::<TestPayload>::open(&path).unwrap();
        n_torn_rounds += u64::from(recovery.n_truncated_bytes > 0);
        let stored: BTreeSet<String> = ops
            .iter()
            .map(|op| crate::identity::hex(&op.id().0))
            .collect();
        let missing: Vec<_> = acked.difference(&stored).collect();
        assert!(
            missing.is_empty(),
            "round {round}: acknowledged ops lost: {missing:?}"
        );
        // Every accepted record is a whole op of the one author's gapless chain.
        for (i, op) in ops.iter().enumerate() {
            assert_eq!(op.seq(), i as u64 + 1, "round {round}");
            if i > 0 {
                assert_eq!(op.deps(), &[ops[i - 1].id()]);
            }
        }
    }
    // The blocking rounds always leave a torn record: the recovery path really ran.
    assert!(
        n_torn_rounds >= N_KILL_ROUNDS / 2,
        "only {n_torn_rounds} kills landed inside a record"
    );
    let (_, ops, _) = OpStore::<TestPayload>::open(&path).unwrap();
    assert!(ops.len() >= acked.len());
    assert!(
        ops.iter()
            .all(|op| op.verify(&crate::op::UNNAMED_SESSION).is_ok())
    );
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn a_full_store_refuses_the_append_keeps_what_it_held_and_still_opens() {
    let _no_spawn = no_spawn();
    let path = temp_path("full");
    let key = Keypair::from_seed([9; 32]);
    let limit = 2_000;
    let mut written: Vec<VerifiedOp<TestPayload>> = Vec::new();
    let full = {
        let (mut store, _, _) = OpStore::<TestPayload>::open_with_limit(&path, limit).unwrap();
        loop {
            let op = next_op(&key, written.last().map(|o| o.op()), 100);
            let before = store.len_bytes();
            match store.append(&[op.op()]) {
                Ok(()) => written.push(op),
                Err(error) => {
                    assert_eq!(store.len_bytes(), before, "a refused append wrote nothing");
                    break error;
                }
            }
        }
    };
    let RecordError::Full { size, needed, .. } = full else {
        panic!("expected a full store, got {full}");
    };
    assert!(size <= limit && size + needed > limit);
    assert!(written.len() >= 5, "{} ops fitted", written.len());
    assert_eq!(std::fs::metadata(&path).unwrap().len(), size);
    // Every size the store accepted opens again, with every op it acknowledged.
    let (mut store, ops, recovery) = OpStore::<TestPayload>::open_with_limit(&path, limit).unwrap();
    assert_eq!(recovery.n_truncated_bytes, 0);
    assert_eq!(
        ops,
        written.iter().map(|o| o.op().clone()).collect::<Vec<_>>()
    );
    let op = next_op(&key, written.last().map(|o| o.op()), 100);
    assert!(matches!(
        store.append(&[op.op()]),
        Err(RecordError::Full { .. })
    ));
    drop(store);
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn one_append_of_many_ops_is_one_sync_and_an_empty_one_is_none() {
    let _no_spawn = no_spawn();
    let path = temp_path("syncs");
    let key = Keypair::from_seed([10; 32]);
    let (mut store, _, _) = OpStore::<TestPayload>::open(&path).unwrap();
    let mut ops: Vec<VerifiedOp<TestPayload>> = Vec::new();
    for _ in 0..64 {
        ops.push(next_op(&key, ops.last().map(|o| o.op()), 10));
    }
    store.append(&[]).unwrap();
    assert_eq!(store.n_syncs(), 0);
    store
        .append(&ops.iter().map(|o| o.op()).collect::<Vec<_>>())
        .unwrap();
    assert_eq!(store.n_syncs(), 1);
    drop(store);
    let (_, reopened, _) = OpStore::<TestPayload>::open(&path).unwrap();
    assert_eq!(reopened.len(), 64);
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}
