//! Interval arithmetic over a tape: conservative bounds of every output over a box, and the
//! choices that let [`Tape::simplify`] drop what cannot matter in that box.
//!
//! Bounds are computed in f64 from the interval ends. Round-to-nearest is monotonic, so for
//! monotonic operations the computed ends enclose the f64 point values inside; operations whose
//! library implementations are not guaranteed monotonic are widened by a few ulps. A NaN end
//! means the value may be undefined somewhere in the box.

use std::f64::consts::{FRAC_PI_2, PI};

use super::interval_bulk::Passes;
use crate::compile::{BinaryOp, TernaryOp, UnaryOp};
use crate::tape::{Choice, Tape};

/// A closed interval `[lo, hi]` of the values a function takes over a box, plus whether the
/// function may be undefined (NaN) somewhere in the box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
    /// Whether the value may be NaN somewhere (for example `sqrt` of a range reaching below 0).
    pub nan: bool,
}

impl Interval {
    /// `[lo, hi]`.
    #[inline]
    pub const fn new(lo: f64, hi: f64) -> Interval {
        Interval { lo, hi, nan: false }
    }

    /// The single value `v`.
    #[inline]
    pub fn point(v: f64) -> Interval {
        Interval {
            lo: v,
            hi: v,
            nan: v.is_nan(),
        }
    }

    /// Every real number.
    pub const EVERYTHING: Interval = Interval::new(f64::NEG_INFINITY, f64::INFINITY);
    const NAN: Interval = Interval {
        lo: f64::NAN,
        hi: f64::NAN,
        nan: true,
    };
    const BOOL: Interval = Interval::new(0.0, 1.0);

    /// Whether `v` lies inside; NaN lies inside when the interval may be NaN.
    #[inline]
    pub fn contains(&self, v: f64) -> bool {
        if v.is_nan() {
            self.nan
        } else {
            self.lo <= v && v <= self.hi
        }
    }

    /// Whether the value may be NaN somewhere in the box.
    #[inline]
    pub fn has_nan(&self) -> bool {
        self.nan || self.lo.is_nan() || self.hi.is_nan()
    }

    fn with_nan(mut self, nan: bool) -> Interval {
        self.nan |= nan;
        self
    }

    fn union(self, o: Interval) -> Interval {
        // An interval with NaN ends is NaN everywhere: it adds only the NaN flag.
        if self.ends_nan() {
            return o.with_nan(true);
        }
        if o.ends_nan() {
            return self.with_nan(true);
        }
        Interval {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
            nan: self.nan || o.nan,
        }
    }

    fn definitely_true(self) -> bool {
        !self.has_nan() && (self.lo > 0.0 || self.hi < 0.0)
    }

    fn definitely_false(self) -> bool {
        !self.nan && self.lo == 0.0 && self.hi == 0.0
    }

    fn ends_nan(&self) -> bool {
        self.lo.is_nan() || self.hi.is_nan()
    }

    fn widen(self) -> Interval {
        let w = |v: f64| {
            if v.is_finite() {
                v.abs() * 4.0 * f64::EPSILON + f64::MIN_POSITIVE
            } else {
                0.0
            }
        };
        Interval {
            lo: self.lo - w(self.lo),
            hi: self.hi + w(self.hi),
            nan: self.nan,
        }
    }
}

/// Evaluates a tape over boxes and records the choices for simplification.
///
/// It runs the kernels of [`super::IntervalBulkEval`] over one box per pass, so the two give
/// the same bounds and choices; the rules themselves are the functions below.
#[derive(Clone, Debug)]
pub struct IntervalEval {
    passes: Passes<1>,
}

impl IntervalEval {
    /// An evaluator for `tape`.
    pub fn new(tape: &Tape) -> IntervalEval {
        IntervalEval {
            passes: Passes::new(tape),
        }
    }

    /// The tape this evaluator runs.
    pub fn tape(&self) -> &Tape {
        self.passes.tape()
    }

