//! `testkit`: helpers that several crates' tests, benchmarks and examples need, written once.
//! Only `[dev-dependencies]` name it: nothing shipped depends on it.
//!
//! - [`alloc`]: a counting global allocator, for "this path never allocates" tests and for
//!   heap figures.

pub mod alloc;
