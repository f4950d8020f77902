//! The QUIC node: one UDP endpoint that accepts and dials connections and runs the peer's
//! sans-IO core on a single task.
//!
//! [`Node::spawn`] binds the endpoint and starts three kinds of task on the caller's tokio
//! runtime: the core task (owns the [`Peer`], the optional [`OpStore`], and the only reads
//! of the wall clock), an accept loop, and per connection a reader and a writer. Reliable
//! sync messages travel as length-prefixed frames ([`super::frame`]) on the connection's one
//! bidirectional stream; ephemeral messages travel as QUIC datagrams (a datagram that does
//! not fit the path is dropped: ephemeral values are latest-value-wins and unreliable).
//!
//! The app talks to the node through a cloneable [`NodeHandle`] (commands with replies) and
//! receives [`NodeEvent`]s on a bounded channel. Events are hints for the UI: when the app
//! does not keep up, events are dropped and counted ([`NodeStats::n_events_dropped`]), and
//! the log read through [`NodeHandle::with_peer`] stays the truth.

mod conn;
mod core;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize};

use tokio::sync::{mpsc, oneshot};

use crate::identity::{Keypair, PeerId};
use crate::log::{AuthorError, Insertion, Log};
use crate::net::admission::{AdmissionError, Role};
use crate::net::discovery::DiscoveredPeer;
use crate::net::session::SessionKeys;
use crate::net::tls::{self, TlsError};
use crate::op::OpId;
use crate::payload::Payload;
use crate::peer::{ConnId, Peer};
use crate::store::OpStore;
use crate::sync::state::{CloseReason, EphemeralError, RejectKind, SyncStats};

