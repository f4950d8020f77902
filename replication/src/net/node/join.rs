//! Joining from a snapshot, and serving snapshots to joiners (see the module documentation of
//! [`super`], "Joining from a snapshot"): the core task's state and steps, and the tasks that
//! move a snapshot over a QUIC stream of its own.

use std::collections::{BTreeSet, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::oneshot;

use super::core::Core;
use super::{CloseCode, DisconnectReason, Input, NodeAuthorError, NodeEvent, Shared};
use crate::identity::{OpId, PeerId};
use crate::log::Log;
use crate::net::clock::wall_clock_now;
use crate::payload::Payload;
use crate::peer::ConnId;
use crate::snapshot::{
    MAX_SNAPSHOT_BYTES, SNAPSHOT_FORMAT_VERSION, Snapshot, VerifyError, verify_encoded,
};
use crate::sync::scene::SceneCut;
use crate::time::Timestamp;

/// Snapshots one connection may ask this node for; later requests are not read.
pub const MAX_SNAPSHOTS_SERVED_PER_CONN: usize = 2;
/// A snapshot captured for remotes is given again to requests within this long (and while
/// the log is unchanged), so no remote makes this node capture at will.
pub const SNAPSHOT_CAPTURE_INTERVAL_MILLIS: u64 = 2_000;
/// How long a snapshot may take to arrive (or to be sent), from the request on.
pub const SNAPSHOT_FETCH_TIMEOUT_MILLIS: u64 = 60_000;
/// Bytes of a snapshot request (more is not read).
pub const MAX_SNAPSHOT_REQUEST_BYTES: usize = 16;
/// A fetch reports its progress each time this many more bytes arrived.
pub const SNAPSHOT_PROGRESS_BYTES: u64 = 1 << 20;
/// Authors held while a snapshot is fetched or checked; more are refused until it ends.
pub const MAX_HELD_AUTHORS: usize = 256;
/// How long a remote may take to send its request once it opened the stream.
const REQUEST_TIMEOUT_MILLIS: u64 = 5_000;

/// What a joiner sends on the stream it opens: a snapshot of the format it reads, please.
const SNAPSHOT_REQUEST: [u8; 11] = *b"SCULPTSNAP\x04";
const _: () = assert!(SNAPSHOT_REQUEST[10] == SNAPSHOT_FORMAT_VERSION);
const _: () = assert!(SNAPSHOT_REQUEST.len() <= MAX_SNAPSHOT_REQUEST_BYTES);

/// How a join from a snapshot goes, for the app ([`NodeEvent::Snapshot`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SnapshotNews {
    /// A snapshot is coming from `peer`: this many bytes so far.
    Fetching {
        /// The remote asked.
        peer: PeerId,
        /// Bytes received.
        bytes: u64,
    },
    /// Joined: the log holds the snapshot's ops and their fold matched its scene hash, every
    /// connection syncs the rest, and the check ([`SnapshotNews::Verifying`]) runs.
    Joined {
        /// The remote it came from.
        peer: PeerId,
        /// Ops it held.
        n_ops: usize,
        /// Its encoded size.
        bytes: usize,
        /// Time to decode and join it on the node's task (the wall clock), in microseconds.
        join_micros: u64,
    },
    /// The check has verified this many of the joined ops' signatures.
    Verifying {
        /// Ops checked.
        checked: usize,
        /// Ops to check.
        of: usize,
    },
    /// The check passed and the whole log is stored.
    Verified,
    /// A snapshot from `peer` was not kept: cut short, undecodable, not joining (a scene
    /// that is not its ops' fold among others), none to give, or a forged op found by the
    /// check, or a connection lost before it came (not refused for good: that remote is
    /// asked again on its next connection). The node asks another held connection, or syncs
    /// op by op.
    Refused {
        /// The remote it came from.
        peer: PeerId,
        /// Why, in words.
        why: String,
    },
}

/// An author's payload and its reply, held while a join is fetched or checked.
type HeldAuthor<P> = (P, oneshot::Sender<Result<OpId, NodeAuthorError>>);

