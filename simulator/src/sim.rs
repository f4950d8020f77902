//! The simulation proper: honest peers running the real [`Peer`] core, one hostile peer, a
//! modelled network and disk, and a virtual clock. Events sit in one queue ordered by
//! (virtual time, sequence number); every random choice comes from one of the seed's streams
//! ([`SimRng::stream`]): keys, the workload ([`workload::actions`]), the fault schedule
//! (drawn up front, with the same number of draws whatever is switched off, so a shrunk run
//! keeps its faults' times) and the network (loss, jitter, fsync delays, crash images,
//! hostile messages).

use std::collections::{BTreeMap, BTreeSet};
use std::panic::{self, AssertUnwindSafe};

use replication::log::{Insertion, RefoldBudget};
use replication::membership::{Admission, FounderCommitment, Membership};
use replication::shape::ShapePayload;
use replication::sync::state::CloseReason;
use replication::{ConnId, Event, Keypair, Log, OpId, Peer, Timestamp};

use crate::byzantine::{Aim, Attack, Byzantine, REDIAL_MICROS, SMALL_OP_BYTE_QUOTA, Sends};
use crate::check::{self, Ended, QUIESCENCE_LIMIT_MICROS};
use crate::config::{Config, ConfigError, Faults};
use crate::honest::{Honest, MAX_DRAIN, Scene, guarded, new_honest, note_delivered, panic_text};
use crate::hostile::{self, FLOOD_MESSAGES, Hostile};
use crate::join::Failed;
use crate::memory;
use crate::report::{CatchUp, PeerSample, Report, Sample, Stats};
use crate::rng::SimRng;
use crate::session::{FOUNDER_NONCE, SESSION_CAP_BYTES, SESSION_ID};
use crate::trace::TraceHash;
use crate::workload::{self, Action, HOT_OBJECT};

mod stream;

/// The virtual clock's start (µs); op timestamps are virtual times.
pub const START_MICROS: u64 = 1_000_000_000;
/// Mean virtual time between two user ops (over all peers).
pub const MEAN_OP_GAP_MICROS: u64 = workload::MEAN_ACTION_GAP_MICROS;
/// Most events one run handles (a live-lock guard).
pub const MAX_EVENTS: u64 = 200_000_000;
/// How often, after healing, the harness looks for quiescence.
pub const PROBE_INTERVAL_MICROS: u64 = 50_000;
/// A bandwidth-limited link drops a message that would wait longer than this to be sent.
pub const MAX_LINK_QUEUE_MICROS: u64 = 2_000_000;
/// Shortest simulated fsync.
pub const MIN_FSYNC_MICROS: u64 = 200;
/// Longest simulated fsync.
pub const MAX_FSYNC_MICROS: u64 = 3_000;
/// Most samples a run keeps for its plots (past it, every other one is dropped and the
/// interval doubles).
pub const MAX_SAMPLES: usize = 1024;

const KEYS_STREAM: u64 = 1;
const SCHEDULE_STREAM: u64 = 3;
const NET_STREAM: u64 = 4;
const HOT_STREAM: u64 = 5;
const BYZANTINE_STREAM: u64 = 6;
const DIAL_STREAM: u64 = 7;

/// What can happen at a virtual instant.
#[derive(Debug)]
enum Ev {
    Deliver {
        from: usize,
        to: usize,
        epoch: u64,
        bytes: Vec<u8>,
        /// The flood it belongs to, if any.
        flood: Option<usize>,
    },
    Wake {
        peer: usize,
    },
    User {
        action_idx: usize,
    },
    Hostile,
    /// The byzantine member's core times out.
    HostileWake,
    Flood,
    PartitionStart {
        cut: Vec<(usize, usize)>,
    },
    PartitionEnd {
        cut: Vec<(usize, usize)>,
    },
    Offline {
        peer: usize,
    },
    Online {
        peer: usize,
    },
    /// The peer crashes (now, or at its next write if it has nothing unsynced) and restarts
    /// from its store; it comes back online `restart_micros` after the crash.
    Crash {
        peer: usize,
        restart_micros: u64,
    },
    /// A late peer starts, with an empty log or from a snapshot.
    Join {
        peer: usize,
        snapshot: bool,
    },
    /// A stream connection stalled by a partition reaches its idle timeout.
    IdleTimeout {
        from: usize,
        to: usize,
        epoch: u64,
    },
    /// The remote end of a connection to a crashed peer notices the crash and closes.
    Unlinger {
        to: usize,
        from: usize,
        epoch: u64,
    },
    /// An fsync of the peer's store completes.
    FsyncDone {
        peer: usize,
        generation: u64,
    },
    Heal,
    /// The founder (peer 0) expels one of the hostile member's keys: the one it connects
    /// with (`connection`), or its lease hoarder's.
    Expel {
        connection: bool,
    },
    /// The hostile member dials honest peer `peer` again after it closed their connection.
    Redial {
        peer: usize,
    },
    /// The sender on a stream link that a partition stalled probes: what still waits to
    /// resume goes out.
    StreamProbe {
        from: usize,
        to: usize,
    },
    /// A round of dials by the LAN finder of `a` or `b` comes while their stream connection
    /// is down.
    Dial {
        a: usize,
        b: usize,
    },
    /// A dial between `a` and `b` that found both links open is admitted.
    Dialed {
        a: usize,
        b: usize,
    },
    /// A dial to replace the stalled stream connection of epoch `epoch` between `a` and `b`
    /// is admitted.
    Replace {
        a: usize,
        b: usize,
        epoch: u64,
    },
    /// After healing: stop once honest peers agree and nothing is in flight between them.
    Probe,
    /// Records a sample for the plots (not part of the trace).
    Sample,
}

/// Connection state of an unordered pair of nodes.
#[derive(Debug, Clone, Copy, Default)]
struct Pair {
    connected: bool,
    /// Bumped on every connect and disconnect: messages of an older epoch are dropped.
    epoch: u64,
    /// Until when a dial to replace the pair's stalled connection is under way (streams).
    redial_until: u64,
    /// A dial of the pair's closed stream connection waits for a round or a handshake.
    dialing: bool,
    /// When the round that dials the pair next comes ([`Ev::Dial`]; none while a handshake
    /// is under way): a round at any other time is one a sign of the network's return
    /// brought forward, and does nothing.
    round_at: Option<u64>,
    /// Who dials in that round (or the dial under way).
    dialer: usize,
    /// The dialer of the pair's stream connection, and when its own admission lets its
    /// messages out (the acceptor's went out at once).
    dialer_sends_from: Option<(usize, u64)>,
    /// When the idle timeout closed the pair's stream connection, and until when the end
    /// with the smaller id dials the other again for it.
    lost_at: u64,
    lost_until: u64,
}

