//! The node-integrated discovery client ([`NodeHandle::register_with`]): registration from
//! the node's own UDP socket, introductions, and hole punching.
//!
//! The task registers (RegisterMapped, signed by the node's key, through the node's
//! [`DiscoveryPort`]) at once and every [`REFRESH_INTERVAL_MILLIS`], retrying an unanswered
//! request [`REGISTER_ATTEMPTS`] times. It keeps the server's last cookie: the first
//! registration is answered with a Challenge and sent again at once with the cookie (at most
//! [`MAX_CHALLENGES_PER_REGISTER`] times a round); a refresh reuses the cookie, which stays
//! valid longer than the refresh interval, and costs one round trip. Every peer the server names, in a reply or in an
//! introduction of a newcomer, is punched at once ([`NodeHandle::punch`]), at most
//! [`MAX_PUNCHES_IN_PROGRESS`] at a time and at most [`MAX_INTRODUCTIONS_PER_REFRESH`]
//! introductions per refresh interval. The app sees [`RendezvousEvent`]s on a bounded
//! channel (dropped and counted when it does not read them) and counters in
//! [`crate::net::NodeStats`]. The task ends when the node stops.
//!
//! Only the server's own address is listened to: a reply or introduction from anywhere else,
//! or an introduction for another session, is counted and ignored. That does not
//! authenticate the server (UDP sources can be spoofed): what it says is an address to dial,
//! and admission decides. A spoofer who knows the discovery id can make the node punch an
//! address of its choosing, within the bounds above: like any listed fake peer, it wastes
//! dials and admits no one.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::pin::Pin;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinSet;
use tokio::time::Instant;

use crate::identity::PeerId;
use crate::net::discovery::client::{
    MAX_CHALLENGES_PER_REGISTER, REFRESH_INTERVAL_MILLIS, REGISTER_ATTEMPTS,
    REGISTER_REPLY_TIMEOUT_MILLIS,
};
use crate::net::discovery::message::{Cookie, DiscoveredPeer, DiscoveryMessage, NO_COOKIE};
use crate::net::node::{Counters, DialError, NodeHandle, PunchError, Punched, Unreachable};
use crate::net::session::DiscoveryId;
use crate::net::socket::{DiscoveryPort, DiscoveryReply};
use crate::payload::Payload;
use crate::peer::ConnId;

/// Punches under way at once; peers named beyond that wait for the next refresh (counted
/// in [`crate::net::NodeStats::n_punches_skipped`]).
pub const MAX_PUNCHES_IN_PROGRESS: usize = 16;
/// Rendezvous events queued for the app before new ones are dropped (and counted).
pub const MAX_QUEUED_RENDEZVOUS_EVENTS: usize = 256;
/// Introductions acted on between two refreshes; more are counted as skipped. Whoever can
/// spoof the server's address (and knows the discovery id) could otherwise make a node send
/// punches anywhere: this bounds each node to a few hundred KB per refresh interval.
pub const MAX_INTRODUCTIONS_PER_REFRESH: usize = 16;
/// The shortest time between two registrations a sign of the network's return brings
/// ([`NodeHandle::resumed`], up to four a second): the server allows a source address
/// [`crate::net::discovery::registry::REQUESTS_PER_SEC_PER_SOURCE`] requests a second,
/// shared by every node behind one NAT, and the refresh's own registrations come every
/// [`REFRESH_INTERVAL_MILLIS`].
pub const RESUMED_REGISTER_EVERY_MILLIS: u64 = 5_000;
/// Unreachable peers remembered so that each is reported once (until it connects); past
/// this many the memory is cleared and they may be reported again.
pub const MAX_REMEMBERED_UNREACHABLE: usize = 64;

/// Why [`NodeHandle::register_with`] did not start.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RegisterError {
    /// The node's socket already has a discovery client (one server per node).
    #[error("this node is already registered with a discovery server")]
    AlreadyRegistered,
    /// An IPv6 server cannot be reached from the node's IPv4 socket.
    #[error("cannot reach the discovery server {server} from {local}: listen on [::]:PORT")]
    AddressFamily {
        /// The server.
        server: SocketAddr,
        /// The node's socket.
        local: SocketAddr,
    },
}

