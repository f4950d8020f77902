//! The f32 bulk evaluator: many points per call, one step at a time over a chunk of [`CHUNK`]
//! lanes, so dispatch costs once per step and chunk rather than per point, and each inner loop
//! is a plain loop over arrays that the compiler vectorises. A step is one instruction of the
//! tape, or several fused into one loop (`fuse.rs`), with the same results bit for bit. Steps read
//! coordinates from the caller's slices, and the last step writes a single output straight
//! into the caller's slice. On x86-64 the same loops are compiled again for AVX2 and FMA, and
//! for AVX-512, and the widest build the CPU runs is chosen at run time.

use super::fuse::{self, Arg, Bin, Kind, Lin, Pick, Plan, Shift, Squares, Sum, Term, Then, Un};
use super::real::{fast_cos, fast_sin};
use crate::compile::{BinaryOp, TernaryOp, UnaryOp};
use crate::tape::{Code, Tape};

/// Points evaluated together per step. A register is 2 KiB, so the reference models' tapes (up
/// to 9 registers) and a chunk of coordinates fit in a 48 KiB first-level cache. With 128 lanes
/// each step's dispatch and loop set-up came four times as often, and short tapes took up to
/// 1.7 times as long (BENCHMARKS.md).
pub const CHUNK: usize = 512;

type Lanes = [f32; CHUNK];

/// Points evaluated together in what is left after whole chunks, so that a call for a few
/// points computes a few lanes.
const SMALL: usize = 64;

/// Evaluates a tape over slices of points in f32.
#[derive(Clone, Debug)]
pub struct BulkEval {
    plan: Plan,
    regs: Vec<Lanes>,
    /// The coordinates of a last, partial small chunk, padded.
    pad: [[f32; SMALL]; 3],
    /// Three scratch chunks for the arguments of ternary operations and grid samples; none
    /// when the plan has no such step, so that building an evaluator for a short tape (a
    /// mesher builds one per simplified tape) stays cheap.
    scratch: Vec<Lanes>,
    simd: Simd,
}

impl BulkEval {
    /// An evaluator for `tape`.
    pub fn new(tape: &Tape) -> BulkEval {
        let plan = fuse::plan(tape);
        BulkEval {
            regs: vec![[0.0; CHUNK]; plan.n_regs],
            scratch: vec![[0.0; CHUNK]; if plan.gathers() { 3 } else { 0 }],
            plan,
            pad: [[0.0; SMALL]; 3],
            simd: Simd::widest(),
        }
    }

    /// The tape this evaluator runs.
    pub fn tape(&self) -> &Tape {
        &self.plan.tape
    }

    /// How many steps a chunk of points takes: the tape's instructions, fewer where pairs of
    /// them run as one.
    pub fn n_steps(&self) -> usize {
        self.plan.steps.len()
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
            outs.len() <= self.plan.outputs.len(),
            "more output slices than outputs"
        );
        assert!(
            outs.iter().all(|o| o.len() == n),
            "output slices differ in length"
        );
        let BulkEval {
            plan,
            regs,
            pad,
            scratch,
            simd,
            ..
        } = self;
        let mut start = 0;
        while start < n {
            // Whole chunks, then what is left in small chunks, so that a call for a few points
            // computes a few lanes, not a whole chunk.
            let whole = [x, y, z].map(|c| c[start..].first_chunk::<CHUNK>());
            let mut machine = Machine {
                plan,
                regs,
                scratch,
                simd: *simd,
            };
            start += match whole {
                [Some(x), Some(y), Some(z)] => machine.chunk([x, y, z], t, outs, start, CHUNK),
                _ => {
                    let len = SMALL.min(n - start);
                    let inputs = match [x, y, z].map(|c| c[start..].first_chunk::<SMALL>()) {
                        [Some(x), Some(y), Some(z)] => [x, y, z],
                        _ => {
                            for (p, c) in pad.iter_mut().zip([x, y, z]) {
                                p[..len].copy_from_slice(&c[start..start + len]);
                            }
                            [&pad[0], &pad[1], &pad[2]]
                        }
                    };
                    machine.chunk(inputs, t, outs, start, len)
                }
            };
        }
    }
}

/// What runs a plan: the plan, its registers and scratch.
struct Machine<'a> {
    plan: &'a Plan,
    regs: &'a mut [Lanes],
    scratch: &'a mut [Lanes],
    simd: Simd,
}

