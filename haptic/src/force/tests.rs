//! Trace tests of force rendering: the thesis's Figure 4.6 stack walk, the watermelon, a force
//! field in an invisible cylinder, continuity, passivity and stalls; and over the real container
//! kinds: a mesh sphere against the closed-form one, the device's surface zone on an object
//! that gives no depth.

use glam::DVec3;

use super::zone::HapticZone;
use super::*;
use crate::aabb::Aabb;
use crate::container::{Container, FieldDomain};
use crate::device::sim::{HandModel, SimDevice, Waypoint};
use crate::device::{Capabilities, DeviceSample, HapticDevice};
use crate::shapes::{Analytic, Density, Field, Solid};

const DT: f64 = 0.001;

fn rig(half_extent_world: f64) -> Rig {
    let caps = Capabilities::desktop_pen();
    let box_world = Aabb::new(
        DVec3::splat(-half_extent_world),
        DVec3::splat(half_extent_world),
    );
    Rig {
        caps,
        zone: HapticZone::fit(caps.workspace_metres, box_world),
        params: ForceParams::default(),
    }
}

struct Run {
    positions: Vec<DVec3>,
    outputs: Vec<TickOutput>,
    stacks: Vec<Vec<u64>>,
}

/// Drives the renderer with the tip at given device positions, one per millisecond.
fn drive_kinematic<S: Scene>(scene: &mut S, rig: &Rig, positions: &[DVec3]) -> Run {
    let mut state = ProxyState::new();
    let mut run = Run {
        positions: positions.to_vec(),
        outputs: vec![],
        stacks: vec![],
    };
    for (k, &p) in positions.iter().enumerate() {
        let sample = DeviceSample::at(p, k as u64 * 1000);
        let out = render(scene, &mut state, rig, &sample, k as f64 * DT, DT);
        run.outputs.push(out);
        run.stacks
            .push(state.stack().entries().iter().map(|e| e.id).collect());
    }
    run
}

/// Drives the renderer with a simulated hand that yields to the rendered force.
fn drive_sim<S: Scene>(scene: &mut S, rig: &Rig, mut dev: SimDevice, n_ticks: usize) -> Run {
    let mut state = ProxyState::new();
    let mut run = Run {
        positions: vec![],
        outputs: vec![],
        stacks: vec![],
    };
    for k in 0..n_ticks {
        let sample = dev.sample().unwrap();
        let out = render(scene, &mut state, rig, &sample, k as f64 * DT, DT);
        dev.set_force(out.force_newtons).unwrap();
        run.positions.push(sample.position_metres);
        run.outputs.push(out);
        run.stacks
            .push(state.stack().entries().iter().map(|e| e.id).collect());
    }
    run
}

fn line(from: DVec3, to: DVec3, n: usize) -> Vec<DVec3> {
    (0..n)
        .map(|k| from.lerp(to, k as f64 / (n - 1) as f64))
        .collect()
}

/// Asserts the continuity guarantee and returns the largest raw (pre-safety) jump.
fn assert_continuous(run: &Run, caps: &Capabilities) -> f64 {
    let limit = 0.05 * caps.force_newtons_max + 1e-9;
    let mut raw_jump_max: f64 = 0.0;
    for (k, pair) in run.outputs.windows(2).enumerate() {
        let jump = (pair[1].force_newtons - pair[0].force_newtons).length();
        assert!(
            jump <= limit,
            "tick {k}: force jumped {jump} N (limit {limit})"
        );
        assert!(pair[1].force_newtons.length() <= caps.force_newtons_max + 1e-9);
        raw_jump_max =
            raw_jump_max.max((pair[1].raw_force_newtons - pair[0].raw_force_newtons).length());
    }
    raw_jump_max
}

/// Energy the environment absorbed, computed independently: the sum of `-F_k . dx_k`
/// over the passive part of the output (fields are active by design).
fn absorbed_energy(run: &Run) -> (f64, f64) {
    let mut energy = 0.0;
    let mut energy_min: f64 = 0.0;
    for k in 0..run.positions.len() - 1 {
        energy -= run.outputs[k]
            .force_newtons
            .dot(run.positions[k + 1] - run.positions[k]);
        energy_min = energy_min.min(energy);
    }
    (energy, energy_min)
}

