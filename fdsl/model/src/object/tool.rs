//! Sculpting tools: a bounded solid ([`ToolShape`]) placed at [`Pose`]s. A stroke, the tool
//! swept along a path, compiles to primitive stamps (capsules for a sphere, densified posed
//! copies for other shapes) indexed by their own [`Bvh`], so a point visits only the stamps
//! near it however long the stroke.
//!
//! Tool values follow the F-Rep sign (positive inside) and are distances, or bounds of
//! distances, so an interval over a box follows from one value at its centre and the
//! Lipschitz constant. A tool's support is its stamps' boxes grown by a margin: outside them
//! the tool is empty space ([`NOTHING`]).

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use super::{NOTHING, ObjectError};
use crate::bvh::{Aabb, Bvh};
use crate::limits::{MAX_STROKE_POSES, MAX_STROKE_STAMPS, MAX_TOOL_SIZE};
use fdsl::eval::Interval;

/// Strokes with more stamps than this get their own index.
const MIN_STAMP_INDEX: usize = 32;

/// The tool's solid, in its own coordinates (centred on the origin).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ToolShape {
    /// A ball.
    Sphere {
        /// Its radius.
        radius: f64,
    },
    /// A box with rounded edges.
    Box {
        /// Half the edge lengths.
        half_extents: DVec3,
        /// Edge rounding radius (at most the smallest half extent).
        rounding: f64,
    },
    /// A cylinder along the local y axis.
    Cylinder {
        /// Its radius.
        radius: f64,
        /// Half its height.
        half_height: f64,
    },
}

/// The kinds of [`ToolShape`], the names each is written and read by, and the sizes each is
/// given by ([`ToolSize`]): the one definition that the app's brush line and tool panel,
/// FVRML's `FEdit` and whatever else names a tool iterate ([`ToolKind::ALL`]), so that a new
/// kind is added in this file (its name, sizes and evaluation) and where render draws its
/// outline, and nowhere else.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ToolKind {
    /// [`ToolShape::Sphere`].
    Sphere,
    /// [`ToolShape::Box`].
    Box,
    /// [`ToolShape::Cylinder`].
    Cylinder,
}

impl ToolKind {
    /// Every kind, in the order lists show them.
    pub const ALL: [ToolKind; 3] = [ToolKind::Sphere, ToolKind::Box, ToolKind::Cylinder];

    /// The name files write and read (FVRML's `tool "sphere"`).
    pub fn name(self) -> &'static str {
        match self {
            ToolKind::Sphere => "sphere",
            ToolKind::Box => "box",
            ToolKind::Cylinder => "cylinder",
        }
    }

    /// The word people read and type for it (a brush line, a tool panel): a sphere is a
    /// "ball"; the other kinds are their [`ToolKind::name`].
    pub fn label(self) -> &'static str {
        match self {
            ToolKind::Sphere => "ball",
            other => other.name(),
        }
    }

    /// The kind `text` names, by its [`ToolKind::name`] or its [`ToolKind::label`].
    pub fn from_name(text: &str) -> Option<ToolKind> {
        ToolKind::ALL
            .into_iter()
            .find(|k| k.name() == text || k.label() == text)
    }

    /// The sizes a tool of this kind is given by, in the order files write them.
    pub fn sizes(self) -> &'static [ToolSize] {
        match self {
            ToolKind::Sphere => &[ToolSize::RADIUS],
            ToolKind::Box => &[ToolSize::HALF_EXTENTS, ToolSize::ROUNDING],
            ToolKind::Cylinder => &[ToolSize::RADIUS, ToolSize::HALF_HEIGHT],
        }
    }
}

/// One size a [`ToolKind`] is given by: what a file that writes a tool as its kind and named
/// sizes (FVRML's `FEdit`) reads and writes without knowing any kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolSize {
    /// The name files write and read (FVRML's `radius 0.1`).
    pub name: &'static str,
    /// How many numbers it holds: 1, or 3 for a vector.
    pub n_numbers: usize,
    /// Its value (each of its numbers) when left out; `None`: it must be given.
    pub default: Option<f64>,
}

impl ToolSize {
    /// A ball's or a cylinder's radius.
    pub const RADIUS: ToolSize = ToolSize {
        name: "radius",
        n_numbers: 1,
        default: None,
    };
    /// Half a cylinder's height.
    pub const HALF_HEIGHT: ToolSize = ToolSize {
        name: "halfHeight",
        n_numbers: 1,
        default: None,
    };
    /// Half a box's edge lengths.
    pub const HALF_EXTENTS: ToolSize = ToolSize {
        name: "halfExtents",
        n_numbers: 3,
        default: None,
    };
    /// A box's edge rounding radius (sharp edges when left out).
    pub const ROUNDING: ToolSize = ToolSize {
        name: "rounding",
        n_numbers: 1,
        default: Some(0.0),
    };
    /// Every size of every kind, each once, in the order files write them.
    pub const ALL: [ToolSize; 4] = [
        ToolSize::RADIUS,
        ToolSize::HALF_HEIGHT,
        ToolSize::HALF_EXTENTS,
        ToolSize::ROUNDING,
    ];
}

