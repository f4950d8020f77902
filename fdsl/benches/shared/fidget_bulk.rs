//! fidget's float bulk evaluator called directly, with the three axes passed in the tape's
//! own variable order: the peer at its best for bulk values.
//!
//! fidget's `Shape` wrapper (`ShapeBulkEval::eval`) first copies every point into scratch
//! arrays, one coordinate at a time, so that it can apply an optional transform. That copy
//! is inlined into the caller, and its speed depends on how the caller's code is laid out:
//! on `sphere` the same JIT call took 71 to 160 µs for 65,536 points depending on unrelated
//! edits to the timing loop, while fdsl's time did not move; called directly, 10 µs.

use fidget::context::{Context, Node};
use fidget::eval::{BulkEvaluator, Function, MathFunction, Tape};
use fidget::var::Var;

/// A function's float bulk evaluator and tape, and where each axis goes among its variables.
pub struct RawBulk<F: Function> {
    tape: <F::FloatSliceEval as BulkEvaluator>::Tape,
    eval: F::FloatSliceEval,
    /// For each variable slot, the axis (0, 1, 2 for x, y, z) that fills it.
    slots: Vec<usize>,
}

impl<F: Function + MathFunction> RawBulk<F> {
    /// The evaluator of `root` in `ctx`, whose only variables are the three axes.
    pub fn new(ctx: &Context, root: Node) -> Self {
        let function = F::new(ctx, &[root]).expect("fidget accepts the model");
        let tape = function.float_slice_tape(Default::default());
        let vars = tape.vars();
        let mut slots = vec![0; vars.len().max(1)];
        for (axis, var) in [Var::X, Var::Y, Var::Z].iter().enumerate() {
            if let Some(slot) = vars.get(var) {
                slots[slot] = axis;
            }
        }
        Self {
            tape,
            eval: F::new_float_slice_eval(),
            slots,
        }
    }

    /// Evaluates the function at the points `(xs[i], ys[i], zs[i])`; returns the first
    /// value, and hands every value to `black_box` so that none of the work can be skipped.
    pub fn eval(&mut self, xs: &[f32], ys: &[f32], zs: &[f32]) -> f32 {
        let axes = [xs, ys, zs];
        let mut vars: [&[f32]; 3] = [xs; 3];
        for (slot, axis) in self.slots.iter().enumerate() {
            vars[slot] = axes[*axis];
        }
        let out = self
            .eval
            .eval(&self.tape, &vars[..self.slots.len()])
            .expect("evaluates");
        let values = std::hint::black_box(&out[0]);
        values.first().copied().unwrap_or(f32::NAN)
    }
}
