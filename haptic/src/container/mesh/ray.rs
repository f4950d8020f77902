//! Nearest-hit ray casting over a triangle set for the haptic rays: triangles prepared for
//! Moeller-Trumbore intersection with their winding normals, indexed by model's shared
//! [`model::bvh::Bvh`] (the one the object model's edit history uses), whose traversal keeps
//! its stack in a fixed array, so a query allocates nothing.
//!
//! The shared hierarchy visits every leaf the ray passes through, in no particular order; the
//! nearest hit is kept by shrinking the ray's length as hits are found, and a leaf's
//! triangles are skipped when their own box lies beyond the best hit so far.

use glam::DVec3;

use model::bvh::{Aabb, Bvh};

/// A triangle prepared for intersection: a corner, two edges and the unit normal given by the
/// winding (`e1 x e2`, outward for a counter-clockwise closed mesh).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    /// First corner.
    pub v0: DVec3,
    /// Second corner minus the first.
    pub e1: DVec3,
    /// Third corner minus the first.
    pub e2: DVec3,
    /// Unit normal by winding.
    pub normal: DVec3,
}

impl Triangle {
    /// A triangle from corners; `None` when degenerate (no normal) or not finite.
    pub fn new(a: DVec3, b: DVec3, c: DVec3) -> Option<Self> {
        let (e1, e2) = (b - a, c - a);
        let normal = e1.cross(e2).try_normalize()?;
        (a.is_finite() && b.is_finite() && c.is_finite()).then_some(Self {
            v0: a,
            e1,
            e2,
            normal,
        })
    }

    /// The box around the triangle.
    pub fn aabb(&self) -> Aabb {
        let (b, c) = (self.v0 + self.e1, self.v0 + self.e2);
        Aabb {
            lo: self.v0.min(b).min(c),
            hi: self.v0.max(b).max(c),
        }
    }

    /// The ray parameter of the hit with `origin + t * dir`, `0 <= t <= t_max`
    /// (Moeller-Trumbore, both sides, edges included).
    pub fn intersect(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<f64> {
        let pvec = dir.cross(self.e2);
        let det = self.e1.dot(pvec);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let tvec = origin - self.v0;
        let u = tvec.dot(pvec) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let qvec = tvec.cross(self.e1);
        let v = dir.dot(qvec) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = self.e2.dot(qvec) * inv;
        (0.0..=t_max).contains(&t).then_some(t)
    }
}

/// The nearest hit of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter (distance when the direction is a unit vector).
    pub t: f64,
    /// Index into [`RayIndex::triangles`].
    pub tri_idx: u32,
}

/// Triangles and the hierarchy over their boxes.
#[derive(Clone, Debug)]
pub struct RayIndex {
    bvh: Bvh,
    tris: Vec<Triangle>,
    boxes: Vec<Aabb>,
}

impl RayIndex {
    /// Indexes `tris` (allocates; not for the servo thread).
    pub fn build(tris: Vec<Triangle>) -> Self {
        let boxes: Vec<Aabb> = tris.iter().map(Triangle::aabb).collect();
        Self {
            bvh: Bvh::build(&boxes),
            tris,
            boxes,
        }
    }

    /// The triangles, in the order given.
    pub fn triangles(&self) -> &[Triangle] {
        &self.tris
    }

    /// The nearest triangle hit by `origin + t * dir` with `0 <= t <= t_max`. No allocation.
    pub fn nearest_hit(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        let inv_dir = dir.recip();
        self.bvh.visit_ray(origin, dir, t_max, |item| {
            let idx = item as usize;
            // The leaf was entered within `t_max`; this triangle may still lie beyond the best.
            if self.boxes[idx]
                .ray_interval(origin, inv_dir, t_best)
                .is_none()
            {
                return;
            }
            if let Some(t) = self.tris[idx].intersect(origin, dir, t_best) {
                t_best = t;
                best = Some(Hit { t, tri_idx: item });
            }
        });
        best
    }
}