/// The thesis's Figure 4.6: S1 contains the interpenetrating S2 and S3 on the x axis.
/// Listed S1, S3, S2 so that iteration order differs from crossing order.
fn figure_4_6() -> Vec<Analytic> {
    let sphere = |id, x: f64, radius, density| Analytic {
        density: Some(Density::Uniform(density)),
        ..Analytic::new(
            id,
            Solid::Sphere {
                center: DVec3::new(x, 0.0, 0.0),
                radius,
            },
        )
    };
    vec![
        sphere(1, 0.0, 1.0, 0.1),
        sphere(3, 0.2, 0.3, 0.8),
        sphere(2, -0.15, 0.35, 0.4),
    ]
}

/// World x at the middle of segments A..G of Figure 4.6 and the stack expected there.
const FIGURE_4_6_WALK: [(char, f64, &[u64]); 7] = [
    ('A', -1.2, &[]),
    ('B', -0.75, &[1]),
    ('C', -0.3, &[1, 2]),
    ('D', 0.05, &[1, 2, 3]),
    ('E', 0.35, &[1, 3]),
    ('F', 0.75, &[1]),
    ('G', 1.2, &[]),
];

#[test]
fn figure_4_6_stack_walk_left_to_right() {
    let rig = rig(1.6);
    let mut scene = figure_4_6();
    let s = rig.zone.world_per_device_metre;
    let path = line(
        DVec3::new(-1.4 / s, 0.0, 0.0),
        DVec3::new(1.4 / s, 0.0, 0.0),
        3001,
    );
    let run = drive_kinematic(&mut scene, &rig, &path);
    let speed = (2.8 / s) / 3.0;
    for (segment, x, expected) in FIGURE_4_6_WALK {
        let k = ((x + 1.4) / 2.8 * 3000.0).round() as usize;
        assert_eq!(run.stacks[k], expected, "segment {segment}");
        let out = run.outputs[k];
        assert_eq!(out.top_id, expected.last().copied(), "segment {segment}");
        // The top rules: the density felt is the top container's.
        let density = match out.top_id {
            Some(1) => 0.1,
            Some(2) => 0.4,
            Some(3) => 0.8,
            _ => 0.0,
        };
        let expected_fx = -density * rig.caps.damping_newton_secs_per_metre_max * speed;
        assert!(
            (out.raw_force_newtons.x - expected_fx).abs() < 1e-3,
            "segment {segment}: {} vs {expected_fx}",
            out.raw_force_newtons.x
        );
    }
    assert_continuous(&run, &rig.caps);
    assert!(absorbed_energy(&run).1 >= -1e-9);
}

#[test]
fn figure_4_6_walk_right_to_left_enters_s3_first() {
    let rig = rig(1.6);
    let mut scene = figure_4_6();
    let s = rig.zone.world_per_device_metre;
    let path = line(
        DVec3::new(1.4 / s, 0.0, 0.0),
        DVec3::new(-1.4 / s, 0.0, 0.0),
        3001,
    );
    let run = drive_kinematic(&mut scene, &rig, &path);
    let at = |x: f64| &run.stacks[((1.4 - x) / 2.8 * 3000.0).round() as usize];
    assert_eq!(at(0.35), &[1, 3]);
    // The thesis's "confusing exception": entered from the other side, S2 rules in D.
    assert_eq!(at(0.05), &[1, 3, 2]);
    assert_eq!(at(-0.3), &[1, 2]);
    assert_eq!(at(-1.2), &[] as &[u64]);
}

