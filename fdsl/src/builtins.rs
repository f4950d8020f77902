//! The language's built-in functions: their names and how many arguments each takes. The
//! compiler checks calls against them, and a grid may not take one of their names.

use crate::limits::MAX_CALL_ARGS;

/// Names of the built-in functions, for suggestions.
pub(crate) const FUNCTION_NAMES: &[&str] = &[
    "sin",
    "cos",
    "tan",
    "asin",
    "acos",
    "atan",
    "atan2",
    "sinh",
    "cosh",
    "tanh",
    "sqrt",
    "abs",
    "exp",
    "log",
    "ln",
    "log10",
    "pow",
    "min",
    "max",
    "floor",
    "ceil",
    "round",
    "mod",
    "sign",
    "clamp",
    "sqr",
    "r_and",
    "r_or",
    "r_sub",
    "blend_and",
    "blend_or",
    "blend_sub",
    "step",
];
/// The fewest and most arguments of the built-in function `f`, if it is one.
pub(crate) fn arity(f: &str) -> Option<(usize, usize)> {
    Some(match f {
        "sin" | "cos" | "tan" | "asin" | "acos" | "atan" | "sinh" | "cosh" | "tanh" | "sqrt"
        | "abs" | "exp" | "log" | "ln" | "log10" | "floor" | "ceil" | "round" | "sign" | "sqr" => {
            (1, 1)
        }
        "atan2" | "pow" | "mod" | "r_and" | "r_or" | "r_sub" | "step" => (2, 2),
        "clamp" | "blend_and" | "blend_or" | "blend_sub" => (3, 3),
        "min" | "max" => (2, MAX_CALL_ARGS),
        _ => return None,
    })
}

/// Whether `name` is a function of the language (grids may not take such names).
pub(crate) fn is_builtin_function(name: &str) -> bool {
    arity(name).is_some()
}
