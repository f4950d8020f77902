//! Nodes syncing over real QUIC sockets on 127.0.0.1: convergence of two and three nodes,
//! admission by invite, ephemeral datagrams, and reconnection in the middle of a sync.

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use net_support::*;
use replication::net::admission::AdmissionError;
use replication::net::node::{
    ADMISSION_DELAY_MILLIS, DialError, DisconnectReason, MAX_REJECTIONS_PER_CONN, NodeEvent,
    RefusalKind,
};
use replication::payload::LeaseAction;
use replication::payload::test_payload::TestPayload;
use replication::pending::PendingLimits;
use replication::{Keypair, Log, Timestamp};

#[tokio::test]
async fn two_nodes_converge_on_the_same_op_set() {
    let a = node(1);
    let b = node(2);
    author_some(&a.handle, 1, "alice").await;
    author_some(&b.handle, 2, "bob").await;
    let conn = b.handle.dial(a.handle.local_addr()).await.unwrap();
    converge(&[&a.handle, &b.handle], 8).await;
    // Live ops after the initial catch-up flow too.
    let late = a
        .handle
        .author(TestPayload::Chat("late".into()))
        .await
        .unwrap();
    converge(&[&a.handle, &b.handle], 9).await;
    assert!(op_ids(&b.handle).await.contains(&late));
    let peers = b.handle.connected_peers().await.unwrap();
    assert_eq!(peers, vec![(conn, a.handle.peer_id())]);
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(stats.n_admitted, 1);
    assert_eq!(stats.n_failed_admissions(), 0);
    assert_eq!(stats.connections[0].sync.n_rejected(), 0);
}

#[tokio::test]
async fn three_nodes_converge_through_a_line() {
    let (a, b, c) = (node(1), node(2), node(3));
    let all = [&a.handle, &b.handle, &c.handle];
    // Everyone takes a weak lease on object 7 and edits it offline: nobody saw another's
    // lease, so nobody's edit is bound by one (a lease binds only ops that saw it).
    for (h, tag) in [(&a.handle, "a"), (&b.handle, "b"), (&c.handle, "c")] {
        author_some(h, 7, tag).await;
    }
    // A - B - C: A and C never talk directly.
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    c.handle.dial(b.handle.local_addr()).await.unwrap();
    converge(&all, 12).await;
    let view = observe(&a.handle).await;
    assert!(
        view.iter()
            .all(|(_, mark, _)| *mark == replication::Mark::Effective),
        "concurrent leases bind no one: {view:?}"
    );
    for h in &all[1..] {
        assert_eq!(observe(h).await, view, "every node judges the same");
    }
    // Leases still bind the ops that saw them: C takes the lease over, and A's next edit,
    // authored once A has seen that, is refused on every node.
    let take = TestPayload::Lease(LeaseAction::Acquire {
        object: 7,
        strong: false,
        ttl_micros: 60_000_000,
    });
    c.handle.author(take).await.unwrap();
    converge(&all, 13).await;
    let late = TestPayload::Set {
        object: 7,
        value: "a, too late".into(),
    };
    let late = a.handle.author(late).await.unwrap();
    converge(&all, 14).await;
    for h in all {
        let marks = observe(h).await;
        let (_, mark, active) = marks.iter().find(|(id, _, _)| *id == late).unwrap();
        assert!(
            matches!(mark, replication::Mark::Rejected(_)) && !active,
            "{mark:?}"
        );
    }
    let live = c
        .handle
        .author(TestPayload::Chat("from c".into()))
        .await
        .unwrap();
    converge(&all, 15).await;
    assert!(op_ids(&a.handle).await.contains(&live));
    assert!(a.handle.connected_peers().await.unwrap().len() == 1);
}

#[tokio::test]
async fn a_node_with_the_wrong_invite_is_refused() {
    let mut a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let intruder = node_with(9, OTHER_INVITE, Log::default());
    let refused = intruder.handle.dial(a.handle.local_addr()).await;
    assert!(
        matches!(
            refused,
            Err(DialError::Admission(AdmissionError::RefusedByRemote(_)))
        ),
        "{refused:?}"
    );
    let error = next_event(&mut a.events, "the refusal event", |e| match e {
        NodeEvent::AdmissionFailed { error, .. } => Some(error.clone()),
        _ => None,
    })
    .await;
    assert_eq!(error, AdmissionError::WrongInvite);
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(
        stats.failed_admissions.get(&RefusalKind::WrongInvite),
        Some(&1)
    );
    assert_eq!(stats.n_admitted, 0);
    assert!(stats.connections.is_empty());
    let intruder_stats = intruder.handle.stats().await.unwrap();
    assert_eq!(
        intruder_stats
            .failed_admissions
            .get(&RefusalKind::RefusedByRemote),
        Some(&1)
    );
    assert_eq!(
        n_ops(&intruder.handle).await,
        0,
        "nothing leaked to the intruder"
    );
    // An honest node still gets in afterwards.
    let b = node(2);
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    converge(&[&a.handle, &b.handle], 4).await;
}

