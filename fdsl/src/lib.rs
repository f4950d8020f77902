//! `fdsl`: the sculpt function language. It reads the function strings users type (F-Rep
//! solids, parametric definitions, colours, scripts with `if` and loops), compiles them, and
//! evaluates them fast at points, over slices, over boxes and with exact gradients.
//!
//! The pipeline is source text -> [`syntax::ast`] (with byte spans) -> SSA expression graph
//! ([`compile::Context`], folded and deduplicated) -> register [`Tape`] -> evaluators
//! ([`eval::PointEval`], [`eval::BulkEval`], [`eval::IntervalEval`], [`eval::IntervalBulkEval`],
//! [`eval::GradEval`], [`eval::GradBulkEval`]). Interval evaluation records choices that
//! [`Tape::simplify`] uses to drop branches that cannot matter in a box.
//!
//! Sign convention: `f >= 0` is inside a solid, `f = 0` its surface (as in the thesis and
//! HyperFun). `&` is intersection, `|` union, `\` difference.
//!
//! It is pure: no IO, no clock, no threads, no randomness. Errors never panic: every problem
//! with a text is a [`Diagnostic`] with a span, a plain message and usually a hint, and every
//! dimension of the work is bounded by the constants in [`limits`].
//!
//! What it is not: it knows nothing of objects, edits or scenes (the `model` crate builds
//! them on this one and caches their compiled tapes) nor of files (the `formats` crate).
//! Besides the pipeline it holds sampled volume data a formula may call by name
//! ([`grid::Grid`]) and the reference formulas the checks and benchmarks share ([`models`]).
//! [`n_compiled_on_this_thread`] counts compilations, so that a test can show that a formula
//! is compiled once however many crates use it.
//!
//! ```
//! use fdsl::{Function, eval::{BulkEval, Interval, IntervalEval}};
//!
//! let melon = Function::parse(
//!     r"(1-x^2-y^2-z^2) \ ((0.9*x+0.1*y-0.1*z) & (0.9*y+0.1*z-0.1*x) & (0.9*z+0.1*x-0.1*y))",
//! ).unwrap();
//! let tape = melon.tape();
//! let mut bulk = BulkEval::new(&tape);
//! let (xs, ys, zs) = ([0.0, -0.5, 2.0], [0.0, -0.5, 0.0], [0.0, -0.5, 0.0]);
//! let mut out = [0.0; 3];
//! bulk.eval(&xs, &ys, &zs, 0.0, &mut out);
//! assert!(out[1] > 0.0 && out[2] < 0.0);
//!
//! // Over a box far from the wedge, the difference reduces to the sphere alone.
//! let mut interval = IntervalEval::new(&tape);
//! let i = Interval::new(-0.9, -0.8);
//! interval.eval([i, i, i, Interval::point(0.0)]);
//! let simpler = tape.simplify(interval.choices(), fdsl::tape::Fidelity::Exact);
//! assert!(simpler.len() < tape.len());
//! ```
#![warn(missing_docs)]

mod builtins;
pub mod compile;
pub mod eval;
mod function;
pub mod grid;
pub mod limits;
pub mod models;
pub mod syntax;
pub mod tape;

pub use function::{
    CompileError, Compiled, Function, Grids, MissingOutput, Options, SetOps,
    n_compiled_on_this_thread,
};
pub use syntax::{Diagnostic, Severity, Span};
pub use tape::Tape;
