//! Discovery over real sockets: two nodes find each other through a discovery server on
//! 127.0.0.1 and sync, and the server counts bad input. (LAN discovery by DNS-SD is tested in
//! `net_dnssd.rs`, inside a private network namespace.)

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use net_support::*;
use replication::net::discovery::message::{DiscoveryMessage, REGISTER_BYTES};
use replication::net::discovery::{self, DiscoveredPeer, DiscoveryServer};

#[tokio::test]
async fn two_nodes_find_each_other_through_the_discovery_server_and_sync() {
    let server = DiscoveryServer::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let server_addr = server.local_addr().unwrap();
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    let serving = std::thread::Builder::new()
        .name("discovery-server".into())
        .spawn(move || server.run(&flag))
        .unwrap();

    let keys = session_keys(INVITE);
    let a = node(1);
    let b = node(2);
    author_some(&a.handle, 1, "alice").await;
    author_some(&b.handle, 2, "bob").await;
    let port = |h: &THandle| h.local_addr().port();
    let found = discovery::register(
        server_addr,
        keys.discovery_id(),
        a.handle.peer_id(),
        port(&a.handle),
    )
    .await
    .unwrap();
    assert!(found.is_empty(), "A is the first: {found:?}");
    // Another session registered at the same server stays invisible to ours.
    let other = session_keys(OTHER_INVITE);
    let found = discovery::register(server_addr, other.discovery_id(), [9; 32].into_peer(), 9)
        .await
        .unwrap();
    assert!(found.is_empty());
    // B keeps itself registered and dials whom it learns: A.
    tokio::spawn(discovery::client::stay_registered(
        server_addr,
        keys.discovery_id(),
        b.handle.clone(),
    ));
    converge(&[&a.handle, &b.handle], 8).await;
    // Now A learns B too, at the address B's QUIC endpoint listens on.
    let found = discovery::register(
        server_addr,
        keys.discovery_id(),
        a.handle.peer_id(),
        port(&a.handle),
    )
    .await
    .unwrap();
    assert_eq!(
        found,
        vec![DiscoveredPeer {
            peer: b.handle.peer_id(),
            addr: b.handle.local_addr()
        }]
    );
    // Dialing what it learnt does nothing new: B is already connected.
    assert!(a.handle.dial_discovered(&found).await.is_empty());

    // Garbage, an unpadded registration and a reply-shaped datagram are counted, unanswered.
    let prober = UdpSocket::bind("127.0.0.1:0").unwrap();
    prober
        .send_to(b"GET / HTTP/1.1\r\n\r\n", server_addr)
        .unwrap();
    let mut short = DiscoveryMessage::Register {
        discovery_id: keys.discovery_id(),
        peer: a.handle.peer_id(),
        port: 1,
    }
    .encode();
    short.truncate(REGISTER_BYTES / 2);
    prober.send_to(&short, server_addr).unwrap();
    prober
        .send_to(&DiscoveryMessage::Peers(Vec::new()).encode(), server_addr)
        .unwrap();
    // A last good request, answered, proves the server read the three before it.
    discovery::register(server_addr, other.discovery_id(), [8; 32].into_peer(), 8)
        .await
        .unwrap();
    shutdown.store(true, Ordering::Relaxed);
    let stats = serving.join().unwrap().unwrap();
    assert_eq!(stats.n_malformed, 2, "{stats:?}");
    assert_eq!(stats.n_unexpected, 1, "{stats:?}");
    assert!(stats.n_registered >= 4, "{stats:?}");
    assert_eq!(stats.n_replies, stats.n_registered, "{stats:?}");
}

/// Converts test bytes into a peer id.
trait IntoPeer {
    fn into_peer(self) -> replication::PeerId;
}

impl IntoPeer for [u8; 32] {
    fn into_peer(self) -> replication::PeerId {
        replication::PeerId(self)
    }
}