/// A run in progress.
pub struct Simulation {
    config: Config,
    faults: Faults,
    net: SimRng,
    now: u64,
    seq: u64,
    queue: BTreeMap<(u64, u64), Ev>,
    honest: Vec<Honest>,
    hostile: Option<Hostile>,
    actions: Vec<Action>,
    /// One-way base latency per directed link, `[from][to]`.
    latency_micros: Vec<Vec<u64>>,
    /// When each directed link is free to send again (bandwidth).
    link_free_at: Vec<Vec<u64>>,
    /// Per directed link, its connection's deliveries as a stream ([`Faults::streams`]).
    stream_links: Vec<Vec<stream::StreamLink>>,
    /// Per node, when in each second its LAN finder's rounds of dials come (streams).
    dial_phase_micros: Vec<u64>,
    /// Per node, when a sign of the network's return last brought its dials forward
    /// ([`stream::RESUMED_DIALS_EVERY_MICROS`]).
    resumed_dials_at: Vec<Option<u64>>,
    /// Per directed link, when the first message stalled on it while a partition cuts it,
    /// and the messages, with their connection epochs.
    stalled: BTreeMap<(usize, usize), stream::Stalled>,
    /// Per directed link no longer cut, what stalled on it while it was, if it fits QUIC's
    /// congestion window, with when the sender probes: it goes again once the link's next
    /// message is acknowledged, or at the probe ([`Ev::StreamProbe`]) if sooner.
    resuming: BTreeMap<(usize, usize), (u64, stream::Stalled)>,
    /// Per directed link, messages of a stream connection that came before its hello, with
    /// their epochs: read once the hello is (the node reads a connection's hello first).
    behind_hello: BTreeMap<(usize, usize), stream::EpochMessages>,
    /// Pair state, `[min][max]`.
    pairs: Vec<Vec<Pair>>,
    /// Connections whose other end crashed, still open at `to` (keyed `(to, from)`): messages
    /// the crashed peer sent before the crash, of epoch `.0`, are still delivered until `.1`.
    lingering: BTreeMap<(usize, usize), (u64, u64)>,
    blocked: BTreeMap<(usize, usize), u32>,
    /// When a packet last came over each directed link between honest peers, as far as a
    /// stream connection's idle timer knows (a message, or a keep-alive), and since when each
    /// link that is not cut has been open (streams only).
    last_heard: BTreeMap<(usize, usize), u64>,
    opened_at: BTreeMap<(usize, usize), u64>,
    objects: Vec<u64>,
    stats: Stats,
    trace: TraceHash,
    heal_at: u64,
    last_delivery_at: u64,
    timed_out: bool,
    /// Messages between honest peers on the network now.
    n_in_flight: u64,
    quiet: bool,
    /// What went wrong at restarts and joins (checked at the end).
    restart_failures: Vec<String>,
    /// Ops some peer synced to disk (acknowledged as durable).
    durable: BTreeSet<OpId>,
    /// Own ops a crash lost before they were synced (so before they were ever sent).
    lost_own: BTreeSet<OpId>,
    /// Per flood: (messages delivered, messages accepted).
    floods: Vec<(u64, u64)>,
    samples: Vec<Sample>,
    sample_interval_micros: u64,
}

impl Simulation {
    /// Sets up a run: keys, peers, the full mesh of connections and every scheduled event.
    pub fn new(config: Config) -> Result<Simulation, ConfigError> {
        config.validate()?;
        let faults = config.effective_faults();
        let n = config.n_peers;
        let n_nodes = n + usize::from(config.hostile);
        let mut keys = SimRng::stream(config.seed, KEYS_STREAM);
        let (honest, founder) = new_peers(&config, &faults, &mut keys)?;
        let hostile = (config.hostile).then(|| new_hostile(&config, &faults, &mut keys, founder));
        let mut net = SimRng::stream(config.seed, NET_STREAM);
        let lat = faults.latency_micros;
        let latency_micros = (0..n_nodes)
            .map(|_| (0..n_nodes).map(|_| lat / 2 + net.below(lat + 1)).collect())
            .collect();
        let actions = workload::actions(config.seed, config.n_ops, START_MICROS);
        let mut sim = Simulation {
            faults,
            net,
            now: START_MICROS,
            seq: 0,
            queue: BTreeMap::new(),
            honest,
            hostile,
            actions,
            latency_micros,
            link_free_at: vec![vec![0; n_nodes]; n_nodes],
            stream_links: vec![vec![stream::StreamLink::default(); n_nodes]; n_nodes],
            dial_phase_micros: stream::dial_phases(config.seed, DIAL_STREAM, n_nodes),
            resumed_dials_at: vec![None; n_nodes],
            stalled: BTreeMap::new(),
            resuming: BTreeMap::new(),
            behind_hello: BTreeMap::new(),
            pairs: vec![vec![Pair::default(); n_nodes]; n_nodes],
            lingering: BTreeMap::new(),
            blocked: BTreeMap::new(),
            last_heard: BTreeMap::new(),
            opened_at: BTreeMap::new(),
            objects: vec![HOT_OBJECT],
            stats: Stats::default(),
            trace: TraceHash::default(),
            heal_at: START_MICROS,
            last_delivery_at: START_MICROS,
            timed_out: false,
            n_in_flight: 0,
            quiet: false,
            restart_failures: Vec::new(),
            durable: BTreeSet::new(),
            lost_own: BTreeSet::new(),
            floods: Vec::new(),
            samples: Vec::new(),
            sample_interval_micros: 0,
            config,
        };
        sim.schedule_all();
        Ok(sim)
    }

    fn n_nodes(&self) -> usize {
        self.pairs.len()
    }

    fn hostile_idx(&self) -> Option<usize> {
        self.config.hostile.then_some(self.config.n_peers)
    }

    fn push(&mut self, at: u64, ev: Ev) {
        self.seq += 1;
        self.queue.insert((at, self.seq), ev);
    }

    fn schedule_all(&mut self) {
        let work_end = self.actions.last().map_or(START_MICROS, |a| a.at_micros);
        let span = (work_end - START_MICROS).max(1);
        let mut sched = SimRng::stream(self.config.seed, SCHEDULE_STREAM);
        self.schedule_joins(&mut sched, span);
        self.found_and_admit();
        // Peer 0 creates the object everyone fights over, before anyone connects.
        if let Some(create) =
            workload::hot_object(&mut SimRng::stream(self.config.seed, HOT_STREAM))
        {
            self.author(0, create);
        }
        for a in 0..self.n_nodes() {
            for b in a + 1..self.n_nodes() {
                if self.online(a) && self.online(b) {
                    self.connect_pair(a, b);
                }
            }
        }
        let selected: Vec<usize> = match &self.config.actions {
            Some(keep) => keep.iter().map(|&i| i as usize).collect(),
            None => (0..self.actions.len()).collect(),
        };
        for action_idx in selected {
            let at = self.actions[action_idx].at_micros;
            self.push(at, Ev::User { action_idx });
        }
        self.schedule_faults(&mut sched, span);
        self.schedule_expel(&mut sched, span);
        if self.faults.backlog {
            // The honest peers in two halves from two thirds of the work until healing.
            let n = self.config.n_peers;
            let halves = (0..n / 2).flat_map(|a| (n / 2..n).flat_map(move |b| [(a, b), (b, a)]));
            let cut = halves.collect();
            self.push(START_MICROS + span * 2 / 3, Ev::PartitionStart { cut });
        }
        self.push(work_end + 1, Ev::Heal);
        self.sample_interval_micros = (span / 256).max(10_000);
        self.push(START_MICROS + self.sample_interval_micros, Ev::Sample);
    }

    /// Late joiners (decided before anyone connects). Draws the same whatever is switched off.
    fn schedule_joins(&mut self, sched: &mut SimRng, span: u64) {
        let n = self.config.n_peers;
        for _ in 0..1 + self.config.n_ops / 400 {
            let (draw, at, snapshot) = (
                sched.next_u64(),
                sched.below(span * 6 / 10),
                sched.chance(500),
            );
            if !self.faults.late_joins {
                continue;
            }
            // Peer 0 always starts: it authors the hot object and is the checkers' reference.
            let peer = 1 + (draw % (n as u64 - 1)) as usize;
            if self.honest[peer].started {
                self.honest[peer].started = false;
                self.push(START_MICROS + at, Ev::Join { peer, snapshot });
            }
        }
    }

