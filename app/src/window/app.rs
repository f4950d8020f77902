//! `SculptApp`, the eframe app: the coordinator of a frame. It holds the session's engine,
//! the selection and the status lines, and one part per concern, each in its own module with
//! the state it alone uses: the objects meshed and drawn (`objects.rs`), the command line
//! (`commands.rs`), the panels' rows (`rows.rs`), the session (`session.rs`), the other
//! peers (`peers.rs`), sculpting (`sculpt.rs`), touch (`touch/`), files in and out
//! (`transfer.rs`), the viewport (`viewport/`) and the test hooks (`hooks/`). The bars and
//! the side panel are laid out by `top.rs` and `side.rs`.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use eframe::egui;

use super::commands::CommandLine;
use super::hooks::Hooks;
use super::objects::{MAX_EDIT_WAIT_MILLIS, MESHING_SHOWN_MILLIS, Objects};
use super::peers::PresenceState;
use super::rows::Rows;
use super::sculpt::Sculpt;
use super::session::Session;
use super::touch::Touch;
use super::transfer::Transfer;
use super::viewport::ViewState;
use super::viewport::gpu::ViewportReport;
use ::app::clock::{self, Now, SceneClock};
use ::app::engine::{Engine, EngineConfig, lock};
use ::app::samples::Samples;
use ::app::settings::Settings;

/// Frames whose times are kept for the statistics.
pub const MAX_FRAME_SAMPLES: usize = 600;
/// While time runs and something moves, a frame at least this often (60 per second).
pub const ANIMATION_FRAME_MILLIS: u64 = 16;
/// The side panel's width until the user resizes it, points.
pub const SIDE_PANEL_POINTS: f32 = 400.0;

/// Asks for a frame, from any thread.
pub type Waker = Arc<dyn Fn() + Send + Sync>;

/// The window's layout: what the settings keep of it.
pub struct Layout {
    /// The window's inner size, points (once a frame has read it).
    pub window_points: Option<[f32; 2]>,
    /// The side panel's width, points.
    pub side_panel_points: f32,
}

impl Default for Layout {
    fn default() -> Self {
        Layout {
            window_points: None,
            side_panel_points: SIDE_PANEL_POINTS,
        }
    }
}

/// Frame times, for the state dump.
pub struct FrameStats {
    /// Frames run.
    pub n_frames: u64,
    /// Milliseconds spent building each frame's UI (CPU, this thread).
    pub ui_ms: Samples,
    /// Milliseconds between the starts of successive frames (includes painting).
    pub frame_interval_ms: Samples,
    last_frame_start: Option<Instant>,
    /// When this pass's logic started (taken by the frame that follows it, if one does).
    pass_start: Option<Now>,
    /// Whether a frame ran since the last pass's logic (its picture is presented when the
    /// next pass starts).
    drew: bool,
}

impl FrameStats {
    fn new() -> FrameStats {
        FrameStats {
            n_frames: 0,
            ui_ms: Samples::new(MAX_FRAME_SAMPLES),
            frame_interval_ms: Samples::new(MAX_FRAME_SAMPLES),
            last_frame_start: None,
            pass_start: None,
            drew: false,
        }
    }

    /// A frame starts at `start`.
    fn started(&mut self, start: Instant) {
        if let Some(last) = self.last_frame_start {
            let ms = start.duration_since(last).as_secs_f64() * 1e3;
            self.frame_interval_ms.push(ms);
        }
        self.last_frame_start = Some(start);
        self.n_frames += 1;
    }

    /// When the current frame started (now, before the first frame), the time an edit's
    /// input is timed from.
    pub fn frame_start(&self) -> Instant {
        self.last_frame_start
            .unwrap_or_else(|| clock::now().instant)
    }

    /// The frame that started at `start` is built at `end`.
    fn built(&mut self, start: Instant, end: Instant) {
        self.ui_ms
            .push(end.duration_since(start).as_secs_f64() * 1e3);
    }
}

/// The window's state.
pub struct SculptApp {
    /// The session's engine (joining or opening a demo puts another in its place).
    pub(super) engine: Engine,
    /// How the engine was started (joining starts another from it).
    pub(super) config: EngineConfig,
    /// Asks for a frame (each new engine is given it too).
    pub(super) waker: Waker,
    /// The objects sent to the mesher and drawn.
    pub(super) objects: Objects,
    /// The camera and the pointer.
    pub(super) view: ViewState,
    /// What the viewport's paint callback reports.
    pub(super) viewport: Arc<Mutex<ViewportReport>>,
    /// The selected object.
    pub(super) selected: Option<u64>,
    /// The status line.
    pub(super) status: String,
    /// What the last click picked.
    pub(super) pick_status: String,
    pub(super) command: CommandLine,
    pub(super) rows: Rows,
    pub(super) session: Session,
    pub(super) presence: PresenceState,
    pub(super) sculpt: Sculpt,
    pub(super) touch: Touch,
    pub(super) transfer: Transfer,
    /// The window's layout as last drawn (kept between runs).
    pub(super) layout: Layout,
    /// The scene's time (motions), playing or paused.
    pub(super) scene_clock: SceneClock,
    /// The scene time this frame placed moving objects at, seconds.
    pub(super) frame_time_secs: f64,
    /// The window title last set.
    title: String,
    /// Where the brush, name and colour are kept between runs.
    settings_path: Option<PathBuf>,
    pub(super) hooks: Hooks,
    pub(super) stats: FrameStats,
}

