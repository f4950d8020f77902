//! Haptic devices behind one trait: capabilities, sampling the tip pose and sending a force.
//!
//! Frames and units: positions are in metres in the device's own frame, forces in newtons in
//! the same frame. Implementations: [`sim::SimDevice`] (scripted hand on a spring),
//! [`mouse::MouseDevice`] (a desktop mouse driving the tip), [`trace::TraceDevice`] (replays a
//! recorded trace), and the HID drivers in [`hid`].

pub mod hid;
pub mod mouse;
pub mod sim;
pub mod trace;

use glam::{DQuat, DVec3};

use crate::aabb::Aabb;

/// What a device can do; the force renderer scales everything to stay within these limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capabilities {
    /// Degrees of freedom sensed (3 for position, 6 with orientation).
    pub n_dof_input: u8,
    /// Degrees of freedom actuated (0 for input-only devices, 3 for a force at the tip).
    pub n_dof_output: u8,
    /// The largest force the device can render, in newtons.
    pub force_newtons_max: f64,
    /// The largest stable stiffness of a virtual spring, in newtons per metre.
    pub stiffness_newtons_per_metre_max: f64,
    /// The largest stable viscous damping, in newton-seconds per metre.
    pub damping_newton_secs_per_metre_max: f64,
    /// The box the tip can reach, in metres in the device frame.
    pub workspace_metres: Aabb,
    /// Number of buttons reported in [`DeviceSample::buttons`].
    pub n_buttons: u8,
    /// The smallest motion of the tip the device senses, in metres (0 when unknown).
    pub position_resolution_metres: f64,
}

/// A surface zone the device's own limits set ([`Capabilities::zone_depth_metres`]) is at
/// least this many of its position steps deep, so that the tension's rise through the zone
/// is felt as a slope and not as a step.
pub const MIN_ZONE_DEPTH_STEPS: f64 = 16.0;
/// A surface zone the device's own limits set is at most this fraction of the workspace's
/// shortest side deep, so that a soft device's zone does not swallow what it touches.
pub const MAX_ZONE_DEPTH_WORKSPACE_FRACTION: f64 = 0.05;

impl Capabilities {
    /// A desktop pen-type device (about the size of a Phantom Omni / Touch).
    pub fn desktop_pen() -> Self {
        Self {
            n_dof_input: 6,
            n_dof_output: 3,
            force_newtons_max: 3.3,
            stiffness_newtons_per_metre_max: 1_000.0,
            damping_newton_secs_per_metre_max: 10.0,
            workspace_metres: Aabb::new(DVec3::splat(-0.08), DVec3::splat(0.08)),
            n_buttons: 2,
            // 450 dpi, the nominal resolution of a Phantom Omni.
            position_resolution_metres: 0.0254 / 450.0,
        }
    }

    /// A Falcon-class desktop device (Novint Falcon): 8 N, 3000 N/m and 20 N s/m, the
    /// limits CHAI3D states for it, in its 4-inch (about 0.1 m) cubic workspace; 3 degrees
    /// of freedom in and out, 4 buttons, 400 dpi.
    pub fn falcon() -> Self {
        Self {
            n_dof_input: 3,
            n_dof_output: 3,
            force_newtons_max: 8.0,
            stiffness_newtons_per_metre_max: 3_000.0,
            damping_newton_secs_per_metre_max: 20.0,
            workspace_metres: Aabb::new(DVec3::splat(-0.05), DVec3::splat(0.05)),
            n_buttons: 4,
            position_resolution_metres: 0.0254 / 400.0,
        }
    }

    /// The depth of the surface zone, in device metres, for a container that gives none
    /// (thesis section 4.3: the zone's depth depends on the device's precision, workspace and
    /// maximum force): the depth at which the largest stiffness reaches the largest force,
    /// `force_newtons_max / stiffness_newtons_per_metre_max`, so that a tension of 1 pushes
    /// with the device's whole force at the bottom of the zone; at most
    /// [`MAX_ZONE_DEPTH_WORKSPACE_FRACTION`] of the workspace's shortest side (also when the
    /// device has no stiffness) and at least [`MIN_ZONE_DEPTH_STEPS`] position steps.
    ///
    /// ```
    /// let falcon = haptic::device::Capabilities::falcon();
    /// assert!((falcon.zone_depth_metres() - 8.0 / 3000.0).abs() < 1e-12);
    /// ```
    pub fn zone_depth_metres(&self) -> f64 {
        let deepest =
            MAX_ZONE_DEPTH_WORKSPACE_FRACTION * self.workspace_metres.size().min_element();
        let shallowest = MIN_ZONE_DEPTH_STEPS * self.position_resolution_metres;
        let reach = self.force_newtons_max / self.stiffness_newtons_per_metre_max;
        let reach = if reach.is_finite() { reach } else { deepest };
        let depth = reach.min(deepest).max(shallowest);
        if depth.is_finite() {
            depth.max(0.0)
        } else {
            0.0
        }
    }