#[test]
fn crossings_within_one_tick_are_ordered_along_the_segment() {
    let rig = rig(1.6);
    let mut scene = figure_4_6();
    let s = rig.zone.world_per_device_metre;
    // Rest in B, then one tick jumps into D across S2's and S3's surfaces.
    let mut path = vec![DVec3::new(-0.75 / s, 0.0, 0.0); 5];
    path.push(DVec3::new(0.05 / s, 0.0, 0.0));
    let run = drive_kinematic(&mut scene, &rig, &path);
    assert_eq!(run.stacks[4], [1]);
    assert_eq!(run.stacks[5], [1, 2, 3]);
    // And back in one tick from D to F: both removed regardless of order.
    let mut back = path.clone();
    back.push(DVec3::new(0.75 / s, 0.0, 0.0));
    assert_eq!(drive_kinematic(&mut scene, &rig, &back).stacks[6], [1]);
}

/// A sphere that counts the samples taken of it.
struct Counted {
    inner: Analytic,
    n_samples: usize,
}

impl Container for Counted {
    fn id(&self) -> u64 {
        self.inner.id()
    }
    fn bounds(&self) -> Aabb {
        self.inner.bounds()
    }
    fn value_grad(&mut self, p: DVec3, t: f64) -> (f64, DVec3) {
        self.n_samples += 1;
        self.inner.value_grad(p, t)
    }
    fn tension(&mut self, _p: DVec3, _t: f64) -> Option<f64> {
        None
    }
    fn friction(&mut self, _p: DVec3, _t: f64) -> Option<f64> {
        None
    }
    fn density(&mut self, _p: DVec3, _t: f64) -> Option<f64> {
        None
    }
    fn zone_depth(&mut self, _p: DVec3, _t: f64) -> Option<f64> {
        None
    }
    fn field_domain(&self) -> Option<FieldDomain> {
        None
    }
    fn force_field(&mut self, _uvw: DVec3, _t: f64) -> DVec3 {
        DVec3::ZERO
    }
}

#[test]
fn a_crossing_takes_a_few_samples_and_lies_on_the_surface() {
    let sphere = Analytic::new(
        7,
        Solid::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        },
    );
    let mut scene = vec![Counted {
        inner: sphere,
        n_samples: 0,
    }];
    let mut state = ProxyState::new();
    // One tick's travel at 2 m/s through the surface, entering at x = sqrt(1 - 0.3^2).
    let x = (1.0f64 - 0.09).sqrt();
    let (p0, p1) = (
        DVec3::new(x + 0.0013, 0.3, 0.0),
        DVec3::new(x - 0.0007, 0.3, 0.0),
    );
    update_stack(&mut scene, &mut state, p0, p1, 0.0);
    assert_eq!(state.stack().entries().len(), 1);
    // The tip, the last tip and the search: with 30 bisections, 32 samples.
    assert!(scene[0].n_samples <= 8, "{} samples", scene[0].n_samples);
    let crossing = state.crossings[0].s;
    assert!((crossing - 0.65).abs() < 1e-8, "{crossing}");
    assert!(scene[0].inner.value_grad(p0.lerp(p1, crossing), 0.0).0 >= 0.0);
}

#[test]
fn hip_starting_inside_gets_innermost_on_top_and_forces_ramp_in() {
    let rig = rig(1.6);
    let mut scene = figure_4_6();
    let s = rig.zone.world_per_device_metre;
    // Start in D, moving right: S3 has the smallest metric depth at x = 0.
    let path = line(DVec3::ZERO, DVec3::new(0.1 / s, 0.0, 0.0), 400);
    let run = drive_kinematic(&mut scene, &rig, &path);
    assert_eq!(run.stacks[0], [1, 2, 3]);
    let raw = run.outputs[300].raw_force_newtons.length();
    assert!(raw > 0.1, "raw {raw}");
    // Ramp: the force grows from zero over ramp_in_secs, never ahead of the ramp.
    for (k, out) in run.outputs.iter().enumerate().take(250) {
        let ramp = ((k + 1) as f64 * DT / rig.params.ramp_in_secs).min(1.0);
        assert!(out.force_newtons.length() <= ramp * out.raw_force_newtons.length() + 1e-9);
    }
    assert!(run.outputs[0].force_newtons.length() < 0.01);
}

