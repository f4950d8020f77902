//! Patching an assembled mesh after a remesh: only the changed blocks' vertices, and the
//! triangles of the changed blocks and of the neighbours whose triangles read them, are
//! written again.
//!
//! Layout of a patched mesh: each block's vertices sit in one range of the vertex arrays.
//! A block whose new vertices fit in its range is rewritten in place; one that grew moves to
//! the end with some spare room, and its old range stays behind unreferenced. Triangles may lie
//! in any order: a table names, per triangle, the block that owns it and its position in that
//! block's list, so that a block's surplus triangles are removed by moving the last triangle
//! into each hole (the index buffer always holds exactly the live triangles). When the
//! unreferenced vertices outnumber half the referenced ones, the whole mesh is assembled again.
//!
//! Which triangles depend on which blocks: block B owns the quads of the grid edges it owns,
//! whose four cells lie in B and in the blocks just below it across two axes (B - e_a,
//! B - e_b, B - e_a - e_b), the gap polygons across its split cells' faces, whose other side
//! lies in B + e_a or B - e_a, and its central polygons. So when block X changes, the blocks
//! X, X + e_a, X - e_a and X + e_a + e_b (a != b) emit their triangles again: ten blocks.

use super::{Assembly, NONE, OctreeMeshError, OctreeMesher, Placed, Records};
use crate::mesh::Mesh;
use std::ops::Range;

/// What [`OctreeMesher::mesh_update`] changed in the mesh: what a renderer must upload again.
///
/// Ranges are sorted, disjoint and not adjacent. After the patch the mesh has `n_vertices`
/// vertices and `n_triangles` triangles: buffers that were longer are cut, and everything
/// beyond the old lengths lies in the ranges.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MeshPatch {
    /// The whole mesh was assembled again (the ranges then cover everything).
    pub full: bool,
    /// Vertices (positions, normals and colours) written.
    pub vertex_ranges: Vec<Range<usize>>,
    /// Triangles written (indices `3 * start .. 3 * end`).
    pub triangle_ranges: Vec<Range<usize>>,
    /// Vertices in the mesh after the patch, unreferenced ones included.
    pub n_vertices: usize,
    /// Triangles in the mesh after the patch.
    pub n_triangles: usize,
    /// Blocks with vertices before or after whose records changed.
    pub blocks_changed: usize,
    /// Blocks whose triangles were emitted again (the changed ones and their neighbours).
    pub blocks_reemitted: usize,
}

impl MeshPatch {
    /// Number of vertices written.
    pub fn n_vertices_written(&self) -> usize {
        self.vertex_ranges.iter().map(ExactSizeIterator::len).sum()
    }

    /// Number of triangles written.
    pub fn n_triangles_written(&self) -> usize {
        self.triangle_ranges
            .iter()
            .map(ExactSizeIterator::len)
            .sum()
    }
}

/// Which blocks a patch emits the triangles of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reemit {
    /// The changed blocks and every block whose triangles read their vertices.
    Dependents,
    /// The changed blocks alone: wrong (seams to unchanged neighbours keep stale triangles);
    /// tests use it to show that their comparison catches a patch that forgets seams.
    #[cfg(test)]
    ChangedOnly,
}

/// Block offsets whose triangles read a block's vertices (see the module comment).
const DEPENDENTS: [[i32; 3]; 10] = [
    [0, 0, 0],
    [1, 0, 0],
    [-1, 0, 0],
    [0, 1, 0],
    [0, -1, 0],
    [0, 0, 1],
    [0, 0, -1],
    [1, 1, 0],
    [1, 0, 1],
    [0, 1, 1],
];

/// Where each block's vertices and triangles lie in the mesh last handed out.
pub(super) struct Assembled {
    /// Per block index, its first vertex (`NONE` if it never had vertices).
    offsets: Vec<u32>,
    table: Table,
    /// Vertices in use by some block (the others are unreferenced).
    n_vertices_live: usize,
    /// The mesh's vertex count last handed out, to notice a mesh that is not this one's.
    n_vertices: usize,
}

/// Each block's share of the mesh, and each triangle's owner.
struct Table {
    /// Per block index, its slot, or `NONE`.
    slot_of_block: Vec<u32>,
    slots: Vec<Slot>,
    /// Per triangle, its slot and its position in that slot's list.
    owners: Vec<[u32; 2]>,
}

