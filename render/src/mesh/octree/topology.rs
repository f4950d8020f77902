//! Topology of one grid cell for dual contouring: corner and edge numbering, how the surface
//! crosses each face, the surface patches of a cell as cycles of crossed edges, and how a
//! patch is split into several vertices so that the mesh stays manifold.
//!
//! A patch is the dual of one marching-cubes polygon: its corners are the crossed cell edges,
//! its sides the segments the surface cuts across the cell's faces. One vertex per patch is a
//! fan over that polygon. When a patch crosses one face twice (a tunnel through the cell) and
//! the cell across that face does the same, both sides of the face would share one mesh edge
//! four times; so such a patch gets one vertex per arc of its polygon, chosen so that no vertex
//! touches a face twice, and the arcs are stitched by gap polygons (see `octree.rs`).

/// Corner `k` of a cell has offset bit a of k along axis a.
pub(super) fn corner_offset(k: usize) -> [u32; 3] {
    [(k & 1) as u32, ((k >> 1) & 1) as u32, ((k >> 2) & 1) as u32]
}

/// The corner index of a cell-relative offset.
fn corner_of(o: [u32; 3]) -> usize {
    (o[0] + 2 * o[1] + 4 * o[2]) as usize
}

/// Cell edge along axis `d` whose low end has the offset `low` within the cell.
pub(super) fn edge_index(d: usize, low: [u32; 3]) -> usize {
    d * 4 + low[(d + 1) % 3] as usize + 2 * low[(d + 2) % 3] as usize
}

/// The axis of cell edge `e` and the offset of its low end within the cell.
pub(super) fn edge_low(e: usize) -> (usize, [u32; 3]) {
    let d = e / 4;
    let mut low = [0u32; 3];
    low[(d + 1) % 3] = (e & 1) as u32;
    low[(d + 2) % 3] = ((e >> 1) & 1) as u32;
    (d, low)
}

/// The two corners (low, high) of cell edge `e`.
pub(super) fn edge_corners(e: usize) -> (usize, usize) {
    let (d, low) = edge_low(e);
    let k = corner_of(low);
    (k, k | (1 << d))
}

/// The sign convention: f >= 0 is inside (NaN is outside).
pub(super) fn inside(v: f32) -> bool {
    v >= 0.0
}

/// Faces are numbered `2 * axis + side`, side 0 at the low end of the axis.
pub(super) const N_FACES: usize = 6;

/// The face's corners in cyclic order (q00, q10, q11, q01 in the face's (axis+1, axis+2)
/// coordinates) and its edges (edge i joins corner i and corner i+1).
///
/// The order depends only on the axis, so the two cells sharing a face see its corners in the
/// same order and make the same decision for an ambiguous face.
fn face_corners_and_edges(face: usize) -> ([usize; 4], [usize; 4]) {
    let (f, s) = (face / 2, (face % 2) as u32);
    let (ua, va) = ((f + 1) % 3, (f + 2) % 3);
    let q: [[u32; 3]; 4] = [[0, 0], [1, 0], [1, 1], [0, 1]].map(|[u, w]| {
        let mut o = [0u32; 3];
        o[f] = s;
        o[ua] = u;
        o[va] = w;
        o
    });
    let edges = std::array::from_fn(|i| {
        let (p, r) = (q[i], q[(i + 1) % 4]);
        let d = if p[ua] != r[ua] { ua } else { va };
        let low: [u32; 3] = std::array::from_fn(|a| p[a].min(r[a]));
        edge_index(d, low)
    });
    (q.map(corner_of), edges)
}

/// The segments the surface cuts across face `face`: pairs of crossed cell edges, at most two.
///
/// A face with four crossed edges is ambiguous; the bilinear interpolant's saddle decides
/// whether its inside corners are connected (the asymptotic decider).
pub(super) fn face_segments(v: &[f32; 8], face: usize) -> ([[usize; 2]; 2], usize) {
    let (corners, edges) = face_corners_and_edges(face);
    let val = corners.map(|k| v[k]);
    let crossed: [bool; 4] = std::array::from_fn(|i| inside(val[i]) != inside(val[(i + 1) % 4]));
    let n_crossed = crossed.iter().filter(|&&c| c).count();
    let mut out = [[0usize; 2]; 2];
    match n_crossed {
        2 => {
            let mut on = edges
                .iter()
                .zip(crossed)
                .filter(|(_, c)| *c)
                .map(|(e, _)| *e);
            out[0] = [on.next().unwrap_or(0), on.next().unwrap_or(0)];
            (out, 1)
        }
        4 => {
            let denom = val[0] + val[2] - val[1] - val[3];
            let saddle = if denom != 0.0 {
                (val[0] * val[2] - val[1] * val[3]) / denom
            } else {
                val[0]
            };
            // Cut off corners 0 and 2 when they are not connected through the face's middle,
            // else corners 1 and 3.
            let cut_even = inside(val[0]) != inside(saddle);
            if cut_even {
                out = [[edges[3], edges[0]], [edges[1], edges[2]]];
            } else {
                out = [[edges[0], edges[1]], [edges[2], edges[3]]];
            }
            (out, 2)
        }
        _ => (out, 0),
    }
}

