//! An object's edit history, indexed by bounds so that a point or a box visits only the edits
//! that can change it there: the cost of an evaluation depends on how many edits overlap the
//! point, not on how many there are.
//!
//! The index has three parts, oldest first: a large part over most of the history, a small
//! [`Bvh`] over recent edits, and a short unindexed tail. The large part answers points and
//! boxes through a uniform grid (one cell lookup and a short contiguous list, whatever the
//! history's length; edits much larger than a cell go to a small tree beside it, and boxes
//! meeting more than `MAX_GRID_QUERY_CELLS` cells go to a [`Bvh`] over the whole part), and
//! evaluates its edits from an `EditArena` built with the grid: copies of their evaluation
//! data in cell order. Appending costs nothing until
//! [`History::refresh`]: the tail then moves into the small tree, and the small tree into the
//! large one when it has grown to an eighth of it, so rebuilding costs O(log n) per edit
//! amortised. Queries stay correct without a refresh (the tail is scanned), only slower.

use std::sync::Arc;

use glam::DVec3;

use super::ObjectError;
use super::arena::{EditArena, f32_up};
use super::edit::{CompiledEdit, EditOp};
use crate::bvh::{Aabb, Bvh};
use crate::limits::MAX_EDITS_PER_OBJECT;
use fdsl::eval::Interval;

/// Longest unindexed tail left by [`History::refresh`].
pub const MAX_TAIL: usize = 32;
/// The small tree merges into the large one when it holds more than this many edits and more
/// than an eighth of the large tree.
const MIN_SMALL: usize = 256;

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

/// A box on the grid's lattice of 16-bit steps, rounded outwards, with its edit's index and
/// which of its cells on each axis is its first (16 bytes: a cell's list is read whole).
#[derive(Clone, Copy, Debug)]
struct GridItem {
    lo: [u16; 3],
    hi: [u16; 3],
    /// The edit's index, and `FIRST_X << k` when this is the box's first cell along axis `k`.
    edit_first: u32,
}

/// The bit of [`GridItem::edit_first`] that marks the box's first cell along x (then y, z).
const FIRST_X: u32 = 1 << 29;
/// The edit's index in [`GridItem::edit_first`].
const EDIT_MASK: u32 = FIRST_X - 1;
const _: () = assert!(MAX_EDITS_PER_OBJECT <= EDIT_MASK as usize);

impl GridItem {
    #[inline]
    fn edit(&self) -> u32 {
        self.edit_first & EDIT_MASK
    }

    /// Whether the box may hold a point on lattice step `q` (the caller confirms).
    #[inline]
    fn contains(&self, q: [u16; 3]) -> bool {
        q[0] >= self.lo[0]
            && q[0] <= self.hi[0]
            && q[1] >= self.lo[1]
            && q[1] <= self.hi[1]
            && q[2] >= self.lo[2]
            && q[2] <= self.hi[2]
    }

    /// Whether the box may meet a box spanning lattice steps `lo..=hi` (the caller confirms).
    #[inline]
    fn may_meet(&self, lo: [u16; 3], hi: [u16; 3]) -> bool {
        (0..3).all(|k| self.lo[k] <= hi[k] && lo[k] <= self.hi[k])
    }
}

/// Lattice steps across the grid's widest axis: 16 bits with room to spare, so a point of the
/// grid rounds to a step that fits.
const LATTICE_STEPS: f64 = 65_000.0;
/// The last lattice step.
const MAX_STEP: f64 = u16::MAX as f64;

/// Most cells per indexed box in a grid (a bound on its memory).
const GRID_CELLS_PER_BOX: usize = 8;
/// Box queries meeting more grid cells than this go to the large tree instead.
const MAX_GRID_QUERY_CELLS: usize = 64;

/// A uniform grid over small boxes for point and box queries; boxes spanning more than two
/// cells on an axis go to `large` instead. Items hold their boxes rounded outwards to a
/// lattice of 16-bit steps over the grid: monotone rounding (a coordinate's step is the floor
/// of its scaled offset, a box's high end rounds up) keeps every point of a box on a step
/// inside the box's steps.
#[derive(Clone, Debug, Default)]
struct Grid {
    origin: DVec3,
    inv_cell: f64,
    /// Lattice steps per unit length.
    inv_step: f64,
    dims: [usize; 3],
    /// Cell `c` holds `items[starts[c][0]..starts[c + 1][0]]`: first, from `starts[c][0]`,
    /// the boxes that begin in an earlier cell along x, latest-ending first; then, from
    /// `starts[c][1]`, those that begin in this one, earliest-beginning first. A scan along
    /// either run stops at the first box that ends before (begins after) the query.
    starts: Vec<[u32; 2]>,
    items: Vec<GridItem>,
    large: Level,
}

