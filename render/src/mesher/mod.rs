//! Meshing objects off the caller's thread, incrementally: a [`Mesher`] runs named worker
//! threads (`sculpt-mesher-N`) that take jobs (one object, as the fold left it) from a bounded
//! queue, mesh, colour and place them, and hand the drawable object back through a bounded
//! channel, calling a waker after each result.
//!
//! Incremental path (`incremental.rs`): for each implicit object the workers keep its
//! [`OctreeMesher`](crate::mesh::octree::OctreeMesher) and the mesh last handed out. A job
//! whose object differs from the last one meshed only in its edit history (edits appended,
//! undone, redone, or a stroke preview replaced by the stroke) remeshes only the boxes of the
//! edits that changed, patches the last mesh and recolours only the vertices the patch wrote
//! (and those in a changed colour painting's box) with [`snapshot`](crate::snapshot)'s own
//! colouring; the result carries the [`MeshPatch`] for
//! [`Renderer::patch_object`](crate::gpu::Renderer::patch_object). Anything else (another
//! geometry, appearance, transform, group, depth, an intersection, a grown bounding box)
//! meshes the object whole, and other shapes go through [`snapshot::build`](crate::snapshot::build)
//! as `sculpt render` draws them.
//!
//! Scheduling: at least [`MIN_MESHER_THREADS`] workers, so one object's long mesh never holds
//! up the others; a new object's first look ([`MeshJob::coarse_first`]) goes out at once and
//! its own mesh waits at the queue's end, so a session's new objects all show before any is
//! meshed whole; one object is meshed by one worker at a time (its state is checked out). A
//! newer job for an object replaces its queued one; a worker drops a job that a newer one
//! superseded before it starts, and stops a patch between its boxes when a newer job comes
//! (the octree's remesh has no cancel hook inside a box). So an object's results come in the
//! order of its jobs, and each patch starts from the mesh of the result before it.
//!
//! What it is not: it reads no clock (the caller hands in the one that times the work) and
//! knows nothing of the window that draws its results.

mod incremental;
#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use model::object::{Object, Transform};
use model::scene::ObjectId;

use crate::mesh::Mesh;
use crate::mesh::octree::MeshPatch;
use crate::scene::{Line, SceneObject};
use incremental::Incremental;

/// Most objects with a job waiting for a worker.
pub const MAX_JOBS_QUEUED: usize = 64;
/// Most results waiting for the caller.
pub const MAX_RESULTS_QUEUED: usize = 64;
/// Fewest worker threads: one object's long mesh never holds up the others.
pub const MIN_MESHER_THREADS: usize = 2;
/// Most worker threads (each may hold a whole mesh being built).
pub const MAX_MESHER_THREADS: usize = 4;
/// Most changed edits one job patches; more mesh the object whole.
pub const MAX_PATCH_EDITS: usize = 256;
/// Most threads one object's remesh runs on (see
/// [`OctreeMesher::remesh_parallel`](crate::mesh::octree::OctreeMesher::remesh_parallel)):
/// a large remesh of one object (a whole mesh, a long stroke from a peer) need not wait on
/// one core.
pub const MAX_REMESH_THREADS: usize = 8;

/// Threads one object's remesh may run on when `reserved` cores are left to other work: one
/// per core but those, at least one, at most [`MAX_REMESH_THREADS`]. A command line
/// reserves none; the mesher's jobs reserve one, which the window that shows their meshes
/// needs to draw them (on two cores a job then meshes on one thread: two windows on one such
/// machine, each meshing a peer's new object on both cores, drew it about 15 ms later than
/// with one thread each).
pub fn remesh_threads(reserved: usize) -> usize {
    // Asked once per process: on Linux the answer reads the cgroup files, and every mesh
    // job asks.
    static CORES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    let cores = *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, usize::from));
    cores.saturating_sub(reserved).clamp(1, MAX_REMESH_THREADS)
}

/// Cores meshing beside a window leaves to it (see [`remesh_threads`]).
pub const WINDOW_CORES: usize = 1;

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
    /// When the change that asked for it was made (handed back with the result, for
    /// edit-to-mesh times).
    pub requested_at: Instant,
    /// The scene time to mesh at (shapes, colours and fields that read `t`).
    pub t_secs: f64,
    /// When the object has no mesh kept (its first job, on the incremental path), hand out
    /// a first look [`COARSE_DEPTH_STEP`] levels shallower before the mesh at `depth`: a new
    /// object shows in a small part of its whole mesh's time, then sharpens.
    pub coarse_first: bool,
}

