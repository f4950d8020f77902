//! [`EditArena`]: what the large part of a [`History`](super::History) index needs to
//! evaluate its edits, copied out of the edits into three flat arrays so that a query reads
//! few cache lines and never follows an edit's pointers:
//! - per edit, a *hot* line (64 bytes, indexed by the edit's index): its first box, its
//!   operation, the bounds that tell when it cannot change a value, and where its stamps are;
//!   what a point or box query reads of every edit it meets;
//! - per edit, a *cold* record: its tool's shape, blend radius, Lipschitz bound and full
//!   operation, read only when the edit is evaluated;
//! - the copied stamps, each edit's run contiguous, edits in the grid's spatial order so that
//!   the stamps of the edits one grid cell names lie near each other.
//!
//! A copy changes where the numbers are read from, never the numbers: evaluation through the
//! arena runs the same operations as [`CompiledEdit`]'s.

use glam::DVec3;

use super::edit::{CompiledEdit, EditOp, fold_grad, fold_interval, fold_value, keeps_interval};
use super::tool::{Axis, Stamp, ToolShape, interval_max, scan_eval, scan_interval, scan_value};
use crate::bvh::Aabb;
use fdsl::eval::Interval;

/// What every query reads of an edit: one cache line.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Hot {
    /// The edit's first box (`Aabb::EMPTY` for an edit the arena does not hold).
    box0: Aabb,
    /// At least the tool's [`value_max`](super::tool::value_max) plus the blend radius,
    /// rounded up to single precision: a union keeps every value above it and a subtraction
    /// every value below its negation (see [`keeps_value`](super::edit::keeps_value)).
    keep_above: f32,
    /// At least the tool's Lipschitz bound, rounded up to single precision (for the interval
    /// test, [`keeps_interval`]).
    lipschitz_up: f32,
    /// The edit's stamps are `stamps[first..first + len]`.
    first: u32,
    len: u16,
    kind: Kind,
    /// `COPIED`, and `MIRRORED << axis` for an edit mirrored in the plane normal to `axis`.
    flags: u8,
}

/// The arena evaluates the edit (else its [`CompiledEdit`] does: a tool with an index of its
/// own, a long stroke, has no stamps copied).
const COPIED: u8 = 1;
/// The edit is mirrored in the plane normal to x (shifted by the axis: y, z).
const MIRRORED: u8 = 2;
const MIRROR_AXES: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

impl Hot {
    /// The edit's second box: its first reflected (the same operation as
    /// [`CompiledEdit::new`]'s, so the same bits), if it has a mirror.
    #[inline]
    fn box1(&self) -> Option<Aabb> {
        (0..3)
            .find(|&k| self.flags & (MIRRORED << k) != 0)
            .map(|k| MIRROR_AXES[k].reflect_box(&self.box0))
    }
}

/// The operation without its painted value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
enum Kind {
    Union,
    Subtract,
    Intersect,
    Paint,
}

impl Kind {
    fn of(op: &EditOp) -> Kind {
        match op {
            EditOp::Union => Kind::Union,
            EditOp::Subtract => Kind::Subtract,
            EditOp::Intersect => Kind::Intersect,
            EditOp::Paint { .. } => Kind::Paint,
        }
    }
}

/// What evaluating an edit reads besides its hot line.
#[derive(Clone, Debug)]
struct Cold {
    /// The tool's shape (the stamps do not copy it).
    shape: ToolShape,
    blend: f64,
    lipschitz: f64,
    /// The tool's [`value_max`](super::tool::value_max), which caps its intervals.
    value_max: f64,
    op: EditOp,
    mirror: Option<Axis>,
}

const ABSENT: Hot = Hot {
    box0: Aabb::EMPTY,
    keep_above: f32::INFINITY,
    lipschitz_up: f32::INFINITY,
    first: 0,
    len: 0,
    kind: Kind::Paint,
    flags: 0,
};

