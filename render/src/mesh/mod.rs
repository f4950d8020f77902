//! Triangle meshes and the meshers that build them from functions.
//!
//! [`Mesh`] is the one mesh type every mesher returns and the renderer draws.
//! [`octree`] meshes implicit solids (f >= 0 is inside) through the [`Field`] trait;
//! [`parametric`] triangulates parametric surfaces p(u,v) and sweeps curves p(u) into tubes;
//! [`TapeField`] and [`ObjectField`] plug fdsl functions and objects into the mesher.

pub mod field;
pub mod object_field;
pub mod octree;
pub mod parametric;
pub mod tape_field;

pub use field::Field;
pub use object_field::ObjectField;
pub use tape_field::TapeField;

/// Largest number of vertices a [`Mesh`] may index (indices are `u32`).
pub const MAX_INDEXED_VERTICES: usize = u32::MAX as usize;

/// An axis-aligned box, `lo` to `hi` inclusive, in world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// The corner with the smallest coordinates.
    pub lo: [f32; 3],
    /// The corner with the largest coordinates.
    pub hi: [f32; 3],
}

impl Aabb {
    /// The box from `lo` to `hi`.
    pub fn new(lo: [f32; 3], hi: [f32; 3]) -> Self {
        Self { lo, hi }
    }

    /// The centre of the box.
    pub fn centre(&self) -> [f32; 3] {
        std::array::from_fn(|a| 0.5 * (self.lo[a] + self.hi[a]))
    }

    /// The edge lengths of the box.
    pub fn size(&self) -> [f32; 3] {
        std::array::from_fn(|a| self.hi[a] - self.lo[a])
    }

    /// Whether `p` lies inside the box or on its boundary.
    pub fn contains(&self, p: [f32; 3]) -> bool {
        (0..3).all(|a| self.lo[a] <= p[a] && p[a] <= self.hi[a])
    }

    /// The smallest box holding both.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            lo: std::array::from_fn(|a| self.lo[a].min(other.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(other.hi[a])),
        }
    }
}

/// Why a mesh is not well formed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    /// Normals or colours do not have one entry per position.
    #[error("mesh has {n_positions} positions but {n_other} {what}")]
    AttributeCount {
        /// Number of positions.
        n_positions: usize,
        /// Number of entries in the other attribute.
        n_other: usize,
        /// Which attribute.
        what: &'static str,
    },
    /// The index list is not a whole number of triangles.
    #[error("index count {0} is not a multiple of 3")]
    PartialTriangle(usize),
    /// A triangle refers to a vertex that does not exist.
    #[error("index {index} out of range for {n_positions} vertices")]
    IndexOutOfRange {
        /// The offending index.
        index: u32,
        /// Number of positions.
        n_positions: usize,
    },
    /// More vertices than `u32` indices can address.
    #[error("mesh has {0} vertices, more than {MAX_INDEXED_VERTICES}")]
    TooManyVertices(usize),
}

/// An indexed triangle mesh with per-vertex normals and straight-alpha RGBA colours.
///
/// Triangles wind counter-clockwise seen from outside, so normals point out of the solid.
/// Guarantees depend on the mesher; check them with [`Mesh::open_edges`] and
/// [`Mesh::non_manifold_edges`].
#[derive(Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals, one per position.
    pub normals: Vec<[f32; 3]>,
    /// Vertex colours in linear RGBA 0..1, one per position: the diffuse colour and alpha.
    pub colours: Vec<[f32; 4]>,
    /// Ambient colours in linear RGB 0..1, one per position, or none: then the ambient term
    /// uses the vertex colour (see [`crate::appearance`]).
    pub ambient: Vec<[f32; 3]>,
    /// Three indices per triangle.
    pub indices: Vec<u32>,
}

/// Copies field by field; `clone_from` keeps the buffers' allocations (a patched mesh is
/// written over one handed out earlier).
impl Clone for Mesh {
    fn clone(&self) -> Mesh {
        Mesh {
            positions: self.positions.clone(),
            normals: self.normals.clone(),
            colours: self.colours.clone(),
            ambient: self.ambient.clone(),
            indices: self.indices.clone(),
        }
    }