fn watermelon_hand(rig: &Rig) -> SimDevice {
    let s = rig.zone.world_per_device_metre;
    let at = |y: f64| DVec3::new(-0.1 / s, y / s, -0.1 / s);
    let waypoints = vec![
        Waypoint {
            t_secs: 0.0,
            position_metres: at(1.2),
        },
        Waypoint {
            t_secs: 2.5,
            position_metres: at(0.0),
        },
    ];
    SimDevice::new(rig.caps, waypoints, HandModel::default(), DT).unwrap()
}

#[test]
fn watermelon_tension_pops_then_crunchy_density() {
    let rig = rig(1.6);
    let mut scene = vec![Analytic::watermelon(7, DVec3::ZERO, 1.0)];
    let run = drive_sim(&mut scene, &rig, watermelon_hand(&rig), 2600);
    let first_surface = run
        .outputs
        .iter()
        .position(|o| o.region == Region::Surface)
        .unwrap();
    let first_interior = run
        .outputs
        .iter()
        .position(|o| o.region == Region::Interior)
        .unwrap();
    assert!(
        first_surface < first_interior,
        "tension comes before density"
    );
    // Surface: tension pushes out (+y) and grows with depth until the membrane pops.
    let surface = &run.outputs[first_surface..first_interior];
    let peak = surface
        .iter()
        .map(|o| o.force_newtons.y)
        .fold(0.0, f64::max);
    assert!(peak > 1.5, "peak tension {peak} N");
    assert!(surface.iter().all(|o| o.raw_force_newtons.y >= 0.0));
    // Interior: after the cross-fade, density opposes motion, with crunchy layers.
    let interior = &run.outputs[first_interior + 50..];
    assert!(
        interior
            .iter()
            .all(|o| o.region == Region::Interior && o.top_id == Some(7))
    );
    let mut ratios = vec![];
    for (k, o) in interior.iter().enumerate() {
        let v =
            (run.positions[first_interior + 50 + k] - run.positions[first_interior + 49 + k]) / DT;
        if v.length() > 1e-3 {
            assert!(
                o.raw_force_newtons.dot(v) <= 1e-12,
                "density must resist motion"
            );
            ratios.push(o.raw_force_newtons.length() / v.length());
        }
    }
    let n_peaks = ratios
        .windows(3)
        .filter(|w| w[1] > w[0] && w[1] > w[2])
        .count();
    assert!(n_peaks >= 3, "crunchy layers felt: {n_peaks}");
    let raw_jump = assert_continuous(&run, &rig.caps);
    assert!(
        raw_jump > 0.3 * rig.caps.force_newtons_max,
        "pop-through is a raw jump the limiter smooths: {raw_jump}"
    );
}

#[test]
fn whirlpool_field_in_an_invisible_cylinder() {
    let rig = rig(2.0);
    let mut scene = vec![Analytic::whirlpool(9)];
    let s = rig.zone.world_per_device_metre;
    let inside = DVec3::new(0.8, 0.35, 0.0) / s;
    let run = drive_kinematic(&mut scene, &rig, &vec![inside; 600]);
    let out = run.outputs[599];
    assert_eq!((out.top_id, out.region), (Some(9), Region::Interior));
    // uvw = (0.5, 0.5, 0): the thesis's helical field, at full device force.
    let expected = DVec3::new(-0.05, -0.05, -0.5).normalize() * rig.caps.force_newtons_max;
    assert!((out.force_newtons - expected).length() < 1e-9, "{out:?}");
    // Above the invisible lid there is no field.
    let above = DVec3::new(0.8, 0.9, 0.0) / s;
    let run = drive_kinematic(&mut scene, &rig, &vec![above; 300]);
    assert_eq!(run.outputs[299].force_newtons, DVec3::ZERO);
}

