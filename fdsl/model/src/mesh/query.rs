//! The queries that make a [`TriMesh`] an F-Rep field: closest point, distance, inside by ray
//! parity, signed distance and its gradient, ray hits, and the generalized winding number.
//! None allocates: the hierarchy keeps its traversal stack in a fixed array.

use glam::DVec3;

use super::TriMesh;
use super::geometry::{
    Crossing, closest_point_on_triangle, ray_crossing, ray_triangle, solid_angle_fraction,
    triangle_normal,
};

/// Directions of the parity rays, tried in order until one crosses no edge or vertex. They
/// are deliberately not aligned with axes, diagonals or icosahedral symmetry axes, which is
/// where modelled meshes keep their edges and vertices. Each is flipped to point away from
/// the mesh's centre, which shortens the ray.
const RAY_DIRECTIONS: [DVec3; 9] = [
    DVec3::new(0.6132, 0.2713, 0.7419),
    DVec3::new(-0.3178, 0.8351, 0.4490),
    DVec3::new(0.2219, -0.5477, 0.8066),
    DVec3::new(0.9023, 0.3719, -0.2180),
    DVec3::new(-0.4871, -0.6529, 0.5801),
    DVec3::new(0.1531, 0.9347, -0.3208),
    DVec3::new(0.7331, -0.1759, -0.6570),
    DVec3::new(-0.8617, 0.2381, -0.4478),
    DVec3::new(0.3891, 0.4273, 0.8161),
];

/// How many clear rays vote on an open mesh.
const OPEN_MESH_VOTES: u32 = 3;

/// The point of a mesh nearest to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// The nearest point on the surface.
    pub point: DVec3,
    /// The triangle it lies on (the first found when several are equally near).
    pub triangle_idx: u32,
    /// The distance from the query point to it.
    pub distance: f64,
}

/// Where a ray first meets a mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// The ray parameter: the hit is at `origin + t * dir`.
    pub t: f64,
    /// The triangle hit.
    pub triangle_idx: u32,
    /// The triangle's unit normal by the right-hand rule (outwards for a mesh that faces
    /// outwards), or zero for a triangle without area.
    pub normal: DVec3,
}

impl TriMesh {
    /// The point of the surface nearest to `p`; `None` for an empty mesh or a point that is
    /// not finite.
    pub fn closest(&self, p: DVec3) -> Option<Closest> {
        self.closest_within(p, f64::INFINITY)
    }

    /// The point of the surface nearest to `p` if it is nearer than `max_distance`; cheaper
    /// than [`TriMesh::closest`] when most of the mesh is farther.
    pub fn closest_within(&self, p: DVec3, max_distance: f64) -> Option<Closest> {
        if !p.is_finite() {
            return None;
        }
        let (triangle_idx, distance) = self.bvh.nearest(p, max_distance, |t| {
            let [a, b, c] = self.corners(t);
            p.distance(closest_point_on_triangle(p, a, b, c))
        })?;
        let [a, b, c] = self.corners(triangle_idx);
        Some(Closest {
            point: closest_point_on_triangle(p, a, b, c),
            triangle_idx,
            distance,
        })
    }

    /// The distance from `p` to the surface: infinite for an empty mesh, NaN for a point that
    /// is not finite.
    pub fn distance(&self, p: DVec3) -> f64 {
        if !p.is_finite() {
            return f64::NAN;
        }
        self.closest(p).map_or(f64::INFINITY, |c| c.distance)
    }

    /// Whether `p` is inside, by ray parity: for a closed mesh, the first of several fixed
    /// rays that crosses no edge or vertex decides; for an open mesh, the majority of three
    /// such rays. When all nine rays graze an edge (within a rounding error of one), the side
    /// of the nearest triangle decides. Points on the surface may go either way; points
    /// outside the bounds and points that are not finite are outside.
    pub fn inside(&self, p: DVec3) -> bool {
        if !p.is_finite() || !self.bounds.contains(p) {
            return false;
        }
        let centre = self.bounds.center();
        let (mut votes_in, mut votes_out) = (0, 0);
        for dir in RAY_DIRECTIONS {
            let dir = if (p - centre).dot(dir) < 0.0 {
                -dir
            } else {
                dir
            };
            let (parity, ambiguous) = self.ray_parity(p, dir);
            if ambiguous {
                continue;
            }
            if self.closed {
                return parity;
            }
            if parity {
                votes_in += 1;
            } else {
                votes_out += 1;
            }
            if votes_in + votes_out == OPEN_MESH_VOTES {
                break;
            }
        }
        if votes_in + votes_out == 0 {
            return self.inside_by_nearest_normal(p);
        }
        votes_in > votes_out
    }

    /// The fallback when every ray grazed an edge or vertex, which happens only within a
    /// rounding error of one: which side of the nearest triangle's plane `p` is on (points on
    /// the surface are inside). This is right near faces and edges of a consistently oriented
    /// mesh; it can be wrong only near a vertex where convex and concave edges meet.
    fn inside_by_nearest_normal(&self, p: DVec3) -> bool {
        let Some(closest) = self.closest(p) else {
            return false;
        };
        if closest.distance <= self.surface_epsilon {
            return true;
        }
        let [a, b, c] = self.corners(closest.triangle_idx);
        (p - closest.point).dot(triangle_normal(a, b, c)) * self.outwards() < 0.0
    }

    /// 1 when triangle normals face outwards, -1 for an inside-out closed mesh.
    fn outwards(&self) -> f64 {
        if self.closed && self.signed_volume < 0.0 {
            -1.0
        } else {
            1.0
        }
    }

