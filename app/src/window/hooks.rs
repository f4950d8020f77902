//! Test hooks, set from the command line: scripted command lines (`--command`), a scripted
//! pick (`--pick`), a screenshot of the real window once everything is meshed
//! (`--screenshot`), closing when idle (`--exit-when-idle`) or after a number of frames
//! (`--exit-after-frames`), and a JSON dump of what the window shows (`--dump-state`).
//!
//! Each scripted step waits until every object is drawn as the scene has it, so a screenshot
//! shows the result of every command before it. A hook that cannot finish (a screenshot that
//! cannot be saved, a frame limit reached first) is an error the process exits non-zero with.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, channel};
use std::sync::{Arc, Mutex};

use eframe::egui;
use plot::image::RgbaImage;
use serde_json::{Value, json};

use super::app::SculptApp;
use super::viewport::{StrokeEvent, StrokePhase};
use ::app::engine::lock;

/// Longest `wait-secs:` step a script may ask for.
const MAX_WAIT_SECS: f64 = 60.0;

/// Frames a scripted drag takes from its start to its end.
const DRAG_FRAMES: u32 = 12;

/// How near (scene units) the servo's tool must be to a scripted touch stroke's start before
/// the stroke's button goes down.
const TOUCH_AT_TOLERANCE: f64 = 1e-3;

/// Frames every object must have been drawn as the scene has it before a scripted step runs
/// (one frame paints the new meshes, the next can be captured).
const IDLE_FRAMES_BEFORE_STEP: u32 = 2;

/// The hooks asked for, and their progress.
#[derive(Default)]
pub struct Hooks {
    /// Command lines to run, in order, as if typed.
    pub script: VecDeque<String>,
    /// A click to simulate, as fractions of the viewport's width and height.
    pub pick: Option<[f32; 2]>,
    /// Where to save a screenshot of the window once the script has run.
    pub screenshot: Option<PathBuf>,
    /// Close once the script has run (and the screenshot is saved).
    pub exit_when_idle: bool,
    /// Close after this many frames whatever happened (an error if a hook is unfinished).
    pub exit_after_frames: Option<u64>,
    /// Where to write the state as JSON when the window closes through a hook.
    pub dump_state: Option<PathBuf>,
    /// A `wait-ops: N` step: later steps wait until the session holds N ops.
    step_ops: Option<usize>,
    /// A `wait-secs: S` step: later steps wait until then (the scene's time runs on).
    step_until: Option<std::time::Instant>,
    /// A scripted drag in progress: from and to (fractions of the viewport), and the frame.
    drag: Option<([[f32; 2]; 2], u32)>,
    /// A scripted touch stroke in progress: from and to (scene coordinates), and the frame.
    touch_drag: Option<([glam::DVec3; 2], u32)>,
    /// A `wait-touch-steady` step: later steps wait until the servo has run without a stall
    /// for the watch's window.
    touch_steady: Option<::app::touch::live::SteadyWatch>,
    /// The force (newtons, device frame) when the last `wait-touch-steady` step ended.
    pub steady_force: Option<[f64; 3]>,
    /// Scripted steps wait until the session holds this many ops.
    pub wait_ops: Option<usize>,
    /// Scripted steps wait until this many other peers' presence is known.
    pub wait_presence: usize,
    /// Set when a hook failed; the process exits non-zero with it.
    pub failure: Arc<Mutex<Option<String>>>,
    idle_frames: u32,
    screenshot_rx: Option<Receiver<Result<(), String>>>,
    screenshot_done: bool,
    closing: bool,
}

impl Hooks {
    /// Whether any hook drives the window (then it repaints continuously).
    pub fn active(&self) -> bool {
        !self.script.is_empty()
            || self.pick.is_some()
            || self.screenshot.is_some()
            || self.exit_when_idle
            || self.exit_after_frames.is_some()
    }