/// What the rendezvous tells the app.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RendezvousEvent {
    /// The server answered a registration (the first or a refresh) with these peers, which
    /// are being punched (those not connected yet).
    Registered {
        /// The server.
        server: SocketAddr,
        /// The session's other peers, at their public addresses.
        found: Vec<DiscoveredPeer>,
    },
    /// A registration went unanswered after [`REGISTER_ATTEMPTS`]; tried again at the next
    /// refresh.
    NoAnswer {
        /// The server.
        server: SocketAddr,
        /// Requests sent.
        n_attempts: u32,
    },
    /// The server introduced a peer that just registered; it is being punched.
    Introduced {
        /// The newcomer, at its public address.
        peer: DiscoveredPeer,
    },
    /// A punch made a connection (or found one the peer had dialed).
    Connected {
        /// The peer as discovered.
        peer: DiscoveredPeer,
        /// The connection.
        conn: ConnId,
        /// Dials made.
        n_attempts: u32,
    },
    /// No direct connection formed with a discovered peer; reported once per peer and
    /// address until it connects. Its `Display` is a message for a person.
    Unreachable(Unreachable),
    /// A punch failed for a reason retrying does not change (for example the peer does not
    /// know the invite).
    DialFailed {
        /// The peer as discovered.
        peer: DiscoveredPeer,
        /// Why.
        error: DialError,
    },
}

/// A running node-integrated registration: its events. It runs until the node stops.
#[derive(Debug)]
pub struct Rendezvous {
    /// What happens, for the app to show.
    pub events: mpsc::Receiver<RendezvousEvent>,
}

/// Starts the rendezvous task of `node` on `runtime`.
pub(crate) fn spawn<P: Payload + Send + 'static>(
    runtime: &tokio::runtime::Handle,
    node: NodeHandle<P>,
    port: DiscoveryPort,
    server: SocketAddr,
    discovery_id: DiscoveryId,
) -> Rendezvous {
    let (events, queue) = mpsc::channel(MAX_QUEUED_RENDEZVOUS_EVENTS);
    let task = Task {
        me: node.peer_id(),
        node,
        port,
        server: SocketAddr::new(server.ip().to_canonical(), server.port()),
        discovery_id,
        events,
        punching: BTreeSet::new(),
        reported: BTreeSet::new(),
        punches: JoinSet::new(),
        n_introduced: 0,
        cookie: NO_COOKIE,
    };
    runtime.spawn(task.run());
    Rendezvous { events: queue }
}

type PunchOutcome = (DiscoveredPeer, Result<Punched, PunchError>);

struct Task<P> {
    me: PeerId,
    node: NodeHandle<P>,
    port: DiscoveryPort,
    server: SocketAddr,
    discovery_id: DiscoveryId,
    events: mpsc::Sender<RendezvousEvent>,
    /// Peers with a punch under way.
    punching: BTreeSet<PeerId>,
    /// Peers reported unreachable (not again until they connect).
    reported: BTreeSet<DiscoveredPeer>,
    punches: JoinSet<PunchOutcome>,
    /// Introductions acted on since the last refresh.
    n_introduced: usize,
    /// The server's last cookie for this socket ([`NO_COOKIE`] before the first challenge).
    cookie: Cookie,
}

/// What a reply means for the registration round.
enum Heard {
    /// The registration was answered: the round is over.
    Answered,
    /// The server issued a cookie: register again with it.
    Challenged,
    /// Nothing for the round.
    Other,
}

