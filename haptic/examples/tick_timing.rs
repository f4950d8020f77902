//! Servo timing measurements that divan cannot give: per-tick compute percentiles, a paced
//! servo thread's period statistics, an instruction-count workload for callgrind, and the
//! cost of denormal (subnormal) numbers in the tick.
//!
//! ```text
//! cargo run --release -p haptic --example tick_timing -- compute [n_ticks]
//! cargo run --release -p haptic --example tick_timing -- period [secs]
//! cargo run --release -p haptic --example tick_timing -- ticks <kind> <n_objects> <n_ticks>
//! cargo run --release -p haptic --example tick_timing -- denormals
//! ```
//!
//! `kind` is `closed-form`, `fdsl`, `mesh`, `object` (the fdsl watermelons as objects of the
//! object model), `object-10k` (the same, each carved with 10^4 dents all over) or
//! `object-10k-far` (10^4 dents each, all where the tip never goes: the cost of a long
//! history alone). `ticks` runs the servo without reading the clock,
//! for `valgrind --tool=callgrind` (see BENCHMARKS.md).

use std::time::{Duration, Instant};

use glam::DVec3;
use haptic::aabb::Aabb;
use haptic::container::object::ObjectContainer;
use haptic::container::{Container, Scene};
use haptic::device::sim::{HandModel, SimDevice};
use haptic::device::{Capabilities, DeviceSample};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, ProxyState, Rig, render};
use haptic::servo::{Servo, ServoConfig, spawn};
use haptic::shapes::{
    circle_waypoints, fdsl_watermelon, fdsl_watermelon_grid, mesh_grid, object_watermelon_scene,
    sphere_dents, watermelon_grid,
};

const WATERMELON: &str = include_str!("../../tests/data/models/watermelon.fdsl");

#[expect(
    clippy::disallowed_methods,
    reason = "a timing tool reads the monotonic clock"
)]
fn now() -> Instant {
    Instant::now()
}

fn rig() -> Rig {
    let caps = Capabilities::desktop_pen();
    Rig {
        caps,
        zone: HapticZone::fit(
            caps.workspace_metres,
            Aabb::new(DVec3::splat(-1.6), DVec3::splat(1.6)),
        ),
        params: ForceParams::default(),
    }
}

fn device() -> SimDevice {
    let caps = Capabilities::desktop_pen();
    SimDevice::new(
        caps,
        circle_waypoints(0.05, 0.5, 1),
        HandModel::default(),
        0.001,
    )
    .expect("a valid scripted device")
    .looping()
}

fn scene(kind: &str, n_objects: usize) -> Vec<Box<dyn Container>> {
    fn boxed<C: Container + 'static>(v: Vec<C>) -> Vec<Box<dyn Container>> {
        v.into_iter()
            .map(|c| Box::new(c) as Box<dyn Container>)
            .collect()
    }
    match kind {
        "closed-form" => boxed(watermelon_grid(n_objects)),
        "fdsl" => {
            let geometry = fdsl::Function::parse(WATERMELON).expect("the reference model parses");
            boxed(fdsl_watermelon_grid(&geometry, n_objects).expect("valid containers"))
        }
        "mesh" => boxed(mesh_grid(n_objects, 2).expect("valid meshes")),
        "object" | "object-10k" | "object-10k-far" => {
            let dents = match kind {
                "object" => vec![],
                "object-10k" => sphere_dents(10_000, 0.02).expect("valid dents"),
                _ => far_dents(10_000),
            };
            let scene =
                object_watermelon_scene(WATERMELON, n_objects, &dents).expect("valid objects");
            let (containers, refused) = ObjectContainer::from_scene(&scene);
            assert!(refused.is_empty(), "{refused:?}");
            boxed(containers)
        }
        other => {
            panic!("unknown scene kind {other:?}: closed-form, fdsl, mesh, object or object-10k")
        }
    }
}

