//! fidget's bulk and interval evaluators called directly, with the three axes passed in the
//! tape's own variable order: the peer at its best for bulk values, gradients and intervals.
//!
//! fidget's `Shape` wrapper (`ShapeBulkEval::eval`) first copies every point into scratch
//! arrays, one coordinate at a time, so that it can apply an optional transform. That copy
//! is inlined into the caller, and its speed depends on how the caller's code is laid out:
//! on `sphere` the same JIT call took 71 to 160 µs for 65,536 points depending on unrelated
//! edits to the timing loop, while fdsl's time did not move; called directly, 10 µs. For one
//! interval, `ShapeTracingEval::eval` walks the tape's variable map and fills a scratch array on
//! every call, which is most of a short tape's cost.

use fidget::context::{Context, Node};
use fidget::eval::{BulkEvaluator, Function, MathFunction, Tape, TracingEvaluator};
use fidget::var::{Var, VarMap};

/// For each variable slot of a tape, the axis (0, 1, 2 for x, y, z) that fills it.
fn axis_slots(vars: &VarMap) -> Vec<usize> {
    let mut slots = vec![0; vars.len().max(1)];
    for (axis, var) in [Var::X, Var::Y, Var::Z].iter().enumerate() {
        if let Some(slot) = vars.get(var) {
            slots[slot] = axis;
        }
    }
    slots
}

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
        Self {
            slots: axis_slots(tape.vars()),
            tape,
            eval: E::new(),
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

/// A tracing (interval) evaluator and its tape, and which axis fills each variable.
pub struct RawTracing<E: TracingEvaluator> {
    tape: E::Tape,
    eval: E,
    slots: Vec<usize>,
}

/// fidget's interval evaluator of `root` in `ctx`, whose only variables are the three axes.
pub fn intervals<F: Function + MathFunction>(
    ctx: &Context,
    root: Node,
) -> RawTracing<F::IntervalEval> {
    let function = F::new(ctx, &[root]).expect("fidget accepts the model");
    let tape = function.interval_tape(Default::default());
    RawTracing {
        slots: axis_slots(tape.vars()),
        tape,
        eval: F::IntervalEval::default(),
    }
}

impl<E: TracingEvaluator> RawTracing<E> {
    /// The function's value (an interval, for an interval evaluator) over `axes` (x, y, z).
    pub fn eval(&mut self, axes: [E::Data; 3]) -> E::Data {
        let mut vars = axes;
        for (slot, axis) in self.slots.iter().enumerate() {
            vars[slot] = axes[*axis];
        }
        let (out, _trace) = self
            .eval
            .eval(&self.tape, &vars[..self.slots.len()])
            .expect("evaluates");
        out[0]
    }
}