/// When the next registration round is due: at the refresh (true), or at once when the node
/// hears a remote after a silence (false: the network may be back, and the server's answer
/// names the peers to punch; the introductions' allowance is not renewed by it), at most
/// once every [`RESUMED_REGISTER_EVERY_MILLIS`] since `resumed_at`, the last such round.
async fn next_round(
    refresh: &mut tokio::time::Interval,
    resumed: &mut tokio::sync::watch::Receiver<u64>,
    resumed_at: &mut Option<Instant>,
) -> bool {
    let every = Duration::from_millis(RESUMED_REGISTER_EVERY_MILLIS);
    loop {
        tokio::select! {
            _ = refresh.tick() => return true,
            Ok(()) = resumed.changed() => {
                let now = Instant::now();
                if resumed_at.is_none_or(|at| now >= at + every) {
                    *resumed_at = Some(now);
                    return false;
                }
            }
        }
    }
}

fn sleep_millis(millis: u64) -> Pin<Box<tokio::time::Sleep>> {
    Box::pin(tokio::time::sleep(Duration::from_millis(millis)))
}

impl<P: Payload + Send + 'static> Task<P> {
    async fn run(mut self) {
        let mut refresh = tokio::time::interval(Duration::from_millis(REFRESH_INTERVAL_MILLIS));
        refresh.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        // Requests sent in the current round, while it waits for the answer.
        let mut n_sent: Option<u32> = None;
        // Challenges answered in the current round.
        let mut n_challenges = 0;
        let mut reply_timer = sleep_millis(0);
        let mut resumed = self.node.resumed();
        let mut resumed_at = None;
        loop {
            tokio::select! {
                () = self.node.stopped() => return,
                refreshed = next_round(&mut refresh, &mut resumed, &mut resumed_at),
                    if n_sent.is_none() =>
                {
                    if refreshed {
                        self.n_introduced = 0;
                    }
                    self.send_register().await;
                    n_sent = Some(1);
                    n_challenges = 0;
                    reply_timer = sleep_millis(REGISTER_REPLY_TIMEOUT_MILLIS);
                }
                () = &mut reply_timer, if n_sent.is_some() => {
                    let sent = n_sent.unwrap_or(REGISTER_ATTEMPTS);
                    if sent < REGISTER_ATTEMPTS {
                        self.send_register().await;
                        n_sent = Some(sent + 1);
                        reply_timer = sleep_millis(REGISTER_REPLY_TIMEOUT_MILLIS);
                    } else {
                        Counters::add(&self.node.counters().n_registrations_unanswered);
                        let server = self.server;
                        self.emit(RendezvousEvent::NoAnswer { server, n_attempts: sent });
                        n_sent = None;
                    }
                }
                reply = self.port.recv() => match reply {
                    Some(reply) => match self.on_reply(reply) {
                        Heard::Answered => n_sent = None,
                        // Answered at once, within the round; a challenge outside a round, or
                        // past the limit, waits for the next request.
                        Heard::Challenged
                            if n_sent.is_some() && n_challenges < MAX_CHALLENGES_PER_REGISTER =>
                        {
                            n_challenges += 1;
                            self.send_register().await;
                            reply_timer = sleep_millis(REGISTER_REPLY_TIMEOUT_MILLIS);
                        }
                        Heard::Challenged | Heard::Other => {}
                    },
                    // The node's socket is gone.
                    None => return,
                },
                Some(done) = self.punches.join_next(), if !self.punches.is_empty() => {
                    match done {
                        Ok(outcome) => self.on_punched(outcome),
                        // A punch that panicked leaves no peer to clear: forget them all,
                        // at worst a peer gets two punches at once (the duplicate rule copes).
                        Err(_) => self.punching.clear(),
                    }
                }
            }
        }
    }

    async fn send_register(&mut self) {
        let request =
            DiscoveryMessage::register_mapped(self.node.keypair(), self.discovery_id, self.cookie);
        // A failed send is an unanswered attempt: the reply timer retries it.
        let _ = self.port.send(&request, self.server).await;
    }

    fn emit(&self, event: RendezvousEvent) {
        if self.events.try_send(event).is_err() {
            Counters::add(&self.node.counters().n_rendezvous_events_dropped);
        }
    }

    /// Handles one reply.
    fn on_reply(&mut self, reply: DiscoveryReply) -> Heard {
        let counters = self.node.counters();
        if reply.from != self.server {
            Counters::add(&counters.n_stray_discovery);
            return Heard::Other;
        }
        match reply.message {
            DiscoveryMessage::Peers(found) => {
                Counters::add(&counters.n_registrations);
                for peer in &found {
                    self.start_punch(*peer);
                }
                let server = self.server;
                self.emit(RendezvousEvent::Registered { server, found });
                Heard::Answered
            }
            DiscoveryMessage::Challenge { cookie } => {
                self.cookie = cookie;
                Heard::Challenged
            }
            DiscoveryMessage::Introduce { discovery_id, peer }
                if discovery_id == self.discovery_id =>
            {
                Counters::add(&counters.n_introductions);
                if self.n_introduced >= MAX_INTRODUCTIONS_PER_REFRESH {
                    Counters::add(&counters.n_punches_skipped);
                    return Heard::Other;
                }
                self.n_introduced += 1;
                self.start_punch(peer);
                self.emit(RendezvousEvent::Introduced { peer });
                Heard::Other
            }
            _ => {
                Counters::add(&counters.n_stray_discovery);
                Heard::Other
            }
        }
    }

    fn start_punch(&mut self, peer: DiscoveredPeer) {
        if peer.peer == self.me || self.punching.contains(&peer.peer) {
            return;
        }
        if self.punches.len() >= MAX_PUNCHES_IN_PROGRESS {
            Counters::add(&self.node.counters().n_punches_skipped);
            return;
        }
        self.punching.insert(peer.peer);
        let node = self.node.clone();
        self.punches
            .spawn(async move { (peer, node.punch(peer).await) });
    }

    fn on_punched(&mut self, (peer, outcome): PunchOutcome) {
        self.punching.remove(&peer.peer);
        match outcome {
            Ok(Punched { conn, n_attempts }) => {
                self.reported.retain(|d| d.peer != peer.peer);
                if n_attempts > 0 {
                    self.emit(RendezvousEvent::Connected {
                        peer,
                        conn,
                        n_attempts,
                    });
                }
            }
            Err(PunchError::Unreachable(unreachable)) => {
                if self.reported.len() >= MAX_REMEMBERED_UNREACHABLE {
                    self.reported.clear();
                }
                if self.reported.insert(peer) {
                    self.emit(RendezvousEvent::Unreachable(unreachable));
                }
            }
            Err(PunchError::Dial(DialError::Gone)) => {}
            Err(PunchError::Dial(error)) => {
                self.emit(RendezvousEvent::DialFailed { peer, error });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sign of the network's return brings a registration at once, but a second sign within
    /// [`RESUMED_REGISTER_EVERY_MILLIS`] brings none (the server's allowance is per source
    /// address, shared behind a NAT); after it, one does again.
    #[test]
    fn signs_bring_a_registration_at_most_every_few_seconds() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .unwrap();
        runtime.block_on(async {
            let mut refresh = tokio::time::interval(Duration::from_millis(REFRESH_INTERVAL_MILLIS));
            // The first tick, at once, is the first registration's.
            refresh.tick().await;
            let (sign, mut resumed) = tokio::sync::watch::channel(0u64);
            let mut at = None;
            let wait = Duration::from_millis(100);
            let mut next = async |at: &mut Option<Instant>| {
                sign.send_modify(|n| *n += 1);
                let round = next_round(&mut refresh, &mut resumed, at);
                tokio::time::timeout(wait, round).await.ok()
            };
            assert_eq!(next(&mut at).await, Some(false), "a sign registers at once");
            assert_eq!(next(&mut at).await, None, "not twice within the floor");
            at = at.map(|t| t - Duration::from_millis(RESUMED_REGISTER_EVERY_MILLIS));
            assert_eq!(next(&mut at).await, Some(false), "and again after it");
        });
    }
}
