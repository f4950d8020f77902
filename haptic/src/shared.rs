//! A shared tool in the servo: two peers' devices coupled through the network by wave
//! variables ([`crate::force::wave`]), so each feels the other and delay cannot make the
//! coupling active.
//!
//! Every [`crate::servo::Servo`] owns one [`SharedToolLink`], shared with the app through
//! [`crate::servo::ServoLink::shared`]. The app starts the coupling
//! ([`SharedToolLink::start`]) when two peers hold the tool together and stops it when either
//! lets go; its network side hands the other peer's packets in
//! ([`SharedToolLink::deliver`]) and sends the servo's own out
//! ([`SharedToolLink::take_outgoing`]). Between the two sides each direction is a latest-value
//! slot (a sequence lock over plain atomics): the servo never waits, never allocates, and a
//! packet it misses is subsumed by the next one, whose cumulative energy account covers it.
//!
//! The coupling runs in device metres: each device's tip, and its filtered velocity, against
//! the wave port's spring. The coupling's force is added to the scene's and the sum clamped to
//! the device's maximum; on its own it is at most [`MAX_COUPLING_FORCE_SHARE`] of that maximum,
//! so that a partner (who is another peer, not trusted) can push at most that hard.

use std::sync::atomic::{AtomicU64, Ordering, fence};

use glam::DVec3;

use crate::force::wave::{WaveCoupling, WavePacket, WavePort};

/// The largest part of the device's maximum force the coupling alone may apply.
pub const MAX_COUPLING_FORCE_SHARE: f64 = 0.5;

/// The coupling a shared tool uses unless the app chooses another: stiff and lightly damped,
/// as the haptic crate's delay test holds it passive at 0, 50 and 200 ms.
pub const DEFAULT_COUPLING: WaveCoupling = WaveCoupling {
    impedance: 10.0,
    stiffness: 500.0,
    damping: 2.0,
};

/// A latest-value slot for one [`WavePacket`]: one writer, any readers, no locks.
#[derive(Debug, Default)]
struct PacketSlot {
    /// Even when stable, odd while written; 0 before the first packet.
    seq: AtomicU64,
    /// `t_secs`, the wave's x, y, z and `energy_sent_joules`, as bits.
    words: [AtomicU64; 5],
}

