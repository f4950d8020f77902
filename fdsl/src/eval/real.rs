//! Scalar maths shared by the evaluators: branch-free f32 sine and cosine that vectorise, and
//! the `Real` trait that lets the gradient evaluator run in f32 and f64.

use std::f32::consts::FRAC_2_PI;

// pi/2 split in three parts for Cody-Waite range reduction; the first two have few enough
// significant bits that `j * PIO2_x` is exact for the quadrant counts we use.
const PIO2_HI: f32 = 1.570_312_5;
const PIO2_MID: f32 = 4.837_513e-4;
const PIO2_LO: f32 = 7.549_79e-8;
/// Adding then subtracting this rounds an f32 to the nearest integer (for |v| < 2^22).
const ROUND_MAGIC: f32 = 12_582_912.0;

/// sin and cos of `r` in [-pi/4, pi/4] by minimax polynomials (Cephes coefficients).
#[inline(always)]
fn sin_cos_poly(r: f32) -> (f32, f32) {
    let r2 = r * r;
    let s = r + r * r2 * (-1.666_665_5e-1 + r2 * (8.332_161e-3 + r2 * -1.951_529_6e-4));
    let c =
        1.0 - 0.5 * r2 + r2 * r2 * (4.166_664_6e-2 + r2 * (-1.388_731_6e-3 + r2 * 2.443_315_7e-5));
    (s, c)
}

/// `sin(x)` for f32 without branches or library calls, so that loops over slices vectorise.
///
/// The error is below 5e-7 for |x| < 200 and grows with |x| (range reduction in f32): it is
/// not meant for |x| beyond 10^5, far outside any model's coordinates. NaN and infinities give
/// NaN.
#[inline(always)]
pub fn fast_sin(x: f32) -> f32 {
    sin_quadrant(x, 0)
}

/// `cos(x)`, like [`fast_sin`].
#[inline(always)]
pub fn fast_cos(x: f32) -> f32 {
    sin_quadrant(x, 1)
}

#[inline(always)]
fn sin_quadrant(x: f32, shift: i32) -> f32 {
    let j = (x * FRAC_2_PI + ROUND_MAGIC) - ROUND_MAGIC;
    let r = ((x - j * PIO2_HI) - j * PIO2_MID) - j * PIO2_LO;
    let q = (j as i32).wrapping_add(shift);
    let (s, c) = sin_cos_poly(r);
    let v = if q & 1 == 0 { s } else { c };
    if q & 2 == 0 { v } else { -v }
}

/// The operations the gradient evaluator needs, in f32 or f64.
pub trait Real:
    Copy
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// From f64 (rounding).
    fn from_f64(v: f64) -> Self;
    /// To f64 (exact).
    fn to_f64(self) -> f64;
    /// Sine.
    fn sin(self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// The reference semantics of the tape's operations, applied in this precision.
    fn unary(op: crate::compile::UnaryOp, a: Self) -> Self;
    /// Binary operations in this precision.
    fn binary(op: crate::compile::BinaryOp, a: Self, b: Self) -> Self;
    /// Ternary operations in this precision.
    fn ternary(op: crate::compile::TernaryOp, a: Self, b: Self, c: Self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// e^self.
    fn exp(self) -> Self;
    /// Round down.
    fn floor(self) -> Self;
    /// Whether NaN.
    fn is_nan(self) -> bool;
}

macro_rules! impl_real {
    ($t:ty, $sin:expr, $cos:expr) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                f64::from(self)
            }
            #[inline(always)]
            fn sin(self) -> Self {
                $sin(self)
            }
            #[inline(always)]
            fn cos(self) -> Self {
                $cos(self)
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn ln(self) -> Self {
                <$t>::ln(self)
            }
            #[inline(always)]
            fn exp(self) -> Self {
                <$t>::exp(self)
            }
            #[inline(always)]
            fn floor(self) -> Self {
                <$t>::floor(self)
            }
            #[inline(always)]
            fn is_nan(self) -> bool {
                <$t>::is_nan(self)
            }
            #[inline(always)]
            fn unary(op: crate::compile::UnaryOp, a: Self) -> Self {
                use crate::compile::UnaryOp as U;
                match op {
                    U::Sin => $sin(a),
                    U::Cos => $cos(a),
                    U::Neg => -a,
                    U::Abs => a.abs(),
                    U::Sqrt => a.sqrt(),
                    U::Square => a * a,
                    U::Floor => a.floor(),
                    U::Ceil => a.ceil(),
                    _ => op.apply(a as f64) as $t,
                }
            }
            #[inline(always)]
            fn binary(op: crate::compile::BinaryOp, a: Self, b: Self) -> Self {
                use crate::compile::BinaryOp as B;
                match op {
                    B::Add => a + b,
                    B::Sub => a - b,
                    B::Mul => a * b,
                    B::Div => a / b,
                    B::Min => {
                        if a.is_nan() || b.is_nan() {
                            <$t>::NAN
                        } else {
                            a.min(b)
                        }
                    }
                    B::Max => {
                        if a.is_nan() || b.is_nan() {
                            <$t>::NAN
                        } else {
                            a.max(b)
                        }
                    }
                    B::RAnd => a + b - (a * a + b * b).sqrt(),
                    B::ROr => a + b + (a * a + b * b).sqrt(),
                    _ => op.apply(a as f64, b as f64) as $t,
                }
            }
            #[inline(always)]
            fn ternary(op: crate::compile::TernaryOp, a: Self, b: Self, c: Self) -> Self {
                op.apply(a as f64, b as f64, c as f64) as $t
            }
        }
    };
}

impl_real!(f32, fast_sin, fast_cos);
impl_real!(f64, f64::sin, f64::cos);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_sin_and_cos_are_accurate() {
        let mut worst = 0.0f64;
        let mut x = -200.0f32;
        while x < 200.0 {
            let s = (fast_sin(x) as f64 - (x as f64).sin()).abs();
            let c = (fast_cos(x) as f64 - (x as f64).cos()).abs();
            worst = worst.max(s).max(c);
            x += 0.001_37;
        }
        assert!(worst < 5e-7, "worst error {worst}");
        assert!(fast_sin(f32::NAN).is_nan());
        assert!(fast_cos(f32::INFINITY).is_nan());
        assert!((fast_sin(1.0e4) as f64 - (1.0e4f64).sin()).abs() < 1e-3);
    }
}