/// `n` dents of radius 0.02 on the caps `|z| > 0.6` of the unit sphere, which the tip
/// (circling in the plane `z = 0` through the watermelons' centres) never comes near.
fn far_dents(n: usize) -> Vec<std::sync::Arc<model::object::CompiledEdit>> {
    use model::object::{CompiledEdit, Edit, EditOp, Pose, ToolShape};
    (0..n)
        .map(|k| {
            let z = if k % 2 == 0 { 1.0 } else { -1.0 } * (0.7 + 0.3 * (k as f64 / n as f64));
            let angle = k as f64 * 2.399_963;
            let ring = (1.0 - z * z).sqrt();
            let at = DVec3::new(ring * angle.cos(), ring * angle.sin(), z);
            let tool = ToolShape::Sphere { radius: 0.02 };
            let edit = Edit::stamp(EditOp::Subtract, tool, Pose::at(at));
            std::sync::Arc::new(CompiledEdit::new(edit).expect("a valid dent"))
        })
        .collect()
}

fn servo<S: Scene>(scene: S) -> Servo<SimDevice, S> {
    let (mut servo, link) = Servo::init(device(), rig());
    link.scenes.publish(Box::new(scene));
    for _ in 0..1000 {
        servo.step(0.001);
    }
    servo
}

fn percentile_micros(sorted: &[Duration], q: f64) -> f64 {
    let idx = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[idx].as_secs_f64() * 1e6
}

/// Times `n_ticks` servo steps one by one for each scene kind and size.
fn compute(n_ticks: usize) {
    println!("per-tick compute, {n_ticks} ticks each (tip circling through the grid)");
    println!("| scene | objects | median | p99 | p99.9 | max |");
    println!("|---|---|---|---|---|---|");
    let kinds = [
        "closed-form",
        "fdsl",
        "mesh",
        "object",
        "object-10k",
        "object-10k-far",
    ];
    for kind in kinds {
        let sizes: &[usize] = if kind.starts_with("object-10k") {
            &[64]
        } else {
            &[1, 16, 64]
        };
        for &n_objects in sizes {
            let mut servo = servo(scene(kind, n_objects));
            let mut times = Vec::with_capacity(n_ticks);
            for _ in 0..n_ticks {
                let start = now();
                std::hint::black_box(servo.step(std::hint::black_box(0.001)));
                times.push(start.elapsed());
            }
            times.sort_unstable();
            let p = |q| percentile_micros(&times, q);
            println!(
                "| {kind} | {n_objects} | {:.2} us | {:.2} us | {:.2} us | {:.1} us |",
                p(0.5),
                p(0.99),
                p(0.999),
                p(1.0)
            );
        }
    }
}

/// Runs the paced servo thread over 64 fdsl watermelons for `secs` and prints its statistics.
fn period(secs: f64) {
    let config = ServoConfig {
        thread_name: "haptic-servo-timing".into(),
        ..ServoConfig::default()
    };
    let (servo, link) = Servo::init(device(), rig());
    link.scenes.publish(Box::new(scene("fdsl", 64)));
    let handle = spawn(servo, &config).expect("the servo thread starts");
    println!("priority: {:?}", handle.priority());
    std::thread::sleep(Duration::from_secs_f64(secs));
    let stats = link.stats.snapshot();
    drop(handle.stop());
    println!(
        "ticks {} over {secs} s, overruns (period > 2 ms) {}, stalls {}",
        stats.n_ticks, stats.n_overruns, stats.n_stalls
    );
    let [p50, p99, p999, max] = stats.period_micros;
    println!("period  p50 {p50} us, p99 {p99} us, p99.9 {p999} us, max {max} us (10 us buckets)");
    let [p50, p99, p999, max] = stats.compute_micros;
    println!("compute p50 {p50} us, p99 {p99} us, p99.9 {p999} us, max {max} us (10 us buckets)");
}

