//! Trace tests over fdsl containers: scripted trajectories of a simulated hand driven through
//! `Servo::step` (device read, stack, forces, safety, device write), asserting stacks, forces,
//! continuity (a force jump per tick of at most 5% of the device's maximum) and passivity
//! (the energy the environment absorbed never below -epsilon on closed paths).
//!
//! (a) The thesis's Figure 4.6: S1 containing the interpenetrating S2 and S3, segments A-G.
//! (b) The watermelon of `tests/data/models/watermelon.fdsl`: tension, pop-through, crunchy
//!     density.
//! (c) The thesis's Figure 7.4: a helical field inside an invisible cylinder.
//! (d) Objects of the shared object model (`ObjectContainer`): the watermelon feels the same
//!     as its function container, a carved sphere is hollow, painted density is felt where
//!     it was painted only.
#![allow(
    clippy::unwrap_used,
    reason = "test helpers outside #[test] fns unwrap"
)]

use glam::DVec3;
use haptic::aabb::Aabb;
use haptic::container::Scene;
use haptic::container::function::FunctionContainer;
use haptic::container::object::ObjectContainer;
use haptic::container::properties::{PropertySpec, Scalar};
use haptic::device::sim::{HandModel, SimDevice, Waypoint};
use haptic::device::{Capabilities, DeviceSample};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, ProxyState, Region, Rig, render};
use haptic::servo::Servo;
use haptic::shapes::{Analytic, fdsl_watermelon, fdsl_whirlpool, object_watermelon};

const DT: f64 = 0.001;
const WATERMELON: &str = include_str!("../../tests/data/models/watermelon.fdsl");

fn rig(half_extent_world: f64) -> Rig {
    let caps = Capabilities::desktop_pen();
    let world = Aabb::new(
        DVec3::splat(-half_extent_world),
        DVec3::splat(half_extent_world),
    );
    Rig {
        caps,
        zone: HapticZone::fit(caps.workspace_metres, world),
        params: ForceParams::default(),
    }
}

/// One servo tick as the test sees it.
#[derive(Clone, Debug)]
struct Tick {
    tip_metres: DVec3,
    hip_world: DVec3,
    force_newtons: DVec3,
    velocity_device: DVec3,
    top_id: Option<u64>,
    region: Region,
    stack: Vec<u64>,
}

/// Runs the servo over `scene` with a simulated hand following `waypoints` (world points,
/// seconds) for `n_ticks`.
fn run_servo<S: Scene>(
    scene: S,
    rig: &Rig,
    waypoints: &[(f64, DVec3)],
    n_ticks: usize,
) -> Vec<Tick> {
    let waypoints = waypoints
        .iter()
        .map(|&(t_secs, p_world)| Waypoint {
            t_secs,
            position_metres: p_world / rig.zone.world_per_device_metre,
        })
        .collect();
    let device = SimDevice::new(rig.caps, waypoints, HandModel::default(), DT).unwrap();
    let (mut servo, link) = Servo::init(device, *rig);
    link.scenes.publish(Box::new(scene));
    (0..n_ticks)
        .map(|_| {
            let out = servo.step(DT);
            let tip_metres = servo.device().tip_metres();
            Tick {
                tip_metres,
                hip_world: rig.zone.world_from_device(tip_metres),
                force_newtons: out.force_newtons,
                velocity_device: servo.state().velocity_device(),
                top_id: out.top_id,
                region: out.region,
                stack: servo
                    .state()
                    .stack()
                    .entries()
                    .iter()
                    .map(|e| e.id)
                    .collect(),
            }
        })
        .collect()
}

/// The continuity guarantee: no force jump above 5% of the maximum, never above the maximum.
fn assert_continuous(ticks: &[Tick], caps: &Capabilities) {
    let limit = 0.05 * caps.force_newtons_max + 1e-9;
    for (k, pair) in ticks.windows(2).enumerate() {
        let jump = (pair[1].force_newtons - pair[0].force_newtons).length();
        assert!(
            jump <= limit,
            "tick {k}: force jumped {jump} N (limit {limit})"
        );
        assert!(pair[1].force_newtons.length() <= caps.force_newtons_max + 1e-9);
    }
}

