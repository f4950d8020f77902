//! The `cfg(loom)` switch: the atomics and `Arc` the lock-free [`crate::handoff`] is built on,
//! from `std`, or from loom when built with `RUSTFLAGS="--cfg loom"` so that
//! `tests/loom.rs` can model-check every interleaving of publish, take, retire and collect.
//!
//! Only the handoff goes through here: the servo's statistics are independent relaxed
//! counters that need no model checking.

#[cfg(loom)]
pub(crate) use loom::sync::Arc;
#[cfg(loom)]
pub(crate) use loom::sync::atomic::{AtomicPtr, Ordering};

#[cfg(not(loom))]
pub(crate) use std::sync::Arc;
#[cfg(not(loom))]
pub(crate) use std::sync::atomic::{AtomicPtr, Ordering};