impl Machine<'_> {
    /// Evaluates the `len` points from `start` whose coordinates are the first `len` of
    /// `inputs`, in the first `N` lanes of each register; returns `len`.
    fn chunk<const N: usize>(
        &mut self,
        inputs: [&[f32; N]; 3],
        t: f32,
        outs: &mut [&mut [f32]],
        start: usize,
        len: usize,
    ) -> usize {
        let lanes = Lanes3 { inputs, t };
        let plan = self.plan;
        // A single output made by the last step is written straight to the caller's slice.
        let sink = match (&mut *outs, plan.last_writes_output()) {
            ([out], true) => out[start..].first_chunk_mut::<N>(),
            _ => None,
        };
        let direct = sink.is_some();
        run(self.simd, plan, self.regs, &lanes, self.scratch, sink);
        if direct {
            return len;
        }
        for (k, out) in outs.iter_mut().enumerate() {
            let out = &mut out[start..start + len];
            match plan.outputs[k] {
                Arg::Reg(r) => out.copy_from_slice(&self.regs[r as usize][..len]),
                Arg::Input(s) if s < 3 => out.copy_from_slice(&inputs[s as usize][..len]),
                Arg::Input(_) => out.fill(t),
                Arg::Const(c) => out.fill(c),
            }
        }
        len
    }
}

/// The first `N` lanes of a register.
#[inline(always)]
fn lanes_of<const N: usize>(reg: &Lanes) -> &[f32; N] {
    const { assert!(N <= CHUNK) };
    reg.first_chunk()
        .expect("a register holds at least N lanes")
}

/// The first `N` lanes of a register, to write.
#[inline(always)]
fn lanes_of_mut<const N: usize>(reg: &mut Lanes) -> &mut [f32; N] {
    const { assert!(N <= CHUNK) };
    reg.first_chunk_mut()
        .expect("a register holds at least N lanes")
}

/// A chunk's coordinates: `N` lanes of x, y and z, and one time.
struct Lanes3<'a, const N: usize> {
    inputs: [&'a [f32; N]; 3],
    t: f32,
}

/// Which build of the loops runs: the portable one, or one compiled for the wider vectors the
/// CPU reports at run time. Each gives the same bits: the loops use no fused multiply-add and
/// no operation whose result depends on the vector width.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Simd {
    Portable,
    /// AVX2 and FMA: eight lanes a vector.
    Avx2,
    /// AVX-512: sixteen lanes a vector, where fidget's JIT and the builds of the other bulk
    /// evaluators use eight.
    Avx512,
}

impl Simd {
    /// The widest build this CPU runs.
    pub(super) fn widest() -> Simd {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx512f") && has!("avx512vl") && has!("avx2") && has!("fma") {
                return Simd::Avx512;
            }
            if has!("avx2") && has!("fma") {
                return Simd::Avx2;
            }
        }
        Simd::Portable
    }

    /// Every build this CPU runs, the portable one first.
    #[cfg(test)]
    fn available() -> Vec<Simd> {
        let all = [Simd::Portable, Simd::Avx2, Simd::Avx512];
        let widest = Simd::widest();
        all.into_iter()
            .take_while(|&s| s != widest)
            .chain([widest])
            .collect()
    }
}

/// Runs the plan over the first `N` lanes of the registers. With a `sink`, the last step writes
/// there instead of to its register.
fn run<const N: usize>(
    simd: Simd,
    plan: &Plan,
    regs: &mut [Lanes],
    lanes: &Lanes3<N>,
    scratch: &mut [Lanes],
    sink: Option<&mut [f32; N]>,
) {
    match simd {
        #[cfg(target_arch = "x86_64")]
        #[expect(unsafe_code, reason = "calling a function compiled for AVX-512")]
        // SAFETY: `Simd::Avx512` is only chosen when the CPU reports AVX-512 (F and VL), AVX2
        // and FMA at run time.
        Simd::Avx512 => unsafe { run_avx512(plan, regs, lanes, scratch, sink) },
        #[cfg(target_arch = "x86_64")]
        #[expect(unsafe_code, reason = "calling a function compiled for AVX2 and FMA")]
        // SAFETY: `Simd::Avx2` is only chosen when the CPU reports AVX2 and FMA at run time.
        Simd::Avx2 => unsafe { run_wide(plan, regs, lanes, scratch, sink) },
        _ => run_plan(plan, regs, lanes, scratch, sink),
    }
}

/// Whether the CPU runs the AVX2 and FMA builds of the evaluators' loops.
pub(super) fn wide_simd_available() -> bool {
    Simd::widest() != Simd::Portable
}

/// Defines `$name`, [`run_plan`] compiled for the target features `$features`.
macro_rules! run_plan_built_for {
    ($name:ident, $features:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $name<const N: usize>(
            plan: &Plan,
            regs: &mut [Lanes],
            lanes: &Lanes3<N>,
            scratch: &mut [Lanes],
            sink: Option<&mut [f32; N]>,
        ) {
            run_plan(plan, regs, lanes, scratch, sink);
        }
    };
}

run_plan_built_for!(run_wide, "avx2,fma");
run_plan_built_for!(run_avx512, "avx512f,avx512vl,avx2,fma");

/// An argument of a step over `N` lanes: lanes, or one value for every lane.
#[derive(Clone, Copy)]
enum Src<'a, const N: usize> {
    R(&'a [f32; N]),
    C(f32),
}

