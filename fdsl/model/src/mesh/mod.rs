//! Triangle meshes as solids: [`TriMesh`] (validated vertices and triangles, indexed by a
//! [`Bvh`]) answers the F-Rep questions, inside or outside, distance, signed distance and its
//! gradient, and ray hits, without allocating, so the haptic loop can call them at 1 kHz.
//! Reading and writing mesh files (STL, OBJ, glTF) is the `formats` crate's.
//!
//! Sign convention: as everywhere in the object model, `f >= 0` is inside, so
//! [`TriMesh::signed_distance`] is positive inside and its gradient points inwards.
//!
//! What is guaranteed, and what is not:
//! - Every mesh has at most [`MAX_MESH_VERTICES`] vertices and [`MAX_MESH_TRIANGLES`]
//!   triangles, finite coordinates and indices in range; triangles may be degenerate.
//! - [`TriMesh::is_closed`] is exact (combinatorial): every edge is shared by exactly two
//!   triangles that run along it in opposite directions. Closed meshes may still
//!   self-intersect; inside then means "an odd number of surfaces around".
//! - For a closed mesh, [`TriMesh::inside`] is decided by one ray crossing no edge or vertex
//!   (ray parity). For an open mesh it is the majority of three such rays, which treats small
//!   holes as if they were filled but gives no meaningful inside for a sheet; use
//!   `-distance(p)` as the field of a surface that bounds nothing.
//!
//! ```
//! use model::mesh::{self, TriMesh};
//! use glam::DVec3;
//!
//! let cube = mesh::shapes::cube(DVec3::splat(-1.0), DVec3::splat(1.0));
//! assert!(cube.is_closed());
//! assert_eq!(cube.signed_distance(DVec3::new(0.5, 0.0, 0.0)), 0.5);
//! assert_eq!(cube.signed_distance(DVec3::new(3.0, 0.0, 0.0)), -2.0);
//! let (positions, triangles) = cube.clone().into_parts();
//! assert_eq!(TriMesh::new(positions, triangles).unwrap(), cube);
//! ```

pub mod geometry;
mod query;
pub mod shapes;

use std::fmt;

use glam::DVec3;
use thiserror::Error;

use crate::bvh::{Aabb, Bvh};

pub use query::{Closest, RayHit};

/// The most vertices a mesh may have (4 Mi).
pub const MAX_MESH_VERTICES: usize = 4 * 1024 * 1024;
/// The most triangles a mesh may have (4 Mi).
pub const MAX_MESH_TRIANGLES: usize = 4 * 1024 * 1024;

/// Distances below this fraction of a mesh's size count as on its surface.
const SURFACE_EPSILON: f64 = 1e-12;

/// Why a mesh could not be built from its parts.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum MeshError {
    /// More vertices than [`MAX_MESH_VERTICES`].
    #[error("{n_vertices} vertices is more than the limit of {MAX_MESH_VERTICES}")]
    TooManyVertices {
        /// How many there were.
        n_vertices: usize,
    },
    /// More triangles than [`MAX_MESH_TRIANGLES`].
    #[error("{n_triangles} triangles is more than the limit of {MAX_MESH_TRIANGLES}")]
    TooManyTriangles {
        /// How many there were.
        n_triangles: usize,
    },
    /// A coordinate is infinite or not a number.
    #[error("vertex {vertex_idx} has a coordinate that is not a finite number")]
    NotFinite {
        /// The vertex.
        vertex_idx: usize,
    },
    /// A triangle names a vertex that does not exist.
    #[error("triangle {triangle_idx} uses vertex {index}, but there are only {n_vertices}")]
    IndexOutOfRange {
        /// The triangle.
        triangle_idx: usize,
        /// The index it holds.
        index: u32,
        /// How many vertices there are.
        n_vertices: usize,
    },
}

/// A triangle mesh: vertex positions and triangles of vertex indices, counter-clockwise seen
/// from outside, with its bounding box, a bounding volume hierarchy over its triangles and
/// whether it is closed, all computed once on construction.
#[derive(Clone)]
pub struct TriMesh {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    bvh: Bvh,
    bounds: Aabb,
    closed: bool,
    signed_volume: f64,
    /// Distances up to this count as on the surface: 1e-12 of the bounds' diagonal, where the
    /// direction from the nearest point is rounding noise.
    surface_epsilon: f64,
}

