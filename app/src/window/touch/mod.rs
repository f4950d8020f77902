//! Touching the scene: the haptic servo on the live scene (driven by the mouse or a 3D
//! mouse), its force sent to a force-feedback device, the tool held with another peer, the
//! path recorded, and what the viewport draws of it (the zone, the tool, the force). The
//! Touch section of the side panel is `panel.rs`.

mod panel;

use std::sync::mpsc::Receiver;
use std::time::Instant;

use render::mesh::Aabb;
use render::scene::Scene;
use render::snapshot::render_from_scene;

use super::app::SculptApp;
use super::objects::moved_box;
use ::app::clock;
use ::app::engine::lock;
use ::app::touch::body::ToolBody;
use ::app::touch::live::LiveTouch;
use ::app::touch::probe;
use ::app::touch::record::{ForceHistory, ForceSample, Recorder};
use ::app::touch::shared::{SharedState, SharedTool};
use ::app::touch::spacemouse::SpaceMouseDriver;
use haptic::device::hid::HidDeviceInfo;
use replication::PeerId;

/// Colours of the haptic zone, the touch tool and the force it meets.
const TOUCH_ZONE_COLOUR: [f32; 4] = [0.9, 0.9, 0.9, 0.6];
const TOUCH_TOOL_COLOUR: [f32; 4] = [0.2, 0.9, 1.0, 1.0];
const TOUCH_FORCE_COLOUR: [f32; 4] = [1.0, 0.3, 0.2, 1.0];

/// The force-feedback devices found, or why none could be listed.
pub type DeviceList = Result<Vec<HidDeviceInfo>, String>;

/// Everything of touch the window keeps.
pub struct Touch {
    /// Touch with the mouse: the servo on the live scene, while on.
    pub live: Option<LiveTouch>,
    /// A 3D mouse moving the touch tool, while chosen and touch is on; its button presses
    /// arrive on the receiver.
    pub spacemouse: Option<(SpaceMouseDriver, Receiver<bool>)>,
    /// The shared tool (while touching): coupled with the peer it is held with when that
    /// peer holds it back.
    pub shared_tool: Option<SharedTool>,
    /// The peer this user holds the touch tool with.
    pub hold_with: Option<PeerId>,
    /// Where holding the tool with that peer stands.
    pub shared_state: SharedState,
    /// The touch tool's body, which other peers feel while it is tangible.
    pub body: ToolBody,
    /// The force-feedback devices last listed for the Touch section, or why none could be.
    force_devices: Option<DeviceList>,
    /// A listing under way, on a thread of its own.
    force_listing: Option<Receiver<DeviceList>>,
    /// A force-feedback device being opened, on a thread of its own.
    force_opening: Option<::app::touch::force_output::Opening>,
    /// The touch tool's path being recorded, and when recording began.
    pub recording: Option<(Recorder, Instant)>,
    /// Recent force and energy for the Touch section's plot, timed from `opened`.
    pub force_history: ForceHistory,
    /// When the window opened.
    opened: Instant,
}

impl Touch {
    /// Not touching; `opened` is when the window opened (the plot's time zero).
    pub fn new(opened: Instant) -> Touch {
        Touch {
            live: None,
            spacemouse: None,
            shared_tool: None,
            hold_with: None,
            shared_state: SharedState::Alone,
            body: ToolBody::default(),
            force_devices: None,
            force_listing: None,
            force_opening: None,
            recording: None,
            force_history: ForceHistory::default(),
            opened,
        }
    }
}

impl SculptApp {
    /// Starts or stops touching the scene with the mouse (the servo and its feed).
    pub(super) fn set_touching(&mut self, on: bool) -> Result<(), String> {
        match (on, self.touch.live.take()) {
            (true, None) => {
                let view = std::sync::Arc::clone(self.engine.view());
                let model = ::app::touch::DeviceModel::Falcon;
                let live = LiveTouch::start(view, model)?;
                match SharedTool::start(&self.engine, live.shared_link()) {
                    Ok(tool) => self.touch.shared_tool = Some(tool),
                    Err(e) => log::warn!("no shared tool: {e}"),
                }
                self.touch.live = Some(live);
                self.status = "touching with the mouse: the tool follows the pointer; \
                               Shift+wheel moves it in depth"
                    .into();
            }
            (true, Some(live)) => self.touch.live = Some(live),
            (false, Some(live)) => {
                self.touch.spacemouse = None;
                self.stop_touch_recording();
                if let Some(tool) = self.touch.shared_tool.take() {
                    tool.stop(&self.engine);
                }
                self.touch.shared_state = SharedState::Alone;
                live.stop();
            }
            (false, None) => {}
        }
        Ok(())
    }

