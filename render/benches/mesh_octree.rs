//! Benchmark `mesh_octree`: dual contouring through the `Field` trait, on closed-form fields
//! and on the reference models against `fidget`'s mesher at equal depth.
//!
//! Run with `cargo bench -p render --bench mesh_octree`; `-- reference_models` runs only the
//! comparison with fidget. Before the benchmarks it prints, per model and depth, the
//! triangle counts and the open and non-manifold edges of both meshers' output.
//!
//! `-- reference_models_on_every_core` meshes the same models at depth 7 on every core (ours
//! through `mesh_on_threads`, fidget's on rayon's global pool).
//!
//! Otherwise both meshers run on one thread over [-1.2, 1.2]^3 with 2^depth cells along each axis:
//! ours as [`TapeField`] over an fdsl tape, fidget's `Octree::build` + `walk_dual` on the same
//! function converted by `fdsl/benches/fidget_peer.rs` (negated: fidget's inside is negative)
//! and scaled by 1.2, since fidget meshes [-1, 1]^3.

use divan::Bencher;
use fidget::context::Tree;
use fidget::shape::Shape;
use render::mesh::octree::{MeshSettings, OctreeMesher, mesh, mesh_on_threads};
use render::mesh::{Aabb, Field, Mesh, TapeField};

#[path = "../../fdsl/benches/fidget_peer.rs"]
#[allow(dead_code, reason = "shared with fdsl's benches, which use more of it")]
mod fidget_peer;