/// The evaluation data of the edits of an index's large part (see the module documentation),
/// indexed by the edits' indices in the history.
#[derive(Clone, Debug, Default)]
pub(crate) struct EditArena {
    hot: Vec<Hot>,
    cold: Vec<Cold>,
    stamps: Vec<(Aabb, Stamp)>,
}

impl EditArena {
    /// An arena for edits `0..edits.len()`, with room for exactly the stamps of those that
    /// `order` names (no more memory than their copies need).
    pub(crate) fn new(edits: &[&CompiledEdit], order: &[u32]) -> EditArena {
        let n_stamps = order
            .iter()
            .map(|&e| copied_stamps(edits[e as usize]).0.len())
            .sum();
        let mut arena = EditArena {
            hot: vec![ABSENT; edits.len()],
            cold: Vec::with_capacity(edits.len()),
            stamps: Vec::with_capacity(n_stamps),
        };
        for e in edits {
            arena.cold.push(Cold {
                shape: e.edit().tool,
                blend: e.edit().blend_radius,
                lipschitz: copied_stamps(e).1,
                value_max: e.tool().value_max(),
                op: e.edit().op,
                mirror: e.edit().mirror,
            });
        }
        for &idx in order {
            arena.copy(idx, edits[idx as usize]);
        }
        arena
    }

    /// Copies edit `idx` in: its hot line, and its stamps as the next run. A tool with an
    /// index of its own (a long stroke) has no stamps copied: such an edit is evaluated
    /// through its [`CompiledEdit`] (see [`EditArena::copied`]). Paintings copy no stamps
    /// either (they leave the value alone; what they paint is read from the edit itself).
    fn copy(&mut self, idx: u32, edit: &CompiledEdit) {
        let (stamps, lipschitz) = copied_stamps(edit);
        let first = u32::try_from(self.stamps.len()).expect("an arena holds < 2^32 stamps");
        let len = u16::try_from(stamps.len()).expect("copied tools have few stamps");
        let value_max = edit.tool().value_max();
        let blend = edit.edit().blend_radius;
        let mut flags = 0;
        if let Some(axis) = edit.edit().mirror {
            flags |= MIRRORED << (axis as u8);
        }
        if edit.tool().scanned_stamps().is_some() {
            flags |= COPIED;
        }
        self.hot[idx as usize] = Hot {
            box0: edit.boxes()[0],
            // The relative 1e-9 covers the rounding of the sum (see `keeps_value`).
            keep_above: f32_up((value_max + blend) * (1.0 + 1e-9)),
            lipschitz_up: f32_up(lipschitz),
            first,
            len,
            kind: Kind::of(&edit.edit().op),
            flags,
        };
        self.stamps.extend_from_slice(stamps);
    }

    /// The operation of edit `e`.
    #[inline]
    pub(crate) fn op(&self, e: u32) -> EditOp {
        self.cold[e as usize].op
    }

    /// Whether edit `e` is evaluated from the arena (else from its [`CompiledEdit`]).
    #[inline]
    pub(crate) fn copied(&self, e: u32) -> bool {
        self.hot[e as usize].flags & COPIED != 0
    }

    /// Bytes held (hot lines, cold records and stamps, counting reserved capacity).
    pub(crate) fn bytes(&self) -> usize {
        self.hot.capacity() * size_of::<Hot>()
            + self.cold.capacity() * size_of::<Cold>()
            + self.stamps.capacity() * size_of::<(Aabb, Stamp)>()
    }

    /// Whether the region of edit `e` holds `p` (activity is the history's).
    #[inline]
    pub(crate) fn touches(&self, e: u32, p: DVec3) -> bool {
        let h = &self.hot[e as usize];
        h.box0.contains(p) || h.box1().is_some_and(|b| b.contains(p))
    }

