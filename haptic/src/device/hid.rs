//! HID drivers through `hidapi` (Linux hidraw backend): a 3Dconnexion SpaceMouse as 6-DOF
//! input, and a HID PID force-feedback device streaming a constant-force effect.
//!
//! Missing hardware is an [`OpenError`], never a panic; malformed reports are counted and
//! dropped. Report parsing and building are pure functions, unit-tested here and tested end
//! to end against the FUSE fake device in `tests/fake-hid/`.
//!
//! Non-guarantees: the PID driver uses the report ids of the PID specification's example
//! layout (constants below) rather than parsing the device's report descriptor, and renders
//! the force's x component on one axis.

use glam::{DQuat, DVec3};
use hidapi::{HidApi, HidDevice};

use super::{Capabilities, DeviceError, DeviceSample, HapticDevice};
use crate::aabb::Aabb;

/// 3Dconnexion vendor ids (current and the older Logitech-era one).
pub const SPACEMOUSE_VENDOR_IDS: [u16; 2] = [0x256f, 0x046d];
/// HID usage page and usage of a multi-axis controller.
pub const MULTI_AXIS_USAGE: (u16, u16) = (0x01, 0x08);
/// Axis reading that maps to full deflection.
pub const AXIS_FULL_SCALE: f64 = 350.0;
/// Largest rotation of the tip orientation at full deflection, radians.
pub const ROTATION_FULL_SCALE_RADIANS: f64 = 0.5;
/// At most this many pending reports are drained per sample.
pub const MAX_REPORTS_PER_SAMPLE: usize = 32;
/// Longest input report accepted, bytes.
pub const MAX_REPORT_BYTES: usize = 64;
/// Nominal sample period used for timestamps (the driver reads no clock), microseconds.
const PERIOD_MICROS: u64 = 1_000;

/// Why a HID device could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// hidapi could not start (no hidraw access).
    #[error("HID access unavailable: {0}")]
    Api(hidapi::HidError),
    /// No matching device is connected.
    #[error("no matching HID device found")]
    NotFound,
    /// The device was found but could not be opened.
    #[error("cannot open HID device: {0}")]
    Open(hidapi::HidError),
    /// The force-feedback effect could not be created.
    #[error("force-feedback setup failed: {0}")]
    Effect(&'static str),
}

/// Why an input report was rejected.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ReportError {
    /// Empty or too short for its report id.
    #[error("report too short for id {0}")]
    TooShort(u8),
    /// An id this driver does not know.
    #[error("unknown report id {0}")]
    UnknownId(u8),
}

/// The SpaceMouse's latest axes and buttons.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpaceMouseState {
    /// X Y Z translation axes, raw.
    pub translation: [i16; 3],
    /// Rx Ry Rz rotation axes, raw.
    pub rotation: [i16; 3],
    /// Button bit mask.
    pub buttons: u32,
}

fn i16_at(report: &[u8], idx: usize) -> i16 {
    i16::from_le_bytes([report[idx], report[idx + 1]])
}

/// Applies one input report: id 1 translation (old models) or all six axes (new models,
/// 13 bytes), id 2 rotation, id 3 buttons.
pub fn apply_spacemouse_report(
    state: &mut SpaceMouseState,
    report: &[u8],
) -> Result<(), ReportError> {
    let (&id, body) = report.split_first().ok_or(ReportError::TooShort(0))?;
    let axes = |offset: usize| [0, 1, 2].map(|k| i16_at(body, offset + 2 * k));
    match id {
        1 if body.len() >= 12 => {
            state.translation = axes(0);
            state.rotation = axes(6);
        }
        1 | 2 if body.len() >= 6 => {
            let target = if id == 1 {
                &mut state.translation
            } else {
                &mut state.rotation
            };
            *target = axes(0);
        }
        3 if !body.is_empty() => {
            let mut bytes = [0u8; 4];
            let n = body.len().min(4);
            bytes[..n].copy_from_slice(&body[..n]);
            state.buttons = u32::from_le_bytes(bytes);
        }
        1..=3 => return Err(ReportError::TooShort(id)),
        _ => return Err(ReportError::UnknownId(id)),
    }
    Ok(())
}