/// The core task's part of snapshot joins.
pub(super) struct JoinState<P> {
    /// Set while this node waits to join from a snapshot.
    joining: Option<Joining>,
    /// Set from a join until its check ends.
    unverified: Option<Unverified<P>>,
    /// Authors waiting for the fetch or the check to end.
    held: VecDeque<HeldAuthor<P>>,
    /// The last snapshot captured for remotes.
    served: Option<Served>,
}

impl<P> Default for JoinState<P> {
    fn default() -> Self {
        Self {
            joining: None,
            unverified: None,
            held: VecDeque::new(),
            served: None,
        }
    }
}

/// Waiting to join: admitted connections held back from sync, and the fetch under way.
#[derive(Default)]
struct Joining {
    held: BTreeSet<ConnId>,
    fetching: Option<(ConnId, PeerId)>,
    /// Remotes whose snapshot was refused (not asked again).
    refused: BTreeSet<PeerId>,
}

/// A joined log whose check runs.
struct Unverified<P> {
    from: PeerId,
    /// An empty log set up for the session, to start again from if the check fails.
    empty: Log<P>,
    n_ops: usize,
}

/// A capture given to remotes.
struct Served {
    cut: SceneCut,
    at: Timestamp,
    bytes: Arc<Vec<u8>>,
}

impl<P> JoinState<P> {
    /// Whether admitted connections are held back from sync.
    pub(super) fn holds_connections(&self) -> bool {
        self.joining.is_some()
    }

    /// Whether authoring waits: a snapshot is being fetched, or a joined one checked (until
    /// then nothing may be stored, and an op sent but not stored could be signed again).
    pub(super) fn holds_authors(&self) -> bool {
        self.unverified.is_some() || self.joining.as_ref().is_some_and(|j| j.fetching.is_some())
    }
}

