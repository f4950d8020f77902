//! Evaluation benchmarks: fdsl against the `fidget` crate (its bytecode VM and its JIT) in the
//! same run, on the reference models of `tests/data/models/`.
//!
//! Workloads, each reported as items per second by divan:
//! - `bulk_values`: f32 values at 65,536 scattered points;
//! - `bulk_gradients`: f32 values and gradients at 16,384 points;
//! - `interval`: bounds over 4,096 small boxes;
//! - `pruned`: what a mesher does: an octree over [-1.2, 1.2]^3 to depth 5, interval
//!   evaluation and tape simplification at each box, and 4^3 point values in each ambiguous
//!   leaf. For the R-function models, compare `pruned` with their min/max twins.
//!
//! Run with `cargo bench -p fdsl --bench eval`. The domain fitting of a formula's solid, which
//! was measured here, is the object model's: `cargo bench -p model --bench fit_domain`.

use divan::Bencher;
use divan::counter::ItemsCount;
use fdsl::Function;
use fdsl::eval::{BulkEval, GradBulkEval, Interval, IntervalBulkEval, IntervalEval};
use fdsl::tape::{Fidelity, Tape};
use fidget::shape::Shape;

#[path = "shared/fidget_bulk.rs"]
mod fidget_bulk;
mod fidget_peer;
#[path = "shared/points.rs"]
mod points;
use points::points;

/// The names of the reference models, the benchmarks' arguments.
fn models() -> impl Iterator<Item = &'static str> {
    fdsl::models::REFERENCE_MODELS
        .into_iter()
        .map(|(name, _)| name)
}

fn source(model: &str) -> &'static str {
    fdsl::models::reference_model(model).expect("a reference model")
}

fn tape(model: &str) -> Tape {
    Function::parse(source(model))
        .unwrap_or_else(|e| panic!("{model}: {e}"))
        .tape()
}

const N_VALUES: usize = 65_536;
const N_GRADIENTS: usize = 16_384;
const N_BOXES: usize = 4_096;
const PRUNE_DEPTH: u32 = 5;
const LEAF_SAMPLES: usize = 4;

fn main() {
    divan::main();
}

mod bulk_values {
    use super::*;

    #[divan::bench(args = models())]
    fn fdsl(bencher: Bencher, model: &str) {
        let tape = tape(model);
        let (xs, ys, zs) = points(N_VALUES);
        let mut eval = BulkEval::new(&tape);
        let mut out = vec![0.0; N_VALUES];
        bencher.counter(ItemsCount::new(N_VALUES)).bench_local(|| {
            eval.eval(&xs, &ys, &zs, 0.0, &mut out);
            divan::black_box(&out);
        });
    }

    fn peer<F: fidget::eval::Function + fidget::eval::MathFunction + Clone>(
        bencher: Bencher,
        model: &str,
    ) {
        let (ctx, root) = fidget_peer::to_fidget(&tape(model));
        let mut eval = fidget_bulk::values::<F>(&ctx, root);
        let (xs, ys, zs) = points(N_VALUES);
        bencher.counter(ItemsCount::new(N_VALUES)).bench_local(|| {
            divan::black_box(eval.eval(&xs, &ys, &zs));
        });
    }

    #[divan::bench(args = models())]
    fn fidget_vm(bencher: Bencher, model: &str) {
        peer::<fidget::vm::VmFunction>(bencher, model);
    }

    #[divan::bench(args = models())]
    fn fidget_jit(bencher: Bencher, model: &str) {
        peer::<fidget::jit::JitFunction>(bencher, model);
    }
}

mod bulk_gradients {
    use super::*;

    #[divan::bench(args = models())]
    fn fdsl(bencher: Bencher, model: &str) {
        let tape = tape(model);
        let (xs, ys, zs) = points(N_GRADIENTS);
        let mut eval = GradBulkEval::new(&tape);
        let mut out = vec![Default::default(); N_GRADIENTS];
        bencher
            .counter(ItemsCount::new(N_GRADIENTS))
            .bench_local(|| {
                eval.eval(&xs, &ys, &zs, 0.0, &mut out);
                divan::black_box(&out);
            });
    }