/// How many pairs dial each other at once: enough that the remote's duplicate close reaches a
/// dialer still in admission in some of them (it did in a CI run with one pair).
const N_SIMULTANEOUS_PAIRS: u8 = 24;

#[tokio::test]
async fn peers_that_dial_each_other_at_once_keep_one_connection_and_count_no_failure() {
    let mut pairs = Vec::new();
    for i in 0..N_SIMULTANEOUS_PAIRS {
        pairs.push((node(10 + 2 * i), node(11 + 2 * i)));
    }
    let dials: Vec<_> = pairs
        .iter()
        .map(|(a, b)| {
            let (a, b) = (a.handle.clone(), b.handle.clone());
            tokio::spawn(
                async move { tokio::join!(a.dial(b.local_addr()), b.dial(a.local_addr())) },
            )
        })
        .collect();
    let mut n_duplicates = 0;
    for ((a, b), dialing) in pairs.iter().zip(dials) {
        let (from_a, from_b) = dialing.await.unwrap();
        // Each dial ends connected, or told that the remote kept the other connection.
        for r in [&from_a, &from_b] {
            assert!(
                matches!(
                    r,
                    Ok(_) | Err(DialError::Admission(AdmissionError::Superseded))
                ),
                "{r:?}"
            );
        }
        eventually("each pair keeps one connection", || async {
            a.handle.connected_peers().await.unwrap().len() == 1
                && b.handle.connected_peers().await.unwrap().len() == 1
        })
        .await;
        for h in [&a.handle, &b.handle] {
            let stats = h.stats().await.unwrap();
            assert_eq!(stats.n_failed_admissions(), 0, "{stats:?}");
            n_duplicates += stats.n_duplicates;
        }
    }
    assert!(
        n_duplicates >= u64::from(N_SIMULTANEOUS_PAIRS),
        "{n_duplicates}"
    );
}

#[tokio::test]
async fn dialing_oneself_is_refused() {
    let a = node(1);
    let result = a.handle.dial(a.handle.local_addr()).await;
    assert_eq!(result, Err(DialError::SelfConnection));
    // Both ends of the looped connection are this node, and both refuse it.
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(
        stats.failed_admissions.get(&RefusalKind::SelfConnection),
        Some(&2)
    );
    assert!(stats.connections.is_empty());
}

#[tokio::test]
async fn an_ephemeral_value_arrives_as_a_datagram_and_is_not_stored() {
    let a = node(1);
    let mut b = node(2);
    author_some(&a.handle, 1, "alice").await;
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    converge(&[&a.handle, &b.handle], 4).await;
    a.handle
        .send_ephemeral(5, b"pose 1 2 3".to_vec())
        .await
        .unwrap();
    let (peer, value) = next_event(&mut b.events, "the ephemeral value", |e| match e {
        NodeEvent::Ephemeral {
            peer,
            channel: 5,
            value,
            ..
        } => Some((*peer, value.clone())),
        _ => None,
    })
    .await;
    assert_eq!(peer, a.handle.peer_id());
    assert_eq!(value, b"pose 1 2 3");
    assert_eq!(
        n_ops(&b.handle).await,
        4,
        "ephemeral values never enter the log"
    );
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(stats.n_datagrams_dropped, 0);
    // Too large for the core: refused at the source, nothing sent.
    let big = vec![0; replication::sync::message::MAX_EPHEMERAL_BYTES + 1];
    assert!(a.handle.send_ephemeral(5, big).await.is_err());
}

