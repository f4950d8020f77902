//! A measured catch-up over real loopback QUIC: a node that holds N ops, a second empty node
//! dials it, and we time until the first node's sync reports that the second acknowledged
//! everything. The same catch-up between two in-memory peers (the sans-IO core with no
//! sockets, same signature checks) runs first as the baseline, and the test prints both,
//! their ratio, and the bytes on the wire.
//!
//! The recorded figure (N = 10 000) comes from a release build:
//! `cargo test --release -p replication --test net_catchup -- --nocapture`; set
//! `NET_CATCHUP_OPS` for another N (at most [`MAX_MEASURED_OPS`]). A debug build runs the
//! same path with N = 32, because unoptimised ed25519 verification manages only about 40 ops
//! per second.

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use net_support::*;
use replication::net::node::NodeEvent;
use replication::payload::test_payload::TestPayload;
use replication::{ConnId, Keypair, Log, Peer, Timestamp};

#[expect(
    clippy::disallowed_methods,
    reason = "a measurement reads the wall clock"
)]
fn stopwatch() -> Instant {
    Instant::now()
}

#[expect(
    clippy::disallowed_methods,
    reason = "the in-memory baseline paces by the wall clock"
)]
fn wall_now() -> Timestamp {
    let micros = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_micros();
    Timestamp(micros as u64)
}

/// N chat ops of about 60 bytes of text each, authored by one peer.
fn authored_log(n_ops: usize) -> Log<TestPayload> {
    let alice = Keypair::from_seed([1; 32]);
    let mut log = Log::default();
    log.set_session_id(session_keys(INVITE).session_id());
    for op_idx in 0..n_ops {
        let text = format!("op {op_idx:06}: a line of a sculpting session's chat history");
        log.author(
            &alice,
            Timestamp(1_000 + op_idx as u64),
            TestPayload::Chat(text),
        )
        .unwrap();
    }
    log
}

/// The baseline: the same sync between two in-memory peers, bytes moved by direct calls.
/// Returns the time and the sync bytes sent by the holder.
fn in_memory_catch_up(log: Log<TestPayload>) -> (Duration, u64) {
    let n_ops = log.len();
    let session = session_keys(INVITE).session_id();
    let mut a = Peer::new(Keypair::from_seed([1; 32]), session, log);
    let mut b = Peer::<TestPayload>::new(Keypair::from_seed([2; 32]), session, Log::default());
    let start = stopwatch();
    a.connect(wall_now(), ConnId(1)).unwrap();
    b.connect(wall_now(), ConnId(1)).unwrap();
    let deadline = start + PATIENCE;
    while b.log().len() < n_ops {
        assert!(stopwatch() < deadline, "the in-memory sync stalled");
        let now = wall_now();
        a.handle_timeout(now);
        b.handle_timeout(now);
        while let Some((conn, bytes)) = a.poll_transmit(now) {
            b.handle_input(now, conn, &bytes);
        }
        while let Some((conn, bytes)) = b.poll_transmit(now) {
            a.handle_input(now, conn, &bytes);
        }
        while a.poll_event().is_some() || b.poll_event().is_some() {}
    }
    let elapsed = start.elapsed();
    let bytes_out = a.connections().map(|(_, s)| s.stats().n_bytes_out).sum();
    (elapsed, bytes_out)
}

struct QuicFigures {
    elapsed: Duration,
    sync_bytes_out: u64,
    udp_bytes_total: u64,
}

/// Starts the holder node on its own thread and runtime, as a separate process would run
/// it, so that the holder's and the newcomer's core tasks use both cores.
fn spawn_holder(log: Log<TestPayload>) -> (TNode, tokio::sync::oneshot::Sender<()>) {
    let (node_tx, node_rx) = std::sync::mpsc::channel();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    std::thread::Builder::new()
        .name("holder-node".into())
        .spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            runtime.block_on(async {
                node_tx.send(node_with(1, INVITE, log)).unwrap();
                // Keep the runtime (and the node's tasks) alive until the test is done.
                let _ = stop_rx.await;
            });
        })
        .unwrap();
    (node_rx.recv().unwrap(), stop_tx)
}

async fn quic_catch_up(mut a: TNode, n_ops: usize) -> QuicFigures {
    let b = node(2);
    let start = stopwatch();
    b.handle.dial(a.handle.local_addr()).await.unwrap();
    // The holder's sync says "up to date" once the newcomer acknowledged every op.
    next_event(
        &mut a.events,
        "the newcomer to acknowledge everything",
        |e| matches!(e, NodeEvent::UpToDate { .. }).then_some(()),
    )
    .await;
    let elapsed = start.elapsed();
    assert_eq!(net_support::n_ops(&b.handle).await, n_ops);
    assert_eq!(op_ids(&b.handle).await, op_ids(&a.handle).await);
    let stats = a.handle.stats().await.unwrap();
    let conn = &stats.connections[0];
    assert_eq!(conn.sync.n_rejected(), 0);
    QuicFigures {
        elapsed,
        sync_bytes_out: conn.sync.n_bytes_out,
        udp_bytes_total: conn.udp_bytes_sent + conn.udp_bytes_received,
    }
}

/// The most ops `NET_CATCHUP_OPS` may ask for.
const MAX_MEASURED_OPS: usize = 1_000_000;

/// How many ops a release build measures: `NET_CATCHUP_OPS`, else 10 000.
fn measured_ops() -> usize {
    let asked = std::env::var("NET_CATCHUP_OPS").ok();
    asked
        .map_or(10_000, |n| {
            n.parse::<usize>().expect("NET_CATCHUP_OPS is a count")
        })
        .clamp(1, MAX_MEASURED_OPS)
}

#[test]
fn a_second_node_catches_up_over_loopback_quic() {
    let n_ops = if cfg!(debug_assertions) {
        32
    } else {
        measured_ops()
    };
    let log = authored_log(n_ops);
    let op_bytes: u64 = log.entries().map(|e| e.op.encoded().len() as u64).sum();
    let (baseline, baseline_bytes) = in_memory_catch_up(log.clone());
    let (holder, stop_holder) = spawn_holder(log);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let quic = runtime.block_on(quic_catch_up(holder, n_ops));
    let _ = stop_holder.send(());
    let ratio = quic.elapsed.as_secs_f64() / baseline.as_secs_f64();
    println!(
        "net_catchup: {n_ops} ops ({op_bytes} bytes of ops): loopback QUIC {:.1} ms, \
         in-memory sans-IO {:.1} ms, ratio {ratio:.2}; sync bytes sent {} (in-memory {}); \
         UDP bytes both ways {} ({:.3} per sync byte)",
        quic.elapsed.as_secs_f64() * 1e3,
        baseline.as_secs_f64() * 1e3,
        quic.sync_bytes_out,
        baseline_bytes,
        quic.udp_bytes_total,
        quic.udp_bytes_total as f64 / quic.sync_bytes_out as f64,
    );
    // The wire carries at least the sync messages, which carry at least the ops. (A batch
    // whose ack takes over a second, as in a loaded debug build, is sent again by design, so
    // the sync bytes have no upper bound here.)
    assert!(quic.udp_bytes_total > quic.sync_bytes_out);
    assert!(quic.sync_bytes_out >= op_bytes);
}
