//! The haptic zone: a movable, resizable box that maps the device workspace into the scene.

use glam::{DQuat, DVec3};

use crate::aabb::Aabb;

/// Maps device coordinates (metres) into world coordinates: `world = center + rotation *
/// ((device - workspace_center) * world_per_device_metre)`.
///
/// Forces stay in device units: a penetration of `d` world units is `d /
/// world_per_device_metre` metres at the tip, so stiffness is scaled with the zone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HapticZone {
    /// Where the workspace centre lands in the world.
    pub center_world: DVec3,
    /// World units per device metre (uniform scale, > 0).
    pub world_per_device_metre: f64,
    /// Orientation of the zone in the world.
    pub rotation: DQuat,
    /// Centre of the device workspace, device frame.
    pub workspace_center_device: DVec3,
}

impl HapticZone {
    /// The largest zone of the same shape as `workspace` that fits in `box_world`, centred in it.
    pub fn fit(workspace: Aabb, box_world: Aabb) -> Self {
        let ws = workspace.size().max(DVec3::splat(f64::MIN_POSITIVE));
        let scale = (box_world.size() / ws).min_element().max(f64::MIN_POSITIVE);
        Self {
            center_world: box_world.center(),
            world_per_device_metre: scale,
            rotation: DQuat::IDENTITY,
            workspace_center_device: workspace.center(),
        }
    }

    /// The zone moved by `delta_world`.
    pub fn moved_by(self, delta_world: DVec3) -> Self {
        Self {
            center_world: self.center_world + delta_world,
            ..self
        }
    }

    /// The zone scaled about its centre by `factor` (> 0).
    pub fn resized(self, factor: f64) -> Self {
        assert!(factor > 0.0 && factor.is_finite(), "zone factor {factor}");
        Self {
            world_per_device_metre: self.world_per_device_metre * factor,
            ..self
        }
    }

    /// A device position in world coordinates.
    pub fn world_from_device(&self, p_device: DVec3) -> DVec3 {
        self.center_world
            + self.rotation
                * ((p_device - self.workspace_center_device) * self.world_per_device_metre)
    }

    /// A world point in device coordinates: the inverse of [`HapticZone::world_from_device`].
    pub fn device_from_world(&self, p_world: DVec3) -> DVec3 {
        self.workspace_center_device
            + self.rotation.inverse() * (p_world - self.center_world) / self.world_per_device_metre
    }

    /// A world direction (or force) in device axes.
    pub fn device_from_world_dir(&self, v_world: DVec3) -> DVec3 {
        self.rotation.inverse() * v_world
    }

    /// A world distance in device metres.
    pub fn device_metres(&self, world_distance: f64) -> f64 {
        world_distance / self.world_per_device_metre
    }

    /// A distance in device metres in world units: the inverse of
    /// [`HapticZone::device_metres`].
    pub fn world_distance(&self, device_metres: f64) -> f64 {
        device_metres * self.world_per_device_metre
    }

    /// The world box the device workspace covers (for drawing the zone).
    pub fn box_world(&self, workspace: Aabb) -> Aabb {
        let corners = [workspace.min, workspace.max].map(|c| self.world_from_device(c));
        let mut lo = corners[0].min(corners[1]);
        let mut hi = corners[0].max(corners[1]);
        for k in 0..8 {
            let pick = |bit: usize, axis: usize| {
                if k & bit == 0 {
                    workspace.min[axis]
                } else {
                    workspace.max[axis]
                }
            };
            let c = self.world_from_device(DVec3::new(pick(1, 0), pick(2, 1), pick(4, 2)));
            lo = lo.min(c);
            hi = hi.max(c);
        }
        Aabb::new(lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_maps_workspace_corners_into_the_box() {
        let ws = Aabb::new(DVec3::splat(-0.1), DVec3::splat(0.1));
        let target = Aabb::new(DVec3::new(0.0, 0.0, 0.0), DVec3::new(4.0, 2.0, 8.0));
        let zone = HapticZone::fit(ws, target);
        assert_eq!(zone.world_per_device_metre, 10.0);
        assert_eq!(
            zone.world_from_device(DVec3::ZERO),
            DVec3::new(2.0, 1.0, 4.0)
        );
        let b = zone.box_world(ws);
        assert!((b.min - DVec3::new(1.0, 0.0, 3.0)).length() < 1e-12);
        assert!(target.contains(b.min) && target.contains(b.max));
        let moved = zone.moved_by(DVec3::X).resized(0.5);
        assert_eq!(
            moved.world_from_device(DVec3::splat(0.1)),
            DVec3::new(3.5, 1.5, 4.5)
        );
        assert_eq!(moved.device_metres(0.5), 0.1);
        assert_eq!(moved.world_distance(0.1), 0.5);
        let turned = HapticZone {
            rotation: DQuat::from_rotation_y(0.7),
            ..moved
        };
        let p = DVec3::new(0.03, -0.02, 0.05);
        let back = turned.device_from_world(turned.world_from_device(p));
        assert!((back - p).length() < 1e-12, "{back} vs {p}");
    }
}
