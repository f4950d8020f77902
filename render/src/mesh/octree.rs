//! Dual contouring of an implicit solid over an adaptive octree with interval pruning.
//!
//! The box to mesh is split recursively; interval arithmetic discards every octree node the
//! surface cannot cross, and [`Field::simplify`] may hand a cheaper field to each subtree.
//! Surviving leaves are blocks of [`BLOCK_CELLS`]^3 cells whose grid values are evaluated in
//! one bulk call. Each cell crossed by the surface gets one vertex per surface patch (so
//! ambiguous cells stay manifold, as in dual marching cubes), placed by minimising a quadric
//! error function of the edge crossings and their normals: sharp edges and corners are kept.
//! Each sign-changing grid edge emits a quad joining the vertices of its four cells.
//!
//! Guarantees: when the surface lies strictly inside the box, the mesh is watertight, its
//! triangles wind counter-clockwise seen from outside, and each vertex lies in its cell.
//! Non-guarantees: triangles may self-intersect near sharp features thinner than a cell;
//! features smaller than a cell may be missed; cells are not collapsed where the surface is
//! flat (the resolution near the surface is uniform). Where the surface leaves the box the
//! mesh is open along the box, which is what stitching a remeshed region needs.

use super::field::Field;
use super::{Aabb, MESH_VERTICES_MAX, Mesh, normalise_or_up};
use std::collections::BTreeMap;

/// Deepest octree allowed: 2^10 = 1024 cells along each axis.
pub const OCTREE_DEPTH_MAX: u8 = 10;
/// Cells along each axis of a leaf block evaluated in one bulk call.
pub const BLOCK_CELLS: u32 = 8;
/// Tikhonov weight pulling a vertex towards its crossings' mean, in cell units.
const QEF_REGULARISATION: f32 = 0.01;
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
    /// The depth exceeds [`OCTREE_DEPTH_MAX`].
    #[error("octree depth {0} exceeds the maximum {OCTREE_DEPTH_MAX}")]
    DepthTooLarge(u8),
    /// The box has no volume, or non-finite corners.
    #[error("bounds {0:?} are empty or not finite")]
    BadBounds(Aabb),
    /// The surface needs more vertices than a mesh can index.
    #[error("mesh would exceed {MESH_VERTICES_MAX} vertices")]
    TooManyVertices,
}

/// Counters that show how much work pruning saved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshStats {
    /// Octree nodes (of any size) discarded by interval arithmetic.
    pub nodes_pruned: usize,
    /// Leaf blocks whose grid was evaluated.
    pub blocks_evaluated: usize,
    /// Number of times [`Field::simplify`] returned a simplified field.
    pub fields_simplified: usize,
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

/// A mesher that keeps its evaluated blocks, so that only an edit's box is meshed again.
///
/// [`OctreeMesher::remesh`] drops every block whose closed box meets the dirty box and
/// evaluates those again; all other blocks are kept. A block's vertices depend only on its
/// own grid values, and quads are emitted from kept and new blocks alike, so the remeshed
/// region stitches with its surroundings exactly: the result equals meshing the edited
/// field from scratch.
pub struct OctreeMesher {
    grid: Grid,
    /// Evaluated blocks that the surface crosses, by block coordinates.
    blocks: BTreeMap<[u32; 3], Block>,
}

