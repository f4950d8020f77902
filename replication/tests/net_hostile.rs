//! Hostile clients against a node over real QUIC on 127.0.0.1: garbage admission, garbage
//! frames, an oversized frame and stray datagrams are cut off and counted, while an honest
//! node keeps syncing with the same node. Attackers that hold connection slots send from
//! 127.0.0.2 (Linux routes all of 127/8 to loopback), honest nodes from 127.0.0.1.

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::time::Duration;

use net_support::*;
use replication::net::admission::{self, ADMISSION_FRAME_BYTES, ADMISSION_TIMEOUT_MILLIS};
use replication::net::frame::{self, MAX_FRAME_BYTES};
use replication::net::node::{
    ACCEPT_TIMEOUT_MILLIS, CloseCode, MAX_ADMISSIONS_IN_PROGRESS,
    MAX_ADMISSIONS_IN_PROGRESS_PER_ADDRESS, MAX_CONNECTIONS_PER_ADDRESS, MAX_REJECTIONS_PER_CONN,
    RefusalKind,
};
use replication::net::tls;
use replication::payload::test_payload::TestPayload;
use replication::peer::MAX_CONNECTIONS;
use replication::sync::message::{Message, PROTOCOL_VERSION};
use replication::sync::state::MAX_EARLY_MESSAGES;
use replication::{Keypair, OpId};

/// Where attackers send from: another loopback address than the honest nodes' 127.0.0.1.
const ATTACKER_IP: &str = "127.0.0.2";

/// A raw QUIC connection to `addr` that has passed the TLS handshake only.
async fn raw_connection(addr: SocketAddr) -> quinn::Connection {
    raw_connection_from("127.0.0.1", addr).await.unwrap()
}

/// A QUIC client endpoint on `ip`, any port.
fn client_endpoint(ip: &str) -> quinn::Endpoint {
    quinn::Endpoint::client(SocketAddr::new(ip.parse().unwrap(), 0)).unwrap()
}

/// A raw QUIC connection from `ip` to `addr`: the TLS handshake only, or why it failed.
async fn raw_connection_from(
    ip: &str,
    addr: SocketAddr,
) -> Result<quinn::Connection, quinn::ConnectionError> {
    connect(&client_endpoint(ip), addr).await
}

async fn connect(
    endpoint: &quinn::Endpoint,
    addr: SocketAddr,
) -> Result<quinn::Connection, quinn::ConnectionError> {
    endpoint
        .connect_with(tls::client_config().unwrap(), addr, tls::SERVER_NAME)
        .unwrap()
        .await
}