impl<P: Payload + Send + 'static> Core<P> {
    /// Holds admitted connections back until a snapshot is joined or refused.
    pub(super) fn start_joining(&mut self) {
        self.join.joining = Some(Joining::default());
    }

    /// Holds `conn` back from sync, and asks it for a snapshot if none is being fetched.
    pub(super) fn hold_back(&mut self, conn: ConnId) {
        if let Some(joining) = &mut self.join.joining {
            joining.held.insert(conn);
        }
        self.fetch_next();
    }

    /// Authors `payload` now, or holds it until the join's fetch or check ends.
    pub(super) fn author_or_hold(
        &mut self,
        payload: P,
        reply: oneshot::Sender<Result<OpId, NodeAuthorError>>,
    ) {
        if self
            .join
            .joining
            .as_ref()
            .is_some_and(|j| j.fetching.is_none())
        {
            // Nobody to join from yet: an edit starts the log here instead.
            self.end_joining();
        }
        if self.join.holds_authors() {
            if self.join.held.len() >= MAX_HELD_AUTHORS {
                let _ = reply.send(Err(NodeAuthorError::Joining));
            } else {
                self.join.held.push_back((payload, reply));
            }
            return;
        }
        let _ = reply.send(self.author(payload));
    }

    /// A held connection is gone.
    pub(super) fn forget_held(&mut self, conn: ConnId) {
        let Some(joining) = &mut self.join.joining else {
            return;
        };
        joining.held.remove(&conn);
        if let Some((_, peer)) = joining.fetching.filter(|(c, _)| *c == conn) {
            joining.fetching = None;
            // Not refused for good: the remote may be asked again when it reconnects.
            self.stats.n_snapshots_refused += 1;
            let why = "the connection ended before the snapshot came".to_string();
            self.emit(NodeEvent::Snapshot(SnapshotNews::Refused { peer, why }));
            self.fetch_next();
        }
    }

    /// Asks a held connection whose remote was not refused for a snapshot; with none left
    /// (and some held), syncs op by op.
    fn fetch_next(&mut self) {
        let Some(joining) = &self.join.joining else {
            return;
        };
        if joining.fetching.is_some() {
            return;
        }
        let next = (joining.held.iter())
            .filter_map(|c| {
                self.conns
                    .get(c)
                    .map(|l| (*c, l.peer, l.connection.clone()))
            })
            .find(|(_, peer, _)| !joining.refused.contains(peer));
        match next {
            Some((conn, peer, connection)) => {
                if let Some(joining) = &mut self.join.joining {
                    joining.fetching = Some((conn, peer));
                }
                tokio::spawn(fetch(self.shared.clone(), conn, connection));
                self.emit(NodeEvent::Snapshot(SnapshotNews::Fetching {
                    peer,
                    bytes: 0,
                }));
            }
            None if !joining.held.is_empty() => self.end_joining(),
            None => {}
        }
    }

    /// Stops holding connections back: each syncs from here.
    fn end_joining(&mut self) {
        let Some(joining) = self.join.joining.take() else {
            return;
        };
        for conn in joining.held {
            self.release_conn(conn);
        }
        self.release_held();
    }

    /// Authors what was held, once nothing holds it any more.
    fn release_held(&mut self) {
        while !self.join.holds_authors() {
            let Some((payload, reply)) = self.join.held.pop_front() else {
                return;
            };
            let _ = reply.send(self.author(payload));
        }
    }

    pub(super) fn on_snapshot_progress(&mut self, conn: ConnId, bytes: u64) {
        let fetching = self.join.joining.as_ref().and_then(|j| j.fetching);
        if let Some((c, peer)) = fetching
            && c == conn
        {
            self.emit(NodeEvent::Snapshot(SnapshotNews::Fetching { peer, bytes }));
        }
    }

    /// A fetch ended: joins the snapshot, or refuses it and asks the next connection. A fetch
    /// whose connection ended refuses nothing: the remote is asked again on its next one.
    pub(super) fn on_snapshot_fetched(
        &mut self,
        conn: ConnId,
        result: Result<Vec<u8>, FetchFailure>,
    ) {
        let Some(joining) = &mut self.join.joining else {
            return;
        };
        let Some((_, peer)) = joining.fetching.filter(|(c, _)| *c == conn) else {
            return;
        };
        let result = match result {
            Err(FetchFailure::Lost) => return self.forget_held(conn),
            Err(FetchFailure::Refused(why)) => Err(why),
            Ok(bytes) => Ok(bytes),
        };
        joining.fetching = None;
        let joined = result.and_then(|bytes| {
            if bytes.is_empty() {
                return Err("it had no snapshot to give".into());
            }
            self.join_bytes(bytes, peer)
        });
        if let Err(why) = joined {
            self.refuse_snapshot(peer, why);
            return self.fetch_next();
        }
        self.end_joining();
    }

    /// Decodes and joins `bytes` from `peer`, adopts the joined log, and starts the check.
    fn join_bytes(&mut self, bytes: Vec<u8>, peer: PeerId) -> Result<(), String> {
        let started = wall_clock_now();
        let snapshot = Snapshot::<P>::decode(&bytes).map_err(|e| e.to_string())?;
        let n_ops = snapshot.n_ops();
        let empty = self.peer.log().clone();
        let observer = self.observer.as_mut().ok_or("this node keeps no scene")?;
        let log = (observer.join_snapshot(snapshot, empty.clone(), wall_clock_now()))
            .ok_or("this node keeps no scene")?
            .map_err(|e| e.to_string())?;
        if self.peer.replace_log(log).is_none() {
            unreachable!("a joining node's connections are all held back");
        }
        let join_micros = wall_clock_now().0.saturating_sub(started.0);
        let n_bytes = bytes.len();
        let inputs = self.shared.inputs.clone();
        let session = self.peer.log().session_id();
        let spawned = std::thread::Builder::new()
            .name("snapshot-verify".into())
            .spawn(move || {
                let mut last = 0;
                let mut progress = |checked: usize| {
                    if checked >= last + 8 * crate::snapshot::MAX_VERIFY_BATCH_OPS {
                        last = checked;
                        let _ = inputs.blocking_send(Input::VerifyProgress { checked });
                    }
                };
                let result = verify_encoded::<P>(&bytes, &session, &mut progress);
                let _ = inputs.blocking_send(Input::Verified { result });
            });
        if let Err(e) = spawned {
            // Without its check the join cannot be kept.
            if let Some(observer) = &mut self.observer {
                observer.refold(&empty);
            }
            let _ = self.peer.replace_log(empty);
            return Err(format!("cannot start its check: {e}"));
        }
        self.changed = true;
        self.stats.n_snapshot_joins += 1;
        self.join.unverified = Some(Unverified {
            from: peer,
            empty,
            n_ops,
        });
        self.emit(NodeEvent::Snapshot(SnapshotNews::Joined {
            peer,
            n_ops,
            bytes: n_bytes,
            join_micros,
        }));
        Ok(())
    }

    fn refuse_snapshot(&mut self, peer: PeerId, why: String) {
        if let Some(joining) = &mut self.join.joining {
            joining.refused.insert(peer);
        }
        self.stats.n_snapshots_refused += 1;
        self.emit(NodeEvent::Snapshot(SnapshotNews::Refused { peer, why }));
    }

    pub(super) fn on_verify_progress(&mut self, checked: usize) {
        if let Some(u) = &self.join.unverified {
            let of = u.n_ops;
            self.emit(NodeEvent::Snapshot(SnapshotNews::Verifying { checked, of }));
        }
    }

    /// The check of the joined snapshot ended: the log is stored, or, with a forged op,
    /// dropped with every connection.
    pub(super) fn on_verified(&mut self, result: Result<(), VerifyError>) {
        let Some(unverified) = self.join.unverified.take() else {
            return;
        };
        match result {
            Ok(()) => {
                let all: Vec<OpId> = self.peer.log().entries().map(|e| e.op.id()).collect();
                if let Err(error) = super::core::persist(&mut self.store, self.peer.log(), &all) {
                    return self.stop(error);
                }
                let of = unverified.n_ops;
                self.emit(NodeEvent::Snapshot(SnapshotNews::Verifying {
                    checked: of,
                    of,
                }));
                self.emit(NodeEvent::Snapshot(SnapshotNews::Verified));
            }
            Err(e) => {
                let conns: Vec<ConnId> = self.conns.keys().copied().collect();
                for conn in conns {
                    let reason = Some(DisconnectReason::SnapshotRefused);
                    self.drop_conn(conn, CloseCode::Closed, reason);
                }
                let empty = unverified.empty;
                if let Some(observer) = &mut self.observer {
                    observer.refold(&empty);
                }
                if self.peer.replace_log(empty).is_none() {
                    unreachable!("every connection was just dropped");
                }
                self.changed = true;
                self.refuse_snapshot(unverified.from, e.to_string());
            }
        }
        self.release_held();
    }

    /// A remote asks for a snapshot: the last capture if recent or still current, else a new
    /// one; nothing while this node joins or keeps no scene.
    pub(super) fn on_snapshot_request(&mut self, conn: ConnId, send: quinn::SendStream) {
        if !self.conns.contains_key(&conn) {
            return;
        }
        let now = wall_clock_now();
        let bytes = if self.join.holds_connections() || self.join.unverified.is_some() {
            None
        } else {
            self.capture(now)
        };
        match &bytes {
            Some(_) => self.stats.n_snapshots_served += 1,
            None => self.stats.n_snapshots_declined += 1,
        }
        tokio::spawn(send_snapshot(send, bytes));
    }

    fn capture(&mut self, now: Timestamp) -> Option<Arc<Vec<u8>>> {
        let cut = SceneCut::of(self.peer.log());
        let interval = SNAPSHOT_CAPTURE_INTERVAL_MILLIS * 1_000;
        if let Some(s) = &self.join.served
            && (s.cut == cut || now.0 < s.at.0.saturating_add(interval))
        {
            return Some(s.bytes.clone());
        }
        let captured = self.observer.as_mut()?.capture_snapshot(self.peer.log())?;
        match captured {
            Ok(bytes) => {
                let bytes = Arc::new(bytes);
                self.join.served = Some(Served {
                    cut,
                    at: now,
                    bytes: bytes.clone(),
                });
                Some(bytes)
            }
            // Too large to give: the joiner syncs op by op.
            Err(_) => None,
        }
    }
}

