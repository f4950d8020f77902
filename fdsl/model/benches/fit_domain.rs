//! The domain a formula's solid gets when a command makes an object of it
//! (`model::object::fit_domain`: an octree of interval bounds over ±64 to depth 11), on the
//! reference models of `tests/data/models/`; fidget has no such search, so there is no peer.
//!
//! Run with `cargo bench -p model --bench fit_domain`.

use divan::Bencher;
use fdsl::Function;
use fdsl::tape::Tape;

/// The names of the reference models, the benchmarks' arguments.
fn models() -> impl Iterator<Item = &'static str> {
    fdsl::models::REFERENCE_MODELS
        .into_iter()
        .map(|(name, _)| name)
}

fn tape(model: &str) -> Tape {
    let source = fdsl::models::reference_model(model).expect("a reference model");
    Function::parse(source)
        .unwrap_or_else(|e| panic!("{model}: {e}"))
        .tape()
}

fn main() {
    divan::main();
}

mod fit_domain {
    use super::*;

    #[divan::bench(args = models(), sample_count = 10)]
    fn fdsl(bencher: Bencher, model: &str) {
        let tape = tape(model);
        bencher.bench_local(|| divan::black_box(model::object::fit_domain(&tape, 0.0)));
    }
}
