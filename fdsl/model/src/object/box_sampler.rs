//! [`BoxSampler`]: an object restricted to a box, evaluated over many points at once (a
//! mesher's block, a ray's piece).
//!
//! Restricting gathers once what the fold needs inside the box: the active shape edits whose
//! boxes overlap it, in history order (from the history's index, or from the list of an
//! enclosing restriction), the last intersection that leaves the whole box empty, and the
//! geometry's tape simplified for the box where that keeps every value. Evaluation then
//! folds each edit over all the points in turn, so the edit's compiled data stays in cache,
//! and runs the geometry's tape over all the points at once.
//!
//! At every point of the box, values, gradients and intervals of sub-boxes are those of
//! [`Sampler`], bit for bit: each point sees the same edits in the same order, folded by the
//! same functions, over the same base value. That holds because
//! - the edits touching a point of the box are among those overlapping the box, and an
//!   intersection whose boxes miss the box leaves nothing there (the sampler restarts after it
//!   too);
//! - paintings leave values, gradients and intervals unchanged and are not gathered;
//! - the geometry's tape runs through [`SliceEval`], which applies the point evaluator's own
//!   operations in f64, and it is simplified only by exact choices: selects whose condition
//!   has one sign over the box and blends whose arguments are farther apart than the blend
//!   radius. Choices of `min`/`max` are not taken: where the two arguments tie, `f64::min`
//!   may return either zero of `+0`/`-0` and the gradient takes the first argument, so the
//!   simplified tape could differ from the full one in the sign of a zero or a gradient;
//! - gradients of the geometry come from the point path (forward-mode per point, as
//!   [`Sampler::gradient`]); only their fold over the edits is in bulk;
//! - imported meshes are evaluated per point by their signed distance, as the point path does;
//!   parametric geometry has no field (empty space) on both paths.
//!
//! Points outside the box are evaluated through a [`Sampler`] made on first need.
//! Evaluation allocates only to grow scratch buffers to the largest batch seen.

use std::sync::Arc;

use glam::DVec3;

use super::edit::{CompiledEdit, EditOp};
use super::history::HistoryEntry;
use super::sample::Shape;
use super::slice_eval::SliceEval;
use super::space::Transform;
use super::{CompiledShape, NOTHING, Object, Sampler};
use crate::bvh::Aabb;
use fdsl::compile::BinaryOp;
use fdsl::eval::Interval;
use fdsl::tape::{Choice, Code, Fidelity, Tape};

/// A restriction of a sampler holding more edits than this gathers its edits from the
/// history's index rather than by scanning its own list; an interval over a sub-box of such a
/// sampler goes through the point path's index likewise.
pub const MAX_SCAN_EDITS: usize = 256;

/// An object restricted to a box at a fixed time, evaluated over many points at once.
///
/// Made by [`Sampler::restrict`] (or [`BoxSampler::restrict`] for a box inside this one), it
/// holds the edits that reach the box, gathered once, and the geometry's tape simplified for
/// the box where that changes no value. At every point of the box its values, gradients and
/// intervals of sub-boxes are [`Sampler`]'s bit for bit (a property test checks this), so
/// callers may mix the two paths; the geometry's gradients are computed per point as the
/// sampler does, and only the edits' fold over them is in bulk. Points and boxes outside the
/// box go through a `Sampler` made on first need. Evaluation allocates only to grow scratch
/// buffers to the largest batch seen.
pub struct BoxSampler {
    object: Arc<Object>,
    region: Aabb,
    t: f64,
    /// Edits before this one cannot reach the box: an intersection leaves it empty.
    first: usize,
    /// The active shape edits from `first` on whose boxes overlap the box, ascending.
    edits: Vec<u32>,
    /// The intersections among `edits`, ascending.
    intersects: Vec<u32>,
    /// The geometry, when it reaches the box (`first == 0`).
    geometry: Option<BoxShape>,
    /// The point path, for points and boxes outside the box.
    fallback: Option<Box<Sampler>>,
    /// Per point, the first edit of its fold (after the last intersection missing it).
    from: Vec<u32>,
    /// Points outside the box.
    outside: Vec<u32>,
    /// Points in the geometry's space.
    local: [Vec<f64>; 3],
    /// The points sorted into buckets of the box (see [`Buckets`]).
    buckets: Buckets,
    /// Values and gradients in bucket order.
    sorted_values: Vec<f64>,
    sorted_gradients: Vec<(f64, DVec3)>,
}

