//! The scene's objects as the window meshes and draws them: which ones the engine said
//! changed, the jobs sent to render's `Mesher` (an edit re-meshes its own object only), the
//! meshes that came back, and where moving objects are at the frame's scene time.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use model::object::{Object, Sampler, Transform};
use model::scene::{ObjectId, Scene as ModelScene};
use render::mesh::octree::MeshPatch;
use render::mesh::{Aabb, Mesh};
use render::mesher::{MeshJob, MeshKind, Meshed, Mesher};
use render::scene::{Line, Scene, SceneObject};
use render::snapshot::render_from_scene;

use ::app::clock;
use ::app::samples::Samples;

/// Edit-to-mesh and edit-to-pixels times kept.
pub const MAX_EDIT_SAMPLES: usize = 100;
/// Patches kept for the viewport between its draws.
pub const MAX_PATCHES_KEPT: usize = 256;
/// Meshing that has run this long shows in the title ("meshing N…").
pub const MESHING_SHOWN_MILLIS: u64 = 200;
/// While time runs, an object whose drawing reads `t` is meshed again at most this often.
pub const ANIMATION_REMESH_MILLIS: u64 = 100;
/// A frame that sent the mesher an edit (this window's stroke released or command taken,
/// another peer's op)
/// waits for its mesh until this long after the frame began, so that the frame which took the
/// edit draws it; a mesh that takes longer is drawn by a later frame.
pub const MAX_EDIT_WAIT_MILLIS: u64 = 25;
/// Colour of the selected object's box.
const SELECTION_COLOUR: [f32; 4] = [1.0, 0.85, 0.2, 1.0];

/// A patch for `Renderer::patch_object`: the object, the mesh it starts from, the mesh it
/// makes, and the ranges written.
pub type PatchForRenderer = (ObjectId, Arc<Mesh>, Arc<Mesh>, MeshPatch);

/// Edits timed to the screen, by whose they are: this window's (from the start of the frame
/// that took their input) and another peer's (from their op's timestamp); one of each may
/// share a mesh, and each is timed.
type BySource<T> = [Option<T>; 2];
/// This window's edits in a [`BySource`].
const LOCAL: usize = 0;
/// Another peer's edits in a [`BySource`].
const REMOTE: usize = 1;

/// Another peer's op stamped `stamp` (micros of its wall clock), as an instant of ours.
fn remote_instant(stamp: replication::Timestamp) -> Instant {
    let now = clock::now();
    let age = Duration::from_micros(now.wall.0.saturating_sub(stamp.0));
    now.instant.checked_sub(age).unwrap_or(now.instant)
}

/// One scene object as the window tracks it: what was sent to the mesher, what is drawn.
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
    /// What is drawn is a first look at a shallower depth ([`Meshed::coarse`]): its mesh at
    /// the window's depth follows.
    pub drawn_coarse: bool,
    /// When a mesh for a later time was last asked for, while none is in flight.
    time_job: Option<TimeJob>,
    /// An edit waiting to be drawn: the first generation that holds it, and its timing.
    awaited_edit: BySource<(u64, Instant)>,
    /// Its last job was a preview, not the scene's object.
    pub previewed: bool,
    /// The scene's object is to be meshed once the preview on the worker is drawn.
    remesh_after_preview: bool,
}

impl Tracked {
    /// Renderer world from object where it is drawn this frame (moved to the frame's time).
    pub fn world_from_object_now(&self) -> Option<glam::Mat4> {
        let drawn = self.drawn.as_ref()?.world_from_object;
        Some(self.moving.as_ref().map_or(drawn, |m| m.world_now))
    }

    /// Marks it stale, or, while a preview of it is on the worker, once that is drawn
    /// ([`Objects::remesh_previews`]).
    fn remesh_when_drawn(&mut self) {
        if self.previewed && !self.is_drawn_as_is() {
            self.remesh_after_preview = true;
        } else {
            self.stale = true;
        }
    }

    /// Whether it is drawn as the scene has it, with nothing waiting to be sent.
    fn is_drawn_as_is(&self) -> bool {
        self.pending.is_none() && self.drawn_generation == self.generation && !self.drawn_coarse
    }

