//! [`ObjectContainer`]: a haptic container over an object of the shared object model
//! ([`model::object`]), so that what the app sculpts is what the hand feels: the container's
//! own geometry, or the object's geometry with its sculpting edits folded in, with painted
//! properties overriding the object's formulas.
//!
//! Everything is evaluated by a [`model::object::Sampler`] in object coordinates and scene
//! time; this module maps world points into the object. The placement is a general affine
//! map `world_from_object` (the object model's one rule, `model::scene::world_from_object`:
//! group transforms, the object's transform and its motion): points
//! go through its inverse, gradients through the inverse-transpose (`grad_world = A^T
//! grad_object` for `object = A world + b`), so the metric depth `f / |grad f|` the renderer
//! computes is in world units however the object is scaled or sheared.
//!
//! Units (the haptic convention, the thesis's normalised values): tension and density are
//! fractions of the device's maximum stiffness and damping, friction a coefficient in
//! `[0, 1]`, the surface-zone depth is in scene (world) units as the object model states, and
//! the force field is a fraction of the device's maximum force. The field's direction is
//! mapped from object to world axes by `world_from_object`'s linear part and its length is
//! kept, so scaling an object does not weaken its field.
//!
//! Bounds: the world box of the container's domain (or of the object's domain and union
//! edits, [`model::object::Object::bounds`]). A solid without a domain or a moving object has
//! infinite bounds: it is correct, but evaluated on every tick instead of only when the tip
//! is in its box.
//!
//! A container is built off the servo thread (it clones and indexes the object and reserves
//! the sampler's scratch space); sampling allocates nothing afterwards, whatever the length
//! of the edit history, with one exception the sampler documents: a point inside the boxes
//! of more edits than it reserved room for (the history's length, at least 64 and at most
//! `MAX_RESERVED_HITS`, 4096, in model's sampler) grows its hit list, once.

use glam::{DAffine3, DMat3, DVec3};

use model::object::{Object, Paintable, Sampler, Shape, Transform};
use model::scene::ObjectId;

use super::Container;
use crate::aabb::Aabb;

/// Why an object cannot become a haptic container.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ObjectContainerError {
    /// `world_from_object` is not finite or not invertible (a degenerate group transform).
    #[error("object {id}: its world placement is not finite or not invertible")]
    BadPlacement {
        /// The container id.
        id: u64,
    },
    /// Its formulas cost more per sample than a servo tick can pay
    /// ([`MAX_TOUCH_INSTRUCTIONS`]): it is seen but not felt, and the tick keeps its budget.
    #[error(
        "object {id} is too costly to feel: {instructions} instructions a sample, the servo \
         pays at most {max}; it is drawn but not felt (simplify its formulas)"
    )]
    TooCostly {
        /// The container id.
        id: u64,
        /// `Object::touch_instructions`.
        instructions: usize,
        /// [`MAX_TOUCH_INSTRUCTIONS`].
        max: usize,
    },
}

/// Most tape instructions one sample of a container may run (`Object::touch_instructions`):
/// a tick samples a touched container up to about 36 times (a gradient, the search for a
/// crossing, the properties, the field), and the point evaluator runs an instruction in a
/// few nanoseconds, so this keeps one container well under the 1 ms tick. A formula a peer
/// may send can unroll to `fdsl::limits::MAX_GRAPH_NODES`, 25 times more.
pub const MAX_TOUCH_INSTRUCTIONS: usize = 8192;

/// The object's placement at one time: what maps world points and vectors into it and back.
#[derive(Clone, Copy, Debug)]
struct Frame {
    t_secs: f64,
    world_from_object: Transform,
    object_from_world: DAffine3,
    /// Object gradients to world gradients: the transpose of `object_from_world`'s linear
    /// part.
    grad_world_from_object: DMat3,
}

impl Frame {
    /// The frame of `world_from_object`, if it is finite and invertible.
    fn new(world_from_object: &Transform, t_secs: f64) -> Option<Frame> {
        let object_from_world = world_from_object.inverse()?.parent_from_child;
        Some(Frame {
            t_secs,
            world_from_object: *world_from_object,
            object_from_world,
            grad_world_from_object: object_from_world.matrix3.transpose(),
        })
    }
}

/// A haptic container over one object of the object model; see the module documentation.
pub struct ObjectContainer {
    id: u64,
    sampler: Sampler,
    world_from_parent: Transform,
    moving: bool,
    frame: Frame,
    bounds: Aabb,
}

impl std::fmt::Debug for ObjectContainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ObjectContainer")
            .field("id", &self.id)
            .field("moving", &self.moving)
            .field("bounds", &self.bounds)
            .finish_non_exhaustive()
    }
}

/// The box, in object space, outside which the container's value is negative; `None` when
/// unbounded.
fn container_bounds_object(object: &Object) -> Option<model::bvh::Aabb> {
    match &object.data().physics.container {
        Some(container) => {
            let in_object = |b: &model::bvh::Aabb| container.transform.aabb(b);
            match (&container.shape, &container.domain) {
                // A parametric shape has no field: the sampler gives empty space everywhere.
                (Shape::Parametric { .. }, _) => Some(model::bvh::Aabb::EMPTY),
                (_, Some(domain)) => Some(in_object(&domain.aabb())),
                (Shape::Mesh(mesh), None) => Some(in_object(&mesh.bounds())),
                (Shape::Implicit(_), None) => None,
            }
        }
        None => object.bounds(),
    }
}