impl BoxSampler {
    /// `object` restricted to `region` at time `t`, its edits gathered from the history.
    pub(super) fn new(object: Arc<Object>, region: &Aabb, t: f64) -> BoxSampler {
        let history = object.history();
        let mut edits = Vec::new();
        history.collect_box(region, &mut edits);
        let first = history
            .last_intersect_where(|e| !overlaps(e, region))
            .map_or(0, |k| k + 1);
        let entries = history.entries();
        edits.retain(|&i| i as usize >= first && entries[i as usize].edit.is_geometric());
        BoxSampler::with_edits(object, region, t, first, edits)
    }

    fn with_edits(
        object: Arc<Object>,
        region: &Aabb,
        t: f64,
        first: usize,
        edits: Vec<u32>,
    ) -> BoxSampler {
        let entries = object.history().entries();
        let intersects = edits
            .iter()
            .copied()
            .filter(|&i| matches!(entries[i as usize].edit.edit().op, EditOp::Intersect))
            .collect();
        let geometry = match (&object.parts().geometry, first) {
            (Some(g), 0) => Some(BoxShape::new(g, region, t)),
            _ => None,
        };
        BoxSampler {
            region: *region,
            t,
            first,
            edits,
            intersects,
            geometry,
            fallback: None,
            from: Vec::new(),
            outside: Vec::new(),
            local: [Vec::new(), Vec::new(), Vec::new()],
            buckets: Buckets::default(),
            sorted_values: Vec::new(),
            sorted_gradients: Vec::new(),
            object,
        }
    }

    /// The object sampled.
    pub fn object(&self) -> &Arc<Object> {
        &self.object
    }

    /// The box.
    pub fn region(&self) -> &Aabb {
        &self.region
    }

    /// The time.
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Number of edits folded inside the box.
    pub fn n_edits(&self) -> usize {
        self.edits.len()
    }

    /// Whether the geometry's tape was simplified for the box.
    pub fn is_simplified(&self) -> bool {
        self.geometry.as_ref().is_some_and(|g| g.simplified)
    }

    /// The object restricted to `sub`: from this sampler's edits when `sub` lies inside the
    /// box and they are few, else from the history.
    pub fn restrict(&self, sub: &Aabb) -> BoxSampler {
        if !self.region.contains_box(sub) || self.edits.len() > MAX_SCAN_EDITS {
            return BoxSampler::new(self.object.clone(), sub, self.t);
        }
        let entries = self.object.history().entries();
        let first = self.first_over(sub);
        let edits = self
            .edits
            .iter()
            .copied()
            .filter(|&i| i as usize >= first && overlaps(&entries[i as usize].edit, sub))
            .collect();
        BoxSampler::with_edits(self.object.clone(), sub, self.t, first, edits)
    }

    /// The first edit that can reach `sub` (inside the box).
    fn first_over(&self, sub: &Aabb) -> usize {
        let entries = self.object.history().entries();
        self.intersects
            .iter()
            .rev()
            .find(|&&i| !overlaps(&entries[i as usize].edit, sub))
            .map_or(self.first, |&i| self.first.max(i as usize + 1))
    }

    fn fallback(&mut self) -> &mut Sampler {
        let object = &self.object;
        self.fallback
            .get_or_insert_with(|| Box::new(Sampler::new(object.clone())))
    }

    /// Finds the points outside the box and the first edit of each point's fold.
    fn prepare(&mut self, points: &[DVec3]) {
        self.outside.clear();
        for (i, p) in points.iter().enumerate() {
            if !self.region.contains(*p) {
                self.outside.push(i as u32);
            }
        }
        self.from.clear();
        self.from.resize(points.len(), self.first as u32);
        let entries = self.object.history().entries();
        for &k in &self.intersects {
            let e = &entries[k as usize].edit;
            if e.covers(&self.region) {
                continue;
            }
            for (from, p) in self.from.iter_mut().zip(points) {
                if !e.touches(*p) {
                    *from = k + 1;
                }
            }
        }
    }