impl ToolShape {
    /// The tool of `kind` that fits a box `2 * size` across, as a brush of that size makes
    /// it: a ball of radius `size`, a cube of half edge `size` with edges rounded by a fifth
    /// of it, a cylinder of radius `size` as tall as it is wide.
    pub fn of_kind(kind: ToolKind, size: f64) -> ToolShape {
        match kind {
            ToolKind::Sphere => ToolShape::Sphere { radius: size },
            ToolKind::Box => ToolShape::Box {
                half_extents: DVec3::splat(size),
                rounding: size * 0.2,
            },
            ToolKind::Cylinder => ToolShape::Cylinder {
                radius: size,
                half_height: size,
            },
        }
    }

    /// The tool of `kind` whose sizes ([`ToolKind::sizes`], in that order) hold `values`,
    /// each with as many numbers as its size takes; `None` when `values` do not fit those
    /// sizes. Whether the tool is valid is left to [`crate::object::CompiledEdit::new`], as
    /// for any edit.
    pub fn from_sizes(kind: ToolKind, values: &[Vec<f64>]) -> Option<ToolShape> {
        let sizes = kind.sizes();
        let fits = values.len() == sizes.len()
            && (sizes.iter().zip(values)).all(|(s, v)| v.len() == s.n_numbers);
        if !fits {
            return None;
        }
        Some(match kind {
            ToolKind::Sphere => ToolShape::Sphere {
                radius: values[0][0],
            },
            ToolKind::Box => ToolShape::Box {
                half_extents: DVec3::from_slice(&values[0]),
                rounding: values[1][0],
            },
            ToolKind::Cylinder => ToolShape::Cylinder {
                radius: values[0][0],
                half_height: values[1][0],
            },
        })
    }

    /// The values of its kind's sizes ([`ToolKind::sizes`]), in that order: what
    /// [`ToolShape::from_sizes`] takes back.
    pub fn size_values(&self) -> Vec<Vec<f64>> {
        match *self {
            ToolShape::Sphere { radius } => vec![vec![radius]],
            ToolShape::Box {
                half_extents,
                rounding,
            } => vec![half_extents.to_array().to_vec(), vec![rounding]],
            ToolShape::Cylinder {
                radius,
                half_height,
            } => vec![vec![radius], vec![half_height]],
        }
    }

    /// Its kind.
    pub fn kind(&self) -> ToolKind {
        match self {
            ToolShape::Sphere { .. } => ToolKind::Sphere,
            ToolShape::Box { .. } => ToolKind::Box,
            ToolShape::Cylinder { .. } => ToolKind::Cylinder,
        }
    }

    /// Half the edge lengths of the box around the shape.
    pub fn half_extents(&self) -> DVec3 {
        match *self {
            ToolShape::Sphere { radius } => DVec3::splat(radius),
            ToolShape::Box { half_extents, .. } => half_extents,
            ToolShape::Cylinder {
                radius,
                half_height,
            } => DVec3::new(radius, half_height, radius),
        }
    }

    fn validate(&self) -> Result<(), ObjectError> {
        let h = self.half_extents();
        let ok = h.is_finite() && h.min_element() > 0.0 && h.max_element() <= MAX_TOOL_SIZE;
        let rounding_ok = match *self {
            ToolShape::Box {
                rounding,
                half_extents,
            } => rounding.is_finite() && rounding >= 0.0 && rounding <= half_extents.min_element(),
            _ => true,
        };
        if ok && rounding_ok {
            Ok(())
        } else {
            Err(ObjectError::BadTool {
                reason: "tool sizes must be positive, finite and at most MAX_TOOL_SIZE",
            })
        }
    }
}

/// Where a tool is: position, orientation and a uniform scale, in object coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// The tool's centre.
    pub position: DVec3,
    /// Its orientation (normalised when compiled).
    pub rotation: DQuat,
    /// Uniform scale (positive).
    pub scale: f64,
}

impl Pose {
    /// A pose at `position`, unrotated and unscaled.
    pub fn at(position: DVec3) -> Pose {
        Pose {
            position,
            rotation: DQuat::IDENTITY,
            scale: 1.0,
        }
    }

    fn is_valid(&self) -> bool {
        self.position.is_finite()
            && self.position.abs().max_element() <= MAX_TOOL_SIZE
            && self.rotation.is_finite()
            && self.rotation.length_squared() > 1e-12
            && self.scale.is_finite()
            && self.scale > 0.0
            && self.scale <= MAX_TOOL_SIZE
    }
}

/// One primitive of a compiled tool.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Stamp {
    /// Points within a linearly varying radius of the segment `a`-`b`.
    Capsule {
        a: DVec3,
        b: DVec3,
        radius_a: f64,
        radius_b: f64,
    },
    /// A box or cylinder at a pose (the shape is the tool's: every stamp of a tool has the
    /// same, so it is not copied into each).
    Posed {
        position: DVec3,
        rotation: DQuat,
        scale: f64,
    },
}

