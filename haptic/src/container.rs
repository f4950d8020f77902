//! What the force renderer needs from a scene: haptic containers with optional physical
//! properties, evaluated at world points.
//!
//! Sign convention (F-Rep): `f >= 0` is inside, `f = 0` the surface; the distance to the
//! surface is estimated by the metric depth `f / |grad f|`.
//!
//! Implementations: [`function::FunctionContainer`] (fdsl functions over a box),
//! [`mesh::MeshContainer`] (closed triangle meshes located by haptic rays), both with
//! [`properties::Properties`]; [`object::ObjectContainer`] (an object of the shared object
//! model, sculpting edits and painted properties included); and the closed-form
//! [`crate::shapes::Analytic`] for tests.

pub mod function;
pub mod mesh;
pub mod object;
pub mod properties;

use glam::DVec3;

use crate::aabb::Aabb;

/// Gradients shorter than this have no usable normal (e.g. the centre of a sphere): the
/// metric depth `f / |grad f|` is not taken there.
pub const MIN_GRADIENT_NORM: f64 = 1e-9;

/// How a force field's domain and time are mapped (thesis 7.3, `FForce` `parameters`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldDomain {
    /// The world box the field is defined over.
    pub box_world: Aabb,
    /// The (u, v, w) ranges the box maps to, e.g. `[-1,1] x [0,1] x [-1,1]`.
    pub uvw: Aabb,
    /// The field repeats with this period; 0 means it never repeats.
    pub cycle_interval_secs: f64,
    /// Within each cycle the field acts for this long; infinite means always.
    pub time_span_secs: f64,
}

impl FieldDomain {
    /// Maps a world point to the field's (u, v, w).
    pub fn uvw_from_world(&self, p: DVec3) -> DVec3 {
        let size = self.box_world.size().max(DVec3::splat(f64::MIN_POSITIVE));
        let unit = (p - self.box_world.min) / size;
        self.uvw.min + unit * self.uvw.size()
    }

    /// The field's own time at scene time `t_secs`, or `None` when it is not acting.
    pub fn local_time(&self, t_secs: f64) -> Option<f64> {
        let t_local = if self.cycle_interval_secs > 0.0 {
            t_secs.rem_euclid(self.cycle_interval_secs)
        } else {
            t_secs
        };
        (t_local <= self.time_span_secs).then_some(t_local)
    }
}

/// A haptic container: a solid (`f >= 0` inside) with optional surface, interior and field
/// properties.
///
/// Methods take `&mut self` because evaluators keep scratch registers. They are called from
/// the servo thread: they must not allocate, lock or block. A property that returns `None`
/// is disabled.
pub trait Container: Send {
    /// Stable identity of the container across snapshots (the object id).
    fn id(&self) -> u64;
    /// A world box enclosing every point where `value_grad` is `>= 0`.
    fn bounds(&self) -> Aabb;
    /// The function value and its gradient at world point `p`, time `t_secs`.
    fn value_grad(&mut self, p: DVec3, t_secs: f64) -> (f64, DVec3);
    /// Surface tension in `[0, 1]` (fraction of the device's maximum stiffness).
    fn tension(&mut self, p: DVec3, t_secs: f64) -> Option<f64>;
    /// Surface friction coefficient in `[0, 1]`.
    fn friction(&mut self, p: DVec3, t_secs: f64) -> Option<f64>;
    /// Interior density in `[0, 1]` (fraction of the device's maximum damping).
    fn density(&mut self, p: DVec3, t_secs: f64) -> Option<f64>;
    /// Depth of the surface zone in world units at `p`; `None` when the container gives none,
    /// and the renderer then uses the device's own ([`crate::force::Rig::zone_depth_world`]).
    fn zone_depth(&mut self, p: DVec3, t_secs: f64) -> Option<f64>;
    /// The force field's domain and timing, `None` when the container has no field mapped
    /// through a [`FieldDomain`] (the default; see [`Container::field_at`]).
    fn field_domain(&self) -> Option<FieldDomain> {
        None
    }
    /// The force field at `uvw` (in the field domain) and field time `t_local_secs`; its
    /// magnitude is a fraction of the device's maximum force (clamped to 1). Only called
    /// through the default [`Container::field_at`], when `field_domain` is `Some`.
    fn force_field(&mut self, uvw: DVec3, t_local_secs: f64) -> DVec3 {
        let _ = (uvw, t_local_secs);
        DVec3::ZERO
    }
    /// The force field at world point `p` and scene time `t_secs`, in world axes, as a
    /// fraction of the device's maximum force (the renderer clamps its length to 1); `None`
    /// where no field acts. The default maps `p` and `t_secs` through
    /// [`Container::field_domain`] and evaluates [`Container::force_field`]; a container
    /// whose field has its own mapping (an object of `model::object`) answers here directly.
    fn field_at(&mut self, p: DVec3, t_secs: f64) -> Option<DVec3> {
        let domain = self.field_domain()?;
        let t_local = domain.local_time(t_secs)?;
        Some(self.force_field(domain.uvw_from_world(p), t_local))
    }
    /// Where the segment `p0 -> p1` first crosses the surface, as a fraction of its length,
    /// when the container can tell faster than by narrowing a bracket with `value_grad` (a
    /// mesh casts the segment as one ray). `None` means "narrow" ([`model::root::crossing`]).
    fn first_crossing(&mut self, p0: DVec3, p1: DVec3, t_secs: f64) -> Option<f64> {
        let _ = (p0, p1, t_secs);
        None
    }
}

/// A scene snapshot as the servo sees it: an indexed set of containers.
pub trait Scene: Send {
    /// Number of containers.
    fn n_containers(&self) -> usize;
    /// The container at `idx` (`idx < n_containers()`).
    fn container_mut(&mut self, idx: usize) -> &mut dyn Container;
}

impl<C: Container> Scene for Vec<C> {
    fn n_containers(&self) -> usize {
        self.len()
    }
    fn container_mut(&mut self, idx: usize) -> &mut dyn Container {
        &mut self[idx]
    }
}

impl Scene for Vec<Box<dyn Container>> {
    fn n_containers(&self) -> usize {
        self.len()
    }
    fn container_mut(&mut self, idx: usize) -> &mut dyn Container {
        self[idx].as_mut()
    }
}
