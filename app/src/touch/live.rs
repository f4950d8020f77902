//! Touch in the running app: the 1 kHz servo on the live scene, driven by the mouse.
//!
//! [`LiveTouch::start`] fits a haptic zone around the scene's tangible objects, starts the
//! haptic crate's paced servo thread with a mouse-driven device, and the haptic crate's
//! [`Feed`] over the engine's view (which is its [`SceneSource`]), which hands the servo a new
//! snapshot whenever the view changes (only the changed objects are rebuilt).
//! The window moves the tip ([`LiveTouch::move_by_world`], the pointer mapped through its own
//! camera) and reads what the servo did ([`LiveTouch::stats`]): the haptic interface point,
//! the force and the object touched. A mouse renders no force, so the forces are computed
//! for a device model (a Falcon-class device by default) and shown, not felt; the same
//! servo drives a force-feedback device when one is attached.

use std::collections::BTreeSet;

use glam::DVec3;
use haptic::aabb::Aabb;
use haptic::container::object::ObjectContainer;
use haptic::device::mouse::{MouseDevice, MouseHandle};
use haptic::device::{Capabilities, DeviceError, DeviceSample, HapticDevice};
use haptic::feed::{Feed, SceneSource, Snapshot};
use haptic::force::zone::HapticZone;
use haptic::servo::{Servo, ServoConfig, ServoHandle, ServoStats, StatsSnapshot, spawn};
use model::scene::{ObjectId, Scene};

use super::body::{PeerTool, peer_tools};
use super::force_output::{self, ForceOutput, OutputSlot};
use super::{DeviceModel, bounds_of, rig, zone_for};
use crate::engine::{SharedView, View, lock};

/// The engine's view as the servo's feed reads it: its scene, the objects each change
/// touched, and the other peers' tangible tools from their presence.
impl SceneSource for View {
    type Tool = PeerTool;

    fn scene(&self) -> &Scene {
        View::scene(self)
    }

    fn changes_since(&self, cursor: u64) -> (Option<BTreeSet<ObjectId>>, u64) {
        View::changes_since(self, cursor)
    }

    fn remote_tools(&self) -> Vec<PeerTool> {
        peer_tools(self.presence())
    }
}

/// The mouse's input with a device model's force capabilities: forces are computed for that
/// model and shown, never rendered.
pub struct ShownForce {
    mouse: MouseDevice,
    caps: Capabilities,
    /// A force-feedback device the force also goes to, when one is chosen.
    output: OutputSlot,
}

impl HapticDevice for ShownForce {
    fn capabilities(&self) -> &Capabilities {
        &self.caps
    }
    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        self.mouse.sample()
    }
    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError> {
        self.output.write(force_newtons);
        Ok(())
    }
}

/// The sizes a zone may take, relative to the one fitted at start.
pub const ZONE_SIZE_RANGE: (f64, f64) = (0.1, 10.0);

/// Where the tool starts, as a fraction of the workspace's height below its top.
const START_BELOW_TOP: f64 = 0.05;

/// Watches a running servo for a stretch of ticks with no stall. After a stall (a tick or a
/// device sample more than the stall time late, which a starved machine gives) the force is
/// zero and ramps in again, so a force read before such a stretch has passed may be a
/// recovery, not what the scene pushes with.
#[derive(Clone, Copy, Debug)]
pub struct SteadyWatch {
    window: std::time::Duration,
    since: std::time::Instant,
    n_stalls: u64,
}

impl SteadyWatch {
    /// Starts watching at `now`, when the servo had rendered `stats`; steady after `window`
    /// with no stall (at least the ramp-in, or the force may still be ramping).
    pub fn new(
        window: std::time::Duration,
        stats: &StatsSnapshot,
        now: std::time::Instant,
    ) -> Self {
        SteadyWatch {
            window,
            since: now,
            n_stalls: stats.n_stalls,
        }
    }

    /// Notes the servo's `stats` read at `now`; true once no tick has stalled for the window
    /// (a stall seen late restarts the window from when it was seen, never earlier).
    pub fn observe(&mut self, stats: &StatsSnapshot, now: std::time::Instant) -> bool {
        if stats.n_stalls != self.n_stalls {
            self.n_stalls = stats.n_stalls;
            self.since = now;
        }
        now.saturating_duration_since(self.since) >= self.window
    }
}