    /// Takes the mesher's `done` when it is newer than what is drawn (a later job, or the same
    /// object meshed at a later scene time); returns whether it was.
    fn take_meshed(&mut self, done: Meshed) -> bool {
        let same = done.generation == self.drawn_generation;
        let newer = done.generation > self.drawn_generation
            || (same && done.t_secs > self.drawn_t_secs)
            || (same && self.drawn_coarse && !done.coarse);
        if !newer {
            return false;
        }
        self.kind = Some(done.kind);
        self.drawn_generation = done.generation;
        self.drawn_t_secs = done.t_secs;
        self.drawn_coarse = done.coarse;
        if let Some(job) = self.time_job.as_mut() {
            job.done = true;
        }
        if self.drawn_generation == self.generation && !self.drawn_coarse {
            self.meshing_since = None;
        }
        self.drawn_box = done.object.as_ref().and_then(world_box);
        self.drawn = done.object;
        self.lines = done.lines;
        self.n_triangles = done.n_triangles;
        self.skipped = done.skipped;
        self.mesh_secs = done.mesh_secs;
        true
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
    sampler: Sampler,
    world_from_group: Transform,
    /// Renderer world from object at the time the drawn mesh was made (where the mesher
    /// placed it and its arrows).
    world_at_drawn: glam::Mat4,
    /// At the last frame's scene time.
    pub world_now: glam::Mat4,
}

impl Moving {
    fn new(object: &Object, world_from_group: Transform) -> Moving {
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

    /// Renderer world from object at scene time `t_secs`: the object model's one rule for
    /// where an object is, as the mesher places it at 0.
    fn world_at(&mut self, t_secs: f64) -> glam::Mat4 {
        let scene_from_object =
            model::scene::world_from_object(&self.world_from_group, &mut self.sampler, t_secs);
        render_from_scene() * glam::DMat4::from(scene_from_object.parent_from_child).as_mat4()
    }

    /// Where what was drawn at the mesh's time is now (force arrows, the drawn box).
    fn since_drawn(&self) -> glam::Mat4 {
        self.world_now * self.world_at_drawn.inverse()
    }
}

/// How the meshes were made and how long edits took to show.
pub struct MeshStats {
    /// Milliseconds from the start of the frame that took an edit's input (the stroke's
    /// release, the line's Enter) to its object's new mesh coming back from the mesher.
    pub edit_to_mesh_ms: Samples,
    /// The same, to the start of the frame after the one that drew that mesh (so the drawn
    /// frame was presented).
    pub edit_to_pixels_ms: Samples,
    /// From another peer's op's timestamp (its author's clock: meaningful where the clocks
    /// agree, as on one machine) to the start of the frame after the one that drew it; ops
    /// that arrive when catching up count from when they were made.
    pub remote_edit_to_pixels_ms: Samples,
    /// From another peer's op's timestamp to its object's new mesh coming back (also while
    /// the window is covered and draws nothing).
    pub remote_edit_to_mesh_ms: Samples,
    /// The worker's milliseconds for each patch drawn ([`Meshed::mesh_secs`]).
    pub patch_ms: Samples,
    /// Meshes drawn that patched the last one.
    pub n_patched: u64,
    /// Meshes drawn whole.
    pub n_whole: u64,
    /// First looks drawn ([`Meshed::coarse`]), before new objects' meshes at full depth
    /// (not counted in `n_whole`).
    pub n_coarse: u64,
    /// This window's edits timed to a later job than the first that held them (a stroke's
    /// last preview superseded on the worker before it was drawn).
    pub n_edits_superseded: u64,
    /// Edits whose mesh the frame that sent them waited for and drew.
    pub n_edits_awaited: u64,
    /// Edits whose frame waited for their mesh until [`MAX_EDIT_WAIT_MILLIS`] in vain.
    pub n_edit_waits_expired: u64,
}

/// The objects sent to the mesher and drawn.
pub struct Objects {
    mesher: Mesher,
    /// Every object of the scene, by id.
    pub tracked: BTreeMap<ObjectId, Tracked>,
    /// Patches of meshes swapped in since the viewport last took them.
    patches: Vec<PatchForRenderer>,
    /// Octree depth of implicit objects.
    pub depth: u8,
    /// Where this window is in the engine's change stream.
    changes_cursor: u64,
    /// The scene changed since objects were last compared with what was sent.
    pub dirty: bool,
    /// An edit whose object is not yet sent to the mesher.
    edit_at: BySource<Instant>,
    /// The input time of the edit a stroke's last preview is timed as.
    previewed_edit: Option<Instant>,
    /// An edit whose mesh this frame draws: the next frame's start, after this one is
    /// presented, ends its time to pixels.
    drawing_edit: BySource<Instant>,
    /// The newest remote op timestamp already timed.
    remote_seen: Option<replication::Timestamp>,
    /// An edit, this window's or another peer's, went to the mesher since the last
    /// [`Objects::await_sent_edits`].
    edit_sent: [bool; 2],
    /// How meshes were made.
    pub stats: MeshStats,
}

impl Objects {
    /// None yet, with a mesher whose workers call `wake` when a mesh is ready.
    pub fn start(depth: u8, wake: impl Fn() + Send + Sync + 'static) -> std::io::Result<Objects> {
        Ok(Objects {
            mesher: Mesher::start(|| clock::now().instant, wake)?,
            tracked: BTreeMap::new(),
            patches: Vec::new(),
            depth,
            changes_cursor: 0,
            dirty: true,
            edit_at: [None; 2],
            previewed_edit: None,
            drawing_edit: [None; 2],
            remote_seen: None,
            edit_sent: [false; 2],
            stats: MeshStats {
                edit_to_mesh_ms: Samples::new(MAX_EDIT_SAMPLES),
                edit_to_pixels_ms: Samples::new(MAX_EDIT_SAMPLES),
                remote_edit_to_pixels_ms: Samples::new(MAX_EDIT_SAMPLES),
                remote_edit_to_mesh_ms: Samples::new(MAX_EDIT_SAMPLES),
                patch_ms: Samples::new(MAX_EDIT_SAMPLES),
                n_patched: 0,
                n_whole: 0,
                n_coarse: 0,
                n_edits_superseded: 0,
                n_edits_awaited: 0,
                n_edit_waits_expired: 0,
            },
        })
    }

