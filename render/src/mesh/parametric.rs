//! Triangulation of parametric surfaces and tubes around parametric curves.
//!
//! Surfaces p(u,v) are sampled adaptively in their (u,v) domain: an edge of the current
//! triangulation is split where the surface bulges more than a tolerance from the chord, and
//! the (u,v) points are triangulated with `spade`'s constrained Delaunay triangulation (the
//! domain boundary is a constraint, ready for trimmed domains). Curves p(u) become closed
//! tubes with end caps, sampled adaptively along u.
//!
//! Guarantees: surface vertices lie exactly on p(u,v), triangles wind counter-clockwise in
//! (u,v) so normals follow dp/du x dp/dv, tubes are watertight. Non-guarantees: a surface
//! patch is open along its domain boundary and is not welded where p is periodic (a sphere
//! from one patch has a seam); the tolerance bounds chord error at edge midpoints only.

use super::{MAX_INDEXED_VERTICES, Mesh, normalise_or_up};
use spade::handles::FixedVertexHandle;
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

/// Most vertices a parametric mesh may have.
pub const MAX_PARAMETRIC_VERTICES: usize = 1 << 22;
/// Most refinement rounds; each round can split every edge once.
pub const MAX_REFINE_ROUNDS: usize = 24;
/// Most divisions of the initial grid along u or v, and of a tube's initial sampling.
pub const MAX_INITIAL_DIVISIONS: u32 = 4096;
/// Most sides a tube's cross-section may have.
pub const MAX_TUBE_SIDES: u32 = 1024;

/// A rectangle in (u,v) parameter space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvDomain {
    /// Range of u.
    pub u: (f32, f32),
    /// Range of v.
    pub v: (f32, f32),
}

/// How finely to triangulate a parametric surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSettings {
    /// The (u,v) rectangle to cover.
    pub domain: UvDomain,
    /// Divisions of the initial grid along u and along v (at least 1).
    pub initial_divisions: u32,
    /// Largest allowed distance, in world units, between p at an edge's (u,v) midpoint and
    /// the midpoint of the edge's 3D chord.
    pub tolerance: f32,
    /// Stop refining once the mesh has this many vertices (at most [`MAX_PARAMETRIC_VERTICES`]).
    pub vertices_max: usize,
}

/// How to sweep a tube along a parametric curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TubeSettings {
    /// Range of u.
    pub domain: (f32, f32),
    /// Tube radius in world units.
    pub radius: f32,
    /// Vertices around each ring (at least 3).
    pub n_sides: u32,
    /// Initial number of segments along u (at least 1).
    pub initial_divisions: u32,
    /// Largest allowed distance between p at a segment's midpoint and the chord's midpoint.
    pub tolerance: f32,
    /// Stop refining once the curve has this many samples.
    pub samples_max: usize,
}

/// Why a parametric mesh could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ParametricError {
    /// A setting is out of range; the message names it.
    #[error("invalid setting: {0}")]
    BadSetting(&'static str),
    /// spade refused a point (for example a NaN parameter).
    #[error("triangulation failed: {0}")]
    Triangulation(String),
}