    /// The solid's value at each point (object space), as [`Sampler::value`] gives it.
    pub fn values(&mut self, points: &[DVec3], out: &mut [f64]) {
        assert_eq!(points.len(), out.len(), "one output per point");
        self.prepare(points);
        match &mut self.geometry {
            Some(g) => g.values(points, self.t, out, &mut self.local),
            None => out.fill(NOTHING),
        }
        for (o, &from) in out.iter_mut().zip(&self.from) {
            if from > 0 {
                *o = NOTHING;
            }
        }
        let batch = Batch {
            edits: &self.edits,
            entries: self.object.history().entries(),
            region: &self.region,
            points,
            from: &self.from,
        };
        let mut sorted = std::mem::take(&mut self.sorted_values);
        (self.buckets).fold(batch, out, &mut sorted, |e, v, p| e.apply_value(v, p));
        self.sorted_values = sorted;
        if !self.outside.is_empty() {
            let t = self.t;
            let outside = std::mem::take(&mut self.outside);
            let sampler = self.fallback();
            for &i in &outside {
                out[i as usize] = sampler.value(points[i as usize], t);
            }
            self.outside = outside;
        }
    }

    /// The solid's value and gradient at each point, as [`Sampler::gradient`] gives them.
    pub fn gradients(&mut self, points: &[DVec3], out: &mut [(f64, DVec3)]) {
        assert_eq!(points.len(), out.len(), "one output per point");
        self.prepare(points);
        let t = self.t;
        for ((o, p), &from) in out.iter_mut().zip(points).zip(&self.from) {
            *o = match (&mut self.geometry, from) {
                (Some(g), 0) => g.shape.gradient(*p, t),
                _ => (NOTHING, DVec3::ZERO),
            };
        }
        let batch = Batch {
            edits: &self.edits,
            entries: self.object.history().entries(),
            region: &self.region,
            points,
            from: &self.from,
        };
        let mut sorted = std::mem::take(&mut self.sorted_gradients);
        (self.buckets).fold(batch, out, &mut sorted, |e, v, p| e.apply_grad(v, p));
        self.sorted_gradients = sorted;
        if !self.outside.is_empty() {
            let outside = std::mem::take(&mut self.outside);
            let sampler = self.fallback();
            for &i in &outside {
                out[i as usize] = sampler.gradient(points[i as usize], t);
            }
            self.outside = outside;
        }
    }

    /// An interval holding the value at every point of `sub`, as [`Sampler::interval`]
    /// gives it.
    pub fn interval(&mut self, sub: &Aabb) -> Interval {
        let t = self.t;
        if !self.region.contains_box(sub) || self.edits.len() > MAX_SCAN_EDITS {
            return self.fallback().interval(sub, t);
        }
        let from = self.first_over(sub);
        let mut v = match (&mut self.geometry, from) {
            (Some(g), 0) => g.shape.interval(sub, t),
            _ => Interval::point(NOTHING),
        };
        if self.object.history().leaves_interval(v, sub) {
            return v;
        }
        let entries = self.object.history().entries();
        for &j in &self.edits {
            let e = &entries[j as usize].edit;
            if j as usize >= from && overlaps(e, sub) {
                v = e.apply_interval(v, sub);
            }
        }
        v
    }
}

/// Batches smaller than this are folded edit by edit over every point, without buckets.
const MIN_BUCKETS_POINTS: usize = 64;
/// Most buckets along each axis.
const MAX_BUCKETS_PER_AXIS: usize = 8;
/// Points per bucket aimed at.
const POINTS_PER_BUCKET: usize = 2;

/// A batch of points sorted into a grid of buckets over the box, so that each edit visits
/// only the points of the buckets its bounds overlap (a point lies in one bucket, whose index
/// grows with its coordinates, so a point inside an edit's box lies in one of the buckets
/// between those of the box's corners). Folding edit by edit in history order keeps each
/// point's order of edits.
#[derive(Default)]
struct Buckets {
    n_axis: usize,
    /// The region's low corner, and buckets per unit length along each axis.
    origin: DVec3,
    per_unit: DVec3,
    /// Bucket of each point, then the points in bucket order.
    bucket_of: Vec<u32>,
    order: Vec<u32>,
    /// Bucket `b` holds `order[starts[b]..starts[b + 1]]`.
    starts: Vec<u32>,
    points: Vec<DVec3>,
    from: Vec<u32>,
    /// The batch's axes when it is a lattice, which needs no buckets.
    lattice: Lattice,
}