impl Grid {
    /// Indexes `boxes` (from [`boxes_of`] over `entries`, every edit of the part) and copies
    /// the edits into an arena, their stamps in cell order: the stamps of the edits one cell
    /// names sit together.
    fn build(boxes: &[(Aabb, u32)], entries: &[HistoryEntry]) -> (Grid, EditArena) {
        let edits: Vec<&CompiledEdit> = entries.iter().map(|e| &*e.edit).collect();
        if boxes.is_empty() {
            return (Grid::default(), EditArena::new(&edits, &[]));
        }
        let mut grid = Grid::sized(boxes);
        let arena = EditArena::new(&edits, &grid.arena_order(boxes, entries.len()));
        grid.index(boxes);
        (grid, arena)
    }

    /// An empty grid over the boxes' bounds (at least one box), with cells about the size of a
    /// typical box, but no more cells than the memory bound.
    fn sized(boxes: &[(Aabb, u32)]) -> Grid {
        let bounds = boxes.iter().fold(Aabb::EMPTY, |a, (b, _)| a.union(b));
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
        let widest = (0..3).map(|k| dims[k] as f64 * cell).fold(0.0, f64::max);
        Grid {
            origin: bounds.lo,
            inv_cell: 1.0 / cell,
            inv_step: LATTICE_STEPS / widest,
            dims,
            ..Grid::default()
        }
    }

    /// The arena's order of the `n_entries` edits: by the cell of their first box's low corner
    /// (large boxes last), so that a cell's items name nearby records; edits with no box are
    /// left out.
    fn arena_order(&self, boxes: &[(Aabb, u32)], n_entries: usize) -> Vec<u32> {
        let dims = self.dims;
        let n_cells = dims[0] * dims[1] * dims[2];
        let mut key = vec![usize::MAX; n_entries];
        for (b, e) in boxes {
            let k = &mut key[*e as usize];
            if *k == usize::MAX {
                let [x, y, z] = self.cell_of(b.lo);
                let spans = (0..3).any(|a| self.cell_of(b.hi)[a] - [x, y, z][a] > 1);
                *k = if spans {
                    n_cells
                } else {
                    x + dims[0] * (y + dims[1] * z)
                };
            }
        }
        let mut order: Vec<u32> = (0..n_entries as u32)
            .filter(|&e| key[e as usize] != usize::MAX)
            .collect();
        order.sort_by_key(|&e| (key[e as usize], e));
        order
    }

    /// Fills the sized grid: each small box in every cell it meets, the large ones in the
    /// tree.
    fn index(&mut self, boxes: &[(Aabb, u32)]) {
        let n_cells = self.dims[0] * self.dims[1] * self.dims[2];
        let mut large = Vec::new();
        let mut counts = vec![0u32; n_cells + 1];
        let mut small = Vec::with_capacity(boxes.len());
        for (b, e) in boxes {
            let (lo, hi) = (self.cell_of(b.lo), self.cell_of(b.hi));
            if (0..3).any(|k| hi[k] - lo[k] > 1) {
                large.push((*b, *e));
                continue;
            }
            self.for_cells(lo, hi, |c| counts[c] += 1);
            small.push((*b, *e, lo, hi));
        }
        let mut total = 0u32;
        for c in counts.iter_mut() {
            let n = *c;
            *c = total;
            total += n;
        }
        let mut items = self.cell_items(&small, &counts, total as usize);
        self.starts = Vec::with_capacity(counts.len());
        for c in 0..n_cells {
            let cell = &mut items[counts[c] as usize..counts[c + 1] as usize];
            cell.sort_by_key(|item| match item.edit_first & FIRST_X {
                0 => (false, u16::MAX - item.hi[0]),
                _ => (true, item.lo[0]),
            });
            let n_before = cell
                .iter()
                .take_while(|i| i.edit_first & FIRST_X == 0)
                .count();
            self.starts.push([counts[c], counts[c] + n_before as u32]);
        }
        self.starts.push([total, total]);
        self.items = items;
        self.large = Level::from_boxes(&large);
    }