/// Maps axes to a tip pose: deflection is position within the workspace (position control).
pub fn spacemouse_pose(state: &SpaceMouseState, workspace: &Aabb) -> (DVec3, DQuat) {
    let unit = |axes: [i16; 3]| {
        DVec3::from_array(axes.map(|a| (f64::from(a) / AXIS_FULL_SCALE).clamp(-1.0, 1.0)))
    };
    let position = workspace.center() + unit(state.translation) * workspace.size() * 0.5;
    let rotation = unit(state.rotation) * ROTATION_FULL_SCALE_RADIANS;
    (position, DQuat::from_scaled_axis(rotation))
}

/// A 3Dconnexion SpaceMouse: 6-DOF input, no force output.
pub struct SpaceMouse {
    device: HidDevice,
    caps: Capabilities,
    state: SpaceMouseState,
    n_samples: u64,
    n_bad_reports: u64,
}

impl SpaceMouse {
    /// Opens the first multi-axis controller from 3Dconnexion.
    pub fn open_first() -> Result<Self, OpenError> {
        let api = HidApi::new().map_err(OpenError::Api)?;
        let info = api
            .device_list()
            .find(|d| {
                SPACEMOUSE_VENDOR_IDS.contains(&d.vendor_id())
                    && (d.usage_page(), d.usage()) == MULTI_AXIS_USAGE
            })
            .ok_or(OpenError::NotFound)?;
        let device = info.open_device(&api).map_err(OpenError::Open)?;
        device.set_blocking_mode(false).map_err(OpenError::Open)?;
        let workspace = Aabb::new(DVec3::splat(-0.08), DVec3::splat(0.08));
        Ok(Self {
            device,
            caps: Capabilities {
                n_dof_input: 6,
                n_dof_output: 0,
                force_newtons_max: 0.0,
                stiffness_newtons_per_metre_max: 0.0,
                damping_newton_secs_per_metre_max: 0.0,
                workspace_metres: workspace,
                n_buttons: 2,
                position_resolution_metres: 0.0,
            },
            state: SpaceMouseState::default(),
            n_samples: 0,
            n_bad_reports: 0,
        })
    }

    /// The raw axes and buttons.
    pub fn state(&self) -> SpaceMouseState {
        self.state
    }

    /// Reports dropped as malformed.
    pub fn n_bad_reports(&self) -> u64 {
        self.n_bad_reports
    }

    /// Reads one report, waiting up to `timeout_millis`; returns whether one arrived.
    pub fn poll(&mut self, timeout_millis: i32) -> Result<bool, DeviceError> {
        let mut buf = [0u8; MAX_REPORT_BYTES];
        let n = self
            .device
            .read_timeout(&mut buf, timeout_millis)
            .map_err(|_| DeviceError::Io("hidraw read failed"))?;
        if n == 0 {
            return Ok(false);
        }
        if apply_spacemouse_report(&mut self.state, &buf[..n]).is_err() {
            self.n_bad_reports += 1;
        }
        Ok(true)
    }
}

impl HapticDevice for SpaceMouse {
    fn capabilities(&self) -> &Capabilities {
        &self.caps
    }

    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        for _ in 0..MAX_REPORTS_PER_SAMPLE {
            if !self.poll(0)? {
                break;
            }
        }
        self.n_samples += 1;
        let (position_metres, orientation) =
            spacemouse_pose(&self.state, &self.caps.workspace_metres);
        Ok(DeviceSample {
            position_metres,
            orientation,
            buttons: self.state.buttons,
            timestamp_micros: self.n_samples * PERIOD_MICROS,
        })
    }

    fn set_force(&mut self, _force_newtons: DVec3) -> Result<(), DeviceError> {
        Ok(())
    }
}

/// HID PID report ids (the PID specification's example layout).
pub mod pid_report {
    /// Output: Set Effect.
    pub const SET_EFFECT: u8 = 0x01;
    /// Output: Set Constant Force.
    pub const SET_CONSTANT_FORCE: u8 = 0x05;
    /// Output: Effect Operation.
    pub const EFFECT_OPERATION: u8 = 0x0a;
    /// Feature (set): Create New Effect.
    pub const CREATE_NEW_EFFECT: u8 = 0x0b;
    /// Feature (get): PID Block Load.
    pub const BLOCK_LOAD: u8 = 0x0c;
}

