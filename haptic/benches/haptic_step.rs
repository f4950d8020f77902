//! `haptic_step`: one servo tick (simulated device read, stack update, force rendering, safety
//! layer, force write) with the tip circling through a grid of 1, 16 and 64 watermelons.
//!
//! Three scene kinds in the same run: closed-form watermelons (the peer: the cheapest possible
//! container), the same watermelons as fdsl functions (`tests/data/models/watermelon.fdsl`
//! geometry, tension, friction and crunchy density as fdsl functions), and icosphere meshes
//! located by haptic rays (320 triangles each), and the fdsl watermelons as objects of the
//! shared object model (`ObjectContainer` over `model::object::Sampler`), plain and carved
//! with 10^4 small dents each (history-independent cost: a point visits only the edits
//! whose box holds it). Budget: well under 1 ms per tick (the 1 kHz period); the goal for
//! 64 fdsl objects is a p99.9 of 100 us or less (percentiles come from
//! `examples/tick_timing.rs`, divan reports medians and means). Must show 0 allocations under
//! `divan::AllocProfiler`.

use glam::DVec3;
use haptic::aabb::Aabb;
use haptic::container::Scene;
use haptic::container::object::ObjectContainer;
use haptic::device::Capabilities;
use haptic::device::sim::{HandModel, SimDevice};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, Rig};
use haptic::servo::Servo;
use haptic::shapes::{
    circle_waypoints, fdsl_watermelon_grid, mesh_grid, object_watermelon_scene, sphere_dents,
    watermelon_grid,
};

#[global_allocator]
static ALLOC: divan::AllocProfiler = divan::AllocProfiler::system();

const WATERMELON: &str = include_str!("../../tests/data/models/watermelon.fdsl");

fn main() {
    divan::main();
}

fn servo<S: Scene>(scene: S) -> Servo<SimDevice, S> {
    let caps = Capabilities::desktop_pen();
    let world = Aabb::new(DVec3::splat(-1.6), DVec3::splat(1.6));
    let rig = Rig {
        caps,
        zone: HapticZone::fit(caps.workspace_metres, world),
        params: ForceParams::default(),
    };
    let waypoints = circle_waypoints(0.05, 0.5, 1);
    let device = SimDevice::new(caps, waypoints, HandModel::default(), 0.001)
        .expect("a valid scripted device")
        .looping();
    let (mut servo, link) = Servo::init(device, rig);
    link.scenes.publish(Box::new(scene));
    // Take the snapshot and warm up past the ramp-in.
    for _ in 0..300 {
        servo.step(0.001);
    }
    servo
}

#[divan::bench(args = [1, 16, 64])]
fn haptic_step(bencher: divan::Bencher, n_objects: usize) {
    let mut servo = servo(watermelon_grid(n_objects));
    bencher.bench_local(|| servo.step(divan::black_box(0.001)));
}

#[divan::bench(args = [1, 16, 64])]
fn haptic_step_fdsl(bencher: divan::Bencher, n_objects: usize) {
    let geometry = fdsl::Function::parse(WATERMELON).expect("the reference model parses");
    let scene = fdsl_watermelon_grid(&geometry, n_objects).expect("valid containers");
    let mut servo = servo(scene);
    bencher.bench_local(|| servo.step(divan::black_box(0.001)));
}

#[divan::bench(args = [1, 16, 64])]
fn haptic_step_mesh(bencher: divan::Bencher, n_objects: usize) {
    let mut servo = servo(mesh_grid(n_objects, 2).expect("valid meshes"));
    bencher.bench_local(|| servo.step(divan::black_box(0.001)));
}

fn object_grid(n_objects: usize, n_dents: usize) -> Vec<ObjectContainer> {
    let dents = sphere_dents(n_dents, 0.02).expect("valid dents");
    let scene = object_watermelon_scene(WATERMELON, n_objects, &dents).expect("valid objects");
    let (containers, refused) = ObjectContainer::from_scene(&scene);
    assert!(refused.is_empty(), "{refused:?}");
    containers
}

#[divan::bench(args = [1, 16, 64])]
fn haptic_step_object(bencher: divan::Bencher, n_objects: usize) {
    let mut servo = servo(object_grid(n_objects, 0));
    bencher.bench_local(|| servo.step(divan::black_box(0.001)));
}

/// 64 objects with 10^4 edits each.
#[divan::bench(args = [64])]
fn haptic_step_object_10k_edits(bencher: divan::Bencher, n_objects: usize) {
    let mut servo = servo(object_grid(n_objects, 10_000));
    bencher.bench_local(|| servo.step(divan::black_box(0.001)));
}
