//! From syntax to a register tape: lowering the AST to an SSA expression graph (with constant
//! folding and common-subexpression elimination), then scheduling the graph into a [`Tape`].
//!
//! [`Tape`]: crate::tape::Tape

pub mod graph;
pub mod lower;
pub mod ops;

pub use graph::{Context, Node, Op};
pub use ops::{BinaryOp, TernaryOp, UnaryOp};
