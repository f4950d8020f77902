//! Two peers that worked apart, each with a backlog of ops the other lacks, all concurrent,
//! meet in memory: the virtual time until both hold everything, the ops each received per op
//! it lacked (what was sent again after the pending buffer dropped it), and the wall time.
//!
//! `cargo bench -p replication --bench backlogs [-- N...]`: backlogs of N ops a side (by
//! default 8,192, 16,384, 32,768 and 50,000). Time moves 1 ms a round; a run gives up after
//! 60 s of it.

use std::time::Instant;

use replication::payload::test_payload::TestPayload;
use replication::{ConnId, Keypair, Peer, Timestamp};

/// Virtual time after which a run is reported as not converged.
const MAX_VIRTUAL_MICROS: u64 = 60_000_000;

fn main() {
    let sizes: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let sizes = if sizes.is_empty() {
        vec![8_192, 16_384, 32_768, 50_000]
    } else {
        sizes
    };
    println!("| ops a side | converged after (virtual) | ops received per op lacked | wall |");
    println!("|---|---|---|---|");
    for n in sizes {
        run(n);
    }
}

/// A peer holding `n` ops of its own ([`TestPayload::backlog`]).
fn peer_with_backlog(seed: u8, n: usize) -> Peer<TestPayload> {
    let mut peer = Peer::new(Keypair::from_seed([seed; 32]), [5; 16], Default::default());
    for k in 0..n {
        let payload = TestPayload::backlog(seed, k);
        peer.author(Timestamp(k as u64 * 50), payload)
            .expect("a valid op");
    }
    peer
}

fn run(n: usize) {
    let mut peers = [peer_with_backlog(1, n), peer_with_backlog(2, n)];
    let start = n as u64 * 50;
    peers[0]
        .connect(Timestamp(start), ConnId(1))
        .expect("a slot");
    peers[1]
        .accept(Timestamp(start), ConnId(0), 7)
        .expect("a slot");
    let wall = clock();
    let mut t = start;
    while peers.iter().any(|p| p.log().len() < 2 * n) && t < start + MAX_VIRTUAL_MICROS {
        let now = Timestamp(t);
        for p in peers.iter_mut() {
            p.handle_timeout(now);
        }
        for from in 0..2 {
            while let Some((_, bytes)) = peers[from].poll_transmit(now) {
                peers[1 - from].handle_input(now, ConnId(from as u64), &bytes);
            }
        }
        for p in peers.iter_mut() {
            while p.poll_event().is_some() {}
        }
        t += 1_000;
    }
    let took = wall.elapsed().as_secs_f64();
    let received: u64 = (peers.iter())
        .flat_map(|p| p.connections().map(|(_, s)| s.stats().n_ops_in))
        .sum();
    let virtual_s = (t - start) as f64 / 1e6;
    let held = peers.iter().map(|p| p.log().len()).min().unwrap_or(0);
    let converged = if held == 2 * n {
        format!("{virtual_s:.3} s")
    } else {
        format!("not after {virtual_s:.0} s ({held} of {} held)", 2 * n)
    };
    let per_op = received as f64 / (2 * n) as f64;
    println!("| {n} | {converged} | {per_op:.2} | {took:.1} s |");
}

#[expect(
    clippy::disallowed_methods,
    reason = "a benchmark times real work on the wall clock"
)]
fn clock() -> Instant {
    Instant::now()
}