/// One block's share of the mesh.
struct Slot {
    /// Its vertices in use, from its offset.
    n_vertices: u32,
    /// Vertices its range holds, used or not.
    capacity: u32,
    /// Its triangles.
    triangles: Vec<u32>,
}

impl Assembled {
    fn new(n_blocks_total: usize) -> Self {
        Assembled {
            offsets: vec![NONE; n_blocks_total],
            table: Table {
                slot_of_block: vec![NONE; n_blocks_total],
                slots: Vec::new(),
                owners: Vec::new(),
            },
            n_vertices_live: 0,
            n_vertices: 0,
        }
    }

    /// Whether `mesh` is the one this layout describes, as far as lengths tell.
    fn matches(&self, mesh: &Mesh) -> bool {
        let n = self.n_vertices;
        mesh.positions.len() == n
            && mesh.normals.len() == n
            && mesh.colours.len() == n
            && mesh.ambient.is_empty()
            && mesh.indices.len() == 3 * self.table.owners.len()
    }

    /// Records one block of a whole assembly.
    fn place_whole(&mut self, placed: Placed) {
        self.offsets[placed.block_idx] = placed.first_vertex;
        if placed.n_vertices == 0 && placed.triangles.is_empty() {
            return;
        }
        let table = &mut self.table;
        assert_eq!(
            table.owners.len(),
            placed.triangles.start,
            "blocks are placed in triangle order"
        );
        let s = table.slot(placed.block_idx);
        let slot = &mut table.slots[s];
        slot.n_vertices = placed.n_vertices as u32;
        slot.capacity = placed.n_vertices as u32;
        slot.triangles = placed.triangles.clone().map(|t| t as u32).collect();
        table
            .owners
            .extend((0..placed.triangles.len()).map(|p| [s as u32, p as u32]));
        self.n_vertices_live += placed.n_vertices;
    }
}

impl Table {
    /// The slot of block `idx`, made empty if it has none.
    fn slot(&mut self, idx: usize) -> usize {
        if self.slot_of_block[idx] == NONE {
            self.slot_of_block[idx] = self.slots.len() as u32;
            self.slots.push(Slot {
                n_vertices: 0,
                capacity: 0,
                triangles: Vec::new(),
            });
        }
        self.slot_of_block[idx] as usize
    }

    /// Replaces block `idx`'s triangles with `new` (three indices each), noting the triangles
    /// written in `written`.
    fn replace_triangles(
        &mut self,
        idx: usize,
        new: &[u32],
        indices: &mut Vec<u32>,
        written: &mut Vec<u32>,
    ) {
        if self.slot_of_block[idx] == NONE && new.is_empty() {
            return;
        }
        let s = self.slot(idx);
        let mut old = std::mem::take(&mut self.slots[s].triangles);
        let n_new = new.len() / 3;
        let n_kept = old.len().min(n_new);
        for (p, &t) in old[..n_kept].iter().enumerate() {
            let t = t as usize;
            indices[3 * t..3 * t + 3].copy_from_slice(&new[3 * p..3 * p + 3]);
        }
        written.extend_from_slice(&old[..n_kept]);
        if n_new > n_kept {
            for p in n_kept..n_new {
                let t = self.owners.len() as u32;
                indices.extend_from_slice(&new[3 * p..3 * p + 3]);
                self.owners.push([s as u32, p as u32]);
                old.push(t);
                written.push(t);
            }
            self.slots[s].triangles = old;
            return;
        }
        let mut surplus = old.split_off(n_kept);
        self.slots[s].triangles = old;
        // Last first: the triangle moved into a hole is then never one still to remove.
        surplus.sort_unstable_by(|a, b| b.cmp(a));
        for t in surplus {
            self.remove_triangle(t as usize, indices, written);
        }
    }

    /// Removes triangle `t` (already dropped from its slot's list) by moving the last
    /// triangle into its place.
    fn remove_triangle(&mut self, t: usize, indices: &mut Vec<u32>, written: &mut Vec<u32>) {
        let last = self.owners.len() - 1;
        if t != last {
            indices.copy_within(3 * last..3 * last + 3, 3 * t);
            let [s, p] = self.owners[last];
            self.owners[t] = [s, p];
            self.slots[s as usize].triangles[p as usize] = t as u32;
            written.push(t as u32);
        }
        self.owners.truncate(last);
        indices.truncate(3 * last);
    }
}

