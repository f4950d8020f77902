//! `haptic_step`: one servo tick (simulated device read, stack update, force rendering, safety
//! layer, force write) over scenes of 1, 16 and 64 watermelons, with the tip circling through
//! them. Budget: well under 1 ms per tick (the 1 kHz period); the measured figure should be
//! a few microseconds. Must show 0 allocations under `divan::AllocProfiler`.

use glam::DVec3;
use haptic::container::Aabb;
use haptic::device::Capabilities;
use haptic::device::sim::{HandModel, SimDevice};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, Rig};
use haptic::servo::Servo;
use haptic::shapes::{Analytic, circle_waypoints, watermelon_grid};

#[global_allocator]
static ALLOC: divan::AllocProfiler = divan::AllocProfiler::system();

fn main() {
    divan::main();
}

fn servo(n_objects: usize) -> Servo<SimDevice, Vec<Analytic>> {
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
    link.scenes.publish(Box::new(watermelon_grid(n_objects)));
    // Take the snapshot and warm up past the ramp-in.
    for _ in 0..300 {
        servo.step(0.001);
    }
    servo
}

#[divan::bench(args = [1, 16, 64])]
fn haptic_step(bencher: divan::Bencher, n_objects: usize) {
    let mut servo = servo(n_objects);
    bencher.bench_local(|| servo.step(divan::black_box(0.001)));
}