/// Why a fetch gave no snapshot.
#[derive(Debug)]
pub(super) enum FetchFailure {
    /// The connection ended (closed, replaced by another to the same remote, timed out): the
    /// remote is not refused, and is asked again on its next connection.
    Lost,
    /// The remote's answer is not kept (too large, too slow, its stream reset), in words: the
    /// remote is not asked again.
    Refused(String),
}

impl From<quinn::ConnectionError> for FetchFailure {
    fn from(_: quinn::ConnectionError) -> Self {
        Self::Lost
    }
}

impl From<quinn::WriteError> for FetchFailure {
    fn from(e: quinn::WriteError) -> Self {
        match e {
            quinn::WriteError::ConnectionLost(_) => Self::Lost,
            e => Self::Refused(e.to_string()),
        }
    }
}

impl From<quinn::ReadError> for FetchFailure {
    fn from(e: quinn::ReadError) -> Self {
        match e {
            quinn::ReadError::ConnectionLost(_) => Self::Lost,
            e => Self::Refused(e.to_string()),
        }
    }
}

/// Asks `connection` for a snapshot and reads it (at most [`MAX_SNAPSHOT_BYTES`], within
/// [`SNAPSHOT_FETCH_TIMEOUT_MILLIS`]), reporting progress; the core hears how it ended.
async fn fetch(shared: Arc<Shared>, conn: ConnId, connection: quinn::Connection) {
    let reading = async {
        let (mut send, mut recv) = connection.open_bi().await?;
        send.write_all(&SNAPSHOT_REQUEST).await?;
        let _ = send.finish();
        let mut bytes = Vec::new();
        let mut reported = 0;
        while let Some(chunk) = recv.read_chunk(MAX_SNAPSHOT_BYTES, true).await? {
            if bytes.len() + chunk.bytes.len() > MAX_SNAPSHOT_BYTES {
                return Err(FetchFailure::Refused(format!(
                    "over {MAX_SNAPSHOT_BYTES} bytes"
                )));
            }
            bytes.extend_from_slice(&chunk.bytes);
            let n = bytes.len() as u64;
            if n >= reported + SNAPSHOT_PROGRESS_BYTES {
                reported = n;
                let progress = Input::SnapshotProgress { conn, bytes: n };
                let _ = shared.inputs.send(progress).await;
            }
        }
        Ok(bytes)
    };
    let deadline = Duration::from_millis(SNAPSHOT_FETCH_TIMEOUT_MILLIS);
    let result = (tokio::time::timeout(deadline, reading).await).unwrap_or_else(|_| {
        Err(FetchFailure::Refused(format!(
            "not in {SNAPSHOT_FETCH_TIMEOUT_MILLIS} ms"
        )))
    });
    let _ = (shared.inputs)
        .send(Input::SnapshotFetched { conn, result })
        .await;
}

