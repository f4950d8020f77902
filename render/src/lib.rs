//! Seeing fdsl scenes: meshing, colour, wgpu drawing, headless images and 2D plots.
//!
//! It knows nothing of egui or replication: the app embeds it through `prepare`/`paint`.
#![warn(missing_docs)]
