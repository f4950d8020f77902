//! Benchmark `remesh_object`: the latency of "edit applied -> mesh updated" on an object-model
//! object with 10^4 edits, against meshing the whole object from scratch at the same depth.
//!
//! Run with `cargo bench -p render --bench remesh_object`. Before the benchmarks it prints the
//! object, the mesh sizes and, per depth, one edit's latency split into its steps, with the
//! whole assembly and the patched one timed on the same remeshed state.
//!
//! The object is the unit ball (in a 2.2-unit domain) carved by 10^4 edits spread over its
//! surface along a golden-angle spiral: ball tools of radius 0.04, every second edit a short
//! stroke of two poses, every fifth edit adding instead of carving. Meshing is over
//! [-1.25, 1.25]^3 through [`ObjectField`] (fdsl's `Sampler` restricted to each octree node's
//! box, `BoxSampler`, which folds a block's edits over all its points at once).
//!
//! - `edit_to_mesh`: one more edit (at a new place each iteration): `Object::apply`,
//!   `Object::prepare`, a new `ObjectField` (the sampler's snapshot of the object), remesh of
//!   the edit's boxes (`OctreeMesher::remesh`), then `OctreeMesher::mesh` (the whole mesh
//!   assembled again, as the renderer needs it). The history grows by one edit per iteration.
//! - `edit_to_patched_mesh`: the same, but `OctreeMesher::mesh_update` patches the previous
//!   mesh instead: only the changed blocks' vertices and the triangles that read them are
//!   written (now and then, when unreferenced vertices pile up, the whole mesh is assembled).
//! - `full_mesh`: meshing the same object from scratch (`mesh`) at the same depth.

use divan::Bencher;
use fdsl::object::{Domain, Edit, EditOp, Formula, Geometry, Object, ObjectData, Pose, ToolShape};
use glam::DVec3;
use render::mesh::object_field::{Dirty, dirty_boxes};
use render::mesh::octree::{MeshSettings, OctreeMesher, mesh};
use render::mesh::{Aabb, Mesh, ObjectField};

/// Edits in the object before the benchmark adds more.
const N_EDITS: usize = 10_000;
/// Radius of the ball tool.
const TOOL_RADIUS: f64 = 0.04;
/// Depths benchmarked: cells of 0.0195 and 0.0098 units (the tool is 4 and 8 cells across).
const DEPTHS: [u8; 2] = [7, 8];

fn main() {
    print_breakdown();
    divan::main();
}

/// Edit `k` of a spiral of `n` over the unit sphere, turned by `phase` radians.
fn edit(k: usize, n: usize, phase: f64) -> Edit {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let y = 1.0 - 2.0 * ((k % n) as f64 + 0.5) / n as f64;
    let ring = (1.0 - y * y).max(0.0).sqrt();
    let phi = golden * k as f64 + phase;
    let at = DVec3::new(ring * phi.cos(), y, ring * phi.sin());
    let op = if k % 5 == 4 {
        EditOp::Union
    } else {
        EditOp::Subtract
    };
    let tool = ToolShape::Sphere {
        radius: TOOL_RADIUS,
    };
    if k.is_multiple_of(2) {
        Edit::stamp(op, tool, Pose::at(at))
    } else {
        let side = at.any_orthonormal_vector() * 0.03;
        Edit::stroke(op, tool, vec![Pose::at(at - side), Pose::at(at + side)])
    }
}

fn object() -> Object {
    let mut object = Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new("1-sqrt(x^2+y^2+z^2)").expect("short formula"),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    })
    .expect("the ball compiles");
    for k in 0..N_EDITS {
        object.apply(edit(k, N_EDITS, 0.0)).expect("valid edit");
    }
    object.prepare();
    object
}

fn settings(depth: u8) -> MeshSettings {
    MeshSettings {
        bounds: Aabb::new([-1.25; 3], [1.25; 3]),
        depth,
    }
}

/// A mesher holding the full mesh of `object` at `depth`.
fn meshed(object: &Object, depth: u8) -> OctreeMesher {
    let mut mesher = OctreeMesher::new(&settings(depth)).expect("valid settings");
    mesher
        .remesh(&mut ObjectField::new(object, 0.0), settings(depth).bounds)
        .expect("meshes");
    mesher
}

/// Applies edit `k` of the added spiral and remeshes its boxes; returns blocks evaluated.
fn apply_and_remesh(object: &mut Object, mesher: &mut OctreeMesher, k: usize, depth: u8) -> usize {
    let idx = object
        .apply(edit(k * 7919, N_EDITS, 0.5))
        .expect("valid edit");
    object.prepare();
    let mut field = ObjectField::new(object, 0.0);
    let dirty = dirty_boxes(&object.history().entries()[idx].edit);
    let boxes = match dirty {
        Dirty::Boxes(boxes) => boxes,
        Dirty::Everywhere => vec![settings(depth).bounds],
    };
    boxes
        .iter()
        .map(|b| {
            mesher
                .remesh(&mut field, *b)
                .map_or(0, |s| s.blocks_evaluated)
        })
        .sum()
}

