//! Dual contouring of an implicit solid over an adaptive octree with interval pruning.
//!
//! The box to mesh is split recursively; interval arithmetic discards every octree node the
//! surface cannot cross, and [`Field::simplify`] may hand a cheaper field to each subtree.
//! Surviving leaves are blocks of [`BLOCK_CELLS`]^3 cells whose grid values are evaluated in
//! one bulk call. Each cell crossed by the surface gets one vertex per surface patch (so
//! ambiguous cells stay manifold, as in dual marching cubes), placed by minimising a quadric
//! error function of the edge crossings' tangent planes (from f and its gradient there),
//! over the cell: sharp edges and corners are kept, and a vertex on a crease or a corner
//! takes the mean of its faces' normals, not whichever face the gradient of a `min` picks
//! (see `octree/qef.rs`). Each sign-changing grid edge emits a quad joining the vertices of
//! its four cells.
//!
//! Watertightness rests on one rule: every grid value is computed once, by the block that
//! owns the point (a block owns the points of its upper faces; the lowest blocks also own the
//! grid's lower faces), and every cell reads it from there. A pruned block owns a constant
//! of the sign its interval proved. So two cells sharing a face always see the same corner
//! values, whatever field (simplified tape) each block was evaluated with, and decide the
//! face alike. A pruned block whose lower neighbour's values still disagree in sign (interval
//! arithmetic in f64 against bulk values in f32 near zero) gets cells like any other.
//! Manifoldness rests on splitting the vertex of a patch that crosses one face twice (see
//! `octree/topology.rs`): the pieces are joined by gap polygons across the face and a polygon inside
//! the cell.
//!
//! Guarantees: when the surface lies strictly inside the box, the mesh is watertight and
//! edge-manifold, its triangles wind counter-clockwise seen from outside, and each vertex lies
//! in its cell, or within half a cell of it (and inside the box) where it follows a crease or
//! a corner of flat faces that meet just outside. A vertex whose crossings lie on flat faces
//! lies where their planes meet (on the face, the crease or the corner, to 1e-3 of a cell)
//! when that point is in its cell or, for such a feature, within that half cell; on curved
//! faces, within about the sagitta of a cell. A vertex and its normal depend only on its
//! cell's values and on the block's field at points of the cell, so a remeshed block places
//! them as a whole mesh does.
//! Non-guarantees: vertices may be non-manifold (two sheets may share a vertex where a thin
//! feature pinches); triangles may self-intersect near sharp features thinner than a cell,
//! and a few tiny ones may turn over where a crease passes within rounding of grid points;
//! features smaller than a cell may be missed; cells are not collapsed where the surface is
//! flat (the resolution near the surface is uniform); a vertex has one normal, so the shading
//! of the triangles either side of a crease blends towards the crease vertices' mean normal
//! (a soft band about a cell wide, not a sharp line). Where the surface leaves the box the
//! mesh is open along the box, which is what stitching a remeshed region needs.

mod assembly;
mod parallel;
mod qef;
mod topology;

pub use assembly::MeshPatch;
pub use parallel::{MIN_PARALLEL_BLOCKS, PARALLEL_LEVELS};

use super::field::Field;
use super::{Aabb, MAX_INDEXED_VERTICES, Mesh, normalise_or_up};
use qef::{Bracket, FEATURE_REACH_CELLS, Hermite, feature, refine_crossings, solve_qef};
use std::collections::BTreeMap;
use topology::{
    MAX_PATCH_EDGES, MAX_PATCHES, N_FACES, Patch, cell_patches, corner_offset, edge_across,
    edge_corners, edge_index, face_segments, inside, quad_cells, quad_runs_to, split_patch,
};

/// Deepest octree allowed: 2^10 = 1024 cells along each axis.
pub const MAX_OCTREE_DEPTH: u8 = 10;
/// Cells along each axis of a leaf block evaluated in one bulk call.
pub const BLOCK_CELLS: u32 = 8;
/// Marker for "no vertex" in cell tables.
const NONE: u32 = u32::MAX;

/// What to mesh and how finely.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshSettings {
    /// The box to mesh, in world units.
    pub bounds: Aabb,
    /// Octree depth: the box is cut into 2^depth cells along each axis.
    pub depth: u8,
}

/// Why meshing could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum OctreeMeshError {
    /// The depth exceeds [`MAX_OCTREE_DEPTH`].
    #[error("octree depth {0} exceeds the maximum {MAX_OCTREE_DEPTH}")]
    DepthTooLarge(u8),
    /// The box has no volume, or non-finite corners.
    #[error("bounds {0:?} are empty or not finite")]
    BadBounds(Aabb),
    /// The surface needs more vertices than a mesh can index.
    #[error("mesh would exceed {MAX_INDEXED_VERTICES} vertices")]
    TooManyVertices,
}

/// Counters that show how much work pruning saved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshStats {
    /// Octree nodes above the blocks whose interval was not asked: a block in them that the
    /// remesh kept is crossed by the surface, so none could be discarded.
    pub intervals_skipped: usize,
    /// Octree nodes (of any size) discarded by interval arithmetic.
    pub nodes_pruned: usize,
    /// Leaf blocks whose grid was evaluated.
    pub blocks_evaluated: usize,
    /// Number of times [`Field::simplify`] returned a simplified field.
    pub fields_simplified: usize,
    /// Surface patches given several vertices to stay manifold.
    pub patches_split: usize,
    /// Blocks next to a remeshed range whose lattice values did not change, so their cells
    /// were kept rather than built again.
    pub blocks_unchanged: usize,
}

impl std::ops::AddAssign for MeshStats {
    fn add_assign(&mut self, o: MeshStats) {
        self.intervals_skipped += o.intervals_skipped;
        self.nodes_pruned += o.nodes_pruned;
        self.blocks_evaluated += o.blocks_evaluated;
        self.fields_simplified += o.fields_simplified;
        self.patches_split += o.patches_split;
        self.blocks_unchanged += o.blocks_unchanged;
    }
}

/// Meshes the surface f = 0 of `field` inside `settings.bounds`.
pub fn mesh<F: Field>(field: &mut F, settings: &MeshSettings) -> Result<Mesh, OctreeMeshError> {
    mesh_with_stats(field, settings).map(|(m, _)| m)
}

/// Like [`mesh`], also returning how many nodes were pruned and blocks evaluated.
pub fn mesh_with_stats<F: Field>(
    field: &mut F,
    settings: &MeshSettings,
) -> Result<(Mesh, MeshStats), OctreeMeshError> {
    let mut mesher = OctreeMesher::new(settings)?;
    let stats = mesher.remesh(field, settings.bounds)?;
    Ok((mesher.mesh()?, stats))
}

/// Like [`mesh_with_stats`], on up to `n_threads` threads, with the same result (see
/// [`OctreeMesher::remesh_parallel`]).
pub fn mesh_on_threads<F: Field + Send>(
    field: &mut F,
    settings: &MeshSettings,
    n_threads: usize,
) -> Result<(Mesh, MeshStats), OctreeMeshError> {
    let mut mesher = OctreeMesher::new(settings)?;
    let stats = mesher.remesh_parallel(field, settings.bounds, n_threads)?;
    Ok((mesher.mesh()?, stats))
}

