//! Joining from a snapshot over loopback QUIC: a joiner takes the first peer's snapshot,
//! syncs the rest, and stores the whole log once its check passes; a snapshot holding ops
//! signed for another session is dropped with every connection, and a remote with no
//! snapshot or a broken one leaves the joiner syncing op by op; two joiners that both start
//! empty (two windows opening one new invite) sync both ways.

mod net_support;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};

use net_support::{INVITE, THandle, converge, eventually, n_ops, next_event, session_keys};
use replication::log::Insertion;
use replication::materialize::Materialized;
use replication::materialize::test_scene::TestScene;
use replication::net::node::{NodeEvent, Observer, SnapshotNews};
use replication::net::{Node, NodeConfig};
use replication::payload::test_payload::TestPayload;
use replication::snapshot::{CaptureError, JoinError, Snapshot};
use replication::store::OpStore;
use replication::{Keypair, Log, Peer, Timestamp};

type TScene = Materialized<TestPayload, TestScene>;

/// A test node's scene, folded from scratch whenever the log changed (small logs only), which
/// serves `serve` instead of its own snapshot when set.
struct Folder {
    scene: Arc<Mutex<TScene>>,
    serve: Option<Vec<u8>>,
}

impl Folder {
    fn scene(&self) -> std::sync::MutexGuard<'_, TScene> {
        self.scene.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl Observer<TestPayload> for Folder {
    fn inserted(&mut self, _log: &Log<TestPayload>, _insertion: &Insertion) {}

    fn settled(&mut self, peer: &mut Peer<TestPayload>, changed: bool) {
        if changed {
            *self.scene() = Materialized::fold(peer.log());
        }
    }

    fn capture_snapshot(
        &mut self,
        log: &Log<TestPayload>,
    ) -> Option<Result<Vec<u8>, CaptureError>> {
        Some(match &self.serve {
            Some(bytes) => Ok(bytes.clone()),
            None => Snapshot::capture(log, &self.scene()).encode(),
        })
    }

    fn join_snapshot(
        &mut self,
        snapshot: Snapshot<TestPayload>,
        log: Log<TestPayload>,
        now: Timestamp,
    ) -> Option<Result<Log<TestPayload>, JoinError>> {
        Some(snapshot.join::<TestScene>(log, now).map(|(log, scene)| {
            *self.scene() = scene;
            log
        }))
    }

    fn refold(&mut self, log: &Log<TestPayload>) {
        *self.scene() = Materialized::fold(log);
    }
}

/// `n` chat lines by key `seed`, signed for `session`.
fn chat_log(seed: u8, n: usize, session: replication::identity::SessionId) -> Log<TestPayload> {
    let key = Keypair::from_seed([seed; 32]);
    let mut log = Log::default();
    log.set_session_id(session);
    for i in 0..n {
        let line = TestPayload::Chat(format!("line {i} of {seed}"));
        log.author(&key, Timestamp(1 + i as u64), line)
            .expect("authors");
    }
    log
}

fn spawn(
    seed: u8,
    log: Log<TestPayload>,
    store: Option<&Path>,
    join_from_snapshot: bool,
    serve: Option<Vec<u8>>,
) -> Node<TestPayload> {
    let store = store.map(|p| OpStore::open(p).expect("store opens").0);
    let folder = Folder {
        scene: Arc::new(Mutex::new(TScene::fold(&Log::default()))),
        serve,
    };
    Node::spawn_observed(
        NodeConfig {
            keypair: Keypair::from_seed([seed; 32]),
            keys: session_keys(INVITE),
            listen: "127.0.0.1:0".parse().expect("loopback address"),
            log,
            store,
            join_from_snapshot,
        },
        Some(Box::new(folder)),
    )
    .expect("node starts")
}

fn store_path(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sculpt-net-snapshot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch directory");
    let path = dir.join(name);
    let _ = std::fs::remove_file(&path);
    path
}

fn stored(path: &Path) -> usize {
    OpStore::<TestPayload>::open(path)
        .expect("store opens")
        .1
        .len()
}

async fn stats(handle: &THandle) -> replication::net::node::NodeStats {
    handle.stats().await.expect("node running")
}

#[tokio::test]
async fn a_joiner_takes_a_snapshot_syncs_the_rest_and_stores_it_once_checked() {
    let session = session_keys(INVITE).session_id();
    let a = spawn(1, chat_log(1, 300, session), None, false, None);
    let path = store_path("joined");
    let mut b = spawn(2, Log::default(), Some(&path), true, None);
    b.handle.dial(a.handle.local_addr()).await.expect("dials");
    let joined = next_event(&mut b.events, "the join", |e| match e {
        NodeEvent::Snapshot(SnapshotNews::Joined { n_ops, .. }) => Some(*n_ops),
        _ => None,
    })
    .await;
    assert_eq!(joined, 300);
    // An edit made while the check runs waits for it, then goes out like any other.
    b.handle
        .author(TestPayload::Chat("from b".into()))
        .await
        .expect("authors");
    next_event(&mut b.events, "the check", |e| {
        matches!(e, NodeEvent::Snapshot(SnapshotNews::Verified)).then_some(())
    })
    .await;
    a.handle
        .author(TestPayload::Chat("from a".into()))
        .await
        .expect("authors");
    converge(&[&a.handle, &b.handle], 302).await;
    let (sa, sb) = (stats(&a.handle).await, stats(&b.handle).await);
    assert_eq!(
        (
            sa.n_snapshots_served,
            sb.n_snapshot_joins,
            sb.n_snapshots_refused
        ),
        (1, 1, 0)
    );
    b.handle.shutdown().await.expect("stops");
    eventually("the joiner's store is released", || async {
        OpStore::<TestPayload>::open(&path).is_ok()
    })
    .await;
    assert_eq!(
        stored(&path),
        302,
        "the joined log and what came after are stored"
    );
}

#[tokio::test]
async fn a_snapshot_of_ops_signed_for_another_session_is_dropped_and_sync_goes_op_by_op() {
    let session = session_keys(INVITE).session_id();
    // A hostile member serves a snapshot whose ops are signed for another session: the join
    // takes them on trust, the check finds them.
    let forged_log = chat_log(7, 50, [9; 16]);
    let forged =
        (Snapshot::capture(&forged_log, &TScene::fold(&forged_log)).encode()).expect("encodes");
    let a = spawn(1, chat_log(1, 40, session), None, false, Some(forged));
    let path = store_path("forged");
    let mut b = spawn(2, Log::default(), Some(&path), true, None);
    b.handle.dial(a.handle.local_addr()).await.expect("dials");
    let why = next_event(&mut b.events, "the refusal", |e| match e {
        NodeEvent::Snapshot(SnapshotNews::Refused { why, .. }) => Some(why.clone()),
        _ => None,
    })
    .await;
    assert!(why.contains("not signed"), "{why}");
    // Every connection was dropped with the joined log; dialed again, it syncs op by op.
    eventually("the joined log is dropped", || async {
        n_ops(&b.handle).await == 0
    })
    .await;
    b.handle
        .dial(a.handle.local_addr())
        .await
        .expect("dials again");
    converge(&[&a.handle, &b.handle], 40).await;
    let sb = stats(&b.handle).await;
    assert_eq!((sb.n_snapshot_joins, sb.n_snapshots_refused), (1, 1));
    b.handle.shutdown().await.expect("stops");
    eventually("the joiner's store is released", || async {
        OpStore::<TestPayload>::open(&path).is_ok()
    })
    .await;
    assert_eq!(stored(&path), 40, "none of the forged ops was stored");
}

#[tokio::test]
async fn no_snapshot_or_a_broken_one_leaves_the_joiner_syncing_op_by_op() {
    let session = session_keys(INVITE).session_id();
    // A plain node keeps no scene, so it has no snapshot to give.
    let plain = net_support::node_with(1, INVITE, chat_log(1, 30, session));
    // One that serves bytes that are not a snapshot.
    let broken = spawn(
        3,
        chat_log(1, 30, session),
        None,
        false,
        Some(b"not a snapshot".to_vec()),
    );
    for (remote, what) in [
        (&plain.handle, "no snapshot"),
        (&broken.handle, "at byte 0"),
    ] {
        let mut b = spawn(2, Log::default(), None, true, None);
        b.handle.dial(remote.local_addr()).await.expect("dials");
        let why = next_event(&mut b.events, "the refusal", |e| match e {
            NodeEvent::Snapshot(SnapshotNews::Refused { why, .. }) => Some(why.clone()),
            _ => None,
        })
        .await;
        assert!(why.contains(what), "{why}");
        converge(&[remote, &b.handle], 30).await;
        let sb = stats(&b.handle).await;
        assert_eq!((sb.n_snapshot_joins, sb.n_snapshots_refused), (0, 1));
        b.handle.shutdown().await.expect("stops");
    }
}

#[tokio::test]
async fn two_joiners_with_empty_logs_sync_both_ways() {
    let a = spawn(1, Log::default(), None, true, None);
    let b = spawn(2, Log::default(), None, true, None);
    b.handle.dial(a.handle.local_addr()).await.expect("dials");
    // B says something first, then A answers, as two windows joining one invite do.
    b.handle
        .author(TestPayload::Chat("hello from b".into()))
        .await
        .expect("authors");
    eventually("a has b's op", || async { n_ops(&a.handle).await == 1 }).await;
    for i in 0..3 {
        a.handle
            .author(TestPayload::Chat(format!("a says {i}")))
            .await
            .expect("authors");
    }
    converge(&[&a.handle, &b.handle], 4).await;
    for node in [a, b] {
        node.handle.shutdown().await.expect("stops");
    }
}

/// The ops of the snapshot a joiner joins from, refusing none before it.
async fn joined_without_refusal(events: &mut tokio::sync::mpsc::Receiver<NodeEvent>) -> usize {
    next_event(events, "the join", |e| match e {
        NodeEvent::Snapshot(SnapshotNews::Joined { n_ops, .. }) => Some(*n_ops),
        NodeEvent::Snapshot(SnapshotNews::Refused { why, .. }) => panic!("refused: {why}"),
        _ => None,
    })
    .await
}

#[tokio::test]
async fn dialing_a_remote_again_while_its_snapshot_comes_keeps_the_one_connection() {
    let session = session_keys(INVITE).session_id();
    let a = spawn(1, chat_log(1, 300, session), None, false, None);
    let mut b = spawn(2, Log::default(), None, true, None);
    let addr = a.handle.local_addr();
    let first = b.handle.dial(addr).await.expect("dials");
    next_event(&mut b.events, "the fetch", |e| {
        matches!(e, NodeEvent::Snapshot(SnapshotNews::Fetching { .. })).then_some(())
    })
    .await;
    // The app dials its `--dial` addresses again while none of the connections its stats
    // list goes there, and a connection held back for the join is not listed yet. A second
    // connection would replace the first at both ends, and the fetch on it with it.
    let again = b.handle.dial(addr).await.expect("dials");
    assert_eq!(again, first);
    let joined = joined_without_refusal(&mut b.events).await;
    assert_eq!(joined, 300);
    assert_eq!(b.handle.dial(addr).await, Ok(first), "and once joined");
    let (sa, sb) = (stats(&a.handle).await, stats(&b.handle).await);
    assert_eq!(
        (sa.n_duplicates, sb.n_duplicates, sb.n_snapshots_refused),
        (0, 0, 0)
    );
}

/// Bytes a remote serves slowly enough that its connection can be cut while they come (they
/// are no snapshot: the fetch never ends with them).
const LONG_SERVE_BYTES: usize = 32 << 20;

#[tokio::test]
async fn a_snapshot_fetch_cut_by_its_connection_asks_the_remote_again_when_it_returns() {
    let session = session_keys(INVITE).session_id();
    let log = chat_log(1, 30, session);
    let a = spawn(1, log.clone(), None, false, Some(vec![0; LONG_SERVE_BYTES]));
    let mut b = spawn(2, Log::default(), None, true, None);
    b.handle.dial(a.handle.local_addr()).await.expect("dials");
    next_event(&mut b.events, "the fetch under way", |e| match e {
        NodeEvent::Snapshot(SnapshotNews::Fetching { bytes, .. }) => (*bytes > 0).then_some(()),
        _ => None,
    })
    .await;
    // The remote closes the connection mid-fetch and comes back (restarted: the same key, a
    // new address). Whichever the joiner hears of first, the fetch's failed read or its
    // connection's end, the remote was not refused: it is asked again.
    let peers = a.handle.connected_peers().await.expect("running");
    assert!(a.handle.close(peers[0].0).await.expect("running"));
    let why = next_event(&mut b.events, "the cut fetch", |e| match e {
        NodeEvent::Snapshot(SnapshotNews::Refused { why, .. }) => Some(why.clone()),
        _ => None,
    })
    .await;
    assert!(why.contains("connection ended"), "{why}");
    a.handle.shutdown().await.expect("stops");
    let back = spawn(1, log, None, false, None);
    b.handle
        .dial(back.handle.local_addr())
        .await
        .expect("dials");
    let joined = joined_without_refusal(&mut b.events).await;
    assert_eq!(joined, 30);
    converge(&[&back.handle, &b.handle], 30).await;
}
