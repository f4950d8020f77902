//! The mesher's tests: patches against whole meshes and colourings, the choice of path,
//! superseded jobs, and the pool's scheduling.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use glam::DVec3;
use model::object::{
    ColorDef, ColorMap, Domain, Edit, EditOp, Formula, Geometry, Object, ObjectData, PaintValue,
    Paintable, Pose, ToolShape, Transform,
};
use model::scene::ObjectId;

use super::incremental::{Incremental, merged, recolour};
use super::{
    COARSE_DEPTH_STEP, MIN_COARSE_FIRST_DEPTH, MIN_MESHER_THREADS, MeshJob, MeshKind, Meshed,
    Mesher, Spares,
};
use crate::appearance::CompiledAppearance;
use crate::mesh::{Mesh, n_open_edges};

/// Reads the clock for jobs' `requested_at` and the pool's timing (the tests time nothing).
#[expect(
    clippy::disallowed_methods,
    reason = "a job carries an instant and the pool times its work; no test reads a duration"
)]
fn now() -> Instant {
    Instant::now()
}

/// One job as a worker meshes it. The tests share their spare meshes (of every size), so
/// patches are written over meshes of other objects and tests.
fn mesh(
    job: Box<MeshJob>,
    state: Option<Incremental>,
    superseded: &dyn Fn() -> bool,
) -> (Option<Meshed>, Option<Incremental>) {
    static SPARES: std::sync::LazyLock<Spares> = std::sync::LazyLock::new(Spares::default);
    super::incremental::mesh(job, state, superseded, &SPARES)
}

/// Whether `object`'s run boxes were made (as a patch's are, from its base's) and are those
/// made afresh for its mesh; then makes them, as a worker does once it hands an object out.
fn runs_made_and_fresh(object: &crate::scene::SceneObject) -> bool {
    let fresh = crate::scene::PickRuns::default();
    fresh.prepare(&object.mesh);
    let made = object
        .pick_runs
        .runs_made_for(&object.mesh)
        .map(<[_]>::to_vec);
    object.pick_runs.prepare(&object.mesh);
    made.is_some() && made.as_deref() == fresh.runs_made_for(&object.mesh)
}

/// The unit ball in a domain, coloured by a colour map of its height.
fn ball() -> Object {
    let mut data = ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new("1-sqrt(x^2+y^2+z^2)").unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    };
    data.appearance.diffuse = Some(ColorDef::Map {
        formula: Formula::new("y").unwrap(),
        map: ColorMap {
            keys: vec![(-1.0, [0.9, 0.1, 0.1]), (1.0, [0.1, 0.9, 0.1])],
        },
    });
    Object::new(data).unwrap()
}

fn job(object: &Object, generation: u64, depth: u8) -> Box<MeshJob> {
    Box::new(MeshJob {
        id: ObjectId(1),
        object: object.clone(),
        world_from_group: Transform::IDENTITY,
        generation,
        depth,
        requested_at: now(),
        t_secs: 0.0,
        coarse_first: false,
    })
}

/// A ball of radius 0.3 carved at the top of the unit ball.
fn carve_at_the_top() -> Edit {
    Edit::stamp(EditOp::Subtract, ball_tool(0.3), Pose::at(DVec3::Z))
}

fn ball_tool(radius: f64) -> ToolShape {
    ToolShape::Sphere { radius }
}

/// Every triangle's corners (position, normal, colour), each triangle starting at its
/// least corner, sorted: equal for meshes with the same triangles in any order.
fn triangles(mesh: &Mesh) -> Vec<[[i64; 10]; 3]> {
    let q = |v: f32| (f64::from(v) * 1e5).round() as i64;
    let corner = |i: u32| {
        let i = i as usize;
        let (p, n, c) = (mesh.positions[i], mesh.normals[i], mesh.colours[i]);
        [p[0], p[1], p[2], n[0], n[1], n[2], c[0], c[1], c[2], c[3]].map(q)
    };
    let mut out: Vec<[[i64; 10]; 3]> = mesh
        .indices
        .chunks_exact(3)
        .map(|t| {
            let c = [corner(t[0]), corner(t[1]), corner(t[2])];
            let first = (0..3).min_by_key(|&k| c[k]).unwrap_or(0);
            [c[first], c[(first + 1) % 3], c[(first + 2) % 3]]
        })
        .collect();
    out.sort_unstable();
    out
}

