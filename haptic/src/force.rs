//! Force rendering as a pure function of (scene snapshot, proxy state, device sample, time,
//! `dt_secs`): HIP location by function sign, the entry-order container stack, surface
//! tension with pop-through, friction, density, force fields, and the safety layer.
//!
//! Per tick, [`render`]:
//! 1. maps the device tip through the [`HapticZone`] to the haptic interface point (HIP);
//! 2. updates the [`ContainerStack`]: containers whose sign changed along the segment
//!    travelled are ordered by the root of `f` on that segment ([`model::root::crossing`]),
//!    entering pushes, leaving removes; a HIP with no history gets a deterministic stack,
//!    innermost on top;
//! 3. renders the top container: within its surface zone (metric depth `f/|grad f|` below the
//!    zone depth) surface tension along the outward normal plus friction against tangential
//!    motion; deeper (the membrane popped), density as viscosity on filtered velocity; a force
//!    field anywhere inside, in the container's normalised domain with cycle and time span;
//! 4. makes it safe: a passivity observer adds damping when energy was injected, switching
//!    effects cross-fades, forces ramp in after a start or stall, the total is clamped to the
//!    device's maximum force and its change per tick is limited; a stall gives zero force.
//!
//! Guarantees: no allocation, no locks, no clock; output magnitude `<= force_newtons_max`;
//! `|F(k) - F(k-1)| <= force_step_fraction_max * force_newtons_max` except when dropping to
//! zero on a stall. Non-guarantees: two crossings of the same container within one tick are
//! not seen (at 1 kHz a tick moves well under a millimetre).

pub mod coupling;
pub mod stack;
pub mod wave;
pub mod zone;

#[cfg(test)]
mod tests;

use glam::DVec3;

use crate::container::{Container, MIN_GRADIENT_NORM, Scene};
use crate::device::{Capabilities, DeviceSample};
use stack::{ContainerStack, StackEntry};
use zone::HapticZone;

/// The most containers a scene may present to the renderer; further ones are not touched.
pub const MAX_CONTAINERS: usize = 256;
/// Filtered velocity components below this are zero (see `render`; BENCHMARKS.md has the
/// measurement), metres per second.
pub const VELOCITY_FLUSH_METRES_PER_SEC: f64 = 1e-12;
/// Dissipated energy the passivity observer may bank, joules; a bounded reserve keeps old
/// dissipation from hiding new injection.
pub const MAX_ENERGY_RESERVE_JOULES: f64 = 0.01;

/// Tunable safety and filtering parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceParams {
    /// Largest change of the output per tick, as a fraction of the device's maximum force.
    pub force_step_fraction_max: f64,
    /// Duration of the cross-fade when the ruling effect changes, seconds.
    pub crossfade_secs: f64,
    /// Forces ramp from zero to full over this time after a start or a stall, seconds.
    pub ramp_in_secs: f64,
    /// A tick or device sample gap longer than this is a stall: zero force, seconds.
    pub stall_secs: f64,
    /// Cut-off of the first-order velocity filter, hertz.
    pub velocity_cutoff_hz: f64,
    /// Below this tangential speed friction fades out linearly, metres per second.
    pub friction_speed_metres_per_sec: f64,
    /// Whether the passivity observer may add damping.
    pub passivity: bool,
}

impl Default for ForceParams {
    fn default() -> Self {
        Self {
            force_step_fraction_max: 0.05,
            crossfade_secs: 0.01,
            ramp_in_secs: 0.25,
            stall_secs: 0.005,
            velocity_cutoff_hz: 40.0,
            friction_speed_metres_per_sec: 0.005,
            passivity: true,
        }
    }
}

/// Everything about the rig that is not the scene: device limits, zone, parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rig {
    /// The device's capabilities.
    pub caps: Capabilities,
    /// Where the device workspace sits in the scene.
    pub zone: HapticZone,
    /// Safety and filtering parameters.
    pub params: ForceParams,
}

impl Rig {
    /// The surface zone's depth in world units where a container gives none: the device's
    /// own ([`Capabilities::zone_depth_metres`]) through the zone's scale, so that resizing
    /// the zone keeps the depth the hand feels.
    pub fn zone_depth_world(&self) -> f64 {
        self.zone.world_distance(self.caps.zone_depth_metres())
    }
}

