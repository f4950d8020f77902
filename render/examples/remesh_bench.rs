//! Stroke released to pixels updated, as the window does it, for an object with 10^4 edits at
//! octree depths 7 and 8: the incremental path of [`render::mesher::Mesher`] (what the window
//! meshes with) against the whole remesh the window did before it, in the same run.
//!
//! The object is render's `remesh_object` benchmark object: the unit ball (in a 2.2-unit
//! domain) carved by 10^4 edits spread over its surface along a golden-angle spiral (ball
//! tools of radius 0.04, every second edit a short stroke, every fifth adding instead of
//! carving). Each measured step is one more stroke (at a new place), as an op released in the
//! window leaves the object.
//!
//! - incremental: a `Mesher` with one worker (the window's has two to four) is handed the
//!   object; the worker remeshes the stroke's boxes, patches the last mesh and recolours the
//!   vertices written; the patch goes to the renderer (`Renderer::patch_object`) and a frame
//!   is drawn and read back (`Headless::render`: prepare, draw, copy to the CPU).
//! - whole: what the window did before: `render::snapshot::build` of a one-object scene
//!   (octree mesh of everything, appearance), the new mesh uploaded whole and the same frame
//!   drawn and read back.
//!
//! The clock starts when the edited object is handed over and stops when the frame's pixels
//! are back. Medians are printed per depth, with the ratio whole / incremental, and the part
//! of each spent meshing and colouring (the worker's own time; `snapshot::build`).
//!
//! `cargo run -p render --release --example remesh_bench` (`-- --quick` for 10^3 edits and
//! fewer samples). With no wgpu adapter it says so and exits non-zero.

use std::time::{Duration, Instant};

use model::object::Transform;
use model::object::{Edit, Object};
use model::scene::ObjectId;
use render::camera::Camera;
use render::gpu::offscreen::Headless;
use render::mesher::{MeshJob, MeshKind, Meshed, Mesher};
use render::scene::Scene;
use render::snapshot::{SnapshotSettings, build};

/// Why the benchmark stopped.
type Error = Box<dyn std::error::Error>;

/// Edits in the object before the benchmark adds strokes.
const N_EDITS: usize = 10_000;
/// Radius of the ball tool.
const TOOL_RADIUS: f64 = 0.04;
/// Depths measured.
const DEPTHS: [u8; 2] = [7, 8];
/// Strokes measured per depth on the incremental path.
const N_INCREMENTAL: usize = 21;
/// Strokes measured per depth with the whole remesh.
const N_WHOLE: usize = 5;
/// The frame drawn after each stroke.
const FRAME_PX: [u32; 2] = [640, 480];
/// Longest wait for one mesh.
const MESH_WAIT_SECS: u64 = 600;

/// Reads the one clock this benchmark uses.
#[allow(
    clippy::disallowed_methods,
    reason = "a benchmark program measures wall time"
)]
fn now() -> Instant {
    Instant::now()
}