/// Longest patch polygon: every edge of the cell crossed.
pub(super) const MAX_PATCH_EDGES: usize = 12;
/// Most patches in one cell (four separated corners).
pub(super) const MAX_PATCHES: usize = 4;

/// One surface patch of a cell: its crossed edges in order around it, and the face of each
/// side (side k joins `edges[k]` and `edges[k + 1]`, cyclically).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Patch {
    pub(super) edges: [u8; MAX_PATCH_EDGES],
    pub(super) side_faces: [u8; MAX_PATCH_EDGES],
    pub(super) len: u8,
}

/// The patches of a cell with corner values `v`.
///
/// Each crossed edge lies on two faces and belongs to exactly one segment on each, so the
/// segments form disjoint cycles: one per patch.
pub(super) fn cell_patches(v: &[f32; 8]) -> ([Patch; MAX_PATCHES], usize) {
    const UNSET: (u8, u8) = (u8::MAX, u8::MAX);
    // For each edge, its neighbours around the patch: (other edge, face of the segment).
    let mut next = [[UNSET; 2]; 12];
    for face in 0..N_FACES {
        let (segments, n) = face_segments(v, face);
        for &[a, b] in &segments[..n] {
            for (from, to) in [(a, b), (b, a)] {
                let slot = usize::from(next[from][0] != UNSET);
                next[from][slot] = (to as u8, face as u8);
            }
        }
    }
    let mut patches = [Patch::default(); MAX_PATCHES];
    let mut n_patches = 0;
    let mut visited = [false; 12];
    for start in 0..12 {
        if visited[start] || next[start][0] == UNSET || n_patches == MAX_PATCHES {
            continue;
        }
        let patch = &mut patches[n_patches];
        n_patches += 1;
        let (mut cur, mut came_from_face) = (start, u8::MAX);
        for _ in 0..MAX_PATCH_EDGES {
            visited[cur] = true;
            patch.edges[patch.len as usize] = cur as u8;
            let (to, face) = if next[cur][0].1 == came_from_face {
                next[cur][1]
            } else {
                next[cur][0]
            };
            patch.side_faces[patch.len as usize] = face;
            patch.len += 1;
            if to as usize == start || to == u8::MAX {
                break;
            }
            (cur, came_from_face) = (to as usize, face);
        }
    }
    (patches, n_patches)
}

/// Bit set of the faces in `faces`, or `None` if a face repeats.
fn distinct_faces(faces: impl Iterator<Item = u8>) -> Option<u8> {
    let mut set = 0u8;
    for f in faces {
        let bit = 1u8 << f;
        if set & bit != 0 {
            return None;
        }
        set |= bit;
    }
    Some(set)
}

/// Splits a patch into vertices: the vertex (group) of each polygon corner, and the count.
///
/// A vertex touches the sides between its corners and the two cut sides at its ends; no
/// vertex may touch one face twice. One group when the polygon crosses each face once; else
/// the first pair of cut sides that gives two valid arcs; else one vertex per corner (always
/// valid: a corner's two sides lie on the two different faces that hold its edge).
pub(super) fn split_patch(p: &Patch) -> ([u8; MAX_PATCH_EDGES], usize) {
    let m = p.len as usize;
    let sf = &p.side_faces[..m];
    let mut groups = [0u8; MAX_PATCH_EDGES];
    if distinct_faces(sf.iter().copied()).is_some() {
        return (groups, 1);
    }
    for i in 0..m {
        for j in i + 1..m {
            let a = distinct_faces(sf[i..=j].iter().copied());
            let b = distinct_faces(sf[j..].iter().chain(&sf[..=i]).copied());
            if a.is_some() && b.is_some() {
                for g in &mut groups[i + 1..=j] {
                    *g = 1;
                }
                return (groups, 2);
            }
        }
    }
    for (k, g) in groups.iter_mut().enumerate().take(m) {
        *g = k as u8;
    }
    (groups, m)
}

/// The four cells around a grid edge, in the order the mesher emits their quad, as offsets
/// `(o1, o2)` subtracted along the edge's axes (d+1, d+2) from the edge's low point.
const QUAD_CELLS: [(u32, u32); 4] = [(1, 1), (0, 1), (0, 0), (1, 0)];

/// Where the cell with offsets `o` sits in [`QUAD_CELLS`].
fn quad_position(o: (u32, u32)) -> usize {
    QUAD_CELLS.iter().position(|&q| q == o).unwrap_or(0)
}

/// The cells around a grid edge in emitted order, counter-clockwise seen from outside:
/// offsets `(o1, o2)` to subtract along axes d+1 and d+2 from the edge's low point.
pub(super) fn quad_cells(low_inside: bool) -> [(u32, u32); 4] {
    if low_inside {
        QUAD_CELLS
    } else {
        let [a, b, c, d] = QUAD_CELLS;
        [d, c, b, a]
    }
}