impl PacketSlot {
    /// Writes `p` (only one thread may write a slot).
    fn store(&self, p: &WavePacket) {
        let seq = self.seq.load(Ordering::Relaxed);
        self.seq.store(seq.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        let values = [p.t_secs, p.wave.x, p.wave.y, p.wave.z, p.energy_sent_joules];
        for (word, value) in self.words.iter().zip(values) {
            word.store(value.to_bits(), Ordering::Relaxed);
        }
        self.seq.store(seq.wrapping_add(2), Ordering::Release);
    }

    /// The latest packet and its sequence number; `None` before the first one or while it is
    /// being written (the reader tries again on its next tick rather than wait).
    fn load(&self) -> Option<(u64, WavePacket)> {
        let before = self.seq.load(Ordering::Acquire);
        if before == 0 || before & 1 == 1 {
            return None;
        }
        let w = self
            .words
            .each_ref()
            .map(|word| f64::from_bits(word.load(Ordering::Relaxed)));
        fence(Ordering::Acquire);
        if self.seq.load(Ordering::Relaxed) != before {
            return None;
        }
        Some((
            before,
            WavePacket {
                t_secs: w[0],
                wave: DVec3::new(w[1], w[2], w[3]),
                energy_sent_joules: w[4],
            },
        ))
    }
}

/// The app's handle on one servo's shared tool (see the module documentation).
#[derive(Debug, Default)]
pub struct SharedToolLink {
    /// Packets from the other peer, for the servo.
    inbound: PacketSlot,
    /// The servo's packets, for the other peer.
    outbound: PacketSlot,
    /// 0: no coupling; otherwise the coupling's generation (a new one starts afresh).
    generation: AtomicU64,
    /// The last generation handed out.
    generations: AtomicU64,
    /// The coupling's impedance, stiffness and damping, as bits (set before `generation`).
    coupling: [AtomicU64; 3],
    /// The last outbound sequence number taken by [`SharedToolLink::take_outgoing`].
    taken: AtomicU64,
    /// The inbound sequence number when the coupling started: packets up to it belong to an
    /// earlier coupling.
    start_seq: AtomicU64,
    /// The other side's energy account in the last packet up to `start_seq`, joules, as bits:
    /// the new coupling takes in only what the other side sends beyond it.
    start_peer_sent_bits: AtomicU64,
    /// Wave energy in and out of this side so far, joules, and the coupling force, newtons
    /// (device frame), as bits: written by the servo.
    energy_in_bits: AtomicU64,
    energy_out_bits: AtomicU64,
    force_bits: [AtomicU64; 3],
    /// What the ports of ended couplings took in and sent, joules, as bits (servo only): each
    /// side's account runs on across couplings, so the other side never counts energy twice.
    ended_in_bits: AtomicU64,
    ended_out_bits: AtomicU64,
}

impl SharedToolLink {
    /// Starts a coupling with `coupling` (a fresh one: the port at the tool, no wave in
    /// flight), replacing any running one. Non-positive impedance or stiffness, or negative
    /// damping, fall back to [`DEFAULT_COUPLING`].
    pub fn start(&self, coupling: WaveCoupling) {
        let valid = coupling.impedance > 0.0
            && coupling.stiffness > 0.0
            && coupling.damping >= 0.0
            && coupling.impedance.is_finite()
            && coupling.stiffness.is_finite()
            && coupling.damping.is_finite();
        let c = if valid { coupling } else { DEFAULT_COUPLING };
        for (word, value) in self
            .coupling
            .iter()
            .zip([c.impedance, c.stiffness, c.damping])
        {
            word.store(value.to_bits(), Ordering::Relaxed);
        }
        // The latest packet and its number, read whole: a packet being written is waited
        // for (one writer, a few stores; this is the app's thread, not the servo's).
        let (seq, peer_sent) = loop {
            if let Some((seq, p)) = self.inbound.load() {
                break (seq, p.energy_sent_joules);
            }
            if self.inbound.seq.load(Ordering::Acquire) == 0 {
                break (0, 0.0);
            }
            std::hint::spin_loop();
        };
        self.start_seq.store(seq, Ordering::Relaxed);
        self.start_peer_sent_bits
            .store(peer_sent.to_bits(), Ordering::Relaxed);
        let generation = self.generations.fetch_add(1, Ordering::Relaxed) + 1;
        self.generation.store(generation, Ordering::Release);
    }

    /// Stops the coupling: the servo adds no coupling force from its next tick.
    pub fn stop(&self) {
        self.generation.store(0, Ordering::Release);
    }

    /// Whether a coupling runs.
    pub fn is_coupled(&self) -> bool {
        self.generation.load(Ordering::Acquire) != 0
    }

    /// Hands the servo a packet from the other peer (one thread delivers). A packet with a
    /// number that is not finite, or a negative energy, is dropped.
    pub fn deliver(&self, packet: &WavePacket) {
        let finite = packet.t_secs.is_finite()
            && packet.wave.is_finite()
            && packet.energy_sent_joules.is_finite()
            && packet.energy_sent_joules >= 0.0;
        if finite {
            self.inbound.store(packet);
        }
    }

    /// The servo's newest packet not taken before, to send to the other peer.
    pub fn take_outgoing(&self) -> Option<WavePacket> {
        let (seq, packet) = self.outbound.load()?;
        (self.taken.swap(seq, Ordering::Relaxed) != seq).then_some(packet)
    }

    /// Wave energy this side has taken in from the link, joules, over every coupling.
    pub fn energy_in_joules(&self) -> f64 {
        f64::from_bits(self.energy_in_bits.load(Ordering::Relaxed))
    }

    /// Wave energy this side has sent into the link, joules, over every coupling.
    pub fn energy_out_joules(&self) -> f64 {
        f64::from_bits(self.energy_out_bits.load(Ordering::Relaxed))
    }

    /// The coupling's latest force on the device, newtons, device frame.
    pub fn force_newtons(&self) -> DVec3 {
        let [x, y, z] = self
            .force_bits
            .each_ref()
            .map(|b| f64::from_bits(b.load(Ordering::Relaxed)));
        DVec3::new(x, y, z)
    }

