//! The node's connection tasks: the accept loop, dialing, admission, and per connection a
//! frame reader, a datagram reader and a frame writer. They move bytes; every decision is
//! taken by the core task.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::{Arc, MutexGuard, PoisonError};
use std::time::Duration;

use tokio::sync::mpsc;

use super::{
    ACCEPT_TIMEOUT_MILLIS, CloseCode, Counters, Input, MAX_ADMISSIONS_IN_PROGRESS,
    MAX_ADMISSIONS_IN_PROGRESS_PER_ADDRESS, MAX_CONNECTIONS_PER_ADDRESS, MAX_FRAMES_READ_AT_ONCE,
    RefusalKind, Shared,
};
use crate::net::admission::{self, AdmissionError, Admitted, Role};
use crate::net::frame::{self, FrameError};
use crate::net::prefix::AddressPrefix;
use crate::net::tls::SERVER_NAME;
use crate::peer::ConnId;

impl Shared {
    pub(super) fn next_conn_id(&self) -> ConnId {
        ConnId(self.next_conn.fetch_add(1, Ordering::Relaxed))
    }

    async fn report_failure(&self, conn: Option<ConnId>, addr: SocketAddr, error: AdmissionError) {
        let input = match RefusalKind::of(&error) {
            Some(kind) => Input::AdmissionFailed {
                conn,
                addr,
                error,
                kind,
            },
            None => Input::Superseded { conn, addr },
        };
        // The core task only goes away when the node stops; then nobody needs the news.
        let _ = self.inputs.send(input).await;
    }
}

/// What the accepting side holds: connections in admission, in all and by source address,
/// and admitted connections by source address.
#[derive(Debug, Default)]
pub(super) struct AcceptLoad {
    n_admitting: usize,
    /// An entry goes when both of its counts are zero, so there are at most as many as
    /// accepted connections alive.
    per_address: BTreeMap<AddressPrefix, AddressLoad>,
}

/// What one source address holds of the accepting side.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct AddressLoad {
    n_admitting: usize,
    n_admitted: usize,
}

impl AcceptLoad {
    /// Takes an admission slot for `prefix`, or says which limit is reached.
    fn reserve(&mut self, prefix: AddressPrefix) -> Result<(), RefusalKind> {
        if self.n_admitting >= MAX_ADMISSIONS_IN_PROGRESS {
            return Err(RefusalKind::Busy);
        }
        let load = self.per_address.entry(prefix).or_default();
        let full = load.n_admitting >= MAX_ADMISSIONS_IN_PROGRESS_PER_ADDRESS
            || load.n_admitting + load.n_admitted >= MAX_CONNECTIONS_PER_ADDRESS;
        if full {
            self.forget_if_idle(prefix);
            return Err(RefusalKind::AddressBusy);
        }
        load.n_admitting += 1;
        self.n_admitting += 1;
        Ok(())
    }

    /// Ends an admission of `prefix`; when `admitted`, the connection goes on counting
    /// against its address until [`AcceptLoad::release_admitted`].
    fn end_admission(&mut self, prefix: AddressPrefix, admitted: bool) {
        self.n_admitting -= 1;
        let load = self.per_address.entry(prefix).or_default();
        load.n_admitting -= 1;
        if admitted {
            load.n_admitted += 1;
        }
        self.forget_if_idle(prefix);
    }

    fn release_admitted(&mut self, prefix: AddressPrefix) {
        let load = self.per_address.entry(prefix).or_default();
        load.n_admitted -= 1;
        self.forget_if_idle(prefix);
    }

    fn forget_if_idle(&mut self, prefix: AddressPrefix) {
        if self.per_address.get(&prefix) == Some(&AddressLoad::default()) {
            self.per_address.remove(&prefix);
        }
    }
}

