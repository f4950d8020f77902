//! Closed meshes made from parameters: an axis-aligned box and an icosphere. Tests and
//! benchmarks measure queries on them against analytic answers.

use std::collections::BTreeMap;

use glam::DVec3;

use super::TriMesh;

/// The most subdivisions [`icosphere`] accepts: 20 * 4^8 = 1,310,720 triangles.
pub const MAX_ICOSPHERE_SUBDIVISIONS: u32 = 8;

/// The closed box between `lo` and `hi` (any two opposite corners): 8 vertices and 12
/// triangles (two per face) facing outwards.
///
/// # Panics
/// If a corner is not finite.
pub fn cube(lo: DVec3, hi: DVec3) -> TriMesh {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    // Vertex i has x = hi.x when bit 0 of i is set, y when bit 1 is, z when bit 2 is.
    let positions: Vec<[f32; 3]> = (0..8)
        .map(|i| {
            let pick = |bit: u32, l: f64, h: f64| (if i & (1 << bit) != 0 { h } else { l }) as f32;
            [
                pick(0, lo.x, hi.x),
                pick(1, lo.y, hi.y),
                pick(2, lo.z, hi.z),
            ]
        })
        .collect();
    let triangles = vec![
        [0, 4, 6],
        [0, 6, 2],
        [1, 3, 7],
        [1, 7, 5],
        [0, 1, 5],
        [0, 5, 4],
        [2, 6, 7],
        [2, 7, 3],
        [0, 2, 3],
        [0, 3, 1],
        [4, 5, 7],
        [4, 7, 6],
    ];
    match TriMesh::new(positions, triangles) {
        Ok(mesh) => mesh,
        Err(e) => panic!("the box from {lo} to {hi}: {e}"),
    }
}

/// Each of `triangles` split in four at its edges' midpoints, pushed out onto the unit sphere
/// (added to `vertices`, once per edge).
fn subdivided(vertices: &mut Vec<DVec3>, triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut midpoints: BTreeMap<(u32, u32), u32> = BTreeMap::new();
    let mut midpoint = |a: u32, b: u32, vertices: &mut Vec<DVec3>| -> u32 {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            let m = (vertices[a as usize] + vertices[b as usize]).normalize();
            vertices.push(m);
            vertices.len() as u32 - 1
        })
    };
    let mut finer = Vec::with_capacity(4 * triangles.len());
    for &[a, b, c] in triangles {
        let ab = midpoint(a, b, vertices);
        let bc = midpoint(b, c, vertices);
        let ca = midpoint(c, a, vertices);
        finer.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
    }
    finer
}

/// The sphere of `radius` around the origin approximated by an icosahedron whose triangles are
/// split in four `subdivisions` times, vertices pushed out onto the sphere: 20 * 4^n
/// triangles facing outwards, closed. The faces are chords, so the mesh lies between the
/// sphere and a slightly smaller concentric one.
///
/// # Panics
/// If `subdivisions` exceeds [`MAX_ICOSPHERE_SUBDIVISIONS`] or `radius` is not finite.
pub fn icosphere(radius: f64, subdivisions: u32) -> TriMesh {
    assert!(
        subdivisions <= MAX_ICOSPHERE_SUBDIVISIONS,
        "at most {MAX_ICOSPHERE_SUBDIVISIONS} subdivisions, not {subdivisions}"
    );
    let g = (1.0 + 5f64.sqrt()) / 2.0;
    let mut vertices: Vec<DVec3> = [
        (-1.0, g, 0.0),
        (1.0, g, 0.0),
        (-1.0, -g, 0.0),
        (1.0, -g, 0.0),
        (0.0, -1.0, g),
        (0.0, 1.0, g),
        (0.0, -1.0, -g),
        (0.0, 1.0, -g),
        (g, 0.0, -1.0),
        (g, 0.0, 1.0),
        (-g, 0.0, -1.0),
        (-g, 0.0, 1.0),
    ]
    .into_iter()
    .map(|(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        triangles = subdivided(&mut vertices, &triangles);
    }
    let positions = vertices
        .iter()
        .map(|v| (*v * radius).as_vec3().to_array())
        .collect();
    match TriMesh::new(positions, triangles) {
        Ok(mesh) => mesh,
        Err(e) => panic!("icosphere of radius {radius}: {e}"),
    }
}