    /// Bounds of the first output over the box `p = [x, y, z, t]`.
    // Inlined where the object model samples (another crate), as when they were one crate.
    #[inline]
    pub fn eval(&mut self, p: [Interval; 4]) -> Interval {
        self.passes.load(0, &p);
        self.passes.run(1);
        self.output(0)
    }

    /// Bounds of output `idx` after the last [`IntervalEval::eval`].
    #[inline]
    pub fn output(&self, idx: usize) -> Interval {
        self.passes.output(idx, 0)
    }

    /// The choices of the last evaluation, one per instruction, for [`Tape::simplify`].
    pub fn choices(&self) -> &[Choice] {
        self.passes.choices().as_flattened()
    }
}

/// A grid's bounds over a box of coordinates: the samples the box's cells reach.
pub(super) fn sample(grid: &crate::grid::Grid, p: [Interval; 3]) -> Interval {
    if p.iter().any(Interval::ends_nan) {
        return Interval::NAN;
    }
    let nan = p.iter().any(|i| i.nan);
    match grid.bounds(p.map(|i| i.lo), p.map(|i| i.hi)) {
        Some((lo, hi)) => Interval::new(lo, hi).with_nan(nan),
        None => Interval::NAN,
    }
}

fn monotone(a: Interval, f: impl Fn(f64) -> f64) -> Interval {
    Interval {
        lo: f(a.lo),
        hi: f(a.hi),
        nan: a.nan,
    }
}

#[inline(always)]
pub(super) fn unary(op: UnaryOp, a: Interval) -> Interval {
    if a.ends_nan() {
        return Interval::NAN;
    }
    if op == UnaryOp::Not && a.nan {
        return Interval::BOOL;
    }
    unary_finite(op, a).with_nan(a.nan)
}

/// Bounds of a unary operation over an interval with numeric ends.
// tidy:table: the interval bounds of every unary operation, one arm each.
#[inline(always)]
fn unary_finite(op: UnaryOp, a: Interval) -> Interval {
    match op {
        UnaryOp::Neg => Interval::new(-a.hi, -a.lo),
        UnaryOp::Abs => {
            if a.lo >= 0.0 {
                a
            } else if a.hi <= 0.0 {
                Interval::new(-a.hi, -a.lo)
            } else {
                Interval::new(0.0, (-a.lo).max(a.hi))
            }
        }
        UnaryOp::Square => {
            if a.lo >= 0.0 {
                Interval::new(a.lo * a.lo, a.hi * a.hi)
            } else if a.hi <= 0.0 {
                Interval::new(a.hi * a.hi, a.lo * a.lo)
            } else {
                Interval::new(0.0, (a.lo * a.lo).max(a.hi * a.hi))
            }
        }
        UnaryOp::Sqrt => {
            if a.hi < 0.0 {
                Interval::NAN
            } else {
                monotone(Interval::new(a.lo.max(0.0), a.hi), f64::sqrt).with_nan(a.lo < 0.0)
            }
        }
        UnaryOp::Sin => periodic(a, f64::sin, FRAC_PI_2, -FRAC_PI_2),
        UnaryOp::Cos => periodic(a, f64::cos, 0.0, PI),
        UnaryOp::Tan => {
            let k = ((a.lo - FRAC_PI_2) / PI).floor();
            let next_pole = FRAC_PI_2 + (k + 1.0) * PI;
            if a.hi - a.lo >= PI || a.hi >= next_pole || !a.lo.is_finite() || !a.hi.is_finite() {
                Interval::EVERYTHING
            } else {
                monotone(a, f64::tan).widen()
            }
        }
        UnaryOp::Asin | UnaryOp::Acos => {
            if a.hi < -1.0 || a.lo > 1.0 {
                return Interval::NAN;
            }
            let c =
                Interval::new(a.lo.max(-1.0), a.hi.min(1.0)).with_nan(a.lo < -1.0 || a.hi > 1.0);
            if op == UnaryOp::Asin {
                monotone(c, f64::asin).widen()
            } else {
                Interval::new(c.hi.acos(), c.lo.acos())
                    .with_nan(c.nan)
                    .widen()
            }
        }
        UnaryOp::Atan => monotone(a, f64::atan).widen(),
        UnaryOp::Exp => {
            let r = monotone(a, f64::exp).widen();
            Interval::new(r.lo.max(0.0), r.hi)
        }
        UnaryOp::Ln => {
            if a.hi < 0.0 {
                Interval::NAN
            } else {
                monotone(Interval::new(a.lo.max(0.0), a.hi), f64::ln)
                    .with_nan(a.lo < 0.0)
                    .widen()
            }
        }
        UnaryOp::Floor => monotone(a, f64::floor),
        UnaryOp::Ceil => monotone(a, f64::ceil),
        UnaryOp::Sign => monotone(a, |v| UnaryOp::Sign.apply(v)),
        UnaryOp::Not => {
            if a.definitely_true() {
                Interval::point(0.0)
            } else if a.definitely_false() {
                Interval::point(1.0)
            } else {
                Interval::BOOL
            }
        }
    }
}

