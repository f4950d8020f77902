//! A connection stalled by an outage: two nodes talk through a UDP relay on 127.0.0.1 that
//! can drop every datagram, as a Wi-Fi drop or an unplugged cable does. Once the outage ends,
//! QUIC's own probes have backed off (each waits twice as long as the last), so the stalled
//! connection would resume only at the next one; the end with the smaller id dials again
//! instead, and the new connection replaces the stalled one at both ends. An outage longer
//! than the idle timeout closes the connection: the smaller id then dials the remote again
//! until it answers, whatever finds peers.

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use net_support::*;
use replication::payload::test_payload::TestPayload;
use tokio::net::UdpSocket;

/// Forwards datagrams between a node that sends to its front and the node at `target`
/// (from its back), both ways, unless cut. Every flow between the two nodes' sockets, a new
/// connection's included, goes through the same two sockets.
struct Relay {
    front: SocketAddr,
    cut: Arc<AtomicBool>,
}

impl Relay {
    async fn start(target: SocketAddr) -> Relay {
        let front = Arc::new(UdpSocket::bind("127.0.0.1:0").await.unwrap());
        let back = Arc::new(UdpSocket::bind("127.0.0.1:0").await.unwrap());
        let cut = Arc::new(AtomicBool::new(false));
        let relay = Relay {
            front: front.local_addr().unwrap(),
            cut: cut.clone(),
        };
        let (front_in, back_out, cut_in) = (front.clone(), back.clone(), cut.clone());
        let (sender, client) = tokio::sync::watch::channel(None::<SocketAddr>);
        tokio::spawn(async move {
            let mut buf = vec![0u8; 65_536];
            while let Ok((n, from)) = front_in.recv_from(&mut buf).await {
                sender.send_replace(Some(from));
                if !cut_in.load(Ordering::SeqCst) {
                    let _ = back_out.send_to(&buf[..n], target).await;
                }
            }
        });
        tokio::spawn(async move {
            let mut buf = vec![0u8; 65_536];
            while let Ok((n, _)) = back.recv_from(&mut buf).await {
                let to = *client.borrow();
                if let Some(to) = to
                    && !cut.load(Ordering::SeqCst)
                {
                    let _ = front.send_to(&buf[..n], to).await;
                }
            }
        });
        relay
    }

    fn set_cut(&self, cut: bool) {
        self.cut.store(cut, Ordering::SeqCst);
    }
}

/// The two nodes with their stats, the one with the smaller id first (the one that dials).
async fn smaller_id_first(
    mut handles: [&THandle; 2],
) -> [(&THandle, replication::net::node::NodeStats); 2] {
    handles.sort_by_key(|h| h.peer_id());
    let [lower, higher] = handles;
    [
        (lower, lower.stats().await.unwrap()),
        (higher, higher.stats().await.unwrap()),
    ]
}

/// Two nodes whose connection goes through a relay, dialed by the first, each with four ops
/// of its own, synced; and the connection's id at the first.
async fn synced_through_relay() -> (TNode, TNode, Relay, replication::ConnId) {
    let (a, b) = (node(1), node(2));
    let relay = Relay::start(b.handle.local_addr()).await;
    let first = a.handle.dial(relay.front).await.unwrap();
    author_some(&a.handle, 1, "a").await;
    author_some(&b.handle, 2, "b").await;
    converge(&[&a.handle, &b.handle], 8).await;
    (a, b, relay, first)
}

/// Long enough that QUIC's probes, doubling from about 30 ms on loopback, leave seconds
/// between the outage's end and their next try.
const OUTAGE: Duration = Duration::from_millis(4_000);
/// What a redial may take from the outage's end to both logs equal: a dial begun during the
/// outage gives way within a quarter second, then a handshake, an admission and a hello on
/// loopback (slack for a loaded machine).
/// Ops each end authors three times during the outage, of about [`BULKY_BYTES`] each: more
/// than QUIC's congestion window lets out unacknowledged, so what follows waits for a probe.
const N_BULKY: usize = 60;
const BULKY_BYTES: usize = 200;
const MAX_RESUME: Duration = Duration::from_millis(1_500);

