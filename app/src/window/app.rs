//! `SculptApp`, the eframe app: the solo session, the objects sent to the mesher and drawn, the
//! camera, the selection and the command line. Panels are drawn by `panel.rs`, the viewport
//! by `viewport.rs`; test hooks (scripted commands, screenshot, state dump) by `hooks.rs`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use eframe::egui;
use glam::Vec3;
use model::scene::ObjectId;
use render::mesh::octree::MeshPatch;
use render::mesh::{Aabb, Mesh};
use render::mesher::{MeshJob, MeshKind, Mesher};
use render::scene::{Line, PickHit, Scene, SceneObject};
use render::snapshot::render_from_scene;

use super::hooks::Hooks;
use super::viewport::{Modes, StrokeEvent, StrokePhase, ViewState, ViewportReport, viewport_ui};
use ::app::brush::{Brush, Stroke};
use ::app::clock::{self, Now};
use ::app::command::{self, Planned};
use ::app::engine::{
    CameraPose, ChatRow, Engine, EngineConfig, HistoryRow, PeerRow, Pending, Presence, Validated,
    lock,
};
use ::app::touch::probe;
use replication::PeerId;

/// Frames whose times are kept for the statistics.
pub const FRAME_SAMPLES_MAX: usize = 600;
/// Edit-to-mesh times kept.
pub const EDIT_SAMPLES_MAX: usize = 100;
/// What the File menu's path field does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileAction {
    /// Bring a scene or mesh file into the session.
    Import,
    /// Write the selection (or the scene) to a file.
    Export,
    /// Record the touch tool's path to a file.
    RecordTouch,
}

/// Colour of the brush outline and the stroke being drawn.
const BRUSH_COLOUR: [f32; 4] = [1.0, 1.0, 1.0, 1.0];
/// Milliseconds between preview meshes of a stroke being drawn.
const PREVIEW_MILLIS: u64 = 120;
/// Half the size of another peer's pointer cross, in world units.
const PRESENCE_CROSS_SIZE: f32 = 0.06;
/// Half the size of the cross (in a box) that marks another peer's touch tool, world units.
const PRESENCE_TOOL_SIZE: f32 = 0.15;
/// Colour of the selected object's box.
const SELECTION_COLOUR: [f32; 4] = [1.0, 0.85, 0.2, 1.0];
/// Patches kept for the viewport between its draws.
pub const PATCHES_KEPT_MAX: usize = 256;
/// Meshing that has run this long shows in the title ("meshing N…").
pub const MESHING_SHOWN_MILLIS: u64 = 200;
/// While time runs and something moves, a frame at least this often (60 per second).
pub const ANIMATION_FRAME_MILLIS: u64 = 16;
/// Colours of the haptic zone, the touch tool and the force it meets.
const TOUCH_ZONE_COLOUR: [f32; 4] = [0.9, 0.9, 0.9, 0.6];
const TOUCH_TOOL_COLOUR: [f32; 4] = [0.2, 0.9, 1.0, 1.0];
const TOUCH_FORCE_COLOUR: [f32; 4] = [1.0, 0.3, 0.2, 1.0];
/// Shift+wheel moves the touch tool by this fraction of the scene's radius per point.
const TOUCH_DEPTH_PER_SCROLL_POINT: f32 = 0.002;
/// The side panel's width until the user resizes it, points.
pub const SIDE_PANEL_POINTS: f32 = 400.0;
/// While time runs, an object whose drawing reads `t` is meshed again at most this often.
pub const ANIMATION_REMESH_MILLIS: u64 = 100;

/// A patch for `Renderer::patch_object`: the object, the mesh it starts from, the mesh it
/// makes, and the ranges written.
pub type PatchForRenderer = (ObjectId, Arc<Mesh>, Arc<Mesh>, MeshPatch);

/// One scene object as the app tracks it: what was sent to the mesher, what is drawn.
#[derive(Default)]
pub struct Tracked {
    /// The engine said it changed since it was last sent to be meshed.
    stale: bool,
    /// Counts jobs for this object.
    pub generation: u64,
    /// The generation now drawn.
    pub drawn_generation: u64,
    /// A job the mesher's queue had no room for.
    pending: Option<Box<MeshJob>>,
    /// The drawable object, once meshed.
    pub drawn: Option<SceneObject>,
    /// Its box in the renderer's world, found once when its mesh arrives (frames read it to
    /// frame the camera and box the selection without scanning the mesh).
    pub drawn_box: Option<Aabb>,
    /// Its force-field arrows.
    pub lines: Vec<Line>,
    /// Triangles in its mesh.
    pub n_triangles: usize,
    /// Why it is (partly) not drawn.
    pub skipped: Option<String>,
    /// Seconds its last mesh took on the worker.
    pub mesh_secs: f64,
    /// How its drawn mesh was made.
    pub kind: Option<MeshKind>,
    /// Since when it has waited for a mesh (none while drawn as the scene has it).
    pub meshing_since: Option<Instant>,
    /// Its motion, for an object that moves with the scene's time.
    pub moving: Option<Box<Moving>>,
    /// Something drawn of it reads `t` (shape, colours, field): meshed again as time runs.
    pub timed: bool,
    /// The scene time its drawn mesh was made at.
    pub drawn_t_secs: f64,
    /// When a mesh for a later time was last asked for, while none is in flight.
    time_job: Option<TimeJob>,
}

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

/// A mesh asked for because time ran (not because the object changed): it keeps the
/// object's generation, so waiting for it is not "meshing" and does not hold up idleness.
#[derive(Clone, Copy)]
struct TimeJob {
    asked_at: Instant,
    done: bool,
}

/// What places a moving object at the scene's time: its motion (through a sampler of the
/// object as meshed) and its group's transform. Meshes are made at time 0; frames only move
/// them (the renderer keeps the uploaded buffers).
pub struct Moving {
    sampler: model::object::Sampler,
    world_from_group: model::object::Transform,
    /// Renderer world from object at the time the drawn mesh was made (where the mesher
    /// placed it and its arrows).
    world_at_drawn: glam::Mat4,
    /// At the last frame's scene time.
    pub world_now: glam::Mat4,
}

impl Moving {
    fn new(object: &model::object::Object, world_from_group: model::object::Transform) -> Moving {
        let mut moving = Moving {
            sampler: object.sampler(),
            world_from_group,
            world_at_drawn: glam::Mat4::IDENTITY,
            world_now: glam::Mat4::IDENTITY,
        };
        moving.world_at_drawn = moving.world_at(0.0);
        moving.world_now = moving.world_at_drawn;
        moving
    }

    /// Renderer world from object at scene time `t_secs` (as the mesher places it at 0).
    fn world_at(&mut self, t_secs: f64) -> glam::Mat4 {
        let scene_from_object = self.world_from_group.then(&self.sampler.placement(t_secs));
        render_from_scene() * glam::DMat4::from(scene_from_object.parent_from_child).as_mat4()
    }

    /// Where what was drawn at the mesh's time is now (force arrows, the drawn box).
    fn since_drawn(&self) -> glam::Mat4 {
        self.world_now * self.world_at_drawn.inverse()
    }
}

