//! A shared tool between two peers over a delayed network link, kept passive by wave
//! variables with energy bookkeeping.
//!
//! Coupling two devices with a spring through a link that delays each side's position by
//! tens of milliseconds makes the spring active: each side pulls towards where the other
//! was, the delayed forces feed energy in, and the tool shakes. The usual cure (Niemeyer and
//! Slotine's wave variables) sends, instead of positions or forces, the wave
//! `u = (F + b v) / sqrt(2 b)` (force `F` the side applies to the link, velocity `v` of its
//! end, wave impedance `b`). A link that only delays waves stores the energy in flight and
//! never makes any, whatever the constant delay.
//!
//! Jitter, reordering and loss break that argument (a held wave is energy sent twice), so
//! each packet also carries the sender's cumulative outgoing wave energy, and a receiver
//! never takes in more wave energy than the other side has sent: it scales down any incoming
//! wave that would overdraw the account. With that, the link is passive for any delay, jitter
//! and loss; delay costs only stiffness (the tool feels softer the longer the delay).
//!
//! Each side runs a [`WavePort`] at its servo rate: its device holds one end of a
//! spring-damper whose other end is the link's port (massless). Packets go over the
//! ephemeral channel; [`WavePort::receive`] takes them in any order.
//!
//! Guarantees: [`WavePort::step`] does not allocate; its output is finite for finite inputs.
//! Non-guarantees: positions drift apart slowly under loss (waves carry velocities), which
//! a caller may correct with a weak, passivity-checked position term.

use glam::DVec3;

/// One packet from a side of the link to the other.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WavePacket {
    /// The sender's tick time, seconds (orders packets; stale ones are ignored).
    pub t_secs: f64,
    /// The outgoing wave `u`, sqrt(newtons times world units per second).
    pub wave: DVec3,
    /// The sender's outgoing wave energy so far, joules.
    pub energy_sent_joules: f64,
}

/// Settings of one side's coupling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WaveCoupling {
    /// Wave impedance `b`, newton-seconds per world unit (> 0): high feels stiff and heavy,
    /// low feels soft and light.
    pub impedance: f64,
    /// Stiffness of the spring between the device and the port, newtons per world unit.
    pub stiffness: f64,
    /// Damping of that spring, newton-seconds per world unit (>= 0).
    pub damping: f64,
}

/// One side of the delayed link: its device's spring-damper, the port's position, the last
/// wave received and the energy accounts.
#[derive(Clone, Copy, Debug)]
pub struct WavePort {
    coupling: WaveCoupling,
    /// The port's position (the spring's far end), world.
    port: DVec3,
    /// The newest wave received and its send time.
    wave_in: DVec3,
    wave_in_t_secs: f64,
    /// What the other side says it has sent, joules.
    peer_energy_sent_joules: f64,
    /// What the other side had said it sent before this port began, joules: energy an earlier
    /// port of this side may already have taken in.
    peer_baseline_joules: f64,
    /// What this side's earlier ports sent, joules: added to this port's account on the
    /// wire, so the other side sees one account that only grows.
    sent_before_joules: f64,
    /// Wave energy taken in from the link so far, joules.
    energy_in_joules: f64,
    /// Wave energy sent into the link so far, joules.
    energy_out_joules: f64,
}

impl WavePort {
    /// A side at rest with its port at the device's tip `at`.
    pub fn new(coupling: WaveCoupling, at: DVec3) -> WavePort {
        WavePort::continuing(coupling, at, 0.0, 0.0)
    }