    /// Hostile traffic, partitions, peers offline and crashes. Every draw happens whatever is
    /// switched off, so switching one kind off keeps the others' times.
    fn schedule_faults(&mut self, sched: &mut SimRng, span: u64) {
        let n = self.config.n_peers;
        let n_ops = self.config.n_ops;
        let faults = self.faults;
        let hostile = self.config.hostile;
        for _ in 0..n_ops / 5 + 1 {
            let at = START_MICROS + sched.below(span);
            if hostile {
                self.push(at, Ev::Hostile);
            }
        }
        for _ in 0..1 + n_ops / 500 {
            let at = START_MICROS + sched.below(span);
            if hostile && faults.flood {
                self.push(at, Ev::Flood);
            }
        }
        for _ in 0..1 + n_ops / 150 {
            let start = START_MICROS + sched.below(span);
            let duration = 300_000 + sched.below(3_000_000);
            let (sides, asymmetric) = (sched.next_u64(), sched.chance(300));
            let side = |p: usize| sides >> p & 1 == 1;
            let mut cut = Vec::new();
            for a in 0..n {
                for b in 0..n {
                    if side(a) && !side(b) {
                        cut.push((a, b));
                        if !asymmetric {
                            cut.push((b, a));
                        }
                    }
                }
            }
            if faults.partitions && !cut.is_empty() {
                self.push(start, Ev::PartitionStart { cut: cut.clone() });
                self.push(start + duration, Ev::PartitionEnd { cut });
            }
        }
        for _ in 0..1 + n_ops / 200 {
            let (draw, start) = (sched.next_u64(), START_MICROS + sched.below(span));
            let duration = 500_000 + sched.below(5_000_000);
            let peer = (draw % n as u64) as usize;
            if faults.offline {
                self.push(start, Ev::Offline { peer });
                self.push(start + duration, Ev::Online { peer });
            }
        }
        for _ in 0..1 + n_ops / 300 {
            let (draw, start) = (sched.next_u64(), START_MICROS + sched.below(span));
            let restart = 200_000 + sched.below(2_000_000);
            let peer = (draw % n as u64) as usize;
            if faults.crashes {
                let restart_micros = restart;
                self.push(
                    start,
                    Ev::Crash {
                        peer,
                        restart_micros,
                    },
                );
            }
        }
    }

    /// In a session that binds its authors, peer 0 founds it (its admission of itself) and
    /// admits every other peer's key and the hostile member's, each with an equal share of
    /// half the session's cap (a founder who knows its members; the node's default grant
    /// shrinks with every key admitted).
    fn found_and_admit(&mut self) {
        let founder = self.honest[0].peer.peer_id();
        let Some(cap) = self.honest[0].peer.log().founder_budget() else {
            return;
        };
        let founding = Admission {
            key: founder,
            grant_bytes: 0,
            nonce: Some(FOUNDER_NONCE),
        };
        self.author(0, ShapePayload::Admit(Box::new(founding)));
        let grant_bytes = cap / (2 * self.n_nodes() as u64);
        let members = (self.honest[1..].iter().map(|h| h.peer.peer_id()))
            .chain(self.hostile.as_ref().map(Hostile::peer_id))
            .collect::<Vec<_>>();
        for key in members {
            let admission = Admission {
                key,
                grant_bytes,
                nonce: None,
            };
            self.author(0, ShapePayload::Admit(Box::new(admission)));
        }
    }

    /// The founder's expels of the hostile member: its lease hoarder's key in the third
    /// quarter of the work, the key it connects with in the last (drawn last, so the draws
    /// above keep their times).
    fn schedule_expel(&mut self, sched: &mut SimRng, span: u64) {
        let hoarder_at = START_MICROS + span / 2 + sched.below(span / 4);
        let connection_at = START_MICROS + span * 3 / 4 + sched.below(span / 4);
        if self.config.hostile && self.faults.expel {
            self.push(hoarder_at, Ev::Expel { connection: false });
            self.push(connection_at, Ev::Expel { connection: true });
        }
    }

    /// The founder (peer 0, when it runs) expels one of the hostile member's keys: every
    /// honest peer must then void what that key signs without having seen the expel, and
    /// close its connections to the key it connects with.
    fn expel_hostile(&mut self, connection: bool) {
        let Some(hostile) = self.hostile.as_ref() else {
            return;
        };
        let member = match (&hostile.byzantine, connection) {
            (Some(byz), false) => byz.hoarder_id(),
            _ => hostile.peer_id(),
        };
        let founder = &self.honest[0];
        if !founder.started || founder.panicked.is_some() {
            return;
        }
        self.stats.n_expels += 1;
        let expel = Membership {
            member,
            expel: true,
            nonce: FOUNDER_NONCE,
        };
        self.author(0, ShapePayload::Member(Box::new(expel)));
    }

    /// Runs to quiescence (or the limit) and checks the outcome.
    pub fn run(mut self) -> Report {
        while let Some(((at, _), ev)) = self.queue.pop_first() {
            if at > self.heal_at.max(START_MICROS) + QUIESCENCE_LIMIT_MICROS
                && self.heal_at > START_MICROS
            {
                self.timed_out = true;
                break;
            }
            self.stats.n_events += 1;
            if self.stats.n_events > MAX_EVENTS {
                self.timed_out = true;
                break;
            }
            self.now = at;
            if !matches!(ev, Ev::Sample) {
                self.trace.u64(at);
            }
            self.handle(ev);
            if self.quiet {
                break;
            }
        }
        self.sample();
        check::finish(self.ended())
    }

    /// What the run ended with, for the checkers.
    fn ended(self) -> Ended {
        Ended {
            heal_micros: self.heal_at - START_MICROS,
            last_delivery_micros: self.last_delivery_at - START_MICROS,
            end_micros: self.now - START_MICROS,
            trace_hash: self.trace.value(),
            timed_out: self.timed_out,
            config: self.config,
            faults: self.faults,
            honest: self.honest,
            hostile: self.hostile,
            stats: self.stats,
            latency_micros: self.latency_micros,
            restart_failures: self.restart_failures,
            durable: self.durable,
            lost_own: self.lost_own,
            floods: self.floods,
            samples: self.samples,
        }
    }

    /// Handles one event; all but deliveries, redials, probes and samples go into the trace
    /// under a code of their own.
    // tidy:table: one arm per event kind, each its trace code and a call.
    fn handle(&mut self, ev: Ev) {
        match ev {
            Ev::Deliver {
                from,
                to,
                epoch,
                bytes,
                flood,
            } => self.deliver(from, to, epoch, &bytes, flood),
            Ev::Wake { peer } => {
                self.trace.u64(1);
                self.wake(peer);
            }
            Ev::User { action_idx } => {
                self.trace.u64(2);
                self.user_action(action_idx);
            }
            Ev::Hostile => {
                self.trace.u64(3);
                self.hostile_send();
            }
            Ev::HostileWake => {
                self.trace.u64(18);
                self.byzantine_wake();
            }
            Ev::Flood => {
                self.trace.u64(14);
                self.hostile_flood();
            }
            Ev::PartitionStart { cut } => {
                self.trace.u64(4);
                if self.faults.streams {
                    self.stream_partition_start(&cut);
                }
                self.partition(cut, true);
            }
            Ev::PartitionEnd { cut } => {
                self.trace.u64(5);
                let unblocked = self.faults.streams.then(|| cut.clone());
                self.partition(cut, false);
                if let Some(links) = unblocked {
                    self.stream_unblocked(&links);
                }
            }
            ev @ (Ev::IdleTimeout { .. }
            | Ev::StreamProbe { .. }
            | Ev::Replace { .. }
            | Ev::Dial { .. }
            | Ev::Dialed { .. }) => {
                self.handle_stream(ev);
            }
            Ev::Offline { peer } => {
                self.trace.u64(6);
                self.go_offline(peer);
            }
            Ev::Crash {
                peer,
                restart_micros,
            } => {
                self.trace.u64(9);
                self.crash_or_arm(peer, restart_micros);
            }
            Ev::Online { peer } => {
                self.trace.u64(7);
                self.come_online(peer);
            }
            Ev::Join { peer, snapshot } => {
                self.trace.u64(15);
                self.join(peer, snapshot);
            }
            Ev::Unlinger { to, from, epoch } => {
                self.trace.u64(17);
                self.unlinger(to, from, epoch);
            }
            Ev::FsyncDone { peer, generation } => {
                self.trace.u64(16);
                self.fsync_done(peer, generation);
            }
            Ev::Heal => {
                self.trace.u64(8);
                self.heal();
            }
            Ev::Expel { connection } => {
                self.trace.u64(19);
                self.expel_hostile(connection);
            }
            Ev::Redial { peer } => self.redial(peer),
            Ev::Probe => self.probe(),
            Ev::Sample => {
                self.sample();
                self.push(self.now + self.sample_interval_micros, Ev::Sample);
            }
        }
    }