/// Frame and meshing times, for the status line and the state dump.
#[derive(Default)]
pub struct Stats {
    /// Frames run.
    pub n_frames: u64,
    /// Milliseconds spent building each frame's UI (CPU, this thread).
    pub ui_ms: Vec<f64>,
    /// Milliseconds between the starts of successive frames (includes painting).
    pub frame_interval_ms: Vec<f64>,
    /// Milliseconds from an edit being authored to its object's new mesh being drawn.
    pub edit_to_mesh_ms: Vec<f64>,
    /// Meshes drawn, by how they were made.
    pub n_patched: u64,
    pub n_whole: u64,
    last_frame_start: Option<Instant>,
}

fn push_bounded(samples: &mut Vec<f64>, value: f64, max: usize) {
    if samples.len() >= max {
        samples.remove(0);
    }
    samples.push(value);
}

/// The window's state.
pub struct SculptApp {
    pub(super) engine: Engine,
    mesher: Mesher,
    /// Patches of meshes swapped in since the viewport last took them.
    pub(super) patches: Vec<PatchForRenderer>,
    depth: u8,
    pub(super) objects: BTreeMap<ObjectId, Tracked>,
    /// Where this window is in the engine's change stream.
    changes_cursor: u64,
    /// The scene changed since objects were last compared with what was sent.
    dirty: bool,
    /// When the last edit was authored (for edit-to-mesh times).
    last_edit_at: Option<Instant>,
    pub(super) view: ViewState,
    pub(super) viewport: Arc<Mutex<ViewportReport>>,
    pub(super) selected: Option<u64>,
    pub(super) input: String,
    pub(super) input_error: Option<String>,
    pub(super) status: String,
    pub(super) pick_status: String,
    pub(super) chat: Vec<ChatRow>,
    pub(super) history: Vec<HistoryRow>,
    pub(super) peers: Vec<PeerRow>,
    pub(super) n_online: usize,
    /// Display names by short peer id (this peer's and the peers met).
    pub(super) names: BTreeMap<String, String>,
    /// Asks for a frame (a new engine after Join is given it too).
    waker: Option<std::sync::Arc<dyn Fn() + Send + Sync>>,
    pub(super) news: Vec<String>,
    news_next: u64,
    /// The view generation the rows were copied at.
    rows_at: Option<u64>,
    /// A command's op on its way to the store, with what it does.
    pending: Option<(Pending, Planned)>,
    /// The invite is shown (after "Share").
    pub(super) show_invite: bool,
    /// The session was shared or joined: no peers then means offline, not solo.
    pub(super) shared: bool,
    /// How the engine was started (a Join starts another from it).
    pub(super) config: EngineConfig,
    /// The invite typed into "Join", and why it was refused.
    pub(super) join_input: Option<(String, Option<String>)>,
    /// The brush a drag sculpts with.
    pub(super) brush: Brush,
    /// Touch with the mouse: the servo on the live scene, while on.
    pub(super) touch: Option<::app::touch::live::LiveTouch>,
    /// A 3D mouse moving the touch tool, while chosen and touch is on; its button presses
    /// arrive on the receiver.
    pub(super) spacemouse: Option<(
        ::app::touch::spacemouse::SpaceMouseDriver,
        std::sync::mpsc::Receiver<bool>,
    )>,
    /// The shared tool (while touching): coupled with the peer it is held with when that
    /// peer holds it back.
    pub(super) shared_tool: Option<::app::touch::shared::SharedTool>,
    /// The peer this user holds the touch tool with, and where that stands.
    pub(super) hold_with: Option<replication::PeerId>,
    pub(super) shared_state: ::app::touch::shared::SharedState,
    /// The touch tool's body, which other peers feel while it is tangible.
    pub(super) tool_body: ::app::touch::body::ToolBody,
    /// The force-feedback devices last listed for the Touch section, or why none could be.
    pub(super) force_devices: Option<Result<Vec<haptic::device::hid::HidDeviceInfo>, String>>,
    /// A listing under way, on a thread of its own.
    pub(super) force_listing:
        Option<std::sync::mpsc::Receiver<Result<Vec<haptic::device::hid::HidDeviceInfo>, String>>>,
    /// A force-feedback device being opened, on a thread of its own.
    pub(super) force_opening: Option<::app::touch::force_output::Opening>,
    /// The touch tool's path being recorded, and when recording began.
    pub(super) touch_recording: Option<(::app::touch::record::Recorder, Instant)>,
    /// Recent force and energy for the Touch section's plot, timed from `opened`.
    pub(super) force_history: ::app::touch::record::ForceHistory,
    /// When the window opened.
    opened: Instant,
    /// The window's layout as last drawn (kept between runs).
    pub(super) layout: Layout,
    /// The scene's time (motions), playing or paused.
    pub(super) scene_clock: clock::SceneClock,
    /// The scene time this frame placed moving objects at, seconds.
    pub(super) frame_time_secs: f64,
    /// A drag on a surface sculpts (otherwise it orbits).
    pub(super) sculpting: bool,
    /// The stroke being drawn.
    stroke: Option<Stroke>,
    /// When the stroke's last preview was sent to the mesher.
    preview_at: Option<Instant>,
    /// The last stroke's points (scene coordinates), for the state dump.
    pub(super) last_stroke: Option<Vec<glam::DVec3>>,
    /// The peer whose camera this window follows.
    pub(super) following: Option<PeerId>,
    /// The surface point under the pointer, in the renderer's world.
    pointer: Option<Vec3>,
    /// The presence last handed to the engine.
    pub(super) presence_sent: Option<Presence>,
    /// The window title last set.
    title: String,
    /// Where the brush, name and colour are kept between runs.
    settings_path: Option<PathBuf>,
    /// The File menu's path field: import or export, the path typed, and the last error.
    pub(super) file_input: Option<(FileAction, String, Option<String>)>,
    /// Ops of an import still to author, one at a time.
    import_queue: std::collections::VecDeque<replication::shape::ShapePayload>,
    /// An export running on its own thread.
    export: Option<std::sync::mpsc::Receiver<Result<String, String>>>,
    pub(super) hooks: Hooks,
    pub(super) stats: Stats,
}

impl SculptApp {
    /// The app over an opened session; `wake` is how the mesher asks for a frame.
    pub fn new(
        engine: Engine,
        config: EngineConfig,
        depth: u8,
        hooks: Hooks,
        wake: std::sync::Arc<dyn Fn() + Send + Sync>,
    ) -> std::io::Result<SculptApp> {
        let engine_wake = wake.clone();
        lock(engine.view()).set_waker(Box::new(move || engine_wake()));
        let mesher_wake = wake.clone();
        let shared = config.invite.is_some()
            || !config.network.dial.is_empty()
            || config.network.discovery.is_some();
        let (selected, status) = {
            let view = lock(engine.view());
            let selected = view.scene().objects().next().map(|(id, _)| id.0);
            let status = view.opening_status();
            (selected, status)
        };
        Ok(SculptApp {
            engine,
            mesher: Mesher::start(|| clock::now().instant, move || mesher_wake())?,
            patches: Vec::new(),
            depth,
            objects: BTreeMap::new(),
            changes_cursor: 0,
            dirty: true,
            last_edit_at: None,
            view: ViewState::default(),
            viewport: Arc::new(Mutex::new(ViewportReport::default())),
            selected,
            input: String::new(),
            input_error: None,
            status,
            pick_status: "click an object to pick it".into(),
            chat: Vec::new(),
            history: Vec::new(),
            peers: Vec::new(),
            n_online: 0,
            names: BTreeMap::new(),
            waker: Some(wake),
            news: Vec::new(),
            news_next: 0,
            rows_at: None,
            pending: None,
            show_invite: false,
            shared,
            config,
            join_input: None,
            following: None,
            brush: Brush::default(),
            sculpting: false,
            scene_clock: clock::SceneClock::new(clock::now().instant),
            layout: Layout::default(),
            touch: None,
            spacemouse: None,
            shared_tool: None,
            hold_with: None,
            shared_state: ::app::touch::shared::SharedState::Alone,
            tool_body: ::app::touch::body::ToolBody::default(),
            force_devices: None,
            force_listing: None,
            force_opening: None,
            touch_recording: None,
            force_history: ::app::touch::record::ForceHistory::default(),
            opened: clock::now().instant,
            frame_time_secs: 0.0,
            stroke: None,
            preview_at: None,
            last_stroke: None,
            pointer: None,
            presence_sent: None,
            title: String::new(),
            settings_path: None,
            file_input: None,
            import_queue: std::collections::VecDeque::new(),
            export: None,
            hooks,
            stats: Stats::default(),
        })
    }

