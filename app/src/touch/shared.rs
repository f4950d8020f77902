//! The shared tool: two peers hold one touch tool and feel each other (the thesis's shared
//! tool, here peer to peer). This is the app's network side of [`haptic::shared`].
//!
//! A user holds the tool with another peer by naming it ([`Presence::holds_tool_with`]); when
//! each names the other and both touch, [`SharedTool::update`] starts the coupling of this
//! servo's [`SharedToolLink`], and stops it as soon as either lets go, stops touching or
//! leaves. While coupled, the partner's wave packets (on [`SHARED_TOOL_CHANNEL`]; anyone
//! else's are dropped) go into the servo, and a `sculpt-shared-tool` thread sends the servo's
//! own at [`SHARED_TOOL_RATE_HZ`]. The packets are wave variables with an energy account, so
//! network delay, jitter and loss cost stiffness, never stability (the haptic crate's
//! `shared_servo` test holds it passive at 0, 50 and 200 ms one way).
//!
//! Packets come from peers: their format is replication's ([`SharedToolPacket`], beside the
//! other wire messages), whose decoder refuses any length, version or number it does not
//! expect; this module converts them to and from the servo's [`WavePacket`], and the servo
//! bounds what a partner can push ([`haptic::shared`]).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use glam::DVec3;
use haptic::force::wave::WavePacket;
use haptic::shared::{DEFAULT_COUPLING, SharedToolLink};
use replication::PeerId;
use replication::sync::ephemeral::SHARED_TOOL_CHANNEL;
use replication::sync::ephemeral::shared_tool::SharedToolPacket;

use crate::engine::{Engine, EphemeralSender};
use replication::sync::ephemeral::presence::Presence;

/// How many packets a second the shared tool sends while coupled.
pub const SHARED_TOOL_RATE_HZ: u64 = 250;

/// The servo's packet `p` as the wire carries it.
pub fn to_packet(p: &WavePacket) -> SharedToolPacket {
    SharedToolPacket {
        t_secs: p.t_secs,
        wave: p.wave.to_array(),
        energy_sent_joules: p.energy_sent_joules,
    }
}

/// A packet from the wire as the servo takes it.
pub fn from_packet(p: SharedToolPacket) -> WavePacket {
    WavePacket {
        t_secs: p.t_secs,
        wave: DVec3::from_array(p.wave),
        energy_sent_joules: p.energy_sent_joules,
    }
}

/// Who this peer is coupled with: the peer it holds the tool with (`wanted`), when that peer's
/// presence names it back and that peer touches.
pub fn partner(me: PeerId, wanted: Option<PeerId>, theirs: Option<&Presence>) -> Option<PeerId> {
    let wanted = wanted?;
    let theirs = theirs?;
    (wanted != me && theirs.holds_tool_with == Some(me.0) && theirs.tool.is_some())
        .then_some(wanted)
}

/// Where holding the tool together stands, for the Touch section.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SharedState {
    /// This peer holds the tool alone.
    Alone,
    /// This peer holds it with another, which has not (yet) held it back or does not touch.
    Waiting(PeerId),
    /// Coupled: each feels the other.
    Coupled(PeerId),
}

/// What [`SharedTool::stats`] reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SharedStats {
    /// Packets sent.
    pub n_sent: u64,
    /// Partner packets taken in.
    pub n_received: u64,
    /// Packets refused or from a peer this one is not coupled with.
    pub n_dropped: u64,
    /// Wave energy taken in from the link, joules.
    pub energy_in_joules: f64,
    /// Wave energy sent into the link, joules.
    pub energy_out_joules: f64,
    /// The coupling's force on the device, newtons.
    pub force_newtons: DVec3,
}

/// Counters shared between the engine's listener, the sender thread and the face.
#[derive(Default)]
struct Counters {
    n_sent: AtomicU64,
    n_received: AtomicU64,
    n_dropped: AtomicU64,
}

/// One peer's shared tool: the listener on [`SHARED_TOOL_CHANNEL`] and the sender thread.
pub struct SharedTool {
    link: Arc<SharedToolLink>,
    partner: Arc<Mutex<Option<PeerId>>>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    sender: Option<std::thread::JoinHandle<()>>,
}