    /// Forgets every object, for another session's scene.
    pub fn reset(&mut self) {
        self.tracked.clear();
        self.changes_cursor = 0;
        self.dirty = true;
    }

    /// An edit of this window's, whose input the frame that started at `input_at` took, is
    /// stored: the scene is compared again, and the objects it changed are timed from
    /// `input_at` to their mesh and to the frame that draws it.
    pub fn edited(&mut self, input_at: Instant) {
        // A stroke's last preview timed it already.
        if self.previewed_edit.take() != Some(input_at) {
            self.edit_at[LOCAL] = Some(input_at);
        }
        self.dirty = true;
    }

    /// A frame starts at `now`, so the one before it was presented: an edit it drew has
    /// reached the screen.
    pub fn presented(&mut self, now: Instant) {
        let samples = [
            &mut self.stats.edit_to_pixels_ms,
            &mut self.stats.remote_edit_to_pixels_ms,
        ];
        for (drawing, samples) in self.drawing_edit.iter_mut().zip(samples) {
            if let Some(at) = drawing.take() {
                samples.push(now.duration_since(at).as_secs_f64() * 1e3);
            }
        }
    }

    /// Whether this frame draws an edit's mesh (the next frame, which times it, is wanted
    /// at once).
    pub fn draws_an_edit(&self) -> bool {
        self.drawing_edit.iter().any(Option::is_some)
    }

    /// Marks the objects the engine says changed since the last call stale (all of them when
    /// it cannot say; one whose preview is on the worker once that is drawn); returns whether
    /// any may have changed.
    pub fn take_changes(&mut self, view: &::app::engine::View) -> bool {
        let (changes, cursor) = view.changes_since(self.changes_cursor);
        self.changes_cursor = cursor;
        let Some(changes) = changes else {
            self.dirty = true;
            for (id, _) in view.scene().objects() {
                self.tracked.entry(id).or_default().stale = true;
            }
            return true;
        };
        self.dirty |= !changes.is_empty();
        let remote = view.last_remote_edit();
        if !changes.is_empty() && remote > self.remote_seen {
            self.remote_seen = remote;
            self.edit_at[REMOTE] = remote.map(remote_instant);
        }
        for id in &changes {
            self.tracked.entry(*id).or_default().remesh_when_drawn();
        }
        !changes.is_empty()
    }

