//! The node's core task: owns the [`Peer`] and the store, reads the wall clock, feeds the
//! sans-IO core with frames, datagrams, commands and timeouts, and after every step drains
//! its events (storing delivered ops first) and then its transmits.

use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{mpsc, oneshot};
use tokio::time::Instant;

use super::join::JoinState;
use super::{
    CloseCode, Command, ConnStats, Counters, DialError, DisconnectReason, Input,
    MAX_LOST_DIALS_PER_PEER, MAX_LOST_PEERS, MAX_QUEUED_FRAMES_PER_CONN, MAX_REJECTIONS_PER_CONN,
    NodeAuthorError, NodeEvent, NodeStats, Observer, REDIAL_LOST_EVERY_MILLIS,
    REDIAL_LOST_FOR_MILLIS, RefusalKind, Shared, conn,
};
use crate::identity::{OpId, PeerId};
use crate::log::Log;
use crate::membership::Admission;
use crate::net::admission::{AdmissionError, Role};
use crate::net::clock::{duration_until, wall_clock_now};
use crate::net::prefix::AddressPrefix;
use crate::payload::Payload;
use crate::peer::{ConnId, ConnectError, Peer};
use crate::store::OpStore;
use crate::sync::message::Message;
use crate::sync::state::{CloseReason, Event, MIN_REDIAL_HANDSHAKE_MICROS};
use crate::time::Timestamp;

/// One admitted connection.
pub(super) struct Live {
    pub(super) peer: PeerId,
    role: Role,
    pub(super) connection: quinn::Connection,
    /// Starts its readers once the peer takes it ([`Core::open_in_peer`]).
    start: Option<oneshot::Sender<()>>,
    frames: mpsc::Sender<Vec<u8>>,
    /// When it was admitted (its key, unknown to a log that binds authors, is admitted
    /// [`super::ADMISSION_DELAY_MILLIS`] later).
    since: Timestamp,
    /// The UDP datagrams it had received at its last stall event ([`Core::on_stalled`]).
    rx_at_stall: Option<u64>,
}

/// A peer whose connection the idle timeout closed, dialed again for a while
/// ([`super::REDIAL_LOST_EVERY_MILLIS`]).
struct Lost {
    addr: SocketAddr,
    /// When the next dial is due.
    next: Instant,
    /// When to stop.
    until: Instant,
    /// What each dial's handshake may take: as a stall's redial, twice the round trip.
    handshake: Duration,
}

pub(super) struct Core<P> {
    pub(super) peer: Peer<P>,
    pub(super) observer: Option<Box<dyn Observer<P>>>,
    /// True when the log changed since the observer last saw a settled step.
    pub(super) changed: bool,
    pub(super) store: Option<OpStore<P>>,
    endpoint: quinn::Endpoint,
    pub(super) shared: Arc<Shared>,
    pub(super) conns: BTreeMap<ConnId, Live>,
    dials: BTreeMap<ConnId, oneshot::Sender<Result<ConnId, DialError>>>,
    /// Dials under way to the remotes of stalled connections: the new id, the stalled one
    /// and its peer.
    redials: BTreeMap<ConnId, (ConnId, PeerId)>,
    /// Peers lost to the idle timeout that this node dials again (at most [`MAX_LOST_PEERS`]).
    lost: BTreeMap<PeerId, Lost>,
    /// Dials under way to lost peers: the new id, the peer.
    lost_dials: BTreeMap<ConnId, PeerId>,
    /// When a remote heard after a silence last brought the dials forward
    /// ([`super::RESUMED_DIALS_EVERY_MILLIS`]).
    resumed_at: Option<Instant>,
    events: mpsc::Sender<NodeEvent>,
    pub(super) stats: NodeStats,
    /// Joining from a snapshot, and serving them.
    pub(super) join: JoinState<P>,
    /// Counted outside this task (socket, rendezvous, punches); read into the stats.
    counters: Arc<Counters>,
    /// The first bytes of every encoded ephemeral message (version and tag).
    ephemeral_prefix: [u8; 2],
    /// Per source address, when this node last admitted a key met from there (at most
    /// [`super::MAX_ADMISSION_SOURCES`]).
    admitted_from: BTreeMap<AddressPrefix, Timestamp>,
    running: bool,
}

/// The version and tag bytes that open an encoded [`Message::Ephemeral`], learnt from the
/// core's own encoder so the transport never hard-codes the wire format.
fn ephemeral_prefix() -> [u8; 2] {
    let bytes = Message::Ephemeral {
        channel: 0,
        seq: 0,
        value: Vec::new(),
    }
    .encode();
    [bytes[0], bytes[1]]
}

