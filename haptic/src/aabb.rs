//! [`Aabb`], the axis-aligned box the crate's layers share: a device's workspace (metres), a
//! container's bounds and a haptic zone's box (world units).

use glam::DVec3;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: DVec3,
    /// Largest corner.
    pub max: DVec3,
}

impl Aabb {
    /// A box from two corners (`min <= max` per axis).
    pub fn new(min: DVec3, max: DVec3) -> Self {
        assert!(min.cmple(max).all(), "Aabb::new: min {min} > max {max}");
        Self { min, max }
    }

    /// The box centre.
    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    /// Edge lengths.
    pub fn size(&self) -> DVec3 {
        self.max - self.min
    }

    /// True when `p` is inside or on the box.
    pub fn contains(&self, p: DVec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The nearest point of the box to `p`.
    pub fn clamp(&self, p: DVec3) -> DVec3 {
        p.clamp(self.min, self.max)
    }
}
