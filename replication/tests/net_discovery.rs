//! Discovery over real sockets: two nodes find each other through a discovery server on
//! 127.0.0.1 and sync; the server counts bad input; and LAN multicast discovery, run inside
//! a private network namespace so that multicast never leaves this test.

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::net::{Ipv4Addr, UdpSocket};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use net_support::*;
use replication::net::discovery::lan::{self, LanConfig, LanDiscovery};
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

/// Set in the child process that runs inside the private network namespace.
const IN_NAMESPACE: &str = "SCULPT_NET_TEST_IN_NAMESPACE";

#[test]
fn lan_multicast_discovery_finds_peers_that_then_sync() {
    if std::env::var_os(IN_NAMESPACE).is_some() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        return runtime.block_on(lan_in_namespace());
    }
    // Multicast is sent only inside a network namespace of our own (loopback only), never
    // on the machine's real interfaces: the test re-runs itself there.
    let usable = Command::new("unshare")
        .args(["-rn", "ip", "link", "set", "lo", "up"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !usable {
        eprintln!(
            "skipped: `unshare -rn` or `ip` is not available, so LAN multicast is untested here"
        );
        return;
    }
    let exe = std::env::current_exe().unwrap();
    let output = Command::new("unshare")
        .args(["-rn", "sh", "-c", "ip link set lo up && exec \"$0\" \"$@\""])
        .arg(exe)
        .args([
            "lan_multicast_discovery_finds_peers_that_then_sync",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(IN_NAMESPACE, "1")
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        output.status.success(),
        "the namespaced run failed:\n{text}"
    );
    assert!(
        text.contains("1 passed"),
        "the namespaced run ran no test:\n{text}"
    );
}

async fn lan_in_namespace() {
    let keys = session_keys(INVITE);
    let config = LanConfig {
        interface: Ipv4Addr::LOCALHOST,
        ..LanConfig::default()
    };
    let a = node(1);
    let b = node(2);
    author_some(&a.handle, 1, "alice").await;
    author_some(&b.handle, 2, "bob").await;
    let bind = |h: &THandle| {
        LanDiscovery::bind(
            config,
            keys.discovery_id(),
            h.peer_id(),
            h.local_addr().port(),
        )
        .unwrap()
    };
    // First by hand: A's announcement reaches B (and A's own socket, which skips it).
    let (mut lan_a, mut lan_b) = (bind(&a.handle), bind(&b.handle));
    let other = session_keys(OTHER_INVITE);
    let mut lan_other =
        LanDiscovery::bind(config, other.discovery_id(), [3; 32].into_peer(), 3).unwrap();
    lan_other.announce().await.unwrap();
    lan_a.announce().await.unwrap();
    let found = tokio::time::timeout(PATIENCE, lan_b.recv())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        found,
        DiscoveredPeer {
            peer: a.handle.peer_id(),
            addr: a.handle.local_addr()
        }
    );
    assert_eq!(lan_b.stats().n_other_sessions, 1);
    let quiet = std::time::Duration::from_millis(300);
    let found = tokio::time::timeout(quiet, lan_a.recv()).await;
    assert!(
        found.is_err(),
        "A hears only itself and the other session: {found:?}"
    );
    assert_eq!(lan_a.stats().n_own, 1);
    // Then the loops: both announce, both hear each other, both dial; one connection stays.
    tokio::spawn(lan::announce_and_dial(lan_a, a.handle.clone()));
    tokio::spawn(lan::announce_and_dial(lan_b, b.handle.clone()));
    converge(&[&a.handle, &b.handle], 8).await;
    eventually("a single connection remains", || async {
        a.handle.connected_peers().await.unwrap().len() == 1
            && b.handle.connected_peers().await.unwrap().len() == 1
    })
    .await;
}