/// The lowest running total of the energy the environment absorbed: the force sent after a
/// sample acts while the tip moves to the next one.
fn absorbed_energy_min(ticks: &[Tick]) -> (f64, f64) {
    let mut energy = 0.0;
    let mut energy_min: f64 = 0.0;
    for pair in ticks.windows(2) {
        energy -= pair[0]
            .force_newtons
            .dot(pair[1].tip_metres - pair[0].tip_metres);
        energy_min = energy_min.min(energy);
    }
    (energy, energy_min)
}

fn parse(text: &str) -> fdsl::Function {
    fdsl::Function::parse(text).unwrap()
}

/// A sphere container from an fdsl text with a constant density given as a function.
fn fdsl_sphere(id: u64, x: f64, radius: f64, density: f64) -> FunctionContainer {
    let text = format!("{radius}^2 - (x - ({x}))^2 - y^2 - z^2");
    let props = PropertySpec {
        density: Some(Scalar::Function(parse(&density.to_string()))),
        ..PropertySpec::default()
    };
    let center = DVec3::new(x, 0.0, 0.0);
    FunctionContainer::new(
        id,
        &parse(&text),
        (center - radius, center + radius),
        &props,
    )
    .unwrap()
}

/// Figure 4.6: S1 (id 1) contains S2 (id 2) and S3 (id 3), which interpenetrate; listed S1,
/// S3, S2 so that the scene order differs from the crossing order.
fn figure_4_6() -> Vec<FunctionContainer> {
    vec![
        fdsl_sphere(1, 0.0, 1.0, 0.1),
        fdsl_sphere(3, 0.2, 0.3, 0.8),
        fdsl_sphere(2, -0.15, 0.35, 0.4),
    ]
}

/// Surfaces crossed along the x axis: S1 at -1 and 1, S2 at -0.5 and 0.2, S3 at -0.1 and 0.5.
const BOUNDARIES: [f64; 6] = [-1.0, -0.5, -0.1, 0.2, 0.5, 1.0];

/// Segment letter and the stack the thesis expects there, walking left to right.
fn segment_left_to_right(x: f64) -> (char, &'static [u64]) {
    match x {
        x if x < -1.0 => ('A', &[]),
        x if x < -0.5 => ('B', &[1]),
        x if x < -0.1 => ('C', &[1, 2]),
        x if x < 0.2 => ('D', &[1, 2, 3]),
        x if x < 0.5 => ('E', &[1, 3]),
        x if x < 1.0 => ('F', &[1]),
        _ => ('G', &[]),
    }
}

/// Walking back, right to left: S3 is entered before S2, so S2 rules in D (the thesis's
/// "confusing exception").
fn segment_right_to_left(x: f64) -> &'static [u64] {
    match x {
        x if x > 1.0 => &[],
        x if x > 0.5 => &[1],
        x if x > 0.2 => &[1, 3],
        x if x > -0.1 => &[1, 3, 2],
        x if x > -0.5 => &[1, 2],
        x if x > -1.0 => &[1],
        _ => &[],
    }
}

#[test]
fn figure_4_6_stack_walk_there_and_back_through_the_servo() {
    let rig = rig(1.6);
    let start = DVec3::new(-1.4, 0.0, 0.0);
    let turn = DVec3::new(1.4, 0.0, 0.0);
    let path = [
        (0.0, start),
        (3.0, turn),
        (3.2, turn),
        (6.2, start),
        (6.5, start),
    ];
    let ticks = run_servo(figure_4_6(), &rig, &path, 6500);
    let mut n_per_segment = std::collections::BTreeMap::new();
    for (k, tick) in ticks.iter().enumerate() {
        let x = tick.hip_world.x;
        if BOUNDARIES.iter().any(|b| (x - b).abs() < 1e-6) {
            continue;
        }
        let expected = if k < 3100 {
            let (letter, expected) = segment_left_to_right(x);
            *n_per_segment.entry(letter).or_insert(0) += 1;
            expected
        } else {
            segment_right_to_left(x)
        };
        assert_eq!(tick.stack, expected, "tick {k} at x = {x}");
        assert_eq!(tick.top_id, expected.last().copied(), "tick {k}");
        // Away from surfaces (past the cross-fade), the top container's density rules:
        // F = -density * damping_max * filtered velocity.
        let clear = BOUNDARIES.iter().all(|b| (x - b).abs() > 0.05);
        if clear && k > 300 {
            let density = match tick.top_id {
                Some(1) => 0.1,
                Some(2) => 0.4,
                Some(3) => 0.8,
                _ => 0.0,
            };
            let expected_force =
                -tick.velocity_device * density * rig.caps.damping_newton_secs_per_metre_max;
            assert!(
                (tick.force_newtons - expected_force).length() < 0.02,
                "tick {k}: {} vs {expected_force}",
                tick.force_newtons
            );
        }
    }
    assert_eq!(n_per_segment.len(), 7, "{n_per_segment:?}");
    assert!(
        n_per_segment.values().all(|&n| n >= 100),
        "{n_per_segment:?}"
    );
    assert_continuous(&ticks, &rig.caps);
    let (energy, energy_min) = absorbed_energy_min(&ticks);
    assert!(energy_min >= -1e-9, "energy dipped to {energy_min} J");
    assert!(energy > 1e-4, "density dissipates: {energy} J");
}

