//! One peer: its key, its log and one [`SyncState`] per connection, behind a single sans-IO
//! surface that routes inputs and drains outputs (what the app and the simulator drive).
//!
//! Across connections the peer decides whom to ask for what it lacks: when some remote's
//! version vector shows ops of an author this peer does not hold, it sends one
//! [`Message::Want`](crate::sync::message::Message::Want) to one holder at once: the author
//! itself when it is connected and shows them (its want goes on the connection that carries
//! the author's own sends, so nothing crosses twice), else the holder that delivered the
//! most. It asks the next holder when the one asked gave all it shows, or if it sent no op
//! for its resend timeout (growth from other connections does not count); after a third
//! peer, the author is asked again. An ask that timed out goes again to two holders at once,
//! so that a second loss on a lossy link (the want or its answer) does not cost a second
//! timeout. Those timeouts come from the round trips measured on each
//! connection (its first hello answered, then acknowledged batches), so on a LAN a lost op
//! is repaired in milliseconds and on a slow link nobody is asked too early; a connection
//! without a measurement waits what the peer's other connections measure, and none waits
//! longer than [`RELAY_AFTER_MICROS`] and [`WANT_RETRY_MICROS`]. Wants are reconsidered
//! [`WANT_COALESCE_MICROS`] after input and at the soonest deadline of an open ask, so neither
//! a lack a have reveals nor a timed-out ask waits for a periodic check.
//! A holder that answered in that time with messages but not one op claimed what it does not
//! send: its claim is withdrawn ([`SyncState::withdraw_claim`]) and not learnt again from it
//! for [`CLAIM_WITHDRAWN_MICROS`](crate::sync::state::CLAIM_WITHDRAWN_MICROS), so made-up
//! claims cost a retry period each, not work for the connection's life. A holder that sent
//! nothing at all (a partition) keeps its claims, and so does an author asked for its own ops
//! (a third peer is asked next, and the author again after it).

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use crate::causal::VersionVector;
use crate::identity::{Keypair, PeerId, SessionId};
use crate::log::{AuthorError, Insertion, Log};
use crate::op::VerifiedOp;
use crate::payload::Payload;
use crate::pending::Origin;
use crate::sync::message::{DIGEST_BYTES, SceneAt};
use crate::sync::scene::{ObjectHashes, SceneCut, SceneEvent};
use crate::sync::state::{
    EphemeralError, Event, OpByteQuota, RELAY_AFTER_MICROS, RESEND_AFTER_MICROS, SyncConfig,
    SyncState,
};
use crate::time::Timestamp;

/// A want that brought nothing for the holder's resend timeout, and at most this long (1 s),
/// goes to the next holder.
pub const WANT_RETRY_MICROS: u64 = RESEND_AFTER_MICROS;
/// Open wants are reconsidered at their asks' deadlines, and at least this often (100 ms).
pub const WANT_CHECK_MICROS: u64 = 100_000;
/// After input, wants are reconsidered this long after the last time (10 ms): a have or a
/// batch is acted on at once, and a burst of messages costs one pass.
pub const WANT_COALESCE_MICROS: u64 = 10_000;

/// Most simultaneous connections one peer keeps. When all are taken, a new one (dialed or
/// accepted) takes the slot of the least useful accepted connection (see [`Peer::accept`]),
/// so remotes that dial in cannot lock out an honest accept or a dial.
pub const MAX_CONNECTIONS: usize = 64;

/// Most scene events ([`Peer::poll_scene_event`]) queued for the scene's owner; more are
/// dropped (each connection's scene check makes a few a window, so only an owner that never
/// polls sees this).
pub const MAX_QUEUED_SCENE_EVENTS: usize = 4 * MAX_CONNECTIONS;

/// A connection's id, chosen by the caller (the transport or the simulator).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ConnId(pub u64);

/// Why a connection could not be opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ConnectError {
    /// Already [`MAX_CONNECTIONS`] connections, none of them accepted (so none to evict).
    #[error("already {MAX_CONNECTIONS} connections")]
    TooMany,
    /// This id is in use.
    #[error("connection {0:?} already open")]
    InUse(ConnId),
    /// The id cannot be mapped to an origin (it is `u64::MAX`).
    #[error("connection id {0:?} out of range")]
    OutOfRange(ConnId),
}

/// A peer: key pair, log and its connections.
#[derive(Debug)]
pub struct Peer<P> {
    keypair: Keypair,
    session_id: SessionId,
    log: Log<P>,
    connections: BTreeMap<ConnId, SyncState<P>>,
    /// How each connection holds its slot (one entry per connection).
    slots: BTreeMap<ConnId, Slot>,
    events: VecDeque<(ConnId, Event)>,
    /// Authors whose ops some remote holds and this peer lacks (at most one entry per author
    /// named in a connection's version vector, so bounded by the connections' limits).
    wants: BTreeMap<PeerId, WantState>,
    /// Set by input; wants are reconsidered [`WANT_COALESCE_MICROS`] after `wants_checked_at`
    /// while set, and at `want_check_at` (the first open want's deadline) while any is open.
    wants_dirty: bool,
    wants_checked_at: Option<Timestamp>,
    want_check_at: Timestamp,
    /// The owner's scene hash at the log's current cut, if it said one.
    scene: Option<SceneAt>,
    /// The owner's per-object hashes and the scene hash they were taken at (for connections
    /// opened since, and later mismatches while the scene hash stays the same).
    object_hashes: Option<(SceneAt, Arc<ObjectHashes>)>,
    /// What the connections' scene checks ask of the scene's owner.
    scene_events: VecDeque<(ConnId, SceneEvent)>,
}

/// How a connection holds its slot: when it opened, and for one the remote dialed, the
/// source group the transport named.
#[derive(Clone, Copy, Debug)]
struct Slot {
    opened_at: Timestamp,
    accepted_from: Option<u64>,
}

/// What this peer asked for one author's ops.
#[derive(Clone, Copy, Debug)]
struct WantState {
    /// When, where and at what held seq it was last asked for, if it was.
    asked: Option<Asked>,
    /// How many holders were asked so far (picks the next).
    n_asked: usize,
}

/// One ask for an author's ops: when, of which connection, at what held seq, and how many
/// messages and ops that connection had sent by then.
#[derive(Clone, Copy, Debug)]
struct Asked {
    at: Timestamp,
    conn: ConnId,
    had: u64,
    n_messages: u64,
    n_ops: u64,
}

impl Asked {
    fn new<P: Payload>(at: Timestamp, conn: ConnId, had: u64, sync: Option<&SyncState<P>>) -> Self {
        let stats = sync.map(SyncState::stats);
        Self {
            at,
            conn,
            had,
            n_messages: stats.map_or(0, |s| s.n_messages_in),
            n_ops: stats.map_or(0, |s| s.n_ops_in),
        }
    }

    /// The connection sent ops since: the log's growth may be its doing (ops from elsewhere
    /// do not show that the holder asked got the want).
    fn delivered<P: Payload>(&self, sync: Option<&SyncState<P>>) -> bool {
        sync.is_some_and(|s| s.stats().n_ops_in > self.n_ops)
    }

    /// The connection answered since (some message came) but sent no op at all: it claimed
    /// ops it does not send. A silent one (a partition, a dead link) is only waited for.
    fn unanswered<P: Payload>(&self, sync: Option<&SyncState<P>>) -> bool {
        sync.is_some_and(|s| {
            s.stats().n_messages_in > self.n_messages && s.stats().n_ops_in == self.n_ops
        })
    }
}

/// One pass of [`Peer::update_wants`] over the authors this peer lacks: the asks it makes
/// per connection, the claims it withdraws, and when it must look again.
struct WantPass<'a, P: Payload> {
    now: Timestamp,
    connections: &'a BTreeMap<ConnId, SyncState<P>>,
    /// The median resend timeout the connections measured, if any did.
    typical: Option<u64>,
    /// The connection to each remote, by the remote's id.
    direct: Vec<(PeerId, ConnId)>,
    asks: BTreeMap<ConnId, VersionVector>,
    withdraw: Vec<(ConnId, PeerId)>,
    check_at: Timestamp,
}

impl<P: Payload> WantPass<'_, P> {
    /// How long an ask of `conn` is waited for (less for the author's own connection).
    fn retry_of(&self, conn: &ConnId, from_author: bool) -> u64 {
        let timeout = (self.connections.get(conn))
            .and_then(SyncState::resend_timeout)
            .or(self.typical);
        match timeout {
            Some(t) if from_author => t.min(RELAY_AFTER_MICROS),
            None if from_author => RELAY_AFTER_MICROS,
            Some(t) => t.min(WANT_RETRY_MICROS),
            None => WANT_RETRY_MICROS,
        }
    }

    /// Whether `conn` shows more of `author`'s ops than the `have` this peer holds.
    fn holds_more(&self, conn: &ConnId, author: &PeerId, have: u64) -> bool {
        (self.connections.get(conn)).is_some_and(|s| s.remote_version_vector().get(author) > have)
    }

    /// Asks for `author`'s ops past `have` (its `want`), unless an ask still runs.
    fn want(&mut self, author: PeerId, have: u64, want: &mut WantState) {
        // The author's own connection, if it shows more of the author than this peer holds.
        let author_conn = (self.direct.iter())
            .find(|(remote, _)| *remote == author)
            .map(|(_, conn)| *conn)
            .filter(|conn| self.holds_more(conn, &author, have));
        let Some(timed_out) = self.last_ask(author, have, author_conn, want) else {
            return;
        };
        // The author is asked first (and again after each third peer): it sends on the
        // connection that carries its own pushes, so nothing goes twice, and the want tells
        // it where to start.
        let last = want.asked.map(|a| a.conn);
        let to_author = author_conn.filter(|c| Some(*c) != last);
        let holders = if to_author.is_none() || timed_out {
            self.holders(author, have, author_conn)
        } else {
            Vec::new()
        };
        let next = want.n_asked % holders.len().max(1);
        let conn = match to_author {
            Some(conn) => conn,
            None => {
                let Some(&conn) = holders.get(next) else {
                    want.asked = None;
                    return;
                };
                conn
            }
        };
        // An ask that brought nothing in its time is made again of two holders at once:
        // on a lossy link the want or its answer is lost often enough that waiting out a
        // second timeout, then a third, is the tail of convergence. A hedge costs the
        // author's ops sent twice, only where an ask already failed.
        let hedge = if timed_out {
            (1..=holders.len())
                .map(|k| holders[(next + k) % holders.len()])
                .find(|c| *c != conn)
        } else {
            None
        };
        for conn in std::iter::once(conn).chain(hedge) {
            let seq = self.connections[&conn].remote_version_vector().get(&author);
            self.asks.entry(conn).or_default().raise(author, seq);
        }
        want.asked = Some(Asked::new(
            self.now,
            conn,
            have,
            self.connections.get(&conn),
        ));
        want.n_asked += 1 + usize::from(hedge.is_some());
        let retry = self.retry_of(&conn, Some(conn) == author_conn);
        self.check_at = self.check_at.min(self.now.saturating_add_micros(retry));
    }

    /// Where the last ask for `author`'s ops past `have` (its `want`) stands: `None` while it
    /// is waited for (its holder is delivering, or its time is not up), else whether it timed
    /// out (false when there was none, or its holder shows nothing more). A timed-out ask of
    /// another holder than the author's own connection (`author_conn`) that answered without
    /// ops has its claim withdrawn.
    fn last_ask(
        &mut self,
        author: PeerId,
        have: u64,
        author_conn: Option<ConnId>,
        want: &mut WantState,
    ) -> Option<bool> {
        let Some(asked) = want.asked else {
            return Some(false);
        };
        if !self.holds_more(&asked.conn, &author, have) {
            return Some(false);
        }
        let sync = self.connections.get(&asked.conn);
        let from_author = Some(asked.conn) == author_conn;
        let retry = self.retry_of(&asked.conn, from_author);
        if have > asked.had && asked.delivered(sync) {
            // The holder is delivering: give it more time.
            want.asked = Some(Asked::new(self.now, asked.conn, have, sync));
            self.check_at = self.check_at.min(self.now.saturating_add_micros(retry));
            return None;
        }
        let due = asked.at.saturating_add_micros(retry);
        if self.now < due {
            self.check_at = self.check_at.min(due);
            return None;
        }
        if !from_author && asked.unanswered(sync) {
            // The claim is withdrawn, and the next holder, if any, is asked.
            self.withdraw.push((asked.conn, author));
        }
        Some(true)
    }

    /// The connections to ask for `author`'s ops past `have`, in turn: a holder that gave
    /// all it shows is not waited for, and those that delivered the most so far come first,
    /// so a remote that only claims to hold ops (a replayed have) and sends none is tried
    /// last. The one whose claim was just withdrawn is left out, and the author's own
    /// connection (`author_conn`) too when there are others.
    fn holders(&self, author: PeerId, have: u64, author_conn: Option<ConnId>) -> Vec<ConnId> {
        let mut by_delivered: Vec<(u64, ConnId)> = (self.connections.iter())
            .filter(|(c, _)| self.holds_more(c, &author, have))
            .map(|(c, s)| (s.stats().n_ops_delivered, *c))
            .collect();
        by_delivered.sort_by_key(|&(n, conn)| (std::cmp::Reverse(n), conn));
        let mut holders: Vec<ConnId> = by_delivered.into_iter().map(|(_, conn)| conn).collect();
        if let Some(&(failed, _)) = self.withdraw.last().filter(|(_, a)| *a == author) {
            holders.retain(|conn| *conn != failed);
        }
        if holders.len() > 1 {
            holders.retain(|conn| Some(*conn) != author_conn);
        }
        holders
    }
}

