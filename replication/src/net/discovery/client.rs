//! The discovery client's older half and its constants: [`register`] sends a registration
//! from a separate UDP socket, naming the node's QUIC port, which is right only where the
//! host's address is public (a NAT maps that socket, not the node's). Nodes use
//! [`NodeHandle::register_with`] instead (see [`super::rendezvous`]), which registers from
//! the node's own socket and punches through NATs; [`stay_registered`] runs it.
//!
//! Both do the server's round trip: the first registration carries no cookie and is
//! answered with a Challenge; the registration sent again with that cookie (and signed by
//! the peer's key, as every registration is) is listed and answered with the peers.

use std::io;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr};
use std::time::Duration;

use tokio::net::UdpSocket;

use crate::identity::Keypair;
use crate::net::discovery::message::{
    Cookie, DiscoveredPeer, DiscoveryMessage, MAX_DATAGRAM_BYTES, NO_COOKIE,
};
use crate::net::node::NodeHandle;
use crate::net::session::DiscoveryId;
use crate::payload::Payload;

/// Requests sent before [`register`] gives up.
pub const REGISTER_ATTEMPTS: u32 = 3;
/// Challenges one registration answers (each with the request sent again at once, not
/// counted as an attempt); more mean the server's cookies do not hold for this client, or
/// someone spoofs the server, and the rest wait for the reply timer.
pub const MAX_CHALLENGES_PER_REGISTER: u32 = 2;
/// How long each attempt waits for the reply.
pub const REGISTER_REPLY_TIMEOUT_MILLIS: u64 = 700;
/// How often a node registers again (well within the server's 60 s expiry, and often
/// enough to keep a NAT's mapping of the node's socket towards the server open).
pub const REFRESH_INTERVAL_MILLIS: u64 = 20_000;

/// Why registration failed.
#[derive(Debug, thiserror::Error)]
pub enum DiscoveryError {
    /// The local socket failed.
    #[error("discovery socket failed: {0}")]
    Io(#[from] io::Error),
    /// The server did not answer.
    #[error("no answer from the discovery server after {0} attempts")]
    NoAnswer(u32),
}

/// Registers `keypair`'s peer (reachable on `quic_port` at this host's address as the
/// server sees it) under `discovery_id`, answering the server's challenge, and returns the
/// other peers the server knows in that session.
pub async fn register(
    server: SocketAddr,
    discovery_id: DiscoveryId,
    keypair: &Keypair,
    quic_port: u16,
) -> Result<Vec<DiscoveredPeer>, DiscoveryError> {
    let local: SocketAddr = if server.is_ipv4() {
        (Ipv4Addr::UNSPECIFIED, 0).into()
    } else {
        (Ipv6Addr::UNSPECIFIED, 0).into()
    };
    let socket = UdpSocket::bind(local).await?;
    let mut buf = vec![0; MAX_DATAGRAM_BYTES + 1];
    let mut cookie = NO_COOKIE;
    let mut n_attempts = 0;
    let mut n_challenges = 0;
    while n_attempts < REGISTER_ATTEMPTS {
        let request = DiscoveryMessage::register(keypair, discovery_id, quic_port, cookie);
        socket.send_to(&request.encode(), server).await?;
        let wait = Duration::from_millis(REGISTER_REPLY_TIMEOUT_MILLIS);
        match tokio::time::timeout(wait, receive_answer(&socket, server, &mut buf)).await {
            Ok(Ok(Answer::Peers(found))) => return Ok(found),
            Ok(Ok(Answer::Challenge(issued))) if n_challenges < MAX_CHALLENGES_PER_REGISTER => {
                n_challenges += 1;
                cookie = issued;
            }
            Ok(Ok(Answer::Challenge(_))) | Err(_) => n_attempts += 1,
            Ok(Err(e)) => return Err(e),
        }
    }
    Err(DiscoveryError::NoAnswer(REGISTER_ATTEMPTS))
}

/// What the server answered.
enum Answer {
    Peers(Vec<DiscoveredPeer>),
    Challenge(Cookie),
}

/// Waits for a well-formed answer from `server`; anything else is ignored.
async fn receive_answer(
    socket: &UdpSocket,
    server: SocketAddr,
    buf: &mut [u8],
) -> Result<Answer, DiscoveryError> {
    loop {
        let (n, from) = socket.recv_from(buf).await?;
        if from != server {
            continue;
        }
        match DiscoveryMessage::decode(&buf[..n]) {
            Ok(DiscoveryMessage::Peers(peers)) => return Ok(Answer::Peers(peers)),
            Ok(DiscoveryMessage::Challenge { cookie }) => return Ok(Answer::Challenge(cookie)),
            _ => {}
        }
    }
}

/// Keeps `node` registered with `server` under `discovery_id` and dials every peer it
/// learns, until the node stops: [`NodeHandle::register_with`], with its events drained.
/// If the node's socket is already registered elsewhere (or cannot reach the server's
/// address family), it falls back to [`register`] from a separate socket every
/// [`REFRESH_INTERVAL_MILLIS`] and [`NodeHandle::dial_discovered`].
pub async fn stay_registered<P: Payload + Send + 'static>(
    server: SocketAddr,
    discovery_id: DiscoveryId,
    node: NodeHandle<P>,
) {
    if let Ok(mut rendezvous) = node.register_with(server, discovery_id) {
        while rendezvous.events.recv().await.is_some() {}
        return;
    }
    let port = node.local_addr().port();
    loop {
        if let Ok(found) = register(server, discovery_id, node.keypair(), port).await {
            node.dial_discovered(&found).await;
        }
        tokio::time::sleep(Duration::from_millis(REFRESH_INTERVAL_MILLIS)).await;
        if node.stats().await.is_err() {
            return;
        }
    }
}
