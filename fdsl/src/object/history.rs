//! An object's edit history, indexed by bounds so that a point or a box visits only the edits
//! that can change it there: the cost of an evaluation depends on how many edits overlap the
//! point, not on how many there are.
//!
//! The index has three parts, oldest first: a large part over most of the history, a small
//! [`Bvh`] over recent edits, and a short unindexed tail. The large part answers points and
//! boxes through a uniform grid (one cell lookup and a short contiguous list, whatever the
//! history's length; edits much larger than a cell go to a small tree beside it, and boxes
//! meeting more than `GRID_QUERY_CELLS_MAX` cells go to a [`Bvh`] over the whole part), and
//! evaluates its edits from an `EditArena` built with the grid: copies of their evaluation
//! data in cell order. Appending costs nothing until
//! [`History::refresh`]: the tail then moves into the small tree, and the small tree into the
//! large one when it has grown to an eighth of it, so rebuilding costs O(log n) per edit
//! amortised. Queries stay correct without a refresh (the tail is scanned), only slower.

use std::sync::Arc;

use glam::DVec3;

use super::ObjectError;
use super::arena::EditArena;
use super::edit::{CompiledEdit, EditOp};
use crate::bvh::{Aabb, Bvh};
use crate::eval::Interval;
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

/// A box in single precision, rounded outwards, with its edit's slot in the arena.
#[derive(Clone, Copy, Debug)]
struct GridItem {
    lo: [f32; 3],
    hi: [f32; 3],
    slot: u32,
}

impl GridItem {
    fn new(b: &Aabb, slot: u32) -> GridItem {
        GridItem {
            lo: b.lo.to_array().map(|v| (v as f32).next_down()),
            hi: b.hi.to_array().map(|v| (v as f32).next_up()),
            slot,
        }
    }

    /// Whether the box may meet `region` (it holds the exact box: the caller confirms).
    #[inline]
    fn may_meet(&self, region: &Aabb) -> bool {
        (0..3).all(|k| self.lo[k] as f64 <= region.hi[k] && region.lo[k] <= self.hi[k] as f64)
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
/// Box queries meeting more grid cells than this go to the large tree instead.
const GRID_QUERY_CELLS_MAX: usize = 64;

/// A uniform grid over small boxes for point and box queries; boxes spanning more than two
/// cells on an axis go to `large` instead. Items name slots of the arena built with the grid
/// (`large.edit_of` too holds slots, not edit indices).
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

/// The grid and arena of the large part, and each edit's slot in that arena.
struct GridBuild {
    grid: Grid,
    arena: EditArena,
    slot_of: Vec<u32>,
}

impl Grid {
    /// Indexes `boxes` (from [`boxes_of`] over `entries[..n]`, every edit of the part) and
    /// copies the edits into an arena in cell order: the edits one cell names sit together.
    fn build(boxes: &[(Aabb, u32)], entries: &[HistoryEntry]) -> GridBuild {
        let mut built = GridBuild {
            grid: Grid::default(),
            arena: EditArena::default(),
            slot_of: vec![NO_SLOT; entries.len()],
        };
        if boxes.is_empty() {
            return built;
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
        // Arena order: edits by the cell of their first box's low corner (large boxes last),
        // so that a cell's items name nearby records.
        let n_cells = dims[0] * dims[1] * dims[2];
        let mut key = vec![usize::MAX; entries.len()];
        for (b, e) in boxes {
            let k = &mut key[*e as usize];
            if *k == usize::MAX {
                let [x, y, z] = grid.cell_of(b.lo);
                let spans = (0..3).any(|a| grid.cell_of(b.hi)[a] - [x, y, z][a] > 1);
                *k = if spans {
                    n_cells
                } else {
                    x + dims[0] * (y + dims[1] * z)
                };
            }
        }
        let mut order: Vec<u32> = (0..entries.len() as u32)
            .filter(|&e| key[e as usize] != usize::MAX)
            .collect();
        order.sort_by_key(|&e| (key[e as usize], e));
        built.arena = EditArena::with_room_for(order.iter().map(|&e| &*entries[e as usize].edit));
        for e in order {
            let entry = &entries[e as usize];
            built.slot_of[e as usize] = built.arena.push(e, &entry.edit);
        }
        let slot_of = &built.slot_of;
        let mut large = Vec::new();
        let mut counts = vec![0u32; n_cells + 1];
        let mut small = Vec::with_capacity(boxes.len());
        for (b, e) in boxes {
            let slot = slot_of[*e as usize];
            let (lo, hi) = (grid.cell_of(b.lo), grid.cell_of(b.hi));
            if (0..3).any(|k| hi[k] - lo[k] > 1) {
                large.push((*b, slot));
                continue;
            }
            grid.for_cells(lo, hi, |c| counts[c] += 1);
            small.push((*b, slot, lo, hi));
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
            slot: 0,
        };
        let mut items = vec![empty; total as usize];
        for (b, slot, lo, hi) in small {
            grid.for_cells(lo, hi, |c| {
                items[next[c] as usize] = GridItem::new(&b, slot);
                next[c] += 1;
            });
        }
        grid.items = items;
        grid.large = Level::from_boxes(&large);
        built.grid = grid;
        built
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

    /// Calls `visit(slot)` for every box that may contain `p` (tested in single precision,
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
                        visit(item.slot);
                    }
                }
            }
        }
        let large = &self.large;
        large
            .bvh
            .visit_point(p, |i| visit(large.edit_of[i as usize]));
    }

    /// Calls `visit(slot)` for every box that may meet `region` (the caller confirms; a box in
    /// several cells comes once per cell), and returns true; or returns false, visiting
    /// nothing, when the region is not an ordered box or meets more than
    /// [`GRID_QUERY_CELLS_MAX`] cells (the tree answers it better).
    fn visit_box(&self, region: &Aabb, mut visit: impl FnMut(u32)) -> bool {
        let ordered = (0..3).all(|k| region.lo[k] <= region.hi[k]);
        if !ordered {
            return false;
        }
        if !self.starts.is_empty() {
            let (lo, hi) = (self.cell_of(region.lo), self.cell_of(region.hi));
            let n_cells: usize = (0..3).map(|k| hi[k] - lo[k] + 1).product();
            if n_cells > GRID_QUERY_CELLS_MAX {
                return false;
            }
            self.for_cells(lo, hi, |c| {
                let range = self.starts[c] as usize..self.starts[c + 1] as usize;
                for item in &self.items[range] {
                    if item.may_meet(region) {
                        visit(item.slot);
                    }
                }
            });
        }
        let large = &self.large;
        large
            .bvh
            .visit_box(region, |i| visit(large.edit_of[i as usize]));
        true
    }
}