    fn peer<F: fidget::eval::Function + fidget::eval::MathFunction + Clone>(
        bencher: Bencher,
        model: &str,
    ) {
        let (ctx, root) = fidget_peer::to_fidget(&tape(model));
        let mut eval = fidget_bulk::gradients::<F>(&ctx, root);
        let (xs, ys, zs) = points(N_GRADIENTS);
        let (xs, ys, zs): (Vec<fidget::types::Grad>, Vec<_>, Vec<_>) = (
            xs.iter()
                .map(|&v| fidget::types::Grad::new(v, 1.0, 0.0, 0.0))
                .collect(),
            ys.iter()
                .map(|&v| fidget::types::Grad::new(v, 0.0, 1.0, 0.0))
                .collect(),
            zs.iter()
                .map(|&v| fidget::types::Grad::new(v, 0.0, 0.0, 1.0))
                .collect(),
        );
        bencher
            .counter(ItemsCount::new(N_GRADIENTS))
            .bench_local(|| {
                divan::black_box(eval.eval(&xs, &ys, &zs));
            });
    }

    #[divan::bench(args = models())]
    fn fidget_vm(bencher: Bencher, model: &str) {
        peer::<fidget::vm::VmFunction>(bencher, model);
    }

    #[divan::bench(args = models())]
    fn fidget_jit(bencher: Bencher, model: &str) {
        peer::<fidget::jit::JitFunction>(bencher, model);
    }
}

/// Small boxes at the scattered points.
fn boxes() -> Vec<[f32; 3]> {
    let (xs, ys, zs) = points(N_BOXES);
    (0..N_BOXES).map(|i| [xs[i], ys[i], zs[i]]).collect()
}

const BOX_SIZE: f32 = 0.1;

mod interval {
    use super::*;

    #[divan::bench(args = models())]
    fn fdsl(bencher: Bencher, model: &str) {
        let tape = tape(model);
        let mut eval = IntervalEval::new(&tape);
        let boxes = boxes();
        bencher.counter(ItemsCount::new(N_BOXES)).bench_local(|| {
            for b in &boxes {
                let i = |k: usize| Interval::new(b[k] as f64, (b[k] + BOX_SIZE) as f64);
                divan::black_box(eval.eval([i(0), i(1), i(2), Interval::point(0.0)]));
            }
        });
    }

    /// The same boxes through the bulk evaluator, [`fdsl::eval::BOX_CHUNK`] boxes per pass;
    /// each box's choices are recorded, as `fdsl` and fidget's tracing evaluators record them.
    #[divan::bench(args = models())]
    fn fdsl_bulk(bencher: Bencher, model: &str) {
        let tape = tape(model);
        let mut eval = IntervalBulkEval::new(&tape);
        let boxes: Vec<[Interval; 4]> = boxes()
            .iter()
            .map(|b| {
                let i = |k: usize| Interval::new(b[k] as f64, (b[k] + BOX_SIZE) as f64);
                [i(0), i(1), i(2), Interval::point(0.0)]
            })
            .collect();
        let mut out = vec![Interval::point(0.0); N_BOXES];
        bencher.counter(ItemsCount::new(N_BOXES)).bench_local(|| {
            eval.eval(&boxes, &mut out);
            divan::black_box(&out);
        });
    }

    fn peer<F: fidget::eval::Function + fidget::eval::MathFunction + Clone>(
        bencher: Bencher,
        model: &str,
    ) {
        let (ctx, root) = fidget_peer::to_fidget(&tape(model));
        let mut eval = fidget_bulk::intervals::<F>(&ctx, root);
        let boxes = boxes();
        bencher.counter(ItemsCount::new(N_BOXES)).bench_local(|| {
            for b in &boxes {
                let i = |k: usize| fidget::types::Interval::new(b[k], b[k] + BOX_SIZE);
                divan::black_box(eval.eval([i(0), i(1), i(2)]));
            }
        });
    }

    #[divan::bench(args = models())]
    fn fidget_vm(bencher: Bencher, model: &str) {
        peer::<fidget::vm::VmFunction>(bencher, model);
    }

    #[divan::bench(args = models())]
    fn fidget_jit(bencher: Bencher, model: &str) {
        peer::<fidget::jit::JitFunction>(bencher, model);
    }
}

mod pruned {
    use super::*;