/// The number of leaf blocks [`mesh`] evaluates for `field` and `settings`
/// ([`MeshStats::blocks_evaluated`]), found by interval arithmetic alone: the same octree
/// descent, pruning and [`Field::simplify`] calls as meshing, without evaluating any block.
/// Callers with a budget use it to choose a depth before they mesh.
pub fn count_blocks<F: Field>(
    field: &mut F,
    settings: &MeshSettings,
) -> Result<usize, OctreeMeshError> {
    fn node<F: Field>(grid: &Grid, field: &mut F, origin: [u32; 3], size: u32) -> usize {
        let lo = grid.point(origin);
        let hi = grid.point(origin.map(|o| o + size));
        let (f_lo, f_hi) = field.interval(lo, hi);
        if f_lo > 0.0 || f_hi < 0.0 {
            return 0;
        }
        let mut simplified = field.simplify(lo, hi);
        let field: &mut F = simplified.as_mut().unwrap_or(field);
        if size <= grid.block {
            return 1;
        }
        let half = size / 2;
        (0..8)
            .map(|k| {
                let child = std::array::from_fn(|a| origin[a] + corner_offset(k)[a] * half);
                node(grid, field, child, half)
            })
            .sum()
    }
    let grid = Grid::new(settings)?;
    Ok(node(&grid, field, [0; 3], grid.n_cells))
}

/// A mesher that keeps its evaluated blocks, so that only an edit's box is meshed again.
///
/// [`OctreeMesher::remesh`] evaluates again every block whose closed box meets the dirty box,
/// and recomputes the cells (not the values) of the blocks just above them, which read those
/// values; all other blocks are kept. The result is watertight and manifold like a full mesh
/// of the edited field, and equal to it wherever pruning made the same decisions (always,
/// for fields whose interval bounds do not depend on far-away parts of the field).
///
/// [`OctreeMesher::mesh`] assembles the whole mesh from the kept blocks;
/// [`OctreeMesher::mesh_update`] patches the mesh it handed out last, writing only the
/// changed blocks' vertices and the triangles that read them, and says which ranges changed.
pub struct OctreeMesher {
    grid: Grid,
    /// Blocks along each axis.
    n_blocks: u32,
    /// Per block (x fastest), the value of all the grid points it owns when it has no record:
    /// plus or minus [`Grid::rep`], the sign its interval proved or its values showed.
    reps: Vec<f32>,
    /// Blocks with a record: those with crossed cells, and evaluated blocks kept by a remesh.
    blocks: BTreeMap<[u32; 3], Block>,
    /// Blocks whose records a remesh replaced or dropped since the last
    /// [`OctreeMesher::mesh_update`].
    changes: Changes,
    /// Where each block's vertices and triangles lie in the mesh that
    /// [`OctreeMesher::mesh_update`] last handed out.
    assembled: Option<assembly::Assembled>,
}

/// Blocks changed since the mesh was last patched.
#[derive(Default)]
struct Changes {
    /// Block indices, possibly repeated; at most the number of blocks (then `all` is set).
    blocks: Vec<u32>,
    /// Every block may have changed: the next patch assembles the whole mesh.
    all: bool,
}

impl Changes {
    /// Notes that block `idx` (of `n_blocks_total`) changed.
    fn push(&mut self, idx: usize, n_blocks_total: usize) {
        if self.all {
            return;
        }
        if self.blocks.len() >= n_blocks_total {
            // A bounded log: past one entry per block, patching saves nothing.
            self.blocks.clear();
            self.all = true;
            return;
        }
        self.blocks.push(idx as u32);
    }
}

impl OctreeMesher {
    /// An empty mesher for `settings`; call [`OctreeMesher::remesh`] with the whole bounds.
    pub fn new(settings: &MeshSettings) -> Result<Self, OctreeMeshError> {
        let grid = Grid::new(settings)?;
        let n_blocks = grid.n_cells / grid.block;
        // Until a block is visited it counts as outside.
        let reps = vec![-grid.rep(); (n_blocks * n_blocks * n_blocks) as usize];
        Ok(Self {
            grid,
            n_blocks,
            reps,
            blocks: BTreeMap::new(),
            changes: Changes {
                blocks: Vec::new(),
                all: true,
            },
            assembled: None,
        })
    }

    /// Evaluates again every block that `dirty` (world units) touches, using `field`.
    ///
    /// `field` must be the whole current field; it must equal the old one outside `dirty`.
    pub fn remesh<F: Field>(
        &mut self,
        field: &mut F,
        dirty: Aabb,
    ) -> Result<MeshStats, OctreeMeshError> {
        let Some((range, wide)) = self.begin(dirty) else {
            return Ok(MeshStats::default());
        };
        Ok(self.visit_whole(field, range, wide))
    }

    /// One visit from the root on this thread, over the blocks `wide` holds (see
    /// [`OctreeMesher::begin`]).
    fn visit_whole<F: Field>(
        &mut self,
        field: &mut F,
        range: BlockRange,
        wide: BlockRange,
    ) -> MeshStats {
        let local = self.take_local(wide);
        let mut visit = Visit::new(self, local, range, wide);
        visit.node(field, [0; 3], self.grid.n_cells);
        let Visit { local, stats, .. } = visit;
        self.put_local(local);
        stats
    }

    /// The blocks `dirty` touches (`range`) and those a remesh of them may change (`wide`:
    /// the range and the blocks just above it, which read its values); forgets the range's
    /// records and notes its blocks as changed. `None` when `dirty` touches no block.
    fn begin(&mut self, dirty: Aabb) -> Option<(BlockRange, BlockRange)> {
        let range = self.grid.blocks_touching(dirty)?;
        let last = self.n_blocks - 1;
        let wide = BlockRange {
            lo: range.lo,
            hi: range.hi.map(|h| (h + 1).min(last)),
        };
        self.blocks.retain(|k, _| !range.contains(*k));
        self.note_changed(range);
        Some((range, wide))
    }

