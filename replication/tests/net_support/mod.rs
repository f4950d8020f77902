//! Helpers shared by the `net_*` integration tests: nodes on 127.0.0.1, polling with a
//! deadline, and op-set comparison.

#![allow(
    dead_code,
    reason = "each test binary uses a different subset of the helpers"
)]

use std::collections::{BTreeMap, BTreeSet};
use std::future::Future;
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use replication::net::node::NodeEvent;
use replication::net::{Invite, Node, NodeConfig, NodeHandle, SessionKeys};
use replication::payload::LeaseAction;
use replication::payload::test_payload::TestPayload;
use replication::{Keypair, Log, OpId};

/// The invite every honest test node uses.
pub const INVITE: &str = "7m6ev-tzwff-057jy-6w0z1-mdsgb-ppr41-n5kh6";
/// The invite of another session.
pub const OTHER_INVITE: &str = "jjx9f-k1qqv-xv5sj-z7vzr-sgty0-1e832-6vb7f";

/// How long a test may wait for anything before it fails.
pub const PATIENCE: Duration = Duration::from_secs(20);

pub type TNode = Node<TestPayload>;
pub type THandle = NodeHandle<TestPayload>;

/// A node with key `seed` in the session of `invite`, listening on 127.0.0.1.
pub fn node_with(seed: u8, invite: &str, log: Log<TestPayload>) -> TNode {
    Node::spawn(NodeConfig {
        keypair: Keypair::from_seed([seed; 32]),
        keys: session_keys(invite),
        listen: "127.0.0.1:0".parse().expect("loopback address"),
        log,
        store: None,
        join_from_snapshot: false,
    })
    .expect("node starts")
}

/// The keys of the session of `invite` (one of the test invites above), derived once per
/// test binary: the discovery id's stretch is slow on purpose.
pub fn session_keys(invite: &str) -> SessionKeys {
    static KEYS: Mutex<BTreeMap<String, SessionKeys>> = Mutex::new(BTreeMap::new());
    let mut keys = KEYS.lock().unwrap_or_else(PoisonError::into_inner);
    keys.entry(invite.to_owned())
        .or_insert_with(|| SessionKeys::from_invite(&Invite::parse(invite).expect("test invite")))
        .clone()
}

/// A node with key `seed` in the honest test session, with an empty log.
pub fn node(seed: u8) -> TNode {
    node_with(seed, INVITE, Log::default())
}

/// Polls `check` every few milliseconds until it returns true; panics with `what` after
/// [`PATIENCE`].
pub async fn eventually<F, Fut>(what: &str, mut check: F)
where
    F: FnMut() -> Fut,
    Fut: Future<Output = bool>,
{
    let polling = async {
        while !check().await {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    };
    if tokio::time::timeout(PATIENCE, polling).await.is_err() {
        panic!("timed out waiting until {what}");
    }
}

/// Waits for the first event that `pick` maps to `Some`, skipping the others.
pub async fn next_event<T>(
    events: &mut tokio::sync::mpsc::Receiver<NodeEvent>,
    what: &str,
    mut pick: impl FnMut(&NodeEvent) -> Option<T>,
) -> T {
    let waiting = async {
        loop {
            let event = events.recv().await.expect("node running");
            if let Some(found) = pick(&event) {
                return found;
            }
        }
    };
    match tokio::time::timeout(PATIENCE, waiting).await {
        Ok(found) => found,
        Err(_) => panic!("timed out waiting for {what}"),
    }
}

/// The ids of every op in the node's log, with their verdicts, in linear order.
pub async fn observe(handle: &THandle) -> Vec<(OpId, replication::Mark, bool)> {
    handle
        .with_peer(|p| {
            p.log()
                .entries()
                .map(|e| (e.op.id(), e.mark, e.active))
                .collect()
        })
        .await
        .expect("node running")
}

/// The set of op ids in the node's log.
pub async fn op_ids(handle: &THandle) -> BTreeSet<OpId> {
    handle
        .with_peer(|p| p.log().entries().map(|e| e.op.id()).collect())
        .await
        .expect("node running")
}

/// Number of ops in the node's log.
pub async fn n_ops(handle: &THandle) -> usize {
    handle
        .with_peer(|p| p.log().len())
        .await
        .expect("node running")
}

/// Waits until every node holds exactly `n_expected` ops and they all agree on the order and
/// the verdicts.
pub async fn converge(handles: &[&THandle], n_expected: usize) {
    eventually(
        &format!("{} nodes converge on {n_expected} ops", handles.len()),
        || async {
            let mut views = Vec::new();
            for h in handles {
                views.push(observe(h).await);
            }
            views.iter().all(|v| v.len() == n_expected) && views.windows(2).all(|w| w[0] == w[1])
        },
    )
    .await;
}

/// Authors a few ops: an edit of `object` (which makes it), a lease on it, another edit and
/// a chat line.
pub async fn author_some(handle: &THandle, object: u64, tag: &str) -> Vec<OpId> {
    let payloads = [
        TestPayload::Set {
            object,
            value: format!("{tag} first"),
        },
        TestPayload::Lease(LeaseAction::Acquire {
            object,
            strong: false,
            ttl_micros: 60_000_000,
        }),
        TestPayload::Set {
            object,
            value: format!("{tag} second"),
        },
        TestPayload::Chat(format!("{tag} says hi")),
    ];
    let mut ids = Vec::new();
    for payload in payloads {
        ids.push(handle.author(payload).await.expect("authoring works"));
    }
    ids
}