/// Triangulates p(u,v) over `settings.domain`, colouring each vertex with `colour(uv, p)`.
pub fn triangulate_surface(
    mut surface: impl FnMut([f32; 2]) -> [f32; 3],
    mut colour: impl FnMut([f32; 2], [f32; 3]) -> [f32; 4],
    settings: &SurfaceSettings,
) -> Result<Mesh, ParametricError> {
    let vertices_max = checked_vertices_max(settings)?;
    let d = settings.domain;
    let n = settings.initial_divisions;
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut uvs: Vec<[f32; 2]> = Vec::new();
    let lerp = |r: (f32, f32), i: u32| r.0 + (r.1 - r.0) * i as f32 / n as f32;
    let mut grid = Vec::with_capacity(((n + 1) * (n + 1)) as usize);
    for j in 0..=n {
        for i in 0..=n {
            let uv = [lerp(d.u, i), lerp(d.v, j)];
            grid.push(insert_uv(
                &mut cdt,
                &mut positions,
                &mut uvs,
                &mut surface,
                uv,
            )?);
        }
    }
    // The boundary, walked around the rectangle, becomes constraint edges.
    let at = |i: u32, j: u32| grid[(i + (n + 1) * j) as usize];
    let boundary: Vec<FixedVertexHandle> = (0..n)
        .map(|i| at(i, 0))
        .chain((0..n).map(|j| at(n, j)))
        .chain((1..=n).rev().map(|i| at(i, n)))
        .chain((1..=n).rev().map(|j| at(0, j)))
        .collect();
    for (k, &h) in boundary.iter().enumerate() {
        cdt.add_constraint(h, boundary[(k + 1) % boundary.len()]);
    }
    for _ in 0..MAX_REFINE_ROUNDS {
        let splits = edges_to_split(&cdt, &positions, &uvs, &mut surface, settings.tolerance);
        if splits.is_empty() || positions.len() >= vertices_max {
            break;
        }
        for m in splits.into_iter().take(vertices_max - positions.len()) {
            insert_uv(&mut cdt, &mut positions, &mut uvs, &mut surface, m)?;
        }
    }
    let indices = cdt
        .inner_faces()
        .flat_map(|f| f.vertices().map(|v| v.fix().index() as u32))
        .collect();
    let colours = uvs
        .iter()
        .zip(&positions)
        .map(|(&uv, &p)| colour(uv, p))
        .collect();
    let mut mesh = Mesh {
        positions,
        colours,
        indices,
        ..Mesh::default()
    };
    mesh.recompute_normals();
    Ok(mesh)
}

/// The vertex budget of a surface's settings, or the setting that is out of range.
fn checked_vertices_max(settings: &SurfaceSettings) -> Result<usize, ParametricError> {
    let d = settings.domain;
    let finite = [d.u.0, d.u.1, d.v.0, d.v.1].iter().all(|x| x.is_finite());
    if !(finite && d.u.0 < d.u.1 && d.v.0 < d.v.1) {
        return Err(ParametricError::BadSetting(
            "domain must be a finite, non-empty rectangle",
        ));
    }
    if settings.initial_divisions == 0 || settings.initial_divisions > MAX_INITIAL_DIVISIONS {
        return Err(ParametricError::BadSetting(
            "initial_divisions out of range",
        ));
    }
    if settings.tolerance.is_nan() || settings.tolerance <= 0.0 {
        return Err(ParametricError::BadSetting("tolerance must be positive"));
    }
    Ok(settings
        .vertices_max
        .min(MAX_PARAMETRIC_VERTICES)
        .min(MAX_INDEXED_VERTICES))
}

/// The (u,v) midpoints of the edges whose chord strays from the surface by more than
/// `tolerance`.
fn edges_to_split(
    cdt: &ConstrainedDelaunayTriangulation<Point2<f64>>,
    positions: &[[f32; 3]],
    uvs: &[[f32; 2]],
    surface: &mut impl FnMut([f32; 2]) -> [f32; 3],
    tolerance: f32,
) -> Vec<[f32; 2]> {
    let mut splits = Vec::new();
    for e in cdt.undirected_edges() {
        let [a, b] = e.vertices().map(|v| v.fix().index());
        let m = [0.5 * (uvs[a][0] + uvs[b][0]), 0.5 * (uvs[a][1] + uvs[b][1])];
        let chord: [f32; 3] = std::array::from_fn(|k| 0.5 * (positions[a][k] + positions[b][k]));
        let p = surface(m);
        let err2: f32 = (0..3).map(|k| (p[k] - chord[k]).powi(2)).sum();
        if err2 > tolerance * tolerance {
            splits.push(m);
        }
    }
    splits
}

