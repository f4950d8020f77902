//! Evaluators over a [`Tape`]: single points in f64 (for haptics), bulk slices in f32 (for
//! meshing and rendering), intervals over boxes (for pruning space and simplifying tapes), and
//! exact forward-mode gradients in both precisions.
//!
//! Each evaluator is built once per tape, owns its scratch registers, and never allocates while
//! evaluating, so it can run inside the 1 kHz haptic loop.
//!
//! [`Tape`]: crate::tape::Tape

mod bulk;
mod grad;
mod grad_bulk;
mod interval;
mod interval_bulk;
mod point;
mod real;

pub use bulk::{BulkEval, CHUNK};
pub use grad::{Grad, GradEval};
pub use grad_bulk::GradBulkEval;
pub use interval::{Interval, IntervalEval};
pub use interval_bulk::{BOX_CHUNK, IntervalBulkEval};
pub use point::PointEval;
pub use real::{fast_cos, fast_sin};