impl<P: Payload> Peer<P> {
    /// A peer in session `session_id` with an existing (for example reloaded) log, which it
    /// names the session of ([`Log::set_session_id`]).
    pub fn new(keypair: Keypair, session_id: SessionId, mut log: Log<P>) -> Self {
        log.set_session_id(session_id);
        Self {
            keypair,
            session_id,
            log,
            connections: BTreeMap::new(),
            slots: BTreeMap::new(),
            events: VecDeque::new(),
            wants: BTreeMap::new(),
            wants_dirty: false,
            wants_checked_at: None,
            want_check_at: Timestamp(0),
            scene: None,
            object_hashes: None,
            scene_events: VecDeque::new(),
        }
    }

    /// This peer's id.
    pub fn peer_id(&self) -> PeerId {
        self.keypair.peer_id()
    }

    /// The log.
    pub fn log(&self) -> &Log<P> {
        &self.log
    }

    /// Puts `log` in place of this peer's log, which it returns: how a node that joined from a
    /// snapshot takes the joined log, and gives it up when the snapshot proves forged. Only
    /// while no connection is open (each one's sync state reads the log); else nothing
    /// changes and `None` comes back.
    pub fn replace_log(&mut self, mut log: Log<P>) -> Option<Log<P>> {
        if !self.connections.is_empty() {
            return None;
        }
        log.set_session_id(self.session_id);
        self.wants.clear();
        self.wants_dirty = false;
        self.scene = None;
        self.object_hashes = None;
        self.scene_events.clear();
        Some(std::mem::replace(&mut self.log, log))
    }

    /// Open connections, in id order.
    pub fn connections(&self) -> impl Iterator<Item = (&ConnId, &SyncState<P>)> {
        self.connections.iter()
    }

    /// Authors a local op; every connection streams it out on its next `poll_transmit`.
    pub fn author(
        &mut self,
        now: Timestamp,
        payload: P,
    ) -> Result<(VerifiedOp<P>, Insertion), AuthorError> {
        let authored = self.log.author(&self.keypair, now, payload)?;
        self.close_expelled(now);
        Ok(authored)
    }

    /// Opens a connection this peer dialed (state is built afresh for every connection). It
    /// is never evicted; when [`MAX_CONNECTIONS`] are open, it takes the slot of an accepted
    /// one (see [`Peer::accept`]).
    pub fn connect(&mut self, now: Timestamp, conn: ConnId) -> Result<(), ConnectError> {
        self.open(now, conn, None)
    }

    /// Opens a connection the remote dialed, from `source`: a group the transport names (a
    /// hash of the remote's address prefix, say), whose connections compete for slots.
    /// When [`MAX_CONNECTIONS`] are open, the least useful accepted connection is closed to
    /// make room (`Event::Closed(CloseReason::Evicted)` on it): one of the source with the
    /// most accepted connections, among those the one that delivered the fewest ops this
    /// peer lacked (and whose remote authored none it holds), the oldest of equals. So
    /// remotes from a few sources that hold every slot lose them to anyone else, a new
    /// remote is never refused for want of a slot, and a remote that brings ops is kept
    /// over one that only holds a slot.
    pub fn accept(
        &mut self,
        now: Timestamp,
        conn: ConnId,
        source: u64,
    ) -> Result<(), ConnectError> {
        self.open(now, conn, Some(source))
    }

    fn open(
        &mut self,
        now: Timestamp,
        conn: ConnId,
        accepted_from: Option<u64>,
    ) -> Result<(), ConnectError> {
        if self.connections.contains_key(&conn) {
            return Err(ConnectError::InUse(conn));
        }
        // Origin 0 is the local peer; connection n is origin n + 1.
        let origin = Origin(
            conn.0
                .checked_add(1)
                .ok_or(ConnectError::OutOfRange(conn))?,
        );
        if self.connections.len() >= MAX_CONNECTIONS {
            self.evict_accepted(accepted_from)?;
        }
        let config = SyncConfig {
            session_id: self.session_id,
            local: self.peer_id(),
            origin,
        };
        let mut sync = SyncState::new(now, config);
        if let Some(micros) = self.typical_resend_timeout() {
            sync.assume_resend_timeout(micros);
        }
        if let Some(at) = self.scene {
            sync.set_local_scene(at);
        }
        self.connections.insert(conn, sync);
        let slot = Slot {
            opened_at: now,
            accepted_from,
        };
        self.slots.insert(conn, slot);
        assert!(
            self.connections.len() <= MAX_CONNECTIONS,
            "more than MAX_CONNECTIONS connections"
        );
        Ok(())
    }

    /// Closes the least useful accepted connection (see [`Peer::accept`]) to make room for one
    /// more, from `source` if the remote dialed it; `TooMany` if none was accepted.
    fn evict_accepted(&mut self, source: Option<u64>) -> Result<(), ConnectError> {
        let mut by_source: BTreeMap<u64, usize> = BTreeMap::new();
        for from in self
            .slots
            .values()
            .filter_map(|s| s.accepted_from)
            .chain(source)
        {
            *by_source.entry(from).or_default() += 1;
        }
        let held = self.log.version_vector();
        let usefulness = |conn: &ConnId| {
            let sync = self.connections.get(conn);
            let delivered = sync.map_or(0, |s| s.stats().n_ops_delivered);
            let known = sync
                .and_then(SyncState::remote)
                .is_some_and(|remote| held.get(&remote) > 0);
            (delivered, known)
        };
        let victim = (self.slots.iter())
            .filter_map(|(conn, slot)| Some((conn, slot.accepted_from?, slot.opened_at)))
            .max_by_key(|(conn, from, opened_at)| {
                let crowd = by_source.get(from).copied().unwrap_or(0);
                (
                    crowd,
                    std::cmp::Reverse(usefulness(conn)),
                    std::cmp::Reverse(*opened_at),
                )
            })
            .map(|(conn, _, _)| *conn)
            .ok_or(ConnectError::TooMany)?;
        self.disconnect(victim);
        let closed = Event::Closed(crate::sync::state::CloseReason::Evicted);
        self.events.push_back((victim, closed));
        Ok(())
    }

    /// The transport proved that the remote of `conn` holds `peer` (at admission): its sync
    /// hello must name it, or the connection closes before anything the remote sent is
    /// handled ([`SyncState::set_admitted`]). Call it right after opening `conn`.
    pub fn set_admitted(&mut self, conn: ConnId, peer: PeerId) {
        if let Some(sync) = self.connections.get_mut(&conn) {
            sync.set_admitted(peer);
        }
    }

    /// Replaces the quota of new op bytes the remote of `conn` may make this peer take
    /// ([`SyncState::set_op_byte_quota`]).
    pub fn set_op_byte_quota(&mut self, now: Timestamp, conn: ConnId, quota: OpByteQuota) {
        if let Some(sync) = self.connections.get_mut(&conn) {
            sync.set_op_byte_quota(now, quota);
        }
    }

    /// Forgets a connection (the transport lost it); nothing acknowledged is lost.
    pub fn disconnect(&mut self, conn: ConnId) {
        self.connections.remove(&conn);
        self.slots.remove(&conn);
    }

    /// Handles bytes received on `conn`; unknown connections are ignored.
    pub fn handle_input(&mut self, now: Timestamp, conn: ConnId, bytes: &[u8]) {
        if let Some(sync) = self.connections.get_mut(&conn) {
            let first = self.events.len();
            let len = self.log.len();
            sync.handle_input(now, bytes, &mut self.log);
            drain(conn, sync, (&mut self.events, &mut self.scene_events));
            self.charge_others(conn, first);
            if self.log.len() > len {
                // Ops get through: connections stalled in backoff try again soon.
                for (_, sync) in self.connections.iter_mut().filter(|(c, _)| **c != conn) {
                    sync.wake(now);
                }
            }
            self.wants_dirty = true;
            self.close_expelled(now);
        }
    }

    /// Hands the insertions among `events[first..]`, which `conn`'s input caused, to the
    /// other connections, so each counts what they refused or evicted of its own remote's ops.
    fn charge_others(&mut self, conn: ConnId, first: usize) {
        let foreign: Vec<Insertion> = (self.events.range(first..))
            .filter_map(|(_, e)| match e {
                Event::Delivered(i) if !i.refused.is_empty() || !i.evicted.is_empty() => {
                    Some(i.clone())
                }
                _ => None,
            })
            .collect();
        for insertion in &foreign {
            for (other, sync) in self.connections.iter_mut().filter(|(c, _)| **c != conn) {
                sync.charge(insertion);
                drain(*other, sync, (&mut self.events, &mut self.scene_events));
            }
        }
    }

    /// Closes every connection to a member the founder expelled, once the member was told
    /// ([`crate::sync::state::EXPEL_NOTICE_MICROS`]), and all of them at once when it
    /// expelled this peer: an expel may arrive on any connection.
    fn close_expelled(&mut self, now: Timestamp) {
        if self.log.expelled().is_empty() {
            return;
        }
        for (conn, sync) in &mut self.connections {
            sync.close_if_expelled(now, &self.log);
            drain(*conn, sync, (&mut self.events, &mut self.scene_events));
        }
    }

    /// Handles the passing of time on every connection.
    pub fn handle_timeout(&mut self, now: Timestamp) {
        for (conn, sync) in &mut self.connections {
            if sync.poll_timeout(&self.log).is_some_and(|t| t <= now) {
                sync.handle_timeout(now, &mut self.log);
                drain(*conn, sync, (&mut self.events, &mut self.scene_events));
            }
        }
        if self.want_due().is_some_and(|t| t <= now) {
            self.update_wants(now);
        }
        // Ops from the future wait for the clock; their delivery is reported on a live
        // connection (without one they wait for the next insertion).
        if let Some(&conn) = self.connections.keys().next()
            && self.log.next_due().is_some_and(|t| t <= now)
        {
            let insertion = self.log.release_due(now);
            if !insertion.delivered.is_empty() || !insertion.refused.is_empty() {
                self.events.push_back((conn, Event::Delivered(insertion)));
                self.wants_dirty = true;
            }
        }
    }

    /// The median of the resend timeouts measured on this peer's connections, if any was:
    /// what a connection without a measurement of its own assumes.
    fn typical_resend_timeout(&self) -> Option<u64> {
        let mut measured: Vec<u64> = (self.connections.values())
            .filter_map(SyncState::resend_timeout)
            .collect();
        if measured.is_empty() {
            return None;
        }
        let mid = measured.len() / 2;
        Some(*measured.select_nth_unstable(mid).1)
    }

