//! Sculpting edits: adding, carving or intersecting with a tool swept along a stroke, and
//! painting a property inside the tool's volume; and the set operations (sharp or blended)
//! that fold them into an object's value, gradient and interval.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

use super::ObjectError;
use super::appearance::Rgb;
use super::tool::{Axis, CompiledTool, Pose, ToolShape};
use crate::bvh::Aabb;
use fdsl::eval::Interval;

/// A property an edit can paint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Paintable {
    /// Diffuse colour.
    Color,
    /// Transparency.
    Transparency,
    /// Shininess.
    Shininess,
    /// Surface tension.
    Tension,
    /// Surface friction.
    Friction,
    /// Surface-zone depth.
    ZoneDepth,
    /// Interior density.
    Density,
}

impl Paintable {
    /// Every paintable property.
    pub const ALL: [Paintable; 7] = [
        Paintable::Color,
        Paintable::Transparency,
        Paintable::Shininess,
        Paintable::Tension,
        Paintable::Friction,
        Paintable::ZoneDepth,
        Paintable::Density,
    ];
}

/// The value painted inside the tool.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum PaintValue {
    /// A scalar (tension, friction, density, depth, transparency, shininess).
    Scalar(f64),
    /// A colour.
    Color(Rgb),
}

/// What an edit does.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum EditOp {
    /// Adds the tool's volume.
    Union,
    /// Carves the tool's volume away.
    Subtract,
    /// Keeps only what lies inside the tool.
    Intersect,
    /// Inside the tool, `property` takes `value`; outside it keeps what it had.
    Paint {
        /// The property painted.
        property: Paintable,
        /// Its new value inside the tool.
        value: PaintValue,
    },
}

/// One sculpting edit: a tool swept along a stroke (one pose for a single stamp).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Edit {
    /// Union, subtraction, intersection or painting.
    pub op: EditOp,
    /// The tool's solid.
    pub tool: ToolShape,
    /// The stroke: the tool's poses in object coordinates, in drawing order.
    pub path: Vec<Pose>,
    /// Smooth blending radius for set operations (0 is sharp).
    pub blend_radius: f64,
    /// Also apply the edit mirrored in this plane.
    pub mirror: Option<Axis>,
}

impl Edit {
    /// A single stamp of `tool` at `pose`.
    pub fn stamp(op: EditOp, tool: ToolShape, pose: Pose) -> Edit {
        Edit {
            op,
            tool,
            path: vec![pose],
            blend_radius: 0.0,
            mirror: None,
        }
    }

    /// A stroke along `path`.
    pub fn stroke(op: EditOp, tool: ToolShape, path: Vec<Pose>) -> Edit {
        Edit {
            op,
            tool,
            path,
            blend_radius: 0.0,
            mirror: None,
        }
    }
}

/// An edit ready to evaluate.
#[derive(Clone, Debug)]
pub struct CompiledEdit {
    /// Shared with whoever holds the edit (a replicated op), not copied.
    edit: Arc<Edit>,
    tool: CompiledTool,
    /// One box, or two with a mirror: outside them the edit changes nothing that matters.
    boxes: [Aabb; 2],
}

// Every held edit is compiled (a replicated edit op holds one), so its size is per op held.
const _: () = assert!(size_of::<CompiledEdit>() <= 152);

/// Two compiled edits are equal when their edits are: the rest is a function of the edit.
impl PartialEq for CompiledEdit {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.edit, &other.edit) || *self.edit == *other.edit
    }
}

/// Encoded as its [`Edit`], so a compiled edit and the edit it came from encode alike.
impl Serialize for CompiledEdit {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.edit.serialize(s)
    }
}

/// Decoded as an [`Edit`] and compiled on the spot: an edit that does not compile is a
/// decoding error, so whoever decodes one holds it ready to fold and never compiles it again.
impl<'de> Deserialize<'de> for CompiledEdit {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let edit = Edit::deserialize(d)?;
        CompiledEdit::new(edit).map_err(serde::de::Error::custom)
    }
}

