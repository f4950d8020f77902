//! Hostile clients against a node over real QUIC on 127.0.0.1: garbage admission, garbage
//! frames, an oversized frame and stray datagrams are cut off and counted, while an honest
//! node keeps syncing with the same node.

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::net::SocketAddr;

use net_support::*;
use replication::Keypair;
use replication::net::admission::{self, ADMISSION_FRAME_BYTES};
use replication::net::node::{CloseCode, MAX_REJECTIONS_PER_CONN, RefusalKind};
use replication::net::{frame, tls};
use replication::payload::test_payload::TestPayload;

/// A raw QUIC connection to `addr` that has passed the TLS handshake only.
async fn raw_connection(addr: SocketAddr) -> quinn::Connection {
    let endpoint = quinn::Endpoint::client("127.0.0.1:0".parse().unwrap()).unwrap();
    endpoint
        .connect_with(tls::client_config().unwrap(), addr, tls::SERVER_NAME)
        .unwrap()
        .await
        .unwrap()
}

/// A raw connection admitted with the real invite under key `seed`.
async fn admitted(addr: SocketAddr, seed: u8) -> (quinn::Connection, admission::Admitted) {
    let connection = raw_connection(addr).await;
    let keys = session_keys(INVITE);
    let admitted = admission::admit_dialer(&connection, &keys, &Keypair::from_seed([seed; 32]))
        .await
        .unwrap();
    (connection, admitted)
}

/// Waits until the node closes `connection` and returns its close code.
async fn closed_code(connection: &quinn::Connection) -> u64 {
    let error = tokio::time::timeout(PATIENCE, connection.closed())
        .await
        .expect("the node closes the connection");
    match error {
        quinn::ConnectionError::ApplicationClosed(close) => close.error_code.into_inner(),
        other => panic!("unexpected close: {other}"),
    }
}

#[tokio::test]
async fn hostile_clients_are_cut_off_and_counted_while_honest_sync_continues() {
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let honest = node(2);
    honest.handle.dial(a.handle.local_addr()).await.unwrap();
    converge(&[&a.handle, &honest.handle], 4).await;
    let addr = a.handle.local_addr();

    // 1. No invite: 130 bytes of noise where the admission frame goes.
    let stranger = raw_connection(addr).await;
    let (mut send, _recv) = stranger.open_bi().await.unwrap();
    send.write_all(&[0x55; ADMISSION_FRAME_BYTES])
        .await
        .unwrap();
    assert_eq!(closed_code(&stranger).await, CloseCode::Refused as u64);

    // 2. Admitted, then a datagram that is no ephemeral message and a stream of garbage.
    let (garbler, mut garbage) = admitted(addr, 66).await;
    garbler.send_datagram(vec![0xff; 40].into()).unwrap();
    eventually("the stray datagram is counted", || async {
        a.handle.stats().await.unwrap().n_bad_datagrams == 1
    })
    .await;
    for i in 0..MAX_REJECTIONS_PER_CONN + 8 {
        let noise = vec![i as u8; 100 + i as usize];
        if frame::write_frame(&mut garbage.send, &noise).await.is_err() {
            break; // Already cut off.
        }
    }
    assert_eq!(closed_code(&garbler).await, CloseCode::Protocol as u64);

    // 3. Admitted, then a frame header announcing 4 GiB.
    let (bloater, mut bloat) = admitted(addr, 67).await;
    bloat.send.write_all(&u32::MAX.to_be_bytes()).await.unwrap();
    assert_eq!(closed_code(&bloater).await, CloseCode::Protocol as u64);

    // The honest connection survived all of it and still syncs both ways.
    let from_honest = honest
        .handle
        .author(TestPayload::Chat("still here".into()))
        .await
        .unwrap();
    a.handle
        .author(TestPayload::Chat("me too".into()))
        .await
        .unwrap();
    converge(&[&a.handle, &honest.handle], 6).await;
    assert!(op_ids(&a.handle).await.contains(&from_honest));

    let stats = a.handle.stats().await.unwrap();
    assert_eq!(
        stats.failed_admissions.get(&RefusalKind::Malformed),
        Some(&1)
    );
    assert_eq!(stats.n_cut_off, 1);
    assert_eq!(stats.n_oversized_frames, 1);
    assert_eq!(stats.n_bad_datagrams, 1);
    assert_eq!(stats.n_admitted, 3);
    assert_eq!(stats.connections.len(), 1, "only the honest node is left");
    assert_eq!(stats.connections[0].peer, honest.handle.peer_id());
    assert_eq!(stats.connections[0].sync.n_rejected(), 0);
}
