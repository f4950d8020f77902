//! The QUIC node: one UDP endpoint that accepts and dials connections and runs the peer's
//! sans-IO core on a single task.
//!
//! [`Node::spawn`] binds the endpoint and starts three kinds of task on the caller's tokio
//! runtime: the core task (owns the [`Peer`], the optional [`OpStore`], and the only reads
//! of the wall clock), an accept loop, and per connection a reader and a writer. Reliable
//! sync messages travel as length-prefixed frames ([`super::frame`]), each on a unidirectional
//! stream of its own, sent in order and read as they come (at most
//! [`MAX_FRAMES_READ_AT_ONCE`] at a time), so a lost packet delays only its own message;
//! the admission's bidirectional stream stays open while the connection lives. Ephemeral
//! messages travel as QUIC datagrams (a datagram that does
//! not fit the path is dropped: ephemeral values are latest-value-wins and unreliable).
//!
//! The app talks to the node through a cloneable [`NodeHandle`] (commands with replies) and
//! receives [`NodeEvent`]s on a bounded channel. Events are hints for the UI: when the app
//! does not keep up, events are dropped and counted ([`NodeStats::n_events_dropped`]), and
//! the log read through [`NodeHandle::with_peer`] stays the truth.
//!
//! # Stalled connections
//!
//! After an outage QUIC probes a connection at intervals it doubles while the outage lasts,
//! so one whose unacknowledged data filled its congestion window would resume only at the
//! next probe, up to the outage's length after it ended. The sync core says when a
//! connection has stalled ([`crate::sync::state::Event::Stalled`]: batches wait and the
//! remote has been silent a few resend timeouts, or the remote is heard but has shown for as
//! long that it hears nothing of ours; said at the end with the smaller id only). At the
//! second such event of a silence, if the connection received no UDP datagram since the first
//! (a remote that is busy but reachable still acknowledges packets), or at once when the
//! remote hears nothing of ours (its acknowledgements come in while our data waits on a
//! probe: half open), the node dials the remote's address again: one dial at a time per connection, each giving up on its
//! handshake after the event's `handshake_micros`, quietly (no
//! [`NodeEvent::AdmissionFailed`]). Admitted, the new connection replaces the stalled one at
//! both ends, as any second connection to a peer does: both keep the one whose dialer has
//! the smaller id, and the newer one from the same dialer ([`NodeStats::n_stall_redials`],
//! [`NodeStats::n_stalls_replaced`]).
//!
//! # Joining from a snapshot
//!
//! A node started with [`NodeConfig::join_from_snapshot`] and an empty log holds its first
//! admitted connections back from sync and asks one of them, on a QUIC stream of its own,
//! for a [`Snapshot`] (at most [`crate::snapshot::MAX_SNAPSHOT_BYTES`], within
//! [`SNAPSHOT_FETCH_TIMEOUT_MILLIS`]). Its [`Observer`] joins it (the ops inserted unverified,
//! folded, and the fold checked against the snapshot's scene hash); then every connection
//! syncs what the snapshot lacks, and a thread named `snapshot-verify` checks the signatures
//! ([`crate::snapshot::verify_encoded`]). Nothing of the joined log is stored and no op is
//! authored (authoring waits, at most [`MAX_HELD_AUTHORS`]) until that check passes: then
//! the whole log is stored in one append. A forged op drops the joined log and every
//! connection, and the node syncs op by op from an empty log. A remote with nothing to give,
//! a failed fetch or a snapshot that does not join (a scene hash that is not its ops' fold
//! among others) is refused and the next held connection is asked, or, with none left,
//! every held connection syncs op by op. A fetch whose connection ends refuses nobody: its
//! remote is asked again on its next connection. A dial to an address this node holds a
//! connection to returns that connection, so a dial loop cannot replace one under its fetch.
//!
//! A node serves a snapshot to each connection at most [`MAX_SNAPSHOTS_SERVED_PER_CONN`]
//! times, and captures one at most every [`SNAPSHOT_CAPTURE_INTERVAL_MILLIS`] (a request in
//! between gets the last capture, which the remote then completes by sync), so no remote
//! makes it capture at will.
//!
//! The endpoint's UDP socket is a [`DemuxSocket`]: discovery replies are taken out of the
//! QUIC traffic for the node's discovery client, so that [`NodeHandle::register_with`]
//! registers from the socket peers must dial (behind a NAT, the server sees and lists that
//! socket's public mapping), and [`NodeHandle::punch`] dials a discovered peer with the
//! retries hole punching needs.

mod conn;
mod core;
mod join;
mod punch;

pub use join::{
    MAX_HELD_AUTHORS, MAX_SNAPSHOT_REQUEST_BYTES, MAX_SNAPSHOTS_SERVED_PER_CONN,
    SNAPSHOT_CAPTURE_INTERVAL_MILLIS, SNAPSHOT_FETCH_TIMEOUT_MILLIS, SNAPSHOT_PROGRESS_BYTES,
    SnapshotNews,
};
pub use punch::{
    MAX_PUNCH_ATTEMPTS, PUNCH_HANDSHAKE_TIMEOUT_MILLIS, PunchError, Punched, Unreachable,
};

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use tokio::sync::{mpsc, oneshot, watch};

use crate::identity::{Keypair, OpId, PeerId};
use crate::log::{AuthorError, Insertion, Log};
use crate::net::admission::{self, AdmissionError, Role};
use crate::net::discovery::DiscoveredPeer;
use crate::net::discovery::rendezvous::{self, RegisterError, Rendezvous};
use crate::net::session::{DiscoveryId, SessionKeys};
use crate::net::socket::{DemuxSocket, DiscoveryPort, SocketCounters};
use crate::net::tls::{self, TlsError};
use crate::payload::Payload;
use crate::peer::{ConnId, Peer};
use crate::snapshot::{CaptureError, JoinError, Snapshot, VerifyError};
use crate::store::OpStore;
use crate::sync::state::{CloseReason, EphemeralError, RejectKind, SyncStats};
use crate::time::Timestamp;