    /// The events of stream connections ([`Faults::streams`]).
    fn handle_stream(&mut self, ev: Ev) {
        match ev {
            Ev::IdleTimeout { from, to, epoch } => {
                self.trace.u64(20);
                self.stream_idle_timeout(from, to, epoch);
            }
            Ev::StreamProbe { from, to } => {
                self.trace.u64(23);
                // A probe of what waits now, not of what an earlier partition left.
                if self
                    .resuming
                    .get(&(from, to))
                    .is_some_and(|r| r.0 == self.now)
                {
                    self.stream_resume(from, to, 0);
                }
            }
            Ev::Replace { a, b, epoch } => {
                self.trace.u64(21);
                self.stream_replace(a, b, epoch);
            }
            Ev::Dial { a, b } => {
                let now = self.now;
                if self.pair(a, b).round_at == Some(now) {
                    self.trace.u64(24);
                    self.stream_dial_round(a, b);
                }
            }
            Ev::Dialed { a, b } => {
                self.trace.u64(25);
                self.stream_dialed(a, b);
            }
            _ => unreachable!("not a stream event: {ev:?}"),
        }
    }

    /// The peer's timer.
    fn wake(&mut self, peer: usize) {
        let now = self.now;
        let h = &mut self.honest[peer];
        if h.wake_at == Some(now) {
            h.wake_at = None;
        }
        guarded(h, |p| p.handle_timeout(Timestamp(now)));
        self.flush(peer);
    }

    /// A partition of the directed links `cut` starts (`true`) or ends; partitions overlap.
    fn partition(&mut self, cut: Vec<(usize, usize)>, start: bool) {
        for link in cut {
            if start {
                let count = self.blocked.entry(link).or_default();
                *count += 1;
                if *count == 1 && self.faults.streams {
                    self.stream_keep_alives(link);
                }
            } else if let Some(c) = self.blocked.get_mut(&link) {
                *c -= 1;
                if *c == 0 {
                    self.blocked.remove(&link);
                    if self.faults.streams {
                        self.opened_at.insert(link, self.now);
                    }
                }
            }
        }
    }

    /// A crash is due: most wait for the peer's next write (half of them for an op of its
    /// own: a crash while saving an edit), so they lose unsynced ops and tear records; the
    /// others strike whenever they come.
    fn crash_or_arm(&mut self, peer: usize, restart_micros: u64) {
        let h = &mut self.honest[peer];
        if !h.started || h.panicked.is_some() {
            return;
        }
        if h.disk.n_unsynced() == 0 && self.net.chance(700) {
            h.crash_armed = Some((restart_micros, self.net.chance(500)));
        } else {
            self.crash(peer, restart_micros);
        }
    }

    /// The remote end of a connection to a crashed peer notices the crash, unless the
    /// connection was replaced since.
    fn unlinger(&mut self, to: usize, from: usize, epoch: u64) {
        if self
            .lingering
            .get(&(to, from))
            .is_some_and(|l| l.0 == epoch)
        {
            self.lingering.remove(&(to, from));
            guarded(&mut self.honest[to], |p| p.disconnect(ConnId(from as u64)));
        }
    }

    /// After healing: stops once honest peers agree and nothing is in flight between them.
    fn probe(&mut self) {
        if self.n_in_flight == 0 && self.agreed() {
            self.quiet = true;
        } else {
            self.push(self.now + PROBE_INTERVAL_MICROS, Ev::Probe);
        }
    }

    fn user_action(&mut self, action_idx: usize) {
        let action = self.actions[action_idx];
        let peer = action.peer(self.config.n_peers);
        let me = self.honest[peer].peer.peer_id();
        // A peer whose admission has not reached it yet waits, as the app's user does.
        if !self.honest[peer].started || !self.honest[peer].peer.log().is_admitted(&me) {
            self.stats.n_actions_skipped += 1;
            return;
        }
        let mut rng = SimRng::new(action.seed);
        let payload = self.honest[peer].user.next(&mut rng, peer, &self.objects);
        match payload {
            Some(payload) => self.author(peer, payload),
            None => self.stats.n_author_errors += 1,
        }
    }

    /// The peer crashes: its connections die with it, but the other ends notice only later
    /// (a transport's idle timeout), so what it sent before the crash still arrives.
    fn crash(&mut self, peer: usize, restart_micros: u64) {
        self.honest[peer].crash_armed = None;
        let linger = 2 * self.faults.latency_micros + 2 * self.faults.jitter_micros + 1;
        for other in 0..self.honest.len() {
            let pair = *self.pair(peer, other);
            if other == peer || !pair.connected {
                continue;
            }
            let until = self.now + linger + MAX_LINK_QUEUE_MICROS;
            self.lingering.insert((other, peer), (pair.epoch, until));
            let p = self.pair(peer, other);
            p.connected = false;
            p.epoch += 1;
            let epoch = pair.epoch;
            self.push(
                until,
                Ev::Unlinger {
                    to: other,
                    from: peer,
                    epoch,
                },
            );
        }
        if self.faults.streams {
            // Its connection to the hostile member dies with it too (going offline over
            // streams only stalls connections), and so do the dials again it was making.
            for other in self.honest.len()..self.n_nodes() {
                self.disconnect_pair(peer, other);
            }
            for other in 0..self.honest.len() {
                let me = self.honest[peer].peer.peer_id();
                if other != peer && me < self.honest[other].peer.peer_id() {
                    self.pair(peer, other).lost_until = 0;
                }
            }
        }
        self.go_offline(peer);
        self.restart(peer);
        self.push(self.now + restart_micros, Ev::Online { peer });
    }

    fn heal(&mut self) {
        self.blocked.clear();
        let stalled: Vec<(usize, usize)> = self.stalled.keys().copied().collect();
        self.stream_unblocked(&stalled);
        // Every op some honest peer holds, with its encoded size: what each must end with.
        let mut held = BTreeMap::new();
        for h in &self.honest {
            for e in h.peer.log().entries() {
                held.entry(e.op.id()).or_insert(e.op.encoded().len() as u64);
            }
        }
        let total: u64 = held.values().sum();
        for h in &mut self.honest {
            h.offline_depth = 0;
            h.crash_armed = None;
            let log = h.peer.log();
            let own: u64 = (log.entries()).filter_map(|e| held.get(&e.op.id())).sum();
            h.catch_up = CatchUp {
                n_held_at_heal: log.len(),
                n_bytes_lacked: total - own,
                ..CatchUp::default()
            };
        }
        for a in 0..self.n_nodes() {
            for b in a + 1..self.n_nodes() {
                if self.online(a) && self.online(b) {
                    self.reconnect_pair(a, b);
                }
            }
        }
        self.heal_at = self.now;
        self.last_delivery_at = self.now;
        self.push(self.now + PROBE_INTERVAL_MICROS, Ev::Probe);
    }

    /// The peer's network goes: its connections close at once over datagrams; over stream
    /// connections they stall, as in a partition, and the idle timeout closes those the
    /// outage outlasts.
    fn go_offline(&mut self, peer: usize) {
        self.honest[peer].offline_depth += 1;
        if self.honest[peer].offline_depth == 1 {
            if self.faults.streams {
                let links = self.links_of(peer);
                self.stream_partition_start(&links);
                self.partition(links, true);
                return;
            }
            for other in 0..self.n_nodes() {
                if other != peer {
                    self.disconnect_pair(peer, other);
                }
            }
        }
    }

    fn come_online(&mut self, peer: usize) {
        let h = &mut self.honest[peer];
        if h.offline_depth == 0 {
            return;
        }
        h.offline_depth -= 1;
        if h.offline_depth > 0 {
            return;
        }
        let started = h.started;
        if self.faults.streams {
            let links = self.links_of(peer);
            self.partition(links.clone(), false);
            self.stream_unblocked(&links);
        }
        if started {
            self.connect_all(peer);
        }
    }

    /// Both directed links between `peer` and every other node.
    fn links_of(&self, peer: usize) -> Vec<(usize, usize)> {
        (0..self.n_nodes())
            .filter(|&other| other != peer)
            .flat_map(|other| [(peer, other), (other, peer)])
            .collect()
    }