/// Bounds of a 2pi-periodic function with maxima at `max_at + 2k pi` and minima at
/// `min_at + 2k pi`, with values in [-1, 1].
fn periodic(a: Interval, f: fn(f64) -> f64, max_at: f64, min_at: f64) -> Interval {
    if !(a.lo.is_finite() && a.hi.is_finite()) {
        // The function of an infinite end is NaN (`sin(ln(0))`).
        return Interval::new(-1.0, 1.0).with_nan(true);
    }
    let width = a.hi - a.lo;
    if width >= 2.0 * PI || width.is_nan() {
        return Interval::new(-1.0, 1.0);
    }
    let contains = |at: f64| {
        let k = ((a.lo - at) / (2.0 * PI)).ceil();
        at + k * 2.0 * PI <= a.hi
    };
    let (fa, fb) = (f(a.lo), f(a.hi));
    let lo = if contains(min_at) { -1.0 } else { fa.min(fb) };
    let hi = if contains(max_at) { 1.0 } else { fa.max(fb) };
    Interval::new(lo, hi).widen().clamp_unit()
}

impl Interval {
    fn clamp_unit(self) -> Interval {
        Interval {
            lo: self.lo.max(-1.0),
            hi: self.hi.min(1.0),
            nan: self.nan,
        }
    }
}

fn mul(a: Interval, b: Interval) -> Interval {
    // The corners miss 0 * inf when the zero lies inside one factor and the other is unbounded.
    let unbounded = |i: Interval| i.lo.is_infinite() || i.hi.is_infinite();
    let holds_zero = |i: Interval| i.lo <= 0.0 && i.hi >= 0.0;
    if (unbounded(a) && holds_zero(b)) || (unbounded(b) && holds_zero(a)) {
        return Interval::EVERYTHING.with_nan(true);
    }
    hull([a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi])
}

/// The smallest interval holding four corner values; a NaN corner (0 * inf, inf - inf) makes
/// the result unbounded and maybe undefined.
fn hull(p: [f64; 4]) -> Interval {
    if p.iter().any(|v| v.is_nan()) {
        return Interval::EVERYTHING.with_nan(true);
    }
    Interval::new(
        p.iter().copied().fold(f64::INFINITY, f64::min),
        p.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    )
}

fn compare(definitely: bool, definitely_not: bool) -> Interval {
    if definitely {
        Interval::point(1.0)
    } else if definitely_not {
        Interval::point(0.0)
    } else {
        Interval::BOOL
    }
}

/// Which argument decides `min(a, b)` over the box, exactly or by sign.
fn min_choice(a: Interval, b: Interval) -> Choice {
    if a.hi <= b.lo {
        Choice::Left
    } else if b.hi <= a.lo {
        Choice::Right
    } else if b.lo > 0.0 || a.hi < 0.0 {
        Choice::SignLeft
    } else if a.lo > 0.0 || b.hi < 0.0 {
        Choice::SignRight
    } else {
        Choice::Both
    }
}