/// [`triangles`] without the colours.
fn white(mesh: &Mesh) -> Vec<[[i64; 10]; 3]> {
    let mut m = mesh.clone();
    m.colours.iter_mut().for_each(|c| *c = [1.0; 4]);
    triangles(&m)
}

#[test]
fn ranges_are_sorted_and_joined() {
    assert_eq!(
        merged(vec![5..7, 0..2, 1..3, 7..9, 12..13]),
        vec![0..3, 5..9, 12..13]
    );
    assert!(merged(Vec::new()).is_empty());
}

/// Vertices used by a triangle of `mesh` whose colour is not what colouring the whole
/// mesh for `object` gives.
fn wrongly_coloured(object: &Object, mesh: &Mesh) -> usize {
    let mut appearance = CompiledAppearance::of(object);
    let mut whole = mesh.clone();
    let everything = std::slice::from_ref(&(0..mesh.n_vertices())).to_vec();
    recolour(object, &mut appearance, &mut whole, &everything, Vec::new());
    let used: BTreeSet<u32> = mesh.indices.iter().copied().collect();
    used.iter()
        .filter(|&&i| mesh.colours[i as usize] != whole.colours[i as usize])
        .count()
}

#[test]
fn carves_and_colour_paintings_patch_to_the_whole_meshs_triangles_and_colours() {
    let never = || false;
    let mut object = ball();
    let (first, state) = mesh(job(&object, 1, 5), None, &never);
    let first = first.unwrap();
    assert_eq!(first.kind, MeshKind::Whole);
    // A whole mesh's run boxes are made once it is out.
    assert!(!runs_made_and_fresh(first.object.as_ref().unwrap()));
    assert!(first.patch.as_ref().is_some_and(|(_, p)| p.full));
    let mut state = state;
    let edits = [
        Edit::stamp(
            EditOp::Subtract,
            ball_tool(0.3),
            Pose::at(DVec3::new(0.0, 0.0, 1.0)),
        ),
        Edit::stamp(
            EditOp::Paint {
                property: Paintable::Color,
                value: PaintValue::Color([0.1, 0.2, 0.95]),
            },
            ball_tool(0.4),
            Pose::at(DVec3::new(1.0, 0.0, 0.0)),
        ),
        Edit::stamp(
            // Inside the domain: the meshed box stays the same.
            EditOp::Union,
            ball_tool(0.15),
            Pose::at(DVec3::new(0.0, 0.9, 0.0)),
        ),
    ];
    for (k, edit) in edits.into_iter().enumerate() {
        object.apply(edit).unwrap();
        let generation = 2 + k as u64;
        let (done, next) = mesh(job(&object, generation, 5), state, &never);
        let done = done.unwrap();
        assert_eq!(done.kind, MeshKind::Patch, "edit {k}");
        let (base, patch) = done.patch.unwrap();
        assert!(!patch.full, "edit {k}");
        let drawn = done.object.unwrap();
        assert!(runs_made_and_fresh(&drawn), "edit {k}");
        let drawn = drawn.mesh;
        // Copying the patch's ranges into the base gives the new mesh (what the renderer
        // uploads), and it has the whole mesh's triangles and colours.
        let mut copied = Mesh::clone(&base);
        copied.positions.resize(patch.n_vertices, [0.0; 3]);
        copied.normals.resize(patch.n_vertices, [0.0; 3]);
        copied.colours.resize(patch.n_vertices, [0.0; 4]);
        copied.indices.resize(3 * patch.n_triangles, 0);
        for r in &patch.vertex_ranges {
            for i in r.clone() {
                copied.positions[i] = drawn.positions[i];
                copied.normals[i] = drawn.normals[i];
                copied.colours[i] = drawn.colours[i];
            }
        }
        for r in &patch.triangle_ranges {
            copied.indices[3 * r.start..3 * r.end]
                .copy_from_slice(&drawn.indices[3 * r.start..3 * r.end]);
        }
        assert!(
            copied == *drawn,
            "edit {k}: the patch's ranges make the mesh"
        );
        // Its triangles are those the mesher assembles whole (render's invariant), and
        // every vertex a triangle uses has the colour a whole colouring gives it.
        let own = next.as_ref().unwrap().octree.mesh().unwrap();
        assert!(white(&drawn) == white(&own), "edit {k}");
        assert_eq!(wrongly_coloured(&object, &drawn), 0, "edit {k}");
        state = next;
    }
    // Undoing the painting recolours its box, back to the colour map.
    let painted_before = wrongly_coloured(&object, &state.as_ref().unwrap().mesh);
    object.undo(1);
    let stale = wrongly_coloured(&object, &state.as_ref().unwrap().mesh);
    assert!(
        painted_before == 0 && stale > 20,
        "{stale} vertices were painted"
    );
    let (done, _) = mesh(job(&object, 9, 5), state, &never);
    let done = done.unwrap();
    assert_eq!(done.kind, MeshKind::Patch);
    assert_eq!(wrongly_coloured(&object, &done.object.unwrap().mesh), 0);
}