impl OctreeMesher {
    /// An empty mesher for `settings`; call [`OctreeMesher::remesh`] with the whole bounds.
    pub fn new(settings: &MeshSettings) -> Result<Self, OctreeMeshError> {
        if settings.depth > OCTREE_DEPTH_MAX {
            return Err(OctreeMeshError::DepthTooLarge(settings.depth));
        }
        let b = settings.bounds;
        let sane = (0..3).all(|a| b.lo[a].is_finite() && b.hi[a].is_finite() && b.lo[a] < b.hi[a]);
        if !sane {
            return Err(OctreeMeshError::BadBounds(b));
        }
        let n_cells = 1u32 << settings.depth;
        let grid = Grid {
            lo: b.lo,
            step: std::array::from_fn(|a| (b.hi[a] - b.lo[a]) / n_cells as f32),
            n_cells,
            block: BLOCK_CELLS.min(n_cells),
        };
        Ok(Self {
            grid,
            blocks: BTreeMap::new(),
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
        let mut stats = MeshStats::default();
        let Some(range) = self.grid.blocks_touching(dirty) else {
            return Ok(stats);
        };
        self.blocks.retain(|k, _| !range.contains(*k));
        let mut visit = Visit {
            grid: self.grid,
            range,
            blocks: &mut self.blocks,
            stats: &mut stats,
        };
        visit.node(field, [0; 3], self.grid.n_cells)?;
        Ok(stats)
    }

    /// Number of kept blocks, all of which the surface crosses.
    pub fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// Assembles the mesh of all kept blocks.
    pub fn mesh(&self) -> Result<Mesh, OctreeMeshError> {
        let mut offsets = BTreeMap::new();
        let mut mesh = Mesh::default();
        for (key, block) in &self.blocks {
            let offset = u32::try_from(mesh.positions.len())
                .map_err(|_| OctreeMeshError::TooManyVertices)?;
            offsets.insert(*key, offset);
            mesh.positions.extend_from_slice(&block.positions);
            mesh.normals.extend_from_slice(&block.normals);
        }
        if mesh.positions.len() >= NONE as usize {
            return Err(OctreeMeshError::TooManyVertices);
        }
        mesh.colours = vec![[1.0; 4]; mesh.positions.len()];
        for block in self.blocks.values() {
            self.emit_quads(block, &offsets, &mut mesh);
        }
        Ok(mesh)
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
    fn point(&self, i: [u32; 3]) -> [f32; 3] {
        std::array::from_fn(|a| self.lo[a] + i[a] as f32 * self.step[a])
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

/// One evaluated leaf block that the surface crosses.
struct Block {
    origin: [u32; 3],
    /// (block + 1)^3 grid values, x fastest.
    values: Vec<f32>,
    /// Per cell (x fastest), an index into `cells` or `NONE`.
    cell_entry: Vec<u32>,
    /// Per crossed cell, the block-local vertex of each of its 12 edges (`NONE` if uncrossed).
    cells: Vec<[u32; 12]>,
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
}

/// One octree traversal restricted to the blocks of `range`.
struct Visit<'a> {
    grid: Grid,
    range: BlockRange,
    blocks: &'a mut BTreeMap<[u32; 3], Block>,
    stats: &'a mut MeshStats,
}

/// Corner `k` of a cell has offset bit a of k along axis a.
fn corner_offset(k: usize) -> [u32; 3] {
    [(k & 1) as u32, ((k >> 1) & 1) as u32, ((k >> 2) & 1) as u32]
}

/// Cell edge along axis `d` whose low end has the offset `low` within the cell.
fn edge_index(d: usize, low: [u32; 3]) -> usize {
    d * 4 + low[(d + 1) % 3] as usize + 2 * low[(d + 2) % 3] as usize
}

/// The two corners (low, high) of cell edge `e`.
fn edge_corners(e: usize) -> (usize, usize) {
    let d = e / 4;
    let mut low = [0u32; 3];
    low[(d + 1) % 3] = (e & 1) as u32;
    low[(d + 2) % 3] = ((e >> 1) & 1) as u32;
    let k = (low[0] + 2 * low[1] + 4 * low[2]) as usize;
    (k, k | (1 << d))
}

fn inside(v: f32) -> bool {
    v >= 0.0
}

/// Groups the crossed edges of a cell into surface patches: returns a patch id per edge.
fn cell_patches(v: &[f32; 8]) -> ([u8; 12], u8) {
    let mut parent: [u8; 12] = std::array::from_fn(|i| i as u8);
    fn find(parent: &mut [u8; 12], mut i: u8) -> u8 {
        while parent[i as usize] != i {
            i = parent[i as usize];
        }
        i
    }
    let crossed: [bool; 12] = std::array::from_fn(|e| {
        let (a, b) = edge_corners(e);
        inside(v[a]) != inside(v[b])
    });
    for f in 0..3 {
        for s in 0..2u32 {
            let (ua, va) = ((f + 1) % 3, (f + 2) % 3);
            // Face corners in cyclic order q00, q10, q11, q01, as cell-relative offsets.
            let q: [[u32; 3]; 4] = [[0, 0], [1, 0], [1, 1], [0, 1]].map(|[u, w]| {
                let mut o = [0u32; 3];
                o[f] = s;
                o[ua] = u;
                o[va] = w;
                o
            });
            let val = q.map(|o| v[(o[0] + 2 * o[1] + 4 * o[2]) as usize]);
            // Edge i joins corner i and corner i+1.
            let edges: [usize; 4] = std::array::from_fn(|i| {
                let (p, r) = (q[i], q[(i + 1) % 4]);
                let d = if p[ua] != r[ua] { ua } else { va };
                let low: [u32; 3] = std::array::from_fn(|a| p[a].min(r[a]));
                edge_index(d, low)
            });
            let on: Vec<usize> = edges.iter().copied().filter(|&e| crossed[e]).collect();
            let pairs: Vec<(usize, usize)> = match on.len() {
                2 => vec![(on[0], on[1])],
                4 => {
                    let denom = val[0] + val[2] - val[1] - val[3];
                    let saddle = if denom != 0.0 {
                        (val[0] * val[2] - val[1] * val[3]) / denom
                    } else {
                        val[0]
                    };
                    let inside_connected = inside(saddle);
                    // Cut off corners 0 and 2, or corners 1 and 3.
                    let cut_even = inside(val[0]) != inside_connected;
                    if cut_even {
                        vec![(edges[3], edges[0]), (edges[1], edges[2])]
                    } else {
                        vec![(edges[0], edges[1]), (edges[2], edges[3])]
                    }
                }
                _ => Vec::new(),
            };
            for (a, b) in pairs {
                let (ra, rb) = (find(&mut parent, a as u8), find(&mut parent, b as u8));
                parent[ra as usize] = rb;
            }
        }
    }
    let mut patch = [u8::MAX; 12];
    let mut root_patch = [u8::MAX; 12];
    let mut n_patches = 0u8;
    for e in 0..12 {
        if crossed[e] {
            let r = find(&mut parent, e as u8) as usize;
            if root_patch[r] == u8::MAX {
                root_patch[r] = n_patches;
                n_patches += 1;
            }
            patch[e] = root_patch[r];
        }
    }
    (patch, n_patches)
}

/// Bisection steps that locate each edge crossing before the final linear interpolation.
///
/// Linear interpolation alone misplaces crossings where f has a kink along the edge (near
/// CSG edges), which would round off sharp features; 6 steps bound the error by 1/64 cell.
const CROSSING_BISECTIONS: usize = 6;

/// A sign change of f on the segment `pa..pb`, bracketed in `t.0..t.1` with values `f`.
struct Bracket {
    pa: [f32; 3],
    pb: [f32; 3],
    t: (f32, f32),
    f: (f32, f32),
}

impl Bracket {
    fn at(&self, t: f32) -> [f32; 3] {
        std::array::from_fn(|a| self.pa[a] + t * (self.pb[a] - self.pa[a]))
    }

    /// The crossing by linear interpolation inside the bracket.
    fn crossing(&self) -> [f32; 3] {
        let s = self.f.0 / (self.f.0 - self.f.1);
        let s = if s.is_finite() {
            s.clamp(0.0, 1.0)
        } else {
            0.5
        };
        self.at(self.t.0 + s * (self.t.1 - self.t.0))
    }
}

/// Narrows every bracket by bisection, evaluating all midpoints of a round in one bulk call.
fn refine_crossings<F: Field>(field: &mut F, brackets: &mut [Bracket]) {
    let n = brackets.len();
    let (mut xs, mut ys, mut zs) = (vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]);
    let mut out = vec![0.0f32; n];
    for _ in 0..CROSSING_BISECTIONS {
        for (i, b) in brackets.iter().enumerate() {
            let p = b.at(0.5 * (b.t.0 + b.t.1));
            (xs[i], ys[i], zs[i]) = (p[0], p[1], p[2]);
        }
        field.values(&xs, &ys, &zs, &mut out);
        for (b, &fm) in brackets.iter_mut().zip(&out) {
            let tm = 0.5 * (b.t.0 + b.t.1);
            if inside(fm) == inside(b.f.0) {
                (b.t.0, b.f.0) = (tm, fm);
            } else {
                (b.t.1, b.f.1) = (tm, fm);
            }
        }
    }
}

/// Minimises the sum of squared distances to the planes (p_i, n_i), regularised towards the
/// mean of the p_i, and clamps the result into the cell `lo..=hi`.
fn solve_qef(
    points: &[[f32; 3]],
    normals: &[[f32; 3]],
    lo: [f32; 3],
    hi: [f32; 3],
    h: f32,
) -> [f32; 3] {
    let n_points = points.len().max(1) as f32;
    let c: [f32; 3] = std::array::from_fn(|a| points.iter().map(|p| p[a]).sum::<f32>() / n_points);
    let mut ata = [[0.0f32; 3]; 3];
    let mut atb = [0.0f32; 3];
    for (p, g) in points.iter().zip(normals) {
        let len = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
        if !(len > f32::MIN_POSITIVE && len.is_finite()) {
            continue;
        }
        let n = g.map(|x| x / len);
        let b = (0..3).map(|a| n[a] * (p[a] - c[a])).sum::<f32>() / h;
        for r in 0..3 {
            for k in 0..3 {
                ata[r][k] += n[r] * n[k];
            }
            atb[r] += n[r] * b;
        }
    }
    for (r, row) in ata.iter_mut().enumerate() {
        row[r] += QEF_REGULARISATION;
    }
    let y = solve3(ata, atb).unwrap_or([0.0; 3]);
    std::array::from_fn(|a| (c[a] + h * y[a]).clamp(lo[a], hi[a]))
}

/// Solves the 3x3 system m x = b by Cramer's rule.
fn solve3(m: [[f32; 3]; 3], b: [f32; 3]) -> Option<[f32; 3]> {
    let det = |m: [[f32; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    if !(d.abs() > f32::MIN_POSITIVE && d.is_finite()) {
        return None;
    }
    let x: [f32; 3] = std::array::from_fn(|col| {
        let mut mc = m;
        for (r, row) in mc.iter_mut().enumerate() {
            row[col] = b[r];
        }
        det(mc) / d
    });
    x.iter().all(|v| v.is_finite()).then_some(x)
}

impl Visit<'_> {
    /// Visits the octree node of `size` cells at `origin`, pruning or evaluating it.
    fn node<F: Field>(
        &mut self,
        field: &mut F,
        origin: [u32; 3],
        size: u32,
    ) -> Result<(), OctreeMeshError> {
        let bc = self.grid.block;
        let first = origin.map(|o| o / bc);
        let last = origin.map(|o| (o + size) / bc - 1);
        if (0..3).any(|a| last[a] < self.range.lo[a] || first[a] > self.range.hi[a]) {
            return Ok(());
        }
        let lo = self.grid.point(origin);
        let hi = self.grid.point(origin.map(|o| o + size));
        let (f_lo, f_hi) = field.interval(lo, hi);
        if f_lo > 0.0 || f_hi < 0.0 {
            self.stats.nodes_pruned += 1;
            return Ok(());
        }
        let mut simplified = field.simplify(lo, hi);
        let field: &mut F = match simplified.as_mut() {
            Some(s) => {
                self.stats.fields_simplified += 1;
                s
            }
            None => field,
        };
        if size <= bc {
            self.stats.blocks_evaluated += 1;
            if let Some(block) = evaluate_block(&self.grid, field, origin) {
                self.blocks.insert(first, block);
            }
            return Ok(());
        }
        let half = size / 2;
        for k in 0..8 {
            let child = std::array::from_fn(|a| origin[a] + corner_offset(k)[a] * half);
            self.node(field, child, half)?;
        }
        Ok(())
    }
}

/// A crossed cell of a block and where its crossings start in the block's crossing list.
struct Crossed {
    cell_local: [u32; 3],
    patch: [u8; 12],
    n_patches: u8,
    first_crossing: usize,
}

/// Evaluates a leaf block's grid and places the vertices of its crossed cells; `None` when
/// the surface does not cross it.
fn evaluate_block<F: Field>(grid: &Grid, field: &mut F, origin: [u32; 3]) -> Option<Block> {
    let bc = grid.block;
    let np = bc + 1;
    let n_points = (np * np * np) as usize;
    let (mut xs, mut ys, mut zs) = (
        Vec::with_capacity(n_points),
        Vec::with_capacity(n_points),
        Vec::with_capacity(n_points),
    );
    for z in 0..np {
        for y in 0..np {
            for x in 0..np {
                let p = grid.point([origin[0] + x, origin[1] + y, origin[2] + z]);
                xs.push(p[0]);
                ys.push(p[1]);
                zs.push(p[2]);
            }
        }
    }
    let mut values = vec![0.0f32; n_points];
    field.values(&xs, &ys, &zs, &mut values);
    let at = |l: [u32; 3]| (l[0] + np * (l[1] + np * l[2])) as usize;

    // Crossings of every crossed cell edge, refined and given gradients in bulk.
    let mut crossed_cells = Vec::new();
    let mut brackets: Vec<Bracket> = Vec::new();
    for z in 0..bc {
        for y in 0..bc {
            for x in 0..bc {
                let l = [x, y, z];
                let v: [f32; 8] = std::array::from_fn(|k| {
                    values[at(std::array::from_fn(|a| l[a] + corner_offset(k)[a]))]
                });
                let n_in = v.iter().filter(|&&f| inside(f)).count();
                if n_in == 0 || n_in == 8 {
                    continue;
                }
                let (patch, n_patches) = cell_patches(&v);
                let first_crossing = brackets.len();
                let cell: [u32; 3] = std::array::from_fn(|a| origin[a] + l[a]);
                for (e, _) in patch.iter().enumerate().filter(|(_, p)| **p != u8::MAX) {
                    let (ka, kb) = edge_corners(e);
                    let corner = |k: usize| {
                        grid.point(std::array::from_fn(|a| cell[a] + corner_offset(k)[a]))
                    };
                    let (pa, pb) = (corner(ka), corner(kb));
                    brackets.push(Bracket {
                        pa,
                        pb,
                        t: (0.0, 1.0),
                        f: (v[ka], v[kb]),
                    });
                }
                crossed_cells.push(Crossed {
                    cell_local: l,
                    patch,
                    n_patches,
                    first_crossing,
                });
            }
        }
    }
    if crossed_cells.is_empty() {
        return None;
    }
    refine_crossings(field, &mut brackets);
    let crossings: Vec<[f32; 3]> = brackets.iter().map(Bracket::crossing).collect();
    let grads = gradients_at(field, &crossings);

    let h = (grid.step[0] + grid.step[1] + grid.step[2]) / 3.0;
    let mut cell_entry = vec![NONE; (bc * bc * bc) as usize];
    let mut cells = Vec::with_capacity(crossed_cells.len());
    let mut positions = Vec::new();
    for c in &crossed_cells {
        let cell: [u32; 3] = std::array::from_fn(|a| origin[a] + c.cell_local[a]);
        let (lo, hi) = (grid.point(cell), grid.point(cell.map(|i| i + 1)));
        let mut entry = [NONE; 12];
        // Crossings are stored in edge order for the crossed edges only.
        let crossing_of: Vec<(u8, usize)> = c
            .patch
            .iter()
            .filter(|&&p| p != u8::MAX)
            .enumerate()
            .map(|(i, &p)| (p, c.first_crossing + i))
            .collect();
        for patch in 0..c.n_patches {
            let mine = crossing_of.iter().filter(|(p, _)| *p == patch);
            let pts: Vec<[f32; 3]> = mine.clone().map(|&(_, i)| crossings[i]).collect();
            let nrm: Vec<[f32; 3]> = mine.map(|&(_, i)| grads[i]).collect();
            let vertex = positions.len() as u32;
            positions.push(solve_qef(&pts, &nrm, lo, hi, h));
            for (slot, _) in entry.iter_mut().zip(c.patch).filter(|(_, p)| *p == patch) {
                *slot = vertex;
            }
        }
        let l = c.cell_local;
        cell_entry[(l[0] + bc * (l[1] + bc * l[2])) as usize] = cells.len() as u32;
        cells.push(entry);
    }
    // Outward normals are minus the gradient.
    let normals = gradients_at(field, &positions)
        .into_iter()
        .map(|g| normalise_or_up(g.map(|c| -c)))
        .collect();
    Some(Block {
        origin,
        values,
        cell_entry,
        cells,
        positions,
        normals,
    })
}

/// The gradients of `field` at `points`, in one bulk call.
fn gradients_at<F: Field>(field: &mut F, points: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let xs: Vec<f32> = points.iter().map(|p| p[0]).collect();
    let ys: Vec<f32> = points.iter().map(|p| p[1]).collect();
    let zs: Vec<f32> = points.iter().map(|p| p[2]).collect();
    let mut g = vec![[0.0f32; 3]; points.len()];
    field.gradients(&xs, &ys, &zs, &mut g);
    g
}

impl OctreeMesher {
    /// The global index of the vertex that cell `cell` has on its edge `e`, if any.
    fn cell_vertex(
        &self,
        offsets: &BTreeMap<[u32; 3], u32>,
        cell: [u32; 3],
        e: usize,
    ) -> Option<u32> {
        let bc = self.grid.block;
        let key = cell.map(|c| c / bc);
        let block = self.blocks.get(&key)?;
        let l = cell.map(|c| c % bc);
        let entry = block.cell_entry[(l[0] + bc * (l[1] + bc * l[2])) as usize];
        let v = block.cells.get(entry as usize)?[e];
        (v != NONE)
            .then(|| offsets.get(&key).map(|o| o + v))
            .flatten()
    }

    /// Emits two triangles for every crossed grid edge that `block` owns.
    fn emit_quads(&self, block: &Block, offsets: &BTreeMap<[u32; 3], u32>, mesh: &mut Mesh) {
        let bc = self.grid.block;
        let n = self.grid.n_cells;
        let np = bc + 1;
        let at = |l: [u32; 3]| (l[0] + np * (l[1] + np * l[2])) as usize;
        for z in 0..bc {
            for y in 0..bc {
                for x in 0..bc {
                    let l = [x, y, z];
                    let p: [u32; 3] = std::array::from_fn(|a| block.origin[a] + l[a]);
                    let f0 = block.values[at(l)];
                    for d in 0..3 {
                        let (a1, a2) = ((d + 1) % 3, (d + 2) % 3);
                        if p[a1] == 0 || p[a2] == 0 || p[a1] >= n || p[a2] >= n {
                            continue;
                        }
                        let mut l1 = l;
                        l1[d] += 1;
                        if inside(f0) == inside(block.values[at(l1)]) {
                            continue;
                        }
                        // The four cells around the edge, counter-clockwise about +d.
                        let quad = [(1, 1), (0, 1), (0, 0), (1, 0)].map(|(o1, o2)| {
                            let mut cell = p;
                            cell[a1] -= o1;
                            cell[a2] -= o2;
                            let mut low = [0u32; 3];
                            low[a1] = o1;
                            low[a2] = o2;
                            self.cell_vertex(offsets, cell, edge_index(d, low))
                        });
                        let [Some(q0), Some(q1), Some(q2), Some(q3)] = quad else {
                            continue;
                        };
                        // Inside at the low end means the outward normal is +d.
                        let q = if inside(f0) {
                            [q0, q1, q2, q3]
                        } else {
                            [q3, q2, q1, q0]
                        };
                        mesh.indices.extend(split_quad(&mesh.positions, q));
                    }
                }
            }
        }
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