    /// True when the device can output a force at all.
    pub fn has_force_output(&self) -> bool {
        self.n_dof_output > 0 && self.force_newtons_max > 0.0
    }
}

/// One reading of the device.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceSample {
    /// Tip position in metres, device frame.
    pub position_metres: DVec3,
    /// Tip orientation (identity for 3-DOF devices).
    pub orientation: DQuat,
    /// Button bit mask, bit i for button i.
    pub buttons: u32,
    /// The device's own timestamp in microseconds (monotonic, arbitrary origin).
    pub timestamp_micros: u64,
}

impl DeviceSample {
    /// A sample at `position_metres` with identity orientation and no buttons.
    pub fn at(position_metres: DVec3, timestamp_micros: u64) -> Self {
        Self {
            position_metres,
            orientation: DQuat::IDENTITY,
            buttons: 0,
            timestamp_micros,
        }
    }
}

/// Why a device could not be read or commanded.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum DeviceError {
    /// The device went away (unplugged, closed, end of a replayed trace).
    #[error("device disconnected")]
    Disconnected,
    /// The device answered with something we could not use.
    #[error("bad report from device: {0}")]
    BadReport(&'static str),
    /// An operating system error talking to the device (static text: errors on the servo
    /// path must not allocate).
    #[error("device I/O error: {0}")]
    Io(&'static str),
}

/// A haptic device: read the tip, send a force.
///
/// `sample` and `set_force` are called from the servo thread once per tick: implementations
/// must not allocate or block there beyond the device I/O itself.
pub trait HapticDevice: Send {
    /// What the device can do.
    fn capabilities(&self) -> &Capabilities;
    /// Reads the current tip pose.
    fn sample(&mut self) -> Result<DeviceSample, DeviceError>;
    /// Commands a force in newtons, device frame; it holds until the next call.
    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError>;
}

impl<D: HapticDevice + ?Sized> HapticDevice for Box<D> {
    fn capabilities(&self) -> &Capabilities {
        (**self).capabilities()
    }
    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        (**self).sample()
    }
    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError> {
        (**self).set_force(force_newtons)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_zone_depth_is_where_stiffness_reaches_the_force_within_precision_and_workspace() {
        let pen = Capabilities::desktop_pen();
        assert!((pen.zone_depth_metres() - 3.3 / 1000.0).abs() < 1e-12);
        // A stiff, weak device: the zone keeps 16 position steps.
        let stiff = Capabilities {
            stiffness_newtons_per_metre_max: 1e7,
            ..pen
        };
        let steps = MIN_ZONE_DEPTH_STEPS * pen.position_resolution_metres;
        assert!((stiff.zone_depth_metres() - steps).abs() < 1e-15);
        // No stiffness at all, or a soft one: at most a twentieth of the workspace.
        let limp = Capabilities {
            stiffness_newtons_per_metre_max: 0.0,
            ..pen
        };
        assert!(
            (limp.zone_depth_metres() - 0.16 * MAX_ZONE_DEPTH_WORKSPACE_FRACTION).abs() < 1e-15
        );
        let soft = Capabilities {
            stiffness_newtons_per_metre_max: 1.0,
            ..pen
        };
        assert_eq!(soft.zone_depth_metres(), limp.zone_depth_metres());
        // A device without force or workspace: no zone, never NaN.
        let nothing = Capabilities {
            force_newtons_max: 0.0,
            stiffness_newtons_per_metre_max: 0.0,
            workspace_metres: Aabb::new(DVec3::ZERO, DVec3::ZERO),
            position_resolution_metres: 0.0,
            ..pen
        };
        assert_eq!(nothing.zone_depth_metres(), 0.0);
    }
}
