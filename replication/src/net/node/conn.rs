//! The node's connection tasks: the accept loop, dialing, admission, and per connection a
//! frame reader, a datagram reader and a frame writer. They move bytes; every decision is
//! taken by the core task.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use tokio::sync::mpsc;

use super::{CloseCode, Input, MAX_ADMISSIONS_IN_PROGRESS, RefusalKind, Shared};
use crate::net::admission::{self, AdmissionError, Admitted, Role};
use crate::net::frame::{self, FrameError};
use crate::net::tls::SERVER_NAME;
use crate::peer::ConnId;

impl Shared {
    pub(super) fn next_conn_id(&self) -> ConnId {
        ConnId(self.next_conn.fetch_add(1, Ordering::Relaxed))
    }

    async fn report_failure(&self, conn: Option<ConnId>, addr: SocketAddr, error: AdmissionError) {
        let kind = RefusalKind::from(&error);
        // The core task only goes away when the node stops; then nobody needs the news.
        let _ = self
            .inputs
            .send(Input::AdmissionFailed {
                conn,
                addr,
                error,
                kind,
            })
            .await;
    }
}

/// Holds one of the [`MAX_ADMISSIONS_IN_PROGRESS`] slots until dropped.
struct AdmissionSlot(Arc<Shared>);

impl Drop for AdmissionSlot {
    fn drop(&mut self) {
        self.0
            .admissions_in_progress
            .fetch_sub(1, Ordering::Relaxed);
    }
}

/// Accepts incoming connections until the endpoint closes.
pub(super) async fn accept_loop(endpoint: quinn::Endpoint, shared: Arc<Shared>) {
    while let Some(incoming) = endpoint.accept().await {
        let addr = incoming.remote_address();
        let in_progress = shared
            .admissions_in_progress
            .fetch_add(1, Ordering::Relaxed);
        let slot = AdmissionSlot(shared.clone());
        if in_progress >= MAX_ADMISSIONS_IN_PROGRESS {
            incoming.refuse();
            drop(slot);
            // Never block the accept loop on a busy core: a lost count is better.
            let _ = shared.inputs.try_send(Input::AdmissionFailed {
                conn: None,
                addr,
                error: AdmissionError::Connection("too many admissions in progress".into()),
                kind: RefusalKind::Busy,
            });
            continue;
        }
        tokio::spawn(accept_one(shared.clone(), incoming, slot));
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
    let outcome = tokio::time::timeout(admission::admission_timeout(), attempt).await;
    drop(slot);
    match outcome {
        Ok(Ok((connection, admitted))) => {
            let conn = shared.next_conn_id();
            run_connection(shared, conn, Role::Acceptor, connection, admitted).await;
        }
        Ok(Err(error)) => shared.report_failure(None, addr, error).await,
        Err(_) => {
            shared
                .report_failure(None, addr, AdmissionError::Timeout)
                .await
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

/// Hands an admitted connection to the core task, then reads its frames until it ends.
async fn run_connection(
    shared: Arc<Shared>,
    conn: ConnId,
    role: Role,
    connection: quinn::Connection,
    admitted: Admitted,
) {
    let Admitted { peer, send, recv } = admitted;
    let admitted = Input::Admitted {
        conn,
        role,
        connection: connection.clone(),
        peer,
        send,
    };
    // The core hears of the connection before any of its frames or datagrams (one sender,
    // FIFO; the datagram task starts after this send).
    if shared.inputs.send(admitted).await.is_err() {
        return;
    }
    tokio::spawn(read_datagrams(shared.clone(), conn, connection.clone()));
    read_frames(shared, conn, connection, recv).await;
}

async fn read_frames(
    shared: Arc<Shared>,
    conn: ConnId,
    connection: quinn::Connection,
    mut recv: quinn::RecvStream,
) {
    let end = loop {
        match frame::read_frame(&mut recv).await {
            Ok(Some(bytes)) => {
                if shared
                    .inputs
                    .send(Input::Frame { conn, bytes })
                    .await
                    .is_err()
                {
                    return;
                }
            }
            Ok(None) => {
                break Input::Lost {
                    conn,
                    reason: "the remote finished the sync stream".into(),
                };
            }
            Err(FrameError::TooLarge(len)) => {
                connection.close(CloseCode::Protocol.var_int(), b"frame too large");
                break Input::OversizedFrame { conn, len };
            }
            Err(e) => {
                break Input::Lost {
                    conn,
                    reason: e.to_string(),
                };
            }
        }
    };
    let _ = shared.inputs.send(end).await;
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

/// Writes the frames the core task queues for one connection, in order, until the core
/// drops the queue (the connection is over) or the stream fails.
pub(super) async fn write_frames(mut send: quinn::SendStream, mut frames: mpsc::Receiver<Vec<u8>>) {
    while let Some(body) = frames.recv().await {
        if frame::write_frame(&mut send, &body).await.is_err() {
            return;
        }
    }
    // Already finished or reset when the connection is gone: nothing more to do.
    let _ = send.finish();
}