impl Buckets {
    /// The bucket holding `p` along each axis, clamped to the grid. Any function of `p` that
    /// grows with each coordinate will do: an edit's points lie in the buckets between those
    /// of its bounds' corners.
    #[inline]
    fn cell(&self, p: DVec3) -> [usize; 3] {
        let q = ((p - self.origin) * self.per_unit).max(DVec3::ZERO);
        let last = self.n_axis - 1;
        [q.x as usize, q.y as usize, q.z as usize].map(|c| c.min(last))
    }

    /// Sorts `points` (and their first edits) into buckets over `region`.
    fn sort(&mut self, region: &Aabb, points: &[DVec3], from: &[u32]) {
        let by_count = (points.len() / POINTS_PER_BUCKET) as f64;
        self.n_axis = (by_count.cbrt() as usize).clamp(1, MAX_BUCKETS_PER_AXIS);
        let n = self.n_axis;
        self.origin = region.lo;
        self.per_unit = n as f64 / region.size().max(DVec3::splat(f64::MIN_POSITIVE));
        self.starts.clear();
        self.starts.resize(n * n * n + 1, 0);
        self.bucket_of.clear();
        for p in points {
            let [x, y, z] = self.cell(*p);
            let b = x + n * (y + n * z);
            self.bucket_of.push(b as u32);
            self.starts[b + 1] += 1;
        }
        for b in 0..n * n * n {
            self.starts[b + 1] += self.starts[b];
        }
        self.order.clear();
        self.order.resize(points.len(), 0);
        let mut next = std::mem::take(&mut self.from);
        next.clear();
        next.extend_from_slice(&self.starts[..n * n * n]);
        for (i, &b) in self.bucket_of.iter().enumerate() {
            self.order[next[b as usize] as usize] = i as u32;
            next[b as usize] += 1;
        }
        self.points.clear();
        self.points
            .extend(self.order.iter().map(|&i| points[i as usize]));
        next.clear();
        next.extend(self.order.iter().map(|&i| from[i as usize]));
        self.from = next;
    }

    /// Folds the batch's edits into `out`, each over the points it touches from their first
    /// edits on, with `apply`; `sorted` is scratch.
    fn fold<T: Copy>(
        &mut self,
        batch: Batch<'_>,
        out: &mut [T],
        sorted: &mut Vec<T>,
        apply: impl Fn(&CompiledEdit, T, DVec3) -> T,
    ) {
        let (edits, entries, points, from) = (batch.edits, batch.entries, batch.points, batch.from);
        if edits.is_empty() {
            return;
        }
        let covers_all = batch.covers_all();
        if points.len() < MIN_BUCKETS_POINTS {
            for &j in edits {
                let e = &entries[j as usize].edit;
                let all = covers_all(j, e);
                for ((o, p), &f) in out.iter_mut().zip(points).zip(from) {
                    if all || (f <= j && e.touches(*p)) {
                        *o = apply(e, *o, *p);
                    }
                }
            }
            return;
        }
        if self.lattice.read(points) {
            self.lattice.fold(batch, out, &apply);
            return;
        }
        self.sort(batch.region, points, from);
        sorted.clear();
        sorted.extend(self.order.iter().map(|&i| out[i as usize]));
        let n = self.n_axis;
        for &j in edits {
            let e = &entries[j as usize].edit;
            if covers_all(j, e) {
                for (v, p) in sorted.iter_mut().zip(&self.points) {
                    *v = apply(e, *v, *p);
                }
                continue;
            }
            let bounds = e.bounds();
            let (lo, hi) = (self.cell(bounds.lo), self.cell(bounds.hi));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    let row = n * (y + n * z);
                    let range =
                        self.starts[row + lo[0]] as usize..self.starts[row + hi[0] + 1] as usize;
                    for k in range {
                        let p = self.points[k];
                        if self.from[k] <= j && e.touches(p) {
                            sorted[k] = apply(e, sorted[k], p);
                        }
                    }
                }
            }
        }
        for (k, &i) in self.order.iter().enumerate() {
            out[i as usize] = sorted[k];
        }
    }
}

