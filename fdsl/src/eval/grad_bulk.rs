//! The f32 bulk gradient evaluator: values and forward-mode derivatives over slices of points,
//! one instruction at a time over a chunk of [`CHUNK`] lanes.
//!
//! Each register is a structure of arrays (the value, d/dx, d/dy and d/dz, each a chunk of
//! lanes), so each rule is a plain loop over arrays that the compiler vectorises; keeping value
//! and gradient together per point instead vectorised poorly (BENCHMARKS.md). On x86-64 CPUs
//! with AVX2 and FMA the same loops are compiled a second time for those features and chosen
//! at run time. Rust never fuses a multiply and an add on its own, so both builds round alike.
//!
//! Every lane computes exactly what the scalar rules of `grad.rs` compute in f32 (the same
//! functions, in the same order), so a lane's result is that of [`super::GradEval`]'s rules
//! run in f32, bit for bit, NaN and the sign of zero included.

use super::grad::{
    Grad, binary, chain_factors, max_takes_a, min_takes_a, scale, ternary, unary, unary_factor,
};
use super::real::Real;
use crate::compile::{BinaryOp, TernaryOp, UnaryOp};
use crate::tape::{Code, Operand, Tape};

/// Points evaluated together per instruction. Each register holds four arrays (the value and
/// its three derivatives), so this is a quarter of [`super::CHUNK`], and the same number of
/// registers fits in the first-level cache.
const CHUNK: usize = 128;

type Lanes = [f32; CHUNK];

/// One register over a chunk: values and the three partial derivatives, each in its own array.
#[derive(Clone, Debug)]
struct GradLanes {
    v: Lanes,
    /// d/dx, d/dy, d/dz.
    d: [Lanes; 3],
}

impl GradLanes {
    const ZERO: GradLanes = GradLanes {
        v: [0.0; CHUNK],
        d: [[0.0; CHUNK]; 3],
    };

    fn fill(&mut self, g: Grad<f32>) {
        self.v.fill(g.v);
        self.d[0].fill(g.dx);
        self.d[1].fill(g.dy);
        self.d[2].fill(g.dz);
    }

    #[inline(always)]
    fn get(&self, i: usize) -> Grad<f32> {
        Grad {
            v: self.v[i],
            dx: self.d[0][i],
            dy: self.d[1][i],
            dz: self.d[2][i],
        }
    }

    #[inline(always)]
    fn set(&mut self, i: usize, g: Grad<f32>) {
        self.v[i] = g.v;
        self.d[0][i] = g.dx;
        self.d[1][i] = g.dy;
        self.d[2][i] = g.dz;
    }
}

/// Values and gradients over slices of points in f32 (for surface normals).
///
/// Like [`super::BulkEval`], it runs one instruction at a time over a chunk of [`CHUNK`]
/// points, so the tape is interpreted once per chunk rather than once per point.
#[derive(Clone, Debug)]
pub struct GradBulkEval {
    tape: Tape,
    regs: Vec<GradLanes>,
    /// Three scratch chunks for the arguments of blends.
    scratch: Box<[GradLanes; 3]>,
    wide: bool,
}

impl GradBulkEval {
    /// An evaluator for `tape`.
    pub fn new(tape: &Tape) -> GradBulkEval {
        GradBulkEval {
            tape: tape.clone(),
            regs: vec![GradLanes::ZERO; tape.n_regs()],
            scratch: Box::new([GradLanes::ZERO, GradLanes::ZERO, GradLanes::ZERO]),
            wide: super::bulk::wide_simd_available(),
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
                if slot == 3 {
                    lanes.v.fill(t);
                } else {
                    lanes.v[..len].copy_from_slice(coords[slot]);
                    // Lanes past the end compute from 0, not from the previous chunk's points.
                    lanes.v[len..].fill(0.0);
                }
                for (axis, d) in lanes.d.iter_mut().enumerate() {
                    d.fill(if axis == slot { 1.0 } else { 0.0 });
                }
            }
            self.run();
            let out = &mut out[start..start + len];
            match self.tape.outputs()[0] {
                Operand::Reg(r) => {
                    let lanes = &self.regs[r as usize];
                    for (i, o) in out.iter_mut().enumerate() {
                        *o = lanes.get(i);
                    }
                }
                Operand::Const(c) => out.fill(Grad::constant(c as f32)),
            }
            start += len;
        }
    }

    fn run(&mut self) {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            #[expect(unsafe_code, reason = "calling a function compiled for AVX2 and FMA")]
            // SAFETY: `wide` is only set when the CPU reports AVX2 and FMA at run time.
            unsafe {
                run_wide(&self.tape, &mut self.regs, &mut self.scratch)
            };
            return;
        }
        run_tape(&self.tape, &mut self.regs, &mut self.scratch);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_wide(tape: &Tape, regs: &mut [GradLanes], scratch: &mut [GradLanes; 3]) {
    run_tape(tape, regs, scratch);
}