    /// The scripted pick, once the script has run and everything is drawn.
    pub fn take_pick_if_ready(&mut self, idle: bool) -> Option<[f32; 2]> {
        if idle && self.script.is_empty() && self.idle_frames >= IDLE_FRAMES_BEFORE_STEP {
            self.pick.take()
        } else {
            None
        }
    }

    /// This frame's event of a scripted drag (`drag: X0,Y0:X1,Y1` in the script), if one runs.
    pub fn scripted_stroke(&mut self, size_px: [u32; 2], _idle: bool) -> Option<StrokeEvent> {
        let ([from, to], frame) = self.drag?;
        let t = (frame as f32 / DRAG_FRAMES as f32).min(1.0);
        let at = [0, 1].map(|a| (from[a] + (to[a] - from[a]) * t) * size_px[a] as f32);
        let phase = match frame {
            0 => StrokePhase::Begin,
            f if f > DRAG_FRAMES => StrokePhase::End,
            _ => StrokePhase::Move,
        };
        self.drag = (frame <= DRAG_FRAMES).then_some(([from, to], frame + 1));
        Some(StrokeEvent { phase, px: at })
    }

    fn fail(&self, message: String) {
        if let Ok(mut failure) = self.failure.lock()
            && failure.is_none()
        {
            *failure = Some(message);
        }
    }
}

