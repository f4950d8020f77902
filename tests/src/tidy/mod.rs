//! Workspace rules checked by a test (`tests/tests/tidy.rs`), each in its own module:
//! - [`deps`]: the dependency map in `ARCHITECTURE.md` against the edges `cargo metadata`
//!   reports;
//! - [`files`]: every source file opens with a `//!` header, and words a crate must not use;
//! - [`modules`]: no import circle between the top-level modules of a crate;
//! - [`functions`]: no function over 100 lines, and none over 70 unless it is a marked table;
//! - [`names`]: limits are `MAX_*`, never `*_MAX`.
//!
//! They read source text through [`source`], a scanner that blanks comments and literals.

pub mod deps;
pub mod files;
pub mod functions;
pub mod modules;
pub mod names;
pub mod source;