/// Inserts a (u,v) point, evaluating p there when the vertex is new.
fn insert_uv(
    cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>,
    positions: &mut Vec<[f32; 3]>,
    uvs: &mut Vec<[f32; 2]>,
    surface: &mut impl FnMut([f32; 2]) -> [f32; 3],
    uv: [f32; 2],
) -> Result<FixedVertexHandle, ParametricError> {
    let h = cdt
        .insert(Point2::new(f64::from(uv[0]), f64::from(uv[1])))
        .map_err(|e| ParametricError::Triangulation(format!("{e:?}")))?;
    if h.index() == positions.len() {
        positions.push(surface(uv));
        uvs.push(uv);
    }
    Ok(h)
}

/// Sweeps a closed, capped tube of `settings.radius` along p(u), colouring with `colour(u, p)`.
pub fn tube(
    mut curve: impl FnMut(f32) -> [f32; 3],
    mut colour: impl FnMut(f32, [f32; 3]) -> [f32; 4],
    settings: &TubeSettings,
) -> Result<Mesh, ParametricError> {
    let (u0, u1) = settings.domain;
    if !(u0.is_finite() && u1.is_finite() && u0 < u1) {
        return Err(ParametricError::BadSetting(
            "domain must be finite and non-empty",
        ));
    }
    if !(settings.radius > 0.0 && settings.tolerance > 0.0) {
        return Err(ParametricError::BadSetting(
            "radius and tolerance must be positive",
        ));
    }
    if !(3..=MAX_TUBE_SIDES).contains(&settings.n_sides) {
        return Err(ParametricError::BadSetting("n_sides out of range"));
    }
    if settings.initial_divisions == 0 || settings.initial_divisions > MAX_INITIAL_DIVISIONS {
        return Err(ParametricError::BadSetting(
            "initial_divisions out of range",
        ));
    }
    let n_sides = settings.n_sides as usize;
    let samples_max = settings
        .samples_max
        .min((MAX_PARAMETRIC_VERTICES - 2) / n_sides)
        .max(2);
    let n0 = settings.initial_divisions;
    let mut us: Vec<f32> = (0..=n0)
        .map(|i| u0 + (u1 - u0) * i as f32 / n0 as f32)
        .collect();
    let mut ps: Vec<[f32; 3]> = us.iter().map(|&u| curve(u)).collect();
    for _ in 0..MAX_REFINE_ROUNDS {
        let mut next_u = vec![us[0]];
        let mut next_p = vec![ps[0]];
        let mut split = false;
        for i in 0..us.len() - 1 {
            if next_u.len() + (us.len() - i) < samples_max {
                let m = 0.5 * (us[i] + us[i + 1]);
                let pm = curve(m);
                let err2: f32 = (0..3)
                    .map(|k| (pm[k] - 0.5 * (ps[i][k] + ps[i + 1][k])).powi(2))
                    .sum();
                if err2 > settings.tolerance * settings.tolerance {
                    next_u.push(m);
                    next_p.push(pm);
                    split = true;
                }
            }
            next_u.push(us[i + 1]);
            next_p.push(ps[i + 1]);
        }
        (us, ps) = (next_u, next_p);
        if !split {
            break;
        }
    }
    Ok(sweep(&us, &ps, &mut colour, settings.radius, n_sides))
}

