//! [`ObjectField`]: a [`model::object::Object`] (its geometry folded with its edit history)
//! as a [`Field`] for the octree mesher, and the boxes an edit dirties, for
//! [`OctreeMesher::remesh`](super::octree::OctreeMesher::remesh).
//!
//! An object with edits goes through model's [`Sampler`], restricted to each octree node the
//! mesher visits: [`Field::simplify`] hands each node a field over model's [`BoxSampler`] for
//! the node's box (the edits whose boxes overlap it, gathered once from the history's index or
//! from the parent node's list; the geometry's tape simplified for the box where that is
//! exact), whose `values` and `gradients` fold each edit over the whole batch of points and
//! run the geometry's tape over all of them at once. Its values are the sampler's bit for bit
//! (f64, rounded to f32 here), so a remesh may mix restricted and unrestricted fields. Before
//! the first restriction (the root's interval) the field asks the sampler directly. An
//! implicit geometry without edits is evaluated in f32 in bulk instead, through its tape (see
//! [`ObjectField::new`]).
//!
//! Incremental meshing rests on a property of the fold: an edit changes the solid only inside
//! its boxes ([`CompiledEdit::boxes`], which include the tool's margin and blend radius),
//! except an intersection, which empties everything outside its tool. So after a union or a
//! subtraction only the blocks those boxes touch are evaluated again
//! ([`dirty_boxes`]); after an intersection, the whole object is.

use glam::{DAffine3, DVec3};
use model::object::{BoxSampler, CompiledEdit, Domain, EditOp, Object, Sampler, Shape, Slot};

use super::Aabb;
use super::field::Field;
use super::tape_field::{TapeField, outward};

/// An object's solid at a fixed time `t`, in object space, f >= 0 inside.
pub struct ObjectField {
    inner: Inner,
}

enum Inner {
    /// Geometry and edits, through model's sampler, one point at a time.
    Sampler { sampler: Box<Sampler>, t: f64 },
    /// Geometry and edits restricted to an octree node's box, in bulk.
    Region(Box<RegionField>),
    /// An implicit geometry without edits, through fdsl's bulk evaluators.
    Shape(Box<ShapeField>),
}

impl ObjectField {
    /// A field over `object` as it is now (later edits do not reach it) at time `t_secs`.
    ///
    /// An implicit geometry without active shape edits is evaluated in bulk (f32, fdsl's
    /// `BulkEval`, with tape simplification per box), like [`TapeField`],
    /// through its transform and clipped by its domain as model's `Sampler` does; anything
    /// else goes through the sampler (f64), restricted to each octree node's box by
    /// [`Field::simplify`] (see the module documentation). The two agree to f32 rounding, so
    /// keep one object on one path while remeshing it incrementally.
    pub fn new(object: &Object, t_secs: f64) -> ObjectField {
        let bulk = ShapeField::of(object, t_secs).map(|s| Inner::Shape(Box::new(s)));
        ObjectField {
            inner: bulk.unwrap_or_else(|| Inner::Sampler {
                sampler: Box::new(object.sampler()),
                t: t_secs,
            }),
        }
    }

    /// A field over the object `sampler` evaluates (always through the sampler, restricted to
    /// boxes by [`Field::simplify`]), at time `t_secs`.
    pub fn from_sampler(sampler: Sampler, t_secs: f64) -> ObjectField {
        ObjectField {
            inner: Inner::Sampler {
                sampler: Box::new(sampler),
                t: t_secs,
            },
        }
    }

    /// Whether values come from fdsl's bulk evaluators (else from the sampler).
    pub fn is_bulk(&self) -> bool {
        matches!(self.inner, Inner::Shape(_))
    }
}

fn point(x: f32, y: f32, z: f32) -> DVec3 {
    DVec3::new(x.into(), y.into(), z.into())
}

impl Field for ObjectField {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let region = f64_box(lo, hi);
        let iv = match &mut self.inner {
            Inner::Shape(s) => return s.interval(lo, hi),
            Inner::Sampler { sampler, t } => sampler.interval(&region, *t),
            Inner::Region(r) => r.sampler.interval(&region),
        };
        if iv.nan || iv.lo.is_nan() || iv.hi.is_nan() {
            (f32::NAN, f32::NAN)
        } else {
            outward(iv.lo, iv.hi)
        }
    }

    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        let (sampler, t) = match &mut self.inner {
            Inner::Shape(s) => return s.values(xs, ys, zs, out),
            Inner::Region(r) => return r.values(xs, ys, zs, out),
            Inner::Sampler { sampler, t } => (sampler, *t),
        };
        for (i, o) in out.iter_mut().enumerate().take(xs.len()) {
            *o = sampler.value(point(xs[i], ys[i], zs[i]), t) as f32;
        }
    }

    fn gradients(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [[f32; 3]]) {
        let (sampler, t) = match &mut self.inner {
            Inner::Shape(s) => return s.gradients(xs, ys, zs, out),
            Inner::Region(r) => return r.gradients(xs, ys, zs, out),
            Inner::Sampler { sampler, t } => (sampler, *t),
        };
        for (i, o) in out.iter_mut().enumerate().take(xs.len()) {
            let (_, g) = sampler.gradient(point(xs[i], ys[i], zs[i]), t);
            *o = g.to_array().map(|c| c as f32);
        }
    }

    fn fork(&self) -> Option<Self> {
        match &self.inner {
            Inner::Shape(s) => Some(ObjectField {
                inner: Inner::Shape(s.clone()),
            }),
            Inner::Sampler { sampler, t } => Some(ObjectField::from_sampler(
                Sampler::new(sampler.object().clone()),
                *t,
            )),
            // Never asked: a region's field always simplifies.
            Inner::Region(_) => None,
        }
    }

    fn simplify(&mut self, lo: [f32; 3], hi: [f32; 3]) -> Option<Self> {
        match &mut self.inner {
            Inner::Shape(s) => s.simplify(lo, hi).map(|s| ObjectField {
                inner: Inner::Shape(Box::new(s)),
            }),
            Inner::Sampler { sampler, t } => {
                let restricted = sampler.restrict(&f64_box(lo, hi), *t);
                Some(RegionField::field(restricted))
            }
            Inner::Region(r) => Some(RegionField::field(r.sampler.restrict(&f64_box(lo, hi)))),
        }
    }
}