#[test]
fn force_field_respects_cycle_interval_and_time_span() {
    let rig = rig(2.0);
    let solid = Solid::Sphere {
        center: DVec3::ZERO,
        radius: 1.0,
    };
    let domain = FieldDomain {
        box_world: solid.bounds(),
        uvw: Aabb::new(DVec3::ZERO, DVec3::ONE),
        cycle_interval_secs: 0.4,
        time_span_secs: 0.2,
    };
    let mut scene = vec![Analytic {
        field: Some((Field::Constant(DVec3::new(0.0, 0.5, 0.0)), domain)),
        ..Analytic::new(4, solid)
    }];
    let run = drive_kinematic(&mut scene, &rig, &vec![DVec3::ZERO; 1200]);
    let raw_y = |ms: usize| run.outputs[ms].raw_force_newtons.y;
    let on = 0.5 * rig.caps.force_newtons_max;
    for ms in [50, 150, 450, 550, 850, 950] {
        assert!((raw_y(ms) - on).abs() < 1e-12, "field on at {ms} ms");
    }
    for ms in [250, 350, 650, 750, 1050, 1150] {
        assert_eq!(raw_y(ms), 0.0, "field off at {ms} ms");
    }
    assert_continuous(&run, &rig.caps);
}

#[test]
fn closed_paths_never_inject_energy() {
    let rig = rig(1.6);
    let s = rig.zone.world_per_device_metre;
    let at = |y: f64| DVec3::new(-0.1 / s, y / s, -0.1 / s);
    let mut melon = vec![Analytic::watermelon(7, DVec3::ZERO, 1.0)];
    // In and out of the rind's surface zone; through the rind to the flesh and back.
    for deepest in [0.97, 0.5] {
        let mut path = line(at(1.1), at(deepest), 1500);
        path.extend(line(at(deepest), at(1.1), 1500));
        let run = drive_kinematic(&mut melon, &rig, &path);
        let (energy, energy_min) = absorbed_energy(&run);
        assert!(
            energy_min >= -1e-5,
            "deepest {deepest}: energy dipped to {energy_min} J"
        );
        assert!(energy >= -1e-5, "deepest {deepest}: {energy} J");
        assert_continuous(&run, &rig.caps);
    }
    let mut fig = figure_4_6();
    let mut path = line(
        DVec3::new(-1.4 / s, 0.0, 0.0),
        DVec3::new(1.4 / s, 0.0, 0.0),
        2000,
    );
    path.extend(line(
        DVec3::new(1.4 / s, 0.0, 0.0),
        DVec3::new(-1.4 / s, 0.0, 0.0),
        2000,
    ));
    let run = drive_kinematic(&mut fig, &rig, &path);
    assert!(absorbed_energy(&run).1 >= -1e-9);
}

/// A sphere whose surface gets stiffer after `switch_secs`: going in soft and coming out
/// stiff returns more energy than was stored, an active environment.
struct Stiffening {
    inner: Analytic,
    switch_secs: f64,
}

impl Container for Stiffening {
    fn id(&self) -> u64 {
        self.inner.id()
    }
    fn bounds(&self) -> Aabb {
        self.inner.bounds()
    }
    fn value_grad(&mut self, p: DVec3, t: f64) -> (f64, DVec3) {
        self.inner.value_grad(p, t)
    }
    fn tension(&mut self, _p: DVec3, t: f64) -> Option<f64> {
        Some(if t < self.switch_secs { 0.1 } else { 1.0 })
    }
    fn friction(&mut self, _p: DVec3, _t: f64) -> Option<f64> {
        None
    }
    fn density(&mut self, _p: DVec3, _t: f64) -> Option<f64> {
        None
    }
    fn zone_depth(&mut self, _p: DVec3, _t: f64) -> Option<f64> {
        Some(0.2)
    }
    fn field_domain(&self) -> Option<FieldDomain> {
        None
    }
    fn force_field(&mut self, _uvw: DVec3, _t: f64) -> DVec3 {
        DVec3::ZERO
    }
}