/// An argument of an instruction over a chunk: the lanes of a register, or a constant (whose
/// derivatives are zero). Kernels are generic over it, so a constant costs no loads.
trait Arg: Copy {
    fn v(self, i: usize) -> f32;
    fn d(self, axis: usize, i: usize) -> f32;
}

impl Arg for &GradLanes {
    #[inline(always)]
    fn v(self, i: usize) -> f32 {
        self.v[i]
    }

    #[inline(always)]
    fn d(self, axis: usize, i: usize) -> f32 {
        self.d[axis][i]
    }
}

#[derive(Clone, Copy)]
struct Constant(f32);

impl Arg for Constant {
    #[inline(always)]
    fn v(self, _: usize) -> f32 {
        self.0
    }

    #[inline(always)]
    fn d(self, _: usize, _: usize) -> f32 {
        0.0
    }
}

#[inline(always)]
fn lane(a: impl Arg, i: usize) -> Grad<f32> {
    Grad {
        v: a.v(i),
        dx: a.d(0, i),
        dy: a.d(1, i),
        dz: a.d(2, i),
    }
}

#[inline(always)]
fn src_lane(s: Src<'_>, i: usize) -> Grad<f32> {
    match s {
        Src::R(a) => lane(a, i),
        Src::C(c) => Grad::constant(c),
    }
}

#[derive(Clone, Copy)]
enum Src<'a> {
    R(&'a GradLanes),
    C(f32),
}

#[inline(always)]
fn run_tape(tape: &Tape, regs: &mut [GradLanes], scratch: &mut [GradLanes; 3]) {
    for instr in tape.instrs() {
        let out = instr.out as usize;
        let Some((o, args)) = super::split_out(regs, out) else {
            continue;
        };
        let src = |arg: Operand| match arg {
            Operand::Reg(r) => Src::R(args.get(r)),
            Operand::Const(c) => Src::C(c as f32),
        };
        let [a, b, c] = instr.args;
        match instr.code {
            Code::Unary(op) => match src(a) {
                Src::R(a) => unary_lanes(op, o, a),
                Src::C(a) => o.fill(unary(op, Grad::constant(a))),
            },
            Code::Binary(op) => match (src(a), src(b)) {
                (Src::R(a), Src::R(b)) => binary_lanes(op, o, a, b),
                (Src::R(a), Src::C(b)) => binary_lanes(op, o, a, Constant(b)),
                (Src::C(a), Src::R(b)) => binary_lanes(op, o, Constant(a), b),
                (Src::C(a), Src::C(b)) => o.fill(binary(op, Grad::constant(a), Grad::constant(b))),
            },
            Code::Ternary(TernaryOp::Select) => select_lanes(o, src(a), src(b), src(c)),
            Code::Ternary(op) => blend_lanes(op, o, [src(a), src(b), src(c)], scratch),
            Code::Sample(g) => {
                let grid = &tape.grids()[g as usize];
                let [a, b, c] = [src(a), src(b), src(c)];
                for i in 0..CHUNK {
                    let r =
                        super::grad::sample(grid, src_lane(a, i), src_lane(b, i), src_lane(c, i));
                    o.v[i] = r.v;
                    o.d[0][i] = r.dx;
                    o.d[1][i] = r.dy;
                    o.d[2][i] = r.dz;
                }
            }
        }
    }
}

