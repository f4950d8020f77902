//! Proves that `Servo::step` never allocates: a counting global allocator armed around ticks
//! that cross containers (closed-form, fdsl functions with properties and fields, meshes
//! located by haptic rays, objects of the object model with 10^4 sculpting edits each, a
//! moving object with a force field), swap snapshots, stall and lose the device.
#![allow(
    clippy::unwrap_used,
    reason = "test helpers outside #[test] fns unwrap"
)]

use glam::DVec3;
use haptic::aabb::Aabb;
use haptic::container::Container;
use haptic::container::mesh::{MeshContainer, RayParams};
use haptic::container::object::ObjectContainer;
use haptic::container::properties::{PropertySpec, Scalar};
use haptic::device::Capabilities;
use haptic::device::sim::{HandModel, SimDevice};
use haptic::device::trace::{Trace, TraceDevice};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, Rig};
use haptic::servo::Servo;
use haptic::shapes::{
    circle_waypoints, fdsl_watermelon_grid, fdsl_whirlpool, icosphere, object_watermelon_scene,
    sphere_dents, watermelon_grid,
};
use testkit::alloc::{CountingAlloc, allocations_in as count_allocs};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

fn rig() -> Rig {
    let caps = Capabilities::desktop_pen();
    let world = Aabb::new(DVec3::splat(-1.6), DVec3::splat(1.6));
    Rig {
        caps,
        zone: HapticZone::fit(caps.workspace_metres, world),
        params: ForceParams::default(),
    }
}

#[test]
fn servo_step_never_allocates() {
    // The counter works: an allocation while armed is seen.
    assert_eq!(
        count_allocs(|| drop(std::hint::black_box(vec![1u8; 16]))),
        2
    );

    let caps = Capabilities::desktop_pen();
    let device = SimDevice::new(
        caps,
        circle_waypoints(0.05, 0.5, 8),
        HandModel::default(),
        0.001,
    )
    .unwrap();
    let (mut servo, link) = Servo::init(device, rig());
    link.scenes.publish(Box::new(watermelon_grid(64)));
    // A shared tool runs too, its partner's packets arriving between ticks.
    link.shared.start(haptic::shared::DEFAULT_COUPLING);
    let mut n_allocs = 0;
    let mut n_crossing_ticks = 0;
    let mut last_top = None;
    for round in 0..8 {
        n_allocs += count_allocs(|| {
            for tick in 0..500 {
                // One long tick per round: the stall path, then the ramp back in.
                let dt = if tick == 250 { 0.02 } else { 0.001 };
                link.shared.deliver(&haptic::force::wave::WavePacket {
                    t_secs: f64::from(round * 500 + tick) * 1e-3,
                    wave: DVec3::new(0.1, 0.0, -0.1),
                    energy_sent_joules: f64::from(tick) * 1e-3,
                });
                let out = servo.step(dt);
                let _ = link.shared.take_outgoing();
                if out.top_id != last_top {
                    n_crossing_ticks += 1;
                    last_top = out.top_id;
                }
            }
        });
        // App side, allocation allowed: a new snapshot, collect the retired one.
        link.scenes
            .publish(Box::new(watermelon_grid(if round % 2 == 0 {
                16
            } else {
                64
            })));
        link.collect_retired();
    }
    assert_eq!(n_allocs, 0, "Servo::step allocated");
    assert!(
        n_crossing_ticks > 20,
        "the path crossed containers: {n_crossing_ticks}"
    );
    assert!(link.stats.snapshot().n_stalls >= 8);
    assert!(link.shared.energy_in_joules() > 0.0, "the coupling ran");

    // The device-failure path does not allocate either.
    let trace = Trace {
        caps,
        events: vec![],
    };
    let (mut servo, _link) =
        Servo::<_, Vec<haptic::shapes::Analytic>>::init(TraceDevice::new(&trace), rig());
    assert_eq!(
        count_allocs(|| for _ in 0..10 {
            servo.step(0.001);
        }),
        0
    );
}

/// A mixed scene: 64 fdsl watermelons, the fdsl whirlpool (a force field) and two mesh spheres
/// on the circle the tip follows.
fn mixed_scene(n_melons: usize) -> Vec<Box<dyn Container>> {
    let geometry =
        fdsl::Function::parse(include_str!("../../tests/data/models/watermelon.fdsl")).unwrap();
    let mut scene: Vec<Box<dyn Container>> = fdsl_watermelon_grid(&geometry, n_melons)
        .unwrap()
        .into_iter()
        .map(|c| Box::new(c) as Box<dyn Container>)
        .collect();
    scene.push(Box::new(fdsl_whirlpool(1000).unwrap()));
    let props = PropertySpec {
        tension: Some(Scalar::Constant(0.5)),
        zone_depth: Some(Scalar::Constant(0.05)),
        density: Some(Scalar::Function(
            fdsl::Function::parse("0.3 + 0.2*x").unwrap(),
        )),
        ..PropertySpec::default()
    };
    for (k, x) in [(0u64, 1.0), (1, -1.0)] {
        let (vertices, triangles) = icosphere(DVec3::new(x, 0.0, 0.0), 0.3, 3);
        let mesh = MeshContainer::new(
            2000 + k,
            &vertices,
            &triangles,
            &props,
            RayParams::default(),
        )
        .unwrap();
        scene.push(Box::new(mesh));
    }
    scene
}

