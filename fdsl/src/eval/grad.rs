//! Exact gradients by forward-mode differentiation: every register carries a value and its
//! partial derivatives with respect to x, y and z.
//!
//! Where an operation is not differentiable (the crease of `min`, a step of `floor`), the
//! derivative of the branch the value came from is used, which is what surface normals need.
//!
//! The rules are written once, per scalar, and shared: [`GradEval`] runs them in f64 at a point,
//! and the bulk evaluator (`grad_bulk.rs`) runs them in f32 on each lane of its arrays.

use super::real::Real;
use crate::compile::{BinaryOp, TernaryOp, UnaryOp};
use crate::grid::Grid;
use crate::tape::{Code, Operand, Tape};

/// A value with its gradient.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Grad<T> {
    /// The value.
    pub v: T,
    /// d/dx.
    pub dx: T,
    /// d/dy.
    pub dy: T,
    /// d/dz.
    pub dz: T,
}

impl<T: Real> Grad<T> {
    pub(super) fn constant(v: T) -> Self {
        Grad {
            v,
            dx: T::ZERO,
            dy: T::ZERO,
            dz: T::ZERO,
        }
    }

    /// The value with the gradient scaled by `k`.
    fn chain(v: T, k: T, a: Self) -> Self {
        Grad {
            v,
            dx: scale(a.dx, k),
            dy: scale(a.dy, k),
            dz: scale(a.dz, k),
        }
    }

    /// `ka * a' + kb * b'`.
    fn chain2(v: T, ka: T, a: Self, kb: T, b: Self) -> Self {
        Grad {
            v,
            dx: scale(a.dx, ka) + scale(b.dx, kb),
            dy: scale(a.dy, ka) + scale(b.dy, kb),
            dz: scale(a.dz, ka) + scale(b.dz, kb),
        }
    }

    /// The gradient as an array `[dx, dy, dz]`.
    pub fn gradient(&self) -> [T; 3] {
        [self.dx, self.dy, self.dz]
    }
}

/// `d * k`, where a zero factor wins over an infinite one (the derivative of `sqrt` at 0 of a
/// constant is 0, and so is the derivative of `sign` of anything).
#[inline(always)]
pub(super) fn scale<T: Real>(d: T, k: T) -> T {
    if d == T::ZERO || k == T::ZERO {
        T::ZERO
    } else {
        d * k
    }
}

/// `d op(a) / da`, given `a` and the value `v = op(a)`.
#[inline(always)]
pub(super) fn unary_factor<T: Real>(op: UnaryOp, a: T, v: T) -> T {
    let two = T::ONE + T::ONE;
    match op {
        UnaryOp::Neg => -T::ONE,
        UnaryOp::Abs => {
            if a < T::ZERO {
                -T::ONE
            } else {
                T::ONE
            }
        }
        UnaryOp::Sqrt => T::ONE / (two * v),
        UnaryOp::Square => two * a,
        UnaryOp::Sin => a.cos(),
        UnaryOp::Cos => -a.sin(),
        UnaryOp::Tan => {
            let c = a.cos();
            T::ONE / (c * c)
        }
        UnaryOp::Asin => T::ONE / (T::ONE - a * a).sqrt(),
        UnaryOp::Acos => -T::ONE / (T::ONE - a * a).sqrt(),
        UnaryOp::Atan => T::ONE / (T::ONE + a * a),
        UnaryOp::Exp => v,
        UnaryOp::Ln => T::ONE / a,
        UnaryOp::Floor | UnaryOp::Ceil | UnaryOp::Sign | UnaryOp::Not => T::ZERO,
    }
}

#[inline(always)]
pub(super) fn unary<T: Real>(op: UnaryOp, a: Grad<T>) -> Grad<T> {
    let v = T::unary(op, a.v);
    Grad::chain(v, unary_factor(op, a.v, v), a)
}

