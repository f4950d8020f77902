//! An object's edit history, indexed by bounds so that a point or a box visits only the edits
//! that can change it there: the cost of an evaluation depends on how many edits overlap the
//! point, not on how many there are.
//!
//! The index has three parts, oldest first: a large [`Bvh`] over most of the history, a small
//! one over recent edits, and a short unindexed tail. Appending costs nothing until
//! [`History::refresh`]: the tail then moves into the small tree, and the small tree into the
//! large one when it has grown to an eighth of it, so rebuilding costs O(log n) per edit
//! amortised. Queries stay correct without a refresh (the tail is scanned), only slower.

use std::sync::Arc;

use glam::DVec3;

use super::ObjectError;
use super::edit::{CompiledEdit, EditOp};
use crate::bvh::{Aabb, Bvh};
use crate::limits::MAX_EDITS_PER_OBJECT;

/// Longest unindexed tail left by [`History::refresh`].
pub const TAIL_MAX: usize = 32;
/// The small tree merges into the large one when it holds more than this many edits and more
/// than an eighth of the large tree.
const SMALL_MIN: usize = 1024;

/// One edit in the history.
#[derive(Clone, Debug)]
pub struct HistoryEntry {
    /// The edit.
    pub edit: Arc<CompiledEdit>,
    /// False once undone: the fold skips it.
    pub active: bool,
}

#[derive(Clone, Debug, Default)]
struct Level {
    bvh: Bvh,
    /// Item of the tree -> edit index (a mirrored edit has two items).
    edit_of: Vec<u32>,
}

impl Level {
    fn build(entries: &[HistoryEntry], range: std::ops::Range<usize>) -> Level {
        let mut boxes = Vec::with_capacity(range.len());
        let mut edit_of = Vec::with_capacity(range.len());
        for i in range {
            for b in entries[i].edit.boxes() {
                if !b.is_empty() {
                    boxes.push(*b);
                    edit_of.push(i as u32);
                }
            }
        }
        Level {
            bvh: Bvh::build(&boxes),
            edit_of,
        }
    }
}

/// The ordered, indexed edits of one object.
#[derive(Clone, Debug, Default)]
pub struct History {
    entries: Vec<HistoryEntry>,
    big: Level,
    small: Level,
    /// Edits `[0, big_end)` are in the large tree.
    big_end: usize,
    /// Edits `[big_end, indexed_end)` are in the small tree; the rest is the tail.
    indexed_end: usize,
    /// Indices of intersections, ascending (they act outside their boxes too).
    intersects: Vec<u32>,
}

impl History {
    /// Number of edits, undone ones included.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there are no edits.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The edits in order.
    pub fn entries(&self) -> &[HistoryEntry] {
        &self.entries
    }

    /// Appends an edit (indexed at the next [`History::refresh`]); returns its index.
    pub fn push(&mut self, edit: Arc<CompiledEdit>) -> Result<usize, ObjectError> {
        if self.entries.len() >= MAX_EDITS_PER_OBJECT {
            return Err(ObjectError::TooManyEdits);
        }
        let idx = self.entries.len();
        if matches!(edit.edit().op, EditOp::Intersect) {
            self.intersects.push(idx as u32);
        }
        self.entries.push(HistoryEntry { edit, active: true });
        Ok(idx)
    }

    /// Undoes (`false`) or redoes (`true`) edit `idx`. Returns false if there is no such edit.
    pub fn set_active(&mut self, idx: usize, active: bool) -> bool {
        match self.entries.get_mut(idx) {
            Some(e) => {
                e.active = active;
                true
            }
            None => false,
        }
    }

    /// Keeps the first `n` edits (a re-fold from a checkpoint restarts here).
    pub fn truncate(&mut self, n: usize) {
        if n >= self.entries.len() {
            return;
        }
        self.entries.truncate(n);
        self.intersects.retain(|&i| (i as usize) < n);
        if n < self.big_end {
            self.big = Level::default();
            self.small = Level::default();
            self.big_end = 0;
            self.indexed_end = 0;
        } else if n < self.indexed_end {
            self.small = Level::default();
            self.indexed_end = self.big_end;
        }
    }

    /// Moves the tail into the trees (see the module documentation).
    pub fn refresh(&mut self) {
        let n = self.entries.len();
        if n - self.indexed_end <= TAIL_MAX {
            return;
        }
        let small_len = n - self.big_end;
        if small_len > SMALL_MIN && small_len > self.big_end / 8 {
            self.big = Level::build(&self.entries, 0..n);
            self.small = Level::default();
            self.big_end = n;
        } else {
            self.small = Level::build(&self.entries, self.big_end..n);
        }
        self.indexed_end = n;
    }

