//! Benchmark `mesh_octree`: dual contouring of closed-form fields through the `Field` trait.
//!
//! Run with `cargo bench -p render --bench mesh_octree`. The same workloads will be meshed by
//! `fidget`'s mesher once `fdsl` implements `Field` over its tapes.

use render::mesh::octree::{MeshSettings, OctreeMesher, mesh};
use render::mesh::{Aabb, Field};

fn main() {
    divan::main();
}

/// Union (max) of spheres `(centre, radius)`, f >= 0 inside.
struct Spheres(Vec<([f32; 3], f32)>);

impl Field for Spheres {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        self.0
            .iter()
            .fold((f32::NEG_INFINITY, f32::NEG_INFINITY), |acc, (c, r)| {
                let near: f32 = (0..3)
                    .map(|a| (c[a].clamp(lo[a], hi[a]) - c[a]).powi(2))
                    .sum();
                let far: f32 = (0..3)
                    .map(|a| (c[a] - lo[a]).abs().max((hi[a] - c[a]).abs()).powi(2))
                    .sum();
                (acc.0.max(r - far.sqrt()), acc.1.max(r - near.sqrt()))
            })
    }

    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.0.iter().fold(f32::NEG_INFINITY, |m, (c, r)| {
                let d = ((xs[i] - c[0]).powi(2) + (ys[i] - c[1]).powi(2) + (zs[i] - c[2]).powi(2))
                    .sqrt();
                m.max(r - d)
            });
        }
    }
}

fn settings(depth: u8) -> MeshSettings {
    MeshSettings {
        bounds: Aabb::new([-1.0; 3], [1.0; 3]),
        depth,
    }
}

#[divan::bench(args = [5, 6, 7])]
fn sphere(depth: u8) -> usize {
    let mut field = Spheres(vec![([0.0; 3], 0.8)]);
    mesh(&mut field, &settings(depth)).map_or(0, |m| m.n_triangles())
}

#[divan::bench(args = [6, 7])]
fn union_of_eight_spheres(depth: u8) -> usize {
    let parts = (0..8)
        .map(|k| {
            (
                [k & 1, k >> 1 & 1, k >> 2 & 1].map(|b| if b == 1 { 0.4 } else { -0.4 }),
                0.35,
            )
        })
        .collect();
    mesh(&mut Spheres(parts), &settings(depth)).map_or(0, |m| m.n_triangles())
}

/// Remeshing the box of one small edit on a mesh already built.
#[divan::bench(args = [6, 7])]
fn remesh_edit(bencher: divan::Bencher, depth: u8) {
    let base = vec![([0.0; 3], 0.7)];
    let mut mesher = OctreeMesher::new(&settings(depth)).expect("valid settings");
    let _ = mesher.remesh(&mut Spheres(base.clone()), settings(depth).bounds);
    let mut edited = base;
    edited.push(([0.7, 0.0, 0.0], 0.1));
    let edit = Aabb::new([0.6, -0.1, -0.1], [0.8, 0.1, 0.1]);
    bencher.bench_local(|| {
        let _ = mesher.remesh(&mut Spheres(edited.clone()), edit);
        mesher.mesh().map_or(0, |m| m.n_triangles())
    });
}