    /// The items of the `small` boxes (box, edit, first and last cell), `total` in all, each
    /// cell's from `starts[cell]` on in the boxes' order, flagged on the axes where the cell
    /// is the box's first.
    fn cell_items(
        &self,
        small: &[(Aabb, u32, [usize; 3], [usize; 3])],
        starts: &[u32],
        total: usize,
    ) -> Vec<GridItem> {
        let dims = self.dims;
        let mut next = starts.to_vec();
        let empty = GridItem {
            lo: [0; 3],
            hi: [0; 3],
            edit_first: 0,
        };
        let mut items = vec![empty; total];
        for &(b, e, lo, hi) in small {
            let (qlo, qhi) = (self.step_down(b.lo), self.step_up(b.hi));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let c = x + dims[0] * (y + dims[1] * z);
                        let first = [x == lo[0], y == lo[1], z == lo[2]];
                        let flags = (0..3)
                            .filter(|&k| first[k])
                            .fold(0, |f, k| f | (FIRST_X << k));
                        items[next[c] as usize] = GridItem {
                            lo: qlo,
                            hi: qhi,
                            edit_first: e | flags,
                        };
                        next[c] += 1;
                    }
                }
            }
        }
        items
    }

    /// The lattice step at or below `p`, clamped to the lattice (rounding is monotone: a
    /// larger coordinate never gets a smaller step). The cast truncates, which is the floor
    /// of a clamped, so non-negative, value (and needs no `floor` call).
    #[inline]
    fn step_down(&self, p: DVec3) -> [u16; 3] {
        let q = ((p - self.origin) * self.inv_step).clamp(DVec3::ZERO, DVec3::splat(MAX_STEP));
        [q.x as u16, q.y as u16, q.z as u16]
    }

    /// The lattice step at or above `p`, clamped to the lattice.
    #[inline]
    fn step_up(&self, p: DVec3) -> [u16; 3] {
        let q = ((p - self.origin) * self.inv_step).clamp(DVec3::ZERO, DVec3::splat(MAX_STEP));
        let up = |v: f64| {
            let s = v as u16;
            if f64::from(s) < v { s + 1 } else { s }
        };
        [up(q.x), up(q.y), up(q.z)]
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

    /// Calls `visit(edit)` for every box that may contain `p` (tested on the lattice, rounded
    /// outwards: the caller confirms).
    #[inline]
    fn visit_point(&self, p: DVec3, mut visit: impl FnMut(u32)) {
        if !self.starts.is_empty() {
            let q = (p - self.origin) * self.inv_cell;
            let inside = (0..3).all(|k| q[k] >= 0.0 && q[k] <= self.dims[k] as f64);
            if inside {
                let [x, y, z] = self.cell_of(p);
                let c = x + self.dims[0] * (y + self.dims[1] * z);
                let step = self.step_down(p);
                let [begin, mid] = self.starts[c].map(|i| i as usize);
                let end = self.starts[c + 1][0] as usize;
                for item in &self.items[begin..mid] {
                    if item.hi[0] < step[0] {
                        break;
                    }
                    if item.contains(step) {
                        visit(item.edit());
                    }
                }
                for item in &self.items[mid..end] {
                    if item.lo[0] > step[0] {
                        break;
                    }
                    if item.contains(step) {
                        visit(item.edit());
                    }
                }
            }
        }
        let large = &self.large;
        large
            .bvh
            .visit_point(p, |i| visit(large.edit_of[i as usize]));
    }

    /// Calls `visit(edit)` for every box that may meet `region` (the caller confirms), and
    /// returns true; or returns false, visiting nothing, when the region is not an ordered box
    /// or meets more than [`MAX_GRID_QUERY_CELLS`] cells (the tree answers it better).
    ///
    /// A box in several of the region's cells comes once, from the cell holding the low
    /// corner of its overlap with the region: along each axis, the region's first cell or
    /// the box's own first cell (cells are monotone in the coordinate, so the overlap's low
    /// corner, the larger of the two low corners, lies in the later of the two first cells).
    fn visit_box(&self, region: &Aabb, mut visit: impl FnMut(u32)) -> bool {
        let ordered = (0..3).all(|k| region.lo[k] <= region.hi[k]);
        if !ordered {
            return false;
        }
        if !self.starts.is_empty() {
            let (lo, hi) = (self.cell_of(region.lo), self.cell_of(region.hi));
            let n_cells: usize = (0..3).map(|k| hi[k] - lo[k] + 1).product();
            if n_cells > MAX_GRID_QUERY_CELLS {
                return false;
            }
            let (qlo, qhi) = (self.step_down(region.lo), self.step_up(region.hi));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        // Bits an item needs: its first cell along each axis where this cell
                        // is not the region's first.
                        let need = [x > lo[0], y > lo[1], z > lo[2]]
                            .iter()
                            .enumerate()
                            .filter(|(_, later)| **later)
                            .fold(0, |f, (k, _)| f | (FIRST_X << k));
                        let c = x + self.dims[0] * (y + self.dims[1] * z);
                        let [begin, mid] = self.starts[c].map(|i| i as usize);
                        let end = self.starts[c + 1][0] as usize;
                        // Past the region's first cell along x, only boxes beginning here
                        // count (see above), so the first run is skipped.
                        let before = if x > lo[0] { mid..mid } else { begin..mid };
                        for item in &self.items[before] {
                            if item.hi[0] < qlo[0] {
                                break;
                            }
                            if item.edit_first & need == need && item.may_meet(qlo, qhi) {
                                visit(item.edit());
                            }
                        }
                        for item in &self.items[mid..end] {
                            if item.lo[0] > qhi[0] {
                                break;
                            }
                            if item.edit_first & need == need && item.may_meet(qlo, qhi) {
                                visit(item.edit());
                            }
                        }
                    }
                }
            }
        }
        let large = &self.large;
        large
            .bvh
            .visit_box(region, |i| visit(large.edit_of[i as usize]));
        true
    }
}

