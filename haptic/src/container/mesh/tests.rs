//! Mesh containers against analytic answers: a cube and an icosphere, points inside, outside
//! and near edges and corners; nearest hits over the shared BVH against brute force. (The
//! forces a mesh sphere renders are compared with the closed-form sphere's in the force
//! renderer's tests.)

use glam::DVec3;

use super::ray::Hit;
use super::*;
use crate::container::properties::Scalar;

/// fdsl's reference cube `[center - half, center + half]`, 12 outward triangles.
fn cube_mesh(center: DVec3, half: f64) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    model::mesh::shapes::cube(center - DVec3::splat(half), center + DVec3::splat(half)).into_parts()
}

/// fdsl's reference icosphere of `radius` (`20 * 4^n` outward triangles) moved to `center`.
fn icosphere(center: DVec3, radius: f64, n_subdivisions: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let (mut vertices, triangles) =
        model::mesh::shapes::icosphere(radius, n_subdivisions).into_parts();
    for v in &mut vertices {
        *v = (glam::Vec3::from_array(*v) + center.as_vec3()).to_array();
    }
    (vertices, triangles)
}

/// A small deterministic generator (xorshift64*), uniform in `[lo, hi)`.
struct Rng(u64);

impl Rng {
    fn next(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        lo + (hi - lo) * (bits as f64 / (1u64 << 53) as f64)
    }

    fn vec(&mut self, lo: f64, hi: f64) -> DVec3 {
        DVec3::new(self.next(lo, hi), self.next(lo, hi), self.next(lo, hi))
    }
}

fn container(mesh: &(Vec<[f32; 3]>, Vec<[u32; 3]>)) -> MeshContainer {
    MeshContainer::new(
        1,
        &mesh.0,
        &mesh.1,
        &PropertySpec::default(),
        RayParams::default(),
    )
    .unwrap()
}

#[test]
fn bvh_nearest_hit_equals_brute_force() {
    let c = container(&icosphere(DVec3::new(0.1, -0.2, 0.3), 1.0, 3));
    assert_eq!(c.n_triangles(), 1280);
    let mut rng = Rng(7);
    let mut n_hits = 0;
    for _ in 0..2000 {
        let origin = rng.vec(-1.6, 1.6);
        let dir = rng.vec(-1.0, 1.0);
        let t_max = rng.next(0.1, 4.0);
        let brute = c
            .index
            .triangles()
            .iter()
            .enumerate()
            .filter_map(|(k, tri)| {
                tri.intersect(origin, dir, t_max).map(|t| Hit {
                    t,
                    tri_idx: k as u32,
                })
            })
            .min_by(|a, b| a.t.total_cmp(&b.t));
        let fast = c.index.nearest_hit(origin, dir, t_max);
        assert_eq!(fast.map(|h| h.t), brute.map(|h| h.t), "{origin} {dir}");
        n_hits += usize::from(fast.is_some());
    }
    assert!(n_hits > 300, "the rays hit something: {n_hits}");
}

/// Signed distance to the cube `[-1, 1]^3`, positive inside.
fn cube_depth(p: DVec3) -> f64 {
    let q = p.abs() - DVec3::ONE;
    let outside = q.max(DVec3::ZERO).length();
    if outside > 0.0 {
        -outside
    } else {
        -q.max_element()
    }
}

#[test]
fn cube_inside_outside_and_depth_match_the_analytic_cube() {
    let mut c = container(&cube_mesh(DVec3::ZERO, 1.0));
    let mut rng = Rng(11);
    let mut points: Vec<DVec3> = (0..3000).map(|_| rng.vec(-1.5, 1.5)).collect();
    // Near edges and corners, just inside and just outside.
    for s in [0.999, 1.001, 0.99, 1.01] {
        points.extend([
            DVec3::new(s, s, 0.3),
            DVec3::new(-s, 0.2, s),
            DVec3::new(0.0, -s, -s),
            DVec3::splat(s),
            DVec3::new(-s, s, -s),
        ]);
    }
    let mut n_inside = 0;
    for p in points {
        let truth = cube_depth(p);
        if truth.abs() < 1e-6 {
            continue;
        }
        let (f, grad) = c.value_grad(p, 0.0);
        assert_eq!(f >= 0.0, truth >= 0.0, "sign at {p}: {f} vs {truth}");
        if truth > 0.0 {
            n_inside += 1;
            // Inside a convex mesh the nearest hit plane is the nearest face.
            assert!((f - truth).abs() < 1e-6, "depth at {p}: {f} vs {truth}");
            assert!((grad.length() - 1.0).abs() < 1e-9);
            // The gradient points inward, away from the nearest face.
            let axis = p.abs().max_element();
            let face = DVec3::select(p.abs().cmpeq(DVec3::splat(axis)), p.signum(), DVec3::ZERO);
            assert!(grad.dot(face) < -0.99, "normal at {p}: {grad}");
        } else {
            // Outside, plane distances are lower bounds of the true distance.
            assert!(-f <= -truth + 1e-6, "distance at {p}: {f} vs {truth}");
        }
    }
    assert!(n_inside > 500);
    assert_eq!(
        c.ray_stats().n_refined,
        0,
        "a closed convex mesh never refines"
    );
}

