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
    engine.author(planned.payload).unwrap().wait().unwrap();
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
    engine.author(planned.payload).unwrap().wait().unwrap();
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

#[test]
fn femur_one_peer_holds_the_bone_the_other_drills_through_a_takeover_and_exports_it() {
    let (dir_a, dir_b) = (scratch("femur-a"), scratch("femur-b"));
    let femur = app::demos::find("femur").unwrap();
    let a = Engine::start(
        EngineConfig {
            demo: Some(femur),
            ..EngineConfig::on_loopback(&dir_a)
        },
        T0,
    )
    .unwrap();
    wait_view(&a, "the femur", |v| v.scene().len() == 4);
    let addr = lock(a.view()).listen_addr().unwrap();
    let b = Engine::start(
        EngineConfig {
            invite: Some(a.invite().clone()),
            network: Network {
                dial: vec![addr],
                ..EngineConfig::on_loopback(&dir_b).network
            },
            ..EngineConfig::on_loopback(&dir_b)
        },
        T0,
    )
    .unwrap();
    wait_view(&b, "the femur from a", |v| v.scene().len() == 4);
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
    let report = app::transfer::export(&scene, Some(fdsl::scene::ObjectId(bone)), &out, 6).unwrap();
    assert_eq!(report.closed, Some(true), "{:?}", report.notes);
    let solid = fdsl::mesh::stl::read(&std::fs::read(&out).unwrap()).unwrap();
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
