//! Tests of the octree mesher against closed-form fields.

use super::*;

mod sharp;

/// Interval of |x - c| for x in lo..=hi.
fn abs_interval(lo: f32, hi: f32, c: f32) -> (f32, f32) {
    let (a, b) = (lo - c, hi - c);
    let max = a.abs().max(b.abs());
    let min = if a <= 0.0 && b >= 0.0 {
        0.0
    } else {
        a.abs().min(b.abs())
    };
    (min, max)
}

#[derive(Clone)]
struct Sphere {
    centre: [f32; 3],
    radius: f32,
}

impl Sphere {
    fn at(&self, p: [f32; 3]) -> f32 {
        let d: f32 = (0..3).map(|a| (p[a] - self.centre[a]).powi(2)).sum();
        self.radius - d.sqrt()
    }
}

impl Field for Sphere {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let r: [(f32, f32); 3] =
            std::array::from_fn(|a| abs_interval(lo[a], hi[a], self.centre[a]));
        let dmin = r.iter().map(|(l, _)| l * l).sum::<f32>().sqrt();
        let dmax = r.iter().map(|(_, h)| h * h).sum::<f32>().sqrt();
        (self.radius - dmax, self.radius - dmin)
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        for i in 0..xs.len() {
            out[i] = self.at([xs[i], ys[i], zs[i]]);
        }
    }
}

/// An axis-aligned box solid: min over axes of (half - |x - c|).
#[derive(Clone)]
struct Cuboid {
    centre: [f32; 3],
    half: [f32; 3],
}

impl Field for Cuboid {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let mut out = (f32::INFINITY, f32::INFINITY);
        for a in 0..3 {
            let (l, h) = abs_interval(lo[a], hi[a], self.centre[a]);
            out = (out.0.min(self.half[a] - h), out.1.min(self.half[a] - l));
        }
        out
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        for i in 0..xs.len() {
            let p = [xs[i], ys[i], zs[i]];
            out[i] = (0..3)
                .map(|a| self.half[a] - (p[a] - self.centre[a]).abs())
                .fold(f32::INFINITY, f32::min);
        }
    }
}

/// Union (max) of two spheres; `simplify` drops a sphere that cannot matter in a box.
#[derive(Clone)]
struct Union {
    parts: Vec<Sphere>,
    simplifying: bool,
}

impl Field for Union {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        self.parts
            .iter_mut()
            .map(|s| s.interval(lo, hi))
            .fold((f32::NEG_INFINITY, f32::NEG_INFINITY), |a, b| {
                (a.0.max(b.0), a.1.max(b.1))
            })
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        for i in 0..xs.len() {
            out[i] = self
                .parts
                .iter()
                .map(|s| s.at([xs[i], ys[i], zs[i]]))
                .fold(f32::NEG_INFINITY, f32::max);
        }
    }
    fn simplify(&mut self, lo: [f32; 3], hi: [f32; 3]) -> Option<Self> {
        if !self.simplifying || self.parts.len() < 2 {
            return None;
        }
        let iv: Vec<(f32, f32)> = self.parts.iter_mut().map(|s| s.interval(lo, hi)).collect();
        let best_lo = iv.iter().map(|i| i.0).fold(f32::NEG_INFINITY, f32::max);
        // A part whose upper bound is below another's lower bound never wins the max.
        let keep: Vec<Sphere> = self
            .parts
            .iter()
            .zip(&iv)
            .filter(|(_, i)| i.1 >= best_lo)
            .map(|(s, _)| s.clone())
            .collect();
        (keep.len() < self.parts.len()).then_some(Union {
            parts: keep,
            simplifying: true,
        })
    }
}

fn unit_box() -> Aabb {
    Aabb::new([-1.0; 3], [1.0; 3])
}

fn assert_closed_manifold(m: &Mesh) {
    assert!(m.n_triangles() > 0, "empty mesh");
    assert_eq!(m.validate(), Ok(()));
    assert_eq!(m.open_edges(), 0, "open edges");
    assert_eq!(m.non_manifold_edges(), 0, "non-manifold edges");
    assert_eq!(m.degenerate_triangles(), 0, "degenerate triangles");
    assert_eq!(m.misoriented_edges(), 0, "inconsistent winding");
    assert!(m.signed_volume() > 0.0, "normals face inwards");
}

