//! Meshing off the UI thread: named worker threads take jobs (one object, as the fold left it)
//! from a bounded queue, mesh, colour and place them, and hand the drawable object back
//! through a bounded channel, waking the UI.
//!
//! Incremental path: for each implicit object the workers keep render's `OctreeMesher` and the
//! mesh last handed out. A job whose object differs from the last one meshed only in its edit
//! history (edits appended, undone, redone, or a stroke preview replaced by the stroke) remeshes
//! only the boxes of the edits that changed (`OctreeMesher::remesh`), patches the last mesh
//! (`OctreeMesher::mesh_update`) and recolours only the vertices the patch wrote (and those in
//! a changed colour painting's box); the result carries the `MeshPatch` for
//! `Renderer::patch_object`. Anything else (another geometry, appearance, transform, group,
//! depth, an intersection, a grown bounding box) meshes the object whole, and other shapes go
//! through `render::snapshot::build` as `sculpt render` draws them.
//!
//! Scheduling: at least [`MESHER_THREADS_MIN`] workers, so one object's long mesh never holds
//! up the others; one object is meshed by one worker at a time (its state is checked out). A
//! newer job for an object replaces its queued one; a worker drops a job that a newer one
//! superseded before it starts, and stops a patch between its boxes when a newer job comes
//! (render's remesh has no cancel hook inside a box).

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::ops::Range;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Instant;

use glam::{DMat4, DVec3, Mat4};
use model::object::history::HistoryEntry;
use model::object::{CompiledEdit, EditOp, Object, Paintable, Shape, Transform};
use model::scene::ObjectId;
use render::appearance::CompiledAppearance;
use render::mesh::object_field::{Dirty, dirty_boxes, mesh_bounds, to_f32_box};
use render::mesh::octree::{MeshPatch, MeshSettings, OCTREE_DEPTH_MAX, OctreeMesher};
use render::mesh::{Aabb, Mesh, ObjectField};
use render::scene::{Line, Material, SceneObject};
use render::snapshot::{SnapshotSettings, build, render_from_scene};

use ::app::clock;

/// Most objects with a job waiting for a worker.
pub const JOBS_QUEUED_MAX: usize = 64;
/// Most results waiting for the UI.
pub const RESULTS_QUEUED_MAX: usize = 64;
/// Fewest worker threads: one object's long mesh never holds up the others.
pub const MESHER_THREADS_MIN: usize = 2;
/// Most worker threads (each may hold a whole mesh being built).
pub const MESHER_THREADS_MAX: usize = 4;
/// Most changed edits one job patches; more mesh the object whole.
pub const PATCH_EDITS_MAX: usize = 256;
/// Cells kept between an object's bounds and its octree's for a patch. `mesh_bounds` leaves
/// 2.5 for a surface the domain clips; a union's box already reaches past its solid (by the
/// tool's margin), so one cell keeps the surface strictly inside.
const GRID_MARGIN_CELLS: f32 = 1.0;

/// One object to mesh.
pub struct MeshJob {
    /// Its id.
    pub id: ObjectId,
    /// The object as folded (geometry, appearance, edits).
    pub object: Object,
    /// The transform of the group it hangs from (scene space, +y up).
    pub world_from_group: Transform,
    /// Counts this object's jobs; results of older ones are stale.
    pub generation: u64,
    /// Octree depth for implicit shapes.
    pub depth: u8,
    /// When the change that asked for it was made (for edit-to-mesh times).
    pub requested_at: Instant,
    /// The scene time to mesh at (shapes, colours and fields that read `t`).
    pub t_secs: f64,
}

/// How a result was made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshKind {
    /// Meshed from scratch.
    Whole,
    /// The previous mesh patched where the changed edits act.
    Patch,
    /// Nothing visible changed (a painting of a physics property): the previous mesh.
    Unchanged,
}

impl MeshKind {
    /// The name the state dump uses.
    pub fn name(self) -> &'static str {
        match self {
            MeshKind::Whole => "whole",
            MeshKind::Patch => "patch",
            MeshKind::Unchanged => "unchanged",
        }
    }
}

