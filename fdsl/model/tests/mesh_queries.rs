//! `model::mesh` queries against analytic answers: a box, an icosphere and a torus (closed,
//! non-convex, genus one), inside and outside, exact distances, gradients, points aimed at
//! edges and vertices, ray hits, open and inside-out meshes; that the queries agree with brute
//! force and the winding number on random points; and that they never allocate.
#![allow(
    clippy::unwrap_used,
    reason = "test helpers unwrap what a test expects to succeed"
)]

use std::f64::consts::PI;

use glam::DVec3;
use model::mesh::geometry::closest_point_on_triangle;
use model::mesh::{TriMesh, shapes};
use proptest::prelude::*;
use testkit::alloc::{CountingAlloc, allocations_in as allocations};

#[global_allocator]
static ALLOCATOR: CountingAlloc = CountingAlloc;

/// The box [-1, 1]^3.
fn unit_box() -> TriMesh {
    shapes::cube(DVec3::splat(-1.0), DVec3::splat(1.0))
}

/// The F-Rep field of the box [-h, h]^3 (positive inside): minus the usual signed distance.
fn box_field(p: DVec3, h: f64) -> f64 {
    let q = p.abs() - DVec3::splat(h);
    -(q.max(DVec3::ZERO).length() + q.max_element().min(0.0))
}

