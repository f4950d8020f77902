//! The bulk interval evaluator: bounds over many boxes per call, one instruction at a time over
//! a chunk of [`BOX_CHUNK`] boxes, so the tape is interpreted once per instruction and chunk
//! rather than once per instruction and box.
//!
//! Each register is a structure of arrays (lower ends, upper ends and NaN flags, each a chunk
//! of lanes). The common operations have branch-free kernels written for these arrays, which
//! the compiler vectorises; the rest call the scalar rules of `interval.rs` lane by lane. On
//! x86-64 CPUs with AVX2 and FMA the loops are compiled a second time for those features and
//! chosen at run time; Rust never fuses a multiply and an add on its own, so both builds
//! round alike.
//!
//! Every lane's bounds, NaN flag and choice are exactly those of the scalar rules run
//! instruction by instruction over the same box, bit for bit
//! (`bulk_intervals_are_the_scalar_rules_bit_for_bit`). [`super::IntervalEval`] runs these
//! kernels over one box per pass: dispatched once per instruction and operand kind, it bounds
//! a box 1.2 to 3 times faster than the same rules dispatched per operation inside a generic
//! loop did (BENCHMARKS.md).

use super::interval::{Interval, binary, sample, ternary, unary};
use crate::compile::{BinaryOp, UnaryOp};
use crate::tape::{Choice, Code, Operand, Tape};

/// Boxes evaluated together per instruction.
pub const BOX_CHUNK: usize = 64;

/// One register over a pass of up to `N` boxes.
#[derive(Clone, Debug)]
struct IntervalLanes<const N: usize> {
    lo: [f64; N],
    hi: [f64; N],
    nan: [bool; N],
}

impl<const N: usize> IntervalLanes<N> {
    const ZERO: IntervalLanes<N> = IntervalLanes {
        lo: [0.0; N],
        hi: [0.0; N],
        nan: [false; N],
    };

    fn fill(&mut self, v: Interval) {
        self.lo.fill(v.lo);
        self.hi.fill(v.hi);
        self.nan.fill(v.nan);
    }

    #[inline(always)]
    fn set(&mut self, i: usize, v: Interval) {
        self.lo[i] = v.lo;
        self.hi[i] = v.hi;
        self.nan[i] = v.nan;
    }

    #[inline(always)]
    fn get(&self, i: usize) -> Interval {
        Interval {
            lo: self.lo[i],
            hi: self.hi[i],
            nan: self.nan[i],
        }
    }
}

/// A tape's registers and choices over passes of up to `N` boxes: the engine of both
/// [`IntervalBulkEval`] (64 boxes) and [`super::IntervalEval`] (one box).
#[derive(Clone, Debug)]
pub(super) struct Passes<const N: usize> {
    tape: Tape,
    regs: Vec<IntervalLanes<N>>,
    /// One pass of choices per instruction, for the last pass run.
    choices: Vec<[Choice; N]>,
    wide: bool,
}

impl<const N: usize> Passes<N> {
    pub(super) fn new(tape: &Tape) -> Passes<N> {
        Passes {
            tape: tape.clone(),
            regs: vec![IntervalLanes::ZERO; tape.n_regs()],
            choices: vec![[Choice::Both; N]; tape.len()],
            // One box per pass has nothing to vectorise.
            wide: N > 1 && super::bulk::wide_simd_available(),
        }
    }

    pub(super) fn tape(&self) -> &Tape {
        &self.tape
    }

    /// Sets box `i` of the next pass.
    #[inline]
    pub(super) fn load(&mut self, i: usize, b: &[Interval; 4]) {
        for (slot, reg) in self.tape.inputs().iter().enumerate() {
            if let Some(r) = reg {
                self.regs[*r as usize].set(i, b[slot]);
            }
        }
    }

    /// Runs the tape over the first `n` boxes.
    pub(super) fn run(&mut self, n: usize) {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            #[expect(unsafe_code, reason = "calling a function compiled for AVX2 and FMA")]
            // SAFETY: `wide` is only set when the CPU reports AVX2 and FMA at run time.
            unsafe {
                run_wide(&self.tape, &mut self.regs, &mut self.choices, n)
            };
            return;
        }
        run_tape(&self.tape, &mut self.regs, &mut self.choices, n);
    }

    /// Output `idx` over box `i` of the last pass.
    #[inline]
    pub(super) fn output(&self, idx: usize, i: usize) -> Interval {
        match self.tape.outputs()[idx] {
            Operand::Reg(r) => self.regs[r as usize].get(i),
            Operand::Const(c) => Interval::point(c),
        }
    }

    /// The last pass's choices, one pass per instruction.
    pub(super) fn choices(&self) -> &[[Choice; N]] {
        &self.choices
    }
}