    /// A side at rest at `at` that follows earlier ports of the same side: they sent
    /// `sent_before_joules` in all, and the other side had said it sent
    /// `peer_baseline_joules` when this one began. Packets carry this side's whole account,
    /// and this port takes in only what the other side sends beyond the baseline, so a side
    /// that restarts its port can neither take in twice what was sent once, nor make the
    /// other side's account look smaller.
    pub fn continuing(
        coupling: WaveCoupling,
        at: DVec3,
        sent_before_joules: f64,
        peer_baseline_joules: f64,
    ) -> WavePort {
        let finite_or_zero = |v: f64| if v.is_finite() { v.max(0.0) } else { 0.0 };
        let baseline = finite_or_zero(peer_baseline_joules);
        WavePort {
            coupling,
            port: at,
            wave_in: DVec3::ZERO,
            wave_in_t_secs: f64::NEG_INFINITY,
            peer_energy_sent_joules: baseline,
            peer_baseline_joules: baseline,
            sent_before_joules: finite_or_zero(sent_before_joules),
            energy_in_joules: 0.0,
            energy_out_joules: 0.0,
        }
    }

    /// Takes a packet from the other side, in any order: an older one than the newest seen
    /// is ignored; the energy account only grows. Non-finite packets are ignored.
    pub fn receive(&mut self, packet: &WavePacket) {
        let finite = packet.t_secs.is_finite()
            && packet.wave.is_finite()
            && packet.energy_sent_joules.is_finite();
        if !finite {
            return;
        }
        if packet.t_secs > self.wave_in_t_secs {
            self.wave_in_t_secs = packet.t_secs;
            self.wave_in = packet.wave;
        }
        self.peer_energy_sent_joules = self.peer_energy_sent_joules.max(packet.energy_sent_joules);
    }

    /// One tick of `dt_secs` with the device's tip at `device` moving at `device_velocity`
    /// (world units and seconds): returns the force on the device (newtons) and the packet
    /// to send to the other side.
    pub fn step(
        &mut self,
        device: DVec3,
        device_velocity: DVec3,
        t_secs: f64,
        dt_secs: f64,
    ) -> (DVec3, WavePacket) {
        let WaveCoupling {
            impedance: b,
            stiffness: k,
            damping: c,
        } = self.coupling;
        let root = (2.0 * b).sqrt();
        // The incoming wave, scaled so that the energy taken in never exceeds what the other
        // side has sent (jitter, reordering and loss cannot make energy).
        let mut v = self.wave_in;
        let wanted = 0.5 * v.length_squared() * dt_secs;
        let allowed =
            (self.peer_energy_sent_joules - self.peer_baseline_joules - self.energy_in_joules)
                .max(0.0);
        if wanted > allowed {
            v *= if wanted > 0.0 {
                (allowed / wanted).sqrt()
            } else {
                0.0
            };
        }
        // The massless port: the spring's force equals what the port applies to the link,
        // F = b x' + sqrt(2b) v, with the spring c (x'_d - x') + k (x_d - x) = F.
        let port_velocity = (c * device_velocity + k * (device - self.port) - root * v) / (c + b);
        let force_on_link = b * port_velocity + root * v;
        let u = root * port_velocity + v;
        self.port += port_velocity * dt_secs;
        self.energy_in_joules += 0.5 * v.length_squared() * dt_secs;
        self.energy_out_joules += 0.5 * u.length_squared() * dt_secs;
        let packet = WavePacket {
            t_secs,
            wave: u,
            energy_sent_joules: self.sent_before_joules + self.energy_out_joules,
        };
        (-force_on_link, packet)
    }

    /// The port's position, world (where this side's spring pulls the device).
    pub fn port(&self) -> DVec3 {
        self.port
    }

    /// Puts the port back at the device's tip `at` (after a pause, so the spring does not
    /// snap), keeping the energy accounts: moving the port takes the spring's stored energy
    /// away, never adds any, and what may still be taken in from the link stays what the other
    /// side has sent less what was taken.
    pub fn reanchor(&mut self, at: DVec3) {
        self.port = at;
    }

    /// Wave energy taken in from the link so far, joules.
    pub fn energy_in_joules(&self) -> f64 {
        self.energy_in_joules
    }

    /// Wave energy sent into the link so far, joules.
    pub fn energy_out_joules(&self) -> f64 {
        self.energy_out_joules
    }
}
