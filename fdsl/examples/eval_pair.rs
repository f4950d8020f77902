//! fdsl's bulk value evaluator against fidget's JIT and VM, timed by one plain loop for all
//! three, with fidget called through its raw bulk evaluator (`benches/shared/fidget_bulk.rs`).
//!
//! The three evaluators take turns, round after round, on the same 65,536 points, and each
//! reports the median of its rounds: a check of the divan `eval` bench's `bulk_values` by a
//! second harness.
//!
//! Run with `cargo run --release -p fdsl --example eval_pair [-- MODEL...]`.

use fdsl::Function;
use fdsl::eval::BulkEval;

#[path = "../benches/shared/fidget_bulk.rs"]
#[expect(dead_code, reason = "this example times values, not gradients")]
mod fidget_bulk;
#[path = "../benches/fidget_peer.rs"]
mod fidget_peer;
#[path = "../benches/shared/points.rs"]
mod points;
#[path = "../benches/shared/timing.rs"]
mod timing;
use timing::{per_call, quantile};

/// Points per call, as the bench's `bulk_values`.
const N_POINTS: usize = 65_536;
/// Rounds; each evaluator runs once per round.
const N_ROUNDS: usize = 21;
/// Each timed batch runs at least this long.
const MIN_BATCH_SECONDS: f64 = 0.02;

/// One evaluator under test: a call over the points.
type Run<'a> = Box<dyn FnMut() + 'a>;

fn fidget_run<'a, F: fidget::eval::Function + fidget::eval::MathFunction + Clone + 'a>(
    tape: &fdsl::tape::Tape,
    (xs, ys, zs): &'a (Vec<f32>, Vec<f32>, Vec<f32>),
) -> Run<'a> {
    let (ctx, root) = fidget_peer::to_fidget(tape);
    let mut eval = fidget_bulk::values::<F>(&ctx, root);
    Box::new(move || {
        std::hint::black_box(eval.eval(xs, ys, zs));
    })
}

fn main() {
    let asked: Vec<String> = std::env::args().skip(1).collect();
    let points = points::points(N_POINTS);
    println!("| model | fdsl | fidget JIT | fidget VM | fdsl vs JIT | fdsl vs VM |");
    println!("|---|---|---|---|---|---|");
    for (model, source) in fdsl::models::REFERENCE_MODELS {
        if !asked.is_empty() && !asked.iter().any(|a| a == model) {
            continue;
        }
        let tape = Function::parse(source)
            .unwrap_or_else(|e| panic!("{model}: {e}"))
            .tape();
        let mut eval = BulkEval::new(&tape);
        let mut out = vec![0.0; N_POINTS];
        let (xs, ys, zs) = &points;
        let mut runs: Vec<Run<'_>> = vec![
            Box::new(|| {
                eval.eval(xs, ys, zs, 0.0, &mut out);
                std::hint::black_box(&out);
            }),
            fidget_run::<fidget::jit::JitFunction>(&tape, &points),
            fidget_run::<fidget::vm::VmFunction>(&tape, &points),
        ];
        // Warm up, and size each batch to at least `MIN_BATCH_SECONDS`.
        let calls: Vec<usize> = runs
            .iter_mut()
            .map(|run| {
                let once = per_call(&mut *run, 3);
                (MIN_BATCH_SECONDS / once).ceil().max(1.0) as usize
            })
            .collect();
        let mut times = vec![Vec::with_capacity(N_ROUNDS); runs.len()];
        for round in 0..N_ROUNDS {
            // A different evaluator goes first in each round.
            for k in 0..runs.len() {
                let i = (round + k) % runs.len();
                times[i].push(per_call(&mut runs[i], calls[i]));
            }
        }
        let [fdsl, jit, vm] = [0, 1, 2].map(|i| quantile(&times[i], 0.5));
        println!(
            "| {model} | {:.1} µs | {:.1} µs | {:.1} µs | {:.2} | {:.2} |",
            fdsl * 1e6,
            jit * 1e6,
            vm * 1e6,
            jit / fdsl,
            vm / fdsl
        );
    }
}
