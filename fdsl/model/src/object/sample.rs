//! [`Sampler`]: evaluates one object at object-space points and scene time: the solid's value,
//! gradient and interval over a box (base geometry folded with the edits that touch the
//! point), colours, each physical property, the force field and the object's motion. It owns
//! its evaluators and scratch space, so after creation it does not allocate (the haptic loop
//! relies on this).

use std::sync::Arc;

use glam::{DMat3, DQuat, DVec3};

use super::appearance::Rgb;
use super::box_sampler::BoxSampler;
use super::edit::{EditOp, PaintValue, Paintable};
use super::history::Hit;
use super::space::Transform;
use super::{CompiledColor, CompiledShape, NOTHING, Object};
use crate::bvh::Aabb;
use fdsl::eval::{GradEval, Interval, IntervalEval, PointEval};

/// Ray hits are located to this fraction of the ray's length.
pub const RAY_TOLERANCE: f64 = 1e-9;
/// Most pieces of one ray whose interval is evaluated (65,536). A surface-like function along
/// the ray (the constant 0, a tangent plane) keeps every piece ambiguous; past this the ray
/// counts as missing instead of visiting all 10^7 pieces of `RAY_TOLERANCE`.
pub const MAX_RAY_PIECES: usize = 1 << 16;

/// The most hits a new sampler reserves room for.
pub const MAX_RESERVED_HITS: usize = 4096;

/// The grey of an object without a diffuse colour.
pub const DEFAULT_DIFFUSE: Rgb = [0.8, 0.8, 0.8];

/// Evaluators for one shape.
pub(super) struct ShapeEval {
    point: PointEval,
    grad: GradEval,
    pub(super) interval: IntervalEval,
}

/// A shape's evaluators and placement: the point path, which the box-restricted sampler
/// shares for gradients and intervals.
pub(super) struct Shape {
    pub(super) eval: Option<ShapeEval>,
    pub(super) compiled: CompiledShape,
    /// Transposed linear part of object -> shape space, for the chain rule.
    jacobian_t: DMat3,
}

impl Shape {
    pub(super) fn new(compiled: &CompiledShape) -> Shape {
        Shape {
            eval: compiled.tape.as_ref().map(|t| ShapeEval {
                point: PointEval::new(t),
                grad: GradEval::new(t),
                interval: IntervalEval::new(t),
            }),
            jacobian_t: compiled.local_from_object.linear().transpose(),
            compiled: compiled.clone(),
        }
    }

    fn value(&mut self, p: DVec3, t: f64) -> f64 {
        let q = self.compiled.local_from_object.point(p);
        let f = match (&mut self.eval, &self.compiled.mesh) {
            (Some(e), _) => e.point.eval([q.x, q.y, q.z, t]),
            (None, Some(m)) => m.signed_distance(q),
            (None, None) => return NOTHING,
        };
        match &self.compiled.domain {
            Some(d) => f.min(d.signed_distance(q)),
            None => f,
        }
    }

    pub(super) fn gradient(&mut self, p: DVec3, t: f64) -> (f64, DVec3) {
        let q = self.compiled.local_from_object.point(p);
        let mut out = match (&mut self.eval, &self.compiled.mesh) {
            (Some(e), _) => {
                let g = e.grad.eval([q.x, q.y, q.z, t]);
                (g.v, DVec3::new(g.dx, g.dy, g.dz))
            }
            (None, Some(m)) => m.value_gradient(q),
            (None, None) => return (NOTHING, DVec3::ZERO),
        };
        if let Some(d) = &self.compiled.domain {
            let dv = d.signed_distance(q);
            if dv < out.0 {
                let h = 1e-6 * d.size.max_element();
                let grad = DVec3::new(
                    d.signed_distance(q + DVec3::X * h) - d.signed_distance(q - DVec3::X * h),
                    d.signed_distance(q + DVec3::Y * h) - d.signed_distance(q - DVec3::Y * h),
                    d.signed_distance(q + DVec3::Z * h) - d.signed_distance(q - DVec3::Z * h),
                ) / (2.0 * h);
                out = (dv, grad);
            }
        }
        (out.0, self.jacobian_t * out.1)
    }

