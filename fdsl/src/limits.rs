//! Named limits on everything that grows while reading and compiling a function.
//!
//! Function text comes from users and from remote peers, so every dimension of the work is
//! bounded here; exceeding one is a diagnostic with a location, never a panic or a hang.

/// The longest source text accepted, in bytes.
pub const MAX_SOURCE_BYTES: usize = 64 * 1024;
/// The deepest nesting within one expression: parentheses, calls, prefix operators, `^`
/// and pending binary operators. The parser and the lowering keep it on the heap, not the
/// stack (long flat chains such as `x+x+...+x` nest nothing: they are limited by length).
pub const MAX_NESTING_DEPTH: usize = 256;
/// The deepest nesting of statements: blocks, `if`, `else` (so each `else if` of a chain),
/// `for` and `while`. Statements are read and lowered by recursion, so this bounds the stack
/// a compilation needs; at this depth the whole pipeline fits a 256 KiB thread.
pub const MAX_STATEMENT_DEPTH: usize = 64;
/// The most nodes an expression graph may hold after deduplication.
pub const MAX_GRAPH_NODES: usize = 200_000;
/// An object's formula may unroll to at most this many graph nodes plus
/// [`MAX_FORMULA_NODES_PER_BYTE`] per byte of its text ([`formula_node_budget`]): formulas
/// travel between peers, and a short loop that unrolls to [`MAX_GRAPH_NODES`] would make every
/// receiver compile a hundred times more per byte than a typed expression does.
pub const MAX_FORMULA_NODES_BASE: usize = 256;
/// See [`MAX_FORMULA_NODES_BASE`]. Typed expressions need less than one node per byte (the
/// reference models 0.14 to 0.86).
pub const MAX_FORMULA_NODES_PER_BYTE: usize = 16;

/// The most graph nodes an object's formula of `source_bytes` may unroll to.
pub fn formula_node_budget(source_bytes: usize) -> usize {
    MAX_FORMULA_NODES_BASE
        .saturating_add(MAX_FORMULA_NODES_PER_BYTE.saturating_mul(source_bytes))
        .min(MAX_GRAPH_NODES)
}

/// The most iterations one loop may run when it is unrolled.
pub const MAX_LOOP_TRIPS: usize = 1024;
/// The most statements executed while unrolling a whole program (its fuel).
pub const MAX_STATEMENT_FUEL: usize = 100_000;
/// The most distinct variables a program may name.
pub const MAX_VARIABLES: usize = 512;
/// The most arguments one call may take (for the variadic `min` and `max`).
pub const MAX_CALL_ARGS: usize = 64;
/// The most outputs (assigned variables or functions) one program may define.
pub const MAX_OUTPUTS: usize = 64;
/// The most diagnostics reported for one source; later ones are dropped.
pub const MAX_DIAGNOSTICS: usize = 32;