#[test]
fn other_changes_mesh_whole_and_a_superseded_job_is_dropped_before_it_starts() {
    let never = || false;
    let mut object = ball();
    let (_, state) = mesh(job(&object, 1, 5), None, &never);
    // A newer job waits: this one is dropped, and the kept state is untouched.
    object.apply(carve_at_the_top()).unwrap();
    let (none, state) = mesh(job(&object, 2, 5), state, &|| true);
    assert!(none.is_none() && state.is_some());
    // Another depth, then another appearance: whole.
    let (done, state) = mesh(job(&object, 3, 6), state, &never);
    assert_eq!(done.unwrap().kind, MeshKind::Whole);
    object
        .set(model::object::Field::Diffuse(Some(ColorDef::Constant([
            0.2, 0.4, 0.9,
        ]))))
        .unwrap();
    let (done, _) = mesh(job(&object, 4, 6), state, &never);
    assert_eq!(done.unwrap().kind, MeshKind::Whole);
}

#[test]
fn a_long_mesh_of_one_object_does_not_hold_up_another() {
    let mesher = Mesher::with_threads(MIN_MESHER_THREADS, now, || {}).unwrap();
    // Object 1 at depth 8 takes seconds; object 2 at depth 4 a few milliseconds.
    let mut long = job(&ball(), 1, 8);
    long.id = ObjectId(1);
    let mut short = job(&ball(), 1, 4);
    short.id = ObjectId(2);
    assert!(mesher.try_send(long).is_ok());
    std::thread::sleep(Duration::from_millis(50));
    assert!(mesher.try_send(short).is_ok());
    let first = mesher.recv_timeout(Duration::from_secs(600)).unwrap();
    assert_eq!(first.id, ObjectId(2), "the short job came first");
    let second = mesher.recv_timeout(Duration::from_secs(600)).unwrap();
    assert_eq!(second.id, ObjectId(1));
}

#[test]
fn a_new_object_shows_a_first_look_then_its_mesh_and_later_jobs_patch() {
    let mesher = Mesher::with_threads(MIN_MESHER_THREADS, now, || {}).unwrap();
    let wait = || mesher.recv_timeout(Duration::from_secs(600)).unwrap();
    let depth = MIN_COARSE_FIRST_DEPTH;
    let mut object = ball();
    let mut first = job(&object, 1, depth);
    first.coarse_first = true;
    assert!(mesher.try_send(first).is_ok());
    let (look, whole) = (wait(), wait());
    assert!(look.coarse && !whole.coarse);
    assert_eq!((look.generation, whole.generation), (1, 1));
    assert_eq!((look.kind, whole.kind), (MeshKind::Whole, MeshKind::Whole));
    let (look_mesh, whole_mesh) = (look.object.unwrap().mesh, whole.object.unwrap().mesh);
    // The first look is the object meshed shallower: what a job at that depth gives.
    let (shallow, _) = mesh(job(&object, 1, depth - COARSE_DEPTH_STEP), None, &|| false);
    assert!(triangles(&look_mesh) == triangles(&shallow.unwrap().object.unwrap().mesh));
    assert!(
        look.n_triangles * 4 < whole.n_triangles,
        "{} and {}",
        look.n_triangles,
        whole.n_triangles
    );
    // The mesh is what a job without a first look gives, and its patch starts from the look.
    let (direct, _) = mesh(job(&object, 1, depth), None, &|| false);
    assert!(triangles(&whole_mesh) == triangles(&direct.unwrap().object.unwrap().mesh));
    let (base, patch) = whole.patch.unwrap();
    assert!(std::sync::Arc::ptr_eq(&base, &look_mesh) && patch.full);
    // The next job patches the kept mesh, with no first look though it asks for one.
    object.apply(carve_at_the_top()).unwrap();
    let mut next = job(&object, 2, depth);
    next.coarse_first = true;
    assert!(mesher.try_send(next).is_ok());
    let patched = wait();
    assert_eq!(
        (patched.kind, patched.coarse, patched.generation),
        (MeshKind::Patch, false, 2)
    );
    assert!(mesher.recv_timeout(Duration::from_millis(200)).is_none());
    // Shallow jobs take none.
    let mut shallow = job(&object, 1, MIN_COARSE_FIRST_DEPTH - 1);
    shallow.id = ObjectId(7);
    shallow.coarse_first = true;
    assert!(mesher.try_send(shallow).is_ok());
    assert!(!wait().coarse);
    assert!(mesher.recv_timeout(Duration::from_millis(200)).is_none());
}

