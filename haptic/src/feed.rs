//! The live scene to the servo: a scene that changes object by object (the app's session,
//! edited by peers) becomes haptic snapshots, each rebuilding only the objects that changed.
//!
//! The scene's owner implements [`SceneSource`] (the app's engine view): the scene itself,
//! which objects changed since a consumer's cursor (or that every object may have), and the
//! tangible bodies felt beside the scene's objects (other peers' touch tools,
//! [`RemoteTool`], which the owner reads from their presence). A [`Snapshotter`] reads it
//! under the owner's lock and copies out only the objects named (all of them when every
//! object may have changed: a group edit, or a cursor older than the owner keeps). Each copy
//! is prepared off the lock (its edit history indexed) and kept behind an `Arc`; unchanged
//! objects keep theirs, so an edit costs the preparation of its own object, never of the
//! whole scene. A [`Snapshot`] is then one [`ObjectContainer`] per tangible object over those
//! shared, prepared objects (each container only adds its sampler's scratch space), then the
//! remote tools, at most [`MAX_REMOTE_TOOLS`], with container ids from
//! [`REMOTE_TOOL_ID_BASE`] on; a snapshot is built again when the tools move or change, and
//! they cost only their own small objects.
//!
//! A [`Feed`] runs a snapshotter on the `sculpt-haptic-feed` thread and publishes each
//! snapshot through the lock-free [`crate::handoff`]: the servo takes it at its next tick by
//! one atomic swap and never waits, and the snapshots it retires are freed here, on the
//! feed's thread. The feed wakes when its [`Feed::waker`] is called (chain it into the
//! owner's change notification) and looks at least every [`FEED_POLL_MILLIS`] anyway.

mod snapshotter;
#[cfg(test)]
mod tests;

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use model::object::Object;
use model::scene::{ObjectId, Scene};

use crate::container::object::{ObjectContainer, ObjectContainerError};
use crate::handoff::Publisher;

pub use snapshotter::Snapshotter;

/// The feed looks at the scene at least this often, even when nobody wakes it.
pub const FEED_POLL_MILLIS: u64 = 100;

/// The container id of the first remote tool (in the order the source lists them), the next
/// one's one more: above every object id (objects take 63 bits).
pub const REMOTE_TOOL_ID_BASE: u64 = 1 << 63;

/// Most remote tools felt at once (the nearest are not chosen: the first the source lists).
pub const MAX_REMOTE_TOOLS: usize = 16;

/// What the servo renders on the live scene: one container per tangible object, in id
/// order, then the remote tools.
pub type Snapshot = Vec<ObjectContainer>;

/// A live scene as the feed reads it, under its owner's lock (see the module documentation).
pub trait SceneSource {
    /// Another peer's tool as the owner describes it.
    type Tool: RemoteTool;

    /// The scene.
    fn scene(&self) -> &Scene;

    /// What changed since `cursor` (0 at first): the objects, or `None` when every object
    /// may have changed, and the cursor to ask from next time.
    fn changes_since(&self, cursor: u64) -> (Option<BTreeSet<ObjectId>>, u64);

    /// The tangible tools felt beside the scene's objects, in a stable order (the feed takes
    /// the first [`MAX_REMOTE_TOOLS`]).
    fn remote_tools(&self) -> Vec<Self::Tool>;
}

/// A tangible body felt beside the scene's objects (another peer's touch tool): compared
/// with the last snapshot's to decide whether to build again, and built into an object off
/// the owner's lock.
pub trait RemoteTool: PartialEq + Send {
    /// The body as an object placed in the scene's world, or `None` when it cannot be made
    /// (it is then left out).
    fn object(&self) -> Option<Object>;
}