#[tokio::test]
async fn a_connection_killed_mid_sync_reconnects_and_converges() {
    // Several batches of at most 64, so the kill lands in the middle; few in a debug build,
    // which verifies only about 40 signatures per second.
    const N_OPS: usize = if cfg!(debug_assertions) { 150 } else { 5_000 };
    let mut log = Log::default();
    log.set_session_id(session_keys(INVITE).session_id());
    let alice = Keypair::from_seed([1; 32]);
    for i in 0..N_OPS {
        let payload = TestPayload::Chat(format!("line {i}"));
        log.author(&alice, Timestamp(1_000 + i as u64), payload)
            .unwrap();
    }
    let a = node_with(1, INVITE, log);
    let mut b = node(2);
    let first = b.handle.dial(a.handle.local_addr()).await.unwrap();
    // Kill the connection as soon as the first batch lands.
    next_event(&mut b.events, "the first batch", |e| {
        matches!(e, NodeEvent::Delivered { .. }).then_some(())
    })
    .await;
    assert!(b.handle.close(first).await.unwrap());
    let n_at_kill = n_ops(&b.handle).await;
    assert!(
        n_at_kill > 0 && n_at_kill < N_OPS,
        "the kill must land mid-sync: {n_at_kill} of {N_OPS}"
    );
    let reason = next_event(&mut b.events, "the disconnect", |e| match e {
        NodeEvent::Disconnected { reason, .. } => Some(reason.clone()),
        _ => None,
    })
    .await;
    assert_eq!(reason, DisconnectReason::Closed);
    eventually("A notices the loss", || async {
        a.handle.connected_peers().await.unwrap().is_empty()
    })
    .await;
    // A fresh connection starts a fresh sync state and finishes the job.
    let second = b.handle.dial(a.handle.local_addr()).await.unwrap();
    assert_ne!(first, second);
    converge(&[&a.handle, &b.handle], N_OPS).await;
}

/// A scratch file path for this test, removed first.
fn scratch_store(name: &str) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("sculpt-net-{}-{name}.ops", std::process::id()));
    let _ = std::fs::remove_file(&path);
    path
}

/// A node of the test session whose ops go to a new store at `path`.
fn node_with_store(seed: u8, path: &std::path::Path) -> TNode {
    let (store, _, _) = replication::store::OpStore::<TestPayload>::open(path).unwrap();
    replication::net::Node::spawn(replication::net::NodeConfig {
        keypair: Keypair::from_seed([seed; 32]),
        keys: session_keys(INVITE),
        listen: "127.0.0.1:0".parse().unwrap(),
        log: Log::default(),
        store: Some(store),
        join_from_snapshot: false,
    })
    .unwrap()
}

#[tokio::test]
async fn a_node_with_a_store_persists_authored_and_received_ops() {
    use replication::store::OpStore;
    let path = scratch_store("persist");
    let b = node_with_store(2, &path);
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    author_some(&b.handle, 2, "bob").await;
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    converge(&[&a.handle, &b.handle], 8).await;
    let held = op_ids(&b.handle).await;
    b.handle.shutdown().await.unwrap();
    // Reopened, the store holds every op B authored or received, signatures checked.
    let mut reloaded = Log::<TestPayload>::default();
    reloaded.set_session_id(session_keys(INVITE).session_id());
    OpStore::open_into(&path, Timestamp(0), &mut reloaded).unwrap();
    let stored: std::collections::BTreeSet<_> = reloaded.entries().map(|e| e.op.id()).collect();
    assert_eq!(stored, held);
    std::fs::remove_file(&path).unwrap();
}

#[tokio::test]
async fn a_received_batch_of_ops_costs_one_fsync_not_one_per_op() {
    use replication::store::OpStore;
    let path = scratch_store("batched-fsync");
    let b = node_with_store(2, &path);
    let a = node(1);
    let n_ops = 320;
    for i in 0..n_ops {
        a.handle
            .author(TestPayload::Chat(format!("line {i}")))
            .await
            .unwrap();
    }
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    converge(&[&a.handle, &b.handle], n_ops).await;
    let syncs = b.handle.stats().await.unwrap().n_store_syncs;
    // Batches carry up to 64 ops; a step may deliver one or several.
    assert!(
        (1..=n_ops as u64 / 8).contains(&syncs),
        "{syncs} fsyncs for {n_ops} received ops"
    );
    b.handle.shutdown().await.unwrap();
    let mut reloaded = Log::<TestPayload>::default();
    reloaded.set_session_id(session_keys(INVITE).session_id());
    OpStore::open_into(&path, Timestamp(0), &mut reloaded).unwrap();
    assert_eq!(reloaded.len(), n_ops);
    std::fs::remove_file(&path).unwrap();
}