/// The box `lo..=hi` in double precision (exactly).
fn f64_box(lo: [f32; 3], hi: [f32; 3]) -> model::bvh::Aabb {
    model::bvh::Aabb::new(point(lo[0], lo[1], lo[2]), point(hi[0], hi[1], hi[2]))
}

/// The object restricted to an octree node's box, with scratch space for batches of points.
struct RegionField {
    sampler: BoxSampler,
    points: Vec<DVec3>,
    values: Vec<f64>,
    gradients: Vec<(f64, DVec3)>,
}

impl RegionField {
    fn field(sampler: BoxSampler) -> ObjectField {
        ObjectField {
            inner: Inner::Region(Box::new(RegionField {
                sampler,
                points: Vec::new(),
                values: Vec::new(),
                gradients: Vec::new(),
            })),
        }
    }

    fn load(&mut self, xs: &[f32], ys: &[f32], zs: &[f32]) {
        self.points.clear();
        self.points
            .extend((0..xs.len()).map(|i| point(xs[i], ys[i], zs[i])));
    }

    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        self.load(xs, ys, zs);
        self.values.resize(self.points.len(), 0.0);
        self.sampler.values(&self.points, &mut self.values);
        for (o, v) in out.iter_mut().zip(&self.values) {
            *o = *v as f32;
        }
    }

    fn gradients(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [[f32; 3]]) {
        self.load(xs, ys, zs);
        self.gradients.resize(self.points.len(), (0.0, DVec3::ZERO));
        self.sampler.gradients(&self.points, &mut self.gradients);
        for (o, (_, g)) in out.iter_mut().zip(&self.gradients) {
            *o = g.to_array().map(|c| c as f32);
        }
    }
}

/// An implicit geometry's tape in its own space, mapped from object space by the inverse of
/// its transform and clipped by its domain: `min(f(q), domain distance(q))`, `q` the local
/// point, as model's sampler evaluates a shape.
#[derive(Clone)]
struct ShapeField {
    tape: TapeField,
    local_from_object: DAffine3,
    identity: bool,
    domain: Option<Domain>,
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
}

impl ShapeField {
    /// The bulk field of `object`'s geometry when it is implicit and no active edit changes
    /// its shape; `None` otherwise.
    fn of(object: &Object, t: f64) -> Option<ShapeField> {
        let geometry = object.data().geometry.as_ref()?;
        if !matches!(geometry.shape, Shape::Implicit(_)) {
            return None;
        }
        let edited = object
            .history()
            .entries()
            .iter()
            .any(|e| e.active && e.edit.is_geometric());
        if edited {
            return None;
        }
        // The tape the object compiled when its geometry was set: nothing is compiled here.
        let tape = object.tape(Slot::Geometry)?;
        let local_from_object = geometry.transform.inverse()?.parent_from_child;
        Some(ShapeField {
            tape: TapeField::new(tape, t as f32),
            identity: local_from_object == DAffine3::IDENTITY,
            local_from_object,
            domain: geometry.domain,
            xs: Vec::new(),
            ys: Vec::new(),
            zs: Vec::new(),
        })
    }

    /// Maps the points into local space, into the scratch vectors.
    fn map_to_local(&mut self, xs: &[f32], ys: &[f32], zs: &[f32]) {
        self.xs.clear();
        self.ys.clear();
        self.zs.clear();
        for i in 0..xs.len() {
            let q = self
                .local_from_object
                .transform_point3(point(xs[i], ys[i], zs[i]));
            self.xs.push(q.x as f32);
            self.ys.push(q.y as f32);
            self.zs.push(q.z as f32);
        }
    }