/// Bounds of a tape over many boxes at once, with each box's choices for [`Tape::simplify`].
///
/// It gives what [`super::IntervalEval`] gives box by box, faster when there are many boxes to
/// bound at once (the cells of `crate::object::fit_domain`'s search).
#[derive(Clone, Debug)]
pub struct IntervalBulkEval {
    passes: Passes<BOX_CHUNK>,
    /// Where the last chunk evaluated starts among the boxes of the last call.
    last_chunk: usize,
    /// How many boxes the last chunk holds.
    last_len: usize,
}

impl IntervalBulkEval {
    /// An evaluator for `tape`.
    pub fn new(tape: &Tape) -> IntervalBulkEval {
        IntervalBulkEval {
            passes: Passes::new(tape),
            last_chunk: 0,
            last_len: 0,
        }
    }

    /// The tape this evaluator runs.
    pub fn tape(&self) -> &Tape {
        self.passes.tape()
    }

    /// Bounds of the first output over each box `[x, y, z, t]` of `boxes`, written to `out`.
    ///
    /// # Panics
    /// If `out` and `boxes` differ in length.
    pub fn eval(&mut self, boxes: &[[Interval; 4]], out: &mut [Interval]) {
        assert_eq!(boxes.len(), out.len(), "boxes and outputs differ in length");
        self.last_chunk = 0;
        self.last_len = 0;
        for (start, (chunk, out)) in boxes
            .chunks(BOX_CHUNK)
            .zip(out.chunks_mut(BOX_CHUNK))
            .enumerate()
        {
            for (i, b) in chunk.iter().enumerate() {
                self.passes.load(i, b);
            }
            self.passes.run(chunk.len());
            for (i, o) in out.iter_mut().enumerate() {
                *o = self.passes.output(0, i);
            }
            self.last_chunk = start * BOX_CHUNK;
            self.last_len = chunk.len();
        }
    }