#[test]
fn passivity_observer_damps_an_active_surface() {
    let mut rig = rig(1.6);
    let s = rig.zone.world_per_device_metre;
    let at = |x: f64| DVec3::new(x / s, 0.0, 0.0);
    let mut path = line(at(1.2), at(0.9), 300);
    path.extend(line(at(0.9), at(1.2), 300));
    let mut energies = [0.0; 2];
    for (slot, passivity) in energies.iter_mut().zip([false, true]) {
        rig.params.passivity = passivity;
        let inner = Analytic::new(
            5,
            Solid::Sphere {
                center: DVec3::ZERO,
                radius: 1.0,
            },
        );
        let mut scene = vec![Stiffening {
            inner,
            switch_secs: 0.3,
        }];
        let run = drive_kinematic(&mut scene, &rig, &path);
        *slot = absorbed_energy(&run).0;
        assert_continuous(&run, &rig.caps);
    }
    let [without, with] = energies;
    assert!(
        without < -5e-3,
        "the stiffening surface injects energy: {without} J"
    );
    assert!(
        with > 0.5 * without,
        "the observer removes at least half of it: {with} vs {without} J"
    );
}

#[test]
fn stall_gives_zero_force_then_ramps_back() {
    let rig = rig(2.0);
    let mut scene = vec![Analytic::whirlpool(9)];
    let s = rig.zone.world_per_device_metre;
    let p = DVec3::new(0.8, 0.35, 0.0) / s;
    let mut state = ProxyState::new();
    let mut t = 0.0;
    let mut ts = 0;
    let mut tick = |state: &mut ProxyState, dt: f64, ts: u64, t: f64| {
        render(&mut scene, state, &rig, &DeviceSample::at(p, ts), t, dt)
    };
    for _ in 0..400 {
        ts += 1000;
        t += DT;
        tick(&mut state, DT, ts, t);
    }
    assert!(state.force_newtons().length() > 3.0);
    // The loop stalled for 20 ms: zero at once.
    ts += 20_000;
    let out = tick(&mut state, 0.02, ts, t + 0.02);
    assert!(out.stalled && out.force_newtons == DVec3::ZERO);
    // A device whose timestamps jump is a stall too, even with a normal dt.
    ts += 1000;
    let out = tick(&mut state, DT, ts, t);
    assert!(!out.stalled);
    ts += 50_000;
    assert!(tick(&mut state, DT, ts, t).stalled);
    // Recovery ramps in again from zero.
    ts += 1000;
    let out = tick(&mut state, DT, ts, t);
    assert!(out.force_newtons.length() < 0.02, "{out:?}");
    // Non-finite positions are a stall, never a panic.
    let out = render(
        &mut scene,
        &mut state,
        &rig,
        &DeviceSample::at(DVec3::NAN, ts + 1000),
        t,
        DT,
    );
    assert!(out.stalled && out.force_newtons == DVec3::ZERO);
}

#[test]
fn stack_follows_scene_changes_by_id() {
    let rig = rig(1.6);
    let mut scene = figure_4_6();
    let mut state = ProxyState::new();
    let s = rig.zone.world_per_device_metre;
    let p = DVec3::new(0.0, 0.0, 0.0) / s;
    render(
        &mut scene,
        &mut state,
        &rig,
        &DeviceSample::at(p, 0),
        0.0,
        DT,
    );
    assert_eq!(
        state
            .stack()
            .entries()
            .iter()
            .map(|e| e.id)
            .collect::<Vec<_>>(),
        [1, 2, 3]
    );
    // A new snapshot without S3 and with the others reordered.
    let mut next: Vec<Analytic> = vec![scene[2].clone(), scene[0].clone()];
    let out = render(
        &mut next,
        &mut state,
        &rig,
        &DeviceSample::at(p, 1000),
        DT,
        DT,
    );
    let entries = state.stack().entries();
    assert_eq!(
        entries.iter().map(|e| (e.id, e.idx)).collect::<Vec<_>>(),
        [(1, 1), (2, 0)]
    );
    assert_eq!(out.top_id, Some(2));
}