#[tokio::test]
async fn a_connection_stalled_by_an_outage_is_redialed_when_it_ends() {
    let (a, b, relay, first) = synced_through_relay().await;

    relay.set_cut(true);
    // Both ends edit during the outage, so batches wait at both.
    for i in 0..3 {
        for h in [&a.handle, &b.handle] {
            for j in 0..N_BULKY {
                let line = format!("offline {i} {j} {}", "x".repeat(BULKY_BYTES));
                h.author(TestPayload::Chat(line)).await.unwrap();
            }
        }
        tokio::time::sleep(OUTAGE / 3).await;
    }
    relay.set_cut(false);
    let healed = tokio::time::Instant::now();
    converge(&[&a.handle, &b.handle], 8 + 6 * N_BULKY).await;
    let resumed = healed.elapsed();

    let [(lower, low), (higher, high)] = smaller_id_first([&a.handle, &b.handle]).await;
    assert!(low.n_stall_redials >= 1, "the smaller id redials: {low:?}");
    assert_eq!(low.n_stalls_replaced, 1, "{low:?}");
    assert_eq!(high.n_stall_redials, 0, "only the smaller id redials");
    assert_eq!(low.n_failed_admissions(), 0, "a failed redial is not news");
    for h in [lower, higher] {
        let peers = h.connected_peers().await.unwrap();
        assert_eq!(peers.len(), 1, "one connection each, the new one");
    }
    let peers = a.handle.connected_peers().await.unwrap();
    if a.handle.peer_id() < b.handle.peer_id() {
        assert_ne!(peers[0].0, first, "the stalled connection was replaced");
    }
    assert!(
        resumed < MAX_RESUME,
        "took {resumed:?} after the outage to converge"
    );
    println!("converged {resumed:?} after a {OUTAGE:?} outage");
}

/// Longer than QUIC's idle timeout, which then closes the connection at both ends.
const LONG_OUTAGE: Duration =
    Duration::from_millis(replication::net::tls::IDLE_TIMEOUT_MILLIS + 1_000);
/// What a dial again may take from the long outage's end to both logs equal: the next dial
/// within a quarter second, then a handshake, an admission and a hello on loopback (slack for
/// a loaded machine).
const MAX_RECONNECT: Duration = Duration::from_millis(2_000);

#[tokio::test]
async fn a_connection_the_idle_timeout_closed_is_dialed_again_when_the_outage_ends() {
    let (a, b, relay, _) = synced_through_relay().await;

    relay.set_cut(true);
    for h in [&a.handle, &b.handle] {
        h.author(TestPayload::Chat("away".into())).await.unwrap();
    }
    // Nobody finds peers here (no finder, no dial of the app's): only the node's own dials
    // can bring the two together again once the idle timeout has closed their connection.
    let closed = tokio::time::Instant::now();
    tokio::time::sleep(LONG_OUTAGE).await;
    for h in [&a.handle, &b.handle] {
        let peers = h.connected_peers().await.unwrap();
        assert!(peers.is_empty(), "the idle timeout closed it: {peers:?}");
    }
    relay.set_cut(false);
    let healed = tokio::time::Instant::now();
    converge(&[&a.handle, &b.handle], 10).await;
    let back = healed.elapsed();

    let [(_, low), (_, high)] = smaller_id_first([&a.handle, &b.handle]).await;
    // It dialed while the outage lasted (those failed quietly), then once it was over.
    assert!(
        low.n_lost_redials >= 2,
        "the smaller id dials again: {low:?}"
    );
    assert_eq!(low.n_lost_reconnected, 1, "{low:?}");
    assert_eq!(high.n_lost_redials, 0, "only the smaller id dials again");
    assert_eq!(
        low.n_failed_admissions(),
        0,
        "a failed dial again is not news"
    );
    assert!(
        back < MAX_RECONNECT,
        "took {back:?} after a {:?} outage to converge",
        closed.elapsed() - back
    );
    println!("converged {back:?} after a {LONG_OUTAGE:?} outage");
}

/// Short enough that QUIC's probes still find the path soon after: the stalled connection
/// resumes by itself, and its first message is the first sign that the network is back.
const SHORT_OUTAGE: Duration = Duration::from_millis(1_500);

/// The first word from a remote after a silence tells whatever finds peers that the network
/// may be back ([`NodeHandle::resumed`](replication::net::node::NodeHandle::resumed)), and
/// so does a dial that replaced a stalled connection: the end with the smaller id, which
/// either hears the stalled connection again or replaces it, always learns it once the outage
/// ends; it is counted at most once per
/// [`replication::net::node::RESUMED_DIALS_EVERY_MILLIS`].
#[tokio::test]
async fn a_remote_heard_after_an_outage_brings_the_dials_forward() {
    let (a, b, relay, _) = synced_through_relay().await;

    relay.set_cut(true);
    let [(lower, low), (higher, _)] = smaller_id_first([&a.handle, &b.handle]).await;
    let mut resumed = lower.resumed();
    // A few bytes at each end: batches wait at both.
    for h in [lower, higher] {
        h.author(TestPayload::Chat("away".into())).await.unwrap();
    }
    tokio::time::sleep(SHORT_OUTAGE).await;
    assert!(
        !resumed.has_changed().unwrap(),
        "nothing came during the outage"
    );
    assert_eq!(
        lower.stats().await.unwrap().n_resumed_rounds,
        low.n_resumed_rounds
    );
    relay.set_cut(false);
    converge(&[lower, higher], 10).await;
    let after = lower.stats().await.unwrap();
    assert!(
        after.n_resumed_rounds > low.n_resumed_rounds,
        "the network's return was noted: {after:?}"
    );
    assert!(resumed.has_changed().unwrap(), "the finders hear of it");
    resumed.mark_unchanged();
}
