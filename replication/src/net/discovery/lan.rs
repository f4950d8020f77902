//! LAN discovery without a server: peers announce `(discovery id, peer id, QUIC port)` to an
//! IPv4 multicast group and listen for each other's announcements.
//!
//! Announcements carry no secret (the discovery id is a hash of the invite) and prove
//! nothing: a listener learns an address to dial, and admission decides. Multicast stays on
//! the local link (TTL 1).

use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::time::Duration;

use socket2::{Domain, Protocol, Socket, Type};
use tokio::net::UdpSocket;

use crate::identity::PeerId;
use crate::net::discovery::message::{DiscoveredPeer, DiscoveryMessage, MAX_DATAGRAM_BYTES};
use crate::net::node::NodeHandle;
use crate::net::session::DiscoveryId;
use crate::payload::Payload;

/// The default multicast group (administratively scoped, RFC 2365).
pub const LAN_GROUP: Ipv4Addr = Ipv4Addr::new(239, 255, 83, 67);
/// The default multicast port.
pub const LAN_PORT: u16 = 48_372;
/// How often [`announce_and_dial`] announces.
pub const ANNOUNCE_INTERVAL_MILLIS: u64 = 2_000;
/// Multicast hops: the local link only.
pub const MULTICAST_TTL: u32 = 1;

/// Where to announce and listen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LanConfig {
    /// The multicast group.
    pub group: Ipv4Addr,
    /// The UDP port every peer of the LAN listens on.
    pub port: u16,
    /// The local interface address to announce and listen on (`UNSPECIFIED`: the OS picks).
    pub interface: Ipv4Addr,
}

impl Default for LanConfig {
    fn default() -> Self {
        Self {
            group: LAN_GROUP,
            port: LAN_PORT,
            interface: Ipv4Addr::UNSPECIFIED,
        }
    }
}

/// Counters of received announcements.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LanStats {
    /// Announcements sent.
    pub n_announced: u64,
    /// Announcements of other peers of this session.
    pub n_found: u64,
    /// Our own announcements, looped back.
    pub n_own: u64,
    /// Announcements of other sessions.
    pub n_other_sessions: u64,
    /// Datagrams that are not announcements.
    pub n_malformed: u64,
}

/// One peer's LAN announcer and listener.
#[derive(Debug)]
pub struct LanDiscovery {
    socket: UdpSocket,
    target: SocketAddrV4,
    announcement: Vec<u8>,
    discovery_id: DiscoveryId,
    peer: PeerId,
    stats: LanStats,
}

impl LanDiscovery {
    /// Joins the group on the configured interface. Several listeners on one host share the
    /// port (`SO_REUSEADDR`). Must be called inside a tokio runtime.
    pub fn bind(
        config: LanConfig,
        discovery_id: DiscoveryId,
        peer: PeerId,
        quic_port: u16,
    ) -> io::Result<Self> {
        let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))?;
        socket.set_reuse_address(true)?;
        socket.bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, config.port)).into())?;
        socket.join_multicast_v4(&config.group, &config.interface)?;
        socket.set_multicast_if_v4(&config.interface)?;
        socket.set_multicast_loop_v4(true)?;
        socket.set_multicast_ttl_v4(MULTICAST_TTL)?;
        socket.set_nonblocking(true)?;
        let socket = UdpSocket::from_std(socket.into())?;
        let announcement = DiscoveryMessage::Announce {
            discovery_id,
            peer,
            port: quic_port,
        }
        .encode();
        Ok(Self {
            socket,
            target: SocketAddrV4::new(config.group, config.port),
            announcement,
            discovery_id,
            peer,
            stats: LanStats::default(),
        })
    }

    /// The counters.
    pub fn stats(&self) -> &LanStats {
        &self.stats
    }

    /// Announces this peer once.
    pub async fn announce(&mut self) -> io::Result<()> {
        self.socket.send_to(&self.announcement, self.target).await?;
        self.stats.n_announced += 1;
        Ok(())
    }

    /// Waits for the next announcement of another peer of this session; the address is the
    /// announcement's source IP with the announced port. Other datagrams are counted and
    /// skipped.
    pub async fn recv(&mut self) -> io::Result<DiscoveredPeer> {
        let mut buf = vec![0; MAX_DATAGRAM_BYTES + 1];
        loop {
            let (n, from) = self.socket.recv_from(&mut buf).await?;
            match DiscoveryMessage::decode(&buf[..n]) {
                Ok(DiscoveryMessage::Announce {
                    discovery_id,
                    peer,
                    port,
                }) => {
                    if peer == self.peer {
                        self.stats.n_own += 1;
                    } else if discovery_id != self.discovery_id {
                        self.stats.n_other_sessions += 1;
                    } else {
                        self.stats.n_found += 1;
                        let addr = SocketAddr::new(from.ip(), port);
                        return Ok(DiscoveredPeer { peer, addr });
                    }
                }
                Ok(_) | Err(_) => self.stats.n_malformed += 1,
            }
        }
    }
}

/// Announces `node` every [`ANNOUNCE_INTERVAL_MILLIS`] and dials each peer of the session
/// it hears, until the node stops or the socket fails.
pub async fn announce_and_dial<P: Payload + Send + 'static>(
    mut lan: LanDiscovery,
    node: NodeHandle<P>,
) -> io::Result<()> {
    let mut tick = tokio::time::interval(Duration::from_millis(ANNOUNCE_INTERVAL_MILLIS));
    loop {
        tokio::select! {
            _ = tick.tick() => {
                if node.stats().await.is_err() {
                    return Ok(());
                }
                lan.announce().await?;
            }
            found = lan.recv() => {
                node.dial_discovered(&[found?]).await;
            }
        }
    }
}
