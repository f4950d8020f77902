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
//! [-1.25, 1.25]^3 through [`ObjectField`] (model's `Sampler` restricted to each octree node's
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
//!
//! The printed breakdown also uploads each edit's mesh to a headless wgpu device (as
//! `render::gpu::offscreen` makes it: Vulkan on llvmpipe here) with two renderers on one
//! scene: one handed each edit's patch (`Renderer::patch_object`, so `prepare` writes only the
//! patch's ranges) and one not (`prepare` uploads the new mesh whole). It times `prepare`
//! followed by an empty submit and a wait for the device (so the copies are done) and counts
//! the bytes each wrote.

use divan::Bencher;
use model::object::{Edit, Object};
use render::gpu::Renderer;
use render::mesh::object_field::{Dirty, dirty_boxes};
use render::mesh::octree::{MeshSettings, OctreeMesher, mesh};
use render::mesh::{Aabb, Mesh, ObjectField};
use render::scene::{Material, Scene};
use std::sync::Arc;

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

/// Edit `k` of the shared spiral workload ([`model::models::spiral_edit`]).
fn edit(k: usize, n: usize, phase: f64) -> Edit {
    model::models::spiral_edit(k, n, phase, TOOL_RADIUS)
}

fn object() -> Object {
    model::models::spiral_ball(N_EDITS, TOOL_RADIUS).expect("the workload compiles")
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

/// A headless device as `render::gpu::offscreen::Headless` makes it, or `None` without an
/// adapter.
fn device() -> Option<(wgpu::Device, wgpu::Queue)> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter =
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .ok()?;
    println!("device: {:?}", adapter.get_info().name);
    pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("remesh_object bench"),
        required_limits: wgpu::Limits::downlevel_defaults(),
        ..Default::default()
    }))
    .ok()
}

/// Two renderers on one device drawing `scene`: the first is handed patches, the second
/// uploads each new mesh whole.
struct Uploads {
    device: wgpu::Device,
    queue: wgpu::Queue,
    patched: Renderer,
    whole: Renderer,
}

impl Uploads {
    fn new() -> Option<Self> {
        let (device, queue) = device()?;
        let renderer = || {
            Renderer::new(
                &device,
                &queue,
                wgpu::TextureFormat::Rgba8UnormSrgb,
                Some(wgpu::TextureFormat::Depth32Float),
            )
        };
        let (patched, whole) = (renderer(), renderer());
        Some(Self {
            device,
            queue,
            patched,
            whole,
        })
    }

    /// Prepares `scene` with `renderer` and waits for the device; returns milliseconds and
    /// bytes written.
    fn prepare(&mut self, patched: bool, scene: &Scene) -> (f64, u64) {
        let renderer = if patched {
            &mut self.patched
        } else {
            &mut self.whole
        };
        let started = now();
        renderer
            .prepare(&self.device, &self.queue, scene, [640, 480])
            .expect("a valid mesh");
        self.queue.submit([]);
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("the device finishes");
        (
            started.elapsed().as_secs_f64() * 1e3,
            renderer.mesh_bytes_uploaded(),
        )
    }
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
        let first_patch = mesher.mesh_update(&mut patched).expect("assembles");
        println!(
            "  first patch (the whole mesh and its layout): {:.1?}",
            started.elapsed()
        );
        let mut current = Arc::new(patched);
        let mut scene = Scene::default();
        scene.add_object(
            Arc::clone(&current),
            glam::Mat4::IDENTITY,
            Material::default(),
        );
        let mut uploads = Uploads::new();
        if let Some(u) = uploads.as_mut() {
            let empty = Arc::new(Mesh::default());
            u.patched
                .patch_object(0, &empty, &current, &first_patch)
                .expect("a patch of this mesh");
            u.prepare(true, &scene);
            u.prepare(false, &scene);
        } else {
            println!("  no wgpu adapter: uploads not measured");
        }
        // Per edit: milliseconds and bytes of the patched and of the whole upload.
        let mut gpu_steps: Vec<[f64; 4]> = Vec::new();
        // Median over 21 edits of each step.
        let mut steps: Vec<[f64; 5]> = Vec::new();
        let mut n_blocks = Vec::new();
        let (mut written, mut n_full) = (Vec::new(), 0);
        for k in 1..=21 {
            // The renderers hold `current`: the patch goes into a copy (not timed).
            let mut patched = Mesh::clone(&current);
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
            let next = Arc::new(patched);
            if let Some(u) = uploads.as_mut() {
                u.patched
                    .patch_object(0, &current, &next, &patch)
                    .expect("a patch of the uploaded mesh");
                scene.objects[0].mesh = Arc::clone(&next);
                let (patched_ms, patched_bytes) = u.prepare(true, &scene);
                let (whole_ms, whole_bytes) = u.prepare(false, &scene);
                gpu_steps.push([
                    patched_ms,
                    patched_bytes as f64,
                    whole_ms,
                    whole_bytes as f64,
                ]);
            }
            current = next;
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
        if !gpu_steps.is_empty() {
            let gpu_median = |i: usize| {
                let mut v: Vec<f64> = gpu_steps.iter().map(|s| s[i]).collect();
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let (patched_ms, whole_ms) = (gpu_median(0), gpu_median(2));
            println!(
                "  upload, medians of 21 (prepare + device wait): patched {patched_ms:.3} ms, {:.0} bytes; whole {whole_ms:.3} ms, {:.0} bytes; whole / patched: {:.1} in time, {:.0} in bytes",
                gpu_median(1),
                gpu_median(3),
                whole_ms / patched_ms,
                gpu_median(3) / gpu_median(1),
            );
        }
    }
}
