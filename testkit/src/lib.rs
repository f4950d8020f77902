//! `testkit`: helpers that several crates' tests, benchmarks and examples need, written once.
//! Only `[dev-dependencies]` name it: nothing shipped depends on it.
//!
//! - [`alloc`]: a counting global allocator, for "this path never allocates" tests and for
//!   heap figures.
//! - [`rng`]: a small seeded generator (xorshift64) for deterministic test data.
//! - [`stack`]: runs a closure on a thread with a small stack, so that unbounded recursion on
//!   deep input is a crash in tests, not a pass on the harness's large stacks.

pub mod alloc;
pub mod rng;
pub mod stack;