    fn want_due(&self) -> Option<Timestamp> {
        let changed = (self.wants_dirty).then(|| {
            (self.wants_checked_at).map_or(Timestamp(0), |t| {
                t.saturating_add_micros(WANT_COALESCE_MICROS)
            })
        });
        let open = (!self.wants.is_empty()).then_some(self.want_check_at);
        changed.into_iter().chain(open).min()
    }

    /// Asks one holder for each author's ops this peer lacks (see the module docs).
    fn update_wants(&mut self, now: Timestamp) {
        self.wants_dirty = false;
        self.wants_checked_at = Some(now);
        let held = self.log.version_vector();
        // The most any remote holds of each author this peer lacks.
        let mut lacking = VersionVector::new();
        let mut direct = Vec::new();
        for (conn, sync) in &self.connections {
            if let Some(remote) = sync.remote() {
                direct.push((remote, *conn));
            }
            for (author, seq) in sync.remote_version_vector().iter() {
                if *seq > held.get(author) {
                    lacking.raise(*author, *seq);
                }
            }
        }
        self.wants.retain(|author, _| lacking.get(author) > 0);
        // How long a connection's answer is waited for: its measured resend timeout (the
        // round trip and its spread), else the typical one, capped by the constants.
        let typical = self.typical_resend_timeout();
        if let Some(micros) = typical {
            // Connections without a round trip of their own follow what the others measure.
            for sync in self.connections.values_mut() {
                sync.assume_resend_timeout(micros);
            }
        }
        let mut pass = WantPass {
            now,
            connections: &self.connections,
            typical,
            direct,
            asks: BTreeMap::new(),
            withdraw: Vec::new(),
            // The soonest moment an open ask times out, and at the latest a period from now.
            check_at: now.saturating_add_micros(WANT_CHECK_MICROS),
        };
        for (author, _) in lacking.iter() {
            let want = self.wants.entry(*author).or_insert(WantState {
                asked: None,
                n_asked: 0,
            });
            pass.want(*author, held.get(author), want);
        }
        let WantPass {
            asks,
            withdraw,
            check_at,
            ..
        } = pass;
        self.want_check_at = check_at;
        for (conn, author) in withdraw {
            if let Some(sync) = self.connections.get_mut(&conn) {
                sync.withdraw_claim(now, &author, &self.log);
            }
        }
        for (conn, vv) in asks {
            if let Some(sync) = self.connections.get_mut(&conn) {
                sync.want(vv, &self.log);
            }
        }
    }

    /// Sends the latest value on an ephemeral channel to every connection.
    pub fn send_ephemeral(&mut self, channel: u32, value: &[u8]) -> Result<(), EphemeralError> {
        for sync in self.connections.values_mut() {
            sync.send_ephemeral(channel, value.to_vec())?;
        }
        Ok(())
    }

    /// The next message to send and its connection.
    pub fn poll_transmit(&mut self, now: Timestamp) -> Option<(ConnId, Vec<u8>)> {
        self.connections.iter_mut().find_map(|(conn, sync)| {
            sync.poll_transmit(now, &self.log)
                .map(|bytes| (*conn, bytes))
        })
    }

    /// The next event and the connection it came from.
    pub fn poll_event(&mut self) -> Option<(ConnId, Event)> {
        self.events.pop_front()
    }

    /// The scene's owner folded the log to `cut` and its scene hashes to `hash`: every
    /// connection compares it with its remote's ([`crate::sync::scene`]). Ignored (false) when
    /// the log is no longer at `cut`. Call it after each fold, then drain the `poll_*`.
    pub fn set_scene_hash(&mut self, cut: SceneCut, hash: [u8; DIGEST_BYTES]) -> bool {
        if cut != SceneCut::of(&self.log) {
            return false;
        }
        let at = cut.with_hash(hash);
        if self.scene != Some(at) {
            self.scene = Some(at);
            for sync in self.connections.values_mut() {
                sync.set_local_scene(at);
            }
        }
        true
    }

    /// The owner's per-object hashes at `cut`, which a [`SceneEvent::Mismatch`] there asked
    /// for: sent to the remotes whose scene differs, and compared with theirs. Ignored (false)
    /// when the owner's scene hash is not at `cut`. They belong to the scene hash last set.
    pub fn set_object_hashes(&mut self, cut: SceneCut, hashes: ObjectHashes) -> bool {
        let Some(at) = self.scene.filter(|at| at.cut == cut.digest) else {
            return false;
        };
        self.object_hashes = Some((at, Arc::new(hashes)));
        self.reuse_object_hashes(cut)
    }

    /// Hands the per-object hashes the owner last set to the connections again, if they were
    /// taken at `cut` and the scene hash has not changed since (false if not): what answers a
    /// later [`SceneEvent::Mismatch`] at the same scene without hashing it again. A scene that
    /// changed at the same cut (a refold, or a fold gone wrong again) needs fresh ones: the
    /// old ones would name what differed then, not now.
    pub fn reuse_object_hashes(&mut self, cut: SceneCut) -> bool {
        let Some((at, hashes)) = &self.object_hashes else {
            return false;
        };
        if at.cut != cut.digest || self.scene != Some(*at) {
            return false;
        }
        for (conn, sync) in &mut self.connections {
            sync.set_local_object_hashes(cut.digest, hashes);
            drain(*conn, sync, (&mut self.events, &mut self.scene_events));
        }
        true
    }

    /// The next thing the scene check asks of the scene's owner, and the connection.
    pub fn poll_scene_event(&mut self) -> Option<(ConnId, SceneEvent)> {
        self.scene_events.pop_front()
    }

    /// When [`Peer::handle_timeout`] should next be called.
    pub fn poll_timeout(&self) -> Option<Timestamp> {
        self.connections
            .values()
            .filter_map(|s| s.poll_timeout(&self.log))
            .chain(self.want_due())
            .chain(self.log.next_due().filter(|_| !self.connections.is_empty()))
            .min()
    }
}

/// Moves `sync`'s events to the peer's queues: the scene check's to the scene's owner
/// (within [`MAX_QUEUED_SCENE_EVENTS`]), the rest to the transport.
fn drain<P: Payload>(conn: ConnId, sync: &mut SyncState<P>, queues: Queues<'_>) {
    let (events, scene_events) = queues;
    while let Some(event) = sync.poll_event() {
        match event {
            Event::Scene(scene) if scene_events.len() < MAX_QUEUED_SCENE_EVENTS => {
                scene_events.push_back((conn, scene));
            }
            Event::Scene(_) => {}
            event => events.push_back((conn, event)),
        }
    }
}