    /// Sends the objects the engine says changed to the mesher (only those: an edit
    /// re-meshes its own object), and forgets objects that are gone.
    fn sync_objects(&mut self, now: Now) {
        let scene_t = self.scene_clock.secs(now.instant);
        let view = lock(self.engine.view());
        let (changes, cursor) = view.changes_since(self.changes_cursor);
        self.changes_cursor = cursor;
        if self.selected.is_none() {
            // The first object to appear (the demo, or a joined session's) is selected.
            self.selected = view.scene().objects().next().map(|(id, _)| id.0);
        }
        if let Some(live) = &self.touch
            && changes.as_ref().is_none_or(|c| !c.is_empty())
        {
            live.wake();
        }
        if let Some(changes) = changes {
            self.dirty |= !changes.is_empty();
            for id in changes {
                self.objects.entry(id).or_default().stale = true;
            }
        } else {
            self.dirty = true;
            for (id, _) in view.scene().objects() {
                self.objects.entry(id).or_default().stale = true;
            }
        }
        if self.dirty {
            self.dirty = false;
            let scene = view.scene();
            let mesher = &self.mesher;
            self.objects.retain(|id, _| {
                let kept = scene.object(*id).is_some();
                if !kept {
                    mesher.forget(*id);
                }
                kept
            });
            for (id, tracked) in &mut self.objects {
                if !std::mem::take(&mut tracked.stale) {
                    continue;
                }
                let Some(entry) = scene.scene_object(*id) else {
                    continue;
                };
                tracked.generation += 1;
                tracked.meshing_since.get_or_insert(now.instant);
                let world_from_group = scene.world_from_group(entry.group);
                tracked.moving = entry
                    .object
                    .data()
                    .motion
                    .is_some()
                    .then(|| Box::new(Moving::new(&entry.object, world_from_group)));
                tracked.timed = render::animation::object_reads_time(&entry.object);
                tracked.time_job = None;
                tracked.pending = Some(Box::new(MeshJob {
                    id: *id,
                    object: entry.object.clone(),
                    world_from_group,
                    generation: tracked.generation,
                    depth: self.depth,
                    requested_at: self.last_edit_at.unwrap_or(now.instant),
                    t_secs: scene_t,
                }));
            }
        }
        // Time ran: what reads `t` is meshed again at the new time, one job at a time per
        // object and at most every ANIMATION_REMESH_MILLIS.
        if self.scene_clock.playing() {
            let scene = view.scene();
            let every = std::time::Duration::from_millis(ANIMATION_REMESH_MILLIS);
            for (id, tracked) in &mut self.objects {
                let due = tracked.timed
                    && tracked.pending.is_none()
                    && tracked.drawn_generation == tracked.generation
                    && tracked
                        .time_job
                        .is_none_or(|j| j.done && now.instant.duration_since(j.asked_at) >= every);
                let Some(entry) = scene.scene_object(*id).filter(|_| due) else {
                    continue;
                };
                tracked.time_job = Some(TimeJob {
                    asked_at: now.instant,
                    done: false,
                });
                tracked.pending = Some(Box::new(MeshJob {
                    id: *id,
                    object: entry.object.clone(),
                    world_from_group: scene.world_from_group(entry.group),
                    generation: tracked.generation,
                    depth: self.depth,
                    requested_at: now.instant,
                    t_secs: scene_t,
                }));
            }
        }
        drop(view);
        for tracked in self.objects.values_mut() {
            if let Some(job) = tracked.pending.take() {
                tracked.pending = self.mesher.try_send(job).err();
            }
        }
    }

    /// Takes finished meshes. One of an older job than the latest is still drawn when newer
    /// than what is drawn (the workers mesh each object's jobs in order and drop superseded
    /// ones before they start), so each patch starts from the mesh drawn.
    fn receive_meshes(&mut self, now: Now) {
        while let Some(done) = self.mesher.try_recv() {
            let Some(tracked) = self.objects.get_mut(&done.id) else {
                continue;
            };
            // Newer: a later job, or the same object meshed at a later scene time.
            let newer = done.generation > tracked.drawn_generation
                || (done.generation == tracked.drawn_generation
                    && done.t_secs > tracked.drawn_t_secs);
            if !newer {
                continue;
            }
            if let (Some((base, patch)), Some(o)) = (done.patch, &done.object) {
                if self.patches.len() >= PATCHES_KEPT_MAX {
                    // The viewport has not drawn for a while: it uploads whole meshes then.
                    self.patches.clear();
                }
                self.patches
                    .push((done.id, base, Arc::clone(&o.mesh), patch));
            }
            match done.kind {
                MeshKind::Patch => self.stats.n_patched += 1,
                MeshKind::Whole => self.stats.n_whole += 1,
                MeshKind::Unchanged => {}
            }
            tracked.kind = Some(done.kind);
            tracked.drawn_generation = done.generation;
            tracked.drawn_t_secs = done.t_secs;
            if let Some(job) = tracked.time_job.as_mut() {
                job.done = true;
            }
            if tracked.drawn_generation == tracked.generation {
                tracked.meshing_since = None;
            }
            tracked.drawn_box = done.object.as_ref().and_then(world_box);
            tracked.drawn = done.object;
            tracked.lines = done.lines;
            tracked.n_triangles = done.n_triangles;
            tracked.skipped = done.skipped;
            tracked.mesh_secs = done.mesh_secs;
            if self.last_edit_at.is_some() {
                let ms = now.instant.duration_since(done.requested_at).as_secs_f64() * 1e3;
                push_bounded(&mut self.stats.edit_to_mesh_ms, ms, EDIT_SAMPLES_MAX);
            }
        }
    }

    /// Whether every object is drawn as the scene now has it.
    pub fn is_idle(&self) -> bool {
        !self.dirty
            && self.pending.is_none()
            && self.import_queue.is_empty()
            && self.export.is_none()
            && self.stroke.is_none()
            && self
                .objects
                .values()
                .all(|t| t.pending.is_none() && t.drawn_generation == t.generation)
    }