/// `n` QUIC Initial packets with distinct connection ids, as a real client sends them first:
/// captured by a plain UDP socket standing in for a server, to be replayed at a node by a
/// sender that never answers (half-open connections).
async fn initial_packets(n: usize) -> Vec<Vec<u8>> {
    let sink = tokio::net::UdpSocket::bind((ATTACKER_IP, 0)).await.unwrap();
    let endpoint = client_endpoint(ATTACKER_IP);
    let config = tls::client_config().unwrap();
    let connecting: Vec<_> = (0..n)
        .map(|_| {
            endpoint
                .connect_with(config.clone(), sink.local_addr().unwrap(), tls::SERVER_NAME)
                .unwrap()
        })
        .collect();
    let mut seen = BTreeSet::new();
    let mut packets = Vec::new();
    let mut buf = vec![0; 2048];
    while packets.len() < n {
        let (len, _) = tokio::time::timeout(PATIENCE, sink.recv_from(&mut buf))
            .await
            .expect("the client sends its Initial packets")
            .unwrap();
        // Long header: flags, version (4), destination connection id length, the id.
        let dcid_len = usize::from(buf[5]);
        if seen.insert(buf[6..6 + dcid_len].to_vec()) {
            packets.push(buf[..len].to_vec());
        }
    }
    drop(connecting);
    packets
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

    // 2. Admitted, then a datagram that is no ephemeral message and frames of garbage: the
    // first on the admission's stream, where the hello goes, the others on streams of their
    // own.
    let (garbler, mut garbage) = admitted(addr, 66).await;
    garbler.send_datagram(vec![0xff; 40].into()).unwrap();
    eventually("the stray datagram is counted", || async {
        a.handle.stats().await.unwrap().n_bad_datagrams == 1
    })
    .await;
    frame::write_frame(&mut garbage.send, &[0xee; 99])
        .await
        .unwrap();
    for i in 0..MAX_REJECTIONS_PER_CONN + 8 {
        let noise = vec![i as u8; 100 + i as usize];
        if frame::write_one_frame(&garbler, &noise).await.is_err() {
            break; // Already cut off.
        }
    }
    assert_eq!(closed_code(&garbler).await, CloseCode::Protocol as u64);

    // 3. Admitted, then a frame header announcing 4 GiB, as the first frame and as a later
    // one on a stream of its own.
    let (bloater, mut bloat) = admitted(addr, 67).await;
    bloat.send.write_all(&u32::MAX.to_be_bytes()).await.unwrap();
    assert_eq!(closed_code(&bloater).await, CloseCode::Protocol as u64);
    let (bloater, mut bloat) = admitted(addr, 75).await;
    frame::write_frame(&mut bloat.send, b"hi").await.unwrap();
    let mut stream = bloater.open_uni().await.unwrap();
    stream.write_all(&u32::MAX.to_be_bytes()).await.unwrap();
    assert_eq!(closed_code(&bloater).await, CloseCode::Protocol as u64);

    // 4. Admitted, then a second frame on the admission's stream, which carries only the
    // first, a frame followed by more bytes on one stream, and a frame cut short by the end
    // of its stream.
    let (writer, mut admission) = admitted(addr, 72).await;
    for body in [b"first", b"later"] {
        frame::write_frame(&mut admission.send, body).await.unwrap();
    }
    assert_eq!(closed_code(&writer).await, CloseCode::Protocol as u64);
    let (trailer, mut admission) = admitted(addr, 73).await;
    frame::write_frame(&mut admission.send, b"first")
        .await
        .unwrap();
    let mut stream = trailer.open_uni().await.unwrap();
    let trailing = [frame::encode_frame(b"one").unwrap(), vec![0; 3]].concat();
    stream.write_all(&trailing).await.unwrap();
    let _ = stream.finish();
    assert_eq!(closed_code(&trailer).await, CloseCode::Protocol as u64);
    let (cutter, mut admission) = admitted(addr, 77).await;
    frame::write_frame(&mut admission.send, b"first")
        .await
        .unwrap();
    let mut stream = cutter.open_uni().await.unwrap();
    let cut_short = &frame::encode_frame(b"ten bytes!").unwrap()[..7];
    stream.write_all(cut_short).await.unwrap();
    let _ = stream.finish();
    assert_eq!(closed_code(&cutter).await, CloseCode::Protocol as u64);

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
    assert_eq!(stats.n_oversized_frames, 2);
    assert_eq!(stats.n_bad_datagrams, 1);
    assert_eq!(stats.n_admitted, 7);
    assert_eq!(stats.connections.len(), 1, "only the honest node is left");
    assert_eq!(stats.connections[0].peer, honest.handle.peer_id());
    assert_eq!(stats.connections[0].sync.n_rejected(), 0);
}