#[test]
fn new_objects_all_show_their_first_looks_before_any_is_meshed_whole() {
    // One worker, three new objects (a session opening): their first looks come first, in
    // the jobs' order, then their meshes.
    let mesher = Mesher::with_threads(1, now, || {}).unwrap();
    for id in 1..=3 {
        let mut job = job(&ball(), 1, MIN_COARSE_FIRST_DEPTH);
        job.id = ObjectId(id);
        job.coarse_first = true;
        assert!(mesher.try_send(job).is_ok());
    }
    let order: Vec<(u64, bool)> = (0..6)
        .map(|_| {
            let done = mesher.recv_timeout(Duration::from_secs(600)).unwrap();
            (done.id.0, done.coarse)
        })
        .collect();
    assert_eq!(
        order,
        [
            (1, true),
            (2, true),
            (3, true),
            (1, false),
            (2, false),
            (3, false)
        ]
    );
    // A newer job of an object whose first look was handed out replaces its requeued one.
    let mut first = job(&ball(), 1, MIN_COARSE_FIRST_DEPTH);
    first.id = ObjectId(9);
    first.coarse_first = true;
    let mut newer = job(&ball(), 2, MIN_COARSE_FIRST_DEPTH);
    newer.id = ObjectId(9);
    assert!(mesher.try_send(first).is_ok());
    let look = mesher.recv_timeout(Duration::from_secs(600)).unwrap();
    assert!(look.coarse && look.generation == 1);
    assert!(mesher.try_send(newer).is_ok());
    let rest: Vec<(bool, u64)> = std::iter::from_fn(|| {
        mesher
            .recv_timeout(Duration::from_millis(2_000))
            .map(|d| (d.coarse, d.generation))
    })
    .collect();
    assert_eq!(rest.last(), Some(&(false, 2)), "{rest:?}");
    assert!(rest.len() <= 2, "{rest:?}");
}

#[test]
fn implicit_meshes_whole_and_patched_are_closed_and_say_so() {
    let never = || false;
    let mut object = ball();
    let (done, state) = mesh(job(&object, 1, 5), None, &never);
    let drawn = done.unwrap().object.unwrap();
    assert!(drawn.closed);
    assert_eq!(n_open_edges(&drawn.mesh), 0);
    object.apply(carve_at_the_top()).unwrap();
    let (done, _) = mesh(job(&object, 2, 5), state, &never);
    let done = done.unwrap();
    assert_eq!(done.kind, MeshKind::Patch);
    let drawn = done.object.unwrap();
    assert!(drawn.closed);
    assert_eq!(n_open_edges(&drawn.mesh), 0);
    // A ball larger than its domain: the domain's faces close it.
    let big = Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new("1.5-sqrt(x^2+y^2+z^2)").unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    })
    .unwrap();
    let (done, _) = mesh(job(&big, 1, 5), None, &never);
    let drawn = done.unwrap().object.unwrap();
    assert!(drawn.closed);
    assert_eq!(n_open_edges(&drawn.mesh), 0);
}

