//! The queries haptic's 1 kHz servo makes of an object's [`Sampler`] each tick
//! (`haptic::force::render` over an `ObjectContainer`), replayed here without haptic along a
//! tool path that strokes the surface.
//!
//! Each tick the servo
//! - asks the value and gradient at the tip (`update_stack`, `Sampler::container_gradient`,
//!   which is [`Sampler::gradient`] for an object without its own container);
//! - when the sign changed since the last tick, asks the value at the last tip and narrows
//!   the segment between them to the crossing ([`model::root::crossing`], a gradient at each
//!   step: an object container gives no first crossing of its own);
//! - inside the solid, asks the value and gradient again (`effect_force`), then the zone
//!   depth, and within the zone the tension, else (or where no tension is defined) the
//!   density: painted scalars, each a lookup of the paintings at the tip
//!   ([`Sampler::scalar`]); and the force field ([`Sampler::force`]).
//!
//! The object is the only container and its space is the world's. The workload's object has
//! no physics formulas and paints colour only, so each property is a lookup of paintings
//! that finds none (a product object needs physics to be felt at all; formulas would add a
//! tape evaluation per property, the same at every history length).
//!
//! The tool path: the tip circles the sphere's surface at [`SPEED_PER_SEC`] object units per
//! second (2 m/s on a sphere of radius 1 m, 0.2 m/s on one of 10 cm), weaving in latitude
//! and in and out of the surface by [`DEPTH_SWING`], one point every millisecond.

use glam::DVec3;
use model::object::{Paintable, Sampler};

/// Ticks in one pass: about four seconds of stroking.
pub const N_TICKS: usize = 4096;
/// The servo's period, seconds.
const TICK_SECS: f64 = 1e-3;
/// The tip's speed along the surface, object units per second.
const SPEED_PER_SEC: f64 = 2.0;
/// How far the tip goes in and out of the surface, object units.
const DEPTH_SWING: f64 = 0.02;
/// The surface zone's depth (the device's, as no property sets it), object units.
const ZONE_DEPTH: f64 = 0.03;

/// The tip at every tick of one pass.
pub fn tool_path() -> Vec<DVec3> {
    (0..N_TICKS)
        .map(|i| {
            let t = i as f64 * TICK_SECS;
            let longitude = SPEED_PER_SEC * t;
            let latitude = 0.6 * (0.7 * t).sin();
            let radius = 1.0 + DEPTH_SWING * (2.0 * std::f64::consts::TAU * t).sin();
            radius
                * DVec3::new(
                    latitude.cos() * longitude.cos(),
                    latitude.cos() * longitude.sin(),
                    latitude.sin(),
                )
        })
        .collect()
}

/// One pass of the servo's queries along `path` (a sum of what they return).
pub fn run(sampler: &mut Sampler, path: &[DVec3]) -> f64 {
    let mut sum = 0.0;
    let mut inside = false;
    let mut last = path[0];
    for &tip in path {
        let (f, _) = sampler.gradient(tip, 0.0);
        if (f >= 0.0) != inside {
            inside = f >= 0.0;
            sum += crossing(sampler, last, tip, f);
        }
        if inside {
            sum += effect(sampler, tip);
        }
        last = tip;
    }
    sum
}

/// The crossing of the surface between the last tip `p0` and `p1`, as `update_stack`
/// finds it.
fn crossing(sampler: &mut Sampler, p0: DVec3, p1: DVec3, f1: f64) -> f64 {
    let f0 = sampler.gradient(p0, 0.0).0;
    model::root::crossing(0.0, f0, 1.0, f1, |s| {
        sampler.gradient(p0.lerp(p1, s), 0.0).0
    })
}

/// What `effect_force` asks of the ruling container at the tip.
fn effect(sampler: &mut Sampler, tip: DVec3) -> f64 {
    let (f, grad) = sampler.gradient(tip, 0.0);
    let depth = f.max(0.0) / grad.length().max(f64::MIN_POSITIVE);
    let zone = sampler
        .scalar(Paintable::ZoneDepth, tip, 0.0)
        .unwrap_or(ZONE_DEPTH);
    let tension = if depth < zone {
        sampler.scalar(Paintable::Tension, tip, 0.0)
    } else {
        None
    };
    let felt = match tension {
        Some(t) => t + sampler.scalar(Paintable::Friction, tip, 0.0).unwrap_or(0.0),
        None => sampler.scalar(Paintable::Density, tip, 0.0).unwrap_or(0.0),
    };
    let field = sampler.force(tip, 0.0).map_or(0.0, |v| v.x);
    depth + felt + field
}
