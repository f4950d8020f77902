//! The shared tool through the real servo: two servos with simulated hands, their
//! `SharedToolLink`s joined by a delayed, jittery, lossy link as the app's network side joins
//! them (latest packet only, taken at the sender's rate). A moves her device in circles, B holds
//! his still: B feels A, and the coupling stays passive at 0, 50 and 200 ms one-way delay
//! (an energy observer on both devices: the coupling never gives out energy it did not take in).
#![allow(
    clippy::unwrap_used,
    reason = "test helpers outside #[test] fns unwrap"
)]

use std::collections::VecDeque;

use glam::DVec3;
use haptic::aabb::Aabb;
use haptic::container::Container;
use haptic::device::sim::{HandModel, SimDevice, Waypoint};
use haptic::device::{Capabilities, HapticDevice as _};
use haptic::force::wave::WavePacket;
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, Rig};
use haptic::servo::Servo;
use haptic::shapes::circle_waypoints;
use haptic::shared::DEFAULT_COUPLING;
use rand_core::{RngCore, SeedableRng};

/// No objects: only the coupling acts.
type Scene = Vec<Box<dyn Container>>;

const DT: f64 = 0.001;
const SECONDS: f64 = 6.0;
/// How often the network side sends the servo's latest packet (the app's rate).
const SEND_EVERY_TICKS: usize = 4;

fn rig() -> Rig {
    let caps = Capabilities::falcon();
    Rig {
        caps,
        zone: HapticZone::fit(
            caps.workspace_metres,
            Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0)),
        ),
        params: ForceParams::default(),
    }
}

/// One direction of the network: packets arrive after the delay plus jitter in [-J, J]
/// (overtaking each other), a share of them lost.
struct Wire {
    delay_secs: f64,
    jitter_secs: f64,
    loss: f64,
    in_flight: VecDeque<(f64, WavePacket)>,
}