/// A meshed object.
pub struct Meshed {
    /// Its id.
    pub id: ObjectId,
    /// The job's generation.
    pub generation: u64,
    /// The drawable object (renderer world, +z up), `None` when nothing could be drawn.
    pub object: Option<SceneObject>,
    /// Force-field arrows.
    pub lines: Vec<Line>,
    /// Triangles meshed.
    pub n_triangles: usize,
    /// Why (part of) it is not drawn.
    pub skipped: Option<String>,
    /// Seconds the worker spent on it.
    pub mesh_secs: f64,
    /// From the job.
    pub requested_at: Instant,
    /// The scene time it was meshed and placed at: the job's for a mesh through `snapshot`,
    /// 0 for the incremental path (which meshes nothing that reads `t` and places at 0).
    pub t_secs: f64,
    /// How it was made.
    pub kind: MeshKind,
    /// For `Renderer::patch_object`: the mesh this object's previous result carried, and the
    /// patch from it to this one's (whole for a first mesh, so that the renderer gives the
    /// buffers room for later patches).
    pub patch: Option<(Arc<Mesh>, MeshPatch)>,
}

/// What the workers keep of one implicit object between its jobs.
struct Incremental {
    /// The object the octree's blocks hold, except inside `dirty`.
    object: Object,
    world_from_group: Transform,
    depth: u8,
    bounds: Aabb,
    octree: OctreeMesher,
    /// The last mesh handed out (coloured, ambient colours included).
    mesh: Arc<Mesh>,
    appearance: CompiledAppearance,
    world_from_object: Mat4,
    material: Material,
    /// Boxes a stopped patch may have remeshed with a newer field: the next job remeshes them.
    dirty: Vec<Aabb>,
}

/// Jobs waiting, and the per-object state of objects not being meshed.
#[derive(Default)]
struct Queue {
    /// The latest job of each object (a newer one replaces it).
    jobs: BTreeMap<ObjectId, Box<MeshJob>>,
    /// Objects with a job, oldest first.
    order: VecDeque<ObjectId>,
    /// Objects a worker is meshing.
    busy: BTreeSet<ObjectId>,
    /// Objects removed while busy: their state is dropped when the worker returns it.
    gone: BTreeSet<ObjectId>,
    states: BTreeMap<ObjectId, Incremental>,
    closed: bool,
}

struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // A worker that panicked left the queue consistent (it only holds the lock briefly).
        self.queue
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Whether a newer job for `id` is waiting.
    fn superseded(&self, id: ObjectId) -> bool {
        self.lock().jobs.contains_key(&id)
    }
}

/// The workers' two ends.
pub struct Mesher {
    shared: Arc<Shared>,
    results: Receiver<Meshed>,
}

impl Drop for Mesher {
    fn drop(&mut self) {
        self.shared.lock().closed = true;
        self.shared.ready.notify_all();
    }
}

impl Mesher {
    /// Starts the workers; `wake` is called after each result (it asks the UI for a frame).
    pub fn start(wake: impl Fn() + Send + Sync + 'static) -> std::io::Result<Mesher> {
        let n_threads = std::thread::available_parallelism()
            .map_or(MESHER_THREADS_MIN, usize::from)
            .clamp(MESHER_THREADS_MIN, MESHER_THREADS_MAX);
        Mesher::with_threads(n_threads, wake)
    }