    pub(super) fn interval(&mut self, region: &Aabb, t: f64) -> Interval {
        let local = self.compiled.local_from_object.aabb(region);
        let iv = |lo: f64, hi: f64| Interval::new(lo, hi);
        let f = match (&mut self.eval, &self.compiled.mesh) {
            (Some(e), _) => e.interval.eval([
                iv(local.lo.x, local.hi.x),
                iv(local.lo.y, local.hi.y),
                iv(local.lo.z, local.hi.z),
                Interval::point(t),
            ]),
            (None, Some(m)) => {
                // A signed distance changes by at most the distance moved.
                let c = m.signed_distance(local.center());
                let r = local.size().length() * 0.5;
                Interval::new(c - r, c + r)
            }
            (None, None) => return Interval::point(NOTHING),
        };
        match &self.compiled.domain {
            Some(d) => {
                let c = d.signed_distance(local.center());
                let r = local.size().length() * 0.5;
                Interval {
                    lo: f.lo.min(c - r),
                    hi: f.hi.min(c + r),
                    nan: f.nan,
                }
            }
            None => f,
        }
    }
}

enum Color {
    Constant(Rgb),
    Rgb(PointEval),
    Map(PointEval, super::ColorMap),
}

impl Color {
    fn new(c: &CompiledColor) -> Color {
        match c {
            CompiledColor::Constant(rgb) => Color::Constant(*rgb),
            CompiledColor::Rgb(tape) => Color::Rgb(PointEval::new(tape)),
            CompiledColor::Map(tape, map) => Color::Map(PointEval::new(tape), map.clone()),
        }
    }

    fn eval(&mut self, q: [f64; 4]) -> Rgb {
        match self {
            Color::Constant(c) => *c,
            Color::Rgb(e) => {
                let mut rgb = [0.0; 3];
                e.eval_all(q, &mut rgb);
                rgb.map(|v| {
                    if v.is_nan() {
                        0.0
                    } else {
                        v.clamp(0.0, 1.0) as f32
                    }
                })
            }
            Color::Map(e, map) => map.color(e.eval(q)),
        }
    }
}

/// Which colour of the illumination model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorSlot {
    /// Diffuse.
    Diffuse,
    /// Ambient.
    Ambient,
    /// Specular.
    Specular,
}

/// Evaluates one object; see the module documentation.
pub struct Sampler {
    object: Arc<Object>,
    geometry: Option<Shape>,
    container: Option<Shape>,
    colors: [Option<Color>; 3],
    /// Transparency, shininess, displacement.
    looks: [Option<PointEval>; 3],
    /// Tension, friction, zone depth, density.
    feels: [Option<PointEval>; 4],
    force: Option<PointEval>,
    /// The field's domain, its space from object space, and its space's linear part into
    /// object space (computed once: the haptic loop asks every tick).
    force_space: (super::Domain, Transform, DMat3),
    motion: [Option<PointEval>; 2],
    hits: Vec<Hit>,
    /// The point (its bits) whose edits `hits` holds, if it holds a point's: the haptic loop
    /// asks the gradient twice and the painted properties at one point each tick, and they
    /// share one index lookup. The object cannot change under the sampler.
    hits_at: Option<[u64; 3]>,
}

impl Sampler {
    /// A sampler over `object` (which it keeps alive).
    pub fn new(object: Arc<Object>) -> Sampler {
        let parts = object.parts();
        let point = |t: &Option<fdsl::Tape>| t.as_ref().map(PointEval::new);
        let motion = match &parts.motion {
            Some([a, b]) => [point(a), point(b)],
            None => [None, None],
        };
        let (domain, object_from_field) = field_domain(&object);
        let force_space = (
            domain,
            object_from_field.inverse().unwrap_or(Transform::IDENTITY),
            object_from_field.linear(),
        );
        Sampler {
            force_space,
            geometry: parts.geometry.as_ref().map(Shape::new),
            container: parts.container.as_deref().map(Shape::new),
            colors: [0, 1, 2].map(|i| parts.colors[i].as_ref().map(Color::new)),
            looks: [0, 1, 2].map(|i| point(&parts.looks[i])),
            feels: [0, 1, 2, 3].map(|i| point(&parts.feels[i])),
            force: point(&parts.force),
            motion,
            // Room for every edit overlapping one point or box in practice, so the haptic
            // loop does not allocate; more overlap grows it once.
            hits: Vec::with_capacity(object.history().len().clamp(64, MAX_RESERVED_HITS)),
            hits_at: None,
            object,
        }
    }