/// Commands queued from handles to the core task before `send` waits.
pub const MAX_QUEUED_COMMANDS: usize = 64;
/// Events queued for the app before new ones are dropped (and counted).
pub const MAX_QUEUED_EVENTS: usize = 4096;
/// Inputs (frames, datagrams, connection news) queued from connection tasks to the core
/// task before readers wait, which pushes back on the remote through QUIC flow control.
pub const MAX_QUEUED_INPUTS: usize = 64;
/// Sync frames of one connection read at once, each from a stream of its own (at most
/// [`super::frame::MAX_FRAME_BYTES`] each, 8 MiB in all); the remote's other streams wait in
/// QUIC's buffers, within [`super::tls::MAX_RECEIVE_WINDOW_BYTES`].
pub const MAX_FRAMES_READ_AT_ONCE: usize = 32;
/// Frames queued for one connection's writer; a connection that falls this far behind is
/// closed as a slow reader.
pub const MAX_QUEUED_FRAMES_PER_CONN: usize = 256;
/// Sync rejections that are offences (malformed, forged, rate-limited, ...; not ops dropped
/// because the pending buffer was full, [`crate::sync::state::RejectKind::is_offence`]) one
/// connection may cause before it is cut off.
pub const MAX_REJECTIONS_PER_CONN: u64 = 32;
/// Incoming connections in handshake or admission at once; more are refused.
pub const MAX_ADMISSIONS_IN_PROGRESS: usize = 64;
/// Incoming connections in handshake or admission at once from one source address (an IPv4
/// address or an IPv6 /64, see [`crate::net::prefix::AddressPrefix`]); more from there are refused, so one
/// source holds at most this many of the [`MAX_ADMISSIONS_IN_PROGRESS`] slots.
pub const MAX_ADMISSIONS_IN_PROGRESS_PER_ADDRESS: usize = 4;
/// Accepted connections (admitted or in admission) from one source address at once, whatever
/// peer ids they prove: an invite holder who makes new keys gets no more than this many of
/// the [`crate::peer::MAX_CONNECTIONS`] slots from one address, and when every slot is taken
/// a newcomer takes one from the address holding the most ([`crate::peer::Peer::accept`]).
/// Connections this node dialed are not counted.
pub const MAX_CONNECTIONS_PER_ADDRESS: usize = 8;
/// A peer whose connection the idle timeout closed (an outage or a partition outlasted it) is
/// dialed again by the end with the smaller id at once and then this often (250 ms), whatever
/// finds peers, for [`REDIAL_LOST_FOR_MILLIS`]: the two meet again within about this long of
/// the network's return plus a handshake, where a finder's rounds take a second or more.
pub const REDIAL_LOST_EVERY_MILLIS: u64 = 250;
/// A node that hears a remote after a silence of at least
/// [`crate::sync::state::MIN_STALL_MICROS`] ([`crate::sync::state::Event::Resumed`]), or
/// whose dial replaces a stalled connection or reaches a lost peer (the network may be back
/// after an outage or a partition), dials its lost peers at once and
/// tells its finders ([`NodeHandle::resumed`]), which dial the peers they know and have no
/// connection to: at most once this often (250 ms), so a remote that speaks in bursts, or
/// many remotes speaking again at once, cost at most four rounds of dials a second.
pub const RESUMED_DIALS_EVERY_MILLIS: u64 = 250;
/// How long a lost peer is dialed again (60 s); a finder's rounds go on after that.
pub const REDIAL_LOST_FOR_MILLIS: u64 = 60_000;
/// Most lost peers dialed again at once (the connection slots' number).
pub const MAX_LOST_PEERS: usize = crate::peer::MAX_CONNECTIONS;
/// Most dials under way to one lost peer: each may take the handshake time a stall's redial
/// has, which can be longer than [`REDIAL_LOST_EVERY_MILLIS`].
pub const MAX_LOST_DIALS_PER_PEER: usize = 2;
/// How long an accepted connection may take, from its validated first packet, to finish the
/// QUIC handshake and send a valid admission frame (a few round trips and one lost packet's
/// resend). Shorter than the dialer's [`admission::ADMISSION_TIMEOUT_MILLIS`], so that a
/// connection that never admits frees its slot soon.
pub const ACCEPT_TIMEOUT_MILLIS: u64 = 2_000;
/// In a session that binds its authors, how long a connection to a key the log does not know
/// stays up before this node admits the key ([`crate::membership::Admission`]), so that sync
/// first brings an admission another member made.
pub const ADMISSION_DELAY_MILLIS: u64 = 2_000;
/// This node admits at most one new key per source address (an IPv4 address or an IPv6 /64)
/// in this long, so a member rejoining under fresh keys from one address drains admitters'
/// budgets ([`crate::Log::default_grant`]) no faster.
pub const ADMISSION_INTERVAL_MILLIS: u64 = 60_000;
/// Source addresses whose last admission this node remembers; the oldest is forgotten first.
pub const MAX_ADMISSION_SOURCES: usize = 1024;

/// QUIC application close codes this node sends.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum CloseCode {
    /// The node is shutting down.
    Shutdown = 0,
    /// Admission failed.
    Refused = 1,
    /// The remote broke the protocol (oversized frame, too many rejections, wrong identity).
    Protocol = 2,
    /// Another connection to the same peer is kept instead.
    Duplicate = 3,
    /// The app asked to close it.
    Closed = 4,
    /// The remote did not read fast enough.
    Slow = 5,
    /// The sync core ended the session (wrong session or protocol).
    Sync = 6,
}