#[divan::bench(args = DEPTHS, sample_count = 20, sample_size = 5)]
fn edit_to_mesh(bencher: Bencher, depth: u8) {
    let mut object = object();
    let mut mesher = meshed(&object, depth);
    let mut k = 0;
    bencher.bench_local(|| {
        k += 1;
        apply_and_remesh(&mut object, &mut mesher, k, depth);
        mesher.mesh().map_or(0, |m| m.n_triangles())
    });
}

#[divan::bench(args = DEPTHS, sample_count = 20, sample_size = 5)]
fn edit_to_patched_mesh(bencher: Bencher, depth: u8) {
    let mut object = object();
    let mut mesher = meshed(&object, depth);
    let mut patched = Mesh::default();
    mesher.mesh_update(&mut patched).expect("assembles");
    let mut k = 0;
    bencher.bench_local(|| {
        k += 1;
        apply_and_remesh(&mut object, &mut mesher, k, depth);
        mesher
            .mesh_update(&mut patched)
            .map_or(0, |p| p.n_triangles)
    });
}

#[divan::bench(args = DEPTHS, sample_count = 5, sample_size = 1)]
fn full_mesh(bencher: Bencher, depth: u8) {
    let object = object();
    bencher.bench_local(|| {
        mesh(&mut ObjectField::new(&object, 0.0), &settings(depth)).map_or(0, |m| m.n_triangles())
    });
}

/// Reads the clock for the printed breakdown.
#[allow(
    clippy::disallowed_methods,
    reason = "a benchmark program measures wall time"
)]
fn now() -> std::time::Instant {
    std::time::Instant::now()
}

fn print_breakdown() {
    // Under `cargo test` benches run once as tests: skip the breakdown there.
    if std::env::args().any(|a| a == "--test") {
        return;
    }
    let started = now();
    let mut object = object();
    println!(
        "object: unit ball with {} edits, built and indexed in {:.1?}",
        object.history().len(),
        started.elapsed()
    );
    for depth in DEPTHS {
        let started = now();
        let mut mesher = meshed(&object, depth);
        let full = started.elapsed();
        let m = mesher.mesh().expect("assembles");
        println!(
            "depth {depth}: full mesh {full:.1?}, {} triangles, {} vertices, {} open and {} non-manifold edges",
            m.n_triangles(),
            m.n_vertices(),
            m.open_edges(),
            m.non_manifold_edges()
        );
        let started = now();
        let mut patched = Mesh::default();
        mesher.mesh_update(&mut patched).expect("assembles");
        println!(
            "  first patch (the whole mesh and its layout): {:.1?}",
            started.elapsed()
        );
        // Median over 21 edits of each step.
        let mut steps: Vec<[f64; 5]> = Vec::new();
        let mut n_blocks = Vec::new();
        let (mut written, mut n_full) = (Vec::new(), 0);
        for k in 1..=21 {
            let t0 = now();
            let idx = object
                .apply(edit(k * 104_729, N_EDITS, 1.5))
                .expect("valid edit");
            object.prepare();
            let t1 = now();
            let mut field = ObjectField::new(&object, 0.0);
            let t2 = now();
            let mut blocks = 0;
            if let Dirty::Boxes(boxes) = dirty_boxes(&object.history().entries()[idx].edit) {
                for b in boxes {
                    blocks += mesher
                        .remesh(&mut field, b)
                        .map_or(0, |s| s.blocks_evaluated);
                }
            }
            let t3 = now();
            let n = mesher.mesh().map_or(0, |m| m.n_triangles());
            let t4 = now();
            let patch = mesher.mesh_update(&mut patched).expect("patches");
            let t5 = now();
            assert!(n > 0 && patch.n_triangles == n);
            n_full += usize::from(patch.full);
            written.push((
                patch.n_triangles_written(),
                patch.n_vertices_written(),
                patch.triangle_ranges.len(),
                patch.vertex_ranges.len(),
            ));
            n_blocks.push(blocks);
            steps
                .push([t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4].map(|d| d.as_secs_f64() * 1e3));
        }
        let median = |i: usize| {
            let mut v: Vec<f64> = steps.iter().map(|s| s[i]).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        n_blocks.sort_unstable();
        written.sort_unstable();
        let (triangles_written, vertices_written, triangle_ranges, vertex_ranges) =
            written[written.len() / 2];
        println!(
            "  one edit, medians of 21 (ms): apply+prepare {:.3}, sampler snapshot {:.3}, remesh {:.3} ({} blocks evaluated), assemble mesh {:.3}, patch mesh {:.3} ({} triangles in {} ranges and {} vertices in {} ranges written, {} of 21 patches whole)",
            median(0),
            median(1),
            median(2),
            n_blocks[n_blocks.len() / 2],
            median(3),
            median(4),
            triangles_written,
            triangle_ranges,
            vertices_written,
            vertex_ranges,
            n_full
        );
    }
}