/// A running servo on the live scene with its feed and the mouse that moves it.
pub struct LiveTouch {
    servo: ServoHandle<ShownForce, Snapshot>,
    feed: Feed,
    waker: Box<dyn Fn() + Send>,
    stats: std::sync::Arc<ServoStats>,
    mouse: MouseHandle,
    /// The zone the servo renders with (changed by [`LiveTouch::set_zone`]).
    zone: HapticZone,
    /// The zone fitted at start, which sizes are relative to.
    fitted: HapticZone,
    /// The rig the servo renders with, less its zone, and where new ones go.
    rig: haptic::force::Rig,
    rigs: haptic::handoff::Publisher<haptic::force::Rig>,
    workspace: Aabb,
    model: DeviceModel,
    button: std::sync::atomic::AtomicBool,
    shared: std::sync::Arc<haptic::shared::SharedToolLink>,
    force_output: ForceOutput,
}

impl LiveTouch {
    /// Starts touching `view`'s scene with the mouse, forces computed for `model`.
    pub fn start(view: SharedView, model: DeviceModel) -> Result<LiveTouch, String> {
        let bounds = {
            let view = lock(&view);
            let (containers, _) = ObjectContainer::from_scene(view.scene());
            bounds_of(&containers)
        };
        let (mouse, handle) = MouseDevice::new();
        let model_caps = model.capabilities();
        let caps = Capabilities {
            n_dof_input: 3,
            workspace_metres: mouse.capabilities().workspace_metres,
            n_buttons: mouse.capabilities().n_buttons,
            ..model_caps
        };
        // The zone is fitted with the model's workspace, as `sculpt touch` fits it, so that a
        // recorded path replays to the forces shown here; the mouse's larger workspace only
        // gives the tool room around it.
        let zone = zone_for(&model_caps, bounds, None);
        // The tool starts near the top of the workspace, above the objects the zone is fitted
        // around: started at its centre it would begin inside them, and a hand that begins
        // inside a skin never feels it (the stack takes it as already through).
        let w = caps.workspace_metres;
        let start = DVec3::new(
            0.5 * (w.min.x + w.max.x),
            w.max.y - START_BELOW_TOP * (w.max.y - w.min.y),
            0.5 * (w.min.z + w.max.z),
        );
        handle.move_by_metres(start - handle.position_metres());
        let (force_output, output) = force_output::channel(caps.force_newtons_max);
        let device = ShownForce {
            mouse,
            caps,
            output,
        };
        let mut servo_rig = rig(model, zone);
        servo_rig.caps = caps;
        let base_rig = servo_rig;
        let (servo, link) = Servo::init(device, servo_rig);
        let stats = std::sync::Arc::clone(&link.stats);
        let shared = std::sync::Arc::clone(&link.shared);
        let rigs = link.rigs;
        let feed = Feed::spawn(view, link.scenes).map_err(|e| e.to_string())?;
        let config = ServoConfig {
            thread_name: "sculpt-servo".into(),
            ..ServoConfig::default()
        };
        let servo = match spawn(servo, &config) {
            Ok(servo) => servo,
            Err(e) => {
                feed.stop();
                return Err(e.to_string());
            }
        };
        Ok(LiveTouch {
            servo,
            waker: Box::new(feed.waker()),
            feed,
            stats,
            mouse: handle,
            zone,
            fitted: zone,
            rig: base_rig,
            rigs,
            workspace: caps.workspace_metres,
            model,
            button: std::sync::atomic::AtomicBool::new(false),
            shared,
            force_output,
        })
    }

    /// Moves the tip by `delta` in scene units (the window maps pointer motion through its
    /// camera into the scene first).
    pub fn move_by_world(&self, delta: DVec3) {
        let zone = self.zone();
        let metres = zone.device_from_world_dir(delta) * zone.device_metres(1.0);
        self.mouse.move_by_metres(metres);
    }

