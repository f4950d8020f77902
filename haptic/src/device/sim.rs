//! A simulated device: a hand following scripted waypoints, holding the tip through a
//! spring-damper, so the tip responds to the force it is sent (a spring-mass hand model).
//!
//! It keeps its own virtual clock: every [`HapticDevice::sample`] advances it by one period.

use glam::DVec3;

use super::{Capabilities, DeviceError, DeviceSample, HapticDevice};

/// Integration sub-steps per device period, for a stable stiff hand spring.
const N_SUBSTEPS: usize = 8;
/// The most waypoints one script may hold.
pub const MAX_WAYPOINTS: usize = 100_000;

/// A point the hand passes through at a time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Waypoint {
    /// When the hand is there, in seconds from the start.
    pub t_secs: f64,
    /// Where the hand is, in metres, device frame.
    pub position_metres: DVec3,
}

/// How the hand holds the tip: tip mass on a spring-damper pulled toward the hand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HandModel {
    /// Tip plus finger mass, kilograms.
    pub mass_kg: f64,
    /// Grip stiffness, newtons per metre.
    pub stiffness_newtons_per_metre: f64,
    /// Grip damping, newton-seconds per metre.
    pub damping_newton_secs_per_metre: f64,
}

impl Default for HandModel {
    fn default() -> Self {
        Self {
            mass_kg: 0.1,
            stiffness_newtons_per_metre: 300.0,
            damping_newton_secs_per_metre: 4.0,
        }
    }
}

/// Why a simulated device could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimError {
    /// No waypoints were given.
    #[error("a scripted trajectory needs at least one waypoint")]
    NoWaypoints,
    /// More than [`MAX_WAYPOINTS`] waypoints.
    #[error("too many waypoints: {0} (limit {MAX_WAYPOINTS})")]
    TooManyWaypoints(usize),
    /// Waypoint times go backwards or a value is not finite.
    #[error("waypoint {0} is not finite or goes back in time")]
    BadWaypoint(usize),
    /// The period or hand model is not positive and finite.
    #[error("period and hand model must be positive and finite")]
    BadParameters,
}

/// A scripted, simulated haptic device.
#[derive(Clone, Debug)]
pub struct SimDevice {
    caps: Capabilities,
    waypoints: Vec<Waypoint>,
    hand: HandModel,
    period_secs: f64,
    n_samples: u64,
    tip_metres: DVec3,
    tip_velocity: DVec3,
    force_newtons: DVec3,
    looping: bool,
}

impl SimDevice {
    /// A device whose hand follows `waypoints` (linear in between, holding the last one).
    pub fn new(
        caps: Capabilities,
        waypoints: Vec<Waypoint>,
        hand: HandModel,
        period_secs: f64,
    ) -> Result<Self, SimError> {
        let first = waypoints.first().ok_or(SimError::NoWaypoints)?;
        if waypoints.len() > MAX_WAYPOINTS {
            return Err(SimError::TooManyWaypoints(waypoints.len()));
        }
        for (idx, w) in waypoints.iter().enumerate() {
            let backwards = idx > 0 && w.t_secs < waypoints[idx - 1].t_secs;
            if !w.t_secs.is_finite() || !w.position_metres.is_finite() || backwards {
                return Err(SimError::BadWaypoint(idx));
            }
        }
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !(positive(period_secs)
            && positive(hand.mass_kg)
            && positive(hand.stiffness_newtons_per_metre)
            && hand.damping_newton_secs_per_metre.is_finite())
        {
            return Err(SimError::BadParameters);
        }
        let tip_metres = first.position_metres;
        Ok(Self {
            caps,
            waypoints,
            hand,
            period_secs,
            n_samples: 0,
            tip_metres,
            tip_velocity: DVec3::ZERO,
            force_newtons: DVec3::ZERO,
            looping: false,
        })
    }

    /// Makes the script repeat forever (time wraps at the last waypoint).
    pub fn looping(self) -> Self {
        Self {
            looping: true,
            ..self
        }
    }

    /// Virtual time of the last sample, seconds.
    pub fn time_secs(&self) -> f64 {
        self.n_samples as f64 * self.period_secs
    }

    /// True once the script's last waypoint time has passed.
    pub fn finished(&self) -> bool {
        !self.looping
            && self
                .waypoints
                .last()
                .is_none_or(|w| self.time_secs() >= w.t_secs)
    }

    /// The tip position of the last sample, metres, device frame.
    pub fn tip_metres(&self) -> DVec3 {
        self.tip_metres
    }

    /// The force last commanded, newtons.
    pub fn force_newtons(&self) -> DVec3 {
        self.force_newtons
    }