    /// Forgets objects that are gone and makes jobs for the stale ones, once the scene
    /// changed.
    pub fn send_stale(&mut self, scene: &ModelScene, now: Instant, t_secs: f64) {
        if !std::mem::take(&mut self.dirty) {
            return;
        }
        let mesher = &self.mesher;
        let edit_at = std::mem::take(&mut self.edit_at);
        self.tracked.retain(|id, _| {
            let kept = scene.object(*id).is_some();
            if !kept {
                mesher.forget(*id);
            }
            kept
        });
        for (id, tracked) in &mut self.tracked {
            if !std::mem::take(&mut tracked.stale) {
                continue;
            }
            let Some(entry) = scene.scene_object(*id) else {
                continue;
            };
            tracked.generation += 1;
            tracked.meshing_since.get_or_insert(now);
            for (awaited, at) in tracked.awaited_edit.iter_mut().zip(edit_at) {
                if let Some(at) = at {
                    awaited.get_or_insert((tracked.generation, at));
                }
            }
            tracked.previewed = false;
            tracked.remesh_after_preview = false;
            let world_from_group = scene.world_from_group(entry.group);
            tracked.moving = entry
                .object
                .data()
                .motion
                .is_some()
                .then(|| Box::new(Moving::new(&entry.object, world_from_group)));
            tracked.timed = render::animation::object_reads_time(&entry.object);
            tracked.time_job = None;
            for (sent, at) in self.edit_sent.iter_mut().zip(edit_at) {
                *sent |= at.is_some();
            }
            tracked.pending = Some(Box::new(MeshJob {
                id: *id,
                object: entry.object.clone(),
                world_from_group,
                generation: tracked.generation,
                depth: self.depth,
                requested_at: edit_at[LOCAL].or(edit_at[REMOTE]).unwrap_or(now),
                t_secs,
                coarse_first: true,
            }));
        }
    }

    /// Time ran: what reads `t` is meshed again at the new time, one job at a time per
    /// object and at most every [`ANIMATION_REMESH_MILLIS`].
    pub fn ask_time_jobs(&mut self, scene: &ModelScene, now: Instant, t_secs: f64) {
        let every = Duration::from_millis(ANIMATION_REMESH_MILLIS);
        for (id, tracked) in &mut self.tracked {
            let due = tracked.timed
                && tracked.is_drawn_as_is()
                && tracked
                    .time_job
                    .is_none_or(|j| j.done && now.duration_since(j.asked_at) >= every);
            let Some(entry) = scene.scene_object(*id).filter(|_| due) else {
                continue;
            };
            tracked.time_job = Some(TimeJob {
                asked_at: now,
                done: false,
            });
            tracked.pending = Some(Box::new(MeshJob {
                id: *id,
                object: entry.object.clone(),
                world_from_group: scene.world_from_group(entry.group),
                generation: tracked.generation,
                depth: self.depth,
                requested_at: now,
                t_secs,
                coarse_first: false,
            }));
        }
    }

    /// A preview of object `id` as `object` (a stroke being drawn, or finished and on its
    /// way to the store), placed by `world_from_group` and meshed at `t_secs`; `edit_input_at`
    /// times it as an edit whose input the frame that started then took.
    pub fn preview(
        &mut self,
        id: ObjectId,
        object: Object,
        world_from_group: Transform,
        now: Instant,
        t_secs: f64,
        edit_input_at: Option<Instant>,
    ) {
        let tracked = self.tracked.entry(id).or_default();
        tracked.generation += 1;
        tracked.meshing_since.get_or_insert(now);
        tracked.previewed = true;
        if let Some(at) = edit_input_at {
            tracked.awaited_edit[LOCAL] = Some((tracked.generation, at));
            self.previewed_edit = Some(at);
            self.edit_sent[LOCAL] = true;
        }
        tracked.pending = Some(Box::new(MeshJob {
            id,
            object,
            world_from_group,
            generation: tracked.generation,
            depth: self.depth,
            requested_at: now,
            t_secs,
            coarse_first: true,
        }));
    }

    /// Objects last sent as a preview are meshed again as the scene has them: the stroke's
    /// op was stored (the mesh is then usually the preview's, and nothing is drawn again, but
    /// the fold may have rejected it) or `refused` (then no edit of theirs is timed).
    ///
    /// A stored stroke's preview still on the worker is finished and drawn first: a job sent
    /// now would supersede it, and the worker drops a superseded job, even one half done, to
    /// mesh the scene's object from the start, which is usually the preview's object again.
    /// Once the preview is drawn, the scene's mesh of it is found unchanged in a few boxes.
    pub fn remesh_previews(&mut self, refused: bool) {
        for tracked in self.tracked.values_mut() {
            if !tracked.previewed {
                continue;
            }
            if refused {
                tracked.awaited_edit[LOCAL] = None;
                tracked.stale = true;
            } else {
                tracked.remesh_when_drawn();
            }
            self.dirty = true;
        }
    }

