//! The reference models compile, evaluate where we know their values, agree with the `fidget`
//! crate (the benchmark peer) within f32 tolerance, and prune as a mesher needs.

#![allow(
    clippy::unwrap_used,
    reason = "test helpers unwrap what a test expects to succeed"
)]

use fdsl::Function;
use fdsl::eval::{BulkEval, Interval, IntervalEval, PointEval};
use fdsl::tape::Fidelity;
use fidget::shape::Shape;

#[path = "../benches/fidget_peer.rs"]
mod fidget_peer;

const MODELS: &[(&str, &str)] = &fdsl::models::REFERENCE_MODELS;

fn grid() -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let n = 17;
    let mut g = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let c = |v: usize| -1.2 + 2.4 * v as f32 / (n - 1) as f32;
                g.0.push(c(i));
                g.1.push(c(j));
                g.2.push(c(k));
            }
        }
    }
    g
}

#[test]
fn every_reference_model_compiles_and_evaluates() {
    for (name, src) in MODELS {
        let f = Function::parse(src).unwrap_or_else(|e| panic!("{name}:\n{e}"));
        let v = PointEval::new(&f.tape()).eval([0.0, 0.0, 0.0, 0.0]);
        let far = PointEval::new(&f.tape()).eval([3.0, 3.0, 3.0, 0.0]);
        assert!(v.is_finite(), "{name}: {v}");
        if *name != "script_field" {
            assert!(far < 0.0, "{name} is bounded: {far} outside");
        }
    }
    let melon = Function::parse(MODELS[4].1).unwrap().tape();
    let mut p = PointEval::new(&melon);
    assert!(p.eval([-0.5, -0.5, -0.5, 0.0]) > 0.0, "flesh is inside");
    assert!(p.eval([0.5, 0.5, 0.5, 0.0]) < 0.0, "the wedge is cut away");
}

#[test]
fn values_agree_with_fidget() {
    let (xs, ys, zs) = grid();
    for (name, src) in MODELS {
        let tape = Function::parse(src).unwrap().tape();
        let mut ours = vec![0.0f32; xs.len()];
        BulkEval::new(&tape).eval(&xs, &ys, &zs, 0.0, &mut ours);
        let (ctx, root) = fidget_peer::to_fidget(&tape);
        let shape = Shape::<fidget::vm::VmFunction>::new(&ctx, root).unwrap();
        let t = shape.float_slice_tape(Default::default());
        let mut eval = Shape::<fidget::vm::VmFunction>::new_float_slice_eval();
        let theirs = eval.eval(&t, &xs, &ys, &zs).unwrap();
        let mut point = PointEval::new(&tape);
        for i in 0..xs.len() {
            let exact = point.eval([xs[i] as f64, ys[i] as f64, zs[i] as f64, 0.0]);
            let (a, b) = (ours[i] as f64, -theirs[i] as f64);
            if exact.abs() > 1e6 {
                // The 100 chained R-function unions grow like 2^100 far outside the spheres
                // and overflow f32; both evaluators are meaningless there.
                continue;
            }
            // Stated tolerance: 1e-5 relative to the value's scale per 10 operations, as f32
            // rounding errors accumulate (100 chained R-function unions cancel large terms).
            let tolerance = 1e-6 * (1.0 + exact.abs()) * tape.len() as f64;
            assert!(
                (a - exact).abs() <= tolerance,
                "{name} at {i}: fdsl {a} vs f64 {exact}"
            );
            assert!(
                (b - exact).abs() <= tolerance,
                "{name} at {i}: fidget {b} vs f64 {exact}"
            );
        }
    }
}

/// Counts ambiguous leaves and the total tape length evaluated in them over an octree.
fn prune(tape: &fdsl::Tape, lo: [f64; 3], size: f64, depth: u32) -> (usize, usize) {
    let mut interval = IntervalEval::new(tape);
    let i = |k: usize| Interval::new(lo[k], lo[k] + size);
    let b = interval.eval([i(0), i(1), i(2), Interval::point(0.0)]);
    if !b.has_nan() && (b.lo > 0.0 || b.hi < 0.0) {
        return (0, 0);
    }
    let simpler = tape.simplify(interval.choices(), Fidelity::Sign);
    if depth == 0 {
        return (1, simpler.len());
    }
    let half = size / 2.0;
    let mut total = (0, 0);
    for c in 0..8 {
        let o = [(c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64];
        let (n, len) = prune(
            &simpler,
            [
                lo[0] + o[0] * half,
                lo[1] + o[1] * half,
                lo[2] + o[2] * half,
            ],
            half,
            depth - 1,
        );
        total = (total.0 + n, total.1 + len);
    }
    total
}

#[test]
fn r_function_models_prune_like_their_min_max_twins() {
    for (rfunc, minmax) in [(2, 1), (5, 4)] {
        let r = Function::parse(MODELS[rfunc].1).unwrap().tape();
        let m = Function::parse(MODELS[minmax].1).unwrap().tape();
        let (r_leaves, r_len) = prune(&r, [-1.2; 3], 2.4, 4);
        let (m_leaves, m_len) = prune(&m, [-1.2; 3], 2.4, 4);
        let (r_mean, m_mean) = (
            r_len as f64 / r_leaves as f64,
            m_len as f64 / m_leaves as f64,
        );
        // The same surface, so about the same leaves; and the pruned tapes are as short, up to
        // the R-function's own few operations.
        let leaves_ratio = r_leaves as f64 / m_leaves as f64;
        assert!(
            (0.9..1.5).contains(&leaves_ratio),
            "{}: {r_leaves} vs {m_leaves} leaves",
            MODELS[rfunc].0
        );
        assert!(
            r_mean <= 1.5 * m_mean + 6.0,
            "{}: mean tape {r_mean} vs {m_mean}",
            MODELS[rfunc].0
        );
        assert!(
            r_mean < r.len() as f64 / 2.0,
            "{}: pruning left {r_mean} of {}",
            MODELS[rfunc].0,
            r.len()
        );
    }
}