#[test]
fn sphere_is_watertight_manifold_outward_and_on_the_surface() {
    let mut s = Sphere {
        centre: [0.05, -0.02, 0.03],
        radius: 0.7,
    };
    let settings = MeshSettings {
        bounds: unit_box(),
        depth: 5,
    };
    let (m, stats) = mesh_with_stats(&mut s, &settings).unwrap();
    assert_closed_manifold(&m);
    let h = 2.0 / 32.0;
    for p in &m.positions {
        assert!(
            s.at(*p).abs() < 0.1 * h,
            "vertex {p:?} is {} off the surface",
            s.at(*p)
        );
    }
    let volume = m.signed_volume();
    let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.7f64.powi(3);
    assert!(
        (volume - exact).abs() < 0.02 * exact,
        "volume {volume} vs {exact}"
    );
    // Normals point away from the centre.
    for (p, n) in m.positions.iter().zip(&m.normals) {
        let radial: f32 = (0..3).map(|a| (p[a] - s.centre[a]) * n[a]).sum();
        assert!(radial > 0.0);
    }
    // 4^3 = 64 blocks of 8^3 cells exist; pruning must skip some.
    assert!(
        stats.blocks_evaluated < 64 && stats.nodes_pruned > 0,
        "{stats:?}"
    );
}

#[test]
fn box_keeps_its_sharp_corners_and_edges() {
    let mut b = Cuboid {
        centre: [0.013, 0.021, -0.017],
        half: [0.5, 0.4, 0.3],
    };
    let m = mesh(
        &mut b,
        &MeshSettings {
            bounds: unit_box(),
            depth: 5,
        },
    )
    .unwrap();
    assert_closed_manifold(&m);
    let h = 2.0 / 32.0;
    for k in 0..8 {
        let corner: [f32; 3] = std::array::from_fn(|a| {
            b.centre[a]
                + if k >> a & 1 == 1 {
                    b.half[a]
                } else {
                    -b.half[a]
                }
        });
        let nearest = m
            .positions
            .iter()
            .map(|p| {
                (0..3)
                    .map(|a| (p[a] - corner[a]).powi(2))
                    .sum::<f32>()
                    .sqrt()
            })
            .fold(f32::INFINITY, f32::min);
        assert!(nearest < 0.05 * h, "corner {corner:?} missed by {nearest}");
    }
    let exact = 8.0 * 0.5 * 0.4 * 0.3;
    assert!(
        (m.signed_volume() - exact).abs() < 1e-3,
        "volume {}",
        m.signed_volume()
    );
}

#[test]
fn union_of_two_spheres_is_one_closed_manifold_and_simplify_changes_nothing() {
    let parts = vec![
        Sphere {
            centre: [-0.3, 0.01, 0.02],
            radius: 0.45,
        },
        Sphere {
            centre: [0.35, -0.02, 0.01],
            radius: 0.4,
        },
    ];
    let settings = MeshSettings {
        bounds: unit_box(),
        depth: 6,
    };
    let mut plain = Union {
        parts: parts.clone(),
        simplifying: false,
    };
    let (a, sa) = mesh_with_stats(&mut plain, &settings).unwrap();
    assert_closed_manifold(&a);
    assert_eq!(sa.fields_simplified, 0);
    let mut simplifying = Union {
        parts,
        simplifying: true,
    };
    let (b, sb) = mesh_with_stats(&mut simplifying, &settings).unwrap();
    assert!(sb.fields_simplified > 0, "{sb:?}");
    assert_eq!(a, b, "a simplified field must give the same mesh");
}

#[test]
fn thin_plate_two_cells_thick_is_closed_and_manifold() {
    let h = 2.0 / 64.0;
    let mut plate = Cuboid {
        centre: [0.01, -0.01, 0.003],
        half: [0.6, 0.5, h],
    };
    let m = mesh(
        &mut plate,
        &MeshSettings {
            bounds: unit_box(),
            depth: 6,
        },
    )
    .unwrap();
    assert_closed_manifold(&m);
    for p in &m.positions {
        assert!(
            (p[2] - plate.centre[2]).abs() < h * 1.05,
            "vertex {p:?} off the plate"
        );
    }
}

#[test]
fn region_cutting_a_sphere_is_open_only_along_the_box() {
    let mut s = Sphere {
        centre: [0.0; 3],
        radius: 0.7,
    };
    let region = Aabb::new([0.0, -1.0, -1.0], [1.0, 1.0, 1.0]);
    let m = mesh(
        &mut s,
        &MeshSettings {
            bounds: region,
            depth: 5,
        },
    )
    .unwrap();
    assert!(m.open_edges() > 0);
    assert_eq!(m.non_manifold_edges(), 0);
    assert!(m.positions.iter().all(|p| region.contains(*p)));
}

