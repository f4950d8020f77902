//! Touch in the app: `sculpt touch` run as a process over the thesis's scenes writes the
//! forces the haptic crate's own containers give along the same path (the closed-form
//! whirlpool, the watermelon of its trace tests), and refuses bad files with their location;
//! the live feed gives a running servo a peer's edit within one snapshot.
#![allow(
    clippy::unwrap_used,
    reason = "helpers outside #[test] fns unwrap process output"
)]

use std::path::{Path, PathBuf};

use glam::DVec3;
use haptic::aabb::Aabb;
use haptic::shapes::{Analytic, fdsl_watermelon};

mod touch_support;

use app::touch::path::TouchPath;
use app::touch::{DeviceModel, TICK_SECS, replay, rig, zone_for};
use touch_support::{csv, sculpt_touch, touch};

const WATERMELON_FDSL: &str = include_str!("../../tests/data/models/watermelon.fdsl");

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("touch-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A file of the repository, by its path from the repository's root.
fn repo_file(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(relative)
}

fn scene_file(name: &str) -> PathBuf {
    repo_file(&format!("tests/data/scenes/{name}"))
}

/// The path's point at each tick, as the replay samples it.
fn points(path_csv: &str) -> Vec<DVec3> {
    let path = TouchPath::parse(path_csv).unwrap();
    let mut cursor = 0;
    (0..path.n_ticks(TICK_SECS))
        .map(|k| path.at_tick(k, TICK_SECS, &mut cursor).hip_scene)
        .collect()
}

fn assert_same_forces(cli: &[(f64, DVec3)], library: &[DVec3]) {
    assert_eq!(cli.len(), library.len());
    for (k, ((t, a), b)) in cli.iter().zip(library).enumerate() {
        assert!((t - k as f64 * TICK_SECS).abs() < 1e-6, "tick {k}: t = {t}");
        assert!((*a - *b).length() < 1e-6, "tick {k}: {a} vs {b}");
    }
}

#[test]
fn the_whirlpool_pulls_round_and_down_as_the_haptic_crates_closed_form_does() {
    let dir = scratch("whirlpool");
    // Rest inside the pool, go round the axis, then rise above the lid and rest there.
    let mut rows = vec![(0.0, DVec3::new(0.8, 0.35, 0.0))];
    for k in 0..=100 {
        let angle = f64::from(k) * 0.03;
        let p = DVec3::new(0.8 * angle.cos(), 0.35, 0.8 * angle.sin());
        rows.push((0.5 + f64::from(k) * 0.01, p));
    }
    let last = rows[rows.len() - 1].1;
    rows.push((1.7, last + DVec3::new(0.0, 0.55, 0.0)));
    rows.push((2.2, last + DVec3::new(0.0, 0.55, 0.0)));
    let path_csv = csv(&rows);
    let forces = touch(&dir, &scene_file("figure_7_4.wrl"), &path_csv, &[]);
    assert_eq!(forces.len(), 2201);

    // The haptic crate's closed-form whirlpool (its trace tests check their fdsl container
    // against it) over the same path through the same servo: the same forces.
    let caps = DeviceModel::Falcon.capabilities();
    let pool = Aabb::new(DVec3::new(-1.6, 0.0, -1.6), DVec3::new(1.6, 0.7, 1.6));
    let rig = rig(DeviceModel::Falcon, zone_for(&caps, Some(pool), None));
    let library = replay(
        vec![Analytic::whirlpool(0)],
        rig,
        TouchPath::parse(&path_csv).unwrap(),
    );
    assert_same_forces(&forces, &library.forces_newtons);

    // What the thesis says it feels like: round the axis and down, at the device's full
    // force, inside the pool; nothing above the lid.
    let hips = points(&path_csv);
    let mut n_inside = 0;
    for (k, ((_, f), hip)) in forces.iter().zip(&hips).enumerate() {
        if (300..1500).contains(&k) {
            let radial = DVec3::new(hip.x, 0.0, hip.z).normalize();
            let round = DVec3::Y.cross(radial);
            assert!(f.dot(round) > 3.0 * f.dot(radial).abs(), "tick {k}: {f}");
            assert!(f.y < 0.0, "tick {k}: down the pool: {f}");
            assert!((f.length() - 8.0).abs() < 0.05, "a Falcon-class 8 N: {f}");
            n_inside += 1;
        }
        if k > 1800 {
            assert_eq!(*f, DVec3::ZERO, "tick {k}: above the lid");
        }
    }
    assert_eq!(n_inside, 1200);
}

/// The haptic crate's watermelon (`object_watermelon`: its trace tests' geometry, tension,
/// zone and crunchy density) at the origin, as an FVRML file.
fn haptic_watermelon_file(dir: &Path) -> PathBuf {
    let object = haptic::shapes::object_watermelon(WATERMELON_FDSL, DVec3::ZERO, 1.0).unwrap();
    let mut scene = model::scene::Scene::new();
    scene
        .insert_object(model::scene::ObjectId(0), object, None)
        .unwrap();
    let path = dir.join("watermelon_haptic.wrl");
    std::fs::write(&path, formats::fvrml::write(&formats::fvrml::save(&scene))).unwrap();
    path
}

/// The trace tests' watermelon hand, kinematic: rest above, down through the rind into the
/// flesh, rest, and back out.
fn watermelon_rows() -> Vec<(f64, DVec3)> {
    let at = |y: f64| DVec3::new(-0.2, y, -0.2);
    vec![
        (0.0, at(1.2)),
        (0.3, at(1.2)),
        (2.8, at(0.0)),
        (3.0, at(0.0)),
        (5.5, at(1.2)),
    ]
}

#[test]
fn the_watermelons_rind_pushes_out_harder_with_depth_then_pops_as_in_the_trace_tests() {
    let dir = scratch("watermelon");
    let file = haptic_watermelon_file(&dir);
    let path_csv = csv(&watermelon_rows());
    // The trace tests' rig: a desktop pen, 20 scene units per device metre.
    let forces = touch(
        &dir,
        &file,
        &path_csv,
        &["--device", "desktop-pen", "--world-per-metre", "20"],
    );
    let caps = DeviceModel::DesktopPen.capabilities();
    let zone = zone_for(&caps, None, Some(20.0));
    let geometry = fdsl::Function::parse(WATERMELON_FDSL).unwrap();
    let library = replay(
        vec![fdsl_watermelon(0, &geometry, DVec3::ZERO, 1.0).unwrap()],
        rig(DeviceModel::DesktopPen, zone),
        TouchPath::parse(&path_csv).unwrap(),
    );
    // The trace tests' function container over the same path: the same forces.
    assert_same_forces(&forces, &library.forces_newtons);

    // Going down (ticks 300..2800): the rind pushes out (+y), harder the deeper, until the
    // membrane pops near the zone depth 0.05 (the trace test's bounds, 0.03..0.08, and its
    // peak above 1.5 N); then the flesh only resists motion.
    let hips = points(&path_csv);
    let depth = |k: usize| 1.0 - hips[k].length();
    let first_touch = (0..2800).find(|&k| depth(k) > 0.0).unwrap();
    let peak_tick = (first_touch..2800)
        .max_by(|&a, &b| forces[a].1.y.total_cmp(&forces[b].1.y))
        .unwrap();
    let peak = forces[peak_tick].1.y;
    assert!(peak > 1.5, "peak tension {peak} N");
    assert!(
        (0.03..0.08).contains(&depth(peak_tick)),
        "pops at depth {}",
        depth(peak_tick)
    );
    for k in first_touch + 15..peak_tick {
        let (f, before) = (forces[k].1, forces[k - 10].1);
        assert!(f.y > 0.0 && f.y > before.y, "tick {k}: {f} after {before}");
    }
    for (k, (_, f)) in forces.iter().enumerate().take(2800).skip(peak_tick + 100) {
        assert!(
            f.y >= 0.0 && f.y < 0.5 * peak,
            "tick {k}: flesh resists {f}"
        );
    }
    // At rest in the flesh nothing pushes; back outside nothing at all.
    assert!(forces[2990].1.length() < 1e-3, "{}", forces[2990].1);
    assert_eq!(forces.last().unwrap().1, DVec3::ZERO);
}

#[test]
fn the_demo_watermelons_rind_holds_a_resting_hand_then_pops() {
    // The demo scene (`scenes/watermelon.wrl`): tension 1 over a surface zone 0.05
    // deep. A hand comes down onto the rind, rests 0.03 inside it, then pushes on to 0.12 and
    // rests in the flesh.
    let dir = scratch("watermelon-wrl");
    let (x, z) = (-0.2, -0.2);
    let at_radius = |r: f64| DVec3::new(x, (r * r - x * x - z * z).sqrt(), z);
    let rows = [
        (0.0, at_radius(1.2)),
        (0.3, at_radius(1.2)),
        (2.3, at_radius(0.97)),
        (2.8, at_radius(0.97)),
        (4.8, at_radius(0.88)),
        (5.3, at_radius(0.88)),
    ];
    let path_csv = csv(&rows);
    let forces = touch(&dir, &repo_file("scenes/watermelon.wrl"), &path_csv, &[]);
    let outward = |k: usize| forces[k].1.dot(points(&path_csv)[k].normalize());
    // Resting in the rind, inside its zone: the membrane pushes the hand back out.
    // (4.2 N when this was written, of the Falcon's 8 N.)
    let resting = outward(2790);
    assert!(resting > 2.0, "resting in the rind: {resting} N");
    assert!(
        resting > 0.95 * forces[2790].1.length(),
        "the push is along the rind's normal: {}",
        forces[2790].1
    );
    // Pushed through the zone: the membrane popped; resting in the flesh nothing pushes.
    let popped = forces[5290].1;
    let peak = (2800..4800).map(outward).fold(f64::MIN, f64::max);
    assert!(popped.length() < 1e-3, "resting in the flesh: {popped}");
    assert!(
        peak >= resting,
        "the push grows until it pops: {peak} after {resting}"
    );
}

/// A ball of radius 1 written the way the thesis writes physics: a tension and nothing else.
const TENSION_ONLY_BALL: &str = r#"#VRML V2.0 utf8
DEF Ball FShape {
  geometry FGeometry { definition "1-sqrt(x^2+y^2+z^2)" bboxSize 2.2 2.2 2.2 }
  physics FPhysics { surface FSurface { tension FTension { definition "1" } } }
}
"#;

#[test]
fn a_ball_with_tension_and_no_depth_pushes_out_within_the_zone_the_device_sets() {
    let dir = scratch("tension-only");
    let scene = dir.join("ball.wrl");
    let at = |y: f64| DVec3::new(0.0, y, 0.0);
    // Down onto the top of the ball, a rest 0.03 inside, then on to 0.15 inside.
    let rows = [
        (0.0, at(1.2)),
        (0.3, at(1.2)),
        (1.3, at(0.97)),
        (1.8, at(0.97)),
        (2.8, at(0.85)),
        (3.3, at(0.85)),
    ];
    let path_csv = csv(&rows);
    std::fs::write(&scene, TENSION_ONLY_BALL).unwrap();
    let (input, output) = (dir.join("in.csv"), dir.join("out.csv"));
    std::fs::write(&input, &path_csv).unwrap();
    let run = sculpt_touch(&scene, &input, &output, &[]);
    let stdout = text(&run.stdout);
    assert!(run.status.success(), "{}", text(&run.stderr));
    // The zone is fitted around the ball (22 scene units per device metre) and the Falcon's
    // 8 N at 3000 N/m sets the zone 2.67 mm deep: 0.0587 scene units.
    assert!(
        stdout.contains("surface zone where no FDepth is given: 2.67 mm at the device, 0.0587"),
        "{stdout}"
    );
    let forces = touch_support::read_forces(&output);
    let max = DeviceModel::Falcon.capabilities().force_newtons_max;
    assert!(forces.iter().all(|(_, f)| f.length() <= max + 1e-9));
    // Resting 0.03 inside, about half way into the zone: pushed out (up) with about half
    // the device's force.
    let resting = forces[1790].1;
    assert!(
        resting.y > 0.4 * max && resting.y < 0.6 * max,
        "resting in the zone: {resting}"
    );
    assert!(
        resting.y > 0.99 * resting.length(),
        "along the normal: {resting}"
    );
    // Past the zone the membrane popped: nothing pushes.
    assert!(forces[3290].1.length() < 1e-3, "{}", forces[3290].1);

    // An explicit depth overrides the device's: 0.2 deep, the second rest is still in it.
    let deep = TENSION_ONLY_BALL.replace(
        "definition \"1\" } }",
        "definition \"1\" } depth FDepth { definition \"0.2\" } }",
    );
    std::fs::write(&scene, deep).unwrap();
    let forces = touch(&dir, &scene, &path_csv, &[]);
    assert!(
        forces[3290].1.y > 0.9 * max,
        "still in the given zone: {}",
        forces[3290].1
    );
}

#[test]
fn figure_7_8s_campus_container_is_felt_on_the_campus_it_is_grouped_with() {
    // Figure 7.8 as printed, its remote campus (`Inline`, not fetched) replaced by a local
    // stand-in: one building, a box 1 wide and 1 high on the origin. The physics-only FShape
    // (geometry "0", tension "1", friction "0.3", no depth) makes it tangible.
    let dir = scratch("figure-7-8");
    let printed = std::fs::read_to_string(scene_file("figure_7_8.wrl")).unwrap();
    let remote = "http://cospace.sce.ntu.edu.sg/vircampus/enter.wrl";
    assert!(printed.contains(remote));
    let scene = dir.join("figure_7_8.wrl");
    std::fs::write(&scene, printed.replace(remote, "enter.wrl")).unwrap();
    std::fs::write(
        dir.join("enter.wrl"),
        "#VRML V2.0 utf8\nShape { geometry Box { size 1 1 1 } }\n",
    )
    .unwrap();
    // Down onto the roof (y = 0.5), a rest 0.013 in (half the device's zone: the zone
    // spans the box at 10 scene units per device metre), a slide along +x at that depth,
    // and a rest.
    let at = |x: f64, y: f64| DVec3::new(x, y, 0.0);
    let rows = [
        (0.0, at(0.0, 0.7)),
        (0.3, at(0.0, 0.7)),
        (1.3, at(0.0, 0.487)),
        (1.8, at(0.0, 0.487)),
        (2.8, at(0.3, 0.487)),
        (3.3, at(0.3, 0.487)),
    ];
    let (input, output) = (dir.join("in.csv"), dir.join("out.csv"));
    std::fs::write(&input, csv(&rows)).unwrap();
    let run = sculpt_touch(&scene, &input, &output, &[]);
    let stderr = text(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(
        stderr.contains("gives its physics to the 1 shapes grouped with it"),
        "{stderr}"
    );
    assert!(
        text(&run.stdout).contains("1 objects felt"),
        "{}",
        text(&run.stdout)
    );
    let forces = touch_support::read_forces(&output);
    let max = DeviceModel::Falcon.capabilities().force_newtons_max;
    assert!(forces.iter().all(|(_, f)| f.length() <= max + 1e-9));
    // Tension: resting half way into the zone, pushed up with about half the device's force.
    let resting = forces[1790].1;
    assert!(
        resting.y > 0.4 * max && resting.y < 0.6 * max && resting.x.abs() < 1e-6,
        "resting on the roof: {resting}"
    );
    // Friction: sliding along +x, a force against the motion 0.3 of the push.
    for k in [2300, 2500, 2700] {
        let f = forces[k].1;
        assert!(f.y > 0.4 * max, "tick {k}: still pushed out: {f}");
        assert!(
            (-f.x / f.y - 0.3).abs() < 0.03,
            "tick {k}: friction 0.3 against the slide: {f}"
        );
    }
    // At rest again friction fades: only the push.
    assert!(
        forces[3290].1.x.abs() < 0.05 * forces[3290].1.y,
        "{}",
        forces[3290].1
    );
}

#[test]
fn bad_paths_and_scenes_are_errors_with_their_location_and_write_nothing() {
    let dir = scratch("bad");
    let (input, output) = (dir.join("in.csv"), dir.join("out.csv"));
    let scene = scene_file("figure_7_4.wrl");
    let run = |input: &Path, scene: &Path, extra: &[&str]| {
        let out = sculpt_touch(scene, input, &output, extra);
        assert!(!out.status.success());
        let stderr = text(&out.stderr);
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!output.exists(), "nothing is written");
        stderr
    };
    std::fs::write(&input, "t,x,y,z,button\n0,0,0,0,0\n0.5,0,zz,0,1\n").unwrap();
    let stderr = run(&input, &scene, &[]);
    let located = format!("{}:3:7: y is not a number: `zz`", input.display());
    assert!(stderr.contains(&located), "{stderr}");

    std::fs::write(&input, "x,y,z\n").unwrap();
    let stderr = run(&input, &scene, &[]);
    assert!(
        stderr.contains(":1:1: expected the header `t,x,y,z,button`"),
        "{stderr}"
    );

    std::fs::write(&input, "t,x,y,z,button\n0,0,0,0,0\n").unwrap();
    let broken = dir.join("broken.wrl");
    std::fs::write(
        &broken,
        "#VRML V2.0 utf8\nFShape {\n  geometry FGeometry {\n",
    )
    .unwrap();
    let stderr = run(&input, &broken, &[]);
    assert!(
        stderr.contains(&format!("{}:", broken.display())),
        "{stderr}"
    );
    assert!(stderr.contains("cannot load the scene"), "{stderr}");

    let stderr = run(&input, &scene, &["--world-per-metre", "0"]);
    assert!(
        stderr.contains("--world-per-metre must be positive"),
        "{stderr}"
    );
    let stderr = run(&dir.join("missing.csv"), &scene, &[]);
    assert!(stderr.contains("missing.csv"), "{stderr}");
}

mod live {
    //! Two engines on loopback; peer B runs the servo on its live scene through the feed.

    use std::sync::{Arc, Mutex};
    use std::time::{Duration, Instant};

    use app::engine::{Engine, EngineConfig, Network, lock};
    use app::touch::{DeviceModel, rig, zone_for};
    use glam::DVec3;
    use haptic::aabb::Aabb;
    use haptic::device::sim::{HandModel, SimDevice, Waypoint};
    use haptic::feed::Feed;
    use haptic::servo::{Servo, ServoConfig, ServoLink, StatsSnapshot};
    use model::object::{Domain, Edit, EditOp, Field, Formula, Geometry, ObjectData, Physics};
    use model::object::{Pose, Property, ToolShape};
    use replication::shape::ShapePayload;

    const T0: replication::Timestamp = replication::Timestamp(1_795_355_107_000_000);

    fn config(store: &std::path::Path) -> EngineConfig {
        EngineConfig::on_loopback(store)
    }

    fn now() -> Instant {
        app::clock::now().instant
    }

    /// Waits (at most 20 s) until `done` holds.
    fn wait(what: &str, mut done: impl FnMut() -> bool) {
        let deadline = now() + Duration::from_secs(20);
        while !done() {
            assert!(now() < deadline, "timed out waiting for {what}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    fn author(engine: &Engine, payload: ShapePayload) {
        engine.author(payload).unwrap().wait().unwrap();
    }

    /// A ball of `radius` at `(x, 0, 0)` with a tense surface zone 0.1 deep.
    fn ball(x: f64, radius: f64) -> ObjectData {
        let property = |text: &str| Some(Property::new(Formula::new(text).unwrap()));
        let formula = format!("{radius} - sqrt((x - {x})^2 + y^2 + z^2)");
        ObjectData {
            name: "ball".into(),
            geometry: Some(Geometry::implicit_in(
                Formula::new(&formula).unwrap(),
                Domain::new(DVec3::new(x, 0.0, 0.0), DVec3::splat(2.2 * radius)),
            )),
            physics: Physics {
                tension: property("0.8"),
                zone_depth: property("0.1"),
                ..Physics::default()
            }
            .into(),
            ..ObjectData::default()
        }
    }

    /// Authors `payload` on A and waits until B's servo shows `felt`; returns the time from
    /// the op's arrival in B's view (B's view waker) to that tick being seen, and the
    /// servo's statistics then.
    fn edit_and_feel(
        a: &Engine,
        payload: ShapePayload,
        arrivals: &Mutex<Vec<Instant>>,
        stats: &haptic::servo::ServoStats,
        felt: impl Fn(&StatsSnapshot) -> bool,
    ) -> (Duration, StatsSnapshot, StatsSnapshot) {
        let n_arrivals = arrivals.lock().unwrap().len();
        let before = stats.snapshot();
        assert!(!felt(&before), "{before:?}");
        author(a, payload);
        let deadline = now() + Duration::from_secs(20);
        let (seen, after) = loop {
            let s = stats.snapshot();
            if felt(&s) {
                break (now(), s);
            }
            assert!(now() < deadline, "never felt: {s:?}");
            std::thread::yield_now();
        };
        let arrived = arrivals.lock().unwrap()[n_arrivals];
        (seen.duration_since(arrived), before, after)
    }

    #[test]
    fn a_peers_edit_is_felt_by_the_servo_within_one_snapshot() {
        let (da, db) = (super::scratch("live-a"), super::scratch("live-b"));
        let a = Engine::start(config(&da), T0).unwrap();
        // The ball B's hand will rest in, and another one far from it.
        let first = lock(a.view()).next_object();
        let (object, other) = (first.id(), first.skip(1).unwrap().id());
        for (k, x, radius) in [(0, 0.0, 1.0), (1, 3.0, 0.5)] {
            author(&a, first.skip(k).unwrap().create(ball(x, radius), None));
        }
        let addr = lock(a.view()).listen_addr().unwrap();
        let b_config = EngineConfig {
            invite: Some(a.invite().clone()),
            network: Network {
                dial: vec![addr],
                ..config(&db).network
            },
            ..config(&db)
        };
        let b = Engine::start(b_config, T0).unwrap();
        wait("the balls on b", || lock(b.view()).scene().len() == 2);

        // B's servo: a Falcon-class device held by a firm simulated hand that rests 0.05
        // deep in the ball's 0.1-deep surface zone, at the top.
        let caps = DeviceModel::Falcon.capabilities();
        let ball_box = Aabb::new(DVec3::splat(-1.1), DVec3::splat(1.1));
        let zone = zone_for(&caps, Some(ball_box), None);
        let rest = DVec3::new(0.0, 0.95, 0.0);
        let hand = HandModel {
            stiffness_newtons_per_metre: 3_000.0,
            damping_newton_secs_per_metre: 40.0,
            ..HandModel::default()
        };
        let waypoints = vec![Waypoint {
            t_secs: 0.0,
            position_metres: zone.device_from_world(rest),
        }];
        let device = SimDevice::new(caps, waypoints, hand, 0.001).unwrap();
        // A loaded test machine may pause the (normal-priority) servo thread for longer
        // than the 5 ms after which a real device is treated as stalled; allow 100 ms.
        let mut servo_rig = rig(DeviceModel::Falcon, zone);
        servo_rig.params.stall_secs = 0.1;
        let (servo, link) = Servo::init(device, servo_rig);
        let ServoLink { scenes, stats, .. } = link;
        let feed = Feed::spawn(Arc::clone(b.view()), scenes).unwrap();
        let arrivals: Arc<Mutex<Vec<Instant>>> = Arc::default();
        let (noted, wake_feed) = (Arc::clone(&arrivals), feed.waker());
        lock(b.view()).set_waker(Box::new(move || {
            noted.lock().unwrap().push(app::clock::now().instant);
            wake_feed();
        }));
        let config = ServoConfig {
            realtime_priority: false,
            thread_name: "haptic-servo-live-test".into(),
            ..ServoConfig::default()
        };
        let handle = haptic::servo::spawn(servo, &config).unwrap();
        // Ramped in and settled: the rind holds the hand out with a steady force.
        wait("the rind to push back", || {
            let s = stats.snapshot();
            s.n_ticks > 1_000 && s.top_id == Some(object) && s.force_newtons.y > 1.5
        });
        std::thread::sleep(Duration::from_millis(300));
        let steady = stats.snapshot().force_newtons;
        assert_eq!(feed.stats().n_snapshots, 1, "one snapshot so far");
        assert_eq!(feed.stats().n_rebuilt, 2);

        // A slackens the ball's surface: B's hand sinks deeper and is pushed less.
        let tension = ShapePayload::Set {
            object,
            field: Box::new(Field::Tension(Some(Property::new(
                Formula::new("0.2").unwrap(),
            )))),
        };
        let taken = stats.snapshot().n_scenes_taken;
        let (slack_latency, before, after) = edit_and_feel(&a, tension, &arrivals, &stats, |s| {
            s.n_scenes_taken > taken && s.force_newtons.y < steady.y - 0.3
        });
        assert_eq!(
            after.n_scenes_taken,
            before.n_scenes_taken + 1,
            "felt within one snapshot"
        );
        assert_eq!(after.top_id, Some(object));
        assert!(
            after.force_newtons.y < steady.y,
            "{:?}",
            after.force_newtons
        );
        std::thread::sleep(Duration::from_millis(300));

        // A carves a hole where B's device rests: B's hand is in free space at once.
        let carve = ShapePayload::edit(
            object,
            Edit::stamp(
                EditOp::Subtract,
                ToolShape::Sphere { radius: 0.3 },
                Pose::at(rest),
            ),
        )
        .expect("a valid edit");
        let taken = stats.snapshot().n_scenes_taken;
        let (carve_latency, before, after) = edit_and_feel(&a, carve, &arrivals, &stats, |s| {
            s.n_scenes_taken > taken && s.top_id.is_none()
        });
        assert_eq!(after.n_scenes_taken, before.n_scenes_taken + 1);
        wait("the force to fade out", || {
            stats.snapshot().force_newtons == DVec3::ZERO
        });
        let feed_stats = feed.stats();
        assert_eq!(feed_stats.n_snapshots, 3);
        assert_eq!(
            feed_stats.n_rebuilt, 4,
            "each edit rebuilt its own object only"
        );
        assert_eq!(feed_stats.n_objects, 2);
        // A deletes the other ball: the next snapshot leaves it out and rebuilds nothing.
        author(&a, ShapePayload::Delete { object: other });
        wait("the deletion", || feed.stats().n_snapshots == 4);
        assert_eq!((feed.stats().n_objects, feed.stats().n_rebuilt), (1, 4));
        eprintln!(
            "remote edit arrival to felt: tension {} us, carve {} us; feed build {} us",
            slack_latency.as_micros(),
            carve_latency.as_micros(),
            feed_stats.last_build_micros
        );
        assert!(slack_latency < Duration::from_secs(2) && carve_latency < Duration::from_secs(2));
        let servo = handle.stop().unwrap();
        feed.stop();
        assert_eq!(servo.state().stack().entries().len(), 0);
        b.shutdown();
        a.shutdown();
        let _ = std::fs::remove_dir_all(&da);
        let _ = std::fs::remove_dir_all(&db);
    }
}

// The demo scenes (`scenes/`): what the thesis says the user feels in each.

/// Mean force over ticks `range`.
fn mean_force(forces: &[(f64, DVec3)], range: std::ops::Range<usize>) -> DVec3 {
    let n = range.len() as f64;
    range.map(|k| forces[k].1).sum::<DVec3>() / n
}

#[test]
fn the_wind_pushes_along_the_cones_axis_fading_with_distance_and_stops_outside_it() {
    let dir = scratch("demo-wind");
    // The cone's apex is at z = 0.1 in front of the fan, its axis +z, radius 0.9 at z = 2.5.
    let rows = [
        (0.0, DVec3::new(0.0, 0.0, 0.5)),
        (1.0, DVec3::new(0.0, 0.0, 0.5)),
        (2.0, DVec3::new(0.0, 0.0, 2.2)),
        (3.0, DVec3::new(0.0, 0.0, 2.2)),
        (4.0, DVec3::new(0.0, 1.2, 2.2)),
        (5.0, DVec3::new(0.0, 1.2, 2.2)),
    ];
    let forces = touch(&dir, &repo_file("scenes/wind.wrl"), &csv(&rows), &[]);
    let near = mean_force(&forces, 500..1000);
    let far = mean_force(&forces, 2500..3000);
    // Along the axis, away from the fan (0.6 of the Falcon's 8 N at the apex).
    assert!(
        near.z > 3.0 && near.z > 0.98 * near.length(),
        "near: {near}"
    );
    assert!(far.z > 0.5 && far.z > 0.98 * far.length(), "far: {far}");
    assert!(
        far.z < 0.5 * near.z,
        "fades with distance: {far} after {near}"
    );
    // Above the cone (its radius is 0.79 there) there is no wind at all.
    for (k, (_, f)) in forces.iter().enumerate().skip(4300) {
        assert_eq!(*f, DVec3::ZERO, "tick {k}: outside the cone");
    }
}

#[test]
fn the_demo_whirlpool_pulls_round_in_and_down() {
    let dir = scratch("demo-whirlpool");
    let mut rows = vec![(0.0, DVec3::new(0.8, 0.35, 0.0))];
    for k in 0..=100 {
        let angle = f64::from(k) * 0.03;
        rows.push((
            0.5 + f64::from(k) * 0.01,
            DVec3::new(0.8 * angle.cos(), 0.35, 0.8 * angle.sin()),
        ));
    }
    let path_csv = csv(&rows);
    let forces = touch(&dir, &repo_file("scenes/whirlpool.wrl"), &path_csv, &[]);
    let hips = points(&path_csv);
    for k in 300..1500 {
        let (f, hip) = (forces[k].1, hips[k]);
        let radial = DVec3::new(hip.x, 0.0, hip.z).normalize();
        let round = DVec3::Y.cross(radial);
        assert!(f.dot(round) > 3.0 * f.dot(radial).abs(), "tick {k}: {f}");
        assert!(f.dot(radial) < 0.0, "tick {k}: in towards the axis: {f}");
        assert!(f.y < 0.0, "tick {k}: down: {f}");
    }
}

#[test]
fn the_campus_walls_are_solid_and_the_lawn_is_softer() {
    let dir = scratch("demo-campus");
    // The library's east wall is the plane x = -0.7 (from y 0 to 1.2, z -1.4 to 0.2); a hand
    // comes from the east and rests 0.02 inside it, then goes down onto the lawn (y = 0) in
    // the open and rests 0.02 inside the ground.
    let rows = [
        (0.0, DVec3::new(-0.3, 0.6, -0.6)),
        (0.5, DVec3::new(-0.3, 0.6, -0.6)),
        (1.5, DVec3::new(-0.72, 0.6, -0.6)),
        (2.0, DVec3::new(-0.72, 0.6, -0.6)),
        (2.5, DVec3::new(-0.3, 0.6, -0.6)),
        (3.0, DVec3::new(-0.3, 0.6, 1.5)),
        (4.0, DVec3::new(-0.3, -0.02, 1.5)),
        (4.5, DVec3::new(-0.3, -0.02, 1.5)),
    ];
    let forces = touch(&dir, &repo_file("scenes/campus.wrl"), &csv(&rows), &[]);
    let wall = mean_force(&forces, 1800..2000);
    let lawn = mean_force(&forces, 4300..4500);
    // The wall pushes the hand straight back out, east.
    assert!(
        wall.x > 1.0 && wall.x > 0.95 * wall.length(),
        "wall: {wall}"
    );
    // The lawn pushes up, with less than a third of the wall's stiffness (0.3 against 1).
    assert!(
        lawn.y > 0.2 && lawn.y > 0.95 * lawn.length(),
        "lawn: {lawn}"
    );
    assert!(
        lawn.y < 0.5 * wall.x,
        "the lawn is softer: {lawn} against {wall}"
    );
    // In the open, above the lawn, nothing.
    assert_eq!(forces[2900].1, DVec3::ZERO);
}

/// The femur's resistance to a hand moving at 0.5 units a second along `rows`, averaged over
/// ticks `range`.
fn femur_drag(dir: &Path, rows: &[(f64, DVec3)], range: std::ops::Range<usize>) -> DVec3 {
    let forces = touch(dir, &repo_file("scenes/femur.wrl"), &csv(rows), &[]);
    mean_force(&forces, range)
}

#[test]
fn the_femurs_marrow_is_softer_than_its_bone() {
    // Into the femoral head (bone through and through: a ball of radius 0.3 at
    // (-0.5, 1.5, 0)) from above, and into the shaft's marrow (radius 0.12) from the side,
    // both at 0.5 units a second; the drag is measured 0.1 to 0.2 below the head's surface
    // zone and across the marrow's middle (x from 0.1 to 0.01).
    let head = [
        (0.0, DVec3::new(-0.5, 2.0, 0.0)),
        (0.5, DVec3::new(-0.5, 2.0, 0.0)),
        (1.5, DVec3::new(-0.5, 1.5, 0.0)),
    ];
    let bone = femur_drag(&scratch("demo-femur-head"), &head, 1140..1340);
    let shaft = [
        (0.0, DVec3::new(0.5, 0.0, 0.0)),
        (0.5, DVec3::new(0.5, 0.0, 0.0)),
        (1.5, DVec3::new(0.0, 0.0, 0.0)),
    ];
    let marrow = femur_drag(&scratch("demo-femur-shaft"), &shaft, 1300..1480);
    // Both resist the motion (the hand moves -y into the head and -x into the shaft).
    assert!(bone.y > 0.0 && bone.y > 0.9 * bone.length(), "bone: {bone}");
    assert!(
        marrow.x > 0.0 && marrow.x > 0.9 * marrow.length(),
        "marrow: {marrow}"
    );
    // Density 0.85 against 0.2: 0.24 N against 0.057 N when this was written.
    assert!(
        bone.length() > 3.0 * marrow.length(),
        "bone {bone} against marrow {marrow}"
    );
}

#[test]
fn a_shape_without_physics_does_not_hide_the_container_it_overlaps() {
    // A felt ball, then a plain VRML sphere of the same size over it (a polygon model's
    // stand-in): entered at once, the plain one used to be on top of the haptic stack and
    // the hand felt nothing. Objects without physics are seen, not felt.
    let dir = scratch("plain-over-felt");
    let scene = dir.join("scene.wrl");
    std::fs::write(
        &scene,
        "FShape { geometry Sphere { radius 1 }\n  physics FPhysics { surface FSurface {\n    \
         tension FTension { definition \"1\" } depth FDepth { definition \"0.05\" } } } }\n\
         Shape { geometry Sphere { radius 1 } }\n",
    )
    .unwrap();
    let rows = [
        (0.0, DVec3::new(0.0, 1.3, 0.0)),
        (0.3, DVec3::new(0.0, 1.3, 0.0)),
        (1.3, DVec3::new(0.0, 0.98, 0.0)),
        (1.6, DVec3::new(0.0, 0.98, 0.0)),
    ];
    let forces = touch(&dir, &scene, &csv(&rows), &[]);
    let resting = mean_force(&forces, 1400..1600);
    assert!(resting.y > 1.0, "the felt ball pushes back: {resting}");
}

/// The shark's heading and the centre of its wake at scene time `t_secs` (closed form of
/// `scenes/shark.wrl`'s motion: a circle of radius 1.3 every 10 s, nose along the circle, the
/// wake 1.35 behind the shark's centre).
fn shark_wake(t_secs: f64) -> (DVec3, DVec3) {
    let angle = std::f64::consts::TAU * t_secs / 10.0;
    let centre = 1.3 * DVec3::new(angle.cos(), 0.0, -angle.sin());
    let heading = DVec3::new(-angle.sin(), 0.0, -angle.cos());
    (heading, centre - 1.35 * heading)
}

#[test]
fn the_sharks_wake_follows_its_motion_in_time() {
    let dir = scratch("demo-shark");
    // The hand rests for a whole lap where the wake's middle passes a quarter of the way
    // round (t = 2.5 s), just outside the shark's circle.
    let (_, here) = shark_wake(2.5);
    let rows = [(0.0, here), (10.0, here)];
    let forces = touch(&dir, &repo_file("scenes/shark.wrl"), &csv(&rows), &[]);
    assert_eq!(forces.len(), 10_001);
    // While the wake passes, it drags the hand along the shark's heading at that instant, as
    // strongly as the field's closed form says: half of the Falcon's 8 N in the wake's middle,
    // fading towards its edge (semi-axes 0.5 along the shark, 0.3 across).
    let mut n_felt = 0;
    for k in (2200..=2800).step_by(50) {
        let (f, t) = (forces[k].1, forces[k].0);
        let (heading, centre) = shark_wake(t);
        let side = DVec3::Y.cross(heading);
        let offset = here - centre;
        let (u, w) = (offset.dot(heading) / 0.5, offset.dot(side) / 0.3);
        let expected = 8.0 * 0.5 * (1.0 - u * u - w * w).max(0.0);
        assert!(
            (f.length() - expected).abs() < 0.15 * expected + 0.05,
            "t = {t}: {f}, expected {expected} N along {heading}"
        );
        if expected > 0.5 {
            n_felt += 1;
            assert!(
                f.dot(heading) > 0.98 * f.length(),
                "t = {t}: {f} is not along {heading}"
            );
        }
    }
    assert!(n_felt >= 7, "{n_felt}");
    // The heading turns with the shark: a quarter lap later the wake is elsewhere, and for
    // the rest of the lap nothing touches the hand.
    for (k, (t, f)) in forces.iter().enumerate() {
        let (_, centre) = shark_wake(*t);
        if (here - centre).length() > 0.6 {
            assert_eq!(
                *f,
                DVec3::ZERO,
                "tick {k}: the wake is {centre}, far from {here}"
            );
        }
    }
}

/// The mean force felt pushing straight into the MRI demo's cut face (z = 0) at `(x, y)`,
/// from z = 0.3 to z = -0.3 at 0.6 units a second, while the hand is between z = `from` and
/// z = `to` (inside the head).
fn mri_drag(name: &str, x: f64, y: f64, from: f64, to: f64) -> DVec3 {
    let rows = [
        (0.0, DVec3::new(x, y, 0.3)),
        (0.5, DVec3::new(x, y, 0.3)),
        (1.5, DVec3::new(x, y, -0.3)),
    ];
    let forces = touch(
        &scratch(name),
        &repo_file("scenes/mri.wrl"),
        &csv(&rows),
        &[],
    );
    // z = 0.3 - 0.6 (t - 0.5); forces are written every millisecond.
    let ms = |z: f64| ((0.5 + (0.3 - z) / 0.6) * 1000.0) as usize;
    mean_force(&forces, ms(from)..ms(to))
}

#[test]
fn the_scans_density_is_felt_tissue_by_tissue() {
    // Straight into the cut face through brain, through the tumour's middle, and down a
    // ventricle (hollow: the fluid is below the solid's threshold).
    let brain = mri_drag("demo-mri-brain", -0.3, -0.3, -0.1, -0.25);
    let tumour = mri_drag("demo-mri-tumour", 0.24, 0.3, -0.04, -0.14);
    let ventricle = mri_drag("demo-mri-ventricle", -0.14, 0.12, -0.05, -0.2);
    // The tissue resists the motion (the hand moves -z).
    assert!(
        brain.z > 0.0 && brain.z > 0.9 * brain.length(),
        "brain: {brain}"
    );
    assert!(
        tumour.z > 0.0 && tumour.z > 0.9 * tumour.length(),
        "tumour: {tumour}"
    );
    // Density is the scan's value: the tumour (about 1 at its middle) against the brain
    // (0.6), and nothing in the hollow ventricle (0.36 N and 0.78 N and 0 when this was
    // written).
    assert!(
        tumour.length() > 1.4 * brain.length(),
        "tumour {tumour} against brain {brain}"
    );
    assert!(
        ventricle.length() < 0.2 * brain.length(),
        "ventricle {ventricle} against brain {brain}"
    );
}