    /// Hands the waiting jobs to the mesher (those its queue has no room for wait on).
    pub fn flush(&mut self) {
        for tracked in self.tracked.values_mut() {
            if let Some(job) = tracked.pending.take() {
                tracked.pending = self.mesher.try_send(job).err();
            }
        }
    }

    /// Takes finished meshes. One of an older job than the latest is still drawn when newer
    /// than what is drawn (the workers mesh each object's jobs in order and drop superseded
    /// ones before they start), so each patch starts from the mesh drawn.
    pub fn receive(&mut self, now: Instant) {
        while let Some(done) = self.mesher.try_recv() {
            self.take(done, now);
        }
    }

    /// Waits until `deadline` at most for the meshes of the edits sent to the mesher since the
    /// last call (a stroke's release, another peer's op), taking every mesh that comes
    /// meanwhile; returns at once when none was sent. The frame that sent an edit then draws
    /// its mesh, one frame sooner than when the next frame takes it; while it waits, the
    /// mesher has the cores.
    pub fn await_sent_edits(&mut self, mut now: Instant, deadline: Instant) {
        let sent = std::mem::take(&mut self.edit_sent);
        let waiting = |objects: &Objects, source: usize| {
            sent[source]
                && objects.drawing_edit[source].is_none()
                && objects
                    .tracked
                    .values()
                    .any(|t| t.awaited_edit[source].is_some())
        };
        while [LOCAL, REMOTE].into_iter().any(|s| waiting(self, s)) {
            let left = deadline.saturating_duration_since(now);
            let Some(done) = self.mesher.recv_timeout(left) else {
                break;
            };
            now = clock::now().instant;
            self.take(done, now);
        }
        for source in [LOCAL, REMOTE].into_iter().filter(|s| sent[*s]) {
            match waiting(self, source) {
                true => self.stats.n_edit_waits_expired += 1,
                false => self.stats.n_edits_awaited += 1,
            }
        }
    }

    /// Leaves the edits sent since the last [`Objects::await_sent_edits`] to later frames.
    pub fn forget_sent_edits(&mut self) {
        self.edit_sent = [false; 2];
    }

    /// Takes one finished mesh, taken from the mesher at `now`.
    fn take(&mut self, mut done: Meshed, now: Instant) {
        let Some(tracked) = self.tracked.get_mut(&done.id) else {
            return;
        };
        let (id, kind, generation, coarse) = (done.id, done.kind, done.generation, done.coarse);
        let patch = done.patch.take();
        let mesh = done.object.as_ref().map(|o| Arc::clone(&o.mesh));
        let mesh_ms = done.mesh_secs * 1e3;
        if !tracked.take_meshed(done) {
            return;
        }
        if tracked.remesh_after_preview && tracked.is_drawn_as_is() {
            tracked.remesh_after_preview = false;
            tracked.stale = true;
            self.dirty = true;
        }
        if let (Some((base, patch)), Some(mesh)) = (patch, mesh) {
            if self.patches.len() >= MAX_PATCHES_KEPT {
                // The viewport has not drawn for a while: it uploads whole meshes then.
                self.patches.clear();
            }
            self.patches.push((id, base, mesh, patch));
        }
        match kind {
            _ if coarse => self.stats.n_coarse += 1,
            MeshKind::Patch => {
                self.stats.n_patched += 1;
                self.stats.patch_ms.push(mesh_ms);
            }
            MeshKind::Whole => self.stats.n_whole += 1,
            MeshKind::Unchanged => {}
        }
        for source in [LOCAL, REMOTE] {
            let awaited = &mut tracked.awaited_edit[source];
            let Some((first, at)) = awaited.filter(|(g, _)| generation >= *g) else {
                continue;
            };
            *awaited = None;
            self.stats.n_edits_superseded += u64::from(source == LOCAL && generation > first);
            let ms = now.duration_since(at).as_secs_f64() * 1e3;
            let samples = [
                &mut self.stats.edit_to_mesh_ms,
                &mut self.stats.remote_edit_to_mesh_ms,
            ];
            samples[source].push(ms);
            let drawing = &mut self.drawing_edit[source];
            *drawing = Some(drawing.map_or(at, |d| d.min(at)));
        }
    }