    /// Objects that have waited for a mesh longer than [`MESHING_SHOWN_MILLIS`] (the title
    /// shows them; a frame is asked for while any waits, so the title changes in time).
    pub fn n_meshing_long(&self, now: Instant) -> usize {
        let shown = std::time::Duration::from_millis(MESHING_SHOWN_MILLIS);
        self.objects
            .values()
            .filter(|t| {
                t.meshing_since
                    .is_some_and(|s| now.duration_since(s) >= shown)
            })
            .count()
    }

    /// Objects waiting for a mesh.
    pub fn n_meshing(&self) -> usize {
        self.objects
            .values()
            .filter(|t| t.drawn_generation != t.generation)
            .count()
    }

    /// Runs one line of the command/chat input: hands its op to the engine, or shows its
    /// error. One line at a time: the next waits until this one's op is stored.
    pub fn submit(&mut self, line: &str) {
        let Some(command) = command::parse(line) else {
            return;
        };
        if let command::Command::Probe(text) = command {
            match self.tool_body.parse(text) {
                Ok(body) => {
                    self.tool_body = body;
                    self.input_error = None;
                    self.input.clear();
                    self.status = format!("touch tool: {}", body.describe());
                }
                Err(e) => self.input_error = Some(e),
            }
            return;
        }
        if let command::Command::Tool(text) = command {
            match self.brush.parse(text) {
                Ok(brush) => {
                    self.brush = brush;
                    self.sculpting = true;
                    self.input_error = None;
                    self.input.clear();
                    self.status = format!("tool: {} (drag on a surface)", brush.describe());
                }
                Err(e) => self.input_error = Some(e),
            }
            return;
        }
        if self.pending.is_some() {
            self.input_error = Some("the last command is still being saved; try again".into());
            return;
        }
        let planned = command::plan(command, &lock(self.engine.view()), self.selected);
        let planned = match planned {
            Ok(planned) => planned,
            Err(error) => {
                self.input_error = Some(error);
                return;
            }
        };
        match self.engine.author_validated(planned.payload.clone()) {
            Ok(pending) => self.pending = Some((pending, planned)),
            Err(e) => self.input_error = Some(e.to_string()),
        }
    }

    /// Takes the reply to the pending command, if it came.
    fn receive_reply(&mut self, now: Now) {
        let Some(reply) = self.pending.as_ref().and_then(|(p, _)| p.try_take()) else {
            return;
        };
        let Some((_, planned)) = self.pending.take() else {
            return;
        };
        match reply {
            Ok(_) => {
                self.input_error = None;
                self.input.clear();
                self.status = planned.summary;
                if planned.select.is_some() {
                    self.selected = planned.select;
                }
                self.last_edit_at = Some(now.instant);
                self.dirty = true;
            }
            Err(e) => self.input_error = Some(e),
        }
    }

    /// Chat, history and peer rows, copied from the engine's view when it changed.
    fn refresh_rows(&mut self) {
        let view = lock(self.engine.view());
        if self.rows_at != Some(view.generation()) {
            self.chat = view.chat().to_vec();
            self.history = view.history().to_vec();
            self.rows_at = Some(view.generation());
        }
        self.peers = view.peers().to_vec();
        self.n_online = view.n_online();
        let me = view.peer_id().short();
        drop(view);
        self.names = self
            .peers
            .iter()
            .map(|p| (p.peer.short(), p.name.clone()))
            .chain([(me, self.engine.presence().name)])
            .collect();
        let (lines, next) = self.engine.news_since(self.news_next);
        self.news_next = next;
        self.news.extend(lines);
        let excess = self
            .news
            .len()
            .saturating_sub(::app::engine::MAX_NEWS_LINES);
        self.news.drain(..excess);
    }

    /// What the viewport draws: objects in id order (their ids alongside, for picking), arrows
    /// and the selection box.
    pub(super) fn drawn_scene(&self) -> (Scene, Vec<ObjectId>) {
        let mut scene = Scene::default();
        let mut ids = Vec::new();
        for (id, tracked) in &self.objects {
            let moved = tracked
                .moving
                .as_ref()
                .map(|m| (m.world_now, m.since_drawn()));
            if let Some(o) = &tracked.drawn {
                let mut o = o.clone();
                if let Some((world_now, _)) = moved {
                    o.world_from_object = world_now;
                }
                scene.objects.push(o);
                ids.push(*id);
                if self.selected == Some(id.0)
                    && let Some(b) = tracked.drawn_box
                {
                    scene.add_box(
                        moved.map_or(b, |(_, m)| moved_box(&b, &m)),
                        SELECTION_COLOUR,
                    );
                }
            }
            match moved {
                None => scene.lines.extend_from_slice(&tracked.lines),
                Some((_, m)) => scene.lines.extend(tracked.lines.iter().map(|l| Line {
                    from: m.transform_point3(l.from),
                    to: m.transform_point3(l.to),
                    colour: l.colour,
                })),
            }
        }
        self.draw_presence(&mut scene);
        self.draw_touch(&mut scene);
        (scene, ids)
    }

    /// Other peers' pointers (a cross), touch tools (a larger cross in a box) and selections
    /// (a box) in their colours.
    fn draw_presence(&self, scene: &mut Scene) {
        let view = lock(self.engine.view());
        for p in view.presence().values() {
            let [r, g, b] = p.colour.map(|c| f32::from(c) / 255.0);
            let colour = [r, g, b, 1.0];
            if let Some(at) = p.pointer {
                scene.add_crosshair(Vec3::from_array(at), PRESENCE_CROSS_SIZE, colour);
            }
            if let Some(at) = p.tool.map(Vec3::from_array) {
                scene.add_crosshair(at, PRESENCE_TOOL_SIZE, colour);
                let half = Vec3::splat(PRESENCE_TOOL_SIZE * 0.35);
                scene.add_box(
                    Aabb::new((at - half).to_array(), (at + half).to_array()),
                    colour,
                );
            }
            if let Some(b) = p
                .selected
                .and_then(|id| self.objects.get(&ObjectId(id)))
                .and_then(|t| t.drawn_box)
            {
                scene.add_box(b, colour);
            }
        }
    }

    /// Hands this window's presence to the engine when it changed.
    fn publish_presence(&mut self) {
        let mut presence = self.engine.presence();
        presence.pointer = self.pointer.map(|p| p.to_array());
        presence.tool = self.touch.as_ref().map(|live| {
            render_from_scene()
                .transform_point3(live.stats().hip_world.as_vec3())
                .to_array()
        });
        presence.holds_tool_with = self.hold_with.filter(|_| self.touch.is_some()).map(|p| p.0);
        presence.tool_body = (self.touch.is_some() && self.tool_body.is_tangible())
            .then(|| self.tool_body.to_wire());
        presence.selected = self.selected;
        let c = &self.view.camera;
        presence.camera = Some(CameraPose {
            target: c.target.to_array(),
            orbit: [c.yaw, c.pitch, c.distance],
        });
        if self.presence_sent.as_ref() != Some(&presence)
            && self.engine.set_presence(presence.clone()).is_ok()
        {
            self.presence_sent = Some(presence);
        }
    }

    /// Copies the followed peer's camera, while it is connected.
    fn follow(&mut self) {
        let Some(peer) = self.following else {
            return;
        };
        let camera = lock(self.engine.view())
            .presence()
            .get(&peer)
            .map(|p| p.camera);
        match camera {
            Some(Some(pose)) => {
                let c = &mut self.view.camera;
                c.target = Vec3::from_array(pose.target);
                [c.yaw, c.pitch, c.distance] = pose.orbit;
                self.view.moved = true;
            }
            Some(None) => {}
            None => self.following = None,
        }
    }

