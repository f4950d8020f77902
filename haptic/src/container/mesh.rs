//! [`MeshContainer`]: a haptic container whose geometry is a closed triangle mesh, located by
//! multiple haptic rays (thesis 6.5, Figures 6.3 and 6.4).
//!
//! From the HIP, rays are cast in the directions `(cos u, sin u cos v, sin u sin v)` for a
//! uniform grid of `u` in `(0, pi)` and `v` in `[0, 2 pi)`. For each ray the nearest hit counts:
//! `g = ray . N` with the triangle's outward normal `N` is positive when the ray leaves the
//! solid (the HIP is inside) and negative when it enters it (outside). A coarse set of rays
//! decides when it is unanimous; when rays disagree (an open or self-intersecting mesh, a
//! grazing ray) a finer set is cast and the majority decides, the nearest hit breaking ties:
//! the ray count adapts to the local complexity. The ray length adapts too: it reaches the
//! farthest corner of the mesh's box, so from inside a closed mesh every ray hits; a user may
//! cap it ([`RayParams::length_max`]), and a point no ray reaches is outside.
//!
//! The distance to the surface is the smallest distance from the HIP to the planes of the hit
//! triangles on the decided side, `|(v0 - p) . N|`, and the gradient is `-N` of that plane
//! (`f >= 0` inside, so `f` grows inward). Sparse rays can miss the nearest facet, so up to
//! [`PROBE_RAYS`] more rays are cast along the best plane's normal, toward it, keeping a
//! nearer plane when they find one. A point outside the mesh's box is outside at once,
//! at its distance to the box.
//!
//! Guarantees: for a closed, consistently wound mesh the sign is exact except within
//! rounding of the surface; inside a convex mesh the distance is exact. Non-guarantees: plane
//! distances underestimate the depth in concave regions and outside near edges (they are
//! lower bounds there); a thin feature between rays can be missed by the distance (never by
//! the sign, which every single ray decides alone for a closed mesh).
//!
//! Nothing here allocates after [`MeshContainer::new`]: the triangles are indexed once by
//! model's shared [`model::bvh::Bvh`] ([`ray::RayIndex`]), whose traversal uses a fixed stack. Crossings of the segment travelled in one tick are found by casting that
//! segment as one ray ([`Container::first_crossing`]) instead of narrowing a bracket.

pub mod ray;
#[cfg(test)]
mod tests;

use glam::DVec3;

use super::function::checked_box;
use super::properties::{Properties, PropertyError, PropertySpec};
use super::{Container, FieldDomain};
use crate::aabb::Aabb;
use ray::{RayIndex, Triangle};

/// The most triangles one mesh container may hold.
pub const MAX_TRIANGLES: usize = 1 << 22;
/// The most vertices one mesh container may hold.
pub const MAX_VERTICES: usize = 1 << 22;
/// The most rays in one set (coarse or refined).
pub const MAX_RAYS: usize = 1024;
/// Rays cast toward the nearest plane found, to find a nearer one.
pub const PROBE_RAYS: usize = 2;

/// How many haptic rays to cast, and how far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayParams {
    /// Samples of `u` (polar angle) in the coarse set.
    pub n_u: u16,
    /// Samples of `v` (azimuth) in the coarse set.
    pub n_v: u16,
    /// Samples of `u` in the refined set, cast when the coarse rays disagree.
    pub n_u_refined: u16,
    /// Samples of `v` in the refined set.
    pub n_v_refined: u16,
    /// The longest ray, world units (infinite: reach the far corner of the mesh's box).
    pub length_max: f64,
}

impl Default for RayParams {
    fn default() -> Self {
        Self {
            n_u: 3,
            n_v: 4,
            n_u_refined: 8,
            n_v_refined: 12,
            length_max: f64::INFINITY,
        }
    }
}

/// Why a mesh container could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    /// No non-degenerate triangle.
    #[error("the mesh has no non-degenerate triangle")]
    Empty,
    /// More triangles than [`MAX_TRIANGLES`].
    #[error("too many triangles: {0} (limit {MAX_TRIANGLES})")]
    TooManyTriangles(usize),
    /// More vertices than [`MAX_VERTICES`].
    #[error("too many vertices: {0} (limit {MAX_VERTICES})")]
    TooManyVertices(usize),
    /// A triangle names a vertex that does not exist.
    #[error("triangle {triangle} names vertex {vertex}, but there are {n_vertices}")]
    IndexOutOfRange {
        /// The triangle.
        triangle: usize,
        /// The vertex index it names.
        vertex: u32,
        /// How many vertices there are.
        n_vertices: usize,
    },
    /// A vertex is not finite.
    #[error("vertex {0} is not finite")]
    NotFinite(usize),
    /// A ray set is empty or larger than [`MAX_RAYS`], or the length is not positive.
    #[error("bad ray parameters: {0:?}")]
    BadRays(RayParams),
    /// A property could not be compiled.
    #[error(transparent)]
    Property(#[from] PropertyError),
}