/// Which argument decides `max(a, b)` over the box, exactly or by sign.
fn max_choice(a: Interval, b: Interval) -> Choice {
    if a.lo >= b.hi {
        Choice::Left
    } else if b.lo >= a.hi {
        Choice::Right
    } else if b.hi < 0.0 || a.lo > 0.0 {
        Choice::SignLeft
    } else if a.hi < 0.0 || b.lo > 0.0 {
        Choice::SignRight
    } else {
        Choice::Both
    }
}

/// The value interval of `min`/`max` given its choice.
fn chosen(choice: Choice, a: Interval, b: Interval, both: Interval) -> Interval {
    match choice {
        Choice::Left => a,
        Choice::Right => b,
        _ => both,
    }
}

/// R-functions decide by sign only: their value mixes both arguments everywhere.
fn sign_only(choice: Choice) -> Choice {
    match choice {
        Choice::Left => Choice::SignLeft,
        Choice::Right => Choice::SignRight,
        c => c,
    }
}

#[inline(always)]
pub(super) fn binary(op: BinaryOp, a: Interval, b: Interval) -> (Interval, Choice) {
    let nan = a.has_nan() || b.has_nan();
    let logic = matches!(
        op,
        BinaryOp::Lt | BinaryOp::Le | BinaryOp::Eq | BinaryOp::And | BinaryOp::Or
    );
    if nan && logic {
        // A comparison turns NaN into a number: anything is possible.
        return (Interval::BOOL, Choice::Both);
    }
    if a.ends_nan() || b.ends_nan() {
        return (Interval::NAN, Choice::Both);
    }
    let (value, choice) = binary_finite(op, a, b);
    let value = if value.ends_nan() {
        Interval::EVERYTHING.with_nan(true)
    } else {
        value
    };
    // NaN propagates through min and max, so neither argument alone decides.
    (value.with_nan(nan), if nan { Choice::Both } else { choice })
}

/// Bounds and choice of a binary operation over intervals with numeric ends.
// tidy:table: the interval bounds and choice of every binary operation, one arm each.
#[inline(always)]
fn binary_finite(op: BinaryOp, a: Interval, b: Interval) -> (Interval, Choice) {
    let value = match op {
        BinaryOp::Add => Interval::new(a.lo + b.lo, a.hi + b.hi),
        BinaryOp::Sub => Interval::new(a.lo - b.hi, a.hi - b.lo),
        BinaryOp::Mul => mul(a, b),
        BinaryOp::Div => {
            if b.lo > 0.0 || b.hi < 0.0 {
                hull([a.lo / b.lo, a.lo / b.hi, a.hi / b.lo, a.hi / b.hi])
            } else {
                // 0/0 is NaN; anything else over a range through 0 is unbounded.
                Interval::EVERYTHING.with_nan(a.lo <= 0.0 && a.hi >= 0.0)
            }
        }
        BinaryOp::Min => {
            let choice = min_choice(a, b);
            let both = Interval::new(a.lo.min(b.lo), a.hi.min(b.hi));
            return (chosen(choice, a, b, both), choice);
        }
        BinaryOp::Max => {
            let choice = max_choice(a, b);
            let both = Interval::new(a.lo.max(b.lo), a.hi.max(b.hi));
            return (chosen(choice, a, b, both), choice);
        }
        BinaryOp::RAnd | BinaryOp::ROr => {
            // Both are non-decreasing in each argument.
            let value = Interval::new(op.apply(a.lo, b.lo), op.apply(a.hi, b.hi));
            let choice = if op == BinaryOp::RAnd {
                min_choice(a, b)
            } else {
                max_choice(a, b)
            };
            let value = if value.ends_nan() {
                Interval::EVERYTHING.with_nan(true)
            } else {
                value.widen()
            };
            return (value, sign_only(choice));
        }
        BinaryOp::Pow => {
            if a.lo > 0.0 {
                // For a positive base, a^b is monotonic in each argument: the corners bound it.
                hull([
                    a.lo.powf(b.lo),
                    a.lo.powf(b.hi),
                    a.hi.powf(b.lo),
                    a.hi.powf(b.hi),
                ])
                .widen()
            } else {
                // A negative base with a fractional exponent is NaN.
                Interval::EVERYTHING.with_nan(true)
            }
        }
        BinaryOp::Atan2 => {
            if b.lo > 0.0 && b.lo.is_finite() {
                hull([
                    a.lo.atan2(b.lo),
                    a.lo.atan2(b.hi),
                    a.hi.atan2(b.lo),
                    a.hi.atan2(b.hi),
                ])
                .widen()
            } else {
                Interval::new(-PI, PI).widen()
            }
        }
        BinaryOp::Mod => modulo(a, b),
        BinaryOp::Lt => compare(a.hi < b.lo, a.lo >= b.hi),
        BinaryOp::Le => compare(a.hi <= b.lo, a.lo > b.hi),
        BinaryOp::Eq => compare(
            a.lo == a.hi && b.lo == b.hi && a.lo == b.lo,
            a.hi < b.lo || b.hi < a.lo,
        ),
        BinaryOp::And => compare(
            a.definitely_true() && b.definitely_true(),
            a.definitely_false() || b.definitely_false(),
        ),
        BinaryOp::Or => compare(
            a.definitely_true() || b.definitely_true(),
            a.definitely_false() && b.definitely_false(),
        ),
    };
    (value, Choice::Both)
}

