//! End-to-end scenarios across the sculpt crates, and the tidy checks that keep the workspace
//! honest.
//!
//! This crate is not shipped: it only holds checks that span crates.
//! [`footprint`] measures the thesis's central claim end to end: signed function-string ops
//! (a model's create op, a sculpting session's edit ops) against the meshes they describe
//! (binary STL and GLB from render's octree mesher, and the mesh delta of each edit).
//! [`tidy`] holds the workspace rules: the dependency map written in `ARCHITECTURE.md` against
//! the real edges reported by `cargo metadata`, a `//!` header on every source file, no import
//! circle between a crate's top-level modules, short functions and one way to name limits.
//!
//! ```
//! let map = tests::tidy::deps::parse_dependency_map("```tidy-deps\nfdsl ->\nrender -> fdsl\n```")
//!     .unwrap();
//! assert!(map["render"].contains("fdsl"));
//! ```
#![warn(missing_docs)]

pub mod footprint;
pub mod tidy;
