//! Discovery over real sockets: two nodes find each other through a discovery server on
//! 127.0.0.1 and sync, and the server counts bad input. (LAN discovery by DNS-SD is tested in
//! `net_dnssd.rs`, inside a private network namespace.)

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use net_support::*;
use replication::Keypair;
use replication::net::discovery::message::{DiscoveryMessage, NO_COOKIE, REGISTER_BYTES};
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
    let alice = Keypair::from_seed([1; 32]);
    assert_eq!(alice.peer_id(), a.handle.peer_id());
    let found = discovery::register(server_addr, keys.discovery_id(), &alice, port(&a.handle))
        .await
        .unwrap();
    assert!(found.is_empty(), "A is the first: {found:?}");
    // Another session registered at the same server stays invisible to ours.
    let other = session_keys(OTHER_INVITE);
    let stranger = Keypair::from_seed([9; 32]);
    let found = discovery::register(server_addr, other.discovery_id(), &stranger, 9)
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
    let found = discovery::register(server_addr, keys.discovery_id(), &alice, port(&a.handle))
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
    let mut short = DiscoveryMessage::register(&alice, keys.discovery_id(), 1, NO_COOKIE).encode();
    short.truncate(REGISTER_BYTES / 2);
    prober.send_to(&short, server_addr).unwrap();
    prober
        .send_to(&DiscoveryMessage::Peers(Vec::new()).encode(), server_addr)
        .unwrap();
    // A last good request, answered, proves the server read the three before it.
    discovery::register(
        server_addr,
        other.discovery_id(),
        &Keypair::from_seed([8; 32]),
        8,
    )
    .await
    .unwrap();
    shutdown.store(true, Ordering::Relaxed);
    let stats = serving.join().unwrap().unwrap();
    assert_eq!(stats.n_malformed, 2, "{stats:?}");
    assert_eq!(stats.n_unexpected, 1, "{stats:?}");
    assert!(stats.n_registered >= 4, "{stats:?}");
    assert_eq!(stats.n_replies, stats.n_registered, "{stats:?}");
    // Every registration went through one challenge round trip (the node's rendezvous keeps
    // its cookie between refreshes), and nothing was answered with more than it sent.
    assert!(stats.n_challenged >= 4, "{stats:?}");
    assert!(stats.n_bytes_sent <= stats.n_bytes_received, "{stats:?}");
}
