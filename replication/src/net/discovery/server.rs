//! The discovery server's socket loop (`sculpt discovery --listen ADDR`): a blocking UDP
//! socket around the sans-IO [`Registry`], which challenges and answers registrations and
//! sends the introductions they cause. It needs no async runtime. The registry's cookie key
//! is drawn here, from the operating system, once per run.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::net::clock::wall_clock_now;
use crate::net::discovery::message::MAX_DATAGRAM_BYTES;
use crate::net::discovery::registry::{Registry, RegistryStats};
use crate::net::tls;
use crate::time::Timestamp;

/// How often the loop checks the shutdown flag while no datagram arrives.
pub const SHUTDOWN_POLL_MILLIS: u64 = 100;
/// How often expired registrations are swept (1 s).
pub const EXPIRE_EVERY_MICROS: u64 = 1_000_000;

/// Why the server stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The socket could not be bound.
    #[error("cannot bind {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The OS error.
        source: io::Error,
    },
    /// The socket failed.
    #[error("discovery socket failed: {0}")]
    Io(#[from] io::Error),
    /// No secure random bytes for the cookie key.
    #[error("no secure random bytes for the discovery cookie key: {0}")]
    Random(quinn::rustls::Error),
}

/// A bound discovery server, not yet running.
#[derive(Debug)]
pub struct DiscoveryServer {
    socket: UdpSocket,
    registry: Registry,
}

impl DiscoveryServer {
    /// Binds the UDP socket.
    pub fn bind(addr: SocketAddr) -> Result<Self, ServeError> {
        let socket = UdpSocket::bind(addr).map_err(|source| ServeError::Bind { addr, source })?;
        socket.set_read_timeout(Some(Duration::from_millis(SHUTDOWN_POLL_MILLIS)))?;
        // A fresh key per run: cookies of an earlier run fail, and the client simply answers
        // the new challenge.
        let cookie_key = tls::secure_random().map_err(ServeError::Random)?;
        Ok(Self {
            socket,
            registry: Registry::new(cookie_key),
        })
    }

    /// The bound address (useful with port 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Answers registrations and sends the introductions they cause until `shutdown` is set
    /// (checked at least every [`SHUTDOWN_POLL_MILLIS`]); returns the counters.
    pub fn run(self, shutdown: &AtomicBool) -> Result<RegistryStats, ServeError> {
        self.run_reporting(shutdown, u64::MAX, |_, _| {})
    }

    /// [`DiscoveryServer::run`], calling `report` with the counters and the number of
    /// registrations held every `every_micros` (what `sculpt discovery` prints).
    pub fn run_reporting(
        mut self,
        shutdown: &AtomicBool,
        every_micros: u64,
        mut report: impl FnMut(&RegistryStats, usize),
    ) -> Result<RegistryStats, ServeError> {
        let mut next_report = wall_clock_now().saturating_add_micros(every_micros);
        // One byte more than the limit, so an oversized datagram is seen as such rather than
        // silently truncated to a valid length.
        let mut buf = vec![0; MAX_DATAGRAM_BYTES + 1];
        let mut next_sweep = Timestamp(0);
        while !shutdown.load(Ordering::Relaxed) {
            let received = self.socket.recv_from(&mut buf);
            let now = wall_clock_now();
            if now >= next_sweep {
                self.registry.expire(now);
                next_sweep = now.saturating_add_micros(EXPIRE_EVERY_MICROS);
            }
            if now >= next_report {
                report(self.registry.stats(), self.registry.n_registrations());
                next_report = now.saturating_add_micros(every_micros);
            }
            match received {
                Ok((n, from)) => {
                    if let Some(reply) = self.registry.handle_datagram(now, from, &buf[..n])
                        && self.socket.send_to(&reply, from).is_err()
                    {
                        self.registry.count_send_failure();
                    }
                    // Introductions of the peer that just registered, to the session's peers
                    // (within the request's bytes, see the registry).
                    while let Some((to, introduction)) = self.registry.poll_transmit() {
                        if self.socket.send_to(&introduction, to).is_err() {
                            self.registry.count_send_failure();
                        }
                    }
                }
                // Timeouts let the loop see the shutdown flag; the others are ICMP news
                // about earlier replies, which a UDP server ignores.
                Err(e) if is_transient(&e) => {}
                Err(e) => return Err(ServeError::Io(e)),
            }
        }
        Ok(self.registry.stats().clone())
    }
}

fn is_transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock
            | io::ErrorKind::TimedOut
            | io::ErrorKind::Interrupted
            | io::ErrorKind::ConnectionRefused
            | io::ErrorKind::ConnectionReset
    )
}

/// Runs a discovery server on `addr` until `shutdown` is set: what
/// `sculpt discovery --listen ADDR` calls. Blocks the calling thread.
pub fn serve(addr: SocketAddr, shutdown: &AtomicBool) -> Result<RegistryStats, ServeError> {
    DiscoveryServer::bind(addr)?.run(shutdown)
}
