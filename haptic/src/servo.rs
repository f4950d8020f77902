//! The 1 kHz servo: [`Servo`] (init / reset / step, the per-tick work) and [`spawn`], a named
//! thread that paces it with a deadline sleep then a short spin, at real-time priority where
//! permitted.
//!
//! `Servo::step` does not allocate, lock, parse or log (proven by `tests/no_alloc.rs` and the
//! `haptic_step` bench); its only syscalls are the device's own I/O. Scene snapshots and rig
//! settings arrive through [`crate::handoff`]; replaced ones go back to the app on its ring.
//! Timing statistics are atomics the app reads with [`ServoStats::snapshot`].

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use glam::DVec3;

use crate::container::{Container, Scene};
use crate::device::HapticDevice;
use crate::force::{self, ProxyState, Region, Rig};
use crate::handoff::{self, Publisher, Receiver};
use crate::shared::{self, Coupled, SharedToolLink};

/// Width of one histogram bucket, microseconds.
pub const HISTOGRAM_BUCKET_MICROS: u64 = 10;
/// Buckets per histogram; the last one also counts everything longer.
pub const HISTOGRAM_BUCKETS: usize = 1_000;
/// The servo rate, hertz.
pub const SERVO_RATE_HZ: f64 = 1_000.0;
/// The SCHED_FIFO priority requested for the servo thread.
pub const REALTIME_PRIORITY: i32 = 80;

/// A scene with no containers, rendered before the first snapshot arrives.
struct NoScene;

impl Scene for NoScene {
    fn n_containers(&self) -> usize {
        0
    }
    fn container_mut(&mut self, idx: usize) -> &mut dyn Container {
        unreachable!("NoScene has no container {idx}")
    }
}

/// A lock-free histogram of durations.
#[derive(Debug)]
struct Histogram {
    buckets: Box<[AtomicU64]>,
    max_micros: AtomicU64,
}

impl Histogram {
    fn new() -> Self {
        Self {
            buckets: (0..HISTOGRAM_BUCKETS).map(|_| AtomicU64::new(0)).collect(),
            max_micros: AtomicU64::new(0),
        }
    }

    fn record(&self, micros: u64) {
        let idx = ((micros / HISTOGRAM_BUCKET_MICROS) as usize).min(HISTOGRAM_BUCKETS - 1);
        self.buckets[idx].fetch_add(1, Ordering::Relaxed);
        self.max_micros.fetch_max(micros, Ordering::Relaxed);
    }

    /// The upper edge of the bucket holding the `q` quantile, microseconds (0 when empty).
    fn quantile_micros(&self, q: f64) -> u64 {
        let counts: Vec<u64> = self
            .buckets
            .iter()
            .map(|b| b.load(Ordering::Relaxed))
            .collect();
        let total: u64 = counts.iter().sum();
        if total == 0 {
            return 0;
        }
        let rank = ((q * total as f64).ceil() as u64).clamp(1, total);
        let mut seen = 0;
        for (idx, count) in counts.iter().enumerate() {
            seen += count;
            if seen >= rank {
                return (idx as u64 + 1) * HISTOGRAM_BUCKET_MICROS;
            }
        }
        HISTOGRAM_BUCKETS as u64 * HISTOGRAM_BUCKET_MICROS
    }
}

/// Timing and state the servo publishes for the app (all atomics: written by the servo
/// without locks, read by anyone).
#[derive(Debug)]
pub struct ServoStats {
    period: Histogram,
    compute: Histogram,
    n_ticks: AtomicU64,
    n_overruns: AtomicU64,
    n_device_errors: AtomicU64,
    n_stalls: AtomicU64,
    n_scenes_taken: AtomicU64,
    force_bits: [AtomicU64; 3],
    tip_bits: [AtomicU64; 3],
    energy_bits: AtomicU64,
    top_id: AtomicU64,
}

/// A copy of [`ServoStats`] for display.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StatsSnapshot {
    /// Ticks run.
    pub n_ticks: u64,
    /// Ticks that started more than one period late.
    pub n_overruns: u64,
    /// Device reads or writes that failed.
    pub n_device_errors: u64,
    /// Ticks rendered as stalls (zero force).
    pub n_stalls: u64,
    /// Scene snapshots the servo has taken from the handoff (each replaces the one before).
    pub n_scenes_taken: u64,
    /// Tick period percentiles (50, 99, 99.9) and maximum, microseconds.
    pub period_micros: [u64; 4],
    /// Tick compute percentiles (50, 99, 99.9) and maximum, microseconds.
    pub compute_micros: [u64; 4],
    /// The last force sent, newtons, device frame.
    pub force_newtons: DVec3,
    /// The last HIP, world.
    pub hip_world: DVec3,
    /// The ruling container, if any.
    pub top_id: Option<u64>,
    /// The passivity observer's energy after the last tick, joules: what the rendering has
    /// dissipated minus what it injected (negative while it has injected energy).
    pub energy_joules: f64,
}

