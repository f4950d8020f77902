//! The f32 bulk evaluator: many points per call, one instruction at a time over a chunk of
//! [`CHUNK`] lanes, so dispatch costs once per instruction and chunk rather than per point, and
//! each inner loop is a plain loop over arrays that the compiler vectorises. On x86-64 CPUs with
//! AVX2 and FMA the same loops are compiled a second time for those features and chosen at run
//! time.

use super::real::{fast_cos, fast_sin};
use crate::compile::{BinaryOp, TernaryOp, UnaryOp};
use crate::tape::{Code, Instr, Operand, Tape};

/// Points evaluated together per instruction.
pub const CHUNK: usize = 128;

type Lanes = [f32; CHUNK];

/// Evaluates a tape over slices of points in f32.
#[derive(Clone, Debug)]
pub struct BulkEval {
    tape: Tape,
    regs: Vec<Lanes>,
    /// Three scratch chunks for constant arguments of ternary operations.
    scratch: Box<[Lanes; 3]>,
    wide: bool,
}

impl BulkEval {
    /// An evaluator for `tape`.
    pub fn new(tape: &Tape) -> BulkEval {
        BulkEval {
            tape: tape.clone(),
            regs: vec![[0.0; CHUNK]; tape.n_regs()],
            scratch: Box::new([[0.0; CHUNK]; 3]),
            wide: wide_simd_available(),
        }
    }

    /// The tape this evaluator runs.
    pub fn tape(&self) -> &Tape {
        &self.tape
    }

    /// The first output at the points `(x[i], y[i], z[i], t)`, written to `out[i]`.
    ///
    /// All four slices must have the same length.
    pub fn eval(&mut self, x: &[f32], y: &[f32], z: &[f32], t: f32, out: &mut [f32]) {
        self.eval_outputs(x, y, z, t, &mut [out]);
    }