#[test]
fn ambiguous_checkerboard_cells_stay_manifold() {
    // Many small spheres touching the grid diagonally create ambiguous faces.
    struct Bumps;
    impl Field for Bumps {
        fn interval(&mut self, _: [f32; 3], _: [f32; 3]) -> (f32, f32) {
            (f32::NAN, f32::NAN)
        }
        fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
            for i in 0..xs.len() {
                let (x, y, z) = (xs[i] * 9.0, ys[i] * 9.0, zs[i] * 9.0);
                let inner = x.sin() * y.sin() * z.sin() + 0.1;
                let shell = 0.8 - (xs[i] * xs[i] + ys[i] * ys[i] + zs[i] * zs[i]).sqrt();
                out[i] = inner.min(shell);
            }
        }
    }
    let m = mesh(
        &mut Bumps,
        &MeshSettings {
            bounds: unit_box(),
            depth: 4,
        },
    )
    .unwrap();
    assert_closed_manifold(&m);
}

#[test]
fn bad_settings_are_errors() {
    let mut s = Sphere {
        centre: [0.0; 3],
        radius: 0.5,
    };
    assert_eq!(
        mesh(
            &mut s,
            &MeshSettings {
                bounds: unit_box(),
                depth: 11
            }
        ),
        Err(OctreeMeshError::DepthTooLarge(11))
    );
    let flat = Aabb::new([0.0; 3], [1.0, 1.0, 0.0]);
    assert_eq!(
        mesh(
            &mut s,
            &MeshSettings {
                bounds: flat,
                depth: 3
            }
        ),
        Err(OctreeMeshError::BadBounds(flat))
    );
}

#[test]
fn remeshing_an_edit_box_equals_meshing_from_scratch() {
    let a = Sphere {
        centre: [-0.2, 0.01, 0.02],
        radius: 0.5,
    };
    let b = Sphere {
        centre: [0.45, 0.03, -0.01],
        radius: 0.3,
    };
    let settings = MeshSettings {
        bounds: unit_box(),
        depth: 5,
    };
    let mut mesher = OctreeMesher::new(&settings).unwrap();
    let full_stats = mesher.remesh(&mut a.clone(), settings.bounds).unwrap();
    let before = mesher.mesh().unwrap();
    assert_eq!(before, mesh(&mut a.clone(), &settings).unwrap());

    // The edit adds sphere b: only its bounding box changes.
    let edit = Aabb::new(
        b.centre.map(|c| c - b.radius),
        b.centre.map(|c| c + b.radius),
    );
    let mut edited = Union {
        parts: vec![a.clone(), b.clone()],
        simplifying: false,
    };
    let stats = mesher.remesh(&mut edited, edit).unwrap();
    let after = mesher.mesh().unwrap();
    assert_closed_manifold(&after);
    assert_eq!(
        after,
        mesh(&mut edited, &settings).unwrap(),
        "stitched remesh differs"
    );
    assert_ne!(after, before);
    assert!(
        stats.blocks_evaluated < full_stats.blocks_evaluated + full_stats.nodes_pruned,
        "{stats:?}"
    );
    assert!(
        stats.blocks_evaluated <= 27,
        "an edit of this size touches at most 3^3 blocks: {stats:?}"
    );

    // Undoing the edit over the same box restores the original mesh.
    mesher.remesh(&mut a.clone(), edit).unwrap();
    assert_eq!(mesher.mesh().unwrap(), before);
    // A box outside the bounds changes nothing.
    let outside = Aabb::new([5.0; 3], [6.0; 3]);
    assert_eq!(
        mesher.remesh(&mut edited, outside).unwrap(),
        MeshStats::default()
    );
}

/// Thin gyroid sheets inside a ball: tunnels through cells, so patches must be split.
struct GyroidShell {
    frequency: f32,
    thickness: f32,
}

impl Field for GyroidShell {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        // The gyroid term lies in [-1.5, 1.5]; the ball term bounds the rest.
        let mut ball = Sphere {
            centre: [0.0; 3],
            radius: 0.9,
        };
        let (b_lo, b_hi) = ball.interval(lo, hi);
        (
            (self.thickness - 1.5 / self.frequency).min(b_lo),
            self.thickness.min(b_hi),
        )
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        let k = self.frequency;
        for i in 0..xs.len() {
            let (x, y, z) = (xs[i] * k, ys[i] * k, zs[i] * k);
            let g = x.sin() * y.cos() + y.sin() * z.cos() + z.sin() * x.cos();
            let r = (xs[i] * xs[i] + ys[i] * ys[i] + zs[i] * zs[i]).sqrt();
            out[i] = (self.thickness - g.abs() / k).min(0.9 - r);
        }
    }
}

#[test]
fn thin_gyroid_sheets_are_closed_and_manifold_with_split_patches() {
    let mut n_split = 0;
    for depth in [4, 5, 6] {
        let mut g = GyroidShell {
            frequency: 9.0,
            thickness: 0.02,
        };
        let settings = MeshSettings {
            bounds: unit_box(),
            depth,
        };
        let (m, stats) = mesh_with_stats(&mut g, &settings).unwrap();
        assert_closed_manifold(&m);
        n_split += stats.patches_split;
    }
    assert!(n_split > 0, "no tunnel was met: the split path is untested");
}

