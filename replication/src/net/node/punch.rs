//! Dialing a discovered peer through NATs (UDP hole punching over the QUIC socket).
//!
//! Both sides of a pair dial each other at about the same time (the discovery server's
//! reply tells the newcomer, its introduction tells the others). Each side's first packets
//! open its own NAT's mapping towards the other; packets that arrive at the other NAT before
//! that NAT has opened its own mapping are dropped. So a punch is a few short dials in a row
//! ([`MAX_PUNCH_ATTEMPTS`], each giving the QUIC handshake
//! [`PUNCH_HANDSHAKE_TIMEOUT_MILLIS`]; quinn resends its first packet within each), and it
//! stops as soon as a connection to the peer exists, whichever side dialed it. Two
//! connections made at once are settled by the node's duplicate rule.
//!
//! When no connection forms, the outcome is an [`Unreachable`] error (counted in
//! [`NodeStats::n_unreachable`](super::NodeStats::n_unreachable)) whose message tells a
//! person what to do instead.

use std::fmt;
use std::net::SocketAddr;
use std::time::Duration;

use super::{Counters, DialError, NodeHandle};
use crate::identity::PeerId;
use crate::net::admission::AdmissionError;
use crate::net::discovery::DiscoveredPeer;
use crate::payload::Payload;
use crate::peer::ConnId;

/// Dials one punch makes before it reports the peer unreachable.
pub const MAX_PUNCH_ATTEMPTS: u32 = 3;
/// How long each punch dial waits for the QUIC handshake (quinn resends its first packet
/// after about a second, so each dial sends it at least twice).
pub const PUNCH_HANDSHAKE_TIMEOUT_MILLIS: u64 = 2_000;

/// A punch that worked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Punched {
    /// The connection to the peer (perhaps one the peer dialed).
    pub conn: ConnId,
    /// Dials made; 0 when the peer was already connected.
    pub n_attempts: u32,
}

/// No direct connection formed with a discovered peer: the typed outcome of hole punching
/// that did not work. Its message is meant for a person.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unreachable {
    /// The peer (its claimed id).
    pub peer: PeerId,
    /// The address dialed (its public, NAT-mapped address as the discovery server saw it).
    pub addr: SocketAddr,
    /// Dials made.
    pub n_attempts: u32,
    /// Why the last dial failed.
    pub last_error: AdmissionError,
}

impl fmt::Display for Unreachable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "cannot reach peer {} at {} directly ({} attempts, last: {}): both sides may be \
             behind NATs that cannot be punched (symmetric NAT); connect on a LAN or give one \
             side a public address with --listen and --dial",
            self.peer.short(),
            self.addr,
            self.n_attempts,
            self.last_error
        )
    }
}

impl std::error::Error for Unreachable {}

/// Why a punch did not produce a connection.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PunchError {
    /// Every dial timed out or failed in the handshake: see [`Unreachable`].
    #[error(transparent)]
    Unreachable(#[from] Unreachable),
    /// A dial failed for a reason retrying does not change (the remote refused admission,
    /// it is this node, too many connections, the node stopped).
    #[error(transparent)]
    Dial(DialError),
}

/// Whether another dial may get through: the handshake timed out or failed on the way.
fn worth_retrying(e: &DialError) -> Option<&AdmissionError> {
    match e {
        DialError::Admission(a @ (AdmissionError::Timeout | AdmissionError::Connection(_))) => {
            Some(a)
        }
        _ => None,
    }
}

impl<P: Payload + Send + 'static> NodeHandle<P> {
    /// Dials a discovered peer through NATs: up to [`MAX_PUNCH_ATTEMPTS`] short dials, until
    /// a connection to that peer exists (dialed by either side). For hole punching the peer
    /// must dial this node at about the same time, which the discovery server arranges for
    /// nodes registered with [`NodeHandle::register_with`]; that method punches on its own.
    pub async fn punch(&self, peer: DiscoveredPeer) -> Result<Punched, PunchError> {
        let gone = |_| PunchError::Dial(DialError::Gone);
        if let Some(conn) = self.connection_to(peer.peer).await.map_err(gone)? {
            return Ok(Punched {
                conn,
                n_attempts: 0,
            });
        }
        let counters = self.counters();
        Counters::add(&counters.n_punches);
        let handshake_timeout = Duration::from_millis(PUNCH_HANDSHAKE_TIMEOUT_MILLIS);
        let mut last_error = AdmissionError::Timeout;
        for n_attempts in 1..=MAX_PUNCH_ATTEMPTS {
            match self.dial_within(peer.addr, handshake_timeout).await {
                Ok(conn) => {
                    Counters::add(&counters.n_punched);
                    return Ok(Punched { conn, n_attempts });
                }
                Err(e) => match worth_retrying(&e) {
                    Some(a) => last_error = a.clone(),
                    None => return Err(PunchError::Dial(e)),
                },
            }
            // The peer's own dial may have got through meanwhile.
            if let Some(conn) = self.connection_to(peer.peer).await.map_err(gone)? {
                Counters::add(&counters.n_punched);
                return Ok(Punched { conn, n_attempts });
            }
        }
        Counters::add(&counters.n_unreachable);
        Err(PunchError::Unreachable(Unreachable {
            peer: peer.peer,
            addr: peer.addr,
            n_attempts: MAX_PUNCH_ATTEMPTS,
            last_error,
        }))
    }
}
