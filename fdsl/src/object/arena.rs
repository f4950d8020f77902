//! [`EditArena`]: what the large part of a [`History`](super::History) index needs to
//! evaluate its edits, copied into two contiguous arrays in the grid's spatial order, so that
//! the edits one grid cell names lie near each other in memory instead of behind one pointer
//! each, scattered over the heap. A copy changes where the numbers are read from, never the
//! numbers: evaluation through the arena runs the same operations as [`CompiledEdit`]'s.

use glam::DVec3;

use super::edit::{CompiledEdit, EditOp, fold_grad, fold_interval, fold_value};
use super::tool::{Axis, Stamp, scan_eval, scan_interval};
use crate::bvh::Aabb;
use crate::eval::Interval;

/// One edit's evaluation data; its stamps are `stamps[first..first + len]` of the arena.
#[derive(Clone, Debug)]
struct Record {
    /// The edit's boxes (the second is empty without a mirror).
    boxes: [Aabb; 2],
    blend: f64,
    lipschitz: f64,
    op: EditOp,
    mirror: Option<Axis>,
    active: bool,
    /// False when the tool keeps an index of its own: no stamps are copied and the edit is
    /// evaluated through its [`CompiledEdit`].
    copied: bool,
    /// The edit's index in the history.
    edit: u32,
    first: u32,
    len: u32,
}

/// The evaluation data of the edits of an index's large part (see the module documentation).
#[derive(Clone, Debug, Default)]
pub(crate) struct EditArena {
    records: Vec<Record>,
    /// Every record's stamps with their grown boxes, record after record.
    stamps: Vec<(Aabb, Stamp)>,
}

impl EditArena {
    /// Copies edit `idx` in as the next record and returns its slot. A tool with an index of
    /// its own (a long stroke) has no stamps copied: such an edit is evaluated through its
    /// [`CompiledEdit`] (see [`EditArena::copied`]). Paintings copy no stamps either (they
    /// leave the value alone; what they paint is read from the edit itself).
    pub(crate) fn push(&mut self, idx: u32, edit: &CompiledEdit, active: bool) -> u32 {
        let scanned = edit.tool().scanned_stamps();
        let op = edit.edit().op;
        let (stamps, lipschitz) = match (op, scanned) {
            (EditOp::Paint { .. }, _) | (_, None) => (&[][..], 0.0),
            (_, Some(s)) => s,
        };
        let slot = u32::try_from(self.records.len()).expect("an arena holds fewer than 2^32 edits");
        self.records.push(Record {
            boxes: *edit.boxes(),
            blend: edit.edit().blend_radius,
            lipschitz,
            op,
            mirror: edit.edit().mirror,
            active,
            copied: scanned.is_some(),
            edit: idx,
            first: u32::try_from(self.stamps.len()).expect("an arena holds fewer than 2^32 stamps"),
            len: stamps.len() as u32,
        });
        self.stamps.extend_from_slice(stamps);
        slot
    }

    /// The history index of the edit in `slot`.
    #[inline]
    pub(crate) fn edit(&self, slot: u32) -> u32 {
        self.records[slot as usize].edit
    }

    /// Whether the edit in `slot` is evaluated from the arena (else from its [`CompiledEdit`]).
    #[inline]
    pub(crate) fn copied(&self, slot: u32) -> bool {
        self.records[slot as usize].copied
    }

    /// Bytes held (records and stamps, counting reserved capacity).
    pub(crate) fn bytes(&self) -> usize {
        self.records.capacity() * size_of::<Record>()
            + self.stamps.capacity() * size_of::<(Aabb, Stamp)>()
    }

    pub(crate) fn set_active(&mut self, slot: u32, active: bool) {
        self.records[slot as usize].active = active;
    }

    /// Whether the edit in `slot` is active and its region holds `p`.
    #[inline]
    pub(crate) fn touches(&self, slot: u32, p: DVec3) -> bool {
        let r = &self.records[slot as usize];
        r.active && (r.boxes[0].contains(p) || r.boxes[1].contains(p))
    }

    /// Whether the edit in `slot` is active and its region meets `region`.
    #[inline]
    pub(crate) fn meets(&self, slot: u32, region: &Aabb) -> bool {
        let r = &self.records[slot as usize];
        r.active && r.boxes.iter().any(|b| b.overlaps(region))
    }

    #[inline]
    fn stamps_of(&self, r: &Record) -> &[(Aabb, Stamp)] {
        &self.stamps[r.first as usize..(r.first + r.len) as usize]
    }

    /// [`CompiledEdit::apply_value`] of the edit in `slot`.
    #[inline]
    pub(crate) fn apply_value(&self, slot: u32, f: f64, p: DVec3) -> f64 {
        let r = &self.records[slot as usize];
        if let EditOp::Paint { .. } = r.op {
            return f;
        }
        let stamps = self.stamps_of(r);
        let direct = scan_eval(stamps, p).0;
        let g = match r.mirror {
            Some(axis) => direct.max(scan_eval(stamps, axis.reflect(p)).0),
            None => direct,
        };
        fold_value(&r.op, f, g, r.blend)
    }

    /// [`CompiledEdit::apply_grad`] of the edit in `slot`.
    #[inline]
    pub(crate) fn apply_grad(&self, slot: u32, f: (f64, DVec3), p: DVec3) -> (f64, DVec3) {
        let r = &self.records[slot as usize];
        if let EditOp::Paint { .. } = r.op {
            return f;
        }
        let stamps = self.stamps_of(r);
        let direct = scan_eval(stamps, p);
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
        let r = &self.records[slot as usize];
        if let EditOp::Paint { .. } = r.op {
            return f;
        }
        let stamps = self.stamps_of(r);
        let direct = scan_interval(stamps, r.lipschitz, region);
        let g = match r.mirror {
            Some(axis) => {
                let m = scan_interval(stamps, r.lipschitz, &axis.reflect_box(region));
                Interval::new(direct.lo.max(m.lo), direct.hi.max(m.hi))
            }
            None => direct,
        };
        let covered = r.boxes[0].contains_box(region) || r.boxes[1].contains_box(region);
        fold_interval(&r.op, f, g, r.blend, covered)
    }
}