    /// Whether the ray from `p` along `dir` crosses the surface an odd number of times, and
    /// whether some crossing was too close to an edge or vertex to count.
    fn ray_parity(&self, p: DVec3, dir: DVec3) -> (bool, bool) {
        let (mut odd, mut ambiguous) = (false, false);
        self.bvh.visit_ray(p, dir, f64::INFINITY, |t| {
            let [a, b, c] = self.corners(t);
            match ray_crossing(p, dir, a, b, c) {
                Crossing::Miss => {}
                Crossing::Hit(_) => odd = !odd,
                Crossing::Ambiguous => ambiguous = true,
            }
        });
        (odd, ambiguous)
    }

    /// The signed distance, positive inside ([`TriMesh::inside`] decides the sign): an
    /// F-Rep field whose zero set is the surface. Negative infinity for an empty mesh, NaN
    /// for a point that is not finite.
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        self.value_gradient(p).0
    }

    /// The signed distance and its gradient, a unit vector pointing inwards: away from the
    /// nearest point inside, towards it outside. On the surface (within 1e-12 of the mesh's
    /// size, where the direction to the nearest point is rounding noise) the value is 0 and
    /// the gradient is the inward normal of the nearest triangle. For an empty mesh
    /// `(-inf, 0)`; for a point that is not finite `(NaN, 0)`.
    pub fn value_gradient(&self, p: DVec3) -> (f64, DVec3) {
        if !p.is_finite() {
            return (f64::NAN, DVec3::ZERO);
        }
        let Some(closest) = self.closest(p) else {
            return (f64::NEG_INFINITY, DVec3::ZERO);
        };
        if closest.distance <= self.surface_epsilon {
            let [a, b, c] = self.corners(closest.triangle_idx);
            return (0.0, -self.outwards() * triangle_normal(a, b, c));
        }
        let away = (p - closest.point) / closest.distance;
        if self.inside(p) {
            (closest.distance, away)
        } else {
            (-closest.distance, -away)
        }
    }

    /// The gradient of [`TriMesh::signed_distance`]; see [`TriMesh::value_gradient`].
    pub fn gradient(&self, p: DVec3) -> DVec3 {
        self.value_gradient(p).1
    }

    /// The first point where the ray `origin + t * dir`, `0 <= t <= t_max`, meets the
    /// surface (edges included), if any; `dir` need not be a unit vector.
    pub fn ray_hit(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<RayHit> {
        if !origin.is_finite() || !dir.is_finite() || dir == DVec3::ZERO || t_max.is_nan() {
            return None;
        }
        let mut best: Option<(f64, u32)> = None;
        self.bvh.visit_ray(origin, dir, t_max, |t| {
            let limit = best.map_or(t_max, |(best_t, _)| best_t);
            let [a, b, c] = self.corners(t);
            if let Some(hit_t) = ray_triangle(origin, dir, limit, a, b, c)
                && best.is_none_or(|(best_t, _)| hit_t < best_t)
            {
                best = Some((hit_t, t));
            }
        });
        best.map(|(t, triangle_idx)| {
            let [a, b, c] = self.corners(triangle_idx);
            RayHit {
                t,
                triangle_idx,
                normal: triangle_normal(a, b, c),
            }
        })
    }

    /// The generalized winding number at `p` (Jacobson et al. 2013): the signed solid angle of
    /// the surface over 4 pi, 1 inside and 0 outside a closed outward-facing mesh, and a
    /// smooth in-between near the holes of an open one. It visits every triangle (no
    /// hierarchy), so it is for checks and offline work, not the haptic loop.
    pub fn winding_number(&self, p: DVec3) -> f64 {
        (0..self.triangles.len() as u32)
            .map(|t| {
                let [a, b, c] = self.corners(t);
                solid_angle_fraction(p, a, b, c)
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::shapes;

    /// Points from which the first parity ray runs exactly through a vertex or the middle of
    /// an edge: the crossing must be flagged and another ray must decide, correctly.
    #[test]
    fn rays_through_vertices_and_edges_are_retried() {
        let sphere = shapes::icosphere(1.0, 2);
        let vertex = |i: u32| DVec3::from_array(sphere.positions()[i as usize].map(f64::from));
        let mut targets: Vec<DVec3> = (0..sphere.positions().len() as u32).map(vertex).collect();
        targets.extend(
            sphere
                .triangles()
                .iter()
                .map(|&[a, b, _]| (vertex(a) + vertex(b)) * 0.5),
        );
        let centre = sphere.bounds().center();
        let (mut n_checked, mut n_ambiguous) = (0, 0);
        for &target in &targets {
            for &dir in &RAY_DIRECTIONS[..2] {
                for s in [0.05, 0.3, 0.6, 1.5, 3.0] {
                    for p in [target - dir * s, target + dir * s] {
                        let rho = p.length();
                        if rho > 0.9 && rho < 1.0 + 1e-6 {
                            continue;
                        }
                        let first = if (p - centre).dot(RAY_DIRECTIONS[0]) < 0.0 {
                            -RAY_DIRECTIONS[0]
                        } else {
                            RAY_DIRECTIONS[0]
                        };
                        if dir == RAY_DIRECTIONS[0] && (target - p).dot(first) > 0.0 {
                            let (_, ambiguous) = sphere.ray_parity(p, first);
                            assert!(ambiguous, "the ray from {p} runs through {target}");
                            n_ambiguous += 1;
                        }
                        assert_eq!(sphere.inside(p), rho < 0.9, "{p} aimed at {target}");
                        n_checked += 1;
                    }
                }
            }
        }
        assert!(
            n_ambiguous > 400 && n_checked > 5000,
            "{n_ambiguous} {n_checked}"
        );
    }
}