/// A stroke's previews, each the stroke so far, patch only around the stamps each adds (past
/// 32 stamps the tool is indexed), and every patch has the triangles and colours of the
/// object meshed whole; the same strokes that are no continuation (their first pose moves)
/// patch every block the strokes reach.
#[test]
fn a_stroke_drawn_further_patches_only_its_new_stamps_to_the_whole_meshs_triangles() {
    let never = || false;
    let depth = 6;
    let ball = ball();
    let pose = |k: usize| {
        let t = k as f64 * 0.06;
        Pose::at(DVec3::new(t.cos(), t.sin(), 0.3 * t) * 0.97)
    };
    let preview = |n: usize, nudge: f64| {
        let mut path: Vec<Pose> = (0..n).map(pose).collect();
        path[0].position.z += nudge;
        let mut object = ball.clone();
        object
            .apply(Edit::stroke(EditOp::Subtract, ball_tool(0.1), path))
            .unwrap();
        object
    };
    let (_, mut grown) = mesh(job(&preview(1, 0.0), 1, depth), None, &never);
    let (_, mut moved) = mesh(job(&preview(1, 0.0), 1, depth), None, &never);
    let patched = |state, object: &Object, generation| {
        let (done, state) = mesh(job(object, generation, depth), state, &never);
        let done = done.unwrap();
        assert_eq!(done.kind, MeshKind::Patch);
        let changed = done.patch.as_ref().unwrap().1.blocks_changed;
        let drawn = done.object.unwrap();
        // The first patch's base was never handed out: its runs were not made.
        assert!(
            runs_made_and_fresh(&drawn) || generation == 2,
            "{generation}"
        );
        (drawn.mesh, changed, state)
    };
    let mut last = 1;
    for (k, n) in [2, 6, 12, 20, 21, 30, 31, 38, 44, 45]
        .into_iter()
        .enumerate()
    {
        let generation = 2 + k as u64;
        let object = preview(n, 0.0);
        let (drawn, changed, state) = patched(grown, &object, generation);
        grown = state;
        let (whole, _) = mesh(job(&object, generation, depth), None, &never);
        let whole = whole.unwrap();
        assert_eq!(whole.kind, MeshKind::Whole);
        assert!(
            white(&drawn) == white(&whole.object.unwrap().mesh),
            "{n} poses"
        );
        assert_eq!(wrongly_coloured(&object, &drawn), 0, "{n} poses");
        let nudge = if k % 2 == 0 { 1e-3 } else { 0.0 };
        let (_, all, state) = patched(moved, &preview(n, nudge), generation);
        moved = state;
        eprintln!("{last} to {n} poses: {changed} blocks changed against {all}");
        if n == last + 1 && n > 20 {
            assert!(
                3 * changed < all,
                "{n} poses: {changed} blocks against {all}"
            );
        }
        last = n;
    }
}

#[test]
fn a_spare_mesh_is_taken_only_once_nobody_holds_it_and_few_are_kept() {
    let spares = Spares::default();
    let triangle = |x: f32| Mesh {
        positions: vec![[x, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        normals: vec![[1.0, 0.0, 0.0]; 3],
        colours: vec![[1.0; 4]; 3],
        ambient: Vec::new(),
        indices: vec![0, 1, 2],
    };
    let drawn = std::sync::Arc::new(triangle(1.0));
    spares.give(std::sync::Arc::clone(&drawn));
    assert!(spares.take().is_none(), "the window still draws it");
    drop(drawn);
    assert_eq!(spares.take(), Some(triangle(1.0)));
    assert!(spares.take().is_none(), "taken once");
    for k in 0..super::MAX_SPARE_MESHES + 2 {
        spares.give(std::sync::Arc::new(triangle(k as f32)));
    }
    // The oldest went: the newest are kept, oldest first.
    for k in 2..super::MAX_SPARE_MESHES + 2 {
        assert_eq!(spares.take(), Some(triangle(k as f32)));
    }
    assert!(spares.take().is_none());
    // Written over, a spare holds exactly the mesh copied into it.
    let mut spare = triangle(5.0);
    let mut larger = triangle(2.0);
    larger.positions.push([3.0; 3]);
    larger.ambient = vec![[0.5; 3]; 4];
    spare.clone_from(&larger);
    assert_eq!(spare, larger);
    spare.clone_from(&triangle(7.0));
    assert_eq!(spare, triangle(7.0));
}