#[test]
fn sim_hand_pushing_a_sphere_settles_on_its_surface() {
    // Closed loop: the simulated hand pushes 10 mm into a hard sphere and is held near the
    // surface by the tension spring; the force balances the hand's grip.
    let rig = rig(1.6);
    let s = rig.zone.world_per_device_metre;
    let mut scene = vec![Analytic {
        tension: Some(1.0),
        zone_depth: 0.5,
        ..Analytic::new(
            1,
            Solid::Sphere {
                center: DVec3::ZERO,
                radius: 1.0,
            },
        )
    }];
    let waypoints = vec![
        Waypoint {
            t_secs: 0.0,
            position_metres: DVec3::new(1.1 / s, 0.0, 0.0),
        },
        Waypoint {
            t_secs: 0.5,
            position_metres: DVec3::new(1.0 / s - 0.004, 0.0, 0.0),
        },
    ];
    let dev = SimDevice::new(rig.caps, waypoints, HandModel::default(), DT).unwrap();
    let run = drive_sim(&mut scene, &rig, dev, 2000);
    let last = run.outputs[1999];
    let tip = run.positions[1999];
    let penetration = 1.0 / s - tip.x;
    // Grip spring (300 N/m) and surface spring (1000 N/m) share the 4 mm: 300*4/1300 mm deep.
    assert!(
        (penetration - 0.004 * 300.0 / 1300.0).abs() < 1e-4,
        "penetration {penetration}"
    );
    assert!(
        (last.force_newtons.x - 1000.0 * penetration).abs() < 0.02,
        "{last:?}"
    );
}

// Force rendering over the real container kinds: a mesh against the closed-form sphere, and
// the device's surface zone where an object gives no depth.

#[test]
fn mesh_sphere_feels_like_the_closed_form_sphere() {
    use crate::container::mesh::{MeshContainer, RayParams};
    use crate::container::properties::{PropertySpec, Scalar};
    use crate::shapes::icosphere;

    let caps = Capabilities::desktop_pen();
    let rig = Rig {
        caps,
        zone: HapticZone::fit(
            caps.workspace_metres,
            Aabb::new(DVec3::splat(-1.6), DVec3::splat(1.6)),
        ),
        params: ForceParams::default(),
    };
    let s = rig.zone.world_per_device_metre;
    let mesh = icosphere(DVec3::ZERO, 1.0, 4);
    let props = PropertySpec {
        tension: Some(Scalar::Constant(0.6)),
        zone_depth: Some(Scalar::Constant(0.2)),
        density: Some(Scalar::Constant(0.3)),
        ..PropertySpec::default()
    };
    let mut meshes =
        vec![MeshContainer::new(1, &mesh.0, &mesh.1, &props, RayParams::default()).unwrap()];
    let mut analytic = vec![Analytic {
        tension: Some(0.6),
        zone_depth: 0.2,
        density: Some(Density::Uniform(0.3)),
        ..Analytic::new(
            1,
            Solid::Sphere {
                center: DVec3::ZERO,
                radius: 1.0,
            },
        )
    }];
    let (mut state_mesh, mut state_analytic) = (ProxyState::new(), ProxyState::new());
    let dir = DVec3::new(0.3, 0.8, 0.52).normalize();
    let mut regions = vec![];
    let (mut n_region_mismatches, mut difference_sum) = (0, 0.0);
    for k in 0..1500u32 {
        // From 1.3 down to 0.5 along `dir`, world units.
        let r = 1.3 - 0.8 * f64::from(k) / 1500.0;
        let sample = DeviceSample::at(dir * r / s, u64::from(k) * 1000);
        let t = f64::from(k) * 1e-3;
        let a = render(&mut meshes, &mut state_mesh, &rig, &sample, t, 1e-3);
        let b = render(&mut analytic, &mut state_analytic, &rig, &sample, t, 1e-3);
        // Facets lie up to 0.001 inside the sphere: regions change a tick or two later.
        n_region_mismatches += usize::from(a.region != b.region);
        let difference = (a.force_newtons - b.force_newtons).length();
        assert!(
            difference < 0.12 * caps.force_newtons_max,
            "tick {k}: {} vs {}",
            a.force_newtons,
            b.force_newtons
        );
        difference_sum += difference;
        regions.push(a.region);
    }
    assert!(n_region_mismatches <= 6, "{n_region_mismatches}");
    assert!(difference_sum / 1500.0 < 0.01 * caps.force_newtons_max);
    assert!(regions.contains(&Region::Surface) && regions.contains(&Region::Interior));
    assert!(meshes[0].ray_stats().n_locations > 1000);
}

