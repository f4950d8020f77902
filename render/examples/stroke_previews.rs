//! A stroke's previews on an object with a long history, as the window sends them: the stroke
//! so far, every few poses, then the whole stroke at its release, each meshed by the mesher's
//! pool against the object's kept octree. Prints the worker's time (`Meshed::mesh_secs`) per
//! preview and per release, twice in the same run: as the pool meshes a stroke drawn further
//! (only around the stamps each preview adds), and with every preview made a new stroke (its
//! first pose moved by 1e-9, so the pool remeshes both strokes' boxes, as before it knew
//! continuations).
//!
//! `cargo run -p render --release --example stroke_previews` (`-- N` for another history
//! length).

use std::time::{Duration, Instant};

use glam::DVec3;
use model::object::{Edit, EditOp, Object, Pose, ToolShape, Transform};
use model::scene::ObjectId;
use render::mesher::{MIN_MESHER_THREADS, MeshJob, MeshKind, Mesher};

/// History length unless given.
const N_EDITS: usize = 10_000;
/// Octree depth (cells of 0.0195 units across the unit ball's box).
const DEPTH: u8 = 7;
/// The history's ball tools.
const HISTORY_TOOL_RADIUS: f64 = 0.04;
/// The stroke's ball tool (the window test's `tool: carve ball radius 0.05`).
const STROKE_TOOL_RADIUS: f64 = 0.05;
/// Poses per stroke, this far apart (the window keeps points a quarter radius apart).
const STROKE_POSES: usize = 40;
const POSE_SPACING: f64 = 0.015;
/// Poses added between previews (about what a drag adds in the window's 120 ms).
const POSES_PER_PREVIEW: usize = 4;
/// Strokes drawn, each from another point of the ball.
const N_STROKES: usize = 5;

#[allow(
    clippy::disallowed_methods,
    reason = "a benchmark program measures wall time"
)]
fn now() -> Instant {
    Instant::now()
}

/// Stroke `s` with its first `n` poses, along a great circle just under the surface.
fn stroke(s: usize, n: usize, nudge: f64) -> Edit {
    let start = 0.9 * s as f64;
    let mut path: Vec<Pose> = (0..n)
        .map(|k| {
            let t = start + k as f64 * POSE_SPACING;
            Pose::at(DVec3::new(t.cos(), 0.3 * t.sin(), t.sin()).normalize() * 0.98)
        })
        .collect();
    path[0].position.y += nudge;
    let tool = ToolShape::Sphere {
        radius: STROKE_TOOL_RADIUS,
    };
    Edit::stroke(EditOp::Subtract, tool, path)
}

/// Meshes `object` in the pool as object 1's job `generation`: the worker's seconds.
fn meshed(mesher: &Mesher, object: Object, generation: u64) -> (f64, MeshKind) {
    let job = Box::new(MeshJob {
        id: ObjectId(1),
        object,
        world_from_group: Transform::IDENTITY,
        generation,
        depth: DEPTH,
        requested_at: now(),
        t_secs: 0.0,
        coarse_first: false,
    });
    assert!(mesher.try_send(job).is_ok(), "the pool takes the job");
    let done = mesher
        .recv_timeout(Duration::from_secs(600))
        .expect("the pool meshes the job");
    (done.mesh_secs, done.kind)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let n_edits = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(N_EDITS);
    let ball = model::models::spiral_ball(n_edits, HISTORY_TOOL_RADIUS).expect("compiles");
    let mesher = Mesher::with_threads(MIN_MESHER_THREADS, now, || {}).expect("threads start");
    let (whole_secs, _) = meshed(&mesher, ball.clone(), 1);
    println!("{n_edits} edits, depth {DEPTH}: meshed whole in {whole_secs:.2} s");
    let mut generation = 1;
    for (label, nudged) in [("drawn further", false), ("each a new stroke", true)] {
        let (mut previews, mut releases) = (Vec::new(), Vec::new());
        for s in 0..N_STROKES {
            let sizes = (1..STROKE_POSES / POSES_PER_PREVIEW).map(|k| k * POSES_PER_PREVIEW);
            let sizes = sizes.chain([STROKE_POSES]);
            for (k, n) in sizes.enumerate() {
                let nudge = if nudged && k % 2 == 1 { 1e-9 } else { 0.0 };
                let mut object = ball.clone();
                object
                    .apply(stroke(s, n, nudge))
                    .expect("the stroke compiles");
                generation += 1;
                let (secs, kind) = meshed(&mesher, object, generation);
                assert_eq!(kind, MeshKind::Patch, "{label}: a patch");
                match n {
                    STROKE_POSES => releases.push(secs * 1e3),
                    _ => previews.push(secs * 1e3),
                }
            }
            // The stored stroke's mesh, then the ball again for the next stroke.
            generation += 1;
            meshed(&mesher, ball.clone(), generation);
        }
        let n = previews.len();
        println!(
            "{label}: preview median {:.1} ms (max {:.1}, {n} previews), release median {:.1} ms \
             (max {:.1}, {} releases)",
            median(previews.clone()),
            previews.iter().copied().fold(0.0, f64::max),
            median(releases.clone()),
            releases.iter().copied().fold(0.0, f64::max),
            releases.len()
        );
    }
}