impl CloseCode {
    pub(crate) fn var_int(self) -> quinn::VarInt {
        quinn::VarInt::from_u32(self as u32)
    }
}

/// What the node needs to start.
#[derive(Debug)]
pub struct NodeConfig<P> {
    /// This peer's key pair (its id, op signatures and admission proofs).
    pub keypair: Keypair,
    /// The session's keys, from its invite.
    pub keys: SessionKeys,
    /// The UDP address to bind (port 0 picks a free port).
    pub listen: SocketAddr,
    /// The log to start from (for example loaded with [`OpStore::open_into`]).
    pub log: Log<P>,
    /// If set, every op the node authors or receives is appended (and fsynced) here before
    /// anything more is sent, as the crate's driving rules require.
    pub store: Option<OpStore<P>>,
    /// Join from a snapshot when `log` is empty: the first admitted peer is asked for one
    /// before any connection syncs op by op (see [the module](self#joining-from-a-snapshot)).
    pub join_from_snapshot: bool,
}

/// Why the node could not start.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// Not called inside a tokio runtime.
    #[error("Node::spawn must be called inside a tokio runtime")]
    NoRuntime,
    /// TLS or QUIC configuration failed.
    #[error(transparent)]
    Tls(#[from] TlsError),
    /// The UDP socket could not be bound.
    #[error("cannot bind {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The OS error.
        source: std::io::Error,
    },
}

/// The node has stopped (shut down, or its store failed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the node has stopped")]
pub struct NodeGone;

/// Why a dial did not produce a connection.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DialError {
    /// The node has stopped.
    #[error("the node has stopped")]
    Gone,
    /// The handshake or admission failed (wrong invite on either side, timeout, ...).
    #[error(transparent)]
    Admission(#[from] AdmissionError),
    /// The address is this node.
    #[error("the remote is this node")]
    SelfConnection,
    /// Already [`crate::peer::MAX_CONNECTIONS`] connections, all of them dialed by this node.
    #[error("too many connections")]
    TooManyConnections,
    /// The session's founder expelled the remote, or this node ([`crate::membership`]).
    #[error("the session's founder expelled {0}")]
    Expelled(PeerId),
}

/// Why an op could not be authored through the node.
#[derive(Debug, thiserror::Error)]
pub enum NodeAuthorError {
    /// The node has stopped.
    #[error("the node has stopped")]
    Gone,
    /// The log refused to author it.
    #[error(transparent)]
    Author(#[from] AuthorError),
    /// The op could not be stored; the node stops.
    #[error("the op store failed: {0}")]
    Store(String),
    /// More than [`MAX_HELD_AUTHORS`] edits wait for a join from a snapshot to be checked.
    #[error("the session is being joined; edit again in a moment")]
    Joining,
}

/// Why an ephemeral value was not sent.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NodeEphemeralError {
    /// The node has stopped.
    #[error("the node has stopped")]
    Gone,
    /// The core refused the value.
    #[error(transparent)]
    Refused(#[from] EphemeralError),
}

/// Why a connection ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DisconnectReason {
    /// The app closed it ([`NodeHandle::close`]).
    Closed,
    /// The transport lost it, or the remote closed it.
    Lost(String),
    /// The remote caused more than [`MAX_REJECTIONS_PER_CONN`] sync rejections that are
    /// offences.
    CutOff {
        /// Offences counted on this connection.
        n_offences: u64,
    },
    /// The remote announced a frame over [`super::frame::MAX_FRAME_BYTES`].
    OversizedFrame {
        /// The announced length.
        len: u64,
    },
    /// The remote's sync hello claims another peer id than the one it proved at admission.
    IdentityMismatch,
    /// Another connection to the same peer is kept instead.
    Duplicate,
    /// The remote did not read fast enough ([`MAX_QUEUED_FRAMES_PER_CONN`]).
    SlowReader,
    /// The sync core ended the session.
    Sync(CloseReason),
    /// A snapshot this node joined from held a forged op: every connection was closed and
    /// the joined log dropped, and the node syncs op by op from an empty log.
    SnapshotRefused,
}

/// Kinds of failed admission, counted in [`NodeStats::failed_admissions`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RefusalKind {
    /// The remote does not know the invite.
    WrongInvite,
    /// The remote does not own the peer id it claims.
    BadSignature,
    /// A malformed, unknown-version or reflected admission frame.
    Malformed,
    /// Handshake and admission took too long.
    Timeout,
    /// The QUIC handshake or the stream failed.
    Connection,
    /// The remote refused us.
    RefusedByRemote,
    /// Too many admissions in progress ([`MAX_ADMISSIONS_IN_PROGRESS`]).
    Busy,
    /// Too many admissions in progress or connections from the remote's address
    /// ([`MAX_ADMISSIONS_IN_PROGRESS_PER_ADDRESS`], [`MAX_CONNECTIONS_PER_ADDRESS`]).
    AddressBusy,
    /// The remote is this node.
    SelfConnection,
    /// Already [`crate::peer::MAX_CONNECTIONS`] connections, all of them dialed by this node
    /// (otherwise an accepted one makes room).
    TooManyConnections,
    /// The remote, or this node, is expelled from the session: admitted by the invite, it
    /// would be closed as soon as the sync starts.
    Expelled,
}

impl RefusalKind {
    /// The kind of a failed admission; none for a connection the remote closed as a
    /// duplicate, which is not a failure (the two peers are connected by the other one).
    fn of(e: &AdmissionError) -> Option<Self> {
        Some(match e {
            AdmissionError::WrongInvite => Self::WrongInvite,
            AdmissionError::BadSignature => Self::BadSignature,
            AdmissionError::Malformed(_)
            | AdmissionError::UnknownVersion(_)
            | AdmissionError::WrongRole => Self::Malformed,
            AdmissionError::Timeout => Self::Timeout,
            AdmissionError::Exporter | AdmissionError::Connection(_) => Self::Connection,
            AdmissionError::RefusedByRemote(_) => Self::RefusedByRemote,
            AdmissionError::Superseded => return None,
        })
    }
}