/// `(d/da, d/db)` of the binary operations whose derivative is `ka a' + kb b'` everywhere:
/// the arithmetic ones, `atan2`, `%` and the R-functions. The others (`min`, `max`, `pow` and
/// the comparisons) have their own rules in [`binary`] and never reach here.
#[inline(always)]
pub(super) fn chain_factors<T: Real>(op: BinaryOp, a: T, b: T) -> (T, T) {
    let one = T::ONE;
    match op {
        BinaryOp::Add => (one, one),
        BinaryOp::Sub => (one, -one),
        BinaryOp::Mul => (b, a),
        BinaryOp::Div => (one / b, -a / (b * b)),
        BinaryOp::Atan2 => {
            let d = a * a + b * b;
            (b / d, -a / d)
        }
        BinaryOp::Mod => (one, -(a / b).floor()),
        BinaryOp::RAnd | BinaryOp::ROr => {
            let s = (a * a + b * b).sqrt();
            let sign = if op == BinaryOp::RAnd { -one } else { one };
            // Both factors are computed before the choice, so that the bulk loops see a
            // select rather than a branch.
            let (ka, kb) = (one + sign * a / s, one + sign * b / s);
            if s == T::ZERO { (one, one) } else { (ka, kb) }
        }
        BinaryOp::Min
        | BinaryOp::Max
        | BinaryOp::Pow
        | BinaryOp::Lt
        | BinaryOp::Le
        | BinaryOp::Eq
        | BinaryOp::And
        | BinaryOp::Or => unreachable!("{op:?} has no chain factors"),
    }
}

/// Whether `min(a, b)` takes its value (and so its derivative) from `a`.
#[inline(always)]
pub(super) fn min_takes_a<T: Real>(a: T, b: T) -> bool {
    a <= b || b.is_nan()
}

/// Whether `max(a, b)` takes its value (and so its derivative) from `a`.
#[inline(always)]
pub(super) fn max_takes_a<T: Real>(a: T, b: T) -> bool {
    a >= b || b.is_nan()
}

#[inline(always)]
pub(super) fn binary<T: Real>(op: BinaryOp, a: Grad<T>, b: Grad<T>) -> Grad<T> {
    let v = T::binary(op, a.v, b.v);
    let zero = T::ZERO;
    let one = T::ONE;
    match op {
        BinaryOp::Min => {
            if min_takes_a(a.v, b.v) {
                Grad { v, ..a }
            } else {
                Grad { v, ..b }
            }
        }
        BinaryOp::Max => {
            if max_takes_a(a.v, b.v) {
                Grad { v, ..a }
            } else {
                Grad { v, ..b }
            }
        }
        BinaryOp::Pow => {
            let ka = if b.dx == zero && b.dy == zero && b.dz == zero {
                b.v * T::binary(BinaryOp::Pow, a.v, b.v - one)
            } else {
                b.v * v / a.v
            };
            let kb = if b.dx == zero && b.dy == zero && b.dz == zero {
                zero
            } else {
                v * a.v.ln()
            };
            Grad::chain2(v, ka, a, kb, b)
        }
        BinaryOp::Lt | BinaryOp::Le | BinaryOp::Eq | BinaryOp::And | BinaryOp::Or => {
            Grad::constant(v)
        }
        BinaryOp::Add
        | BinaryOp::Sub
        | BinaryOp::Mul
        | BinaryOp::Div
        | BinaryOp::Atan2
        | BinaryOp::Mod
        | BinaryOp::RAnd
        | BinaryOp::ROr => {
            let (ka, kb) = chain_factors(op, a.v, b.v);
            Grad::chain2(v, ka, a, kb, b)
        }
    }
}

#[inline(always)]
pub(super) fn ternary<T: Real>(op: TernaryOp, a: Grad<T>, b: Grad<T>, c: Grad<T>) -> Grad<T> {
    match op {
        TernaryOp::Select => {
            if a.v != T::ZERO {
                b
            } else {
                c
            }
        }
        TernaryOp::BlendMin => blend_min(a, b, c),
        TernaryOp::BlendMax => {
            let neg = |g: Grad<T>| Grad {
                v: -g.v,
                dx: -g.dx,
                dy: -g.dy,
                dz: -g.dz,
            };
            neg(blend_min(neg(a), neg(b), c))
        }
    }
}