    /// Connects `peer` to every peer online (over streams through dials, which fail across a
    /// partition until it ends).
    fn connect_all(&mut self, peer: usize) {
        for other in 0..self.n_nodes() {
            if other != peer && self.online(other) {
                self.reconnect_pair(peer, other);
            }
        }
    }

    /// Connects `a` and `b` again after a connection between them closed (or one of them
    /// started): at once over datagrams, and over stream connections through a dial
    /// ([`Simulation::stream_dial`]).
    fn reconnect_pair(&mut self, a: usize, b: usize) {
        if self.faults.streams {
            self.stream_dial(a, b);
        } else {
            self.connect_pair(a, b);
        }
    }

    /// A late peer starts: from a snapshot of peer 0's log and scene when asked (and peer 0
    /// has not panicked), else empty.
    fn join(&mut self, idx: usize, snapshot: bool) {
        let mut joined = false;
        if snapshot && self.honest[0].panicked.is_none() && idx != 0 {
            let budget = refold_budget(&self.faults);
            let now = Timestamp(self.now);
            // The hostile member hands out a third of the snapshots, with a planted scene.
            let planted = self.hostile.is_some() && self.faults.forgery && self.net.chance(333);
            let (producer, joiner) = (&self.honest[0], &self.honest[idx]);
            match crate::join::from_snapshot(producer, joiner, budget, now, planted) {
                Ok((bytes, peer, scene)) => {
                    let h = &mut self.honest[idx];
                    h.peer = peer;
                    h.scene = scene;
                    h.disk.snapshot = Some(bytes);
                    let held: Vec<OpId> = h.peer.log().entries().map(|e| e.op.id()).collect();
                    crate::honest::note_delivered(h, &held);
                    self.stats.n_snapshot_joins += 1;
                    joined = true;
                }
                Err(Failed::Refused(_)) if planted => self.stats.n_snapshots_refused += 1,
                Err(Failed::Refused(e) | Failed::Other(e)) => self
                    .restart_failures
                    .push(format!("peer {idx}: snapshot join failed: {e}")),
            }
        }
        if !joined {
            self.stats.n_late_joins += 1;
        }
        self.honest[idx].started = true;
        if self.honest[idx].offline_depth == 0 {
            self.connect_all(idx);
        }
        self.flush(idx);
    }

    /// Restarts a crashed peer from what its store kept (see [`crate::store`]); pending ops,
    /// connection state and the scene are lost.
    fn restart(&mut self, idx: usize) {
        self.stats.n_crashes += 1;
        let now = Timestamp(self.now);
        let h = &mut self.honest[idx];
        if h.panicked.is_some() {
            return;
        }
        let recovered = memory::with_slot(h.slot, || {
            panic::catch_unwind(AssertUnwindSafe(|| {
                h.disk.crash(h.peer.log(), &mut self.net, now)
            }))
        });
        let recovered = match recovered {
            Ok(Ok(r)) => r,
            Ok(Err(e)) => {
                self.restart_failures.push(format!("peer {idx}: {e}"));
                return;
            }
            Err(e) => {
                h.panicked = Some(panic_text(e.as_ref()));
                return;
            }
        };
        self.stats.n_lost_unsynced += recovered.lost.len() as u64;
        self.stats.n_torn_tails += u64::from(recovered.n_truncated_bytes > 0);
        let me = h.peer.peer_id();
        for id in &recovered.lost {
            if h.peer.log().get(id).is_some_and(|op| op.author() == me) {
                self.lost_own.insert(*id);
            }
        }
        h.authored.retain(|id| !self.lost_own.contains(id));
        let mut log = recovered.log;
        log.set_refold_budget(refold_budget(&self.faults));
        h.scene = memory::with_slot(h.slot, || Scene::fold(&log));
        let key = Keypair::from_seed(h.key_seed);
        h.peer = memory::with_slot(h.slot, || Peer::new(key, SESSION_ID, log));
        h.wake_at = None;
    }

    /// Whether every live honest peer holds the same op set with nothing pending.
    fn agreed(&self) -> bool {
        let mut live = self.honest.iter().filter(|h| h.panicked.is_none());
        let Some(first) = live.next() else {
            return true;
        };
        let vv = first.peer.log().version_vector();
        // Forks too: learning one changes verdicts, not version vectors.
        let forks = |h: &Honest| h.peer.log().forks().authors().collect::<Vec<_>>();
        let first_forks = forks(first);
        first.peer.log().n_pending() == 0
            && live.all(|h| {
                h.peer.log().n_pending() == 0
                    && h.peer.log().version_vector() == vv
                    && forks(h) == first_forks
            })
    }

    fn online(&self, node: usize) -> bool {
        self.honest
            .get(node)
            .is_none_or(|h| h.offline_depth == 0 && h.started)
    }

    fn pair(&mut self, a: usize, b: usize) -> &mut Pair {
        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
        &mut self.pairs[lo][hi]
    }

    fn connect_pair(&mut self, a: usize, b: usize) {
        if self.pair(a, b).connected {
            return;
        }
        let now = Timestamp(self.now);
        for (x, y) in [(a, b), (b, a)] {
            // A new connection replaces one still open from before the other end crashed.
            if self.lingering.remove(&(x, y)).is_some() {
                guarded(&mut self.honest[x], |p| p.disconnect(ConnId(y as u64)));
            }
            if let Some(h) = self.honest.get_mut(x) {
                // A refused connect (too many, id in use) leaves the pair unusable from this
                // side; honest runs never hit it, and the checkers would see the divergence.
                let _ = guarded(h, |p| p.connect(now, ConnId(y as u64)));
            }
            self.admit_link(x, y);
        }
        let pair = self.pair(a, b);
        pair.connected = true;
        pair.epoch += 1;
        // The node forgets a lost peer once connected to it again.
        pair.lost_until = 0;
        if let Some(other) = self.other_than_hostile(a, b) {
            self.byzantine_link(other, true);
        }
        for x in [a, b] {
            if x < self.honest.len() {
                self.flush(x);
            }
        }
    }

    fn disconnect_pair(&mut self, a: usize, b: usize) {
        if !self.pair(a, b).connected {
            return;
        }
        for (x, y) in [(a, b), (b, a)] {
            if let Some(h) = self.honest.get_mut(x) {
                guarded(h, |p| p.disconnect(ConnId(y as u64)));
            }
        }
        let pair = self.pair(a, b);
        pair.connected = false;
        pair.epoch += 1;
        if let Some(other) = self.other_than_hostile(a, b) {
            self.byzantine_link(other, false);
        }
    }

    /// The honest end of the pair `(a, b)` if the other end is the hostile member.
    fn other_than_hostile(&self, a: usize, b: usize) -> Option<usize> {
        let h = self.hostile_idx()?;
        (a == h).then_some(b).or((b == h).then_some(a))
    }

    fn author(&mut self, peer: usize, payload: ShapePayload) {
        let now = Timestamp(self.now);
        let h = &mut self.honest[peer];
        let authored = guarded(h, |p| p.author(now, payload.clone()));
        match authored {
            Some(Ok((op, insertion))) => {
                self.stats.n_ops_authored += 1;
                self.trace.bytes(&op.id().0);
                h.user.authored(&payload, op.id());
                h.authored.push(op.id());
                if h.peer.log().mark(&op.id()) == Some(replication::Mark::Effective) {
                    h.effective_at_author.push(op.id());
                }
                note_delivered(h, &insertion.delivered);
                h.disk.append(&insertion.delivered);
                let Honest {
                    peer, scene, slot, ..
                } = h;
                memory::with_slot(*slot, || scene.apply_insertion(peer.log(), &insertion));
                if let ShapePayload::Create { object, .. } = payload
                    && !self.objects.contains(&object)
                {
                    self.objects.push(object);
                }
            }
            Some(Err(e)) => {
                self.stats.n_author_errors += 1;
                let what = e
                    .to_string()
                    .split_whitespace()
                    .take(3)
                    .collect::<Vec<_>>()
                    .join(" ");
                *self.stats.author_errors.entry(what).or_default() += 1;
            }
            None => self.stats.n_author_errors += 1,
        }
        self.flush(peer);
    }

