//! The operations of the expression graph and the tape, with their exact scalar semantics.
//!
//! Every evaluator (point, bulk, interval, gradient) implements these same definitions; the
//! scalar `apply_*` functions here are the reference the others are tested against.

/// Operations of one argument.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum UnaryOp {
    /// `-a`
    Neg,
    /// `|a|`
    Abs,
    /// `sqrt(a)`
    Sqrt,
    /// `a*a`
    Square,
    /// `sin(a)`
    Sin,
    /// `cos(a)`
    Cos,
    /// `tan(a)`
    Tan,
    /// `asin(a)`
    Asin,
    /// `acos(a)`
    Acos,
    /// `atan(a)`
    Atan,
    /// `exp(a)`
    Exp,
    /// Natural logarithm.
    Ln,
    /// Round down.
    Floor,
    /// Round up.
    Ceil,
    /// -1, 0 or 1.
    Sign,
    /// 1 when `a == 0`, else 0.
    Not,
}

/// Operations of two arguments.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum BinaryOp {
    /// `a + b`
    Add,
    /// `a - b`
    Sub,
    /// `a * b`
    Mul,
    /// `a / b`
    Div,
    /// `min(a, b)`: intersection of solids.
    Min,
    /// `max(a, b)`: union of solids.
    Max,
    /// `a ^ b` for a general exponent.
    Pow,
    /// `atan2(a, b)`
    Atan2,
    /// `a - b * floor(a / b)`: the result has the sign of `b`.
    Mod,
    /// 1 when `a < b`, else 0.
    Lt,
    /// 1 when `a <= b`, else 0.
    Le,
    /// 1 when `a == b`, else 0.
    Eq,
    /// 1 when both are non-zero, else 0.
    And,
    /// 1 when either is non-zero, else 0.
    Or,
    /// R-function intersection (R0 system): `a + b - sqrt(a^2 + b^2)`.
    RAnd,
    /// R-function union (R0 system): `a + b + sqrt(a^2 + b^2)`.
    ROr,
}

/// Operations of three arguments.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum TernaryOp {
    /// `if c != 0 { a } else { b }` (the lowering of `if/else`).
    Select,
    /// Smooth intersection with blend radius `r`: `min(a,b) - h^2 r / 4`, `h = max(r - |a-b|, 0) / r`.
    BlendMin,
    /// Smooth union with blend radius `r`: `max(a,b) + h^2 r / 4`.
    BlendMax,
}

impl UnaryOp {
    /// The reference value in f64.
    ///
    /// Inlined so that a caller's loop over one known operation is that operation's
    /// arithmetic: the object model's slice evaluator is such a loop, in another crate.
    #[inline]
    pub fn apply(self, a: f64) -> f64 {
        match self {
            UnaryOp::Neg => -a,
            UnaryOp::Abs => a.abs(),
            UnaryOp::Sqrt => a.sqrt(),
            UnaryOp::Square => a * a,
            UnaryOp::Sin => a.sin(),
            UnaryOp::Cos => a.cos(),
            UnaryOp::Tan => a.tan(),
            UnaryOp::Asin => a.asin(),
            UnaryOp::Acos => a.acos(),
            UnaryOp::Atan => a.atan(),
            UnaryOp::Exp => a.exp(),
            UnaryOp::Ln => a.ln(),
            UnaryOp::Floor => a.floor(),
            UnaryOp::Ceil => a.ceil(),
            UnaryOp::Sign => sign(a),
            UnaryOp::Not => bool_to_f64(a == 0.0),
        }
    }
}

impl BinaryOp {
    /// The reference value in f64.
    ///
    /// Inlined so that a caller's loop over one known operation is that operation's
    /// arithmetic: the object model's slice evaluator is such a loop, in another crate.
    #[inline]
    pub fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            BinaryOp::Add => a + b,
            BinaryOp::Sub => a - b,
            BinaryOp::Mul => a * b,
            BinaryOp::Div => a / b,
            BinaryOp::Min => min_nan(a, b),
            BinaryOp::Max => max_nan(a, b),
            BinaryOp::Pow => a.powf(b),
            BinaryOp::Atan2 => a.atan2(b),
            BinaryOp::Mod => a - b * (a / b).floor(),
            BinaryOp::Lt => bool_to_f64(a < b),
            BinaryOp::Le => bool_to_f64(a <= b),
            BinaryOp::Eq => bool_to_f64(a == b),
            BinaryOp::And => bool_to_f64(a != 0.0 && b != 0.0),
            BinaryOp::Or => bool_to_f64(a != 0.0 || b != 0.0),
            BinaryOp::RAnd => a + b - (a * a + b * b).sqrt(),
            BinaryOp::ROr => a + b + (a * a + b * b).sqrt(),
        }
    }

    /// Whether `op(a, b) == op(b, a)`, used to canonicalise argument order.
    pub fn is_commutative(self) -> bool {
        matches!(
            self,
            BinaryOp::Add
                | BinaryOp::Mul
                | BinaryOp::Min
                | BinaryOp::Max
                | BinaryOp::Eq
                | BinaryOp::And
                | BinaryOp::Or
                | BinaryOp::RAnd
                | BinaryOp::ROr
        )
    }
}

impl TernaryOp {
    /// The reference value in f64.
    ///
    /// Inlined so that a caller's loop over one known operation is that operation's
    /// arithmetic: the object model's slice evaluator is such a loop, in another crate.
    #[inline]
    pub fn apply(self, a: f64, b: f64, c: f64) -> f64 {
        match self {
            TernaryOp::Select => {
                if a != 0.0 {
                    b
                } else {
                    c
                }
            }
            TernaryOp::BlendMin => blend_min(a, b, c),
            TernaryOp::BlendMax => -blend_min(-a, -b, c),
        }
    }
}

fn blend_min(a: f64, b: f64, r: f64) -> f64 {
    let h = (r - (a - b).abs()).max(0.0) / r;
    min_nan(a, b) - h * h * r * 0.25
}

/// `min` that propagates NaN (so that an undefined value is never hidden).
pub fn min_nan(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.min(b)
    }
}

/// `max` that propagates NaN.
pub fn max_nan(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

fn sign(a: f64) -> f64 {
    if a > 0.0 {
        1.0
    } else if a < 0.0 {
        -1.0
    } else {
        a
    }
}

fn bool_to_f64(b: bool) -> f64 {
    if b { 1.0 } else { 0.0 }
}