    /// The haptic zone the servo renders with.
    pub fn zone(&self) -> HapticZone {
        self.zone
    }

    /// Moves the zone so that its centre is at `center` (scene units) and scales it to
    /// `size` times the zone fitted at start (clamped to [`ZONE_SIZE_RANGE`]); the servo
    /// renders with it from its next tick. The tool moves with the zone (the hand did not
    /// move), and stiffness scales with it: a zone twice as large feels half as stiff per
    /// scene unit.
    pub fn set_zone(&mut self, center: DVec3, size: f64) {
        if !center.is_finite() || !size.is_finite() {
            return;
        }
        let size = size.clamp(ZONE_SIZE_RANGE.0, ZONE_SIZE_RANGE.1);
        let zone = HapticZone {
            center_world: center,
            world_per_device_metre: self.fitted.world_per_device_metre * size,
            ..self.fitted
        };
        self.zone = zone;
        self.rigs
            .publish(Box::new(haptic::force::Rig { zone, ..self.rig }));
        self.rigs.collect_retired();
    }

    /// The surface zone where a scene gives no depth, as the Touch section shows it
    /// ([`crate::touch::zone_depth_text`] for this device and zone).
    pub fn zone_depth_text(&self) -> String {
        crate::touch::zone_depth_text(&self.rig.caps, &self.zone)
    }

    /// The zone's size relative to the one fitted at start.
    pub fn zone_size(&self) -> f64 {
        self.zone().world_per_device_metre / self.fitted.world_per_device_metre
    }

    /// Moves the tip so that the haptic interface point is at `p` (scene units), as far as
    /// the workspace reaches.
    pub fn move_to_world(&self, p: DVec3) {
        let target = self.zone().device_from_world(p);
        self.mouse
            .move_by_metres(target - self.mouse.position_metres());
    }

    /// The mouse device the servo samples, for another input to move (a 3D mouse).
    pub fn mouse_handle(&self) -> MouseHandle {
        self.mouse.clone()
    }