/// Whether the quad of cell edge `e` (low corner inside: `low_inside`) runs from this cell
/// straight to the cell across `face`, which must hold `e`.
pub(super) fn quad_runs_to(e: usize, face: usize, low_inside: bool) -> bool {
    let (d, low) = edge_low(e);
    let (a1, a2) = ((d + 1) % 3, (d + 2) % 3);
    let here = (low[a1], low[a2]);
    let f = face / 2;
    let there = if f == a1 {
        (1 - here.0, here.1)
    } else {
        (here.0, 1 - here.1)
    };
    let (i, j) = (quad_position(here), quad_position(there));
    if low_inside {
        j == (i + 1) % 4
    } else {
        i == (j + 1) % 4
    }
}

/// The same grid edge as cell edge `e` (on `face`), numbered in the cell across `face`.
pub(super) fn edge_across(e: usize, face: usize) -> usize {
    let (d, mut low) = edge_low(e);
    let f = face / 2;
    low[f] = 1 - low[f];
    edge_index(d, low)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(inside_corners: &[usize]) -> [f32; 8] {
        std::array::from_fn(|k| {
            if inside_corners.contains(&k) {
                1.0
            } else {
                -1.0
            }
        })
    }

    #[test]
    fn edges_and_corners_agree() {
        for e in 0..12 {
            let (d, low) = edge_low(e);
            assert_eq!(edge_index(d, low), e);
            let (a, b) = edge_corners(e);
            assert_eq!(b - a, 1 << d);
        }
    }

    #[test]
    fn one_corner_is_a_triangle_and_all_patches_are_cycles() {
        let (p, n) = cell_patches(&values(&[0]));
        assert_eq!(n, 1);
        assert_eq!(p[0].len, 3);
        assert_eq!(split_patch(&p[0]).1, 1);
        // Every one of the 256 sign patterns: each crossed edge in exactly one patch, and
        // consecutive corners of a patch share the face of their side.
        for bits in 0u32..256 {
            let v: [f32; 8] = std::array::from_fn(|k| if bits >> k & 1 == 1 { 0.7 } else { -0.3 });
            let (patches, n) = cell_patches(&v);
            let mut seen = [0u8; 12];
            for p in &patches[..n] {
                let m = p.len as usize;
                assert!(m >= 3, "{bits:08b}: patch of {m}");
                for k in 0..m {
                    seen[p.edges[k] as usize] += 1;
                    let face = p.side_faces[k] as usize;
                    let (_, edges) = face_corners_and_edges(face);
                    assert!(edges.contains(&(p.edges[k] as usize)));
                    assert!(edges.contains(&(p.edges[(k + 1) % m] as usize)));
                }
                let (groups, g) = split_patch(p);
                assert!(g >= 1 && g <= m);
                // No group touches a face twice.
                for group in 0..g as u8 {
                    let mut touched = Vec::new();
                    for k in 0..m {
                        let (here, next) = (groups[k], groups[(k + 1) % m]);
                        if here == group || next == group {
                            touched.push(p.side_faces[k]);
                        }
                    }
                    let n_touched = touched.len();
                    touched.sort_unstable();
                    touched.dedup();
                    assert_eq!(touched.len(), n_touched, "{bits:08b}: group {group}");
                }
            }
            for (e, &n_seen) in seen.iter().enumerate() {
                let (a, b) = edge_corners(e);
                let crossed = (bits >> a & 1) != (bits >> b & 1);
                assert_eq!(n_seen, u8::from(crossed), "{bits:08b}: edge {e}");
            }
        }
    }

    #[test]
    fn a_tunnel_through_an_ambiguous_face_is_split() {
        // Inside 0,3,4,6,7: the bottom face (z = 0) is ambiguous and, with its inside corners
        // separated, one patch crosses it twice.
        let mut v = values(&[0, 3, 4, 6, 7]);
        // Make the bottom face's saddle negative (inside corners not connected there).
        v[1] = -2.0;
        v[2] = -2.0;
        let (patches, n) = cell_patches(&v);
        let split = patches[..n].iter().filter(|p| split_patch(p).1 > 1).count();
        assert_eq!(split, 1, "{:?}", &patches[..n]);
    }

    #[test]
    fn quad_orientation_is_opposite_for_the_two_edges_of_a_segment() {
        // Around a cut-off corner the two quads sharing a segment pass the face the other way.
        let v = values(&[0]);
        for face in [0usize, 2, 4] {
            let (segments, n) = face_segments(&v, face);
            assert_eq!(n, 1);
            let [a, b] = segments[0];
            let low_inside = |e: usize| inside(v[edge_corners(e).0]);
            assert_ne!(
                quad_runs_to(a, face, low_inside(a)),
                quad_runs_to(b, face, low_inside(b))
            );
            assert_eq!(edge_across(edge_across(a, face), face), a);
        }
    }
}
