//! Touch: the haptic servo on the app's scenes.
//!
//! - [`replay`]: the real servo ([`haptic::servo::Servo`]) run headless over a path read
//!   from CSV ([`path::TouchPath`]), one step per 1 kHz tick, with a device that replays the
//!   path ([`PathDevice`]); what `sculpt touch <scene.wrl> --trace IN.csv --out OUT.csv`
//!   runs. The scene's objects become haptic containers through the haptic crate's own
//!   `ObjectContainer::from_scene`, exactly as its trace tests build them.
//! - [`live`]: the servo on the live scene in the running app, moved by the mouse.
//! - [`record`]: the live tool's path recorded for replay, and the force history the window plots.
//! - [`spacemouse`]: a 3D mouse as the live touch tool's input, on a thread of its own.
//! - [`body`]: the touch tool's own body, and other peers' tangible tools read from their
//!   presence for the live servo's feed (`haptic::feed`, which turns the engine's per-object
//!   changes into snapshots).
//! - [`shared`]: two peers holding one tool over the network.
//!
//! Units and frames: a path gives the haptic interface point (HIP) in the scene's own
//! coordinates (+y up); the [`HapticZone`] maps the device's workspace onto the scene, by
//! default the smallest cube around the scene's bounded objects ([`zone_for`]), so forces
//! are newtons of the chosen [`DeviceModel`] in device axes (the same axes as the scene's:
//! the zone does not rotate).

pub mod body;
pub mod force_output;
pub mod live;
pub mod path;
pub mod probe;
pub mod record;
pub mod shared;
pub mod spacemouse;

use glam::{DQuat, DVec3};
use haptic::aabb::Aabb;
use haptic::container::object::ObjectContainer;
use haptic::container::{Container as _, Scene};
use haptic::device::{Capabilities, DeviceError, DeviceSample, HapticDevice};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, Rig};
use haptic::servo::{SERVO_RATE_HZ, Servo};

use path::TouchPath;

/// One servo tick, seconds.
pub const TICK_SECS: f64 = 1.0 / SERVO_RATE_HZ;

/// The device whose limits forces are rendered for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceModel {
    /// A Falcon-class device: 8 N, 3000 N/m, 20 N s/m, a 0.1 m cube.
    #[default]
    Falcon,
    /// A desktop pen (Phantom Omni / Touch class): 3.3 N, 1000 N/m, 10 N s/m, a 0.16 m cube.
    DesktopPen,
}

impl DeviceModel {
    /// Its capabilities.
    pub fn capabilities(self) -> Capabilities {
        match self {
            DeviceModel::Falcon => Capabilities::falcon(),
            DeviceModel::DesktopPen => Capabilities::desktop_pen(),
        }
    }
}

/// The world box around every container with finite bounds, if any.
pub fn bounds_of(containers: &[ObjectContainer]) -> Option<Aabb> {
    containers
        .iter()
        .map(|c| c.bounds())
        .filter(|b| b.min.is_finite() && b.max.is_finite())
        .reduce(|a, b| Aabb::new(a.min.min(b.min), a.max.max(b.max)))
}

/// The haptic zone: the device's workspace centred on `bounds` (the origin without), scaled
/// by `world_per_device_metre` or else so that the workspace's shortest side spans the
/// bounds' longest (a cubic workspace then covers the whole box); 1 scene unit per metre
/// when there is nothing to cover.
pub fn zone_for(
    caps: &Capabilities,
    bounds: Option<Aabb>,
    world_per_device_metre: Option<f64>,
) -> HapticZone {
    let workspace = caps.workspace_metres;
    let side_metres = workspace.size().min_element();
    let center_world = bounds.map_or(DVec3::ZERO, |b| b.center());
    let fitted = bounds
        .map(|b| b.size().max_element() / side_metres)
        .filter(|s| s.is_finite() && *s > 0.0);
    HapticZone {
        center_world,
        world_per_device_metre: world_per_device_metre.or(fitted).unwrap_or(1.0),
        rotation: DQuat::IDENTITY,
        workspace_center_device: workspace.center(),
    }
}