impl CompiledEdit {
    /// Validates and compiles an edit (an `Edit`, or an `Arc<Edit>` to share).
    pub fn new(edit: impl Into<Arc<Edit>>) -> Result<CompiledEdit, ObjectError> {
        super::compiled::count_edit_compilation();
        let edit = edit.into();
        let blend = edit.blend_radius;
        if !(blend.is_finite() && blend >= 0.0) {
            return Err(ObjectError::BadStroke {
                reason: "the blend radius must be finite and not negative",
            });
        }
        if let EditOp::Paint { value, .. } = edit.op {
            let ok = match value {
                PaintValue::Scalar(v) => v.is_finite(),
                PaintValue::Color(c) => c.iter().all(|v| (0.0..=1.0).contains(v)),
            };
            if !ok {
                return Err(ObjectError::BadPaint);
            }
        }
        let tool = CompiledTool::new(edit.tool, &edit.path, blend)?;
        let bounds = tool.bounds();
        let boxes = match edit.mirror {
            Some(axis) => [bounds, axis.reflect_box(&bounds)],
            None => [bounds, Aabb::EMPTY],
        };
        Ok(CompiledEdit { edit, tool, boxes })
    }

    /// The edit as given.
    pub fn edit(&self) -> &Edit {
        &self.edit
    }

    /// The edit as given, shared.
    pub fn shared_edit(&self) -> &Arc<Edit> {
        &self.edit
    }

    /// The compiled tool.
    pub(crate) fn tool(&self) -> &CompiledTool {
        &self.tool
    }

    /// The boxes outside which the edit is inert (the second is empty without a mirror).
    pub fn boxes(&self) -> &[Aabb; 2] {
        &self.boxes
    }

    /// Where `self` can differ from `earlier` when it is the same edit swept further (a stroke
    /// being drawn: `earlier`'s poses are the first of `self`'s), as [`CompiledEdit::boxes`]
    /// gives boxes: around the stamps the longer stroke adds. Outside them the two edits take
    /// the same values, so a mesh of the one needs remeshing only there. `None` when `self` is
    /// not such a continuation (another brush, other poses, or a larger pose that widens every
    /// stamp's box).
    pub fn grown_from(&self, earlier: &CompiledEdit) -> Option<[Aabb; 2]> {
        let (a, b) = (&*earlier.edit, &*self.edit);
        let same_brush = a.op == b.op
            && a.tool == b.tool
            && a.blend_radius == b.blend_radius
            && a.mirror == b.mirror;
        if !same_brush || !b.path.starts_with(&a.path) {
            return None;
        }
        let region = self.tool.grown_from(&earlier.tool)?;
        Some(match b.mirror {
            Some(axis) => [region, axis.reflect_box(&region)],
            None => [region, Aabb::EMPTY],
        })
    }

    /// The box around everything the edit can touch.
    pub fn bounds(&self) -> Aabb {
        self.boxes[0].union(&self.boxes[1])
    }

    /// Whether `p` lies in the edit's region.
    #[inline]
    pub fn touches(&self, p: DVec3) -> bool {
        self.boxes[0].contains(p) || self.boxes[1].contains(p)
    }

    /// Whether `region` lies entirely in one of the edit's boxes.
    pub(crate) fn covers(&self, region: &Aabb) -> bool {
        self.boxes[0].contains_box(region) || self.boxes[1].contains_box(region)
    }

    /// How far beyond the tool's solid its stamps' boxes reach (half the tool's size plus the
    /// blend radius): values are exact within this band.
    pub fn margin(&self) -> f64 {
        self.tool.margin()
    }

    /// Number of primitive stamps the stroke compiled to.
    pub fn n_stamps(&self) -> usize {
        self.tool.n_stamps()
    }

    /// Whether the edit is a set operation (not painting).
    pub fn is_geometric(&self) -> bool {
        !matches!(self.edit.op, EditOp::Paint { .. })
    }

