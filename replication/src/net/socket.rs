//! The node's one UDP socket, shared by QUIC and the discovery client.
//!
//! A discovery server can only tell peers behind NAT routers where to dial if the node's
//! registration leaves from the very socket QUIC uses: the server then sees (and lists) the
//! NAT's mapping of that socket, the one address through which the peer can be reached.
//! [`DemuxSocket`] wraps the endpoint's socket for quinn: it hands quinn every datagram except
//! discovery replies (Peers, Introduce and Challenge, see [`DiscoveryMessage::is_reply`]),
//! which it passes to the node's [`DiscoveryPort`] on a bounded queue; the port sends
//! discovery datagrams through the same socket.
//!
//! A datagram that opens like a discovery message but does not decode, or decodes to a
//! message a server receives rather than sends, goes to quinn, which drops what is not QUIC.
//! A QUIC packet cannot be mistaken for a reply unless its first bytes spell `"SCD"`, the
//! version and a reply tag, and the rest decodes to the exact length of a reply: quinn's
//! connection ids are random, so this does not happen by accident.
//!
//! Non-guarantees: a reply arriving while [`MAX_QUEUED_DISCOVERY_REPLIES`] wait unread is
//! dropped and counted; discovery replies are retried by their senders.

use std::fmt;
use std::future::poll_fn;
use std::io::{self, IoSliceMut};
use std::net::{IpAddr, SocketAddr};
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll, ready};

use quinn::udp::{RecvMeta, Transmit};
use quinn::{AsyncUdpSocket, UdpPoller};
use tokio::sync::mpsc;

use crate::net::discovery::message::{DISCOVERY_WIRE_VERSION, DiscoveryMessage, MAGIC};

/// Discovery replies waiting for the node's discovery client; more are dropped and counted.
pub const MAX_QUEUED_DISCOVERY_REPLIES: usize = 32;
/// Times a discovery send waits for the socket to become writable before it gives up.
pub const MAX_SEND_WAITS: u32 = 4;

/// A discovery reply taken out of the QUIC traffic.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DiscoveryReply {
    /// Where it came from (IPv4-mapped IPv6 addresses are given as IPv4).
    pub from: SocketAddr,
    /// The decoded reply.
    pub message: DiscoveryMessage,
}

/// The socket's counters, shared with the node's statistics.
#[derive(Debug, Default)]
pub struct SocketCounters {
    n_replies: AtomicU64,
    n_replies_dropped: AtomicU64,
}

impl SocketCounters {
    /// Discovery replies passed to the discovery client.
    pub fn n_replies(&self) -> u64 {
        self.n_replies.load(Ordering::Relaxed)
    }

    /// Discovery replies dropped because [`MAX_QUEUED_DISCOVERY_REPLIES`] waited unread (or
    /// nobody listens any more).
    pub fn n_replies_dropped(&self) -> u64 {
        self.n_replies_dropped.load(Ordering::Relaxed)
    }
}

/// The endpoint's socket as quinn sees it: everything but discovery replies.
#[derive(Debug)]
pub struct DemuxSocket {
    inner: Arc<dyn AsyncUdpSocket>,
    replies: mpsc::Sender<DiscoveryReply>,
    counters: Arc<SocketCounters>,
}

impl DemuxSocket {
    /// Wraps `inner` (for example from [`quinn::Runtime::wrap_udp_socket`]); returns the
    /// socket to give quinn and the port for the discovery client.
    pub fn new(
        inner: Arc<dyn AsyncUdpSocket>,
        counters: Arc<SocketCounters>,
    ) -> (Arc<Self>, DiscoveryPort) {
        let (replies, queue) = mpsc::channel(MAX_QUEUED_DISCOVERY_REPLIES);
        let poller = inner.clone().create_io_poller();
        let port = DiscoveryPort {
            socket: inner.clone(),
            poller,
            replies: queue,
        };
        let demux = Arc::new(Self {
            inner,
            replies,
            counters,
        });
        (demux, port)
    }

    /// Takes the datagram(s) of one receive if they are discovery replies; false leaves them
    /// to quinn. A batch of segments (GRO) is taken only when every segment is a reply.
    fn divert(&self, bytes: &[u8], meta: &RecvMeta) -> bool {
        if !(bytes.starts_with(MAGIC) && bytes.get(MAGIC.len()) == Some(&DISCOVERY_WIRE_VERSION)) {
            return false;
        }
        let stride = meta.stride.max(1);
        let mut replies = Vec::with_capacity(bytes.len().div_ceil(stride));
        for segment in bytes.chunks(stride) {
            match DiscoveryMessage::decode(segment) {
                Ok(message) if message.is_reply() => replies.push(message),
                _ => return false,
            }
        }
        let from = canonical(meta.addr);
        for message in replies {
            match self.replies.try_send(DiscoveryReply { from, message }) {
                Ok(()) => self.counters.n_replies.fetch_add(1, Ordering::Relaxed),
                Err(_) => self
                    .counters
                    .n_replies_dropped
                    .fetch_add(1, Ordering::Relaxed),
            };
        }
        true
    }
}