    /// Takes the records and representatives of the blocks of `keys` out, for one traversal
    /// to change ([`OctreeMesher::put_local`] puts them back).
    fn take_local(&mut self, keys: BlockRange) -> Local {
        let (lo, hi) = (keys.lo, keys.hi);
        let mut blocks = BTreeMap::new();
        for x in lo[0]..=hi[0] {
            let row: Vec<[u32; 3]> = (self.blocks.range([x, lo[1], lo[2]]..=[x, hi[1], hi[2]]))
                .map(|(k, _)| *k)
                .filter(|k| keys.contains(*k))
                .collect();
            for k in row {
                if let Some(b) = self.blocks.remove(&k) {
                    blocks.insert(k, b);
                }
            }
        }
        let mut reps = Vec::with_capacity(keys.n_blocks());
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    reps.push(self.reps[self.block_idx([x, y, z])]);
                }
            }
        }
        Local {
            keys,
            blocks,
            reps,
            changes: Vec::new(),
        }
    }

    /// Puts back what a traversal changed (see [`OctreeMesher::take_local`]).
    fn put_local(&mut self, local: Local) {
        let Local {
            keys,
            blocks,
            reps,
            changes,
        } = local;
        self.blocks.extend(blocks);
        let mut next = reps.into_iter();
        for z in keys.lo[2]..=keys.hi[2] {
            for y in keys.lo[1]..=keys.hi[1] {
                for x in keys.lo[0]..=keys.hi[0] {
                    let idx = self.block_idx([x, y, z]);
                    self.reps[idx] = next.next().unwrap_or(self.reps[idx]);
                }
            }
        }
        let n_total = self.reps.len();
        for idx in changes {
            self.changes.push(idx as usize, n_total);
        }
    }

    /// Notes every block of `range` as changed (blocks just above it are noted by
    /// `Visit::finish` when their cells change).
    fn note_changed(&mut self, range: BlockRange) {
        let n_total = self.reps.len();
        let n_range: usize = (0..3)
            .map(|a| (range.hi[a] - range.lo[a] + 1) as usize)
            .product();
        if n_range >= n_total {
            self.changes.blocks.clear();
            self.changes.all = true;
            return;
        }
        for z in range.lo[2]..=range.hi[2] {
            for y in range.lo[1]..=range.hi[1] {
                for x in range.lo[0]..=range.hi[0] {
                    self.changes.push(self.block_idx([x, y, z]), n_total);
                }
            }
        }
    }

    /// Number of kept blocks with a record (crossed by the surface, or kept by a remesh).
    pub fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// Whether no grid point on the box's faces is inside: then the surface lies strictly
    /// inside the box, and the mesh is watertight and wound counter-clockwise seen from
    /// outside (the guarantees above), so a renderer may cull its back faces. Reads only the
    /// blocks along the box's faces (their records' values, or the sign a block's points
    /// share).
    pub fn encloses(&self) -> bool {
        let last = self.n_blocks - 1;
        let at_side = |k: u32| k == 0 || k == last;
        (0..=last).all(|k2| {
            (0..=last).all(|k1| {
                // Inside the box's side layers only the first and last block of a row.
                let step = if at_side(k1) || at_side(k2) {
                    1
                } else {
                    last.max(1)
                };
                (0..=last)
                    .step_by(step as usize)
                    .all(|k0| self.outside_on_the_faces([k0, k1, k2]))
            })
        })
    }

    /// Whether no grid point on the box's faces that block `key` holds is inside.
    fn outside_on_the_faces(&self, key: [u32; 3]) -> bool {
        let Some(block) = self.blocks.get(&key) else {
            return !inside(self.reps[self.block_idx(key)]);
        };
        let (n, bc) = (self.grid.n_cells, self.grid.block);
        let lattice = || 0..=bc;
        lattice().all(|l2| {
            lattice().all(|l1| {
                lattice().all(|l0| {
                    let l = [l0, l1, l2];
                    let on_face = (0..3).any(|a| {
                        let p = block.origin[a] + l[a];
                        p == 0 || p == n
                    });
                    !on_face || !inside(block.values[self.grid.at(l)])
                })
            })
        })
    }

    /// Assembles the mesh of all kept blocks.
    pub fn mesh(&self) -> Result<Mesh, OctreeMeshError> {
        let mut mesh = Mesh::default();
        self.assemble_into(&mut mesh, |_| {})?;
        Ok(mesh)
    }

    /// Assembles the mesh of all kept blocks into `mesh` (emptied first), block after block in
    /// key order; tells `placed` where each block's vertices and triangles went.
    fn assemble_into(
        &self,
        mesh: &mut Mesh,
        mut placed: impl FnMut(Placed),
    ) -> Result<(), OctreeMeshError> {
        // Dense tables by block index: lookups across block faces are the inner loop.
        let mut offsets = vec![NONE; self.reps.len()];
        let mut records: Vec<Option<&Block>> = vec![None; self.reps.len()];
        *mesh = Mesh::default();
        let n_vertices: usize = self.blocks.values().map(|b| b.positions.len()).sum();
        if n_vertices >= NONE as usize {
            return Err(OctreeMeshError::TooManyVertices);
        }
        mesh.positions.reserve(n_vertices);
        mesh.normals.reserve(n_vertices);
        for (key, block) in &self.blocks {
            let idx = self.block_idx(*key);
            offsets[idx] = mesh.positions.len() as u32;
            records[idx] = Some(block);
            mesh.positions.extend_from_slice(&block.positions);
            mesh.normals.extend_from_slice(&block.normals);
        }
        mesh.colours = vec![[1.0; 4]; mesh.positions.len()];
        let assembly = Assembly {
            offsets: &offsets,
            records: Records::Dense(records),
        };
        for (key, block) in &self.blocks {
            let idx = self.block_idx(*key);
            let first_triangle = mesh.indices.len() / 3;
            self.emit_block(block, &assembly, &mesh.positions, &mut mesh.indices, idx);
            placed(Placed {
                block_idx: idx,
                first_vertex: offsets[idx],
                n_vertices: block.positions.len(),
                triangles: first_triangle..mesh.indices.len() / 3,
            });
        }
        Ok(())
    }

    /// Appends to `out` every triangle block `block` (index `idx`) owns: the quads of the grid
    /// edges it owns, the gap polygons across its split cells' faces, its central polygons.
    fn emit_block(
        &self,
        block: &Block,
        assembly: &Assembly<'_>,
        positions: &[[f32; 3]],
        out: &mut Vec<u32>,
        idx: usize,
    ) {
        let offset = assembly.offsets[idx];
        self.emit_quads(block, offset, assembly, positions, out);
        self.emit_gaps(block, offset, assembly, positions, out);
        for central in &block.centrals {
            for k in 1..central.len().saturating_sub(1) {
                out.extend([central[0], central[k], central[k + 1]].map(|v| v + offset));
            }
        }
    }

    fn block_idx(&self, k: [u32; 3]) -> usize {
        (k[0] + self.n_blocks * (k[1] + self.n_blocks * k[2])) as usize
    }
}

/// An inclusive box of block coordinates.
#[derive(Clone, Copy, Debug)]
struct BlockRange {
    lo: [u32; 3],
    hi: [u32; 3],
}

impl BlockRange {
    fn contains(&self, k: [u32; 3]) -> bool {
        (0..3).all(|a| self.lo[a] <= k[a] && k[a] <= self.hi[a])
    }

    fn n_blocks(&self) -> usize {
        (0..3)
            .map(|a| (self.hi[a] - self.lo[a] + 1) as usize)
            .product()
    }

    /// The index of block `k` (inside) among the range's, x fastest.
    fn index(&self, k: [u32; 3]) -> usize {
        let n: [usize; 3] = std::array::from_fn(|a| (self.hi[a] - self.lo[a] + 1) as usize);
        let l: [usize; 3] = std::array::from_fn(|a| (k[a] - self.lo[a]) as usize);
        l[0] + n[0] * (l[1] + n[1] * l[2])
    }
}