/// Reads a connection's snapshot requests (at most [`MAX_SNAPSHOTS_SERVED_PER_CONN`]) and
/// hands each to the core, which answers on its stream.
pub(super) async fn serve_requests(
    shared: Arc<Shared>,
    conn: ConnId,
    connection: quinn::Connection,
) {
    for _ in 0..MAX_SNAPSHOTS_SERVED_PER_CONN {
        let Ok((send, mut recv)) = connection.accept_bi().await else {
            return;
        };
        let deadline = Duration::from_millis(REQUEST_TIMEOUT_MILLIS);
        let request = tokio::time::timeout(deadline, recv.read_to_end(MAX_SNAPSHOT_REQUEST_BYTES));
        match request.await {
            Ok(Ok(bytes)) if bytes == SNAPSHOT_REQUEST => {
                let input = Input::SnapshotRequest { conn, send };
                if shared.inputs.send(input).await.is_err() {
                    return;
                }
            }
            // Not a request this build knows: answered with nothing.
            _ => drop(send),
        }
    }
}

/// Writes a snapshot (or, for `None`, nothing) and finishes the stream.
async fn send_snapshot(mut send: quinn::SendStream, bytes: Option<Arc<Vec<u8>>>) {
    if let Some(bytes) = bytes {
        let deadline = Duration::from_millis(SNAPSHOT_FETCH_TIMEOUT_MILLIS);
        match tokio::time::timeout(deadline, send.write_all(&bytes)).await {
            Ok(Ok(())) => {}
            _ => {
                let _ = send.reset(quinn::VarInt::from_u32(0));
                return;
            }
        }
    }
    let _ = send.finish();
}