impl TriMesh {
    /// Checks the parts (limits, finite coordinates, indices in range) and indexes them.
    /// Triangles may be degenerate and vertices unused.
    pub fn new(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Result<TriMesh, MeshError> {
        if positions.len() > MAX_MESH_VERTICES {
            return Err(MeshError::TooManyVertices {
                n_vertices: positions.len(),
            });
        }
        if triangles.len() > MAX_MESH_TRIANGLES {
            return Err(MeshError::TooManyTriangles {
                n_triangles: triangles.len(),
            });
        }
        if let Some(vertex_idx) = positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NotFinite { vertex_idx });
        }
        for (triangle_idx, t) in triangles.iter().enumerate() {
            if let Some(&index) = t.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(MeshError::IndexOutOfRange {
                    triangle_idx,
                    index,
                    n_vertices: positions.len(),
                });
            }
        }
        Ok(TriMesh::index(positions, triangles))
    }

    /// Builds a mesh from a triangle soup (three corners per triangle) by merging corners
    /// with exactly equal coordinates, as [`TriMesh::welded`] does.
    pub fn from_triangle_soup(soup: &[[[f32; 3]; 3]]) -> Result<TriMesh, MeshError> {
        if soup.len() > MAX_MESH_TRIANGLES {
            return Err(MeshError::TooManyTriangles {
                n_triangles: soup.len(),
            });
        }
        let corners = soup.as_flattened();
        if let Some(vertex_idx) = corners
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NotFinite { vertex_idx });
        }
        let triangles = (0..soup.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]);
        let (positions, triangles) = weld(corners, triangles);
        Ok(TriMesh::index(positions, triangles))
    }

    /// The same surface with vertices of exactly equal coordinates merged (`-0.0` equals
    /// `0.0`), unused vertices dropped, vertices numbered in order of first use, and
    /// triangles that use one vertex twice dropped. Exporters that split vertices along
    /// texture seams or per face produce open meshes that this closes.
    pub fn welded(&self) -> TriMesh {
        let (positions, triangles) = weld(&self.positions, self.triangles.iter().copied());
        TriMesh::index(positions, triangles)
    }

    fn index(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> TriMesh {
        let mut mesh = TriMesh {
            positions,
            triangles,
            bvh: Bvh::default(),
            bounds: Aabb::EMPTY,
            closed: false,
            signed_volume: 0.0,
            surface_epsilon: 0.0,
        };
        let boxes: Vec<Aabb> = (0..mesh.triangles.len())
            .map(|t| {
                let [a, b, c] = mesh.corners(t as u32);
                Aabb::new(a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        mesh.bvh = Bvh::build(&boxes);
        mesh.bounds = mesh.bvh.bounds();
        if !mesh.bounds.is_empty() {
            mesh.surface_epsilon = SURFACE_EPSILON * mesh.bounds.size().length();
        }
        mesh.closed = is_closed(&mesh.triangles);
        mesh.signed_volume = (0..mesh.triangles.len())
            .map(|t| {
                let [a, b, c] = mesh.corners(t as u32);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        mesh
    }

    /// The vertex positions.
    pub fn positions(&self) -> &[[f32; 3]] {
        &self.positions
    }

    /// The triangles, three vertex indices each, counter-clockwise seen from outside.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The parts, for a caller that wants to change them and build a new mesh.
    pub fn into_parts(self) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (self.positions, self.triangles)
    }

    /// Whether the mesh has no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The box around every triangle (unused vertices are not counted), or [`Aabb::EMPTY`].
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Whether every edge is shared by exactly two triangles that run along it in opposite
    /// directions (so the surface is closed and consistently oriented), and no triangle uses
    /// a vertex twice. An empty mesh is not closed.
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// The volume enclosed, by the divergence theorem: positive when the triangles face
    /// outwards, negative when the mesh is inside out; meaningful only for closed meshes.
    pub fn signed_volume(&self) -> f64 {
        self.signed_volume
    }

    /// The corners of triangle `triangle_idx` in f64.
    ///
    /// # Panics
    /// If `triangle_idx` is out of range.
    #[inline]
    pub fn corners(&self, triangle_idx: u32) -> [DVec3; 3] {
        let [a, b, c] = self.triangles[triangle_idx as usize];
        [self.position(a), self.position(b), self.position(c)]
    }

    #[inline]
    fn position(&self, vertex_idx: u32) -> DVec3 {
        let [x, y, z] = self.positions[vertex_idx as usize];
        DVec3::new(f64::from(x), f64::from(y), f64::from(z))
    }
}

impl fmt::Debug for TriMesh {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TriMesh")
            .field("n_vertices", &self.positions.len())
            .field("n_triangles", &self.triangles.len())
            .field("bounds", &self.bounds)
            .field("closed", &self.closed)
            .finish_non_exhaustive()
    }
}

/// Two meshes are equal when their positions (compared as numbers) and triangles are.
impl PartialEq for TriMesh {
    fn eq(&self, other: &TriMesh) -> bool {
        self.positions == other.positions && self.triangles == other.triangles
    }
}

/// Merges equal positions; see [`TriMesh::welded`]. Positions must be finite and indices in
/// range.
fn weld(
    positions: &[[f32; 3]],
    triangles: impl Iterator<Item = [u32; 3]>,
) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    // Adding 0.0 turns -0.0 into 0.0; positions are finite, so the bits then compare exactly
    // when the numbers do.
    let key = |i: u32| positions[i as usize].map(|c| (c + 0.0).to_bits());
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.sort_unstable_by_key(|&i| (key(i), i));
    let mut representative = vec![0u32; positions.len()];
    let mut run_start = 0;
    for k in 0..order.len() {
        if key(order[k]) != key(order[run_start]) {
            run_start = k;
        }
        representative[order[k] as usize] = order[run_start];
    }
    let mut new_idx = vec![u32::MAX; positions.len()];
    let mut welded_positions = Vec::new();
    let mut welded_triangles = Vec::new();
    for t in triangles {
        let t = t.map(|i| {
            let r = representative[i as usize] as usize;
            if new_idx[r] == u32::MAX {
                new_idx[r] = welded_positions.len() as u32;
                welded_positions.push(positions[r]);
            }
            new_idx[r]
        });
        if t[0] != t[1] && t[1] != t[2] && t[2] != t[0] {
            welded_triangles.push(t);
        }
    }
    (welded_positions, welded_triangles)
}

/// Whether every directed edge appears once and its reverse once, with no triangle using a
/// vertex twice.
fn is_closed(triangles: &[[u32; 3]]) -> bool {
    if triangles.is_empty() {
        return false;
    }
    let mut edges: Vec<u64> = Vec::with_capacity(3 * triangles.len());
    for &[a, b, c] in triangles {
        if a == b || b == c || c == a {
            return false;
        }
        for (from, to) in [(a, b), (b, c), (c, a)] {
            edges.push(u64::from(from) << 32 | u64::from(to));
        }
    }
    edges.sort_unstable();
    if edges.windows(2).any(|w| w[0] == w[1]) {
        return false;
    }
    edges
        .iter()
        .all(|&e| edges.binary_search(&e.rotate_right(32)).is_ok())
}