impl Local {
    /// Nothing: a traversal that only reads (the plan of a parallel remesh).
    fn none() -> Local {
        Local {
            keys: BlockRange {
                lo: [1; 3],
                hi: [0; 3],
            },
            blocks: BTreeMap::new(),
            reps: Vec::new(),
            changes: Vec::new(),
        }
    }
}

/// What one traversal may change, taken out of the mesher: the records and representatives
/// of the blocks of `keys`, and the blocks outside the remeshed range whose cells changed.
/// Everything else the traversal reads from the mesher, which it does not change.
struct Local {
    keys: BlockRange,
    blocks: BTreeMap<[u32; 3], Block>,
    /// Per block of `keys` ([`BlockRange::index`]), as [`OctreeMesher::reps`].
    reps: Vec<f32>,
    /// Mesher block indices, as [`Changes::blocks`].
    changes: Vec<u32>,
}

/// The sampling lattice: grid point i along axis a sits at `lo[a] + i * step[a]`.
#[derive(Clone, Copy, Debug)]
struct Grid {
    lo: [f32; 3],
    step: [f32; 3],
    n_cells: u32,
    block: u32,
}

impl Grid {
    /// The lattice of `settings`, checked.
    fn new(settings: &MeshSettings) -> Result<Grid, OctreeMeshError> {
        if settings.depth > MAX_OCTREE_DEPTH {
            return Err(OctreeMeshError::DepthTooLarge(settings.depth));
        }
        let b = settings.bounds;
        let sane = (0..3).all(|a| b.lo[a].is_finite() && b.hi[a].is_finite() && b.lo[a] < b.hi[a]);
        if !sane {
            return Err(OctreeMeshError::BadBounds(b));
        }
        let n_cells = 1u32 << settings.depth;
        Ok(Grid {
            lo: b.lo,
            step: std::array::from_fn(|a| (b.hi[a] - b.lo[a]) / n_cells as f32),
            n_cells,
            block: BLOCK_CELLS.min(n_cells),
        })
    }

    fn point(&self, i: [u32; 3]) -> [f32; 3] {
        std::array::from_fn(|a| self.lo[a] + i[a] as f32 * self.step[a])
    }

    /// The box a vertex of the cell `lo..=hi` may move to to follow a sharp feature: the cell
    /// grown by [`FEATURE_REACH_CELLS`], within the grid.
    fn reach(&self, lo: [f32; 3], hi: [f32; 3]) -> [[f32; 3]; 2] {
        let end = self.point([self.n_cells; 3]);
        let margin = self.step.map(|s| FEATURE_REACH_CELLS * s);
        [
            std::array::from_fn(|a| (lo[a] - margin[a]).max(self.lo[a])),
            std::array::from_fn(|a| (hi[a] + margin[a]).min(end[a])),
        ]
    }

    /// The mean cell size.
    fn h(&self) -> f32 {
        (self.step[0] + self.step[1] + self.step[2]) / 3.0
    }

    /// The magnitude that stands for the values of a block without a record: a cell size,
    /// about what a distance field has one cell away from its surface.
    fn rep(&self) -> f32 {
        self.h()
    }

    /// Grid points along an axis of a block with a (bc + 1)-point lattice.
    fn lattice(&self) -> u32 {
        self.block + 1
    }

    /// Index of lattice point `l` within a block's values.
    fn at(&self, l: [u32; 3]) -> usize {
        let np = self.lattice();
        (l[0] + np * (l[1] + np * l[2])) as usize
    }

    /// The first lattice index a block owns along each axis: 1, or 0 at the grid's low faces.
    fn owned_from(&self, key: [u32; 3]) -> [u32; 3] {
        key.map(|k| u32::from(k > 0))
    }

    /// The blocks whose closed boxes meet `b`, widened by a cell against rounding.
    fn blocks_touching(&self, b: Aabb) -> Option<BlockRange> {
        let n = i64::from(self.n_cells);
        let bc = i64::from(self.block);
        let mut range = BlockRange {
            lo: [0; 3],
            hi: [0; 3],
        };
        for a in 0..3 {
            let to_grid = |x: f32| f64::from((x - self.lo[a]) / self.step[a]);
            let (lo, hi) = (to_grid(b.lo[a]).floor(), to_grid(b.hi[a]).ceil());
            let outside = hi < -1.0 || lo > (n + 1) as f64 || lo > hi;
            if !(lo.is_finite() && hi.is_finite()) || outside {
                return None;
            }
            let lo = (lo as i64 - 1).clamp(0, n);
            let hi = (hi as i64 + 1).clamp(0, n);
            // Block k covers grid points k*bc ..= (k+1)*bc.
            range.lo[a] = ((lo + bc - 1) / bc - 1).clamp(0, n / bc - 1) as u32;
            range.hi[a] = (hi / bc).clamp(0, n / bc - 1) as u32;
        }
        Some(range)
    }
}

/// One block with a record: its lattice values and the vertices of its crossed cells.
struct Block {
    origin: [u32; 3],
    /// (block + 1)^3 lattice values, x fastest: the block's own where it owns the point,
    /// copied from the owning neighbour on its lower faces.
    values: Vec<f32>,
    /// Per cell (x fastest), an index into `cells` or `NONE`.
    cell_entry: Vec<u32>,
    /// Per crossed cell, the block-local vertex of each of its 12 edges (`NONE` if uncrossed).
    cells: Vec<[u32; 12]>,
    /// Per crossed cell, its position in the block.
    cell_local: Vec<[u32; 3]>,
    /// Crossed cells (indices into `cells`) with a patch split into several vertices.
    split_cells: Vec<u32>,
    /// Polygons (block-local vertices, wound outwards) joining the pieces of a patch split
    /// into three or more vertices.
    centrals: Vec<Vec<u32>>,
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
}

/// What a visit does with an octree node (see `Visit::step`).
enum Step {
    Skip,
    Prune {
        first: [u32; 3],
        last: [u32; 3],
        rep: f32,
    },
    Open {
        lo: [f32; 3],
        hi: [f32; 3],
    },
}

/// Where the values a block owns come from.
enum Owned<'a> {
    /// A record's lattice values.
    Values(&'a [f32]),
    /// One value for every point.
    Rep(f32),
}

/// One octree traversal: blocks in `range` are evaluated again; blocks in `wide` (the range
/// and the blocks just above it, which read its values) get their cells recomputed.
struct Visit<'a> {
    /// The blocks outside `local`, read only.
    mesher: &'a OctreeMesher,
    local: Local,
    range: BlockRange,
    wide: BlockRange,
    stats: MeshStats,
}

impl<'a> Visit<'a> {
    fn new(mesher: &'a OctreeMesher, local: Local, range: BlockRange, wide: BlockRange) -> Self {
        Visit {
            mesher,
            local,
            range,
            wide,
            stats: MeshStats::default(),
        }
    }