fn modulo(a: Interval, b: Interval) -> Interval {
    if b.lo <= 0.0 && b.hi >= 0.0 {
        // `a mod 0` is NaN.
        return Interval::EVERYTHING.with_nan(true);
    }
    if b.lo == b.hi && b.lo != 0.0 && a.lo.is_finite() && a.hi.is_finite() {
        let k_lo = (a.lo / b.lo).floor();
        let k_hi = (a.hi / b.lo).floor();
        if k_lo == k_hi {
            return Interval::new(a.lo - b.lo * k_lo, a.hi - b.lo * k_lo).widen();
        }
    }
    // An infinite `a` has no remainder: NaN.
    let nan = !a.lo.is_finite() || !a.hi.is_finite();
    if b.lo > 0.0 {
        Interval::new(0.0, b.hi).with_nan(nan)
    } else {
        Interval::new(b.lo, 0.0).with_nan(nan)
    }
}

pub(super) fn ternary(op: TernaryOp, a: Interval, b: Interval, c: Interval) -> (Interval, Choice) {
    match op {
        TernaryOp::Select => {
            if a.ends_nan() || a.nan {
                // A NaN condition counts as true (`NaN != 0`), so both branches stay possible.
                (b.union(c), Choice::Both)
            } else if a.definitely_true() {
                (b, Choice::Left)
            } else if a.definitely_false() {
                (c, Choice::Right)
            } else {
                (b.union(c), Choice::Both)
            }
        }
        TernaryOp::BlendMin | TernaryOp::BlendMax => {
            if a.has_nan() || b.has_nan() || c.has_nan() || c.lo <= 0.0 {
                return (Interval::EVERYTHING.with_nan(true), Choice::Both);
            }
            let d = Interval::new(a.lo - b.hi, a.hi - b.lo);
            let min = op == TernaryOp::BlendMin;
            // Far apart, the blend is exactly min (or max).
            if d.lo >= c.hi {
                return if min {
                    (b, Choice::Right)
                } else {
                    (a, Choice::Left)
                };
            }
            if d.hi <= -c.hi {
                return if min {
                    (a, Choice::Left)
                } else {
                    (b, Choice::Right)
                };
            }
            let bump = c.hi * 0.25;
            let value = if min {
                Interval::new(a.lo.min(b.lo) - bump, a.hi.min(b.hi))
            } else {
                Interval::new(a.lo.max(b.lo), a.hi.max(b.hi) + bump)
            };
            (value.widen(), Choice::Both)
        }
    }
}
