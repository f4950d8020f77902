//! The scattered points the evaluation benchmarks evaluate every model at, shared by the
//! `eval` benchmark and the `eval_pair` example so both time the same work.

/// Deterministic scattered points in [-1.2, 1.2]^3.
pub fn points(n: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut rng = testkit::rng::XorShift64(0x2545_f491_4f6c_dd1d);
    let mut next = || rng.unit_f32() * 2.4 - 1.2;
    let mut xs = Vec::with_capacity(n);
    let mut ys = Vec::with_capacity(n);
    let mut zs = Vec::with_capacity(n);
    for _ in 0..n {
        xs.push(next());
        ys.push(next());
        zs.push(next());
    }
    (xs, ys, zs)
}
