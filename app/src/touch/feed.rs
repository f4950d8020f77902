//! The live scene to the servo: the engine's per-object changes become haptic snapshots.
//!
//! A [`Snapshotter`] reads `View::changes_since(cursor)` and copies out only the objects
//! named (all of them when the view says everything may have changed: a group edit, or a
//! cursor older than the view keeps). Each copy is prepared off the view's lock (its edit
//! history indexed) and kept behind an `Arc`; unchanged objects keep theirs, so an edit
//! costs the preparation of its own object, never of the whole scene. A snapshot is then
//! one `ObjectContainer` per object over those shared, prepared objects (each container
//! only adds its sampler's scratch space).
//!
//! Other peers' touch tools with a tangible body ([`super::body::ToolBody`], in their
//! presence) join the snapshot as balls at their tool points, with container ids from
//! [`REMOTE_TOOL_ID_BASE`] on; a snapshot is built again when they move or change, and they
//! cost only their own small objects.
//!
//! A [`Feed`] runs a snapshotter on the `sculpt-haptic-feed` thread and publishes each
//! snapshot through the haptic crate's lock-free handoff (`haptic::handoff`): the servo
//! takes it at its next tick by one atomic swap and never waits, and the snapshots it
//! retires are freed here, on the feed's thread. The feed wakes when its [`Feed::waker`] is
//! called (chain it into the engine view's waker) and looks at least every
//! [`FEED_POLL_MILLIS`] anyway.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::Duration;

use haptic::container::object::ObjectContainer;
use haptic::handoff::Publisher;
use model::object::{Object, Sampler, Transform};
use model::scene::ObjectId;

use crate::engine::{SharedView, lock};

/// The feed looks at the view at least this often, even when nobody wakes it.
pub const FEED_POLL_MILLIS: u64 = 100;

/// What the servo renders on the live scene: one container per object, in id order, then
/// other peers' tangible tools.
pub type LiveScene = Vec<ObjectContainer>;

/// The container id of the first remote peer's tool (in peer id order), the next one's one
/// more: above every object id (objects take 63 bits).
pub const REMOTE_TOOL_ID_BASE: u64 = 1 << 63;

/// Most remote tools felt at once (the nearest are not chosen: the first peers by id).
pub const MAX_REMOTE_TOOLS: usize = 16;

/// A remote peer's tangible tool: where (scene coordinates) and its body.
type RemoteTool = (replication::PeerId, glam::DVec3, super::body::ToolBody);

/// An object copied out of the view and prepared for sampling.
struct Prepared {
    object: Arc<Object>,
    world_from_group: Transform,
}

/// One snapshot and what building it took.
pub struct Built {
    /// The snapshot.
    pub scene: LiveScene,
    /// Objects copied out and prepared again for it (the others were reused).
    pub n_rebuilt: usize,
    /// Objects that cannot be felt (a degenerate placement), with why.
    pub refused: Vec<(ObjectId, String)>,
}

/// Builds haptic snapshots of a view's scene, object by object as they change.
#[derive(Default)]
pub struct Snapshotter {
    cursor: u64,
    prepared: BTreeMap<ObjectId, Prepared>,
    /// The remote tools in the last snapshot.
    tools: Vec<RemoteTool>,
}

impl Snapshotter {
    /// A snapshotter that has seen nothing (its first update takes every object).
    pub fn new() -> Snapshotter {
        Snapshotter::default()
    }

