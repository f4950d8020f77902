//! What evaluating an object with a long history costs against the same object with 10 edits,
//! timed by one plain loop on the `history` bench's workload
//! (`benches/shared/history_workload.rs`): the same points and boxes, the same objects.
//!
//! The `history` bench times each size in its own run of samples, one after another, so a
//! change in the machine's speed between them (this project's shared machines swing by up to
//! two times within seconds) lands in the ratio. Here each longer history is timed in pairs
//! with the 10-edit object, round after round, and the ratio is taken within the round: the
//! median over rounds, with its spread.
//!
//! Run with `cargo run --release -p model --example history_pair [-- value|gradient|interval...]`.

use glam::DVec3;
use model::bvh::Aabb;
use model::object::Sampler;
use std::hint::black_box;

#[path = "../benches/shared/history_workload.rs"]
mod history_workload;
#[path = "../../benches/shared/timing.rs"]
mod timing;
use timing::{per_call, quantile};

/// History lengths; the first is the base of the ratios.
const EDIT_COUNTS: [usize; 4] = [10, 1_000, 10_000, 100_000];
/// Rounds; each of a pair runs once per round.
const N_ROUNDS: usize = 41;
/// Each timed batch runs at least this long.
const MIN_BATCH_SECONDS: f64 = 0.01;

/// The queries timed.
#[derive(Clone, Copy)]
enum Query {
    Value,
    Gradient,
    Interval,
}

impl Query {
    const ALL: [(&'static str, Query); 3] = [
        ("value", Query::Value),
        ("gradient", Query::Gradient),
        ("interval", Query::Interval),
    ];

    /// One pass over the workload's points (or boxes).
    fn run(self, sampler: &mut Sampler, points: &[DVec3], boxes: &[Aabb]) -> f64 {
        match self {
            Query::Value => points.iter().map(|p| sampler.value(*p, 0.0)).sum(),
            Query::Gradient => points.iter().map(|p| sampler.gradient(*p, 0.0).1.x).sum(),
            Query::Interval => boxes.iter().map(|b| sampler.interval(b, 0.0).hi).sum(),
        }
    }
}

/// Times `query` on sampler `i` and on the first (10 edits) in turns: the median seconds per
/// point of each, and the ratio of the two in each round.
fn run_pair(
    query: Query,
    samplers: &mut [Sampler],
    i: usize,
    points: &[DVec3],
    boxes: &[Aabb],
) -> ([f64; 2], Vec<f64>) {
    let pair = [0, i];
    // Warm up, and size each batch to at least `MIN_BATCH_SECONDS`.
    let calls = pair.map(|j| {
        let s = &mut samplers[j];
        let once = per_call(
            || {
                black_box(query.run(s, points, boxes));
            },
            3,
        );
        (MIN_BATCH_SECONDS / once).ceil().max(1.0) as usize
    });
    let mut times = [Vec::with_capacity(N_ROUNDS), Vec::with_capacity(N_ROUNDS)];
    for round in 0..N_ROUNDS {
        // Either goes first in turn.
        for k in 0..2 {
            let which = (round + k) % 2;
            let s = &mut samplers[pair[which]];
            let run = || {
                black_box(query.run(s, points, boxes));
            };
            times[which].push(per_call(run, calls[which]));
        }
    }
    let ratios = (0..N_ROUNDS).map(|r| times[1][r] / times[0][r]).collect();
    let per_point = [0, 1].map(|k| quantile(&times[k], 0.5) / points.len() as f64);
    (per_point, ratios)
}

fn main() {
    let asked: Vec<String> = std::env::args().skip(1).collect();
    let points = history_workload::points();
    let boxes = history_workload::boxes();
    let mut samplers: Vec<Sampler> = EDIT_COUNTS
        .iter()
        .map(|&n| history_workload::object_with_edits(n).sampler())
        .collect();
    println!(
        "| query | edits | median per point (10 edits in the same rounds) | ratio to 10 edits: median (p10 to p90 of rounds) |"
    );
    println!("|---|---|---|---|");
    for (name, query) in Query::ALL {
        if !asked.is_empty() && !asked.iter().any(|a| a == name) {
            continue;
        }
        for (i, n) in EDIT_COUNTS.iter().enumerate().skip(1) {
            let ([base, long], ratios) = run_pair(query, &mut samplers, i, &points, &boxes);
            println!(
                "| {name} | {n} | {:.1} ns ({:.1} ns) | {:.2} ({:.2} to {:.2}) |",
                long * 1e9,
                base * 1e9,
                quantile(&ratios, 0.5),
                quantile(&ratios, 0.1),
                quantile(&ratios, 0.9),
            );
        }
    }
}