impl ServoStats {
    fn new() -> Self {
        Self {
            period: Histogram::new(),
            compute: Histogram::new(),
            n_ticks: AtomicU64::new(0),
            n_overruns: AtomicU64::new(0),
            n_device_errors: AtomicU64::new(0),
            n_stalls: AtomicU64::new(0),
            n_scenes_taken: AtomicU64::new(0),
            force_bits: Default::default(),
            energy_bits: AtomicU64::new(0),
            tip_bits: Default::default(),
            top_id: AtomicU64::new(u64::MAX),
        }
    }

    /// Records one paced tick (called by the servo thread).
    fn record_timing(&self, period_micros: u64, compute_micros: u64, overrun: bool) {
        self.period.record(period_micros);
        self.compute.record(compute_micros);
        if overrun {
            self.n_overruns.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Reads everything (allocates: app side only).
    pub fn snapshot(&self) -> StatsSnapshot {
        let quantiles = |h: &Histogram| {
            // Buckets report their upper edge, which can lie above the largest value seen.
            let max = h.max_micros.load(Ordering::Relaxed);
            [
                h.quantile_micros(0.5).min(max),
                h.quantile_micros(0.99).min(max),
                h.quantile_micros(0.999).min(max),
                max,
            ]
        };
        let vec3 = |bits: &[AtomicU64; 3]| {
            DVec3::from_array(
                bits.each_ref()
                    .map(|b| f64::from_bits(b.load(Ordering::Relaxed))),
            )
        };
        let top = self.top_id.load(Ordering::Relaxed);
        StatsSnapshot {
            n_ticks: self.n_ticks.load(Ordering::Relaxed),
            n_overruns: self.n_overruns.load(Ordering::Relaxed),
            n_device_errors: self.n_device_errors.load(Ordering::Relaxed),
            n_stalls: self.n_stalls.load(Ordering::Relaxed),
            n_scenes_taken: self.n_scenes_taken.load(Ordering::Relaxed),
            period_micros: quantiles(&self.period),
            compute_micros: quantiles(&self.compute),
            force_newtons: vec3(&self.force_bits),
            hip_world: vec3(&self.tip_bits),
            top_id: (top != u64::MAX).then_some(top),
            energy_joules: f64::from_bits(self.energy_bits.load(Ordering::Relaxed)),
        }
    }
}

fn store_vec3(bits: &[AtomicU64; 3], v: DVec3) {
    for (slot, x) in bits.iter().zip(v.to_array()) {
        slot.store(x.to_bits(), Ordering::Relaxed);
    }
}

/// What one step did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutcome {
    /// The force sent, newtons, device frame.
    pub force_newtons: DVec3,
    /// The ruling container.
    pub top_id: Option<u64>,
    /// The HIP's region.
    pub region: Region,
    /// True when the tick was a stall or the device failed (zero force).
    pub stalled: bool,
}

/// The servo's per-tick state: device, proxy state, current snapshot and rig.
pub struct Servo<D, S> {
    device: D,
    rig: Rig,
    state: ProxyState,
    scene: Option<Box<S>>,
    retiring_scene: Option<Box<S>>,
    retiring_rig: Option<Box<Rig>>,
    scenes: Receiver<S>,
    rigs: Receiver<Rig>,
    stats: Arc<ServoStats>,
    t_secs: f64,
    shared: Arc<SharedToolLink>,
    coupled: Option<Coupled>,
}

/// The app's side of a servo: publish snapshots and rig settings, read statistics.
pub struct ServoLink<S> {
    /// Publishes scene snapshots.
    pub scenes: Publisher<S>,
    /// Publishes rig settings (zone moves, parameter changes).
    pub rigs: Publisher<Rig>,
    /// Statistics written by the servo.
    pub stats: Arc<ServoStats>,
    /// The shared tool: a coupling with another peer's device ([`crate::shared`]).
    pub shared: Arc<SharedToolLink>,
}

impl<S: Send> ServoLink<S> {
    /// Frees retired snapshots and settings (call regularly from the app).
    pub fn collect_retired(&self) -> usize {
        self.scenes.collect_retired() + self.rigs.collect_retired()
    }
}

impl<D: HapticDevice, S: Scene> Servo<D, S> {
    /// Builds the servo (allocates) and the app's link to it. `rig.caps` is replaced by the
    /// device's capabilities.
    pub fn init(device: D, rig: Rig) -> (Self, ServoLink<S>) {
        let (scene_tx, scene_rx) = handoff::channel();
        let (rig_tx, rig_rx) = handoff::channel();
        let stats = Arc::new(ServoStats::new());
        let shared = Arc::new(SharedToolLink::default());
        let rig = Rig {
            caps: *device.capabilities(),
            ..rig
        };
        let servo = Self {
            device,
            rig,
            state: ProxyState::new(),
            scene: None,
            retiring_scene: None,
            retiring_rig: None,
            scenes: scene_rx,
            rigs: rig_rx,
            stats: Arc::clone(&stats),
            t_secs: 0.0,
            shared: Arc::clone(&shared),
            coupled: None,
        };
        let link = ServoLink {
            scenes: scene_tx,
            rigs: rig_tx,
            stats,
            shared,
        };
        (servo, link)
    }