/// `min(a,b) - h^2 r / 4` with `h = max(r - |a-b|, 0) / r`.
#[inline(always)]
fn blend_min<T: Real>(a: Grad<T>, b: Grad<T>, r: Grad<T>) -> Grad<T> {
    let v = T::ternary(TernaryOp::BlendMin, a.v, b.v, r.v);
    let m = binary(BinaryOp::Min, a, b);
    let diff = a.v - b.v;
    let abs = if diff < T::ZERO { -diff } else { diff };
    if abs.partial_cmp(&r.v) != Some(std::cmp::Ordering::Less) {
        return Grad { v, ..m };
    }
    let s = if diff < T::ZERO { -T::ONE } else { T::ONE };
    let h = (r.v - abs) / r.v;
    let quarter = T::from_f64(0.25);
    let two = T::ONE + T::ONE;
    // dh = -s (da - db) / r + |a-b| dr / r^2
    let dh = |da: T, db: T, dr: T| -s * (da - db) / r.v + abs * dr / (r.v * r.v);
    let d =
        |dm: T, da: T, db: T, dr: T| dm - quarter * (two * h * r.v * dh(da, db, dr) + h * h * dr);
    Grad {
        v,
        dx: d(m.dx, a.dx, b.dx, r.dx),
        dy: d(m.dy, a.dy, b.dy, r.dy),
        dz: d(m.dz, a.dz, b.dz, r.dz),
    }
}

/// A grid sampled at `(a, b, c)`, computed in f64: its value, and the chain rule through the
/// grid's gradient.
pub(super) fn sample<T: Real>(grid: &Grid, a: Grad<T>, b: Grad<T>, c: Grad<T>) -> Grad<T> {
    let (v, g) = grid.value_grad([a.v.to_f64(), b.v.to_f64(), c.v.to_f64()]);
    let [ka, kb, kc] = g.map(T::from_f64);
    let d = |x: T, y: T, z: T| scale(x, ka) + scale(y, kb) + scale(z, kc);
    Grad {
        v: T::from_f64(v),
        dx: d(a.dx, b.dx, c.dx),
        dy: d(a.dy, b.dy, c.dy),
        dz: d(a.dz, b.dz, c.dz),
    }
}

fn run<T: Real>(tape: &Tape, regs: &mut [Grad<T>], p: [T; 4]) {
    for (slot, reg) in tape.inputs().iter().enumerate() {
        let Some(r) = reg else { continue };
        let mut g = Grad::constant(p[slot]);
        match slot {
            0 => g.dx = T::ONE,
            1 => g.dy = T::ONE,
            2 => g.dz = T::ONE,
            _ => {}
        }
        regs[*r as usize] = g;
    }
    for instr in tape.instrs() {
        let get = |o: Operand| match o {
            Operand::Reg(r) => regs[r as usize],
            Operand::Const(c) => Grad::constant(T::from_f64(c)),
        };
        let [a, b, c] = instr.args;
        regs[instr.out as usize] = match instr.code {
            Code::Unary(op) => unary(op, get(a)),
            Code::Binary(op) => binary(op, get(a), get(b)),
            Code::Ternary(op) => ternary(op, get(a), get(b), get(c)),
            Code::Sample(g) => sample(&tape.grids()[g as usize], get(a), get(b), get(c)),
        };
    }
}

fn output<T: Real>(tape: &Tape, regs: &[Grad<T>], idx: usize) -> Grad<T> {
    match tape.outputs()[idx] {
        Operand::Reg(r) => regs[r as usize],
        Operand::Const(c) => Grad::constant(T::from_f64(c)),
    }
}

/// Value and gradient at one point in f64 (for haptics).
#[derive(Clone, Debug)]
pub struct GradEval {
    tape: Tape,
    regs: Vec<Grad<f64>>,
}

impl GradEval {
    /// An evaluator for `tape`.
    pub fn new(tape: &Tape) -> GradEval {
        GradEval {
            tape: tape.clone(),
            regs: vec![Grad::default(); tape.n_regs()],
        }
    }

    /// Value and gradient of the first output at `p = [x, y, z, t]`.
    // Inlined where the object model samples (another crate), as when they were one crate.
    #[inline]
    pub fn eval(&mut self, p: [f64; 4]) -> Grad<f64> {
        run(&self.tape, &mut self.regs, p);
        output(&self.tape, &self.regs, 0)
    }
}

/// Value and gradient of the first output at one point by the scalar rules in f32: the
/// reference the bulk evaluator must equal bit for bit.
#[cfg(test)]
pub(super) fn eval_f32(tape: &Tape, p: [f32; 4]) -> Grad<f32> {
    let mut regs = vec![Grad::default(); tape.n_regs()];
    run(tape, &mut regs, p);
    output(tape, &regs, 0)
}