impl Shared {
    fn accepting(&self) -> MutexGuard<'_, AcceptLoad> {
        // The counts stay consistent whatever panicked while holding the lock: every change
        // is one step.
        self.accepting
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

/// Holds one admission slot of an address until dropped or turned into a
/// [`ConnectionSlot`].
struct AdmissionSlot {
    shared: Arc<Shared>,
    prefix: AddressPrefix,
    /// Set once [`AdmissionSlot::admitted`] has handed the slot on.
    done: bool,
}

impl AdmissionSlot {
    fn reserve(shared: &Arc<Shared>, prefix: AddressPrefix) -> Result<Self, RefusalKind> {
        shared.accepting().reserve(prefix)?;
        Ok(Self {
            shared: shared.clone(),
            prefix,
            done: false,
        })
    }

    /// The connection is admitted: it keeps counting against its address while it lives.
    fn admitted(mut self) -> ConnectionSlot {
        self.done = true;
        self.shared.accepting().end_admission(self.prefix, true);
        ConnectionSlot {
            shared: self.shared.clone(),
            prefix: self.prefix,
        }
    }
}

impl Drop for AdmissionSlot {
    fn drop(&mut self) {
        if !self.done {
            self.shared.accepting().end_admission(self.prefix, false);
        }
    }
}

/// One of an address's [`MAX_CONNECTIONS_PER_ADDRESS`], held while an accepted connection
/// lives.
struct ConnectionSlot {
    shared: Arc<Shared>,
    prefix: AddressPrefix,
}

impl Drop for ConnectionSlot {
    fn drop(&mut self) {
        self.shared.accepting().release_admitted(self.prefix);
    }
}

/// Accepts incoming connections until the endpoint closes.
///
/// A first packet whose source address is not validated yet is answered with a stateless
/// retry: the node keeps nothing, and a dialer that really sends from that address echoes
/// the token at the cost of one round trip. Only a validated attempt takes an admission slot
/// and counts against its address, so a spoofer cannot use up a victim's share, and a source
/// that never completes holds its slots for at most [`ACCEPT_TIMEOUT_MILLIS`].
pub(super) async fn accept_loop(endpoint: quinn::Endpoint, shared: Arc<Shared>) {
    while let Some(incoming) = endpoint.accept().await {
        let addr = incoming.remote_address();
        if !incoming.remote_address_validated() {
            match incoming.retry() {
                Ok(()) => Counters::add(&shared.counters.n_retries),
                // Only a validated attempt cannot be retried, which was checked above.
                Err(refused) => refused.into_incoming().ignore(),
            }
            continue;
        }
        match AdmissionSlot::reserve(&shared, AddressPrefix::of(addr.ip())) {
            Ok(slot) => {
                tokio::spawn(accept_one(shared.clone(), incoming, slot));
            }
            Err(kind) => {
                incoming.refuse();
                let reason = match kind {
                    RefusalKind::Busy => "too many admissions in progress",
                    _ => "too many connections from this address",
                };
                // Never block the accept loop on a busy core: a lost count is better.
                let _ = shared.inputs.try_send(Input::AdmissionFailed {
                    conn: None,
                    addr,
                    error: AdmissionError::Connection(reason.into()),
                    kind,
                });
            }
        }
    }
}

async fn accept_one(shared: Arc<Shared>, incoming: quinn::Incoming, slot: AdmissionSlot) {
    let addr = incoming.remote_address();
    let attempt = async {
        let connection = incoming
            .await
            .map_err(|e| AdmissionError::Connection(e.to_string()))?;
        match admission::admit_acceptor(&connection, &shared.keys, &shared.keypair).await {
            Ok(admitted) => Ok((connection, admitted)),
            Err(e) => {
                connection.close(CloseCode::Refused.var_int(), e.to_string().as_bytes());
                Err(e)
            }
        }
    };
    let deadline = Duration::from_millis(ACCEPT_TIMEOUT_MILLIS);
    let outcome = tokio::time::timeout(deadline, attempt).await;
    match outcome {
        Ok(Ok((connection, admitted))) => {
            let _slot = slot.admitted();
            let conn = shared.next_conn_id();
            run_connection(shared, conn, Role::Acceptor, connection, admitted).await;
        }
        Ok(Err(error)) => {
            drop(slot);
            shared.report_failure(None, addr, error).await;
        }
        Err(_) => {
            drop(slot);
            shared
                .report_failure(None, addr, AdmissionError::Timeout)
                .await;
        }
    }
}

/// Dials `addr` as connection `conn`; the core task answers the dial when it hears back.
/// The QUIC handshake may take `handshake_timeout`, the whole admission
/// [`admission::admission_timeout`].
pub(super) async fn dial(
    shared: Arc<Shared>,
    endpoint: quinn::Endpoint,
    conn: ConnId,
    addr: SocketAddr,
    handshake_timeout: Duration,
) {
    let attempt = async {
        let connecting = endpoint
            .connect(addr, SERVER_NAME)
            .map_err(|e| AdmissionError::Connection(e.to_string()))?;
        // Dropping an unfinished handshake abandons it; a punch then starts a fresh one.
        let connection = tokio::time::timeout(handshake_timeout, connecting)
            .await
            .map_err(|_| AdmissionError::Timeout)?
            .map_err(|e| AdmissionError::Connection(e.to_string()))?;
        match admission::admit_dialer(&connection, &shared.keys, &shared.keypair).await {
            Ok(admitted) => Ok((connection, admitted)),
            Err(e) => {
                connection.close(CloseCode::Refused.var_int(), e.to_string().as_bytes());
                Err(e)
            }
        }
    };
    match tokio::time::timeout(admission::admission_timeout(), attempt).await {
        Ok(Ok((connection, admitted))) => {
            run_connection(shared, conn, Role::Dialer, connection, admitted).await;
        }
        Ok(Err(error)) => shared.report_failure(Some(conn), addr, error).await,
        Err(_) => {
            shared
                .report_failure(Some(conn), addr, AdmissionError::Timeout)
                .await;
        }
    }
}

/// Hands an admitted connection to the core task, answers its snapshot requests, and once
/// the core starts it (at once, or after a join from a snapshot) reads its frames until it
/// ends.
async fn run_connection(
    shared: Arc<Shared>,
    conn: ConnId,
    role: Role,
    connection: quinn::Connection,
    admitted: Admitted,
) {
    let Admitted { peer, send, recv } = admitted;
    let (start, started) = tokio::sync::oneshot::channel();
    let admitted = Input::Admitted {
        conn,
        role,
        connection: connection.clone(),
        peer,
        send,
        start,
    };
    // The core hears of the connection before any of its frames or datagrams (one sender,
    // FIFO; the readers start after this send).
    if shared.inputs.send(admitted).await.is_err() {
        return;
    }
    tokio::spawn(super::join::serve_requests(
        shared.clone(),
        conn,
        connection.clone(),
    ));
    // Until started, the remote's frames wait in QUIC's flow-control window. A connection
    // that is lost meanwhile is reported by its reader all the same.
    let lost = tokio::select! {
        started = started => started.is_err(),
        reason = connection.closed() => {
            let _ = shared.inputs.send(Input::Lost { conn, reason: reason.to_string() }).await;
            return;
        }
    };
    if lost {
        // The core dropped the connection before starting it.
        return;
    }
    tokio::spawn(read_datagrams(shared.clone(), conn, connection.clone()));
    read_frames(shared, conn, connection, recv).await;
}

/// Reads the remote's sync frames: the first (its hello) on the admission's stream
/// (`lifeline`), so that nothing overtakes it, then each on a unidirectional stream of its
/// own, up to [`MAX_FRAMES_READ_AT_ONCE`] streams at a time, each handed to the core task as
/// soon as it is whole: a stream waiting for a lost packet holds up no other. The admission's
/// stream carries nothing more; the remote finishing it ends the connection.
async fn read_frames(
    shared: Arc<Shared>,
    conn: ConnId,
    connection: quinn::Connection,
    mut lifeline: quinn::RecvStream,
) {
    let end = match frame::read_frame(&mut lifeline).await {
        Ok(Some(bytes)) => {
            if shared
                .inputs
                .send(Input::Frame { conn, bytes })
                .await
                .is_err()
            {
                return;
            }
            read_streams(&shared, conn, &connection, lifeline).await
        }
        Ok(None) => Input::Lost {
            conn,
            reason: "the remote finished the admission stream".into(),
        },
        Err(e) => frame_error(conn, &connection, e),
    };
    let _ = shared.inputs.send(end).await;
}

/// The frames after the first, each on a stream of its own, until the connection ends: what
/// ended it.
async fn read_streams(
    shared: &Shared,
    conn: ConnId,
    connection: &quinn::Connection,
    mut lifeline: quinn::RecvStream,
) -> Input {
    let mut reads = tokio::task::JoinSet::new();
    let mut byte = [0; 1];
    let ended = lifeline.read(&mut byte);
    tokio::pin!(ended);
    loop {
        let read = tokio::select! {
            stream = connection.accept_uni(), if reads.len() < MAX_FRAMES_READ_AT_ONCE => {
                match stream {
                    Ok(stream) => {
                        reads.spawn(frame::read_one_frame(stream));
                        continue;
                    }
                    Err(e) => return Input::Lost { conn, reason: e.to_string() },
                }
            }
            Some(read) = reads.join_next() => read,
            ended = &mut ended => {
                let reason = match ended {
                    Ok(None) => "the remote finished the admission stream".into(),
                    Ok(Some(_)) => {
                        connection.close(CloseCode::Protocol.var_int(), b"bytes after the hello");
                        "the remote wrote on the admission stream after its hello".into()
                    }
                    Err(e) => e.to_string(),
                };
                return Input::Lost { conn, reason };
            }
        };
        match read {
            Ok(Ok(bytes)) => {
                if shared
                    .inputs
                    .send(Input::Frame { conn, bytes })
                    .await
                    .is_err()
                {
                    return Input::Lost {
                        conn,
                        reason: "the node stopped".into(),
                    };
                }
            }
            Ok(Err(
                e @ (FrameError::TooLarge(_) | FrameError::Trailing | FrameError::Truncated),
            )) => {
                return frame_error(conn, connection, e);
            }
            // A stream that failed: the connection's end, if that is what it was, shows at
            // the next accept.
            Ok(Err(_)) => {}
            // The read panicked (it does not) or was cancelled (the loop owns the set).
            Err(e) => {
                return Input::Lost {
                    conn,
                    reason: e.to_string(),
                };
            }
        }
    }
}

/// What ends a connection whose remote sent a bad frame (too large, cut short by the end of
/// its stream, or followed by more bytes), or whose stream failed.
fn frame_error(conn: ConnId, connection: &quinn::Connection, error: FrameError) -> Input {
    match error {
        FrameError::TooLarge(len) => {
            connection.close(CloseCode::Protocol.var_int(), b"frame too large");
            Input::OversizedFrame { conn, len }
        }
        FrameError::Trailing | FrameError::Truncated => {
            connection.close(
                CloseCode::Protocol.var_int(),
                b"a stream that is not one frame",
            );
            Input::Lost {
                conn,
                reason: error.to_string(),
            }
        }
        e => Input::Lost {
            conn,
            reason: e.to_string(),
        },
    }
}

async fn read_datagrams(shared: Arc<Shared>, conn: ConnId, connection: quinn::Connection) {
    // Ends with the connection; the frame reader reports the loss.
    while let Ok(bytes) = connection.read_datagram().await {
        let input = Input::Datagram {
            conn,
            bytes: bytes.to_vec(),
        };
        if shared.inputs.send(input).await.is_err() {
            return;
        }
    }
}

/// Writes the frames the core task queues for one connection, in order: the first (the hello)
/// on the admission's stream `lifeline`, each later one on a new unidirectional stream, until
/// the core drops the queue (the connection is over: `lifeline` is finished) or the
/// connection fails.
pub(super) async fn write_frames(
    connection: quinn::Connection,
    mut lifeline: quinn::SendStream,
    mut frames: mpsc::Receiver<Vec<u8>>,
) {
    let mut first = true;
    while let Some(body) = frames.recv().await {
        let written = if first {
            frame::write_frame(&mut lifeline, &body).await
        } else {
            frame::write_one_frame(&connection, &body).await
        };
        if written.is_err() {
            return;
        }
        first = false;
    }
    // Already finished or reset when the connection is gone: nothing more to do.
    let _ = lifeline.finish();
}