    /// The tool's value (positive inside) and gradient at `p`, mirror included.
    #[inline]
    pub(crate) fn tool_eval(&self, p: DVec3) -> (f64, DVec3) {
        let direct = self.tool.eval(self.edit.tool, p);
        match self.edit.mirror {
            Some(axis) => {
                let (v, g) = self.tool.eval(self.edit.tool, axis.reflect(p));
                if v > direct.0 {
                    (v, axis.reflect(g))
                } else {
                    direct
                }
            }
            None => direct,
        }
    }

    /// The tool's value at `p` by definition, mirror included, visiting every stamp without an
    /// index: the best stamp whose grown box holds `p`, else empty space. The fast paths must
    /// agree with it.
    pub fn raw_tool_value(&self, p: DVec3) -> f64 {
        let direct = self.tool.raw_value(self.edit.tool, p);
        match self.edit.mirror {
            Some(axis) => direct.max(self.tool.raw_value(self.edit.tool, axis.reflect(p))),
            None => direct,
        }
    }

    /// The tool's value at `p`.
    #[inline]
    pub(crate) fn tool_value(&self, p: DVec3) -> f64 {
        let direct = self.tool.value(self.edit.tool, p);
        match self.edit.mirror {
            Some(axis) => direct.max(self.tool.value(self.edit.tool, axis.reflect(p))),
            None => direct,
        }
    }

    /// An interval of the tool's values over `region`.
    pub(crate) fn tool_interval(&self, region: &Aabb) -> Interval {
        let direct = self.tool.interval(self.edit.tool, region);
        match self.edit.mirror {
            Some(axis) => {
                let m = self
                    .tool
                    .interval(self.edit.tool, &axis.reflect_box(region));
                Interval::new(direct.lo.max(m.lo), direct.hi.max(m.hi))
            }
            None => direct,
        }
    }

    /// Whether `p` is inside the tool (painting applies).
    #[inline]
    pub(crate) fn paints(&self, p: DVec3) -> bool {
        self.touches(p) && self.tool_value(p) >= 0.0
    }

    /// The value after this edit, given the value `f` before it, at `p`.
    #[inline]
    pub(crate) fn apply_value(&self, f: f64, p: DVec3) -> f64 {
        let (op, b) = (&self.edit.op, self.edit.blend_radius);
        if keeps_value(op, f, self.tool.value_max(), b) {
            return f;
        }
        fold_value(op, f, self.tool_value(p), b)
    }

    /// Value and gradient after this edit.
    #[inline]
    pub(crate) fn apply_grad(&self, f: (f64, DVec3), p: DVec3) -> (f64, DVec3) {
        let (op, b) = (&self.edit.op, self.edit.blend_radius);
        if keeps_value(op, f.0, self.tool.value_max(), b) {
            return f;
        }
        fold_grad(op, f, self.tool_eval(p), b)
    }

    /// Interval after this edit over `region`, which the edit's boxes may cover only in part
    /// (then the edit is inert over the rest).
    pub(crate) fn apply_interval(&self, f: Interval, region: &Aabb) -> Interval {
        let (op, b) = (&self.edit.op, self.edit.blend_radius);
        let covered = self.covers(region);
        let g_max = self.tool.interval_max(region);
        let g = match keeps_interval(op, f, g_max, covered) {
            true => Interval::new(g_max, g_max),
            false => self.tool_interval(region),
        };
        fold_interval(op, f, g, b, covered)
    }

    /// The value an intersection leaves outside its region: empty space (a tool's support is
    /// its region; an intersection with nothing is nothing).
    pub(crate) fn outside_value(&self) -> f64 {
        super::NOTHING
    }
}

/// The value after an edit of `op` with blend radius `b` whose tool has the value `g`, given
/// the value `f` before it (what [`CompiledEdit::apply_value`] and the edit arena share).
#[inline]
pub(crate) fn fold_value(op: &EditOp, f: f64, g: f64, b: f64) -> f64 {
    match op {
        EditOp::Union => smooth_max(f, g, b),
        EditOp::Subtract => smooth_min(f, -g, b),
        EditOp::Intersect => smooth_min(f, g, b),
        EditOp::Paint { .. } => f,
    }
}