impl Stamp {
    fn aabb(&self, shape: ToolShape) -> Aabb {
        match *self {
            Stamp::Capsule {
                a,
                b,
                radius_a,
                radius_b,
            } => Aabb::new(a, b).expand(radius_a.max(radius_b)),
            Stamp::Posed {
                position,
                rotation,
                scale,
            } => {
                let half = shape.half_extents() * scale;
                let m = glam::DMat3::from_quat(rotation);
                let extent = DVec3::new(
                    m.row(0).abs().dot(half),
                    m.row(1).abs().dot(half),
                    m.row(2).abs().dot(half),
                );
                Aabb::around(position, extent)
            }
        }
    }

    /// A bound of how fast the value changes with distance.
    fn lipschitz(&self) -> f64 {
        match *self {
            Stamp::Capsule {
                a,
                b,
                radius_a,
                radius_b,
            } => {
                let len = a.distance(b);
                if len > 0.0 {
                    1.0 + (radius_b - radius_a).abs() / len
                } else {
                    1.0
                }
            }
            Stamp::Posed { .. } => 1.0,
        }
    }

    /// Value (positive inside) and gradient at `p`.
    #[inline]
    fn eval(&self, shape: ToolShape, p: DVec3) -> (f64, DVec3) {
        match *self {
            Stamp::Capsule {
                a,
                b,
                radius_a,
                radius_b,
            } => {
                let Closest { ab, len2, s, c, r } = closest(a, b, radius_a, radius_b, p);
                let d = p - c;
                let len = d.length();
                let mut grad = if len > 0.0 { -d / len } else { DVec3::ZERO };
                if s > 0.0 && s < 1.0 {
                    // The radius varies with the closest point's parameter.
                    grad += ab * ((radius_b - radius_a) / len2);
                }
                (r - len, grad)
            }
            Stamp::Posed {
                position,
                rotation,
                scale,
            } => {
                let q = rotation.inverse() * (p - position) / scale;
                let (sd, g) = local_sdf(shape, q);
                (-sd * scale, -(rotation * g))
            }
        }
    }
}

/// The point of a capsule's axis closest to a point, and what finding it computed.
struct Closest {
    /// The axis, `b - a`, and its squared length.
    ab: DVec3,
    len2: f64,
    /// The closest point's parameter along the axis, in [0, 1].
    s: f64,
    /// The closest point, and the radius there.
    c: DVec3,
    r: f64,
}

/// The point of the axis from `a` to `b` closest to `p`, and the radius there: the shared
/// start of [`Stamp::eval`] and [`Stamp::value`], so that both compute it by the same
/// operations.
#[inline(always)]
fn closest(a: DVec3, b: DVec3, radius_a: f64, radius_b: f64, p: DVec3) -> Closest {
    let ab = b - a;
    let len2 = ab.length_squared();
    let s = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let c = a + ab * s;
    let r = radius_a + (radius_b - radius_a) * s;
    Closest { ab, len2, s, c, r }
}

impl Stamp {
    /// The value of [`Stamp::eval`] alone, by the same operations (so the same bits) without
    /// the gradient's.
    #[inline(always)]
    fn value(&self, shape: ToolShape, p: DVec3) -> f64 {
        match *self {
            Stamp::Capsule {
                a,
                b,
                radius_a,
                radius_b,
            } => {
                let Closest { c, r, .. } = closest(a, b, radius_a, radius_b, p);
                r - (p - c).length()
            }
            Stamp::Posed {
                position,
                rotation,
                scale,
            } => {
                let q = rotation.inverse() * (p - position) / scale;
                -local_distance(shape, q) * scale
            }
        }
    }
}

/// The distance of [`local_sdf`] alone, by the same operations.
#[inline]
fn local_distance(shape: ToolShape, q: DVec3) -> f64 {
    match shape {
        ToolShape::Box {
            half_extents,
            rounding,
        } => {
            let d = q.abs() - (half_extents - DVec3::splat(rounding));
            let len = d.max(DVec3::ZERO).length();
            if len > 0.0 {
                len - rounding
            } else {
                d[d.max_position()] - rounding
            }
        }
        ToolShape::Cylinder {
            radius,
            half_height,
        } => {
            let radial = (q.x * q.x + q.z * q.z).sqrt();
            let dr = radial - radius;
            let dy = q.y.abs() - half_height;
            if dr > 0.0 && dy > 0.0 {
                (dr * dr + dy * dy).sqrt()
            } else if dr > dy {
                dr
            } else {
                dy
            }
        }
        ToolShape::Sphere { radius } => q.length() - radius,
    }
}

/// Signed distance (negative inside) and its gradient, for boxes and cylinders.
///
/// Always inlined: called, it returned the four numbers through memory, and its caller read
/// them back in pieces that straddled its stores, a stall on every posed stamp.
#[inline(always)]
fn local_sdf(shape: ToolShape, q: DVec3) -> (f64, DVec3) {
    match shape {
        ToolShape::Box {
            half_extents,
            rounding,
        } => {
            let d = q.abs() - (half_extents - DVec3::splat(rounding));
            let outside = d.max(DVec3::ZERO);
            let len = outside.length();
            if len > 0.0 {
                (len - rounding, q.signum() * outside / len)
            } else {
                let axis = d.max_position();
                let mut g = DVec3::ZERO;
                g[axis] = q[axis].signum();
                (d[axis] - rounding, g)
            }
        }
        ToolShape::Cylinder {
            radius,
            half_height,
        } => {
            let radial = (q.x * q.x + q.z * q.z).sqrt();
            let dr = radial - radius;
            let dy = q.y.abs() - half_height;
            let radial_dir = if radial > 0.0 {
                DVec3::new(q.x / radial, 0.0, q.z / radial)
            } else {
                DVec3::X
            };
            let axial_dir = DVec3::new(0.0, q.y.signum(), 0.0);
            if dr > 0.0 && dy > 0.0 {
                let len = (dr * dr + dy * dy).sqrt();
                (len, (radial_dir * dr + axial_dir * dy) / len)
            } else if dr > dy {
                (dr, radial_dir)
            } else {
                (dy, axial_dir)
            }
        }
        ToolShape::Sphere { radius } => {
            let len = q.length();
            let g = if len > 0.0 { q / len } else { DVec3::ZERO };
            (len - radius, g)
        }
    }
}