/// An IPv4-mapped IPv6 address as IPv4; anything else as it is.
fn canonical(addr: SocketAddr) -> SocketAddr {
    SocketAddr::new(addr.ip().to_canonical(), addr.port())
}

impl AsyncUdpSocket for DemuxSocket {
    fn create_io_poller(self: Arc<Self>) -> Pin<Box<dyn UdpPoller>> {
        self.inner.clone().create_io_poller()
    }

    fn try_send(&self, transmit: &Transmit) -> io::Result<()> {
        self.inner.try_send(transmit)
    }

    fn poll_recv(
        &self,
        cx: &mut Context,
        bufs: &mut [IoSliceMut<'_>],
        meta: &mut [RecvMeta],
    ) -> Poll<io::Result<usize>> {
        let n = ready!(self.inner.poll_recv(cx, bufs, meta))?;
        let mut n_kept = 0;
        for i in 0..n {
            let len = meta[i].len.min(bufs[i].len());
            if self.divert(&bufs[i][..len], &meta[i]) {
                continue;
            }
            // Move the kept datagram down by swapping buffer slices (no copy): the caller
            // reads datagram k from `bufs[k]`, whichever of its buffers that is.
            bufs.swap(n_kept, i);
            meta.swap(n_kept, i);
            n_kept += 1;
        }
        // Zero is a valid answer: quinn polls again, under its own fairness limit.
        Poll::Ready(Ok(n_kept))
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        self.inner.local_addr()
    }

    fn max_transmit_segments(&self) -> usize {
        self.inner.max_transmit_segments()
    }

    fn max_receive_segments(&self) -> usize {
        self.inner.max_receive_segments()
    }

    fn may_fragment(&self) -> bool {
        self.inner.may_fragment()
    }
}

/// The discovery client's end of the node's socket: replies in, discovery datagrams out.
pub struct DiscoveryPort {
    socket: Arc<dyn AsyncUdpSocket>,
    poller: Pin<Box<dyn UdpPoller>>,
    replies: mpsc::Receiver<DiscoveryReply>,
}

impl fmt::Debug for DiscoveryPort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DiscoveryPort")
            .field("socket", &self.socket)
            .finish_non_exhaustive()
    }
}