impl SharedTool {
    /// Listens for partner packets through `engine` and starts the sender for the servo whose
    /// link is `link` (coupled only once [`SharedTool::update`] finds a partner).
    pub fn start(engine: &Engine, link: Arc<SharedToolLink>) -> std::io::Result<SharedTool> {
        let partner = Arc::new(Mutex::new(None::<PeerId>));
        let counters = Arc::new(Counters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let sender = {
            let (link, partner, counters, stop) = (
                Arc::clone(&link),
                Arc::clone(&partner),
                Arc::clone(&counters),
                Arc::clone(&stop),
            );
            let out = engine.ephemeral_sender();
            std::thread::Builder::new()
                .name("sculpt-shared-tool".into())
                .spawn(move || send_loop(&link, &partner, &counters, &stop, &out))?
        };
        let listener = {
            let (link, partner, counters) = (
                Arc::clone(&link),
                Arc::clone(&partner),
                Arc::clone(&counters),
            );
            move |peer: PeerId, bytes: &[u8]| {
                let from_partner = *lock(&partner) == Some(peer);
                match SharedToolPacket::decode(bytes).map(from_packet) {
                    Ok(packet) if from_partner => {
                        link.deliver(&packet);
                        counters.n_received.fetch_add(1, Ordering::Relaxed);
                    }
                    _ => {
                        counters.n_dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
        };
        engine.listen_ephemeral(SHARED_TOOL_CHANNEL, Some(Box::new(listener)));
        Ok(SharedTool {
            link,
            partner,
            counters,
            stop,
            sender: Some(sender),
        })
    }

    /// Couples or uncouples from what this peer wants (`wanted`, the peer it holds the tool
    /// with) and that peer's presence; call whenever either may have changed (every frame).
    pub fn update(
        &self,
        me: PeerId,
        wanted: Option<PeerId>,
        theirs: Option<&Presence>,
    ) -> SharedState {
        let now = partner(me, wanted, theirs);
        let mut current = lock(&self.partner);
        if *current != now {
            match now {
                Some(_) => self.link.start(DEFAULT_COUPLING),
                None => self.link.stop(),
            }
            *current = now;
        }
        match (now, wanted) {
            (Some(p), _) => SharedState::Coupled(p),
            (None, Some(w)) if w != me => SharedState::Waiting(w),
            _ => SharedState::Alone,
        }
    }

    /// Packets, energy and force so far.
    pub fn stats(&self) -> SharedStats {
        SharedStats {
            n_sent: self.counters.n_sent.load(Ordering::Relaxed),
            n_received: self.counters.n_received.load(Ordering::Relaxed),
            n_dropped: self.counters.n_dropped.load(Ordering::Relaxed),
            energy_in_joules: self.link.energy_in_joules(),
            energy_out_joules: self.link.energy_out_joules(),
            force_newtons: self.link.force_newtons(),
        }
    }

    /// Uncouples, stops listening and stops the sender.
    pub fn stop(mut self, engine: &Engine) {
        self.shut(Some(engine));
    }

    fn shut(&mut self, engine: Option<&Engine>) {
        self.link.stop();
        *lock(&self.partner) = None;
        if let Some(engine) = engine {
            engine.listen_ephemeral(SHARED_TOOL_CHANNEL, None);
        }
        self.stop.store(true, Ordering::Relaxed);
        if let Some(sender) = self.sender.take()
            && sender.join().is_err()
        {
            log::error!("the shared-tool sender panicked");
        }
    }
}

impl Drop for SharedTool {
    fn drop(&mut self) {
        self.shut(None);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Sends the servo's newest packet at [`SHARED_TOOL_RATE_HZ`] while coupled.
fn send_loop(
    link: &SharedToolLink,
    partner: &Mutex<Option<PeerId>>,
    counters: &Counters,
    stop: &AtomicBool,
    out: &EphemeralSender,
) {
    let period = Duration::from_micros(1_000_000 / SHARED_TOOL_RATE_HZ);
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(period);
        if lock(partner).is_none() {
            continue;
        }
        let Some(packet) = link.take_outgoing() else {
            continue;
        };
        match out.send(SHARED_TOOL_CHANNEL, to_packet(&packet).encode()) {
            Ok(()) => {
                counters.n_sent.fetch_add(1, Ordering::Relaxed);
            }
            // A newer packet follows; its energy account covers this one.
            Err(crate::engine::RequestError::Busy) => {}
            Err(crate::engine::RequestError::Stopped) => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::{EngineConfig, Network, lock as lock_view};
    use crate::touch::DeviceModel;
    use crate::touch::live::LiveTouch;

    /// Waits (at most 20 s) until `done` holds.
    fn wait(what: &str, mut done: impl FnMut() -> bool) {
        let deadline = crate::clock::now().instant + Duration::from_secs(20);
        while !done() {
            assert!(crate::clock::now().instant < deadline, "timed out: {what}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Sets this engine's presence: touching, holding the tool with `with`.
    fn hold_with(engine: &Engine, with: Option<PeerId>) {
        let mut p = engine.presence();
        p.tool = Some([0.0; 3]);
        p.holds_tool_with = with.map(|p| p.0);
        engine.set_presence(p).unwrap();
    }

    fn update(tool: &SharedTool, engine: &Engine, wanted: Option<PeerId>) -> SharedState {
        let me = engine.peer_id();
        let view = lock_view(engine.view());
        let theirs = wanted.and_then(|w| view.presence().get(&w));
        tool.update(me, wanted, theirs)
    }

    #[test]
    fn two_peers_holding_the_tool_together_feel_each_other_over_quic() {
        let dir = std::env::temp_dir().join(format!("sculpt-shared-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let start = |name: &str, dial: Option<(&Engine, std::net::SocketAddr)>| {
            let store = dir.join(name);
            let base = EngineConfig::on_loopback(&store);
            let config = match dial {
                None => EngineConfig {
                    demo: crate::demos::find("watermelon").ok(),
                    ..base
                },
                Some((first, addr)) => EngineConfig {
                    invite: Some(first.invite().clone()),
                    network: Network {
                        dial: vec![addr],
                        ..base.network.clone()
                    },
                    ..base
                },
            };
            Engine::start(config, crate::clock::now().wall).unwrap()
        };
        let a = start("a", None);
        wait("a's demo", || !lock_view(a.view()).scene().is_empty());
        let addr = lock_view(a.view()).listen_addr().unwrap();
        let b = start("b", Some((&a, addr)));
        wait("b joins", || !lock_view(b.view()).scene().is_empty());
        let touch = |e: &Engine| LiveTouch::start(Arc::clone(e.view()), DeviceModel::Falcon);
        let (live_a, live_b) = (touch(&a).unwrap(), touch(&b).unwrap());
        let tool_a = SharedTool::start(&a, live_a.shared_link()).unwrap();
        let tool_b = SharedTool::start(&b, live_b.shared_link()).unwrap();
        let (ida, idb) = (a.peer_id(), b.peer_id());

        // A holds the tool with B; B does not yet: A waits, nothing couples.
        hold_with(&a, Some(idb));
        hold_with(&b, None);
        wait("b sees a holding", || {
            lock_view(b.view())
                .presence()
                .get(&ida)
                .is_some_and(|p| p.holds_tool_with == Some(idb.0))
        });
        assert_eq!(update(&tool_a, &a, Some(idb)), SharedState::Waiting(idb));
        assert_eq!(update(&tool_b, &b, None), SharedState::Alone);
        assert!(!live_a.shared_link().is_coupled());

        // B holds it back: both couple.
        hold_with(&b, Some(ida));
        wait("both coupled", || {
            update(&tool_a, &a, Some(idb)) == SharedState::Coupled(idb)
                && update(&tool_b, &b, Some(ida)) == SharedState::Coupled(ida)
        });

        // A moves her tool back and forth along x above the melon; B holds still and is
        // pulled along x.
        let mut max_b_x = 0.0f64;
        let t0 = crate::clock::now().instant;
        while t0.elapsed() < Duration::from_millis(1500) {
            let t = t0.elapsed().as_secs_f64();
            live_a.move_to_world(glam::DVec3::new(
                0.3 * (std::f64::consts::TAU * t).sin(),
                1.4,
                0.0,
            ));
            update(&tool_a, &a, Some(idb));
            update(&tool_b, &b, Some(ida));
            max_b_x = max_b_x.max(tool_b.stats().force_newtons.x.abs());
            std::thread::sleep(Duration::from_millis(2));
        }
        let (sa, sb) = (tool_a.stats(), tool_b.stats());
        assert!(sa.n_sent > 50 && sb.n_received > 50, "{sa:?} {sb:?}");
        assert!(max_b_x > 0.2, "b feels a along x: {max_b_x} N, {sb:?}");
        // The link makes no energy: B takes in at most what A sent.
        assert!(
            sb.energy_in_joules <= sa.energy_out_joules + 1e-9,
            "{sa:?} {sb:?}"
        );

        // A lets go: B is left waiting and feels nothing more.
        hold_with(&a, None);
        wait("b uncoupled", || {
            update(&tool_b, &b, Some(ida)) == SharedState::Waiting(ida)
        });
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(tool_b.stats().force_newtons, glam::DVec3::ZERO);

        tool_a.stop(&a);
        tool_b.stop(&b);
        live_a.stop();
        live_b.stop();
        b.shutdown();
        a.shutdown();
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn presence(tool: bool, holds: Option<PeerId>) -> Presence {
        Presence {
            name: "p".into(),
            colour: [0; 3],
            pointer: None,
            tool: tool.then_some([0.0; 3]),
            selected: None,
            camera: None,
            holds_tool_with: holds.map(|p| p.0),
            tool_body: None,
        }
    }

    #[test]
    fn wave_packets_travel_as_shared_tool_packets() {
        let p = WavePacket {
            t_secs: 12.5,
            wave: DVec3::new(0.5, -1.0, 2.0),
            energy_sent_joules: 0.75,
        };
        let bytes = to_packet(&p).encode();
        assert_eq!(SharedToolPacket::decode(&bytes).map(from_packet), Ok(p));
        assert_eq!(to_packet(&p).wave, [0.5, -1.0, 2.0]);
    }

    #[test]
    fn two_peers_are_partners_only_when_each_holds_the_tool_with_the_other_and_touches() {
        let (a, b, c) = (PeerId([1; 32]), PeerId([2; 32]), PeerId([3; 32]));
        assert_eq!(partner(a, Some(b), Some(&presence(true, Some(a)))), Some(b));
        assert_eq!(partner(a, None, Some(&presence(true, Some(a)))), None);
        assert_eq!(partner(a, Some(b), Some(&presence(true, Some(c)))), None);
        assert_eq!(partner(a, Some(b), Some(&presence(false, Some(a)))), None);
        assert_eq!(partner(a, Some(b), None), None, "b left");
        assert_eq!(partner(a, Some(a), Some(&presence(true, Some(a)))), None);
    }
}