    /// Several outputs at once: `outs[k][i]` receives output `k` at point `i`.
    pub fn eval_outputs(
        &mut self,
        x: &[f32],
        y: &[f32],
        z: &[f32],
        t: f32,
        outs: &mut [&mut [f32]],
    ) {
        let n = x.len();
        assert!(
            y.len() == n && z.len() == n,
            "coordinate slices differ in length"
        );
        assert!(
            outs.len() <= self.tape.outputs().len(),
            "more output slices than outputs"
        );
        assert!(
            outs.iter().all(|o| o.len() == n),
            "output slices differ in length"
        );
        let inputs = self.tape.inputs();
        let mut start = 0;
        while start < n {
            let len = CHUNK.min(n - start);
            let coords = [
                &x[start..start + len],
                &y[start..start + len],
                &z[start..start + len],
            ];
            for (slot, reg) in inputs.iter().enumerate() {
                let Some(r) = reg else { continue };
                let lanes = &mut self.regs[*r as usize];
                if slot == 3 {
                    lanes.fill(t);
                } else {
                    lanes[..len].copy_from_slice(coords[slot]);
                }
            }
            self.run();
            for (k, out) in outs.iter_mut().enumerate() {
                match self.tape.outputs()[k] {
                    Operand::Reg(r) => {
                        out[start..start + len].copy_from_slice(&self.regs[r as usize][..len])
                    }
                    Operand::Const(c) => out[start..start + len].fill(c as f32),
                }
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

/// Whether the CPU runs the AVX2 and FMA builds of the evaluators' loops.
pub(super) fn wide_simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_wide(tape: &Tape, regs: &mut [Lanes], scratch: &mut [Lanes; 3]) {
    run_tape(tape, regs, scratch);
}

/// An argument of an instruction over a chunk: lanes of a register, or one constant.
#[derive(Clone, Copy)]
enum Src<'a> {
    R(&'a Lanes),
    C(f32),
}

macro_rules! lanes1 {
    ($o:ident, $a:ident, |$x:ident| $body:expr) => {
        for i in 0..CHUNK {
            let $x = $a[i];
            $o[i] = $body;
        }
    };
}

macro_rules! lanes2 {
    ($o:ident, $a:expr, $b:expr, |$x:ident, $y:ident| $body:expr) => {
        match ($a, $b) {
            (Src::R(a), Src::R(b)) => {
                for i in 0..CHUNK {
                    let $x = a[i];
                    let $y = b[i];
                    $o[i] = $body;
                }
            }
            (Src::R(a), Src::C(c)) => {
                for i in 0..CHUNK {
                    let $x = a[i];
                    let $y = c;
                    $o[i] = $body;
                }
            }
            (Src::C(c), Src::R(b)) => {
                for i in 0..CHUNK {
                    let $x = c;
                    let $y = b[i];
                    $o[i] = $body;
                }
            }
            (Src::C(c), Src::C(d)) => {
                let $x = c;
                let $y = d;
                let v = $body;
                $o.fill(v);
            }
        }
    };
}

#[inline(always)]
fn min_nan(a: f32, b: f32) -> f32 {
    let m = if b < a { b } else { a };
    if b.is_nan() { b } else { m }
}

#[inline(always)]
fn max_nan(a: f32, b: f32) -> f32 {
    let m = if b > a { b } else { a };
    if b.is_nan() { b } else { m }
}

#[inline(always)]
fn bool_f32(b: bool) -> f32 {
    if b { 1.0 } else { 0.0 }
}

#[inline(always)]
fn run_tape(tape: &Tape, regs: &mut [Lanes], scratch: &mut [Lanes; 3]) {
    for instr in tape.instrs() {
        let out = instr.out as usize;
        match instr.code {
            Code::Ternary(op) => {
                ternary(op, instr, regs, scratch);
                continue;
            }
            Code::Sample(g) => {
                sample(&tape.grids()[g as usize], instr, regs, scratch);
                continue;
            }
            Code::Unary(_) | Code::Binary(_) => {}
        }
        let Some((o, args)) = super::split_out(regs, out) else {
            continue;
        };
        let src = |arg: Operand| match arg {
            Operand::Reg(r) => Src::R(args.get(r)),
            Operand::Const(c) => Src::C(c as f32),
        };
        match instr.code {
            Code::Unary(op) => {
                let a = match src(instr.args[0]) {
                    Src::R(a) => a,
                    Src::C(c) => {
                        o.fill(<f32 as super::real::Real>::unary(op, c));
                        continue;
                    }
                };
                unary(op, o, a);
            }
            Code::Binary(op) => binary(op, o, src(instr.args[0]), src(instr.args[1])),
            Code::Ternary(_) | Code::Sample(_) => {}
        }
    }
}

#[inline(always)]
fn unary(op: UnaryOp, o: &mut Lanes, a: &Lanes) {
    match op {
        UnaryOp::Neg => lanes1!(o, a, |x| -x),
        UnaryOp::Abs => lanes1!(o, a, |x| x.abs()),
        UnaryOp::Sqrt => lanes1!(o, a, |x| x.sqrt()),
        UnaryOp::Square => lanes1!(o, a, |x| x * x),
        UnaryOp::Sin => lanes1!(o, a, |x| fast_sin(x)),
        UnaryOp::Cos => lanes1!(o, a, |x| fast_cos(x)),
        UnaryOp::Tan => lanes1!(o, a, |x| fast_sin(x) / fast_cos(x)),
        UnaryOp::Floor => lanes1!(o, a, |x| x.floor()),
        UnaryOp::Ceil => lanes1!(o, a, |x| x.ceil()),
        UnaryOp::Sign => lanes1!(o, a, |x| if x > 0.0 {
            1.0
        } else if x < 0.0 {
            -1.0
        } else {
            x
        }),
        UnaryOp::Not => lanes1!(o, a, |x| bool_f32(x == 0.0)),
        UnaryOp::Asin => lanes1!(o, a, |x| x.asin()),
        UnaryOp::Acos => lanes1!(o, a, |x| x.acos()),
        UnaryOp::Atan => lanes1!(o, a, |x| x.atan()),
        UnaryOp::Exp => lanes1!(o, a, |x| x.exp()),
        UnaryOp::Ln => lanes1!(o, a, |x| x.ln()),
    }
}

#[inline(always)]
fn binary(op: BinaryOp, o: &mut Lanes, a: Src, b: Src) {
    match op {
        BinaryOp::Add => lanes2!(o, a, b, |x, y| x + y),
        BinaryOp::Sub => lanes2!(o, a, b, |x, y| x - y),
        BinaryOp::Mul => lanes2!(o, a, b, |x, y| x * y),
        BinaryOp::Div => lanes2!(o, a, b, |x, y| x / y),
        BinaryOp::Min => lanes2!(o, a, b, |x, y| min_nan(x, y)),
        BinaryOp::Max => lanes2!(o, a, b, |x, y| max_nan(x, y)),
        BinaryOp::Pow => lanes2!(o, a, b, |x, y| x.powf(y)),
        BinaryOp::Atan2 => lanes2!(o, a, b, |x, y| x.atan2(y)),
        BinaryOp::Mod => lanes2!(o, a, b, |x, y| x - y * (x / y).floor()),
        BinaryOp::Lt => lanes2!(o, a, b, |x, y| bool_f32(x < y)),
        BinaryOp::Le => lanes2!(o, a, b, |x, y| bool_f32(x <= y)),
        BinaryOp::Eq => lanes2!(o, a, b, |x, y| bool_f32(x == y)),
        BinaryOp::And => lanes2!(o, a, b, |x, y| bool_f32(x != 0.0 && y != 0.0)),
        BinaryOp::Or => lanes2!(o, a, b, |x, y| bool_f32(x != 0.0 || y != 0.0)),
        BinaryOp::RAnd => lanes2!(o, a, b, |x, y| x + y - (x * x + y * y).sqrt()),
        BinaryOp::ROr => lanes2!(o, a, b, |x, y| x + y + (x * x + y * y).sqrt()),
    }
}

/// Copies an instruction's three arguments into scratch chunks (constants filled), so that
/// its output may share a register with none of them.
fn gather(instr: &Instr, regs: &[Lanes], scratch: &mut [Lanes; 3]) {
    for (k, arg) in instr.args.iter().enumerate() {
        match *arg {
            Operand::Reg(r) => scratch[k] = regs[r as usize],
            Operand::Const(c) => scratch[k].fill(c as f32),
        }
    }
}

/// Grid samples are computed per lane in f64 (the point evaluator's value, rounded).
fn sample(grid: &crate::grid::Grid, instr: &Instr, regs: &mut [Lanes], scratch: &mut [Lanes; 3]) {
    gather(instr, regs, scratch);
    let o = &mut regs[instr.out as usize];
    let [a, b, c] = &*scratch;
    for i in 0..CHUNK {
        o[i] = grid.value([f64::from(a[i]), f64::from(b[i]), f64::from(c[i])]) as f32;
    }
}

/// Ternary operations are rare; their arguments are copied into scratch chunks first, so the
/// output may share a register with none of them and constants need no special case.
fn ternary(op: TernaryOp, instr: &Instr, regs: &mut [Lanes], scratch: &mut [Lanes; 3]) {
    gather(instr, regs, scratch);
    let o = &mut regs[instr.out as usize];
    let [a, b, c] = &*scratch;
    match op {
        TernaryOp::Select => {
            for i in 0..CHUNK {
                o[i] = if a[i] != 0.0 { b[i] } else { c[i] };
            }
        }
        TernaryOp::BlendMin => {
            for i in 0..CHUNK {
                o[i] = blend_min(a[i], b[i], c[i]);
            }
        }
        TernaryOp::BlendMax => {
            for i in 0..CHUNK {
                o[i] = -blend_min(-a[i], -b[i], c[i]);
            }
        }
    }
}

#[inline(always)]
fn blend_min(a: f32, b: f32, r: f32) -> f32 {
    let h = (r - (a - b).abs()).max(0.0) / r;
    min_nan(a, b) - h * h * r * 0.25
}