/// `op(a)` with derivative `k a'`.
#[inline(always)]
fn chain1(o: &mut GradLanes, a: &GradLanes, f: impl Fn(f32) -> (f32, f32)) {
    for i in 0..CHUNK {
        let (v, k) = f(a.v[i]);
        o.v[i] = v;
        o.d[0][i] = scale(a.d[0][i], k);
        o.d[1][i] = scale(a.d[1][i], k);
        o.d[2][i] = scale(a.d[2][i], k);
    }
}

/// `a + b` or `a - b`, whose factors are constants: one loop.
#[inline(always)]
fn linear2(o: &mut GradLanes, a: impl Arg, b: impl Arg, op: BinaryOp) {
    for i in 0..CHUNK {
        let (x, y) = (a.v(i), b.v(i));
        let (ka, kb) = chain_factors(op, x, y);
        o.v[i] = f32::binary(op, x, y);
        for axis in 0..3 {
            o.d[axis][i] = scale(a.d(axis, i), ka) + scale(b.d(axis, i), kb);
        }
    }
}

/// `op(a, b)` with derivative `ka a' + kb b'`, for factors that vary by lane.
#[inline(always)]
fn chain2(o: &mut GradLanes, a: impl Arg, b: impl Arg, f: impl Fn(f32, f32) -> (f32, f32, f32)) {
    // The factors go through memory. In one loop with the derivatives, LLVM splits the body
    // by which factors are zero and vectorises it with masked loads and stores; two loops ran
    // the R-function models 2 to 3 times faster (`cargo bench -p fdsl --bench eval`).
    let mut ka = [0.0; CHUNK];
    let mut kb = [0.0; CHUNK];
    for i in 0..CHUNK {
        let (v, fa, fb) = f(a.v(i), b.v(i));
        o.v[i] = v;
        ka[i] = fa;
        kb[i] = fb;
    }
    for axis in 0..3 {
        for i in 0..CHUNK {
            o.d[axis][i] = scale(a.d(axis, i), ka[i]) + scale(b.d(axis, i), kb[i]);
        }
    }
}

/// `min` or `max`: the derivatives of the argument the value came from.
#[inline(always)]
fn pick(o: &mut GradLanes, a: impl Arg, b: impl Arg, op: BinaryOp, takes_a: fn(f32, f32) -> bool) {
    for i in 0..CHUNK {
        let (x, y) = (a.v(i), b.v(i));
        o.v[i] = f32::binary(op, x, y);
        let from_a = takes_a(x, y);
        for axis in 0..3 {
            // Both loads come before the choice, so the loop body has no branch.
            let (da, db) = (a.d(axis, i), b.d(axis, i));
            o.d[axis][i] = if from_a { da } else { db };
        }
    }
}

#[inline(always)]
fn unary_lanes(op: UnaryOp, o: &mut GradLanes, a: &GradLanes) {
    macro_rules! each {
        ($($v:ident),*) => {
            match op {
                $(UnaryOp::$v => chain1(o, a, |x| {
                    let v = f32::unary(UnaryOp::$v, x);
                    (v, unary_factor(UnaryOp::$v, x, v))
                }),)*
            }
        };
    }
    each!(
        Neg, Abs, Sqrt, Square, Sin, Cos, Tan, Asin, Acos, Atan, Exp, Ln, Floor, Ceil, Sign, Not
    )
}