/// Something the app should know.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NodeEvent {
    /// A connection is admitted and the remote's sync hello arrived.
    Connected {
        /// The connection.
        conn: ConnId,
        /// The remote, proven at admission.
        peer: PeerId,
        /// The remote's address.
        addr: SocketAddr,
        /// Which side dialed.
        role: Role,
    },
    /// A connection ended; its sync state is gone (nothing acknowledged is lost).
    Disconnected {
        /// The connection.
        conn: ConnId,
        /// The remote.
        peer: PeerId,
        /// Why.
        reason: DisconnectReason,
    },
    /// Ops arrived and were inserted; the scene must refold as the insertion says.
    Delivered {
        /// The connection they came on.
        conn: ConnId,
        /// The remote that sent them (not necessarily their author).
        peer: PeerId,
        /// What changed.
        insertion: Insertion,
    },
    /// The remote's latest value on an ephemeral channel (never stored).
    Ephemeral {
        /// The connection.
        conn: ConnId,
        /// The remote.
        peer: PeerId,
        /// The stream.
        channel: u32,
        /// The value.
        value: Vec<u8>,
    },
    /// The remote has acknowledged everything this node holds.
    UpToDate {
        /// The connection.
        conn: ConnId,
        /// The remote.
        peer: PeerId,
    },
    /// Input from this connection showed that `author` signed two ops with one seq, `seq`
    /// the lowest known ([`crate::fork`]): its ops from there on count for nothing. `author`
    /// may be this node's own identity, run twice or restored from an old copy.
    Forked {
        /// The connection.
        conn: ConnId,
        /// The author that equivocated.
        author: PeerId,
        /// The seq it signed twice.
        seq: u64,
    },
    /// The core dropped bad input from this connection (also counted in its stats).
    Rejected {
        /// The connection.
        conn: ConnId,
        /// The remote.
        peer: PeerId,
        /// What kind.
        kind: RejectKind,
        /// A plain description.
        detail: String,
    },
    /// A connection was not admitted.
    AdmissionFailed {
        /// The remote's address.
        addr: SocketAddr,
        /// Why.
        error: AdmissionError,
    },
    /// How a join from a snapshot goes ([`NodeConfig::join_from_snapshot`]).
    Snapshot(SnapshotNews),
    /// The node stopped because its store failed.
    Stopped {
        /// The store error.
        error: String,
    },
}

/// One live connection's counters.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConnStats {
    /// The connection.
    pub conn: ConnId,
    /// The remote.
    pub peer: PeerId,
    /// The remote's address.
    pub addr: SocketAddr,
    /// Which side dialed.
    pub role: Role,
    /// The sync core's counters (messages, bytes of sync messages, ops, rejections).
    pub sync: SyncStats,
    /// Bytes in UDP datagrams sent on this connection (QUIC headers, TLS and acks included).
    pub udp_bytes_sent: u64,
    /// Bytes in UDP datagrams received on this connection.
    pub udp_bytes_received: u64,
    /// The current round-trip estimate.
    pub rtt_micros: u64,
}