    /// Starts `n_threads` workers (at least one).
    pub fn with_threads(
        n_threads: usize,
        wake: impl Fn() + Send + Sync + 'static,
    ) -> std::io::Result<Mesher> {
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue::default()),
            ready: Condvar::new(),
        });
        let (result_tx, results) = sync_channel::<Meshed>(RESULTS_QUEUED_MAX);
        let wake: Arc<dyn Fn() + Send + Sync> = Arc::new(wake);
        for k in 0..n_threads.max(1) {
            let (shared, result_tx, wake) =
                (Arc::clone(&shared), result_tx.clone(), Arc::clone(&wake));
            std::thread::Builder::new()
                .name(format!("sculpt-mesher-{k}"))
                .spawn(move || work(&shared, &result_tx, &*wake))?;
        }
        Ok(Mesher { shared, results })
    }

    /// Queues a job, replacing the object's queued one; gives it back when the queue is full
    /// (try again next frame).
    pub fn try_send(&self, job: Box<MeshJob>) -> Result<(), Box<MeshJob>> {
        let mut queue = self.shared.lock();
        let id = job.id;
        if !queue.jobs.contains_key(&id) {
            if queue.jobs.len() >= JOBS_QUEUED_MAX {
                return Err(job);
            }
            queue.order.push_back(id);
        }
        queue.jobs.insert(id, job);
        drop(queue);
        self.shared.ready.notify_all();
        Ok(())
    }

    /// Forgets an object that left the scene (its queued job and kept state).
    pub fn forget(&self, id: ObjectId) {
        let mut queue = self.shared.lock();
        queue.jobs.remove(&id);
        queue.order.retain(|o| *o != id);
        queue.states.remove(&id);
        if queue.busy.contains(&id) {
            queue.gone.insert(id);
        }
    }

    /// A finished result, if one is waiting.
    pub fn try_recv(&self) -> Option<Meshed> {
        self.results.try_recv().ok()
    }

    /// Waits up to `timeout` for a finished result (for benchmarks and tests).
    #[allow(dead_code, reason = "used by the remesh benchmark example")]
    pub fn recv_timeout(&self, timeout: std::time::Duration) -> Option<Meshed> {
        self.results.recv_timeout(timeout).ok()
    }
}

fn work(shared: &Shared, results: &SyncSender<Meshed>, wake: &(dyn Fn() + Send + Sync)) {
    loop {
        let (job, state) = {
            let mut queue = shared.lock();
            loop {
                if queue.closed {
                    return;
                }
                let free = queue.order.iter().position(|id| !queue.busy.contains(id));
                if let Some(at) = free {
                    let Some(id) = queue.order.remove(at) else {
                        continue;
                    };
                    let Some(job) = queue.jobs.remove(&id) else {
                        continue;
                    };
                    queue.busy.insert(id);
                    let state = queue.states.remove(&id);
                    break (job, state);
                }
                queue = shared
                    .ready
                    .wait(queue)
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
            }
        };
        let id = job.id;
        let (out, state) = mesh(job, state, &|| shared.superseded(id));
        {
            let mut queue = shared.lock();
            queue.busy.remove(&id);
            if !queue.gone.remove(&id)
                && let Some(state) = state
            {
                queue.states.insert(id, state);
            }
        }
        // A job for this object may have waited for it.
        shared.ready.notify_all();
        if let Some(out) = out {
            if results.send(out).is_err() {
                return;
            }
            wake();
        }
    }
}

/// Meshes one job: patched from `state` when only edits changed, otherwise whole. `None` when
/// a newer job superseded it (`superseded` is asked before the work and between boxes).
fn mesh(
    job: Box<MeshJob>,
    state: Option<Incremental>,
    superseded: &dyn Fn() -> bool,
) -> (Option<Meshed>, Option<Incremental>) {
    if superseded() {
        return (None, state);
    }
    let start = clock::now().instant;
    let MeshJob {
        id,
        mut object,
        world_from_group,
        generation,
        depth,
        requested_at,
        t_secs,
    } = *job;
    object.prepare();
    let mut out = Meshed {
        id,
        generation,
        object: None,
        lines: Vec::new(),
        n_triangles: 0,
        skipped: None,
        mesh_secs: 0.0,
        requested_at,
        t_secs,
        kind: MeshKind::Whole,
        patch: None,
    };
    let previous = state.as_ref().map(|s| Arc::clone(&s.mesh));
    let state = match state {
        Some(state) if state.depth == depth && state.world_from_group == world_from_group => {
            match patch(state, &object, superseded) {
                Patched::Done(state, patch, kind) => {
                    out.kind = kind;
                    out.patch = patch;
                    Some(state)
                }
                Patched::Stopped(state) => return (None, Some(state)),
                Patched::Whole => None,
            }
        }
        _ => None,
    };
    let state = match state {
        Some(state) => Some(state),
        None if patchable(&object) => match mesh_whole(object, world_from_group, depth) {
            Ok((state, patch)) => {
                let base = previous.unwrap_or_default();
                out.patch = Some((base, patch));
                Some(state)
            }
            Err(reason) => {
                out.skipped = Some(reason);
                None
            }
        },
        None => {
            snapshot(id, object, world_from_group, depth, t_secs, &mut out);
            None
        }
    };
    if let Some(state) = &state {
        out.t_secs = 0.0;
        out.n_triangles = state.mesh.n_triangles();
        out.object = (out.n_triangles > 0).then(|| SceneObject {
            mesh: Arc::clone(&state.mesh),
            world_from_object: state.world_from_object,
            material: state.material,
        });
    }
    out.mesh_secs = clock::now().instant.duration_since(start).as_secs_f64();
    (Some(out), state)
}

