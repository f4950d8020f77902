//! [`EditArena`]: what the large part of a [`History`](super::History) index needs to
//! evaluate its edits, copied into one contiguous array in the grid's spatial order (each
//! edit's record followed by its stamps), so that the edits one grid cell names lie near each
//! other in memory instead of behind one pointer each, scattered over the heap. A copy changes where the numbers are read from, never the
//! numbers: evaluation through the arena runs the same operations as [`CompiledEdit`]'s.

use glam::DVec3;

use super::edit::{
    CompiledEdit, EditOp, fold_grad, fold_interval, fold_value, keeps_interval, keeps_value,
};
use super::tool::{Axis, Stamp, interval_max, scan_eval, scan_interval};
use crate::bvh::Aabb;
use crate::eval::Interval;

/// One edit's evaluation data; its `len` stamps follow it in the arena.
#[derive(Clone, Debug)]
struct Record {
    /// The edit's boxes (the second is empty without a mirror).
    boxes: [Aabb; 2],
    blend: f64,
    lipschitz: f64,
    /// The tool's [`value_max`](super::tool::value_max), rounded up to single precision (still
    /// a bound; a record must not outgrow a stamp).
    value_max: f32,
    op: EditOp,
    mirror: Option<Axis>,
    /// False when the tool keeps an index of its own: no stamps are copied and the edit is
    /// evaluated through its [`CompiledEdit`].
    copied: bool,
    /// The edit's index in the history.
    edit: u32,
    len: u32,
}

/// An element of the arena.
#[derive(Clone, Debug)]
enum Item {
    /// An edit, followed by its stamps.
    Edit(Record),
    /// A stamp with its grown box.
    Stamp((Aabb, Stamp)),
}

/// The evaluation data of the edits of an index's large part (see the module documentation).
#[derive(Clone, Debug, Default)]
pub(crate) struct EditArena {
    items: Vec<Item>,
}