/// Levels a first look ([`MeshJob::coarse_first`]) is shallower than its job: a sixteenth of
/// the surface's cells, so about that part of the time.
pub const COARSE_DEPTH_STEP: u8 = 2;
/// Jobs shallower than this mesh no first look (their whole mesh is quick already).
pub const MIN_COARSE_FIRST_DEPTH: u8 = 6;

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
    /// The name a state dump uses.
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
    /// For [`Renderer::patch_object`](crate::gpu::Renderer::patch_object): the mesh this
    /// object's previous result carried, and the patch from it to this one's (whole for a
    /// first mesh, so that the renderer gives the buffers room for later patches).
    pub patch: Option<(Arc<Mesh>, MeshPatch)>,
    /// A first look at a shallower depth ([`MeshJob::coarse_first`]): the job's own result
    /// follows, with the same generation, unless a newer job supersedes it.
    pub coarse: bool,
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
    spares: Spares,
}

/// Most meshes kept to write patches into ([`Spares`]): about one out and one drawn for each
/// of two objects patched in turn.
pub const MAX_SPARE_MESHES: usize = 4;

/// Meshes handed out before the last of their objects, which a later patch of any object is
/// written into once nobody else holds them (the window has drawn their successors): writing
/// into fresh buffers made the kernel map and zero them page by page, more than half of a
/// small stroke's patch.
#[derive(Default)]
pub(super) struct Spares(Mutex<VecDeque<Arc<Mesh>>>);

impl Spares {
    fn lock(&self) -> MutexGuard<'_, VecDeque<Arc<Mesh>>> {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A kept mesh nobody else holds, to overwrite.
    pub(super) fn take(&self) -> Option<Mesh> {
        let mut spares = self.lock();
        for _ in 0..spares.len() {
            match Arc::try_unwrap(spares.pop_front()?) {
                Ok(mesh) => return Some(mesh),
                Err(held) => spares.push_back(held),
            }
        }
        None
    }

    /// Keeps `mesh` (a patch's base), dropping the oldest beyond [`MAX_SPARE_MESHES`].
    pub(super) fn give(&self, mesh: Arc<Mesh>) {
        let mut spares = self.lock();
        spares.push_back(mesh);
        while spares.len() > MAX_SPARE_MESHES {
            spares.pop_front();
        }
    }
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

    /// Waits for a job of an object no worker is meshing and checks it out with the object's
    /// kept state; `None` once the mesher is dropped.
    fn next_job(&self) -> Option<(Box<MeshJob>, Option<Incremental>)> {
        let mut queue = self.lock();
        loop {
            if queue.closed {
                return None;
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
                return Some((job, state));
            }
            queue = self
                .ready
                .wait(queue)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }

    /// Checks an object's state back in with its job queued again at the end, unless a
    /// newer job replaced it meanwhile (or the object was forgotten). Only a worker's job
    /// comes back so, so the queue holds at most [`MAX_JOBS_QUEUED`] and one a worker.
    fn requeue(&self, job: Box<MeshJob>, state: Option<Incremental>) {
        let id = job.id;
        {
            let mut queue = self.lock();
            if !queue.jobs.contains_key(&id) && !queue.gone.contains(&id) {
                queue.order.push_back(id);
                queue.jobs.insert(id, job);
            }
        }
        self.done(id, state);
    }

    /// Checks an object's state back in (dropped if the object was forgotten meanwhile).
    fn done(&self, id: ObjectId, state: Option<Incremental>) {
        {
            let mut queue = self.lock();
            queue.busy.remove(&id);
            if !queue.gone.remove(&id)
                && let Some(state) = state
            {
                queue.states.insert(id, state);
            }
        }
        // A job for this object may have waited for it.
        self.ready.notify_all();
    }
}

/// The worker pool's two ends: jobs in, results out. Dropping it stops the workers (each
/// after its current job).
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
    /// Starts a worker per core, within [`MIN_MESHER_THREADS`] and [`MAX_MESHER_THREADS`].
    /// `now` reads the clock that times each job ([`Meshed::mesh_secs`]); `wake` is called
    /// after each result (it asks the UI for a frame).
    pub fn start(
        now: fn() -> Instant,
        wake: impl Fn() + Send + Sync + 'static,
    ) -> std::io::Result<Mesher> {
        let n_threads = std::thread::available_parallelism()
            .map_or(MIN_MESHER_THREADS, usize::from)
            .clamp(MIN_MESHER_THREADS, MAX_MESHER_THREADS);
        Mesher::with_threads(n_threads, now, wake)
    }