/// Whether an object can take the incremental path: an implicit shape (what the octree meshes
/// alone), without a geometric texture (a patch reads the mesh's positions, which that moves)
/// and without force arrows (which edits move).
fn patchable(object: &Object) -> bool {
    let data = object.data();
    let implicit = data
        .geometry
        .as_ref()
        .is_some_and(|g| matches!(g.shape, Shape::Implicit(_)));
    let force = data.physics.force.as_ref().is_some_and(|f| f.enabled);
    implicit
        && data.appearance.displacement.is_none()
        && !force
        && !render::animation::object_reads_time(object)
}

enum Patched {
    Done(Incremental, Option<(Arc<Mesh>, MeshPatch)>, MeshKind),
    /// A newer job came between boxes: the state, with the boxes to remesh next time.
    Stopped(Incremental),
    /// Not an edit-only change: mesh whole.
    Whole,
}

fn is_colour_paint(edit: &CompiledEdit) -> bool {
    matches!(
        edit.edit().op,
        EditOp::Paint {
            property: Paintable::Color,
            ..
        }
    )
}

/// The edits whose activity differs between `old` and `new` (changed in a common prefix of
/// the same edits, or in the tails after it); `None` past [`PATCH_EDITS_MAX`].
fn changed_edits<'a>(old: &'a Object, new: &'a Object) -> Option<Vec<&'a CompiledEdit>> {
    let (a, b) = (old.history().entries(), new.history().entries());
    let same = |x: &HistoryEntry, y: &HistoryEntry| {
        Arc::ptr_eq(&x.edit, &y.edit) || x.edit.edit() == y.edit.edit()
    };
    let prefix = a.iter().zip(b).take_while(|(x, y)| same(x, y)).count();
    let mut changed = Vec::new();
    for (x, y) in a[..prefix].iter().zip(&b[..prefix]) {
        if x.active != y.active {
            changed.push(&*y.edit);
        }
    }
    let tails = a[prefix..].iter().chain(&b[prefix..]);
    for e in tails.filter(|e| e.active) {
        if changed.len() >= PATCH_EDITS_MAX {
            return None;
        }
        changed.push(&*e.edit);
    }
    Some(changed)
}