/// Appends the delivered ops to the store (fsync) before anything more is sent.
pub(super) fn persist<P: Payload>(
    store: &mut Option<OpStore<P>>,
    log: &Log<P>,
    ids: &[OpId],
) -> Result<(), String> {
    let Some(store) = store else {
        return Ok(());
    };
    let ops: Vec<_> = ids.iter().filter_map(|id| log.get(id)).collect();
    assert_eq!(
        ops.len(),
        ids.len(),
        "a delivered op is missing from the log"
    );
    store.append(&ops).map_err(|e| e.to_string())
}

impl<P: Payload + Send + 'static> Core<P> {
    pub(super) fn new(
        peer: Peer<P>,
        observer: Option<Box<dyn Observer<P>>>,
        store: Option<OpStore<P>>,
        endpoint: quinn::Endpoint,
        shared: Arc<Shared>,
        events: mpsc::Sender<NodeEvent>,
        counters: Arc<Counters>,
    ) -> Self {
        Self {
            peer,
            observer,
            // The observer hears of the log it starts from at the first settled step.
            changed: true,
            store,
            endpoint,
            shared,
            conns: BTreeMap::new(),
            dials: BTreeMap::new(),
            redials: BTreeMap::new(),
            lost: BTreeMap::new(),
            lost_dials: BTreeMap::new(),
            resumed_at: None,
            events,
            stats: NodeStats::default(),
            counters,
            ephemeral_prefix: ephemeral_prefix(),
            admitted_from: BTreeMap::new(),
            running: true,
            join: JoinState::default(),
        }
    }

    pub(super) async fn run(
        mut self,
        mut commands: mpsc::Receiver<Command<P>>,
        mut inputs: mpsc::Receiver<Input>,
    ) {
        while self.running {
            let now = wall_clock_now();
            let wait = self.peer.poll_timeout().map(|t| duration_until(now, t));
            let lost_due = self.next_lost_dial();
            tokio::select! {
                // The app's commands first, then due timers, then the network: a busy network
                // neither delays a local edit nor starves the resend and pacing timers.
                biased;
                command = commands.recv() => match command {
                    Some(command) => self.on_command(command),
                    // Every handle is gone: nobody can use the node any more.
                    None => self.running = false,
                },
                () = tokio::time::sleep(wait.unwrap_or_default()), if wait.is_some() => {
                    self.peer.handle_timeout(wall_clock_now());
                }
                () = tokio::time::sleep_until(lost_due.unwrap_or_else(Instant::now)),
                    if lost_due.is_some() => self.redial_lost(),
                Some(input) = inputs.recv() => self.on_input(input),
            }
            self.settle(wall_clock_now());
        }
        let conns: Vec<ConnId> = self.conns.keys().copied().collect();
        for conn in conns {
            self.drop_conn(conn, CloseCode::Shutdown, None);
        }
        self.endpoint
            .close(CloseCode::Shutdown.var_int(), b"shutdown");
    }

    pub(super) fn emit(&mut self, event: NodeEvent) {
        if self.events.try_send(event).is_err() {
            self.stats.n_events_dropped += 1;
        }
    }

    fn on_command(&mut self, command: Command<P>) {
        match command {
            Command::Dial {
                addr,
                handshake_timeout,
                reply,
            } => {
                // Already connected there (a connection held back for a join included): a
                // second connection would only replace the first at both ends.
                if let Some(open) = self.conn_to(addr) {
                    let _ = reply.send(Ok(open));
                    return;
                }
                let conn = self.shared.next_conn_id();
                self.dials.insert(conn, reply);
                self.spawn_dial(conn, addr, handshake_timeout);
            }
            Command::Author { payload, reply } => self.author_or_hold(payload, reply),
            Command::Ephemeral {
                channel,
                value,
                reply,
            } => {
                let _ = reply.send(self.peer.send_ephemeral(channel, &value));
            }
            Command::Close { conn, reply } => {
                let open = self.conns.contains_key(&conn);
                self.drop_conn(conn, CloseCode::Closed, Some(DisconnectReason::Closed));
                let _ = reply.send(open);
            }
            Command::Peers { reply } => {
                let peers = self.conns.iter().map(|(c, l)| (*c, l.peer)).collect();
                let _ = reply.send(peers);
            }
            Command::Stats { reply } => {
                let _ = reply.send(self.stats_snapshot());
            }
            Command::Query(query) => query(&self.peer),
            Command::Shutdown { reply } => {
                self.running = false;
                let _ = reply.send(());
            }
        }
    }

    pub(super) fn author(&mut self, payload: P) -> Result<OpId, NodeAuthorError> {
        let (op, insertion) = self.peer.author(wall_clock_now(), payload)?;
        if let Err(error) = persist(&mut self.store, self.peer.log(), &insertion.delivered) {
            self.stop(error.clone());
            return Err(NodeAuthorError::Store(error));
        }
        self.observe(&insertion);
        // The author hears back only once the observer has seen its op settled (a face reads
        // its own edit in the view as soon as the reply comes).
        if let Some(observer) = &mut self.observer {
            observer.settled(&mut self.peer, std::mem::take(&mut self.changed));
        }
        Ok(op.op().id())
    }

    /// Stops the node: an op that cannot be stored must never be sent.
    pub(super) fn stop(&mut self, error: String) {
        self.running = false;
        self.emit(NodeEvent::Stopped { error });
    }

    fn on_input(&mut self, input: Input) {
        match input {
            Input::Admitted {
                conn,
                role,
                connection,
                peer,
                send,
                start,
            } => self.on_admitted(conn, role, connection, peer, send, start),
            Input::SnapshotRequest { conn, send } => self.on_snapshot_request(conn, send),
            Input::SnapshotProgress { conn, bytes } => self.on_snapshot_progress(conn, bytes),
            Input::SnapshotFetched { conn, result } => self.on_snapshot_fetched(conn, result),
            Input::VerifyProgress { checked } => self.on_verify_progress(checked),
            Input::Verified { result } => self.on_verified(result),
            Input::AdmissionFailed {
                conn,
                addr,
                error,
                kind,
            } => self.on_admission_failed(conn, addr, error, kind),
            Input::Superseded { conn, addr } => {
                self.stats.n_duplicates += 1;
                if let Some(c) = conn {
                    self.redials.remove(&c);
                    self.lost_dials.remove(&c);
                }
                if let Some(reply) = conn.and_then(|c| self.dials.remove(&c)) {
                    // The dial's answer is the connection the remote kept, when it is here
                    // already (the usual order); otherwise the caller learns why, and the
                    // kept connection's admission is reported as any other.
                    let kept = self
                        .conns
                        .iter()
                        .find(|(_, l)| l.connection.remote_address() == addr)
                        .map(|(&c, _)| c);
                    let _ =
                        reply.send(kept.ok_or(DialError::Admission(AdmissionError::Superseded)));
                }
            }
            Input::Frame { conn, bytes } => {
                self.peer.handle_input(wall_clock_now(), conn, &bytes);
            }
            Input::Datagram { conn, bytes } => {
                if bytes.starts_with(&self.ephemeral_prefix) {
                    self.peer.handle_input(wall_clock_now(), conn, &bytes);
                } else {
                    self.stats.n_bad_datagrams += 1;
                }
            }
            Input::OversizedFrame { conn, len } => {
                self.stats.n_oversized_frames += 1;
                let reason = DisconnectReason::OversizedFrame { len };
                self.drop_conn(conn, CloseCode::Protocol, Some(reason));
            }
            Input::Lost { conn, reason } => {
                self.note_lost(conn);
                self.drop_conn(
                    conn,
                    CloseCode::Closed,
                    Some(DisconnectReason::Lost(reason)),
                );
            }
        }
    }

    /// A dial or an accept failed before admission: counted, answered and told, unless it
    /// was a redial of a stalled connection.
    fn on_admission_failed(
        &mut self,
        conn: Option<ConnId>,
        addr: std::net::SocketAddr,
        error: AdmissionError,
        kind: RefusalKind,
    ) {
        // A redial that found its remote still cut off is no news: the stalled connection
        // goes on, and its next stall dials again.
        if conn.and_then(|c| self.redials.remove(&c)).is_some() {
            return;
        }
        // So is a dial to a lost peer that is still away: the next one is due soon.
        if conn.and_then(|c| self.lost_dials.remove(&c)).is_some() {
            return;
        }
        *self.stats.failed_admissions.entry(kind).or_insert(0) += 1;
        if let Some(reply) = conn.and_then(|c| self.dials.remove(&c)) {
            let _ = reply.send(Err(DialError::Admission(error.clone())));
        }
        self.emit(NodeEvent::AdmissionFailed { addr, error });
    }

    fn refuse(
        &mut self,
        connection: &quinn::Connection,
        reply: Option<oneshot::Sender<Result<ConnId, DialError>>>,
        kind: RefusalKind,
        error: DialError,
    ) {
        connection.close(CloseCode::Refused.var_int(), error.to_string().as_bytes());
        *self.stats.failed_admissions.entry(kind).or_insert(0) += 1;
        if let Some(reply) = reply {
            let _ = reply.send(Err(error));
        }
    }

    fn on_admitted(
        &mut self,
        conn: ConnId,
        role: Role,
        connection: quinn::Connection,
        peer: PeerId,
        send: quinn::SendStream,
        start: oneshot::Sender<()>,
    ) {
        let reply = self.dials.remove(&conn);
        let lost_dial = self.lost_dials.remove(&conn);
        // A redial that reached the stalled connection's peer, which the new one replaces: the
        // remote may have closed the old one already, having admitted the new one first.
        let stalled = (self.redials.remove(&conn))
            .filter(|&(_, p)| p == peer)
            .map(|(s, _)| s);
        if let Some((kind, error)) = self.refusal(peer) {
            return self.refuse(&connection, reply, kind, error);
        }
        if let Err(old) = self.settle_duplicate(peer, role, &connection) {
            connection.close(CloseCode::Duplicate.var_int(), b"duplicate");
            if let Some(reply) = reply {
                let _ = reply.send(Ok(old));
            }
            return;
        }
        let replaced = stalled.is_some_and(|s| !self.conns.contains_key(&s));
        if replaced {
            self.stats.n_stalls_replaced += 1;
        }
        let holding = self.join.holds_connections();
        if !holding
            && let Err(ConnectError::TooMany) = self.open_in_peer(conn, role, &connection, peer)
        {
            let kind = RefusalKind::TooManyConnections;
            return self.refuse(&connection, reply, kind, DialError::TooManyConnections);
        }
        let (frames, queue) = mpsc::channel(MAX_QUEUED_FRAMES_PER_CONN);
        tokio::spawn(conn::write_frames(connection.clone(), send, queue));
        self.conns.insert(
            conn,
            Live {
                peer,
                role,
                connection,
                start: Some(start),
                frames,
                since: wall_clock_now(),
                rx_at_stall: None,
            },
        );
        self.stats.n_admitted += 1;
        let reconnected = self.lost.remove(&peer).is_some() && lost_dial.is_some();
        if reconnected {
            self.stats.n_lost_reconnected += 1;
        }
        // A dial that waited out a stall or an outage got through: as good a sign that the
        // network is back as a silent remote heard again.
        if replaced || reconnected {
            self.on_resumed();
        }
        if let Some(reply) = reply {
            let _ = reply.send(Ok(conn));
        }
        if holding {
            self.hold_back(conn);
        } else {
            self.start_readers(conn);
        }
    }

    /// Opens a connection held back during a join in the peer and starts its readers, or
    /// drops it when every slot is taken.
    pub(super) fn release_conn(&mut self, conn: ConnId) {
        let Some(live) = self.conns.get(&conn) else {
            return;
        };
        let (role, connection, peer) = (live.role, live.connection.clone(), live.peer);
        if self.open_in_peer(conn, role, &connection, peer).is_ok() {
            return self.start_readers(conn);
        }
        *(self.stats.failed_admissions)
            .entry(RefusalKind::TooManyConnections)
            .or_insert(0) += 1;
        let reason = DisconnectReason::Sync(CloseReason::Evicted);
        self.drop_conn(conn, CloseCode::Refused, Some(reason));
    }

    /// Starts a connection's readers once the peer holds it.
    fn start_readers(&mut self, conn: ConnId) {
        if let Some(start) = self.conns.get_mut(&conn).and_then(|l| l.start.take()) {
            let _ = start.send(());
        }
    }

    /// Hands an admitted connection to `peer` to the sync core.
    fn open_in_peer(
        &mut self,
        conn: ConnId,
        role: Role,
        connection: &quinn::Connection,
        peer: PeerId,
    ) -> Result<(), ConnectError> {
        // A connection the remote dialed competes for slots with those of its address
        // prefix; when all are taken, the least useful accepted one makes room.
        let opened = match role {
            Role::Dialer => self.peer.connect(wall_clock_now(), conn),
            Role::Acceptor => {
                let source = AddressPrefix::of(connection.remote_address().ip()).key();
                self.peer.accept(wall_clock_now(), conn, source)
            }
        };
        match opened {
            // The sync hello must name the id admission proved, or nothing it sent counts.
            Ok(()) => {
                self.peer.set_admitted(conn, peer);
                Ok(())
            }
            Err(ConnectError::TooMany) => Err(ConnectError::TooMany),
            Err(e @ (ConnectError::InUse(_) | ConnectError::OutOfRange(_))) => {
                // Ids come from one counter that starts at 1: neither can happen.
                unreachable!("connection id from the node's counter refused: {e}");
            }
        }
    }

    /// Why an admitted connection to `peer` is refused at once, if it is: `peer` is this
    /// node's own key, or an expelled member's, or this node is expelled. An expelled member
    /// holds the invite but syncs with nobody: refused here, before it costs a connection
    /// slot, a sync state and a connected-then-left pair of events.
    fn refusal(&self, peer: PeerId) -> Option<(RefusalKind, DialError)> {
        let me = self.peer.peer_id();
        if peer == me {
            return Some((RefusalKind::SelfConnection, DialError::SelfConnection));
        }
        let out = [peer, me]
            .into_iter()
            .find(|p| self.peer.log().is_expelled(p))?;
        Some((RefusalKind::Expelled, DialError::Expelled(out)))
    }

    /// The open connection whose remote is at `addr`, admitted or held back for a join.
    fn conn_to(&self, addr: std::net::SocketAddr) -> Option<ConnId> {
        (self.conns.iter())
            .find(|(_, l)| l.connection.remote_address() == addr)
            .map(|(c, _)| *c)
    }

    /// Settles two connections to one peer (both dialed at once, or a redial): both sides keep
    /// the one whose dialer has the smaller id, and the newer one when the dialer is the same
    /// (a redial means the dialer believes the old one is dead). A connection from another
    /// address of the peer (a restarted process on a new port, a NAT rebinding) replaces the
    /// old one: only the peer's key could open it, and the old path is most likely dead, while
    /// simultaneous dials always share both sockets' addresses. Drops the old connection when
    /// the new one, of `role` over `connection`, is kept; the old one's id when it stays.
    fn settle_duplicate(
        &mut self,
        peer: PeerId,
        role: Role,
        connection: &quinn::Connection,
    ) -> Result<(), ConnId> {
        let me = self.peer.peer_id();
        let dialer = |role: Role| if role == Role::Dialer { me } else { peer };
        let existing = self.conns.iter().find(|(_, l)| l.peer == peer);
        let Some((&old, live)) = existing else {
            return Ok(());
        };
        let moved = live.connection.remote_address() != connection.remote_address();
        self.stats.n_duplicates += 1;
        if moved || dialer(role) <= dialer(live.role) {
            self.drop_conn(old, CloseCode::Duplicate, Some(DisconnectReason::Duplicate));
            Ok(())
        } else {
            Err(old)
        }
    }

    /// Closes and forgets a connection; `reason` None means no event (shutdown).
    pub(super) fn drop_conn(
        &mut self,
        conn: ConnId,
        code: CloseCode,
        reason: Option<DisconnectReason>,
    ) {
        let Some(live) = self.conns.remove(&conn) else {
            return;
        };
        self.forget_held(conn);
        let text = reason
            .as_ref()
            .map(|r| format!("{r:?}"))
            .unwrap_or_default();
        live.connection.close(code.var_int(), text.as_bytes());
        self.peer.disconnect(conn);
        self.stats.n_disconnected += 1;
        if let Some(reason) = reason {
            self.emit(NodeEvent::Disconnected {
                conn,
                peer: live.peer,
                reason,
            });
        }
    }

    /// After every step: events (and storage) first, then limits, then the observer (whose
    /// scene check may queue messages), then transmits.
    fn settle(&mut self, now: Timestamp) {
        self.drain_events();
        if !self.running {
            return;
        }
        self.enforce_rejection_limit();
        self.admit_newcomers(now);
        if let Some(observer) = &mut self.observer {
            observer.settled(&mut self.peer, std::mem::take(&mut self.changed));
        }
        self.drain_transmits(now);
    }

    /// In a session that binds its authors, admits the keys of connections up for
    /// [`super::ADMISSION_DELAY_MILLIS`] that the log does not know (no op and no admission
    /// of theirs is held), once this node may write: at most one per source address every
    /// [`super::ADMISSION_INTERVAL_MILLIS`], each granted [`Log::default_grant`].
    fn admit_newcomers(&mut self, now: Timestamp) {
        let log = self.peer.log();
        let me = self.peer.peer_id();
        if !log.binds_authors() || !log.is_admitted(&me) || self.join.holds_authors() {
            return;
        }
        let delay = super::ADMISSION_DELAY_MILLIS * 1_000;
        let interval = super::ADMISSION_INTERVAL_MILLIS * 1_000;
        let due: Vec<(PeerId, AddressPrefix)> = (self.conns.values())
            .filter(|l| now.0 >= l.since.0.saturating_add(delay) && !log.is_admitted(&l.peer))
            .map(|l| {
                (
                    l.peer,
                    AddressPrefix::of(l.connection.remote_address().ip()),
                )
            })
            .collect();
        for (key, prefix) in due {
            let recent = (self.admitted_from.get(&prefix))
                .is_some_and(|at| now.0 < at.0.saturating_add(interval));
            if recent || self.peer.log().is_admitted(&key) {
                continue;
            }
            let grant_bytes = self.peer.log().default_grant(&me);
            let Some(payload) = P::admitting(Admission {
                key,
                grant_bytes,
                nonce: None,
            }) else {
                return;
            };
            if self.admitted_from.len() >= super::MAX_ADMISSION_SOURCES
                && let Some(oldest) = (self.admitted_from.iter())
                    .min_by_key(|(_, at)| **at)
                    .map(|(p, _)| *p)
            {
                self.admitted_from.remove(&oldest);
            }
            self.admitted_from.insert(prefix, now);
            if self.author(payload).is_ok() {
                self.stats.n_keys_admitted += 1;
            }
        }
    }

    /// Shows the observer a stored insertion.
    fn observe(&mut self, insertion: &crate::log::Insertion) {
        if insertion.delivered.is_empty() && insertion.refold.is_none() {
            return;
        }
        self.changed = true;
        if let Some(observer) = &mut self.observer {
            observer.inserted(self.peer.log(), insertion);
        }
    }

    /// Drains the core's events. Every op they deliver is appended to the store in one write
    /// and one fsync, before the observer or the app hears of any of them and before anything
    /// more is sent: a batch of 64 received ops costs one fsync, not 64.
    // tidy:table: one arm per sync event.
    fn drain_events(&mut self) {
        let events: Vec<_> = std::iter::from_fn(|| self.peer.poll_event()).collect();
        let delivered: Vec<OpId> = events
            .iter()
            .filter_map(|(_, event)| match event {
                Event::Delivered(insertion) => Some(insertion.delivered.iter().copied()),
                _ => None,
            })
            .flatten()
            .collect();
        // A joined log is stored whole once its check passes ([`JoinState`]).
        let unchecked = self.join.holds_authors();
        if !unchecked && let Err(error) = persist(&mut self.store, self.peer.log(), &delivered) {
            return self.stop(error);
        }
        for (conn, event) in events {
            let Some(peer) = self.conns.get(&conn).map(|l| l.peer) else {
                continue;
            };
            let event = match event {
                // The core closed it before handling anything it sent.
                Event::Closed(CloseReason::NotAdmitted { .. }) => {
                    self.stats.n_identity_mismatches += 1;
                    let reason = DisconnectReason::IdentityMismatch;
                    self.drop_conn(conn, CloseCode::Protocol, Some(reason));
                    continue;
                }
                Event::Connected { .. } => {
                    let Some(live) = self.conns.get(&conn) else {
                        continue;
                    };
                    NodeEvent::Connected {
                        conn,
                        peer,
                        addr: live.connection.remote_address(),
                        role: live.role,
                    }
                }
                Event::Delivered(insertion) => {
                    self.observe(&insertion);
                    NodeEvent::Delivered {
                        conn,
                        peer,
                        insertion,
                    }
                }
                Event::Rejected { kind, detail } => NodeEvent::Rejected {
                    conn,
                    peer,
                    kind,
                    detail,
                },
                Event::Ephemeral { channel, value } => NodeEvent::Ephemeral {
                    conn,
                    peer,
                    channel,
                    value,
                },
                Event::UpToDate => NodeEvent::UpToDate { conn, peer },
                Event::Stalled {
                    handshake_micros,
                    again,
                    unheard,
                } => {
                    let handshake = Duration::from_micros(handshake_micros);
                    self.on_stalled(conn, handshake, again, unheard);
                    continue;
                }
                Event::Resumed { .. } => {
                    self.on_resumed();
                    continue;
                }
                // On the observer's own queue (`Peer::poll_scene_event`), never here.
                Event::Scene(_) => continue,
                Event::Forked { author, seq } => NodeEvent::Forked { conn, author, seq },
                Event::Closed(reason) => {
                    if reason == CloseReason::Evicted {
                        self.stats.n_evicted += 1;
                    }
                    let reason = DisconnectReason::Sync(reason);
                    self.drop_conn(conn, CloseCode::Sync, Some(reason));
                    continue;
                }
            };
            self.emit(event);
        }
    }

    /// The sync core says `conn` stalled: dials its remote again if the remote shows it
    /// hears nothing of ours (`unheard`: our sends wait in QUIC, whatever comes in), or if
    /// this is not the first stall event of a silence and the connection has received no UDP
    /// datagram since the last one. A remote that is busy (a join, a long fold) but reachable
    /// still acknowledges packets; only one cut off sends nothing at all.
    fn on_stalled(
        &mut self,
        conn: ConnId,
        handshake_timeout: Duration,
        again: bool,
        unheard: bool,
    ) {
        let Some(live) = self.conns.get_mut(&conn) else {
            return;
        };
        let received = live.connection.stats().udp_rx.datagrams;
        let noted = live.rx_at_stall.replace(received);
        if unheard || (again && noted == Some(received)) {
            self.redial(conn, handshake_timeout);
        }
    }

    /// A remote spoke after a silence, or a dial replaced a stalled connection or reached a
    /// lost peer: the network may be back. Unless that happened less
    /// than [`super::RESUMED_DIALS_EVERY_MILLIS`] ago, the lost peers are due at once and
    /// the finders hear of it ([`super::NodeHandle::resumed`]).
    fn on_resumed(&mut self) {
        let now = Instant::now();
        let every = Duration::from_millis(super::RESUMED_DIALS_EVERY_MILLIS);
        if self.resumed_at.is_some_and(|at| now < at + every) {
            return;
        }
        self.resumed_at = Some(now);
        self.stats.n_resumed_rounds += 1;
        for lost in self.lost.values_mut() {
            lost.next = lost.next.min(now);
        }
        self.shared.resumed.send_modify(|n| *n += 1);
    }

    /// Dials the remote of the stalled connection `stalled` again, unless a dial to it is
    /// under way: the handshake may take `handshake_timeout`, after which a fresh one (at the
    /// next stall event) does better than QUIC's backed-off retries of a lost first packet.
    /// Admitted, the new connection replaces the stalled one at both ends
    /// ([`Core::settle_duplicate`]: the sync core says a stall only at the end with the
    /// smaller id).
    fn redial(&mut self, stalled: ConnId, handshake_timeout: Duration) {
        let Some(live) = self.conns.get(&stalled) else {
            return;
        };
        if self.redials.values().any(|&(c, _)| c == stalled) {
            return;
        }
        let addr = live.connection.remote_address();
        let conn = self.shared.next_conn_id();
        self.redials.insert(conn, (stalled, live.peer));
        self.stats.n_stall_redials += 1;
        self.spawn_dial(conn, addr, handshake_timeout);
    }

    /// Notes the peer of connection `conn`, which is being lost, for dials again when the idle
    /// timeout closed it and this end has the smaller id (as for a stalled connection, so the
    /// two ends do not both dial); a remote that closed it, and a full list, are left to the
    /// finders.
    fn note_lost(&mut self, conn: ConnId) {
        let Some(live) = self.conns.get(&conn) else {
            return;
        };
        let timed_out = matches!(
            live.connection.close_reason(),
            Some(quinn::ConnectionError::TimedOut)
        );
        let full = self.lost.len() >= MAX_LOST_PEERS && !self.lost.contains_key(&live.peer);
        if !timed_out || self.peer.peer_id() > live.peer || full {
            return;
        }
        let floor = Duration::from_micros(MIN_REDIAL_HANDSHAKE_MICROS);
        let now = Instant::now();
        let lost = Lost {
            addr: live.connection.remote_address(),
            next: now,
            until: now + Duration::from_millis(REDIAL_LOST_FOR_MILLIS),
            handshake: (2 * live.connection.rtt())
                .clamp(floor, crate::net::admission::admission_timeout()),
        };
        self.lost.insert(live.peer, lost);
    }

    /// When the next dial to a lost peer is due (or one of them is to be forgotten).
    fn next_lost_dial(&self) -> Option<Instant> {
        self.lost.values().map(|l| l.next.min(l.until)).min()
    }

    /// Dials the lost peers that are due, at most [`MAX_LOST_DIALS_PER_PEER`] at a time each,
    /// and forgets those connected again, refused, or lost [`REDIAL_LOST_FOR_MILLIS`] ago.
    fn redial_lost(&mut self) {
        let now = Instant::now();
        let connected: BTreeSet<PeerId> = self.conns.values().map(|l| l.peer).collect();
        let refused: BTreeSet<PeerId> = (self.lost.keys())
            .filter(|p| self.refusal(**p).is_some())
            .copied()
            .collect();
        self.lost
            .retain(|p, l| now < l.until && !connected.contains(p) && !refused.contains(p));
        let every = Duration::from_millis(REDIAL_LOST_EVERY_MILLIS);
        let mut due = Vec::new();
        for (peer, lost) in &mut self.lost {
            if lost.next <= now {
                lost.next = now + every;
                due.push((*peer, lost.addr, lost.handshake));
            }
        }
        for (peer, addr, handshake) in due {
            let under_way = self.lost_dials.values().filter(|p| **p == peer).count();
            if under_way >= MAX_LOST_DIALS_PER_PEER {
                continue;
            }
            let conn = self.shared.next_conn_id();
            self.lost_dials.insert(conn, peer);
            self.stats.n_lost_redials += 1;
            self.spawn_dial(conn, addr, handshake);
        }
    }

    /// Dials `addr` as connection `conn` on a task of its own ([`conn::dial`]).
    fn spawn_dial(&self, conn: ConnId, addr: SocketAddr, handshake_timeout: Duration) {
        let (shared, endpoint) = (self.shared.clone(), self.endpoint.clone());
        tokio::spawn(conn::dial(shared, endpoint, conn, addr, handshake_timeout));
    }

    fn enforce_rejection_limit(&mut self) {
        let over: Vec<(ConnId, u64)> = self
            .peer
            .connections()
            .map(|(conn, sync)| (*conn, sync.stats().n_offences()))
            .filter(|(_, n)| *n > MAX_REJECTIONS_PER_CONN)
            .collect();
        for (conn, n_offences) in over {
            self.stats.n_cut_off += 1;
            let reason = DisconnectReason::CutOff { n_offences };
            self.drop_conn(conn, CloseCode::Protocol, Some(reason));
        }
    }

    fn drain_transmits(&mut self, now: Timestamp) {
        let mut slow = Vec::new();
        while let Some((conn, bytes)) = self.peer.poll_transmit(now) {
            let Some(live) = self.conns.get(&conn) else {
                continue;
            };
            if bytes.starts_with(&self.ephemeral_prefix) {
                let fits = live
                    .connection
                    .max_datagram_size()
                    .is_some_and(|max| bytes.len() <= max);
                if !fits || live.connection.send_datagram(bytes.into()).is_err() {
                    self.stats.n_datagrams_dropped += 1;
                }
                continue;
            }
            match live.frames.try_send(bytes) {
                Ok(()) => {}
                Err(mpsc::error::TrySendError::Full(_)) => slow.push(conn),
                // The writer ended with the connection; its reader reports the loss.
                Err(mpsc::error::TrySendError::Closed(_)) => {}
            }
        }
        for conn in slow {
            if self.conns.contains_key(&conn) {
                self.stats.n_slow_readers += 1;
                self.drop_conn(conn, CloseCode::Slow, Some(DisconnectReason::SlowReader));
            }
        }
    }

    fn stats_snapshot(&self) -> NodeStats {
        let mut stats = self.stats.clone();
        self.counters.fill(&mut stats);
        stats.n_store_syncs = self.store.as_ref().map_or(0, OpStore::n_syncs);
        stats.connections = self
            .peer
            .connections()
            .filter_map(|(conn, sync)| {
                let live = self.conns.get(conn)?;
                let quic = live.connection.stats();
                Some(ConnStats {
                    conn: *conn,
                    peer: live.peer,
                    addr: live.connection.remote_address(),
                    role: live.role,
                    sync: sync.stats().clone(),
                    udp_bytes_sent: quic.udp_tx.bytes,
                    udp_bytes_received: quic.udp_rx.bytes,
                    rtt_micros: u64::try_from(live.connection.rtt().as_micros())
                        .unwrap_or(u64::MAX),
                })
            })
            .collect();
        stats
    }
}