/// The edit is not evaluated by the arena.
const NO_SLOT: u32 = u32::MAX;

/// An edit a query found: its index in the history and whether the arena evaluates it (then
/// the slot is the index again). Hits order as their edits do.
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
    /// Bounds over every edit pushed, for [`History::leaves_interval`].
    reach: Reach,
}

/// Bounds over a history's unions and subtractions (undone ones and, after a truncation,
/// removed ones included: each only makes [`History::leaves_interval`] answer false more
/// often), rounded up to single precision (12 bytes: every object holds one).
#[derive(Clone, Copy, Debug)]
struct Reach {
    /// At least the largest [`value_max`](super::tool::value_max) of a union's tool, and of
    /// a subtraction's: no end of their tools' intervals exceeds it. Infinite once one
    /// blends (its interval then grows whatever its tool's).
    union_max: f32,
    subtract_max: f32,
    /// At least the largest size of an edit's box along any axis: a region larger along some
    /// axis lies inside no box.
    box_size: f32,
}

impl Default for Reach {
    fn default() -> Self {
        Reach {
            union_max: f32::NEG_INFINITY,
            subtract_max: f32::NEG_INFINITY,
            box_size: 0.0,
        }
    }
}

impl Reach {
    fn add(&mut self, edit: &CompiledEdit) {
        let max = match edit.edit().op {
            EditOp::Union => &mut self.union_max,
            EditOp::Subtract => &mut self.subtract_max,
            EditOp::Intersect | EditOp::Paint { .. } => return,
        };
        let value_max = if edit.edit().blend_radius == 0.0 {
            f32_up(edit.tool().value_max())
        } else {
            f32::INFINITY
        };
        // NaN compares below no end: once there, the test always fails, as it should.
        if value_max > *max || value_max.is_nan() {
            *max = value_max;
        }
        for b in edit.boxes().iter().filter(|b| !b.is_empty()) {
            self.box_size = self.box_size.max(f32_up(b.size().max_element()));
        }
    }
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
        self.reach.add(&edit);
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
        if n - self.indexed_end <= MAX_TAIL {
            return;
        }
        let small_len = n - self.big_end;
        if small_len > MIN_SMALL && small_len > self.big_end / 8 {
            let boxes = boxes_of(&self.entries, 0..n);
            let (grid, arena) = Grid::build(&boxes, &self.entries);
            self.large = Arc::new(Large {
                tree: Level::from_boxes(&boxes),
                grid,
                arena,
            });
            self.small = Level::default();
            self.big_end = n;
        } else {
            self.small = Level::build(&self.entries, self.big_end..n);
        }
        self.indexed_end = n;
    }

    /// Whether folding every edit over `f`, an interval of the geometry over `region`, gives
    /// `f` bit for bit, so that no edit need be visited. It does when there is no
    /// intersection and no blend, no edit's box holds the whole region, neither end of `f` is
    /// zero or NaN, and every union's tool stays below `f.hi` and every subtraction's negated
    /// tool above `f.lo`: then each edit either is kept by
    /// [`keeps_interval`](super::edit::keeps_interval)'s second case or, evaluated, folds to
    /// `f` for the same reason (its tool's interval ends at most its `value_max`). A mesher's
    /// large boxes, where the geometry's interval spans far past zero both ways, are answered
    /// so whatever the history's length.
    pub(crate) fn leaves_interval(&self, f: Interval, region: &Aabb) -> bool {
        let r = &self.reach;
        let nonzero = |x: f64| x.abs() > 0.0;
        self.intersects.is_empty()
            && nonzero(f.lo)
            && nonzero(f.hi)
            && f64::from(r.union_max) < f.hi
            && f64::from(r.subtract_max) < -f.lo
            && region.size().max_element() > f64::from(r.box_size)
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
        self.large.grid.visit_point(p, |e| {
            if self.active[e as usize] && arena.touches(e, p) {
                take(self.hit(e));
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

    /// The hit for edit `e` of the large part.
    #[inline]
    fn hit(&self, e: u32) -> Hit {
        match self.large.arena.copied(e) {
            true => Hit::new(e, e),
            false => Hit::new(e, NO_SLOT),
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
        let mut take_large = |e: u32| {
            if self.active[e as usize] && large.arena.meets(e, region) {
                take(self.hit(e));
            }
        };
        if !large.grid.visit_box(region, &mut take_large) {
            let tree = &large.tree;
            tree.bvh
                .visit_box(region, |i| take_large(tree.edit_of[i as usize]));
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
        self.large.arena.bytes()
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

    /// The fold by definition, without the index, the arena or the inert-edit shortcut:
    /// every active edit in order through `CompiledEdit`'s full tool evaluation (an
    /// intersection that misses leaves empty space).
    struct Reference<'a> {
        history: &'a History,
        base: crate::object::Sampler,
    }

    impl Reference<'_> {
        fn value(&mut self, p: DVec3) -> f64 {
            let mut v = self.base.value(p, 0.0);
            for e in self.history.entries().iter().filter(|e| e.active) {
                let (op, b) = (&e.edit.edit().op, e.edit.edit().blend_radius);
                if e.edit.touches(p) {
                    v = crate::object::edit::fold_value(op, v, e.edit.tool_value(p), b);
                } else if matches!(op, EditOp::Intersect) {
                    v = crate::object::NOTHING;
                }
            }
            v
        }

        fn gradient(&mut self, p: DVec3) -> (f64, DVec3) {
            let mut v = self.base.gradient(p, 0.0);
            for e in self.history.entries().iter().filter(|e| e.active) {
                let (op, b) = (&e.edit.edit().op, e.edit.edit().blend_radius);
                if e.edit.touches(p) {
                    v = crate::object::edit::fold_grad(op, v, e.edit.tool_eval(p), b);
                } else if matches!(op, EditOp::Intersect) {
                    v = (crate::object::NOTHING, DVec3::ZERO);
                }
            }
            v
        }

        fn interval(&mut self, region: &Aabb) -> Interval {
            let mut v = self.base.interval(region, 0.0);
            for e in self.history.entries().iter().filter(|e| e.active) {
                let (op, b) = (&e.edit.edit().op, e.edit.edit().blend_radius);
                if e.edit.boxes().iter().any(|x| x.overlaps(region)) {
                    let g = e.edit.tool_interval(region);
                    let covered = e.edit.covers(region);
                    v = crate::object::edit::fold_interval(op, v, g, b, covered);
                } else if matches!(op, EditOp::Intersect) {
                    v = Interval::point(crate::object::NOTHING);
                }
            }
            v
        }
    }

    /// The unit sphere sculpted by 1,500 strokes of every tool, on and off its surface, short
    /// (copied into the arena) and long (their own index), some mirrored, every eleventh
    /// undone; with `every_kind`, some intersections and blends too. The stamps' centres and
    /// sizes come back beside it.
    fn sculpted(every_kind: bool) -> (crate::object::Object, Vec<(DVec3, f64)>) {
        use crate::object::Object;
        use crate::object::tool::Axis;
        let mut rng = testkit::rng::XorShift64(0x2545_f491_4f6c_dd1d);
        let mut next = move || rng.unit_f64();
        let mut object = Object::implicit("1 - x^2 - y^2 - z^2").unwrap();
        let mut centres = Vec::new();
        for i in 0..1500 {
            let at = DVec3::new(next(), next(), next()) * 2.2 - DVec3::splat(1.1);
            // Half the edits on the sphere's surface, where sculpting happens and where
            // values are near the tools' (so the inert-edit test is tight).
            let at = match i % 2 {
                0 => at.normalize_or(DVec3::X) * (1.0 + 0.04 * (next() - 0.5)),
                _ => at,
            };
            let size = 0.01 + 0.06 * next();
            centres.push((at, size));
            let tool = match i % 3 {
                0 => ToolShape::Sphere { radius: size },
                1 => ToolShape::Box {
                    half_extents: DVec3::new(size, size * 0.7, size * 1.2),
                    rounding: size * 0.2,
                },
                _ => ToolShape::Cylinder {
                    radius: size,
                    half_height: size * 1.5,
                },
            };
            let n_poses = if i % 97 == 0 { 40 } else { 1 + i % 4 };
            let step = DVec3::new(next(), next(), next()) * size;
            let path = (0..n_poses)
                .map(|k| Pose {
                    position: at + step * k as f64,
                    rotation: glam::DQuat::from_rotation_y(0.3 * k as f64 + next()),
                    scale: 1.0 + 0.3 * next(),
                })
                .collect();
            let op = match i % 41 {
                40 if every_kind => EditOp::Intersect,
                k if k % 2 == 0 => EditOp::Union,
                _ => EditOp::Subtract,
            };
            let mut edit = Edit::stroke(op, tool, path);
            let blend = 0.02 * next();
            if i % 5 == 0 && every_kind {
                edit.blend_radius = blend;
            }
            edit.mirror = [None, None, None, Some(Axis::X), Some(Axis::Z)][i % 5];
            object.apply(edit).unwrap();
        }
        object.prepare();
        for i in (0..1500).step_by(11) {
            object.history_mut().set_active(i, false);
        }
        let history = object.history();
        assert_eq!(history.tail_len(), 0);
        assert!(history.big_end > 0, "the arena is in use");
        (object, centres)
    }

    /// Checks the sampler against the fold by definition at 6,000 points and boxes of the
    /// half sizes `halves` around them (half anywhere, half in or near a stamp, where its
    /// tool's values are highest and the inert-edit test is closest to its bound); returns
    /// how many boxes [`History::leaves_interval`] answered.
    fn check_against_the_definition(
        object: &crate::object::Object,
        centres: &[(DVec3, f64)],
        halves: &[f64],
    ) -> usize {
        use crate::object::Object;
        let mut rng = testkit::rng::XorShift64(0x9e37_79b9_7f4a_7c15);
        let mut next = move || rng.unit_f64();
        let history = object.history();
        let mut reference = Reference {
            history,
            base: Object::implicit("1 - x^2 - y^2 - z^2").unwrap().sampler(),
        };
        let mut sampler = object.sampler();
        let mut n_left = 0;
        for k in 0..6000 {
            let p = match k % 2 {
                0 => DVec3::new(next(), next(), next()) * 2.4 - DVec3::splat(1.2),
                _ => {
                    let (at, size) = centres[(next() * centres.len() as f64) as usize];
                    at + (DVec3::new(next(), next(), next()) - DVec3::splat(0.5)) * size
                }
            };
            let (a, b) = (sampler.value(p, 0.0), reference.value(p));
            assert_eq!(a.to_bits(), b.to_bits(), "value at {p}");
            let (a, b) = (sampler.gradient(p, 0.0), reference.gradient(p));
            assert_eq!(a.0.to_bits(), b.0.to_bits(), "gradient value at {p}");
            assert_eq!(
                a.1.to_array().map(f64::to_bits),
                b.1.to_array().map(f64::to_bits)
            );
            let half = halves[k % halves.len()];
            let region = Aabb::around(p, DVec3::splat(half));
            let (a, b) = (sampler.interval(&region, 0.0), reference.interval(&region));
            assert_eq!(
                (a.lo.to_bits(), a.hi.to_bits(), a.nan),
                (b.lo.to_bits(), b.hi.to_bits(), b.nan),
                "interval around {p} of half size {half}"
            );
            n_left += usize::from(
                history.leaves_interval(reference.base.interval(&region, 0.0), &region),
            );
        }
        n_left
    }

    #[test]
    fn indexed_evaluation_is_the_fold_by_definition_bit_for_bit() {
        let (object, centres) = sculpted(true);
        let n_left =
            check_against_the_definition(&object, &centres, &[0.001, 0.01, 1.0 / 64.0, 0.05, 0.3]);
        assert_eq!(n_left, 0, "intersections and blends are visited");
    }

    #[test]
    fn a_history_that_cannot_change_a_large_box_is_not_visited_and_gives_its_fold() {
        // No intersection and no blend: over boxes larger than every edit's (its longest
        // stroke's is about 2 across), where the sphere's interval spans zero by more than
        // any tool reaches, the fold is the sphere's interval bit for bit, and the sampler
        // answers without visiting an edit.
        let (object, centres) = sculpted(false);
        let halves = [0.001, 0.01, 0.05, 0.3, 0.6, 1.2];
        let n_left = check_against_the_definition(&object, &centres, &halves);
        assert!(
            n_left >= 6000 / halves.len(),
            "{n_left} of 6000 boxes left as they were"
        );
        assert!(
            n_left < 6000 / 2,
            "{n_left}: boxes inside a stroke's are folded"
        );
        let root = Aabb::around(DVec3::ZERO, DVec3::splat(1.2));
        let f = Interval::new(-2.0, 1.0);
        assert!(object.history().leaves_interval(f, &root));
        // Not where an end is zero, or where a tool reaches past it.
        assert!(
            !object
                .history()
                .leaves_interval(Interval::new(-0.0, 1.0), &root)
        );
        assert!(
            !object
                .history()
                .leaves_interval(Interval::new(-2.0, 0.01), &root)
        );
        assert!(
            !object
                .history()
                .leaves_interval(Interval::new(-0.01, 1.0), &root)
        );
        // Nor with an intersection or a blend anywhere in the history.
        let (object, _) = sculpted(true);
        assert!(!object.history().leaves_interval(f, &root));
    }

    #[test]
    fn grid_box_queries_find_each_overlapping_edit_once() {
        // Boxes from a point to several cells wide, on and off the edits' corners: the grid
        // (with its once-per-box rule) and the tree give what a scan gives, and the grid
        // visits no edit twice.
        let mut h = History::default();
        let point = |i: usize| {
            let a = i as f64;
            DVec3::new((a * 0.37).sin(), (a * 0.23).cos(), (a * 0.11).sin()) * 0.5
        };
        for i in 0..3000 {
            h.push(edit_at(point(i))).unwrap();
        }
        h.refresh();
        assert_eq!(h.tail_len(), 0);
        let mut out = Vec::new();
        for k in 0..400 {
            let half = [0.0, 0.001, 0.02, 0.05, 0.09, 0.3][k % 6];
            let center = point(k * 13) + DVec3::splat(0.05 * ((k % 3) as f64 - 1.0));
            let region = Aabb::around(center, DVec3::splat(half));
            h.collect_box(&region, &mut out);
            let want: Vec<u32> = (0..h.len() as u32)
                .filter(|&i| h.entries()[i as usize].edit.bounds().overlaps(&region))
                .collect();
            assert_eq!(out, want, "around {center} of half size {half}");
            let mut seen = Vec::new();
            if h.large.grid.visit_box(&region, |e| seen.push(e)) {
                let n = seen.len();
                seen.sort_unstable();
                seen.dedup();
                assert_eq!(seen.len(), n, "the grid visits each box once");
            }
        }
    }
}