    /// What touch does each frame after the viewport: the device's button (the viewport's or
    /// a 3D mouse's), the stroke it holds, the plot and recording, the shared tool and the
    /// force-feedback device.
    pub(super) fn touch_frame(&mut self, viewport_button: Option<bool>) {
        if let Some(down) = viewport_button {
            self.touch_button(down);
        }
        let presses: Vec<bool> = self
            .touch
            .spacemouse
            .as_ref()
            .map(|(_, presses)| presses.try_iter().collect())
            .unwrap_or_default();
        for down in presses {
            self.touch_button(down);
        }
        self.follow_touch_stroke();
        self.record_touch();
        self.update_shared_tool();
        self.poll_force_output();
    }

    /// Sends the servo's force to the HID force-feedback device `ids` (`VID:PID`), opened on
    /// a thread of its own (the status line says how it went), or shows it only (`None`);
    /// touch must be on.
    pub(super) fn set_force_output(&mut self, ids: Option<(u16, u16)>) -> Result<(), String> {
        let Some(live) = &mut self.touch.live else {
            return Err("turn touch on before choosing a force-feedback device".into());
        };
        match ids {
            Some((vendor, product)) => {
                self.touch.force_opening =
                    Some(live.force_output_ref().start_open(vendor, product));
                self.status =
                    format!("opening the force-feedback device {vendor:04x}:{product:04x}…");
            }
            None => {
                self.touch.force_opening = None;
                live.force_output().close();
                self.status = live.force_output_ref().status();
            }
        }
        Ok(())
    }

    /// Takes what the force-feedback threads answered, and closes devices the servo handed
    /// back.
    fn poll_force_output(&mut self) {
        let touch = &mut self.touch;
        if let Some(rx) = &touch.force_listing
            && let Ok(listed) = rx.try_recv()
        {
            touch.force_devices = Some(listed);
            touch.force_listing = None;
        }
        let Some(live) = &mut touch.live else {
            touch.force_opening = None;
            return;
        };
        live.force_output_ref().collect();
        if let Some(opening) = &touch.force_opening
            && let Some(outcome) = live.force_output().finish_open(opening)
        {
            self.status = match outcome {
                Ok(()) => live.force_output_ref().status(),
                Err(e) => e,
            };
            touch.force_opening = None;
        }
    }

    /// Couples the shared tool when the peer it is held with holds it back, and uncouples
    /// when either lets go.
    fn update_shared_tool(&mut self) {
        let Some(tool) = &self.touch.shared_tool else {
            return;
        };
        let me = self.engine.peer_id();
        let view = lock(self.engine.view());
        let theirs = self.touch.hold_with.and_then(|p| view.presence().get(&p));
        let state = tool.update(me, self.touch.hold_with, theirs);
        drop(view);
        if state == self.touch.shared_state {
            return;
        }
        let name = |p| lock(self.engine.view()).peer_label(p);
        self.status = match state {
            SharedState::Coupled(p) => {
                format!(
                    "holding the tool with {}: each of you feels the other",
                    name(p)
                )
            }
            SharedState::Waiting(p) => format!("waiting for {} to hold the tool with you", name(p)),
            SharedState::Alone => "holding the tool alone".into(),
        };
        self.touch.shared_state = state;
    }

    /// Adds this frame's force and energy to the plot and, while recording, the tool's point
    /// to the recorded path.
    fn record_touch(&mut self) {
        let Some(live) = &self.touch.live else {
            return;
        };
        let s = live.stats();
        let now = clock::now().instant;
        self.touch.force_history.push(ForceSample {
            t_secs: (now - self.touch.opened).as_secs_f64(),
            force_newtons: s.force_newtons.length(),
            energy_joules: s.energy_joules,
        });
        let button = live.button_down();
        let Some((recorder, since)) = &mut self.touch.recording else {
            return;
        };
        match recorder.push((now - *since).as_secs_f64(), s.hip_world, button) {
            Ok(true) => {}
            Ok(false) => {
                self.status = "the touch recording reached its limit and stopped".into();
                self.stop_touch_recording();
            }
            Err(e) => {
                self.status = format!("cannot record the touch path: {e}");
                self.touch.recording = None;
            }
        }
    }

    /// Records the touch tool's path to `path` (touch must be on), replayable with
    /// `sculpt touch SCENE --trace PATH`.
    pub(super) fn start_touch_recording(&mut self, path: &std::path::Path) -> Result<(), String> {
        if self.touch.live.is_none() {
            return Err("turn touch on before recording".into());
        }
        let recorder = Recorder::create(path)
            .map_err(|e| format!("cannot record to {}: {e}", path.display()))?;
        self.touch.recording = Some((recorder, clock::now().instant));
        self.status = format!("recording the touch path to {}", path.display());
        Ok(())
    }