fn main() {
    print_triangle_counts();
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
fn remesh_edit(bencher: Bencher, depth: u8) {
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

/// Half the side of the meshed cube.
const HALF_SIDE: f32 = 1.2;

/// Model `name`'s source text.
fn source(name: &str) -> &'static str {
    fdsl::models::reference_model(name).expect("a reference model")
}

fn tape(name: &str) -> fdsl::Tape {
    fdsl::Function::parse(source(name))
        .expect("reference models compile")
        .tape()
}

fn ours(name: &str, depth: u8) -> Mesh {
    let settings = MeshSettings {
        bounds: Aabb::new([-HALF_SIDE; 3], [HALF_SIDE; 3]),
        depth,
    };
    mesh(&mut TapeField::new(&tape(name), 0.0), &settings).expect("meshes")
}

/// fidget's shape for model `name`, stretched from [-1.2, 1.2]^3 onto its [-1, 1]^3.
fn peer_shape<F: fidget::eval::MathFunction>(name: &str) -> Shape<F> {
    let (ctx, root) = fidget_peer::to_fidget(&tape(name));
    let tree = ctx.export(root).expect("a node of this context");
    let s = HALF_SIDE;
    Shape::from(tree.remap_xyz(Tree::x() * s, Tree::y() * s, Tree::z() * s))
}

fn peer<F>(shape: &Shape<F>, depth: u8) -> fidget::mesh::Mesh
where
    F: fidget::eval::Function + fidget::eval::MathFunction + fidget::render::RenderHints + Clone,
{
    peer_on(shape, depth, None)
}

/// [`peer`] on `threads` (`None`: this thread).
fn peer_on<F>(
    shape: &Shape<F>,
    depth: u8,
    threads: Option<&fidget::render::ThreadPool>,
) -> fidget::mesh::Mesh
where
    F: fidget::eval::Function + fidget::eval::MathFunction + fidget::render::RenderHints + Clone,
{
    let bound = shape.clone().try_into().expect("no variables but x, y, z");
    let settings = fidget::mesh::Settings {
        depth,
        threads,
        ..Default::default()
    };
    fidget::mesh::Octree::build(&bound, &settings)
        .expect("not cancelled")
        .walk_dual()
}

/// Times our mesh of model `name` at `depth` on `threads` (one: [`mesh`]'s own path).
fn bench_ours(bencher: Bencher, (name, depth): (&str, u8), threads: usize) {
    let tape = tape(name);
    let settings = MeshSettings {
        bounds: Aabb::new([-HALF_SIDE; 3], [HALF_SIDE; 3]),
        depth,
    };
    bencher.bench_local(|| {
        let field = &mut TapeField::new(&tape, 0.0);
        let (m, _) = mesh_on_threads(field, &settings, threads).expect("meshes");
        m.n_triangles()
    });
}

/// fidget's mesh in our type (scaled back to [-1.2, 1.2]^3), for the edge checks.
fn to_mesh(m: &fidget::mesh::Mesh) -> Mesh {
    Mesh {
        positions: m
            .vertices
            .iter()
            .map(|v| [v.x, v.y, v.z].map(|c| c * HALF_SIDE))
            .collect(),
        indices: m
            .triangles
            .iter()
            .flat_map(|t| [t.x, t.y, t.z].map(|i| u32::try_from(i).unwrap_or(u32::MAX)))
            .collect(),
        ..Mesh::default()
    }
}

fn print_triangle_counts() {
    // Under `cargo test` benches run once as tests: skip the table there.
    if std::env::args().any(|a| a == "--test") {
        return;
    }
    println!(
        "model              depth  triangles ours (open, non-manifold)  fidget (open, non-manifold)"
    );
    for depth in [6u8, 7] {
        for (name, _) in fdsl::models::surface_models() {
            let a = ours(name, depth);
            let b = to_mesh(&peer(&peer_shape::<fidget::vm::VmFunction>(name), depth));
            println!(
                "{name:18} {depth:5}  {:>9} ({}, {})  {:>9} ({}, {})",
                a.n_triangles(),
                a.open_edges(),
                a.non_manifold_edges(),
                b.n_triangles(),
                b.open_edges(),
                b.non_manifold_edges()
            );
        }
    }
}

mod reference_models {
    use super::*;

    /// Every surface model at depths 6 and 7.
    fn args() -> impl Iterator<Item = (&'static str, u8)> {
        [6, 7]
            .into_iter()
            .flat_map(|depth| fdsl::models::surface_models().map(move |(name, _)| (name, depth)))
    }

    #[divan::bench(args = args(), sample_count = 5, sample_size = 1)]
    fn render(bencher: Bencher, arg: (&str, u8)) {
        bench_ours(bencher, arg, 1);
    }

    #[divan::bench(args = args(), sample_count = 5, sample_size = 1)]
    fn fidget_vm(bencher: Bencher, arg: (&str, u8)) {
        let (name, depth) = arg;
        let shape = peer_shape::<fidget::vm::VmFunction>(name);
        bencher.bench_local(|| peer(&shape, depth).triangles.len());
    }

    // fidget's JIT is left out: its mesher compiles every simplified tape, which took 10.9 to
    // 17.1 s for gyroid_sphere at depth 6 (5 samples), about 100 times its VM; the VM is the
    // fairer peer for meshing, as for fdsl's pruned-octree benchmark.
}

/// The same models meshed on every core: ours through `mesh_on_threads` (subtrees in waves,
/// the same mesh as on one thread), fidget's VM on rayon's global pool (a thread per core).
mod reference_models_on_every_core {
    use super::*;

    fn args() -> impl Iterator<Item = (&'static str, u8)> {
        fdsl::models::surface_models().map(|(name, _)| (name, 7))
    }

    fn cores() -> usize {
        std::thread::available_parallelism().map_or(1, usize::from)
    }

    #[divan::bench(args = args(), sample_count = 5, sample_size = 1)]
    fn render(bencher: Bencher, arg: (&str, u8)) {
        bench_ours(bencher, arg, cores());
    }

    #[divan::bench(args = args(), sample_count = 5, sample_size = 1)]
    fn fidget_vm(bencher: Bencher, arg: (&str, u8)) {
        let (name, depth) = arg;
        let shape = peer_shape::<fidget::vm::VmFunction>(name);
        let pool = fidget::render::ThreadPool::Global;
        bencher.bench_local(|| peer_on(&shape, depth, Some(&pool)).triangles.len());
    }
}
