//! A mouse-driven device for users without haptic hardware: the app feeds pointer motion and
//! wheel steps from its thread; the servo samples the resulting tip position. No force output.

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use glam::DVec3;

use super::{Capabilities, DeviceError, DeviceSample, HapticDevice};
use crate::aabb::Aabb;

/// Tip travel per pixel of pointer motion, metres.
pub const METRES_PER_PIXEL: f64 = 0.0002;
/// Tip travel per wheel step (depth), metres.
pub const METRES_PER_WHEEL_STEP: f64 = 0.004;
/// The nominal sample period of the mouse device, microseconds.
const PERIOD_MICROS: u64 = 1_000;

#[derive(Debug, Default)]
struct Shared {
    xyz_bits: [AtomicU64; 3],
    buttons: AtomicU32,
}

/// The app's side: moves the tip (any thread, lock-free).
#[derive(Clone, Debug)]
pub struct MouseHandle {
    shared: Arc<Shared>,
    workspace: Aabb,
}

impl MouseHandle {
    /// Moves the tip by a pointer motion (pixels; screen y grows downward) and wheel steps.
    pub fn move_by(&self, dx_pixels: f64, dy_pixels: f64, wheel_steps: f64) {
        self.move_by_metres(DVec3::new(
            dx_pixels * METRES_PER_PIXEL,
            -dy_pixels * METRES_PER_PIXEL,
            -wheel_steps * METRES_PER_WHEEL_STEP,
        ));
    }

    /// The tip's position, metres, device frame.
    pub fn position_metres(&self) -> DVec3 {
        read(&self.shared)
    }

    /// Moves the tip by `delta` metres in the device frame (a caller that maps pointer
    /// motion through its own camera), clamped to the workspace; non-finite moves are ignored.
    pub fn move_by_metres(&self, delta: DVec3) {
        let now = read(&self.shared);
        let next = self.workspace.clamp(
            now + if delta.is_finite() {
                delta
            } else {
                DVec3::ZERO
            },
        );
        for (slot, v) in self.shared.xyz_bits.iter().zip(next.to_array()) {
            slot.store(v.to_bits(), Ordering::Relaxed);
        }
    }

    /// Sets the button mask (bit 0: left, bit 1: right).
    pub fn set_buttons(&self, buttons: u32) {
        self.shared.buttons.store(buttons, Ordering::Relaxed);
    }
}

fn read(shared: &Shared) -> DVec3 {
    let [x, y, z] = &shared.xyz_bits;
    DVec3::new(
        f64::from_bits(x.load(Ordering::Relaxed)),
        f64::from_bits(y.load(Ordering::Relaxed)),
        f64::from_bits(z.load(Ordering::Relaxed)),
    )
}

/// The servo's side: a 3-DOF input-only device.
#[derive(Debug)]
pub struct MouseDevice {
    caps: Capabilities,
    shared: Arc<Shared>,
    n_samples: u64,
}

impl MouseDevice {
    /// A mouse device with the tip at the centre of a 16 cm workspace, and its handle.
    pub fn new() -> (Self, MouseHandle) {
        let workspace = Aabb::new(DVec3::splat(-0.08), DVec3::splat(0.08));
        let caps = Capabilities {
            n_dof_input: 3,
            n_dof_output: 0,
            force_newtons_max: 0.0,
            stiffness_newtons_per_metre_max: 0.0,
            damping_newton_secs_per_metre_max: 0.0,
            workspace_metres: workspace,
            n_buttons: 2,
            position_resolution_metres: 0.0,
        };
        let shared = Arc::new(Shared::default());
        let handle = MouseHandle {
            shared: Arc::clone(&shared),
            workspace,
        };
        (
            Self {
                caps,
                shared,
                n_samples: 0,
            },
            handle,
        )
    }
}

impl HapticDevice for MouseDevice {
    fn capabilities(&self) -> &Capabilities {
        &self.caps
    }
    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        self.n_samples += 1;
        let mut sample = DeviceSample::at(read(&self.shared), self.n_samples * PERIOD_MICROS);
        sample.buttons = self.shared.buttons.load(Ordering::Relaxed);
        Ok(sample)
    }
    fn set_force(&mut self, _force_newtons: DVec3) -> Result<(), DeviceError> {
        // An input-only device: the force is shown by the app, not rendered.
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pointer_moves_tip_and_stays_in_workspace() {
        let (mut dev, handle) = MouseDevice::new();
        handle.move_by(50.0, 25.0, 1.0);
        handle.set_buttons(1);
        let s = dev.sample().unwrap();
        assert!((s.position_metres - DVec3::new(0.01, -0.005, -0.004)).length() < 1e-12);
        assert_eq!(s.buttons, 1);
        handle.move_by(1e9, 0.0, 0.0);
        handle.move_by(f64::NAN, 0.0, 0.0);
        let s2 = dev.sample().unwrap();
        assert_eq!(s2.position_metres.x, 0.08);
        assert!(s2.timestamp_micros > s.timestamp_micros);
        assert!(!dev.capabilities().has_force_output());
    }
}