    fn coupling(&self) -> WaveCoupling {
        let [impedance, stiffness, damping] = self
            .coupling
            .each_ref()
            .map(|b| f64::from_bits(b.load(Ordering::Relaxed)));
        WaveCoupling {
            impedance,
            stiffness,
            damping,
        }
    }

    fn publish(&self, force: DVec3, port: Option<&WavePort>) {
        for (bits, value) in self.force_bits.iter().zip(force.to_array()) {
            bits.store(value.to_bits(), Ordering::Relaxed);
        }
        let (ended_in, ended_out) = self.ended();
        let (energy_in, energy_out) = port.map_or((0.0, 0.0), |p| {
            (p.energy_in_joules(), p.energy_out_joules())
        });
        self.energy_in_bits
            .store((ended_in + energy_in).to_bits(), Ordering::Relaxed);
        self.energy_out_bits
            .store((ended_out + energy_out).to_bits(), Ordering::Relaxed);
    }

    /// What the ports of ended couplings took in and sent, joules.
    fn ended(&self) -> (f64, f64) {
        (
            f64::from_bits(self.ended_in_bits.load(Ordering::Relaxed)),
            f64::from_bits(self.ended_out_bits.load(Ordering::Relaxed)),
        )
    }

    /// Adds an ending coupling's port to the ended accounts (the servo thread only).
    fn end(&self, port: &WavePort) {
        let (ended_in, ended_out) = self.ended();
        self.ended_in_bits.store(
            (ended_in + port.energy_in_joules()).to_bits(),
            Ordering::Relaxed,
        );
        self.ended_out_bits.store(
            (ended_out + port.energy_out_joules()).to_bits(),
            Ordering::Relaxed,
        );
    }
}

/// The servo's side of a running coupling.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Coupled {
    generation: u64,
    port: WavePort,
    /// The inbound sequence number last taken.
    seen: u64,
    /// The last tick stalled: the port is put back at the tip on the next one.
    paused: bool,
}

/// What the servo knows of one tick, for the shared tool.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tick {
    /// The device's tip, metres, device frame.
    pub tip_metres: DVec3,
    /// Its filtered velocity, metres per second.
    pub velocity_metres_per_sec: DVec3,
    /// The device's maximum force, newtons.
    pub force_max_newtons: f64,
    /// The servo's time, seconds.
    pub t_secs: f64,
    /// The tick's length, seconds.
    pub dt_secs: f64,
    /// The tick stalled (the scene renders no force either).
    pub stalled: bool,
}

/// One servo tick of the shared tool: the coupling force on the device (newtons, device
/// frame), zero when no coupling runs or the tick stalled. Never allocates or waits.
pub(crate) fn step(link: &SharedToolLink, coupled: &mut Option<Coupled>, tick: Tick) -> DVec3 {
    let Tick {
        tip_metres,
        velocity_metres_per_sec,
        force_max_newtons,
        t_secs,
        dt_secs,
        stalled,
    } = tick;
    let generation = link.generation.load(Ordering::Acquire);
    if generation == 0 {
        // Once, when a coupling ends: off, the tick costs one atomic load.
        if let Some(ended) = coupled.take() {
            link.end(&ended.port);
            link.publish(DVec3::ZERO, None);
        }
        return DVec3::ZERO;
    }
    if stalled || !tip_metres.is_finite() {
        // A stall pauses the coupling; it does not end it. A fresh port would start a fresh
        // energy account, and could then take in again wave energy the other side reported
        // before the stall, which the old port had already taken.
        if let Some(c) = coupled.as_mut().filter(|c| c.generation == generation) {
            c.paused = true;
            link.publish(DVec3::ZERO, Some(&c.port));
        }
        return DVec3::ZERO;
    }
    let c = current(link, coupled, generation, tip_metres);
    if c.paused {
        c.port.reanchor(tip_metres);
        c.paused = false;
    }
    if let Some((seq, packet)) = link.inbound.load()
        && seq != c.seen
    {
        c.seen = seq;
        c.port.receive(&packet);
    }
    let velocity = if velocity_metres_per_sec.is_finite() {
        velocity_metres_per_sec
    } else {
        DVec3::ZERO
    };
    let (force, packet) = c.port.step(tip_metres, velocity, t_secs, dt_secs);
    link.outbound.store(&packet);
    let force = if force.is_finite() {
        force.clamp_length_max(MAX_COUPLING_FORCE_SHARE * force_max_newtons)
    } else {
        DVec3::ZERO
    };
    link.publish(force, Some(&c.port));
    force
}