/// `o[i] = f(a[i], b[i])`, one loop per kind of argument so that each vectorises.
#[inline(always)]
fn lanes2<const N: usize>(o: &mut [f32; N], a: Src<N>, b: Src<N>, f: impl Fn(f32, f32) -> f32) {
    match (a, b) {
        (Src::R(a), Src::R(b)) => {
            for i in 0..N {
                o[i] = f(a[i], b[i]);
            }
        }
        (Src::R(a), Src::C(c)) => {
            for i in 0..N {
                o[i] = f(a[i], c);
            }
        }
        (Src::C(c), Src::R(b)) => {
            for i in 0..N {
                o[i] = f(c, b[i]);
            }
        }
        (Src::C(c), Src::C(d)) => o.fill(f(c, d)),
    }
}

/// `o[i] = g(f(a[i], b[i]), c[i])`: a fused pair of binary operations.
#[inline(always)]
fn lanes3<const N: usize>(
    o: &mut [f32; N],
    a: Src<N>,
    b: Src<N>,
    c: Src<N>,
    f: impl Fn(f32, f32) -> f32,
    g: impl Fn(f32, f32) -> f32,
) {
    match (a, b, c) {
        (Src::R(a), Src::R(b), Src::R(c)) => {
            for i in 0..N {
                o[i] = g(f(a[i], b[i]), c[i]);
            }
        }
        (Src::R(a), Src::R(b), Src::C(c)) => {
            for i in 0..N {
                o[i] = g(f(a[i], b[i]), c);
            }
        }
        (Src::R(a), Src::C(b), Src::R(c)) => {
            for i in 0..N {
                o[i] = g(f(a[i], b), c[i]);
            }
        }
        (Src::R(a), Src::C(b), Src::C(c)) => {
            for i in 0..N {
                o[i] = g(f(a[i], b), c);
            }
        }
        (Src::C(a), Src::R(b), Src::R(c)) => {
            for i in 0..N {
                o[i] = g(f(a, b[i]), c[i]);
            }
        }
        (Src::C(a), Src::R(b), Src::C(c)) => {
            for i in 0..N {
                o[i] = g(f(a, b[i]), c);
            }
        }
        // The plan never fuses an operation of two constants; computed once all the same.
        (Src::C(a), Src::C(b), c) => lanes2(o, Src::C(f(a, b)), c, g),
    }
}

/// Matches `$e` and runs `$body` with `$f` bound to the lane function of its arm, so that each
/// arm's loops are compiled for that function.
macro_rules! bind {
    ($e:expr, $f:ident => $body:expr, { $($pat:pat => $lane:expr),+ $(,)? }) => {
        match $e {
            $($pat => {
                let $f = $lane;
                $body
            })+
        }
    };
}

/// Binds `$f` to the lane function of a fusing unary operation.
macro_rules! with_un {
    ($u:expr, $f:ident => $body:expr) => {
        bind!($u, $f => $body, {
            Un::Neg => move |x: f32| -x,
            Un::Abs => move |x: f32| x.abs(),
            Un::Sqrt => move |x: f32| x.sqrt(),
            Un::Square => move |x: f32| x * x,
        })
    };
}

/// Binds `$f` to the lane function of a fusing inner binary operation.
macro_rules! with_bin {
    ($b:expr, $f:ident => $body:expr) => {
        bind!($b, $f => $body, {
            Bin::Add => move |x: f32, y: f32| x + y,
            Bin::Sub => move |x: f32, y: f32| x - y,
            Bin::Mul => move |x: f32, y: f32| x * y,
            Bin::Min => move |x: f32, y: f32| min_nan(x, y),
            Bin::Max => move |x: f32, y: f32| max_nan(x, y),
        })
    };
}

/// Binds `$f` to the lane function `(v, a) -> then(v, a)` of a fusing outer operation.
macro_rules! with_then {
    ($t:expr, $f:ident => $body:expr) => {
        bind!($t, $f => $body, {
            Then::Add => move |v: f32, a: f32| v + a,
            Then::Mul => move |v: f32, a: f32| v * a,
            Then::Sub => move |v: f32, a: f32| v - a,
            Then::SubFrom => move |v: f32, a: f32| a - v,
            Then::Min => move |v: f32, a: f32| min_nan(v, a),
            Then::MinOf => move |v: f32, a: f32| min_nan(a, v),
            Then::Max => move |v: f32, a: f32| max_nan(v, a),
            Then::MaxOf => move |v: f32, a: f32| max_nan(a, v),
            Then::RAnd => move |v: f32, a: f32| r_and(v, a),
            Then::ROr => move |v: f32, a: f32| r_or(v, a),
        })
    };
}

/// Binds `$f` to the lane function `(v, a) -> lin(v, a)`.
macro_rules! with_lin {
    ($t:expr, $f:ident => $body:expr) => {
        bind!($t, $f => $body, {
            Lin::Add => move |v: f32, a: f32| v + a,
            Lin::Sub => move |v: f32, a: f32| v - a,
            Lin::SubFrom => move |v: f32, a: f32| a - v,
        })
    };
}