/// Spare vertices given to a block that outgrew its range, so that it can grow a little in
/// place next time.
fn spare_vertices(n: usize) -> usize {
    n / 4 + 4
}

impl OctreeMesher {
    /// Brings `mesh` up to date with the remeshes since the last call and says what changed.
    ///
    /// `mesh` must be the mesh this mesher's last `mesh_update` left, unmodified; its lengths
    /// are checked, and a mesh that does not match (such as an empty one at the first call),
    /// a remesh of everything, or too many unreferenced vertices make it assemble the whole
    /// mesh again. Otherwise only the changed blocks' vertices and the triangles that read
    /// them are written. The result has the same triangles (the same corner positions,
    /// normals and colours) as [`OctreeMesher::mesh`], in another order, and may hold
    /// unreferenced vertices (at most half as many as referenced ones); it has no ambient
    /// colours.
    pub fn mesh_update(&mut self, mesh: &mut Mesh) -> Result<MeshPatch, OctreeMeshError> {
        self.patch_mesh(mesh, Reemit::Dependents)
    }

    /// Like [`OctreeMesher::mesh_update`], but emits only the changed blocks' triangles:
    /// wrong, for tests that must catch it.
    #[cfg(test)]
    pub(crate) fn mesh_update_forgetting_seams(
        &mut self,
        mesh: &mut Mesh,
    ) -> Result<MeshPatch, OctreeMeshError> {
        self.patch_mesh(mesh, Reemit::ChangedOnly)
    }

    fn patch_mesh(
        &mut self,
        mesh: &mut Mesh,
        reemit: Reemit,
    ) -> Result<MeshPatch, OctreeMeshError> {
        let changes = std::mem::take(&mut self.changes);
        let usable = self
            .assembled
            .take()
            .filter(|state| !changes.all && state.matches(mesh));
        let Some(mut state) = usable else {
            return self.assemble_whole(mesh);
        };
        let changed = self.changed_blocks(changes.blocks, &state);
        let mut written_vertices = Vec::with_capacity(changed.len());
        for &idx in &changed {
            written_vertices.extend(self.place_vertices(&mut state, idx, mesh)?);
        }
        let reemitted = self.dependents(&changed, reemit);
        let mut written_triangles = Vec::new();
        let mut scratch = Vec::new();
        let assembly = Assembly {
            offsets: &state.offsets,
            records: Records::Sparse(&self.blocks),
        };
        for &idx in &reemitted {
            scratch.clear();
            if let Some(block) = self.blocks.get(&self.block_key(idx)) {
                self.emit_block(block, &assembly, &mesh.positions, &mut scratch, idx);
            }
            let (indices, written) = (&mut mesh.indices, &mut written_triangles);
            state
                .table
                .replace_triangles(idx, &scratch, indices, written);
        }
        let n_vertices = mesh.positions.len();
        if n_vertices - state.n_vertices_live > state.n_vertices_live / 2 {
            return self.assemble_whole(mesh);
        }
        state.n_vertices = n_vertices;
        let n_triangles = state.table.owners.len();
        self.assembled = Some(state);
        written_vertices.sort_unstable_by_key(|r| r.start);
        written_triangles.sort_unstable();
        written_triangles.dedup();
        let triangles = written_triangles
            .into_iter()
            .map(|t| t as usize)
            .filter(|&t| t < n_triangles)
            .map(|t| t..t + 1);
        Ok(MeshPatch {
            full: false,
            vertex_ranges: merge(written_vertices),
            triangle_ranges: merge(triangles),
            n_vertices,
            n_triangles,
            blocks_changed: changed.len(),
            blocks_reemitted: reemitted.len(),
        })
    }
}

impl OctreeMesher {
    /// The distinct blocks of `noted` that have vertices now or had some in the mesh, sorted:
    /// a block without vertices has no triangles and gives none to its neighbours.
    fn changed_blocks(&self, mut noted: Vec<u32>, state: &Assembled) -> Vec<usize> {
        noted.sort_unstable();
        noted.dedup();
        noted
            .into_iter()
            .map(|idx| idx as usize)
            .filter(|&idx| {
                let s = state.table.slot_of_block[idx];
                let had = s != NONE && state.table.slots[s as usize].n_vertices > 0;
                let has = self
                    .blocks
                    .get(&self.block_key(idx))
                    .is_some_and(|b| !b.positions.is_empty());
                had || has
            })
            .collect()
    }