    /// The local box around the object-space box `lo..=hi`.
    fn local_box(&self, lo: [f32; 3], hi: [f32; 3]) -> ([f32; 3], [f32; 3]) {
        if self.identity {
            return (lo, hi);
        }
        let region = model::bvh::Aabb::new(point(lo[0], lo[1], lo[2]), point(hi[0], hi[1], hi[2]));
        let local = model::object::Transform {
            parent_from_child: self.local_from_object,
        }
        .aabb(&region);
        (
            local.lo.to_array().map(|v| (v as f32).next_down()),
            local.hi.to_array().map(|v| (v as f32).next_up()),
        )
    }

    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let (llo, lhi) = self.local_box(lo, hi);
        let (f_lo, f_hi) = self.tape.interval(llo, lhi);
        match &self.domain {
            Some(d) if !(f_lo.is_nan() || f_hi.is_nan()) => {
                // As fdsl bounds the domain term: its distance changes by at most the distance
                // moved from the box's centre.
                let (clo, chi) = (point(llo[0], llo[1], llo[2]), point(lhi[0], lhi[1], lhi[2]));
                let c = d.signed_distance(0.5 * (clo + chi));
                let r = 0.5 * (chi - clo).length();
                let (d_lo, d_hi) = outward(c - r, c + r);
                (f_lo.min(d_lo), f_hi.min(d_hi))
            }
            _ => (f_lo, f_hi),
        }
    }

    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        if self.identity && self.domain.is_none() {
            return self.tape.values(xs, ys, zs, out);
        }
        self.map_to_local(xs, ys, zs);
        self.tape.values(&self.xs, &self.ys, &self.zs, out);
        if let Some(d) = &self.domain {
            for (i, o) in out.iter_mut().enumerate() {
                let q = point(self.xs[i], self.ys[i], self.zs[i]);
                *o = o.min(d.signed_distance(q) as f32);
            }
        }
    }

    fn gradients(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [[f32; 3]]) {
        self.map_to_local(xs, ys, zs);
        let n = xs.len();
        self.tape.gradients(&self.xs, &self.ys, &self.zs, out);
        if let Some(d) = self.domain {
            let mut f = vec![0.0f32; n];
            self.tape.values(&self.xs, &self.ys, &self.zs, &mut f);
            let h = 1e-6 * d.size.max_element();
            for (i, g) in out.iter_mut().enumerate() {
                let q = point(self.xs[i], self.ys[i], self.zs[i]);
                if d.signed_distance(q) < f64::from(f[i]) {
                    let axis = |a: DVec3| {
                        (d.signed_distance(q + a * h) - d.signed_distance(q - a * h)) / (2.0 * h)
                    };
                    *g = [axis(DVec3::X), axis(DVec3::Y), axis(DVec3::Z)].map(|c| c as f32);
                }
            }
        }
        if !self.identity {
            // The chain rule: the object-space gradient is J^T times the local one.
            let jt = self.local_from_object.matrix3.transpose();
            for g in out.iter_mut() {
                let v = jt * DVec3::from_array(g.map(f64::from));
                *g = v.to_array().map(|c| c as f32);
            }
        }
    }

    fn simplify(&mut self, lo: [f32; 3], hi: [f32; 3]) -> Option<ShapeField> {
        let (llo, lhi) = self.local_box(lo, hi);
        let tape = self.tape.simplify(llo, lhi)?;
        Some(ShapeField {
            tape,
            local_from_object: self.local_from_object,
            identity: self.identity,
            domain: self.domain,
            xs: Vec::new(),
            ys: Vec::new(),
            zs: Vec::new(),
        })
    }
}

/// The box `b` in single precision, rounded outwards; `None` when empty or not finite.
pub fn to_f32_box(b: &model::bvh::Aabb) -> Option<Aabb> {
    if b.is_empty() || !(b.lo.is_finite() && b.hi.is_finite()) {
        return None;
    }
    let lo = b.lo.to_array().map(|v| (v as f32).next_down());
    let hi = b.hi.to_array().map(|v| (v as f32).next_up());
    Some(Aabb::new(lo, hi))
}

/// Where the solid may have changed when `edit` was applied, undone or redone.
#[derive(Clone, Debug, PartialEq)]
pub enum Dirty {
    /// Only inside these boxes (none for a painting, which changes colours, not the shape).
    Boxes(Vec<Aabb>),
    /// Anywhere: an intersection empties everything outside its tool.
    Everywhere,
}

/// The region `edit` changes (see [`Dirty`]); remesh each box in turn.
pub fn dirty_boxes(edit: &CompiledEdit) -> Dirty {
    match edit.edit().op {
        EditOp::Intersect => Dirty::Everywhere,
        EditOp::Paint { .. } => Dirty::Boxes(Vec::new()),
        EditOp::Union | EditOp::Subtract => {
            Dirty::Boxes(edit.boxes().iter().filter_map(to_f32_box).collect())
        }
    }
}

