//! Exact gradients by forward-mode differentiation: every register carries a value and its
//! partial derivatives with respect to x, y and z.
//!
//! Where an operation is not differentiable (the crease of `min`, a step of `floor`), the
//! derivative of the branch the value came from is used, which is what surface normals need.

use super::CHUNK;
use super::real::Real;
use crate::compile::{BinaryOp, TernaryOp, UnaryOp};
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
    fn constant(v: T) -> Self {
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
fn scale<T: Real>(d: T, k: T) -> T {
    if d == T::ZERO || k == T::ZERO {
        T::ZERO
    } else {
        d * k
    }
}

#[inline(always)]
fn unary<T: Real>(op: UnaryOp, a: Grad<T>) -> Grad<T> {
    let v = T::unary(op, a.v);
    let two = T::ONE + T::ONE;
    let k = match op {
        UnaryOp::Neg => -T::ONE,
        UnaryOp::Abs => {
            if a.v < T::ZERO {
                -T::ONE
            } else {
                T::ONE
            }
        }
        UnaryOp::Sqrt => T::ONE / (two * v),
        UnaryOp::Square => two * a.v,
        UnaryOp::Sin => a.v.cos(),
        UnaryOp::Cos => -a.v.sin(),
        UnaryOp::Tan => {
            let c = a.v.cos();
            T::ONE / (c * c)
        }
        UnaryOp::Asin => T::ONE / (T::ONE - a.v * a.v).sqrt(),
        UnaryOp::Acos => -T::ONE / (T::ONE - a.v * a.v).sqrt(),
        UnaryOp::Atan => T::ONE / (T::ONE + a.v * a.v),
        UnaryOp::Exp => v,
        UnaryOp::Ln => T::ONE / a.v,
        UnaryOp::Floor | UnaryOp::Ceil | UnaryOp::Sign | UnaryOp::Not => T::ZERO,
    };
    Grad::chain(v, k, a)
}

#[inline(always)]
fn binary<T: Real>(op: BinaryOp, a: Grad<T>, b: Grad<T>) -> Grad<T> {
    let v = T::binary(op, a.v, b.v);
    let zero = T::ZERO;
    let one = T::ONE;
    match op {
        BinaryOp::Add => Grad::chain2(v, one, a, one, b),
        BinaryOp::Sub => Grad::chain2(v, one, a, -one, b),
        BinaryOp::Mul => Grad::chain2(v, b.v, a, a.v, b),
        BinaryOp::Div => Grad::chain2(v, one / b.v, a, -a.v / (b.v * b.v), b),
        BinaryOp::Min => {
            if a.v <= b.v || b.v.is_nan() {
                Grad { v, ..a }
            } else {
                Grad { v, ..b }
            }
        }
        BinaryOp::Max => {
            if a.v >= b.v || b.v.is_nan() {
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
        BinaryOp::Atan2 => {
            let d = a.v * a.v + b.v * b.v;
            Grad::chain2(v, b.v / d, a, -a.v / d, b)
        }
        BinaryOp::Mod => Grad::chain2(v, one, a, -(a.v / b.v).floor(), b),
        BinaryOp::Lt | BinaryOp::Le | BinaryOp::Eq | BinaryOp::And | BinaryOp::Or => {
            Grad::constant(v)
        }
        BinaryOp::RAnd | BinaryOp::ROr => {
            let s = (a.v * a.v + b.v * b.v).sqrt();
            let sign = if op == BinaryOp::RAnd { -one } else { one };
            if s == zero {
                Grad::chain2(v, one, a, one, b)
            } else {
                Grad::chain2(v, one + sign * a.v / s, a, one + sign * b.v / s, b)
            }
        }
    }
}

#[inline(always)]
fn ternary<T: Real>(op: TernaryOp, a: Grad<T>, b: Grad<T>, c: Grad<T>) -> Grad<T> {
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
    pub fn eval(&mut self, p: [f64; 4]) -> Grad<f64> {
        run(&self.tape, &mut self.regs, p);
        output(&self.tape, &self.regs, 0)
    }
}

/// Values and gradients over slices of points in f32 (for surface normals).
///
/// Like [`super::BulkEval`], it runs one instruction at a time over a chunk of
/// [`CHUNK`] points, so the tape is interpreted once per chunk rather than once per point.
#[derive(Clone, Debug)]
pub struct GradBulkEval {
    tape: Tape,
    regs: Vec<[Grad<f32>; CHUNK]>,
}

type GradLanes = [Grad<f32>; CHUNK];

impl GradBulkEval {
    /// An evaluator for `tape`.
    pub fn new(tape: &Tape) -> GradBulkEval {
        GradBulkEval {
            tape: tape.clone(),
            regs: vec![[Grad::default(); CHUNK]; tape.n_regs()],
        }
    }

    /// Value and gradient of the first output at each point, written to `out`.
    pub fn eval(&mut self, x: &[f32], y: &[f32], z: &[f32], t: f32, out: &mut [Grad<f32>]) {
        let n = x.len();
        assert!(
            y.len() == n && z.len() == n && out.len() == n,
            "slices differ in length"
        );
        let mut start = 0;
        while start < n {
            let len = CHUNK.min(n - start);
            let coords = [
                &x[start..start + len],
                &y[start..start + len],
                &z[start..start + len],
            ];
            for (slot, reg) in self.tape.inputs().iter().enumerate() {
                let Some(r) = reg else { continue };
                let lanes = &mut self.regs[*r as usize];
                for (i, g) in lanes.iter_mut().enumerate() {
                    let v = if slot == 3 {
                        t
                    } else {
                        coords[slot].get(i).copied().unwrap_or(0.0)
                    };
                    *g = Grad::constant(v);
                    match slot {
                        0 => g.dx = 1.0,
                        1 => g.dy = 1.0,
                        2 => g.dz = 1.0,
                        _ => {}
                    }
                }
            }
            for instr in self.tape.instrs() {
                run_instr(instr, &mut self.regs);
            }
            match self.tape.outputs()[0] {
                Operand::Reg(r) => {
                    out[start..start + len].copy_from_slice(&self.regs[r as usize][..len])
                }
                Operand::Const(c) => out[start..start + len].fill(Grad::constant(c as f32)),
            }
            start += len;
        }
    }
}

/// One instruction over a chunk. The operation is matched once, outside the lane loop, so
/// each loop body is the scalar rule specialised to that operation.
fn run_instr(instr: &crate::tape::Instr, regs: &mut [GradLanes]) {
    let lane = |regs: &[GradLanes], o: Operand, i: usize| match o {
        Operand::Reg(r) => regs[r as usize][i],
        Operand::Const(c) => Grad::constant(c as f32),
    };
    let [a, b, c] = instr.args;
    let out = instr.out as usize;
    let mut result = [Grad::default(); CHUNK];
    macro_rules! each {
        ($f:expr) => {
            for (i, r) in result.iter_mut().enumerate() {
                *r = $f(i);
            }
        };
    }
    match instr.code {
        Code::Unary(op) => {
            macro_rules! u {
                ($($v:ident),*) => {
                    match op {
                        $(UnaryOp::$v => each!(|i| unary(UnaryOp::$v, lane(regs, a, i))),)*
                    }
                };
            }
            u!(
                Neg, Abs, Sqrt, Square, Sin, Cos, Tan, Asin, Acos, Atan, Exp, Ln, Floor, Ceil,
                Sign, Not
            )
        }
        Code::Binary(op) => {
            macro_rules! b {
                ($($v:ident),*) => {
                    match op {
                        $(BinaryOp::$v => each!(|i| binary(BinaryOp::$v, lane(regs, a, i), lane(regs, b, i))),)*
                    }
                };
            }
            b!(
                Add, Sub, Mul, Div, Min, Max, Pow, Atan2, Mod, Lt, Le, Eq, And, Or, RAnd, ROr
            )
        }
        Code::Ternary(op) => {
            each!(|i| ternary(op, lane(regs, a, i), lane(regs, b, i), lane(regs, c, i)))
        }
    }
    regs[out] = result;
}

/// Value and gradient of the first output at one point by the scalar rules in f32: the
/// reference the bulk evaluator must equal bit for bit.
#[cfg(test)]
fn eval_f32(tape: &Tape, p: [f32; 4]) -> Grad<f32> {
    let mut regs = vec![Grad::default(); tape.n_regs()];
    run(tape, &mut regs, p);
    output(tape, &regs, 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Function;

    /// Sources that together use every operation, with registers and constants in each
    /// argument, creases (`x == y`), domain edges and NaN producers.
    const SOURCES: &[&str] = &[
        "-(x*y-z)",
        "abs(x*y-z)",
        "sqrt(x*y-z)",
        "sqrt(x)",
        "sqr(x*y-z)",
        "sin(x*y-z)",
        "cos(x*y-z)",
        "tan(x*y-z)",
        "asin(x*y-z)",
        "acos(x*y-z)",
        "atan(x*y-z)",
        "exp(x*y-z)",
        "ln(x*y-z)",
        "floor(x*y-z)",
        "ceil(x*y-z)",
        "sign(x*y-z)",
        "round(x*y-z)",
        "!(x*y-z)",
        "(x*y) + (z-x)",
        "(x*y) + 0.5",
        "(x*y) - (z-x)",
        "0.5 - (z-x)",
        "(x*y) * (z-x)",
        "0.5 * (z-x)",
        "(x*y) / (z-x)",
        "(x*y) / 0.5",
        "0.5 / (z-x)",
        "(x*y) % (z-x)",
        "(x*y) % 0.5",
        "0.5 % (z-x)",
        "min(x*y, z-x)",
        "min(x*y, 0.5)",
        "max(x*y, z-x)",
        "max(0.5, z-x)",
        "min(x, y)",
        "max(x, y)",
        "(x*y) & (z-x)",
        "(x*y) | (z-x)",
        "(x*y) \\ (z-x)",
        "(x*y) < (z-x)",
        "(x*y) <= 0.5",
        "(x*y) == (z-x)",
        "(x*y) && (z-x)",
        "0.5 || (z-x)",
        "pow(x*y, z-x)",
        "pow(x, 0.5)",
        "pow(2, z-x)",
        "x^0.5",
        "atan2(x*y, z-x)",
        "atan2(0.5, z-x)",
        "r_and(x*y, z-x)",
        "r_or(x*y, 0.5)",
        "r_sub(x, y)",
        "step(x, y*z)",
        "blend_and(x*y, z-x, 0.5)",
        "blend_or(x, y, z)",
        "blend_sub(x*y, z, 0.3)",
        "clamp(x*y, z, 0.5)",
        "x*t + sin(t*y)",
        "function frep(x,y,z,t) { g = 0.8; if (x*y > 0) g = sin(z); return g; }",
        "function frep(x,y,z,t) { g = y*z; if (x < y) g = sqrt(z); return g; }",
        "function frep(x,y,z,t) { g = y*z; if (x < y) g = 0.3; return g; }",
        "function frep(x,y,z,t) { g = 0.8; if (x < y) g = 0.3; return g + x*0; }",
        "0.25",
    ];

    const SPECIAL: [f32; 13] = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.5,
        2.0,
        0.7,
        -0.3,
        1e-30,
        1e30,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
    ];

    /// Every combination of the special values (2,197 points: several chunks and a partial one).
    fn points() -> [Vec<f32>; 3] {
        let mut p = [Vec::new(), Vec::new(), Vec::new()];
        for &x in &SPECIAL {
            for &y in &SPECIAL {
                for &z in &SPECIAL {
                    p[0].push(x);
                    p[1].push(y);
                    p[2].push(z);
                }
            }
        }
        p
    }

    fn same(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn bulk_gradients_are_the_scalar_rules_bit_for_bit() {
        let [xs, ys, zs] = points();
        let t = 0.25;
        let mut out = vec![Grad::default(); xs.len()];
        for src in SOURCES {
            let tape = Function::parse(src).unwrap().tape();
            let mut eval = GradBulkEval::new(&tape);
            eval.eval(&xs, &ys, &zs, t, &mut out);
            for (i, b) in out.iter().enumerate() {
                let s = eval_f32(&tape, [xs[i], ys[i], zs[i], t]);
                let agree =
                    same(b.v, s.v) && same(b.dx, s.dx) && same(b.dy, s.dy) && same(b.dz, s.dz);
                assert!(
                    agree,
                    "{src} at {:?}: bulk {b:?}, scalar {s:?}",
                    [xs[i], ys[i], zs[i]]
                );
            }
        }
    }
}
