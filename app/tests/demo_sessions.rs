//! The collaborative demo scenes as scripted two-peer sessions on loopback: two engines over
//! real QUIC sockets, each edit planned as the window plans it (commands and brush strokes),
//! ending with both peers at the same scene hash, the expected ops effective or rejected, and
//! the result exported and read back.
#![allow(
    clippy::unwrap_used,
    reason = "a scripted session; any failure is the test's"
)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use app::brush::{Brush, Stroke};
use app::command::{parse, plan};
use app::engine::{Engine, EngineConfig, Network, View, lock};
use glam::DVec3;
use replication::Timestamp;
use touch_support::{csv, touch};

mod touch_support;

const T0: Timestamp = Timestamp(1_795_355_107_000_000);

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("demo-session-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Waits (at most 30 s) until `done` holds for the engine's view.
fn wait_view(engine: &Engine, what: &str, done: impl Fn(&View) -> bool) {
    let deadline = app::clock::now().instant + Duration::from_secs(30);
    while !done(&lock(engine.view())) {
        assert!(
            app::clock::now().instant < deadline,
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn object_named(engine: &Engine, name: &str) -> u64 {
    let view = lock(engine.view());
    let ids: Vec<u64> = view.scene().objects().map(|(id, _)| id.0).collect();
    ids.into_iter()
        .find(|&id| view.object_label(id) == name)
        .unwrap()
}

/// Plans `line` as the window's command line would with `object` selected, and authors it.
fn command(engine: &Engine, object: u64, line: &str) {
    let planned = plan(parse(line).unwrap(), &lock(engine.view()), Some(object)).unwrap();
    engine
        .author_validated(planned.payload)
        .unwrap()
        .wait()
        .unwrap();
}

/// Drags `brush` (a `tool:` line) across `object` from `from` to `to` (scene coordinates),
/// as a drag in the window draws a stroke, and authors the one op it makes.
fn stroke(engine: &Engine, object: u64, brush: &str, from: DVec3, to: DVec3) {
    let brush = Brush::default().parse(brush).unwrap();
    let planned = {
        let view = lock(engine.view());
        let mut stroke = Stroke::begin(&view, object, brush, from).unwrap();
        for k in 1..=10 {
            stroke.push(from.lerp(to, f64::from(k) / 10.0));
        }
        stroke.finish(&view).unwrap()
    };
    engine
        .author_validated(planned.payload)
        .unwrap()
        .wait()
        .unwrap();
}

/// The status of the latest history row whose text contains `what` (a stroke is
/// "sculpted NAME").
fn status(engine: &Engine, what: &str) -> String {
    let view = lock(engine.view());
    let row = view.history().iter().rev().find(|h| h.what.contains(what));
    row.map(|h| h.status.clone()).unwrap_or_default()
}

/// Both peers show the latest stroke as rejected.
fn both_rejected(a: &Engine, b: &Engine) {
    for peer in [a, b] {
        let latest = status(peer, "sculpted");
        assert!(latest.starts_with("rejected"), "{latest}");
    }
}

/// A session on loopback: one peer opens demo `name` (in `dir_a`), the other joins it with
/// the invite (in `dir_b`); returns both once each holds the demo's `n_objects` objects and
/// the joiner its admission (the session binds its authors).
fn demo_pair(name: &str, dir_a: &Path, dir_b: &Path, n_objects: usize) -> (Engine, Engine) {
    let demo = app::demos::find(name).unwrap();
    let a = Engine::start(
        EngineConfig {
            demo: Some(demo),
            ..EngineConfig::on_loopback(dir_a)
        },
        T0,
    )
    .unwrap();
    wait_view(&a, "the demo", |v| v.scene().len() == n_objects);
    let addr = lock(a.view()).listen_addr().unwrap();
    let b = Engine::start(
        EngineConfig {
            invite: Some(a.invite().clone()),
            network: Network {
                dial: vec![addr],
                ..EngineConfig::on_loopback(dir_b).network
            },
            ..EngineConfig::on_loopback(dir_b)
        },
        T0,
    )
    .unwrap();
    wait_view(&b, "the demo from the other peer and its admission", |v| {
        v.scene().len() == n_objects && v.admitted()
    });
    (a, b)
}

#[test]
fn femur_one_peer_holds_the_bone_the_other_drills_through_a_takeover_and_exports_it() {
    let (dir_a, dir_b) = (scratch("femur-a"), scratch("femur-b"));
    let (a, b) = demo_pair("femur", &dir_a, &dir_b, 4);
    let bone = object_named(&a, "Bone");
    assert_eq!(object_named(&b, "Bone"), bone);

    // A grabs the bone under a weak lease to hold it steady.
    command(&a, bone, "lease");
    let holder = a.peer_id().short();
    wait_view(&b, "a's lease", |v| {
        v.lease(bone).is_some_and(|l| l.holder.short() == holder)
    });
    // B drills straight in from the side without asking: refused while A holds it.
    let drill = "carve cylinder radius 0.06";
    let (outside, inside) = (DVec3::new(0.4, 0.0, 0.0), DVec3::new(0.0, 0.0, 0.0));
    stroke(&b, bone, drill, outside, inside);
    let n_ops = lock(b.view()).n_ops();
    wait_view(&a, "b's first drill", |v| v.n_ops() == n_ops);
    both_rejected(&a, &b);
    // B takes the bone over (a weak lease gives way) and drills: that one holds, and A's
    // next edit of the bone, a density painting, is refused in its turn.
    command(&b, bone, "lease");
    stroke(&b, bone, drill, outside, inside);
    let drilled = lock(b.view()).n_ops();
    wait_view(&a, "b's takeover and drill", |v| v.n_ops() == drilled);
    assert_eq!(status(&a, "sculpted"), "effective");
    stroke(
        &a,
        bone,
        "paint density 0.3 ball radius 0.1",
        outside,
        inside,
    );
    let n_ops = lock(a.view()).n_ops();
    wait_view(&b, "a's painting", |v| v.n_ops() == n_ops);
    both_rejected(&a, &b);
    // B undoes its drill and does it again; both peers end with the same scene.
    command(&b, bone, "undo");
    command(&b, bone, "redo");
    let n_ops = lock(b.view()).n_ops();
    wait_view(&a, "b's undo and redo", |v| v.n_ops() == n_ops);
    assert_eq!(
        lock(a.view()).scene_hash_hex(),
        lock(b.view()).scene_hash_hex()
    );

    // The drilled bone exported from A reads back closed, with the hole where B drilled.
    let out = dir_a.join("bone.stl");
    let scene = lock(a.view()).scene().clone();
    let report =
        app::transfer::export(&scene, Some(model::scene::ObjectId(bone)), &out, 6).unwrap();
    assert_eq!(report.closed, Some(true), "{:?}", report.notes);
    let solid = formats::mesh::stl::read(&std::fs::read(&out).unwrap()).unwrap();
    assert!(solid.is_closed());
    assert!(
        solid.signed_distance(DVec3::new(0.15, 0.0, 0.0)) < 0.0,
        "the drill hole is empty"
    );
    assert!(
        solid.signed_distance(DVec3::new(0.0, 0.0, 0.15)) > 0.0,
        "beside the hole, bone"
    );
    drop(b);
    drop(a);
}

/// The classroom's mechanical part (Figure 7.9's "mechanical assembly"): a plate with a boss,
/// bored through. In the model's own coordinates; the model sits 0.3 above the bench.
const CLASSROOM_PART: &str = "(((0.8-abs(x)) & (0.5-abs(z)) & (0.1-abs(y))) | \
                              ((0.25-sqrt(x^2+z^2)) & (y+0.1) & (0.45-y))) \\ (0.1-sqrt(x^2+z^2))";

#[test]
fn classroom_two_students_shape_colour_weigh_dig_and_paint_one_model_and_save_it() {
    let (dir_a, dir_b) = (scratch("classroom-a"), scratch("classroom-b"));
    // "Student" opens the classroom; "WeiLei" joins with the invite.
    let (student, weilei) = demo_pair("classroom", &dir_a, &dir_b, 2);
    let model = object_named(&student, "Model");
    assert_eq!(object_named(&weilei, "Model"), model);

    // Figure 7.10, line by line: the student loads the shape, WeiLei colours it, the student
    // gives it a density.
    command(&student, model, &format!("shape: {CLASSROOM_PART}"));
    command(&weilei, model, "colour: 0.3+0.2*y, 0.45, 0.75-0.2*y");
    command(&student, model, "density: 0.6");
    // WeiLei's big cylinder paints friction over the plate's +x end; the student's small
    // cylinder digs two holes through the plate's -x end and softens the skin beside them.
    let big = "paint friction 0.9 cylinder radius 0.3";
    stroke(
        &weilei,
        model,
        big,
        DVec3::new(0.55, 0.4, -0.2),
        DVec3::new(0.55, 0.4, 0.2),
    );
    let small = "carve cylinder radius 0.06";
    for z in [-0.25, 0.25] {
        stroke(
            &student,
            model,
            small,
            DVec3::new(-0.55, 0.55, z),
            DVec3::new(-0.55, 0.05, z),
        );
    }
    let soften = "paint tension 0.3 cylinder radius 0.06";
    stroke(
        &student,
        model,
        soften,
        DVec3::new(-0.3, 0.4, 0.0),
        DVec3::new(-0.3, 0.4, 0.1),
    );
    let n_ops = lock(student.view()).n_ops();
    wait_view(&weilei, "everyone's edits", |v| v.n_ops() == n_ops);
    for peer in [&student, &weilei] {
        let view = lock(peer.view());
        let edits: Vec<&str> = view
            .history()
            .iter()
            .filter(|h| h.what.contains("Model"))
            .map(|h| h.status.as_str())
            .collect();
        assert!(
            edits.len() >= 7 && edits.iter().all(|s| *s == "effective"),
            "{edits:?}"
        );
    }
    assert_eq!(
        lock(student.view()).scene_hash_hex(),
        lock(weilei.view()).scene_hash_hex()
    );

    // "save": the student writes the scene as FVRML; it reads back with the same objects and
    // the painted friction where WeiLei's cylinder went.
    let saved = dir_a.join("classroom-saved.wrl");
    let scene = lock(student.view()).scene().clone();
    app::transfer::export(&scene, None, &saved, 6).unwrap();
    let mut no_files = |path: &str| Err(format!("no file {path}"));
    let text = std::fs::read_to_string(&saved).unwrap();
    let loaded = formats::fvrml::load(
        &text,
        &formats::fvrml::LoadOptions::default(),
        &mut no_files,
    )
    .unwrap()
    .scene;
    assert_eq!(loaded.len(), 2);
    let part = loaded
        .objects()
        .find(|(_, o)| o.object.data().name == "Model")
        .map(|(_, o)| o.object.clone())
        .unwrap();
    let mut sampler = model::object::Sampler::new(std::sync::Arc::new(part));
    let friction = model::object::Paintable::Friction;
    // (The model's own coordinates: 0.3 below the scene's.)
    assert_eq!(
        sampler.scalar(friction, DVec3::new(0.55, 0.1, 0.0), 0.0),
        Some(0.9)
    );
    assert_ne!(
        sampler.scalar(friction, DVec3::new(-0.55, 0.1, 0.0), 0.0),
        Some(0.9)
    );

    // Felt from the saved file: a hand going down through a hole meets nothing; beside it,
    // the plate's density resists (the plate spans y 0.2 to 0.4 in the scene).
    let down = |x: f64, z: f64| {
        [
            (0.0, DVec3::new(x, 0.6, z)),
            (0.2, DVec3::new(x, 0.6, z)),
            (1.0, DVec3::new(x, 0.1, z)),
        ]
    };
    let through_hole = touch(&dir_a, &saved, &csv(&down(-0.55, 0.25)), &[]);
    let beside = touch(&dir_a, &saved, &csv(&down(-0.55, 0.0)), &[]);
    // Ticks 400 to 600: the hand between y 0.35 and 0.225, inside the plate.
    let drag =
        |forces: &[(f64, DVec3)]| forces[400..600].iter().map(|f| f.1).sum::<DVec3>() / 200.0;
    let (hole, solid) = (drag(&through_hole), drag(&beside));
    assert!(hole.length() < 1e-9, "the hole is empty: {hole}");
    assert!(
        solid.y > 0.05 && solid.y > 0.9 * solid.length(),
        "the plate: {solid}"
    );
    drop(weilei);
    drop(student);
}