    /// Forgets the proxy history (the next tick locates the HIP afresh and ramps in).
    pub fn reset(&mut self) {
        self.state.reset();
    }

    /// The device (e.g. to read a simulated device's state in tests).
    pub fn device(&self) -> &D {
        &self.device
    }

    /// Sets the scene time, seconds: the next `step(dt_secs)` renders at `t_secs + dt_secs`
    /// (a replay whose path starts at a given scene time sets it once before stepping).
    pub fn set_time_secs(&mut self, t_secs: f64) {
        self.t_secs = t_secs;
    }

    /// The proxy state.
    pub fn state(&self) -> &ProxyState {
        &self.state
    }

    /// Takes new snapshots and settings, retiring the old ones without freeing them here.
    fn poll_handoffs(&mut self) {
        if let Some(old) = self.retiring_scene.take() {
            self.retiring_scene = self.scenes.retire(old).err();
        }
        if self.retiring_scene.is_none()
            && let Some(next) = self.scenes.take()
        {
            self.stats.n_scenes_taken.fetch_add(1, Ordering::Relaxed);
            if let Some(old) = self.scene.replace(next) {
                self.retiring_scene = self.scenes.retire(old).err();
            }
        }
        if let Some(old) = self.retiring_rig.take() {
            self.retiring_rig = self.rigs.retire(old).err();
        }
        if self.retiring_rig.is_none()
            && let Some(next) = self.rigs.take()
        {
            self.rig = Rig {
                caps: self.rig.caps,
                ..*next
            };
            self.retiring_rig = self.rigs.retire(next).err();
        }
    }

    /// One tick: read the device, render, command the force. No allocation, lock or log.
    pub fn step(&mut self, dt_secs: f64) -> StepOutcome {
        self.poll_handoffs();
        self.t_secs += dt_secs;
        self.stats.n_ticks.fetch_add(1, Ordering::Relaxed);
        let sample = match self.device.sample() {
            Ok(sample) => sample,
            Err(_) => return self.fail_safe(),
        };
        let out = match self.scene.as_deref_mut() {
            Some(scene) => force::render(
                scene,
                &mut self.state,
                &self.rig,
                &sample,
                self.t_secs,
                dt_secs,
            ),
            None => force::render(
                &mut NoScene,
                &mut self.state,
                &self.rig,
                &sample,
                self.t_secs,
                dt_secs,
            ),
        };
        let tick = shared::Tick {
            tip_metres: sample.position_metres,
            velocity_metres_per_sec: self.state.velocity_device(),
            force_max_newtons: self.rig.caps.force_newtons_max,
            t_secs: self.t_secs,
            dt_secs,
            stalled: out.stalled,
        };
        let coupling = shared::step(&self.shared, &mut self.coupled, tick);
        let force_newtons = if coupling == DVec3::ZERO {
            out.force_newtons
        } else {
            (out.force_newtons + coupling).clamp_length_max(self.rig.caps.force_newtons_max)
        };
        if self.device.set_force(force_newtons).is_err() {
            return self.fail_safe();
        }
        if out.stalled {
            self.stats.n_stalls.fetch_add(1, Ordering::Relaxed);
        }
        store_vec3(&self.stats.force_bits, force_newtons);
        store_vec3(&self.stats.tip_bits, out.hip_world);
        self.stats
            .energy_bits
            .store(self.state.energy_joules().to_bits(), Ordering::Relaxed);
        self.stats
            .top_id
            .store(out.top_id.unwrap_or(u64::MAX), Ordering::Relaxed);
        StepOutcome {
            force_newtons,
            top_id: out.top_id,
            region: out.region,
            stalled: out.stalled,
        }
    }