    /// Starts `n_threads` workers (at least one); see [`Mesher::start`].
    pub fn with_threads(
        n_threads: usize,
        now: fn() -> Instant,
        wake: impl Fn() + Send + Sync + 'static,
    ) -> std::io::Result<Mesher> {
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue::default()),
            ready: Condvar::new(),
            spares: Spares::default(),
        });
        let (result_tx, results) = sync_channel::<Meshed>(MAX_RESULTS_QUEUED);
        let wake: Arc<dyn Fn() + Send + Sync> = Arc::new(wake);
        for k in 0..n_threads.max(1) {
            let (shared, result_tx, wake) =
                (Arc::clone(&shared), result_tx.clone(), Arc::clone(&wake));
            std::thread::Builder::new()
                .name(format!("sculpt-mesher-{k}"))
                .spawn(move || work(&shared, &result_tx, now, &*wake))?;
        }
        Ok(Mesher { shared, results })
    }

    /// Queues a job, replacing the object's queued one; gives it back when the queue is full
    /// (try again later).
    pub fn try_send(&self, job: Box<MeshJob>) -> Result<(), Box<MeshJob>> {
        let mut queue = self.shared.lock();
        let id = job.id;
        if !queue.jobs.contains_key(&id) {
            if queue.jobs.len() >= MAX_JOBS_QUEUED {
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

    /// Waits up to `timeout` for a finished result.
    pub fn recv_timeout(&self, timeout: Duration) -> Option<Meshed> {
        self.results.recv_timeout(timeout).ok()
    }
}

/// A worker: meshes jobs until the mesher is dropped or nobody takes results any more.
fn work(
    shared: &Shared,
    results: &SyncSender<Meshed>,
    now: fn() -> Instant,
    wake: &(dyn Fn() + Send + Sync),
) {
    // Hands a result out; false once nobody takes them.
    let deliver = |mut out: Meshed, start: Instant| {
        out.mesh_secs = now().duration_since(start).as_secs_f64();
        let picked = (out.object.as_ref()).map(|o| (o.pick_runs.clone(), Arc::clone(&o.mesh)));
        if results.send(out).is_err() {
            return false;
        }
        wake();
        if let Some((runs, mesh)) = picked {
            runs.prepare(&mesh);
        }
        true
    };
    while let Some((job, state)) = shared.next_job() {
        let id = job.id;
        let superseded = || shared.superseded(id);
        if state.is_none() && wants_a_first_look(&job) {
            let start = now();
            let (out, coarse) =
                incremental::mesh(first_look(&job), None, &superseded, &shared.spares);
            let delivered = out.is_none_or(|mut out| {
                out.coarse = true;
                deliver(out, start)
            });
            // The job's own mesh waits behind the jobs queued meanwhile, from the first
            // look's state: a session's new objects all show a first look before any is
            // meshed whole. Without a state (the first look could not be meshed) it goes now.
            if coarse.is_some() {
                shared.requeue(job, coarse);
                if !delivered {
                    return;
                }
                continue;
            }
            if !delivered {
                shared.done(id, None);
                return;
            }
        }
        let start = now();
        let (out, state) = incremental::mesh(job, state, &superseded, &shared.spares);
        shared.done(id, state);
        if let Some(out) = out
            && !deliver(out, start)
        {
            return;
        }
    }
}

/// Whether `job` meshes a first look before its own mesh (asked, deep enough, and on the
/// incremental path, whose kept state the first look starts).
fn wants_a_first_look(job: &MeshJob) -> bool {
    job.coarse_first && job.depth >= MIN_COARSE_FIRST_DEPTH && incremental::patchable(&job.object)
}

/// The job of `job`'s first look: the same object, [`COARSE_DEPTH_STEP`] levels shallower.
fn first_look(job: &MeshJob) -> Box<MeshJob> {
    Box::new(MeshJob {
        id: job.id,
        object: job.object.clone(),
        world_from_group: job.world_from_group,
        generation: job.generation,
        depth: job.depth - COARSE_DEPTH_STEP,
        requested_at: job.requested_at,
        t_secs: job.t_secs,
        coarse_first: false,
    })
}
