//! The plain-loop timing shared by the examples that check the divan benches (`eval_pair`,
//! `history_pair`).

/// Seconds per call of `run`, timed over a batch of `calls` calls (`run` keeps its result
/// from being optimised away, for example with `std::hint::black_box`).
pub fn per_call(mut run: impl FnMut(), calls: usize) -> f64 {
    #[expect(
        clippy::disallowed_methods,
        reason = "a benchmark times real work: this is its one clock"
    )]
    let start = std::time::Instant::now();
    for _ in 0..calls {
        run();
    }
    start.elapsed().as_secs_f64() / calls as f64
}

/// The value at quantile `q` of `xs` (the median at 0.5, the middle one of an odd count).
pub fn quantile(xs: &[f64], q: f64) -> f64 {
    let mut xs = xs.to_vec();
    xs.sort_by(f64::total_cmp);
    xs[((xs.len() - 1) as f64 * q).round() as usize]
}