    /// A device failure: forget history, try to zero the force, count it.
    fn fail_safe(&mut self) -> StepOutcome {
        self.stats.n_device_errors.fetch_add(1, Ordering::Relaxed);
        self.state.reset();
        self.coupled = None;
        // The device already failed once this tick; a second failure changes nothing.
        let _ = self.device.set_force(DVec3::ZERO);
        store_vec3(&self.stats.force_bits, DVec3::ZERO);
        StepOutcome {
            force_newtons: DVec3::ZERO,
            top_id: None,
            region: Region::Free,
            stalled: true,
        }
    }
}

/// How the servo thread is paced.
#[derive(Clone, Debug, PartialEq)]
pub struct ServoConfig {
    /// Tick rate, hertz.
    pub rate_hz: f64,
    /// Busy-wait this long before each deadline instead of sleeping, microseconds.
    pub spin_micros: u64,
    /// Ask for SCHED_FIFO real-time priority.
    pub realtime_priority: bool,
    /// The thread's name.
    pub thread_name: String,
}

impl Default for ServoConfig {
    fn default() -> Self {
        Self {
            rate_hz: SERVO_RATE_HZ,
            spin_micros: 100,
            realtime_priority: true,
            thread_name: "haptic-servo".into(),
        }
    }
}

/// Whether the servo thread runs at real-time priority.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Priority {
    /// SCHED_FIFO was granted.
    Realtime,
    /// Not asked for.
    Normal,
    /// Asked for and refused with this OS error number.
    Refused(i32),
}

/// Why the servo thread could not start.
#[derive(Debug, thiserror::Error)]
pub enum SpawnError {
    /// The rate is not positive and finite.
    #[error("servo rate must be positive and finite, got {0} Hz")]
    BadRate(f64),
    /// The OS refused to create the thread.
    #[error("cannot start the servo thread: {0}")]
    Thread(#[from] std::io::Error),
    /// The thread ended before reporting its priority.
    #[error("the servo thread ended during start-up")]
    StartupLost,
}

/// A running servo thread.
pub struct ServoHandle<D, S> {
    running: Arc<AtomicBool>,
    thread: JoinHandle<Servo<D, S>>,
    priority: Priority,
}

impl<D, S> ServoHandle<D, S> {
    /// The priority the thread got.
    pub fn priority(&self) -> Priority {
        self.priority
    }

    /// Stops the thread (the force is zeroed first) and gives the servo back.
    pub fn stop(self) -> std::thread::Result<Servo<D, S>> {
        self.running.store(false, Ordering::Release);
        self.thread.join()
    }
}

/// The monotonic clock: the one place the haptic crate reads time (the servo's pacing and
/// timing, and the feed's build time).
#[expect(
    clippy::disallowed_methods,
    reason = "the haptic crate reads the monotonic clock here only"
)]
pub(crate) fn monotonic_now() -> Instant {
    Instant::now()
}

#[cfg(target_os = "linux")]
#[expect(unsafe_code, reason = "pthread_setschedparam is an FFI call")]
fn request_realtime() -> Priority {
    let param = libc::sched_param {
        sched_priority: REALTIME_PRIORITY,
    };
    // SAFETY: `pthread_self` is always valid for the calling thread, and `param` is a valid,
    // initialised `sched_param` that outlives the call.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Priority::Realtime
    } else {
        Priority::Refused(rc)
    }
}

#[cfg(not(target_os = "linux"))]
fn request_realtime() -> Priority {
    Priority::Refused(0)
}

/// Sleeps until shortly before `deadline`, then spins until it.
fn wait_until(deadline: Instant, spin: Duration) {
    let now = monotonic_now();
    if let Some(sleep) = deadline
        .checked_duration_since(now)
        .and_then(|d| d.checked_sub(spin))
    {
        std::thread::sleep(sleep);
    }
    while monotonic_now() < deadline {
        std::hint::spin_loop();
    }
}