    /// The patches since the last call, each with its object's index in the drawn scene's
    /// `ids` (those of objects not drawn are dropped).
    pub fn take_patches(
        &mut self,
        ids: &[ObjectId],
    ) -> Vec<(usize, Arc<Mesh>, Arc<Mesh>, MeshPatch)> {
        std::mem::take(&mut self.patches)
            .into_iter()
            .filter_map(|(id, base, mesh, patch)| {
                let idx = ids.iter().position(|i| *i == id)?;
                Some((idx, base, mesh, patch))
            })
            .collect()
    }

    /// Whether every object is drawn as the scene has it.
    pub fn is_idle(&self) -> bool {
        !self.dirty && self.tracked.values().all(Tracked::is_drawn_as_is)
    }

    /// Objects that have waited for a mesh longer than [`MESHING_SHOWN_MILLIS`] (the title
    /// shows them; a frame is asked for while any waits, so the title changes in time).
    pub fn n_meshing_long(&self, now: Instant) -> usize {
        let shown = Duration::from_millis(MESHING_SHOWN_MILLIS);
        self.tracked
            .values()
            .filter(|t| {
                t.meshing_since
                    .is_some_and(|s| now.duration_since(s) >= shown)
            })
            .count()
    }

    /// Objects waiting for a mesh.
    pub fn n_meshing(&self) -> usize {
        self.tracked
            .values()
            .filter(|t| t.drawn_generation != t.generation || t.drawn_coarse)
            .count()
    }

    /// Triangles drawn.
    pub fn n_triangles(&self) -> usize {
        self.tracked.values().map(|t| t.n_triangles).sum()
    }

    /// Object `id`'s box in the renderer's world, as drawn.
    pub fn drawn_box(&self, id: u64) -> Option<Aabb> {
        self.tracked.get(&ObjectId(id)).and_then(|t| t.drawn_box)
    }

    /// A sphere around the drawn objects (centre, radius), for framing the camera.
    pub fn bounding_sphere(&self) -> Option<(Vec3, f32)> {
        bounding_sphere(self.tracked.values().filter_map(|t| t.drawn_box))
    }

    /// Places the moving objects at scene time `t_secs`; returns whether any object moves
    /// or changes with time (so that frames keep coming while time runs).
    pub fn place(&mut self, t_secs: f64) -> bool {
        let mut any = false;
        for tracked in self.tracked.values_mut() {
            any |= tracked.timed;
            if let Some(moving) = tracked.moving.as_mut() {
                moving.world_now = moving.world_at(t_secs);
                moving.world_at_drawn = moving.world_at(tracked.drawn_t_secs);
                any = true;
            }
        }
        any
    }