    /// Drains a peer's events (appending delivered ops to its store), then, once everything
    /// appended is synced, its transmissions; then schedules its next wake-up.
    fn flush(&mut self, idx: usize) {
        let now = self.now;
        for _ in 0..MAX_DRAIN {
            let ev = guarded(&mut self.honest[idx], |p| p.poll_event());
            match ev {
                Some(Some((conn, event))) => self.on_event(idx, conn, event),
                _ => break,
            }
        }
        let delay = MIN_FSYNC_MICROS + self.net.below(MAX_FSYNC_MICROS - MIN_FSYNC_MICROS);
        let h = &mut self.honest[idx];
        if let Some(done) = h.disk.start_sync(now, delay) {
            let generation = h.disk.generation;
            self.push(
                done,
                Ev::FsyncDone {
                    peer: idx,
                    generation,
                },
            );
        }
        let synced = self.honest[idx].disk.n_unsynced() == 0;
        if synced || self.config.sabotage == crate::config::Sabotage::SendUnsynced {
            for _ in 0..MAX_DRAIN {
                let out = guarded(&mut self.honest[idx], |p| p.poll_transmit(Timestamp(now)));
                match out {
                    Some(Some((conn, bytes))) => self.send(idx, conn, bytes),
                    _ => break,
                }
            }
        }
        // An armed crash strikes while something appended is not yet synced.
        let h = &self.honest[idx];
        if let Some((restart_micros, own_only)) = h.crash_armed
            && !synced
            && (!own_only
                || h.authored
                    .last()
                    .is_some_and(|id| !self.durable.contains(id)))
        {
            self.crash(idx, restart_micros);
            return;
        }
        let next = guarded(&mut self.honest[idx], |p| p.poll_timeout()).flatten();
        if let Some(t) = next {
            // While unsynced, nothing can go out before the fsync completes anyway.
            let floor = if synced {
                now + 1
            } else {
                now + MAX_FSYNC_MICROS
            };
            let at = t.0.max(floor);
            let h = &mut self.honest[idx];
            if h.wake_at.is_none_or(|w| at < w) {
                h.wake_at = Some(at);
                self.push(at, Ev::Wake { peer: idx });
            }
        }
    }

    fn fsync_done(&mut self, idx: usize, generation: u64) {
        let h = &mut self.honest[idx];
        if h.disk.generation != generation {
            return;
        }
        self.stats.n_fsyncs += 1;
        let newly = h.disk.complete_sync();
        self.durable.extend(newly.iter().copied());
        self.flush(idx);
    }

    /// Ops delivered at peer `idx` (reported on connection `conn`): noted, appended to its
    /// disk and folded into its scene.
    fn on_delivered(&mut self, idx: usize, conn: ConnId, insertion: Insertion) {
        self.trace.u64(10);
        for id in &insertion.delivered {
            self.trace.bytes(&id.0);
        }
        if !insertion.delivered.is_empty() {
            self.last_delivery_at = self.now;
        }
        let sabotage = self.config.sabotage;
        let h = &mut self.honest[idx];
        if self.heal_at > START_MICROS && !insertion.delivered.is_empty() {
            let since = self.now - self.heal_at;
            let c = &mut h.catch_up;
            if c.n_insertions == 0 {
                c.first_micros = since;
            }
            c.n_delivered += insertion.delivered.len();
            c.n_insertions += 1;
            c.last_micros = since;
            c.last_from = conn.0;
        }
        note_delivered(h, &insertion.delivered);
        h.disk.append(&insertion.delivered);
        h.n_received_insertions += 1;
        let skip = sabotage == crate::config::Sabotage::DropEveryTenthInsertion
            && idx == 0
            && h.n_received_insertions.is_multiple_of(10);
        if !skip {
            let Honest {
                peer, scene, slot, ..
            } = h;
            let log = peer.log();
            let applied = memory::with_slot(*slot, || {
                panic::catch_unwind(AssertUnwindSafe(|| {
                    scene.apply_insertion(log, &insertion);
                }))
            });
            if let Err(e) = applied {
                h.panicked = Some(panic_text(e.as_ref()));
            }
        }
    }

    fn on_event(&mut self, idx: usize, conn: ConnId, event: Event) {
        match event {
            Event::Delivered(insertion) => self.on_delivered(idx, conn, insertion),
            Event::Rejected { kind, .. } => {
                self.trace.u64(11);
                let kind = format!("{kind:?}");
                if Some(conn.0 as usize) == self.hostile_idx() {
                    self.stats.n_hostile_rejects += 1;
                    *self.stats.hostile_rejects.entry(kind).or_default() += 1;
                } else {
                    *self.stats.honest_rejects.entry(kind).or_default() += 1;
                }
            }
            Event::Closed(reason) => {
                self.trace.u64(12);
                if matches!(reason, CloseReason::Expelled { .. }) {
                    self.stats.n_expel_closes += 1;
                }
                // The transport closes both ends.
                let other = conn.0 as usize;
                if other < self.n_nodes() {
                    self.disconnect_pair(idx, other);
                    self.redial_after_close(idx, other, reason);
                }
            }
            Event::Connected { .. } | Event::Ephemeral { .. } | Event::UpToDate => {
                self.trace.u64(13);
            }
            Event::Forked { .. } => {
                self.trace.u64(14);
                self.stats.n_forks_learnt += 1;
            }
            // Over streams the peer dials again, as the node does, from the second event of a
            // silence (nothing reaches a peer through a partition, which the node checks; once
            // it ends the remote's acknowledgements do, which this does not model), or when
            // the remote shows it hears nothing of ours. Datagrams have no connection to
            // replace.
            Event::Stalled {
                handshake_micros,
                again,
                unheard,
            } => {
                let other = conn.0 as usize;
                if self.faults.streams && (again || unheard) && other < self.n_nodes() {
                    self.trace.u64(22);
                    self.stream_redial(idx, other, handshake_micros);
                }
            }
            // Over streams the peer's finders and its own dials of lost peers dial at once
            // every peer it has no connection to, as the node does.
            Event::Resumed { .. } => {
                let other = conn.0 as usize;
                if self.faults.streams && other < self.n_nodes() {
                    self.stream_resumed(idx);
                }
            }
            // The peer hands the scene check's events to its own queue, which the simulator
            // does not drive (no honest peer here tells its peer a scene hash).
            Event::Scene(_) => {}
        }
    }

    /// Puts one honest message on the network.
    fn send(&mut self, from: usize, conn: ConnId, bytes: Vec<u8>) {
        let to = conn.0 as usize;
        // The network holds its own copy: traffic in flight is not the sender's memory.
        let bytes = if memory::installed() {
            bytes.as_slice().to_vec()
        } else {
            bytes
        };
        let h = &mut self.honest[from];
        h.n_messages_sent += 1;
        h.n_bytes_sent += bytes.len() as u64;
        if Some(to) == self.hostile_idx() {
            self.stats.n_messages_to_hostile += 1;
            if let Some(hostile) = &mut self.hostile {
                let copy = hostile.byzantine.is_some().then(|| bytes.clone());
                hostile.capture(bytes, &mut self.net);
                if let Some(copy) = copy {
                    self.byzantine_receive(from, &copy);
                }
            }
            return;
        }
        if to >= self.n_nodes() {
            return;
        }
        self.stats.n_messages += 1;
        self.stats.n_bytes += bytes.len() as u64;
        let kind = replication::sync::message::kind_of(&bytes).unwrap_or("unknown");
        let counted = self.stats.bytes_by_kind.entry(kind).or_default();
        counted.0 += 1;
        counted.1 += bytes.len() as u64;
        if self.faults.streams {
            return self.stream_send(from, to, bytes);
        }
        if self.blocked.contains_key(&(from, to)) {
            self.stats.n_partition_drops += 1;
            return;
        }
        let faults = self.faults;
        if self.net.chance(faults.loss_per_mille) {
            self.stats.n_lost += 1;
            return;
        }
        let Some(departs) = self.transmit_slot(from, to, bytes.len()) else {
            self.stats.n_queue_drops += 1;
            return;
        };
        let epoch = self.pair(from, to).epoch;
        let base = self.latency_micros[from][to];
        let at = departs + base + self.net.below(faults.jitter_micros + 1);
        self.n_in_flight += 1;
        if self.net.chance(faults.dup_per_mille) {
            self.stats.n_duplicated += 1;
            self.n_in_flight += 1;
            let again = departs + base + self.net.below(2 * faults.jitter_micros + 1);
            let copy = bytes.clone();
            self.push(again, deliver(from, to, epoch, copy, None));
        }
        self.push(at, deliver(from, to, epoch, bytes, None));
    }