    /// Leaves this session and joins the one `invite` opens, in its own store directory
    /// beside this one.
    pub(super) fn join(&mut self, text: &str) -> Result<(), String> {
        let invite = replication::net::invite::Invite::parse(text).map_err(|e| e.to_string())?;
        let base = self.config.store.parent().map_or_else(
            || std::path::PathBuf::from("."),
            std::path::Path::to_path_buf,
        );
        let mut config = self.config.clone();
        config.store = base.join(::app::engine::store::joined_dir_name(&invite));
        config.invite = Some(invite);
        config.demo = None;
        self.switch_session(config, true)?;
        self.status = "joined the session; syncing".into();
        Ok(())
    }

    /// Leaves this session and opens `demo`'s own, in its store directory beside this one
    /// (made and given the demo's objects the first time).
    pub(super) fn open_demo(&mut self, demo: &'static ::app::demos::Demo) -> Result<(), String> {
        let base = self.config.store.parent().map_or_else(
            || std::path::PathBuf::from("."),
            std::path::Path::to_path_buf,
        );
        let mut config = self.config.clone();
        config.store = base.join(demo.store_dir_name());
        config.invite = None;
        config.demo = Some(demo);
        self.switch_session(config, false)?;
        self.status = format!("{}: {}", demo.title, demo.about);
        Ok(())
    }

    /// Starts an engine on `config` and puts it in the place of this one (which stops), with
    /// the window's per-session state cleared.
    fn switch_session(&mut self, mut config: EngineConfig, shared: bool) -> Result<(), String> {
        // The servo felt the session left.
        self.set_touching(false)?;
        // The session left is still listening while the new one starts.
        config.network.listen.set_port(0);
        let engine = Engine::start(config.clone(), clock::now().wall).map_err(|e| e.to_string())?;
        if let Some(waker) = &self.waker {
            let waker = waker.clone();
            lock(engine.view()).set_waker(Box::new(move || waker()));
        }
        self.engine = engine;
        self.config = config;
        self.shared = shared;
        self.objects.clear();
        self.changes_cursor = 0;
        self.selected = None;
        self.rows_at = None;
        self.news.clear();
        self.news_next = 0;
        self.following = None;
        self.presence_sent = None;
        self.dirty = true;
        Ok(())
    }

    /// Shows what a click hit in the status line and selects the object.
    pub(super) fn picked(&mut self, hit: Option<PickHit>, ids: &[ObjectId]) {
        let Some(hit) = hit else {
            self.pick_status = "nothing there".into();
            return;
        };
        let Some(id) = ids.get(hit.object_idx) else {
            return;
        };
        self.selected = Some(id.0);
        // The renderer's world is +z up; formulas live in the scene's +y-up space.
        let p = render_from_scene()
            .inverse()
            .transform_point3(hit.point_in_world);
        self.pick_status = format!(
            "picked {} at ({:.3}, {:.3}, {:.3}) (scene coordinates)",
            ::app::engine::lock(self.engine.view()).object_label(id.0),
            p.x,
            p.y,
            p.z
        );
    }

    fn central_ui(&mut self, ui: &mut egui::Ui) {
        let (mut scene, ids) = self.drawn_scene();
        self.draw_brush(&mut scene);
        let sphere = bounding_sphere(self.objects.values().filter_map(|t| t.drawn_box));
        let sculpting = self.sculpting;
        // Each patch goes to the renderer with the object's index in the drawn scene.
        let patches = std::mem::take(&mut self.patches)
            .into_iter()
            .filter_map(|(id, base, mesh, patch)| {
                let idx = ids.iter().position(|i| *i == id)?;
                Some((idx, base, mesh, patch))
            })
            .collect();
        let modes = Modes {
            sculpting,
            touching: self.touch.is_some(),
        };
        let mut input = viewport_ui(
            ui,
            modes,
            &mut self.view,
            &scene,
            patches,
            sphere,
            &self.viewport,
        );
        if let Some(event) = self.hooks.scripted_stroke(input.size_px, self.is_idle()) {
            input.stroke = Some(event);
        }
        if let Some(event) = input.stroke {
            self.stroke_event(event, input.size_px, &scene, &ids);
        } else if input.picked.is_some() || input.missed {
            self.picked(input.picked, &ids);
        }
        if input.moved {
            self.following = None;
        }
        if let Some(px) = input.hover_px {
            let ray = self.view.camera.ray_through_pixel(px, input.size_px);
            self.pointer = scene.pick(&ray).map(|hit| hit.point_in_world);
        }
        if let Some(down) = input.touch_button {
            self.touch_button(down);
        }
        let presses: Vec<bool> = self
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
        if input.hover_px.is_some() || input.depth_scroll != 0.0 {
            let depth =
                input.depth_scroll * TOUCH_DEPTH_PER_SCROLL_POINT * sphere.map_or(1.0, |s| s.1);
            self.touch_follow(input.hover_px, input.size_px, depth);
        }
        if let Some(at) = self.hooks.take_pick_if_ready(self.is_idle()) {
            let size_px = input.size_px;
            let px = [at[0] * size_px[0] as f32, at[1] * size_px[1] as f32];
            let ray = self.view.camera.ray_through_pixel(px, size_px);
            let hit = scene.pick(&ray);
            self.picked(hit, &ids);
        }
    }

    /// The brush's outline where it would act (under the pointer) and the stroke drawn so far.
    fn draw_brush(&self, scene: &mut Scene) {
        if !self.sculpting {
            return;
        }
        let tool = self.brush.tool();
        if let Some(p) = self.pointer {
            let at = glam::Mat4::from_translation(p) * render_from_scene();
            scene.add_tool(&tool, at, BRUSH_COLOUR);
        }
        if let Some(stroke) = &self.stroke {
            let to_world = render_from_scene();
            let points: Vec<Vec3> = stroke
                .scene_points()
                .iter()
                .map(|p| to_world.transform_point3(p.as_vec3()))
                .collect();
            for pair in points.windows(2) {
                scene.lines.push(render::scene::Line {
                    from: pair[0],
                    to: pair[1],
                    colour: BRUSH_COLOUR,
                });
            }
        }
    }

    /// One frame of a sculpting drag: begin on the surface under the pointer, follow the
    /// surface, author one op at the end; a preview of the stroke is meshed meanwhile.
    fn stroke_event(
        &mut self,
        event: StrokeEvent,
        size_px: [u32; 2],
        scene: &Scene,
        ids: &[ObjectId],
    ) {
        let ray = self.view.camera.ray_through_pixel(event.px, size_px);
        let hit = scene.pick(&ray);
        let at_scene = hit.map(|h| {
            render_from_scene()
                .inverse()
                .transform_point3(h.point_in_world)
                .as_dvec3()
        });
        match event.phase {
            StrokePhase::Begin => {
                let (Some(hit), Some(at)) = (hit, at_scene) else {
                    self.status = "start a stroke on an object's surface".into();
                    return;
                };
                let Some(id) = ids.get(hit.object_idx) else {
                    return;
                };
                let view = lock(self.engine.view());
                match Stroke::begin(&view, id.0, self.brush, at) {
                    Ok(stroke) => {
                        self.selected = Some(id.0);
                        self.stroke = Some(stroke);
                        self.preview_at = None;
                    }
                    Err(e) => self.status = e,
                }
            }
            StrokePhase::Move => {
                if let (Some(stroke), Some(at)) = (&mut self.stroke, at_scene) {
                    stroke.push(at);
                    self.preview_stroke();
                }
            }
            StrokePhase::End => self.finish_stroke(at_scene),
        }
    }

