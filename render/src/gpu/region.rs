//! Where a prepare changed the picture below the lines: nowhere, everywhere, or within a
//! rectangle of pixels that bounds the triangles an object's mesh patch changed.
//!
//! A patch rewrites ranges of vertices and triangles. The pixels it may change are those of
//! every triangle that differs, before or after: the triangles in its written ranges, those
//! past the shorter of the two triangle counts, and any triangle using a vertex it wrote (its
//! other vertices may lie far from the patch). Their corners, old and new, bound them in the
//! object's space; the box's eight corners projected to the screen bound the pixels, as long
//! as all lie in front of the eye (a box partly behind it changes everything).

use crate::mesh::Mesh;
use glam::{Mat4, Vec3};
use std::ops::Range;

/// Pixels around a projected box, beyond its extent, for rounding and rasterisation rules.
const MARGIN_PX: f32 = 2.0;
/// Least clip-space w of a corner that counts as in front of the eye.
const MIN_CLIP_W: f32 = 1e-5;

/// What changed below the lines since a kept picture last drew it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Below {
    /// Nothing.
    Same,
    /// The pixels in `[x0, x1) x [y0, y1)`, no others.
    Region([u32; 4]),
    /// Anything.
    All,
}

impl Below {
    /// What changed in `self` or `other`.
    pub(super) fn join(self, other: Below) -> Below {
        match (self, other) {
            (Below::All, _) | (_, Below::All) => Below::All,
            (Below::Same, b) | (b, Below::Same) => b,
            (Below::Region(a), Below::Region(b)) => Below::Region([
                a[0].min(b[0]),
                a[1].min(b[1]),
                a[2].max(b[2]),
                a[3].max(b[3]),
            ]),
        }
    }
}

/// The screen a frame is drawn to: the camera's projection and the picture's size.
#[derive(Clone, Copy)]
pub(super) struct Screen {
    pub view_proj: Mat4,
    pub size_px: [u32; 2],
}

impl Screen {
    /// The pixels an object placed by `world_from_object` may change within `bounds` (its
    /// space): [`Below::Same`] when none is on screen, [`Below::All`] when the box reaches
    /// behind the eye.
    pub(super) fn region(&self, world_from_object: Mat4, bounds: [Vec3; 2]) -> Below {
        let clip_from_object = self.view_proj * world_from_object;
        let size = [self.size_px[0] as f32, self.size_px[1] as f32];
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for k in 0..8 {
            let pick = |axis: usize| {
                if k & (1 << axis) == 0 {
                    bounds[0]
                } else {
                    bounds[1]
                }
            };
            let corner = Vec3::new(pick(0).x, pick(1).y, pick(2).z);
            let clip = clip_from_object * corner.extend(1.0);
            if !clip.is_finite() || clip.w <= MIN_CLIP_W {
                return Below::All;
            }
            let px = [
                (clip.x / clip.w * 0.5 + 0.5) * size[0],
                (0.5 - clip.y / clip.w * 0.5) * size[1],
            ];
            for a in 0..2 {
                lo[a] = lo[a].min(px[a]);
                hi[a] = hi[a].max(px[a]);
            }
        }
        let clamp = |v: f32, a: usize| v.clamp(0.0, size[a]) as u32;
        let [x0, y0] = [0, 1].map(|a| clamp((lo[a] - MARGIN_PX).floor(), a));
        let [x1, y1] = [0, 1].map(|a| clamp((hi[a] + MARGIN_PX).ceil(), a));
        if x0 >= x1 || y0 >= y1 {
            Below::Same
        } else {
            Below::Region([x0, y0, x1, y1])
        }
    }
}

