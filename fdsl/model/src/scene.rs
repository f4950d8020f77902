//! A scene: objects under stable ids, in nested groups with transforms, and a
//! [`SceneSampler`] that answers in scene (world) coordinates what [`Sampler`] answers in an
//! object's own.
//!
//! The coordinate convention: the world is the scene's own frame (+y up, as VRML); an object
//! sits in it by [`world_from_object`] at scene time `t`: its own transform followed by its
//! motion at `t` ([`Sampler::placement`]), then its groups' transforms
//! ([`Scene::world_from_group`]). Every crate places objects by that one function, so what
//! is drawn is where it is felt.

use std::collections::BTreeMap;
use std::sync::Arc;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::bvh::Aabb;
use crate::limits::{MAX_GROUP_DEPTH, MAX_GROUPS, MAX_OBJECTS};
use crate::object::codec;
use crate::object::{
    ColorSlot, Edit, Object, ObjectData, ObjectError, Paintable, Rgb, Sampler, Transform,
};
use fdsl::eval::Interval;

/// An object's id, stable for the object's life (replication derives it from the op that
/// created the object).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct ObjectId(pub u64);

/// A group's id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct GroupId(pub u64);

/// A group: a named transform that objects and other groups hang from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Group {
    /// A label for people.
    pub name: String,
    /// The group it hangs from, if any.
    pub parent: Option<GroupId>,
    /// Group space to parent space.
    pub transform: Transform,
}

/// Why a scene change was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// The id is taken.
    #[error("{0} already exists")]
    Exists(String),
    /// The id names nothing.
    #[error("{0} does not exist")]
    Missing(String),
    /// A limit would be exceeded.
    #[error("the scene already holds the most {0} allowed")]
    Full(&'static str),
    /// The group would hang from itself.
    #[error("group {0} would become its own ancestor")]
    Cycle(u64),
    /// Groups would nest deeper than allowed.
    #[error("groups would nest deeper than {MAX_GROUP_DEPTH}")]
    TooDeep,
    /// The object's description is not valid.
    #[error(transparent)]
    Object(#[from] ObjectError),
}

/// An object in the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneObject {
    /// The object.
    pub object: Object,
    /// The group it hangs from.
    pub group: Option<GroupId>,
}

/// The scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    objects: BTreeMap<ObjectId, SceneObject>,
    groups: BTreeMap<GroupId, Group>,
}

impl Scene {
    /// An empty scene.
    pub fn new() -> Scene {
        Scene::default()
    }

    /// Adds an object under a new id.
    pub fn insert_object(
        &mut self,
        id: ObjectId,
        object: Object,
        group: Option<GroupId>,
    ) -> Result<(), SceneError> {
        if self.objects.contains_key(&id) {
            return Err(SceneError::Exists(format!("object {}", id.0)));
        }
        if self.objects.len() >= MAX_OBJECTS {
            return Err(SceneError::Full("objects"));
        }
        self.check_group(group)?;
        self.objects.insert(id, SceneObject { object, group });
        Ok(())
    }

    /// Removes an object.
    pub fn remove_object(&mut self, id: ObjectId) -> Option<Object> {
        self.objects.remove(&id).map(|o| o.object)
    }

    /// An object.
    pub fn object(&self, id: ObjectId) -> Option<&Object> {
        self.objects.get(&id).map(|o| &o.object)
    }

    /// An object with the group it hangs from.
    pub fn scene_object(&self, id: ObjectId) -> Option<&SceneObject> {
        self.objects.get(&id)
    }

    /// An object, to change.
    pub fn object_mut(&mut self, id: ObjectId) -> Option<&mut Object> {
        self.objects.get_mut(&id).map(|o| &mut o.object)
    }

    /// Applies an edit to an object; returns the edit's index in its history.
    pub fn apply(&mut self, id: ObjectId, edit: Edit) -> Result<usize, SceneError> {
        let object = self
            .object_mut(id)
            .ok_or_else(|| SceneError::Missing(format!("object {}", id.0)))?;
        Ok(object.apply(edit)?)
    }