    /// Ends the stroke in progress at `at` (scene coordinates) and authors its one op.
    fn finish_stroke(&mut self, at: Option<glam::DVec3>) {
        let Some(mut stroke) = self.stroke.take() else {
            return;
        };
        if let Some(at) = at {
            stroke.push(at);
        }
        let planned = stroke.finish(&lock(self.engine.view()));
        self.last_stroke = Some(stroke.scene_points().to_vec());
        match planned {
            Ok(planned) => match self.engine.author_validated(planned.payload.clone()) {
                Ok(pending) => self.pending = Some((pending, planned)),
                Err(e) => self.status = e.to_string(),
            },
            Err(e) => self.status = e,
        }
    }

    /// The touch device's button: pressed on a touched object, the current brush starts a
    /// stroke at the haptic interface point; held, the stroke follows it; released, the
    /// stroke is one op (touch-sculpting).
    pub(super) fn touch_button(&mut self, down: bool) {
        let Some(live) = &self.touch else {
            return;
        };
        live.set_button(down);
        let s = live.stats();
        if !down {
            self.finish_stroke(Some(s.hip_world));
            return;
        }
        let Some(object) = s.top_id else {
            self.status = "touch an object to sculpt it with the device".into();
            return;
        };
        let begun = Stroke::begin(&lock(self.engine.view()), object, self.brush, s.hip_world);
        match begun {
            Ok(stroke) => {
                self.selected = Some(object);
                self.stroke = Some(stroke);
                self.preview_at = None;
            }
            Err(e) => self.status = e,
        }
    }

    /// While the touch device's button is held, the stroke follows the haptic interface
    /// point (previewed as a drawn stroke is).
    fn follow_touch_stroke(&mut self) {
        let Some(live) = &self.touch else {
            return;
        };
        if !live.button_down() {
            return;
        }
        let hip = live.stats().hip_world;
        if let Some(stroke) = &mut self.stroke {
            stroke.push(hip);
            self.preview_stroke();
        }
    }

    /// Runs a named shortcut (also what the keyboard does): undo, redo, sculpt, navigate.
    pub(super) fn shortcut_named(&mut self, name: &str) -> Result<(), String> {
        match name.to_ascii_lowercase().as_str() {
            "undo" | "ctrl+z" => self.submit("undo"),
            "redo" | "ctrl+y" | "ctrl+shift+z" => self.submit("redo"),
            "sculpt" | "b" => self.sculpting = true,
            "play" => self.set_playing(true),
            "pause" => self.set_playing(false),
            "space" => self.set_playing(!self.scene_clock.playing()),
            "navigate" | "escape" => {
                self.sculpting = false;
                self.stroke = None;
            }
            other => {
                return Err(format!(
                    "unknown shortcut `{other}` (undo, redo, sculpt, navigate, play, pause, space)"
                ));
            }
        }
        Ok(())
    }

    /// Keyboard shortcuts, unless a text field has the keyboard.
    fn shortcuts(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let pressed = |key| ctx.input(|i| i.key_pressed(key));
        let (command, shift) = ctx.input(|i| (i.modifiers.command, i.modifiers.shift));
        let action = if command && shift && pressed(egui::Key::Z) {
            Some("redo")
        } else if command && pressed(egui::Key::Z) {
            Some("undo")
        } else if command && pressed(egui::Key::Y) {
            Some("redo")
        } else if pressed(egui::Key::Escape) {
            Some("navigate")
        } else if pressed(egui::Key::B) {
            Some("sculpt")
        } else if pressed(egui::Key::Space) {
            Some("space")
        } else {
            None
        };
        if let Some(action) = action {
            let _ = self.shortcut_named(action);
        }
    }

    /// Places the moving objects at the scene's time for this frame; returns whether any
    /// object moves or changes with time (so that frames keep coming while time runs).
    fn place_moving(&mut self, now: Instant) -> bool {
        let t = self.scene_clock.secs(now);
        self.frame_time_secs = t;
        let mut any = false;
        for tracked in self.objects.values_mut() {
            any |= tracked.timed;
            if let Some(moving) = tracked.moving.as_mut() {
                moving.world_now = moving.world_at(t);
                moving.world_at_drawn = moving.world_at(tracked.drawn_t_secs);
                any = true;
            }
        }
        any
    }

    /// Starts or stops touching the scene with the mouse (the servo and its feed).
    pub(super) fn set_touching(&mut self, on: bool) -> Result<(), String> {
        match (on, self.touch.take()) {
            (true, None) => {
                let view = Arc::clone(self.engine.view());
                let model = ::app::touch::DeviceModel::Falcon;
                let live = ::app::touch::live::LiveTouch::start(view, model)?;
                match ::app::touch::shared::SharedTool::start(&self.engine, live.shared_link()) {
                    Ok(tool) => self.shared_tool = Some(tool),
                    Err(e) => log::warn!("no shared tool: {e}"),
                }
                self.touch = Some(live);
                self.status = "touching with the mouse: the tool follows the pointer; \
                               Shift+wheel moves it in depth"
                    .into();
            }
            (true, Some(live)) => self.touch = Some(live),
            (false, Some(live)) => {
                self.spacemouse = None;
                self.stop_touch_recording();
                if let Some(tool) = self.shared_tool.take() {
                    tool.stop(&self.engine);
                }
                self.shared_state = ::app::touch::shared::SharedState::Alone;
                live.stop();
            }
            (false, None) => {}
        }
        Ok(())
    }

    /// Sends the servo's force to the HID force-feedback device `ids` (`VID:PID`), opened on
    /// a thread of its own (the status line says how it went), or shows it only (`None`);
    /// touch must be on.
    pub(super) fn set_force_output(&mut self, ids: Option<(u16, u16)>) -> Result<(), String> {
        let Some(live) = &mut self.touch else {
            return Err("turn touch on before choosing a force-feedback device".into());
        };
        match ids {
            Some((vendor, product)) => {
                self.force_opening = Some(live.force_output_ref().start_open(vendor, product));
                self.status =
                    format!("opening the force-feedback device {vendor:04x}:{product:04x}…");
            }
            None => {
                self.force_opening = None;
                live.force_output().close();
                self.status = live.force_output_ref().status();
            }
        }
        Ok(())
    }

    /// Takes what the force-feedback threads answered, and closes devices the servo handed
    /// back.
    fn poll_force_output(&mut self) {
        if let Some(rx) = &self.force_listing
            && let Ok(listed) = rx.try_recv()
        {
            self.force_devices = Some(listed);
            self.force_listing = None;
        }
        let Some(live) = &mut self.touch else {
            self.force_opening = None;
            return;
        };
        live.force_output_ref().collect();
        if let Some(opening) = &self.force_opening
            && let Some(outcome) = live.force_output().finish_open(opening)
        {
            self.status = match outcome {
                Ok(()) => live.force_output_ref().status(),
                Err(e) => e,
            };
            self.force_opening = None;
        }
    }