impl SculptApp {
    /// The app over an opened session; `wake` is how the engine and the mesher ask for a
    /// frame.
    pub fn new(
        engine: Engine,
        config: EngineConfig,
        depth: u8,
        hooks: Hooks,
        wake: Waker,
    ) -> std::io::Result<SculptApp> {
        let engine_wake = wake.clone();
        lock(engine.view()).set_waker(Box::new(move || engine_wake()));
        let mesher_wake = wake.clone();
        let objects = Objects::start(depth, move || mesher_wake())?;
        let shared = config.invite.is_some()
            || !config.network.dial.is_empty()
            || config.network.discovery.is_some();
        let (selected, status) = {
            let view = lock(engine.view());
            let selected = view.scene().objects().next().map(|(id, _)| id.0);
            (selected, view.opening_status())
        };
        let now = clock::now().instant;
        Ok(SculptApp {
            engine,
            config,
            waker: wake,
            objects,
            view: ViewState::default(),
            viewport: Arc::new(Mutex::new(ViewportReport::default())),
            selected,
            status,
            pick_status: "click an object to pick it".into(),
            command: CommandLine::default(),
            rows: Rows::default(),
            session: Session {
                shared,
                ..Session::default()
            },
            presence: PresenceState::default(),
            sculpt: Sculpt::default(),
            touch: Touch::new(now),
            transfer: Transfer::default(),
            layout: Layout::default(),
            scene_clock: SceneClock::new(now),
            frame_time_secs: 0.0,
            title: String::new(),
            settings_path: None,
            hooks,
            stats: FrameStats::new(),
        })
    }

    /// Applies kept settings: the brush, and the name and colour unless flags gave them.
    pub fn apply_settings(&mut self, settings: &Settings, path: PathBuf) {
        if let Some(brush) = settings.brush {
            self.sculpt.brush = brush;
        }
        if let Some(width) = settings.side_panel_points {
            self.layout.side_panel_points = width;
        }
        let mut presence = self.engine.presence();
        if self.config.name.is_none()
            && let Some(name) = &settings.name
        {
            presence.name.clone_from(name);
        }
        if let Some(colour) = settings.colour {
            presence.colour = colour;
        }
        let _ = self.engine.set_presence(presence);
        self.settings_path = Some(path);
    }

    /// Keeps the brush, name, colour and layout for the next run.
    fn save_settings(&self) {
        let Some(path) = &self.settings_path else {
            return;
        };
        let presence = self.engine.presence();
        // A name the user never chose (the short id) is not kept: it would follow the user
        // into another store under another id.
        let chosen = presence.name != self.engine.peer_id().short();
        let settings = Settings {
            name: chosen.then_some(presence.name),
            colour: Some(presence.colour),
            brush: Some(self.sculpt.brush),
            window_points: self.layout.window_points,
            side_panel_points: Some(self.layout.side_panel_points),
        };
        if let Err(e) = settings.save(path) {
            log::warn!("cannot keep the settings in {}: {e}", path.display());
        }
    }

    /// Whether every object is drawn as the scene now has it, with nothing on its way.
    pub fn is_idle(&self) -> bool {
        self.objects.is_idle()
            && !self.command.is_pending()
            && self.transfer.is_idle()
            && self.sculpt.stroke.is_none()
    }

    /// Takes what the engine says changed to the mesher (only that: an edit re-meshes its
    /// own object), wakes the servo for it, and asks for what time changed while it runs.
    fn sync_objects(&mut self, now: Now) {
        let t_secs = self.scene_clock.secs(now.instant);
        let view = lock(self.engine.view());
        let changed = self.objects.take_changes(&view);
        if self.selected.is_none() {
            // The first object to appear (the demo, or a joined session's) is selected.
            self.selected = view.scene().objects().next().map(|(id, _)| id.0);
        }
        if changed && let Some(live) = &self.touch.live {
            live.wake();
        }
        self.objects.send_stale(view.scene(), now.instant, t_secs);
        drop(view);
        self.objects.flush();
    }

    /// Asks the mesher for what time changed while it runs (only for a shown window).
    fn ask_time_jobs(&mut self, now: Now) {
        if !self.scene_clock.playing() {
            return;
        }
        let t_secs = self.scene_clock.secs(now.instant);
        let view = lock(self.engine.view());
        self.objects
            .ask_time_jobs(view.scene(), now.instant, t_secs);
        drop(view);
        self.objects.flush();
    }