/// What a fold reads: the edits to fold (ascending), the history's entries, the region, the
/// points and each point's first edit.
#[derive(Clone, Copy)]
struct Batch<'a> {
    edits: &'a [u32],
    entries: &'a [HistoryEntry],
    region: &'a Aabb,
    points: &'a [DVec3],
    from: &'a [u32],
}

impl Batch<'_> {
    /// Whether edit `j` touches every point: where every point's fold starts at the same edit,
    /// an edit from there on one of whose boxes covers the region.
    fn covers_all(&self) -> impl Fn(u32, &CompiledEdit) -> bool + use<'_> {
        let from_all = self.from.first().copied().unwrap_or(0);
        let uniform = self.from.iter().all(|&f| f == from_all);
        move |j, e| uniform && from_all <= j && e.covers(self.region)
    }
}

/// A batch of points that is a lattice, x fastest (a mesher's block): point
/// `x + nx * (y + ny * z)` is `(xs[x], ys[y], zs[z])`, each axis strictly increasing. The
/// points an edit's box holds are then a sub-lattice, found by searching each axis, so a fold
/// visits exactly those points and neither sorts nor tests them against the box.
#[derive(Default)]
struct Lattice {
    axes: [Vec<f64>; 3],
}

impl Lattice {
    /// Whether `points` are a lattice; its axes are read into `self` when they are.
    fn read(&mut self, points: &[DVec3]) -> bool {
        let Some(&p0) = points.first() else {
            return false;
        };
        for axis in &mut self.axes {
            axis.clear();
        }
        let nx = points
            .iter()
            .take_while(|p| p.y == p0.y && p.z == p0.z)
            .count();
        if nx == 0 {
            // The first point's y or z is NaN.
            return false;
        }
        let ny = points
            .iter()
            .step_by(nx)
            .take_while(|p| p.z == p0.z)
            .count();
        if !points.len().is_multiple_of(nx * ny) {
            return false;
        }
        let nz = points.len() / (nx * ny);
        let [xs, ys, zs] = &mut self.axes;
        xs.extend(points[..nx].iter().map(|p| p.x));
        ys.extend(points[..nx * ny].iter().step_by(nx).map(|p| p.y));
        zs.extend(points.iter().step_by(nx * ny).map(|p| p.z));
        let increasing = |a: &[f64]| a.windows(2).all(|w| w[0] < w[1]);
        if !(increasing(xs) && increasing(ys) && increasing(zs)) {
            return false;
        }
        (0..nz).all(|z| {
            (0..ny).all(|y| {
                let row = &points[nx * (y + ny * z)..][..nx];
                (row.iter().zip(&*xs)).all(|(p, &x)| p.x == x && p.y == ys[y] && p.z == zs[z])
            })
        })
    }

    /// The points along axis `a` with `lo <= c <= hi`, as [`Aabb::contains`] tests them.
    fn span(&self, a: usize, lo: f64, hi: f64) -> std::ops::Range<usize> {
        let axis = &self.axes[a];
        axis.partition_point(|&c| c < lo)..axis.partition_point(|&c| c <= hi)
    }

    /// [`Buckets::fold`] over the lattice's points.
    fn fold<T: Copy>(
        &self,
        batch: Batch<'_>,
        out: &mut [T],
        apply: &impl Fn(&CompiledEdit, T, DVec3) -> T,
    ) {
        let (edits, entries, points, from) = (batch.edits, batch.entries, batch.points, batch.from);
        let covers_all = batch.covers_all();
        let (nx, ny) = (self.axes[0].len(), self.axes[1].len());
        for &j in edits {
            let e = &entries[j as usize].edit;
            if covers_all(j, e) {
                for (o, p) in out.iter_mut().zip(points) {
                    *o = apply(e, *o, *p);
                }
                continue;
            }
            // A mirrored edit's two boxes may share points: those of their union are tested.
            let [b0, b1] = e.boxes();
            let (b, test) = match b1.is_empty() {
                true => (*b0, false),
                false => (e.bounds(), true),
            };
            let [xr, yr, zr] = [0, 1, 2].map(|a| self.span(a, b.lo[a], b.hi[a]));
            for z in zr {
                for y in yr.clone() {
                    let row = nx * (y + ny * z);
                    for k in row + xr.start..row + xr.end {
                        let p = points[k];
                        if from[k] <= j && (!test || e.touches(p)) {
                            out[k] = apply(e, out[k], p);
                        }
                    }
                }
            }
        }
    }
}