fn main() -> Result<(), Error> {
    let quick = std::env::args().any(|a| a == "--quick");
    let (n_edits, n_incremental, n_whole) = if quick {
        (N_EDITS / 10, 5, 2)
    } else {
        (N_EDITS, N_INCREMENTAL, N_WHOLE)
    };
    let mut gpu =
        Headless::new().map_err(|e| format!("no wgpu adapter: pixels cannot be measured ({e})"))?;
    println!("device: {}", gpu.adapter_description());
    let started = now();
    let base = object(n_edits)?;
    println!(
        "object: unit ball with {} edits, built in {:.1?}",
        base.history().len(),
        started.elapsed()
    );
    for depth in DEPTHS {
        let mut object = base.clone();
        let mut next_stroke = 0;
        let mut stroke = |object: &mut Object| -> Result<(), Error> {
            next_stroke += 1;
            object.apply(spiral_edit(next_stroke * 7919, n_edits, 0.5))?;
            Ok(())
        };

        // The window's incremental path: the first mesh is whole, then one patch per stroke.
        let mesher = Mesher::with_threads(1, now, || {})?;
        let mut scene = Scene {
            camera: Camera {
                distance: 3.2,
                ..Camera::default()
            },
            ..Scene::default()
        };
        let mut generation = 0;
        let mut incremental_ms = Vec::new();
        let mut incremental_mesh_ms = Vec::new();
        let mut first = None;
        let (mut n_patched, mut n_triangles_written, mut n_triangles) = (0, Vec::new(), 0);
        for k in 0..=n_incremental {
            if k > 0 {
                stroke(&mut object)?;
            }
            generation += 1;
            let t0 = now();
            let done = mesh_with(&mesher, &object, depth, generation)?;
            let drawn = done.object.ok_or("the object has no mesh")?;
            if let Some((base, patch)) = &done.patch {
                gpu.renderer_mut()
                    .patch_object(0, base, &drawn.mesh, patch)?;
                n_triangles_written.push(patch.n_triangles_written());
            }
            n_patched += usize::from(done.kind == MeshKind::Patch);
            n_triangles = drawn.mesh.n_triangles();
            scene.objects.clear();
            scene.objects.push(drawn);
            gpu.render(&scene, FRAME_PX[0], FRAME_PX[1])?;
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            if k == 0 {
                first = Some(ms);
            } else {
                incremental_ms.push(ms);
                incremental_mesh_ms.push(done.mesh_secs * 1e3);
            }
        }
        if n_patched != n_incremental {
            return Err(format!("only {n_patched} of {n_incremental} strokes were patched").into());
        }
        n_triangles_written.sort_unstable();

        // Today's path: each stroke meshed whole through `snapshot::build`, uploaded whole.
        let mut whole_gpu = Headless::new()?;
        let mut whole_ms = Vec::new();
        let mut whole_mesh_ms = Vec::new();
        for _ in 0..n_whole {
            stroke(&mut object)?;
            let t0 = now();
            let mut one = model::scene::Scene::new();
            let mut o = object.clone();
            o.prepare();
            one.insert_object(ObjectId(1), o, None)?;
            let built = build(
                &one,
                &SnapshotSettings {
                    depth,
                    ..SnapshotSettings::default()
                },
            )?;
            whole_mesh_ms.push(t0.elapsed().as_secs_f64() * 1e3);
            let Some(drawn) = built.scene.objects.into_iter().next() else {
                return Err("the whole mesh is empty".into());
            };
            scene.objects.clear();
            scene.objects.push(drawn);
            whole_gpu.render(&scene, FRAME_PX[0], FRAME_PX[1])?;
            whole_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        let (inc, whole) = (median(&mut incremental_ms), median(&mut whole_ms));
        let (inc_mesh, whole_mesh) = (median(&mut incremental_mesh_ms), median(&mut whole_mesh_ms));
        println!(
            "depth {depth}: {n_triangles} triangles; first mesh (whole, with patch state) {:.0} ms",
            first.unwrap_or(0.0)
        );
        println!(
            "  stroke released -> pixels, medians: incremental {inc:.1} ms (of {n_incremental}, \
             {} triangles written), whole {whole:.1} ms (of {n_whole}); whole / incremental {:.1}",
            n_triangles_written
                .get(n_triangles_written.len() / 2)
                .copied()
                .unwrap_or(0),
            whole / inc
        );
        println!(
            "  of which meshed and coloured (worker / snapshot::build): incremental {inc_mesh:.1} ms, \
             whole {whole_mesh:.1} ms; the rest is handing over, upload, draw and read-back"
        );
    }
    Ok(())
}

/// Hands `object` to the mesher and waits for its result.
fn mesh_with(
    mesher: &Mesher,
    object: &Object,
    depth: u8,
    generation: u64,
) -> Result<Meshed, Error> {
    let job = Box::new(MeshJob {
        id: ObjectId(1),
        object: object.clone(),
        world_from_group: Transform::IDENTITY,
        generation,
        depth,
        requested_at: now(),
        t_secs: 0.0,
        coarse_first: false,
    });
    if mesher.try_send(job).is_err() {
        return Err("the mesher's queue is full".into());
    }
    let done = mesher
        .recv_timeout(Duration::from_secs(MESH_WAIT_SECS))
        .ok_or("no mesh in time")?;
    if done.generation != generation {
        return Err("a result of another job".into());
    }
    if let Some(reason) = &done.skipped {
        return Err(format!("not meshed: {reason}").into());
    }
    Ok(done)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Edit `k` of the spiral render's `remesh_object` benchmark sculpts
/// ([`model::models::spiral_edit`]).
fn spiral_edit(k: usize, n: usize, phase: f64) -> Edit {
    model::models::spiral_edit(k, n, phase, TOOL_RADIUS)
}

fn object(n_edits: usize) -> Result<Object, Error> {
    Ok(model::models::spiral_ball(n_edits, TOOL_RADIUS)?)
}