    /// Number of edits not yet in a tree.
    pub fn tail_len(&self) -> usize {
        self.entries.len() - self.indexed_end
    }

    /// Writes to `out`, ascending, the active edits whose region contains `p`.
    #[inline]
    pub fn collect_point(&self, p: DVec3, out: &mut Vec<u32>) {
        out.clear();
        let entries = &self.entries;
        let mut take = |e: u32| {
            let entry = &entries[e as usize];
            if entry.active && entry.edit.touches(p) {
                out.push(e);
            }
        };
        for level in [&self.big, &self.small] {
            level
                .bvh
                .visit_point(p, |i| take(level.edit_of[i as usize]));
        }
        (self.indexed_end as u32..entries.len() as u32).for_each(&mut take);
        finish(out);
    }

    /// Writes to `out`, ascending, the active edits whose region overlaps `region`.
    pub fn collect_box(&self, region: &Aabb, out: &mut Vec<u32>) {
        out.clear();
        let entries = &self.entries;
        let mut take = |e: u32| {
            let entry = &entries[e as usize];
            if entry.active && entry.edit.boxes().iter().any(|b| b.overlaps(region)) {
                out.push(e);
            }
        };
        for level in [&self.big, &self.small] {
            level
                .bvh
                .visit_box(region, |i| take(level.edit_of[i as usize]));
        }
        (self.indexed_end as u32..entries.len() as u32).for_each(&mut take);
        finish(out);
    }

    /// The last active intersection for which `outside` holds, if any: before it, nothing
    /// matters where `outside` holds.
    #[inline]
    pub(crate) fn last_intersect_where(
        &self,
        mut outside: impl FnMut(&CompiledEdit) -> bool,
    ) -> Option<usize> {
        self.intersects.iter().rev().find_map(|&i| {
            let e = &self.entries[i as usize];
            (e.active && outside(&e.edit)).then_some(i as usize)
        })
    }

    /// The edit at `idx`.
    #[inline]
    pub fn get(&self, idx: usize) -> Option<&HistoryEntry> {
        self.entries.get(idx)
    }
}

#[inline]
fn finish(out: &mut Vec<u32>) {
    if out.len() > 1 {
        out.sort_unstable();
        out.dedup();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::edit::Edit;
    use crate::object::tool::{Pose, ToolShape};

    fn edit_at(p: DVec3) -> Arc<CompiledEdit> {
        Arc::new(
            CompiledEdit::new(Edit::stamp(
                EditOp::Union,
                ToolShape::Sphere { radius: 0.05 },
                Pose::at(p),
            ))
            .unwrap(),
        )
    }

    fn brute(h: &History, p: DVec3) -> Vec<u32> {
        (0..h.len() as u32)
            .filter(|&i| {
                let e = &h.entries()[i as usize];
                e.active && e.edit.touches(p)
            })
            .collect()
    }

    #[test]
    fn index_agrees_with_a_scan_through_growth_undo_and_truncation() {
        let mut h = History::default();
        let mut out = Vec::new();
        let point = |i: usize| {
            let a = i as f64;
            DVec3::new((a * 0.37).sin(), (a * 0.23).cos(), (a * 0.11).sin()) * 0.5
        };
        for i in 0..5000 {
            h.push(edit_at(point(i))).unwrap();
            if i % 7 == 0 {
                h.refresh();
            }
            if i % 13 == 0 {
                h.set_active(i / 2, false);
            }
            if i % 500 == 499 {
                for k in 0..50 {
                    let p = point(k * 31) + DVec3::splat(0.01);
                    h.collect_point(p, &mut out);
                    assert_eq!(out, brute(&h, p), "after {i} edits at {p}");
                }
            }
        }
        assert!(h.big_end > 0, "the large tree was built");
        for n in [4000, 2500, 100] {
            h.truncate(n);
            h.refresh();
            for k in 0..50 {
                let p = point(k * 7);
                h.collect_point(p, &mut out);
                assert_eq!(out, brute(&h, p));
            }
        }
        let region = Aabb::around(DVec3::ZERO, DVec3::splat(0.1));
        h.collect_box(&region, &mut out);
        let want: Vec<u32> = (0..h.len() as u32)
            .filter(|&i| {
                let e = &h.entries()[i as usize];
                e.active && e.edit.bounds().overlaps(&region)
            })
            .collect();
        assert_eq!(out, want);
    }
}