/// Presses the tip `depth_world` into the top of a ball with tension 1 (and the given zone
/// depth), kinematically through the force renderer, and returns the steady force.
fn pressed_ball(zone_depth: Option<&str>, depth_world: f64) -> glam::DVec3 {
    use model::object::{Domain, Formula, Geometry, Object, ObjectData, Physics, Property};

    use crate::container::object::ObjectContainer;

    let formula = |text: &str| Formula::new(text).unwrap();
    // The unit ball as a distance, in its domain.
    let data = ObjectData {
        geometry: Some(Geometry {
            domain: Some(Domain::new(DVec3::ZERO, DVec3::splat(2.2))),
            ..Geometry::implicit(formula("1 - sqrt(x^2 + y^2 + z^2)"))
        }),
        physics: Physics {
            tension: Some(Property::new(formula("1"))),
            zone_depth: zone_depth.map(|d| Property::new(formula(d))),
            ..Physics::default()
        }
        .into(),
        ..ObjectData::default()
    };
    let object = Object::new(data).unwrap();
    let mut scene =
        vec![ObjectContainer::from_object(5, &object, model::object::Transform::IDENTITY).unwrap()];
    let caps = Capabilities::falcon();
    let zone = HapticZone::fit(
        caps.workspace_metres,
        Aabb::new(DVec3::splat(-1.1), DVec3::splat(1.1)),
    );
    let rig = Rig {
        caps,
        zone,
        params: ForceParams::default(),
    };
    let mut state = ProxyState::new();
    let mut force = DVec3::ZERO;
    // From above the ball down to the depth in 0.2 s, then held there for 0.4 s.
    for k in 0..600u32 {
        let s = (f64::from(k) / 200.0).min(1.0);
        let hip = DVec3::new(0.0, 1.05 - s * (0.05 + depth_world), 0.0);
        let sample = DeviceSample::at(zone.device_from_world(hip), u64::from(k) * 1000);
        let out = render(
            &mut scene,
            &mut state,
            &rig,
            &sample,
            f64::from(k) * 1e-3,
            1e-3,
        );
        assert!(out.force_newtons.length() <= caps.force_newtons_max + 1e-9);
        force = out.force_newtons;
    }
    force
}

#[test]
fn without_a_zone_depth_the_device_sets_it_and_a_given_depth_overrides_it() {
    let caps = Capabilities::falcon();
    // The zone fitted around the ball: 22 scene units per device metre.
    let zone_world = caps.zone_depth_metres() * 2.2 / 0.1;
    // Half way into the device's zone: half the device's force, pushing out (up).
    let half = pressed_ball(None, 0.5 * zone_world);
    assert!(
        (half.y - 0.5 * caps.force_newtons_max).abs() < 0.05,
        "tension 1 at half the zone: {half}"
    );
    assert!(half.x.abs() < 1e-6 && half.z.abs() < 1e-6, "{half}");
    // Past the device's zone the membrane has popped: nothing pushes.
    let past = pressed_ball(None, 1.5 * zone_world);
    assert!(past.length() < 1e-6, "popped: {past}");
    // A given depth counts instead: the same press is still in a deeper zone, and pushes
    // with the stiffness times the depth, whatever the zone's depth.
    let deeper = pressed_ball(Some("0.5"), 1.5 * zone_world);
    assert!(
        (deeper.y - caps.force_newtons_max).abs() < 0.05,
        "clamped to the device's force: {deeper}"
    );
    // A zero depth is no zone at all.
    let none = pressed_ball(Some("0"), 0.5 * zone_world);
    assert!(none.length() < 1e-6, "{none}");
}