/// Starts the paced servo thread. Logs once (here, not on the servo thread) when real-time
/// priority was asked for and refused.
pub fn spawn<D, S>(
    mut servo: Servo<D, S>,
    config: &ServoConfig,
) -> Result<ServoHandle<D, S>, SpawnError>
where
    D: HapticDevice + 'static,
    S: Scene + 'static,
{
    if !(config.rate_hz.is_finite() && config.rate_hz > 0.0) {
        return Err(SpawnError::BadRate(config.rate_hz));
    }
    let period = Duration::from_secs_f64(1.0 / config.rate_hz);
    let spin = Duration::from_micros(config.spin_micros);
    let running = Arc::new(AtomicBool::new(true));
    let (priority_tx, priority_rx) = std::sync::mpsc::sync_channel(1);
    let want_realtime = config.realtime_priority;
    let thread_running = Arc::clone(&running);
    let thread = std::thread::Builder::new()
        .name(config.thread_name.clone())
        .spawn(move || {
            let priority = if want_realtime {
                request_realtime()
            } else {
                Priority::Normal
            };
            // The spawner waits for this; if it is gone the loop still runs until stopped.
            let _ = priority_tx.send(priority);
            run_loop(&mut servo, &thread_running, period, spin);
            servo
        })?;
    let priority = priority_rx.recv().map_err(|_| SpawnError::StartupLost)?;
    if let Priority::Refused(errno) = priority {
        log::warn!(
            "haptic servo: real-time priority refused (error {errno}); running at normal \
             priority, expect jitter (grant CAP_SYS_NICE or an rtprio limit to fix)"
        );
    }
    Ok(ServoHandle {
        running,
        thread,
        priority,
    })
}

