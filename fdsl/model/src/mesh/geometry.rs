//! Per-triangle geometry in f64 (public for callers that test or extend the mesh queries): the closest point on a triangle, ray crossings that
//! report when they are too close to an edge or a vertex to count, and the solid angle a
//! triangle subtends.

use glam::DVec3;

/// Barycentric margin under which a ray crossing is too close to an edge or vertex to count.
const EDGE_EPSILON: f64 = 1e-9;
/// Relative size of `det` (the sine of the angle between ray and plane) under which a ray is
/// treated as parallel to a triangle.
const PARALLEL_EPSILON: f64 = 1e-12;

/// The point of triangle `(a, b, c)` nearest to `p` (Ericson, "Real-Time Collision Detection",
/// 5.1.5), also for degenerate triangles, whose closest point is on one of their edges.
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom > 0.0 && denom.is_finite() {
        let v = vb / denom;
        let w = vc / denom;
        return a + ab * v + ac * w;
    }
    // A degenerate (zero-area) triangle falls through every region test: take the best edge.
    let candidates = [
        closest_point_on_segment(p, a, b),
        closest_point_on_segment(p, b, c),
        closest_point_on_segment(p, c, a),
    ];
    candidates
        .into_iter()
        .min_by(|x, y| p.distance_squared(*x).total_cmp(&p.distance_squared(*y)))
        .unwrap_or(a)
}

fn closest_point_on_segment(p: DVec3, a: DVec3, b: DVec3) -> DVec3 {
    let ab = b - a;
    let len_sq = ab.length_squared();
    if len_sq <= 0.0 {
        return a;
    }
    a + ab * ((p - a).dot(ab) / len_sq).clamp(0.0, 1.0)
}

/// How a ray meets a triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Crossing {
    /// The ray misses (or the triangle has no area).
    Miss,
    /// The ray crosses the interior at parameter `t >= 0`, clear of edges and vertices.
    Hit(f64),
    /// The ray passes within a rounding error of an edge or vertex, or lies in the
    /// triangle's plane: whether it crosses cannot be decided reliably.
    Ambiguous,
}

/// Where the ray `origin + t * dir`, `t >= 0`, meets triangle `(a, b, c)` (Möller-Trumbore in
/// f64, with margins that flag crossings too close to call).
pub(crate) fn ray_crossing(origin: DVec3, dir: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Crossing {
    let e1 = b - a;
    let e2 = c - a;
    let pvec = dir.cross(e2);
    let det = e1.dot(pvec);
    let normal = e1.cross(e2);
    let area2 = normal.length();
    if area2 == 0.0 || !area2.is_finite() {
        return Crossing::Miss;
    }
    let scale = e1.length().max(e2.length()).max((c - b).length());
    let dir_len = dir.length();
    if det.abs() <= PARALLEL_EPSILON * area2 * dir_len {
        // Parallel: only a ray in the plane could touch the triangle, through its edges.
        let height = normal.dot(origin - a).abs() / area2;
        return if height <= EDGE_EPSILON * scale {
            Crossing::Ambiguous
        } else {
            Crossing::Miss
        };
    }
    let inv = 1.0 / det;
    let tvec = origin - a;
    let u = tvec.dot(pvec) * inv;
    let qvec = tvec.cross(e1);
    let v = dir.dot(qvec) * inv;
    let w = 1.0 - u - v;
    let t = e2.dot(qvec) * inv;
    if u < -EDGE_EPSILON || v < -EDGE_EPSILON || w < -EDGE_EPSILON {
        return Crossing::Miss;
    }
    // A ray starting on the triangle (t near 0) is not flagged: its origin is on the surface,
    // where either answer is right.
    if t < 0.0 {
        return Crossing::Miss;
    }
    if u <= EDGE_EPSILON || v <= EDGE_EPSILON || w <= EDGE_EPSILON {
        return Crossing::Ambiguous;
    }
    Crossing::Hit(t)
}

/// The parameter `t` in `[0, t_max]` at which the ray meets triangle `(a, b, c)`, edges
/// included, for picking: no margins, first hit wins.
pub fn ray_triangle(
    origin: DVec3,
    dir: DVec3,
    t_max: f64,
    a: DVec3,
    b: DVec3,
    c: DVec3,
) -> Option<f64> {
    let e1 = b - a;
    let e2 = c - a;
    let pvec = dir.cross(e2);
    let det = e1.dot(pvec);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let tvec = origin - a;
    let u = tvec.dot(pvec) * inv;
    let qvec = tvec.cross(e1);
    let v = dir.dot(qvec) * inv;
    let t = e2.dot(qvec) * inv;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t >= 0.0 && t <= t_max).then_some(t)
}