/// Brings `state` up to `object` by remeshing the changed edits' boxes and patching the mesh.
fn patch(mut state: Incremental, object: &Object, superseded: &dyn Fn() -> bool) -> Patched {
    if state.object.data() != object.data() || !covers(state.bounds, state.depth, object) {
        return Patched::Whole;
    }
    let Some(changed) = changed_edits(&state.object, object) else {
        return Patched::Whole;
    };
    let mut boxes = std::mem::take(&mut state.dirty);
    let mut colour_boxes = Vec::new();
    for edit in changed {
        if edit.is_geometric() {
            match dirty_boxes(edit) {
                Dirty::Boxes(b) => boxes.extend(b),
                Dirty::Everywhere => return Patched::Whole,
            }
        } else if is_colour_paint(edit) {
            colour_boxes.extend(edit.boxes().iter().filter_map(to_f32_box));
        }
    }
    if boxes.is_empty() && colour_boxes.is_empty() {
        state.object = object.clone();
        return Patched::Done(state, None, MeshKind::Unchanged);
    }
    let mut field = ObjectField::new(object, 0.0);
    for (k, b) in boxes.iter().enumerate() {
        if k > 0 && superseded() {
            // Blocks of the boxes done hold the newer field: remesh every box next time.
            state.dirty = boxes;
            return Patched::Stopped(state);
        }
        if state.octree.remesh(&mut field, *b).is_err() {
            return Patched::Whole;
        }
    }
    let mut mesh = Mesh::clone(&state.mesh);
    let ambient = std::mem::take(&mut mesh.ambient);
    let Ok(mut patch) = state.octree.mesh_update(&mut mesh) else {
        return Patched::Whole;
    };
    let mut ranges = patch.vertex_ranges.clone();
    if !colour_boxes.is_empty() {
        let inside = |p: &[f32; 3]| {
            colour_boxes
                .iter()
                .any(|b| (0..3).all(|a| b.lo[a] <= p[a] && p[a] <= b.hi[a]))
        };
        let painted = (0..mesh.n_vertices()).filter(|&i| inside(&mesh.positions[i]));
        ranges.extend(painted.map(|i| i..i + 1));
        ranges = merged(ranges);
    }
    recolour(object, &mut state.appearance, &mut mesh, &ranges, ambient);
    patch.vertex_ranges = ranges;
    let base = std::mem::replace(&mut state.mesh, Arc::new(mesh));
    state.object = object.clone();
    Patched::Done(state, Some((base, patch)), MeshKind::Patch)
}

/// Whether the octree over `grid` at `depth` still holds `object`'s bounds with
/// [`GRID_MARGIN_CELLS`] to spare: a union that reaches past that needs a larger grid, meshed
/// whole.
fn covers(grid: Aabb, depth: u8, object: &Object) -> bool {
    let Some(b) = object.bounds().as_ref().and_then(to_f32_box) else {
        return false;
    };
    let side = grid.size().into_iter().fold(0.0f32, f32::max);
    let margin = GRID_MARGIN_CELLS * side / (1u32 << depth.min(OCTREE_DEPTH_MAX)) as f32;
    (0..3).all(|a| grid.lo[a] + margin <= b.lo[a] && b.hi[a] <= grid.hi[a] - margin)
}

/// `ranges` sorted, with overlapping and touching ones joined.
fn merged(mut ranges: Vec<Range<usize>>) -> Vec<Range<usize>> {
    ranges.sort_by_key(|r| r.start);
    let mut out: Vec<Range<usize>> = Vec::with_capacity(ranges.len());
    for r in ranges {
        match out.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => out.push(r),
        }
    }
    out
}

/// Sets the colours (and ambient colours, kept in `ambient` until now) of the vertices in
/// `ranges` as `render::snapshot` colours a whole mesh: the appearance at t = 0, then painted
/// colours from the sampler.
fn recolour(
    object: &Object,
    appearance: &mut CompiledAppearance,
    mesh: &mut Mesh,
    ranges: &[Range<usize>],
    mut ambient: Vec<[f32; 3]>,
) {
    let n = mesh.n_vertices();
    let picked: Vec<usize> = ranges
        .iter()
        .flat_map(Clone::clone)
        .filter(|&i| i < n)
        .collect();
    let mut part = Mesh {
        positions: picked.iter().map(|&i| mesh.positions[i]).collect(),
        normals: picked.iter().map(|&i| mesh.normals[i]).collect(),
        ..Mesh::default()
    };
    appearance.apply(&mut part, 0.0);
    let painted = object
        .history()
        .entries()
        .iter()
        .any(|e| e.active && is_colour_paint(&e.edit));
    if painted {
        let mut sampler = object.sampler();
        for (p, c) in part.positions.iter().zip(part.colours.iter_mut()) {
            let rgb = sampler.diffuse(DVec3::from_array(p.map(f64::from)), 0.0);
            c[..3].copy_from_slice(&rgb);
        }
    }
    for (k, &i) in picked.iter().enumerate() {
        mesh.colours[i] = part.colours[k];
    }
    if part.ambient.is_empty() {
        mesh.ambient.clear();
    } else {
        ambient.resize(n, [0.0; 3]);
        for (k, &i) in picked.iter().enumerate() {
            ambient[i] = part.ambient[k];
        }
        mesh.ambient = ambient;
    }
}