    /// The choices, one per instruction, that the last [`IntervalBulkEval::eval`] made for its
    /// box `k`, written to `out` (cleared first) for [`Tape::simplify`].
    ///
    /// Choices are kept for the last [`BOX_CHUNK`] boxes of a call (all of them when a call
    /// bounds at most that many).
    ///
    /// # Panics
    /// If box `k` was not among them.
    pub fn choices(&self, k: usize, out: &mut Vec<Choice>) {
        assert!(
            k >= self.last_chunk && k < self.last_chunk + self.last_len,
            "the choices of box {k} are not kept"
        );
        let lane = k - self.last_chunk;
        out.clear();
        out.extend(self.passes.choices().iter().map(|c| c[lane]));
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_wide<const N: usize>(
    tape: &Tape,
    regs: &mut [IntervalLanes<N>],
    choices: &mut [[Choice; N]],
    n: usize,
) {
    run_tape(tape, regs, choices, n);
}

/// An argument of an instruction over a chunk: the lanes of a register, or a constant.
/// Kernels are generic over it, so a constant costs no loads.
trait Arg: Copy {
    fn lo(self, i: usize) -> f64;
    fn hi(self, i: usize) -> f64;
    fn nan(self, i: usize) -> bool;

    #[inline(always)]
    fn get(self, i: usize) -> Interval {
        Interval {
            lo: self.lo(i),
            hi: self.hi(i),
            nan: self.nan(i),
        }
    }
}

impl<const N: usize> Arg for &IntervalLanes<N> {
    #[inline(always)]
    fn lo(self, i: usize) -> f64 {
        self.lo[i]
    }

    #[inline(always)]
    fn hi(self, i: usize) -> f64 {
        self.hi[i]
    }

    #[inline(always)]
    fn nan(self, i: usize) -> bool {
        self.nan[i]
    }
}

#[derive(Clone, Copy)]
struct Constant(Interval);

impl Arg for Constant {
    #[inline(always)]
    fn lo(self, _: usize) -> f64 {
        self.0.lo
    }

    #[inline(always)]
    fn hi(self, _: usize) -> f64 {
        self.0.hi
    }

    #[inline(always)]
    fn nan(self, _: usize) -> bool {
        self.0.nan
    }
}

#[derive(Clone, Copy)]
enum Src<'a, const N: usize> {
    R(&'a IntervalLanes<N>),
    C(Interval),
}

impl<const N: usize> Src<'_, N> {
    #[inline(always)]
    fn get(self, i: usize) -> Interval {
        match self {
            Src::R(a) => a.get(i),
            Src::C(c) => c,
        }
    }
}

#[inline(always)]
fn run_tape<const N: usize>(
    tape: &Tape,
    regs: &mut [IntervalLanes<N>],
    choices: &mut [[Choice; N]],
    n: usize,
) {
    // Every kernel runs over lanes `0..n`: within the arrays.
    let n = n.min(N);
    for (instr, ch) in tape.instrs().iter().zip(choices.iter_mut()) {
        let out = instr.out as usize;
        let Some((o, args)) = super::split_out(regs, out) else {
            continue;
        };
        let src = |arg: Operand| match arg {
            Operand::Reg(r) => Src::R(args.get(r)),
            Operand::Const(c) => Src::C(Interval::point(c)),
        };
        let [a, b, c] = instr.args;
        match instr.code {
            Code::Unary(op) => match src(a) {
                Src::R(a) => unary_lanes(op, o, a, n),
                Src::C(a) => o.fill(unary(op, a)),
            },
            Code::Binary(op) => match (src(a), src(b)) {
                (Src::R(a), Src::R(b)) => binary_lanes(op, o, ch, a, b, n),
                (Src::R(a), Src::C(b)) => binary_lanes(op, o, ch, a, Constant(b), n),
                (Src::C(a), Src::R(b)) => binary_lanes(op, o, ch, Constant(a), b, n),
                (Src::C(a), Src::C(b)) => {
                    let (v, choice) = binary(op, a, b);
                    o.fill(v);
                    ch.fill(choice);
                }
            },
            Code::Ternary(op) => {
                let [a, b, c] = [src(a), src(b), src(c)];
                for (i, choice) in ch[..n].iter_mut().enumerate() {
                    let v;
                    (v, *choice) = ternary(op, a.get(i), b.get(i), c.get(i));
                    o.set(i, v);
                }
            }
            Code::Sample(g) => {
                let grid = &tape.grids()[g as usize];
                let [a, b, c] = [src(a), src(b), src(c)];
                for i in 0..n {
                    o.set(i, sample(grid, [a.get(i), b.get(i), c.get(i)]));
                }
            }
        }
    }
}

/// A unary rule lane by lane.
#[inline(always)]
fn map1<const N: usize>(
    o: &mut IntervalLanes<N>,
    a: &IntervalLanes<N>,
    n: usize,
    f: impl Fn(Interval) -> Interval,
) {
    for i in 0..n {
        o.set(i, f(a.get(i)));
    }
}

/// A binary rule lane by lane, with its choice.
#[inline(always)]
fn map2<const N: usize>(
    o: &mut IntervalLanes<N>,
    ch: &mut [Choice; N],
    a: impl Arg,
    b: impl Arg,
    n: usize,
    f: impl Fn(Interval, Interval) -> (Interval, Choice),
) {
    for (i, choice) in ch[..n].iter_mut().enumerate() {
        let v;
        (v, *choice) = f(a.get(i), b.get(i));
        o.set(i, v);
    }
}

#[inline(always)]
fn unary_lanes<const N: usize>(
    op: UnaryOp,
    o: &mut IntervalLanes<N>,
    a: &IntervalLanes<N>,
    n: usize,
) {
    macro_rules! each {
        ($($v:ident),*) => {
            match op {
                UnaryOp::Neg => neg(o, a, n),
                UnaryOp::Square => square(o, a, n),
                UnaryOp::Sqrt => sqrt(o, a, n),
                $(UnaryOp::$v => map1(o, a, n, |x| unary(UnaryOp::$v, x)),)*
            }
        };
    }
    each!(
        Abs, Sin, Cos, Tan, Asin, Acos, Atan, Exp, Ln, Floor, Ceil, Sign, Not
    );
}

#[inline(always)]
fn binary_lanes<const N: usize>(
    op: BinaryOp,
    o: &mut IntervalLanes<N>,
    ch: &mut [Choice; N],
    a: impl Arg,
    b: impl Arg,
    n: usize,
) {
    macro_rules! each {
        ($($v:ident),*) => {
            match op {
                BinaryOp::Add => add_sub(o, ch, a, b, n, false),
                BinaryOp::Sub => add_sub(o, ch, a, b, n, true),
                BinaryOp::Mul => mul(o, ch, a, b, n),
                BinaryOp::Min => min_max(o, ch, a, b, n, false),
                BinaryOp::Max => min_max(o, ch, a, b, n, true),
                BinaryOp::RAnd => r_function(o, ch, a, b, n, false),
                BinaryOp::ROr => r_function(o, ch, a, b, n, true),
                $(BinaryOp::$v => map2(o, ch, a, b, n, |x, y| binary(BinaryOp::$v, x, y)),)*
            }
        };
    }
    each!(Div, Pow, Atan2, Mod, Lt, Le, Eq, And, Or);
}

// Branch-free kernels for the operations that dominate distance fields. Each writes, for every
// lane, exactly what the scalar rule of `interval.rs` gives (the same expressions in the same
// order, with its branches turned into selects), so that the loops vectorise.

/// Whether an interval's ends are NaN, which makes it NaN everywhere.
#[inline(always)]
fn ends_nan(lo: f64, hi: f64) -> bool {
    lo.is_nan() | hi.is_nan()
}

/// Writes lane `i`: NaN everywhere if `undefined`, else `[lo, hi]` with the flag `nan`.
#[inline(always)]
fn put<const N: usize>(
    o: &mut IntervalLanes<N>,
    i: usize,
    undefined: bool,
    lo: f64,
    hi: f64,
    nan: bool,
) {
    o.lo[i] = if undefined { f64::NAN } else { lo };
    o.hi[i] = if undefined { f64::NAN } else { hi };
    o.nan[i] = undefined | nan;
}

fn neg<const N: usize>(o: &mut IntervalLanes<N>, a: &IntervalLanes<N>, n: usize) {
    for i in 0..n {
        let (lo, hi) = (a.lo[i], a.hi[i]);
        put(o, i, ends_nan(lo, hi), -hi, -lo, a.nan[i]);
    }
}

fn square<const N: usize>(o: &mut IntervalLanes<N>, a: &IntervalLanes<N>, n: usize) {
    for i in 0..n {
        let (lo, hi) = (a.lo[i], a.hi[i]);
        let (l2, h2) = (lo * lo, hi * hi);
        let up = lo >= 0.0;
        let down = hi <= 0.0;
        let rlo = if up {
            l2
        } else if down {
            h2
        } else {
            0.0
        };
        let rhi = if up {
            h2
        } else if down {
            l2
        } else {
            l2.max(h2)
        };
        put(o, i, ends_nan(lo, hi), rlo, rhi, a.nan[i]);
    }
}

fn sqrt<const N: usize>(o: &mut IntervalLanes<N>, a: &IntervalLanes<N>, n: usize) {
    for i in 0..n {
        let (lo, hi) = (a.lo[i], a.hi[i]);
        let below = hi < 0.0;
        let rlo = lo.max(0.0).sqrt();
        let rhi = hi.sqrt();
        put(
            o,
            i,
            ends_nan(lo, hi) | below,
            rlo,
            rhi,
            a.nan[i] | (lo < 0.0),
        );
    }
}

/// `a + b`, or `a - b` when `sub`.
#[inline(always)]
fn add_sub<const N: usize>(
    o: &mut IntervalLanes<N>,
    ch: &mut [Choice; N],
    a: impl Arg,
    b: impl Arg,
    n: usize,
    sub: bool,
) {
    for i in 0..n {
        let (alo, ahi, blo, bhi) = (a.lo(i), a.hi(i), b.lo(i), b.hi(i));
        let undefined = ends_nan(alo, ahi) | ends_nan(blo, bhi);
        let (lo, hi) = if sub {
            (alo - bhi, ahi - blo)
        } else {
            (alo + blo, ahi + bhi)
        };
        // inf - inf: unbounded and maybe undefined.
        let inf = ends_nan(lo, hi);
        let lo = if inf { f64::NEG_INFINITY } else { lo };
        let hi = if inf { f64::INFINITY } else { hi };
        put(o, i, undefined, lo, hi, inf | a.nan(i) | b.nan(i));
    }
    ch[..n].fill(Choice::Both);
}

#[inline(always)]
fn mul<const N: usize>(
    o: &mut IntervalLanes<N>,
    ch: &mut [Choice; N],
    a: impl Arg,
    b: impl Arg,
    n: usize,
) {
    for i in 0..n {
        let (alo, ahi, blo, bhi) = (a.lo(i), a.hi(i), b.lo(i), b.hi(i));
        let undefined = ends_nan(alo, ahi) | ends_nan(blo, bhi);
        let unbounded = |lo: f64, hi: f64| lo.is_infinite() | hi.is_infinite();
        let holds_zero = |lo: f64, hi: f64| (lo <= 0.0) & (hi >= 0.0);
        // 0 * inf, whether the corners show it or not.
        let zero_inf = (unbounded(alo, ahi) & holds_zero(blo, bhi))
            | (unbounded(blo, bhi) & holds_zero(alo, ahi));
        let p = [alo * blo, alo * bhi, ahi * blo, ahi * bhi];
        let everything = zero_inf | p.iter().any(|v| v.is_nan());
        let lo = p.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = p.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let lo = if everything { f64::NEG_INFINITY } else { lo };
        let hi = if everything { f64::INFINITY } else { hi };
        put(o, i, undefined, lo, hi, everything | a.nan(i) | b.nan(i));
    }
    ch[..n].fill(Choice::Both);
}

/// `min(a, b)`, or `max(a, b)` when `max`, with the argument that decides it.
#[inline(always)]
fn min_max<const N: usize>(
    o: &mut IntervalLanes<N>,
    ch: &mut [Choice; N],
    a: impl Arg,
    b: impl Arg,
    n: usize,
    max: bool,
) {
    for (i, ch) in ch[..n].iter_mut().enumerate() {
        let (alo, ahi, blo, bhi) = (a.lo(i), a.hi(i), b.lo(i), b.hi(i));
        let undefined = ends_nan(alo, ahi) | ends_nan(blo, bhi);
        let nan = a.nan(i) | b.nan(i);
        let [left, right, sign_left, sign_right] = decides(max, alo, ahi, blo, bhi);
        let (both_lo, both_hi) = if max {
            (alo.max(blo), ahi.max(bhi))
        } else {
            (alo.min(blo), ahi.min(bhi))
        };
        let lo = if left {
            alo
        } else if right {
            blo
        } else {
            both_lo
        };
        let hi = if left {
            ahi
        } else if right {
            bhi
        } else {
            both_hi
        };
        put(o, i, undefined, lo, hi, nan);
        // NaN propagates through min and max, so neither argument alone decides.
        *ch = choice(undefined | nan, [left, right, sign_left, sign_right]);
    }
}

/// The rules of `min_choice` (or `max_choice` when `max`) as four flags: the first argument
/// decides, the second does, the first decides the sign, the second does.
#[inline(always)]
fn decides(max: bool, alo: f64, ahi: f64, blo: f64, bhi: f64) -> [bool; 4] {
    if max {
        [
            alo >= bhi,
            blo >= ahi,
            (bhi < 0.0) | (alo > 0.0),
            (ahi < 0.0) | (blo > 0.0),
        ]
    } else {
        [
            ahi <= blo,
            bhi <= alo,
            (blo > 0.0) | (ahi < 0.0),
            (alo > 0.0) | (bhi < 0.0),
        ]
    }
}

/// The first choice `decides` allows, or `Both` when `neither`.
#[inline(always)]
fn choice(neither: bool, [left, right, sign_left, sign_right]: [bool; 4]) -> Choice {
    if neither {
        Choice::Both
    } else if left {
        Choice::Left
    } else if right {
        Choice::Right
    } else if sign_left {
        Choice::SignLeft
    } else if sign_right {
        Choice::SignRight
    } else {
        Choice::Both
    }
}

/// `r_and(a, b)`, or `r_or(a, b)` when `or`: monotone in both arguments, widened for the
/// square root, and decided by sign only.
#[inline(always)]
fn r_function<const N: usize>(
    o: &mut IntervalLanes<N>,
    ch: &mut [Choice; N],
    a: impl Arg,
    b: impl Arg,
    n: usize,
    or: bool,
) {
    let op = if or { BinaryOp::ROr } else { BinaryOp::RAnd };
    let widen = |v: f64| {
        if v.is_finite() {
            v.abs() * 4.0 * f64::EPSILON + f64::MIN_POSITIVE
        } else {
            0.0
        }
    };
    for (i, ch) in ch[..n].iter_mut().enumerate() {
        let (alo, ahi, blo, bhi) = (a.lo(i), a.hi(i), b.lo(i), b.hi(i));
        let undefined = ends_nan(alo, ahi) | ends_nan(blo, bhi);
        let nan = a.nan(i) | b.nan(i);
        let (lo, hi) = (op.apply(alo, blo), op.apply(ahi, bhi));
        let inf = ends_nan(lo, hi);
        let lo = if inf {
            f64::NEG_INFINITY
        } else {
            lo - widen(lo)
        };
        let hi = if inf { f64::INFINITY } else { hi + widen(hi) };
        put(o, i, undefined, lo, hi, inf | nan);
        // R-functions mix both arguments everywhere: at most the sign is decided.
        *ch = match choice(undefined | nan, decides(or, alo, ahi, blo, bhi)) {
            Choice::Left => Choice::SignLeft,
            Choice::Right => Choice::SignRight,
            c => c,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Function;
    use crate::eval::IntervalEval;

    /// The tape run box by box through the scalar rules alone, instruction by instruction:
    /// the reference the kernels must match.
    fn reference(tape: &Tape, p: [Interval; 4]) -> (Interval, Vec<Choice>) {
        let mut regs = vec![Interval::point(0.0); tape.n_regs()];
        for (slot, reg) in tape.inputs().iter().enumerate() {
            if let Some(r) = reg {
                regs[*r as usize] = p[slot];
            }
        }
        let mut choices = vec![Choice::Both; tape.len()];
        for (instr, choice) in tape.instrs().iter().zip(&mut choices) {
            let get = |o: Operand| match o {
                Operand::Reg(r) => regs[r as usize],
                Operand::Const(c) => Interval::point(c),
            };
            let [a, b, c] = instr.args;
            let value;
            (value, *choice) = match instr.code {
                Code::Unary(op) => (unary(op, get(a)), Choice::Both),
                Code::Binary(op) => binary(op, get(a), get(b)),
                Code::Ternary(op) => ternary(op, get(a), get(b), get(c)),
                Code::Sample(g) => (
                    sample(&tape.grids()[g as usize], [get(a), get(b), get(c)]),
                    Choice::Both,
                ),
            };
            regs[instr.out as usize] = value;
        }
        let out = match tape.outputs()[0] {
            Operand::Reg(r) => regs[r as usize],
            Operand::Const(c) => Interval::point(c),
        };
        (out, choices)
    }

    fn same(a: Interval, b: Interval) -> bool {
        a.lo.to_bits() == b.lo.to_bits() && a.hi.to_bits() == b.hi.to_bits() && a.nan == b.nan
    }

    /// A deterministic stream of interval ends: ordinary values, zeros of both signs,
    /// infinities and NaN, so every branch of the scalar rules is reached.
    struct Ends(testkit::rng::XorShift64);

    impl Ends {
        fn value(&mut self) -> f64 {
            let r = self.0.next_u64();
            match r % 16 {
                0 => 0.0,
                1 => -0.0,
                2 => f64::INFINITY,
                3 => f64::NEG_INFINITY,
                4 => f64::NAN,
                5 => 1.0,
                6 => -1.0,
                _ => ((r >> 11) as f64 / (1u64 << 53) as f64) * 8.0 - 4.0,
            }
        }

        fn interval(&mut self) -> Interval {
            let (a, b) = (self.value(), self.value());
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            Interval {
                lo,
                hi,
                nan: self.0.next_u64().is_multiple_of(8),
            }
        }
    }

    const FORMULAS: &[&str] = &[
        "x + y",
        "x - y",
        "x * y",
        "x / y",
        "min(x, y)",
        "max(x, y)",
        "r_and(x, y)",
        "r_or(x, y)",
        "x ^ y",
        "atan2(x, y)",
        "mod(x, y)",
        "x < y",
        "x <= y",
        "x == y",
        "x > 0 && y > 0",
        "x > 0 || y > 0",
        "-x",
        "abs(x)",
        "x^2",
        "sqrt(x)",
        "sin(x)",
        "cos(x)",
        "tan(x)",
        "asin(x)",
        "acos(x)",
        "atan(x)",
        "exp(x)",
        "ln(x)",
        "floor(x)",
        "ceil(x)",
        "sign(x)",
        "!(x > 0)",
        "function f(x, y, z, t) { g = x + 1; if (x < y) g = z; return g; }",
        "blend_and(x, y, z)",
        "blend_or(x, y, z)",
        "x + 2",
        "2 - x",
        "min(x, 0.5)",
        "max(0.5, y)",
        "x * 3",
        "1 / x",
        "2 ^ x",
        "sqrt(x^2 + y^2 + z^2) - t",
        "r_and(x - 0.5, 1 - y) | min(z, 2)",
    ];

    #[test]
    fn bulk_intervals_are_the_scalar_rules_bit_for_bit() {
        let mut ends = Ends(testkit::rng::XorShift64(0x9e37_79b9_7f4a_7c15));
        let mut mine = Vec::new();
        for src in FORMULAS {
            let tape = Function::parse(src)
                .unwrap_or_else(|e| panic!("{src}: {e}"))
                .tape();
            let mut one = IntervalEval::new(&tape);
            let mut bulk = IntervalBulkEval::new(&tape);
            // Eight chunks and a partial one, so lanes past a chunk's end are never read.
            let boxes: Vec<[Interval; 4]> = (0..8 * BOX_CHUNK + 5)
                .map(|_| {
                    [
                        ends.interval(),
                        ends.interval(),
                        ends.interval(),
                        ends.interval(),
                    ]
                })
                .collect();
            let mut out = vec![Interval::point(0.0); boxes.len()];
            bulk.eval(&boxes, &mut out);
            for (b, o) in boxes.iter().zip(&out) {
                let (want, _) = reference(&tape, *b);
                assert!(same(want, *o), "{src} over {b:?}: {o:?}, scalar {want:?}");
            }
            // Choices are kept per chunk: one call per chunk shows every box's.
            for (chunk, out) in boxes.chunks(BOX_CHUNK).zip(out.chunks_mut(BOX_CHUNK)) {
                bulk.eval(chunk, out);
                for (k, b) in chunk.iter().enumerate() {
                    let (want, theirs) = reference(&tape, *b);
                    bulk.choices(k, &mut mine);
                    assert_eq!(theirs, mine, "{src} over {b:?}");
                    // The box-by-box evaluator runs the same kernels one box per pass.
                    let got = one.eval(*b);
                    assert!(
                        same(want, got),
                        "{src} over {b:?}: {got:?}, scalar {want:?}"
                    );
                    assert_eq!(one.choices(), theirs.as_slice(), "{src} over {b:?}");
                }
            }
        }
    }

    #[test]
    fn a_small_call_keeps_every_box_choices() {
        let tape = Function::parse("min(x, y) | max(z, x)").unwrap().tape();
        let mut bulk = IntervalBulkEval::new(&tape);
        let mut scalar = IntervalEval::new(&tape);
        let boxes = [
            [
                Interval::new(0.0, 1.0),
                Interval::new(2.0, 3.0),
                Interval::new(-1.0, 0.0),
                Interval::point(0.0),
            ],
            [
                Interval::new(2.0, 3.0),
                Interval::new(0.0, 1.0),
                Interval::new(5.0, 6.0),
                Interval::point(0.0),
            ],
        ];
        let mut out = [Interval::point(0.0); 2];
        bulk.eval(&boxes, &mut out);
        let mut mine = Vec::new();
        let mut per_box = Vec::new();
        for (k, b) in boxes.iter().enumerate() {
            scalar.eval(*b);
            bulk.choices(k, &mut mine);
            assert_eq!(scalar.choices(), mine.as_slice());
            per_box.push(mine.clone());
        }
        // The two boxes choose differently, so each lane keeps its own choices.
        assert_ne!(per_box[0], per_box[1]);
    }
}