/// An axis-aligned cube whose faces pass exactly through grid points, and whose simplified
/// copies (one per octree node) disagree with each other in value and at exact zeros, as
/// differently simplified tapes may: a positive bias on some boxes, a negative one on others.
///
/// With `widen` = 0 and the faces just off the grid points, interval arithmetic prunes boxes
/// whose faces a neighbour's biased values put inside: the f64-against-f32 disagreement.
#[derive(Clone)]
struct Disagreeing {
    half: f32,
    widen: f32,
    bias: f32,
    depth: u32,
}

impl Field for Disagreeing {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let mut c = Cuboid {
            centre: [0.0; 3],
            half: [self.half; 3],
        };
        let (l, h) = c.interval(lo, hi);
        (l - self.widen, h + self.widen)
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        for i in 0..xs.len() {
            let m = xs[i].abs().max(ys[i].abs()).max(zs[i].abs());
            // Values scaled per box too, so that saddles differ between blocks.
            out[i] = (self.half - m) * (1.0 + self.depth as f32) + self.bias;
        }
    }
    fn simplify(&mut self, lo: [f32; 3], hi: [f32; 3]) -> Option<Self> {
        // Neighbouring boxes of one size have opposite parities.
        let size = hi[0] - lo[0];
        let parity = ((lo[0] + lo[1] + lo[2]) / size).round() as i64 % 2;
        Some(Disagreeing {
            bias: if parity == 0 { 1e-6 } else { -1e-6 },
            depth: self.depth + 1,
            ..*self
        })
    }
}

#[test]
fn blocks_whose_fields_disagree_near_zero_still_stitch() {
    for (half, widen) in [(0.5, 1e-3), (0.5 - 1e-7, 0.0)] {
        for depth in [5, 6] {
            let settings = MeshSettings {
                bounds: unit_box(),
                depth,
            };
            let mut f = Disagreeing {
                half,
                widen,
                bias: 0.0,
                depth: 0,
            };
            let (m, stats) = mesh_with_stats(&mut f, &settings).unwrap();
            assert!(stats.fields_simplified > 0);
            // Faces just off the grid points let interval arithmetic prune next to them.
            assert!(widen > 0.0 || stats.nodes_pruned > 0, "{stats:?}");
            assert_closed_manifold(&m);
            let volume = m.signed_volume();
            assert!((volume - 1.0).abs() < 0.02, "{half} {widen}: {volume}");
        }
    }
}

#[test]
fn counting_blocks_by_intervals_gives_the_blocks_meshing_evaluates() {
    let spheres = Union {
        parts: vec![
            Sphere {
                centre: [-0.3, 0.01, 0.02],
                radius: 0.45,
            },
            Sphere {
                centre: [0.35, -0.02, 0.01],
                radius: 0.4,
            },
        ],
        simplifying: true,
    };
    for depth in [3, 5, 6] {
        let settings = MeshSettings {
            bounds: unit_box(),
            depth,
        };
        let (_, stats) = mesh_with_stats(&mut spheres.clone(), &settings).unwrap();
        let counted = count_blocks(&mut spheres.clone(), &settings).unwrap();
        assert_eq!(counted, stats.blocks_evaluated, "depth {depth}");
        assert!(counted > 0);
    }
    let bad = MeshSettings {
        bounds: unit_box(),
        depth: 11,
    };
    assert_eq!(
        count_blocks(&mut spheres.clone(), &bad),
        Err(OctreeMeshError::DepthTooLarge(11))
    );
}

#[test]
fn the_mesher_says_whether_the_surface_stays_inside_its_box() {
    use crate::mesh::n_open_edges;
    let settings = MeshSettings {
        bounds: unit_box(),
        depth: 5,
    };
    let inside_box = Sphere {
        centre: [0.1, -0.05, 0.0],
        radius: 0.5,
    };
    let leaving = Sphere {
        centre: [0.8, 0.0, 0.1],
        radius: 0.4,
    };
    let mut mesher = OctreeMesher::new(&settings).unwrap();
    mesher
        .remesh(&mut inside_box.clone(), settings.bounds)
        .unwrap();
    assert!(mesher.encloses());
    assert_eq!(n_open_edges(&mesher.mesh().unwrap()), 0);
    // The same mesher remeshed over the whole box with a sphere that leaves it, then back.
    mesher
        .remesh(&mut leaving.clone(), settings.bounds)
        .unwrap();
    assert!(!mesher.encloses());
    assert!(n_open_edges(&mesher.mesh().unwrap()) > 0);
    mesher
        .remesh(&mut inside_box.clone(), settings.bounds)
        .unwrap();
    assert!(mesher.encloses());
}
