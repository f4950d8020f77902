//! Reading function text: the lexer, the abstract syntax tree with byte spans, the parser and
//! diagnostics.
//!
//! The parser does not resolve names or check arities: that is the compiler's job.

pub mod ast;
pub mod diagnostic;
pub mod lexer;
pub mod parser;

pub use diagnostic::{Diagnostic, Severity, Span};