impl DiscoveryPort {
    /// The socket's local address.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Sends one discovery message to `to` from the node's socket. An IPv4 destination is
    /// sent IPv4-mapped from an IPv6 socket; an IPv6 one from an IPv4 socket is an error.
    pub async fn send(&mut self, message: &DiscoveryMessage, to: SocketAddr) -> io::Result<()> {
        let local = self.socket.local_addr()?;
        let destination = match (local.ip(), to.ip()) {
            (IpAddr::V6(_), IpAddr::V4(ip)) => {
                SocketAddr::new(IpAddr::V6(ip.to_ipv6_mapped()), to.port())
            }
            (IpAddr::V4(_), IpAddr::V6(ip)) if ip.to_ipv4_mapped().is_none() => {
                return Err(io::Error::new(
                    io::ErrorKind::Unsupported,
                    format!("cannot reach {to} from the IPv4 socket {local}"),
                ));
            }
            (IpAddr::V4(_), IpAddr::V6(ip)) => {
                SocketAddr::new(IpAddr::V6(ip).to_canonical(), to.port())
            }
            _ => to,
        };
        let contents = message.encode();
        let transmit = Transmit {
            destination,
            ecn: None,
            contents: &contents,
            segment_size: None,
            src_ip: None,
        };
        for _ in 0..MAX_SEND_WAITS {
            match self.socket.try_send(&transmit) {
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    let poller = &mut self.poller;
                    poll_fn(|cx| poller.as_mut().poll_writable(cx)).await?;
                }
                other => return other,
            }
        }
        Err(io::Error::new(
            io::ErrorKind::WouldBlock,
            "the socket stayed busy",
        ))
    }

    /// The next discovery reply; `None` once the node's socket is gone.
    pub async fn recv(&mut self) -> Option<DiscoveryReply> {
        self.replies.recv().await
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use quinn::Runtime;

    use super::*;
    use crate::identity::PeerId;
    use crate::net::discovery::message::DiscoveredPeer;

    const PATIENCE: Duration = Duration::from_secs(20);

    fn demux() -> (Arc<DemuxSocket>, DiscoveryPort, Arc<SocketCounters>) {
        let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let inner = quinn::TokioRuntime.wrap_udp_socket(socket).unwrap();
        let counters = Arc::new(SocketCounters::default());
        let (demux, port) = DemuxSocket::new(inner, counters.clone());
        (demux, port, counters)
    }

    /// Receives through the demultiplexer, as quinn does, until `n` datagrams came through.
    async fn quinn_receives(demux: &DemuxSocket, n: usize) -> Vec<Vec<u8>> {
        let mut got = Vec::new();
        while got.len() < n {
            let mut storage = vec![vec![0_u8; 2048]; 4];
            let mut metas = [RecvMeta::default(); 4];
            let mut bufs: Vec<IoSliceMut<'_>> =
                storage.iter_mut().map(|b| IoSliceMut::new(b)).collect();
            let receiving = poll_fn(|cx| demux.poll_recv(cx, &mut bufs, &mut metas));
            let n_got = tokio::time::timeout(PATIENCE, receiving)
                .await
                .expect("datagrams arrive")
                .unwrap();
            for (buf, meta) in bufs.iter().zip(&metas).take(n_got) {
                got.push(buf[..meta.len].to_vec());
            }
        }
        got
    }

    fn peers_reply(port: u16) -> DiscoveryMessage {
        DiscoveryMessage::Peers(vec![DiscoveredPeer {
            peer: PeerId([1; 32]),
            addr: SocketAddr::from(([127, 0, 0, 1], port)),
        }])
    }

    #[tokio::test]
    async fn discovery_replies_go_to_the_port_and_everything_else_to_quinn() {
        let (demux, mut port, counters) = demux();
        let to = demux.local_addr().unwrap();
        let sender = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let introduce = DiscoveryMessage::Introduce {
            discovery_id: [2; 16],
            peer: DiscoveredPeer {
                peer: PeerId([3; 32]),
                addr: SocketAddr::from(([198, 51, 100, 2], 40_000)),
            },
        };
        let mut undecodable = peers_reply(1).encode();
        undecodable.push(0);
        let register = DiscoveryMessage::register_mapped(
            &crate::identity::Keypair::from_seed([4; 32]),
            [2; 16],
            crate::net::discovery::message::NO_COOKIE,
        )
        .encode();
        let quic_like = vec![0xc0, 0, 0, 0, 1, 8, 1, 2, 3, 4, 5, 6, 7, 8];
        let datagrams = [
            quic_like.clone(),
            peers_reply(1).encode(),
            undecodable.clone(),
            introduce.encode(),
            register.clone(),
        ];
        for d in &datagrams {
            sender.send_to(d, to).await.unwrap();
        }
        // QUIC-looking bytes, a reply that does not decode and a request (which only a
        // server takes) go to quinn, in order; the two replies do not.
        let for_quinn = quinn_receives(&demux, 3).await;
        assert_eq!(for_quinn, vec![quic_like, undecodable, register]);
        let from = sender.local_addr().unwrap();
        let first = port.recv().await.unwrap();
        assert_eq!(
            first,
            DiscoveryReply {
                from,
                message: peers_reply(1)
            }
        );
        let second = port.recv().await.unwrap();
        assert_eq!(
            second,
            DiscoveryReply {
                from,
                message: introduce
            }
        );
        assert_eq!((counters.n_replies(), counters.n_replies_dropped()), (2, 0));
    }

    #[tokio::test]
    async fn unread_replies_are_bounded_and_the_rest_dropped_and_counted() {
        let (demux, mut port, counters) = demux();
        let to = demux.local_addr().unwrap();
        let sender = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let n_over = 3;
        for i in 0..MAX_QUEUED_DISCOVERY_REPLIES + n_over {
            let reply = peers_reply(u16::try_from(i).unwrap() + 1).encode();
            sender.send_to(&reply, to).await.unwrap();
        }
        // A last datagram for quinn proves every reply before it was read.
        sender.send_to(b"not discovery", to).await.unwrap();
        assert_eq!(
            quinn_receives(&demux, 1).await,
            vec![b"not discovery".to_vec()]
        );
        assert_eq!(counters.n_replies(), MAX_QUEUED_DISCOVERY_REPLIES as u64);
        assert_eq!(counters.n_replies_dropped(), n_over as u64);
        // The queue holds the first ones, in order.
        for i in 0..MAX_QUEUED_DISCOVERY_REPLIES {
            let reply = port.recv().await.unwrap();
            assert_eq!(reply.message, peers_reply(u16::try_from(i).unwrap() + 1));
        }
        assert!(port.replies.try_recv().is_err());
    }

    #[tokio::test]
    async fn the_port_sends_from_the_same_socket_as_quinn() {
        let (demux, mut port, _) = demux();
        let receiver = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let message = DiscoveryMessage::register_mapped(
            &crate::identity::Keypair::from_seed([6; 32]),
            [5; 16],
            crate::net::discovery::message::NO_COOKIE,
        );
        port.send(&message, receiver.local_addr().unwrap())
            .await
            .unwrap();
        let mut buf = [0; 2048];
        let (n, from) = tokio::time::timeout(PATIENCE, receiver.recv_from(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(from, demux.local_addr().unwrap());
        assert_eq!(DiscoveryMessage::decode(&buf[..n]), Ok(message));
        // An IPv4 socket cannot reach an IPv6 server, and says so.
        let v6 = SocketAddr::from((std::net::Ipv6Addr::LOCALHOST, 1));
        let refused = port.send(&peers_reply(1), v6).await;
        assert_eq!(refused.unwrap_err().kind(), io::ErrorKind::Unsupported);
    }
}