    /// A new snapshot when objects changed since the last call, else `None`. The view is
    /// locked only to read what changed and to copy those objects.
    pub fn update(&mut self, view: &SharedView) -> Option<Built> {
        let (copies, tools) = self.copy_changed(view);
        if copies.is_none() && tools == self.tools {
            return None;
        }
        let copies = copies.unwrap_or_default();
        let n_rebuilt = copies.iter().filter(|(_, copy)| copy.is_some()).count();
        for (id, copy) in copies {
            match copy {
                Some((mut object, world_from_group)) => {
                    object.prepare();
                    let object = Arc::new(object);
                    self.prepared.insert(
                        id,
                        Prepared {
                            object,
                            world_from_group,
                        },
                    );
                }
                None => {
                    self.prepared.remove(&id);
                }
            }
        }
        let mut scene = Vec::with_capacity(self.prepared.len());
        let mut refused = Vec::new();
        // Objects without physics are seen, not felt (`Object::is_tangible`).
        for (id, p) in self.prepared.iter().filter(|(_, p)| p.object.is_tangible()) {
            let sampler = Sampler::new(Arc::clone(&p.object));
            match ObjectContainer::new(id.0, sampler, p.world_from_group) {
                Ok(container) => scene.push(container),
                Err(e) => refused.push((*id, e.to_string())),
            }
        }
        for ((_, at, body), n) in tools.iter().zip(0u64..) {
            let Some(mut object) = body.object(*at) else {
                continue;
            };
            object.prepare();
            let sampler = Sampler::new(Arc::new(object));
            if let Ok(c) =
                ObjectContainer::new(REMOTE_TOOL_ID_BASE + n, sampler, Transform::IDENTITY)
            {
                scene.push(c);
            }
        }
        self.tools = tools;
        Some(Built {
            scene,
            n_rebuilt,
            refused,
        })
    }

    /// Under the view's lock: the changed objects' copies (`None` for one that is gone; no
    /// list when nothing changed), and the remote tangible tools.
    #[expect(
        clippy::type_complexity,
        reason = "a local list of (id, copy or gone) pairs"
    )]
    fn copy_changed(
        &mut self,
        view: &SharedView,
    ) -> (
        Option<Vec<(ObjectId, Option<(Object, Transform)>)>>,
        Vec<RemoteTool>,
    ) {
        let view = lock(view);
        let scene_from_render = render::snapshot::render_from_scene().inverse();
        let tools: Vec<RemoteTool> = view
            .presence()
            .iter()
            .filter_map(|(peer, p)| {
                let body = super::body::ToolBody::from_wire(p.tool_body?)?;
                let at = scene_from_render.transform_point3(glam::Vec3::from_array(p.tool?));
                body.is_tangible().then_some((*peer, at.as_dvec3(), body))
            })
            .take(MAX_REMOTE_TOOLS)
            .collect();
        let (changes, cursor) = view.changes_since(self.cursor);
        self.cursor = cursor;
        let scene = view.scene();
        let ids: Vec<ObjectId> = match changes {
            Some(ids) if ids.is_empty() => return (None, tools),
            Some(ids) => ids.into_iter().collect(),
            // Everything may have changed: every object of the scene, and every one kept
            // (to drop those that are gone).
            None => {
                let mut all: Vec<ObjectId> = scene.objects().map(|(id, _)| id).collect();
                all.extend(self.prepared.keys().copied());
                all.sort_unstable();
                all.dedup();
                all
            }
        };
        let copies = ids
            .into_iter()
            .map(|id| {
                let copy = scene
                    .scene_object(id)
                    .map(|entry| (entry.object.clone(), scene.world_from_group(entry.group)));
                (id, copy)
            })
            .collect();
        (Some(copies), tools)
    }
}

/// What a feed has done, for display and measurement.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FeedStats {
    /// Snapshots published.
    pub n_snapshots: u64,
    /// Objects prepared again, over all snapshots.
    pub n_rebuilt: u64,
    /// Objects in the last snapshot.
    pub n_objects: u64,
    /// Time from the wake (or poll) to the last snapshot's publication, microseconds.
    pub last_build_micros: u64,
}

#[derive(Default)]
struct SharedStats {
    n_snapshots: AtomicU64,
    n_rebuilt: AtomicU64,
    n_objects: AtomicU64,
    last_build_micros: AtomicU64,
}