/// Where the HIP is relative to the ruling container.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// Outside every container.
    Free,
    /// Inside the top container, within its surface zone, with tension active.
    Surface,
    /// Inside the top container, below the surface zone (or with no tension).
    Interior,
}

/// What one tick produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickOutput {
    /// The force to send, newtons, device frame.
    pub force_newtons: DVec3,
    /// The effect force before the safety layer, newtons, device frame (for plots and tests).
    pub raw_force_newtons: DVec3,
    /// The haptic interface point, world.
    pub hip_world: DVec3,
    /// The ruling container.
    pub top_id: Option<u64>,
    /// The HIP's region in the ruling container.
    pub region: Region,
    /// True when the tick or device stalled (force is zero).
    pub stalled: bool,
    /// Damping added by the passivity observer, newton-seconds per metre.
    pub passivity_damping: f64,
}

#[derive(Clone, Copy, Debug, Default)]
struct Crossing {
    s: f64,
    id: u64,
    idx: u32,
    entering: bool,
}

#[derive(Clone, Copy, Debug)]
struct Prev {
    hip_world: DVec3,
    position_device: DVec3,
    timestamp_micros: u64,
}

/// The proxy state carried between ticks (fixed size; built once at init).
#[derive(Clone, Debug)]
pub struct ProxyState {
    stack: ContainerStack,
    prev: Option<Prev>,
    velocity_device: DVec3,
    force_out: DVec3,
    field_out: DVec3,
    effect: (Option<u64>, Region),
    fade_from: DVec3,
    fade_left_secs: f64,
    ramp: f64,
    energy_joules: f64,
    crossings: [Crossing; MAX_CONTAINERS],
}

impl Default for ProxyState {
    fn default() -> Self {
        Self::new()
    }
}

impl ProxyState {
    /// A state with no history: the next tick locates the HIP from scratch.
    pub fn new() -> Self {
        Self {
            stack: ContainerStack::default(),
            prev: None,
            velocity_device: DVec3::ZERO,
            force_out: DVec3::ZERO,
            field_out: DVec3::ZERO,
            effect: (None, Region::Free),
            fade_from: DVec3::ZERO,
            fade_left_secs: 0.0,
            ramp: 0.0,
            energy_joules: 0.0,
            crossings: [Crossing::default(); MAX_CONTAINERS],
        }
    }

    /// Forgets all history (no allocation).
    pub fn reset(&mut self) {
        self.stack.clear();
        self.prev = None;
        self.velocity_device = DVec3::ZERO;
        self.force_out = DVec3::ZERO;
        self.field_out = DVec3::ZERO;
        self.effect = (None, Region::Free);
        self.fade_left_secs = 0.0;
        self.ramp = 0.0;
        self.energy_joules = 0.0;
    }

    /// The containers the HIP is inside, in entry order (last rules).
    pub fn stack(&self) -> &ContainerStack {
        &self.stack
    }

    /// The passivity observer's energy: dissipated minus injected, joules (bounded above).
    pub fn energy_joules(&self) -> f64 {
        self.energy_joules
    }

    /// The filtered tip velocity, metres per second, device frame.
    pub fn velocity_device(&self) -> DVec3 {
        self.velocity_device
    }

    /// The last force sent, newtons, device frame.
    pub fn force_newtons(&self) -> DVec3 {
        self.force_out
    }
}