/// The box, in the mesh's space, of every triangle that differs between `base` and `mesh`
/// when `mesh` is `base` with `vertex_ranges` and `triangle_ranges` written (see the module
/// documentation); `None` when none differs.
///
/// A triangle the patch wrote as it was (the same corners, normals and colours, through
/// vertices that moved in the buffer) is not counted: it covers the same pixels alike.
pub(super) fn patch_bounds(
    base: &Mesh,
    mesh: &Mesh,
    vertex_ranges: &[Range<usize>],
    triangle_ranges: &[Range<usize>],
) -> Option<[Vec3; 2]> {
    let mut written = vec![false; mesh.n_vertices().max(base.n_vertices())];
    for r in vertex_ranges {
        written[r.clone()].fill(true);
    }
    let mut in_range = vec![false; mesh.n_triangles().max(base.n_triangles())];
    for r in triangle_ranges {
        in_range[r.clone()].fill(true);
    }
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    let mut add = |m: &Mesh, t: usize| {
        for &v in &m.indices[3 * t..3 * t + 3] {
            let p = Vec3::from_array(m.positions[v as usize]);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    };
    let uses_written = |m: &Mesh, t: usize| {
        (m.indices[3 * t..3 * t + 3].iter()).any(|&v| written.get(v as usize) == Some(&true))
    };
    for (t, &ranged) in in_range.iter().enumerate() {
        let (old, new) = (t < base.n_triangles(), t < mesh.n_triangles());
        let touched = ranged || (old && uses_written(base, t)) || (new && uses_written(mesh, t));
        let differs = old != new || (touched && !same_triangle(base, mesh, t));
        if differs {
            if old {
                add(base, t);
            }
            if new {
                add(mesh, t);
            }
        }
    }
    (lo.cmple(hi).all()).then_some([lo, hi])
}

/// Whether triangle `t` of `a` and of `b` draw alike: corner by corner the same position,
/// normal, colour and ambient colour.
fn same_triangle(a: &Mesh, b: &Mesh, t: usize) -> bool {
    let corner = |m: &Mesh, k: usize| {
        let v = m.indices[3 * t + k] as usize;
        (
            m.positions[v],
            m.normals[v],
            m.colours[v],
            m.ambient.get(v).copied(),
        )
    };
    (0..3).all(|k| corner(a, k) == corner(b, k))
}

#[cfg(test)]
#[allow(
    clippy::single_range_in_vec_init,
    reason = "the ranges are a patch's, one range each here"
)]
mod tests {
    use super::*;

    fn square(at: f32) -> Mesh {
        Mesh {
            positions: vec![
                [at, 0.0, 0.0],
                [at + 1.0, 0.0, 0.0],
                [at, 1.0, 0.0],
                [9.0, 9.0, 9.0],
            ],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            colours: vec![[1.0; 4]; 4],
            ambient: Vec::new(),
            indices: vec![0, 1, 2, 1, 3, 2],
        }
    }

    #[test]
    fn a_moved_vertex_bounds_every_triangle_that_uses_it_before_and_after() {
        let base = square(0.0);
        let mut mesh = base.clone();
        mesh.positions[1] = [0.5, -2.0, 0.0];
        // Vertex 1 alone written: both triangles use it, the second reaches the far vertex.
        let b = patch_bounds(&base, &mesh, &[1..2], &[]).unwrap();
        assert_eq!(b, [Vec3::new(0.0, -2.0, 0.0), Vec3::new(9.0, 9.0, 9.0)]);
        // Nothing written: nothing differs.
        assert_eq!(patch_bounds(&base, &base, &[], &[]), None);
        // A triangle rewritten to other vertices: its old and new corners.
        let mut fewer = base.clone();
        fewer.indices = vec![0, 2, 1];
        let b = patch_bounds(&base, &fewer, &[], &[0..1]).unwrap();
        assert_eq!(
            b,
            [Vec3::ZERO, Vec3::new(9.0, 9.0, 9.0)],
            "the dropped triangle counts"
        );
        // A vertex copied to a new slot and a triangle rewritten to use it: it draws alike,
        // so nothing differs, until the copy's colour changes.
        let mut moved = base.clone();
        moved.positions.push(moved.positions[0]);
        moved.normals.push(moved.normals[0]);
        moved.colours.push(moved.colours[0]);
        moved.indices[0] = 4;
        assert_eq!(patch_bounds(&base, &moved, &[4..5], &[0..1]), None);
        moved.colours[4] = [0.5; 4];
        let b = patch_bounds(&base, &moved, &[4..5], &[0..1]).unwrap();
        assert_eq!(
            b,
            [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)],
            "a new colour shows"
        );
    }

    #[test]
    fn regions_join_and_a_box_behind_the_eye_is_everything() {
        let a = Below::Region([1, 2, 3, 4]);
        assert_eq!(a.join(Below::Same), a);
        assert_eq!(
            a.join(Below::Region([0, 3, 2, 9])),
            Below::Region([0, 2, 3, 9])
        );
        assert_eq!(a.join(Below::All), Below::All);
        let camera = crate::camera::Camera {
            distance: 5.0,
            ..Default::default()
        };
        let eye = camera.eye();
        let screen = Screen {
            view_proj: camera.view_projection(1.0),
            size_px: [100, 100],
        };
        let centre = screen.region(Mat4::IDENTITY, [Vec3::splat(-0.1), Vec3::splat(0.1)]);
        let Below::Region([x0, y0, x1, y1]) = centre else {
            panic!("{centre:?}");
        };
        assert!(
            x0 < 50 && 50 < x1 && y0 < 50 && 50 < y1 && x1 - x0 < 20,
            "{centre:?}"
        );
        let behind = [eye - Vec3::splat(0.1), eye + Vec3::splat(0.1)];
        assert_eq!(screen.region(Mat4::IDENTITY, behind), Below::All);
        let side = eye.cross(Vec3::Z).normalize() * 40.0;
        let aside = [side, side + Vec3::ONE];
        assert_eq!(screen.region(Mat4::IDENTITY, aside), Below::Same);
    }
}
