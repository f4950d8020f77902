//! The history workload shared by the `history` bench and the `history_pair` example: the
//! unit sphere with N small random strokes, and the random points and boxes they are sampled
//! at.

use glam::DVec3;
use model::bvh::Aabb;
use model::object::{Edit, EditOp, Object, PaintValue, Paintable, Pose, ToolShape};

/// Points (and boxes) per sample.
pub const N_POINTS: usize = 4096;

/// A small deterministic generator (xorshift64*), so every run sees the same object.
pub struct Rng(pub u64);

impl Rng {
    /// The next number in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A point in the cube of half-size `half` about the origin.
    pub fn in_cube(&mut self, half: f64) -> DVec3 {
        DVec3::new(self.next(), self.next(), self.next()) * (2.0 * half) - DVec3::splat(half)
    }
}

/// The unit sphere with `n` strokes of 4 poses (balls of radius 0.01 and rounded boxes of
/// half-size 0.008 at random places in [-1, 1]^3; 2/5 unions, 2/5 carves, 1/5 colour paint),
/// indexed.
pub fn object_with_edits(n: usize) -> Object {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut object = Object::implicit("1 - x^2 - y^2 - z^2").expect("sphere compiles");
    for i in 0..n {
        let start = rng.in_cube(1.0);
        let path: Vec<Pose> = (0..4)
            .map(|k| Pose::at(start + DVec3::new(0.01 * k as f64, 0.005 * k as f64, 0.0)))
            .collect();
        let op = match i % 5 {
            0 | 1 => EditOp::Union,
            2 | 3 => EditOp::Subtract,
            _ => EditOp::Paint {
                property: Paintable::Color,
                value: PaintValue::Color([1.0, 0.0, 0.0]),
            },
        };
        let tool = if i % 2 == 0 {
            ToolShape::Sphere { radius: 0.01 }
        } else {
            ToolShape::Box {
                half_extents: DVec3::splat(0.008),
                rounding: 0.002,
            }
        };
        object
            .apply(Edit::stroke(op, tool, path))
            .expect("edits are valid");
    }
    object.prepare();
    object
}

/// [`N_POINTS`] random points in [-1.1, 1.1]^3.
pub fn points() -> Vec<DVec3> {
    let mut rng = Rng(0x1234_5678);
    (0..N_POINTS).map(|_| rng.in_cube(1.1)).collect()
}

/// Boxes of edge 1/32 (an octree's finer levels over the object), one around each point.
pub fn boxes() -> Vec<Aabb> {
    points()
        .into_iter()
        .map(|p| Aabb::around(p, DVec3::splat(1.0 / 64.0)))
        .collect()
}
