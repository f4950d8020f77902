//! Store tests: exact reopen, torn and corrupt tails, and a writer child process killed with
//! SIGKILL mid-write many times.

use super::*;
use crate::identity::Keypair;
use crate::op::{OpFields, OpId, VerifiedOp};
use crate::payload::test_payload::TestPayload;
use rand_chacha::ChaCha20Rng;
use rand_core::{RngCore, SeedableRng};
use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

/// Set in the child process: the store path it appends to until killed.
const CHILD_ENV: &str = "SCULPT_STORE_KILL9_CHILD";
/// Set in the child in every other round to the number of acks after which it blocks inside
/// the next record, so the kill is sure to land mid-record; otherwise the kill lands wherever
/// the child happens to be.
const CHILD_BLOCK_ENV: &str = "SCULPT_STORE_KILL9_BLOCK";
/// Kill rounds in the crash test.
const N_KILL_ROUNDS: u64 = 12;

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
    Op::sign(key, fields).unwrap()
}

#[test]
fn reopen_restores_exactly_and_loads_into_a_log() {
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
            n_truncated_bytes: 0
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
fn torn_or_corrupt_tails_are_cut_and_never_accepted() {
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

/// In the child (with [`CHILD_ENV`] set) this appends ops forever, printing `ack <id>` after
/// each durable append, until the parent kills it. Run plainly, it checks the same writer
/// loop for a few ops in-process.
#[test]
fn kill9_child_writer() {
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
            assert!(ops.iter().all(|op| op.verify().is_ok()));
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
        let child = command.spawn().unwrap();
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
    assert!(ops.iter().all(|op| op.verify().is_ok()));
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}