/// The node's counters.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct NodeStats {
    /// Failed admissions, by kind (both directions).
    pub failed_admissions: BTreeMap<RefusalKind, u64>,
    /// Connections admitted.
    pub n_admitted: u64,
    /// Keys this node admitted to the session ([`ADMISSION_DELAY_MILLIS`]).
    pub n_keys_admitted: u64,
    /// Stateless retries sent to connection attempts whose source address was not validated
    /// yet (the dialer echoes the token from its address, and only then does this node keep
    /// any state or count the attempt against the address).
    pub n_retries: u64,
    /// Store appends synced (one `fsync` each) since the node started: one per settled step
    /// that delivered ops, not one per op.
    pub n_store_syncs: u64,
    /// Connections ended.
    pub n_disconnected: u64,
    /// Connections cut off for too many sync rejections.
    pub n_cut_off: u64,
    /// Connections closed for announcing an oversized frame.
    pub n_oversized_frames: u64,
    /// Connections closed for a sync hello that contradicts the admitted identity.
    pub n_identity_mismatches: u64,
    /// Connections closed as duplicates of another connection to the same peer.
    pub n_duplicates: u64,
    /// Dials to the remote of a stalled connection ([`crate::sync::state::Event::Stalled`]), each
    /// given the handshake time the event allows.
    pub n_stall_redials: u64,
    /// Stalled connections replaced by such a dial (the rest timed out or were refused, and
    /// the old connection went on).
    pub n_stalls_replaced: u64,
    /// Dials to a peer whose connection the idle timeout closed ([`REDIAL_LOST_EVERY_MILLIS`]).
    pub n_lost_redials: u64,
    /// Peers connected again by such a dial.
    pub n_lost_reconnected: u64,
    /// Times a sign that the network is back (a remote heard after a silence, a dial that
    /// replaced a stalled connection or reached a lost peer) brought this node's dials
    /// forward ([`RESUMED_DIALS_EVERY_MILLIS`]).
    pub n_resumed_rounds: u64,
    /// Accepted connections closed to make room for a newer one when every slot was taken
    /// ([`crate::peer::Peer::accept`]).
    pub n_evicted: u64,
    /// Connections closed because they did not read fast enough.
    pub n_slow_readers: u64,
    /// Received datagrams that are not ephemeral sync messages (dropped).
    pub n_bad_datagrams: u64,
    /// Ephemeral messages dropped because they did not fit a datagram.
    pub n_datagrams_dropped: u64,
    /// Events dropped because the app did not read them in time.
    pub n_events_dropped: u64,
    /// Discovery replies the socket took out of the QUIC traffic for the discovery client.
    pub n_discovery_replies: u64,
    /// Discovery replies dropped because
    /// [`crate::net::socket::MAX_QUEUED_DISCOVERY_REPLIES`] waited unread.
    pub n_discovery_replies_dropped: u64,
    /// Registrations answered by the discovery server ([`NodeHandle::register_with`]).
    pub n_registrations: u64,
    /// Registrations left unanswered after every attempt.
    pub n_registrations_unanswered: u64,
    /// Introductions of newcomers received from the discovery server.
    pub n_introductions: u64,
    /// Discovery replies ignored: not from the server, or another session's introductions.
    pub n_stray_discovery: u64,
    /// Punches started ([`NodeHandle::punch`] on a peer not connected yet).
    pub n_punches: u64,
    /// Punches that ended with a connection to the peer.
    pub n_punched: u64,
    /// Punches that ended without one after [`MAX_PUNCH_ATTEMPTS`] ([`Unreachable`]).
    pub n_unreachable: u64,
    /// Discovered peers not punched because [`rendezvous::MAX_PUNCHES_IN_PROGRESS`] were
    /// under way or [`rendezvous::MAX_INTRODUCTIONS_PER_REFRESH`] were acted on (tried at the
    /// next refresh).
    pub n_punches_skipped: u64,
    /// Rendezvous events dropped because the app did not read them in time.
    pub n_rendezvous_events_dropped: u64,
    /// Snapshots sent to remotes that asked for one to join from.
    pub n_snapshots_served: u64,
    /// Snapshot requests answered with nothing (this node was joining, keeps no scene, or
    /// the connection had asked [`MAX_SNAPSHOTS_SERVED_PER_CONN`] times).
    pub n_snapshots_declined: u64,
    /// Joins from a snapshot (at most one per node).
    pub n_snapshot_joins: u64,
    /// Snapshots this node fetched and did not keep: cut short, undecodable, not joining, or
    /// found forged afterwards.
    pub n_snapshots_refused: u64,
    /// Live connections, in id order.
    pub connections: Vec<ConnStats>,
}

impl NodeStats {
    /// Failed admissions of every kind.
    pub fn n_failed_admissions(&self) -> u64 {
        self.failed_admissions.values().sum()
    }
}

/// Counters kept outside the core task (by the socket, the rendezvous and punches), read
/// into [`NodeStats`].
#[derive(Debug, Default)]
pub(crate) struct Counters {
    pub(crate) socket: Arc<SocketCounters>,
    pub(crate) n_registrations: AtomicU64,
    pub(crate) n_registrations_unanswered: AtomicU64,
    pub(crate) n_introductions: AtomicU64,
    pub(crate) n_stray_discovery: AtomicU64,
    pub(crate) n_punches: AtomicU64,
    pub(crate) n_punched: AtomicU64,
    pub(crate) n_unreachable: AtomicU64,
    pub(crate) n_punches_skipped: AtomicU64,
    pub(crate) n_rendezvous_events_dropped: AtomicU64,
    pub(crate) n_retries: AtomicU64,
}

impl Counters {
    /// Counts one.
    pub(crate) fn add(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    fn fill(&self, stats: &mut NodeStats) {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        stats.n_discovery_replies = self.socket.n_replies();
        stats.n_discovery_replies_dropped = self.socket.n_replies_dropped();
        stats.n_registrations = get(&self.n_registrations);
        stats.n_registrations_unanswered = get(&self.n_registrations_unanswered);
        stats.n_introductions = get(&self.n_introductions);
        stats.n_stray_discovery = get(&self.n_stray_discovery);
        stats.n_punches = get(&self.n_punches);
        stats.n_punched = get(&self.n_punched);
        stats.n_unreachable = get(&self.n_unreachable);
        stats.n_punches_skipped = get(&self.n_punches_skipped);
        stats.n_rendezvous_events_dropped = get(&self.n_rendezvous_events_dropped);
        stats.n_retries = get(&self.n_retries);
    }
}

type Query<P> = Box<dyn FnOnce(&Peer<P>) + Send>;

/// Sees the node's log change, inside the core task: the way a driver keeps a scene folded
/// (for example a `Materialized` view) without copying the log or racing the node.
///
/// Every method runs on the node's core task between network steps, so it must be quick;
/// the node sends nothing while it runs. The snapshot methods are the slowest (about 0.1 s
/// each at 10^5 ops), and the node calls them at most once per join and once per
/// [`SNAPSHOT_CAPTURE_INTERVAL_MILLIS`] of serving.
pub trait Observer<P>: Send + 'static {
    /// Ops were authored or delivered and are already in the store (if the node has one).
    /// Insertions come in the order the log made them. Those of one received batch come once
    /// the whole batch is in the log: a fold should merge them and apply them at
    /// [`Observer::settled`], not one by one against a log that already holds the later ones.
    fn inserted(&mut self, log: &Log<P>, insertion: &Insertion);

    /// The node finished a step (inputs handled, events stored; transmits are drained right
    /// after), or authored an op (before the author hears back).
    /// `changed` is true when [`Observer::inserted`] was called since the last settled step,
    /// and at the first step (so the observer sees the log it starts from).
    /// The peer is mutable for the scene check only: an observer that folds tells it the
    /// scene hash ([`Peer::set_scene_hash`]) and answers its events
    /// ([`Peer::poll_scene_event`]).
    fn settled(&mut self, peer: &mut Peer<P>, changed: bool);

