//! Test hooks, set from the command line: scripted command lines (`--command`, run by the
//! step table of `steps.rs`), a scripted pick (`--pick`), a screenshot of the real window
//! once everything is meshed (`--screenshot`), closing when idle (`--exit-when-idle`) or
//! after a number of frames (`--exit-after-frames`), and a JSON dump of what the window
//! shows (`--dump-state`, written by `dump.rs`).
//!
//! Each scripted step waits until every object is drawn as the scene has it, so a screenshot
//! shows the result of every command before it. A hook that cannot finish (a screenshot that
//! cannot be saved, a frame limit reached first) is an error the process exits non-zero with.

mod dump;
pub(super) mod steps;

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, channel};
use std::sync::{Arc, Mutex};

use eframe::egui;
use glam::DVec3;
use plot::image::RgbaImage;

use super::WindowArgs;
use super::app::SculptApp;
use super::viewport::{StrokeEvent, StrokePhase};
use ::app::engine::lock;

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
    touch_drag: Option<([DVec3; 2], u32)>,
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
    /// The hooks the window's flags ask for: `--drag` and `--key` run after the
    /// `--command` lines, as the script lines `drag: ...` and `key: ...`.
    pub fn from_args(args: &WindowArgs) -> Hooks {
        let mut script: VecDeque<String> = args.command.iter().cloned().collect();
        for [[x0, y0], [x1, y1]] in &args.drag {
            script.push_back(format!("drag: {x0},{y0}:{x1},{y1}"));
        }
        for key in &args.key {
            script.push_back(format!("key: {key}"));
        }
        Hooks {
            script,
            pick: args.pick,
            screenshot: args.screenshot.clone(),
            exit_when_idle: args.exit_when_idle,
            exit_after_frames: args.exit_after_frames,
            dump_state: args.dump_state.clone(),
            wait_ops: args.wait_ops,
            wait_presence: args.wait_presence,
            ..Hooks::default()
        }
    }

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
    pub fn scripted_stroke(&mut self, size_px: [u32; 2]) -> Option<StrokeEvent> {
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

    /// Whether the screenshot asked for is still to be saved.
    fn screenshot_missing(&self) -> bool {
        self.screenshot.is_some() && !self.screenshot_done
    }
}

impl SculptApp {
    /// Advances the hooks by one frame: a frame limit, a saved screenshot, a touch stroke
    /// under way, the steady watch, then (once everything is drawn and synced) the next
    /// scripted step, and after the last the pick, the screenshot and closing.
    pub(super) fn run_hooks(&mut self, ctx: &egui::Context) {
        if !self.hooks.active() || self.hooks.closing {
            return;
        }
        ctx.request_repaint();
        if self.frame_limit_reached() || self.screenshot_saved() {
            self.close(ctx);
            return;
        }
        if let Some(([from, to], frame)) = self.hooks.touch_drag {
            self.touch_drag_frame(from, to, frame);
            return;
        }
        self.watch_touch_steady();
        if !self.ready_for_step() {
            return;
        }
        if let Some(line) = self.hooks.script.pop_front() {
            self.run_step(&line);
            self.hooks.idle_frames = 0;
            return;
        }
        self.finish_script(ctx);
    }

    /// Whether `--exit-after-frames` is reached; a hook left unfinished then is a failure.
    fn frame_limit_reached(&mut self) -> bool {
        let Some(limit) = self
            .hooks
            .exit_after_frames
            .filter(|limit| self.stats.n_frames >= *limit)
        else {
            return false;
        };
        if !self.hooks.script.is_empty() || self.hooks.screenshot_missing() {
            self.hooks.fail(format!(
                "gave up after {limit} frames: {} scripted commands left, screenshot {}, \
                 {} objects still meshing",
                self.hooks.script.len(),
                if self.hooks.screenshot_done {
                    "saved"
                } else {
                    "not taken"
                },
                self.objects.n_meshing()
            ));
        }
        true
    }

    /// Whether the screenshot asked for has just been saved (or failed to be).
    fn screenshot_saved(&mut self) -> bool {
        let Some(saved) = self
            .hooks
            .screenshot_rx
            .as_ref()
            .and_then(|rx| rx.try_recv().ok())
        else {
            return false;
        };
        self.hooks.screenshot_rx = None;
        self.hooks.screenshot_done = true;
        if let Err(e) = saved {
            self.hooks.fail(e);
        }
        true
    }

    /// Ends a `wait-touch-steady` step once the servo has run steady, keeping its force.
    fn watch_touch_steady(&mut self) {
        let (Some(watch), Some(live)) = (&mut self.hooks.touch_steady, &self.touch.live) else {
            return;
        };
        let stats = live.stats();
        if watch.observe(&stats, ::app::clock::now().instant) {
            let force = stats.force_newtons.to_array();
            println!("sculpt: the servo ran steady: force {force:?} N");
            self.hooks.steady_force = Some(force);
            self.hooks.touch_steady = None;
        }
    }

    /// Counts the frames everything has been drawn and the waits are met; whether the next
    /// step may run (no screenshot or scripted drag under way either).
    fn ready_for_step(&mut self) -> bool {
        let synced = self.hooks.touch_steady.is_none() && {
            let view = lock(self.engine.view());
            self.hooks.wait_ops.is_none_or(|n| view.n_ops() >= n)
                && self.hooks.step_ops.is_none_or(|n| view.n_ops() >= n)
                && view.presence().len() >= self.hooks.wait_presence
                && view.snapshot().is_none_or(|s| !s.busy)
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
        self.hooks.idle_frames >= IDLE_FRAMES_BEFORE_STEP
            && self.hooks.screenshot_rx.is_none()
            && self.hooks.drag.is_none()
    }

    /// After the script: the pick (the viewport takes it this frame), then the screenshot,
    /// then closing.
    fn finish_script(&mut self, ctx: &egui::Context) {
        if self.hooks.pick.is_some() {
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

    /// Closes the window, writing the state dump first when asked for.
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

    /// One frame of a scripted touch stroke: the tool goes to its start, the button goes
    /// down once the servo has moved it there (two frames at the least), the tool moves along
    /// the segment over `DRAG_FRAMES` frames, and the button comes up.
    fn touch_drag_frame(&mut self, from: DVec3, to: DVec3, frame: u32) {
        let Some(live) = &self.touch.live else {
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
