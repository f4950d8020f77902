//! [`Snapshotter`]: haptic snapshots of a [`SceneSource`], object by object as they change.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use model::object::{Object, Sampler, Transform};
use model::scene::ObjectId;

use super::{Built, MAX_REMOTE_TOOLS, REMOTE_TOOL_ID_BASE, RemoteTool, SceneSource, Snapshot};
use crate::container::object::ObjectContainer;

/// An object copied out of the source and prepared for sampling.
struct Prepared {
    object: Arc<Object>,
    world_from_group: Transform,
}

/// One object as the source held it when copied: the object and its groups' placement, or
/// `None` when it is gone.
type ObjectCopy = (ObjectId, Option<(Object, Transform)>);

/// Builds haptic snapshots of a source's scene, object by object as they change.
pub struct Snapshotter<T> {
    cursor: u64,
    prepared: BTreeMap<ObjectId, Prepared>,
    /// The remote tools in the last snapshot.
    tools: Vec<T>,
}

impl<T: RemoteTool> Default for Snapshotter<T> {
    fn default() -> Self {
        Snapshotter {
            cursor: 0,
            prepared: BTreeMap::new(),
            tools: Vec::new(),
        }
    }
}

impl<T: RemoteTool> Snapshotter<T> {
    /// A snapshotter that has seen nothing (its first update takes every object).
    pub fn new() -> Snapshotter<T> {
        Snapshotter::default()
    }

    /// A new snapshot when objects or remote tools changed since the last call, else `None`.
    /// The source is locked only to read what changed and to copy those objects; they are
    /// prepared and the snapshot built after.
    pub fn update<S>(&mut self, source: &Mutex<S>) -> Option<Built>
    where
        S: SceneSource<Tool = T>,
    {
        let (copies, tools) = self.copy_changed(&*lock(source));
        if copies.is_none() && tools == self.tools {
            return None;
        }
        let copies = copies.unwrap_or_default();
        let n_rebuilt = copies.iter().filter(|(_, copy)| copy.is_some()).count();
        self.prepare(copies);
        let (mut scene, refused) = self.object_containers();
        scene.extend(tool_containers(&tools));
        self.tools = tools;
        Some(Built {
            scene,
            n_rebuilt,
            refused,
        })
    }

    /// Under the source's lock: the changed objects' copies (no list when nothing changed),
    /// and the remote tangible tools.
    fn copy_changed<S>(&mut self, source: &S) -> (Option<Vec<ObjectCopy>>, Vec<T>)
    where
        S: SceneSource<Tool = T>,
    {
        let mut tools = source.remote_tools();
        tools.truncate(MAX_REMOTE_TOOLS);
        let (changes, cursor) = source.changes_since(self.cursor);
        self.cursor = cursor;
        let scene = source.scene();
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

    /// Off the lock: prepares each copy and keeps it, and forgets the objects gone.
    fn prepare(&mut self, copies: Vec<ObjectCopy>) {
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
    }

    /// A container per tangible prepared object, in id order, and the objects refused.
    fn object_containers(&self) -> (Snapshot, Vec<(ObjectId, super::ObjectContainerError)>) {
        let mut scene = Vec::with_capacity(self.prepared.len());
        let mut refused = Vec::new();
        // Objects without physics are seen, not felt (`Object::is_tangible`).
        for (id, p) in self.prepared.iter().filter(|(_, p)| p.object.is_tangible()) {
            let sampler = Sampler::new(Arc::clone(&p.object));
            match ObjectContainer::new(id.0, sampler, p.world_from_group) {
                Ok(container) => scene.push(container),
                Err(e) => refused.push((*id, e)),
            }
        }
        (scene, refused)
    }
}

/// The remote tools' containers, ids from [`REMOTE_TOOL_ID_BASE`] by their place in `tools`;
/// a tool that cannot be built is left out (and its id unused).
fn tool_containers<T: RemoteTool>(tools: &[T]) -> impl Iterator<Item = ObjectContainer> + '_ {
    tools.iter().zip(0u64..).filter_map(|(tool, n)| {
        let mut object = tool.object()?;
        object.prepare();
        let sampler = Sampler::new(Arc::new(object));
        ObjectContainer::new(REMOTE_TOOL_ID_BASE + n, sampler, Transform::IDENTITY).ok()
    })
}

/// Locks the source; one whose holder panicked is read as it was left (a source whose updates
/// are applied whole under its lock, as the app's view's are, is still consistent).
fn lock<S>(source: &Mutex<S>) -> MutexGuard<'_, S> {
    source.lock().unwrap_or_else(PoisonError::into_inner)
}