    /// This observer's scene with `log`, as an encoded [`Snapshot`] for a remote that joins
    /// from one; `None` (the default) when it keeps no scene to give.
    fn capture_snapshot(&mut self, log: &Log<P>) -> Option<Result<Vec<u8>, CaptureError>> {
        let _ = log;
        None
    }

    /// Joins `snapshot` into `log` (empty, set up for the session) and adopts its scene in
    /// place of this observer's; the joined log, or why not. `None` (the default) when it
    /// keeps no scene.
    fn join_snapshot(
        &mut self,
        snapshot: Snapshot<P>,
        log: Log<P>,
        now: Timestamp,
    ) -> Option<Result<Log<P>, JoinError>> {
        let _ = (snapshot, log, now);
        None
    }

    /// Forgets the scene and folds `log` from scratch: when a joined log is dropped.
    fn refold(&mut self, log: &Log<P>) {
        let _ = log;
    }
}

/// A request from a handle to the core task.
enum Command<P> {
    Dial {
        addr: SocketAddr,
        /// How long the QUIC handshake may take (admission as a whole is bounded by
        /// [`admission::ADMISSION_TIMEOUT_MILLIS`]).
        handshake_timeout: Duration,
        reply: oneshot::Sender<Result<ConnId, DialError>>,
    },
    Author {
        payload: P,
        reply: oneshot::Sender<Result<OpId, NodeAuthorError>>,
    },
    Ephemeral {
        channel: u32,
        value: Vec<u8>,
        reply: oneshot::Sender<Result<(), EphemeralError>>,
    },
    Close {
        conn: ConnId,
        reply: oneshot::Sender<bool>,
    },
    Peers {
        reply: oneshot::Sender<Vec<(ConnId, PeerId)>>,
    },
    Stats {
        reply: oneshot::Sender<NodeStats>,
    },
    Query(Query<P>),
    Shutdown {
        reply: oneshot::Sender<()>,
    },
}

/// What connection tasks tell the core task.
enum Input {
    Admitted {
        conn: ConnId,
        role: Role,
        connection: quinn::Connection,
        peer: PeerId,
        send: quinn::SendStream,
        /// Starts the connection's readers: sent when the peer takes the connection (at
        /// once, or after a join from a snapshot); dropped, the readers never start.
        start: oneshot::Sender<()>,
    },
    /// The remote asks for a snapshot to join from, on a stream of its own.
    SnapshotRequest {
        conn: ConnId,
        send: quinn::SendStream,
    },
    /// A snapshot being fetched from this connection has come this far, in bytes.
    SnapshotProgress {
        conn: ConnId,
        bytes: u64,
    },
    /// A snapshot fetch from this connection ended: its bytes (empty when the remote had
    /// none to give), or why it failed.
    SnapshotFetched {
        conn: ConnId,
        result: Result<Vec<u8>, join::FetchFailure>,
    },
    /// The check of a joined snapshot has verified this many of its ops' signatures.
    VerifyProgress {
        checked: usize,
    },
    /// The check of a joined snapshot ended.
    Verified {
        result: Result<(), VerifyError>,
    },
    AdmissionFailed {
        conn: Option<ConnId>,
        addr: SocketAddr,
        error: AdmissionError,
        kind: RefusalKind,
    },
    /// The remote closed a connection in admission as a duplicate (both sides dialed at once).
    Superseded {
        conn: Option<ConnId>,
        addr: SocketAddr,
    },
    Frame {
        conn: ConnId,
        bytes: Vec<u8>,
    },
    Datagram {
        conn: ConnId,
        bytes: Vec<u8>,
    },
    OversizedFrame {
        conn: ConnId,
        len: u64,
    },
    Lost {
        conn: ConnId,
        reason: String,
    },
}

/// What every connection task shares.
struct Shared {
    keys: SessionKeys,
    /// A copy of the node's key pair, for admission proofs.
    keypair: Keypair,
    inputs: mpsc::Sender<Input>,
    next_conn: AtomicU64,
    /// Accepted connections in admission and admitted, in all and by source address.
    accepting: Mutex<conn::AcceptLoad>,
    counters: Arc<Counters>,
    /// Counts the times a sign that the network is back brought the dials forward
    /// ([`NodeHandle::resumed`]).
    resumed: watch::Sender<u64>,
}

/// A running node: its handle and its event stream.
#[derive(Debug)]
pub struct Node<P> {
    /// Commands to the node.
    pub handle: NodeHandle<P>,
    /// Events from the node.
    pub events: mpsc::Receiver<NodeEvent>,
}