    /// Couples the shared tool when the peer it is held with holds it back, and uncouples
    /// when either lets go.
    fn update_shared_tool(&mut self) {
        let Some(tool) = &self.shared_tool else {
            return;
        };
        let me = self.engine.peer_id();
        let view = lock(self.engine.view());
        let theirs = self.hold_with.and_then(|p| view.presence().get(&p));
        let state = tool.update(me, self.hold_with, theirs);
        drop(view);
        if state != self.shared_state {
            let name = |p| lock(self.engine.view()).peer_label(p);
            self.status = match state {
                ::app::touch::shared::SharedState::Coupled(p) => {
                    format!(
                        "holding the tool with {}: each of you feels the other",
                        name(p)
                    )
                }
                ::app::touch::shared::SharedState::Waiting(p) => {
                    format!("waiting for {} to hold the tool with you", name(p))
                }
                ::app::touch::shared::SharedState::Alone => "holding the tool alone".into(),
            };
            self.shared_state = state;
        }
    }

    /// Adds this frame's force and energy to the plot and, while recording, the tool's point
    /// to the recorded path.
    fn record_touch(&mut self) {
        let Some(live) = &self.touch else {
            return;
        };
        let s = live.stats();
        let now = clock::now().instant;
        self.force_history.push(::app::touch::record::ForceSample {
            t_secs: (now - self.opened).as_secs_f64(),
            force_newtons: s.force_newtons.length(),
            energy_joules: s.energy_joules,
        });
        let button = live.button_down();
        let Some((recorder, since)) = &mut self.touch_recording else {
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
                self.touch_recording = None;
            }
        }
    }

    /// Records the touch tool's path to `path` (touch must be on), replayable with
    /// `sculpt touch SCENE --trace PATH`.
    pub(super) fn start_touch_recording(&mut self, path: &std::path::Path) -> Result<(), String> {
        if self.touch.is_none() {
            return Err("turn touch on before recording".into());
        }
        let recorder = ::app::touch::record::Recorder::create(path)
            .map_err(|e| format!("cannot record to {}: {e}", path.display()))?;
        self.touch_recording = Some((recorder, clock::now().instant));
        self.status = format!("recording the touch path to {}", path.display());
        Ok(())
    }

    /// Stops recording and says where the path went.
    pub(super) fn stop_touch_recording(&mut self) {
        if let Some((recorder, _)) = self.touch_recording.take() {
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
            self.spacemouse = None;
            return Ok(());
        }
        if self.spacemouse.is_some() {
            return Ok(());
        }
        self.set_touching(true)?;
        let Some(live) = &self.touch else {
            return Err("touch did not start".into());
        };
        let (press, presses) = std::sync::mpsc::channel();
        let driver =
            ::app::touch::spacemouse::SpaceMouseDriver::spawn(live.mouse_handle(), move |down| {
                let _ = press.send(down);
            })
            .map_err(|e| format!("cannot start the 3D mouse thread: {e}"))?;
        self.spacemouse = Some((driver, presses));
        Ok(())
    }

    /// Moves the touch tool under the pointer, in the plane through it that faces the
    /// camera, then `depth` scene units away from the camera.
    fn touch_follow(&self, px: Option<[f32; 2]>, size_px: [u32; 2], depth: f32) {
        let Some(live) = &self.touch else {
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

    /// Runs or stops the scene's time.
    pub(super) fn set_playing(&mut self, playing: bool) {
        self.scene_clock.set_playing(playing, clock::now().instant);
    }

    /// Undoes one of this peer's own ops chosen in the history list.
    pub(super) fn undo_op(&mut self, op: replication::OpId) {
        if self.pending.is_some() {
            return;
        }
        let payload = match Validated::new(replication::shape::ShapePayload::Undo(op)) {
            Ok(payload) => payload,
            Err(e) => {
                self.status = e;
                return;
            }
        };
        let planned = Planned {
            payload: payload.clone(),
            summary: "undid an edit chosen in the history".into(),
            select: None,
        };
        match self.engine.author_validated(payload) {
            Ok(pending) => self.pending = Some((pending, planned)),
            Err(e) => self.status = e.to_string(),
        }
    }

    /// Meshes the stroked object with the stroke so far, at most every [`PREVIEW_MILLIS`].
    fn preview_stroke(&mut self) {
        let now = clock::now().instant;
        if self
            .preview_at
            .is_some_and(|t| now.duration_since(t).as_millis() < u128::from(PREVIEW_MILLIS))
        {
            return;
        }
        let Some(stroke) = &self.stroke else {
            return;
        };
        let id = ObjectId(stroke.object);
        let job = {
            let view = lock(self.engine.view());
            let scene = view.scene();
            let Some(entry) = scene.scene_object(id) else {
                return;
            };
            let mut object = entry.object.clone();
            if object.apply(stroke.edit()).is_err() {
                return;
            }
            (object, scene.world_from_group(entry.group))
        };
        let tracked = self.objects.entry(id).or_default();
        tracked.generation += 1;
        tracked.meshing_since.get_or_insert(now);
        tracked.pending = Some(Box::new(MeshJob {
            id,
            object: job.0,
            world_from_group: job.1,
            generation: tracked.generation,
            depth: self.depth,
            requested_at: now,
            t_secs: self.scene_clock.secs(now),
        }));
        self.preview_at = Some(now);
    }
}

/// A box around an object's mesh in the renderer's world.
fn world_box(o: &SceneObject) -> Option<Aabb> {
    let b = o.mesh.bounds()?;
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for k in 0..8usize {
        let corner = Vec3::from_array(std::array::from_fn(|a| {
            if k >> a & 1 == 1 { b.hi[a] } else { b.lo[a] }
        }));
        let p = o.world_from_object.transform_point3(corner);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    Some(Aabb::new(lo.to_array(), hi.to_array()))
}

/// A sphere around the drawn objects' world `boxes` (centre, radius), for framing the camera.
pub fn bounding_sphere(boxes: impl Iterator<Item = Aabb>) -> Option<(Vec3, f32)> {
    let (lo, hi) = boxes
        .map(|b| (Vec3::from_array(b.lo), Vec3::from_array(b.hi)))
        .reduce(|(lo, hi), (l, h)| (lo.min(l), hi.max(h)))?;
    Some((0.5 * (lo + hi), 0.5 * (hi - lo).length()))
}

impl SculptApp {
    /// Applies kept settings: the brush, and the name and colour unless flags gave them.
    pub fn apply_settings(&mut self, settings: &::app::settings::Settings, path: PathBuf) {
        if let Some(brush) = settings.brush {
            self.brush = brush;
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

    /// Plans the ops of a scene or mesh file and queues them; nothing is authored when the
    /// file is refused.
    pub(super) fn import_file(&mut self, path: &std::path::Path) -> Result<(), String> {
        let next = lock(self.engine.view()).next_object();
        let imported = ::app::transfer::import(path, next).map_err(|e| e.to_string())?;
        self.status = format!(
            "importing {} ({} ops)",
            path.display(),
            imported.payloads.len()
        );
        self.import_queue.extend(imported.payloads);
        Ok(())
    }

    /// Authors the next queued import op once the last one is stored.
    fn author_imports(&mut self) {
        if self.pending.is_some() {
            return;
        }
        let Some(payload) = self.import_queue.pop_front() else {
            return;
        };
        // Refused as the engine's reply would refuse it: shown, and the next op goes on.
        let payload = match Validated::new(payload) {
            Ok(payload) => payload,
            Err(e) => {
                self.input_error = Some(e);
                return;
            }
        };
        let planned = Planned {
            payload: payload.clone(),
            summary: format!("imported; {} ops to go", self.import_queue.len()),
            select: None,
        };
        match self.engine.author_validated(payload) {
            Ok(pending) => self.pending = Some((pending, planned)),
            Err(e) => {
                self.status = format!("import stopped: {e}");
                self.import_queue.clear();
            }
        }
    }

    /// Exports the selected object (or the whole scene) to `path` on a thread of its own.
    pub(super) fn export_file(&mut self, path: PathBuf) -> Result<(), String> {
        if self.export.is_some() {
            return Err("an export is still running".into());
        }
        if formats::registry::FileFormat::of(&path).is_none() {
            return Err(format!(
                "export to {}: give a file ending in {}",
                path.display(),
                formats::registry::EXTENSIONS.join(", ")
            ));
        }
        let scene = lock(self.engine.view()).scene().clone();
        let object = self.selected.map(ObjectId);
        let depth = self.depth;
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("sculpt-export".into())
            .spawn(move || {
                let result = ::app::transfer::export(&scene, object, &path, depth)
                    .map(|report| report.to_string())
                    .map_err(|e| e.to_string());
                let _ = tx.send(result);
            })
            .map_err(|e| e.to_string())?;
        self.export = Some(rx);
        self.status = "exporting…".into();
        Ok(())
    }

    /// Files dropped on the window are imported; an export's result reaches the status line.
    fn files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        for path in dropped {
            if let Err(e) = self.import_file(&path) {
                self.status = e;
            }
        }
        self.author_imports();
        if let Some(result) = self.export.as_ref().and_then(|rx| rx.try_recv().ok()) {
            self.export = None;
            self.status = match result {
                Ok(report) => report.lines().next().unwrap_or("exported").to_string(),
                Err(e) => format!("export failed: {e}"),
            };
        }
    }

    /// Keeps the brush, name and colour for the next run.
    fn save_settings(&self) {
        let Some(path) = &self.settings_path else {
            return;
        };
        let presence = self.engine.presence();
        // A name the user never chose (the short id) is not kept: it would follow the user
        // into another store under another id.
        let chosen = presence.name != self.engine.peer_id().short();
        let settings = ::app::settings::Settings {
            name: chosen.then_some(presence.name),
            colour: Some(presence.colour),
            brush: Some(self.brush),
            window_points: self.layout.window_points,
            side_panel_points: Some(self.layout.side_panel_points),
        };
        if let Err(e) = settings.save(path) {
            log::warn!("cannot keep the settings in {}: {e}", path.display());
        }
    }
}

impl eframe::App for SculptApp {
    fn on_exit(&mut self) {
        self.save_settings();
        let _ = self.set_touching(false);
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let now = clock::now();
        if let Some(last) = self.stats.last_frame_start {
            let ms = now.instant.duration_since(last).as_secs_f64() * 1e3;
            push_bounded(&mut self.stats.frame_interval_ms, ms, FRAME_SAMPLES_MAX);
        }
        self.stats.last_frame_start = Some(now.instant);
        self.stats.n_frames += 1;

        self.receive_meshes(now);
        self.receive_reply(now);
        self.sync_objects(now);
        self.refresh_rows();
        self.follow();
        self.shortcuts(ui.ctx());
        self.files(ui.ctx());
        self.run_hooks(ui.ctx());
        self.publish_presence();
        // Moving objects while time runs, and the touch tool while touching, draw every frame.
        let animating =
            (self.place_moving(now.instant) && self.scene_clock.playing()) || self.touch.is_some();
        let title = match self.n_meshing_long(now.instant) {
            0 => format!("sculpt — {}", self.presence_text()),
            n => format!("sculpt — meshing {n}… — {}", self.presence_text()),
        };
        if title != self.title {
            ui.ctx()
                .send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.title = title;
        }

        egui::Panel::top("sculpt-top").show(ui, |ui| self.top_ui(ui));
        egui::Panel::bottom("sculpt-status").show(ui, |ui| self.status_ui(ui));
        let side = egui::Panel::right("sculpt-side")
            .default_size(self.layout.side_panel_points)
            .resizable(true)
            .show(ui, |ui| self.side_ui(ui, now));
        self.layout.side_panel_points = side.response.rect.width();
        self.layout.window_points = ui
            .ctx()
            .input(|i| i.viewport().inner_rect)
            .map(|r| [r.width(), r.height()]);
        egui::CentralPanel::no_frame().show(ui, |ui| self.central_ui(ui));

        if animating {
            ui.ctx()
                .request_repaint_after(std::time::Duration::from_millis(ANIMATION_FRAME_MILLIS));
        }
        // An edit made this frame is sent to the mesher at the start of the next one.
        if self.dirty {
            ui.ctx().request_repaint();
        }
        if self.n_meshing() > 0 {
            // So that the title says "meshing" once it has taken long, without other input.
            ui.ctx()
                .request_repaint_after(std::time::Duration::from_millis(MESHING_SHOWN_MILLIS));
        }
        let ui_ms = clock::now()
            .instant
            .duration_since(now.instant)
            .as_secs_f64()
            * 1e3;
        push_bounded(&mut self.stats.ui_ms, ui_ms, FRAME_SAMPLES_MAX);
    }
}

impl SculptApp {
    /// The density under the live touch tool, in the object it touches (see [`probe`]).
    fn sampled_density(&self) -> Option<f64> {
        self.sampled_density_in(&lock(self.engine.view()))
    }

    /// [`SculptApp::sampled_density`] with the engine's view already locked.
    pub(crate) fn sampled_density_in(&self, view: &::app::engine::View) -> Option<f64> {
        let stats = self.touch.as_ref()?.stats();
        let t = self.scene_clock.secs(clock::now().instant);
        if stats.n_scenes_taken == 0 {
            // The servo has no scene yet, so no word on what it touches: look it up.
            return probe::density_under(view.scene(), None, stats.hip_world, t);
        }
        // Once it has, it names the object (or none, in empty space): one sampler a frame.
        probe::density_at(view.scene(), stats.top_id?, stats.hip_world, t)
    }

    /// The haptic zone, the tool at the haptic interface point and the force it meets.
    fn draw_touch(&self, scene: &mut Scene) {
        let Some(live) = &self.touch else {
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
        scene.add_tool(
            &model::object::ToolShape::Sphere { radius },
            glam::Mat4::from_translation(hip),
            probe::sampling_colour(self.sampled_density()),
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

/// The box around `b` moved by `m` (its eight corners'), for a moving object's selection.
fn moved_box(b: &Aabb, m: &glam::Mat4) -> Aabb {
    let corners = (0..8).map(|k| {
        let pick = |axis: usize| {
            if k & (1 << axis) == 0 {
                b.lo[axis]
            } else {
                b.hi[axis]
            }
        };
        m.transform_point3(glam::Vec3::new(pick(0), pick(1), pick(2)))
    });
    let (mut lo, mut hi) = (
        glam::Vec3::splat(f32::INFINITY),
        glam::Vec3::splat(f32::NEG_INFINITY),
    );
    for c in corners {
        lo = lo.min(c);
        hi = hi.max(c);
    }
    Aabb::new(lo.to_array(), hi.to_array())
}