    /// The object sampled.
    pub fn object(&self) -> &Arc<Object> {
        &self.object
    }

    /// The object restricted to `region` at time `t`, to evaluate many points of the region
    /// at once (see [`BoxSampler`]); it gathers the edits that reach the region once.
    pub fn restrict(&self, region: &Aabb, t: f64) -> BoxSampler {
        BoxSampler::new(self.object.clone(), region, t)
    }

    /// Gathers into `hits` the active edits whose support holds `p`, unless they are there
    /// already (the servo asks a tick's tip twice).
    ///
    /// The check compares each coordinate on its own: one comparison of the three as a
    /// block of memory read a point its caller had just stored coordinate by coordinate,
    /// which the processor cannot forward from its stores, and stalled every query.
    #[inline(always)]
    fn gather_at_point(&mut self, p: DVec3) {
        let same = self.hits_at.is_some_and(|[x, y, z]| {
            x == p.x.to_bits() && y == p.y.to_bits() && z == p.z.to_bits()
        });
        if !same {
            self.gather_anew(p.x, p.y, p.z);
        }
    }

    /// The lookup of [`Sampler::gather_at_point`], given the point's coordinates one by one
    /// (in registers: a point passed by reference is stored and read back).
    #[inline(never)]
    fn gather_anew(&mut self, x: f64, y: f64, z: f64) {
        let p = DVec3::new(x, y, z);
        self.object.history().hits_at_point(p, &mut self.hits);
        self.hits_at = Some([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]);
    }

    fn base_value(&mut self, p: DVec3, t: f64) -> f64 {
        self.geometry.as_mut().map_or(NOTHING, |g| g.value(p, t))
    }

    /// The solid's value at `p` (object space) and time `t`: positive inside. It is the fold
    /// of the active edits whose support holds `p` over the geometry's value (each tool is
    /// empty space outside its stamps' grown boxes), so it visits only the edits near `p`.
    pub fn value(&mut self, p: DVec3, t: f64) -> f64 {
        self.gather_at_point(p);
        let history = self.object.history();
        let start = history.last_intersect_where(|e| !e.touches(p));
        let (mut v, from) = match start {
            Some(k) => (history.entries()[k].edit.outside_value(), k + 1),
            None => (self.base_value(p, t), 0),
        };
        let history = self.object.history();
        for &hit in &self.hits {
            if hit.edit() >= from {
                v = history.apply_value(hit, v, p);
            }
        }
        v
    }

    /// Value and gradient at `p`.
    pub fn gradient(&mut self, p: DVec3, t: f64) -> (f64, DVec3) {
        self.gather_at_point(p);
        let history = self.object.history();
        let start = history.last_intersect_where(|e| !e.touches(p));
        let (mut v, from) = match start {
            Some(k) => (
                (history.entries()[k].edit.outside_value(), DVec3::ZERO),
                k + 1,
            ),
            None => (
                self.geometry
                    .as_mut()
                    .map_or((NOTHING, DVec3::ZERO), |g| g.gradient(p, t)),
                0,
            ),
        };
        let history = self.object.history();
        for &hit in &self.hits {
            if hit.edit() >= from {
                v = history.apply_grad(hit, v, p);
            }
        }
        v
    }

    /// An interval holding the value at every point of `region` (object space).
    pub fn interval(&mut self, region: &Aabb, t: f64) -> Interval {
        let history = self.object.history();
        self.hits_at = None;
        let start = history.last_intersect_where(|e| !e.boxes().iter().any(|b| b.overlaps(region)));
        let (mut v, from) = match start {
            Some(k) => (
                Interval::point(history.entries()[k].edit.outside_value()),
                k + 1,
            ),
            None => (
                self.geometry
                    .as_mut()
                    .map_or(Interval::point(NOTHING), |g| g.interval(region, t)),
                0,
            ),
        };
        let history = self.object.history();
        if history.leaves_interval(v, region) {
            return v;
        }
        history.hits_in_box(region, &mut self.hits);
        for &hit in &self.hits {
            if hit.edit() >= from {
                v = history.apply_interval(hit, v, region);
            }
        }
        v
    }