impl ObjectContainer {
    /// A container over `sampler`'s object, whose parent space (its group, or the world) is
    /// placed by `world_from_parent`; the object's own transform and motion come from the
    /// sampler. For an unprepared object prefer [`ObjectContainer::from_object`], which
    /// indexes the edit history first.
    pub fn new(
        id: u64,
        mut sampler: Sampler,
        world_from_parent: Transform,
    ) -> Result<ObjectContainer, ObjectContainerError> {
        let instructions = sampler.object().touch_instructions();
        if instructions > MAX_TOUCH_INSTRUCTIONS {
            return Err(ObjectContainerError::TooCostly {
                id,
                instructions,
                max: MAX_TOUCH_INSTRUCTIONS,
            });
        }
        let world_from_object =
            model::scene::world_from_object(&world_from_parent, &mut sampler, 0.0);
        let frame =
            Frame::new(&world_from_object, 0.0).ok_or(ObjectContainerError::BadPlacement { id })?;
        let moving = sampler.object().data().motion.is_some();
        let bounds_object = if moving {
            None
        } else {
            container_bounds_object(sampler.object())
        };
        let bounds = match bounds_object {
            None => Aabb::new(DVec3::NEG_INFINITY, DVec3::INFINITY),
            // Nothing to touch: a point box at the object's origin (its value is negative).
            Some(b) if b.is_empty() => {
                let origin = world_from_object.point(DVec3::ZERO);
                Aabb::new(origin, origin)
            }
            Some(b) => {
                let b = world_from_object.aabb(&b);
                Aabb::new(b.lo, b.hi)
            }
        };
        Ok(ObjectContainer {
            id,
            sampler,
            world_from_parent,
            moving,
            frame,
            bounds,
        })
    }

    /// [`ObjectContainer::new`] over a copy of `object` whose edit history is indexed first
    /// (an unindexed tail is scanned on every evaluation, which a long tail makes slow).
    pub fn from_object(
        id: u64,
        object: &Object,
        world_from_parent: Transform,
    ) -> Result<ObjectContainer, ObjectContainerError> {
        let mut object = object.clone();
        object.prepare();
        Self::new(
            id,
            Sampler::new(std::sync::Arc::new(object)),
            world_from_parent,
        )
    }

    /// The containers of every tangible object of `scene` (`Object::is_tangible`: objects
    /// without physics are seen, not felt, and must not hide the containers they overlap),
    /// by id (`ObjectId(n)` becomes id `n`), in id order: a snapshot for the servo. Objects
    /// whose placement is degenerate are left out and returned with their error. Allocates:
    /// call it off the servo thread.
    pub fn from_scene(
        scene: &model::scene::Scene,
    ) -> (Vec<ObjectContainer>, Vec<(ObjectId, ObjectContainerError)>) {
        let mut containers = Vec::with_capacity(scene.len());
        let mut refused = Vec::new();
        for (id, entry) in scene.objects().filter(|(_, e)| e.object.is_tangible()) {
            let world_from_group = scene.world_from_group(entry.group);
            match Self::from_object(id.0, &entry.object, world_from_group) {
                Ok(container) => containers.push(container),
                Err(error) => refused.push((id, error)),
            }
        }
        (containers, refused)
    }

    /// The sampler (object coordinates), e.g. to evaluate colours for a display of what is
    /// felt.
    pub fn sampler_mut(&mut self) -> &mut Sampler {
        &mut self.sampler
    }

    /// Object space to world space at scene time `t_secs` (the last valid placement when a
    /// motion makes it degenerate).
    pub fn world_from_object(&mut self, t_secs: f64) -> Transform {
        self.frame(t_secs).world_from_object
    }

    /// The placement at `t_secs`, recomputed only for a moving object at a new time (the
    /// servo asks many times per tick at the same time).
    fn frame(&mut self, t_secs: f64) -> Frame {
        if self.moving && self.frame.t_secs != t_secs {
            let world_from_object =
                model::scene::world_from_object(&self.world_from_parent, &mut self.sampler, t_secs);
            // A motion that degenerates keeps the last good placement.
            if let Some(frame) = Frame::new(&world_from_object, t_secs) {
                self.frame = frame;
            }
        }
        self.frame
    }

    fn object_point(&mut self, p_world: DVec3, t_secs: f64) -> DVec3 {
        self.frame(t_secs)
            .object_from_world
            .transform_point3(p_world)
    }

    fn scalar(&mut self, property: Paintable, p_world: DVec3, t_secs: f64) -> Option<f64> {
        let q = self.object_point(p_world, t_secs);
        self.sampler.scalar(property, q, t_secs)
    }
}

impl Container for ObjectContainer {
    fn id(&self) -> u64 {
        self.id
    }

    /// May be infinite (see the module documentation).
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn value_grad(&mut self, p_world: DVec3, t_secs: f64) -> (f64, DVec3) {
        let frame = self.frame(t_secs);
        let q = frame.object_from_world.transform_point3(p_world);
        let (value, grad) = self.sampler.container_gradient(q, t_secs);
        (value, frame.grad_world_from_object * grad)
    }

    fn tension(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.scalar(Paintable::Tension, p, t_secs)
    }

    fn friction(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.scalar(Paintable::Friction, p, t_secs)
    }

    fn density(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.scalar(Paintable::Density, p, t_secs)
    }

    /// Scene units; `None` when the object gives no depth (none, or disabled), so that the
    /// device's own applies; a negative or non-finite depth is no zone.
    fn zone_depth(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.scalar(Paintable::ZoneDepth, p, t_secs).map(|depth| {
            if depth.is_finite() {
                depth.max(0.0)
            } else {
                0.0
            }
        })
    }

    fn field_at(&mut self, p: DVec3, t_secs: f64) -> Option<DVec3> {
        let frame = self.frame(t_secs);
        let q = frame.object_from_world.transform_point3(p);
        let field = self.sampler.force(q, t_secs)?;
        let direction = (frame.world_from_object.linear() * field).normalize_or_zero();
        Some(direction * field.length())
    }
}

#[cfg(test)]
mod tests;