    /// The blocks whose triangles read the vertices of `changed`, sorted.
    fn dependents(&self, changed: &[usize], reemit: Reemit) -> Vec<usize> {
        let offsets: &[[i32; 3]] = match reemit {
            Reemit::Dependents => &DEPENDENTS,
            #[cfg(test)]
            Reemit::ChangedOnly => &DEPENDENTS[..1],
        };
        let n = i64::from(self.n_blocks);
        let mut out = Vec::with_capacity(changed.len() * offsets.len());
        for &idx in changed {
            let key = self.block_key(idx);
            for o in offsets {
                let k: [i64; 3] = std::array::from_fn(|a| i64::from(key[a]) + i64::from(o[a]));
                if k.iter().all(|&c| (0..n).contains(&c)) {
                    out.push(self.block_idx(k.map(|c| c as u32)));
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The key of block index `idx`.
    fn block_key(&self, idx: usize) -> [u32; 3] {
        let n = self.n_blocks as usize;
        [idx % n, idx / n % n, idx / (n * n)].map(|c| c as u32)
    }

    /// Writes block `idx`'s current vertices into its range of `mesh`, moving the range to
    /// the end when they no longer fit; returns the vertices written.
    fn place_vertices(
        &self,
        state: &mut Assembled,
        idx: usize,
        mesh: &mut Mesh,
    ) -> Result<Option<Range<usize>>, OctreeMeshError> {
        let block = self.blocks.get(&self.block_key(idx));
        let (positions, normals) = block.map_or((&[][..], &[][..]), |b| {
            (b.positions.as_slice(), b.normals.as_slice())
        });
        let n = positions.len();
        let s = state.table.slot(idx);
        let slot = &mut state.table.slots[s];
        state.n_vertices_live = state.n_vertices_live - slot.n_vertices as usize + n;
        slot.n_vertices = n as u32;
        if n == 0 {
            return Ok(None);
        }
        let mut written = n;
        if n > slot.capacity as usize {
            let start = mesh.positions.len();
            let capacity = n + spare_vertices(n);
            if start + capacity >= NONE as usize {
                // The layout is dropped with `state`: the next call assembles everything.
                return Err(OctreeMeshError::TooManyVertices);
            }
            mesh.positions.resize(start + capacity, positions[0]);
            mesh.normals.resize(start + capacity, normals[0]);
            mesh.colours.resize(start + capacity, [1.0; 4]);
            state.offsets[idx] = start as u32;
            slot.capacity = capacity as u32;
            // The spare room is new to the mesh too: a copy of the buffers must get it.
            written = capacity;
        }
        let start = state.offsets[idx] as usize;
        mesh.positions[start..start + n].copy_from_slice(positions);
        mesh.normals[start..start + n].copy_from_slice(normals);
        mesh.colours[start..start + n].fill([1.0; 4]);
        Ok(Some(start..start + written))
    }

    /// Assembles the whole mesh into `mesh` and records its layout.
    fn assemble_whole(&mut self, mesh: &mut Mesh) -> Result<MeshPatch, OctreeMeshError> {
        self.changes = super::Changes::default();
        let mut state = Assembled::new(self.reps.len());
        self.assemble_into(mesh, |placed| state.place_whole(placed))?;
        state.n_vertices = mesh.positions.len();
        let (n_vertices, n_triangles) = (mesh.positions.len(), mesh.n_triangles());
        let n_blocks = state.table.slots.len();
        self.assembled = Some(state);
        Ok(MeshPatch {
            full: true,
            vertex_ranges: merge(std::iter::once(0..n_vertices)),
            triangle_ranges: merge(std::iter::once(0..n_triangles)),
            n_vertices,
            n_triangles,
            blocks_changed: n_blocks,
            blocks_reemitted: n_blocks,
        })
    }
}

/// Joins overlapping or adjacent ranges of `sorted` (sorted by start), dropping empty ones.
fn merge(sorted: impl IntoIterator<Item = Range<usize>>) -> Vec<Range<usize>> {
    let mut out: Vec<Range<usize>> = Vec::new();
    for r in sorted.into_iter().filter(|r| !r.is_empty()) {
        match out.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => out.push(r),
        }
    }
    out
}