#[tokio::test]
async fn half_open_and_never_admitting_connections_from_one_address_leave_honest_peers_in() {
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let addr = a.handle.local_addr();
    let n_attempts = MAX_ADMISSIONS_IN_PROGRESS + 4;

    // 1. Half-open: first packets of handshakes that nobody will finish, replayed from a
    // socket that never answers. Each is answered with a stateless retry and holds nothing.
    let spoofer = std::net::UdpSocket::bind((ATTACKER_IP, 0)).unwrap();
    for packet in initial_packets(n_attempts).await {
        spoofer.send_to(&packet, addr).unwrap();
    }
    // The node reads its socket in order: the replays are handled before this dial.
    let honest = node(2);
    honest
        .handle
        .dial(addr)
        .await
        .expect("an honest dial gets in");
    converge(&[&a.handle, &honest.handle], 4).await;
    let n_retries = a.handle.stats().await.unwrap().n_retries;
    assert!(n_retries > n_attempts as u64, "{n_retries} retries");

    // 2. Never admitting: handshakes finished from 127.0.0.2, admission frames never sent.
    // That address holds at most its share of admission slots, the others are refused.
    let attacker = client_endpoint(ATTACKER_IP);
    let mut attempts = tokio::task::JoinSet::new();
    for _ in 0..n_attempts {
        let attacker = attacker.clone();
        attempts.spawn(async move { connect(&attacker, addr).await });
    }
    let mut held = Vec::new();
    while let Some(attempt) = attempts.join_next().await {
        if let Ok(connection) = attempt.unwrap() {
            held.push(connection);
        }
    }
    assert!(
        (1..=MAX_ADMISSIONS_IN_PROGRESS_PER_ADDRESS).contains(&held.len()),
        "{} of {n_attempts} never-admitting connections held a slot",
        held.len()
    );
    // Meanwhile an honest node dials and syncs.
    let late = node(3);
    late.handle
        .dial(addr)
        .await
        .expect("an honest dial gets in");
    let from_late = late
        .handle
        .author(TestPayload::Chat("made it".into()))
        .await
        .unwrap();
    converge(&[&a.handle, &honest.handle, &late.handle], 5).await;
    assert!(op_ids(&a.handle).await.contains(&from_late));
    let stats = a.handle.stats().await.unwrap();
    let n_refused = stats.failed_admissions.get(&RefusalKind::AddressBusy);
    assert!(
        n_refused >= Some(&((n_attempts - held.len()) as u64)),
        "{stats:?}"
    );
    assert_eq!(stats.failed_admissions.get(&RefusalKind::Busy), None);

    // A never-admitting connection frees its slot at the accept deadline, well before the
    // dialer's own admission timeout.
    for connection in &held {
        tokio::time::timeout(PATIENCE, connection.closed())
            .await
            .unwrap();
    }
    let idle = connect(&attacker, addr).await.unwrap();
    let opened = tokio::time::Instant::now();
    tokio::time::timeout(PATIENCE, idle.closed()).await.unwrap();
    let lasted = opened.elapsed();
    assert!(
        lasted < Duration::from_millis(ACCEPT_TIMEOUT_MILLIS + 1_000)
            && lasted < Duration::from_millis(ADMISSION_TIMEOUT_MILLIS),
        "a never-admitting connection lasted {lasted:?}"
    );
}

#[tokio::test]
async fn one_invite_holder_gets_at_most_its_address_share_of_connections() {
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let addr = a.handle.local_addr();
    let keys = session_keys(INVITE);
    // New keys, one connection each, all from one address.
    let attacker = client_endpoint(ATTACKER_IP);
    let n_identities = MAX_CONNECTIONS_PER_ADDRESS + 4;
    let mut admitted = Vec::new();
    for seed in 0..n_identities {
        let Ok(connection) = connect(&attacker, addr).await else {
            continue;
        };
        let keypair = Keypair::from_seed([100 + seed as u8; 32]);
        if let Ok(proof) = admission::admit_dialer(&connection, &keys, &keypair).await {
            admitted.push((connection, proof));
        }
    }
    assert_eq!(admitted.len(), MAX_CONNECTIONS_PER_ADDRESS);
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(
        stats.failed_admissions.get(&RefusalKind::AddressBusy),
        Some(&((n_identities - MAX_CONNECTIONS_PER_ADDRESS) as u64)),
        "{stats:?}"
    );
    // An honest peer from another address still gets in and syncs.
    let honest = node(2);
    honest
        .handle
        .dial(addr)
        .await
        .expect("an honest dial gets in");
    converge(&[&a.handle, &honest.handle], 4).await;
    // A slot of that address frees when one of its connections ends.
    let (first, _) = admitted.remove(0);
    first.close(0u32.into(), b"bye");
    eventually("the closed connection is gone", || async {
        a.handle.stats().await.unwrap().connections.len() == MAX_CONNECTIONS_PER_ADDRESS
    })
    .await;
    let again = connect(&attacker, addr).await.unwrap();
    let keypair = Keypair::from_seed([99; 32]);
    admission::admit_dialer(&again, &keys, &keypair)
        .await
        .expect("a freed slot admits again");
}