    /// Where the hand wants the tip at `t_secs` (piecewise linear).
    pub fn hand_target(&self, t_secs: f64) -> DVec3 {
        let span = self.waypoints.last().map_or(0.0, |w| w.t_secs);
        let t_secs = if self.looping && span > 0.0 {
            t_secs.rem_euclid(span)
        } else {
            t_secs
        };
        let idx = self.waypoints.partition_point(|w| w.t_secs <= t_secs);
        match (
            idx.checked_sub(1).map(|i| self.waypoints[i]),
            self.waypoints.get(idx),
        ) {
            (Some(a), Some(b)) => {
                let span = (b.t_secs - a.t_secs).max(f64::MIN_POSITIVE);
                a.position_metres
                    .lerp(b.position_metres, (t_secs - a.t_secs) / span)
            }
            (Some(a), None) => a.position_metres,
            (None, Some(b)) => b.position_metres,
            (None, None) => self.tip_metres,
        }
    }

    fn integrate(&mut self) {
        let t0 = self.time_secs();
        let h = self.period_secs / N_SUBSTEPS as f64;
        for step_idx in 0..N_SUBSTEPS {
            let t = t0 + step_idx as f64 * h;
            let target = self.hand_target(t);
            let target_velocity = (self.hand_target(t + h) - target) / h;
            let grip = self.hand.stiffness_newtons_per_metre * (target - self.tip_metres)
                + self.hand.damping_newton_secs_per_metre * (target_velocity - self.tip_velocity);
            let accel = (grip + self.force_newtons) / self.hand.mass_kg;
            self.tip_velocity += accel * h;
            self.tip_metres += self.tip_velocity * h;
        }
        self.tip_metres = self.caps.workspace_metres.clamp(self.tip_metres);
    }
}

impl HapticDevice for SimDevice {
    fn capabilities(&self) -> &Capabilities {
        &self.caps
    }

    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        self.integrate();
        self.n_samples += 1;
        let timestamp_micros = (self.time_secs() * 1e6).round() as u64;
        Ok(DeviceSample::at(self.tip_metres, timestamp_micros))
    }

    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError> {
        if !force_newtons.is_finite() {
            return Err(DeviceError::BadReport("force is not finite"));
        }
        let limit = self.caps.force_newtons_max;
        self.force_newtons = force_newtons.clamp_length_max(limit);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line_device(hand: HandModel) -> SimDevice {
        let waypoints = vec![
            Waypoint {
                t_secs: 0.0,
                position_metres: DVec3::ZERO,
            },
            Waypoint {
                t_secs: 1.0,
                position_metres: DVec3::new(0.05, 0.0, 0.0),
            },
        ];
        SimDevice::new(Capabilities::desktop_pen(), waypoints, hand, 0.001).unwrap()
    }

    #[test]
    fn hand_follows_script_without_force() {
        let mut dev = line_device(HandModel::default());
        let mut last = DeviceSample::at(DVec3::ZERO, 0);
        for _ in 0..1500 {
            last = dev.sample().unwrap();
        }
        assert!(dev.finished());
        assert_eq!(last.timestamp_micros, 1_500_000);
        assert!(
            (last.position_metres - DVec3::new(0.05, 0.0, 0.0)).length() < 1e-4,
            "{last:?}"
        );
    }

    #[test]
    fn tip_yields_to_force_like_a_spring() {
        let hand = HandModel::default();
        let mut dev = line_device(hand);
        dev.set_force(DVec3::new(-1.5, 0.0, 0.0)).unwrap();
        let mut last = DeviceSample::at(DVec3::ZERO, 0);
        for _ in 0..3000 {
            last = dev.sample().unwrap();
        }
        // Static equilibrium: grip spring balances the force, 1.5 N / 300 N/m = 5 mm.
        let expected = 0.05 - 1.5 / hand.stiffness_newtons_per_metre;
        assert!((last.position_metres.x - expected).abs() < 1e-4, "{last:?}");
    }

    #[test]
    fn looping_script_repeats() {
        let dev = line_device(HandModel::default()).looping();
        assert!(!dev.finished());
        assert_eq!(dev.hand_target(1.5), dev.hand_target(0.5));
        assert_eq!(dev.hand_target(0.25), DVec3::new(0.0125, 0.0, 0.0));
    }

    #[test]
    fn rejects_bad_scripts() {
        let caps = Capabilities::desktop_pen();
        let hand = HandModel::default();
        assert_eq!(
            SimDevice::new(caps, vec![], hand, 0.001).unwrap_err(),
            SimError::NoWaypoints
        );
        let back = vec![
            Waypoint {
                t_secs: 1.0,
                position_metres: DVec3::ZERO,
            },
            Waypoint {
                t_secs: 0.5,
                position_metres: DVec3::ZERO,
            },
        ];
        assert_eq!(
            SimDevice::new(caps, back, hand, 0.001).unwrap_err(),
            SimError::BadWaypoint(1)
        );
        let one = vec![Waypoint {
            t_secs: 0.0,
            position_metres: DVec3::ZERO,
        }];
        assert_eq!(
            SimDevice::new(caps, one, hand, 0.0).unwrap_err(),
            SimError::BadParameters
        );
    }
}