/// PID effect type of a constant force.
const EFFECT_TYPE_CONSTANT: u8 = 1;
/// PID block load status: success.
const BLOCK_LOAD_SUCCESS: u8 = 1;
/// Largest PID magnitude.
pub const MAX_PID_MAGNITUDE: i16 = 10_000;

/// The Create New Effect feature report for a constant force.
pub fn create_constant_effect_report() -> [u8; 4] {
    [pid_report::CREATE_NEW_EFFECT, EFFECT_TYPE_CONSTANT, 0, 0]
}

/// The Set Effect report: constant force on the x axis, infinite duration, full gain.
pub fn set_effect_report(block_idx: u8) -> [u8; 12] {
    [
        pid_report::SET_EFFECT,
        block_idx,
        EFFECT_TYPE_CONSTANT,
        0xff,
        0xff, // duration: infinite
        0,
        0, // trigger repeat
        0,
        0,    // sample period
        0xff, // gain
        0xff, // no trigger button
        0x01, // axis x enabled
    ]
}

/// The Effect Operation report that starts the effect once (it then runs until stopped).
pub fn start_effect_report(block_idx: u8) -> [u8; 4] {
    [pid_report::EFFECT_OPERATION, block_idx, 1, 1]
}

/// The Set Constant Force report for `force_newtons` on a device of `force_newtons_max`.
pub fn constant_force_report(block_idx: u8, force_newtons: f64, force_newtons_max: f64) -> [u8; 4] {
    let unit = if force_newtons_max > 0.0 && force_newtons.is_finite() {
        (force_newtons / force_newtons_max).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let magnitude = (unit * f64::from(MAX_PID_MAGNITUDE)).round() as i16;
    let [lo, hi] = magnitude.to_le_bytes();
    [pid_report::SET_CONSTANT_FORCE, block_idx, lo, hi]
}

/// HID usage pages and usages of devices that may render force: joysticks and gamepads on
/// the generic desktop page, and anything on the physical interface (PID) page.
pub const FORCE_FEEDBACK_USAGES: [(u16, u16); 2] = [(0x01, 0x04), (0x01, 0x05)];
/// The physical interface device (PID) usage page.
pub const PID_USAGE_PAGE: u16 = 0x0f;

/// A HID device that may take force-feedback effects, for a person to choose.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HidDeviceInfo {
    /// USB vendor id.
    pub vendor_id: u16,
    /// USB product id.
    pub product_id: u16,
    /// The product's name, as the device reports it (may be empty).
    pub name: String,
}

/// The connected HID devices that may render force ([`FORCE_FEEDBACK_USAGES`] or the PID
/// page), each listed once.
pub fn force_feedback_devices() -> Result<Vec<HidDeviceInfo>, OpenError> {
    let api = HidApi::new().map_err(OpenError::Api)?;
    let mut out: Vec<HidDeviceInfo> = Vec::new();
    for d in api.device_list() {
        let usage = (d.usage_page(), d.usage());
        if !(FORCE_FEEDBACK_USAGES.contains(&usage) || usage.0 == PID_USAGE_PAGE) {
            continue;
        }
        let info = HidDeviceInfo {
            vendor_id: d.vendor_id(),
            product_id: d.product_id(),
            name: d.product_string().unwrap_or_default().to_string(),
        };
        if !out
            .iter()
            .any(|o| (o.vendor_id, o.product_id) == (info.vendor_id, info.product_id))
        {
            out.push(info);
        }
    }
    Ok(out)
}

/// A HID PID force-feedback device streaming one constant-force effect.
pub struct PidForce {
    device: HidDevice,
    caps: Capabilities,
    block_idx: u8,
    n_samples: u64,
}