impl<P: Payload + Send + 'static> Node<P> {
    /// Binds the endpoint and starts the node's tasks on the current tokio runtime.
    pub fn spawn(config: NodeConfig<P>) -> Result<Self, NodeError> {
        Self::spawn_observed(config, None)
    }

    /// [`Node::spawn`], with an [`Observer`] that sees every change of the log.
    pub fn spawn_observed(
        config: NodeConfig<P>,
        observer: Option<Box<dyn Observer<P>>>,
    ) -> Result<Self, NodeError> {
        let runtime = tokio::runtime::Handle::try_current().map_err(|_| NodeError::NoRuntime)?;
        let NodeConfig {
            keypair,
            keys,
            listen,
            log,
            store,
            join_from_snapshot,
        } = config;
        let counters = Arc::new(Counters::default());
        let (endpoint, discovery) = bind_endpoint(listen, counters.socket.clone())?;
        let local_addr = endpoint.local_addr().map_err(|source| NodeError::Bind {
            addr: listen,
            source,
        })?;
        let peer_id = keypair.peer_id();
        let keypair_seed = keypair.seed();
        let (input_tx, input_rx) = mpsc::channel(MAX_QUEUED_INPUTS);
        let (command_tx, command_rx) = mpsc::channel(MAX_QUEUED_COMMANDS);
        let (event_tx, event_rx) = mpsc::channel(MAX_QUEUED_EVENTS);
        let (resumed, resumed_rx) = watch::channel(0);
        let shared = Arc::new(Shared {
            keypair: Keypair::from_seed(keypair.seed()),
            keys: keys.clone(),
            inputs: input_tx,
            next_conn: AtomicU64::new(1),
            accepting: Mutex::new(conn::AcceptLoad::default()),
            counters: counters.clone(),
            resumed,
        });
        let joining = join_from_snapshot && log.is_empty();
        let peer = Peer::new(keypair, keys.session_id(), log);
        tokio::spawn(conn::accept_loop(endpoint.clone(), shared.clone()));
        let mut core = core::Core::new(
            peer,
            observer,
            store,
            endpoint,
            shared,
            event_tx,
            counters.clone(),
        );
        if joining {
            core.start_joining();
        }
        tokio::spawn(core.run(command_rx, input_rx));
        Ok(Self {
            handle: NodeHandle {
                commands: command_tx,
                local_addr,
                peer_id,
                shared: Arc::new(HandleShared {
                    discovery: Mutex::new(Some(discovery)),
                    runtime,
                    counters,
                    keypair: Keypair::from_seed(keypair_seed),
                    resumed: resumed_rx,
                }),
            },
            events: event_rx,
        })
    }
}

/// Binds `listen` and builds the QUIC endpoint over a [`DemuxSocket`], so that the discovery
/// client shares the endpoint's socket (and its NAT mapping).
fn bind_endpoint(
    listen: SocketAddr,
    counters: Arc<SocketCounters>,
) -> Result<(quinn::Endpoint, DiscoveryPort), NodeError> {
    let bind_error = |source| NodeError::Bind {
        addr: listen,
        source,
    };
    let socket = std::net::UdpSocket::bind(listen).map_err(bind_error)?;
    let runtime: Arc<dyn quinn::Runtime> = Arc::new(quinn::TokioRuntime);
    let inner = runtime.wrap_udp_socket(socket).map_err(bind_error)?;
    let (demux, discovery) = DemuxSocket::new(inner, counters);
    let mut endpoint = quinn::Endpoint::new_with_abstract_socket(
        quinn::EndpointConfig::default(),
        Some(tls::server_config()?),
        demux,
        runtime,
    )
    .map_err(bind_error)?;
    endpoint.set_default_client_config(tls::client_config()?);
    Ok((endpoint, discovery))
}

/// What every clone of a [`NodeHandle`] shares.
#[derive(Debug)]
struct HandleShared {
    /// The discovery client's end of the socket, until [`NodeHandle::register_with`] takes it.
    discovery: Mutex<Option<DiscoveryPort>>,
    /// The runtime the node runs on (the rendezvous task runs there too).
    runtime: tokio::runtime::Handle,
    counters: Arc<Counters>,
    /// A copy of the node's key pair, which signs its discovery registrations.
    keypair: Keypair,
    /// See [`NodeHandle::resumed`].
    resumed: watch::Receiver<u64>,
}

/// Commands to a running node; cheap to clone.
#[derive(Debug)]
pub struct NodeHandle<P> {
    commands: mpsc::Sender<Command<P>>,
    local_addr: SocketAddr,
    peer_id: PeerId,
    shared: Arc<HandleShared>,
}

impl<P> Clone for NodeHandle<P> {
    fn clone(&self) -> Self {
        Self {
            commands: self.commands.clone(),
            local_addr: self.local_addr,
            peer_id: self.peer_id,
            shared: self.shared.clone(),
        }
    }
}

