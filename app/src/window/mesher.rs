//! Meshing off the UI thread: a named worker thread takes jobs (one object, as the fold left
//! it) from a bounded channel, meshes, colours and places it with `render::snapshot::build`,
//! and hands the drawable object back through a second bounded channel, waking the UI.
//!
//! Jobs for the same object that queue up while the worker is busy are coalesced: only the
//! latest is meshed. Each result carries the job's generation, so the UI drops results that
//! an edit made since has outdated.

use std::collections::BTreeMap;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::time::Instant;

use fdsl::object::{Object, Transform};
use fdsl::scene::ObjectId;
use glam::{DMat4, Mat4};
use render::scene::{Line, SceneObject};
use render::snapshot::{SnapshotSettings, build, render_from_scene};

use ::app::clock;

/// Most jobs waiting for the worker.
pub const JOBS_QUEUED_MAX: usize = 64;
/// Most results waiting for the UI.
pub const RESULTS_QUEUED_MAX: usize = 64;

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
}

/// The worker thread's two ends.
pub struct Mesher {
    jobs: SyncSender<Box<MeshJob>>,
    results: Receiver<Meshed>,
}

impl Mesher {
    /// Starts the worker; `wake` is called after each result (it asks the UI for a frame).
    pub fn start(wake: impl Fn() + Send + 'static) -> std::io::Result<Mesher> {
        let (jobs, job_rx) = sync_channel::<Box<MeshJob>>(JOBS_QUEUED_MAX);
        let (result_tx, results) = sync_channel::<Meshed>(RESULTS_QUEUED_MAX);
        std::thread::Builder::new()
            .name("sculpt-mesher".into())
            .spawn(move || work(&job_rx, &result_tx, &wake))?;
        Ok(Mesher { jobs, results })
    }

    /// Queues a job; gives it back when the queue is full (try again next frame).
    pub fn try_send(&self, job: Box<MeshJob>) -> Result<(), Box<MeshJob>> {
        match self.jobs.try_send(job) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(job) | TrySendError::Disconnected(job)) => Err(job),
        }
    }

    /// A finished result, if one is waiting.
    pub fn try_recv(&self) -> Option<Meshed> {
        self.results.try_recv().ok()
    }
}

fn work(jobs: &Receiver<Box<MeshJob>>, results: &SyncSender<Meshed>, wake: &dyn Fn()) {
    // Ends when the UI drops its sender.
    while let Ok(first) = jobs.recv() {
        let mut latest = BTreeMap::new();
        latest.insert(first.id, first);
        while let Ok(more) = jobs.try_recv() {
            latest.insert(more.id, more);
        }
        for job in latest.into_values() {
            if results.send(mesh(job)).is_err() {
                return;
            }
            wake();
        }
    }
}

/// Meshes one object through a one-object scene, so that `render::snapshot` does everything it
/// does for `sculpt render` (implicit and parametric shapes, edits, painted colours, arrows).
fn mesh(job: Box<MeshJob>) -> Meshed {
    let start = clock::now().instant;
    let MeshJob {
        id,
        mut object,
        world_from_group,
        generation,
        depth,
        requested_at,
    } = *job;
    object.prepare();
    let mut scene = fdsl::scene::Scene::new();
    let settings = SnapshotSettings {
        depth,
        ..SnapshotSettings::default()
    };
    let built = scene
        .insert_object(id, object, None)
        .map_err(|e| e.to_string())
        .and_then(|()| build(&scene, &settings).map_err(|e| e.to_string()));
    let mut out = Meshed {
        id,
        generation,
        object: None,
        lines: Vec::new(),
        n_triangles: 0,
        skipped: None,
        mesh_secs: 0.0,
        requested_at,
    };
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
    out.mesh_secs = clock::now().instant.duration_since(start).as_secs_f64();
    out
}
