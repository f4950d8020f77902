//! End-to-end scenarios across the sculpt crates, and the tidy checks that keep the workspace
//! honest.
//!
//! This crate is not shipped: it only holds checks that span crates.
//! [`footprint`] measures the thesis's central claim end to end: signed function-string ops
//! (a model's create op, a sculpting session's edit ops) against the meshes they describe
//! (binary STL and GLB from render's octree mesher, and the mesh delta of each edit).
//! [`tidy`] reads the dependency map written in `ARCHITECTURE.md` and compares it with the real
//! dependency edges reported by `cargo metadata`, and checks that every source file opens with a
//! `//!` header.
//!
//! ```
//! let map = tests::tidy::parse_dependency_map("```tidy-deps\nfdsl ->\nrender -> fdsl\n```")
//!     .unwrap();
//! assert!(map["render"].contains("fdsl"));
//! ```
#![warn(missing_docs)]

pub mod footprint;
pub mod tidy;