impl PidForce {
    /// Opens the first device with `vendor_id`/`product_id`, creates and starts a constant
    /// force effect of a device rendering up to `force_newtons_max`.
    pub fn open(
        vendor_id: u16,
        product_id: u16,
        force_newtons_max: f64,
    ) -> Result<Self, OpenError> {
        let api = HidApi::new().map_err(OpenError::Api)?;
        let info = api
            .device_list()
            .find(|d| d.vendor_id() == vendor_id && d.product_id() == product_id)
            .ok_or(OpenError::NotFound)?;
        let device = info.open_device(&api).map_err(OpenError::Open)?;
        device
            .send_feature_report(&create_constant_effect_report())
            .map_err(|_| OpenError::Effect("Create New Effect refused"))?;
        let mut load = [0u8; 5];
        load[0] = pid_report::BLOCK_LOAD;
        let n = device
            .get_feature_report(&mut load)
            .map_err(|_| OpenError::Effect("PID Block Load unreadable"))?;
        if n < 3 || load[0] != pid_report::BLOCK_LOAD || load[2] != BLOCK_LOAD_SUCCESS {
            return Err(OpenError::Effect("PID Block Load reports failure"));
        }
        let block_idx = load[1];
        for report in [
            &set_effect_report(block_idx)[..],
            &constant_force_report(block_idx, 0.0, 1.0),
            &start_effect_report(block_idx),
        ] {
            device
                .write(report)
                .map_err(|_| OpenError::Effect("effect upload failed"))?;
        }
        Ok(Self {
            device,
            caps: Capabilities {
                n_dof_input: 0,
                n_dof_output: 1,
                force_newtons_max,
                stiffness_newtons_per_metre_max: 0.0,
                damping_newton_secs_per_metre_max: 0.0,
                workspace_metres: Aabb::new(DVec3::ZERO, DVec3::ZERO),
                n_buttons: 0,
                position_resolution_metres: 0.0,
            },
            block_idx,
            n_samples: 0,
        })
    }

    /// The effect block the device assigned.
    pub fn block_idx(&self) -> u8 {
        self.block_idx
    }
}

impl HapticDevice for PidForce {
    fn capabilities(&self) -> &Capabilities {
        &self.caps
    }

    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        // Output only: the tip does not move.
        self.n_samples += 1;
        Ok(DeviceSample::at(
            DVec3::ZERO,
            self.n_samples * PERIOD_MICROS,
        ))
    }

    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError> {
        let report =
            constant_force_report(self.block_idx, force_newtons.x, self.caps.force_newtons_max);
        self.device
            .write(&report)
            .map_err(|_| DeviceError::Io("hidraw write failed"))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_old_and_new_spacemouse_reports() {
        let mut s = SpaceMouseState::default();
        apply_spacemouse_report(&mut s, &[1, 10, 0, 0xf6, 0xff, 7, 0]).unwrap();
        assert_eq!(s.translation, [10, -10, 7]);
        apply_spacemouse_report(&mut s, &[2, 1, 0, 2, 0, 3, 0]).unwrap();
        assert_eq!(s.rotation, [1, 2, 3]);
        let mut new = vec![1u8];
        for v in [100i16, -200, 300, -4, 5, -6] {
            new.extend(v.to_le_bytes());
        }
        apply_spacemouse_report(&mut s, &new).unwrap();
        assert_eq!((s.translation, s.rotation), ([100, -200, 300], [-4, 5, -6]));
        apply_spacemouse_report(&mut s, &[3, 2]).unwrap();
        assert_eq!(s.buttons, 2);
        assert_eq!(
            apply_spacemouse_report(&mut s, &[]),
            Err(ReportError::TooShort(0))
        );
        assert_eq!(
            apply_spacemouse_report(&mut s, &[2, 1, 0]),
            Err(ReportError::TooShort(2))
        );
        assert_eq!(
            apply_spacemouse_report(&mut s, &[9, 1]),
            Err(ReportError::UnknownId(9))
        );
        // Deflection maps into the workspace, saturating at full scale.
        let ws = Aabb::new(DVec3::splat(-0.08), DVec3::splat(0.08));
        let (p, q) = spacemouse_pose(
            &SpaceMouseState {
                translation: [175, -350, i16::MAX],
                ..s
            },
            &ws,
        );
        assert!((p - DVec3::new(0.04, -0.08, 0.08)).length() < 1e-12);
        assert!(q.is_normalized());
    }

    #[test]
    fn builds_pid_reports() {
        assert_eq!(constant_force_report(3, 1.5, 3.0), [5, 3, 0x88, 0x13]);
        assert_eq!(constant_force_report(3, -9.0, 3.0), [5, 3, 0xf0, 0xd8]);
        assert_eq!(constant_force_report(3, f64::NAN, 3.0), [5, 3, 0, 0]);
        assert_eq!(set_effect_report(2)[..3], [1, 2, 1]);
        assert_eq!(start_effect_report(2), [0x0a, 2, 1, 1]);
    }
}