/// Commands queued from handles to the core task before `send` waits.
pub const MAX_QUEUED_COMMANDS: usize = 64;
/// Events queued for the app before new ones are dropped (and counted).
pub const MAX_QUEUED_EVENTS: usize = 4096;
/// Inputs (frames, datagrams, connection news) queued from connection tasks to the core
/// task before readers wait, which pushes back on the remote through QUIC flow control.
pub const MAX_QUEUED_INPUTS: usize = 64;
/// Frames queued for one connection's writer; a connection that falls this far behind is
/// closed as a slow reader.
pub const MAX_QUEUED_FRAMES_PER_CONN: usize = 256;
/// Sync rejections (malformed, forged, rate-limited, ...) one connection may cause before it
/// is cut off.
pub const MAX_REJECTIONS_PER_CONN: u64 = 32;
/// Incoming connections in handshake or admission at once; more are refused.
pub const MAX_ADMISSIONS_IN_PROGRESS: usize = 16;

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
    fn var_int(self) -> quinn::VarInt {
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
    /// Already [`crate::peer::MAX_CONNECTIONS`] connections.
    #[error("too many connections")]
    TooManyConnections,
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
    /// The remote caused more than [`MAX_REJECTIONS_PER_CONN`] sync rejections.
    CutOff {
        /// Rejections counted on this connection.
        n_rejected: u64,
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
    /// The remote is this node.
    SelfConnection,
    /// Already [`crate::peer::MAX_CONNECTIONS`] connections.
    TooManyConnections,
}

impl From<&AdmissionError> for RefusalKind {
    fn from(e: &AdmissionError) -> Self {
        match e {
            AdmissionError::WrongInvite => Self::WrongInvite,
            AdmissionError::BadSignature => Self::BadSignature,
            AdmissionError::Malformed(_)
            | AdmissionError::UnknownVersion(_)
            | AdmissionError::WrongRole => Self::Malformed,
            AdmissionError::Timeout => Self::Timeout,
            AdmissionError::Exporter | AdmissionError::Connection(_) => Self::Connection,
            AdmissionError::RefusedByRemote(_) => Self::RefusedByRemote,
        }
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
    /// Connections closed because they did not read fast enough.
    pub n_slow_readers: u64,
    /// Received datagrams that are not ephemeral sync messages (dropped).
    pub n_bad_datagrams: u64,
    /// Ephemeral messages dropped because they did not fit a datagram.
    pub n_datagrams_dropped: u64,
    /// Events dropped because the app did not read them in time.
    pub n_events_dropped: u64,
    /// Live connections, in id order.
    pub connections: Vec<ConnStats>,
}

impl NodeStats {
    /// Failed admissions of every kind.
    pub fn n_failed_admissions(&self) -> u64 {
        self.failed_admissions.values().sum()
    }
}

type Query<P> = Box<dyn FnOnce(&Peer<P>) + Send>;

/// Sees the node's log change, inside the core task: the way a driver keeps a scene folded
/// (for example a `Materialized` view) without copying the log or racing the node.
///
/// Both methods run on the node's core task between network steps, so they must be quick;
/// the node sends nothing while they run.
pub trait Observer<P>: Send + 'static {
    /// Ops were authored or delivered and are already in the store (if the node has one).
    /// Insertions come in the order the log made them; hand each to the fold as it comes.
    fn inserted(&mut self, log: &Log<P>, insertion: &Insertion);

    /// The node finished a step (inputs handled, events stored, transmits queued).
    /// `changed` is true when [`Observer::inserted`] was called since the last settled step,
    /// and at the first step (so the observer sees the log it starts from).
    fn settled(&mut self, peer: &Peer<P>, changed: bool);
}

/// A request from a handle to the core task.
enum Command<P> {
    Dial {
        addr: SocketAddr,
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
    },
    AdmissionFailed {
        conn: Option<ConnId>,
        addr: SocketAddr,
        error: AdmissionError,
        kind: RefusalKind,
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
    admissions_in_progress: AtomicUsize,
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
        tokio::runtime::Handle::try_current().map_err(|_| NodeError::NoRuntime)?;
        let NodeConfig {
            keypair,
            keys,
            listen,
            log,
            store,
        } = config;
        let mut endpoint =
            quinn::Endpoint::server(tls::server_config()?, listen).map_err(|source| {
                NodeError::Bind {
                    addr: listen,
                    source,
                }
            })?;
        endpoint.set_default_client_config(tls::client_config()?);
        let local_addr = endpoint.local_addr().map_err(|source| NodeError::Bind {
            addr: listen,
            source,
        })?;
        let peer_id = keypair.peer_id();
        let (input_tx, input_rx) = mpsc::channel(MAX_QUEUED_INPUTS);
        let (command_tx, command_rx) = mpsc::channel(MAX_QUEUED_COMMANDS);
        let (event_tx, event_rx) = mpsc::channel(MAX_QUEUED_EVENTS);
        let shared = Arc::new(Shared {
            keypair: Keypair::from_seed(keypair.seed()),
            keys: keys.clone(),
            inputs: input_tx,
            next_conn: AtomicU64::new(1),
            admissions_in_progress: AtomicUsize::new(0),
        });
        let peer = Peer::new(keypair, keys.session_id(), log);
        tokio::spawn(conn::accept_loop(endpoint.clone(), shared.clone()));
        let core = core::Core::new(peer, observer, store, endpoint, shared, event_tx);
        tokio::spawn(core.run(command_rx, input_rx));
        Ok(Self {
            handle: NodeHandle {
                commands: command_tx,
                local_addr,
                peer_id,
            },
            events: event_rx,
        })
    }
}

/// Commands to a running node; cheap to clone.
#[derive(Debug)]
pub struct NodeHandle<P> {
    commands: mpsc::Sender<Command<P>>,
    local_addr: SocketAddr,
    peer_id: PeerId,
}

impl<P> Clone for NodeHandle<P> {
    fn clone(&self) -> Self {
        Self {
            commands: self.commands.clone(),
            local_addr: self.local_addr,
            peer_id: self.peer_id,
        }
    }
}

impl<P: Payload + Send + 'static> NodeHandle<P> {
    /// The address the endpoint is bound to.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
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
    /// peer already exists and is kept instead, its id is returned.
    pub async fn dial(&self, addr: SocketAddr) -> Result<ConnId, DialError> {
        self.request(|reply| Command::Dial { addr, reply })
            .await
            .map_err(|_| DialError::Gone)?
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