    /// When a message of `n_bytes` has left the link `from -> to`, given what is queued on
    /// it; `None` if the queue is full.
    fn transmit_slot(&mut self, from: usize, to: usize, n_bytes: usize) -> Option<u64> {
        let bandwidth = self.faults.bandwidth_bytes_per_sec;
        if bandwidth == 0 {
            return Some(self.now);
        }
        let free = &mut self.link_free_at[from][to];
        let start = (*free).max(self.now);
        if start - self.now > MAX_LINK_QUEUE_MICROS {
            return None;
        }
        *free = start + (n_bytes as u64 * 1_000_000).div_ceil(bandwidth);
        Some(*free)
    }

    fn deliver(&mut self, from: usize, to: usize, epoch: u64, bytes: &[u8], flood: Option<usize>) {
        if from < self.honest.len() {
            self.n_in_flight -= 1;
        }
        let pair = *self.pair(from, to);
        let current = pair.connected && pair.epoch == epoch;
        let lingering = self
            .lingering
            .get(&(to, from))
            .is_some_and(|l| l.0 == epoch && self.now <= l.1);
        if self.faults.streams
            && (current || lingering)
            && self.stream_holds(from, to, epoch, bytes)
        {
            return;
        }
        if !(current || lingering) || !self.online(to) || to >= self.honest.len() {
            self.stats.n_stale_drops += 1;
            return;
        }
        self.trace.u64(from as u64);
        self.trace.u64(to as u64);
        self.trace.bytes(bytes);
        self.stats.n_delivered += 1;
        if self.faults.streams {
            self.last_heard.insert((from, to), self.now);
        }
        let rate_limited_before = self.stats.hostile_rejects.get("RateLimited").copied();
        let now = Timestamp(self.now);
        guarded(&mut self.honest[to], |p| {
            p.handle_input(now, ConnId(from as u64), bytes);
        });
        if self.faults.streams {
            self.stream_read_behind_hello(from, to, epoch);
        }
        self.flush(to);
        if let Some(f) = flood {
            let limited =
                self.stats.hostile_rejects.get("RateLimited").copied() != rate_limited_before;
            self.stats.n_flood_delivered += 1;
            self.stats.n_flood_accepted += u64::from(!limited);
            if let Some(counts) = self.floods.get_mut(f) {
                counts.0 += 1;
                counts.1 += u64::from(!limited);
            }
        }
    }

    /// Records one sample of every peer for the plots, thinning when there are too many.
    fn sample(&mut self) {
        if self.samples.len() >= MAX_SAMPLES {
            let kept: Vec<Sample> = self.samples.iter().step_by(2).cloned().collect();
            self.samples = kept;
            self.sample_interval_micros *= 2;
        }
        let peers = self
            .honest
            .iter_mut()
            .map(|h| {
                let live_bytes = h.live_bytes();
                h.peak_live_bytes = h.peak_live_bytes.max(live_bytes);
                PeerSample {
                    n_ops_held: h.peer.log().len() as u64,
                    n_messages_sent: h.n_messages_sent,
                    n_bytes_sent: h.n_bytes_sent,
                    live_bytes,
                }
            })
            .collect();
        self.samples.push(Sample {
            at_micros: self.now - START_MICROS,
            peers,
        });
    }
}

/// The hostile member on the network: its tricks, floods and crafted attacks, and its core's
/// traffic.
impl Simulation {
    /// Honest peers the hostile peer can reach now.
    fn hostile_targets(&mut self, h: usize) -> Vec<usize> {
        (0..self.config.n_peers)
            .filter(|t| self.online(*t) && self.pair(*t, h).connected)
            .collect()
    }

    /// The hostile peer sends one of its tricks to a random reachable peer.
    fn hostile_send(&mut self) {
        let Some(h) = self.hostile_idx() else { return };
        let targets = self.hostile_targets(h);
        if targets.is_empty() {
            return;
        }
        // Half of a byzantine member's tricks are crafted attacks (other presets draw nothing
        // here, so their runs are unchanged).
        if self.hostile.as_ref().is_some_and(|x| x.byzantine.is_some())
            && self.net.chance(500)
            && self.byzantine_send(h, &targets)
        {
            return;
        }
        let to = targets[self.net.index(targets.len())];
        let n_kinds = if self.faults.forgery { 7 } else { 5 };
        let kind = self.net.below(n_kinds);
        let (now, rng, honest, stats) = (self.now, &mut self.net, &self.honest, &mut self.stats);
        let messages = (self.hostile.as_mut())
            .and_then(|hostile| hostile.messages(kind, rng, honest, now, stats));
        let messages = messages.unwrap_or_else(|| vec![hostile::garbage(&mut self.net)]);
        self.hostile_deliver(h, messages.into_iter().map(|bytes| (to, bytes)).collect());
    }

    /// Puts the hostile member's messages on its links to their receivers (never lost: its
    /// links are its own).
    fn hostile_deliver(&mut self, h: usize, sends: Sends) {
        for (to, bytes) in sends {
            let epoch = self.pair(h, to).epoch;
            let at = self.now + self.latency_micros[h][to];
            self.stats.n_hostile_messages += 1;
            self.push(at, deliver(h, to, epoch, bytes, None));
        }
    }

    /// Floods one reachable peer with [`FLOOD_MESSAGES`] small messages at one instant.
    fn hostile_flood(&mut self) {
        let Some(h) = self.hostile_idx() else { return };
        let targets = self.hostile_targets(h);
        if targets.is_empty() {
            return;
        }
        let to = targets[self.net.index(targets.len())];
        let epoch = self.pair(h, to).epoch;
        let at = self.now + self.latency_micros[h][to];
        let flood = self.floods.len();
        self.floods.push((0, 0));
        for _ in 0..FLOOD_MESSAGES {
            let mut b = vec![0u8; 8];
            self.net.fill(&mut b);
            self.stats.n_hostile_messages += 1;
            self.push(at, deliver(h, to, epoch, b, Some(flood)));
        }
    }

    /// The byzantine member sends one crafted attack to the reachable peers `targets` (not
    /// empty); false if it had nothing to send.
    fn byzantine_send(&mut self, h: usize, targets: &[usize]) -> bool {
        let menu = Attack::menu(&self.faults);
        if menu.is_empty() {
            return false;
        }
        // The draw is made every time, so the network's stream advances per attack whichever
        // attack the member's turn picks.
        let first = self.net.index(menu.len());
        let Some(byz) = self.byzantine_mut() else {
            return false;
        };
        let attack = byz.next_attack(&menu, first);
        let to = targets[self.net.index(targets.len())];
        let Some(sends) = self.craft(attack, to, targets) else {
            return false;
        };
        *self.stats.byzantine.entry(attack.name()).or_default() += 1;
        self.hostile_deliver(h, sends);
        // What the core authored goes out through its sync.
        self.byzantine_flush();
        true
    }

