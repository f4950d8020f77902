//! [`TapeField`]: an fdsl tape as a [`Field`] for the meshers, with interval pruning and
//! sign-preserving tape simplification per octree box (the mesher reads every grid value from
//! one block only, so neighbouring blocks evaluated with different tapes still agree).

use fdsl::Tape;
use fdsl::eval::{BulkEval, GradBulkEval, Interval, IntervalEval};
use fdsl::tape::Fidelity;

use super::field::Field;

/// A compiled fdsl function sampled at a fixed time `t`.
#[derive(Clone, Debug)]
pub struct TapeField {
    bulk: BulkEval,
    interval: IntervalEval,
    grad: GradBulkEval,
    grad_scratch: Vec<fdsl::eval::Grad<f32>>,
    t: f32,
}

impl TapeField {
    /// A field for the first output of `tape` at time `t`.
    pub fn new(tape: &Tape, t: f32) -> TapeField {
        TapeField {
            bulk: BulkEval::new(tape),
            interval: IntervalEval::new(tape),
            grad: GradBulkEval::new(tape),
            grad_scratch: Vec::new(),
            t,
        }
    }

    /// The tape this field evaluates.
    pub fn tape(&self) -> &Tape {
        self.bulk.tape()
    }

    fn bounds(&mut self, lo: [f32; 3], hi: [f32; 3]) -> Interval {
        let i = |k: usize| Interval::new(lo[k] as f64, hi[k] as f64);
        self.interval
            .eval([i(0), i(1), i(2), Interval::point(self.t as f64)])
    }
}

/// Rounds an f64 bound outwards to f32, so the f32 range still encloses every value.
pub(crate) fn outward(lo: f64, hi: f64) -> (f32, f32) {
    let mut l = lo as f32;
    if l as f64 > lo {
        l = l.next_down();
    }
    let mut h = hi as f32;
    if (h as f64) < hi {
        h = h.next_up();
    }
    (l, h)
}