/// The running coupling of `generation`: the one the servo holds, or a new one at the tip
/// (the one it held, of an earlier generation, ended first).
fn current<'a>(
    link: &SharedToolLink,
    coupled: &'a mut Option<Coupled>,
    generation: u64,
    tip_metres: DVec3,
) -> &'a mut Coupled {
    if let Some(ended) = coupled.as_ref()
        && ended.generation != generation
    {
        link.end(&ended.port);
        *coupled = None;
    }
    coupled.get_or_insert_with(|| {
        // The other side's account as last heard before this coupling: this port takes in
        // only what it sends beyond that (an earlier port may have taken the rest).
        let peer_baseline = f64::from_bits(link.start_peer_sent_bits.load(Ordering::Relaxed));
        let (_, sent_before) = link.ended();
        Coupled {
            generation,
            port: WavePort::continuing(link.coupling(), tip_metres, sent_before, peer_baseline),
            // Packets from before this coupling are not this coupling's.
            seen: link.start_seq.load(Ordering::Relaxed),
            paused: false,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(t: f64) -> WavePacket {
        WavePacket {
            t_secs: t,
            wave: DVec3::new(1.0, -2.0, 0.5),
            energy_sent_joules: 0.25,
        }
    }

    #[test]
    fn a_slot_hands_over_the_latest_packet_once() {
        let link = SharedToolLink::default();
        assert!(link.take_outgoing().is_none(), "nothing written yet");
        link.outbound.store(&packet(1.0));
        assert_eq!(link.take_outgoing(), Some(packet(1.0)));
        assert!(link.take_outgoing().is_none(), "taken once");
        link.outbound.store(&packet(2.0));
        link.outbound.store(&packet(3.0));
        assert_eq!(link.take_outgoing(), Some(packet(3.0)), "the latest wins");
    }

    #[test]
    fn bad_packets_are_dropped_and_the_coupling_starts_and_stops() {
        let link = SharedToolLink::default();
        for bad in [
            WavePacket {
                t_secs: f64::NAN,
                ..packet(0.0)
            },
            WavePacket {
                wave: DVec3::new(f64::INFINITY, 0.0, 0.0),
                ..packet(0.0)
            },
            WavePacket {
                energy_sent_joules: -1.0,
                ..packet(0.0)
            },
        ] {
            link.deliver(&bad);
            assert!(link.inbound.load().is_none(), "{bad:?}");
        }
        let mut coupled = None;
        let tip = DVec3::new(0.01, 0.0, 0.0);
        let tick = |t_secs| Tick {
            tip_metres: tip,
            velocity_metres_per_sec: DVec3::ZERO,
            force_max_newtons: 8.0,
            t_secs,
            dt_secs: 1e-3,
            stalled: false,
        };
        let off = step(&link, &mut coupled, tick(0.0));
        assert_eq!(off, DVec3::ZERO);
        assert!(link.take_outgoing().is_none(), "no coupling, no packets");

        link.start(DEFAULT_COUPLING);
        assert!(link.is_coupled());
        // A partner pushing hard: the coupling pulls, at most its share of the maximum.
        link.deliver(&WavePacket {
            t_secs: 1.0,
            wave: DVec3::new(1e6, 0.0, 0.0),
            energy_sent_joules: 1e9,
        });
        let mut force = DVec3::ZERO;
        for i in 0..10 {
            force = step(&link, &mut coupled, tick(f64::from(i) * 1e-3));
        }
        assert!(force.length() > 1.0, "{force}");
        assert!(force.length() <= 4.0 + 1e-12, "{force}");
        assert!(link.take_outgoing().is_some());
        assert_eq!(link.force_newtons(), force);

        link.stop();
        let after = step(&link, &mut coupled, tick(0.1));
        assert_eq!(after, DVec3::ZERO);
        assert!(coupled.is_none());
        assert_eq!(link.force_newtons(), DVec3::ZERO);
    }
}