/// Meshes a patchable object from scratch, keeping what later patches need.
fn mesh_whole(
    object: Object,
    world_from_group: Transform,
    depth: u8,
) -> Result<(Incremental, MeshPatch), String> {
    let bounds = mesh_bounds(&object, depth)
        .ok_or_else(|| model::object::FitError::Unbounded.to_string())?;
    let mut octree =
        OctreeMesher::new(&MeshSettings { bounds, depth }).map_err(|e| e.to_string())?;
    octree
        .remesh(&mut ObjectField::new(&object, 0.0), bounds)
        .map_err(|e| e.to_string())?;
    let mut mesh = Mesh::default();
    let patch = octree.mesh_update(&mut mesh).map_err(|e| e.to_string())?;
    let mut appearance = CompiledAppearance::of(&object);
    let everything = std::slice::from_ref(&(0..mesh.n_vertices())).to_vec();
    recolour(&object, &mut appearance, &mut mesh, &everything, Vec::new());
    let material = appearance.material(&mesh, 0.0, Material::default());
    let scene_from_object = world_from_group.then(&object.sampler().placement(0.0));
    let world_from_object =
        render_from_scene() * DMat4::from(scene_from_object.parent_from_child).as_mat4();
    let state = Incremental {
        object,
        world_from_group,
        depth,
        bounds,
        octree,
        mesh: Arc::new(mesh),
        appearance,
        world_from_object,
        material,
        dirty: Vec::new(),
    };
    Ok((state, patch))
}

