//! fidget's bulk evaluators called directly, with the three axes passed in the tape's own
//! variable order: the peer at its best for bulk values and gradients.
//!
//! fidget's `Shape` wrapper (`ShapeBulkEval::eval`) first copies every point into scratch
//! arrays, one coordinate at a time, so that it can apply an optional transform. That copy
//! is inlined into the caller, and its speed depends on how the caller's code is laid out:
//! on `sphere` the same JIT call took 71 to 160 µs for 65,536 points depending on unrelated
//! edits to the timing loop, while fdsl's time did not move; called directly, 10 µs.

use fidget::context::{Context, Node};
use fidget::eval::{BulkEvaluator, Function, MathFunction, Tape};
use fidget::var::Var;

/// A bulk evaluator and its tape, and which axis fills each of the tape's variables.
pub struct RawBulk<E: BulkEvaluator> {
    tape: E::Tape,
    eval: E,
    /// For each variable slot, the axis (0, 1, 2 for x, y, z) that fills it.
    slots: Vec<usize>,
}

/// fidget's float evaluator of `root` in `ctx`, whose only variables are the three axes.
pub fn values<F: Function + MathFunction>(ctx: &Context, root: Node) -> RawBulk<F::FloatSliceEval> {
    let function = F::new(ctx, &[root]).expect("fidget accepts the model");
    RawBulk::new(function.float_slice_tape(Default::default()))
}

/// fidget's gradient evaluator of `root` in `ctx`, whose only variables are the three axes.
pub fn gradients<F: Function + MathFunction>(
    ctx: &Context,
    root: Node,
) -> RawBulk<F::GradSliceEval> {
    let function = F::new(ctx, &[root]).expect("fidget accepts the model");
    RawBulk::new(function.grad_slice_tape(Default::default()))
}

impl<E: BulkEvaluator> RawBulk<E> {
    fn new(tape: E::Tape) -> Self {
        let vars = tape.vars();
        let mut slots = vec![0; vars.len().max(1)];
        for (axis, var) in [Var::X, Var::Y, Var::Z].iter().enumerate() {
            if let Some(slot) = vars.get(var) {
                slots[slot] = axis;
            }
        }
        Self {
            tape,
            eval: E::new(),
            slots,
        }
    }

    /// Evaluates the function at the points `(xs[i], ys[i], zs[i])`; returns the first
    /// result, and hands every result to `black_box` so that none of the work can be skipped.
    pub fn eval(&mut self, xs: &[E::Data], ys: &[E::Data], zs: &[E::Data]) -> Option<E::Data> {
        let axes = [xs, ys, zs];
        let mut vars: [&[E::Data]; 3] = [xs; 3];
        for (slot, axis) in self.slots.iter().enumerate() {
            vars[slot] = axes[*axis];
        }
        let out = self
            .eval
            .eval(&self.tape, &vars[..self.slots.len()])
            .expect("evaluates");
        let results = std::hint::black_box(&out[0]);
        results.first().copied()
    }
}