/// A peer's two event queues: the transport's and the scene owner's.
type Queues<'a> = (
    &'a mut VecDeque<(ConnId, Event)>,
    &'a mut VecDeque<(ConnId, SceneEvent)>,
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::materialize::test_scene::TestScene;
    use crate::payload::test_payload::TestPayload;
    use crate::payload::{LeaseAction, ObjectId};
    use crate::sync::message::Message;
    use crate::sync::state::{
        CloseReason, EXPEL_NOTICE_MICROS, HAVE_EVERY_MICROS, MIN_RESEND_AFTER_MICROS,
        PING_FOR_MICROS,
    };

    type TPeer = Peer<TestPayload>;

    /// Delivers every queued message at once, in order, until nothing moves; returns the
    /// events drained on the way, with the index of the peer that had each.
    fn pump(
        peers: &mut [TPeer],
        links: &[(usize, ConnId, usize, ConnId)],
        now: Timestamp,
    ) -> Vec<(usize, Event)> {
        let mut route = BTreeMap::new();
        for &(a, a_conn, b, b_conn) in links {
            route.insert((a, a_conn), (b, b_conn));
            route.insert((b, b_conn), (a, a_conn));
        }
        let mut events = Vec::new();
        for _ in 0..1000 {
            let mut moved = false;
            for from in 0..peers.len() {
                while let Some((conn, bytes)) = peers[from].poll_transmit(now) {
                    let (to, to_conn) = route[&(from, conn)];
                    peers[to].handle_input(now, to_conn, &bytes);
                    moved = true;
                }
            }
            for (i, p) in peers.iter_mut().enumerate() {
                events.extend(std::iter::from_fn(|| p.poll_event()).map(|(_, e)| (i, e)));
            }
            if !moved {
                return events;
            }
        }
        panic!("the sync did not quiesce");
    }

    /// Advances time in 100 ms steps from `t` (timeouts, then delivery) until `done`; returns
    /// the time then. It must come within ten relay delays.
    fn settle(
        peers: &mut [TPeer],
        links: &[(usize, ConnId, usize, ConnId)],
        mut t: u64,
        done: impl Fn(&[TPeer]) -> bool,
    ) -> u64 {
        let start = t;
        while !done(peers) {
            assert!(t < start + 10 * RELAY_AFTER_MICROS, "not relayed by {t}");
            t += 100_000;
            for p in peers.iter_mut() {
                p.handle_timeout(Timestamp(t));
            }
            pump(peers, links, Timestamp(t));
        }
        t
    }

    fn observe(p: &TPeer) -> Vec<(crate::identity::OpId, crate::lease::Mark, bool)> {
        p.log()
            .entries()
            .map(|e| (e.op.id(), e.mark, e.active))
            .collect()
    }

    #[test]
    fn ops_and_lease_verdicts_relay_along_a_line() {
        let session = [3; 16];
        let mut peers: Vec<TPeer> = (1..=3)
            .map(|i| Peer::new(Keypair::from_seed([i; 32]), session, Log::default()))
            .collect();
        // Offline: each peer edits object 1 (which makes it, as far as it knows) and takes it.
        let now = Timestamp(1_000);
        for (i, p) in peers.iter_mut().enumerate() {
            let object = 1;
            p.author(
                now,
                TestPayload::Set {
                    object,
                    value: format!("peer {i}"),
                },
            )
            .unwrap();
            p.author(
                now,
                TestPayload::Lease(LeaseAction::Acquire {
                    object,
                    strong: false,
                    ttl_micros: 10_000_000,
                }),
            )
            .unwrap();
        }
        // A - B - C: A and C never talk directly.
        let links = [(0, ConnId(1), 1, ConnId(1)), (1, ConnId(2), 2, ConnId(1))];
        peers[0].connect(now, ConnId(1)).unwrap();
        peers[1].connect(now, ConnId(1)).unwrap();
        peers[1].connect(now, ConnId(2)).unwrap();
        peers[2].connect(now, ConnId(1)).unwrap();
        assert_eq!(
            peers[1].connect(now, ConnId(2)),
            Err(ConnectError::InUse(ConnId(2)))
        );
        pump(&mut peers, &links, now);
        // A and C hear each other's offline ops through B as soon as they ask: B's haves show
        // them, and their author is not connected to them.
        assert_eq!(peers[0].log().len(), 4);
        let t = settle(&mut peers, &links, now.0, |p| {
            p.iter().all(|p| p.log().len() == 6)
        });
        assert!(t <= now.0 + 2 * HAVE_EVERY_MICROS, "relayed late at {t}");
        assert_eq!(peers[0].log().len(), 6);
        assert_eq!(observe(&peers[0]), observe(&peers[1]));
        assert_eq!(observe(&peers[0]), observe(&peers[2]));
        // No peer saw another's lease when it edited: every offline edit stands everywhere.
        let n_active_sets = peers[0]
            .log()
            .entries()
            .filter(|e| matches!(e.op.payload(), TestPayload::Set { .. }) && e.active)
            .count();
        assert_eq!(n_active_sets, 3);
        let n_rejected: usize = peers
            .iter()
            .map(|p| peers[0].log().rejected_by(&p.peer_id()).len())
            .sum();
        assert_eq!(n_rejected, 0);
        // Live: a new op by C reaches A through B.
        let t0 = t;
        let (live, _) = peers[2]
            .author(Timestamp(t0), TestPayload::Chat("hello".into()))
            .unwrap();
        pump(&mut peers, &links, Timestamp(t0));
        assert!(!peers[0].log().contains(&live.id()));
        let t = settle(&mut peers, &links, t0, |p| p[0].log().contains(&live.id()));
        assert!(t <= t0 + 2 * HAVE_EVERY_MICROS, "relayed late at {t}");
        // Ephemeral values go to every connection and are not stored.
        peers[1].send_ephemeral(4, b"pose").unwrap();
        let mut n_ephemeral = 0;
        while let Some((conn, bytes)) = peers[1].poll_transmit(Timestamp(t)) {
            let to = if conn == ConnId(1) { 0 } else { 2 };
            peers[to].handle_input(Timestamp(t), ConnId(1), &bytes);
            while let Some((_, e)) = peers[to].poll_event() {
                n_ephemeral += usize::from(matches!(e, Event::Ephemeral { channel: 4, .. }));
            }
        }
        assert_eq!(n_ephemeral, 2);
        assert_eq!(peers[0].log().len(), 7);
    }

    /// A link: peer, its connection id, the other peer, its connection id.
    type Link = (usize, ConnId, usize, ConnId);

    /// One tick on links that deliver at once: every timer, then every message sent but those
    /// `lose(from, to, bytes)` picks.
    fn tick_losing(
        peers: &mut [TPeer],
        links: &[Link],
        now: Timestamp,
        mut lose: impl FnMut(usize, usize, &[u8]) -> bool,
    ) {
        for p in peers.iter_mut() {
            p.handle_timeout(now);
        }
        for from in 0..peers.len() {
            while let Some((conn, bytes)) = peers[from].poll_transmit(now) {
                let (a, a_conn, b, b_conn) = (links.iter())
                    .copied()
                    .find(|&(a, ac, b, bc)| (a, ac) == (from, conn) || (b, bc) == (from, conn))
                    .unwrap();
                let (to, to_conn) = if (a, a_conn) == (from, conn) {
                    (b, b_conn)
                } else {
                    (a, a_conn)
                };
                if !lose(from, to, &bytes) {
                    peers[to].handle_input(now, to_conn, &bytes);
                }
            }
        }
    }

    /// Every pair of `n` peers connected; peer `i` reaches peer `j` on `ConnId(j)`.
    fn full_mesh(n: u8, now: Timestamp) -> (Vec<TPeer>, Vec<Link>) {
        let mut peers: Vec<TPeer> = (1..=n)
            .map(|i| Peer::new(Keypair::from_seed([i; 32]), [5; 16], Log::default()))
            .collect();
        let mut links = Vec::new();
        for a in 0..peers.len() {
            for b in a + 1..peers.len() {
                peers[a].connect(now, ConnId(b as u64)).unwrap();
                peers[b].connect(now, ConnId(a as u64)).unwrap();
                links.push((a, ConnId(b as u64), b, ConnId(a as u64)));
            }
        }
        (peers, links)
    }

    fn n_ops_sent(peers: &[TPeer]) -> u64 {
        peers
            .iter()
            .flat_map(|p| p.connections().map(|(_, s)| s.stats().n_ops_out))
            .sum()
    }

    /// Two peers that worked apart, each four times past the pending buffer, converge within
    /// two seconds of ticks (half a second now). Each other's ops land among one's own, so the refold budget holds the
    /// first of them and the rest wait behind it; meanwhile the sender streams on and sends
    /// again what was dropped. When the buffer dropped its newest op, the backlog's far end
    /// held it and every op that could be delivered was dropped on arrival: one side crawled
    /// at about 13 ops a second. An op the full buffer would drop at once is now skipped before
    /// its signature is checked, and a drop is no offence (a node cut such a remote off).
    #[test]
    fn concurrent_backlogs_past_the_pending_buffer_converge() {
        let n = 4 * crate::pending::MAX_PENDING_OPS;
        let mut peers: Vec<TPeer> = (1..=2)
            .map(|i| Peer::new(Keypair::from_seed([i; 32]), [5; 16], Log::default()))
            .collect();
        for (seed, p) in (1..).zip(peers.iter_mut()) {
            for k in 0..n {
                let payload = TestPayload::backlog(seed, k);
                p.author(Timestamp(k as u64 * 50), payload).unwrap();
            }
        }
        let start = n as u64 * 50;
        // One dials, the other accepts, as over the network.
        peers[0].connect(Timestamp(start), ConnId(1)).unwrap();
        peers[1].accept(Timestamp(start), ConnId(0), 7).unwrap();
        let links = [(0, ConnId(1), 1, ConnId(0))];
        let mut t = start;
        while peers.iter().any(|p| p.log().len() < 2 * n) {
            assert!(
                t < start + 2_000_000,
                "not converged after two seconds: {} and {} of {} ops",
                peers[0].log().len(),
                peers[1].log().len(),
                2 * n
            );
            tick_losing(&mut peers, &links, Timestamp(t), |_, _, _| false);
            for p in peers.iter_mut() {
                while let Some((_, event)) = p.poll_event() {
                    assert!(!matches!(event, Event::Rejected { .. }), "{event:?}");
                }
            }
            t += 1_000;
        }
        assert_eq!(
            peers[0].log().version_vector(),
            peers[1].log().version_vector()
        );
        // Most of what the buffer could not keep was dropped before its signature was checked.
        for p in &peers {
            let (_, sync) = p.connections().next().unwrap();
            let (unread, evicted) = (sync.stats().n_ops_unread, p.log().stats().n_evicted);
            assert!(
                unread > evicted,
                "{unread} dropped unread, {evicted} after a check"
            );
            // Drops are no offence, and raise no event.
            let stats = sync.stats();
            assert_eq!(stats.n_rejected(), unread + evicted, "{:?}", stats.rejected);
            assert_eq!(stats.n_offences(), 0);
        }
    }

    #[test]
    fn a_full_mesh_sends_each_op_over_each_link_once() {
        let (mut peers, links) = full_mesh(5, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        let mut t = 0;
        for round in 0..6 {
            for p in peers.iter_mut() {
                for k in 0..3 {
                    p.author(Timestamp(t), TestPayload::Chat(format!("{round} {k}")))
                        .unwrap();
                }
            }
            // Three relay delays of ticks: every relay snapshot matures meanwhile.
            for _ in 0..3 * RELAY_AFTER_MICROS / 100_000 {
                t += 100_000;
                for p in peers.iter_mut() {
                    p.handle_timeout(Timestamp(t));
                }
                pump(&mut peers, &links, Timestamp(t));
            }
        }
        let n_ops = 5 * 6 * 3;
        assert!(peers.iter().all(|p| p.log().len() == n_ops));
        // Authors reach everyone directly and haves arrive before relays mature, so nobody
        // relays: each op went over each of the 4 links from its author once.
        assert_eq!(n_ops_sent(&peers), n_ops as u64 * 4);
    }

    #[test]
    fn a_silent_remote_gets_a_backed_off_trickle_and_a_prompt_resend_when_it_speaks() {
        let (mut peers, links) = full_mesh(2, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        peers[0]
            .author(Timestamp(0), TestPayload::Chat("into the void".into()))
            .unwrap();
        // Peer 1 hears nothing and says nothing for two minutes.
        let (mut n_sent, mut n_pings) = (0, 0);
        let mut t = 0;
        while t < 120_000_000 {
            t += 100_000;
            peers[0].handle_timeout(Timestamp(t));
            while let Some((_, bytes)) = peers[0].poll_transmit(Timestamp(t)) {
                match Message::decode(&bytes) {
                    Ok(Message::Ping) => n_pings += 1,
                    _ => n_sent += 1,
                }
            }
        }
        // One send, then resends after 1.75 round trips of the hello (here the floor of
        // 100 ms), doubling to 32 s: 0.1 to 25.6 s, then twice 32 s; plus one have, and one
        // repeat of the have with a hello (the remote lacks the op; it is not repeated again
        // until the remote speaks).
        assert!(n_sent <= 16, "{n_sent} messages to a silent remote");
        assert!(n_sent >= 10, "{n_sent}: no resends");
        // And pings of a few bytes on the base interval (the floor), for the first
        // `PING_FOR_MICROS` of silence only.
        let most = PING_FOR_MICROS / MIN_RESEND_AFTER_MICROS;
        assert!((most / 2..=most).contains(&n_pings), "{n_pings} pings");
        assert_eq!(peers[1].log().len(), 0);
        // Peer 1 speaks (its periodic have after authoring): peer 0 resends within the base
        // interval, not after the backed-off 32 s.
        peers[1]
            .author(Timestamp(t), TestPayload::Chat("back".into()))
            .unwrap();
        let start = t;
        let done = settle(&mut peers, &links, t, |p| p[1].log().len() == 2);
        assert!(done - start <= 2 * RESEND_AFTER_MICROS, "{}", done - start);
    }

    #[test]
    fn a_holder_that_sends_nothing_is_asked_again_while_ops_come_from_elsewhere() {
        // A, B and D in a full mesh on links that deliver at once; everything A sends D is
        // lost, so D asks B for A's ops, and its wants to B are lost too. Meanwhile A's ops
        // reach D one by one from elsewhere (a store, say). Growth that B did not send used to
        // count as B delivering and restart B's time, so D waited on a want that never
        // arrived for as long as ops trickled in; now D asks again after B's timeout.
        let (mut peers, links) = full_mesh(3, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        let ops: Vec<_> = (0..16)
            .map(|k| {
                (peers[0].author(Timestamp(0), TestPayload::Chat(format!("A {k}"))))
                    .unwrap()
                    .0
            })
            .collect();
        let author = ops[0].author();
        let lost = |from: usize, to: usize, bytes: &[u8]| {
            (from, to) == (0, 2)
                || ((from, to) == (2, 1)
                    && matches!(Message::decode(bytes), Ok(Message::Want { .. })))
        };
        let mut t = 0;
        let asked_at = loop {
            assert!(t < 3 * HAVE_EVERY_MICROS, "D never asked B");
            t += 10_000;
            tick_losing(&mut peers, &links, Timestamp(t), lost);
            if let Some(asked) = peers[2].wants.get(&author).and_then(|w| w.asked) {
                break asked.at.0;
            }
        };
        let mut next = 0;
        while peers[2].wants[&author].n_asked < 2 {
            assert!(
                t < asked_at + MIN_RESEND_AFTER_MICROS + 3 * WANT_CHECK_MICROS,
                "D still waits on B at {t} (asked at {asked_at})"
            );
            t += 10_000;
            if t % 50_000 == 0 && next < ops.len() - 1 {
                (peers[2].log)
                    .insert(Timestamp(t), ops[next].clone(), crate::log::LOCAL_ORIGIN)
                    .unwrap();
                next += 1;
            }
            tick_losing(&mut peers, &links, Timestamp(t), lost);
        }
    }

    #[test]
    fn a_want_that_brought_nothing_is_made_again_of_two_holders_at_once() {
        // A, B, C and D in a full mesh on links that deliver at once, so every timeout is the
        // shortest. Everything A sends D is lost, so D asks B or C for A's ops, and the first
        // two wants D sends are lost. Asking one holder at a time, D's retry was lost too and
        // D waited out a second timeout; now the retry goes to two holders, and one of them
        // answers.
        let (mut peers, links) = full_mesh(4, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        for k in 0..4 {
            (peers[0].author(Timestamp(0), TestPayload::Chat(format!("A {k}")))).unwrap();
        }
        let wants = std::cell::RefCell::new(Vec::new());
        let mut t = 0;
        while peers[3].log().len() < 4 {
            assert!(t < 3 * HAVE_EVERY_MICROS, "D never got A's ops");
            t += 10_000;
            tick_losing(&mut peers, &links, Timestamp(t), |from, to, bytes| {
                let want = from == 3 && matches!(Message::decode(bytes), Ok(Message::Want { .. }));
                if want {
                    wants.borrow_mut().push((t, to));
                }
                from == 0 && to == 3 || want && wants.borrow().len() <= 2
            });
        }
        let wants = wants.into_inner();
        let (first, _) = wants[0];
        // One holder asked first; both others at the retry, at the same time.
        assert_eq!(
            wants.iter().filter(|w| w.0 == first).count(),
            1,
            "{wants:?}"
        );
        let retry: Vec<_> = wants.iter().filter(|w| w.0 == wants[1].0).collect();
        assert_eq!(retry.len(), 2, "{wants:?}");
        assert_ne!(retry[0].1, retry[1].1, "{wants:?}");
        // So the ops came one timeout after the first ask, not two.
        let timeout = MIN_RESEND_AFTER_MICROS + WANT_CHECK_MICROS;
        assert!(
            t <= first + timeout,
            "D got A's ops at {t}, asked at {first}: {wants:?}"
        );
    }

    #[test]
    fn a_have_showing_what_a_peer_lacks_is_answered_within_the_coalescing_delay() {
        // A, B and C in a full mesh on links that deliver at once, ticked every millisecond.
        // Everything A sends C is lost, so C learns of A's op from B's have, which the test
        // holds back and hands C 20 ms after some other message (a ping) made C check its
        // wants. C's want must follow the have within WANT_COALESCE_MICROS; it used to wait
        // for the next periodic check, WANT_CHECK_MICROS after the ping's.
        let (mut peers, links) = full_mesh(3, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        let c_to_b = ConnId(1);
        let mut t = 1_000_000;
        let (op, _) = (peers[0].author(Timestamp(t), TestPayload::Chat("A".into()))).unwrap();
        let held = std::cell::RefCell::new(None);
        while held.borrow().is_none() {
            assert!(t < 3 * HAVE_EVERY_MICROS, "B never told C");
            t += 1_000;
            tick_losing(&mut peers, &links, Timestamp(t), |from, to, bytes| {
                let have = matches!(Message::decode(bytes), Ok(Message::Have { .. }));
                if (from, to) == (1, 2) && have {
                    held.borrow_mut().get_or_insert(bytes.to_vec());
                    return true;
                }
                (from, to) == (0, 2)
            });
        }
        t += 1_000;
        peers[2].handle_input(Timestamp(t), c_to_b, &Message::Ping.encode());
        tick_losing(&mut peers, &links, Timestamp(t), |from, to, _| {
            (from, to) == (0, 2)
        });
        t += 20_000;
        let told = t;
        peers[2].handle_input(Timestamp(t), c_to_b, &held.into_inner().unwrap());
        let mut asked = None;
        while !peers[2].log().contains(&op.id()) {
            assert!(t < told + HAVE_EVERY_MICROS, "C never got A's op");
            tick_losing(&mut peers, &links, Timestamp(t), |from, to, bytes| {
                let want = matches!(Message::decode(bytes), Ok(Message::Want { .. }));
                if (from, to) == (2, 1) && want {
                    asked.get_or_insert(t);
                }
                (from, to) == (0, 2)
            });
            t += 1_000;
        }
        let asked = asked.expect("C asked B");
        assert!(
            asked - told <= WANT_COALESCE_MICROS,
            "told at {told}, asked at {asked}"
        );
    }

    #[test]
    fn a_lost_op_is_relayed_after_the_measured_timeout_not_the_fixed_one() {
        // A, B and C in a full mesh on a link that delivers at once: every connection
        // measures a round trip of 0 and so the shortest resend timeout. Everything A sends C
        // is lost; B's next have tells C that B holds A's op. C asks B after its connection to
        // A's resend timeout (100 ms), not after RELAY_AFTER_MICROS (500 ms).
        let (mut peers, links) = full_mesh(3, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        let timeouts: Vec<Option<u64>> = (peers[2].connections())
            .map(|(_, s)| s.resend_timeout())
            .collect();
        assert_eq!(timeouts, [Some(MIN_RESEND_AFTER_MICROS); 2]);
        let (op, _) = peers[0]
            .author(Timestamp(0), TestPayload::Chat("to C by way of B".into()))
            .unwrap();
        let mut t = 0;
        let mut learnt_at = None;
        while !peers[2].log().contains(&op.id()) {
            assert!(t < 3 * HAVE_EVERY_MICROS, "never relayed");
            t += 10_000;
            tick_losing(&mut peers, &links, Timestamp(t), |from, to, _| {
                (from, to) == (0, 2)
            });
            if learnt_at.is_none() && !peers[2].wants.is_empty() {
                learnt_at = Some(t);
            }
        }
        let learnt_at = learnt_at.expect("C asked for the op");
        assert!(
            t - learnt_at <= MIN_RESEND_AFTER_MICROS + 2 * WANT_CHECK_MICROS,
            "C learnt of the op at {learnt_at} and got it at {t}"
        );
    }

    #[test]
    fn an_author_whose_batches_were_lost_delivers_them_and_nobody_relays() {
        // A, B and C in a full mesh on a link that delivers at once. A's first five batches
        // to B are lost, so A's resends back off. B gets the op from A, not C, which also
        // holds it and delivered B more (before, B waited A's timeout and then asked C, who
        // relayed it).
        let (mut peers, links) = full_mesh(3, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        // C has delivered B more than A, which ranks it first among third peers.
        for k in 0..3 {
            peers[2]
                .author(Timestamp(0), TestPayload::Chat(format!("C {k}")))
                .unwrap();
        }
        pump(&mut peers, &links, Timestamp(0));
        let sent_by_c = |peers: &[TPeer]| -> u64 {
            (peers[2].connections())
                .map(|(_, s)| s.stats().n_ops_out)
                .sum()
        };
        let before = sent_by_c(&peers);
        let (op, _) = peers[0]
            .author(Timestamp(0), TestPayload::Chat("to B, late".into()))
            .unwrap();
        let (mut t, mut n_lost) = (0, 0);
        let mut learnt_at = None;
        while !peers[1].log().contains(&op.id()) {
            assert!(t < 10 * HAVE_EVERY_MICROS, "B never got the op");
            t += 10_000;
            tick_losing(&mut peers, &links, Timestamp(t), |from, to, bytes| {
                let batch = matches!(Message::decode(bytes), Ok(Message::Ops { .. }));
                let lose = (from, to) == (0, 1) && batch && n_lost < 5;
                n_lost += usize::from(lose);
                lose
            });
            if learnt_at.is_none() && peers[1].wants.contains_key(&op.author()) {
                learnt_at = Some(t);
            }
        }
        // If B asked, the answer came at once. Here it need not ask: A pings the silent B, B
        // answers each ping (with a have, then pongs), and every answer makes A send again
        // at once, so the op arrives before A's next have could tell B of it.
        if let Some(learnt_at) = learnt_at {
            assert!(
                t - learnt_at <= 2 * WANT_CHECK_MICROS,
                "B learnt of the op at {learnt_at} and got it at {t}"
            );
        }
        assert!(t < HAVE_EVERY_MICROS, "B got the op at {t}");
        assert_eq!(sent_by_c(&peers), before, "C relayed what A could send");
    }

    #[test]
    fn a_third_peers_op_reaches_a_remote_whose_haves_were_all_lost() {
        // A and B are connected; A gets an op of C's that B can only get from A. Every have A
        // sends B for 15 s is lost, and then A's log does not grow again: A repeats its full
        // have while B is known to lack the op, so B asks for it and gets it.
        let (mut peers, links) = full_mesh(2, Timestamp(0));
        pump(&mut peers, &links, Timestamp(0));
        let carol = ConnId(7);
        peers[0].connect(Timestamp(0), carol).unwrap();
        let c = Keypair::from_seed([3; 32]);
        peers[0].handle_input(Timestamp(0), carol, &hello_from(c.peer_id(), [5; 16]));
        let chat = TestPayload::Chat("hi".into());
        let op = crate::log::tests::signed_in(&[5; 16], &c, (1, 1, 0), vec![], chat);
        let batch = Message::Ops {
            batch_no: 0,
            ops: vec![op.encoded().to_vec()],
        };
        peers[0].handle_input(Timestamp(0), carol, &batch.encode());
        peers[0].disconnect(carol);
        assert!(peers[0].log().contains(&op.id()));
        let mut t = 0;
        while t < 60_000_000 && !peers[1].log().contains(&op.id()) {
            t += 100_000;
            let now = Timestamp(t);
            for p in peers.iter_mut() {
                p.handle_timeout(now);
            }
            if t < 15_000_000 {
                while peers[0].poll_transmit(now).is_some() {}
            }
            pump(&mut peers, &links, now);
        }
        assert!(peers[1].log().contains(&op.id()), "B never got the op");
        assert!(t <= 35_000_000, "got it at {t} µs");
    }

    use crate::causal::MAX_VV_AUTHORS;
    use crate::sync::message::{MAX_MESSAGE_BYTES, PROTOCOL_VERSION};
    use crate::sync::state::tests::log_of_many_authors;
    use crate::sync::state::{CLAIM_WITHDRAWN_MICROS, MAX_REMOTE_UNKNOWN_AUTHORS};

    fn hello_from(peer: PeerId, session_id: SessionId) -> Vec<u8> {
        Message::Hello {
            protocol_version: PROTOCOL_VERSION,
            session_id,
            peer,
            hello_seen: true,
            have: None,
        }
        .encode()
    }

    /// Everything `peer` sends at `now`, each message checked against the wire limits.
    fn transmit_checked(peer: &mut TPeer, now: Timestamp) -> Vec<Message> {
        let mut out = Vec::new();
        while let Some((_, bytes)) = peer.poll_transmit(now) {
            assert!(bytes.len() <= MAX_MESSAGE_BYTES, "{} bytes", bytes.len());
            out.push(Message::decode(&bytes).unwrap());
        }
        while peer.poll_event().is_some() {}
        out
    }

    /// `vv` as haves of at most `chunk` authors each.
    fn haves(vv: &VersionVector, chunk: usize) -> Vec<Vec<u8>> {
        let entries: Vec<(PeerId, u64)> = vv.iter().map(|(a, s)| (*a, *s)).collect();
        entries
            .chunks(chunk)
            .map(|c| {
                let mut part = VersionVector::new();
                for (a, s) in c {
                    part.raise(*a, *s);
                }
                Message::have(part).encode()
            })
            .collect()
    }

    /// A have of [`MAX_VV_AUTHORS`] made-up authors, their ids starting with `round`.
    fn made_up_have(round: u8) -> Vec<u8> {
        let mut vv = VersionVector::new();
        for i in 0..MAX_VV_AUTHORS as u32 {
            let mut id = [round; 32];
            id[..4].copy_from_slice(&i.to_be_bytes());
            vv.raise(PeerId(id), 1);
        }
        Message::have(vv).encode()
    }

    /// What `peer`'s first connection knows its remote to hold.
    fn claims(peer: &TPeer) -> &VersionVector {
        peer.connections().next().unwrap().1.remote_version_vector()
    }

    /// Issue 17: two haves of 4,096 made-up authors each, then a timeout, panicked the peer
    /// (one want named all 8,192 and tripped the outgoing-size assertion).
    #[test]
    fn haves_of_thousands_of_made_up_authors_cost_bounded_memory_and_no_panic() {
        let session = [5; 16];
        let mut a = TPeer::new(Keypair::from_seed([1; 32]), session, Log::default());
        a.connect(Timestamp(0), ConnId(1)).unwrap();
        let mallory = Keypair::from_seed([9; 32]).peer_id();
        a.handle_input(Timestamp(0), ConnId(1), &hello_from(mallory, session));
        for round in 0..2u8 {
            a.handle_input(Timestamp(1), ConnId(1), &made_up_have(round));
        }
        a.handle_timeout(Timestamp(2));
        let mut n_wanted = 0;
        for message in transmit_checked(&mut a, Timestamp(2)) {
            if let Message::Want { vv, .. } = message {
                n_wanted += vv.len();
            }
        }
        // What the connection keeps of the claims is bounded; the rest is counted.
        let (_, sync) = a.connections().next().unwrap();
        assert_eq!(
            sync.remote_version_vector().len(),
            MAX_REMOTE_UNKNOWN_AUTHORS
        );
        assert_eq!(
            sync.stats().n_claims_dropped,
            (2 * MAX_VV_AUTHORS - MAX_REMOTE_UNKNOWN_AUTHORS) as u64
        );
        assert_eq!(n_wanted, MAX_REMOTE_UNKNOWN_AUTHORS);
        assert!(a.wants.len() <= MAX_REMOTE_UNKNOWN_AUTHORS);
        // Nothing arrives: until the claims are withdrawn, the peer does not ask the remote
        // for its full have again, and more strangers are still dropped.
        let mut vv = VersionVector::new();
        vv.raise(PeerId([7; 32]), 1);
        for t in 1..=2 {
            a.handle_timeout(Timestamp(t * RELAY_AFTER_MICROS));
            let messages = transmit_checked(&mut a, Timestamp(t * RELAY_AFTER_MICROS));
            assert!(
                !messages.iter().any(|m| matches!(m, Message::Hello { .. })),
                "{messages:?}"
            );
        }
        // The remote answers, with anything but ops, after the last ask.
        let answered = Timestamp(2 * RELAY_AFTER_MICROS + 1);
        a.handle_input(answered, ConnId(1), &Message::have(vv.clone()).encode());
        let (_, sync) = a.connections().next().unwrap();
        assert_eq!(
            sync.remote_version_vector().len(),
            MAX_REMOTE_UNKNOWN_AUTHORS
        );
        // A retry period after the ask, every claim the remote did not make good is withdrawn:
        // nothing is left to scan or ask for on its account.
        let later = Timestamp(answered.0 + WANT_RETRY_MICROS + WANT_CHECK_MICROS);
        a.handle_timeout(later);
        transmit_checked(&mut a, later);
        a.handle_timeout(Timestamp(later.0 + WANT_CHECK_MICROS));
        let (_, sync) = a.connections().next().unwrap();
        assert!(sync.remote_version_vector().is_empty());
        assert_eq!(
            sync.stats().n_claims_withdrawn,
            MAX_REMOTE_UNKNOWN_AUTHORS as u64
        );
        assert!(a.wants.is_empty(), "{}", a.wants.len());
        // The same claims sent again are not learnt again for a while; a claim to more of a
        // withdrawn author is, and so are new ones.
        let now = Timestamp(later.0 + 2 * WANT_CHECK_MICROS);
        a.handle_input(now, ConnId(1), &made_up_have(0));
        assert!(claims(&a).is_empty());
        let mut more = VersionVector::new();
        more.raise(PeerId([0; 32]), 2);
        a.handle_input(now, ConnId(1), &Message::have(more).encode());
        a.handle_input(now, ConnId(1), &made_up_have(1));
        let (_, sync) = a.connections().next().unwrap();
        assert_eq!(sync.remote_version_vector().get(&PeerId([0; 32])), 2);
        assert_eq!(
            sync.remote_version_vector().len(),
            MAX_REMOTE_UNKNOWN_AUTHORS
        );
        // Those are asked for and withdrawn in turn. Then the first claims, whose withdrawal
        // has lapsed, are learnt again, but for the one withdrawn since.
        let asked = Timestamp(later.0 + CLAIM_WITHDRAWN_MICROS + WANT_CHECK_MICROS);
        a.handle_timeout(asked);
        transmit_checked(&mut a, asked);
        // A remote that sends nothing at all (a partition, a dead link) keeps its claims and is
        // only waited for; one that answers with anything but ops loses them.
        let silent = Timestamp(asked.0 + WANT_RETRY_MICROS + WANT_CHECK_MICROS);
        a.handle_timeout(silent);
        transmit_checked(&mut a, silent);
        assert_eq!(claims(&a).len(), MAX_REMOTE_UNKNOWN_AUTHORS);
        a.handle_input(silent, ConnId(1), &Message::have(vv.clone()).encode());
        let silent = Timestamp(silent.0 + WANT_RETRY_MICROS + WANT_CHECK_MICROS);
        a.handle_timeout(silent);
        assert!(claims(&a).is_empty());
        a.handle_input(silent, ConnId(1), &made_up_have(0));
        let (_, sync) = a.connections().next().unwrap();
        assert_eq!(sync.remote_version_vector().get(&PeerId([0; 32])), 0);
        assert_eq!(
            sync.remote_version_vector().len(),
            MAX_REMOTE_UNKNOWN_AUTHORS - 1
        );
    }

    /// Issue 17: a peer lacking more authors' ops than one want can name sent them in one
    /// want, over the message size limit. Its wants are now split.
    #[test]
    fn wants_for_more_authors_than_one_message_names_are_split() {
        let session = [5; 16];
        let log = log_of_many_authors(8_000);
        let mut claims = VersionVector::new();
        for (author, seq) in log.version_vector().iter() {
            claims.raise(*author, seq + 1);
        }
        let mut a = TPeer::new(Keypair::from_seed([1; 32]), session, log);
        a.connect(Timestamp(0), ConnId(1)).unwrap();
        let remote = Keypair::from_seed([9; 32]).peer_id();
        a.handle_input(Timestamp(0), ConnId(1), &hello_from(remote, session));
        for have in haves(&claims, 4_000) {
            a.handle_input(Timestamp(1), ConnId(1), &have);
        }
        a.handle_timeout(Timestamp(2));
        let mut wanted = VersionVector::new();
        let mut n_wants = 0;
        for message in transmit_checked(&mut a, Timestamp(2)) {
            if let Message::Want { vv, .. } = message {
                wanted.join(&vv);
                n_wants += 1;
            }
        }
        assert_eq!(wanted, claims);
        assert!(n_wants >= 2, "{n_wants} wants");
    }

    /// Issue 17: a peer joins a peer whose log names more authors than one version-vector
    /// message can, and gets all of it.
    #[test]
    fn a_peer_syncs_fully_with_a_log_of_more_authors_than_a_message_names() {
        // The log's ops were signed without a session named.
        let session = crate::op::UNNAMED_SESSION;
        let mut peers = vec![
            TPeer::new(
                Keypair::from_seed([1; 32]),
                session,
                log_of_many_authors(5_000),
            ),
            TPeer::new(Keypair::from_seed([2; 32]), session, Log::default()),
        ];
        let links = [(0, ConnId(1), 1, ConnId(1))];
        for p in peers.iter_mut() {
            p.connect(Timestamp(0), ConnId(1)).unwrap();
        }
        pump(&mut peers, &links, Timestamp(0));
        let mut t = 0;
        while peers[1].log().version_vector() != peers[0].log().version_vector() {
            assert!(
                t < 30_000_000,
                "not synced by {t}: {} ops",
                peers[1].log().len()
            );
            t += 100_000;
            for p in peers.iter_mut() {
                p.handle_timeout(Timestamp(t));
            }
            pump(&mut peers, &links, Timestamp(t));
        }
        assert_eq!(observe(&peers[0]), observe(&peers[1]));
        // More strangers than a connection keeps: the joiner dropped some claims at first and
        // learnt them again after fetching the rest.
        let (_, sync) = peers[1].connections().next().unwrap();
        assert!(sync.stats().n_claims_dropped > 0);
        assert!(t <= 5_000_000, "synced at {t}");
    }

    /// Issue 17, item 6: a member sends a peer with a long history backdated edits, one per
    /// message, each making it refold the whole order and the edited object. The peer holds
    /// what its refold budget cannot pay for, delivers it together once it can, relays it, and
    /// converges with an honest peer.
    #[test]
    fn backdated_ops_held_for_the_refold_budget_are_delivered_together_and_converge() {
        let (mut peers, links) = full_mesh(2, Timestamp(0));
        for i in 0..3_000u64 {
            let value = format!("v{i}");
            peers[0]
                .author(Timestamp(i), TestPayload::Set { object: 1, value })
                .unwrap();
        }
        pump(&mut peers, &links, Timestamp(3_000));
        assert_eq!(peers[1].log().len(), 3_000);
        let now = Timestamp(1_000_000);
        let hostile = ConnId(9);
        peers[0].connect(now, hostile).unwrap();
        let mallory = Keypair::from_seed([9; 32]);
        peers[0].handle_input(now, hostile, &hello_from(mallory.peer_id(), [5; 16]));
        let backdated: Vec<_> = (0..200u8)
            .map(|i| {
                let mut seed = [100; 32];
                seed[1] = i;
                let key = Keypair::from_seed(seed);
                let set = TestPayload::Set {
                    object: 1,
                    value: format!("backdated {i}"),
                };
                crate::log::tests::signed_in(&[5; 16], &key, (1, 1, u64::from(i)), vec![], set)
            })
            .collect();
        for (i, op) in backdated.iter().enumerate() {
            let batch = Message::Ops {
                batch_no: i as u64,
                ops: vec![op.encoded().to_vec()],
            };
            peers[0].handle_input(now, hostile, &batch.encode());
        }
        let stats = peers[0].log().stats();
        assert!(stats.n_held_for_refold > 0, "{stats:?}");
        let held = peers[0].log().n_pending();
        assert!(held > 0);
        peers[0].disconnect(hostile);
        while peers[0].poll_transmit(now).is_some() {}
        let t = settle(&mut peers, &links, now.0, |p| {
            p.iter().all(|p| p.log().len() == 3_200)
        });
        assert!(t <= now.0 + 2_000_000, "delivered at {t}");
        assert_eq!(observe(&peers[0]), observe(&peers[1]));
        // The held ops were delivered at once: one refold more, not one per op.
        let refolded = peers[0].log().stats().n_refolded - stats.n_refolded;
        assert!(
            refolded <= 3_200,
            "{refolded} positions for {held} held ops"
        );
    }

    /// Sends everything `peer` has to send on connections of `sybils`, as nowhere.
    fn discard_sends(peer: &mut TPeer, now: Timestamp) -> Vec<(ConnId, Vec<u8>)> {
        std::iter::from_fn(|| peer.poll_transmit(now)).collect()
    }

    /// Issue 49: 64 slots shared by accepted and dialed connections, 8 accepted per address:
    /// remotes from 8 addresses held them all, and an honest accept or dial failed. A new
    /// connection now takes the slot of the least useful accepted one, from the most crowded
    /// source, so the honest ones get in and stay.
    #[test]
    fn sybils_from_eight_sources_holding_every_slot_lock_out_neither_accepts_nor_dials() {
        let now = Timestamp(1_000);
        let mut a = Peer::new(
            Keypair::from_seed([1; 32]),
            [5; 16],
            Log::<TestPayload>::default(),
        );
        let mut b = Peer::new(Keypair::from_seed([2; 32]), [5; 16], Log::default());
        b.author(now, TestPayload::Chat("honest".into())).unwrap();
        // 8 sources, 8 connections each: every slot.
        for idx in 0..MAX_CONNECTIONS as u64 {
            a.accept(now, ConnId(idx), idx / 8).unwrap();
            let sybil = Keypair::from_seed([100 + idx as u8; 32]).peer_id();
            let hello = Message::Hello {
                protocol_version: crate::sync::message::PROTOCOL_VERSION,
                session_id: [5; 16],
                peer: sybil,
                hello_seen: true,
                have: None,
            };
            a.handle_input(now, ConnId(idx), &hello.encode());
        }
        discard_sends(&mut a, now);
        while a.poll_event().is_some() {}
        // An honest remote dials in from a source of its own, and syncs.
        let honest = ConnId(1_000);
        a.accept(now, honest, 1_000).unwrap();
        b.connect(now, ConnId(1)).unwrap();
        let evicted: Vec<ConnId> = std::iter::from_fn(|| a.poll_event())
            .filter(|(_, e)| *e == Event::Closed(CloseReason::Evicted))
            .map(|(c, _)| c)
            .collect();
        assert_eq!(evicted.len(), 1, "{evicted:?}");
        assert!(evicted[0].0 < MAX_CONNECTIONS as u64);
        assert_eq!(a.connections().count(), MAX_CONNECTIONS);
        for _ in 0..10 {
            for (conn, bytes) in discard_sends(&mut a, now) {
                if conn == honest {
                    b.handle_input(now, ConnId(1), &bytes);
                }
            }
            while let Some((_, bytes)) = b.poll_transmit(now) {
                a.handle_input(now, honest, &bytes);
            }
        }
        assert_eq!(a.log().len(), 1, "the honest remote's op arrived");
        // A dial gets a slot too.
        a.connect(now, ConnId(2_000)).unwrap();
        assert_eq!(a.connections().count(), MAX_CONNECTIONS);
        // However many more Sybils dial in, from the crowded sources or new ones, the honest
        // remote and the dial keep their slots.
        for idx in 0..200 {
            let source = if idx % 2 == 0 { idx % 8 } else { 10_000 + idx };
            a.accept(Timestamp(2_000 + idx), ConnId(3_000 + idx), source)
                .unwrap();
        }
        assert!(a.connections().any(|(c, _)| *c == honest));
        assert!(a.connections().any(|(c, _)| *c == ConnId(2_000)));
        assert_eq!(a.connections().count(), MAX_CONNECTIONS);
        // With every slot dialed, nothing is evicted and the next is refused.
        let mut c = Peer::new(
            Keypair::from_seed([3; 32]),
            [5; 16],
            Log::<TestPayload>::default(),
        );
        for idx in 0..MAX_CONNECTIONS as u64 {
            c.connect(now, ConnId(idx)).unwrap();
        }
        assert_eq!(c.accept(now, ConnId(99), 1), Err(ConnectError::TooMany));
        assert_eq!(c.connect(now, ConnId(99)), Err(ConnectError::TooMany));
    }

    #[test]
    fn the_founder_expels_a_member_and_every_peer_closes_its_connections_to_it() {
        use crate::membership::{FounderCommitment, Membership};
        let nonce = [0xf0; 32];
        let founder = Keypair::from_seed([1; 32]).peer_id();
        let now = Timestamp(0);
        let mut peers: Vec<TPeer> = (1..=3u8)
            .map(|i| {
                let mut log = Log::default();
                log.set_founder(FounderCommitment::of(&founder, &nonce))
                    .unwrap();
                Peer::new(Keypair::from_seed([i; 32]), [5; 16], log)
            })
            .collect();
        let mut links = Vec::new();
        for a in 0..3 {
            for b in a + 1..3 {
                peers[a].connect(now, ConnId(b as u64)).unwrap();
                peers[b].connect(now, ConnId(a as u64)).unwrap();
                links.push((a, ConnId(b as u64), b, ConnId(a as u64)));
            }
        }
        let member = peers[2].peer_id();
        peers[2]
            .author(now, TestPayload::Chat("hello".into()))
            .unwrap();
        pump(&mut peers, &links, now);
        assert!(peers.iter().all(|p| p.log().len() == 1));
        let expel = TestPayload::Member(Membership {
            member,
            expel: true,
            nonce,
        });
        peers[0].author(Timestamp(1_000), expel).unwrap();
        let closed =
            |p: &TPeer, conn: u64| p.connections().any(|(c, s)| c.0 == conn && s.is_closed());
        assert!(!closed(&peers[0], 2), "the member is told first");
        // The expel reaches the member, whose own log now says it is out: it closes every
        // connection, saying so.
        let events = pump(&mut peers, &links, Timestamp(1_000));
        assert!(peers[2].log().is_expelled(&member));
        let told = Event::Closed(CloseReason::Expelled { peer: member });
        assert_eq!(
            events.iter().filter(|(i, e)| *i == 2 && *e == told).count(),
            2
        );
        // The others close theirs within the notice.
        let deadline = 1_000 + EXPEL_NOTICE_MICROS;
        let t = settle(&mut peers, &links, 1_000, |p| {
            closed(&p[0], 2) && closed(&p[1], 2)
        });
        assert!(t <= deadline + 100_000, "closed at {t}");
        assert!(!closed(&peers[1], 0), "and keeps its other connections");
        // What the expelled member writes now reaches nobody, and would count for nothing.
        peers[2]
            .author(Timestamp(t), TestPayload::Chat("still here".into()))
            .unwrap();
        let t = settle(&mut peers, &links, t, |_| true);
        pump(&mut peers, &links, Timestamp(t + HAVE_EVERY_MICROS));
        assert_eq!(peers[0].log().len(), 2);
        assert_eq!(peers[1].log().len(), 2);
        assert!(peers[0].log().is_expelled(&member));
        // A member who is not the founder cannot expel anyone with the same nonce.
        let forged = TestPayload::Member(Membership {
            member: peers[0].peer_id(),
            expel: true,
            nonce,
        });
        peers[1].author(Timestamp(t), forged).unwrap();
        assert!(!closed(&peers[1], 0) && !peers[1].log().is_expelled(&peers[0].peer_id()));
    }

    /// Issue 49: every peer that held the founder's expel closed its connections to the
    /// member at once, so the member, its own log never holding the expel, was never told and
    /// could show nothing. Each keeps the connection for the notice, sends the member what it
    /// lacks (the expel among it) and takes none of its ops; the member learns it even from
    /// a peer that only relays the founder's ops, and every connection to it closes by the
    /// deadline.
    #[test]
    fn an_expelled_member_is_told_before_its_connections_close() {
        use crate::membership::{FounderCommitment, Membership};
        let nonce = [0xf0; 32];
        let founder = Keypair::from_seed([1; 32]).peer_id();
        let mut peers: Vec<TPeer> = (1..=3u8)
            .map(|i| {
                let mut log = Log::default();
                log.set_founder(FounderCommitment::of(&founder, &nonce))
                    .unwrap();
                Peer::new(Keypair::from_seed([i; 32]), [5; 16], log)
            })
            .collect();
        // Founder - relay - member: the member hears the founder only through the relay.
        let links = [(0, ConnId(1), 1, ConnId(0)), (1, ConnId(2), 2, ConnId(1))];
        for (p, c) in [(0, 1), (1, 0), (1, 2), (2, 1)] {
            peers[p].connect(Timestamp(0), ConnId(c)).unwrap();
        }
        let member = peers[2].peer_id();
        peers[2]
            .author(Timestamp(0), TestPayload::Chat("hello".into()))
            .unwrap();
        let t = settle(&mut peers, &links, 0, |p| {
            p.iter().all(|p| p.log().len() == 1)
        });
        let expel = TestPayload::Member(Membership {
            member,
            expel: true,
            nonce,
        });
        peers[0].author(Timestamp(t), expel).unwrap();
        let mut now = t;
        let mut events = Vec::new();
        while !peers[2].log().is_expelled(&member) {
            assert!(now < t + EXPEL_NOTICE_MICROS, "the member was never told");
            now += 10_000;
            for p in peers.iter_mut() {
                p.handle_timeout(Timestamp(now));
            }
            events.extend(pump(&mut peers, &links, Timestamp(now)));
        }
        let told = Event::Closed(CloseReason::Expelled { peer: member });
        assert!(events.contains(&(2, told)), "{events:?}");
        // The relay closes by the deadline.
        let relayed = |p: &TPeer| {
            p.connections()
                .find(|(c, _)| c.0 == 2)
                .map(|(_, s)| s.is_closed())
        };
        while relayed(&peers[1]) == Some(false) {
            assert!(
                now <= t + EXPEL_NOTICE_MICROS + 20_000,
                "still open at {now}"
            );
            now += 10_000;
            peers[1].handle_timeout(Timestamp(now));
        }
        assert_eq!(peers[1].log().len(), 2);
    }

    #[test]
    fn a_fork_one_peer_sees_reaches_every_peer_holding_its_author() {
        // Two copies of one identity (a store copied to a second machine) each author seq 1;
        // a third peer hears both, the fourth knows neither copy.
        let session = [9; 16];
        let copy = || Keypair::from_seed([1; 32]);
        let mut peers: Vec<TPeer> = [copy(), copy(), Keypair::from_seed([3; 32])]
            .into_iter()
            .chain([Keypair::from_seed([4; 32])])
            .map(|k| Peer::new(k, session, Log::default()))
            .collect();
        let now = Timestamp(1_000);
        let twin = peers[0].peer_id();
        peers[0]
            .author(now, TestPayload::Chat("left".into()))
            .unwrap();
        peers[1]
            .author(now, TestPayload::Chat("right".into()))
            .unwrap();
        let links = [(0, ConnId(1), 2, ConnId(1)), (1, ConnId(1), 2, ConnId(2))];
        for (p, c) in [(0, 1), (1, 1), (2, 1), (2, 2)] {
            peers[p].connect(now, ConnId(c)).unwrap();
        }
        pump(&mut peers, &links, now);
        for p in &peers[..3] {
            assert_eq!(p.log().forks().seq_of(&twin), Some(1), "{}", p.peer_id());
        }
        assert_eq!(peers[2].log().len(), 2, "both sides are held");
        // The fourth peer gets the proof only once it holds an op of the twin.
        peers[2]
            .author(now, TestPayload::Chat("hello".into()))
            .unwrap();
        let links = [
            (0, ConnId(1), 2, ConnId(1)),
            (1, ConnId(1), 2, ConnId(2)),
            (2, ConnId(3), 3, ConnId(1)),
        ];
        peers[2].connect(now, ConnId(3)).unwrap();
        peers[3].connect(now, ConnId(1)).unwrap();
        let mut forked = Vec::new();
        let mut t = now.0;
        while peers[3].log().forks().seq_of(&twin).is_none() {
            assert!(t < now.0 + 10 * RELAY_AFTER_MICROS, "no proof by {t}");
            t += 100_000;
            for p in peers.iter_mut() {
                p.handle_timeout(Timestamp(t));
            }
            let events = pump(&mut peers, &links, Timestamp(t));
            forked.extend(
                (events.into_iter())
                    .filter(|(i, e)| *i == 3 && matches!(e, Event::Forked { .. }))
                    .map(|(_, e)| e),
            );
        }
        assert_eq!(peers[3].log().version_vector().get(&twin), 1);
        assert_eq!(peers[3].log().len(), 3, "both sides came with the fork");
        let marks = |p: &TPeer| {
            p.log()
                .entries()
                .map(|e| (e.op.id(), e.mark))
                .collect::<Vec<_>>()
        };
        assert_eq!(marks(&peers[3]), marks(&peers[2]));
        assert_eq!(
            forked,
            [Event::Forked {
                author: twin,
                seq: 1
            }]
        );
        // Two ops offered as a fork that are none, or whose signatures fail, note no fork and
        // count against their sender.
        let third = Keypair::from_seed([3; 32]);
        let session = peers[3].log().session_id();
        let forged = |seq: u64, text: &str, flip: bool| {
            let fields = crate::op::OpFields {
                seq,
                lamport: 9,
                timestamp: now,
                deps: Vec::new(),
                payload: TestPayload::Chat(text.into()),
            };
            let mut bytes = (crate::Op::sign(&third, &session, fields).unwrap().encoded()).to_vec();
            *bytes.last_mut().unwrap() ^= u8::from(flip);
            bytes
        };
        use crate::sync::state::RejectKind;
        let cases = [
            (
                [forged(1, "a", false), forged(2, "b", false)],
                RejectKind::BadForkProof,
            ),
            (
                [forged(1, "a", true), forged(1, "b", true)],
                RejectKind::BadSignature,
            ),
        ];
        for (ops, kind) in cases {
            let message = crate::sync::message::Message::Forked { ops, answer: false };
            peers[3].handle_input(Timestamp(t), ConnId(1), &message.encode());
            assert!(!peers[3].log().forks().contains(&third.peer_id()));
            let rejected = std::iter::from_fn(|| peers[3].poll_event())
                .any(|(_, e)| matches!(e, Event::Rejected { kind: k, .. } if k == kind));
            assert!(rejected, "{kind:?}");
        }
    }

    /// Two peers, each holding a different op a member signed as its seq 1: the member and
    /// the peers.
    fn peers_on_two_sides_of_a_fork(now: Timestamp) -> (Keypair, Vec<TPeer>) {
        let hostile = Keypair::from_seed([6; 32]);
        let fork = |text: &str| {
            let fields = crate::op::OpFields {
                seq: 1,
                lamport: 1,
                timestamp: Timestamp(1),
                deps: Vec::new(),
                payload: TestPayload::Chat(text.into()),
            };
            crate::Op::sign(&hostile, &[9; 16], fields).unwrap()
        };
        let peers = [fork("a"), fork("b")]
            .into_iter()
            .zip(1..)
            .map(|(op, i)| {
                let mut log = Log::default();
                log.insert(now, op, Origin(7)).unwrap();
                Peer::new(Keypair::from_seed([i; 32]), [9; 16], log)
            })
            .collect();
        (hostile, peers)
    }

    #[test]
    fn a_fork_nobody_built_on_is_found_by_the_tips_of_haves() {
        // A member gives each peer a different op as seq 1 and nothing more: no honest op
        // waits for either side, so only the haves' tips can tell the peers apart.
        let now = Timestamp(1_000);
        let (hostile, mut peers) = peers_on_two_sides_of_a_fork(now);
        let links = [(0, ConnId(1), 1, ConnId(1))];
        for p in &mut peers {
            p.connect(now, ConnId(1)).unwrap();
        }
        pump(&mut peers, &links, now);
        for p in &peers {
            assert_eq!(p.log().forks().seq_of(&hostile.peer_id()), Some(1));
            assert_eq!(p.log().len(), 2, "both sides held");
            let (_, sync) = p.connections().next().unwrap();
            assert_eq!(sync.stats().n_ops_asked, 0, "found without asking");
            assert_eq!(sync.stats().n_rejected(), 0);
            for e in p.log().entries() {
                assert_eq!(e.mark, crate::Mark::Rejected(crate::RejectReason::Forked));
                assert!(!e.active);
            }
        }
        let (_, sync) = peers[0].connections().next().unwrap();
        let (_, other) = peers[1].connections().next().unwrap();
        assert!(sync.stats().n_tips_differ + other.stats().n_tips_differ >= 1);
    }

    #[test]
    fn both_sides_of_a_fork_built_on_reach_both_peers_and_every_op_is_delivered() {
        // A member signs two ops as seq 1 and gives one to each peer, and each peer builds on
        // the one it holds.
        let now = Timestamp(1_000);
        let (hostile, mut peers) = peers_on_two_sides_of_a_fork(now);
        for p in &mut peers {
            p.author(now, TestPayload::Chat("on my side".into()))
                .unwrap();
        }
        let links = [(0, ConnId(1), 1, ConnId(1))];
        for p in &mut peers {
            p.connect(now, ConnId(1)).unwrap();
        }
        let t = now.0;
        pump(&mut peers, &links, now);
        for p in &peers {
            assert!(p.log().forks().contains(&hostile.peer_id()));
            let (_, sync) = p.connections().next().unwrap();
            assert_eq!(sync.stats().n_rejected(), 0, "holding a side is no offence");
        }
        // Both sides are held, so the honest ops built on them are delivered, and both peers
        // judge alike: the member's ops rejected, the honest ones standing.
        let t = t + 1_000_000;
        for p in peers.iter_mut() {
            p.handle_timeout(Timestamp(t));
        }
        pump(&mut peers, &links, Timestamp(t));
        let outcome = |p: &TPeer| {
            (p.log().entries())
                .map(|e| (e.op.id(), e.mark, e.active))
                .collect::<Vec<_>>()
        };
        assert_eq!(outcome(&peers[0]), outcome(&peers[1]));
        for p in &peers {
            assert_eq!((p.log().len(), p.log().n_pending()), (4, 0));
            for e in p.log().entries() {
                let expected = if e.op.author() == hostile.peer_id() {
                    crate::Mark::Rejected(crate::RejectReason::Forked)
                } else {
                    crate::Mark::Effective
                };
                assert_eq!(e.mark, expected);
            }
        }
    }

    /// A scene kept beside a peer as the app's engine keeps one: folded from what the peer
    /// delivers, its hash told to the peer, the scene check answered.
    struct Owner {
        scene: crate::materialize::Materialized<TestPayload, TestScene>,
        resyncs: Vec<Vec<ObjectId>>,
        n_mismatches: usize,
    }

    impl Owner {
        fn new(peer: &TPeer) -> Self {
            Self {
                scene: crate::materialize::Materialized::fold(peer.log()),
                resyncs: Vec::new(),
                n_mismatches: 0,
            }
        }

        fn answer(&mut self, peer: &mut TPeer) {
            let cut = SceneCut::of(peer.log());
            while let Some((_, event)) = peer.poll_scene_event() {
                match event {
                    SceneEvent::Mismatch(m) if m.ours.cut == cut.digest => {
                        self.n_mismatches += 1;
                        if !peer.reuse_object_hashes(cut) {
                            assert!(peer.set_object_hashes(cut, self.scene.object_hashes()));
                        }
                    }
                    SceneEvent::Resync(r) if r.cut == cut.digest => {
                        self.scene.resync(peer.log(), &r.objects, r.rest);
                        self.resyncs.push(r.objects);
                    }
                    _ => {}
                }
            }
            assert!(peer.set_scene_hash(cut, self.scene.scene_hash().0));
        }
    }

    /// Steps time by 10 ms from `t` until `done` (within 10 s): the owners answer, messages
    /// are delivered and folded, timeouts run. Returns the time then.
    fn run_scenes(
        peers: &mut [TPeer],
        owners: &mut [Owner],
        links: &[(usize, ConnId, usize, ConnId)],
        mut t: u64,
        done: impl Fn(&[TPeer], &[Owner]) -> bool,
    ) -> u64 {
        let start = t;
        loop {
            for (peer, owner) in peers.iter_mut().zip(owners.iter_mut()) {
                owner.answer(peer);
            }
            for (i, event) in pump(peers, links, Timestamp(t)) {
                if let Event::Delivered(insertion) = event {
                    owners[i].scene.apply_insertion(peers[i].log(), &insertion);
                }
            }
            if done(peers, owners) {
                return t;
            }
            assert!(t < start + 10_000_000, "not done by {t}");
            t += 10_000;
            for peer in peers.iter_mut() {
                peer.handle_timeout(Timestamp(t));
            }
        }
    }

    fn scenes_agree(peers: &[TPeer], _: &[Owner]) -> bool {
        (peers.iter().flat_map(|p| p.connections()))
            .all(|(_, sync)| sync.stats().scene.agrees == Some(true))
    }

    /// Two peers, their owners and their link.
    type Scenes = (
        Vec<TPeer>,
        Vec<Owner>,
        [(usize, ConnId, usize, ConnId); 1],
        u64,
    );

    /// Two connected peers, each authoring `n_objects` objects and a chat line, run until
    /// their scenes agree; the time then.
    fn two_scenes(n_objects: u64) -> Scenes {
        let session = [3; 16];
        let mut peers: Vec<TPeer> = (1..=2)
            .map(|i| Peer::new(Keypair::from_seed([i; 32]), session, Log::default()))
            .collect();
        for (i, p) in (0u64..).zip(peers.iter_mut()) {
            for object in 1..=n_objects {
                let value = format!("v{object}");
                let set = TestPayload::Set {
                    object: object + 1_000 * i,
                    value,
                };
                p.author(Timestamp(0), set).unwrap();
            }
            let chat = TestPayload::Chat(format!("hello from {i}"));
            p.author(Timestamp(0), chat).unwrap();
        }
        let mut owners: Vec<Owner> = peers.iter().map(Owner::new).collect();
        peers[0].connect(Timestamp(0), ConnId(1)).unwrap();
        peers[1].accept(Timestamp(0), ConnId(1), 0).unwrap();
        let links = [(0, ConnId(1), 1, ConnId(1))];
        let t = run_scenes(&mut peers, &mut owners, &links, 0, scenes_agree);
        (peers, owners, links, t)
    }

    fn repaired(peers: &[TPeer], owners: &[Owner]) -> bool {
        owners[0].scene.scene_hash() == owners[1].scene.scene_hash() && scenes_agree(peers, owners)
    }

    #[test]
    fn a_planted_scene_difference_is_found_and_refolded_and_equal_scenes_never_differ() {
        let (mut peers, mut owners, links, t) = two_scenes(3);
        assert_eq!(owners[0].scene.scene_hash(), owners[1].scene.scene_hash());
        for (peer, owner) in peers.iter().zip(&owners) {
            let (_, sync) = peer.connections().next().unwrap();
            assert_eq!(sync.stats().scene.n_mismatches, 0);
            assert_eq!(owner.n_mismatches, 0);
        }
        // B's fold of object 2 now says what its log does not: found, and refolded.
        owners[1].scene.plant_difference(|scene| {
            scene.objects.insert(2, "planted".into());
        });
        let planted_at = t;
        let t = run_scenes(&mut peers, &mut owners, &links, t + 10_000, repaired);
        assert!(
            t - planted_at <= 1_000_000,
            "repaired in {} us",
            t - planted_at
        );
        for (peer, owner) in peers.iter().zip(&owners) {
            let (_, sync) = peer.connections().next().unwrap();
            let stats = &sync.stats().scene;
            assert_eq!((stats.n_mismatches, stats.n_resyncs), (1, 1), "{stats:?}");
            let mismatch = stats.last_mismatch.unwrap();
            assert_eq!(mismatch.ours.cut, mismatch.theirs.cut);
            assert_ne!(mismatch.ours.hash, mismatch.theirs.hash);
            assert_eq!(owner.n_mismatches, 1);
            assert_eq!(
                owner.resyncs,
                [vec![ObjectId(2)]],
                "only the differing object"
            );
        }
        assert_eq!(owners[1].scene.scene().objects[&2], "v2");
    }

    #[test]
    fn a_second_difference_at_the_same_cut_is_found_with_fresh_object_hashes() {
        let (mut peers, mut owners, links, t) = two_scenes(3);
        owners[1].scene.plant_difference(|scene| {
            scene.objects.insert(2, "planted".into());
        });
        let t = run_scenes(&mut peers, &mut owners, &links, t + 10_000, repaired);
        // The log has not moved: the same cut, whose object hashes were taken with object 2
        // wrong. Object 3 goes wrong now; hashes reused from then would name object 2 again.
        owners[1].scene.plant_difference(|scene| {
            scene.objects.insert(3, "planted".into());
        });
        let planted_at = t;
        let t = run_scenes(&mut peers, &mut owners, &links, t + 10_000, repaired);
        // The mismatch comes while the first plant's window is open on both sides, out of
        // step: it is repaired at the first retry, a window (1 s) after the first plant.
        assert!(
            t - planted_at <= 1_500_000,
            "repaired in {} us",
            t - planted_at
        );
        assert_eq!(owners[1].scene.scene().objects[&3], "v3");
        assert!(owners[1].resyncs.iter().any(|r| r.contains(&ObjectId(3))));
    }

    #[test]
    fn more_differing_objects_than_a_window_refolds_are_all_repaired() {
        let n = 2 * crate::sync::scene::MAX_RESYNC_OBJECTS as u64 + 10;
        let (mut peers, mut owners, links, t) = two_scenes(n);
        owners[1].scene.plant_difference(|scene| {
            for object in 1..=n {
                scene.objects.insert(object, "planted".into());
            }
        });
        let planted_at = t;
        let t = run_scenes(&mut peers, &mut owners, &links, t + 10_000, repaired);
        // A window refolds at most MAX_RESYNC_OBJECTS: three windows, starting 1 and 2 s
        // apart.
        assert!(
            t - planted_at <= 3_500_000,
            "repaired in {} us",
            t - planted_at
        );
        for object in 1..=n {
            assert_eq!(
                owners[1].scene.scene().objects[&object],
                format!("v{object}")
            );
        }
        let refolded: usize = owners[1].resyncs.iter().map(Vec::len).sum();
        assert!(refolded >= n as usize, "{refolded}");
    }
}
