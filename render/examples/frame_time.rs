//! Frame-time benchmark: a scene of about 10^6 triangles rendered offscreen, camera orbiting.
//!
//! Run with `cargo run -p render --release --example frame_time -- --frames 20`.
//! Options: `--frames N` (default 20), `--width W --height H` (default 1280 x 720),
//! `--depth D` (mesher depth for the gyroid ball, default 8: about 1.2 million triangles).
//! Each frame is `Headless::render`: it creates the colour and depth targets, draws, copies
//! the picture back and waits for it, so it is the whole cost of one offscreen frame. The
//! meshes are uploaded once, before the first timed frame. Prints the median, fastest and
//! slowest frame and the adapter.
//!
//! Then the same number of frames into one picture kept between frames, as the window keeps
//! it (`Headless::render_kept`), in turns: one with the camera turned (everything drawn) and
//! one with only the crosshair moved, as when a peer's tool moves (the lines drawn over the
//! kept objects). Last, the time of a pick (`Scene::pick`, what every drag and hover frame
//! of the window asks) along a row of pixels across the picture, and of the first pick of a
//! new mesh (which makes the boxes picks look through).

use glam::{Mat4, Vec3};
use render::camera::Camera;
use render::gpu::KeptFrame;
use render::gpu::offscreen::Headless;
use render::mesh::octree::{MeshSettings, mesh};
use render::mesh::{Aabb, TapeField};
use render::scene::{Material, Scene};
use std::sync::Arc;
use std::time::Duration;

/// Reads the one clock this example uses.
#[allow(
    clippy::disallowed_methods,
    reason = "a benchmark program measures wall time"
)]
fn now() -> std::time::Instant {
    std::time::Instant::now()
}

fn arg(name: &str, default: u32) -> u32 {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let (frames, width, height) = (
        arg("--frames", 20),
        arg("--width", 1280),
        arg("--height", 720),
    );
    let depth = u8::try_from(arg("--depth", 8)).unwrap_or(8);
    let tape = fdsl::Function::parse(include_str!("../../tests/data/models/gyroid_sphere.fdsl"))
        .expect("the model compiles")
        .tape();
    let started = now();
    let mut m = mesh(
        &mut TapeField::new(&tape, 0.0),
        &MeshSettings {
            bounds: Aabb::new([-1.2; 3], [1.2; 3]),
            depth,
        },
    )
    .expect("meshes");
    println!(
        "meshed gyroid_sphere at depth {depth}: {} triangles, {} vertices in {:.2?}",
        m.n_triangles(),
        m.n_vertices(),
        started.elapsed()
    );
    m.colour_with(|p| [0.5 + 0.4 * p[0], 0.5 + 0.4 * p[1], 0.5 + 0.4 * p[2], 1.0]);
    let mut scene = Scene {
        camera: Camera {
            distance: 3.2,
            ..Camera::default()
        },
        ..Scene::default()
    };
    scene.add_object(Arc::new(m), Mat4::IDENTITY, Material::default());
    scene.add_box(Aabb::new([-1.0; 3], [1.0; 3]), [1.0; 4]);
    scene.add_crosshair(Vec3::ZERO, 0.2, [1.0, 1.0, 0.0, 1.0]);

    let mut gpu = match Headless::new() {
        Ok(g) => g,
        Err(e) => {
            println!("no GPU adapter: {e}");
            return;
        }
    };
    println!("adapter: {}", gpu.adapter_description());
    let first = now();
    if let Err(e) = gpu.render(&scene, width, height) {
        println!("render failed: {e}");
        return;
    }
    println!("first frame (uploads the mesh): {:.2?}", first.elapsed());
    let mut times: Vec<Duration> = Vec::with_capacity(frames as usize);
    for k in 0..frames {
        scene.camera.yaw = 0.6 + 0.05 * k as f32;
        let t0 = now();
        if let Err(e) = gpu.render(&scene, width, height) {
            println!("render failed: {e}");
            return;
        }
        times.push(t0.elapsed());
    }
    report(&format!("{frames} frames at {width}x{height}"), times);
    kept_frames(&mut gpu, &mut scene, frames, [width, height]);
    picks(&scene, [width, height]);
    // Fifteen copies more, out of the rays' way above the picture: a pick meets their boxes.
    let ball = scene.objects[0].clone();
    for k in 0..15 {
        let mut copy = ball.clone();
        copy.world_from_object = Mat4::from_translation(Vec3::new(3.0 * k as f32 - 21.0, 0.0, 6.0));
        scene.objects.push(copy);
    }
    print!("16 objects, 1 under the rays: ");
    picks(&scene, [width, height]);
}

/// Times picks through 40 pixels along the middle row of a `size` picture, and the first
/// pick of objects whose meshes are new (which makes their `PickRuns`).
fn picks(scene: &Scene, size: [u32; 2]) {
    const N_PICKS: u32 = 40;
    let ray = |i: u32| {
        let px = [
            size[0] as f32 * (0.2 + 0.6 * i as f32 / N_PICKS as f32),
            size[1] as f32 / 2.0,
        ];
        scene.camera.ray_through_pixel(px, size)
    };
    let mut fresh = scene.clone();
    for o in &mut fresh.objects {
        o.pick_runs = Default::default();
    }
    let t0 = now();
    fresh.pick(&ray(0));
    let first = t0.elapsed();
    // The objects as given hold runs made once, as a window's objects do between meshes.
    scene.pick(&ray(0));
    let mut n_hits = 0;
    let t0 = now();
    for i in 0..N_PICKS {
        n_hits += u32::from(scene.pick(&ray(i)).is_some());
    }
    println!(
        "a pick: {:.2?} ({n_hits} of {N_PICKS} rays hit); the first of new meshes {first:.2?}",
        t0.elapsed() / N_PICKS
    );
}

/// Times `frames` pairs of frames into a kept picture: the camera turned, then the crosshair
/// alone moved.
fn kept_frames(gpu: &mut Headless, scene: &mut Scene, frames: u32, [width, height]: [u32; 2]) {
    let mut picture = match gpu.kept_picture(width, height) {
        Ok(p) => p,
        Err(e) => return println!("no kept picture: {e}"),
    };
    let mut times = [Vec::new(), Vec::new()];
    for k in 0..frames {
        for (moved, times) in times.iter_mut().enumerate() {
            if moved == 0 {
                scene.camera.yaw = 0.6 + 0.05 * k as f32;
            } else {
                scene.lines.truncate(scene.lines.len().saturating_sub(3));
                let at = Vec3::new(0.1 * (k as f32).sin(), 0.1 * (k as f32).cos(), 0.0);
                scene.add_crosshair(at, 0.2, [1.0, 1.0, 0.0, 1.0]);
            }
            let t0 = now();
            let expected = [KeptFrame::Whole, KeptFrame::LinesOnly][moved];
            match gpu.render_kept(scene, &mut picture) {
                Ok((_, kept)) if kept == expected => times.push(t0.elapsed()),
                Ok((_, kept)) => return println!("kept frame {kept:?}, not {expected:?}"),
                Err(e) => return println!("render failed: {e}"),
            }
        }
    }
    let [turned, moved] = times;
    report("kept picture, camera turned", turned);
    report("kept picture, crosshair moved", moved);
}

/// Prints the median, fastest and slowest of `times`.
fn report(what: &str, mut times: Vec<Duration>) {
    times.sort_unstable();
    if let (Some(fastest), Some(slowest)) = (times.first(), times.last()) {
        println!(
            "{what}: median {:.1?}, fastest {fastest:.1?}, slowest {slowest:.1?}",
            times[times.len() / 2]
        );
    }
}