    /// The first point where the ray `origin + s * dir`, `0 <= s <= s_max`, crosses the
    /// solid's surface (either way), as `s`; `None` if it does not within `s_max`. It splits
    /// the ray into pieces whose intervals may hold zero (each interval visits only the edits
    /// near its piece) and bisects the first sign change to `RAY_TOLERANCE` of `s_max`,
    /// giving up (`None`) after [`MAX_RAY_PIECES`] pieces.
    pub fn ray_hit(&mut self, origin: DVec3, dir: DVec3, s_max: f64, t: f64) -> Option<f64> {
        if !(origin.is_finite() && dir.is_finite() && s_max.is_finite() && s_max > 0.0) {
            return None;
        }
        let at = |s: f64| origin + dir * s;
        let tolerance = s_max * RAY_TOLERANCE;
        // Pieces to visit, nearest on top; a halving stack is at most 64 deep.
        let mut stack = [(0.0f64, 0.0f64); 64];
        stack[0] = (0.0, s_max);
        let mut top = 1;
        let mut n_pieces = 0;
        while top > 0 && n_pieces < MAX_RAY_PIECES {
            top -= 1;
            n_pieces += 1;
            let (a, b) = stack[top];
            let iv = self.interval(&Aabb::new(at(a), at(b)), t);
            if !iv.nan && (iv.lo > 0.0 || iv.hi < 0.0) {
                continue;
            }
            if b - a <= tolerance * 64.0 || top + 2 > stack.len() {
                // Short enough: look for a sign change by sampling, then bisect it.
                let (mut lo, mut hi) = (a, b);
                let (va, vb) = (self.value(at(a), t), self.value(at(b), t));
                if (va >= 0.0) == (vb >= 0.0) {
                    continue;
                }
                let inside_at_lo = va >= 0.0;
                while hi - lo > tolerance {
                    let mid = 0.5 * (lo + hi);
                    if (self.value(at(mid), t) >= 0.0) == inside_at_lo {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                return Some(hi);
            }
            let mid = 0.5 * (a + b);
            stack[top] = (mid, b);
            stack[top + 1] = (a, mid);
            top += 2;
        }
        None
    }

    /// The newest painting of `property` that covers `p`.
    fn painted(&mut self, property: Paintable, p: DVec3) -> Option<PaintValue> {
        self.gather_at_point(p);
        let history = self.object.history();
        let entries = history.entries();
        // The operation comes from the index: only paintings of `property` visit their edit.
        self.hits
            .iter()
            .rev()
            .find_map(|&hit| match history.op(hit) {
                EditOp::Paint { property: q, value }
                    if q == property && entries[hit.edit()].edit.paints(p) =>
                {
                    Some(value)
                }
                _ => None,
            })
    }

    /// A colour at `p`: painted, else from the appearance, else (diffuse only) a grey.
    pub fn color(&mut self, slot: ColorSlot, p: DVec3, t: f64) -> Option<Rgb> {
        if slot == ColorSlot::Diffuse
            && let Some(PaintValue::Color(c)) = self.painted(Paintable::Color, p)
        {
            return Some(c);
        }
        let q = self.object.parts().appearance_from_object.get().point(p);
        match &mut self.colors[slot as usize] {
            Some(c) => Some(c.eval([q.x, q.y, q.z, t])),
            None => (slot == ColorSlot::Diffuse).then_some(DEFAULT_DIFFUSE),
        }
    }

    /// The diffuse colour at `p`.
    pub fn diffuse(&mut self, p: DVec3, t: f64) -> Rgb {
        self.color(ColorSlot::Diffuse, p, t)
            .unwrap_or(DEFAULT_DIFFUSE)
    }

    /// A scalar property at `p`: painted, else its formula; `None` where it is not defined
    /// (or disabled). Colour is not scalar: it gives `None` (see [`Sampler::color`]).
    pub fn scalar(&mut self, property: Paintable, p: DVec3, t: f64) -> Option<f64> {
        let (slot_enabled, from_appearance, idx) = match property {
            Paintable::Color => return None,
            Paintable::Transparency => (true, true, 0),
            Paintable::Shininess => (true, true, 1),
            Paintable::Tension => (self.enabled(0), false, 0),
            Paintable::Friction => (self.enabled(1), false, 1),
            Paintable::ZoneDepth => (self.enabled(2), false, 2),
            Paintable::Density => (self.enabled(3), false, 3),
        };
        if !slot_enabled {
            return None;
        }
        if let Some(PaintValue::Scalar(v)) = self.painted(property, p) {
            return Some(v);
        }
        let parts = self.object.parts();
        let (space, eval) = if from_appearance {
            (parts.appearance_from_object.get(), &mut self.looks[idx])
        } else {
            (parts.physics_from_object.get(), &mut self.feels[idx])
        };
        let q = space.point(p);
        eval.as_mut().map(|e| e.eval([q.x, q.y, q.z, t]))
    }

    /// Whether a physical property is enabled (absent properties count as enabled, so that
    /// painting can define them).
    fn enabled(&self, idx: usize) -> bool {
        let p = &self.object.data().physics;
        let prop = [&p.tension, &p.friction, &p.zone_depth, &p.density][idx];
        prop.as_ref().is_none_or(|p| p.enabled)
    }

    /// Displacement along the normal (the geometric texture) at `p`, if any.
    pub fn displacement(&mut self, p: DVec3, t: f64) -> Option<f64> {
        let q = self.object.parts().appearance_from_object.get().point(p);
        self.looks[2].as_mut().map(|e| e.eval([q.x, q.y, q.z, t]))
    }

    /// The haptic container's value at `p`: the container's own geometry, else the object's
    /// (with its edits).
    pub fn container_value(&mut self, p: DVec3, t: f64) -> f64 {
        match &mut self.container {
            Some(c) => c.value(p, t),
            None => self.value(p, t),
        }
    }

    /// The haptic container's value and gradient at `p`.
    pub fn container_gradient(&mut self, p: DVec3, t: f64) -> (f64, DVec3) {
        match &mut self.container {
            Some(c) => c.gradient(p, t),
            None => self.gradient(p, t),
        }
    }

    /// The box, in object space, over which the force field's parameters range: the
    /// container's domain, else the geometry's, else the physics domain, else `[-1, 1]^3`.
    pub fn field_domain(&self) -> (super::Domain, Transform) {
        field_domain(&self.object)
    }

    /// The force field at `p` (in object axes, in the field's own units: fractions of a
    /// device's largest force for the haptic crate), if the object has an enabled one.
    pub fn force(&mut self, p: DVec3, t: f64) -> Option<DVec3> {
        let field = self.object.data().physics.force.as_ref()?;
        let (parameters, timing) = (field.parameters, field.timing);
        let (domain, field_from_object, linear) = &self.force_space;
        let eval = self.force.as_mut()?;
        let n = domain.normalise(field_from_object.point(p));
        let u = [0, 1, 2].map(|i| {
            let [lo, hi] = parameters[i];
            lo + n[i] * (hi - lo)
        });
        let mut out = [0.0; 3];
        eval.eval_all([u[0], u[1], u[2], timing.local(t)], &mut out);
        Some(*linear * DVec3::from_array(out))
    }

    /// The object's placement at scene time `t`: object space to its parent's space, its
    /// static transform followed by its motion.
    pub fn placement(&mut self, t: f64) -> Transform {
        let data = self.object.data();
        let Some(motion) = &data.motion else {
            return data.transform;
        };
        let local_t = motion.timing.local(t);
        let mut offset = DVec3::ZERO;
        if let Some(e) = &mut self.motion[0] {
            let mut xyz = [0.0; 3];
            e.eval_all([0.0, 0.0, 0.0, local_t], &mut xyz);
            offset = DVec3::from_array(xyz);
        }
        let mut rotation = DQuat::IDENTITY;
        if let Some(e) = &mut self.motion[1] {
            let angle = e.eval([0.0, 0.0, 0.0, local_t]);
            if angle.is_finite() {
                rotation = DQuat::from_axis_angle(motion.axis.normalize(), angle);
            }
        }
        if !offset.is_finite() {
            offset = DVec3::ZERO;
        }
        Transform::from_trs(offset, rotation, DVec3::ONE).then(&data.transform)
    }
}

/// The force field's domain and its space (see [`Sampler::field_domain`]).
fn field_domain(object: &Object) -> (super::Domain, Transform) {
    let data = object.data();
    let shape = data
        .physics
        .container
        .as_ref()
        .or(data.geometry.as_ref())
        .filter(|g| g.domain.is_some());
    match shape {
        Some(g) => (g.domain.unwrap_or(super::Domain::UNIT), g.transform),
        None => (
            data.physics.domain.unwrap_or(super::Domain::UNIT),
            data.physics.transform,
        ),
    }
}