fn run_loop<D: HapticDevice, S: Scene>(
    servo: &mut Servo<D, S>,
    running: &AtomicBool,
    period: Duration,
    spin: Duration,
) {
    let mut last = monotonic_now();
    let mut deadline = last + period;
    while running.load(Ordering::Acquire) {
        wait_until(deadline, spin);
        let start = monotonic_now();
        let dt = start.duration_since(last);
        last = start;
        servo.step(dt.as_secs_f64());
        let compute = monotonic_now().duration_since(start);
        let overrun = dt > period * 2;
        servo
            .stats
            .record_timing(dt.as_micros() as u64, compute.as_micros() as u64, overrun);
        deadline += period;
        if deadline < start {
            // Fell more than a period behind: skip the missed ticks instead of bursting.
            deadline = start + period;
        }
    }
    let _ = servo.device.set_force(DVec3::ZERO);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aabb::Aabb;
    use crate::device::sim::{HandModel, SimDevice, Waypoint};
    use crate::device::trace::{Trace, TraceDevice};
    use crate::device::{Capabilities, DeviceSample};
    use crate::force::ForceParams;
    use crate::force::zone::HapticZone;
    use crate::shapes::{Analytic, Density, Solid};

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

    fn still_device(at: DVec3) -> SimDevice {
        let waypoints = vec![Waypoint {
            t_secs: 0.0,
            position_metres: at,
        }];
        SimDevice::new(
            Capabilities::desktop_pen(),
            waypoints,
            HandModel::default(),
            0.001,
        )
        .unwrap()
    }

    fn ball(id: u64, radius: f64) -> Analytic {
        Analytic {
            density: Some(Density::Uniform(0.5)),
            ..Analytic::new(
                id,
                Solid::Sphere {
                    center: DVec3::ZERO,
                    radius,
                },
            )
        }
    }

    #[test]
    fn snapshots_swap_in_and_retire_to_the_app() {
        let (mut servo, link) = Servo::init(still_device(DVec3::ZERO), rig());
        assert_eq!(servo.step(0.001).top_id, None);
        link.scenes.publish(Box::new(vec![ball(1, 1.0)]));
        assert_eq!(servo.step(0.001).top_id, Some(1));
        link.scenes
            .publish(Box::new(vec![ball(2, 0.5), ball(1, 1.0)]));
        // Ball 2 appeared around the HIP: it is the last entered, so it rules over 1.
        assert_eq!(servo.step(0.001).top_id, Some(2));
        let ids: Vec<u64> = servo
            .state()
            .stack()
            .entries()
            .iter()
            .map(|e| e.id)
            .collect();
        assert_eq!(ids, [1, 2]);
        assert_eq!(
            link.collect_retired(),
            1,
            "the first snapshot came back to the app"
        );
        // Moving the zone moves the HIP out of everything.
        let far = Rig {
            zone: rig().zone.moved_by(DVec3::new(5.0, 0.0, 0.0)),
            ..rig()
        };
        link.rigs.publish(Box::new(far));
        assert_eq!(servo.step(0.001).top_id, None);
        assert_eq!(link.collect_retired(), 1);
        let stats = link.stats.snapshot();
        assert_eq!(stats.n_ticks, 4);
        assert_eq!(
            stats.n_scenes_taken, 2,
            "two snapshots were published and taken"
        );
        assert_eq!(stats.top_id, None);
        assert!((stats.hip_world.x - 5.0).abs() < 1e-9);
    }

    #[test]
    fn the_scene_clock_starts_where_it_is_set() {
        // A field that acts for the first second of scene time only.
        let timed = || {
            let mut pool = Analytic::whirlpool(4);
            if let Some((_, domain)) = &mut pool.field {
                domain.time_span_secs = 1.0;
            }
            vec![pool]
        };
        let inside = DVec3::new(0.8, 0.35, 0.0) / rig().zone.world_per_device_metre;
        let first_force = |start: Option<f64>| {
            let (mut servo, link) = Servo::init(still_device(inside), rig());
            link.scenes.publish(Box::new(timed()));
            if let Some(t) = start {
                servo.set_time_secs(t);
            }
            // Past the cross-fade of the first entry.
            (0..20).map(|_| servo.step(0.001)).last().unwrap()
        };
        let early = first_force(None);
        assert_eq!(early.top_id, Some(4));
        assert!(early.force_newtons.length() > 0.01, "{early:?}");
        let late = first_force(Some(5.0));
        assert_eq!(late.top_id, Some(4));
        assert_eq!(late.force_newtons, DVec3::ZERO, "the field's span is over");
    }

    #[test]
    fn device_failure_is_zero_force_and_counted() {
        let trace = Trace {
            caps: Capabilities::desktop_pen(),
            events: vec![crate::device::trace::TraceEvent::Sample(DeviceSample::at(
                DVec3::ZERO,
                1000,
            ))],
        };
        let (mut servo, link) = Servo::init(TraceDevice::new(&trace), rig());
        link.scenes.publish(Box::new(vec![ball(1, 1.0)]));
        assert!(!servo.step(0.001).stalled);
        let out = servo.step(0.001);
        assert!(out.stalled && out.force_newtons == DVec3::ZERO);
        assert_eq!(link.stats.snapshot().n_device_errors, 1);
        assert_eq!(servo.device().forces_newtons().last(), Some(&DVec3::ZERO));
    }

    #[test]
    fn histogram_quantiles() {
        let h = Histogram::new();
        assert_eq!(h.quantile_micros(0.5), 0);
        for micros in 0..1000 {
            h.record(micros);
        }
        h.record(1_000_000);
        // Upper bucket edges: the median 500 us lies in [500, 510).
        assert_eq!(h.quantile_micros(0.5), 510);
        assert_eq!(h.quantile_micros(0.99), 1000);
        assert_eq!(
            h.quantile_micros(1.0),
            HISTOGRAM_BUCKETS as u64 * HISTOGRAM_BUCKET_MICROS
        );
        assert_eq!(h.max_micros.load(Ordering::Relaxed), 1_000_000);
    }

    #[test]
    fn paced_thread_runs_swaps_and_stops() {
        let (servo, link) = Servo::init(still_device(DVec3::ZERO), rig());
        link.scenes.publish(Box::new(vec![ball(3, 1.0)]));
        let config = ServoConfig {
            realtime_priority: false,
            thread_name: "haptic-servo-test".into(),
            ..ServoConfig::default()
        };
        assert!(matches!(
            spawn(
                Servo::init(still_device(DVec3::ZERO), rig()).0 as Servo<_, Vec<Analytic>>,
                &ServoConfig {
                    rate_hz: 0.0,
                    ..config.clone()
                }
            ),
            Err(SpawnError::BadRate(_))
        ));
        let handle = spawn(servo, &config).unwrap();
        assert_eq!(handle.priority(), Priority::Normal);
        // Wait (bounded) for ticks; no assertion on timing.
        for _ in 0..5_000 {
            if link.stats.snapshot().n_ticks >= 50 {
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let servo = handle.stop().unwrap();
        let stats = link.stats.snapshot();
        assert!(stats.n_ticks >= 50, "{stats:?}");
        assert_eq!(stats.top_id, Some(3));
        assert!(stats.period_micros[3] > 0 && stats.period_micros[0] <= stats.period_micros[3]);
        assert_eq!(
            servo.device().force_newtons(),
            DVec3::ZERO,
            "force zeroed on stop"
        );
        assert_eq!(servo.state().stack().entries().len(), 1);
    }
}