impl SculptApp {
    /// Advances the hooks by one frame.
    pub(super) fn run_hooks(&mut self, ctx: &egui::Context) {
        if !self.hooks.active() || self.hooks.closing {
            return;
        }
        ctx.request_repaint();
        if let Some(limit) = self.hooks.exit_after_frames
            && self.stats.n_frames >= limit
        {
            if !self.hooks.script.is_empty()
                || (self.hooks.screenshot.is_some() && !self.hooks.screenshot_done)
            {
                self.hooks.fail(format!(
                    "gave up after {limit} frames: {} scripted commands left, screenshot {}, \
                     {} objects still meshing",
                    self.hooks.script.len(),
                    if self.hooks.screenshot_done {
                        "saved"
                    } else {
                        "not taken"
                    },
                    self.n_meshing()
                ));
            }
            self.close(ctx);
            return;
        }
        if let Some(rx) = &self.hooks.screenshot_rx
            && let Ok(saved) = rx.try_recv()
        {
            self.hooks.screenshot_rx = None;
            self.hooks.screenshot_done = true;
            if let Err(e) = saved {
                self.hooks.fail(e);
            }
            self.close(ctx);
            return;
        }
        if let Some(([from, to], frame)) = self.hooks.touch_drag {
            self.touch_drag_frame(from, to, frame);
            return;
        }
        if let (Some(watch), Some(live)) = (&mut self.hooks.touch_steady, &self.touch) {
            let stats = live.stats();
            if watch.observe(&stats, ::app::clock::now().instant) {
                let force = stats.force_newtons.to_array();
                println!("sculpt: the servo ran steady: force {force:?} N");
                self.hooks.steady_force = Some(force);
                self.hooks.touch_steady = None;
            }
        }
        let synced = self.hooks.touch_steady.is_none() && {
            let view = lock(self.engine.view());
            self.hooks.wait_ops.is_none_or(|n| view.n_ops() >= n)
                && self.hooks.step_ops.is_none_or(|n| view.n_ops() >= n)
                && view.presence().len() >= self.hooks.wait_presence
                && self
                    .hooks
                    .step_until
                    .is_none_or(|t| ::app::clock::now().instant >= t)
        };
        if self.is_idle() && synced {
            self.hooks.idle_frames = self.hooks.idle_frames.saturating_add(1);
        } else {
            self.hooks.idle_frames = 0;
        }
        if self.hooks.idle_frames < IDLE_FRAMES_BEFORE_STEP || self.hooks.screenshot_rx.is_some() {
            return;
        }
        if self.hooks.drag.is_some() {
            return;
        }
        if let Some(line) = self.hooks.script.pop_front() {
            if let Some(spec) = line.strip_prefix("drag:") {
                match parse_drag(spec.trim()) {
                    Ok(drag) => {
                        println!("sculpt: scripted drag: {spec}");
                        self.hooks.drag = Some((drag, 0));
                    }
                    Err(e) => self.hooks.fail(format!("bad scripted drag `{spec}`: {e}")),
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(n) = line.strip_prefix("wait-ops:") {
                match n.trim().parse::<usize>() {
                    Ok(n) => self.hooks.step_ops = Some(n),
                    Err(e) => self.hooks.fail(format!("bad `wait-ops: {n}`: {e}")),
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(secs) = line.strip_prefix("wait-secs:") {
                match secs.trim().parse::<f64>() {
                    Ok(s) if (0.0..=MAX_WAIT_SECS).contains(&s) => {
                        println!("sculpt: scripted wait: {s} s");
                        let wait = std::time::Duration::from_secs_f64(s);
                        self.hooks.step_until = Some(::app::clock::now().instant + wait);
                    }
                    _ => self.hooks.fail(format!(
                        "bad `wait-secs: {secs}`: a number of seconds up to {MAX_WAIT_SECS}"
                    )),
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if line.trim() == "wait-touch-steady" {
                match &self.touch {
                    Some(live) => self.hooks.touch_steady = Some(live.steady_watch()),
                    None => self
                        .hooks
                        .fail("`wait-touch-steady` before `touch: on`".into()),
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(word) = line.strip_prefix("touch:") {
                let on = match word.trim() {
                    "on" => true,
                    "off" => false,
                    other => {
                        self.hooks.fail(format!("bad `touch: {other}`: on or off"));
                        return;
                    }
                };
                println!("sculpt: scripted touch: {}", word.trim());
                if let Err(e) = self.set_touching(on) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(target) = line.strip_prefix("touch-record:") {
                let target = target.trim();
                println!("sculpt: scripted touch record: {target}");
                if target == "off" {
                    self.stop_touch_recording();
                } else if let Err(e) = self.start_touch_recording(std::path::Path::new(target)) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(zone) = line.strip_prefix("touch-zone:") {
                println!("sculpt: scripted zone: {}", zone.trim());
                let numbers: Vec<f64> = zone
                    .split([',', ' '])
                    .filter(|w| !w.is_empty())
                    .filter_map(|w| w.parse().ok())
                    .collect();
                match (&mut self.touch, numbers.as_slice()) {
                    (Some(live), &[x, y, z, size]) => {
                        live.set_zone(glam::DVec3::new(x, y, z), size);
                    }
                    (None, _) => self.hooks.fail("`touch-zone:` before `touch: on`".into()),
                    _ => self
                        .hooks
                        .fail(format!("bad `touch-zone: {zone}`: X,Y,Z SIZE")),
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(ids) = line.strip_prefix("touch-force:") {
                let ids = ids.trim();
                println!("sculpt: scripted force output: {ids}");
                let parsed = match ids {
                    "off" => Ok(None),
                    _ => ::app::touch::force_output::parse_ids(ids)
                        .map(Some)
                        .ok_or_else(|| format!("bad `touch-force: {ids}`: VID:PID in hex, or off")),
                };
                if let Err(e) = parsed.and_then(|ids| self.set_force_output(ids)) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(who) = line.strip_prefix("touch-share:") {
                let who = who.trim();
                println!("sculpt: scripted shared tool: {who}");
                if who == "off" {
                    self.hold_with = None;
                } else {
                    let found = lock(self.engine.view())
                        .peers()
                        .iter()
                        .find(|r| r.peer.short() == who || r.name == who)
                        .map(|r| r.peer);
                    match found {
                        Some(peer) => self.hold_with = Some(peer),
                        None => self.hooks.fail(format!(
                            "bad `touch-share: {who}`: no peer with that short id or name"
                        )),
                    }
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(word) = line.strip_prefix("touch-device:") {
                let on = match word.trim() {
                    "3d-mouse" => true,
                    "mouse" => false,
                    other => {
                        self.hooks
                            .fail(format!("bad `touch-device: {other}`: mouse or 3d-mouse"));
                        return;
                    }
                };
                println!("sculpt: scripted touch device: {}", word.trim());
                if let Err(e) = self.set_spacemouse(on) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(spec) = line.strip_prefix("touch-stroke:") {
                let point = |text: &str| -> Option<glam::DVec3> {
                    let v: Vec<f64> = text
                        .split(',')
                        .map(|c| c.trim().parse().ok())
                        .collect::<Option<_>>()?;
                    (v.len() == 3).then(|| glam::DVec3::new(v[0], v[1], v[2]))
                };
                let ends = spec
                    .split_once(':')
                    .and_then(|(a, b)| Some([point(a)?, point(b)?]));
                match (ends, self.touch.is_some()) {
                    (Some(ends), true) => {
                        println!("sculpt: scripted touch stroke: {}", spec.trim());
                        self.hooks.touch_drag = Some((ends, 0));
                    }
                    (None, _) => self.hooks.fail(format!(
                        "bad `touch-stroke: {spec}`: X0,Y0,Z0:X1,Y1,Z1 in scene coordinates"
                    )),
                    (_, false) => self.hooks.fail("`touch-stroke:` before `touch: on`".into()),
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(at) = line.strip_prefix("touch-at:") {
                let point: Vec<f64> = at
                    .split(',')
                    .filter_map(|v| v.trim().parse().ok())
                    .collect();
                match (&self.touch, point.as_slice()) {
                    (Some(live), &[x, y, z]) => live.move_to_world(glam::DVec3::new(x, y, z)),
                    (None, _) => self.hooks.fail("`touch-at:` before `touch: on`".into()),
                    _ => self.hooks.fail(format!("bad `touch-at: {at}`: X,Y,Z")),
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(path) = line.strip_prefix("import:") {
                println!("sculpt: scripted import: {path}");
                if let Err(e) = self.import_file(std::path::Path::new(path.trim())) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(path) = line.strip_prefix("export:") {
                println!("sculpt: scripted export: {path}");
                if let Err(e) = self.export_file(PathBuf::from(path.trim())) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(code) = line.strip_prefix("join:") {
                println!("sculpt: scripted join");
                if let Err(e) = self.join(code.trim()) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(name) = line.strip_prefix("demo:") {
                let name = name.trim();
                println!("sculpt: scripted demo: {name}");
                let opened = ::app::demos::find(name).and_then(|demo| self.open_demo(demo));
                if let Err(e) = opened {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            if let Some(key) = line.strip_prefix("key:") {
                println!("sculpt: scripted key: {key}");
                if let Err(e) = self.shortcut_named(key.trim()) {
                    self.hooks.fail(e);
                }
                self.hooks.idle_frames = 0;
                return;
            }
            println!("sculpt: scripted command: {line}");
            // As if typed: a line that fails stays in the input, above its error.
            self.input.clone_from(&line);
            self.submit(&line);
            if let Some(error) = &self.input_error {
                println!("sculpt: command error:\n{error}");
            }
            self.hooks.idle_frames = 0;
            return;
        }
        if self.hooks.pick.is_some() {
            // The viewport takes it this frame.
            return;
        }
        if let Some(path) = self.hooks.screenshot.clone()
            && !self.hooks.screenshot_done
        {
            let (tx, rx) = channel();
            self.hooks.screenshot_rx = Some(rx);
            let waker = ctx.clone();
            ctx.request_screenshot(move |image| {
                // The receiver lives as long as the app; a failed send means it is closing.
                let _ = tx.send(save_screenshot(&image, &path));
                waker.request_repaint();
            });
            return;
        }
        if self.hooks.exit_when_idle || self.hooks.screenshot.is_some() {
            self.close(ctx);
        }
    }

    fn close(&mut self, ctx: &egui::Context) {
        self.hooks.closing = true;
        if let Some(path) = &self.hooks.dump_state {
            let text = match serde_json::to_string_pretty(&self.state_json()) {
                Ok(text) => text,
                Err(e) => format!("{{\"error\": \"{e}\"}}"),
            };
            if let Err(e) = std::fs::write(path, text) {
                self.hooks
                    .fail(format!("cannot write the state to {}: {e}", path.display()));
            }
        }
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// What the window shows, as JSON (the `--dump-state` hook).
    pub fn state_json(&self) -> Value {
        let mut view = lock(self.engine.view());
        let objects: Vec<Value> = view
            .scene()
            .objects()
            .map(|(id, entry)| {
                let data = entry.object.data();
                let tracked = self.objects.get(&id);
                let history = entry.object.history();
                json!({
                    "id": id.0,
                    "name": view.object_label(id.0),
                    "n_edits": history.len(),
                    "n_active_edits": history.entries().iter().filter(|e| e.active).count(),
                    "lease_holder": view.lease(id.0).map(|l| l.holder.short()),
                    "geometry": data.geometry.as_ref().map(|g| format!("{:?}", g.shape)),
                    "diffuse": data.appearance.diffuse.as_ref().map(|c| format!("{c:?}")),
                    "n_triangles": tracked.map(|t| t.n_triangles),
                    "skipped": tracked.and_then(|t| t.skipped.clone()),
                    "mesh_secs": tracked.map(|t| t.mesh_secs),
                    "mesh_kind": tracked.and_then(|t| t.kind).map(|k| k.name()),
                    "mesh_t_secs": tracked.map(|t| t.drawn_t_secs),
                    "world_from_object": tracked.and_then(|t| {
                        let drawn = t.drawn.as_ref()?.world_from_object;
                        Some(t.moving.as_ref().map_or(drawn, |m| m.world_now).to_cols_array())
                    }),
                })
            })
            .collect();
        let rows = |rows: Vec<Value>| Value::Array(rows);
        let mut state = json!({
            "peer": view.peer_id().short(),
            "store": self.engine.store_dir().display().to_string(),
            "store_error": view.store_error(),
            "notices": view.notices(),
            "n_ops": view.n_ops(),
            "n_loaded": view.n_loaded(),
            "scene_hash": view.scene_hash_hex(),
            "time_secs": self.frame_time_secs,
            "window_points": self.layout.window_points,
            "touch": self.touch.as_ref().map(|live| {
                let s = live.stats();
                json!({
                    "hip": s.hip_world.to_array(),
                    "force": s.force_newtons.to_array(),
                    "steady_force": self.hooks.steady_force,
                    "n_stalls": s.n_stalls,
                    "top_id": s.top_id,
                    "n_ticks": s.n_ticks,
                    "n_overruns": s.n_overruns,
                    "period_micros": s.period_micros,
                    "n_scenes_taken": s.n_scenes_taken,
                    "compute_micros": s.compute_micros,
                    "device_status": self.spacemouse.as_ref().map(|(d, _)| d.status().text()),
                    "energy_joules": s.energy_joules,
                    "sampled_density": self.sampled_density_in(&view),
                    "sampling_colour":
                        ::app::touch::probe::sampling_colour(self.sampled_density_in(&view)),
                    "n_plotted": self.force_history.len(),
                    "recording": self.touch_recording.as_ref().map(|(r, _)| r.n_rows()),
                    "force_output": live.force_output_ref().status(),
                    "zone_centre": live.zone().center_world.to_array(),
                    "zone_size": live.zone_size(),
                    "n_force_writes": live.force_output_ref().n_writes(),
                    "shared_tool": self.shared_tool.as_ref().map(|tool| {
                        let st = tool.stats();
                        let (state, with) = match self.shared_state {
                            ::app::touch::shared::SharedState::Alone => ("alone", None),
                            ::app::touch::shared::SharedState::Waiting(p) => ("waiting", Some(p)),
                            ::app::touch::shared::SharedState::Coupled(p) => ("coupled", Some(p)),
                        };
                        json!({
                            "state": state,
                            "with": with.map(|p| p.short()),
                            "n_sent": st.n_sent,
                            "n_received": st.n_received,
                            "n_dropped": st.n_dropped,
                            "force": st.force_newtons.to_array(),
                            "energy_in_joules": st.energy_in_joules,
                            "energy_out_joules": st.energy_out_joules,
                        })
                    }),
                })
            }),
            "side_panel_points": self.layout.side_panel_points,
            "my_tool": self.presence_sent.as_ref().and_then(|p| p.tool),
            "my_tool_body": self.presence_sent.as_ref().and_then(|p| p.tool_body),
            "playing": self.scene_clock.playing(),
            "selected": self.selected.map(|id| view.object_label(id)),
            "peers": rows(view.peers().iter().map(|p| json!({
                "peer": p.peer.short(), "name": p.name, "online": p.online,
                "addr": p.addr, "how": p.how,
                "rtt_micros": p.rtt_micros, "to_send": p.to_send, "to_receive": p.to_receive,
            })).collect()),
            "news": self.news,
            "tool": self.brush.describe(),
            "name": self.engine.presence().name,
            "sculpting": self.sculpting,
            "last_stroke": self.last_stroke.as_ref().map(|points| {
                points.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>()
            }),
            "probes": self.probes(&view),
            "my_rejections": view.my_rejections().iter().map(|r| r.why.clone()).collect::<Vec<_>>(),
            "presence": rows(view.presence().iter().map(|(peer, p)| json!({
                "peer": peer.short(), "name": p.name, "colour": p.colour,
                "pointer": p.pointer, "tool": p.tool, "selected": p.selected,
            })).collect()),
            "objects": objects,
            "chat": rows(self.chat.iter().map(|c| json!({
                "author": c.author, "time": c.time, "text": c.text,
            })).collect()),
            "history": rows(self.history.iter().map(|h| json!({
                "author": h.author, "time": h.time, "what": h.what, "status": h.status,
            })).collect()),
            "input_error": self.input_error,
            "status": self.status,
            "pick": self.pick_status,
            "viewport_error": self.viewport.lock().ok().and_then(|r| r.error.clone()),
            "prepare_ms": self.viewport.lock().ok().map(|r| summary(&r.prepare_ms)),
            "frames": self.stats.n_frames,
            "ui_ms": summary(&self.stats.ui_ms),
            "frame_interval_ms": summary(&self.stats.frame_interval_ms),
            "edit_to_mesh_ms": self.stats.edit_to_mesh_ms,
            "meshes": json!({
                "patched": self.stats.n_patched,
                "whole": self.stats.n_whole,
            }),
            "last_upload_bytes": self.viewport.lock().ok().map(|r| r.last_upload_bytes),
            "min_upload_bytes": self.viewport.lock().ok().and_then(|r| r.min_upload_bytes),
            "patches_refused": self.viewport.lock().ok().map(|r| r.n_patches_refused),
        });
        // Beside the rest: one more key inside `json!` passes the macro's recursion limit.
        if let Some(live) = &self.touch {
            state["touch"]["zone_depth"] = live.zone_depth_text().into();
        }
        state
    }
}

impl SculptApp {
    /// The selected object's value and scalar properties at the last stroke's points (scene
    /// coordinates), for tests that check what a stroke did through the engine.
    fn probes(&self, view: &::app::engine::View) -> Value {
        use model::object::Paintable;
        let (Some(points), Some(id)) = (&self.last_stroke, self.selected) else {
            return Value::Null;
        };
        let scene = view.scene();
        let Some(entry) = scene.scene_object(model::scene::ObjectId(id)) else {
            return Value::Null;
        };
        let scene_from_object = scene
            .world_from_group(entry.group)
            .then(&entry.object.data().transform);
        let Some(object_from_scene) = scene_from_object.inverse() else {
            return Value::Null;
        };
        let mut sampler = entry.object.sampler();
        let rows: Vec<Value> = points
            .iter()
            .map(|p| {
                let q = object_from_scene.point(*p);
                json!({
                    "at": [p.x, p.y, p.z],
                    "value": sampler.value(q, 0.0),
                    "density": sampler.scalar(Paintable::Density, q, 0.0),
                    "tension": sampler.scalar(Paintable::Tension, q, 0.0),
                })
            })
            .collect();
        Value::Array(rows)
    }
}

/// `X0,Y0:X1,Y1`, fractions of the viewport.
pub fn parse_drag(text: &str) -> Result<[[f32; 2]; 2], String> {
    let point = |p: &str| -> Result<[f32; 2], String> {
        let (x, y) = p.split_once(',').ok_or("a point is X,Y")?;
        let f = |v: &str| {
            v.trim()
                .parse::<f32>()
                .ok()
                .filter(|f| (0.0..=1.0).contains(f))
                .ok_or(format!("`{v}` is not a fraction from 0 to 1"))
        };
        Ok([f(x)?, f(y)?])
    };
    let (a, b) = text.split_once(':').ok_or("a drag is X0,Y0:X1,Y1")?;
    Ok([point(a)?, point(b)?])
}

/// Mean, median, 95th percentile and maximum of some samples.
fn summary(samples: &[f64]) -> Value {
    if samples.is_empty() {
        return Value::Null;
    }
    let mut sorted = samples.to_vec();
    sorted.sort_by(f64::total_cmp);
    let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
    json!({
        "n": sorted.len(),
        "mean": sorted.iter().sum::<f64>() / sorted.len() as f64,
        "p50": at(0.5),
        "p95": at(0.95),
        "max": at(1.0),
    })
}

/// Writes egui's screenshot as a PNG.
fn save_screenshot(image: &egui::ColorImage, path: &std::path::Path) -> Result<(), String> {
    let [width, height] = image.size;
    let picture = RgbaImage {
        width: width as u32,
        height: height as u32,
        pixels: image.pixels.iter().flat_map(|c| c.to_array()).collect(),
    };
    picture
        .save_png(path)
        .map(|()| println!("sculpt: screenshot saved to {}", path.display()))
        .map_err(|e| format!("cannot save the screenshot to {}: {e}", path.display()))
}

impl SculptApp {
    /// One frame of a scripted touch stroke: the tool goes to its start, the button goes
    /// down once the servo has moved it there (two frames at the least), the tool moves along
    /// the segment over `DRAG_FRAMES` frames, and the button comes up.
    fn touch_drag_frame(&mut self, from: glam::DVec3, to: glam::DVec3, frame: u32) {
        let Some(live) = &self.touch else {
            self.hooks.touch_drag = None;
            self.hooks.fail("the touch stroke lost its device".into());
            return;
        };
        let moving = frame.saturating_sub(2);
        match frame {
            0 => live.move_to_world(from),
            // The button goes down once the servo has put the tool there (a starved machine
            // can leave it a few frames behind); the frame limit bounds the wait.
            1 if live.stats().hip_world.distance(from) > TOUCH_AT_TOLERANCE => return,
            1 => {}
            2 => self.touch_button(true),
            _ if moving <= DRAG_FRAMES => {
                live.move_to_world(from.lerp(to, f64::from(moving) / f64::from(DRAG_FRAMES)));
            }
            _ => {
                self.touch_button(false);
                self.hooks.touch_drag = None;
                self.hooks.idle_frames = 0;
                return;
            }
        }
        self.hooks.touch_drag = Some(([from, to], frame + 1));
    }
}
