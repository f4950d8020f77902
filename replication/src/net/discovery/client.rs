//! The discovery client's older half and its constants: [`register`] sends a registration
//! from a separate UDP socket, naming the node's QUIC port, which is right only where the
//! host's address is public (a NAT maps that socket, not the node's). Nodes use
//! [`NodeHandle::register_with`] instead (see [`super::rendezvous`]), which registers from
//! the node's own socket and punches through NATs; [`stay_registered`] runs it.

use std::io;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr};
use std::time::Duration;

use tokio::net::UdpSocket;

use crate::identity::PeerId;
use crate::net::discovery::message::{DiscoveredPeer, DiscoveryMessage, MAX_DATAGRAM_BYTES};
use crate::net::node::NodeHandle;
use crate::net::session::DiscoveryId;
use crate::payload::Payload;

/// Requests sent before [`register`] gives up.
pub const REGISTER_ATTEMPTS: u32 = 3;
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

/// Registers `peer` (reachable on `quic_port` at this host's address as the server sees it)
/// under `discovery_id`, and returns the other peers the server knows in that session.
pub async fn register(
    server: SocketAddr,
    discovery_id: DiscoveryId,
    peer: PeerId,
    quic_port: u16,
) -> Result<Vec<DiscoveredPeer>, DiscoveryError> {
    let local: SocketAddr = if server.is_ipv4() {
        (Ipv4Addr::UNSPECIFIED, 0).into()
    } else {
        (Ipv6Addr::UNSPECIFIED, 0).into()
    };
    let socket = UdpSocket::bind(local).await?;
    let request = DiscoveryMessage::Register {
        discovery_id,
        peer,
        port: quic_port,
    }
    .encode();
    let mut buf = vec![0; MAX_DATAGRAM_BYTES + 1];
    for _ in 0..REGISTER_ATTEMPTS {
        socket.send_to(&request, server).await?;
        let wait = Duration::from_millis(REGISTER_REPLY_TIMEOUT_MILLIS);
        if let Ok(found) =
            tokio::time::timeout(wait, receive_peers(&socket, server, &mut buf)).await
        {
            return found;
        }
    }
    Err(DiscoveryError::NoAnswer(REGISTER_ATTEMPTS))
}

/// Waits for a well-formed reply from `server`; anything else is ignored.
async fn receive_peers(
    socket: &UdpSocket,
    server: SocketAddr,
    buf: &mut [u8],
) -> Result<Vec<DiscoveredPeer>, DiscoveryError> {
    loop {
        let (n, from) = socket.recv_from(buf).await?;
        if from != server {
            continue;
        }
        if let Ok(DiscoveryMessage::Peers(peers)) = DiscoveryMessage::decode(&buf[..n]) {
            return Ok(peers);
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
        if let Ok(found) = register(server, discovery_id, node.peer_id(), port).await {
            node.dial_discovered(&found).await;
        }
        tokio::time::sleep(Duration::from_millis(REFRESH_INTERVAL_MILLIS)).await;
        if node.stats().await.is_err() {
            return;
        }
    }
}