/// The watermelon hand: down through the rind from above, into the flesh, and back out.
fn watermelon_path() -> [(f64, DVec3); 4] {
    let at = |y: f64| DVec3::new(-0.2, y, -0.2);
    [
        (0.0, at(1.2)),
        (2.5, at(0.0)),
        (2.7, at(0.0)),
        (5.2, at(1.2)),
    ]
}

#[test]
fn fdsl_watermelon_tension_pops_then_crunchy_density() {
    let rig = rig(1.6);
    let geometry = parse(WATERMELON);
    let melon = vec![fdsl_watermelon(7, &geometry, DVec3::ZERO, 1.0).unwrap()];
    let ticks = run_servo(melon, &rig, &watermelon_path(), 5400);
    let first_surface = ticks
        .iter()
        .position(|t| t.region == Region::Surface)
        .unwrap();
    let first_interior = ticks
        .iter()
        .position(|t| t.region == Region::Interior)
        .unwrap();
    assert!(
        ticks[..first_surface].iter().all(|t| t.top_id.is_none()),
        "free approach"
    );
    assert!(
        first_surface < first_interior,
        "tension comes before density"
    );
    // Surface: tension pushes out (+y) and grows with depth until the membrane pops.
    let rind = &ticks[first_surface..first_interior];
    assert!(
        rind.iter()
            .all(|t| t.force_newtons.y >= 0.0 && t.top_id == Some(7))
    );
    let peak = rind.iter().map(|t| t.force_newtons.y).fold(0.0, f64::max);
    assert!(peak > 1.5, "peak tension {peak} N");
    let pop_depth = 1.0 - ticks[first_interior].hip_world.length();
    assert!(
        (0.03..0.08).contains(&pop_depth),
        "pops near the zone depth 0.05: {pop_depth}"
    );
    // Flesh, going down: density resists, with crunchy layers (force over speed peaks).
    let flesh: Vec<&Tick> = ticks[first_interior + 50..2500]
        .iter()
        .filter(|t| t.region == Region::Interior)
        .collect();
    assert!(flesh.len() > 1000);
    let mut ratios = vec![];
    for t in &flesh {
        let speed = t.velocity_device.length();
        if speed > 1e-3 {
            assert!(
                t.force_newtons.dot(t.velocity_device) <= 1e-9,
                "density resists motion"
            );
            ratios.push(t.force_newtons.length() / speed);
        }
    }
    let n_peaks = ratios
        .windows(3)
        .filter(|w| w[1] > w[0] && w[1] > w[2])
        .count();
    assert!(n_peaks >= 3, "crunchy layers felt: {n_peaks}");
    // Back out: the stack empties again.
    assert_eq!(ticks.last().unwrap().top_id, None);
    assert_continuous(&ticks, &rig.caps);
    let (energy, energy_min) = absorbed_energy_min(&ticks);
    assert!(energy_min >= -1e-5, "energy dipped to {energy_min} J");
    assert!(energy > 0.0, "{energy} J");
}