    /// Whether the region of edit `e` meets `region`.
    #[inline]
    pub(crate) fn meets(&self, e: u32, region: &Aabb) -> bool {
        let h = &self.hot[e as usize];
        h.box0.overlaps(region) || h.box1().is_some_and(|b| b.overlaps(region))
    }

    /// The stamps of edit `e`.
    #[inline]
    fn stamps_of(&self, h: &Hot) -> &[(Aabb, Stamp)] {
        let first = h.first as usize;
        &self.stamps[first..first + h.len as usize]
    }

    /// Whether an edit keeps the value `f` (a sufficient condition for
    /// [`keeps_value`](super::edit::keeps_value)'s test: the hot line
    /// holds the tool's bound plus the blend radius, rounded up, so `f` above it is above the
    /// tool's bound by at least the blend radius, which is [`smooth_max`]'s first branch).
    ///
    /// [`smooth_max`]: super::edit::smooth_max
    #[inline]
    fn keeps(h: &Hot, f: f64) -> bool {
        let above = f64::from(h.keep_above);
        match h.kind {
            Kind::Union => f > above,
            Kind::Subtract => -f > above,
            Kind::Intersect => false,
            Kind::Paint => true,
        }
    }

    /// [`CompiledEdit::apply_value`] of edit `e`.
    #[inline]
    pub(crate) fn apply_value(&self, e: u32, f: f64, p: DVec3) -> f64 {
        let h = &self.hot[e as usize];
        if EditArena::keeps(h, f) {
            return f;
        }
        let c = &self.cold[e as usize];
        let stamps = self.stamps_of(h);
        let direct = scan_value(stamps, c.shape, p);
        let g = match c.mirror {
            Some(axis) => direct.max(scan_value(stamps, c.shape, axis.reflect(p))),
            None => direct,
        };
        fold_value(&c.op, f, g, c.blend)
    }

    /// [`CompiledEdit::apply_grad`] of edit `e`.
    #[inline]
    pub(crate) fn apply_grad(&self, e: u32, f: (f64, DVec3), p: DVec3) -> (f64, DVec3) {
        let h = &self.hot[e as usize];
        if EditArena::keeps(h, f.0) {
            return f;
        }
        let c = &self.cold[e as usize];
        let stamps = self.stamps_of(h);
        let direct = scan_eval(stamps, c.shape, p);
        let g = match c.mirror {
            Some(axis) => {
                let (v, g) = scan_eval(stamps, c.shape, axis.reflect(p));
                if v > direct.0 {
                    (v, axis.reflect(g))
                } else {
                    direct
                }
            }
            None => direct,
        };
        fold_grad(&c.op, f, g, c.blend)
    }

    /// [`CompiledEdit::apply_interval`] of edit `e`.
    pub(crate) fn apply_interval(&self, e: u32, f: Interval, region: &Aabb) -> Interval {
        let h = &self.hot[e as usize];
        if h.kind == Kind::Paint {
            return f;
        }
        let c = &self.cold[e as usize];
        let covered =
            h.box0.contains_box(region) || h.box1().is_some_and(|b| b.contains_box(region));
        // Bounds at least the tool's value bound and Lipschitz bound give a bound at least
        // `interval_max` (each operation is monotone).
        let g_max = interval_max(f64::from(h.keep_above), f64::from(h.lipschitz_up), region);
        if keeps_interval(&c.op, f, g_max, covered) {
            return fold_interval(&c.op, f, Interval::new(g_max, g_max), c.blend, covered);
        }
        let stamps = self.stamps_of(h);
        let direct = scan_interval(stamps, c.shape, c.lipschitz, c.value_max, region);
        let g = match c.mirror {
            Some(axis) => {
                let reflected = axis.reflect_box(region);
                let m = scan_interval(stamps, c.shape, c.lipschitz, c.value_max, &reflected);
                Interval::new(direct.lo.max(m.lo), direct.hi.max(m.hi))
            }
            None => direct,
        };
        fold_interval(&c.op, f, g, c.blend, covered)
    }
}