/// Steps the servo `n_ticks` times without reading the clock; prints a checksum.
fn ticks(kind: &str, n_objects: usize, n_ticks: usize) {
    let mut servo = servo(scene(kind, n_objects));
    let mut checksum = 0.0;
    for _ in 0..n_ticks {
        checksum += servo.step(0.001).force_newtons.length();
    }
    println!("{kind} x{n_objects}: {n_ticks} ticks, checksum {checksum:.6}");
}

/// Whether subnormal numbers slow the tick: a tip resting inside an fdsl watermelon, where
/// the filtered velocity decays geometrically through the subnormal range to zero, timed per
/// tick and grouped by the velocity's magnitude.
fn denormals() {
    let geometry = fdsl::Function::parse(WATERMELON).expect("the reference model parses");
    let mut scene = vec![fdsl_watermelon(1, &geometry, DVec3::ZERO, 1.0).expect("a container")];
    let rig = rig();
    let mut state = ProxyState::new();
    let inside = DVec3::new(-0.2, 0.3, -0.2) / rig.zone.world_per_device_metre;
    // A moving start, so the velocity filter holds a normal value before the tip stops.
    let mut groups: [Vec<Duration>; 3] = Default::default();
    for k in 0..20_000u64 {
        let p = if k < 100 {
            inside * (1.0 + 0.001 * k as f64)
        } else {
            inside * 1.1
        };
        let sample = DeviceSample::at(p, k * 1000);
        let start = now();
        std::hint::black_box(render(
            &mut scene,
            &mut state,
            &rig,
            &sample,
            k as f64 * 1e-3,
            1e-3,
        ));
        let elapsed = start.elapsed();
        let v = state.velocity_device().abs().max_element();
        let group = if v == 0.0 {
            2
        } else if v < f64::MIN_POSITIVE {
            1
        } else {
            0
        };
        if k >= 200 {
            groups[group].push(elapsed);
        }
    }
    println!("render() of one fdsl watermelon, tip at rest, grouped by |velocity|:");
    for (name, times) in ["normal", "subnormal", "zero"]
        .iter()
        .zip(groups.iter_mut())
    {
        times.sort_unstable();
        if times.is_empty() {
            println!("  {name}: no ticks");
            continue;
        }
        println!(
            "  {name}: {} ticks, median {:.3} us, p99 {:.3} us",
            times.len(),
            percentile_micros(times, 0.5),
            percentile_micros(times, 0.99)
        );
    }
    // The fdsl evaluator on subnormal operands: exp(-720) is subnormal, exp(-700) is not.
    let f = fdsl::Function::parse("exp(-x) * (1 + y) * (1 + z) + exp(-x) * y").expect("parses");
    let mut eval = fdsl::eval::PointEval::new(&f.tape());
    for x in [700.0, 720.0] {
        let n = 1_000_000;
        let start = now();
        let mut sum = 0.0;
        for k in 0..n {
            sum += eval.eval([x, 0.5 + 1e-9 * k as f64, 0.25, 0.0]);
        }
        let per_eval = start.elapsed().as_secs_f64() * 1e9 / n as f64;
        println!(
            "  PointEval exp(-{x}) (value {:e}): {per_eval:.1} ns per point, sum {sum:e}",
            (-x).exp()
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |idx: usize, default: &str| args.get(idx).cloned().unwrap_or(default.to_string());
    match arg(0, "compute").as_str() {
        "compute" => compute(arg(1, "100000").parse().expect("n_ticks is a number")),
        "period" => period(arg(1, "60").parse().expect("secs is a number")),
        "ticks" => ticks(
            &arg(1, "fdsl"),
            arg(2, "64").parse().expect("n_objects is a number"),
            arg(3, "10000").parse().expect("n_ticks is a number"),
        ),
        "denormals" => denormals(),
        other => eprintln!("unknown mode {other:?}: compute, period, ticks or denormals"),
    }
}