impl EditArena {
    /// An arena with room for exactly `edits` (no more memory than their copies need).
    pub(crate) fn with_room_for<'a>(edits: impl Iterator<Item = &'a CompiledEdit>) -> EditArena {
        let n_items = edits.map(|e| 1 + copied_stamps(e).0.len()).sum();
        EditArena {
            items: Vec::with_capacity(n_items),
        }
    }

    /// Copies edit `idx` in as the next record and returns its slot. A tool with an index of
    /// its own (a long stroke) has no stamps copied: such an edit is evaluated through its
    /// [`CompiledEdit`] (see [`EditArena::copied`]). Paintings copy no stamps either (they
    /// leave the value alone; what they paint is read from the edit itself).
    pub(crate) fn push(&mut self, idx: u32, edit: &CompiledEdit) -> u32 {
        let (stamps, lipschitz) = copied_stamps(edit);
        let op = edit.edit().op;
        let slot = u32::try_from(self.items.len()).expect("an arena holds fewer than 2^32 items");
        self.items.push(Item::Edit(Record {
            boxes: *edit.boxes(),
            blend: edit.edit().blend_radius,
            lipschitz,
            value_max: f32_up(edit.tool().value_max()),
            op,
            mirror: edit.edit().mirror,
            copied: edit.tool().scanned_stamps().is_some(),
            edit: idx,
            len: stamps.len() as u32,
        }));
        self.items.extend(stamps.iter().map(|s| Item::Stamp(*s)));
        slot
    }

    /// The history index of the edit in `slot`.
    #[inline]
    pub(crate) fn edit(&self, slot: u32) -> u32 {
        self.record(slot).edit
    }

    /// The operation of the edit in `slot`.
    #[inline]
    pub(crate) fn op(&self, slot: u32) -> EditOp {
        self.record(slot).op
    }

    /// Whether the edit in `slot` is evaluated from the arena (else from its [`CompiledEdit`]).
    #[inline]
    pub(crate) fn copied(&self, slot: u32) -> bool {
        self.record(slot).copied
    }

    /// Bytes held (records and stamps, counting reserved capacity).
    pub(crate) fn bytes(&self) -> usize {
        self.items.capacity() * size_of::<Item>()
    }

    /// Whether the region of the edit in `slot` holds `p` (activity is the history's).
    #[inline]
    pub(crate) fn touches(&self, slot: u32, p: DVec3) -> bool {
        let r = self.record(slot);
        r.boxes[0].contains(p) || r.boxes[1].contains(p)
    }

    /// Whether the region of the edit in `slot` meets `region`.
    #[inline]
    pub(crate) fn meets(&self, slot: u32, region: &Aabb) -> bool {
        self.record(slot).boxes.iter().any(|b| b.overlaps(region))
    }

    #[inline]
    fn record(&self, slot: u32) -> &Record {
        match &self.items[slot as usize] {
            Item::Edit(r) => r,
            Item::Stamp(_) => unreachable!("slot {slot} names a stamp, not an edit"),
        }
    }

    /// The stamps of the edit in `slot`.
    #[inline]
    fn stamps_of(&self, slot: u32, r: &Record) -> impl Iterator<Item = &(Aabb, Stamp)> + Clone {
        let first = slot as usize + 1;
        self.items[first..first + r.len as usize]
            .iter()
            .filter_map(|item| match item {
                Item::Stamp(s) => Some(s),
                Item::Edit(_) => None,
            })
    }

    /// [`CompiledEdit::apply_value`] of the edit in `slot`.
    #[inline]
    pub(crate) fn apply_value(&self, slot: u32, f: f64, p: DVec3) -> f64 {
        let r = self.record(slot);
        if keeps_value(&r.op, f, r.value_max.into(), r.blend) {
            return f;
        }
        let stamps = self.stamps_of(slot, r);
        let direct = scan_eval(stamps.clone(), p).0;
        let g = match r.mirror {
            Some(axis) => direct.max(scan_eval(stamps, axis.reflect(p)).0),
            None => direct,
        };
        fold_value(&r.op, f, g, r.blend)
    }

    /// [`CompiledEdit::apply_grad`] of the edit in `slot`.
    #[inline]
    pub(crate) fn apply_grad(&self, slot: u32, f: (f64, DVec3), p: DVec3) -> (f64, DVec3) {
        let r = self.record(slot);
        if keeps_value(&r.op, f.0, r.value_max.into(), r.blend) {
            return f;
        }
        let stamps = self.stamps_of(slot, r);
        let direct = scan_eval(stamps.clone(), p);
        let g = match r.mirror {
            Some(axis) => {
                let (v, g) = scan_eval(stamps, axis.reflect(p));
                if v > direct.0 {
                    (v, axis.reflect(g))
                } else {
                    direct
                }
            }
            None => direct,
        };
        fold_grad(&r.op, f, g, r.blend)
    }

    /// [`CompiledEdit::apply_interval`] of the edit in `slot`.
    pub(crate) fn apply_interval(&self, slot: u32, f: Interval, region: &Aabb) -> Interval {
        let r = self.record(slot);
        if let EditOp::Paint { .. } = r.op {
            return f;
        }
        let covered = r.boxes[0].contains_box(region) || r.boxes[1].contains_box(region);
        let g_max = interval_max(r.value_max.into(), r.lipschitz, region);
        if keeps_interval(&r.op, f, g_max) {
            return fold_interval(&r.op, f, Interval::new(g_max, g_max), r.blend, covered);
        }
        let stamps = self.stamps_of(slot, r);
        let direct = scan_interval(stamps.clone(), r.lipschitz, region);
        let g = match r.mirror {
            Some(axis) => {
                let m = scan_interval(stamps, r.lipschitz, &axis.reflect_box(region));
                Interval::new(direct.lo.max(m.lo), direct.hi.max(m.hi))
            }
            None => direct,
        };
        fold_interval(&r.op, f, g, r.blend, covered)
    }
}

/// The least single-precision number at least `v`.
fn f32_up(v: f64) -> f32 {
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
    fn an_item_is_a_stamp_with_its_box_and_a_tag() {
        // The arena costs one item per record and per copied stamp (ARCHITECTURE.md and
        // BENCHMARKS.md quote 160 bytes): a record must not make items larger than a stamp.
        assert!(size_of::<Record>() <= size_of::<(Aabb, Stamp)>());
        assert_eq!(size_of::<Item>(), 160);
    }
}