impl<P: Payload + Send + 'static> NodeHandle<P> {
    /// The address the endpoint is bound to.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Changes when the node hears a remote after a silence, or its dial replaces a stalled
    /// connection or reaches a peer the idle timeout lost, at most every
    /// [`RESUMED_DIALS_EVERY_MILLIS`]: the network may be back after an outage or a
    /// partition, so whatever finds peers should dial, at once, the ones it knows and has no
    /// connection to, and replace its dials still waiting for a handshake (their first
    /// packets were most likely lost, and QUIC sends them again only after a backed-off
    /// wait). Starts unchanged.
    pub fn resumed(&self) -> watch::Receiver<u64> {
        let mut resumed = self.shared.resumed.clone();
        resumed.mark_unchanged();
        resumed
    }

    /// This node's peer id.
    pub fn peer_id(&self) -> PeerId {
        self.peer_id
    }

    async fn request<R>(
        &self,
        make: impl FnOnce(oneshot::Sender<R>) -> Command<P>,
    ) -> Result<R, NodeGone> {
        let (reply, answer) = oneshot::channel();
        self.commands
            .send(make(reply))
            .await
            .map_err(|_| NodeGone)?;
        answer.await.map_err(|_| NodeGone)
    }

    /// Dials `addr` and waits for the handshake and admission. If a connection to the same
    /// peer already exists and is kept instead, its id is returned; so is that of an open
    /// connection to `addr`, which is not dialed again (one held back while this node joins
    /// from a snapshot included, which [`NodeStats::connections`] does not list yet).
    pub async fn dial(&self, addr: SocketAddr) -> Result<ConnId, DialError> {
        self.dial_within(addr, admission::admission_timeout()).await
    }

    /// [`NodeHandle::dial`], giving up on the QUIC handshake after `handshake_timeout`.
    async fn dial_within(
        &self,
        addr: SocketAddr,
        handshake_timeout: Duration,
    ) -> Result<ConnId, DialError> {
        self.request(|reply| Command::Dial {
            addr,
            handshake_timeout,
            reply,
        })
        .await
        .map_err(|_| DialError::Gone)?
    }

    /// The connection to `peer`, if there is one.
    async fn connection_to(&self, peer: PeerId) -> Result<Option<ConnId>, NodeGone> {
        let peers = self.connected_peers().await?;
        Ok(peers.into_iter().find(|(_, p)| *p == peer).map(|(c, _)| c))
    }

    /// Registers this node with the discovery server `server` under `discovery_id`, from the
    /// node's own UDP socket, and keeps it registered (every
    /// [`crate::net::discovery::client::REFRESH_INTERVAL_MILLIS`]) until the node stops.
    ///
    /// Behind a NAT the server sees, and lists, the public address the NAT mapped for this
    /// socket: the one other peers can reach. Every peer the server names (in its reply, or
    /// in an introduction of a newcomer, which arrives as soon as the newcomer registers) is
    /// dialed at once with [`NodeHandle::punch`], so both sides of a pair dial each other at
    /// about the same time and each NAT lets the other's packets in. Outcomes arrive on the
    /// returned [`Rendezvous`]'s events and are counted in [`NodeStats`].
    ///
    /// One server per node: the node's socket has one discovery client. The rendezvous
    /// holds a handle, so the node then runs until [`NodeHandle::shutdown`].
    pub fn register_with(
        &self,
        server: SocketAddr,
        discovery_id: DiscoveryId,
    ) -> Result<Rendezvous, RegisterError> {
        let unreachable_family =
            server.is_ipv6() && self.local_addr.is_ipv4() && server.ip().to_canonical().is_ipv6();
        if unreachable_family {
            return Err(RegisterError::AddressFamily {
                server,
                local: self.local_addr,
            });
        }
        let port = self
            .shared
            .discovery
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
            .ok_or(RegisterError::AlreadyRegistered)?;
        Ok(rendezvous::spawn(
            &self.shared.runtime,
            self.clone(),
            port,
            server,
            discovery_id,
        ))
    }

    /// The node's key pair, which signs discovery registrations.
    pub(crate) fn keypair(&self) -> &Keypair {
        &self.shared.keypair
    }

    /// The counters shared with the socket, the rendezvous and punches.
    pub(crate) fn counters(&self) -> &Counters {
        &self.shared.counters
    }

    /// Resolves when the node has stopped (its core task is gone).
    pub(crate) async fn stopped(&self) {
        self.commands.closed().await;
    }

    /// Dials every discovered peer that is not this node and not connected yet, all at once,
    /// and returns each outcome.
    pub async fn dial_discovered(
        &self,
        found: &[DiscoveredPeer],
    ) -> Vec<(DiscoveredPeer, Result<ConnId, DialError>)> {
        let connected = self.connected_peers().await.unwrap_or_default();
        let mut pending = Vec::new();
        for d in found {
            if d.peer == self.peer_id || connected.iter().any(|(_, p)| *p == d.peer) {
                continue;
            }
            let (reply, answer) = oneshot::channel();
            let sent = self
                .commands
                .send(Command::Dial {
                    addr: d.addr,
                    handshake_timeout: admission::admission_timeout(),
                    reply,
                })
                .await;
            pending.push((*d, sent.map(|()| answer)));
        }
        let mut outcomes = Vec::with_capacity(pending.len());
        for (d, answer) in pending {
            let result = match answer {
                Ok(answer) => answer.await.unwrap_or(Err(DialError::Gone)),
                Err(_) => Err(DialError::Gone),
            };
            outcomes.push((d, result));
        }
        outcomes
    }

    /// Authors an op (stored first if the node has a store); every connection streams it.
    pub async fn author(&self, payload: P) -> Result<OpId, NodeAuthorError> {
        self.request(|reply| Command::Author { payload, reply })
            .await
            .map_err(|_| NodeAuthorError::Gone)?
    }

    /// Sends the latest value on an ephemeral channel to every connection, as datagrams.
    pub async fn send_ephemeral(
        &self,
        channel: u32,
        value: Vec<u8>,
    ) -> Result<(), NodeEphemeralError> {
        self.request(|reply| Command::Ephemeral {
            channel,
            value,
            reply,
        })
        .await
        .map_err(|_| NodeEphemeralError::Gone)?
        .map_err(NodeEphemeralError::Refused)
    }

    /// Closes a connection; false if it was not open.
    pub async fn close(&self, conn: ConnId) -> Result<bool, NodeGone> {
        self.request(|reply| Command::Close { conn, reply }).await
    }

    /// The admitted connections and their peers, in id order.
    pub async fn connected_peers(&self) -> Result<Vec<(ConnId, PeerId)>, NodeGone> {
        self.request(|reply| Command::Peers { reply }).await
    }

    /// The node's counters and one entry per live connection.
    pub async fn stats(&self) -> Result<NodeStats, NodeGone> {
        self.request(|reply| Command::Stats { reply }).await
    }

    /// Runs `f` on the peer (its log, its connections' sync states) inside the core task.
    /// Keep `f` short: the node does nothing else meanwhile.
    pub async fn with_peer<R: Send + 'static>(
        &self,
        f: impl FnOnce(&Peer<P>) -> R + Send + 'static,
    ) -> Result<R, NodeGone> {
        let (reply, answer) = oneshot::channel();
        let query: Query<P> = Box::new(move |peer| {
            // The asker may have given up; then the answer has no one to go to.
            let _ = reply.send(f(peer));
        });
        self.commands
            .send(Command::Query(query))
            .await
            .map_err(|_| NodeGone)?;
        answer.await.map_err(|_| NodeGone)
    }

    /// Closes every connection and the endpoint; the node's tasks end.
    pub async fn shutdown(&self) -> Result<(), NodeGone> {
        self.request(|reply| Command::Shutdown { reply }).await
    }
}