/// Whether an edit of `op` with blend radius `b` leaves the value `f` as it is, bit for bit,
/// whatever its tool's value `g` as long as `g <= g_max`: then [`fold_value`] and
/// [`fold_grad`] return `f` itself and the tool need not be evaluated. A union keeps `f` where
/// `f` exceeds every value of the tool by the blend radius, a subtraction where `-f` does
/// (`smooth_max`'s first branch, whose test only gets truer as `g` falls: rounding is
/// monotone), a painting always; an intersection never (a lower `g` lowers the result).
#[inline]
pub(crate) fn keeps_value(op: &EditOp, f: f64, g_max: f64, b: f64) -> bool {
    match op {
        EditOp::Union => keeps_first(f, g_max, b),
        EditOp::Subtract => keeps_first(-f, g_max, b),
        EditOp::Intersect => false,
        EditOp::Paint { .. } => true,
    }
}

/// Whether `smooth_max(a, g, k)` (and its gradient form) returns `a` for every `g <= g_max`.
#[inline]
fn keeps_first(a: f64, g_max: f64, k: f64) -> bool {
    if k <= 0.0 {
        a > g_max
    } else {
        0.5 + 0.5 * (a - g_max) / k >= 1.0
    }
}

/// Whether [`fold_interval`] of an edit of `op` over `f` gives the same bits for every tool
/// interval whose ends are at most `g_max` (then it may be given `[g_max, g_max]` instead of
/// the tool's interval). False for NaN ends. That holds
/// - for a union whose tool stays below both ends of `f`, where each `max(f, g)` is `f`, or a
///   subtraction whose negated tool stays above both, where each `min(f, -g)` is `f`;
/// - when no box of the edit holds the whole region (`covered` false, so the result spans `f`
///   too), for a union whose tool stays below `f.hi`, or a subtraction whose negated tool
///   stays above `f.lo`, if neither end of `f` is zero: then the union gives
///   `[f.lo, f.hi + b / 4]` (its low end is `min(max(f.lo, g.lo), f.lo)`, which is `f.lo`
///   whatever `g.lo`) and the subtraction `[f.lo - b / 4, f.hi]` likewise. Zero ends are left
///   out because `max` and `min` may return either zero of a tie. This is what makes
///   intervals over boxes much larger than the edits (a mesher's upper octree levels) cheap:
///   most edits there are neither evaluated nor scanned.
#[inline]
pub(crate) fn keeps_interval(op: &EditOp, f: Interval, g_max: f64, covered: bool) -> bool {
    // The subtraction is the union of the negated tool, mirrored.
    let (lo, hi) = match op {
        EditOp::Union => (f.lo, f.hi),
        EditOp::Subtract => (-f.hi, -f.lo),
        EditOp::Intersect => return false,
        EditOp::Paint { .. } => return true,
    };
    // Nonzero and not NaN.
    let nonzero = |x: f64| x.abs() > 0.0;
    (g_max < lo && g_max < hi) || (!covered && g_max < hi && nonzero(lo) && nonzero(hi))
}

/// Value and gradient after an edit whose tool has the value and gradient `g`.
#[inline]
pub(crate) fn fold_grad(op: &EditOp, f: (f64, DVec3), g: (f64, DVec3), b: f64) -> (f64, DVec3) {
    let (g, dg) = g;
    match op {
        EditOp::Union => smooth_max_grad(f, (g, dg), b),
        EditOp::Subtract => smooth_min_grad(f, (-g, -dg), b),
        EditOp::Intersect => smooth_min_grad(f, (g, dg), b),
        EditOp::Paint { .. } => f,
    }
}