    /// Presses or releases the device's button (bit 0).
    pub fn set_button(&self, down: bool) {
        self.mouse.set_buttons(u32::from(down));
        self.button
            .store(down, std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether the device's button is held.
    pub fn button_down(&self) -> bool {
        self.button.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Wakes the feed (the view changed) so that the servo gets the change in its next
    /// snapshot rather than at the feed's next poll.
    pub fn wake(&self) {
        (self.waker)();
    }

    /// What the servo has done: the haptic interface point, the force, the touched object,
    /// tick timing.
    pub fn stats(&self) -> StatsSnapshot {
        self.stats.snapshot()
    }

    /// The haptic zone's box in scene units (drawn in the view).
    pub fn zone_box(&self) -> Aabb {
        self.zone().box_world(self.workspace)
    }

    /// Where the force goes besides the screen: a force-feedback device, chosen while
    /// touching ([`super::force_output`]).
    pub fn force_output(&mut self) -> &mut ForceOutput {
        &mut self.force_output
    }

    /// [`LiveTouch::force_output`], to read.
    pub fn force_output_ref(&self) -> &ForceOutput {
        &self.force_output
    }

    /// The servo's shared-tool link, for [`super::shared::SharedTool`].
    pub fn shared_link(&self) -> std::sync::Arc<haptic::shared::SharedToolLink> {
        std::sync::Arc::clone(&self.shared)
    }

    /// A watch for a stretch without stalls twice the servo's ramp-in long, started now.
    pub fn steady_watch(&self) -> SteadyWatch {
        let window = std::time::Duration::from_secs_f64(2.0 * self.rig.params.ramp_in_secs);
        SteadyWatch::new(window, &self.stats(), crate::clock::now().instant)
    }

    /// The device model whose forces are computed.
    pub fn model(&self) -> DeviceModel {
        self.model
    }

    /// Stops the servo (force zeroed first) and the feed.
    pub fn stop(self) {
        if self.servo.stop().is_err() {
            log::error!("the servo thread panicked");
        }
        self.feed.stop();
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::engine::{Engine, EngineConfig, lock};

    /// An engine on loopback in a fresh scratch store (named by `tag`) holding the demo
    /// watermelon, once it is there, and the store's directory.
    pub(crate) fn watermelon_engine(tag: &str) -> (Engine, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("sculpt-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let config = EngineConfig {
            demo: crate::demos::find("watermelon").ok(),
            ..EngineConfig::on_loopback(&dir)
        };
        let engine = Engine::start(config, crate::clock::now().wall).unwrap();
        let deadline = crate::clock::now().instant + std::time::Duration::from_secs(20);
        while lock(engine.view()).scene().is_empty() {
            assert!(crate::clock::now().instant < deadline, "no demo");
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        (engine, dir)
    }

    /// Waits (at most 10 s) until `done` holds for the servo's statistics, and returns them.
    fn wait_stats(
        live: &LiveTouch,
        what: &str,
        mut done: impl FnMut(&StatsSnapshot) -> bool,
    ) -> StatsSnapshot {
        let deadline = crate::clock::now().instant + std::time::Duration::from_secs(10);
        loop {
            let stats = live.stats();
            if done(&stats) {
                return stats;
            }
            assert!(
                crate::clock::now().instant < deadline,
                "timed out waiting for {what}: {stats:?}"
            );
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }

    #[test]
    fn a_steady_watch_restarts_at_every_stall_it_sees() {
        let stats = |n_stalls| StatsSnapshot {
            n_ticks: 0,
            n_overruns: 0,
            n_device_errors: 0,
            n_stalls,
            n_scenes_taken: 0,
            period_micros: [0; 4],
            compute_micros: [0; 4],
            force_newtons: DVec3::ZERO,
            hip_world: DVec3::ZERO,
            top_id: None,
            energy_joules: 0.0,
        };
        let ms = std::time::Duration::from_millis;
        let t0 = crate::clock::now().instant;
        let mut watch = SteadyWatch::new(ms(500), &stats(3), t0);
        assert!(!watch.observe(&stats(3), t0 + ms(499)));
        // A stall seen at 499 ms: the window starts again there.
        assert!(!watch.observe(&stats(4), t0 + ms(499)));
        assert!(!watch.observe(&stats(4), t0 + ms(998)));
        assert!(watch.observe(&stats(4), t0 + ms(999)));
        // An instant before the window's start (clocks read out of order) is not steady.
        assert!(!watch.observe(&stats(5), t0 + ms(1_000)));
        assert!(!watch.observe(&stats(5), t0));
    }

    #[test]
    fn the_mouse_moves_the_servo_into_the_demo_watermelon_and_its_rind_pushes_out() {
        let (engine, dir) = watermelon_engine("live");
        let melon = lock(engine.view()).scene().objects().next().unwrap().0.0;
        let live =
            LiveTouch::start(std::sync::Arc::clone(engine.view()), DeviceModel::Falcon).unwrap();
        wait_stats(&live, "a snapshot", |s| s.n_scenes_taken >= 1);
        // Outside the melon: nothing touched, no force.
        live.move_to_world(DVec3::new(0.0, 1.09, 0.0));
        wait_stats(&live, "the tip above the melon", |s| {
            (s.hip_world - DVec3::new(0.0, 1.09, 0.0)).length() < 1e-3 && s.top_id.is_none()
        });
        // Into the rind's zone from above (the demo's rind is 0.05 deep; the wedge is cut
        // out of the melon's +x, +y, +z corner, so this is on the whole rind): the
        // Falcon-class force points up, out of the melon.
        live.move_to_world(DVec3::new(-0.2, (0.98f64 * 0.98 - 0.08).sqrt(), -0.2));
        wait_stats(&live, "the rind's push", |s| {
            s.top_id == Some(melon) && s.force_newtons.y > 1.0
        });
        let s = live.stats();
        assert!(s.force_newtons.length() <= 8.0 + 1e-9, "{s:?}");
        assert!(s.n_ticks > 0 && s.compute_micros[0] < 1_000, "{s:?}");
        let zone = live.zone_box();
        assert!(
            zone.min.x < -1.0 && zone.max.x > 1.0,
            "the zone covers the melon: {zone:?}"
        );
        live.stop();
        engine.shutdown();
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_zone_twice_as_large_reaches_further_and_feels_half_as_stiff() {
        let (engine, dir) = watermelon_engine("live-zone");
        let mut live =
            LiveTouch::start(std::sync::Arc::clone(engine.view()), DeviceModel::Falcon).unwrap();
        wait_stats(&live, "a snapshot", |s| s.n_scenes_taken >= 1);
        // 0.02 into the rind from above, at the fitted zone and at one twice as large.
        let above = DVec3::new(-0.2, 1.5, -0.2);
        let rind = DVec3::new(-0.2, (0.98f64 * 0.98 - 0.08).sqrt(), -0.2);
        let push = |live: &LiveTouch, what: &str| {
            live.move_to_world(above);
            wait_stats(live, &format!("{what}: above"), |s| s.top_id.is_none());
            live.move_to_world(rind);
            wait_stats(live, &format!("{what}: in the rind"), |s| {
                (s.hip_world - rind).length() < 1e-3 && s.force_newtons.y > 0.2
            });
            // Past the ramp-in and the rate limit, with no stall since (a starved machine
            // gives late ticks, and each restarts the ramp).
            let mut watch = live.steady_watch();
            let steady = wait_stats(live, &format!("{what}: steady"), |s| {
                watch.observe(s, crate::clock::now().instant)
            });
            steady.force_newtons.y
        };
        let fitted = push(&live, "fitted");
        let box_fitted = live.zone_box();
        let centre = live.zone().center_world;
        live.set_zone(centre, 2.0);
        assert!((live.zone_size() - 2.0).abs() < 1e-12);
        let big = live.zone_box();
        assert!(
            ((big.max.x - big.min.x) / (box_fitted.max.x - box_fitted.min.x) - 2.0).abs() < 1e-9,
            "{big:?} against {box_fitted:?}"
        );
        let larger = push(&live, "twice as large");
        let ratio = larger / fitted;
        assert!(
            (0.35..0.65).contains(&ratio),
            "{larger} N against {fitted} N"
        );
        // Sizes are clamped to the range.
        live.set_zone(centre, 1e6);
        assert_eq!(live.zone_size(), ZONE_SIZE_RANGE.1);
        live.stop();
        engine.shutdown();
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn another_peers_tangible_probe_is_felt_where_its_tool_is() {
        let (engine, dir) = watermelon_engine("live-probe");
        let live =
            LiveTouch::start(std::sync::Arc::clone(engine.view()), DeviceModel::Falcon).unwrap();
        wait_stats(&live, "a snapshot", |s| s.n_scenes_taken >= 1);
        // Above the melon: nothing there yet.
        live.move_to_world(DVec3::new(0.0, 1.5, 0.0));
        wait_stats(&live, "the tip above the melon", |s| {
            (s.hip_world.y - 1.5).abs() < 1e-3 && s.top_id.is_none()
        });
        // Another peer's tool arrives there: a probe of radius 0.1 with tension, centred at
        // y = 1.25 (its surface at 1.35), as its presence says (the renderer's world, +z up).
        let probe = crate::touch::body::ToolBody {
            radius: 0.1,
            tension: 0.8,
            friction: 0.0,
            density: 1.0,
        };
        let mut presence = engine.presence();
        presence.tool = Some([0.0, 0.0, 1.25]);
        presence.tool_body = Some(probe.to_wire());
        lock(engine.view()).note_presence(replication::PeerId([9; 32]), presence);
        // Down into its surface zone: the probe pushes the tool back up.
        live.move_to_world(DVec3::new(0.0, 1.33, 0.0));
        wait_stats(&live, "the probe's push", |s| {
            s.top_id == Some(haptic::feed::REMOTE_TOOL_ID_BASE) && s.force_newtons.y > 0.5
        });
        // The peer's tool goes intangible: it is gone from the servo's scene.
        let mut presence = engine.presence();
        presence.tool = Some([0.0, 0.0, 1.25]);
        presence.tool_body = None;
        lock(engine.view()).note_presence(replication::PeerId([9; 32]), presence);
        wait_stats(&live, "the probe gone", |s| s.top_id.is_none());
        live.stop();
        engine.shutdown();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