/// Whether one of the edit's boxes overlaps `region` (the history's box query).
fn overlaps(e: &CompiledEdit, region: &Aabb) -> bool {
    e.boxes().iter().any(|b| b.overlaps(region))
}

/// The geometry over a box: its evaluators, and its tape simplified for the box.
struct BoxShape {
    shape: Shape,
    /// The tape in bulk (none for a mesh or parametric geometry).
    slices: Option<SliceEval>,
    simplified: bool,
}

impl BoxShape {
    fn new(compiled: &CompiledShape, region: &Aabb, t: f64) -> BoxShape {
        let mut shape = Shape::new(compiled);
        let mut simplified = false;
        let slices = match (&compiled.tape, &mut shape.eval) {
            (Some(tape), Some(eval)) => {
                let local = enclosing_box(&compiled.local_from_object, region);
                let iv = |lo: f64, hi: f64| Interval::new(lo, hi);
                eval.interval.eval([
                    iv(local.lo.x, local.hi.x),
                    iv(local.lo.y, local.hi.y),
                    iv(local.lo.z, local.hi.z),
                    Interval::point(t),
                ]);
                let choices = exact_choices(tape, eval.interval.choices());
                simplified = choices.iter().any(|c| *c != Choice::Both);
                Some(if simplified {
                    SliceEval::new(&tape.simplify(&choices, Fidelity::Exact))
                } else {
                    SliceEval::new(tape)
                })
            }
            _ => None,
        };
        BoxShape {
            shape,
            slices,
            simplified,
        }
    }

    /// The shape's value at each point, as the point path computes it.
    fn values(&mut self, points: &[DVec3], t: f64, out: &mut [f64], local: &mut [Vec<f64>; 3]) {
        let compiled = &self.shape.compiled;
        let [xs, ys, zs] = local;
        let n = points.len();
        for coords in [&mut *xs, &mut *ys, &mut *zs] {
            coords.resize(n, 0.0);
        }
        let (x, y, z) = (&mut xs[..n], &mut ys[..n], &mut zs[..n]);
        for (i, p) in points.iter().enumerate() {
            let q = compiled.local_from_object.point(*p);
            (x[i], y[i], z[i]) = (q.x, q.y, q.z);
        }
        let (xs, ys, zs) = (&*xs, &*ys, &*zs);
        match (&mut self.slices, &compiled.mesh) {
            (Some(e), _) => e.eval(xs, ys, zs, t, out),
            (None, Some(m)) => {
                for (i, o) in out.iter_mut().enumerate() {
                    *o = m.signed_distance(DVec3::new(xs[i], ys[i], zs[i]));
                }
            }
            (None, None) => {
                out.fill(NOTHING);
                return;
            }
        }
        if let Some(d) = &compiled.domain {
            for (i, o) in out.iter_mut().enumerate() {
                *o = o.min(d.signed_distance(DVec3::new(xs[i], ys[i], zs[i])));
            }
        }
    }
}

/// A box holding the image under `map` of every point of `region` as computed in f64: the
/// image's box widened well beyond the rounding of the map.
fn enclosing_box(map: &Transform, region: &Aabb) -> Aabb {
    let image = map.aabb(region);
    let m = map.linear();
    let reach = region.lo.abs().max(region.hi.abs());
    let terms = DVec3::new(
        m.row(0).abs().dot(reach),
        m.row(1).abs().dot(reach),
        m.row(2).abs().dot(reach),
    ) + map.parent_from_child.translation.abs()
        + image.lo.abs().max(image.hi.abs());
    let margin = terms.max_element() * 1e-12 + f64::MIN_POSITIVE;
    image.expand(margin)
}

/// The choices of an interval evaluation that simplify `tape` without changing any value or
/// gradient bit: those of selects and blends, not of `min`/`max` (see the module
/// documentation).
fn exact_choices(tape: &Tape, choices: &[Choice]) -> Vec<Choice> {
    tape.instrs()
        .iter()
        .zip(choices)
        .map(|(instr, &c)| match instr.code {
            Code::Binary(BinaryOp::Min | BinaryOp::Max) => Choice::Both,
            Code::Ternary(_) => c,
            _ => Choice::Both,
        })
        .collect()
}