    fn clone_from(&mut self, source: &Mesh) {
        // Every field named, so that a new one cannot be left out.
        let Mesh {
            positions,
            normals,
            colours,
            ambient,
            indices,
        } = source;
        self.positions.clone_from(positions);
        self.normals.clone_from(normals);
        self.colours.clone_from(colours);
        self.ambient.clone_from(ambient);
        self.indices.clone_from(indices);
    }
}

impl Mesh {
    /// Number of vertices.
    pub fn n_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn n_triangles(&self) -> usize {
        self.indices.len() / 3
    }

    /// Checks attribute counts and index ranges: use on meshes from files or peers.
    pub fn validate(&self) -> Result<(), MeshError> {
        let n_positions = self.positions.len();
        if n_positions > MAX_INDEXED_VERTICES {
            return Err(MeshError::TooManyVertices(n_positions));
        }
        for (n_other, what) in [
            (self.normals.len(), "normals"),
            (self.colours.len(), "colours"),
        ] {
            if n_other != n_positions {
                return Err(MeshError::AttributeCount {
                    n_positions,
                    n_other,
                    what,
                });
            }
        }
        if !(self.ambient.is_empty() || self.ambient.len() == n_positions) {
            return Err(MeshError::AttributeCount {
                n_positions,
                n_other: self.ambient.len(),
                what: "ambient colours",
            });
        }
        if !self.indices.len().is_multiple_of(3) {
            return Err(MeshError::PartialTriangle(self.indices.len()));
        }
        match self.indices.iter().find(|&&i| i as usize >= n_positions) {
            Some(&index) => Err(MeshError::IndexOutOfRange { index, n_positions }),
            None => Ok(()),
        }
    }

