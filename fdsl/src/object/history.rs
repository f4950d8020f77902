//! An object's edit history, indexed by bounds so that a point or a box visits only the edits
//! that can change it there: the cost of an evaluation depends on how many edits overlap the
//! point, not on how many there are.
//!
//! The index has three parts, oldest first: a large part over most of the history, a small
//! [`Bvh`] over recent edits, and a short unindexed tail. The large part answers points through
//! a uniform grid (one cell lookup and a short contiguous list, whatever the history's length;
//! edits much larger than a cell go to a small tree beside it) and boxes and rays through a
//! [`Bvh`]. Appending costs nothing until
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
const SMALL_MIN: usize = 256;

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
    fn from_boxes(items: &[(Aabb, u32)]) -> Level {
        let boxes: Vec<Aabb> = items.iter().map(|(b, _)| *b).collect();
        Level {
            bvh: Bvh::build(&boxes),
            edit_of: items.iter().map(|(_, e)| *e).collect(),
        }
    }

    fn build(entries: &[HistoryEntry], range: std::ops::Range<usize>) -> Level {
        Level::from_boxes(&boxes_of(entries, range))
    }
}

/// Every non-empty box of the edits in `range`, with its edit's index.
fn boxes_of(entries: &[HistoryEntry], range: std::ops::Range<usize>) -> Vec<(Aabb, u32)> {
    let mut out = Vec::with_capacity(range.len());
    for i in range {
        for b in entries[i].edit.boxes() {
            if !b.is_empty() {
                out.push((*b, i as u32));
            }
        }
    }
    out
}

/// A box in single precision, rounded outwards, with its edit.
#[derive(Clone, Copy, Debug)]
struct GridItem {
    lo: [f32; 3],
    hi: [f32; 3],
    edit: u32,
}

impl GridItem {
    fn new(b: &Aabb, edit: u32) -> GridItem {
        GridItem {
            lo: b.lo.to_array().map(|v| (v as f32).next_down()),
            hi: b.hi.to_array().map(|v| (v as f32).next_up()),
            edit,
        }
    }

    #[inline]
    fn contains(&self, p: [f32; 3]) -> bool {
        p[0] >= self.lo[0]
            && p[0] <= self.hi[0]
            && p[1] >= self.lo[1]
            && p[1] <= self.hi[1]
            && p[2] >= self.lo[2]
            && p[2] <= self.hi[2]
    }
}

/// Most cells per indexed box in a grid (a bound on its memory).
const GRID_CELLS_PER_BOX: usize = 8;

/// A uniform grid over small boxes for point queries; boxes spanning more than two cells on
/// an axis go to `large` instead.
#[derive(Clone, Debug, Default)]
struct Grid {
    origin: DVec3,
    inv_cell: f64,
    dims: [usize; 3],
    /// Cell `c` holds `items[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    items: Vec<GridItem>,
    large: Level,
}

impl Grid {
    fn build(boxes: &[(Aabb, u32)]) -> Grid {
        if boxes.is_empty() {
            return Grid::default();
        }
        let bounds = boxes.iter().fold(Aabb::EMPTY, |a, (b, _)| a.union(b));
        // Cells about the size of a typical box, but no more cells than the memory bound.
        let mut extents: Vec<f64> = boxes.iter().map(|(b, _)| b.size().max_element()).collect();
        let mid = extents.len() / 2;
        let typical = *extents.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
        let size = bounds.size().max(DVec3::splat(1e-9));
        let max_cells = (GRID_CELLS_PER_BOX * boxes.len()).max(64) as f64;
        let by_memory = (size.x * size.y * size.z / max_cells).cbrt();
        let cell = typical.max(by_memory).max(1e-9);
        let dims = (size / cell)
            .ceil()
            .max(DVec3::ONE)
            .to_array()
            .map(|d| d as usize);
        let mut grid = Grid {
            origin: bounds.lo,
            inv_cell: 1.0 / cell,
            dims,
            ..Grid::default()
        };
        let mut large = Vec::new();
        let mut counts = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        let mut small = Vec::with_capacity(boxes.len());
        for (b, e) in boxes {
            let (lo, hi) = (grid.cell_of(b.lo), grid.cell_of(b.hi));
            if (0..3).any(|k| hi[k] - lo[k] > 1) {
                large.push((*b, *e));
                continue;
            }
            grid.for_cells(lo, hi, |c| counts[c] += 1);
            small.push((*b, *e, lo, hi));
        }
        let mut total = 0u32;
        for c in counts.iter_mut() {
            let n = *c;
            *c = total;
            total += n;
        }
        let mut next = counts.clone();
        grid.starts = counts;
        let empty = GridItem {
            lo: [0.0; 3],
            hi: [0.0; 3],
            edit: 0,
        };
        let mut items = vec![empty; total as usize];
        for (b, e, lo, hi) in small {
            grid.for_cells(lo, hi, |c| {
                items[next[c] as usize] = GridItem::new(&b, e);
                next[c] += 1;
            });
        }
        grid.items = items;
        grid.large = Level::from_boxes(&large);
        grid
    }

    #[inline]
    fn cell_of(&self, p: DVec3) -> [usize; 3] {
        let q = (p - self.origin) * self.inv_cell;
        [0, 1, 2].map(|k| (q[k].max(0.0) as usize).min(self.dims[k] - 1))
    }

    fn for_cells(&self, lo: [usize; 3], hi: [usize; 3], mut f: impl FnMut(usize)) {
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    f(x + self.dims[0] * (y + self.dims[1] * z));
                }
            }
        }
    }

    /// Calls `visit(edit)` for every box that may contain `p` (tested in single precision,
    /// rounded outwards: the caller confirms).
    #[inline]
    fn visit_point(&self, p: DVec3, mut visit: impl FnMut(u32)) {
        if !self.starts.is_empty() {
            let q = (p - self.origin) * self.inv_cell;
            let inside = (0..3).all(|k| q[k] >= 0.0 && q[k] <= self.dims[k] as f64);
            if inside {
                let [x, y, z] = self.cell_of(p);
                let c = x + self.dims[0] * (y + self.dims[1] * z);
                let pf = p.to_array().map(|v| v as f32);
                let range = self.starts[c] as usize..self.starts[c + 1] as usize;
                for item in &self.items[range] {
                    if item.contains(pf) {
                        visit(item.edit);
                    }
                }
            }
        }
        let large = &self.large;
        large
            .bvh
            .visit_point(p, |i| visit(large.edit_of[i as usize]));
    }
}

/// The ordered, indexed edits of one object.
#[derive(Clone, Debug, Default)]
pub struct History {
    entries: Vec<HistoryEntry>,
    /// The large part: a tree for boxes and rays, a grid for points.
    big: Level,
    big_grid: Grid,
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
            self.big_grid = Grid::default();
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
            let boxes = boxes_of(&self.entries, 0..n);
            self.big = Level::from_boxes(&boxes);
            self.big_grid = Grid::build(&boxes);
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
        self.big_grid.visit_point(p, &mut take);
        let small = &self.small;
        small
            .bvh
            .visit_point(p, |i| take(small.edit_of[i as usize]));
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