    /// The drawn objects in id order (their ids alongside, for picking), their arrows, and
    /// the `selected` one's box.
    pub fn drawn_scene(&self, selected: Option<u64>) -> (Scene, Vec<ObjectId>) {
        let mut scene = Scene::default();
        let mut ids = Vec::new();
        for (id, tracked) in &self.tracked {
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
                if selected == Some(id.0)
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
        (scene, ids)
    }
}

/// A box around an object's mesh in the renderer's world.
fn world_box(o: &SceneObject) -> Option<Aabb> {
    Some(moved_box(&o.mesh.bounds()?, &o.world_from_object))
}

/// The box around `b` moved by `m` (its eight corners').
pub fn moved_box(b: &Aabb, m: &glam::Mat4) -> Aabb {
    let corners = (0..8).map(|k| {
        let pick = |axis: usize| {
            if k & (1 << axis) == 0 {
                b.lo[axis]
            } else {
                b.hi[axis]
            }
        };
        m.transform_point3(Vec3::new(pick(0), pick(1), pick(2)))
    });
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for c in corners {
        lo = lo.min(c);
        hi = hi.max(c);
    }
    Aabb::new(lo.to_array(), hi.to_array())
}

/// A sphere around the drawn objects' world `boxes` (centre, radius), for framing the camera.
pub fn bounding_sphere(boxes: impl Iterator<Item = Aabb>) -> Option<(Vec3, f32)> {
    let (lo, hi) = boxes
        .map(|b| (Vec3::from_array(b.lo), Vec3::from_array(b.hi)))
        .reduce(|(lo, hi), (l, h)| (lo.min(l), hi.max(h)))?;
    Some((0.5 * (lo + hi), 0.5 * (hi - lo).length()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ball(radius: f64) -> Object {
        Object::implicit(&format!("{radius} - sqrt(x^2 + y^2 + z^2)")).unwrap()
    }

    /// Previews object 1 as `object`, timed as an edit of this frame's when `input`; the job
    /// goes to the mesher when `sent`, else it is held back (as when the queue is full).
    fn send(objects: &mut Objects, object: Object, input: bool, sent: bool) -> Instant {
        let now = clock::now().instant;
        let input_at = input.then_some(now);
        objects.preview(ObjectId(1), object, Transform::IDENTITY, now, 0.0, input_at);
        if sent {
            objects.flush();
        }
        now
    }

    #[test]
    fn a_frame_waits_for_the_mesh_of_the_edit_it_sent_and_only_then() {
        let mut objects = Objects::start(5, || {}).unwrap();
        let far = Duration::from_secs(600);
        // The edit's mesh is taken by the wait, and this frame draws it.
        let at = send(&mut objects, ball(0.5), true, true);
        objects.await_sent_edits(at, at + far);
        assert!(objects.draws_an_edit());
        assert_eq!(objects.tracked[&ObjectId(1)].drawn_generation, 1);
        assert_eq!(objects.stats.n_edits_awaited, 1);
        assert_eq!(objects.stats.edit_to_mesh_ms.values().len(), 1);
        objects.presented(clock::now().instant);
        // A preview that is no edit of this frame's is left to a later frame.
        let at = send(&mut objects, ball(0.4), false, true);
        objects.await_sent_edits(at, at + far);
        assert_eq!(objects.tracked[&ObjectId(1)].drawn_generation, 1);
        assert_eq!(objects.stats.n_edits_awaited, 1);
        // An edit whose mesh does not come by the deadline (its job held back): the wait gives
        // up then, and says so.
        let at = send(&mut objects, ball(0.3), true, false);
        objects.await_sent_edits(at, at + Duration::from_millis(50));
        assert_eq!(objects.stats.n_edit_waits_expired, 1);
        assert_eq!(objects.stats.n_edits_awaited, 1);
        assert!(!objects.draws_an_edit());
    }

    /// A ball of `radius` in a domain (a shape the mesher meshes).
    fn bounded_ball(radius: f64) -> Object {
        use model::object::{Domain, Formula, Geometry, ObjectData};
        let formula = Formula::new(format!("{radius} - sqrt(x^2 + y^2 + z^2)")).unwrap();
        let domain = Domain::new(glam::DVec3::ZERO, glam::DVec3::splat(2.4 * radius));
        Object::new(ObjectData {
            geometry: Some(Geometry::implicit_in(formula, domain)),
            ..ObjectData::default()
        })
        .unwrap()
    }

    #[test]
    fn a_new_objects_first_look_is_drawn_and_its_mesh_follows() {
        let depth = render::mesher::MIN_COARSE_FIRST_DEPTH;
        let mut objects = Objects::start(depth, || {}).unwrap();
        let far = Duration::from_secs(600);
        // The frame that sent a new object's edit waits for its first look and draws it.
        let at = send(&mut objects, bounded_ball(0.5), true, true);
        objects.await_sent_edits(at, at + far);
        assert!(objects.draws_an_edit());
        assert_eq!(objects.stats.n_edits_awaited, 1);
        let tracked = &objects.tracked[&ObjectId(1)];
        assert!(tracked.drawn_coarse && tracked.drawn_generation == 1);
        let coarse_triangles = tracked.n_triangles;
        assert!(coarse_triangles > 0);
        // Not drawn as the scene has it yet: its mesh at the window's depth is on its way.
        assert!(!tracked.is_drawn_as_is());
        assert_eq!(objects.n_meshing(), 1);
        let deadline = clock::now().instant + far;
        while objects.n_meshing() > 0 {
            assert!(clock::now().instant < deadline, "the mesh came");
            std::thread::sleep(Duration::from_millis(5));
            objects.receive(clock::now().instant);
        }
        let tracked = &objects.tracked[&ObjectId(1)];
        assert!(!tracked.drawn_coarse && tracked.drawn_generation == 1);
        assert!(tracked.is_drawn_as_is());
        assert!(
            tracked.n_triangles > 4 * coarse_triangles,
            "{} and {coarse_triangles}",
            tracked.n_triangles
        );
        assert_eq!((objects.stats.n_coarse, objects.stats.n_whole), (1, 1));
        assert_eq!(objects.n_meshing(), 0);
    }
}
