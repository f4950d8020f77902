//! What evaluating an object with a long history costs against the same object with 10 edits,
//! timed by one plain loop on the `history` bench's workload
//! (`benches/shared/history_workload.rs`): the same objects, and the queries
//! - `value`, `gradient`, `interval`: the bench's random points (and boxes of side 1/32 around
//!   them) in `[-1.1, 1.1]^3`, one query at a time through the [`Sampler`];
//! - `block-values`, `block-intervals`: the queries render's octree mesher makes at depth 7
//!   (`mesher.rs`): each leaf block near the surface restricted from its parent and its
//!   lattice evaluated in one call, and the interval of every node of the descent;
//! - `servo`: the queries haptic's 1 kHz servo makes each tick along a tool path stroking
//!   the surface (`servo.rs`).
//!
//! The mesher's queries depend on the object (pruning follows its surface), so each object
//! is timed on its own descent and the cost is taken per block or per box.
//!
//! The `history` bench times each size in its own run of samples, one after another, so a
//! change in the machine's speed between them (this project's shared machines swing by up to
//! two times within seconds) lands in the ratio. Here each longer history is timed in pairs
//! with the 10-edit object, round after round, and the ratio is taken within the round: the
//! median over rounds, with its spread.
//!
//! Run with `cargo run --release -p model --example history_pair [-- QUERY... EDITS...]`,
//! `QUERY` one of the names above (all by default), `EDITS` one of 1000, 10000 and 100000
//! (all by default).

mod mesher;
mod servo;

use glam::DVec3;
use model::bvh::Aabb;
use model::object::Sampler;
use std::hint::black_box;

#[path = "../../benches/shared/history_workload.rs"]
mod history_workload;
#[path = "../../../benches/shared/timing.rs"]
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
    BlockValues,
    BlockIntervals,
    Servo,
}

/// The random points and boxes and the tool path, the same for every object.
struct Inputs {
    points: Vec<DVec3>,
    boxes: Vec<Aabb>,
    path: Vec<DVec3>,
}

/// One object of the comparison, with its own mesher descent.
struct Subject {
    sampler: Sampler,
    descent: mesher::Descent,
}

impl Query {
    const ALL: [(&'static str, Query); 6] = [
        ("value", Query::Value),
        ("gradient", Query::Gradient),
        ("interval", Query::Interval),
        ("block-values", Query::BlockValues),
        ("block-intervals", Query::BlockIntervals),
        ("servo", Query::Servo),
    ];

    /// One pass of the queries over `s`.
    fn run(self, s: &mut Subject, inputs: &Inputs) -> f64 {
        let sampler = &mut s.sampler;
        match self {
            Query::Value => inputs.points.iter().map(|p| sampler.value(*p, 0.0)).sum(),
            Query::Gradient => (inputs.points.iter())
                .map(|p| sampler.gradient(*p, 0.0).1.x)
                .sum(),
            Query::Interval => (inputs.boxes.iter())
                .map(|b| sampler.interval(b, 0.0).hi)
                .sum(),
            Query::BlockValues => s.descent.block_values(),
            Query::BlockIntervals => s.descent.intervals(sampler),
            Query::Servo => servo::run(sampler, &inputs.path),
        }
    }

    /// Queries in one pass over `s`: points, boxes, blocks or ticks.
    fn n_queries(self, s: &Subject, inputs: &Inputs) -> usize {
        match self {
            Query::Value | Query::Gradient => inputs.points.len(),
            Query::Interval => inputs.boxes.len(),
            Query::BlockValues => s.descent.n_blocks(),
            Query::BlockIntervals => s.descent.n_intervals(),
            Query::Servo => inputs.path.len(),
        }
    }
}

/// Times `query` on subject `i` and on the first (10 edits) in turns: the median seconds per
/// query of each, and the ratio of the two per query in each round.
fn run_pair(
    query: Query,
    subjects: &mut [Subject],
    i: usize,
    inputs: &Inputs,
) -> ([f64; 2], Vec<f64>) {
    let pair = [0, i];
    let n_queries = pair.map(|j| query.n_queries(&subjects[j], inputs) as f64);
    // Warm up, and size each batch to at least `MIN_BATCH_SECONDS`.
    let calls = pair.map(|j| {
        let s = &mut subjects[j];
        let once = per_call(
            || {
                black_box(query.run(s, inputs));
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
            let s = &mut subjects[pair[which]];
            let run = || {
                black_box(query.run(s, inputs));
            };
            times[which].push(per_call(run, calls[which]) / n_queries[which]);
        }
    }
    let ratios = (0..N_ROUNDS).map(|r| times[1][r] / times[0][r]).collect();
    let per_query = [0, 1].map(|k| quantile(&times[k], 0.5));
    (per_query, ratios)
}

fn main() {
    let asked: Vec<String> = std::env::args().skip(1).collect();
    let sizes: Vec<usize> = asked.iter().filter_map(|a| a.parse().ok()).collect();
    let names: Vec<&String> = asked
        .iter()
        .filter(|a| a.parse::<usize>().is_err())
        .collect();
    let inputs = Inputs {
        points: history_workload::points(),
        boxes: history_workload::boxes(),
        path: servo::tool_path(),
    };
    let mut subjects: Vec<Subject> = (EDIT_COUNTS.iter())
        .map(|&n| {
            let mut sampler = history_workload::object_with_edits(n).sampler();
            let descent = mesher::Descent::record(&mut sampler);
            Subject { sampler, descent }
        })
        .collect();
    for (n, s) in EDIT_COUNTS.iter().zip(&subjects) {
        println!(
            "{n} edits: the mesher at depth {} visits {} boxes and {} blocks",
            mesher::DEPTH,
            s.descent.n_intervals(),
            s.descent.n_blocks()
        );
    }
    println!(
        "| query | edits | median per query (10 edits in the same rounds) | ratio to 10 edits: median (p10 to p90 of rounds) |"
    );
    println!("|---|---|---|---|");
    for (name, query) in Query::ALL {
        if !names.is_empty() && !names.iter().any(|a| *a == name) {
            continue;
        }
        for (i, n) in EDIT_COUNTS.iter().enumerate().skip(1) {
            if !sizes.is_empty() && !sizes.contains(n) {
                continue;
            }
            let ([base, long], ratios) = run_pair(query, &mut subjects, i, &inputs);
            println!(
                "| {name} | {n} | {} ({}) | {:.2} ({:.2} to {:.2}) |",
                seconds(long),
                seconds(base),
                quantile(&ratios, 0.5),
                quantile(&ratios, 0.1),
                quantile(&ratios, 0.9),
            );
        }
    }
}

/// A duration in the unit that reads best.
fn seconds(s: f64) -> String {
    if s < 1e-6 {
        format!("{:.1} ns", s * 1e9)
    } else {
        format!("{:.2} µs", s * 1e6)
    }
}