    /// Every object, by id.
    pub fn objects(&self) -> impl Iterator<Item = (ObjectId, &SceneObject)> {
        self.objects.iter().map(|(id, o)| (*id, o))
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    /// Whether there are no objects.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// Every group, by id.
    pub fn groups(&self) -> impl Iterator<Item = (GroupId, &Group)> {
        self.groups.iter().map(|(id, g)| (*id, g))
    }

    /// A group.
    pub fn group(&self, id: GroupId) -> Option<&Group> {
        self.groups.get(&id)
    }

    fn check_group(&self, group: Option<GroupId>) -> Result<(), SceneError> {
        match group {
            Some(g) if !self.groups.contains_key(&g) => {
                Err(SceneError::Missing(format!("group {}", g.0)))
            }
            _ => Ok(()),
        }
    }

    /// Adds a group, or replaces one (its name, parent and transform).
    pub fn set_group(&mut self, id: GroupId, group: Group) -> Result<(), SceneError> {
        if !self.groups.contains_key(&id) && self.groups.len() >= MAX_GROUPS {
            return Err(SceneError::Full("groups"));
        }
        self.check_group(group.parent)?;
        group
            .transform
            .inverse()
            .ok_or(SceneError::Object(ObjectError::BadTransform {
                slot: crate::object::Slot::Transform,
            }))?;
        // Walk up from the new parent: reaching `id` is a cycle. A group already in the scene
        // brings the groups below it along, so they count too.
        let mut depth = 1 + self.height_below(id);
        let mut up = group.parent;
        while let Some(g) = up {
            if g == id {
                return Err(SceneError::Cycle(id.0));
            }
            depth += 1;
            if depth > MAX_GROUP_DEPTH {
                return Err(SceneError::TooDeep);
            }
            up = self.groups.get(&g).and_then(|g| g.parent);
        }
        if depth > MAX_GROUP_DEPTH {
            return Err(SceneError::TooDeep);
        }
        self.groups.insert(id, group);
        Ok(())
    }

    /// How many levels of groups hang below `id` (0 when none does): each group's distance up
    /// to `id`, walked once per group (a distance found is kept for the groups below it), so
    /// this costs O(groups) map lookups whatever the shape of the tree.
    fn height_below(&self, id: GroupId) -> usize {
        // For each group walked: its distance up to `id`, or `None` when `id` is not above it.
        let mut known: BTreeMap<GroupId, Option<usize>> = BTreeMap::new();
        let mut height = 0;
        let mut path = Vec::new();
        for &start in self.groups.keys() {
            path.clear();
            let mut up = Some(start);
            let found = loop {
                match up {
                    None => break None,
                    Some(g) if g == id => break Some(0),
                    Some(g) => {
                        if let Some(&d) = known.get(&g) {
                            break d;
                        }
                        // Depths are bounded on every insert, so no walk is longer than the
                        // limit; a longer one can only be a cycle, which inserts refuse.
                        if path.len() > MAX_GROUP_DEPTH {
                            break None;
                        }
                        path.push(g);
                        up = self.groups.get(&g).and_then(|g| g.parent);
                    }
                }
            };
            for (i, &g) in path.iter().rev().enumerate() {
                let d = found.map(|d| d + i + 1);
                known.insert(g, d);
                height = height.max(d.unwrap_or(0));
            }
        }
        height
    }

    /// Removes a group; what hung from it hangs from its parent.
    pub fn remove_group(&mut self, id: GroupId) -> Option<Group> {
        let group = self.groups.remove(&id)?;
        for g in self.groups.values_mut() {
            if g.parent == Some(id) {
                g.parent = group.parent;
                g.transform = group.transform.then(&g.transform);
            }
        }
        for o in self.objects.values_mut() {
            if o.group == Some(id) {
                o.group = group.parent;
                let t = group.transform.then(&o.object.data().transform);
                // Composing two valid transforms keeps it finite; a degenerate product keeps
                // the old placement rather than failing a removal.
                let _ = o.object.set(crate::object::Field::Transform(Box::new(t)));
            }
        }
        Some(group)
    }

    /// Moves an object into a group (or to the top).
    pub fn set_object_group(
        &mut self,
        id: ObjectId,
        group: Option<GroupId>,
    ) -> Result<(), SceneError> {
        self.check_group(group)?;
        let o = self
            .objects
            .get_mut(&id)
            .ok_or_else(|| SceneError::Missing(format!("object {}", id.0)))?;
        o.group = group;
        Ok(())
    }

    /// Group space to world space for `group`.
    pub fn world_from_group(&self, group: Option<GroupId>) -> Transform {
        let mut t = Transform::IDENTITY;
        let mut up = group;
        let mut depth = 0;
        while let Some(g) = up.and_then(|id| self.groups.get(&id)) {
            t = g.transform.then(&t);
            up = g.parent;
            depth += 1;
            if depth > MAX_GROUP_DEPTH {
                break;
            }
        }
        t
    }

    /// Indexes every object's recent edits (see [`Object::prepare`]).
    pub fn prepare(&mut self) {
        for o in self.objects.values_mut() {
            o.object.prepare();
        }
    }

    /// A sampler over every object (a snapshot: later changes do not reach it).
    pub fn sampler(&self) -> SceneSampler {
        SceneSampler {
            entries: self
                .objects
                .iter()
                .map(|(id, o)| {
                    (
                        *id,
                        SamplerEntry {
                            sampler: o.object.sampler(),
                            world_from_group: self.world_from_group(o.group),
                        },
                    )
                })
                .collect(),
        }
    }

    /// The canonical encoding of the whole scene (objects with their histories, groups).
    pub fn encode(&self) -> Vec<u8> {
        let record = SceneRecord {
            objects: self
                .objects
                .iter()
                .map(|(id, o)| (*id, o.group, codec::encode_object(&o.object)))
                .collect(),
            groups: self.groups.iter().map(|(id, g)| (*id, g.clone())).collect(),
        };
        codec::encode(&record)
    }

    /// Decodes and validates a scene.
    pub fn decode(bytes: &[u8]) -> Result<Scene, SceneError> {
        let record: SceneRecord = codec::decode("scene", bytes)?;
        let mut scene = Scene::new();
        // Parents first: insert groups in an order where every parent precedes its children.
        let mut pending = record.groups;
        while !pending.is_empty() {
            let before = pending.len();
            let mut rest = Vec::new();
            for (id, g) in pending {
                if g.parent.is_none_or(|p| scene.groups.contains_key(&p)) {
                    scene.set_group(id, g)?;
                } else {
                    rest.push((id, g));
                }
            }
            if rest.len() == before {
                return Err(SceneError::Missing(
                    "a parent group (or groups form a cycle)".into(),
                ));
            }
            pending = rest;
        }
        for (id, group, bytes) in record.objects {
            scene.insert_object(id, codec::decode_object(&bytes)?, group)?;
        }
        Ok(scene)
    }

    /// A new object from its description.
    pub fn create(
        &mut self,
        id: ObjectId,
        data: impl Into<Arc<ObjectData>>,
        group: Option<GroupId>,
    ) -> Result<(), SceneError> {
        self.insert_object(id, Object::new(data)?, group)
    }
}

/// Object space to world space at scene time `t_secs`, for an object whose groups place it
/// by `world_from_group` ([`Scene::world_from_group`]): its own transform followed by its
/// motion at `t_secs` ([`Sampler::placement`]), then the groups' transforms. The one placement rule
/// (see the module documentation); it allocates nothing.
pub fn world_from_object(
    world_from_group: &Transform,
    sampler: &mut Sampler,
    t_secs: f64,
) -> Transform {
    world_from_group.then(&sampler.placement(t_secs))
}

#[derive(Serialize, Deserialize)]
struct SceneRecord {
    objects: Vec<(ObjectId, Option<GroupId>, Vec<u8>)>,
    groups: Vec<(GroupId, Group)>,
}

struct SamplerEntry {
    sampler: Sampler,
    world_from_group: Transform,
}

/// Samples a scene in world coordinates; see [`Sampler`] for each quantity.
pub struct SceneSampler {
    entries: BTreeMap<ObjectId, SamplerEntry>,
}

impl SceneSampler {
    /// The ids sampled.
    pub fn ids(&self) -> impl Iterator<Item = ObjectId> + '_ {
        self.entries.keys().copied()
    }