impl Field for TapeField {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let b = self.bounds(lo, hi);
        if b.has_nan() {
            (f32::NAN, f32::NAN)
        } else {
            outward(b.lo, b.hi)
        }
    }

    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        self.bulk.eval(xs, ys, zs, self.t, out);
    }

    fn gradients(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [[f32; 3]]) {
        self.grad_scratch.resize(xs.len(), Default::default());
        self.grad.eval(xs, ys, zs, self.t, &mut self.grad_scratch);
        for (o, g) in out.iter_mut().zip(&self.grad_scratch) {
            *o = g.gradient();
        }
    }

    fn fork(&self) -> Option<Self> {
        Some(self.clone())
    }

    fn simplify(&mut self, lo: [f32; 3], hi: [f32; 3]) -> Option<Self> {
        self.bounds(lo, hi);
        let tape = self
            .tape()
            .simplify(self.interval.choices(), Fidelity::Sign);
        (tape.len() < self.tape().len()).then(|| TapeField::new(&tape, self.t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Aabb;
    use crate::mesh::octree::{MeshSettings, OctreeMesher, mesh_with_stats};

    /// Stated depths for the mesh checks: 2^6 and 2^7 cells along each axis of [-1.2, 1.2]^3.
    const DEPTHS: [u8; 2] = [6, 7];

    fn settings(depth: u8) -> MeshSettings {
        MeshSettings {
            bounds: Aabb::new([-1.2; 3], [1.2; 3]),
            depth,
        }
    }

    /// One test per model, so that the harness runs them in parallel.
    macro_rules! model_meshes_watertight_and_manifold {
        ($($test:ident: $name:literal),* $(,)?) => {$(
            #[test]
            fn $test() {
                let src = fdsl::models::reference_model($name).unwrap();
                for depth in DEPTHS {
                    check_model($name, src, depth);
                }
            }
        )*};
    }

    model_meshes_watertight_and_manifold! {
        sphere_meshes_watertight_and_manifold: "sphere",
        spheres100_meshes_watertight_and_manifold: "spheres100",
        spheres100_rfunc_meshes_watertight_and_manifold: "spheres100_rfunc",
        gyroid_sphere_meshes_watertight_and_manifold: "gyroid_sphere",
        watermelon_meshes_watertight_and_manifold: "watermelon",
        watermelon_rfunc_meshes_watertight_and_manifold: "watermelon_rfunc",
    }

    /// Meshes a model at `depth` and checks it is closed, manifold, consistently wound and,
    /// for distance-like fields, on the surface.
    fn check_model(name: &str, src: &str, depth: u8) {
        let tape = fdsl::Function::parse(src).unwrap().tape();
        let mut field = TapeField::new(&tape, 0.0);
        let (mesh, stats) = mesh_with_stats(&mut field, &settings(depth)).unwrap();
        assert!(!mesh.indices.is_empty(), "{name}: empty mesh");
        // The same on several threads, bit for bit (each subtree's tape simplified again, or
        // forked where it does not simplify).
        let mut parallel = OctreeMesher::new(&settings(depth)).unwrap();
        let bounds = settings(depth).bounds;
        let on_threads =
            (parallel.remesh_parallel(&mut TapeField::new(&tape, 0.0), bounds, 3)).unwrap();
        assert_eq!(on_threads, stats, "{name} at depth {depth} on threads");
        assert!(
            parallel.mesh().unwrap() == mesh,
            "{name} at depth {depth} on threads"
        );
        assert_eq!(mesh.validate(), Ok(()));
        assert_eq!(mesh.open_edges(), 0, "{name} at depth {depth}: open edges");
        assert_eq!(
            mesh.non_manifold_edges(),
            0,
            "{name} at depth {depth}: non-manifold edges"
        );
        assert_eq!(
            mesh.misoriented_edges(),
            0,
            "{name} at depth {depth}: inconsistent winding"
        );
        assert_eq!(mesh.degenerate_triangles(), 0, "{name}: degenerate");
        assert!(mesh.signed_volume() > 0.0, "{name}: normals face inwards");
        assert!(stats.nodes_pruned > 0, "{name}: nothing pruned");
        if name != "sphere" {
            assert!(
                stats.fields_simplified > 0,
                "{name}: no tape was simplified"
            );
        }
        if name.starts_with("gyroid") {
            // The gyroid's thin sheets make tunnels through cells: the split path must run.
            assert!(stats.patches_split > 0, "{name}: {stats:?}");
        }
        if name.ends_with("rfunc") || depth > DEPTHS[0] {
            // R-function values are not distances: f/|grad f| is no measure there. One depth
            // is enough for the distances (the test runs unoptimised).
            return;
        }
        // Vertices lie on the surface to within a fraction of a cell.
        let cell = 2.4 / (1u32 << depth) as f64;
        let mut point = fdsl::eval::GradEval::new(&tape);
        for p in mesh.positions.iter().step_by(7) {
            let g = point.eval([p[0] as f64, p[1] as f64, p[2] as f64, 0.0]);
            let norm = (g.dx * g.dx + g.dy * g.dy + g.dz * g.dz).sqrt().max(1e-9);
            let distance = g.v.abs() / norm;
            assert!(
                distance < cell,
                "{name}: vertex {p:?} is {distance} from the surface"
            );
        }
    }

    /// Remeshing the box of a local edit gives the same surface as meshing the edited
    /// function from scratch: same triangle and vertex counts, closed and manifold.
    #[test]
    fn remesh_after_an_edit_matches_a_full_mesh_of_the_edited_function() {
        let base = fdsl::models::reference_model("watermelon").unwrap().trim();
        // A ball of radius 0.3 added at (0.75, 0.2, -0.1), and a gyroid carved near it.
        let edits = [
            format!("({base}) | (0.3-sqrt((x-0.75)^2+(y-0.2)^2+(z+0.1)^2))"),
            format!(
                "({base}) \\ ((0.35-sqrt((x-0.75)^2+(y-0.2)^2+(z+0.1)^2)) & \
                 (0.05-abs(sin(12*x)*cos(12*y)+sin(12*y)*cos(12*z)+sin(12*z)*cos(12*x))/12))"
            ),
        ];
        let dirty = Aabb::new([0.35, -0.25, -0.55], [1.15, 0.65, 0.35]);
        for depth in DEPTHS {
            let settings = settings(depth);
            let mut mesher = OctreeMesher::new(&settings).unwrap();
            let tape = fdsl::Function::parse(base).unwrap().tape();
            mesher
                .remesh(&mut TapeField::new(&tape, 0.0), settings.bounds)
                .unwrap();
            for edited in &edits {
                let tape = fdsl::Function::parse(edited).unwrap().tape();
                let stats = mesher
                    .remesh(&mut TapeField::new(&tape, 0.0), dirty)
                    .unwrap();
                let remeshed = mesher.mesh().unwrap();
                let (full, full_stats) =
                    mesh_with_stats(&mut TapeField::new(&tape, 0.0), &settings).unwrap();
                assert!(
                    stats.blocks_evaluated < full_stats.blocks_evaluated,
                    "{stats:?} vs {full_stats:?}"
                );
                for m in [&remeshed, &full] {
                    assert_eq!(m.open_edges(), 0, "depth {depth}: {edited}");
                    assert_eq!(m.non_manifold_edges(), 0, "depth {depth}: {edited}");
                    assert_eq!(m.misoriented_edges(), 0, "depth {depth}: {edited}");
                }
                assert_eq!(remeshed.n_triangles(), full.n_triangles(), "{edited}");
                assert_eq!(remeshed.n_vertices(), full.n_vertices(), "{edited}");
                let volume = (remeshed.signed_volume(), full.signed_volume());
                assert!((volume.0 - volume.1).abs() < 1e-4, "{volume:?}");
            }
        }
    }

    #[test]
    fn interval_bounds_round_outwards() {
        let (l, h) = outward(0.1, 0.1);
        assert!((l as f64) <= 0.1 && (h as f64) >= 0.1 && l < h);
    }
}