/// A tool swept along a path, ready to evaluate.
#[derive(Clone, Debug)]
pub(crate) struct CompiledTool {
    /// Each stamp with its box grown by the margin, side by side so that a scan reads one
    /// contiguous array.
    stamps: Vec<(Aabb, Stamp)>,
    /// An index over the boxes when there are many stamps (boxed: most tools have few, and
    /// an absent index then costs a pointer).
    stamp_index: Option<Box<Bvh>>,
    /// How far each stamp's box is grown: beyond it the stamp's distance is at least this, and
    /// the tool counts as empty space there.
    margin: f64,
    lipschitz: f64,
}

impl CompiledTool {
    /// Compiles `shape` swept along `path`; `extra_margin` (a blend radius) widens the band
    /// in which values are exact.
    pub(crate) fn new(
        shape: ToolShape,
        path: &[Pose],
        extra_margin: f64,
    ) -> Result<CompiledTool, ObjectError> {
        shape.validate()?;
        if path.is_empty() || path.len() > MAX_STROKE_POSES {
            return Err(ObjectError::BadStroke {
                reason: "a stroke needs 1 to MAX_STROKE_POSES poses",
            });
        }
        if !path.iter().all(Pose::is_valid) {
            return Err(ObjectError::BadStroke {
                reason: "poses must be finite, with positive scale and a non-zero rotation",
            });
        }
        let poses: Vec<Pose> = path
            .iter()
            .map(|p| Pose {
                rotation: p.rotation.normalize(),
                ..*p
            })
            .collect();
        let stamps = stamps_along(shape, &poses)?;
        let size = poses
            .iter()
            .map(|p| shape.half_extents().max_element() * p.scale)
            .fold(0.0, f64::max);
        let margin = 0.5 * size + extra_margin;
        let stamp_boxes: Vec<Aabb> = stamps
            .iter()
            .map(|s| s.aabb(shape).expand(margin))
            .collect();
        let stamp_index =
            (stamps.len() > MIN_STAMP_INDEX).then(|| Box::new(Bvh::build(&stamp_boxes)));
        let lipschitz = stamps.iter().map(Stamp::lipschitz).fold(1.0, f64::max);
        let stamps = stamp_boxes.into_iter().zip(stamps).collect();
        Ok(CompiledTool {
            stamps,
            stamp_index,
            margin,
            lipschitz,
        })
    }

    /// The box around the tool's support (outside it the tool is empty space): the union of
    /// the stamps' grown boxes, computed on each call (an edit keeps it; see
    /// [`CompiledEdit::boxes`](super::edit::CompiledEdit::boxes)).
    pub(crate) fn bounds(&self) -> Aabb {
        self.stamps.iter().fold(Aabb::EMPTY, |a, (b, _)| a.union(b))
    }

    /// The band half-width within which values are exact.
    pub(crate) fn margin(&self) -> f64 {
        self.margin
    }

    /// An upper bound of the tool's value anywhere: see [`value_max`].
    pub(crate) fn value_max(&self) -> f64 {
        value_max(self.margin)
    }

    /// An upper bound of every end of [`CompiledTool::interval`] over `region`: see
    /// [`interval_max`].
    pub(crate) fn interval_max(&self, region: &Aabb) -> f64 {
        interval_max(value_max(self.margin), self.lipschitz, region)
    }

    /// The box within which `self` can take other values than `earlier` when it is `earlier`
    /// swept further: the same stamps first, grown by the same margin, with the same slope
    /// bound. It holds the boxes of the stamps after the shared ones and of `earlier`'s last
    /// (a one-pose stroke's capsule is the point's, which the next pose replaces); elsewhere
    /// both are the best of the same stamps. `None` when `self` is not such a continuation.
    pub(crate) fn grown_from(&self, earlier: &CompiledTool) -> Option<Aabb> {
        let n = earlier.stamps.len();
        let continues = self.margin == earlier.margin
            && self.lipschitz == earlier.lipschitz
            && n > 0
            && self.stamps.len() >= n
            && self.stamps[..n - 1] == earlier.stamps[..n - 1];
        if !continues {
            return None;
        }
        let fresh = self.stamps[n - 1..].iter().chain(&earlier.stamps[n - 1..]);
        Some(fresh.fold(Aabb::EMPTY, |a, (b, _)| a.union(b)))
    }

    /// Number of primitive stamps.
    pub(crate) fn n_stamps(&self) -> usize {
        self.stamps.len()
    }

