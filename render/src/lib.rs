//! Seeing fdsl scenes: meshing, colour, wgpu drawing, headless images and 2D plots.
//!
//! What it is:
//! - [`mesh`]: the [`Mesh`](mesh::Mesh) type with watertight/manifold checks, the
//!   [`octree`](mesh::octree) dual-contouring mesher for implicit solids (f >= 0 is inside,
//!   watertight and edge-manifold output)
//!   written against the [`Field`](mesh::Field) trait, and [`parametric`](mesh::parametric)
//!   triangulation of surfaces p(u,v) (with `spade`) and tubes around curves p(u);
//! - [`appearance`]: a `model::object::Appearance` applied to a mesh at time t (vertex
//!   colours from parametric RGB or a colour map, transparency as alpha, displacement along
//!   normals, shininess into the [`Material`](scene::Material));
//! - [`scene`] and [`camera`]: what to draw ([`Scene`](scene::Scene), objects with
//!   [`Material`](scene::Material)s, lines for arrows, boxes and cursors), an orbit
//!   [`Camera`](camera::Camera), and CPU picking (`Scene::pick`);
//! - [`gpu`]: the wgpu [`Renderer`](gpu::Renderer) with `prepare`/`paint` for embedding, and
//!   [`offscreen`](gpu::offscreen) rendering to RGBA or PNG on a private headless device;
//! - [`animation`]: a scene kept up to date with time, meshing shapes of time again each
//!   frame within a budget, recolouring and moving only what time changes;
//! - [`snapshot`]: a whole `fdsl` scene (say, an FVRML file) meshed, coloured, placed and
//!   pictured offscreen from cameras that frame it (the `sculpt render` command);
//! - [`mesher`]: the [`Mesher`](mesher::Mesher), named worker threads that mesh objects as
//!   they change, patching an implicit object's last mesh where only its edits changed;
//! - pictures come out as the `plot` crate's `plot::image::RgbaImage` (with PNG encode and
//!   decode); its users name `plot` themselves (it is not re-exported here), and it also
//!   draws tiny-skia heat-map slices and time-series plots.
//!
//! What it is not: it knows nothing of egui or replication (the app wraps
//! [`Renderer`](gpu::Renderer) in an `egui_wgpu` callback), and it does not parse or compile
//! functions: `fdsl` plugs in by implementing [`Field`](mesh::Field).
//!
//! ```
//! use render::mesh::octree::{MeshSettings, mesh};
//! use render::mesh::{Aabb, Field};
//!
//! /// A ball of radius 0.8: f = 0.8 - |p|, positive inside.
//! struct Ball;
//! impl Field for Ball {
//!     fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
//!         let near: f32 = (0..3).map(|a| if lo[a] > 0.0 { lo[a] } else if hi[a] < 0.0 { -hi[a] } else { 0.0 }).map(|d| d * d).sum();
//!         let far: f32 = (0..3).map(|a| lo[a].abs().max(hi[a].abs())).map(|d| d * d).sum();
//!         (0.8 - far.sqrt(), 0.8 - near.sqrt())
//!     }
//!     fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
//!         for i in 0..xs.len() {
//!             out[i] = 0.8 - (xs[i] * xs[i] + ys[i] * ys[i] + zs[i] * zs[i]).sqrt();
//!         }
//!     }
//! }
//!
//! let settings = MeshSettings { bounds: Aabb::new([-1.0; 3], [1.0; 3]), depth: 4 };
//! let ball = mesh(&mut Ball, &settings)?;
//! assert_eq!(ball.open_edges(), 0);
//! assert_eq!(ball.non_manifold_edges(), 0);
//! # Ok::<(), render::mesh::octree::OctreeMeshError>(())
//! ```
#![warn(missing_docs)]

pub mod animation;
pub mod appearance;
pub mod camera;
pub mod gpu;
pub mod mesh;
pub mod mesher;
pub mod scene;
pub mod snapshot;