/// One snapshot and what building it took.
pub struct Built {
    /// The snapshot.
    pub scene: Snapshot,
    /// Objects copied out and prepared again for it (the others were reused).
    pub n_rebuilt: usize,
    /// Objects that cannot be felt (a degenerate placement, formulas too costly), with why.
    pub refused: Vec<(ObjectId, ObjectContainerError)>,
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

/// [`FeedStats`] as the feed's thread writes them.
#[derive(Default)]
struct Counters {
    n_snapshots: AtomicU64,
    n_rebuilt: AtomicU64,
    n_objects: AtomicU64,
    last_build_micros: AtomicU64,
}

/// The `sculpt-haptic-feed` thread: snapshots of a live scene, published to a servo.
pub struct Feed {
    wake: SyncSender<()>,
    running: Arc<AtomicBool>,
    counters: Arc<Counters>,
    thread: JoinHandle<()>,
}

impl Feed {
    /// Starts the feed of `source` into `scenes` (a servo's `ServoLink::scenes`). The first
    /// snapshot (every object) is built at once.
    pub fn spawn<S>(source: Arc<Mutex<S>>, scenes: Publisher<Snapshot>) -> std::io::Result<Feed>
    where
        S: SceneSource + Send + 'static,
    {
        // One pending wake is enough: the feed reads everything that changed when it runs.
        let (wake, woken) = std::sync::mpsc::sync_channel(1);
        let running = Arc::new(AtomicBool::new(true));
        let counters = Arc::new(Counters::default());
        let worker = Worker {
            source,
            scenes,
            woken,
            running: Arc::clone(&running),
            counters: Arc::clone(&counters),
        };
        let thread = std::thread::Builder::new()
            .name("sculpt-haptic-feed".into())
            .spawn(move || worker.run())?;
        Ok(Feed {
            wake,
            running,
            counters,
            thread,
        })
    }

    /// A function that wakes the feed without blocking (call it from the owner's change
    /// notification, which may run under the owner's lock: it only signals).
    pub fn waker(&self) -> impl Fn() + Send + 'static {
        let wake = self.wake.clone();
        move || wake_up(&wake)
    }

    /// What the feed has done so far.
    pub fn stats(&self) -> FeedStats {
        let c = &self.counters;
        FeedStats {
            n_snapshots: c.n_snapshots.load(Ordering::Acquire),
            n_rebuilt: c.n_rebuilt.load(Ordering::Acquire),
            n_objects: c.n_objects.load(Ordering::Acquire),
            last_build_micros: c.last_build_micros.load(Ordering::Acquire),
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

struct Worker<S: SceneSource> {
    source: Arc<Mutex<S>>,
    scenes: Publisher<Snapshot>,
    woken: Receiver<()>,
    running: Arc<AtomicBool>,
    counters: Arc<Counters>,
}

impl<S: SceneSource> Worker<S> {
    fn run(self) {
        let mut snapshotter = Snapshotter::new();
        let mut refused_shown: Vec<(ObjectId, ObjectContainerError)> = Vec::new();
        let poll = Duration::from_millis(FEED_POLL_MILLIS);
        while self.running.load(Ordering::Acquire) {
            let started = crate::servo::monotonic_now();
            // Snapshots the servo retired are freed here, never on the servo's thread.
            self.scenes.collect_retired();
            if let Some(built) = snapshotter.update(&self.source) {
                if built.refused != refused_shown {
                    for (id, why) in &built.refused {
                        log::warn!("object {} cannot be felt: {why}", id.0);
                    }
                    refused_shown = built.refused;
                }
                let n_objects = built.scene.len() as u64;
                self.scenes.publish(Box::new(built.scene));
                let micros = crate::servo::monotonic_now()
                    .duration_since(started)
                    .as_micros();
                let c = &self.counters;
                c.last_build_micros
                    .store(u64::try_from(micros).unwrap_or(u64::MAX), Ordering::Release);
                c.n_objects.store(n_objects, Ordering::Release);
                c.n_rebuilt
                    .fetch_add(built.n_rebuilt as u64, Ordering::AcqRel);
                c.n_snapshots.fetch_add(1, Ordering::AcqRel);
            }
            match self.woken.recv_timeout(poll) {
                Ok(()) | Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
        }
    }
}