    /// Octree descent with interval pruning and sign-preserving simplification; returns the
    /// number of point samples taken, so both sides can be checked to do the same work.
    fn descend(tape: &Tape, lo: [f32; 3], size: f32, depth: u32, scratch: &mut Vec<f32>) -> usize {
        let mut interval = IntervalEval::new(tape);
        let i = |k: usize| Interval::new(lo[k] as f64, (lo[k] + size) as f64);
        let bounds = interval.eval([i(0), i(1), i(2), Interval::point(0.0)]);
        if !bounds.has_nan() && (bounds.lo > 0.0 || bounds.hi < 0.0) {
            return 0;
        }
        let simpler = tape.simplify(interval.choices(), Fidelity::Sign);
        if depth == 0 {
            return sample(&simpler, lo, size, scratch);
        }
        let half = size / 2.0;
        let mut n = 0;
        for child in 0..8 {
            let o = [
                (child & 1) as f32,
                ((child >> 1) & 1) as f32,
                ((child >> 2) & 1) as f32,
            ];
            let child_lo = [
                lo[0] + o[0] * half,
                lo[1] + o[1] * half,
                lo[2] + o[2] * half,
            ];
            n += descend(&simpler, child_lo, half, depth - 1, scratch);
        }
        n
    }

    fn grid(lo: [f32; 3], size: f32) -> [Vec<f32>; 3] {
        let n = LEAF_SAMPLES;
        let step = size / n as f32;
        let mut g = [
            Vec::with_capacity(n * n * n),
            Vec::with_capacity(n * n * n),
            Vec::with_capacity(n * n * n),
        ];
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    g[0].push(lo[0] + (i as f32 + 0.5) * step);
                    g[1].push(lo[1] + (j as f32 + 0.5) * step);
                    g[2].push(lo[2] + (k as f32 + 0.5) * step);
                }
            }
        }
        g
    }

    fn sample(tape: &Tape, lo: [f32; 3], size: f32, out: &mut Vec<f32>) -> usize {
        let [xs, ys, zs] = grid(lo, size);
        out.resize(xs.len(), 0.0);
        BulkEval::new(tape).eval(&xs, &ys, &zs, 0.0, out);
        divan::black_box(&out);
        xs.len()
    }

    #[divan::bench(args = models())]
    fn fdsl(bencher: Bencher, model: &str) {
        let tape = tape(model);
        let mut scratch = Vec::new();
        bencher.bench_local(|| descend(&tape, [-1.2; 3], 2.4, PRUNE_DEPTH, &mut scratch));
    }

    fn peer_descend<F: fidget::eval::Function + fidget::eval::MathFunction + Clone>(
        shape: &Shape<F>,
        lo: [f32; 3],
        size: f32,
        depth: u32,
    ) -> usize {
        let mut interval = Shape::<F>::new_interval_eval();
        let t = shape.interval_tape(Default::default());
        let i = |k: usize| fidget::types::Interval::new(lo[k], lo[k] + size);
        let (bounds, trace) = interval.eval(&t, i(0), i(1), i(2)).expect("evaluates");
        if bounds.lower() > 0.0 || bounds.upper() < 0.0 {
            return 0;
        }
        let simpler = match trace {
            Some(trace) => shape
                .simplify(trace, Default::default(), &mut Default::default())
                .expect("simplifies"),
            None => shape.clone(),
        };
        if depth == 0 {
            let [xs, ys, zs] = grid(lo, size);
            let t = simpler.float_slice_tape(Default::default());
            let mut eval = Shape::<F>::new_float_slice_eval();
            divan::black_box(eval.eval(&t, &xs, &ys, &zs).expect("evaluates"));
            return xs.len();
        }
        let half = size / 2.0;
        let mut n = 0;
        for child in 0..8 {
            let o = [
                (child & 1) as f32,
                ((child >> 1) & 1) as f32,
                ((child >> 2) & 1) as f32,
            ];
            let child_lo = [
                lo[0] + o[0] * half,
                lo[1] + o[1] * half,
                lo[2] + o[2] * half,
            ];
            n += peer_descend(&simpler, child_lo, half, depth - 1);
        }
        n
    }

    fn peer<F: fidget::eval::Function + fidget::eval::MathFunction + Clone>(
        bencher: Bencher,
        model: &str,
    ) {
        let (ctx, root) = fidget_peer::to_fidget(&tape(model));
        let shape = Shape::<F>::new(&ctx, root).expect("fidget accepts the model");
        bencher.bench_local(|| peer_descend(&shape, [-1.2; 3], 2.4, PRUNE_DEPTH));
    }

    #[divan::bench(args = models())]
    fn fidget_vm(bencher: Bencher, model: &str) {
        peer::<fidget::vm::VmFunction>(bencher, model);
    }

    #[divan::bench(args = models())]
    fn fidget_jit(bencher: Bencher, model: &str) {
        peer::<fidget::jit::JitFunction>(bencher, model);
    }
}