/// Interval after an edit whose tool has the interval `g` over a region; `covered` says
/// whether one of the edit's boxes holds the whole region (else the edit is inert over the
/// rest).
#[inline]
pub(crate) fn fold_interval(
    op: &EditOp,
    f: Interval,
    g: Interval,
    b: f64,
    covered: bool,
) -> Interval {
    let applied = match op {
        EditOp::Union => Interval::new(f.lo.max(g.lo), f.hi.max(g.hi) + b * 0.25),
        EditOp::Subtract => Interval::new(f.lo.min(-g.hi) - b * 0.25, f.hi.min(-g.lo)),
        EditOp::Intersect => Interval::new(f.lo.min(g.lo) - b * 0.25, f.hi.min(g.hi)),
        EditOp::Paint { .. } => f,
    };
    let applied = Interval {
        nan: f.nan,
        ..applied
    };
    if covered {
        return applied;
    }
    // Over the part of the region outside the boxes, unions and subtractions leave `f`
    // and an intersection leaves its outside value.
    let rest = match op {
        EditOp::Intersect => Interval::point(super::NOTHING),
        _ => f,
    };
    Interval {
        lo: applied.lo.min(rest.lo),
        hi: applied.hi.max(rest.hi),
        nan: f.nan,
    }
}

/// Smooth maximum with blending radius `k` (the plain maximum for `k = 0`); it exceeds the
/// maximum by at most `k / 4`.
#[inline]
pub fn smooth_max(a: f64, b: f64, k: f64) -> f64 {
    if k <= 0.0 {
        return a.max(b);
    }
    let h = 0.5 + 0.5 * (a - b) / k;
    // Outside the blend the result is exactly one of the operands (no cancellation when one
    // of them is NOTHING).
    if h >= 1.0 {
        a
    } else if h <= 0.0 {
        b
    } else {
        b + (a - b) * h + k * h * (1.0 - h)
    }
}

/// Smooth minimum, the mirror of [`smooth_max`].
#[inline]
pub fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    -smooth_max(-a, -b, k)
}

#[inline]
fn smooth_max_grad(a: (f64, DVec3), b: (f64, DVec3), k: f64) -> (f64, DVec3) {
    if k <= 0.0 {
        return if a.0 >= b.0 { a } else { b };
    }
    let h = 0.5 + 0.5 * (a.0 - b.0) / k;
    if h >= 1.0 {
        a
    } else if h <= 0.0 {
        b
    } else {
        let v = b.0 + (a.0 - b.0) * h + k * h * (1.0 - h);
        (v, b.1.lerp(a.1, h))
    }
}