/// Renders one tick. See the module documentation for the steps and guarantees.
pub fn render<S: Scene + ?Sized>(
    scene: &mut S,
    state: &mut ProxyState,
    rig: &Rig,
    sample: &DeviceSample,
    t_secs: f64,
    dt_secs: f64,
) -> TickOutput {
    let params = &rig.params;
    let hip_world = rig.zone.world_from_device(sample.position_metres);
    let gap_secs = state.prev.map_or(0.0, |prev| {
        sample
            .timestamp_micros
            .saturating_sub(prev.timestamp_micros) as f64
            * 1e-6
    });
    let stalled = !(dt_secs.is_finite() && dt_secs > 0.0 && dt_secs <= params.stall_secs)
        || gap_secs > params.stall_secs
        || !hip_world.is_finite();
    if stalled {
        state.reset();
        return TickOutput {
            force_newtons: DVec3::ZERO,
            raw_force_newtons: DVec3::ZERO,
            hip_world,
            top_id: None,
            region: Region::Free,
            stalled: true,
            passivity_damping: 0.0,
        };
    }
    let dt_device = if gap_secs > 0.0 { gap_secs } else { dt_secs };
    follow(scene, state, params, sample, hip_world, dt_device, t_secs);
    let effect = effect_force(scene, state, rig, hip_world, t_secs);
    let damping = passivity_damping(state, rig, dt_secs);
    let raw = effect.passive + effect.field;
    let target = raw - state.velocity_device * damping;
    let out = safe_output(state, rig, (effect.top_id, effect.region), target, dt_secs);
    state.field_out = effect.field.clamp_length_max(out.length()) * state.ramp;
    TickOutput {
        force_newtons: out,
        raw_force_newtons: raw,
        hip_world,
        top_id: effect.top_id,
        region: effect.region,
        stalled: false,
        passivity_damping: damping,
    }
}

/// Follows the tip from the last tick to `sample` (the HIP now at `hip_world`, `dt_device`
/// seconds later): its filtered velocity, the passivity observer's energy and the container
/// stack; a first tick only places the stack.
fn follow<S: Scene + ?Sized>(
    scene: &mut S,
    state: &mut ProxyState,
    params: &ForceParams,
    sample: &DeviceSample,
    hip_world: DVec3,
    dt_device: f64,
    t_secs: f64,
) {
    match state.prev {
        Some(prev) => {
            let step = sample.position_metres - prev.position_device;
            let alpha = filter_alpha(dt_device, params.velocity_cutoff_hz);
            let velocity = state.velocity_device.lerp(step / dt_device, alpha);
            // Flush speeds no sensor resolves: at rest the filter's geometric decay would
            // otherwise reach subnormal numbers and stay there (the smallest subnormal times
            // `1 - alpha` rounds back to itself), which doubles the cost of a tick.
            state.velocity_device = DVec3::select(
                velocity
                    .abs()
                    .cmplt(DVec3::splat(VELOCITY_FLUSH_METRES_PER_SEC)),
                DVec3::ZERO,
                velocity,
            );
            // Work done on the environment by the hand over the last tick, against the
            // passive part of the force that was acting.
            let passive = state.force_out - state.field_out;
            state.energy_joules =
                (state.energy_joules - passive.dot(step)).min(MAX_ENERGY_RESERVE_JOULES);
            update_stack(scene, state, prev.hip_world, hip_world, t_secs);
        }
        None => {
            state.velocity_device = DVec3::ZERO;
            init_stack(scene, state, hip_world, t_secs);
        }
    }
    state.prev = Some(Prev {
        hip_world,
        position_device: sample.position_metres,
        timestamp_micros: sample.timestamp_micros,
    });
}

/// The coefficient of a first-order low-pass at `cutoff_hz` sampled every `dt_secs`.
fn filter_alpha(dt_secs: f64, cutoff_hz: f64) -> f64 {
    let tau = 1.0 / (std::f64::consts::TAU * cutoff_hz.max(f64::MIN_POSITIVE));
    (dt_secs / (dt_secs + tau)).clamp(0.0, 1.0)
}

/// Damping the passivity controller adds so that the observed energy returns to zero
/// (Hannaford and Ryu), limited by the device's maximum damping.
fn passivity_damping(state: &ProxyState, rig: &Rig, dt_secs: f64) -> f64 {
    let speed_sq = state.velocity_device.length_squared();
    if !rig.params.passivity || state.energy_joules >= 0.0 || speed_sq < 1e-12 {
        return 0.0;
    }
    let needed = -state.energy_joules / (dt_secs * speed_sq);
    needed.min(rig.caps.damping_newton_secs_per_metre_max)
}