    /// The object's sampler (object coordinates).
    pub fn object_sampler(&mut self, id: ObjectId) -> Option<&mut Sampler> {
        self.entries.get_mut(&id).map(|e| &mut e.sampler)
    }

    /// Object space to world space at time `t`.
    pub fn world_from_object(&mut self, id: ObjectId, t: f64) -> Option<Transform> {
        let e = self.entries.get_mut(&id)?;
        Some(world_from_object(&e.world_from_group, &mut e.sampler, t))
    }

    fn local(&mut self, id: ObjectId, t: f64) -> Option<(&mut Sampler, Transform)> {
        let e = self.entries.get_mut(&id)?;
        let world_from_object = world_from_object(&e.world_from_group, &mut e.sampler, t);
        let object_from_world = world_from_object.inverse()?;
        Some((&mut e.sampler, object_from_world))
    }

    /// The solid's value at a world point.
    pub fn value(&mut self, id: ObjectId, p: DVec3, t: f64) -> Option<f64> {
        let (s, inv) = self.local(id, t)?;
        Some(s.value(inv.point(p), t))
    }

    /// Value and world-space gradient.
    pub fn gradient(&mut self, id: ObjectId, p: DVec3, t: f64) -> Option<(f64, DVec3)> {
        let (s, inv) = self.local(id, t)?;
        let (v, g) = s.gradient(inv.point(p), t);
        Some((v, inv.linear().transpose() * g))
    }

    /// An interval over a world-space box.
    pub fn interval(&mut self, id: ObjectId, region: &Aabb, t: f64) -> Option<Interval> {
        let (s, inv) = self.local(id, t)?;
        Some(s.interval(&inv.aabb(region), t))
    }

    /// A colour at a world point.
    pub fn color(&mut self, id: ObjectId, slot: ColorSlot, p: DVec3, t: f64) -> Option<Rgb> {
        let (s, inv) = self.local(id, t)?;
        s.color(slot, inv.point(p), t)
    }

    /// A scalar property at a world point.
    pub fn scalar(&mut self, id: ObjectId, property: Paintable, p: DVec3, t: f64) -> Option<f64> {
        let (s, inv) = self.local(id, t)?;
        s.scalar(property, inv.point(p), t)
    }

    /// The force field at a world point, in world axes.
    pub fn force(&mut self, id: ObjectId, p: DVec3, t: f64) -> Option<DVec3> {
        let (s, inv) = self.local(id, t)?;
        let f = s.force(inv.point(p), t)?;
        let world_linear = inv.inverse()?.linear();
        Some(world_linear * f)
    }
}