/// Issue 49: every connection slot was shared by accepted and dialed connections, and remotes
/// from eight addresses (eight connections each) held all of them, so an honest dial in was
/// refused. A newcomer now takes the slot of the least useful accepted connection.
#[tokio::test]
async fn remotes_holding_every_slot_from_eight_addresses_leave_an_honest_peer_in() {
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let addr = a.handle.local_addr();
    let keys = session_keys(INVITE);
    let mut held = Vec::new();
    for ip_idx in 0..MAX_CONNECTIONS / MAX_CONNECTIONS_PER_ADDRESS {
        let attacker = client_endpoint(&format!("127.0.0.{}", 2 + ip_idx));
        for seed in 0..MAX_CONNECTIONS_PER_ADDRESS {
            let connection = connect(&attacker, addr).await.unwrap();
            let keypair = Keypair::from_seed([(10 + ip_idx * 16 + seed) as u8; 32]);
            let proof = admission::admit_dialer(&connection, &keys, &keypair)
                .await
                .unwrap();
            held.push((connection, proof));
        }
    }
    eventually("every slot is held", || async {
        a.handle.stats().await.unwrap().connections.len() == MAX_CONNECTIONS
    })
    .await;
    // An honest peer dials in from its own address, gets a slot and syncs.
    let honest = node(2);
    honest
        .handle
        .dial(addr)
        .await
        .expect("an honest dial gets in");
    converge(&[&a.handle, &honest.handle], 4).await;
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(stats.n_evicted, 1, "{stats:?}");
    assert_eq!(stats.connections.len(), MAX_CONNECTIONS);
    // Exactly one of the attackers' connections was closed for it.
    let mut n_closed = 0;
    for (connection, _) in &held {
        if connection.close_reason().is_some() {
            n_closed += 1;
        }
    }
    assert_eq!(n_closed, 1);
}

/// Issue 49: a remote admitted under one key could send data ahead of a hello naming another
/// peer, and the node checked the hello's id only after the core had handled the hello and
/// the data it held. The core knows the admitted id now and closes first.
#[tokio::test]
async fn data_ahead_of_a_hello_naming_another_peer_is_never_handled() {
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let (impostor, mut stream) = admitted(a.handle.local_addr(), 68).await;
    let victim = Keypair::from_seed([69; 32]);
    let (id, batch) = chat_batch(&mut session_log(), &victim, "early");
    // The batch first, where the hello goes, then the hello on a stream of its own.
    frame::write_frame(&mut stream.send, &batch.encode())
        .await
        .unwrap();
    frame::write_one_frame(&impostor, &hello_from(&victim).encode())
        .await
        .unwrap();
    assert_eq!(closed_code(&impostor).await, CloseCode::Protocol as u64);
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(stats.n_identity_mismatches, 1, "{stats:?}");
    assert!(!op_ids(&a.handle).await.contains(&id));
}

/// A log in the test session.
fn session_log() -> replication::Log<TestPayload> {
    let mut log = replication::Log::default();
    log.set_session_id(session_keys(INVITE).session_id());
    log
}

/// `keypair`'s next op in `log` (a chat saying `text`), and a batch that carries it alone.
fn chat_batch(
    log: &mut replication::Log<TestPayload>,
    keypair: &Keypair,
    text: &str,
) -> (OpId, Message) {
    let n = log.len() as u64;
    let at = replication::Timestamp(1_000 + n);
    let (op, _) = log
        .author(keypair, at, TestPayload::Chat(text.into()))
        .unwrap();
    let batch = Message::Ops {
        batch_no: n + 1,
        ops: vec![op.encoded().to_vec()],
    };
    (op.op().id(), batch)
}

/// `keypair`'s hello in the test session, naming no holdings.
fn hello_from(keypair: &Keypair) -> Message {
    Message::Hello {
        protocol_version: PROTOCOL_VERSION,
        session_id: session_keys(INVITE).session_id(),
        peer: keypair.peer_id(),
        hello_seen: false,
        have: None,
    }
}