/// Meshes one object through a one-object scene, so that `render::snapshot` does everything it
/// does for `sculpt render` (parametric shapes, imported meshes, textures, force arrows).
fn snapshot(
    id: ObjectId,
    object: Object,
    world_from_group: Transform,
    depth: u8,
    t_secs: f64,
    out: &mut Meshed,
) {
    let mut scene = model::scene::Scene::new();
    let settings = SnapshotSettings {
        depth,
        t_secs,
        ..SnapshotSettings::default()
    };
    let built = scene
        .insert_object(id, object, None)
        .map_err(|e| e.to_string())
        .and_then(|()| build(&scene, &settings).map_err(|e| e.to_string()));
    match built {
        Ok(built) => {
            // The group's transform, moved from the scene's +y-up space into the renderer's.
            let turn = render_from_scene();
            let group =
                turn * DMat4::from(world_from_group.parent_from_child).as_mat4() * turn.inverse();
            let place = |m: Mat4| group * m;
            out.object = built.scene.objects.into_iter().next().map(|mut o| {
                o.world_from_object = place(o.world_from_object);
                o
            });
            out.lines = built
                .scene
                .lines
                .into_iter()
                .map(|l| Line {
                    from: group.transform_point3(l.from),
                    to: group.transform_point3(l.to),
                    colour: l.colour,
                })
                .collect();
            if let Some(report) = built.objects.into_iter().next() {
                out.n_triangles = report.n_triangles;
                out.skipped = report.skipped;
            }
        }
        Err(e) => out.skipped = Some(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::object::{
        ColorDef, ColorMap, Domain, Edit, Formula, Geometry, ObjectData, PaintValue, Pose,
        ToolShape,
    };
    use std::time::Duration;

    /// The unit ball in a domain, coloured by a colour map of its height.
    fn ball() -> Object {
        let mut data = ObjectData {
            geometry: Some(Geometry::implicit_in(
                Formula::new("1-sqrt(x^2+y^2+z^2)").unwrap(),
                Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
            )),
            ..ObjectData::default()
        };
        data.appearance.diffuse = Some(ColorDef::Map {
            formula: Formula::new("y").unwrap(),
            map: ColorMap {
                keys: vec![(-1.0, [0.9, 0.1, 0.1]), (1.0, [0.1, 0.9, 0.1])],
            },
        });
        Object::new(data).unwrap()
    }

    fn job(object: &Object, generation: u64, depth: u8) -> Box<MeshJob> {
        Box::new(MeshJob {
            id: ObjectId(1),
            object: object.clone(),
            world_from_group: Transform::IDENTITY,
            generation,
            depth,
            requested_at: clock::now().instant,
            t_secs: 0.0,
        })
    }

    fn ball_tool(radius: f64) -> ToolShape {
        ToolShape::Sphere { radius }
    }

    /// Every triangle's corners (position, normal, colour), each triangle starting at its
    /// least corner, sorted: equal for meshes with the same triangles in any order.
    fn triangles(mesh: &Mesh) -> Vec<[[i64; 10]; 3]> {
        let q = |v: f32| (f64::from(v) * 1e5).round() as i64;
        let corner = |i: u32| {
            let i = i as usize;
            let (p, n, c) = (mesh.positions[i], mesh.normals[i], mesh.colours[i]);
            [p[0], p[1], p[2], n[0], n[1], n[2], c[0], c[1], c[2], c[3]].map(q)
        };
        let mut out: Vec<[[i64; 10]; 3]> = mesh
            .indices
            .chunks_exact(3)
            .map(|t| {
                let c = [corner(t[0]), corner(t[1]), corner(t[2])];
                let first = (0..3).min_by_key(|&k| c[k]).unwrap_or(0);
                [c[first], c[(first + 1) % 3], c[(first + 2) % 3]]
            })
            .collect();
        out.sort_unstable();
        out
    }

    #[test]
    fn ranges_are_sorted_and_joined() {
        assert_eq!(
            merged(vec![5..7, 0..2, 1..3, 7..9, 12..13]),
            vec![0..3, 5..9, 12..13]
        );
        assert!(merged(Vec::new()).is_empty());
    }

    /// Vertices used by a triangle of `mesh` whose colour is not what colouring the whole
    /// mesh for `object` gives.
    fn wrongly_coloured(object: &Object, mesh: &Mesh) -> usize {
        let mut appearance = CompiledAppearance::of(object);
        let mut whole = mesh.clone();
        let everything = std::slice::from_ref(&(0..mesh.n_vertices())).to_vec();
        recolour(object, &mut appearance, &mut whole, &everything, Vec::new());
        let used: BTreeSet<u32> = mesh.indices.iter().copied().collect();
        used.iter()
            .filter(|&&i| mesh.colours[i as usize] != whole.colours[i as usize])
            .count()
    }

    #[test]
    fn carves_and_colour_paintings_patch_to_the_whole_meshs_triangles_and_colours() {
        let never = || false;
        let mut object = ball();
        let (first, state) = mesh(job(&object, 1, 5), None, &never);
        let first = first.unwrap();
        assert_eq!(first.kind, MeshKind::Whole);
        assert!(first.patch.as_ref().is_some_and(|(_, p)| p.full));
        let mut state = state;
        let edits = [
            Edit::stamp(
                EditOp::Subtract,
                ball_tool(0.3),
                Pose::at(DVec3::new(0.0, 0.0, 1.0)),
            ),
            Edit::stamp(
                EditOp::Paint {
                    property: Paintable::Color,
                    value: PaintValue::Color([0.1, 0.2, 0.95]),
                },
                ball_tool(0.4),
                Pose::at(DVec3::new(1.0, 0.0, 0.0)),
            ),
            Edit::stamp(
                // Inside the domain: the meshed box stays the same.
                EditOp::Union,
                ball_tool(0.15),
                Pose::at(DVec3::new(0.0, 0.9, 0.0)),
            ),
        ];
        for (k, edit) in edits.into_iter().enumerate() {
            object.apply(edit).unwrap();
            let generation = 2 + k as u64;
            let (done, next) = mesh(job(&object, generation, 5), state, &never);
            let done = done.unwrap();
            assert_eq!(done.kind, MeshKind::Patch, "edit {k}");
            let (base, patch) = done.patch.unwrap();
            assert!(!patch.full, "edit {k}");
            let drawn = done.object.unwrap().mesh;
            // Copying the patch's ranges into the base gives the new mesh (what the renderer
            // uploads), and it has the whole mesh's triangles and colours.
            let mut copied = Mesh::clone(&base);
            copied.positions.resize(patch.n_vertices, [0.0; 3]);
            copied.normals.resize(patch.n_vertices, [0.0; 3]);
            copied.colours.resize(patch.n_vertices, [0.0; 4]);
            copied.indices.resize(3 * patch.n_triangles, 0);
            for r in &patch.vertex_ranges {
                for i in r.clone() {
                    copied.positions[i] = drawn.positions[i];
                    copied.normals[i] = drawn.normals[i];
                    copied.colours[i] = drawn.colours[i];
                }
            }
            for r in &patch.triangle_ranges {
                copied.indices[3 * r.start..3 * r.end]
                    .copy_from_slice(&drawn.indices[3 * r.start..3 * r.end]);
            }
            assert!(
                copied == *drawn,
                "edit {k}: the patch's ranges make the mesh"
            );
            // Its triangles are those the mesher assembles whole (render's invariant), and
            // every vertex a triangle uses has the colour a whole colouring gives it.
            let own = next.as_ref().unwrap().octree.mesh().unwrap();
            let white = |m: &Mesh| {
                let mut m = m.clone();
                m.colours.iter_mut().for_each(|c| *c = [1.0; 4]);
                triangles(&m)
            };
            assert!(white(&drawn) == white(&own), "edit {k}");
            assert_eq!(wrongly_coloured(&object, &drawn), 0, "edit {k}");
            state = next;
        }
        // Undoing the painting recolours its box, back to the colour map.
        let painted_before = wrongly_coloured(&object, &state.as_ref().unwrap().mesh);
        object.undo(1);
        let stale = wrongly_coloured(&object, &state.as_ref().unwrap().mesh);
        assert!(
            painted_before == 0 && stale > 20,
            "{stale} vertices were painted"
        );
        let (done, _) = mesh(job(&object, 9, 5), state, &never);
        let done = done.unwrap();
        assert_eq!(done.kind, MeshKind::Patch);
        assert_eq!(wrongly_coloured(&object, &done.object.unwrap().mesh), 0);
    }

    #[test]
    fn other_changes_mesh_whole_and_a_superseded_job_is_dropped_before_it_starts() {
        let never = || false;
        let mut object = ball();
        let (_, state) = mesh(job(&object, 1, 5), None, &never);
        // A newer job waits: this one is dropped, and the kept state is untouched.
        object
            .apply(Edit::stamp(
                EditOp::Subtract,
                ball_tool(0.3),
                Pose::at(DVec3::Z),
            ))
            .unwrap();
        let (none, state) = mesh(job(&object, 2, 5), state, &|| true);
        assert!(none.is_none() && state.is_some());
        // Another depth, then another appearance: whole.
        let (done, state) = mesh(job(&object, 3, 6), state, &never);
        assert_eq!(done.unwrap().kind, MeshKind::Whole);
        object
            .set(model::object::Field::Diffuse(Some(ColorDef::Constant([
                0.2, 0.4, 0.9,
            ]))))
            .unwrap();
        let (done, _) = mesh(job(&object, 4, 6), state, &never);
        assert_eq!(done.unwrap().kind, MeshKind::Whole);
    }

    #[test]
    fn a_long_mesh_of_one_object_does_not_hold_up_another() {
        let mesher = Mesher::with_threads(MESHER_THREADS_MIN, || {}).unwrap();
        // Object 1 at depth 8 takes seconds; object 2 at depth 4 a few milliseconds.
        let mut long = job(&ball(), 1, 8);
        long.id = ObjectId(1);
        let mut short = job(&ball(), 1, 4);
        short.id = ObjectId(2);
        assert!(mesher.try_send(long).is_ok());
        std::thread::sleep(Duration::from_millis(50));
        assert!(mesher.try_send(short).is_ok());
        let first = mesher.recv_timeout(Duration::from_secs(600)).unwrap();
        assert_eq!(first.id, ObjectId(2), "the short job came first");
        let second = mesher.recv_timeout(Duration::from_secs(600)).unwrap();
        assert_eq!(second.id, ObjectId(1));
    }
}