    /// Block `key`'s record, if it has one.
    fn record(&self, key: [u32; 3]) -> Option<&Block> {
        if self.local.keys.contains(key) {
            self.local.blocks.get(&key)
        } else {
            self.mesher.blocks.get(&key)
        }
    }

    /// Block `key`'s representative.
    fn rep(&self, key: [u32; 3]) -> f32 {
        if self.local.keys.contains(key) {
            self.local.reps[self.local.keys.index(key)]
        } else {
            self.mesher.reps[self.mesher.block_idx(key)]
        }
    }

    /// Sets block `key`'s representative (`key` is in `local`).
    fn set_rep(&mut self, key: [u32; 3], rep: f32) {
        let i = self.local.keys.index(key);
        self.local.reps[i] = rep;
    }

    /// Visits the octree node of `size` cells at `origin`, pruning or evaluating it.
    fn node<F: Field>(&mut self, field: &mut F, origin: [u32; 3], size: u32) {
        let (lo, hi) = match self.step(field, origin, size) {
            Step::Skip => return,
            Step::Prune { first, last, rep } => return self.prune(field, first, last, rep),
            Step::Open { lo, hi } => (lo, hi),
        };
        let mut simplified = field.simplify(lo, hi);
        let field: &mut F = match simplified.as_mut() {
            Some(s) => {
                self.stats.fields_simplified += 1;
                s
            }
            None => field,
        };
        if size <= self.mesher.grid.block {
            self.leaf(field, origin.map(|o| o / self.mesher.grid.block));
            return;
        }
        let half = size / 2;
        for k in 0..8 {
            let child = std::array::from_fn(|a| origin[a] + corner_offset(k)[a] * half);
            self.node(field, child, half);
        }
    }

    /// What the visit does with the octree node of `size` cells at `origin`: nothing (it
    /// holds no block the visit may change), prune it (its interval proved one sign), or
    /// open it (simplify the field over `lo..hi` and evaluate or descend).
    fn step<F: Field>(&mut self, field: &mut F, origin: [u32; 3], size: u32) -> Step {
        let grid = self.mesher.grid;
        let bc = grid.block;
        let first = origin.map(|o| o / bc);
        let last = origin.map(|o| (o + size) / bc - 1);
        if (0..3).any(|a| last[a] < self.wide.lo[a] || first[a] > self.wide.hi[a]) {
            return Step::Skip;
        }
        let lo = grid.point(origin);
        let hi = grid.point(origin.map(|o| o + size));
        // A node holding a block this visit leaves as it was, crossed by the surface, holds
        // values of both signs, so no interval can prune it: its interval is not asked (over
        // a long history a large node's interval folds nearly every edit).
        if size > bc && self.holds_kept_crossing(first, last) {
            self.stats.intervals_skipped += 1;
        } else {
            let (f_lo, f_hi) = field.interval(lo, hi);
            if f_lo > 0.0 || f_hi < 0.0 {
                self.stats.nodes_pruned += 1;
                let rep = if f_lo > 0.0 { grid.rep() } else { -grid.rep() };
                return Step::Prune { first, last, rep };
            }
        }
        Step::Open { lo, hi }
    }

    /// Whether a block of `first..=last` outside the blocks this visit may change (`wide`)
    /// has crossed cells: its lattice values, which the field still gives (it is unchanged
    /// outside the dirty box), have both signs.
    fn holds_kept_crossing(&self, first: [u32; 3], last: [u32; 3]) -> bool {
        (first[0]..=last[0]).any(|x| {
            self.mesher
                .blocks
                .range([x, first[1], first[2]]..=[x, last[1], last[2]])
                .any(|(k, b)| {
                    k[2] >= first[2]
                        && k[2] <= last[2]
                        && !b.cells.is_empty()
                        && !self.wide.contains(*k)
                })
        })
    }

    /// Records a pruned node's blocks `first..=last`, then gives cells to those of its blocks
    /// that a neighbour's disagreeing values or a kept record may have left crossed.
    fn prune<F: Field>(&mut self, field: &mut F, first: [u32; 3], last: [u32; 3], rep: f32) {
        let local = self.local.keys;
        let lo: [u32; 3] = std::array::from_fn(|a| first[a].max(local.lo[a]));
        let hi: [u32; 3] = std::array::from_fn(|a| last[a].min(local.hi[a]));
        let keys = || {
            (lo[2]..=hi[2]).flat_map(move |z| {
                (lo[1]..=hi[1]).flat_map(move |y| (lo[0]..=hi[0]).map(move |x| [x, y, z]))
            })
        };
        for k in keys() {
            if self.range.contains(k) {
                self.set_rep(k, rep);
            }
        }
        for k in keys() {
            let on_lower_face = (0..3).any(|a| k[a] == first[a] && k[a] > 0);
            if on_lower_face || !self.range.contains(k) {
                self.finish(field, k, None);
            }
        }
    }

    /// Evaluates (inside `range`) or revisits (in `wide` only) the leaf block `key`.
    fn leaf<F: Field>(&mut self, field: &mut F, key: [u32; 3]) {
        if !self.range.contains(key) {
            self.finish(field, key, None);
            return;
        }
        self.stats.blocks_evaluated += 1;
        let grid = self.mesher.grid;
        let np = grid.lattice();
        let from = grid.owned_from(key);
        let origin = key.map(|k| k * grid.block);
        let n_points = (0..3).map(|a| (np - from[a]) as usize).product::<usize>();
        let (mut xs, mut ys, mut zs) = (
            Vec::with_capacity(n_points),
            Vec::with_capacity(n_points),
            Vec::with_capacity(n_points),
        );
        for z in from[2]..np {
            for y in from[1]..np {
                for x in from[0]..np {
                    let p = grid.point([origin[0] + x, origin[1] + y, origin[2] + z]);
                    xs.push(p[0]);
                    ys.push(p[1]);
                    zs.push(p[2]);
                }
            }
        }
        let mut owned = vec![0.0f32; n_points];
        field.values(&xs, &ys, &zs, &mut owned);
        let mut values = vec![0.0f32; (np * np * np) as usize];
        let mut next = owned.iter();
        for z in from[2]..np {
            for y in from[1]..np {
                for x in from[0]..np {
                    values[grid.at([x, y, z])] = next.next().copied().unwrap_or(f32::NAN);
                }
            }
        }
        self.finish(field, key, Some(values));
    }