/// A box to mesh `object` in at octree `depth`: its bounds (domain and union edits, object
/// space) grown by about two and a half cells, so that a surface clipped by the domain lies
/// strictly inside and the mesh is closed. `None` for an unbounded solid (an implicit
/// formula without a domain) or an empty one.
pub fn mesh_bounds(object: &Object, depth: u8) -> Option<Aabb> {
    let b = to_f32_box(&object.bounds()?)?;
    let side = b.size().into_iter().fold(0.0f32, f32::max);
    if !(side.is_finite() && side > 0.0) {
        return None;
    }
    let n_cells = (1u32 << depth.min(super::octree::MAX_OCTREE_DEPTH)) as f32;
    // Solving side + 2m = n * (m / 2.5) for the margin m keeps 2.5 cells of the grown box.
    let margin = 2.5 * side / (n_cells - 5.0).max(1.0);
    Some(Aabb::new(
        b.lo.map(|v| v - margin),
        b.hi.map(|v| v + margin),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::octree::{MeshSettings, OctreeMesher, mesh_with_stats};
    use crate::mesh::{Mesh, octree};
    use model::object::{Edit, Formula, Geometry, ObjectData, Pose, ToolShape};
    use std::sync::Arc;

    /// The unit ball clipped to a domain (so its bounds are finite).
    fn ball() -> Object {
        Object::new(ObjectData {
            geometry: Some(Geometry::implicit_in(
                Formula::new("1-sqrt(x^2+y^2+z^2)").unwrap(),
                Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
            )),
            ..ObjectData::default()
        })
        .unwrap()
    }

    /// Edit `k` of `n`: a carve (or every fifth a blob added) on the unit sphere along a
    /// golden-angle spiral, alternating single stamps and short strokes.
    fn edit(k: usize, n: usize) -> Edit {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let y = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
        let ring = (1.0 - y * y).max(0.0).sqrt();
        let phi = golden * k as f64;
        let at = DVec3::new(ring * phi.cos(), y, ring * phi.sin());
        let op = if k % 5 == 4 {
            EditOp::Union
        } else {
            EditOp::Subtract
        };
        let tool = ToolShape::Sphere { radius: 0.09 };
        if k.is_multiple_of(2) {
            Edit::stamp(op, tool, Pose::at(at))
        } else {
            let side = at.any_orthonormal_vector() * 0.08;
            Edit::stroke(op, tool, vec![Pose::at(at - side), Pose::at(at + side)])
        }
    }

    fn settings(depth: u8) -> MeshSettings {
        MeshSettings {
            bounds: Aabb::new([-1.25; 3], [1.25; 3]),
            depth,
        }
    }

    fn assert_closed(m: &Mesh, what: &str) {
        assert!(m.n_triangles() > 0, "{what}: empty");
        assert_eq!(m.open_edges(), 0, "{what}: open edges");
        assert_eq!(m.non_manifold_edges(), 0, "{what}: non-manifold edges");
        assert_eq!(m.misoriented_edges(), 0, "{what}: inconsistent winding");
    }

    /// Remeshes the boxes `dirty` with `field`; returns the blocks evaluated again, those
    /// kept unchanged next to them, and the nodes whose intervals were not asked.
    fn remesh(
        mesher: &mut OctreeMesher,
        field: &mut ObjectField,
        dirty: &Dirty,
    ) -> (usize, usize, usize) {
        let boxes = match dirty {
            Dirty::Boxes(boxes) => boxes.clone(),
            Dirty::Everywhere => vec![settings(6).bounds],
        };
        boxes.iter().fold((0, 0, 0), |(e, u, s), b| {
            let stats = mesher.remesh(field, *b).unwrap();
            (
                e + stats.blocks_evaluated,
                u + stats.blocks_unchanged,
                s + stats.intervals_skipped,
            )
        })
    }

    /// Whether two meshes have the same triangles over vertices within `tolerance`.
    fn same_surface(a: &Mesh, b: &Mesh, tolerance: f32) -> bool {
        a.n_triangles() == b.n_triangles()
            && a.n_vertices() == b.n_vertices()
            && a.indices == b.indices
            && a.positions
                .iter()
                .zip(&b.positions)
                .all(|(p, q)| (0..3).all(|k| (p[k] - q[k]).abs() <= tolerance))
    }

    #[test]
    fn object_field_agrees_with_the_sampler_and_bounds_it() {
        let mut object = ball();
        for k in 0..50 {
            object.apply(edit(k, 50)).unwrap();
        }
        object.prepare();
        let mut field = ObjectField::new(&object, 0.0);
        let mut sampler = object.sampler();
        let xs: Vec<f32> = (0..64).map(|i| -1.1 + 2.2 * i as f32 / 63.0).collect();
        let ys: Vec<f32> = xs.iter().map(|x| 0.3 * x).collect();
        let zs: Vec<f32> = xs.iter().map(|x| 0.5 - 0.2 * x).collect();
        let mut out = vec![0.0; 64];
        field.values(&xs, &ys, &zs, &mut out);
        for i in 0..64 {
            let p = point(xs[i], ys[i], zs[i]);
            assert_eq!(out[i], sampler.value(p, 0.0) as f32);
        }
        let (lo, hi) = field.interval([-0.2, 0.1, 0.7], [0.1, 0.4, 1.05]);
        for i in 0..64 {
            let p = [
                -0.2 + 0.3 * (i % 4) as f32 / 3.0,
                0.1 + 0.3 * (i / 16) as f32 / 3.0,
                0.7,
            ];
            let mut v = [0.0];
            field.values(&[p[0]], &[p[1]], &[p[2]], &mut v);
            assert!(lo <= v[0] && v[0] <= hi, "{v:?} outside {lo}..{hi}");
        }
        let mut grads = vec![[0.0; 3]; 1];
        field.gradients(&[0.0], &[0.0], &[0.5], &mut grads);
        assert!((grads[0][2] + 1.0).abs() < 1e-3, "{grads:?}");
    }

    #[test]
    fn a_field_restricted_to_a_box_gives_the_sampler_values_bit_for_bit() {
        let mut object = ball();
        for k in 0..300 {
            object.apply(edit(k, 300)).unwrap();
        }
        object.prepare();
        let mut sampler = object.sampler();
        let mut field = ObjectField::new(&object, 0.0);
        // The root, then a node of it, as the mesher simplifies them.
        let (lo, hi) = ([0.3f32, 0.2, 0.5], [0.8f32, 0.7, 1.0]);
        let mut node = field.simplify([-1.25; 3], [1.25; 3]).unwrap();
        let mut block = node.simplify(lo, hi).unwrap();
        let n = 9;
        let at = |i: usize, a: usize| lo[a] + (hi[a] - lo[a]) * ((i * (a + 2)) % n) as f32 / 8.0;
        // Lattice points of the box, its corners, and two points outside it.
        let mut xs: Vec<f32> = (0..n * n).map(|i| at(i, 0)).collect();
        let mut ys: Vec<f32> = (0..n * n).map(|i| at(i / n, 1)).collect();
        let mut zs: Vec<f32> = (0..n * n).map(|i| at(i % 7, 2)).collect();
        xs.extend([lo[0], hi[0], 1.2, 0.0]);
        ys.extend([lo[1], hi[1], 0.0, -0.9]);
        zs.extend([lo[2], hi[2], 0.1, 0.3]);
        let m = xs.len();
        let mut values = vec![0.0; m];
        block.values(&xs, &ys, &zs, &mut values);
        let mut grads = vec![[0.0; 3]; m];
        block.gradients(&xs, &ys, &zs, &mut grads);
        for i in 0..m {
            let p = point(xs[i], ys[i], zs[i]);
            assert_eq!(
                values[i].to_bits(),
                (sampler.value(p, 0.0) as f32).to_bits()
            );
            let g = sampler.gradient(p, 0.0).1.to_array().map(|c| c as f32);
            assert_eq!(grads[i], g, "at {p}");
        }
        let (sub_lo, sub_hi) = ([0.4, 0.3, 0.6], [0.6, 0.5, 0.8]);
        assert_eq!(
            block.interval(sub_lo, sub_hi),
            field.interval(sub_lo, sub_hi)
        );
    }

    #[test]
    fn an_unedited_implicit_geometry_is_evaluated_in_bulk_like_the_sampler() {
        use model::object::Transform;
        // A squashed, turned and moved ball clipped by a domain that cuts it.
        let object = Object::new(ObjectData {
            geometry: Some(Geometry {
                shape: Shape::Implicit(Formula::new("0.8-sqrt(x^2+y^2+z^2)").unwrap()),
                domain: Some(Domain::new(DVec3::new(0.0, 0.3, 0.0), DVec3::splat(1.6))),
                transform: Transform::from_trs(
                    DVec3::new(0.2, -0.1, 0.05),
                    glam::DQuat::from_rotation_z(0.6),
                    DVec3::new(1.0, 0.7, 1.2),
                ),
            }),
            ..ObjectData::default()
        })
        .unwrap();
        let mut bulk = ObjectField::new(&object, 0.0);
        let mut slow = ObjectField::from_sampler(object.sampler(), 0.0);
        assert!(bulk.is_bulk() && !slow.is_bulk());
        let n = 200;
        let xs: Vec<f32> = (0..n)
            .map(|i| -1.0 + 2.0 * (i as f32 * 0.618).fract())
            .collect();
        let ys: Vec<f32> = (0..n)
            .map(|i| -1.0 + 2.0 * (i as f32 * 0.414).fract())
            .collect();
        let zs: Vec<f32> = (0..n)
            .map(|i| -1.0 + 2.0 * (i as f32 * 0.732).fract())
            .collect();
        let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
        bulk.values(&xs, &ys, &zs, &mut a);
        slow.values(&xs, &ys, &zs, &mut b);
        let (mut ga, mut gb) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        bulk.gradients(&xs, &ys, &zs, &mut ga);
        slow.gradients(&xs, &ys, &zs, &mut gb);
        for i in 0..n {
            assert!((a[i] - b[i]).abs() < 1e-5, "{i}: {} vs {}", a[i], b[i]);
            for k in 0..3 {
                assert!(
                    (ga[i][k] - gb[i][k]).abs() < 1e-3,
                    "{i}: {:?} vs {:?}",
                    ga[i],
                    gb[i]
                );
            }
        }
        let (lo, hi) = bulk.interval([-0.5, -0.2, 0.1], [0.1, 0.4, 0.6]);
        for i in 0..n {
            let p = [
                -0.5 + 0.6 * xs[i].abs(),
                -0.2 + 0.6 * ys[i].abs(),
                0.1 + 0.5 * zs[i].abs(),
            ];
            let mut v = [0.0];
            bulk.values(&[p[0]], &[p[1]], &[p[2]], &mut v);
            assert!(lo <= v[0] && v[0] <= hi, "{v:?} outside {lo}..{hi}");
        }
        // Both mesh to the same closed solid.
        let settings = settings(5);
        let m_bulk = octree::mesh(&mut bulk, &settings).unwrap();
        let m_slow = octree::mesh(&mut slow, &settings).unwrap();
        assert_closed(&m_bulk, "bulk");
        assert_closed(&m_slow, "sampler");
        let (va, vb) = (m_bulk.signed_volume(), m_slow.signed_volume());
        assert!((va - vb).abs() < 1e-3 * vb, "{va} vs {vb}");
        // An edit sends the object through the sampler.
        let mut edited = object.clone();
        edited.apply(edit(0, 10)).unwrap();
        assert!(!ObjectField::new(&edited, 0.0).is_bulk());
    }

    /// After one more edit on an object of 200, remeshing the edit's boxes gives exactly the
    /// mesh that meshing the whole edited object gives; remeshing only the centre of the
    /// edit's box does not, so the comparison catches blocks a remesh misses. Depth 6, since
    /// at depth 5 one block (8 cells, 0.625 units) holds most of an edit's box.
    #[test]
    fn remeshing_an_edit_of_a_200_edit_object_equals_a_full_remesh() {
        let depth = 6;
        let mut object = ball();
        let n = 200;
        for k in 0..n {
            object.apply(edit(k, n)).unwrap();
        }
        object.prepare();
        let mut mesher = OctreeMesher::new(&settings(depth)).unwrap();
        let full_before = mesher
            .remesh(&mut ObjectField::new(&object, 0.0), settings(depth).bounds)
            .unwrap();
        let before = mesher.mesh().unwrap();
        assert_closed(&before, "before");

        // A deep carve between two earlier edits, and a blob added elsewhere.
        let extra = [
            Edit::stroke(
                EditOp::Subtract,
                ToolShape::Sphere { radius: 0.15 },
                vec![
                    Pose::at(DVec3::new(0.55, 0.55, 0.55)),
                    Pose::at(DVec3::new(0.7, 0.45, 0.4)),
                ],
            ),
            Edit::stamp(
                EditOp::Union,
                ToolShape::Box {
                    half_extents: DVec3::new(0.12, 0.1, 0.14),
                    rounding: 0.03,
                },
                Pose::at(DVec3::new(-0.3, -0.95, 0.1)),
            ),
        ];
        let mut previous = before;
        for e in extra {
            let idx = object.apply(e).unwrap();
            object.prepare();
            let dirty = dirty_boxes(&object.history().entries()[idx].edit);
            assert!(matches!(&dirty, Dirty::Boxes(b) if b.len() == 1));

            // Too small a box: only the centre of the edit's box.
            let Dirty::Boxes(boxes) = &dirty else {
                unreachable!()
            };
            let centre = boxes[0].centre();
            let too_small = Aabb::new(centre, centre);

            let mut field = ObjectField::new(&object, 0.0);
            let (full, full_stats) = mesh_with_stats(&mut field, &settings(depth)).unwrap();
            assert_closed(&full, "full");
            assert!(
                !same_surface(&full, &previous, 1e-6),
                "the edit must change the mesh"
            );

            let mut wrong = OctreeMesher::new(&settings(depth)).unwrap();
            let mut old = object.clone();
            old.undo(idx);
            wrong
                .remesh(&mut ObjectField::new(&old, 0.0), settings(depth).bounds)
                .unwrap();
            wrong
                .remesh(&mut ObjectField::new(&object, 0.0), too_small)
                .unwrap();
            assert!(
                !same_surface(&wrong.mesh().unwrap(), &full, 1e-6),
                "a remesh of part of the edit's box must differ from the full mesh"
            );

            let (n_evaluated, n_unchanged, n_skipped) = remesh(&mut mesher, &mut field, &dirty);
            // Some blocks above the range read none of its changed values: kept as they were.
            assert!(n_unchanged > 0, "no block was kept");
            // The nodes above the edit's blocks hold the rest of the ball's surface: none of
            // their intervals is asked, and the mesh is still the full mesh (below).
            assert!(n_skipped > 0, "every node's interval was asked");
            let remeshed = mesher.mesh().unwrap();
            assert_closed(&remeshed, "remeshed");
            assert!(
                n_evaluated < full_stats.blocks_evaluated && n_evaluated > 0,
                "{n_evaluated} blocks evaluated again of {} ({full_before:?})",
                full_stats.blocks_evaluated
            );
            assert!(
                same_surface(&remeshed, &full, 1e-6),
                "remeshed {} triangles, full {}",
                remeshed.n_triangles(),
                full.n_triangles()
            );
            previous = remeshed;
        }
        // Undoing an edit is remeshed through the same boxes.
        let last = object.history().len() - 1;
        let dirty = dirty_boxes(&object.history().entries()[last].edit);
        object.undo(last);
        remesh(&mut mesher, &mut ObjectField::new(&object, 0.0), &dirty);
        let full = octree::mesh(&mut ObjectField::new(&object, 0.0), &settings(depth)).unwrap();
        assert!(same_surface(&mesher.mesh().unwrap(), &full, 1e-6));
    }

    use testkit::rng::XorShift64 as Rng;

    /// A point on the sphere of radius `r`, drawn from `rng`.
    fn on_sphere(rng: &mut Rng, r: f64) -> DVec3 {
        let y = 2.0 * rng.unit_f64() - 1.0;
        let phi = std::f64::consts::TAU * rng.unit_f64();
        let ring = (1.0 - y * y).max(0.0).sqrt();
        r * DVec3::new(ring * phi.cos(), y, ring * phi.sin())
    }

    /// One random step of a sculpting session on `object`: mostly carves and added blobs
    /// (stamps and strokes, balls and boxes), sometimes a painting, an undo or a redo of an
    /// earlier edit. Returns what to remesh and what the step was.
    fn random_step(object: &mut Object, rng: &mut Rng) -> (Dirty, &'static str) {
        let roll = rng.next_u64() % 10;
        let n = object.history().len();
        if roll == 0 {
            let idx = (rng.next_u64() % n as u64) as usize;
            let entry = &object.history().entries()[idx];
            let (dirty, active) = (dirty_boxes(&entry.edit), entry.active);
            if active {
                object.undo(idx);
            } else {
                object.redo(idx);
            }
            object.prepare();
            return (dirty, if active { "undo" } else { "redo" });
        }
        let r = 0.9 + 0.15 * rng.unit_f64();
        let at = on_sphere(rng, r);
        let (op, what) = match roll {
            1 => (
                EditOp::Paint {
                    property: model::object::Paintable::Color,
                    value: model::object::PaintValue::Color([1.0, 0.2, 0.1]),
                },
                "paint",
            ),
            2 | 3 => (EditOp::Union, "union"),
            _ => (EditOp::Subtract, "carve"),
        };
        let tool = if rng.next_u64().is_multiple_of(3) {
            ToolShape::Box {
                half_extents: DVec3::new(0.08, 0.06, 0.1) * (0.5 + rng.unit_f64()),
                rounding: 0.02,
            }
        } else {
            ToolShape::Sphere {
                radius: 0.04 + 0.12 * rng.unit_f64(),
            }
        };
        let e = if rng.next_u64().is_multiple_of(2) {
            Edit::stamp(op, tool, Pose::at(at))
        } else {
            let side = at.any_orthonormal_vector() * (0.2 * rng.unit_f64());
            Edit::stroke(op, tool, vec![Pose::at(at - side), Pose::at(at + side)])
        };
        let idx = object.apply(e).unwrap();
        object.prepare();
        (dirty_boxes(&object.history().entries()[idx].edit), what)
    }

    /// The triangles of `m` as their corners (position, normal, colour), each triangle
    /// starting at its smallest corner (winding kept), sorted: equal for meshes with the same
    /// triangles in any order over any numbering of the vertices.
    fn canonical_triangles(m: &Mesh) -> Vec<[[f32; 10]; 3]> {
        let corner = |i: u32| -> [f32; 10] {
            let (p, n, c) = (
                m.positions[i as usize],
                m.normals[i as usize],
                m.colours[i as usize],
            );
            [p[0], p[1], p[2], n[0], n[1], n[2], c[0], c[1], c[2], c[3]]
        };
        let cmp = |a: &[f32; 10], b: &[f32; 10]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| x.total_cmp(y))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
        };
        let mut out: Vec<[[f32; 10]; 3]> = m
            .triangles()
            .map(|t| {
                let c = t.map(corner);
                let first = (0..3).min_by(|&i, &j| cmp(&c[i], &c[j])).unwrap();
                std::array::from_fn(|k| c[(first + k) % 3])
            })
            .collect();
        out.sort_by(|a, b| {
            (0..3)
                .map(|k| cmp(&a[k], &b[k]))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        out
    }

    /// Whether `a` and `b` have the same triangles (corners within `tolerance`), whatever
    /// their order and vertex numbering.
    fn same_triangles(a: &Mesh, b: &Mesh, tolerance: f32) -> bool {
        let (ta, tb) = (canonical_triangles(a), canonical_triangles(b));
        ta.len() == tb.len()
            && ta.iter().zip(&tb).all(|(x, y)| {
                (0..3).all(|k| (0..10).all(|c| (x[k][c] - y[k][c]).abs() <= tolerance))
            })
    }

    /// What a renderer holding `uploaded` (the mesh before the patch) has after copying
    /// only the patch's ranges from `mesh`.
    fn upload(uploaded: &mut Mesh, mesh: &Mesh, patch: &octree::MeshPatch) {
        // Anything the ranges do not cover keeps this mark and breaks the comparison.
        let mark = [-7.0f32; 3];
        uploaded.positions.resize(patch.n_vertices, mark);
        uploaded.normals.resize(patch.n_vertices, mark);
        uploaded.colours.resize(patch.n_vertices, [-7.0; 4]);
        uploaded.indices.resize(3 * patch.n_triangles, u32::MAX);
        for r in &patch.vertex_ranges {
            uploaded.positions[r.clone()].copy_from_slice(&mesh.positions[r.clone()]);
            uploaded.normals[r.clone()].copy_from_slice(&mesh.normals[r.clone()]);
            uploaded.colours[r.clone()].copy_from_slice(&mesh.colours[r.clone()]);
        }
        for r in &patch.triangle_ranges {
            let r = 3 * r.start..3 * r.end;
            uploaded.indices[r.clone()].copy_from_slice(&mesh.indices[r]);
        }
    }

    /// Remeshes what one random step of a session dirtied, for `steps` steps from a
    /// 200-edit object at depth 6, patching a mesh with `patch` after each; returns how many
    /// patched meshes had other triangles than [`OctreeMesher::mesh`] or were not closed.
    fn patched_session(
        seed: u64,
        steps: usize,
        mut patch: impl FnMut(&mut OctreeMesher, &mut Mesh) -> octree::MeshPatch,
    ) -> usize {
        let depth = 6;
        let mut object = ball();
        for k in 0..200 {
            object.apply(edit(k, 200)).unwrap();
        }
        object.prepare();
        let mut mesher = OctreeMesher::new(&settings(depth)).unwrap();
        mesher
            .remesh(&mut ObjectField::new(&object, 0.0), settings(depth).bounds)
            .unwrap();
        let mut patched = Mesh::default();
        let first = patch(&mut mesher, &mut patched);
        assert!(first.full, "the first patch assembles everything");
        assert!(same_triangles(&patched, &mesher.mesh().unwrap(), 0.0));
        let (mut rng, mut n_wrong, mut n_partial) = (Rng(seed), 0, 0);
        for step in 0..steps {
            // An intersection midway: it dirties everything, so the patch is whole again.
            let (dirty, what) = if step == steps / 2 {
                let e = Edit::stamp(
                    EditOp::Intersect,
                    ToolShape::Sphere { radius: 1.02 },
                    Pose::at(DVec3::new(0.1, 0.0, 0.0)),
                );
                let idx = object.apply(e).unwrap();
                object.prepare();
                (
                    dirty_boxes(&object.history().entries()[idx].edit),
                    "intersect",
                )
            } else {
                random_step(&mut object, &mut rng)
            };
            remesh(&mut mesher, &mut ObjectField::new(&object, 0.0), &dirty);
            let mut uploaded = patched.clone();
            let p = patch(&mut mesher, &mut patched);
            let full = mesher.mesh().unwrap();
            assert_eq!(patched.validate(), Ok(()), "step {step} ({what})");
            let right = same_triangles(&patched, &full, 1e-6)
                && patched.open_edges() == 0
                && patched.non_manifold_edges() == 0
                && patched.misoriented_edges() == 0;
            n_wrong += usize::from(!right);
            // The ranges hold everything that changed: a renderer copying only them has it.
            upload(&mut uploaded, &patched, &p);
            assert!(
                uploaded == patched,
                "step {step} ({what}): ranges miss a change"
            );
            assert_eq!(p.full, what == "intersect", "step {step} ({what}): {p:?}");
            if what == "paint" {
                assert_eq!(p.n_triangles_written() + p.n_vertices_written(), 0);
            }
            if !p.full && p.n_triangles_written() > 0 {
                n_partial += 1;
                assert!(
                    p.n_triangles_written() < p.n_triangles / 2,
                    "step {step} ({what}): {} of {} triangles written",
                    p.n_triangles_written(),
                    p.n_triangles
                );
            }
            // Unreferenced vertices stay bounded.
            let mut used = patched.indices.clone();
            used.sort_unstable();
            used.dedup();
            assert!(
                2 * patched.n_vertices() <= 3 * used.len() + 2,
                "step {step}: {} vertices, {} used",
                patched.n_vertices(),
                used.len()
            );
        }
        assert!(n_partial > steps / 2, "{n_partial} partial patches");
        n_wrong
    }

    /// After each of many random edits, undos and redos (and paintings and an intersection)
    /// on a 200-edit object, the patched mesh has exactly the triangles of a whole assembly,
    /// is closed and manifold, and its patch's ranges hold every change.
    #[test]
    fn a_patched_mesh_equals_the_whole_assembly_after_each_random_edit() {
        let n_wrong = patched_session(0x5eed_2026, 40, |mesher, mesh| {
            mesher.mesh_update(mesh).unwrap()
        });
        assert_eq!(
            n_wrong, 0,
            "patched meshes that differ from a whole assembly"
        );
    }

    /// The comparison above catches a patch that emits only the changed blocks' triangles
    /// and forgets the quads and gap polygons its neighbours own across the seams.
    #[test]
    fn a_patch_that_forgets_the_seams_is_caught() {
        let n_wrong = patched_session(0x5eed_2026, 8, |mesher, mesh| {
            mesher.mesh_update_forgetting_seams(mesh).unwrap()
        });
        assert!(n_wrong > 0, "no step showed the stale seams");
    }

    #[test]
    fn dirty_regions_by_operation() {
        let tool = ToolShape::Sphere { radius: 0.1 };
        let compiled =
            |op| Arc::new(CompiledEdit::new(Edit::stamp(op, tool, Pose::at(DVec3::X))).unwrap());
        let Dirty::Boxes(b) = dirty_boxes(&compiled(EditOp::Subtract)) else {
            panic!("a carve dirties its box")
        };
        assert_eq!(b.len(), 1);
        assert!(b[0].contains([1.0, 0.0, 0.0]) && b[0].contains([1.09, 0.09, -0.09]));
        assert_eq!(dirty_boxes(&compiled(EditOp::Intersect)), Dirty::Everywhere);
        let paint = EditOp::Paint {
            property: model::object::Paintable::Color,
            value: model::object::PaintValue::Color([1.0, 0.0, 0.0]),
        };
        assert_eq!(dirty_boxes(&compiled(paint)), Dirty::Boxes(Vec::new()));
    }

    #[test]
    fn mesh_bounds_hold_the_domain_with_a_margin_and_unbounded_solids_have_none() {
        let b = mesh_bounds(&ball(), 6).unwrap();
        let cell = b.size()[0] / 64.0;
        assert!(
            b.lo[0] < -1.1 - 2.0 * cell && b.hi[0] > 1.1 + 2.0 * cell,
            "{b:?}"
        );
        assert!(b.hi[0] < 1.1 + 3.0 * cell, "{b:?}");
        let unbounded = Object::implicit("1-x^2-y^2-z^2").unwrap();
        assert_eq!(mesh_bounds(&unbounded, 6), None);
    }

    /// A mesh's numbers as bits, to compare two meshes exactly.
    fn bits(m: &Mesh) -> (Vec<[u32; 3]>, Vec<[u32; 3]>, Vec<u32>) {
        let b = |v: &Vec<[f32; 3]>| v.iter().map(|p| p.map(f32::to_bits)).collect();
        (b(&m.positions), b(&m.normals), m.indices.clone())
    }

    #[test]
    fn a_remesh_on_several_threads_equals_one_on_one_bit_for_bit() {
        // A carved ball (every octree node simplified) meshed whole, then remeshed over a
        // large box after more edits, on one thread and on several: the same records (the
        // assembled mesh, bit for bit) and the same counts.
        let n = 240;
        let mut object = ball();
        for k in 0..n {
            object.apply(edit(k, n)).unwrap();
        }
        object.prepare();
        let mut edited = object.clone();
        for k in 0..40 {
            edited.apply(edit(k, 40)).unwrap();
        }
        edited.prepare();
        let dirty = Aabb::new([-1.25, -1.25, -0.3], [1.25, 0.4, 1.25]);
        // The ball alone goes through fdsl's bulk evaluators, whose tape does not simplify
        // at the root: the subtrees take forks of it.
        let plain = ball();
        assert!(ObjectField::new(&plain, 0.0).is_bulk());
        let whole = |threads| {
            let mut m = OctreeMesher::new(&settings(6)).unwrap();
            let field = &mut ObjectField::new(&plain, 0.0);
            let stats = m
                .remesh_parallel(field, settings(6).bounds, threads)
                .unwrap();
            (stats, bits(&m.mesh().unwrap()))
        };
        let one = whole(1);
        for threads in [2, 3] {
            assert!(whole(threads) == one, "the ball on {threads} threads");
        }
        for depth in [5, 6] {
            let run = |threads| {
                let mut m = OctreeMesher::new(&settings(depth)).unwrap();
                let whole = (m.remesh_parallel(
                    &mut ObjectField::new(&object, 0.0),
                    settings(depth).bounds,
                    threads,
                ))
                .unwrap();
                let first = bits(&m.mesh().unwrap());
                let part = (m.remesh_parallel(&mut ObjectField::new(&edited, 0.0), dirty, threads))
                    .unwrap();
                (whole, first, part, bits(&m.mesh().unwrap()))
            };
            let one = run(1);
            // Enough blocks that the threads take them (the part only at depth 6).
            let n_blocks = |d: u8| (1usize << (d - 3)).pow(3);
            assert!(n_blocks(depth) >= octree::MIN_PARALLEL_BLOCKS);
            assert!(depth < 6 || one.2.blocks_evaluated >= octree::MIN_PARALLEL_BLOCKS);
            assert_ne!(one.1, one.3, "the edits change the mesh");
            for threads in [2, 3, 8] {
                let many = run(threads);
                assert_eq!(many.0, one.0, "depth {depth}, {threads} threads: whole");
                assert!(
                    many.1 == one.1,
                    "depth {depth}, {threads} threads: whole mesh"
                );
                assert_eq!(many.2, one.2, "depth {depth}, {threads} threads: part");
                assert!(
                    many.3 == one.3,
                    "depth {depth}, {threads} threads: remeshed"
                );
            }
        }
    }
}