/// No slot: the edit is not in the arena.
const NO_SLOT: u32 = u32::MAX;

/// An edit a query found: its index in the history and, when the arena evaluates it, its slot
/// there. Hits order as their edits do.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct Hit(u64);

impl Hit {
    #[inline]
    fn new(edit: u32, slot: u32) -> Hit {
        Hit(((edit as u64) << 32) | slot as u64)
    }

    /// The edit's index in the history.
    #[inline]
    pub(crate) fn edit(self) -> usize {
        (self.0 >> 32) as usize
    }

    #[inline]
    fn slot(self) -> Option<u32> {
        let slot = self.0 as u32;
        (slot != NO_SLOT).then_some(slot)
    }
}

/// The large part of the index: a grid for points and boxes, a tree for boxes too large for
/// the grid, and the arena of its edits' evaluation data. Immutable once built (activity lives
/// in the history), so copies of an object share it.
#[derive(Debug, Default)]
struct Large {
    tree: Level,
    grid: Grid,
    arena: EditArena,
    /// Edit index -> slot in `arena` (`NO_SLOT` for an edit without boxes).
    slot_of: Vec<u32>,
}

/// The ordered, indexed edits of one object.
#[derive(Clone, Debug, Default)]
pub struct History {
    entries: Vec<HistoryEntry>,
    /// Each entry's `active`, side by side (what the index's queries read).
    active: Vec<bool>,
    large: Arc<Large>,
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
        self.active.push(true);
        Ok(idx)
    }

    /// Undoes (`false`) or redoes (`true`) edit `idx`. Returns false if there is no such edit.
    pub fn set_active(&mut self, idx: usize, active: bool) -> bool {
        match self.entries.get_mut(idx) {
            Some(e) => {
                e.active = active;
                self.active[idx] = active;
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
        self.active.truncate(n);
        self.intersects.retain(|&i| (i as usize) < n);
        if n < self.big_end {
            self.large = Arc::default();
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
            let built = Grid::build(&boxes, &self.entries);
            self.large = Arc::new(Large {
                tree: Level::from_boxes(&boxes),
                grid: built.grid,
                arena: built.arena,
                slot_of: built.slot_of,
            });
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
        self.visit_point(p, |h| out.push(h.edit() as u32));
        finish(out);
    }

    /// [`History::collect_point`] as hits that the `apply_*` methods evaluate.
    #[inline]
    pub(crate) fn hits_at_point(&self, p: DVec3, out: &mut Vec<Hit>) {
        out.clear();
        self.visit_point(p, |h| out.push(h));
        finish(out);
    }

    /// Calls `take` for every active edit whose region contains `p`, some more than once.
    #[inline]
    fn visit_point(&self, p: DVec3, mut take: impl FnMut(Hit)) {
        let arena = &self.large.arena;
        self.large.grid.visit_point(p, |slot| {
            if arena.touches(slot, p) {
                let hit = self.hit(slot);
                if self.active[hit.edit()] {
                    take(hit);
                }
            }
        });
        let entries = &self.entries;
        let mut take_edit = |e: u32| {
            let entry = &entries[e as usize];
            if entry.active && entry.edit.touches(p) {
                take(Hit::new(e, NO_SLOT));
            }
        };
        let small = &self.small;
        small
            .bvh
            .visit_point(p, |i| take_edit(small.edit_of[i as usize]));
        (self.indexed_end as u32..entries.len() as u32).for_each(take_edit);
    }

    /// The hit for arena `slot`.
    #[inline]
    fn hit(&self, slot: u32) -> Hit {
        let arena = &self.large.arena;
        let edit = arena.edit(slot);
        match arena.copied(slot) {
            true => Hit::new(edit, slot),
            false => Hit::new(edit, NO_SLOT),
        }
    }

    /// Writes to `out`, ascending, the active edits whose region overlaps `region`.
    pub fn collect_box(&self, region: &Aabb, out: &mut Vec<u32>) {
        out.clear();
        self.visit_box(region, |h| out.push(h.edit() as u32));
        finish(out);
    }

    /// [`History::collect_box`] as hits that the `apply_*` methods evaluate.
    pub(crate) fn hits_in_box(&self, region: &Aabb, out: &mut Vec<Hit>) {
        out.clear();
        self.visit_box(region, |h| out.push(h));
        finish(out);
    }

    /// Calls `take` for every active edit whose region meets `region`, some more than once.
    fn visit_box(&self, region: &Aabb, mut take: impl FnMut(Hit)) {
        let large = &*self.large;
        let mut take_slot = |slot: u32| {
            if large.arena.meets(slot, region) {
                let hit = self.hit(slot);
                if self.active[hit.edit()] {
                    take(hit);
                }
            }
        };
        if !large.grid.visit_box(region, &mut take_slot) {
            let tree = &large.tree;
            tree.bvh.visit_box(region, |i| {
                take_slot(large.slot_of[tree.edit_of[i as usize] as usize]);
            });
        }
        let entries = &self.entries;
        let mut take_edit = |e: u32| {
            let entry = &entries[e as usize];
            if entry.active && entry.edit.boxes().iter().any(|b| b.overlaps(region)) {
                take(Hit::new(e, NO_SLOT));
            }
        };
        let small = &self.small;
        small
            .bvh
            .visit_box(region, |i| take_edit(small.edit_of[i as usize]));
        (self.indexed_end as u32..entries.len() as u32).for_each(take_edit);
    }

    /// The operation of the hit's edit (from the arena when it is there, which the query has
    /// just read: no visit to the edit itself).
    #[inline]
    pub(crate) fn op(&self, hit: Hit) -> EditOp {
        match hit.slot() {
            Some(slot) => self.large.arena.op(slot),
            None => self.entries[hit.edit()].edit.edit().op,
        }
    }

    /// [`CompiledEdit::apply_value`] of the hit's edit.
    #[inline]
    pub(crate) fn apply_value(&self, hit: Hit, f: f64, p: DVec3) -> f64 {
        match hit.slot() {
            Some(slot) => self.large.arena.apply_value(slot, f, p),
            None => self.entries[hit.edit()].edit.apply_value(f, p),
        }
    }

    /// [`CompiledEdit::apply_grad`] of the hit's edit.
    #[inline]
    pub(crate) fn apply_grad(&self, hit: Hit, f: (f64, DVec3), p: DVec3) -> (f64, DVec3) {
        match hit.slot() {
            Some(slot) => self.large.arena.apply_grad(slot, f, p),
            None => self.entries[hit.edit()].edit.apply_grad(f, p),
        }
    }

    /// [`CompiledEdit::apply_interval`] of the hit's edit.
    pub(crate) fn apply_interval(&self, hit: Hit, f: Interval, region: &Aabb) -> Interval {
        match hit.slot() {
            Some(slot) => self.large.arena.apply_interval(slot, f, region),
            None => self.entries[hit.edit()].edit.apply_interval(f, region),
        }
    }

    /// Bytes the arena of the index's large part holds (a copy of its edits' evaluation data).
    pub fn arena_bytes(&self) -> usize {
        self.large.arena.bytes() + self.large.slot_of.capacity() * size_of::<u32>()
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
fn finish<T: Ord>(out: &mut Vec<T>) {
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
        let copy = h.clone();
        assert!(
            Arc::ptr_eq(&copy.large, &h.large),
            "copies share the large part"
        );
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