/// Counters of the ray casting, for tuning and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    /// Locations computed (cache misses).
    pub n_locations: u64,
    /// Rays cast.
    pub n_rays: u64,
    /// Locations where the coarse rays disagreed and the refined set was cast.
    pub n_refined: u64,
}

#[derive(Clone, Copy, Debug)]
struct Side {
    n_votes: u32,
    /// Smallest plane distance and its triangle's normal.
    nearest: (f64, DVec3),
}

impl Side {
    const NONE: Side = Side {
        n_votes: 0,
        nearest: (f64::INFINITY, DVec3::ZERO),
    };
}

/// A container bounded by a closed triangle mesh, with properties.
#[derive(Clone, Debug)]
pub struct MeshContainer {
    id: u64,
    index: RayIndex,
    bounds: Aabb,
    props: Properties,
    rays: RayParams,
    dirs_coarse: Vec<DVec3>,
    dirs_refined: Vec<DVec3>,
    cache: Option<(DVec3, (f64, DVec3))>,
    stats: RayStats,
}

/// Ray directions `(cos u, sin u cos v, sin u sin v)` on an `n_u x n_v` grid, rows staggered
/// by half a step of `v`, all turned by one fixed rotation so that no ray runs along a
/// coordinate axis or plane (where meshes tend to have edges).
fn ray_directions(n_u: u16, n_v: u16) -> Vec<DVec3> {
    let turn = glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.1234, 0.2345, 0.3456);
    let mut dirs = Vec::with_capacity(usize::from(n_u) * usize::from(n_v));
    for i in 0..n_u {
        let u = std::f64::consts::PI * (f64::from(i) + 0.5) / f64::from(n_u);
        for j in 0..n_v {
            let stagger = 0.5 * f64::from(i % 2);
            let v = std::f64::consts::TAU * (f64::from(j) + stagger) / f64::from(n_v);
            let d = DVec3::new(u.cos(), u.sin() * v.cos(), u.sin() * v.sin());
            dirs.push(turn * d);
        }
    }
    dirs
}