    /// The values block `key` owns: its record's, or its representative.
    fn owned(&self, key: [u32; 3]) -> Owned<'_> {
        match self.record(key) {
            Some(b) => Owned::Values(&b.values),
            None => Owned::Rep(self.rep(key)),
        }
    }

    /// Completes block `key`'s lattice (its own values `fresh`, else those it owns already,
    /// plus its lower faces from their owners), then builds its cells or drops its record.
    fn finish<F: Field>(&mut self, field: &mut F, key: [u32; 3], fresh: Option<Vec<f32>>) {
        let grid = self.mesher.grid;
        let (bc, np) = (grid.block, grid.lattice());
        let from = grid.owned_from(key);
        let kept = fresh.is_none() && self.record(key).is_some();
        let mut values = match fresh {
            Some(v) => v,
            None => {
                let mut v = vec![0.0f32; (np * np * np) as usize];
                self.copy_owned(key, from, &mut v);
                v
            }
        };
        self.copy_lower_faces(key, from, &mut values);
        // A block outside the dirty range sees the field as before; with the same lattice
        // values its record would be built again bit for bit.
        if kept && !self.range.contains(key) && self.holds_values(key, &values) {
            self.stats.blocks_unchanged += 1;
            return;
        }
        let origin = key.map(|k| k * bc);
        let block = build_block(&grid, field, origin, values, &mut self.stats);
        if !self.range.contains(key) {
            let idx = self.mesher.block_idx(key);
            self.local.changes.push(idx as u32);
        }
        match block {
            Ok(block) => {
                self.local.blocks.insert(key, block);
            }
            // A kept record keeps its values: blocks above it read them.
            Err(values) if kept => {
                let block = Block::without_cells(origin, values);
                self.local.blocks.insert(key, block);
            }
            Err(values) => {
                self.local.blocks.remove(&key);
                let sign = if inside(values[0]) { 1.0 } else { -1.0 };
                self.set_rep(key, sign * grid.rep());
            }
        }
    }

    /// Copies into `values` the lattice points of block `key` on its lower faces, edges and
    /// corner, which the blocks below it own.
    fn copy_lower_faces(&self, key: [u32; 3], from: [u32; 3], values: &mut [f32]) {
        let grid = self.mesher.grid;
        let bc = grid.block;
        for mask in 1..8usize {
            let axes: [bool; 3] = std::array::from_fn(|a| mask >> a & 1 == 1);
            if (0..3).any(|a| axes[a] && key[a] == 0) {
                continue;
            }
            let owner: [u32; 3] = std::array::from_fn(|a| key[a] - u32::from(axes[a]));
            let lo: [u32; 3] = std::array::from_fn(|a| if axes[a] { 0 } else { from[a] });
            let shift: [u32; 3] = std::array::from_fn(|a| if axes[a] { bc } else { 0 });
            // Region: lattice index 0 along the mask's axes, the owned range along the others.
            let hi: [u32; 3] = std::array::from_fn(|a| if axes[a] { 0 } else { bc });
            let source = self.owned(owner);
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let l = [x, y, z];
                        values[grid.at(l)] = match source {
                            Owned::Values(v) => {
                                v[grid.at(std::array::from_fn(|a| l[a] + shift[a]))]
                            }
                            Owned::Rep(r) => r,
                        };
                    }
                }
            }
        }
    }

    /// Whether block `key`'s record holds exactly `values`, bit for bit.
    fn holds_values(&self, key: [u32; 3], values: &[f32]) -> bool {
        self.record(key).is_some_and(|b| {
            b.values.len() == values.len()
                && b.values
                    .iter()
                    .zip(values)
                    .all(|(a, v)| a.to_bits() == v.to_bits())
        })
    }

    /// Copies the values block `key` owns (lattice indices `from..=block`) into `out`.
    fn copy_owned(&self, key: [u32; 3], from: [u32; 3], out: &mut [f32]) {
        let grid = self.mesher.grid;
        let bc = grid.block;
        let source = self.owned(key);
        for z in from[2]..=bc {
            for y in from[1]..=bc {
                for x in from[0]..=bc {
                    let i = grid.at([x, y, z]);
                    out[i] = match source {
                        Owned::Values(v) => v[i],
                        Owned::Rep(r) => r,
                    };
                }
            }
        }
    }
}

/// A crossed cell of a block: its patches, and where the indices of its crossings start in
/// the block's list of crossing references (patch by patch, in polygon order).
struct Crossed {
    cell_local: [u32; 3],
    corner_values: [f32; 8],
    patches: [Patch; MAX_PATCHES],
    n_patches: usize,
    first_ref: usize,
}

impl Block {
    fn without_cells(origin: [u32; 3], values: Vec<f32>) -> Block {
        Block {
            origin,
            values,
            cell_entry: Vec::new(),
            cells: Vec::new(),
            cell_local: Vec::new(),
            split_cells: Vec::new(),
            centrals: Vec::new(),
            positions: Vec::new(),
            normals: Vec::new(),
        }
    }

    /// The record's entry for block-local cell `l`, if crossed.
    fn cell(&self, bc: u32, l: [u32; 3]) -> Option<&[u32; 12]> {
        let entry = *self
            .cell_entry
            .get((l[0] + bc * (l[1] + bc * l[2])) as usize)?;
        self.cells.get(entry as usize)
    }
}

/// Finds the crossed cells of a block's complete lattice and places their vertices; gives
/// the values back when no cell is crossed.
fn build_block<F: Field>(
    grid: &Grid,
    field: &mut F,
    origin: [u32; 3],
    values: Vec<f32>,
    stats: &mut MeshStats,
) -> Result<Block, Vec<f32>> {
    let bc = grid.block;
    let Scan {
        crossed_cells,
        mut brackets,
        refs,
    } = scan_cells(grid, origin, &values);
    if crossed_cells.is_empty() {
        return Err(values);
    }
    refine_crossings(field, &mut brackets);
    let placement = Placement {
        grid,
        origin,
        refs: &refs,
        hermite: hermite_data(field, &brackets),
    };
    let mut block = Block::without_cells(origin, values);
    // Per vertex, its normal when it lies on a sharp feature.
    let mut features: Vec<Option<[f32; 3]>> = Vec::new();
    block.cell_entry = vec![NONE; (bc * bc * bc) as usize];
    block.cells.reserve(crossed_cells.len());
    for c in &crossed_cells {
        let (entry, split) = placement.place(c, &mut block, &mut features, stats);
        let l = c.cell_local;
        block.cell_entry[(l[0] + bc * (l[1] + bc * l[2])) as usize] = block.cells.len() as u32;
        if split {
            block.split_cells.push(block.cells.len() as u32);
        }
        block.cells.push(entry);
        block.cell_local.push(l);
    }
    block.normals = vertex_normals(field, &block.positions, features);
    Ok(block)
}

/// The crossed cells of a block's lattice, with the brackets of their crossed edges.
struct Scan {
    crossed_cells: Vec<Crossed>,
    /// One bracket per crossed grid edge, shared by the up to four cells around it.
    brackets: Vec<Bracket>,
    /// Per crossed cell, patch by patch, the brackets of its crossings.
    refs: Vec<u32>,
}

