//! One edit remeshed on objects with long histories: the time `OctreeMesher::remesh` takes for
//! the edit's boxes (the stroke's blocks evaluated again, every node above them visited from
//! the root), on render's `remesh_object` workload (the unit ball carved along a golden-angle
//! spiral, ball tools of radius 0.04) with 10^3, 10^4 and 10^5 edits at depth 7.
//!
//! Each length's whole mesh is also timed on every core (`OctreeMesher::remesh_parallel`), in
//! the same run, and checked to be the same mesh.
//!
//! `cargo run -p render --release --example remesh_history` (`-- N...` for other lengths).

use render::mesh::object_field::{Dirty, dirty_boxes};
use render::mesh::octree::{MeshSettings, OctreeMesher};
use render::mesh::{Aabb, ObjectField};

/// History lengths measured unless given.
const LENGTHS: [usize; 3] = [1_000, 10_000, 100_000];
/// Octree depth (cells of 0.0195 units; the tool is 4 cells across).
const DEPTH: u8 = 7;
/// Edits remeshed per length.
const N_EDITS_TIMED: usize = 21;
/// Radius of the ball tool.
const TOOL_RADIUS: f64 = 0.04;

#[allow(
    clippy::disallowed_methods,
    reason = "a benchmark program measures wall time"
)]
fn now() -> std::time::Instant {
    std::time::Instant::now()
}

fn main() {
    let lengths: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let lengths = if lengths.is_empty() {
        LENGTHS.to_vec()
    } else {
        lengths
    };
    let settings = MeshSettings {
        bounds: Aabb::new([-1.25; 3], [1.25; 3]),
        depth: DEPTH,
    };
    for n in lengths {
        let mut object = model::models::spiral_ball(n, TOOL_RADIUS).expect("the workload compiles");
        let mut mesher = OctreeMesher::new(&settings).expect("valid settings");
        let started = now();
        mesher
            .remesh(&mut ObjectField::new(&object, 0.0), settings.bounds)
            .expect("meshes");
        let full = started.elapsed();
        // The same whole mesh on every core, in the same run.
        let n_threads = std::thread::available_parallelism().map_or(1, usize::from);
        let mut parallel = OctreeMesher::new(&settings).expect("valid settings");
        let started = now();
        parallel
            .remesh_parallel(
                &mut ObjectField::new(&object, 0.0),
                settings.bounds,
                n_threads,
            )
            .expect("meshes");
        let full_parallel = started.elapsed();
        let same = parallel.mesh().ok() == mesher.mesh().ok();
        let mut times = Vec::new();
        let mut blocks = Vec::new();
        for k in 1..=N_EDITS_TIMED {
            let idx = object
                .apply(model::models::spiral_edit(k * 104_729, n, 1.5, TOOL_RADIUS))
                .expect("valid edit");
            object.prepare();
            let mut field = ObjectField::new(&object, 0.0);
            let Dirty::Boxes(boxes) = dirty_boxes(&object.history().entries()[idx].edit) else {
                continue;
            };
            let started = now();
            let mut evaluated = 0;
            for b in boxes {
                evaluated += mesher
                    .remesh(&mut field, b)
                    .map_or(0, |s| s.blocks_evaluated);
            }
            times.push(started.elapsed().as_secs_f64() * 1e3);
            blocks.push(evaluated);
        }
        times.sort_by(f64::total_cmp);
        blocks.sort_unstable();
        println!(
            "{n} edits, depth {DEPTH}: full mesh {:.2} s, on {n_threads} threads {:.2} s \
             ({:.2} times as fast, {}); one edit's remesh median {:.2} ms \
             (fastest {:.2}, slowest {:.2}), {} blocks evaluated (median)",
            full.as_secs_f64(),
            full_parallel.as_secs_f64(),
            full.as_secs_f64() / full_parallel.as_secs_f64(),
            if same {
                "the same mesh"
            } else {
                "ANOTHER MESH"
            },
            times[times.len() / 2],
            times[0],
            times[times.len() - 1],
            blocks[blocks.len() / 2]
        );
    }
}