    /// The triangles as index triples.
    pub fn triangles(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        self.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]])
    }

    /// Whether some vertex colour is less than opaque (the mesh then draws with blending).
    pub fn has_translucent_vertices(&self) -> bool {
        self.colours.iter().any(|c| c[3] < 1.0)
    }

    /// The bounding box of the positions, `None` for an empty mesh.
    pub fn bounds(&self) -> Option<Aabb> {
        let first = *self.positions.first()?;
        let b = Aabb::new(first, first);
        Some((self.positions.iter()).fold(b, |b, &p| b.union(&Aabb::new(p, p))))
    }

    /// Undirected edges with how many triangles use each, sorted by edge.
    fn edge_uses(&self) -> Vec<((u32, u32), usize)> {
        let mut edges: Vec<(u32, u32)> = self
            .triangles()
            .flat_map(|[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        edges.sort_unstable();
        let mut uses: Vec<((u32, u32), usize)> = Vec::new();
        for e in edges {
            match uses.last_mut() {
                Some((last, n)) if *last == e => *n += 1,
                _ => uses.push((e, 1)),
            }
        }
        uses
    }

    /// Number of edges used by exactly one triangle: zero for a watertight mesh.
    pub fn open_edges(&self) -> usize {
        self.edge_uses().iter().filter(|(_, n)| *n == 1).count()
    }

    /// Number of edges used by more than two triangles: zero for a manifold mesh.
    pub fn non_manifold_edges(&self) -> usize {
        self.edge_uses().iter().filter(|(_, n)| *n > 2).count()
    }

    /// Number of directed edges that two or more triangles traverse the same way: zero when
    /// neighbouring triangles wind consistently (an orientable, consistently wound mesh).
    pub fn misoriented_edges(&self) -> usize {
        let mut directed: Vec<(u32, u32)> = self
            .triangles()
            .flat_map(|[a, b, c]| [(a, b), (b, c), (c, a)])
            .collect();
        directed.sort_unstable();
        directed.windows(2).filter(|w| w[0] == w[1]).count()
    }

    /// Number of triangles whose three corners are not distinct vertices.
    pub fn degenerate_triangles(&self) -> usize {
        self.triangles()
            .filter(|[a, b, c]| a == b || b == c || c == a)
            .count()
    }

    /// The signed volume enclosed (divergence theorem): positive when normals face out.
    pub fn signed_volume(&self) -> f64 {
        let p = |i: u32| self.positions[i as usize].map(f64::from);
        self.triangles()
            .map(|[a, b, c]| {
                let (a, b, c) = (p(a), p(b), p(c));
                let cross = [
                    b[1] * c[2] - b[2] * c[1],
                    b[2] * c[0] - b[0] * c[2],
                    b[0] * c[1] - b[1] * c[0],
                ];
                (a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]) / 6.0
            })
            .sum()
    }

    /// Sets every vertex colour from a function of its position.
    pub fn colour_with(&mut self, mut colour: impl FnMut([f32; 3]) -> [f32; 4]) {
        self.colours = self.positions.iter().map(|&p| colour(p)).collect();
    }

    /// Moves every vertex along its normal by `height(p)` (geometric texture); NaN counts as 0.
    ///
    /// Normals are recomputed from the displaced triangles afterwards.
    pub fn displace_along_normals(&mut self, mut height: impl FnMut([f32; 3]) -> f32) {
        let heights: Vec<f32> = self.positions.iter().map(|&p| height(p)).collect();
        self.displace_by(&heights);
    }

    /// Moves vertex i along its normal by `heights[i]` (missing or NaN heights count as 0),
    /// then recomputes the normals from the displaced triangles.
    pub fn displace_by(&mut self, heights: &[f32]) {
        for (i, (p, n)) in self.positions.iter_mut().zip(&self.normals).enumerate() {
            let h = heights.get(i).copied().unwrap_or(0.0);
            let h = if h.is_finite() { h } else { 0.0 };
            *p = std::array::from_fn(|k| p[k] + h * n[k]);
        }
        self.recompute_normals();
    }

    /// Appends `other`, renumbering its indices.
    pub fn append(&mut self, other: &Mesh) -> Result<(), MeshError> {
        let base = self.positions.len();
        let total = base + other.positions.len();
        let base = u32::try_from(base).map_err(|_| MeshError::TooManyVertices(total))?;
        u32::try_from(total).map_err(|_| MeshError::TooManyVertices(total))?;
        if !(self.ambient.is_empty() && other.ambient.is_empty()) {
            // One of the two has ambient colours: the other's are its vertex colours.
            if self.ambient.is_empty() {
                self.ambient = self.colours.iter().map(|c| [c[0], c[1], c[2]]).collect();
            }
            if other.ambient.is_empty() {
                let own = other.colours.iter().map(|c| [c[0], c[1], c[2]]);
                self.ambient.extend(own);
            } else {
                self.ambient.extend_from_slice(&other.ambient);
            }
        }
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.colours.extend_from_slice(&other.colours);
        self.indices.extend(other.indices.iter().map(|i| i + base));
        Ok(())
    }

    /// Normals for a faceted model (a polygon scene, a CAD part): each corner's normal is the
    /// area-weighted average of the triangles at its vertex whose normals lie within
    /// `crease_degrees` of its own triangle's, and a vertex whose corners end up with different
    /// normals is split into one vertex per normal (positions, colours and ambient colours
    /// copied). A box keeps flat faces and straight edges; a finely triangulated smooth
    /// surface keeps its shared vertices. Splits open the mesh along creases, so displacing
    /// it afterwards (`displace_by`) would crack it there.
    pub fn split_creases(&mut self, crease_degrees: f32) {
        let cos_max = crease_degrees.to_radians().cos();
        let n_vertices = self.positions.len();
        let faces: Vec<[f32; 3]> = self
            .triangles()
            .map(|[a, b, c]| {
                triangle_normal_unnormalised(
                    self.positions[a as usize],
                    self.positions[b as usize],
                    self.positions[c as usize],
                )
            })
            .collect();
        let unit: Vec<[f32; 3]> = faces.iter().map(|&n| normalise_or_up(n)).collect();
        let (start, around) = self.triangles_around();
        let (mut positions, mut normals) = (Vec::with_capacity(n_vertices), Vec::new());
        let mut colours = Vec::new();
        let mut ambient = Vec::new();
        // One new vertex per (old vertex, normal).
        let mut made: std::collections::BTreeMap<(u32, [u32; 3]), u32> =
            std::collections::BTreeMap::new();
        let mut indices = Vec::with_capacity(self.indices.len());
        for (corner, &i) in self.indices.iter().enumerate() {
            let own = unit[corner / 3];
            let mut sum = [0.0f32; 3];
            for &t in &around[start[i as usize] as usize..start[i as usize + 1] as usize] {
                let u = unit[t as usize];
                if u[0] * own[0] + u[1] * own[1] + u[2] * own[2] >= cos_max {
                    let n = faces[t as usize];
                    sum = std::array::from_fn(|k| sum[k] + n[k]);
                }
            }
            let normal = normalise_or_up(sum);
            let v = *made
                .entry((i, normal.map(f32::to_bits)))
                .or_insert_with(|| {
                    positions.push(self.positions[i as usize]);
                    normals.push(normal);
                    if let Some(c) = self.colours.get(i as usize) {
                        colours.push(*c);
                    }
                    if let Some(a) = self.ambient.get(i as usize) {
                        ambient.push(*a);
                    }
                    // Fewer new vertices than corners, and corners are indexed by u32.
                    (positions.len() - 1) as u32
                });
            indices.push(v);
        }
        self.positions = positions;
        self.normals = normals;
        if !self.colours.is_empty() {
            self.colours = colours;
        }
        if !self.ambient.is_empty() {
            self.ambient = ambient;
        }
        self.indices = indices;
    }

    /// The triangles around each vertex, as compressed rows: vertex `v`'s are
    /// `around[start[v]..start[v + 1]]`.
    fn triangles_around(&self) -> (Vec<u32>, Vec<u32>) {
        let n_vertices = self.positions.len();
        let mut start = vec![0u32; n_vertices + 1];
        for &i in &self.indices {
            start[i as usize + 1] += 1;
        }
        for v in 0..n_vertices {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut around = vec![0u32; self.indices.len()];
        for (corner, &i) in self.indices.iter().enumerate() {
            around[fill[i as usize] as usize] = (corner / 3) as u32;
            fill[i as usize] += 1;
        }
        (start, around)
    }

    /// Recomputes normals as the area-weighted average of the adjacent triangles' normals.
    pub fn recompute_normals(&mut self) {
        let mut acc = vec![[0.0f32; 3]; self.positions.len()];
        for [a, b, c] in self.triangles() {
            let n = triangle_normal_unnormalised(
                self.positions[a as usize],
                self.positions[b as usize],
                self.positions[c as usize],
            );
            for i in [a, b, c] {
                for k in 0..3 {
                    acc[i as usize][k] += n[k];
                }
            }
        }
        self.normals = acc.into_iter().map(normalise_or_up).collect();
    }
}

/// The cross product (b - a) x (c - a): twice the area times the unit normal.
pub(crate) fn triangle_normal_unnormalised(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [f32; 3] {
    let u: [f32; 3] = std::array::from_fn(|k| b[k] - a[k]);
    let v: [f32; 3] = std::array::from_fn(|k| c[k] - a[k]);
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

/// `v` scaled to unit length, or +z when it has no usable length.
pub(crate) fn normalise_or_up(v: [f32; 3]) -> [f32; 3] {
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len > f32::MIN_POSITIVE && len.is_finite() {
        v.map(|c| c / len)
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// Edges of `mesh` that do not join exactly two triangles (none in a closed mesh).
#[cfg(test)]
pub(crate) fn n_open_edges(mesh: &Mesh) -> usize {
    let mut uses = std::collections::BTreeMap::new();
    for t in mesh.indices.chunks_exact(3) {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_insert(0u32) += 1;
        }
    }
    uses.values().filter(|&&n| n != 2).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetrahedron() -> Mesh {
        let mut m = Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            indices: vec![0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3],
            ..Mesh::default()
        };
        m.recompute_normals();
        m.colour_with(|_| [1.0; 4]);
        m
    }

    #[test]
    fn split_creases_gives_flat_faces_to_a_tetrahedron_and_keeps_a_smooth_fan_shared() {
        let mut m = tetrahedron();
        m.split_creases(40.0);
        assert_eq!(m.validate(), Ok(()));
        // Every dihedral angle of the tetrahedron is a crease: 4 faces x 3 corners.
        assert_eq!(m.n_vertices(), 12);
        for t in m.indices.chunks_exact(3) {
            let n = m.normals[t[0] as usize];
            assert!(t.iter().all(|&i| m.normals[i as usize] == n), "{t:?}");
        }
        assert!(
            (m.signed_volume() - 1.0 / 6.0).abs() < 1e-9,
            "same triangles"
        );
        // A gently folded fan (10 degrees between neighbours) stays one smooth sheet.
        let mut fan = Mesh {
            positions: vec![[0.0, 0.0, 0.0]],
            ..Mesh::default()
        };
        for k in 0..4 {
            let a = (k as f32) * 0.5;
            fan.positions.push([a.cos(), a.sin(), 0.05 * k as f32]);
        }
        fan.indices = vec![0, 1, 2, 0, 2, 3, 0, 3, 4];
        fan.recompute_normals();
        let smooth = fan.clone();
        fan.split_creases(40.0);
        assert_eq!(fan.n_vertices(), smooth.n_vertices());
    }

    #[test]
    fn closed_tetrahedron_has_no_open_or_non_manifold_edges() {
        let m = tetrahedron();
        assert_eq!(m.validate(), Ok(()));
        assert_eq!(m.open_edges(), 0);
        assert_eq!(m.non_manifold_edges(), 0);
        assert!((m.signed_volume() - 1.0 / 6.0).abs() < 1e-9);
    }

    #[test]
    fn removing_a_face_opens_three_edges_and_a_fin_is_non_manifold() {
        let mut m = tetrahedron();
        m.indices.truncate(9);
        assert_eq!(m.open_edges(), 3);
        let mut fin = tetrahedron();
        fin.positions.push([1.0, 1.0, 1.0]);
        fin.normals.push([0.0, 0.0, 1.0]);
        fin.colours.push([1.0; 4]);
        fin.indices.extend([1, 2, 4]);
        assert_eq!(fin.non_manifold_edges(), 1);
        assert_eq!(tetrahedron().misoriented_edges(), 0);
        let mut flipped = tetrahedron();
        flipped.indices.swap(0, 1);
        assert_eq!(flipped.misoriented_edges(), 3);
    }

    #[test]
    fn validate_rejects_bad_indices_and_counts() {
        let mut m = tetrahedron();
        m.indices.push(9);
        assert_eq!(m.validate(), Err(MeshError::PartialTriangle(13)));
        m.indices.extend([0, 1]);
        assert_eq!(
            m.validate(),
            Err(MeshError::IndexOutOfRange {
                index: 9,
                n_positions: 4
            })
        );
        let mut m = tetrahedron();
        m.colours.pop();
        assert!(matches!(
            m.validate(),
            Err(MeshError::AttributeCount {
                what: "colours",
                ..
            })
        ));
    }

    #[test]
    fn displacement_moves_vertices_along_normals_and_keeps_topology() {
        let mut m = tetrahedron();
        let (before, normals) = (m.positions.clone(), m.normals.clone());
        m.displace_along_normals(|p| if p[0] > 0.5 { 0.25 } else { f32::NAN });
        assert_eq!(m.open_edges(), 0);
        for i in 0..4 {
            let expect: [f32; 3] = if before[i][0] > 0.5 {
                std::array::from_fn(|k| before[i][k] + 0.25 * normals[i][k])
            } else {
                before[i]
            };
            assert_eq!(m.positions[i], expect);
        }
        assert_ne!(m.normals, normals);
    }

    #[test]
    fn ambient_colours_are_optional_and_appended_with_the_vertex_colours() {
        let mut m = tetrahedron();
        assert_eq!(m.validate(), Ok(()));
        let mut blue = tetrahedron();
        blue.ambient = vec![[0.0, 0.0, 1.0]; 4];
        assert_eq!(blue.validate(), Ok(()));
        m.append(&blue).unwrap();
        assert_eq!(m.ambient.len(), 8);
        assert_eq!(m.ambient[0], [1.0; 3], "the first mesh's vertex colour");
        assert_eq!(m.ambient[7], [0.0, 0.0, 1.0]);
        m.ambient.pop();
        assert!(matches!(
            m.validate(),
            Err(MeshError::AttributeCount {
                what: "ambient colours",
                ..
            })
        ));
    }

    #[test]
    fn append_renumbers_and_bounds_cover_both() {
        let mut m = tetrahedron();
        let mut other = tetrahedron();
        for p in &mut other.positions {
            p[0] += 2.0;
        }
        m.append(&other).unwrap();
        assert_eq!(m.n_triangles(), 8);
        assert_eq!(m.open_edges(), 0);
        assert_eq!(m.bounds(), Some(Aabb::new([0.0; 3], [3.0, 1.0, 1.0])));
    }
}