#[test]
fn icosphere_inside_outside_and_depth_match_the_analytic_sphere() {
    let mut c = container(&icosphere(DVec3::ZERO, 1.0, 3));
    let mut rng = Rng(3);
    // Level 3 facets lie at most about 0.004 inside the unit sphere.
    let sagitta = 0.005;
    let mut n_checked = 0;
    for _ in 0..3000 {
        let p = rng.vec(-1.3, 1.3);
        let truth = 1.0 - p.length();
        if truth.abs() < sagitta {
            continue;
        }
        n_checked += 1;
        let (f, grad) = c.value_grad(p, 0.0);
        assert_eq!(f >= 0.0, truth >= 0.0, "sign at {p}: {f} vs {truth}");
        if truth > 0.0 {
            // Facet planes of a convex mesh are never nearer than its surface; the probe ray
            // along the best normal finds the nearest facet.
            assert!(f > truth - sagitta, "depth at {p}: {f} vs {truth}");
            let slack = if truth < 0.2 { 0.01 } else { 0.05 * truth };
            assert!(f < truth + slack, "depth at {p}: {f} vs {truth}");
            if truth < 0.5 {
                // Near the surface the plane's normal is the sphere's, within a facet.
                assert!(grad.dot(-p.normalize()) > 0.97, "normal at {p}: {grad}");
            }
        }
    }
    assert!(n_checked > 2500);
}

#[test]
fn overlapping_soup_refines_and_the_majority_decides() {
    // Two interpenetrating cubes as one triangle soup: inside the first but not the second,
    // rays toward the second enter it (they vote outside), the rest vote inside.
    let (mut vertices, mut triangles) = cube_mesh(DVec3::ZERO, 1.0);
    let (v2, t2) = cube_mesh(DVec3::new(1.5, 0.0, 0.0), 1.0);
    let offset = vertices.len() as u32;
    vertices.extend(v2);
    triangles.extend(t2.iter().map(|t| t.map(|i| i + offset)));
    let mut c = container(&(vertices, triangles));
    let (f, _) = c.value_grad(DVec3::new(-0.7, 0.1, 0.2), 0.0);
    assert!(f > 0.0, "inside the first cube: {f}");
    assert!(c.ray_stats().n_refined >= 1, "{:?}", c.ray_stats());
    assert!(c.value_grad(DVec3::new(-1.2, 0.0, 0.0), 0.0).0 < 0.0);
}

#[test]
fn outside_the_box_is_outside_without_rays_and_points_are_cached() {
    let mut c = container(&cube_mesh(DVec3::ZERO, 1.0));
    let (f, g) = c.value_grad(DVec3::new(3.0, 0.0, 0.0), 0.0);
    assert_eq!((f, g), (-2.0, DVec3::NEG_X));
    assert_eq!(c.ray_stats().n_rays, 0);
    let p = DVec3::new(0.2, 0.1, 0.0);
    let first = c.value_grad(p, 0.0);
    let rays = c.ray_stats().n_rays;
    assert!((12..=12 + PROBE_RAYS as u64).contains(&rays), "{rays}");
    assert_eq!(c.value_grad(p, 0.5), first);
    assert_eq!(c.ray_stats().n_rays, rays, "the second ask is cached");
}

#[test]
fn short_rays_see_nothing_deep_inside() {
    let mesh = cube_mesh(DVec3::ZERO, 1.0);
    let rays = RayParams {
        length_max: 0.5,
        ..RayParams::default()
    };
    let mut c = MeshContainer::new(1, &mesh.0, &mesh.1, &PropertySpec::default(), rays).unwrap();
    // Documented: a point no ray reaches is outside.
    assert!(c.value_grad(DVec3::ZERO, 0.0).0 < 0.0);
    assert!(c.value_grad(DVec3::new(0.8, 0.0, 0.0), 0.0).0 > 0.0);
}

#[test]
fn segment_crossing_is_one_ray() {
    let mut c = container(&cube_mesh(DVec3::ZERO, 1.0));
    let s = c
        .first_crossing(DVec3::new(2.0, 0.1, 0.2), DVec3::new(0.0, 0.1, 0.2), 0.0)
        .unwrap();
    assert!((s - 0.5).abs() < 1e-12);
    assert_eq!(
        c.first_crossing(DVec3::new(0.2, 0.0, 0.0), DVec3::new(0.3, 0.0, 0.0), 0.0),
        None
    );
}

#[test]
fn bad_meshes_are_errors() {
    let props = PropertySpec::default();
    let rays = RayParams::default();
    let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert_eq!(
        MeshContainer::new(1, &v, &[[0, 1, 3]], &props, rays).unwrap_err(),
        MeshError::IndexOutOfRange {
            triangle: 0,
            vertex: 3,
            n_vertices: 3
        }
    );
    let nan = [[0.0, f32::NAN, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert_eq!(
        MeshContainer::new(1, &nan, &[[0, 1, 2]], &props, rays).unwrap_err(),
        MeshError::NotFinite(0)
    );
    assert_eq!(
        MeshContainer::new(1, &v, &[[0, 1, 1]], &props, rays).unwrap_err(),
        MeshError::Empty
    );
    let none = RayParams {
        n_u: 0,
        ..RayParams::default()
    };
    assert!(matches!(
        MeshContainer::new(1, &v, &[[0, 1, 2]], &props, none),
        Err(MeshError::BadRays(_))
    ));
    let bad_prop = PropertySpec {
        density: Some(Scalar::Constant(f64::NAN)),
        ..PropertySpec::default()
    };
    assert!(matches!(
        MeshContainer::new(1, &v, &[[0, 1, 2]], &bad_prop, rays),
        Err(MeshError::Property(_))
    ));
}