impl Wire {
    fn send(&mut self, now: f64, p: WavePacket, rng: &mut rand_chacha::ChaCha8Rng) {
        let unit =
            |rng: &mut rand_chacha::ChaCha8Rng| (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        if unit(rng) < self.loss {
            return;
        }
        let jitter = (2.0 * unit(rng) - 1.0) * self.jitter_secs;
        self.in_flight
            .push_back((now + (self.delay_secs + jitter).max(0.0), p));
    }

    fn arrived(&mut self, now: f64) -> Vec<WavePacket> {
        let mut due: Vec<(f64, WavePacket)> = Vec::new();
        self.in_flight.retain(|(at, p)| {
            let arrived = *at <= now;
            if arrived {
                due.push((*at, *p));
            }
            !arrived
        });
        due.sort_by(|a, b| a.0.total_cmp(&b.0));
        due.into_iter().map(|(_, p)| p).collect()
    }
}

#[derive(Debug)]
struct Run {
    /// The least energy the coupling had absorbed from both devices, joules.
    min_absorbed_joules: f64,
    /// The most wave energy B had taken in beyond what A had sent, joules (never positive
    /// when the link makes no energy).
    max_b_in_over_a_out_joules: f64,
    /// Root mean square coupling force on B, newtons.
    rms_force_on_b: f64,
    /// How far B's tip moved along x, metres (A's circle lies in x and y).
    b_travel_x: f64,
}

fn run(delay_secs: f64, jitter_secs: f64, loss: f64, seed: u64) -> Run {
    run_troubled(delay_secs, jitter_secs, loss, seed, Trouble::default())
}

/// What goes wrong now and then during a run, on both sides: A at every `n`th tick, B 50
/// ticks later.
#[derive(Clone, Copy, Debug, Default)]
struct Trouble {
    /// The servo stalls (one tick of 20 ms, past the stall limit), as a loaded machine's
    /// servo thread does.
    stall_every: Option<usize>,
    /// The app starts the coupling afresh, as when a partner lets go and takes hold again.
    restart_every: Option<usize>,
}

fn run_troubled(delay_secs: f64, jitter_secs: f64, loss: f64, seed: u64, trouble: Trouble) -> Run {
    let caps = Capabilities::falcon();
    let hand_a = HandModel {
        stiffness_newtons_per_metre: 300.0,
        damping_newton_secs_per_metre: 8.0,
        ..HandModel::default()
    };
    let hand_b = HandModel {
        stiffness_newtons_per_metre: 60.0,
        damping_newton_secs_per_metre: 1.0,
        ..HandModel::default()
    };
    let a = SimDevice::new(caps, circle_waypoints(0.02, 1.0, 8), hand_a, DT).unwrap();
    let still = vec![Waypoint {
        t_secs: 0.0,
        position_metres: DVec3::new(0.0, 0.0, 0.01),
    }];
    let b = SimDevice::new(caps, still, hand_b, DT).unwrap();
    let (mut servo_a, link_a) = Servo::<_, Scene>::init(a, rig());
    let (mut servo_b, link_b) = Servo::<_, Scene>::init(b, rig());
    link_a.shared.start(DEFAULT_COUPLING);
    link_b.shared.start(DEFAULT_COUPLING);
    let wire = || Wire {
        delay_secs,
        jitter_secs,
        loss,
        in_flight: VecDeque::new(),
    };
    let mut wires = [wire(), wire()];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (mut absorbed, mut min_absorbed) = (0.0f64, 0.0f64);
    let mut max_excess = f64::NEG_INFINITY;
    let mut commanded = [DVec3::ZERO; 2];
    let (mut sum_sq_b, mut b_x) = (0.0, (f64::INFINITY, f64::NEG_INFINITY));
    let n_ticks = (SECONDS / DT) as usize;
    for tick in 0..n_ticks {
        let t = tick as f64 * DT;
        for (side, link) in [&link_a, &link_b].into_iter().enumerate() {
            for p in wires[1 - side].arrived(t) {
                link.shared.deliver(&p);
            }
        }
        let before = [servo_a.device().tip_metres(), servo_b.device().tip_metres()];
        let now = |every: Option<usize>, offset: usize| {
            every.is_some_and(|n| tick % n == (n - 1 + offset) % n)
        };
        for (offset, link) in [(0, &link_a), (50, &link_b)] {
            if now(trouble.restart_every, offset) {
                link.shared.start(DEFAULT_COUPLING);
            }
        }
        let stalls = |offset| now(trouble.stall_every, offset);
        servo_a.step(if stalls(0) { 0.02 } else { DT });
        servo_b.step(if stalls(50) { 0.02 } else { DT });
        let after = [servo_a.device().tip_metres(), servo_b.device().tip_metres()];
        // A device moves during its sample under the force commanded the tick before, so
        // that force did this tick's work.
        for (side, link) in [&link_a, &link_b].into_iter().enumerate() {
            absorbed -= commanded[side].dot(after[side] - before[side]);
            commanded[side] = link.shared.force_newtons();
            if tick % SEND_EVERY_TICKS == 0
                && let Some(p) = link.shared.take_outgoing()
            {
                wires[side].send(t, p, &mut rng);
            }
        }
        min_absorbed = min_absorbed.min(absorbed);
        max_excess =
            max_excess.max(link_b.shared.energy_in_joules() - link_a.shared.energy_out_joules());
        sum_sq_b += link_b.shared.force_newtons().length_squared();
        b_x = (b_x.0.min(after[1].x), b_x.1.max(after[1].x));
    }
    Run {
        min_absorbed_joules: min_absorbed,
        max_b_in_over_a_out_joules: max_excess,
        rms_force_on_b: (sum_sq_b / n_ticks as f64).sqrt(),
        b_travel_x: b_x.1 - b_x.0,
    }
}

#[test]
fn two_servos_share_a_tool_passively_at_0_50_and_200_ms() {
    for (delay, jitter, loss) in [(0.0, 0.0, 0.0), (0.05, 0.01, 0.05), (0.2, 0.02, 0.05)] {
        for seed in 1..=3 {
            let r = run(delay, jitter, loss, seed);
            // Passive: whatever energy the devices got back, they had put in first (a
            // millijoule of slack for the one-tick offset between force and motion).
            assert!(
                r.min_absorbed_joules > -1e-3,
                "{delay} s, seed {seed}: {r:?}"
            );
            // B feels A and is moved by her.
            assert!(r.rms_force_on_b > 0.05, "{delay} s, seed {seed}: {r:?}");
            assert!(r.b_travel_x > 0.002, "{delay} s, seed {seed}: {r:?}");
        }
    }
}

/// Over the whole run B never takes in more wave energy than A's account says she sent, the
/// devices get back no more than they put in, and B still feels A.
fn assert_the_accounts_hold(trouble: Trouble) {
    for seed in 1..=3 {
        let r = run_troubled(0.05, 0.01, 0.05, seed, trouble);
        assert!(r.max_b_in_over_a_out_joules <= 1e-9, "seed {seed}: {r:?}");
        assert!(r.min_absorbed_joules > -1e-3, "seed {seed}: {r:?}");
        assert!(r.rms_force_on_b > 0.05, "seed {seed}: {r:?}");
    }
}

#[test]
fn a_stalling_servo_keeps_its_coupling_and_takes_in_no_more_than_was_sent() {
    // A stall pauses that side: its port and energy account go on.
    assert_the_accounts_hold(Trouble {
        stall_every: Some(300),
        ..Trouble::default()
    });
}

#[test]
fn couplings_started_afresh_take_in_no_more_than_was_sent_over_all_of_them() {
    // Each side's account runs on across its couplings, and a new coupling takes in only what
    // the other side sends after it began.
    assert_the_accounts_hold(Trouble {
        restart_every: Some(700),
        ..Trouble::default()
    });
}

#[test]
fn without_the_coupling_b_feels_nothing_of_a() {
    let caps = Capabilities::falcon();
    let a = SimDevice::new(
        caps,
        circle_waypoints(0.02, 1.0, 2),
        HandModel::default(),
        DT,
    )
    .unwrap();
    let (mut servo, link) = Servo::<_, Scene>::init(a, rig());
    link.shared.deliver(&WavePacket {
        t_secs: 0.0,
        wave: DVec3::new(50.0, 0.0, 0.0),
        energy_sent_joules: 100.0,
    });
    for _ in 0..500 {
        servo.step(DT);
        assert_eq!(servo.device().force_newtons(), DVec3::ZERO);
        assert!(link.shared.take_outgoing().is_none());
    }
    assert!(servo.device().capabilities().has_force_output());
}
