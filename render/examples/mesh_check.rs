//! Meshes every reference model and prints triangle, open-edge and non-manifold-edge counts.
//!
//! Run with `cargo run -p render --release --example mesh_check -- 6 7`.

use render::mesh::octree::{MeshSettings, mesh_with_stats};
use render::mesh::{Aabb, TapeField};

/// A [`TapeField`] that never simplifies, to tell simplification defects from others.
struct Plain(TapeField);

impl render::mesh::Field for Plain {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        self.0.interval(lo, hi)
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        self.0.values(xs, ys, zs, out)
    }
    fn gradients(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [[f32; 3]]) {
        self.0.gradients(xs, ys, zs, out)
    }
}

fn main() {
    let plain = std::env::args().any(|a| a == "--plain");
    let depths: Vec<u8> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    for depth in if depths.is_empty() {
        vec![6, 7]
    } else {
        depths
    } {
        for (name, src) in fdsl::models::surface_models() {
            let Ok(function) = fdsl::Function::parse(src) else {
                println!("{name}: does not parse");
                continue;
            };
            let mut field = TapeField::new(&function.tape(), 0.0);
            let settings = MeshSettings {
                bounds: Aabb::new([-1.2; 3], [1.2; 3]),
                depth,
            };
            let result = if plain {
                mesh_with_stats(&mut Plain(field), &settings)
            } else {
                mesh_with_stats(&mut field, &settings)
            };
            match result {
                Ok((m, stats)) => println!(
                    "depth {depth} {name:18} triangles {:8} open {:4} non-manifold {:4} misoriented {:4} volume {:.4} {stats:?}",
                    m.n_triangles(),
                    m.open_edges(),
                    m.non_manifold_edges(),
                    m.misoriented_edges(),
                    m.signed_volume()
                ),
                Err(e) => println!("{name}: {e}"),
            }
        }
    }
}