/// Finds the crossed cells of the block at `origin` from its complete lattice `values`.
fn scan_cells(grid: &Grid, origin: [u32; 3], values: &[f32]) -> Scan {
    let bc = grid.block;
    let mut crossed_cells = Vec::new();
    let mut brackets: Vec<Bracket> = Vec::new();
    let mut bracket_of_edge = vec![NONE; 3 * values.len()];
    let mut refs: Vec<u32> = Vec::new();
    for z in 0..bc {
        for y in 0..bc {
            for x in 0..bc {
                let l = [x, y, z];
                let v: [f32; 8] = std::array::from_fn(|k| {
                    values[grid.at(std::array::from_fn(|a| l[a] + corner_offset(k)[a]))]
                });
                let n_in = v.iter().filter(|&&f| inside(f)).count();
                if n_in == 0 || n_in == 8 {
                    continue;
                }
                let (patches, n_patches) = cell_patches(&v);
                let first_ref = refs.len();
                let cell: [u32; 3] = std::array::from_fn(|a| origin[a] + l[a]);
                let corner =
                    |k: usize| grid.point(std::array::from_fn(|a| cell[a] + corner_offset(k)[a]));
                for p in &patches[..n_patches] {
                    for &e in &p.edges[..p.len as usize] {
                        let (ka, kb) = edge_corners(e as usize);
                        let edge_key = 3 * grid
                            .at(std::array::from_fn(|a| l[a] + corner_offset(ka)[a]))
                            + (e as usize) / 4;
                        if bracket_of_edge[edge_key] == NONE {
                            bracket_of_edge[edge_key] = brackets.len() as u32;
                            brackets.push(Bracket {
                                pa: corner(ka),
                                pb: corner(kb),
                                t: (0.0, 1.0),
                                f: (v[ka], v[kb]),
                            });
                        }
                        refs.push(bracket_of_edge[edge_key]);
                    }
                }
                crossed_cells.push(Crossed {
                    cell_local: l,
                    corner_values: v,
                    patches,
                    n_patches,
                    first_ref,
                });
            }
        }
    }
    Scan {
        crossed_cells,
        brackets,
        refs,
    }
}

/// The normals of a block's vertices: outward, minus the gradient, except on sharp features
/// (`features` holds theirs; their vertices may lie outside the block's box, where a
/// simplified field may differ).
fn vertex_normals<F: Field>(
    field: &mut F,
    positions: &[[f32; 3]],
    features: Vec<Option<[f32; 3]>>,
) -> Vec<[f32; 3]> {
    let smooth: Vec<[f32; 3]> = (positions.iter().zip(&features))
        .filter(|(_, feature)| feature.is_none())
        .map(|(p, _)| *p)
        .collect();
    let mut grads = vec![[0.0f32; 3]; smooth.len()];
    gradients_at(field, &smooth, &mut grads);
    let mut grads = grads.into_iter();
    features
        .into_iter()
        .map(|feature| match feature {
            Some(normal) => normal,
            None => normalise_or_up(grads.next().unwrap_or_default().map(|c| -c)),
        })
        .collect()
}

/// The Hermite data of every bracketed crossing: its point (the bracket's end nearer the
/// surface), f there (known from the narrowing) and the gradient there, in one bulk call.
fn hermite_data<F: Field>(field: &mut F, brackets: &[Bracket]) -> Vec<Hermite> {
    let crossings: Vec<([f32; 3], f32)> = brackets.iter().map(Bracket::crossing).collect();
    let xs: Vec<f32> = crossings.iter().map(|(p, _)| p[0]).collect();
    let ys: Vec<f32> = crossings.iter().map(|(p, _)| p[1]).collect();
    let zs: Vec<f32> = crossings.iter().map(|(p, _)| p[2]).collect();
    let mut grads = vec![[0.0f32; 3]; crossings.len()];
    field.gradients(&xs, &ys, &zs, &mut grads);
    crossings
        .iter()
        .zip(grads)
        .map(|(&(point, value), gradient)| Hermite {
            point,
            value,
            gradient,
        })
        .collect()
}

/// What the vertices of a block's crossed cells are placed from.
struct Placement<'a> {
    grid: &'a Grid,
    origin: [u32; 3],
    /// Per crossed cell, patch by patch, the index into `hermite` of each crossed edge.
    refs: &'a [u32],
    hermite: Vec<Hermite>,
}

impl Placement<'_> {
    /// Places the vertices of crossed cell `c` at the end of `block.positions` (one per patch,
    /// or per piece of a split patch; their feature normals to `features`), adds the central
    /// polygons of patches split in three or more, and returns the cell's entry (the
    /// block-local vertex of each crossed edge) and whether a patch was split.
    fn place(
        &self,
        c: &Crossed,
        block: &mut Block,
        features: &mut Vec<Option<[f32; 3]>>,
        stats: &mut MeshStats,
    ) -> ([u32; 12], bool) {
        let grid = self.grid;
        let cell: [u32; 3] = std::array::from_fn(|a| self.origin[a] + c.cell_local[a]);
        let bounds = [grid.point(cell), grid.point(cell.map(|i| i + 1))];
        let reach = grid.reach(bounds[0], bounds[1]);
        let mut entry = [NONE; 12];
        let mut split = false;
        let mut crossing = c.first_ref;
        let mut group = [Hermite::default(); MAX_PATCH_EDGES];
        for p in &c.patches[..c.n_patches] {
            let m = p.len as usize;
            let (groups, n_groups) = split_patch(p);
            let first_vertex = block.positions.len() as u32;
            for g in 0..n_groups as u8 {
                let mut n = 0;
                for k in (0..m).filter(|&k| groups[k] == g) {
                    group[n] = self.hermite[self.refs[crossing + k] as usize];
                    n += 1;
                }
                let data = &group[..n];
                let feature = feature(data);
                // Only an open feature's vertex may leave its cell: its normal comes from its
                // crossings, so nothing is evaluated outside the block's box, where a
                // simplified field may differ.
                let reach = match feature {
                    Some(f) if f.open => reach,
                    _ => bounds,
                };
                block
                    .positions
                    .push(solve_qef(data, bounds, reach, grid.h()));
                features.push(feature.map(|f| f.normal));
            }
            for k in 0..m {
                entry[p.edges[k] as usize] = first_vertex + u32::from(groups[k]);
            }
            if n_groups > 1 {
                split = true;
                stats.patches_split += 1;
            }
            if n_groups > 2 {
                block
                    .centrals
                    .push(central_polygon(p, c.corner_values, first_vertex, n_groups));
            }
            crossing += m;
        }
        (entry, split)
    }
}

/// The polygon joining the vertices of a patch split into one vertex per polygon corner
/// (`n_groups` > 2, group k at corner k), wound like the quads around it.
fn central_polygon(p: &Patch, v: [f32; 8], first_vertex: u32, n_groups: usize) -> Vec<u32> {
    // The gap polygon at the side between corners 0 and 1 runs from group 0 to group 1 when
    // the quad of corner 0 runs into the neighbour across that side; the central polygon
    // must then run the other way.
    let e = p.edges[0] as usize;
    let low_inside = inside(v[edge_corners(e).0]);
    let forward = !quad_runs_to(e, p.side_faces[0] as usize, low_inside);
    let mut polygon: Vec<u32> = (0..n_groups as u32).map(|g| first_vertex + g).collect();
    if !forward {
        polygon.reverse();
    }
    polygon
}