    /// Places the moving objects at the scene's time for this frame; returns whether any
    /// object moves or changes with time.
    fn place_moving(&mut self, now: Instant) -> bool {
        let t = self.scene_clock.secs(now);
        self.frame_time_secs = t;
        self.objects.place(t)
    }

    /// The title: where the session stands, and how many objects have waited long for a mesh.
    fn set_title(&mut self, ctx: &egui::Context, now: Instant) {
        let title = match self.objects.n_meshing_long(now) {
            0 => format!("sculpt — {}", self.presence_text()),
            n => format!("sculpt — meshing {n}… — {}", self.presence_text()),
        };
        if title != self.title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.title = title;
        }
    }

    /// The panels around the viewport, then the viewport; the layout is kept as drawn.
    ///
    /// The panels paint no background: the frame is cleared to their fill instead
    /// ([`eframe::App::clear_color`]). A software rasteriser clears for next to nothing but
    /// shades a filled panel pixel by pixel, every frame: on llvmpipe at 900x600 the fills
    /// were about half of a frame that only shows the last picture again.
    fn panels_ui(&mut self, ui: &mut egui::Ui) {
        let bare = egui::Frame::side_top_panel(ui.style()).fill(egui::Color32::TRANSPARENT);
        egui::Panel::top("sculpt-top")
            .frame(bare)
            .show(ui, |ui| self.top_ui(ui));
        egui::Panel::bottom("sculpt-status")
            .frame(bare)
            .show(ui, |ui| self.status_ui(ui));
        let side = egui::Panel::right("sculpt-side")
            .frame(bare)
            .default_size(self.layout.side_panel_points)
            .resizable(true)
            .show(ui, |ui| self.side_ui(ui));
        self.layout.side_panel_points = side.response.rect.width();
        self.layout.window_points = ui
            .ctx()
            .input(|i| i.viewport().inner_rect)
            .map(|r| [r.width(), r.height()]);
        egui::CentralPanel::no_frame().show(ui, |ui| self.central_ui(ui));
    }

    /// Asks for the next frames this one needs.
    fn request_frames(&self, ctx: &egui::Context, animating: bool) {
        if animating {
            ctx.request_repaint_after(Duration::from_millis(ANIMATION_FRAME_MILLIS));
        }
        // An edit made this frame is sent to the mesher at the start of the next one; the
        // frame after one that draws an edit's mesh times it.
        if self.objects.dirty || self.objects.draws_an_edit() {
            ctx.request_repaint();
        }
        if self.objects.n_meshing() > 0 {
            // So that the title says "meshing" once it has taken long, without other input.
            ctx.request_repaint_after(Duration::from_millis(MESHING_SHOWN_MILLIS));
        }
    }
}

impl eframe::App for SculptApp {
    /// The panels' fill, which they do not paint themselves (`panels_ui`).
    fn clear_color(&self, visuals: &egui::Visuals) -> [f32; 4] {
        visuals.panel_fill.to_normalized_gamma_f32()
    }

    fn on_exit(&mut self) {
        self.save_settings();
        let _ = self.set_touching(false);
    }

    /// Runs before every frame, and alone while the window is covered or minimized (eframe
    /// then draws nothing): what the session sends keeps being taken and meshed, so a covered
    /// window shows the scene at once when uncovered, its servo feels remote edits, and its
    /// presence and replies are not held back.
    fn logic(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        let now = clock::now();
        if std::mem::take(&mut self.stats.drew) {
            self.objects.presented(now.instant);
        }
        self.stats.pass_start = Some(now);
        self.objects.receive(now.instant);
        self.receive_reply();
        self.sync_objects(now);
        // Another peer's edit is drawn by this pass's frame when its mesh comes soon, unless
        // the user is dragging or drawing a stroke (the frame then answers at once).
        let busy = self.sculpt.stroke.is_some() || ctx.input(|i| i.pointer.any_down());
        if busy {
            self.objects.forget_sent_edits();
        } else {
            let deadline = now.instant + Duration::from_millis(MAX_EDIT_WAIT_MILLIS);
            (self.objects).await_sent_edits(clock::now().instant, deadline);
        }
        self.publish_presence();
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let now = self.stats.pass_start.take().unwrap_or_else(clock::now);
        self.stats.started(now.instant);
        self.stats.drew = true;
        self.ask_time_jobs(now);
        self.rows.refresh(&self.engine);
        self.follow();
        self.shortcuts(ui.ctx());
        self.transfer_frame(ui.ctx());
        self.run_hooks(ui.ctx());
        // The pointer and camera this frame moved go out now, not at the next pass.
        self.publish_presence();
        // Moving objects while time runs, and the touch tool while touching, draw every frame.
        let animating = (self.place_moving(now.instant) && self.scene_clock.playing())
            || self.touch.live.is_some();
        self.set_title(ui.ctx(), now.instant);
        self.panels_ui(ui);
        self.request_frames(ui.ctx(), animating);
        self.stats.built(now.instant, clock::now().instant);
    }
}