/// A session that binds its authors: a fresh key that a node meets is admitted by it, then
/// syncs and edits; a key that nobody admitted has its ops refused by every node alike.
#[tokio::test]
async fn a_node_admits_a_fresh_key_and_every_node_refuses_a_key_nobody_admitted() {
    use replication::membership::Admission;
    let founder = Keypair::from_seed([1; 32]);
    let nonce = [7; 32];
    let invite = replication::net::Invite::for_founder(&founder.peer_id(), &nonce).to_string();
    let bound = || {
        let invite = replication::net::Invite::parse(&invite).unwrap();
        assert!(invite.binds_authors());
        let mut log = Log::default();
        log.set_founder(invite.founder_commitment()).unwrap();
        log.bind_authors(replication::log::MAX_LOG_BYTES).unwrap();
        log
    };
    let set = |object, value: &str| TestPayload::Set {
        object,
        value: value.into(),
    };
    let a = node_with(1, &invite, bound());
    let founding = TestPayload::Admit(Admission {
        key: founder.peer_id(),
        grant_bytes: 0,
        nonce: Some(nonce),
    });
    a.handle.author(founding).await.unwrap();
    a.handle.author(set(1, "founder's")).await.unwrap();
    let b = node_with(2, &invite, bound());
    let refused = b.handle.author(set(2, "too soon")).await.unwrap_err();
    assert!(
        refused
            .to_string()
            .contains("waiting for a member to admit this peer"),
        "{refused}"
    );
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    let b_id = b.handle.peer_id();
    eventually("b holds its admission", || async {
        b.handle
            .with_peer(move |p| p.log().is_admitted(&b_id))
            .await
            .unwrap()
    })
    .await;
    b.handle.author(set(2, "newcomer's")).await.unwrap();
    converge(&[&a.handle, &b.handle], 4).await;
    assert_eq!(a.handle.stats().await.unwrap().n_keys_admitted, 1);
    // A key minted offline writes in its own log (which does not bind) and sends its ops the
    // moment it connects: every node refuses them, and still does once b admits the key (a
    // does not: one key per source address is admitted per interval, and b's took this
    // address's), since the first of them names no admission.
    let mut own = Log::default();
    let founder_of = replication::net::Invite::parse(&invite).unwrap();
    own.set_founder(founder_of.founder_commitment()).unwrap();
    let c = node_with(3, &invite, own);
    let minted = c.handle.author(set(3, "sybil")).await.unwrap();
    c.handle.author(set(3, "sybil again")).await.unwrap();
    c.handle.dial(a.handle.local_addr()).await.unwrap();
    c.handle.dial(b.handle.local_addr()).await.unwrap();
    eventually("b admits c's key", || async {
        b.handle.stats().await.unwrap().n_keys_admitted == 1
    })
    .await;
    let last = c.handle.author(set(3, "sybil, admitted")).await.unwrap();
    converge(&[&a.handle, &b.handle], 5).await;
    tokio::time::sleep(std::time::Duration::from_millis(2 * ADMISSION_DELAY_MILLIS)).await;
    for h in [&a.handle, &b.handle] {
        let held = op_ids(h).await;
        assert!(!held.contains(&minted) && !held.contains(&last));
        assert_eq!(held.len(), 5);
    }
    assert_eq!(a.handle.stats().await.unwrap().n_keys_admitted, 1);
}

/// `n` ops authored by the node of key `seed` while apart ([`TestPayload::backlog`]), in a
/// log whose pending buffer holds `pending` ops.
fn backlog(seed: u8, n: usize, pending: usize) -> Log<TestPayload> {
    let key = Keypair::from_seed([seed; 32]);
    let mut log = Log::with_pending_limits(PendingLimits {
        max_ops: pending,
        ..PendingLimits::default()
    });
    log.set_session_id(session_keys(INVITE).session_id());
    for k in 0..n {
        let payload = TestPayload::backlog(seed, k);
        log.author(&key, Timestamp(1_000 + k as u64 * 50), payload)
            .unwrap();
    }
    log
}

/// Two nodes that worked apart meet with concurrent backlogs of 32 pending buffers each (a
/// buffer of 128 ops here, so that the overrun does not depend on the machine's speed; with
/// the real 4,096 it took 32,768 ops a side in a release build): the refold budget holds
/// each side's first ops and the streams overrun the buffers. Their drops counted as
/// rejections and cut the connection off within a second, after which the two never
/// synced. Dropped ops are no offence: the nodes converge.
#[tokio::test]
async fn concurrent_backlogs_past_the_pending_buffer_sync_without_a_cut_off() {
    let (n, pending) = (4_096, 128);
    let a = node_with(1, INVITE, backlog(1, n, pending));
    let b = node_with(2, INVITE, backlog(2, n, pending));
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    eventually("both nodes hold both backlogs", || async {
        n_ops(&a.handle).await == 2 * n && n_ops(&b.handle).await == 2 * n
    })
    .await;
    assert_eq!(op_ids(&a.handle).await, op_ids(&b.handle).await);
    let mut n_dropped_full = 0;
    for h in [&a.handle, &b.handle] {
        let stats = h.stats().await.unwrap();
        assert_eq!((stats.n_cut_off, stats.connections.len()), (0, 1));
        let sync = &stats.connections[0].sync;
        assert_eq!(sync.n_offences(), 0, "{:?}", sync.rejected);
        n_dropped_full += sync.n_rejected();
    }
    assert!(n_dropped_full > MAX_REJECTIONS_PER_CONN, "{n_dropped_full}");
}