    /// Stops recording and says where the path went.
    pub(super) fn stop_touch_recording(&mut self) {
        if let Some((recorder, _)) = self.touch.recording.take() {
            self.status = match recorder.finish() {
                Ok((path, n)) => format!(
                    "recorded {n} points to {}: replay with `sculpt touch SCENE --trace {}`",
                    path.display(),
                    path.display()
                ),
                Err(e) => format!("the touch recording could not be finished: {e}"),
            };
        }
    }

    /// Moves the touch tool with a 3D mouse (`true`, turning touch on if need be) or with the
    /// pointer alone (`false`). Without a 3D mouse the driver keeps looking and says so.
    pub(super) fn set_spacemouse(&mut self, on: bool) -> Result<(), String> {
        if !on {
            self.touch.spacemouse = None;
            return Ok(());
        }
        if self.touch.spacemouse.is_some() {
            return Ok(());
        }
        self.set_touching(true)?;
        let Some(live) = &self.touch.live else {
            return Err("touch did not start".into());
        };
        let (press, presses) = std::sync::mpsc::channel();
        let driver = SpaceMouseDriver::spawn(live.mouse_handle(), move |down| {
            let _ = press.send(down);
        })
        .map_err(|e| format!("cannot start the 3D mouse thread: {e}"))?;
        self.touch.spacemouse = Some((driver, presses));
        Ok(())
    }

    /// Moves the touch tool under the pointer, in the plane through it that faces the
    /// camera, then `depth` scene units away from the camera.
    pub(super) fn touch_follow(&self, px: Option<[f32; 2]>, size_px: [u32; 2], depth: f32) {
        let Some(live) = &self.touch.live else {
            return;
        };
        let to_render = render_from_scene();
        let hip = to_render.transform_point3(live.stats().hip_world.as_vec3());
        let camera = &self.view.camera;
        let forward = (camera.target - camera.eye()).normalize_or_zero();
        let mut target = hip;
        if let Some(px) = px {
            let ray = camera.ray_through_pixel(px, size_px);
            let facing = ray.direction.dot(forward);
            if facing.abs() > 1e-6 {
                let s = (hip - ray.origin).dot(forward) / facing;
                target = ray.origin + ray.direction * s;
            }
        }
        target += forward * depth;
        if target != hip {
            let scene_point = to_render.inverse().transform_point3(target);
            live.move_to_world(scene_point.as_dvec3());
        }
    }

    /// The density under the live touch tool, in the object it touches (see [`probe`]), with
    /// the engine's view already locked.
    pub(super) fn sampled_density_in(&self, view: &::app::engine::View) -> Option<f64> {
        let stats = self.touch.live.as_ref()?.stats();
        let t = self.scene_clock.secs(clock::now().instant);
        if stats.n_scenes_taken == 0 {
            // The servo has no scene yet, so no word on what it touches: look it up.
            return probe::density_under(view.scene(), None, stats.hip_world, t);
        }
        // Once it has, it names the object (or none, in empty space): one sampler a frame.
        probe::density_at(view.scene(), stats.top_id?, stats.hip_world, t)
    }

    /// The haptic zone, the tool at the haptic interface point and the force it meets.
    pub(super) fn draw_touch(&self, scene: &mut Scene) {
        let Some(live) = &self.touch.live else {
            return;
        };
        let to_render = render_from_scene();
        let zone = live.zone_box();
        let zone = Aabb::new(zone.min.as_vec3().to_array(), zone.max.as_vec3().to_array());
        scene.add_box(moved_box(&zone, &to_render), TOUCH_ZONE_COLOUR);
        let stats = live.stats();
        let hip = to_render.transform_point3(stats.hip_world.as_vec3());
        let size = (zone.hi[0] - zone.lo[0]) * 0.03;
        scene.add_crosshair(hip, size, TOUCH_TOOL_COLOUR);
        // The sampling sphere, coloured by the density under the tool.
        let radius = f64::from(zone.hi[0] - zone.lo[0]) * probe::SAMPLING_RADIUS_OF_ZONE;
        let density = self.sampled_density_in(&lock(self.engine.view()));
        scene.add_tool(
            &model::object::ToolShape::Sphere { radius },
            glam::Mat4::from_translation(hip),
            probe::sampling_colour(density),
        );
        let force = stats.force_newtons.as_vec3();
        if force.length() > 1e-3 {
            // One zone-width per device maximum (the zone does not rotate: device axes are
            // scene axes).
            let max = live.model().capabilities().force_newtons_max as f32;
            let reach = to_render.transform_vector3(force / max * (zone.hi[0] - zone.lo[0]) * 0.25);
            scene.add_arrow(hip, hip + reach, TOUCH_FORCE_COLOUR);
        }
    }
}