#[test]
fn fdsl_whirlpool_field_matches_the_closed_form_and_pulls_the_hand_round() {
    let rig = rig(2.0);
    let s = rig.zone.world_per_device_metre;
    // Kinematic: at the same HIPs the fdsl container and the closed-form one render the same
    // forces (same field mapping, same timing), on a circle inside and above the lid.
    let mut fdsl_scene = vec![fdsl_whirlpool(9).unwrap()];
    let mut closed_form = vec![Analytic::whirlpool(9)];
    let (mut a_state, mut b_state) = (ProxyState::new(), ProxyState::new());
    for k in 0..2000u32 {
        let angle = f64::from(k) * 0.005;
        let y = if k < 1500 { 0.35 } else { 0.9 };
        let p = DVec3::new(0.8 * angle.cos(), y, 0.8 * angle.sin());
        let sample = DeviceSample::at(p / s, u64::from(k) * 1000);
        let t = f64::from(k) * DT;
        let a = render(&mut fdsl_scene, &mut a_state, &rig, &sample, t, DT);
        let b = render(&mut closed_form, &mut b_state, &rig, &sample, t, DT);
        assert!(
            (a.force_newtons - b.force_newtons).length() < 1e-9,
            "tick {k}"
        );
        assert_eq!((a.top_id, a.region), (b.top_id, b.region));
        if k == 1400 {
            assert!(a.force_newtons.length() > 3.0, "{a:?}");
        }
        if k == 1999 {
            assert_eq!(a.force_newtons, DVec3::ZERO, "no field above the lid");
        }
    }
    // Closed loop: a hand resting inside is pulled round the axis and down.
    let rest = DVec3::new(0.8, 0.35, 0.0);
    let ticks = run_servo(vec![fdsl_whirlpool(9).unwrap()], &rig, &[(0.0, rest)], 1500);
    let last = ticks.last().unwrap();
    assert_eq!((last.top_id, last.region), (Some(9), Region::Interior));
    let radial = DVec3::new(last.hip_world.x, 0.0, last.hip_world.z).normalize();
    let tangential = DVec3::Y.cross(radial);
    let f = last.force_newtons;
    assert!(f.dot(tangential).abs() > 3.0 * f.dot(radial).abs(), "{f}");
    assert!(f.y < 0.0, "down the pool: {f}");
    assert!(
        last.hip_world.distance(rest) > 0.1,
        "the hand yields to the field"
    );
    assert_continuous(&ticks, &rig.caps);
}

#[test]
fn object_model_watermelon_feels_like_its_function_container() {
    let rig = rig(1.6);
    let (center, radius) = (DVec3::new(0.3, -0.2, 0.1), 0.8);
    let path = watermelon_path().map(|(t, p)| (t, center + p * radius));
    let function = vec![fdsl_watermelon(7, &parse(WATERMELON), center, radius).unwrap()];
    let object = object_watermelon(WATERMELON, center, radius).unwrap();
    let objects = vec![ObjectContainer::from_object(7, &object, Default::default()).unwrap()];
    let a = run_servo(function, &rig, &path, 5400);
    let b = run_servo(objects, &rig, &path, 5400);
    let mut n_regions = [0; 3];
    for (k, (a, b)) in a.iter().zip(&b).enumerate() {
        assert!(
            (a.force_newtons - b.force_newtons).length() < 1e-6,
            "tick {k}: {} vs {}",
            a.force_newtons,
            b.force_newtons
        );
        assert_eq!((a.top_id, a.region), (b.top_id, b.region), "tick {k}");
        n_regions[a.region as usize] += 1;
    }
    // The trace went through every region: free, the rind's zone and the flesh.
    assert!(n_regions.iter().all(|&n| n > 100), "{n_regions:?}");
    let peak = b.iter().map(|t| t.force_newtons.y).fold(0.0, f64::max);
    assert!(peak > 1.0, "the rind pushes back: {peak} N");
}

/// A unit ball (`1 - |p|`) with a tense surface and some density, in a domain.
fn ball_object() -> model::object::Object {
    use model::object::{Domain, Formula, Geometry, Object, ObjectData, Physics, Property};
    let property = |text: &str| Some(Property::new(Formula::new(text).unwrap()));
    Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new("1 - sqrt(x^2 + y^2 + z^2)").unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        physics: Physics {
            tension: property("0.8"),
            zone_depth: property("0.05"),
            density: property("0.3"),
            ..Physics::default()
        }
        .into(),
        ..ObjectData::default()
    })
    .unwrap()
}