/// The surface zone where a scene gives no depth (no `FDepth`): the device's own
/// (`Capabilities::zone_depth_metres`: where its stiffness reaches its largest force), in
/// millimetres at the device and in scene units through `zone`. `sculpt touch` prints it and
/// the window's Touch section shows it.
pub fn zone_depth_text(caps: &Capabilities, zone: &HapticZone) -> String {
    let metres = caps.zone_depth_metres();
    let world = zone.world_distance(metres);
    // Three significant digits, however large the scene.
    let decimals = if world > 0.0 && world.is_finite() {
        (2.0 - world.log10().floor()).clamp(0.0, 12.0) as usize
    } else {
        0
    };
    format!(
        "surface zone where no FDepth is given: {:.2} mm at the device, {world:.decimals$} \
         scene units",
        metres * 1e3
    )
}

/// The rig of a device model over a zone, with the haptic crate's default safety settings.
pub fn rig(model: DeviceModel, zone: HapticZone) -> Rig {
    Rig {
        caps: model.capabilities(),
        zone,
        params: ForceParams::default(),
    }
}

/// A device that replays a path tick by tick: its tip is the path's point mapped into the
/// device through the zone, its clock the tick count; forces it is sent are kept.
pub struct PathDevice {
    caps: Capabilities,
    zone: HapticZone,
    path: TouchPath,
    cursor: usize,
    tick: usize,
    forces_newtons: Vec<DVec3>,
}

impl PathDevice {
    /// A device with `caps` replaying `path` through `zone`, with room for the forces of
    /// every tick of the path.
    pub fn new(caps: Capabilities, zone: HapticZone, path: TouchPath) -> PathDevice {
        let n_ticks = path.n_ticks(TICK_SECS);
        PathDevice {
            caps,
            zone,
            path,
            cursor: 0,
            tick: 0,
            forces_newtons: Vec::with_capacity(n_ticks),
        }
    }

    /// The forces sent so far, one per tick, newtons.
    pub fn forces_newtons(&self) -> &[DVec3] {
        &self.forces_newtons
    }
}

impl HapticDevice for PathDevice {
    fn capabilities(&self) -> &Capabilities {
        &self.caps
    }

    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        let row = self.path.at_tick(self.tick, TICK_SECS, &mut self.cursor);
        let timestamp_micros = self.tick as u64 * 1_000;
        self.tick += 1;
        Ok(DeviceSample {
            buttons: u32::from(row.pressed),
            ..DeviceSample::at(self.zone.device_from_world(row.hip_scene), timestamp_micros)
        })
    }

    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError> {
        // Within the capacity reserved for the path: no allocation.
        if self.forces_newtons.len() < self.forces_newtons.capacity() {
            self.forces_newtons.push(force_newtons);
        }
        Ok(())
    }
}

/// Forces over a replayed path: one per tick from the path's first row to its last.
#[derive(Clone, Debug, PartialEq)]
pub struct Replay {
    /// The scene time of the first tick, seconds.
    pub start_secs: f64,
    /// The force sent at each tick, newtons, device axes.
    pub forces_newtons: Vec<DVec3>,
}

impl Replay {
    /// The forces as CSV: the header `t,fx,fy,fz`, then one row per tick (seconds to the
    /// microsecond, newtons to the nanonewton).
    pub fn to_csv(&self) -> String {
        use std::fmt::Write as _;
        let mut out = String::with_capacity(40 * (self.forces_newtons.len() + 1));
        out.push_str("t,fx,fy,fz\n");
        for (tick, f) in self.forces_newtons.iter().enumerate() {
            let t = self.start_secs + tick as f64 * TICK_SECS;
            // Writing to a String cannot fail.
            let _ = writeln!(out, "{t:.6},{:.9},{:.9},{:.9}", f.x, f.y, f.z);
        }
        out
    }
}

/// Runs the servo over `scene` along `path`: one `Servo::step` per tick, the scene's clock
/// starting at the path's first time. Forces ramp in over the servo's first quarter second
/// (its safety layer), as they do when a device is switched on.
pub fn replay<S: Scene + 'static>(scene: S, rig: Rig, path: TouchPath) -> Replay {
    let start_secs = path.start_secs();
    let n_ticks = path.n_ticks(TICK_SECS);
    let device = PathDevice::new(rig.caps, rig.zone, path);
    let (mut servo, link) = Servo::init(device, rig);
    link.scenes.publish(Box::new(scene));
    servo.set_time_secs(start_secs - TICK_SECS);
    for _ in 0..n_ticks {
        servo.step(TICK_SECS);
    }
    Replay {
        start_secs,
        forces_newtons: servo.device().forces_newtons().to_vec(),
    }
}