impl MeshContainer {
    /// Builds a container from vertices and counter-clockwise (outward) triangles. Degenerate
    /// triangles are dropped. Allocates the BVH and the ray directions.
    pub fn new(
        id: u64,
        vertices: &[[f32; 3]],
        triangles: &[[u32; 3]],
        props: &PropertySpec,
        rays: RayParams,
    ) -> Result<Self, MeshError> {
        if vertices.len() > MAX_VERTICES {
            return Err(MeshError::TooManyVertices(vertices.len()));
        }
        if triangles.len() > MAX_TRIANGLES {
            return Err(MeshError::TooManyTriangles(triangles.len()));
        }
        let n_set = |a: u16, b: u16| usize::from(a) * usize::from(b);
        let (coarse, refined) = (
            n_set(rays.n_u, rays.n_v),
            n_set(rays.n_u_refined, rays.n_v_refined),
        );
        if !(1..=MAX_RAYS).contains(&coarse)
            || !(1..=MAX_RAYS).contains(&refined)
            || rays.length_max.is_nan()
            || rays.length_max <= 0.0
        {
            return Err(MeshError::BadRays(rays));
        }
        if let Some(idx) = vertices
            .iter()
            .position(|v| !v.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NotFinite(idx));
        }
        let mut tris = Vec::with_capacity(triangles.len());
        for (triangle, corners) in triangles.iter().enumerate() {
            let mut p = [DVec3::ZERO; 3];
            for (slot, &vertex) in p.iter_mut().zip(corners) {
                let v = vertices
                    .get(vertex as usize)
                    .ok_or(MeshError::IndexOutOfRange {
                        triangle,
                        vertex,
                        n_vertices: vertices.len(),
                    })?;
                *slot = DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
            }
            tris.extend(Triangle::new(p[0], p[1], p[2]));
        }
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for tri in &tris {
            for c in [tri.v0, tri.v0 + tri.e1, tri.v0 + tri.e2] {
                lo = lo.min(c);
                hi = hi.max(c);
            }
        }
        let bounds = checked_box(lo, hi).ok_or(MeshError::Empty)?;
        Ok(Self {
            id,
            index: RayIndex::build(tris),
            bounds,
            props: Properties::new(props, bounds)?,
            rays,
            dirs_coarse: ray_directions(rays.n_u, rays.n_v),
            dirs_refined: ray_directions(rays.n_u_refined, rays.n_v_refined),
            cache: None,
            stats: RayStats::default(),
        })
    }

    /// Ray-casting counters since construction.
    pub fn ray_stats(&self) -> RayStats {
        self.stats
    }

    /// The number of triangles kept (degenerate ones dropped).
    pub fn n_triangles(&self) -> usize {
        self.index.triangles().len()
    }

    /// Casts one set of rays from `p`; returns (inside side, outside side, sign of the
    /// nearest hit: +1 inside, -1 outside, 0 no hit).
    fn cast(&mut self, p: DVec3, length: f64, refined: bool) -> (Side, Side, i8) {
        let dirs = if refined {
            &self.dirs_refined
        } else {
            &self.dirs_coarse
        };
        let (mut inside, mut outside) = (Side::NONE, Side::NONE);
        let mut nearest = (f64::INFINITY, 0i8);
        for &dir in dirs {
            let Some(hit) = self.index.nearest_hit(p, dir, length) else {
                continue;
            };
            let tri = &self.index.triangles()[hit.tri_idx as usize];
            let g = dir.dot(tri.normal);
            let side = if g > 0.0 {
                &mut inside
            } else if g < 0.0 {
                &mut outside
            } else {
                continue;
            };
            side.n_votes += 1;
            let plane_distance = (tri.v0 - p).dot(tri.normal).abs();
            if plane_distance < side.nearest.0 {
                side.nearest = (plane_distance, tri.normal);
            }
            if hit.t < nearest.0 {
                nearest = (hit.t, if g > 0.0 { 1 } else { -1 });
            }
        }
        self.stats.n_rays += dirs.len() as u64;
        (inside, outside, nearest.1)
    }

    /// Refines the nearest plane `(distance, normal)` by casting rays toward it: from
    /// inside (`facing = 1`) along the normal, from outside against it. Each probe lands near
    /// the foot of the perpendicular, where the nearest facet usually is.
    fn probe(
        &mut self,
        p: DVec3,
        mut nearest: (f64, DVec3),
        length: f64,
        facing: f64,
    ) -> (f64, DVec3) {
        for _ in 0..PROBE_RAYS {
            let dir = nearest.1 * facing;
            self.stats.n_rays += 1;
            let Some(hit) = self.index.nearest_hit(p, dir, length) else {
                break;
            };
            let tri = &self.index.triangles()[hit.tri_idx as usize];
            let plane_distance = (tri.v0 - p).dot(tri.normal).abs();
            if dir.dot(tri.normal) * facing <= 0.0 || plane_distance >= nearest.0 {
                break;
            }
            nearest = (plane_distance, tri.normal);
        }
        nearest
    }

    fn locate(&mut self, p: DVec3) -> (f64, DVec3) {
        self.stats.n_locations += 1;
        if !self.bounds.contains(p) {
            let d = p - self.bounds.clamp(p);
            return (-d.length(), -d.normalize_or_zero());
        }
        let far_corner = (p - self.bounds.min).abs().max((p - self.bounds.max).abs());
        let length = (far_corner.length() * (1.0 + 1e-9)).min(self.rays.length_max);
        let (mut inside, mut outside, mut nearest) = self.cast(p, length, false);
        if inside.n_votes > 0 && outside.n_votes > 0 {
            self.stats.n_refined += 1;
            (inside, outside, nearest) = self.cast(p, length, true);
        }
        let is_inside = match inside.n_votes.cmp(&outside.n_votes) {
            std::cmp::Ordering::Greater => true,
            std::cmp::Ordering::Less => false,
            std::cmp::Ordering::Equal => nearest > 0,
        };
        if is_inside {
            let (distance, normal) = self.probe(p, inside.nearest, length, 1.0);
            (distance, -normal)
        } else if outside.n_votes > 0 {
            let (distance, normal) = self.probe(p, outside.nearest, length, -1.0);
            (-distance, -normal)
        } else {
            // Nothing within reach: outside, at least a ray's length from any surface the
            // rays could see.
            (-length, (self.bounds.center() - p).normalize_or_zero())
        }
    }
}

impl Container for MeshContainer {
    fn id(&self) -> u64 {
        self.id
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The geometry does not depend on time, so one location per point is cached (the servo
    /// asks for the HIP twice per tick: stack update, then force).
    fn value_grad(&mut self, p: DVec3, _t_secs: f64) -> (f64, DVec3) {
        if let Some((at, result)) = self.cache
            && at == p
        {
            return result;
        }
        let result = self.locate(p);
        self.cache = Some((p, result));
        result
    }

    fn first_crossing(&mut self, p0: DVec3, p1: DVec3, _t_secs: f64) -> Option<f64> {
        let dir = p1 - p0;
        if dir == DVec3::ZERO || !dir.is_finite() {
            return None;
        }
        self.index.nearest_hit(p0, dir, 1.0).map(|hit| hit.t)
    }

    fn tension(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.props.tension(p, t_secs)
    }

    fn friction(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.props.friction(p, t_secs)
    }

    fn density(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.props.density(p, t_secs)
    }

    fn zone_depth(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.props.zone_depth(p, t_secs)
    }

    fn field_domain(&self) -> Option<FieldDomain> {
        self.props.field_domain()
    }

    fn force_field(&mut self, uvw: DVec3, t_local_secs: f64) -> DVec3 {
        self.props.force_field(uvw, t_local_secs)
    }
}