    /// The byzantine member crafts `attack` on honest peer `to` from what the run shows it.
    fn craft(&mut self, attack: Attack, to: usize, targets: &[usize]) -> Option<Sends> {
        let victim = self.honest.get(to).map(|h| h.user.next_ids());
        let victim_key = self.honest.get(to).map(|h| h.peer.peer_id());
        let third_key = (self.honest.iter().enumerate())
            .find(|(idx, _)| *idx != to)
            .map(|(_, h)| h.peer.peer_id());
        let hostile = self.hostile.as_mut()?;
        let me = hostile.peer_id();
        let batch_no = hostile.next_batch_no();
        let byz = hostile.byzantine.as_mut()?;
        let aim = Aim {
            now: self.now,
            me,
            batch_no,
            to,
            targets,
            objects: &self.objects,
            victim,
            victim_key,
            third_key,
        };
        byz.craft(attack, &aim, &mut self.net)
    }

    /// The transport's part of honest peer `x`'s new connection to node `y`: the id admission
    /// proved (the member's own key for the hostile one), and where a byzantine member runs,
    /// the quota of op bytes scaled to the simulator's logs.
    fn admit_link(&mut self, x: usize, y: usize) {
        let now = Timestamp(self.now);
        let admitted = match self.honest.get(y) {
            Some(h) => Some(h.peer.peer_id()),
            None => self.hostile.as_ref().map(|h| h.peer_id()),
        };
        let byzantine = self.faults.byzantine;
        if let (Some(h), Some(admitted)) = (self.honest.get_mut(x), admitted) {
            guarded(h, |p| {
                p.set_admitted(ConnId(y as u64), admitted);
                if byzantine {
                    p.set_op_byte_quota(now, ConnId(y as u64), SMALL_OP_BYTE_QUOTA);
                }
            });
        }
    }

    /// After honest peer `idx` closed its connection to `other` for `reason`: the hostile
    /// member dials again soon, unless it was expelled.
    fn redial_after_close(&mut self, idx: usize, other: usize, reason: CloseReason) {
        let expelled = matches!(reason, CloseReason::Expelled { .. });
        if Some(other) == self.hostile_idx() && !expelled {
            self.push(self.now + REDIAL_MICROS, Ev::Redial { peer: idx });
        }
    }

    /// The hostile member dials honest peer `peer` again.
    fn redial(&mut self, peer: usize) {
        if let Some(h) = self.hostile_idx()
            && self.online(peer)
        {
            self.connect_pair(peer, h);
        }
    }

    /// Hands a message an honest peer sent the hostile member to its core.
    fn byzantine_receive(&mut self, from: usize, bytes: &[u8]) {
        let now = self.now;
        let Some(byz) = self.byzantine_mut() else {
            return;
        };
        byz.receive(now, from, bytes);
        self.byzantine_flush();
    }

    /// The core's connection to honest peer `other` opened (`true`) or closed.
    fn byzantine_link(&mut self, other: usize, open: bool) {
        let now = self.now;
        let Some(byz) = self.byzantine_mut() else {
            return;
        };
        byz.link(now, other, open);
        if open {
            self.byzantine_flush();
        }
    }

    /// The core's timer.
    fn byzantine_wake(&mut self) {
        let now = self.now;
        let Some(byz) = self.byzantine_mut() else {
            return;
        };
        byz.wake(now);
        self.byzantine_flush();
    }

    fn byzantine_mut(&mut self) -> Option<&mut Byzantine> {
        self.hostile.as_mut()?.byzantine.as_mut()
    }

    /// Puts what the core sends on the network, like an honest peer's but never lost (the
    /// hostile member's links are its own), and schedules its timer.
    fn byzantine_flush(&mut self) {
        let Some(h) = self.hostile_idx() else { return };
        let now = self.now;
        let Some((out, next)) = self.byzantine_mut().map(|byz| byz.drain(now)) else {
            return;
        };
        for (to, bytes) in out {
            if to < self.honest.len() && self.pair(h, to).connected {
                let epoch = self.pair(h, to).epoch;
                let at = now + self.latency_micros[h][to];
                self.push(at, deliver(h, to, epoch, bytes, None));
            }
        }
        if let Some(at) = next {
            self.push(at, Ev::HostileWake);
        }
    }
}

/// A delivery of `bytes` from node `from` to node `to` on their connection of `epoch`, of flood
/// `flood` if any.
fn deliver(from: usize, to: usize, epoch: u64, bytes: Vec<u8>, flood: Option<usize>) -> Ev {
    Ev::Deliver {
        from,
        to,
        epoch,
        bytes,
        flood,
    }
}

/// The log every peer of a run starts with: with a founder, its commitment, and on even
/// seeds the cap of a session that binds its authors.
fn session_log(seed: u64, founder: Option<FounderCommitment>) -> Option<Log<ShapePayload>> {
    let mut log = Log::default();
    if let Some(founder) = founder {
        log.set_founder(founder).ok()?;
        if seed.is_multiple_of(2) {
            log.bind_authors(SESSION_CAP_BYTES).ok()?;
        }
    }
    Some(log)
}

/// The honest peers of `config`, their keys drawn from `keys`, and the founder's commitment
/// (peer 0's, when the founder expels the hostile member).
fn new_peers(
    config: &Config,
    faults: &Faults,
    keys: &mut SimRng,
) -> Result<(Vec<Honest>, Option<FounderCommitment>), ConfigError> {
    let n = config.n_peers;
    let first_slot = memory::reserve_slots(n);
    let mut honest = Vec::with_capacity(n);
    let mut founder = None;
    for i in 0..n {
        let mut key_seed = [0u8; 32];
        keys.fill(&mut key_seed);
        let slot = memory::slot(first_slot, i);
        if i == 0 && faults.expel && config.hostile {
            let key = Keypair::from_seed(key_seed).peer_id();
            founder = Some(FounderCommitment::of(&key, &FOUNDER_NONCE));
        }
        let log = session_log(config.seed, founder).ok_or(ConfigError::Peers(i))?;
        let budget = refold_budget(faults);
        honest.push(new_honest(key_seed, log, slot, budget).ok_or(ConfigError::Peers(i))?);
    }
    Ok((honest, founder))
}

/// The hostile member, its key drawn from `keys` after every honest peer's a run of
/// [`crate::config::MAX_PEERS`] could have; with a byzantine core when `faults` craft attacks.
fn new_hostile(
    config: &Config,
    faults: &Faults,
    keys: &mut SimRng,
    founder: Option<FounderCommitment>,
) -> Hostile {
    let mut key_seed = [0u8; 32];
    for _ in config.n_peers..crate::config::MAX_PEERS {
        keys.fill(&mut key_seed);
    }
    keys.fill(&mut key_seed);
    let mut hostile = Hostile::new(Keypair::from_seed(key_seed));
    if faults.byzantine || faults.lease_attacks || faults.forks {
        let mut stream = SimRng::stream(config.seed, BYZANTINE_STREAM);
        let log = session_log(config.seed, founder).unwrap_or_default();
        let key = Keypair::from_seed(key_seed);
        // Its core authors under the connection key; its own hand-made ops get another.
        let mut own_seed = [0u8; 32];
        stream.fill(&mut own_seed);
        hostile.own_ops_under(Keypair::from_seed(own_seed));
        hostile.byzantine = Some(Byzantine::new(key, stream, log));
    }
    hostile
}

/// The refold budget honest peers run with. Under the byzantine preset it is scaled down to
/// the simulator's logs of hundreds of ops ([`SMALL_REFOLD_BUDGET`]), so the refold flood
/// makes them hold and batch deliveries as a long log would; elsewhere it is the core's.
fn refold_budget(faults: &Faults) -> RefoldBudget {
    if faults.byzantine {
        SMALL_REFOLD_BUDGET
    } else {
        RefoldBudget::default()
    }
}

/// [`RefoldBudget`] for logs about a thousand times shorter than the core's limits assume.
pub const SMALL_REFOLD_BUDGET: RefoldBudget = RefoldBudget {
    free_entries: 32,
    entries_per_second: 2_000,
    burst_entries: 2_000,
};

/// Runs `config` to the end.
pub fn run(config: Config) -> Result<Report, ConfigError> {
    Ok(Simulation::new(config)?.run())
}