/// The signed solid angle triangle `(a, b, c)` subtends at `p`, over 4 pi (Van Oosterom and
/// Strackee): the triangle's share of the generalized winding number.
pub fn solid_angle_fraction(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (a, b, c) = (a - p, b - p, c - p);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c));
    let denominator = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    2.0 * numerator.atan2(denominator) / (4.0 * std::f64::consts::PI)
}

/// The unit normal of triangle `(a, b, c)` by the right-hand rule, or zero when it has no area.
pub fn triangle_normal(a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    (b - a).cross(c - a).normalize_or_zero()
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: DVec3 = DVec3::ZERO;
    const B: DVec3 = DVec3::X;
    const C: DVec3 = DVec3::Y;

    #[test]
    fn closest_point_in_every_region() {
        let cases = [
            (DVec3::new(0.2, 0.2, 1.0), DVec3::new(0.2, 0.2, 0.0)),
            (DVec3::new(-1.0, -1.0, 0.5), A),
            (DVec3::new(2.0, -0.5, 0.0), B),
            (DVec3::new(-0.5, 3.0, 0.0), C),
            (DVec3::new(0.5, -1.0, 2.0), DVec3::new(0.5, 0.0, 0.0)),
            (DVec3::new(-1.0, 0.5, 0.0), DVec3::new(0.0, 0.5, 0.0)),
            (DVec3::new(1.0, 1.0, -1.0), DVec3::new(0.5, 0.5, 0.0)),
        ];
        for (p, want) in cases {
            let got = closest_point_on_triangle(p, A, B, C);
            assert!(got.distance(want) < 1e-12, "{p}: {got} != {want}");
        }
    }

    #[test]
    fn degenerate_triangles_have_a_closest_point() {
        let p = DVec3::new(0.5, 1.0, 0.0);
        let got = closest_point_on_triangle(p, A, B, DVec3::new(2.0, 0.0, 0.0));
        assert!(got.distance(DVec3::new(0.5, 0.0, 0.0)) < 1e-12, "{got}");
        assert_eq!(closest_point_on_triangle(p, B, B, B), B);
    }

    #[test]
    fn crossings_are_hits_misses_or_ambiguous() {
        let down = DVec3::new(0.0, 0.0, -1.0);
        assert_eq!(
            ray_crossing(DVec3::new(0.25, 0.25, 1.0), down, A, B, C),
            Crossing::Hit(1.0)
        );
        assert_eq!(
            ray_crossing(DVec3::new(0.25, 0.25, -1.0), down, A, B, C),
            Crossing::Miss
        );
        assert_eq!(
            ray_crossing(DVec3::new(0.5, 0.5, 1.0), down, A, B, C),
            Crossing::Ambiguous,
            "through the hypotenuse"
        );
        assert_eq!(
            ray_crossing(DVec3::new(0.0, 0.0, 1.0), down, A, B, C),
            Crossing::Ambiguous,
            "through a vertex"
        );
        assert_eq!(
            ray_crossing(DVec3::new(-1.0, 0.2, 0.0), DVec3::X, A, B, C),
            Crossing::Ambiguous,
            "in the plane"
        );
        assert_eq!(
            ray_crossing(DVec3::new(-1.0, 0.2, 0.5), DVec3::X, A, B, C),
            Crossing::Miss,
            "parallel above"
        );
        assert_eq!(
            ray_crossing(DVec3::new(0.25, 0.25, 0.0), down, A, B, C),
            Crossing::Hit(0.0),
            "starts on it"
        );
    }

    #[test]
    fn winding_of_a_closed_tetrahedron() {
        let d = DVec3::Z;
        // Outward-facing (counter-clockwise seen from outside) faces.
        let faces = [(A, C, B), (A, B, d), (A, d, C), (B, C, d)];
        let w = |p: DVec3| -> f64 {
            faces
                .iter()
                .map(|&(a, b, c)| solid_angle_fraction(p, a, b, c))
                .sum()
        };
        assert!((w(DVec3::splat(0.1)) - 1.0).abs() < 1e-12);
        assert!(w(DVec3::splat(2.0)).abs() < 1e-12);
    }
}