#[inline]
fn smooth_min_grad(a: (f64, DVec3), b: (f64, DVec3), k: f64) -> (f64, DVec3) {
    let (v, g) = smooth_max_grad((-a.0, -a.1), (-b.0, -b.1), k);
    (-v, -g)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stroke drawn further takes the shorter stroke's values and gradients, bit for bit,
    /// outside the boxes `grown_from` gives, whichever tool, mirror and stamp count (past 32
    /// stamps a tool evaluates through its index); and only a continuation gets boxes.
    #[test]
    fn a_stroke_drawn_further_changes_only_where_grown_from_says() {
        let tools = [
            ToolShape::Sphere { radius: 0.05 },
            ToolShape::Box {
                half_extents: DVec3::new(0.04, 0.03, 0.05),
                rounding: 0.01,
            },
        ];
        let pose = |k: usize| {
            let t = k as f64 * 0.09;
            Pose::at(DVec3::new(t.cos() * 0.6, t.sin() * 0.6, 0.2 * t.sin()))
        };
        let compiled = |tool, mirror, n: usize, op| {
            let mut edit = Edit::stroke(op, tool, (0..n).map(pose).collect());
            edit.mirror = mirror;
            edit.blend_radius = 0.02;
            CompiledEdit::new(edit).unwrap()
        };
        let mut checked = 0;
        for tool in tools {
            for mirror in [None, Some(Axis::X)] {
                for (short, long) in [(1, 2), (2, 5), (20, 24), (30, 40), (45, 46)] {
                    let old = compiled(tool, mirror, short, EditOp::Subtract);
                    let new = compiled(tool, mirror, long, EditOp::Subtract);
                    let boxes = new.grown_from(&old).expect("a continuation");
                    let volume = |b: &Aabb| b.size().x * b.size().y * b.size().z;
                    if short >= 20 {
                        let (part, whole) = (volume(&boxes[0]), volume(&new.boxes()[0]));
                        assert!(part < 0.5 * whole, "{tool:?} {short}->{long}");
                    }
                    for i in 0..4000 {
                        let a = i as f64;
                        let p =
                            DVec3::new((a * 0.37).sin(), (a * 0.23).cos(), (a * 0.11).sin()) * 0.7;
                        // Stamp centres and their mirror images hit the ties.
                        let p = if i % 5 == 0 {
                            pose(i % long).position
                        } else {
                            p
                        };
                        let p = if i % 10 == 5 { Axis::X.reflect(p) } else { p };
                        if boxes.iter().any(|b| b.contains(p)) {
                            continue;
                        }
                        let (o, n) = (old.tool_eval(p), new.tool_eval(p));
                        assert!(
                            o.0.to_bits() == n.0.to_bits() && o.1 == n.1,
                            "{tool:?} {mirror:?} {short}->{long} at {p}: {o:?} {n:?}"
                        );
                        checked += 1;
                    }
                }
                let five = compiled(tool, mirror, 5, EditOp::Subtract);
                let union = compiled(tool, mirror, 8, EditOp::Union);
                assert!(union.grown_from(&five).is_none(), "another operation");
                assert!(
                    five.grown_from(&compiled(tool, mirror, 8, EditOp::Subtract))
                        .is_none()
                );
                let mut larger = Edit::clone(five.edit());
                larger.path.push(Pose {
                    scale: 2.0,
                    ..pose(5)
                });
                let larger = CompiledEdit::new(larger).unwrap();
                assert!(
                    larger.grown_from(&five).is_none(),
                    "every stamp's box widens"
                );
                let mut moved = Edit::clone(union.edit());
                moved.op = EditOp::Subtract;
                moved.path[0].position.x += 1e-3;
                let moved = CompiledEdit::new(moved).unwrap();
                assert!(moved.grown_from(&five).is_none(), "another first pose");
            }
        }
        assert!(checked > 50_000, "{checked} points outside the boxes");
    }

    #[test]
    fn smooth_operations_stay_within_a_quarter_radius() {
        for (a, b) in [(0.0, 0.0), (0.1, -0.2), (1.0, 0.9), (-0.5, 0.5)] {
            for k in [0.0, 0.1, 0.5] {
                let m = smooth_max(a, b, k);
                assert!(m >= a.max(b) && m <= a.max(b) + k / 4.0 + 1e-15);
                let n = smooth_min(a, b, k);
                assert!(n <= a.min(b) && n >= a.min(b) - k / 4.0 - 1e-15);
            }
        }
        assert_eq!(smooth_max(0.0, 1.0, 0.1), 1.0);
    }

    #[test]
    fn an_edit_that_keeps_the_value_folds_to_the_same_bits() {
        // Every `f` and every tool value `g <= g_max` over edge cases: where the shortcut
        // says the edit keeps `f`, the full fold gives `f` (intervals: the fold with
        // `[g_max, g_max]` gives the full fold's bits).
        let values = [
            f64::NEG_INFINITY,
            super::super::NOTHING,
            -1.0,
            -0.0125,
            -0.01,
            -1e-300,
            -0.0,
            0.0,
            1e-300,
            0.01,
            0.0125,
            1.0,
            f64::INFINITY,
            f64::NAN,
        ];
        let ops = [EditOp::Union, EditOp::Subtract, EditOp::Intersect];
        let (mut kept, mut n_intervals, mut n_outside) = (0, 0, 0);
        for op in &ops {
            for b in [0.0, 0.001, 0.02] {
                for g_max in [0.0, 0.01, 0.0100001] {
                    for &f in &values {
                        for &g in values.iter().filter(|&&g| g <= g_max) {
                            if keeps_value(op, f, g_max, b) {
                                kept += 1;
                                let v = fold_value(op, f, g, b);
                                assert_eq!(v.to_bits(), f.to_bits(), "{op:?} {f} {g} {b}");
                                let d = DVec3::new(0.5, -0.0, 2.0);
                                let (w, dw) = fold_grad(op, (f, d), (g, DVec3::X), b);
                                assert_eq!((w.to_bits(), dw), (f.to_bits(), d));
                            }
                        }
                        for &lo in &values {
                            let f = Interval {
                                lo,
                                hi: f,
                                nan: false,
                            };
                            for covered in [false, true] {
                                if !keeps_interval(op, f, g_max, covered) {
                                    continue;
                                }
                                // Kept only because the edit's boxes do not hold the region.
                                n_outside += usize::from(!keeps_interval(op, f, g_max, true));
                                for &glo in values.iter().filter(|&&g| g <= g_max) {
                                    for &ghi in values.iter().filter(|&&g| g <= g_max) {
                                        n_intervals += 1;
                                        let full = fold_interval(
                                            op,
                                            f,
                                            Interval::new(glo, ghi),
                                            b,
                                            covered,
                                        );
                                        let short = fold_interval(
                                            op,
                                            f,
                                            Interval::new(g_max, g_max),
                                            b,
                                            covered,
                                        );
                                        assert_eq!(
                                            (full.lo.to_bits(), full.hi.to_bits(), full.nan),
                                            (short.lo.to_bits(), short.hi.to_bits(), short.nan),
                                            "{op:?} {f:?} [{glo}, {ghi}] {b} {covered}"
                                        );
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(
            kept > 100 && n_intervals > 100 && n_outside > 100,
            "{kept} {n_intervals} {n_outside}"
        );
    }

    #[test]
    fn a_tool_stays_below_its_value_bound() {
        let shapes = [
            ToolShape::Sphere { radius: 0.3 },
            ToolShape::Box {
                half_extents: DVec3::new(0.2, 0.1, 0.3),
                rounding: 0.05,
            },
            ToolShape::Cylinder {
                radius: 0.15,
                half_height: 0.4,
            },
        ];
        for shape in shapes {
            let path = vec![
                Pose::at(DVec3::ZERO),
                Pose {
                    position: DVec3::new(0.3, 0.1, -0.2),
                    rotation: glam::DQuat::from_rotation_z(0.7),
                    scale: 1.7,
                },
            ];
            let mut edit = Edit::stroke(EditOp::Union, shape, path);
            edit.blend_radius = 0.01;
            edit.mirror = Some(Axis::Y);
            let e = CompiledEdit::new(edit).unwrap();
            let g_max = e.tool().value_max();
            let mut best = f64::NEG_INFINITY;
            for i in 0..4000 {
                let a = i as f64;
                let p = DVec3::new((a * 0.37).sin(), (a * 0.23).cos(), (a * 0.11).sin()) * 0.6;
                let v = e.tool_value(p);
                assert!(v <= g_max, "{shape:?} at {p}: {v} > {g_max}");
                best = best.max(v);
                let region = Aabb::around(p, DVec3::splat(0.01 + 0.001 * (i % 50) as f64));
                let iv = e.tool_interval(&region);
                let i_max = e.tool().interval_max(&region);
                assert!(iv.lo <= i_max && iv.hi <= i_max, "{shape:?} {region:?}");
            }
            // The bound is not vacuous: the tool's deepest points come close to it.
            assert!(best > 0.1 * g_max, "{shape:?}: {best} against {g_max}");
        }
    }

    #[test]
    fn mirrored_edits_act_on_both_sides() {
        let mut edit = Edit::stamp(
            EditOp::Union,
            ToolShape::Sphere { radius: 0.1 },
            Pose::at(DVec3::new(0.5, 0.0, 0.0)),
        );
        edit.mirror = Some(Axis::X);
        let e = CompiledEdit::new(edit).unwrap();
        assert!(e.paints(DVec3::new(0.5, 0.0, 0.0)));
        assert!(e.paints(DVec3::new(-0.5, 0.05, 0.0)));
        assert!(!e.paints(DVec3::ZERO));
        assert_eq!(e.apply_value(-1.0, DVec3::new(-0.5, 0.0, 0.0)), 0.1);
    }
}