/// Cross-fade, ramp-in, clamp to the device maximum and limit the change per tick.
fn safe_output(
    state: &mut ProxyState,
    rig: &Rig,
    key: (Option<u64>, Region),
    target: DVec3,
    dt_secs: f64,
) -> DVec3 {
    let params = &rig.params;
    if key != state.effect {
        state.effect = key;
        state.fade_from = state.force_out;
        state.fade_left_secs = params.crossfade_secs;
    }
    let mut blended = if target.is_finite() {
        target
    } else {
        DVec3::ZERO
    };
    if state.fade_left_secs > 0.0 && params.crossfade_secs > 0.0 {
        let weight = (state.fade_left_secs / params.crossfade_secs).clamp(0.0, 1.0);
        blended = blended.lerp(state.fade_from, weight);
        state.fade_left_secs -= dt_secs;
    }
    state.ramp = if params.ramp_in_secs > 0.0 {
        (state.ramp + dt_secs / params.ramp_in_secs).min(1.0)
    } else {
        1.0
    };
    let force_max = if rig.caps.has_force_output() {
        rig.caps.force_newtons_max
    } else {
        0.0
    };
    let clamped = (blended * state.ramp).clamp_length_max(force_max);
    let step_max = params.force_step_fraction_max * force_max;
    let out = state.force_out + (clamped - state.force_out).clamp_length_max(step_max);
    state.force_out = out;
    out
}

struct Effect {
    passive: DVec3,
    field: DVec3,
    top_id: Option<u64>,
    region: Region,
}

impl Effect {
    /// Outside every container: nothing acts.
    const FREE: Effect = Effect {
        passive: DVec3::ZERO,
        field: DVec3::ZERO,
        top_id: None,
        region: Region::Free,
    };
}

/// A finite value from an untrusted property function, or `None`.
fn finite(value: Option<f64>) -> Option<f64> {
    value.filter(|v| v.is_finite())
}

/// The top container's force at the HIP before the safety layer: tension along the normal
/// and friction within its surface zone, density as viscosity deeper, and its force field.
fn effect_force<S: Scene + ?Sized>(
    scene: &mut S,
    state: &ProxyState,
    rig: &Rig,
    hip: DVec3,
    t_secs: f64,
) -> Effect {
    let Some(top) = state.stack.top() else {
        return Effect::FREE;
    };
    let caps = &rig.caps;
    let container = scene.container_mut(top.idx as usize);
    let (f, grad) = container.value_grad(hip, t_secs);
    let grad_len = grad.length();
    let usable = grad_len > MIN_GRADIENT_NORM && f.is_finite() && grad.is_finite();
    let depth = if usable {
        f.max(0.0) / grad_len
    } else {
        f64::INFINITY
    };
    let zone_depth = container
        .zone_depth(hip, t_secs)
        .unwrap_or_else(|| rig.zone_depth_world());
    let tension = if depth < zone_depth {
        finite(container.tension(hip, t_secs))
    } else {
        None
    };
    let velocity = state.velocity_device;
    let (passive, region) = match tension {
        Some(tension) => {
            let n_device = rig.zone.device_from_world_dir(-grad / grad_len);
            let stiffness = tension.clamp(0.0, 1.0) * caps.stiffness_newtons_per_metre_max;
            let tension_force = n_device * stiffness * rig.zone.device_metres(depth);
            let mut force = tension_force;
            if let Some(mu) = finite(container.friction(hip, t_secs)) {
                let tangential = velocity - velocity.dot(n_device) * n_device;
                let speed = tangential.length();
                let scale = speed.max(rig.params.friction_speed_metres_per_sec);
                force -= tangential / scale * mu.clamp(0.0, 1.0) * tension_force.length();
            }
            (force, Region::Surface)
        }
        None => {
            let force = match finite(container.density(hip, t_secs)) {
                Some(density) => {
                    -velocity * density.clamp(0.0, 1.0) * caps.damping_newton_secs_per_metre_max
                }
                None => DVec3::ZERO,
            };
            (force, Region::Interior)
        }
    };
    Effect {
        passive,
        field: field_force(container, rig, hip, t_secs),
        top_id: Some(top.id),
        region,
    }
}

/// The container's force field at the HIP, newtons, device frame: a fraction of the device's
/// maximum force (at most all of it); zero where no field acts or it is not finite.
fn field_force(container: &mut dyn Container, rig: &Rig, hip: DVec3, t_secs: f64) -> DVec3 {
    container
        .field_at(hip, t_secs)
        .filter(|v| v.is_finite())
        .map_or(DVec3::ZERO, |v| {
            rig.zone.device_from_world_dir(v.clamp_length_max(1.0)) * rig.caps.force_newtons_max
        })
}