#[test]
fn carved_object_is_hollow_where_carved() {
    use model::object::{Edit, EditOp, Pose, ToolShape};
    let rig = rig(1.6);
    let solid = ball_object();
    let mut carved = solid.clone();
    carved
        .apply(Edit::stamp(
            EditOp::Subtract,
            ToolShape::Sphere { radius: 0.5 },
            Pose::at(DVec3::ZERO),
        ))
        .unwrap();
    // From the centre out through the cavity wall into the shell, and out of the ball.
    let path = [
        (0.0, DVec3::ZERO),
        (0.5, DVec3::ZERO),
        (2.0, DVec3::new(0.6, 0.0, 0.0)),
        (2.5, DVec3::new(0.6, 0.0, 0.0)),
        (3.5, DVec3::new(1.3, 0.0, 0.0)),
    ];
    let scene = |object: &model::object::Object| {
        vec![ObjectContainer::from_object(3, object, Default::default()).unwrap()]
    };
    let solid_ticks = run_servo(scene(&solid), &rig, &path, 3600);
    assert_eq!(
        (solid_ticks[400].top_id, solid_ticks[400].region),
        (Some(3), Region::Interior),
        "uncarved, the centre is inside"
    );
    let ticks = run_servo(scene(&carved), &rig, &path, 3600);
    let mut n_cavity = 0;
    let mut n_shell = 0;
    for (k, tick) in ticks.iter().enumerate() {
        let r = tick.hip_world.length();
        if r < 0.48 {
            assert_eq!(tick.top_id, None, "tick {k}: hollow at r = {r}");
            n_cavity += 1;
        } else if (0.52..0.98).contains(&r) {
            assert_eq!(tick.top_id, Some(3), "tick {k}: shell at r = {r}");
            n_shell += 1;
        }
    }
    assert!(n_cavity > 1000 && n_shell > 200, "{n_cavity} {n_shell}");
    // Pressing into the cavity wall from inside, tension pushes back towards the centre.
    let push = ticks
        .iter()
        .filter(|t| t.region == Region::Surface && t.hip_world.x < 0.6)
        .map(|t| t.force_newtons.x)
        .fold(0.0, f64::min);
    assert!(push < -0.5, "the wall pushes back: {push} N");
    assert_continuous(&ticks, &rig.caps);
}

#[test]
fn painted_density_is_felt_inside_the_painted_region_only() {
    use model::object::{Domain, Edit, EditOp, Formula, Geometry, Object, ObjectData};
    use model::object::{PaintValue, Paintable, Pose, ToolShape};
    let rig = rig(1.6);
    // No density of its own: only the paint defines one.
    let mut object = Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new("1 - sqrt(x^2 + y^2 + z^2)").unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    })
    .unwrap();
    let (paint_center, paint_radius) = (DVec3::new(0.4, 0.0, 0.0), 0.3);
    object
        .apply(Edit::stamp(
            EditOp::Paint {
                property: Paintable::Density,
                value: PaintValue::Scalar(0.9),
            },
            ToolShape::Sphere {
                radius: paint_radius,
            },
            Pose::at(paint_center),
        ))
        .unwrap();
    let scene = vec![ObjectContainer::from_object(4, &object, Default::default()).unwrap()];
    let path = [
        (0.0, DVec3::new(-1.3, 0.0, 0.0)),
        (3.0, DVec3::new(1.3, 0.0, 0.0)),
        (3.2, DVec3::new(1.3, 0.0, 0.0)),
    ];
    let ticks = run_servo(scene, &rig, &path, 3200);
    let (mut n_painted, mut n_plain) = (0, 0);
    for (k, tick) in ticks.iter().enumerate().skip(300) {
        let x = tick.hip_world.x;
        let to_paint = (tick.hip_world - paint_center).length() - paint_radius;
        if tick.top_id != Some(4) || (x.abs() - 1.0).abs() < 0.05 || to_paint.abs() < 0.05 {
            continue;
        }
        let density = if to_paint < 0.0 { 0.9 } else { 0.0 };
        let expected = -tick.velocity_device * density * rig.caps.damping_newton_secs_per_metre_max;
        assert!(
            (tick.force_newtons - expected).length() < 0.02,
            "tick {k} at x = {x}: {} vs {expected}",
            tick.force_newtons
        );
        if to_paint < 0.0 {
            assert!(expected.length() > 0.1, "tick {k}: felt {expected}");
            n_painted += 1;
        } else {
            n_plain += 1;
        }
    }
    assert!(n_painted > 200 && n_plain > 500, "{n_painted} {n_plain}");
}