/// Builds rings around the samples with parallel-transported frames, then caps both ends.
fn sweep(
    us: &[f32],
    ps: &[[f32; 3]],
    colour: &mut impl FnMut(f32, [f32; 3]) -> [f32; 4],
    radius: f32,
    n_sides: usize,
) -> Mesh {
    let n = ps.len();
    let sub = |a: [f32; 3], b: [f32; 3]| -> [f32; 3] { std::array::from_fn(|k| a[k] - b[k]) };
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let tangents: Vec<[f32; 3]> = (0..n)
        .map(|i| normalise_or_up(sub(ps[(i + 1).min(n - 1)], ps[i.saturating_sub(1)])))
        .collect();
    // Any vector not parallel to the first tangent starts the frame.
    let t0 = tangents[0];
    let seed = if t0[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let mut normal = normalise_or_up(cross(cross(t0, seed), t0));
    let mut mesh = Mesh::default();
    for i in 0..n {
        let t = tangents[i];
        normal = normalise_or_up(sub(normal, t.map(|c| c * dot(normal, t))));
        let binormal = cross(t, normal);
        for j in 0..n_sides {
            let theta = std::f32::consts::TAU * j as f32 / n_sides as f32;
            let dir: [f32; 3] =
                std::array::from_fn(|k| theta.cos() * normal[k] + theta.sin() * binormal[k]);
            let p: [f32; 3] = std::array::from_fn(|k| ps[i][k] + radius * dir[k]);
            mesh.positions.push(p);
            mesh.normals.push(dir);
            mesh.colours.push(colour(us[i], p));
        }
    }
    let ring = |i: usize, j: usize| (i * n_sides + j % n_sides) as u32;
    for i in 0..n - 1 {
        for j in 0..n_sides {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j + 1),
                ring(i + 1, j),
            );
            mesh.indices.extend([a, b, c, a, c, d]);
        }
    }
    cap_ends(&mut mesh, us, ps, &tangents, colour, n_sides);
    mesh
}

