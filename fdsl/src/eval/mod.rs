//! Evaluators over a [`Tape`]: single points in f64 (for haptics), bulk slices in f32 (for
//! meshing and rendering), intervals over boxes (for pruning space and simplifying tapes), and
//! exact forward-mode gradients in both precisions.
//!
//! Each evaluator is built once per tape, owns its scratch registers, and never allocates while
//! evaluating, so it can run inside the 1 kHz haptic loop.
//!
//! [`Tape`]: crate::tape::Tape

mod bulk;
mod fuse;
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

/// The registers an instruction reads, once its output register is split off for writing.
struct Args<'a, T> {
    below: &'a [T],
    above: &'a [T],
    out: usize,
}

impl<'a, T> Args<'a, T> {
    /// Register `r`.
    ///
    /// # Panics
    /// If `r` is the output register: the tape never writes a register that the same
    /// instruction reads (it allocates the output before freeing the arguments).
    #[inline(always)]
    fn get(&self, r: u32) -> &'a T {
        let r = r as usize;
        assert!(
            r != self.out,
            "an instruction reads its own output register"
        );
        if r < self.out {
            &self.below[r]
        } else {
            &self.above[r - self.out - 1]
        }
    }
}

/// Splits register `out` off from the others, for an instruction that writes it and reads
/// others; `None` if there is no such register.
#[inline(always)]
fn split_out<T>(regs: &mut [T], out: usize) -> Option<(&mut T, Args<'_, T>)> {
    let (below, rest) = regs.split_at_mut(out);
    let (o, above) = rest.split_first_mut()?;
    Some((&mut *o, Args { below, above, out }))
}