/// The least single-precision number at least `v`.
pub(crate) fn f32_up(v: f64) -> f32 {
    let w = v as f32;
    if f64::from(w) < v { w.next_up() } else { w }
}

/// The stamps the arena copies of `edit`, with the Lipschitz bound (none for a painting or a
/// tool with an index of its own).
fn copied_stamps(edit: &CompiledEdit) -> (&[(Aabb, Stamp)], f64) {
    match (edit.edit().op, edit.tool().scanned_stamps()) {
        (EditOp::Paint { .. }, _) | (_, None) => (&[], 0.0),
        (_, Some(s)) => s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_edit_costs_one_line_and_a_cold_record() {
        // The arena costs a hot line and a cold record per edit and a stamp with its box per
        // copied stamp (ARCHITECTURE.md and BENCHMARKS.md quote 160 bytes for a record and
        // for a stamp, the size of the arena's items before they were split): neither may
        // outgrow that. A stamp is 120 bytes since the tool's shape moved to the cold record.
        assert_eq!(size_of::<Hot>(), 64);
        assert!(size_of::<Hot>() + size_of::<Cold>() <= 160);
        assert_eq!(size_of::<(Aabb, Stamp)>(), 120);
    }

    #[test]
    fn an_edit_the_hot_line_keeps_folds_to_the_same_bits() {
        use super::super::edit::{Edit, fold_grad};
        use super::super::tool::{Pose, ToolShape};
        let mut edits = Vec::new();
        for (i, op) in [EditOp::Union, EditOp::Subtract, EditOp::Intersect]
            .into_iter()
            .enumerate()
        {
            for blend in [0.0, 0.003, 0.05] {
                let mut edit = Edit::stamp(
                    op,
                    ToolShape::Sphere {
                        radius: 0.01 + 0.02 * i as f64,
                    },
                    Pose::at(DVec3::ZERO),
                );
                edit.blend_radius = blend;
                edits.push(CompiledEdit::new(edit).unwrap());
            }
        }
        let refs: Vec<&CompiledEdit> = edits.iter().collect();
        let order: Vec<u32> = (0..edits.len() as u32).collect();
        let arena = EditArena::new(&refs, &order);
        let mut n_kept = 0;
        for (e, edit) in edits.iter().enumerate() {
            let (op, b) = (&edit.edit().op, edit.edit().blend_radius);
            let h = &arena.hot[e];
            let g_max = edit.tool().value_max();
            let above = f64::from(h.keep_above);
            // Values at and around the threshold, on both sides of zero.
            let mut fs = Vec::new();
            for x in [
                above,
                g_max,
                g_max + b,
                0.5 * g_max,
                0.0,
                1.0,
                f64::INFINITY,
            ] {
                let mut v = x;
                for _ in 0..4 {
                    fs.extend([v, -v]);
                    v = v.next_up();
                }
            }
            for f in fs {
                if !EditArena::keeps(h, f) {
                    continue;
                }
                n_kept += 1;
                for k in 0..=64 {
                    // Tool values from far below up to the bound itself.
                    let g = g_max - (g_max + 1.0) * (k as f64 / 64.0).powi(3);
                    assert_eq!(fold_value(op, f, g, b).to_bits(), f.to_bits(), "{op:?} {f}");
                    let d = DVec3::new(1.0, -0.0, 0.5);
                    let (v, dv) = fold_grad(op, (f, d), (g, DVec3::Y), b);
                    assert_eq!((v.to_bits(), dv), (f.to_bits(), d));
                }
            }
        }
        assert!(n_kept > 50, "{n_kept}");
    }

    #[test]
    fn single_precision_bounds_round_up() {
        for v in [0.0, 1e-30, 0.1, 0.01, 1.0 / 3.0, 1e30, -0.1] {
            assert!(f64::from(f32_up(v)) >= v, "{v}");
        }
    }
}