/// Writes the gradients of `field` at `points` to `out`, in one bulk call.
fn gradients_at<F: Field>(field: &mut F, points: &[[f32; 3]], out: &mut [[f32; 3]]) {
    let xs: Vec<f32> = points.iter().map(|p| p[0]).collect();
    let ys: Vec<f32> = points.iter().map(|p| p[1]).collect();
    let zs: Vec<f32> = points.iter().map(|p| p[2]).collect();
    field.gradients(&xs, &ys, &zs, out);
}

impl OctreeMesher {
    /// The global index of the vertex that cell `cell` has on its edge `e`, if any.
    fn cell_vertex(&self, assembly: &Assembly<'_>, cell: [u32; 3], e: usize) -> Option<u32> {
        let bc = self.grid.block;
        let key = cell.map(|c| c / bc);
        let idx = self.block_idx(key);
        let record = match &assembly.records {
            Records::Dense(records) => records.get(idx).copied().flatten(),
            Records::Sparse(blocks) => blocks.get(&key),
        };
        let v = record?.cell(bc, cell.map(|c| c % bc))?[e];
        (v != NONE).then(|| assembly.offsets[idx] + v)
    }

    /// Emits two triangles for every crossed grid edge that `block` owns.
    fn emit_quads(
        &self,
        block: &Block,
        offset: u32,
        assembly: &Assembly<'_>,
        positions: &[[f32; 3]],
        out: &mut Vec<u32>,
    ) {
        let grid = &self.grid;
        let bc = grid.block;
        let n = grid.n_cells;
        // A crossed grid edge starting at lattice point l of the block is an edge of the cell
        // at l, which is then crossed: visiting the crossed cells (in the order the block
        // found them, z then y then x) visits every quad the block owns.
        for &l in &block.cell_local {
            let p: [u32; 3] = std::array::from_fn(|a| block.origin[a] + l[a]);
            let f0 = block.values[grid.at(l)];
            for d in 0..3 {
                let (a1, a2) = ((d + 1) % 3, (d + 2) % 3);
                if p[a1] == 0 || p[a2] == 0 || p[a1] >= n || p[a2] >= n {
                    continue;
                }
                let mut l1 = l;
                l1[d] += 1;
                if inside(f0) == inside(block.values[grid.at(l1)]) {
                    continue;
                }
                // The four cells around the edge, wound so the normal points out.
                let quad = quad_cells(inside(f0)).map(|(o1, o2)| {
                    let mut low = [0u32; 3];
                    low[a1] = o1;
                    low[a2] = o2;
                    let e = edge_index(d, low);
                    if l[a1] >= o1 && l[a2] >= o2 {
                        // The cell lies in this block: no map lookup.
                        let mut lc = l;
                        lc[a1] -= o1;
                        lc[a2] -= o2;
                        let v = block.cell(bc, lc)?[e];
                        return (v != NONE).then_some(offset + v);
                    }
                    let mut cell = p;
                    cell[a1] -= o1;
                    cell[a2] -= o2;
                    self.cell_vertex(assembly, cell, e)
                });
                let [Some(q0), Some(q1), Some(q2), Some(q3)] = quad else {
                    continue;
                };
                out.extend(split_quad(positions, [q0, q1, q2, q3]));
            }
        }
    }

    /// Emits the gap polygons across the faces of `block`'s split cells: where the cells on
    /// the two sides of a face segment give its two ends different vertices.
    fn emit_gaps(
        &self,
        block: &Block,
        offset: u32,
        assembly: &Assembly<'_>,
        positions: &[[f32; 3]],
        out: &mut Vec<u32>,
    ) {
        let grid = &self.grid;
        for &ci in &block.split_cells {
            let (entry, l) = (block.cells[ci as usize], block.cell_local[ci as usize]);
            let v: [f32; 8] = std::array::from_fn(|k| {
                block.values[grid.at(std::array::from_fn(|a| l[a] + corner_offset(k)[a]))]
            });
            let cell: [u32; 3] = std::array::from_fn(|a| block.origin[a] + l[a]);
            for face in 0..N_FACES {
                let (f, upper) = (face / 2, face % 2 == 1);
                let across = if upper {
                    cell[f].checked_add(1).filter(|&c| c < grid.n_cells)
                } else {
                    cell[f].checked_sub(1)
                };
                let Some(across) = across else {
                    continue;
                };
                let mut other = cell;
                other[f] = across;
                let (segments, n) = face_segments(&v, face);
                for &[ea, eb] in &segments[..n] {
                    if entry[ea] == entry[eb] {
                        continue;
                    }
                    let (Some(bl), Some(br)) = (
                        self.cell_vertex(assembly, other, edge_across(ea, face)),
                        self.cell_vertex(assembly, other, edge_across(eb, face)),
                    ) else {
                        continue;
                    };
                    // Across a lower face, a cell split there too emits the polygon.
                    if !upper && bl != br {
                        continue;
                    }
                    let (al, ar) = (offset + entry[ea], offset + entry[eb]);
                    let low_inside = inside(v[edge_corners(ea).0]);
                    let cycle = if quad_runs_to(ea, face, low_inside) {
                        [bl, al, ar, br]
                    } else {
                        [al, bl, br, ar]
                    };
                    emit_polygon(positions, cycle, out);
                }
            }
        }
    }
}

/// Per block index, the first global vertex of its record, and the records, while a mesh is
/// assembled.
struct Assembly<'a> {
    offsets: &'a [u32],
    records: Records<'a>,
}

/// The records an assembly reads vertices of neighbouring blocks from.
enum Records<'a> {
    /// By block index (`None` without a record): a whole mesh reads every block.
    Dense(Vec<Option<&'a Block>>),
    /// The mesher's map: a patch reads a few blocks.
    Sparse(&'a BTreeMap<[u32; 3], Block>),
}

/// Where a whole assembly put one block's vertices and triangles.
struct Placed {
    block_idx: usize,
    first_vertex: u32,
    n_vertices: usize,
    triangles: std::ops::Range<usize>,
}

/// Emits a quad whose consecutive corners may coincide: a quad, a triangle or nothing.
fn emit_polygon(positions: &[[f32; 3]], q: [u32; 4], indices: &mut Vec<u32>) {
    let mut distinct = [0u32; 4];
    let mut n = 0;
    for k in 0..4 {
        if q[k] != q[(k + 1) % 4] {
            distinct[n] = q[k];
            n += 1;
        }
    }
    match n {
        4 => indices.extend(split_quad(positions, q)),
        3 => indices.extend(&distinct[..3]),
        _ => {}
    }
}

/// Splits a quad along its shorter diagonal.
fn split_quad(positions: &[[f32; 3]], q: [u32; 4]) -> [u32; 6] {
    let p = |i: u32| positions[i as usize];
    let d2 = |a: [f32; 3], b: [f32; 3]| (0..3).map(|k| (a[k] - b[k]) * (a[k] - b[k])).sum::<f32>();
    if d2(p(q[0]), p(q[2])) <= d2(p(q[1]), p(q[3])) {
        [q[0], q[1], q[2], q[0], q[2], q[3]]
    } else {
        [q[0], q[1], q[3], q[1], q[2], q[3]]
    }
}

#[cfg(test)]
mod tests;
