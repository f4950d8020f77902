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

use crate::container::Aabb;

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
}

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
        }
    }

    /// A Falcon-class desktop device (Novint Falcon): 8 N, 3000 N/m and 20 N s/m, the
    /// limits CHAI3D states for it, in its 4-inch (about 0.1 m) cubic workspace; 3 degrees
    /// of freedom in and out, 4 buttons.
    pub fn falcon() -> Self {
        Self {
            n_dof_input: 3,
            n_dof_output: 3,
            force_newtons_max: 8.0,
            stiffness_newtons_per_metre_max: 3_000.0,
            damping_newton_secs_per_metre_max: 20.0,
            workspace_metres: Aabb::new(DVec3::splat(-0.05), DVec3::splat(0.05)),
            n_buttons: 4,
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