    /// Value and gradient at `p`: the best of the stamps whose grown boxes hold `p`, and
    /// empty space ([`NOTHING`]) where none does (a tool's support is its stamps' boxes).
    #[inline]
    pub(crate) fn eval(&self, shape: ToolShape, p: DVec3) -> (f64, DVec3) {
        let Some(bvh) = &self.stamp_index else {
            return scan_eval(&self.stamps, shape, p);
        };
        let mut best = (NOTHING, DVec3::ZERO);
        bvh.visit_point(p, |i| {
            let (bounds, stamp) = &self.stamps[i as usize];
            if bounds.contains(p) {
                let v = stamp.eval(shape, p);
                if v.0 > best.0 {
                    best = v;
                }
            }
        });
        best
    }

    /// The stamps with their grown boxes when a query scans them all (no index of their own),
    /// and the Lipschitz bound: what an edit arena copies to evaluate the tool without it.
    pub(crate) fn scanned_stamps(&self) -> Option<(&[(Aabb, Stamp)], f64)> {
        match self.stamp_index {
            Some(_) => None,
            None => Some((&self.stamps, self.lipschitz)),
        }
    }

    /// The value by definition, visiting every stamp without the index (for checks).
    pub(crate) fn raw_value(&self, shape: ToolShape, p: DVec3) -> f64 {
        self.stamps
            .iter()
            .filter(|(b, _)| b.contains(p))
            .map(|(_, s)| s.eval(shape, p).0)
            .fold(NOTHING, f64::max)
    }

    /// The value of [`CompiledTool::eval`] alone (the same bits, without the gradients).
    #[inline]
    pub(crate) fn value(&self, shape: ToolShape, p: DVec3) -> f64 {
        let Some(bvh) = &self.stamp_index else {
            return scan_value(&self.stamps, shape, p);
        };
        let mut best = NOTHING;
        bvh.visit_point(p, |i| {
            let (bounds, stamp) = &self.stamps[i as usize];
            if bounds.contains(p) {
                let v = stamp.value(shape, p);
                if v > best {
                    best = v;
                }
            }
        });
        best
    }

    /// An interval holding every value over `region`.
    pub(crate) fn interval(&self, shape: ToolShape, region: &Aabb) -> Interval {
        let Some(bvh) = &self.stamp_index else {
            return scan_interval(
                &self.stamps,
                shape,
                self.lipschitz,
                self.value_max(),
                region,
            );
        };
        let mut bounds = StampBounds::new(shape, self.lipschitz, self.value_max(), region);
        bvh.visit_box(region, |i| bounds.add(&self.stamps[i as usize]));
        bounds.interval()
    }
}

/// An upper bound of the value of a tool of margin `margin`, at any point: a stamp's value is
/// at most its largest half-size (a capsule's `r - len` is at most its larger radius, a posed
/// box's or cylinder's negated distance at most its half-size times its scale, and empty
/// space is [`NOTHING`]), the tool's half-size `size` is the largest of those, and its margin
/// is `size / 2` plus a blend radius that is not negative. The relative `1e-9` covers the
/// rounding of the stamps' arithmetic (a few ulps). Mirrors take the larger of two values of
/// the same tool, so the bound holds for them too.
#[inline]
pub(crate) fn value_max(margin: f64) -> f64 {
    2.0 * margin * (1.0 + 1e-9)
}

/// An upper bound of both ends of a tool's interval over `region` (from [`scan_interval`] or
/// [`CompiledTool::interval`], mirror included) given the tool's [`value_max`] and Lipschitz
/// bound: every end is `NOTHING` or a stamp's value at the centre plus or minus the same
/// `spread`, computed here as they compute it (rounding is monotone, so `v <= value_max`
/// gives `v + spread <= value_max + spread` in floating point too), the upper one capped at
/// `value_max`. So the bound is `value_max` over any region whose size is a number: whether
/// an edit's interval can change a fold does not depend on how large the region is. NaN when
/// the region's size is NaN (then no comparison with it holds).
#[inline]
pub(crate) fn interval_max(value_max: f64, lipschitz: f64, region: &Aabb) -> f64 {
    capped(value_max + spread(lipschitz, region), value_max)
}

/// `v`, or `cap` where `v` exceeds it; NaN stays NaN (unlike `f64::min`).
#[inline]
fn capped(v: f64, cap: f64) -> f64 {
    if v > cap { cap } else { v }
}

/// How far a tool's value can move from the region's centre within the region.
#[inline]
fn spread(lipschitz: f64, region: &Aabb) -> f64 {
    region.size().length() * 0.5 * lipschitz
}

/// A tool's value and gradient at `p` from its stamps in order, without an index: the best of
/// the stamps whose grown boxes hold `p`, else empty space ([`NOTHING`]).
#[inline]
pub(crate) fn scan_eval<'a>(
    stamps: impl IntoIterator<Item = &'a (Aabb, Stamp)>,
    shape: ToolShape,
    p: DVec3,
) -> (f64, DVec3) {
    let mut best = (NOTHING, DVec3::ZERO);
    for (bounds, stamp) in stamps {
        if bounds.contains(p) {
            let v = stamp.eval(shape, p);
            if v.0 > best.0 {
                best = v;
            }
        }
    }
    best
}