/// Re-resolves stack entries to indices of the current scene, dropping vanished containers.
fn resolve_stack<S: Scene + ?Sized>(scene: &mut S, stack: &mut ContainerStack) {
    let n = scene.n_containers().min(MAX_CONTAINERS);
    for entry in stack.entries_mut() {
        let idx = entry.idx as usize;
        if idx < n && scene.container_mut(idx).id() == entry.id {
            continue;
        }
        let found = (0..n).find(|&k| scene.container_mut(k).id() == entry.id);
        // Index n marks an entry to drop.
        entry.idx = found.unwrap_or(n) as u32;
    }
    stack.retain(|e| (e.idx as usize) < n);
}

/// Sorts crossings by (parameter along the segment, id): insertion sort, no allocation.
fn sort_crossings(crossings: &mut [Crossing]) {
    for k in 1..crossings.len() {
        let mut j = k;
        while j > 0 && (crossings[j].s, crossings[j].id) < (crossings[j - 1].s, crossings[j - 1].id)
        {
            crossings.swap(j, j - 1);
            j -= 1;
        }
    }
}

fn update_stack<S: Scene + ?Sized>(
    scene: &mut S,
    state: &mut ProxyState,
    p0: DVec3,
    p1: DVec3,
    t_secs: f64,
) {
    resolve_stack(scene, &mut state.stack);
    let n = scene.n_containers().min(MAX_CONTAINERS);
    let mut n_crossings = 0;
    for idx in 0..n {
        let container = scene.container_mut(idx);
        let id = container.id();
        let was_inside = state.stack.contains(id);
        if !was_inside && !container.bounds().contains(p1) {
            continue;
        }
        let f1 = container.value_grad(p1, t_secs).0;
        let inside = f1 >= 0.0;
        if inside == was_inside {
            continue;
        }
        let s = match container.first_crossing(p0, p1, t_secs) {
            Some(s) => s.clamp(0.0, 1.0),
            // No sign change along the segment (the shape moved under the HIP) gives 1.
            None => model::root::crossing(0.0, container.value_grad(p0, t_secs).0, 1.0, f1, |s| {
                container.value_grad(p0.lerp(p1, s), t_secs).0
            }),
        };
        state.crossings[n_crossings] = Crossing {
            s,
            id,
            idx: idx as u32,
            entering: inside,
        };
        n_crossings += 1;
    }
    sort_crossings(&mut state.crossings[..n_crossings]);
    for crossing in &state.crossings[..n_crossings] {
        if crossing.entering {
            state.stack.push(StackEntry {
                id: crossing.id,
                idx: crossing.idx,
            });
        } else {
            state.stack.remove(crossing.id);
        }
    }
}

/// Builds the stack of a HIP with no history: every container it is inside, the one with the
/// smallest metric depth (the innermost) on top, ties broken by id.
fn init_stack<S: Scene + ?Sized>(scene: &mut S, state: &mut ProxyState, p: DVec3, t_secs: f64) {
    state.stack.clear();
    let n = scene.n_containers().min(MAX_CONTAINERS);
    let mut n_inside = 0;
    for idx in 0..n {
        let container = scene.container_mut(idx);
        if !container.bounds().contains(p) {
            continue;
        }
        let (f, grad) = container.value_grad(p, t_secs);
        if f < 0.0 || !f.is_finite() {
            continue;
        }
        let grad_len = grad.length();
        let depth = if grad_len > MIN_GRADIENT_NORM {
            f / grad_len
        } else {
            f64::INFINITY
        };
        // Deepest first, so that the innermost is pushed last and rules.
        state.crossings[n_inside] = Crossing {
            s: -depth,
            id: container.id(),
            idx: idx as u32,
            entering: true,
        };
        n_inside += 1;
    }
    sort_crossings(&mut state.crossings[..n_inside]);
    for crossing in &state.crossings[..n_inside] {
        state.stack.push(StackEntry {
            id: crossing.id,
            idx: crossing.idx,
        });
    }
}