#[test]
fn servo_step_over_fdsl_and_mesh_containers_never_allocates() {
    let caps = Capabilities::desktop_pen();
    let device = SimDevice::new(
        caps,
        circle_waypoints(0.05, 0.5, 8),
        HandModel::default(),
        0.001,
    )
    .unwrap();
    let (mut servo, link) = Servo::init(device, rig());
    link.scenes.publish(Box::new(mixed_scene(64)));
    let mut n_allocs = 0;
    // Ids seen on top; a fixed array, since inserting into a set would allocate while armed.
    let mut seen = [false; 2048];
    for round in 0..8 {
        n_allocs += count_allocs(|| {
            for tick in 0..500 {
                let dt = if tick == 250 { 0.02 } else { 0.001 };
                link.shared.deliver(&haptic::force::wave::WavePacket {
                    t_secs: f64::from(round * 500 + tick) * 1e-3,
                    wave: DVec3::new(0.1, 0.0, -0.1),
                    energy_sent_joules: f64::from(tick) * 1e-3,
                });
                let out = servo.step(dt);
                let _ = link.shared.take_outgoing();
                if let Some(top) = out.top_id {
                    seen[top as usize % seen.len()] = true;
                }
            }
        });
        link.scenes
            .publish(Box::new(mixed_scene(if round % 2 == 0 { 16 } else { 64 })));
        link.collect_retired();
    }
    assert_eq!(n_allocs, 0, "Servo::step allocated");
    // The path went through fdsl watermelons and both mesh spheres.
    let n_melons_touched = seen[1..=64].iter().filter(|&&s| s).count();
    assert!(n_melons_touched >= 4, "{n_melons_touched}");
    assert!(seen[2000] && seen[2001], "both mesh spheres");
}

/// A ball of radius 0.25 on the tip's circle, swaying along x, with a force field along +z.
fn moving_field_ball() -> ObjectContainer {
    use model::object::{
        Domain, ForceField, Formula, Geometry, Motion, Object, ObjectData, Physics, Timing,
        Transform,
    };
    let formula = |text: &str| Formula::new(text).unwrap();
    let object = Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            formula("0.25 - sqrt(x^2 + y^2 + z^2)"),
            Domain::new(DVec3::ZERO, DVec3::splat(0.6)),
        )),
        physics: Physics {
            force: Some(ForceField {
                formula: formula("x = 0; y = 0; z = 0.5 * u;"),
                parameters: [[0.0, 1.0]; 3],
                timing: Timing::default(),
                enabled: true,
            }),
            ..Physics::default()
        }
        .into(),
        transform: Transform::translate(DVec3::new(0.0, 1.0, 0.0)),
        motion: Some(Motion {
            translation: Some(formula("x = 0.1 * sin(t); y = 0; z = 0;")),
            axis: DVec3::Y,
            angle: None,
            timing: Timing::default(),
        }),
        ..ObjectData::default()
    })
    .unwrap();
    ObjectContainer::from_object(3000, &object, Transform::IDENTITY).unwrap()
}

/// The containers of an object-model scene, and the moving field ball.
fn object_containers(scene: &model::scene::Scene) -> Vec<ObjectContainer> {
    let (mut containers, refused) = ObjectContainer::from_scene(scene);
    assert!(refused.is_empty());
    containers.push(moving_field_ball());
    containers
}

#[test]
fn servo_step_over_object_containers_never_allocates() {
    // 64 watermelons carved with 10^4 dents each, and 16 plain ones.
    let geometry = include_str!("../../tests/data/models/watermelon.fdsl");
    let dents = sphere_dents(10_000, 0.02).unwrap();
    let dented = object_watermelon_scene(geometry, 64, &dents).unwrap();
    assert_eq!(
        dented
            .object(model::scene::ObjectId(1))
            .unwrap()
            .history()
            .len(),
        10_000
    );
    let plain = object_watermelon_scene(geometry, 16, &[]).unwrap();
    let caps = Capabilities::desktop_pen();
    let device = SimDevice::new(
        caps,
        circle_waypoints(0.05, 0.5, 8),
        HandModel::default(),
        0.001,
    )
    .unwrap();
    let (mut servo, link) = Servo::init(device, rig());
    link.scenes.publish(Box::new(object_containers(&dented)));
    let mut n_allocs = 0;
    let mut seen = [false; 4096];
    for round in 0..8 {
        n_allocs += count_allocs(|| {
            for tick in 0..500 {
                let dt = if tick == 250 { 0.02 } else { 0.001 };
                link.shared.deliver(&haptic::force::wave::WavePacket {
                    t_secs: f64::from(round * 500 + tick) * 1e-3,
                    wave: DVec3::new(0.1, 0.0, -0.1),
                    energy_sent_joules: f64::from(tick) * 1e-3,
                });
                let out = servo.step(dt);
                let _ = link.shared.take_outgoing();
                if let Some(top) = out.top_id {
                    seen[top as usize % seen.len()] = true;
                }
            }
        });
        // Every other snapshot has no edits: swapping histories of different lengths.
        let next = if round % 2 == 0 { &plain } else { &dented };
        link.scenes.publish(Box::new(object_containers(next)));
        link.collect_retired();
    }
    assert_eq!(n_allocs, 0, "Servo::step allocated");
    let n_melons_touched = seen[1..=64].iter().filter(|&&s| s).count();
    assert!(n_melons_touched >= 4, "{n_melons_touched}");
    assert!(seen[3000], "the moving field ball");
}