/// The value of [`scan_eval`] alone (the same bits, without the gradients).
#[inline]
pub(crate) fn scan_value<'a>(
    stamps: impl IntoIterator<Item = &'a (Aabb, Stamp)>,
    shape: ToolShape,
    p: DVec3,
) -> f64 {
    let mut best = NOTHING;
    for (bounds, stamp) in stamps {
        if bounds.contains(p) {
            let v = stamp.value(shape, p);
            if v > best {
                best = v;
            }
        }
    }
    best
}

/// A tool's interval over `region` from its stamps in order, without an index; `value_max`
/// is the tool's [`value_max`].
pub(crate) fn scan_interval<'a>(
    stamps: impl IntoIterator<Item = &'a (Aabb, Stamp)>,
    shape: ToolShape,
    lipschitz: f64,
    value_max: f64,
    region: &Aabb,
) -> Interval {
    let mut bounds = StampBounds::new(shape, lipschitz, value_max, region);
    stamps.into_iter().for_each(|stamp| bounds.add(stamp));
    bounds.interval()
}

/// A tool's interval over a region, gathered stamp by stamp in any order. Over the region
/// each stamp whose box meets it is within `spread` of its value at the centre, and no value
/// of the tool exceeds its [`value_max`] (over a region much larger than the stamp, the
/// first bound alone would be loose by about the region's size); where no stamp box holds a
/// point the tool is empty space.
struct StampBounds<'r> {
    shape: ToolShape,
    region: &'r Aabb,
    center: DVec3,
    spread: f64,
    value_max: f64,
    lo: f64,
    hi: f64,
}

impl<'r> StampBounds<'r> {
    fn new(shape: ToolShape, lipschitz: f64, value_max: f64, region: &'r Aabb) -> Self {
        StampBounds {
            shape,
            region,
            center: region.center(),
            spread: spread(lipschitz, region),
            value_max,
            lo: NOTHING,
            hi: NOTHING,
        }
    }

    fn add(&mut self, (bounds, stamp): &(Aabb, Stamp)) {
        if bounds.overlaps(self.region) {
            let v = stamp.value(self.shape, self.center);
            self.hi = self.hi.max(capped(v + self.spread, self.value_max));
            if bounds.contains_box(self.region) {
                self.lo = self.lo.max(v - self.spread);
            }
        }
    }

    fn interval(&self) -> Interval {
        Interval::new(self.lo, self.hi)
    }
}

/// Primitive stamps for `shape` along `poses`.
fn stamps_along(shape: ToolShape, poses: &[Pose]) -> Result<Vec<Stamp>, ObjectError> {
    let too_long = ObjectError::BadStroke {
        reason: "the stroke expands to more than MAX_STROKE_STAMPS stamps",
    };
    if let ToolShape::Sphere { radius } = shape {
        let capsule = |a: &Pose, b: &Pose| Stamp::Capsule {
            a: a.position,
            b: b.position,
            radius_a: radius * a.scale,
            radius_b: radius * b.scale,
        };
        if poses.len() == 1 {
            return Ok(vec![capsule(&poses[0], &poses[0])]);
        }
        return Ok(poses.windows(2).map(|w| capsule(&w[0], &w[1])).collect());
    }
    let posed = |p: &Pose| Stamp::Posed {
        position: p.position,
        rotation: p.rotation,
        scale: p.scale,
    };
    let mut stamps = vec![posed(&poses[0])];
    for w in poses.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        // Keep consecutive copies within half the tool's smallest half-size of each other.
        let spacing = 0.5 * shape.half_extents().min_element() * a.scale.min(b.scale);
        let steps = (a.position.distance(b.position) / spacing).ceil().max(1.0);
        if !steps.is_finite() || stamps.len() as f64 + steps > MAX_STROKE_STAMPS as f64 {
            return Err(too_long);
        }
        let steps = steps as usize;
        for k in 1..=steps {
            let s = k as f64 / steps as f64;
            stamps.push(posed(&Pose {
                position: a.position.lerp(b.position, s),
                rotation: a.rotation.slerp(b.rotation, s),
                scale: a.scale + (b.scale - a.scale) * s,
            }));
        }
    }
    Ok(stamps)
}

/// The mirror plane of a symmetric edit: through the object's origin, normal to an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Axis {
    /// Normal along x (the plane x = 0).
    X,
    /// Normal along y.
    Y,
    /// Normal along z.
    Z,
}

impl Axis {
    /// Reflects `p` in the plane.
    #[inline]
    pub fn reflect(self, mut p: DVec3) -> DVec3 {
        p[self as usize] = -p[self as usize];
        p
    }