/// Binds `$f` to the lane function `(v, a) -> pick(v, a)`.
macro_rules! with_pick {
    ($t:expr, $f:ident => $body:expr) => {
        bind!($t, $f => $body, {
            Pick::Min => move |v: f32, a: f32| min_nan(v, a),
            Pick::MinOf => move |v: f32, a: f32| min_nan(a, v),
            Pick::Max => move |v: f32, a: f32| max_nan(v, a),
            Pick::MaxOf => move |v: f32, a: f32| max_nan(a, v),
        })
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

/// The R-function intersection; the same bits with its arguments swapped.
#[inline(always)]
fn r_and(a: f32, b: f32) -> f32 {
    a + b - (a * a + b * b).sqrt()
}

/// The R-function union; the same bits with its arguments swapped.
#[inline(always)]
fn r_or(a: f32, b: f32) -> f32 {
    a + b + (a * a + b * b).sqrt()
}

#[inline(always)]
fn bool_f32(b: bool) -> f32 {
    if b { 1.0 } else { 0.0 }
}

/// Runs a plan's steps over `N` lanes, writing the last into `sink` when given.
// tidy:table: one arm per fused step kind, kept in one match so the hot loop stays one function
#[inline(always)]
fn run_plan<const N: usize>(
    plan: &Plan,
    regs: &mut [Lanes],
    lanes: &Lanes3<N>,
    scratch: &mut [Lanes],
    mut sink: Option<&mut [f32; N]>,
) {
    let last = plan.steps.len().wrapping_sub(1);
    for (s, step) in plan.steps.iter().enumerate() {
        let out = step.out as usize;
        if let Kind::Plain(code @ (Code::Ternary(_) | Code::Sample(_))) = step.kind {
            let Some(scratch) = scratch.first_chunk_mut::<3>() else {
                unreachable!("an evaluator whose plan gathers holds three scratch chunks")
            };
            let [a, b, c, _] = step.args;
            gather(&[a, b, c], regs, lanes, scratch);
            let o = match sink.as_deref_mut() {
                Some(sink) if s == last => sink,
                _ => lanes_of_mut(&mut regs[out]),
            };
            match code {
                Code::Ternary(op) => ternary(op, o, scratch),
                Code::Sample(g) => sample(&plan.tape.grids()[g as usize], o, scratch),
                Code::Unary(_) | Code::Binary(_) => {}
            }
            continue;
        }
        let Some((o, args)) = super::split_out(regs, out) else {
            continue;
        };
        let o = match sink.as_deref_mut() {
            Some(sink) if s == last => sink,
            _ => lanes_of_mut(o),
        };
        let src = |arg: Arg| match arg {
            Arg::Reg(r) => Src::R(lanes_of(args.get(r))),
            Arg::Input(s) if s < 3 => Src::R(lanes.inputs[s as usize]),
            Arg::Input(_) => Src::C(lanes.t),
            Arg::Const(c) => Src::C(c),
        };
        let [a, b, c, d] = step.args.map(src);
        match step.kind {
            Kind::Plain(Code::Unary(op)) => match a {
                Src::R(a) => unary(op, o, a),
                Src::C(c) => o.fill(<f32 as super::real::Real>::unary(op, c)),
            },
            Kind::Plain(Code::Binary(op)) => binary(op, o, a, b),
            Kind::Plain(Code::Ternary(_) | Code::Sample(_)) => {}
            Kind::UnBin(u, op) => {
                with_un!(u, f => with_bin!(op, g => lanes2(o, a, b, move |x, y| f(g(x, y)))))
            }
            Kind::BinUn(t, u) => {
                with_then!(t, g => with_un!(u, f => lanes2(o, a, b, move |x, y| g(f(x), y))))
            }
            Kind::BinBin(t, op) => with_then!(t, g => with_bin!(op, f => lanes3(o, a, b, c, f, g))),
            Kind::SumSq(t, shift) => with_lin!(t, g => match shift {
                Shift::Plus => lanes3(o, a, b, c, |x, y| (x + y) * (x + y), g),
                Shift::Minus => lanes3(o, a, b, c, |x, y| (x - y) * (x - y), g),
            }),
            Kind::RootPick(p, t) => {
                with_pick!(p, g => with_lin!(t, f => lanes3(o, a, b, c, move |x, y| f(x.sqrt(), y), g)))
            }
            Kind::Sum(sum) => add_terms(o, [a, b, c], &sum, |v, _| v),
            Kind::SumThen(sum, t) => with_then!(t, g => match d {
                Src::R(d) => add_terms(o, [a, b, c], &sum, move |v, i| g(v, d[i])),
                Src::C(d) => add_terms(o, [a, b, c], &sum, move |v, _| g(v, d)),
            }),
            Kind::SumRootPick(sum, p, t, r) => {
                // Each term is `1 * (u - c)^2`, which is `(u - c)^2` bit for bit.
                let square = |t: Term, u: f32| (u - t.c) * (u - t.c);
                with_pick!(p, g => with_lin!(t, f => match d {
                    Src::R(d) => add_terms_with(o, [a, b, c], &sum, square, move |v, i| {
                        g(f(v.sqrt(), r), d[i])
                    }),
                    Src::C(d) => add_terms_with(o, [a, b, c], &sum, square, move |v, _| {
                        g(f(v.sqrt(), r), d)
                    }),
                }))
            }
        }
    }
}

/// `o[i] = finish(((offset + t0) + t1) + t2, i)`, with term `j` computed from lanes `u[j]`.
#[inline(always)]
fn add_terms<const N: usize>(
    o: &mut [f32; N],
    u: [Src<N>; 3],
    sum: &Sum,
    finish: impl Fn(f32, usize) -> f32,
) {
    let square = |t: Term, u: f32| t.k * ((u - t.c) * (u - t.c));
    bind!(sum.squares, term => add_terms_with(o, u, sum, term, finish), {
        Squares::All => square,
        Squares::None => |t: Term, u: f32| t.k * u,
        Squares::Some => move |t: Term, u: f32| if t.square { square(t, u) } else { t.k * u },
    })
}

/// [`add_terms`] with `term` computing each term.
#[inline(always)]
fn add_terms_with<const N: usize>(
    o: &mut [f32; N],
    u: [Src<N>; 3],
    sum: &Sum,
    term: impl Fn(Term, f32) -> f32,
    finish: impl Fn(f32, usize) -> f32,
) {
    let [t0, t1, t2] = sum.terms;
    let lanes = u.map(|u| match u {
        Src::R(lanes) => Some(lanes),
        Src::C(_) => None,
    });
    // The first term, after the offset if there is one.
    macro_rules! start {
        ($s:ident => $body:expr) => {
            bind!(sum.offset, $s => $body, {
                Some(c) => move |t: f32| c + t,
                None => move |t: f32| t,
            })
        };
    }
    match (sum.n, lanes) {
        (1, [Some(a), ..]) => start!(s => {
            for i in 0..N {
                o[i] = finish(s(term(t0, a[i])), i);
            }
        }),
        (2, [Some(a), Some(b), _]) => start!(s => {
            for i in 0..N {
                o[i] = finish(s(term(t0, a[i])) + term(t1, b[i]), i);
            }
        }),
        (3, [Some(a), Some(b), Some(d)]) => start!(s => {
            for i in 0..N {
                o[i] = finish(s(term(t0, a[i])) + term(t1, b[i]) + term(t2, d[i]), i);
            }
        }),
        _ => unreachable!("the plan gives a sum one to three terms of lanes"),
    }
}

macro_rules! lanes1 {
    ($o:ident, $a:ident, |$x:ident| $body:expr) => {
        for i in 0..N {
            let $x = $a[i];
            $o[i] = $body;
        }
    };
}

#[inline(always)]
fn unary<const N: usize>(op: UnaryOp, o: &mut [f32; N], a: &[f32; N]) {
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
fn binary<const N: usize>(op: BinaryOp, o: &mut [f32; N], a: Src<N>, b: Src<N>) {
    match op {
        BinaryOp::Add => lanes2(o, a, b, |x, y| x + y),
        BinaryOp::Sub => lanes2(o, a, b, |x, y| x - y),
        BinaryOp::Mul => lanes2(o, a, b, |x, y| x * y),
        BinaryOp::Div => lanes2(o, a, b, |x, y| x / y),
        BinaryOp::Min => lanes2(o, a, b, min_nan),
        BinaryOp::Max => lanes2(o, a, b, max_nan),
        BinaryOp::Pow => lanes2(o, a, b, |x, y| x.powf(y)),
        BinaryOp::Atan2 => lanes2(o, a, b, |x, y| x.atan2(y)),
        BinaryOp::Mod => lanes2(o, a, b, |x, y| x - y * (x / y).floor()),
        BinaryOp::Lt => lanes2(o, a, b, |x, y| bool_f32(x < y)),
        BinaryOp::Le => lanes2(o, a, b, |x, y| bool_f32(x <= y)),
        BinaryOp::Eq => lanes2(o, a, b, |x, y| bool_f32(x == y)),
        BinaryOp::And => lanes2(o, a, b, |x, y| bool_f32(x != 0.0 && y != 0.0)),
        BinaryOp::Or => lanes2(o, a, b, |x, y| bool_f32(x != 0.0 || y != 0.0)),
        BinaryOp::RAnd => lanes2(o, a, b, r_and),
        BinaryOp::ROr => lanes2(o, a, b, r_or),
    }
}

/// Copies a step's three arguments into scratch chunks (one values filled), so that its output
/// may share a register with none of them.
fn gather<const N: usize>(
    args: &[Arg; 3],
    regs: &[Lanes],
    lanes: &Lanes3<N>,
    scratch: &mut [Lanes; 3],
) {
    for (k, arg) in args.iter().enumerate() {
        match *arg {
            Arg::Reg(r) => scratch[k][..N].copy_from_slice(&regs[r as usize][..N]),
            Arg::Input(s) if s < 3 => scratch[k][..N].copy_from_slice(lanes.inputs[s as usize]),
            Arg::Input(_) => scratch[k][..N].fill(lanes.t),
            Arg::Const(c) => scratch[k][..N].fill(c),
        }
    }
}

/// Grid samples are computed per lane in f64 (the point evaluator's value, rounded).
fn sample<const N: usize>(grid: &crate::grid::Grid, o: &mut [f32; N], scratch: &[Lanes; 3]) {
    let [a, b, c] = scratch;
    for i in 0..N {
        o[i] = grid.value([f64::from(a[i]), f64::from(b[i]), f64::from(c[i])]) as f32;
    }
}

/// Ternary operations are rare; their arguments are copied into scratch chunks first, so the
/// output may share a register with none of them and constants need no special case.
fn ternary<const N: usize>(op: TernaryOp, o: &mut [f32; N], scratch: &[Lanes; 3]) {
    let [a, b, c] = scratch;
    match op {
        TernaryOp::Select => {
            for i in 0..N {
                o[i] = if a[i] != 0.0 { b[i] } else { c[i] };
            }
        }
        TernaryOp::BlendMin => {
            for i in 0..N {
                o[i] = blend_min(a[i], b[i], c[i]);
            }
        }
        TernaryOp::BlendMax => {
            for i in 0..N {
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

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use crate::Function;

    fn tape(src: &str) -> Tape {
        Function::parse(src).expect("a valid formula").tape()
    }

    /// The evaluator with one step per instruction.
    fn unfused(tape: &Tape) -> BulkEval {
        let mut eval = BulkEval::new(tape);
        eval.plan = fuse::plan_with(tape, false);
        eval.regs = vec![[0.0; CHUNK]; eval.plan.n_regs];
        eval.simd = Simd::Portable;
        eval
    }

    /// [`check_every_build`] for the formula `src` at `points`, against its unfused plan; a
    /// text that does not parse passes.
    fn check_formula(src: &str, points: &[(f32, f32, f32)], t: f32) -> Result<(), String> {
        let Ok(f) = Function::parse(src) else {
            return Ok(());
        };
        let tape = f.tape();
        let xs: Vec<f32> = points.iter().map(|p| p.0).collect();
        let ys: Vec<f32> = points.iter().map(|p| p.1).collect();
        let zs: Vec<f32> = points.iter().map(|p| p.2).collect();
        let mut reference = vec![0.0; xs.len()];
        unfused(&tape).eval(&xs, &ys, &zs, t, &mut reference);
        check_every_build(&tape, [&xs, &ys, &zs], t, &reference)
    }

    /// The fused evaluator's values at the points, with each build of the loops this CPU
    /// runs; fails unless every build gives `reference`'s bits.
    fn check_every_build(
        tape: &Tape,
        [xs, ys, zs]: [&[f32]; 3],
        t: f32,
        reference: &[f32],
    ) -> Result<(), String> {
        let mut eval = BulkEval::new(tape);
        let mut out = vec![0.0; xs.len()];
        for simd in Simd::available() {
            eval.simd = simd;
            eval.eval(xs, ys, zs, t, &mut out);
            if let Some(i) = (0..xs.len()).find(|&i| !same_bits(out[i], reference[i])) {
                return Err(format!(
                    "{simd:?} at ({}, {}, {}), t {t}: fused {} unfused {}",
                    xs[i], ys[i], zs[i], out[i], reference[i]
                ));
            }
        }
        Ok(())
    }

    /// Texts over x, y, z and t, mostly of the operations that fuse.
    fn expr() -> impl Strategy<Value = String> {
        let leaf = prop_oneof![
            Just("x".to_string()),
            Just("y".to_string()),
            Just("z".to_string()),
            Just("t".to_string()),
            (-2.0f64..2.0).prop_map(|v| format!("{v:.2}")),
        ];
        leaf.prop_recursive(5, 48, 2, |inner| {
            let un = prop_oneof![
                Just("-"),
                Just("abs"),
                Just("sqrt"),
                Just("sqr"),
                Just("sin")
            ];
            let bin = prop_oneof![
                Just("+"),
                Just("-"),
                Just("*"),
                Just("&"),
                Just("|"),
                Just("/"),
                Just("<")
            ];
            let rfunc = prop_oneof![Just("r_and"), Just("r_or")];
            prop_oneof![
                (un, inner.clone()).prop_map(|(f, a)| if f == "-" {
                    format!("-({a})")
                } else {
                    format!("{f}({a})")
                }),
                (inner.clone(), bin, inner.clone())
                    .prop_map(|(a, op, b)| format!("({a}) {op} ({b})")),
                (inner.clone(), inner.clone())
                    .prop_map(|(a, b)| format!("min(({a}) - ({b}), max({b}, {a}))")),
                (rfunc, inner.clone(), inner).prop_map(|(f, a, b)| format!("{f}({a}, {b})")),
            ]
        })
    }

    /// Coordinates with zeros of both signs and values whose square roots are NaN.
    fn coordinate() -> impl Strategy<Value = f32> {
        prop_oneof![
            4 => -2.0f32..2.0,
            1 => Just(0.0f32),
            1 => Just(-0.0f32),
        ]
    }

    fn same_bits(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

        #[test]
        fn fused_steps_give_the_bits_of_one_step_per_instruction(
            src in expr(),
            points in proptest::collection::vec((coordinate(), coordinate(), coordinate()), 1..1300),
            t in coordinate(),
        ) {
            let checked = check_formula(&src, &points, t);
            prop_assert!(checked.is_ok(), "{src}: {}", checked.unwrap_err());
        }
    }

    /// A term of a sum: `(u - c)^2` or `k * u` in each way it can be written, or a constant,
    /// with `u` a coordinate or a formula.
    fn term() -> impl Strategy<Value = String> {
        let lanes = prop_oneof![
            Just("x".to_string()),
            Just("y".to_string()),
            Just("z".to_string()),
            Just("t".to_string()),
            Just("(x * y - 0.25)".to_string()),
            Just("sin(z)".to_string()),
        ];
        let c = prop_oneof![Just(0.0f64), Just(-0.0), Just(1.0), -1.5f64..1.5];
        (lanes, c, 0..8u8).prop_map(|(u, c, form)| match form {
            0 => format!("({u} - ({c}))^2"),
            1 => format!("(({c}) - {u})^2"),
            2 => format!("({u} + ({c}))^2"),
            3 => format!("(({c}) + {u})^2"),
            4 => format!("{u}^2"),
            5 => format!("({c}) * {u}"),
            6 => format!("{u} * ({c})"),
            _ => format!("({c})"),
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

        #[test]
        fn sums_of_terms_give_the_bits_of_one_step_per_instruction(
            terms in proptest::collection::vec((term(), any::<bool>()), 2..6),
            nested in any::<bool>(),
            points in proptest::collection::vec((coordinate(), coordinate(), coordinate()), 1..600),
            t in coordinate(),
        ) {
            // Sums and differences of two to five terms, left to right or with the last two
            // grouped, read by a root as a ball reads them and by a second formula.
            let join = |terms: &[(String, bool)]| {
                let mut out = terms[0].0.clone();
                for (term, minus) in &terms[1..] {
                    out = format!("{out} {} {term}", if *minus { "-" } else { "+" });
                }
                out
            };
            let sum = match terms.split_at(terms.len() - 2) {
                (head, [a, b]) if nested && !head.is_empty() => {
                    let op = if a.1 { "-" } else { "+" };
                    format!("{} {op} ({})", join(head), join(&[(a.0.clone(), false), b.clone()]))
                }
                _ => join(&terms),
            };
            let src = format!("max(0.4 - sqrt({sum}), min({sum}, x) - 2)");
            let checked = check_formula(&src, &points, t);
            prop_assert!(checked.is_ok(), "{src}: {}", checked.unwrap_err());
        }
    }

    #[test]
    fn each_way_to_write_a_sum_gives_the_bits_of_one_step_per_instruction() {
        // One formula per rewrite of `fuse::sum_of` and `fuse::term`, each a sum in the plan.
        let formulas = [
            "(x - 0.5)^2 + (y + 0.25)^2",
            "(0.5 - x)^2 + (0.25 + y)^2 + z^2",
            "x^2 - (0.75 + y^2)",
            "x^2 - (y^2 - 0.75)",
            "0.3 * z - (0.9 * x - 0.1 * y)",
            "0.3 * z + (0.9 * x - y * 0.1)",
            "1.5 - x^2 - y^2 - z^2",
            "x^2 - 1.5",
            "(z - 1)^2 - 0.5 * x - 2 * y",
            "(t - 0.5) * 2 + x * 3",
            // Sums in the loop of the one operation that reads them.
            "min(x, 0.5 * y - z * 0.25)",
            "min(0.5 * y - z * 0.25, x)",
            "max(0.5 - y^2 - z^2, x)",
            "max(x, 0.5 - y^2 - z^2)",
            "r_and(x, 1 - y^2 - z^2)",
            "r_or(1 - y^2, sin(x))",
            "t - (x^2 + y^2)",
            "(x - 1)^2 + (y - 1)^2 - t",
            "(2 * x + y * 3) * z",
            // A ball's squared distance in the loop of the union or intersection with it.
            "max(x, 0.4 - sqrt((x - 0.5)^2 + (y + 0.25)^2 + z^2))",
            "max(0.4 - sqrt((0.5 - x)^2 + y^2), z - 1)",
            "min(sqrt(x^2 + (y - 1)^2 + (z + 0.5)^2) - 0.5, t)",
            "min(y, sqrt(1 + x^2) + 0.25)",
        ];
        let values = [-1.25f32, -0.5, -0.0, 0.0, 0.5, 1.0, 1.75];
        let mut xs = Vec::new();
        let (mut ys, mut zs) = (Vec::new(), Vec::new());
        for &x in &values {
            for &y in &values {
                for &z in &values {
                    xs.push(x);
                    ys.push(y);
                    zs.push(z);
                }
            }
        }
        for src in formulas {
            let tape = tape(src);
            let fused = BulkEval::new(&tape);
            let sums = fused.plan.steps.iter().filter(|s| {
                matches!(
                    s.kind,
                    Kind::Sum(_) | Kind::SumThen(..) | Kind::SumRootPick(..)
                )
            });
            assert!(sums.count() >= 1, "{src}: {:?}", fused.plan.steps);
            for t in [-0.0, 0.5] {
                let mut reference = vec![0.0; xs.len()];
                unfused(&tape).eval(&xs, &ys, &zs, t, &mut reference);
                if let Err(e) = check_every_build(&tape, [&xs, &ys, &zs], t, &reference) {
                    panic!("{src}: {e}");
                }
            }
        }
    }

    #[test]
    fn distance_formulas_take_a_fifth_of_the_steps() {
        let sphere = BulkEval::new(&tape("1-x^2-y^2-z^2"));
        assert_eq!(sphere.n_steps(), 1, "{:?}", sphere.plan.steps);
        // A ball: the squared distance to its centre, and the radius less the root.
        let ball = "0.3 - sqrt((x-0.1)^2 + (y+0.2)^2 + (z-0.3)^2)";
        assert_eq!(tape(ball).len(), 10);
        assert_eq!(BulkEval::new(&tape(ball)).n_steps(), 2);
        // A union of balls: the second's squared distance, root and radius go into the
        // union's step.
        let two = tape(&format!("({ball}) | (0.2 - sqrt(x^2 + (y-1)^2 + z^2))"));
        assert_eq!(two.len(), 19);
        assert_eq!(BulkEval::new(&two).n_steps(), 3);
        // Not where the radius varies: the squared distance is then a step of its own.
        let varying = tape(&format!("({ball}) | (x - sqrt(x^2 + (y-1)^2 + z^2))"));
        assert_eq!(BulkEval::new(&varying).n_steps(), 4);
        let spheres = tape(crate::models::reference_model("spheres100").expect("a model"));
        // The first ball is read by no union: its sum and its root are a step each.
        assert_eq!(BulkEval::new(&spheres).n_steps(), 101);
        // A cylinder's two terms, written the other way round.
        let cylinder = tape("0.5 - sqrt((0.2 - y)^2 + (x + 0.1)^2)");
        assert_eq!(BulkEval::new(&cylinder).n_steps(), 2);
        // Planes of products with constants, those products shared between the planes, and
        // two of them in the loops of the intersections that read them.
        let watermelon = tape(crate::models::reference_model("watermelon").expect("a model"));
        assert_eq!(watermelon.len(), 22);
        assert_eq!(BulkEval::new(&watermelon).n_steps(), 5);
        // R-functions take sums in as min and max do.
        let rfunc = tape(crate::models::reference_model("watermelon_rfunc").expect("a model"));
        assert_eq!(BulkEval::new(&rfunc).n_steps(), 5);
    }

    #[test]
    fn partial_chunks_and_copied_outputs_match_the_direct_write() {
        let tape = tape("sqrt(abs(x*y - z)) | (t - x^2)");
        let n = CHUNK * 2 + 13;
        let xs: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
        let ys: Vec<f32> = (0..n).map(|i| (i as f32 * 0.11).cos()).collect();
        let zs: Vec<f32> = (0..n).map(|i| (i as f32 * 0.05) - 1.0).collect();
        let mut eval = BulkEval::new(&tape);
        let mut all = vec![0.0; n];
        eval.eval(&xs, &ys, &zs, 0.5, &mut all);
        // Point by point, every call a partial chunk of one point.
        for i in 0..n {
            let mut one = [0.0];
            eval.eval(&xs[i..=i], &ys[i..=i], &zs[i..=i], 0.5, &mut one);
            assert!(same_bits(one[0], all[i]), "point {i}");
        }
        // Through the general output path, which copies from the register.
        let mut again = vec![0.0; n];
        let mut none: [&mut [f32]; 0] = [];
        eval.eval_outputs(&xs, &ys, &zs, 0.5, &mut none);
        eval.eval_outputs(&xs, &ys, &zs, 0.5, &mut [&mut again]);
        assert!(all.iter().zip(&again).all(|(a, b)| same_bits(*a, *b)));
        let mut reference = vec![0.0; n];
        unfused(&tape).eval(&xs, &ys, &zs, 0.5, &mut reference);
        assert!(all.iter().zip(&reference).all(|(a, b)| same_bits(*a, *b)));
    }
}