/// Each sync message travels on a stream of its own, so one whose bytes are late (a lost
/// packet, here a remote that stops halfway) holds up none sent after it.
#[tokio::test]
async fn a_message_is_taken_while_an_earlier_one_waits_for_its_bytes() {
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let (remote, mut admission) = admitted(a.handle.local_addr(), 74).await;
    let keypair = Keypair::from_seed([74; 32]);
    let (id, batch) = chat_batch(&mut session_log(), &keypair, "after the late one");
    // The hello first, on the admission's stream, then a message whose bytes stop halfway,
    // then the batch.
    frame::write_frame(&mut admission.send, &hello_from(&keypair).encode())
        .await
        .unwrap();
    let mut late = remote.open_uni().await.unwrap();
    let header = u32::try_from(MAX_FRAME_BYTES).unwrap().to_be_bytes();
    late.write_all(&[header.as_slice(), &[0; 1000]].concat())
        .await
        .unwrap();
    frame::write_one_frame(&remote, &batch.encode())
        .await
        .unwrap();
    eventually("the op behind the late message is delivered", || async {
        op_ids(&a.handle).await.contains(&id)
    })
    .await;
    // The late message's stream is still open, and nothing was refused.
    assert!(late.write_all(&[0; 10]).await.is_ok());
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(stats.n_cut_off, 0, "{stats:?}");
}

/// The hello goes first, on the admission's stream, and the node reads no other stream before
/// it: messages sent on their own streams ahead of a late hello wait in QUIC's buffers, where
/// they would otherwise overflow the core's few early messages as rejections.
#[tokio::test]
async fn nothing_overtakes_the_hello() {
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let (remote, mut admission) = admitted(a.handle.local_addr(), 76).await;
    let keypair = Keypair::from_seed([76; 32]);
    let mut log = session_log();
    let mut ids = Vec::new();
    for i in 0..2 * MAX_EARLY_MESSAGES {
        let (id, batch) = chat_batch(&mut log, &keypair, &format!("early {i}"));
        ids.push(id);
        frame::write_one_frame(&remote, &batch.encode())
            .await
            .unwrap();
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    frame::write_frame(&mut admission.send, &hello_from(&keypair).encode())
        .await
        .unwrap();
    eventually("every early batch is delivered", || async {
        let held = op_ids(&a.handle).await;
        ids.iter().all(|id| held.contains(id))
    })
    .await;
    let stats = a.handle.stats().await.unwrap();
    let conn = (stats.connections.iter())
        .find(|c| c.peer == keypair.peer_id())
        .expect("the remote is still connected");
    assert_eq!(conn.sync.n_rejected(), 0, "{:?}", conn.sync);
}

/// Asks `connection` for a snapshot with `request` on a stream of its own; the bytes that came
/// back (none when refused or declined), or `None` when no answer came within a second.
async fn ask_snapshot(connection: &quinn::Connection, request: &[u8]) -> Option<Vec<u8>> {
    let asking = async {
        let (mut send, mut recv) = connection.open_bi().await.unwrap();
        send.write_all(request).await.unwrap();
        let _ = send.finish();
        recv.read_to_end(1 << 20).await.unwrap_or_default()
    };
    tokio::time::timeout(Duration::from_secs(1), asking)
        .await
        .ok()
}

#[tokio::test]
async fn a_connection_gets_two_snapshot_requests_read_and_garbage_gets_nothing() {
    use replication::net::node::MAX_SNAPSHOTS_SERVED_PER_CONN;
    use replication::snapshot::{SNAPSHOT_FORMAT_VERSION, SNAPSHOT_MAGIC};
    let a = node(1);
    author_some(&a.handle, 1, "alice").await;
    let addr = a.handle.local_addr();
    let (asker, _sync) = admitted(addr, 71).await;
    let request = [SNAPSHOT_MAGIC.as_slice(), &[SNAPSHOT_FORMAT_VERSION]].concat();
    assert_eq!(MAX_SNAPSHOTS_SERVED_PER_CONN, 2);
    // Not a request: answered with nothing, and counted against the connection's two.
    assert_eq!(ask_snapshot(&asker, b"SCULPTSNAP?").await, Some(Vec::new()));
    // A node without a scene declines a real one.
    assert_eq!(ask_snapshot(&asker, &request).await, Some(Vec::new()));
    // A third is never read.
    assert_eq!(ask_snapshot(&asker, &request).await, None);
    let stats = a.handle.stats().await.unwrap();
    assert_eq!(
        (stats.n_snapshots_declined, stats.n_snapshots_served),
        (1, 0)
    );
    assert!(asker.close_reason().is_none(), "the connection stays up");
    // An honest peer still syncs with the node.
    let honest = node(2);
    honest.handle.dial(addr).await.unwrap();
    converge(&[&a.handle, &honest.handle], 4).await;
}