    /// Reflects a box.
    pub fn reflect_box(self, b: &Aabb) -> Aabb {
        Aabb::new(self.reflect(b.lo), self.reflect(b.hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn finite_difference(tool: &CompiledTool, shape: ToolShape, p: DVec3) -> DVec3 {
        let h = 1e-6;
        DVec3::new(
            tool.value(shape, p + DVec3::X * h) - tool.value(shape, p - DVec3::X * h),
            tool.value(shape, p + DVec3::Y * h) - tool.value(shape, p - DVec3::Y * h),
            tool.value(shape, p + DVec3::Z * h) - tool.value(shape, p - DVec3::Z * h),
        ) / (2.0 * h)
    }

    /// Each kind is named once, read back by its name and its label, and makes a valid
    /// tool of its own kind.
    #[test]
    fn tool_kinds_are_named_once_and_make_their_shapes() {
        for kind in ToolKind::ALL {
            assert_eq!(ToolKind::from_name(kind.name()), Some(kind));
            assert_eq!(ToolKind::from_name(kind.label()), Some(kind));
            let tool = ToolShape::of_kind(kind, 0.25);
            assert_eq!(tool.kind(), kind);
            assert_eq!(ToolShape::from_sizes(kind, &tool.size_values()), Some(tool));
            assert_eq!(ToolShape::from_sizes(kind, &[]), None);
            assert_eq!(ToolShape::from_sizes(kind, &vec![vec![1.0; 2]; 2]), None);
            assert!(kind.sizes().iter().all(|s| ToolSize::ALL.contains(s)));
            assert!(tool.validate().is_ok(), "{tool:?}");
            assert_eq!(tool.half_extents().max_element(), 0.25, "{tool:?}");
            let others = ToolKind::ALL.into_iter().filter(|k| *k != kind);
            for other in others {
                assert!(other.name() != kind.name() && other.label() != kind.label());
            }
        }
        assert_eq!(ToolKind::from_name("ball"), Some(ToolKind::Sphere));
        assert_eq!(ToolKind::from_name("cone"), None);
    }

    #[test]
    fn stamp_values_are_the_values_of_their_evaluation() {
        let shapes = [
            ToolShape::Sphere { radius: 0.1 },
            ToolShape::Box {
                half_extents: DVec3::new(0.2, 0.1, 0.3),
                rounding: 0.02,
            },
            ToolShape::Box {
                half_extents: DVec3::splat(0.1),
                rounding: 0.0,
            },
            ToolShape::Cylinder {
                radius: 0.15,
                half_height: 0.2,
            },
        ];
        let path = [
            Pose::at(DVec3::ZERO),
            Pose {
                position: DVec3::new(0.2, 0.1, 0.0),
                rotation: DQuat::from_rotation_z(0.3),
                scale: 1.5,
            },
            Pose::at(DVec3::new(0.2, 0.1, 0.0)),
        ];
        let mut n = 0;
        for shape in shapes {
            let tool = CompiledTool::new(shape, &path, 0.01).unwrap();
            for i in 0..2000 {
                let a = i as f64;
                let p = DVec3::new((a * 0.37).sin(), (a * 0.23).cos(), (a * 0.11).sin()) * 0.5;
                // Points on the axes and the stamps' centres hit the ties and zero lengths.
                let p = match i % 7 {
                    0 => DVec3::new(p.x, 0.0, 0.0),
                    1 => path[i % 3].position,
                    _ => p,
                };
                for (_, stamp) in &tool.stamps {
                    assert_eq!(
                        stamp.value(shape, p).to_bits(),
                        stamp.eval(shape, p).0.to_bits()
                    );
                    n += 1;
                }
                assert_eq!(
                    tool.value(shape, p).to_bits(),
                    tool.eval(shape, p).0.to_bits()
                );
                assert_eq!(
                    scan_value(&tool.stamps, shape, p).to_bits(),
                    scan_eval(&tool.stamps, shape, p).0.to_bits()
                );
            }
        }
        assert!(n > 10_000);
    }

    #[test]
    fn sphere_stroke_is_a_chain_of_capsules() {
        let path = [
            Pose::at(DVec3::ZERO),
            Pose::at(DVec3::X),
            Pose::at(DVec3::new(1.0, 1.0, 0.0)),
        ];
        let shape = ToolShape::Sphere { radius: 0.1 };
        let tool = CompiledTool::new(shape, &path, 0.0).unwrap();
        assert_eq!(tool.n_stamps(), 2);
        assert!((tool.value(shape, DVec3::new(0.5, 0.05, 0.0)) - 0.05).abs() < 1e-12);
        assert!((tool.value(shape, DVec3::new(1.0, 0.5, 0.08)) - 0.02).abs() < 1e-12);
        // Away from every stamp the tool is empty space.
        assert_eq!(tool.value(shape, DVec3::splat(10.0)), NOTHING);
        assert!(tool.margin() > 0.0);
        let p = DVec3::new(0.3, 0.07, 0.02);
        let g = tool.eval(shape, p).1;
        assert!((g - finite_difference(&tool, shape, p)).length() < 1e-6);
    }

    #[test]
    fn box_and_cylinder_stamps_have_distance_values_and_gradients() {
        let rotation = DQuat::from_rotation_z(0.3);
        for shape in [
            ToolShape::Box {
                half_extents: DVec3::new(0.2, 0.1, 0.3),
                rounding: 0.02,
            },
            ToolShape::Cylinder {
                radius: 0.15,
                half_height: 0.2,
            },
        ] {
            let pose = Pose {
                position: DVec3::new(0.1, 0.2, 0.3),
                rotation,
                scale: 1.5,
            };
            let tool = CompiledTool::new(shape, &[pose], 0.0).unwrap();
            assert!(
                tool.value(shape, pose.position) > 0.0,
                "{shape:?} centre is inside"
            );
            for p in [
                DVec3::new(0.3, 0.25, 0.31),
                DVec3::new(0.15, 0.5, 0.2),
                DVec3::new(-0.1, 0.2, 0.45),
            ] {
                let (v, g) = tool.eval(shape, p);
                if v > -tool.margin() + 1e-3 && v > NOTHING {
                    let fd = finite_difference(&tool, shape, p);
                    assert!((g - fd).length() < 1e-5, "{shape:?} at {p}: {g} vs {fd}");
                }
            }
        }
    }

    #[test]
    fn long_strokes_are_indexed_and_agree_with_brute_force() {
        let path: Vec<Pose> = (0..200)
            .map(|i| {
                let a = i as f64 * 0.05;
                Pose::at(DVec3::new(a.cos(), a.sin(), a * 0.1))
            })
            .collect();
        let shape = ToolShape::Box {
            half_extents: DVec3::splat(0.05),
            rounding: 0.0,
        };
        let tool = CompiledTool::new(shape, &path, 0.0).unwrap();
        assert!(tool.stamp_index.is_some());
        for i in 0..300 {
            let a = i as f64 * 0.0371;
            let p = DVec3::new(a.cos() * 1.02, a.sin(), a * 0.1 + 0.01);
            let brute = tool.raw_value(shape, p);
            assert_eq!(tool.value(shape, p), brute, "at {p}");
        }
    }

    #[test]
    fn intervals_enclose_values() {
        let shape = ToolShape::Sphere { radius: 0.3 };
        let tool = CompiledTool::new(
            shape,
            &[Pose::at(DVec3::ZERO), Pose::at(DVec3::new(0.5, 0.0, 0.0))],
            0.1,
        )
        .unwrap();
        let region = Aabb::new(DVec3::new(0.1, 0.1, 0.1), DVec3::new(0.4, 0.3, 0.2));
        let iv = tool.interval(shape, &region);
        for i in 0..=10 {
            let s = i as f64 / 10.0;
            let p = region.lo.lerp(region.hi, s);
            assert!(iv.contains(tool.value(shape, p)), "{iv:?} at {p}");
        }
    }

    #[test]
    fn intervals_over_regions_larger_than_the_tool_stay_within_its_value_bound() {
        // Over a region much larger than a stamp, a stamp's value at the centre plus the
        // region's spread is loose by about the region's size; no value exceeds the tool's
        // `value_max`, so the interval's upper end is capped there, and still holds every
        // value. Short strokes scan their stamps, long ones go through their own index.
        let shapes = [
            ToolShape::Sphere { radius: 0.05 },
            ToolShape::Box {
                half_extents: DVec3::new(0.04, 0.02, 0.05),
                rounding: 0.01,
            },
            ToolShape::Cylinder {
                radius: 0.03,
                half_height: 0.06,
            },
        ];
        let mut rng = testkit::rng::XorShift64(0x51ed_270b_27c5_3a41);
        let mut next = move || rng.unit_f64();
        for shape in shapes {
            for n_poses in [2, MIN_STAMP_INDEX + 20] {
                let poses: Vec<Pose> = (0..n_poses)
                    .map(|k| Pose::at(DVec3::new(0.01 * k as f64, 0.2, -0.1)))
                    .collect();
                let tool = CompiledTool::new(shape, &poses, 0.0).unwrap();
                assert_eq!(tool.stamp_index.is_some(), n_poses > 2);
                let value_max = tool.value_max();
                for half in [0.01, 0.1, 0.5, 2.0] {
                    let region = Aabb::around(poses[0].position, DVec3::splat(half));
                    let iv = tool.interval(shape, &region);
                    assert!(iv.hi <= value_max, "{iv:?} over a box of half size {half}");
                    if half >= 0.5 {
                        assert_eq!(iv.hi, value_max, "the cap bites over large boxes");
                    }
                    for _ in 0..500 {
                        let s = DVec3::new(next(), next(), next());
                        let p = region.lo + (region.hi - region.lo) * s;
                        assert!(iv.contains(tool.value(shape, p)), "{iv:?} at {p}");
                    }
                }
            }
        }
    }

    #[test]
    fn bad_tools_and_strokes_are_errors() {
        let sphere = ToolShape::Sphere { radius: 0.1 };
        assert!(CompiledTool::new(sphere, &[], 0.0).is_err());
        assert!(
            CompiledTool::new(
                ToolShape::Sphere { radius: -1.0 },
                &[Pose::at(DVec3::ZERO)],
                0.0
            )
            .is_err()
        );
        let nan = Pose::at(DVec3::new(f64::NAN, 0.0, 0.0));
        assert!(CompiledTool::new(sphere, &[nan], 0.0).is_err());
        let tiny_box = ToolShape::Box {
            half_extents: DVec3::splat(1e-9),
            rounding: 0.0,
        };
        let far = [Pose::at(DVec3::ZERO), Pose::at(DVec3::splat(1000.0))];
        assert!(matches!(
            CompiledTool::new(tiny_box, &far, 0.0),
            Err(ObjectError::BadStroke { .. })
        ));
    }
}
