//! Mesh query benchmarks: what the haptic loop and the mesher ask of an imported triangle
//! mesh, on icospheres of 20,480 and 81,920 triangles, against brute force in the same run.
//!
//! Workloads, each reported as points per second by divan:
//! - `distance`, `inside`, `value_gradient`: 1,024 scattered points in [-1.2, 1.2]^3 (about
//!   half inside the unit sphere), through the hierarchy;
//! - `distance_brute_force`, `winding_number`: the same questions over every triangle
//!   (the peers), on the first 16 of those points;
//! - `near_surface_distance` and `near_surface_brute_force`: the haptic case, points within
//!   0.1 of the sphere (the scattered points pushed to radii 0.9 to 1.1). The scattered set is
//!   harder for the hierarchy: near the centre every triangle is about equally far, so little
//!   can be pruned;
//! - `ray_hit`: 1,024 rays from the points towards the origin;
//! - `build`: `TriMesh::new` (hierarchy, closedness, volume), per triangle.
//!
//! Run with `cargo bench -p model --bench mesh_query`.

use divan::Bencher;
use divan::counter::ItemsCount;
use glam::DVec3;
use model::mesh::geometry::closest_point_on_triangle;
use model::mesh::{TriMesh, shapes};

/// Icosphere subdivisions: 20 * 4^5 = 20,480 and 20 * 4^6 = 81,920 triangles.
const SUBDIVISIONS: &[u32] = &[5, 6];
const N_POINTS: usize = 1024;
const N_BRUTE_FORCE_POINTS: usize = 16;

fn main() {
    divan::main();
}

/// Deterministic scattered points in [-1.2, 1.2]^3 (xorshift).
fn points(n: usize) -> Vec<DVec3> {
    let mut rng = testkit::rng::XorShift64(0x2545_f491_4f6c_dd1d);
    let mut next = || rng.unit_f64() * 2.4 - 1.2;
    (0..n).map(|_| DVec3::new(next(), next(), next())).collect()
}

#[divan::bench(args = SUBDIVISIONS)]
fn distance(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = points(N_POINTS);
    bencher.counter(ItemsCount::new(N_POINTS)).bench_local(|| {
        for &p in &points {
            divan::black_box(mesh.distance(p));
        }
    });
}

#[divan::bench(args = SUBDIVISIONS)]
fn distance_brute_force(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = points(N_BRUTE_FORCE_POINTS);
    bencher
        .counter(ItemsCount::new(N_BRUTE_FORCE_POINTS))
        .bench_local(|| {
            for &p in &points {
                divan::black_box(brute_force_distance(&mesh, p));
            }
        });
}

/// The scattered points moved radially into the shell 0.9 <= |p| <= 1.1.
fn near_surface_points(n: usize) -> Vec<DVec3> {
    points(n)
        .into_iter()
        .enumerate()
        .map(|(i, p)| p.normalize() * (0.9 + 0.2 * (i as f64 / n as f64)))
        .collect()
}

#[divan::bench(args = SUBDIVISIONS)]
fn near_surface_distance(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = near_surface_points(N_POINTS);
    bencher.counter(ItemsCount::new(N_POINTS)).bench_local(|| {
        for &p in &points {
            divan::black_box(mesh.distance(p));
        }
    });
}

#[divan::bench(args = SUBDIVISIONS)]
fn near_surface_brute_force(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = near_surface_points(N_POINTS);
    bencher
        .counter(ItemsCount::new(N_BRUTE_FORCE_POINTS))
        .bench_local(|| {
            for &p in points.iter().step_by(N_POINTS / N_BRUTE_FORCE_POINTS) {
                divan::black_box(brute_force_distance(&mesh, p));
            }
        });
}

fn brute_force_distance(mesh: &TriMesh, p: DVec3) -> f64 {
    (0..mesh.triangles().len() as u32)
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            p.distance(closest_point_on_triangle(p, a, b, c))
        })
        .fold(f64::INFINITY, f64::min)
}

#[divan::bench(args = SUBDIVISIONS)]
fn inside(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = points(N_POINTS);
    bencher.counter(ItemsCount::new(N_POINTS)).bench_local(|| {
        for &p in &points {
            divan::black_box(mesh.inside(p));
        }
    });
}

#[divan::bench(args = SUBDIVISIONS)]
fn winding_number(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = points(N_BRUTE_FORCE_POINTS);
    bencher
        .counter(ItemsCount::new(N_BRUTE_FORCE_POINTS))
        .bench_local(|| {
            for &p in &points {
                divan::black_box(mesh.winding_number(p) > 0.5);
            }
        });
}

#[divan::bench(args = SUBDIVISIONS)]
fn value_gradient(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = points(N_POINTS);
    bencher.counter(ItemsCount::new(N_POINTS)).bench_local(|| {
        for &p in &points {
            divan::black_box(mesh.value_gradient(p));
        }
    });
}

#[divan::bench(args = SUBDIVISIONS)]
fn ray_hit(bencher: Bencher, subdivisions: u32) {
    let mesh = shapes::icosphere(1.0, subdivisions);
    let points = points(N_POINTS);
    bencher.counter(ItemsCount::new(N_POINTS)).bench_local(|| {
        for &p in &points {
            divan::black_box(mesh.ray_hit(p, -p, 1.0));
        }
    });
}

#[divan::bench(args = SUBDIVISIONS)]
fn build(bencher: Bencher, subdivisions: u32) {
    let (positions, triangles) = shapes::icosphere(1.0, subdivisions).into_parts();
    bencher
        .counter(ItemsCount::new(triangles.len()))
        .with_inputs(|| (positions.clone(), triangles.clone()))
        .bench_local_values(|(positions, triangles)| {
            TriMesh::new(positions, triangles).map(|m| m.is_closed())
        });
}