/// The `sculpt-haptic-feed` thread: snapshots of a view, published to a servo.
pub struct Feed {
    wake: SyncSender<()>,
    running: Arc<AtomicBool>,
    stats: Arc<SharedStats>,
    thread: JoinHandle<()>,
}

impl Feed {
    /// Starts the feed of `view` into `scenes` (a servo's `ServoLink::scenes`). The first
    /// snapshot (every object) is built at once.
    pub fn spawn(view: SharedView, scenes: Publisher<LiveScene>) -> std::io::Result<Feed> {
        // One pending wake is enough: the feed reads everything that changed when it runs.
        let (wake, woken) = std::sync::mpsc::sync_channel(1);
        let running = Arc::new(AtomicBool::new(true));
        let stats = Arc::new(SharedStats::default());
        let worker = Worker {
            view,
            scenes,
            woken,
            running: Arc::clone(&running),
            stats: Arc::clone(&stats),
        };
        let thread = std::thread::Builder::new()
            .name("sculpt-haptic-feed".into())
            .spawn(move || worker.run())?;
        Ok(Feed {
            wake,
            running,
            stats,
            thread,
        })
    }

    /// A function that wakes the feed without blocking (call it from the view's waker: it
    /// runs on the engine thread under the view's lock, so it only signals).
    pub fn waker(&self) -> impl Fn() + Send + 'static {
        let wake = self.wake.clone();
        move || wake_up(&wake)
    }

    /// What the feed has done so far.
    pub fn stats(&self) -> FeedStats {
        let s = &self.stats;
        FeedStats {
            n_snapshots: s.n_snapshots.load(Ordering::Acquire),
            n_rebuilt: s.n_rebuilt.load(Ordering::Acquire),
            n_objects: s.n_objects.load(Ordering::Acquire),
            last_build_micros: s.last_build_micros.load(Ordering::Acquire),
        }
    }

    /// Stops the thread and waits for it.
    pub fn stop(self) {
        self.running.store(false, Ordering::Release);
        wake_up(&self.wake);
        if self.thread.join().is_err() {
            log::error!("the haptic feed thread panicked");
        }
    }
}

fn wake_up(wake: &SyncSender<()>) {
    match wake.try_send(()) {
        // Full: a wake is already pending. Disconnected: the feed has stopped.
        Ok(()) | Err(TrySendError::Full(())) | Err(TrySendError::Disconnected(())) => {}
    }
}

struct Worker {
    view: SharedView,
    scenes: Publisher<LiveScene>,
    woken: Receiver<()>,
    running: Arc<AtomicBool>,
    stats: Arc<SharedStats>,
}

impl Worker {
    fn run(self) {
        let mut snapshotter = Snapshotter::new();
        let mut refused_shown: Vec<(ObjectId, String)> = Vec::new();
        let poll = Duration::from_millis(FEED_POLL_MILLIS);
        while self.running.load(Ordering::Acquire) {
            let started = crate::clock::now().instant;
            // Snapshots the servo retired are freed here, never on the servo's thread.
            self.scenes.collect_retired();
            if let Some(built) = snapshotter.update(&self.view) {
                if built.refused != refused_shown {
                    for (id, why) in &built.refused {
                        log::warn!("object {} cannot be felt: {why}", id.0);
                    }
                    refused_shown = built.refused;
                }
                let n_objects = built.scene.len() as u64;
                self.scenes.publish(Box::new(built.scene));
                let micros = crate::clock::now()
                    .instant
                    .duration_since(started)
                    .as_micros();
                let s = &self.stats;
                s.last_build_micros
                    .store(u64::try_from(micros).unwrap_or(u64::MAX), Ordering::Release);
                s.n_objects.store(n_objects, Ordering::Release);
                s.n_rebuilt
                    .fetch_add(built.n_rebuilt as u64, Ordering::AcqRel);
                s.n_snapshots.fetch_add(1, Ordering::AcqRel);
            }
            match self.woken.recv_timeout(poll) {
                Ok(()) | Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
        }
    }
}