/// A torus around the z axis: `n_major` x `n_minor` quads split in two, facing outwards.
fn torus(major: f64, minor: f64, n_major: u32, n_minor: u32) -> TriMesh {
    let mut positions = Vec::new();
    for i in 0..n_major {
        let u = 2.0 * PI * f64::from(i) / f64::from(n_major);
        for j in 0..n_minor {
            let v = 2.0 * PI * f64::from(j) / f64::from(n_minor);
            let r = major + minor * v.cos();
            positions.push([
                (r * u.cos()) as f32,
                (r * u.sin()) as f32,
                (minor * v.sin()) as f32,
            ]);
        }
    }
    let idx = |i: u32, j: u32| (i % n_major) * n_minor + (j % n_minor);
    let mut triangles = Vec::new();
    for i in 0..n_major {
        for j in 0..n_minor {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    let mesh = TriMesh::new(positions, triangles).unwrap();
    if mesh.signed_volume() > 0.0 {
        return mesh;
    }
    let (positions, triangles) = mesh.into_parts();
    let flipped = triangles.into_iter().map(|[a, b, c]| [a, c, b]).collect();
    TriMesh::new(positions, flipped).unwrap()
}

/// Deterministic points in the box of half-size `h` (xorshift).
fn scattered_points(n: usize, h: f64, seed: u64) -> Vec<DVec3> {
    let mut rng = testkit::rng::XorShift64(seed);
    let mut next = || rng.unit_f64() * 2.0 * h - h;
    (0..n).map(|_| DVec3::new(next(), next(), next())).collect()
}

fn brute_force_distance(mesh: &TriMesh, p: DVec3) -> f64 {
    (0..mesh.triangles().len() as u32)
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            p.distance(closest_point_on_triangle(p, a, b, c))
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn box_is_closed_with_the_right_volume_and_bounds() {
    let cube = unit_box();
    assert!(cube.is_closed());
    assert_eq!(cube.signed_volume(), 8.0);
    assert_eq!(cube.bounds().lo, DVec3::splat(-1.0));
    assert_eq!(cube.bounds().hi, DVec3::splat(1.0));
    assert!(!cube.is_empty());
}

#[test]
fn box_field_matches_the_analytic_box_on_a_grid() {
    let cube = unit_box();
    let mut n_inside = 0;
    // A 21^3 grid over [-2, 2]^3 with step 0.2 puts points on faces, edges and corners.
    for i in 0..21 {
        for j in 0..21 {
            for k in 0..21 {
                let p = DVec3::new(f64::from(i), f64::from(j), f64::from(k)) * 0.2 - 2.0;
                let want = box_field(p, 1.0);
                let got = cube.signed_distance(p);
                assert!((got - want).abs() < 1e-12, "{p}: {got} != {want}");
                if want.abs() > 1e-9 {
                    assert_eq!(cube.inside(p), want > 0.0, "{p}");
                    n_inside += usize::from(want > 0.0);
                }
                assert!((cube.distance(p) - want.abs()).abs() < 1e-12, "{p}");
            }
        }
    }
    assert_eq!(n_inside, 9 * 9 * 9);
}

#[test]
fn box_gradient_points_inwards() {
    let cube = unit_box();
    let cases = [
        // Outside a face, an edge and a corner: towards the nearest point.
        (DVec3::new(3.0, 0.2, -0.1), DVec3::new(-1.0, 0.0, 0.0)),
        (
            DVec3::new(2.0, 2.0, 0.5),
            DVec3::new(-1.0, -1.0, 0.0).normalize(),
        ),
        (DVec3::splat(-3.0), DVec3::ONE.normalize()),
        // Inside: away from the nearest face.
        (DVec3::new(0.1, 0.9, 0.0), DVec3::new(0.0, -1.0, 0.0)),
        (DVec3::new(0.0, 0.0, -0.7), DVec3::new(0.0, 0.0, 1.0)),
        // On a face: the inward normal.
        (DVec3::new(1.0, 0.25, 0.5), DVec3::new(-1.0, 0.0, 0.0)),
    ];
    for (p, want) in cases {
        let (value, gradient) = cube.value_gradient(p);
        assert!(gradient.distance(want) < 1e-12, "{p}: {gradient} != {want}");
        assert!((value - box_field(p, 1.0)).abs() < 1e-12, "{p}");
        assert_eq!(cube.gradient(p), gradient);
    }
}

#[test]
fn gradient_matches_finite_differences_on_the_torus() {
    let mesh = torus(1.0, 0.4, 48, 24);
    let h = 1e-6;
    let mut n_checked = 0;
    for p in scattered_points(400, 1.6, 7) {
        let (value, gradient) = mesh.value_gradient(p);
        if value.abs() < 0.01 {
            continue;
        }
        let fd = DVec3::new(
            mesh.signed_distance(p + DVec3::X * h) - mesh.signed_distance(p - DVec3::X * h),
            mesh.signed_distance(p + DVec3::Y * h) - mesh.signed_distance(p - DVec3::Y * h),
            mesh.signed_distance(p + DVec3::Z * h) - mesh.signed_distance(p - DVec3::Z * h),
        ) / (2.0 * h);
        // Points on the medial axis have no gradient; they are rare enough to skip.
        if (fd.length() - 1.0).abs() > 1e-3 {
            continue;
        }
        assert!(fd.distance(gradient) < 1e-4, "{p}: {gradient} vs {fd}");
        assert!((gradient.length() - 1.0).abs() < 1e-12);
        n_checked += 1;
    }
    assert!(n_checked > 300, "only {n_checked} points checked");
}

#[test]
fn icosphere_is_closed_and_between_its_two_spheres() {
    let radius = 2.0;
    let sphere = shapes::icosphere(radius, 3);
    assert_eq!(sphere.triangles().len(), 20 * 64);
    assert_eq!(sphere.positions().len(), 642);
    assert!(sphere.is_closed());
    // The largest face's inscribed radius bounds the mesh from inside.
    let inner = (0..sphere.triangles().len() as u32)
        .map(|t| {
            let [a, b, c] = sphere.corners(t);
            let n = (b - a).cross(c - a).normalize();
            n.dot(a).abs()
        })
        .fold(f64::INFINITY, f64::min);
    assert!(inner > 0.99 * radius && inner < radius);
    let volume = 4.0 / 3.0 * PI * radius.powi(3);
    assert!(sphere.signed_volume() < volume && sphere.signed_volume() > 0.98 * volume);
    let slack = 1e-6;
    for p in scattered_points(2000, 3.0, 11) {
        let rho = p.length();
        let d = sphere.distance(p);
        if rho > radius {
            assert!(
                d >= rho - radius - slack && d <= rho - inner + slack,
                "{p}: {d}"
            );
        } else if rho < inner {
            assert!(
                d >= inner - rho - slack && d <= radius - rho + slack,
                "{p}: {d}"
            );
        }
        if rho < inner - slack {
            assert!(sphere.inside(p), "{p}");
            assert!(sphere.signed_distance(p) > 0.0);
        } else if rho > radius + slack {
            assert!(!sphere.inside(p), "{p}");
            assert!(sphere.signed_distance(p) < 0.0);
        }
    }
}

#[test]
fn points_aimed_at_vertices_and_edges_are_classified_right() {
    // Points on lines through every vertex and every edge midpoint, in many directions: any
    // ray cast along such a line meets the surface exactly on an edge or a vertex.
    let sphere = shapes::icosphere(1.0, 2);
    let mut targets: Vec<DVec3> = sphere
        .positions()
        .iter()
        .map(|p| DVec3::from_array(p.map(f64::from)))
        .collect();
    for &[a, b, _] in sphere.triangles() {
        let (a, b) = (
            DVec3::from_array(sphere.positions()[a as usize].map(f64::from)),
            DVec3::from_array(sphere.positions()[b as usize].map(f64::from)),
        );
        targets.push((a + b) * 0.5);
    }
    let directions = [
        DVec3::X,
        DVec3::Y,
        DVec3::Z,
        DVec3::ONE.normalize(),
        DVec3::new(1.0, -1.0, 0.0).normalize(),
    ];
    let mut n_checked = 0;
    for target in &targets {
        for dir in directions {
            for s in [-1.5, -0.5, -0.1, 0.1, 0.5, 1.5] {
                let p = *target + dir * s;
                let rho = p.length();
                if rho < 0.9 {
                    assert!(sphere.inside(p), "{p} aimed at {target}");
                } else if rho > 1.0 + 1e-6 {
                    assert!(!sphere.inside(p), "{p} aimed at {target}");
                } else {
                    continue;
                }
                n_checked += 1;
            }
        }
    }
    assert!(n_checked > 5000, "{n_checked}");
    // Points a hair inside and outside a box's faces, edges and corners.
    let cube = unit_box();
    for (p, inside) in [
        (DVec3::new(1.0 - 1e-12, 1.0 - 1e-12, 0.0), true),
        (DVec3::new(1.0 - 1e-12, 1.0 - 1e-12, 1.0 - 1e-12), true),
        (DVec3::new(1.0 + 1e-12, 1.0, 0.3), false),
        (DVec3::new(-1.0 - 1e-12, -1.0 - 1e-12, -1.0 - 1e-12), false),
        (DVec3::new(0.0, 0.0, 1.0 - 1e-9), true),
        (DVec3::new(0.0, 0.0, 1.0 + 1e-9), false),
    ] {
        assert_eq!(cube.inside(p), inside, "{p}");
    }
}

#[test]
fn torus_inside_matches_its_analytic_shape() {
    let (major, minor) = (1.0, 0.4);
    let mesh = torus(major, minor, 64, 32);
    assert!(mesh.is_closed());
    // Faces are chords, inside the exact torus on its outer side and outside it next to the
    // hole; 0.01 is more than either gap at this resolution.
    let margin = 0.01;
    let mut n_inside = 0;
    for p in scattered_points(5000, 1.5, 3) {
        let tube = ((p.x * p.x + p.y * p.y).sqrt() - major).hypot(p.z);
        if tube < minor - margin {
            assert!(mesh.inside(p), "{p}");
            n_inside += 1;
        } else if tube > minor + margin {
            assert!(!mesh.inside(p), "{p}");
        }
    }
    assert!(n_inside > 300, "{n_inside}");
    // The hole of the torus is outside.
    assert!(!mesh.inside(DVec3::ZERO));
    assert!((mesh.signed_distance(DVec3::ZERO) + (major - minor)).abs() < 0.01);
}

#[test]
fn ray_hits_on_the_box_and_the_sphere() {
    let cube = unit_box();
    let hit = cube
        .ray_hit(DVec3::new(-5.0, 0.3, 0.2), DVec3::X, 100.0)
        .unwrap();
    assert_eq!(hit.t, 4.0);
    assert_eq!(hit.normal, DVec3::new(-1.0, 0.0, 0.0));
    let [a, b, c] = cube.corners(hit.triangle_idx);
    assert!(a.x == -1.0 && b.x == -1.0 && c.x == -1.0);
    // A direction that is not a unit vector scales t.
    let hit = cube
        .ray_hit(DVec3::new(-5.0, 0.3, 0.2), DVec3::X * 2.0, 100.0)
        .unwrap();
    assert_eq!(hit.t, 2.0);
    // From inside, the first hit is the exit.
    let hit = cube.ray_hit(DVec3::ZERO, DVec3::Y, 10.0).unwrap();
    assert_eq!((hit.t, hit.normal), (1.0, DVec3::Y));
    // Through an edge and through a corner: hit, on either triangle.
    let hit = cube
        .ray_hit(DVec3::new(-3.0, -3.0, 0.0), DVec3::new(1.0, 1.0, 0.0), 10.0)
        .unwrap();
    assert!((hit.t - 2.0).abs() < 1e-12);
    let hit = cube.ray_hit(DVec3::splat(3.0), -DVec3::ONE, 10.0).unwrap();
    assert!((hit.t - 2.0).abs() < 1e-12);
    // Misses: too short, pointing away, passing by, degenerate direction.
    assert!(
        cube.ray_hit(DVec3::new(-5.0, 0.3, 0.2), DVec3::X, 3.9)
            .is_none()
    );
    assert!(
        cube.ray_hit(DVec3::new(-5.0, 0.3, 0.2), -DVec3::X, 100.0)
            .is_none()
    );
    assert!(
        cube.ray_hit(DVec3::new(-5.0, 1.5, 0.2), DVec3::X, 100.0)
            .is_none()
    );
    assert!(cube.ray_hit(DVec3::ZERO, DVec3::ZERO, 100.0).is_none());
    assert!(cube.ray_hit(DVec3::NAN, DVec3::X, 100.0).is_none());

    let sphere = shapes::icosphere(1.0, 4);
    for dir in [DVec3::X, DVec3::new(0.3, -0.7, 0.2).normalize()] {
        let hit = sphere.ray_hit(-dir * 5.0, dir, 100.0).unwrap();
        assert!(hit.t > 4.0 - 1e-6 && hit.t < 4.0 + 2e-3, "{}", hit.t);
        assert!(hit.normal.dot(-dir) > 0.99);
    }
}

#[test]
fn closedness_needs_every_edge_twice_in_opposite_directions() {
    let (positions, triangles) = unit_box().into_parts();
    let rebuilt = |triangles: Vec<[u32; 3]>| TriMesh::new(positions.clone(), triangles).unwrap();
    assert!(rebuilt(triangles.clone()).is_closed());
    let mut missing = triangles.clone();
    missing.pop();
    assert!(!rebuilt(missing).is_closed());
    let mut flipped = triangles.clone();
    flipped[3] = [flipped[3][0], flipped[3][2], flipped[3][1]];
    assert!(!rebuilt(flipped).is_closed());
    let mut doubled = triangles.clone();
    doubled.push(triangles[0]);
    doubled.push([triangles[0][0], triangles[0][2], triangles[0][1]]);
    assert!(!rebuilt(doubled).is_closed());
    let mut degenerate = triangles.clone();
    degenerate.push([0, 0, 1]);
    assert!(!rebuilt(degenerate).is_closed());
    assert!(!TriMesh::new(vec![], vec![]).unwrap().is_closed());

    // The same box as a soup of 36 separate corners is open until welded.
    let soup: Vec<[f32; 3]> = triangles
        .iter()
        .flat_map(|t| t.map(|i| positions[i as usize]))
        .collect();
    let split = TriMesh::new(
        soup,
        (0..12).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect(),
    )
    .unwrap();
    assert!(!split.is_closed());
    let welded = split.welded();
    assert!(welded.is_closed());
    assert_eq!(welded.positions().len(), 8);
    assert_eq!(welded.triangles().len(), 12);
}

#[test]
fn inside_out_and_open_meshes() {
    let (positions, triangles) = unit_box().into_parts();
    let inverted = TriMesh::new(
        positions.clone(),
        triangles.iter().map(|&[a, b, c]| [a, c, b]).collect(),
    )
    .unwrap();
    assert!(inverted.is_closed());
    assert_eq!(inverted.signed_volume(), -8.0);
    // Parity does not care about orientation; the surface gradient does.
    assert_eq!(inverted.signed_distance(DVec3::splat(0.5)), 0.5);
    assert_eq!(
        inverted.gradient(DVec3::new(1.0, 0.25, 0.5)),
        DVec3::new(-1.0, 0.0, 0.0)
    );

    // A box missing one triangle: the majority of three rays still finds the inside.
    let mut open = triangles.clone();
    open.remove(0);
    let open = TriMesh::new(positions, open).unwrap();
    assert!(!open.is_closed());
    for p in [
        DVec3::ZERO,
        DVec3::new(0.5, 0.5, 0.5),
        DVec3::new(0.5, -0.2, 0.7),
    ] {
        assert!(open.inside(p), "{p}");
        assert!(open.signed_distance(p) > 0.0);
    }
    assert!(!open.inside(DVec3::splat(1.5)));

    let empty = TriMesh::new(vec![[0.0; 3]], vec![]).unwrap();
    assert!(empty.is_empty());
    assert_eq!(empty.distance(DVec3::ZERO), f64::INFINITY);
    assert!(!empty.inside(DVec3::ZERO));
    assert_eq!(
        empty.value_gradient(DVec3::ZERO),
        (f64::NEG_INFINITY, DVec3::ZERO)
    );
    assert!(empty.closest(DVec3::ZERO).is_none());
    assert!(unit_box().signed_distance(DVec3::NAN).is_nan());
}

#[test]
fn closest_within_respects_its_radius() {
    let cube = unit_box();
    let p = DVec3::new(3.0, 0.0, 0.0);
    assert!(cube.closest_within(p, 1.9).is_none());
    let c = cube.closest_within(p, 2.1).unwrap();
    assert_eq!((c.point, c.distance), (DVec3::new(1.0, 0.0, 0.0), 2.0));
}

#[test]
fn queries_do_not_allocate() {
    let sphere = shapes::icosphere(1.0, 4);
    let torus = torus(1.0, 0.4, 32, 16);
    let points = scattered_points(500, 1.5, 5);
    let mut sink = 0.0;
    let n = allocations(|| {
        for &p in &points {
            for mesh in [&sphere, &torus] {
                sink += mesh.signed_distance(p);
                sink += mesh.value_gradient(p).1.x;
                sink += f64::from(u8::from(mesh.inside(p)));
                sink += mesh.closest(p).map_or(0.0, |c| c.distance);
                sink += mesh.ray_hit(p, DVec3::Z, 10.0).map_or(0.0, |h| h.t);
            }
        }
    });
    assert_eq!(n, 0, "allocations in queries");
    assert!(sink.is_finite());
    // The counter works.
    assert!(allocations(|| drop(vec![1u8; 10])) > 0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn distance_equals_brute_force(x in -3.0..3.0f64, y in -3.0..3.0f64, z in -3.0..3.0f64) {
        let p = DVec3::new(x, y, z);
        for mesh in [torus(1.0, 0.4, 16, 8), shapes::icosphere(1.5, 2)] {
            prop_assert_eq!(mesh.distance(p), brute_force_distance(&mesh, p));
        }
    }

    #[test]
    fn inside_agrees_with_the_winding_number(
        x in -1.6..1.6f64, y in -1.6..1.6f64, z in -0.6..0.6f64,
    ) {
        let p = DVec3::new(x, y, z);
        let mesh = torus(1.0, 0.4, 24, 12);
        let w = mesh.winding_number(p);
        prop_assert!(w.abs() < 1e-9 || (w - 1.0).abs() < 1e-9, "winding {}", w);
        if mesh.distance(p) > 1e-9 {
            prop_assert_eq!(mesh.inside(p), w > 0.5);
        }
    }
}