#[inline(always)]
fn binary_lanes(op: BinaryOp, o: &mut GradLanes, a: impl Arg, b: impl Arg) {
    macro_rules! chain {
        ($v:ident) => {
            chain2(o, a, b, |x, y| {
                let (ka, kb) = chain_factors(BinaryOp::$v, x, y);
                (f32::binary(BinaryOp::$v, x, y), ka, kb)
            })
        };
    }
    macro_rules! constant {
        ($v:ident) => {
            for i in 0..CHUNK {
                o.v[i] = f32::binary(BinaryOp::$v, a.v(i), b.v(i));
            }
            for d in &mut o.d {
                d.fill(0.0);
            }
        };
    }
    match op {
        BinaryOp::Add => linear2(o, a, b, BinaryOp::Add),
        BinaryOp::Sub => linear2(o, a, b, BinaryOp::Sub),
        BinaryOp::Mul => chain!(Mul),
        BinaryOp::Div => chain!(Div),
        BinaryOp::Atan2 => chain!(Atan2),
        BinaryOp::Mod => chain!(Mod),
        BinaryOp::RAnd => chain!(RAnd),
        BinaryOp::ROr => chain!(ROr),
        BinaryOp::Min => pick(o, a, b, BinaryOp::Min, min_takes_a),
        BinaryOp::Max => pick(o, a, b, BinaryOp::Max, max_takes_a),
        BinaryOp::Lt => {
            constant!(Lt);
        }
        BinaryOp::Le => {
            constant!(Le);
        }
        BinaryOp::Eq => {
            constant!(Eq);
        }
        BinaryOp::And => {
            constant!(And);
        }
        BinaryOp::Or => {
            constant!(Or);
        }
        // The rule of `pow` depends on whether the exponent's gradient is zero, lane by lane;
        // it is rare (integer powers become products), so it runs the scalar rule per lane.
        BinaryOp::Pow => {
            for i in 0..CHUNK {
                o.set(i, binary(BinaryOp::Pow, lane(a, i), lane(b, i)));
            }
        }
    }
}

/// `if a != 0 { b } else { c }`, value and derivatives alike.
#[inline(always)]
fn select_lanes(o: &mut GradLanes, a: Src, b: Src, c: Src) {
    #[inline(always)]
    fn each(o: &mut GradLanes, a: &GradLanes, b: impl Arg, c: impl Arg) {
        for i in 0..CHUNK {
            let from_b = a.v[i] != 0.0;
            // Loads before the choice, as in `pick`.
            let (vb, vc) = (b.v(i), c.v(i));
            o.v[i] = if from_b { vb } else { vc };
            for axis in 0..3 {
                let (db, dc) = (b.d(axis, i), c.d(axis, i));
                o.d[axis][i] = if from_b { db } else { dc };
            }
        }
    }
    let a = match a {
        Src::R(a) => a,
        Src::C(a) => {
            match if a != 0.0 { b } else { c } {
                Src::R(r) => o.clone_from(r),
                Src::C(k) => o.fill(Grad::constant(k)),
            }
            return;
        }
    };
    match (b, c) {
        (Src::R(b), Src::R(c)) => each(o, a, b, c),
        (Src::R(b), Src::C(c)) => each(o, a, b, Constant(c)),
        (Src::C(b), Src::R(c)) => each(o, a, Constant(b), c),
        (Src::C(b), Src::C(c)) => each(o, a, Constant(b), Constant(c)),
    }
}

/// Blends are rare: their arguments are copied into scratch chunks and the scalar rule runs
/// per lane.
fn blend_lanes(op: TernaryOp, o: &mut GradLanes, args: [Src; 3], scratch: &mut [GradLanes; 3]) {
    for (s, arg) in scratch.iter_mut().zip(args) {
        match arg {
            Src::R(r) => s.clone_from(r),
            Src::C(c) => s.fill(Grad::constant(c)),
        }
    }
    let [a, b, c] = &*scratch;
    for i in 0..CHUNK {
        o.set(i, ternary(op, a.get(i), b.get(i), c.get(i)));
    }
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
            // Both builds of the loops, where the CPU has the wide one.
            let builds: &[bool] = if eval.wide { &[false, true] } else { &[false] };
            for &wide in builds {
                eval.wide = wide;
                eval.eval(&xs, &ys, &zs, t, &mut out);
                for (i, b) in out.iter().enumerate() {
                    let s = super::super::grad::eval_f32(&tape, [xs[i], ys[i], zs[i], t]);
                    let agree =
                        same(b.v, s.v) && same(b.dx, s.dx) && same(b.dy, s.dy) && same(b.dz, s.dz);
                    assert!(
                        agree,
                        "{src} (wide {wide}) at {:?}: bulk {b:?}, scalar {s:?}",
                        [xs[i], ys[i], zs[i]]
                    );
                }
            }
        }
    }
}