/// Closes both ends of a swept tube with a fan around the end sample, facing along the
/// tangent outwards.
fn cap_ends(
    mesh: &mut Mesh,
    us: &[f32],
    ps: &[[f32; 3]],
    tangents: &[[f32; 3]],
    colour: &mut impl FnMut(f32, [f32; 3]) -> [f32; 4],
    n_sides: usize,
) {
    let ring = |i: usize, j: usize| (i * n_sides + j % n_sides) as u32;
    for (end, sign) in [(0usize, -1.0f32), (ps.len() - 1, 1.0)] {
        let centre = mesh.positions.len() as u32;
        mesh.positions.push(ps[end]);
        mesh.normals.push(tangents[end].map(|c| c * sign));
        mesh.colours.push(colour(us[end], ps[end]));
        for j in 0..n_sides {
            let (a, b) = (ring(end, j), ring(end, j + 1));
            mesh.indices.extend(if sign < 0.0 {
                [centre, b, a]
            } else {
                [centre, a, b]
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    fn sphere(uv: [f32; 2]) -> [f32; 3] {
        let (theta, phi) = (uv[0] * PI, uv[1] * PI);
        [phi.sin() * theta.cos(), phi.sin() * theta.sin(), phi.cos()]
    }

    fn patch_settings(tolerance: f32) -> SurfaceSettings {
        SurfaceSettings {
            domain: UvDomain {
                u: (0.0, 1.0),
                v: (0.2, 0.8),
            },
            initial_divisions: 2,
            tolerance,
            vertices_max: 100_000,
        }
    }

    #[test]
    fn sphere_patch_vertices_lie_on_the_sphere_and_refinement_adapts() {
        let coarse = triangulate_surface(sphere, |_, _| [1.0; 4], &patch_settings(0.01)).unwrap();
        let fine = triangulate_surface(sphere, |_, _| [1.0; 4], &patch_settings(0.001)).unwrap();
        for m in [&coarse, &fine] {
            assert_eq!(m.validate(), Ok(()));
            assert_eq!(m.non_manifold_edges(), 0);
            for p in &m.positions {
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                assert!((r - 1.0).abs() < 1e-5, "vertex {p:?} at radius {r}");
            }
        }
        assert!(
            coarse.n_triangles() > 8,
            "coarse patch was not refined: {}",
            coarse.n_triangles()
        );
        assert!(
            fine.n_triangles() > 3 * coarse.n_triangles(),
            "{} vs {}",
            fine.n_triangles(),
            coarse.n_triangles()
        );
        // Chord error shrinks with the tolerance: check triangle centroids' distance to the sphere.
        let worst = |m: &Mesh| {
            m.triangles()
                .map(|t| {
                    let c: [f32; 3] = std::array::from_fn(|k| {
                        t.iter().map(|&i| m.positions[i as usize][k]).sum::<f32>() / 3.0
                    });
                    1.0 - (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
                })
                .fold(0.0f32, f32::max)
        };
        assert!(worst(&fine) < worst(&coarse));
        assert!(worst(&fine) < 0.005, "worst chord error {}", worst(&fine));
    }

    #[test]
    fn a_plane_is_not_refined_and_colour_comes_from_the_closure() {
        let m = triangulate_surface(
            |uv| [uv[0], uv[1], 0.0],
            |uv, _| [uv[0], uv[1], 0.0, 1.0],
            &patch_settings(0.001),
        )
        .unwrap();
        assert_eq!(m.n_vertices(), 9);
        assert_eq!(m.n_triangles(), 8);
        assert_eq!(m.open_edges(), 8);
        for (p, c) in m.positions.iter().zip(&m.colours) {
            assert_eq!([p[0], p[1]], [c[0], c[1]]);
        }
        // Counter-clockwise in (u,v) means the normal is du x dv = +z.
        assert!(m.normals.iter().all(|n| n[2] > 0.99));
    }

    #[test]
    fn helix_tube_is_closed_manifold_at_its_radius() {
        let helix = |u: f32| [u.cos(), u.sin(), 0.2 * u];
        let settings = TubeSettings {
            domain: (0.0, 4.0 * PI),
            radius: 0.1,
            n_sides: 12,
            initial_divisions: 4,
            tolerance: 0.005,
            samples_max: 10_000,
        };
        let m = tube(helix, |u, _| [u, 0.0, 0.0, 1.0], &settings).unwrap();
        assert_eq!(m.validate(), Ok(()));
        assert_eq!(m.open_edges(), 0);
        assert_eq!(m.non_manifold_edges(), 0);
        assert!(m.signed_volume() > 0.0, "tube is inside out");
        let n_rings = (m.n_vertices() - 2) / 12;
        assert!(n_rings > 40, "helix was not refined: {n_rings} rings");
        // Every ring vertex is one radius from the axis sample it was built around.
        for i in 0..n_rings {
            let ring = &m.positions[i * 12..(i + 1) * 12];
            let centre: [f32; 3] =
                std::array::from_fn(|k| ring.iter().map(|p| p[k]).sum::<f32>() / 12.0);
            for p in ring {
                let r = (0..3)
                    .map(|k| (p[k] - centre[k]).powi(2))
                    .sum::<f32>()
                    .sqrt();
                assert!((r - 0.1).abs() < 1e-4, "ring {i} radius {r}");
            }
        }
        let straight = tube(
            |u| [u, 0.0, 0.0],
            |_, _| [1.0; 4],
            &TubeSettings {
                domain: (0.0, 1.0),
                ..settings
            },
        )
        .unwrap();
        assert_eq!(
            (straight.n_vertices() - 2) / 12,
            5,
            "a straight line needs no refinement"
        );
    }

    #[test]
    fn bad_settings_are_errors() {
        let mut s = patch_settings(0.01);
        s.domain.u = (1.0, 0.0);
        assert!(matches!(
            triangulate_surface(sphere, |_, _| [1.0; 4], &s),
            Err(ParametricError::BadSetting(_))
        ));
        let t = TubeSettings {
            domain: (0.0, 1.0),
            radius: 0.1,
            n_sides: 2,
            initial_divisions: 1,
            tolerance: 0.1,
            samples_max: 10,
        };
        assert!(matches!(
            tube(|u| [u, 0.0, 0.0], |_, _| [1.0; 4], &t),
            Err(ParametricError::BadSetting(_))
        ));
    }
}
