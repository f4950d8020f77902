//! The simulation proper: honest peers running the real [`Peer`] core, one hostile peer, a
//! modelled network and a virtual clock. Events sit in one queue ordered by (virtual time,
//! sequence number); every random choice comes from the run's one [`SimRng`].

use std::collections::{BTreeMap, BTreeSet};
use std::panic::{self, AssertUnwindSafe};

use replication::log::{LOCAL_ORIGIN, OrderKey};
use replication::materialize::{FoldEntry, Materialize, Materialized, SceneHash};
use replication::shape::{ShapePayload, ShapeScene};
use replication::sync::message::MAX_MESSAGE_BYTES;
use replication::{ConnId, Event, Keypair, Log, OpId, Peer, Timestamp};

use crate::config::{Config, ConfigError, Sabotage};
use crate::report::Report;
use crate::rng::SimRng;
use crate::trace::TraceHash;
use crate::workload::{self, HOT_OBJECT, User};

/// The virtual clock's start (µs); op timestamps are virtual times.
pub const START_MICROS: u64 = 1_000_000_000;
/// The session every peer joins.
pub const SESSION_ID: [u8; 16] = *b"sculpt-simulator";
/// Mean virtual time between two user ops (over all peers).
pub const MEAN_OP_GAP_MICROS: u64 = 20_000;
/// How long after healing the network may take to go quiet before the run counts as stuck.
pub const QUIESCENCE_LIMIT_MICROS: u64 = 600_000_000;
/// Most messages the hostile peer keeps for replays.
pub const MAX_CAPTURED_MESSAGES: usize = 256;
/// Most events one run handles (a live-lock guard).
pub const MAX_EVENTS: u64 = 200_000_000;
/// How often, after healing, the harness looks for quiescence.
pub const PROBE_INTERVAL_MICROS: u64 = 50_000;
/// Most messages drained from one peer in one go (a live-lock guard).
pub const MAX_DRAIN: usize = 1_000_000;

type Scene = Materialized<ShapePayload, ShapeScene>;

/// What can happen at a virtual instant.
#[derive(Debug)]
enum Ev {
    Deliver {
        from: usize,
        to: usize,
        epoch: u64,
        bytes: Vec<u8>,
    },
    Wake {
        peer: usize,
    },
    User {
        peer: usize,
    },
    Hostile,
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
    /// The peer crashes and restarts from its store; it comes back with an [`Ev::Online`].
    Crash {
        peer: usize,
    },
    Heal,
    /// After healing: stop once honest peers agree and nothing is in flight between them.
    Probe,
}

/// One honest peer and what the harness knows about it.
struct Honest {
    /// The key's seed (a restart rebuilds the key from it).
    key_seed: [u8; 32],
    peer: Peer<ShapePayload>,
    /// Kept up to date incrementally from every insertion, as the app does.
    scene: Scene,
    user: User,
    /// Ops delivered so far, to check that every op's deps came before it.
    seen: BTreeSet<[u8; 32]>,
    n_received_insertions: u64,
    panicked: Option<String>,
    offline_depth: u32,
    wake_at: Option<u64>,
    n_causal_violations: u64,
    authored: Vec<OpId>,
}

/// Connection state of an unordered pair of nodes.
#[derive(Debug, Clone, Copy, Default)]
struct Pair {
    connected: bool,
    /// Bumped on every connect and disconnect: messages of an older epoch are dropped.
    epoch: u64,
}

/// Counters a run reports.
#[derive(Debug, Default, Clone)]
pub struct Stats {
    /// Ops the users authored (the hot object's creation included).
    pub n_ops_authored: u64,
    /// Ops the core refused to author.
    pub n_author_errors: u64,
    /// Messages honest peers sent to honest peers.
    pub n_messages: u64,
    /// Bytes honest peers sent to honest peers.
    pub n_bytes: u64,
    /// Messages honest peers sent to the hostile peer (which never answers, so hellos and
    /// batches to it are resent every second until the run ends).
    pub n_messages_to_hostile: u64,
    /// Messages handed to an honest peer.
    pub n_delivered: u64,
    /// Messages lost at random.
    pub n_lost: u64,
    /// Extra copies made.
    pub n_duplicated: u64,
    /// Messages dropped by a partition.
    pub n_partition_drops: u64,
    /// Messages that arrived after their connection was gone.
    pub n_stale_drops: u64,
    /// Messages the hostile peer sent.
    pub n_hostile_messages: u64,
    /// Rejections honest peers reported about honest connections, by kind.
    pub honest_rejects: BTreeMap<String, u64>,
    /// Rejections honest peers reported about the hostile connection.
    pub n_hostile_rejects: u64,
    /// Events handled.
    pub n_events: u64,
    /// Crashes and restarts.
    pub n_crashes: u64,
}

/// A run in progress.
pub struct Simulation {
    config: Config,
    rng: SimRng,
    now: u64,
    seq: u64,
    queue: BTreeMap<(u64, u64), Ev>,
    honest: Vec<Honest>,
    /// One-way base latency per directed link, `[from][to]`.
    latency_micros: Vec<Vec<u64>>,
    /// Pair state, `[min][max]`.
    pairs: Vec<Vec<Pair>>,
    blocked: BTreeMap<(usize, usize), u32>,
    captured: Vec<Vec<u8>>,
    objects: Vec<u64>,
    stats: Stats,
    trace: TraceHash,
    heal_at: u64,
    last_delivery_at: u64,
    timed_out: bool,
    /// Messages between honest peers on the network now.
    n_in_flight: u64,
    quiet: bool,
    /// What went wrong at restarts (checked at the end).
    restart_failures: Vec<String>,
}

impl Simulation {
    /// Sets up a run: keys, peers, the full mesh of connections and every scheduled event.
    pub fn new(config: Config) -> Result<Simulation, ConfigError> {
        config.validate()?;
        let mut rng = SimRng::new(config.seed);
        let n = config.n_peers;
        let n_nodes = n + usize::from(config.hostile);
        let mut honest = Vec::with_capacity(n);
        for i in 0..n {
            let mut seed = [0u8; 32];
            rng.fill(&mut seed);
            let keypair = Keypair::from_seed(seed);
            let log = Log::default();
            let scene = Scene::fold(&log).map_err(|_| ConfigError::Peers(i))?;
            honest.push(Honest {
                key_seed: seed,
                peer: Peer::new(keypair, SESSION_ID, log),
                scene,
                user: User::default(),
                seen: BTreeSet::new(),
                n_received_insertions: 0,
                panicked: None,
                offline_depth: 0,
                wake_at: None,
                n_causal_violations: 0,
                authored: Vec::new(),
            });
        }
        let lat = config.faults.latency_micros;
        let latency_micros = (0..n_nodes)
            .map(|_| (0..n_nodes).map(|_| lat / 2 + rng.below(lat + 1)).collect())
            .collect();
        let mut sim = Simulation {
            config,
            rng,
            now: START_MICROS,
            seq: 0,
            queue: BTreeMap::new(),
            honest,
            latency_micros,
            pairs: vec![vec![Pair::default(); n_nodes]; n_nodes],
            blocked: BTreeMap::new(),
            captured: Vec::new(),
            objects: vec![HOT_OBJECT],
            stats: Stats::default(),
            trace: TraceHash::default(),
            heal_at: START_MICROS,
            last_delivery_at: START_MICROS,
            timed_out: false,
            n_in_flight: 0,
            quiet: false,
            restart_failures: Vec::new(),
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
        let n = self.config.n_peers;
        // Peer 0 creates the object everyone fights over, before anyone connects.
        if let Some(create) = workload::hot_object(&mut self.rng) {
            self.author(0, create);
        }
        for a in 0..self.n_nodes() {
            for b in a + 1..self.n_nodes() {
                self.connect_pair(a, b);
            }
        }
        let mut t = START_MICROS;
        for _ in 0..self.config.n_ops {
            t += 1 + self.rng.below(2 * MEAN_OP_GAP_MICROS);
            let peer = self.rng.index(n);
            self.push(t, Ev::User { peer });
        }
        let work_end = t;
        let span = work_end - START_MICROS;
        if self.config.hostile {
            for _ in 0..self.config.n_ops / 5 + 1 {
                let at = START_MICROS + self.rng.below(span);
                self.push(at, Ev::Hostile);
            }
        }
        let faults = self.config.faults;
        if faults.partitions {
            for _ in 0..1 + self.config.n_ops / 150 {
                let start = START_MICROS + self.rng.below(span);
                let duration = 300_000 + self.rng.below(3_000_000);
                let side: Vec<bool> = (0..n).map(|_| self.rng.chance(500)).collect();
                let asymmetric = self.rng.chance(300);
                let mut cut = Vec::new();
                for a in 0..n {
                    for b in 0..n {
                        if side[a] && !side[b] {
                            cut.push((a, b));
                            if !asymmetric {
                                cut.push((b, a));
                            }
                        }
                    }
                }
                if !cut.is_empty() {
                    self.push(start, Ev::PartitionStart { cut: cut.clone() });
                    self.push(start + duration, Ev::PartitionEnd { cut });
                }
            }
        }
        if faults.offline {
            for _ in 0..1 + self.config.n_ops / 200 {
                let peer = self.rng.index(n);
                let start = START_MICROS + self.rng.below(span);
                let duration = 500_000 + self.rng.below(5_000_000);
                self.push(start, Ev::Offline { peer });
                self.push(start + duration, Ev::Online { peer });
            }
        }
        if faults.crashes {
            for _ in 0..1 + self.config.n_ops / 300 {
                let peer = self.rng.index(n);
                let start = START_MICROS + self.rng.below(span);
                let restart = 200_000 + self.rng.below(2_000_000);
                self.push(start, Ev::Crash { peer });
                self.push(start + restart, Ev::Online { peer });
            }
        }
        self.push(work_end + 1, Ev::Heal);
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
            self.trace.u64(at);
            self.handle(ev);
            if self.quiet {
                break;
            }
        }
        self.finish()
    }

    fn handle(&mut self, ev: Ev) {
        match ev {
            Ev::Deliver {
                from,
                to,
                epoch,
                bytes,
            } => self.deliver(from, to, epoch, &bytes),
            Ev::Wake { peer } => {
                self.trace.u64(1);
                let now = self.now;
                let h = &mut self.honest[peer];
                if h.wake_at == Some(now) {
                    h.wake_at = None;
                }
                guarded(h, |p| p.handle_timeout(Timestamp(now)));
                self.flush(peer);
            }
            Ev::User { peer } => {
                self.trace.u64(2);
                let payload = self.honest[peer]
                    .user
                    .next(&mut self.rng, peer, &self.objects);
                match payload {
                    Some(payload) => self.author(peer, payload),
                    None => self.stats.n_author_errors += 1,
                }
            }
            Ev::Hostile => {
                self.trace.u64(3);
                self.hostile_send();
            }
            Ev::PartitionStart { cut } => {
                self.trace.u64(4);
                for link in cut {
                    *self.blocked.entry(link).or_default() += 1;
                }
            }
            Ev::PartitionEnd { cut } => {
                self.trace.u64(5);
                for link in cut {
                    if let Some(c) = self.blocked.get_mut(&link) {
                        *c -= 1;
                        if *c == 0 {
                            self.blocked.remove(&link);
                        }
                    }
                }
            }
            Ev::Offline { peer } => {
                self.trace.u64(6);
                self.go_offline(peer);
            }
            Ev::Crash { peer } => {
                self.trace.u64(9);
                self.go_offline(peer);
                self.restart(peer);
            }
            Ev::Online { peer } => {
                self.trace.u64(7);
                let h = &mut self.honest[peer];
                if h.offline_depth > 0 {
                    h.offline_depth -= 1;
                    if h.offline_depth == 0 {
                        for other in 0..self.n_nodes() {
                            if other != peer && self.online(other) {
                                self.connect_pair(peer, other);
                            }
                        }
                    }
                }
            }
            Ev::Heal => {
                self.trace.u64(8);
                self.blocked.clear();
                for h in &mut self.honest {
                    h.offline_depth = 0;
                }
                for a in 0..self.n_nodes() {
                    for b in a + 1..self.n_nodes() {
                        self.connect_pair(a, b);
                    }
                }
                self.heal_at = self.now;
                self.last_delivery_at = self.now;
                self.push(self.now + PROBE_INTERVAL_MICROS, Ev::Probe);
            }
            Ev::Probe => {
                if self.n_in_flight == 0 && self.agreed() {
                    self.quiet = true;
                } else {
                    self.push(self.now + PROBE_INTERVAL_MICROS, Ev::Probe);
                }
            }
        }
    }

    fn go_offline(&mut self, peer: usize) {
        self.honest[peer].offline_depth += 1;
        if self.honest[peer].offline_depth == 1 {
            for other in 0..self.n_nodes() {
                if other != peer {
                    self.disconnect_pair(peer, other);
                }
            }
        }
    }

    /// Restarts a crashed peer from its store. The store holds every op the log delivered
    /// (the driver appends each before the next transmit), so it is modelled as those ops in
    /// linear order; pending ops, connection state and the scene are lost.
    fn restart(&mut self, idx: usize) {
        self.stats.n_crashes += 1;
        let now = Timestamp(self.now);
        let h = &mut self.honest[idx];
        if h.panicked.is_some() {
            return;
        }
        let old = h.peer.log();
        let stored: Vec<_> = old.entries().map(|e| e.op.clone()).collect();
        let (n_before, vv_before) = (old.len(), old.version_vector().clone());
        let reloaded = panic::catch_unwind(AssertUnwindSafe(|| {
            let mut log = Log::default();
            let mut n_refused = 0usize;
            for op in stored {
                match op.into_verified() {
                    Ok(op) => {
                        if log.insert(now, op, LOCAL_ORIGIN).is_err() {
                            n_refused += 1;
                        }
                    }
                    Err(_) => n_refused += 1,
                }
            }
            (log, n_refused)
        }));
        let (log, n_refused) = match reloaded {
            Ok(r) => r,
            Err(e) => {
                h.panicked = Some(panic_text(e.as_ref()));
                return;
            }
        };
        if n_refused > 0 || log.len() != n_before || *log.version_vector() != vv_before {
            self.restart_failures.push(format!(
                "peer {idx}: restart reloaded {} of {n_before} ops ({n_refused} refused)",
                log.len()
            ));
        }
        match Scene::fold(&log) {
            Ok(scene) => h.scene = scene,
            Err(e) => self
                .restart_failures
                .push(format!("peer {idx}: reloaded log does not fold: {e}")),
        }
        h.peer = Peer::new(Keypair::from_seed(h.key_seed), SESSION_ID, log);
        h.wake_at = None;
    }

    /// Whether every live honest peer holds the same op set with nothing pending.
    fn agreed(&self) -> bool {
        let mut live = self.honest.iter().filter(|h| h.panicked.is_none());
        let Some(first) = live.next() else {
            return true;
        };
        let vv = first.peer.log().version_vector();
        first.peer.log().n_pending() == 0
            && live.all(|h| h.peer.log().n_pending() == 0 && h.peer.log().version_vector() == vv)
    }

    fn online(&self, node: usize) -> bool {
        self.honest.get(node).is_none_or(|h| h.offline_depth == 0)
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
            if let Some(h) = self.honest.get_mut(x) {
                // A refused connect (too many, id in use) leaves the pair unusable from this
                // side; honest runs never hit it, and the checkers would see the divergence.
                let _ = guarded(h, |p| p.connect(now, ConnId(y as u64)));
            }
        }
        let pair = self.pair(a, b);
        pair.connected = true;
        pair.epoch += 1;
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
                note_delivered(h, &insertion.delivered);
                let Honest { peer, scene, .. } = h;
                scene.apply_insertion(peer.log(), &insertion);
                if let ShapePayload::Create { object, .. } = payload
                    && !self.objects.contains(&object)
                {
                    self.objects.push(object);
                }
            }
            Some(Err(_)) | None => self.stats.n_author_errors += 1,
        }
        self.flush(peer);
    }

    /// Drains a peer's transmissions and events, then schedules its next wake-up.
    fn flush(&mut self, idx: usize) {
        let now = self.now;
        for _ in 0..MAX_DRAIN {
            let out = guarded(&mut self.honest[idx], |p| p.poll_transmit(Timestamp(now)));
            match out {
                Some(Some((conn, bytes))) => self.send(idx, conn, bytes),
                _ => break,
            }
        }
        for _ in 0..MAX_DRAIN {
            let ev = guarded(&mut self.honest[idx], |p| p.poll_event());
            match ev {
                Some(Some((conn, event))) => self.on_event(idx, conn, event),
                _ => break,
            }
        }
        let next = guarded(&mut self.honest[idx], |p| p.poll_timeout()).flatten();
        if let Some(t) = next {
            let at = t.0.max(now + 1);
            let h = &mut self.honest[idx];
            if h.wake_at.is_none_or(|w| at < w) {
                h.wake_at = Some(at);
                self.push(at, Ev::Wake { peer: idx });
            }
        }
    }

    fn on_event(&mut self, idx: usize, conn: ConnId, event: Event) {
        match event {
            Event::Delivered(insertion) => {
                self.trace.u64(10);
                for id in &insertion.delivered {
                    self.trace.bytes(&id.0);
                }
                if !insertion.delivered.is_empty() {
                    self.last_delivery_at = self.now;
                }
                let sabotage = self.config.sabotage;
                let h = &mut self.honest[idx];
                note_delivered(h, &insertion.delivered);
                h.n_received_insertions += 1;
                let skip = sabotage == Sabotage::DropEveryTenthInsertion
                    && idx == 0
                    && h.n_received_insertions.is_multiple_of(10);
                if !skip {
                    let Honest { peer, scene, .. } = h;
                    let log = peer.log();
                    let applied = panic::catch_unwind(AssertUnwindSafe(|| {
                        scene.apply_insertion(log, &insertion);
                    }));
                    if let Err(e) = applied {
                        h.panicked = Some(panic_text(e.as_ref()));
                    }
                }
            }
            Event::Rejected { kind, .. } => {
                self.trace.u64(11);
                if Some(conn.0 as usize) == self.hostile_idx() {
                    self.stats.n_hostile_rejects += 1;
                } else {
                    *self
                        .stats
                        .honest_rejects
                        .entry(format!("{kind:?}"))
                        .or_default() += 1;
                }
            }
            Event::Closed(_) => {
                self.trace.u64(12);
                // The transport closes both ends.
                let other = conn.0 as usize;
                if other < self.n_nodes() {
                    self.disconnect_pair(idx, other);
                }
            }
            Event::Connected { .. } | Event::Ephemeral { .. } | Event::UpToDate => {
                self.trace.u64(13);
            }
        }
    }

    /// Puts one honest message on the network.
    fn send(&mut self, from: usize, conn: ConnId, bytes: Vec<u8>) {
        let to = conn.0 as usize;
        if Some(to) == self.hostile_idx() {
            self.stats.n_messages_to_hostile += 1;
            if self.captured.len() < MAX_CAPTURED_MESSAGES {
                self.captured.push(bytes);
            } else {
                let slot = self.rng.index(MAX_CAPTURED_MESSAGES);
                self.captured[slot] = bytes;
            }
            return;
        }
        if to >= self.n_nodes() {
            return;
        }
        self.stats.n_messages += 1;
        self.stats.n_bytes += bytes.len() as u64;
        if self.blocked.contains_key(&(from, to)) {
            self.stats.n_partition_drops += 1;
            return;
        }
        let faults = self.config.faults;
        if self.rng.chance(faults.loss_per_mille) {
            self.stats.n_lost += 1;
            return;
        }
        let epoch = self.pair(from, to).epoch;
        let base = self.latency_micros[from][to];
        let at = self.now + base + self.rng.below(faults.jitter_micros + 1);
        self.n_in_flight += 1;
        if self.rng.chance(faults.dup_per_mille) {
            self.stats.n_duplicated += 1;
            self.n_in_flight += 1;
            let again = self.now + base + self.rng.below(2 * faults.jitter_micros + 1);
            self.push(
                again,
                Ev::Deliver {
                    from,
                    to,
                    epoch,
                    bytes: bytes.clone(),
                },
            );
        }
        self.push(
            at,
            Ev::Deliver {
                from,
                to,
                epoch,
                bytes,
            },
        );
    }

    fn deliver(&mut self, from: usize, to: usize, epoch: u64, bytes: &[u8]) {
        if from < self.honest.len() {
            self.n_in_flight -= 1;
        }
        let pair = *self.pair(from, to);
        if !pair.connected || pair.epoch != epoch || !self.online(to) || to >= self.honest.len() {
            self.stats.n_stale_drops += 1;
            return;
        }
        self.trace.u64(from as u64);
        self.trace.u64(to as u64);
        self.trace.bytes(bytes);
        self.stats.n_delivered += 1;
        let now = Timestamp(self.now);
        guarded(&mut self.honest[to], |p| {
            p.handle_input(now, ConnId(from as u64), bytes);
        });
        self.flush(to);
    }

    /// The hostile peer sends garbage, an oversized message or a replay to a random peer.
    fn hostile_send(&mut self) {
        let Some(h) = self.hostile_idx() else { return };
        let targets: Vec<usize> = (0..self.config.n_peers)
            .filter(|t| self.online(*t) && self.pair(*t, h).connected)
            .collect();
        if targets.is_empty() {
            return;
        }
        let to = targets[self.rng.index(targets.len())];
        let kind = if self.captured.is_empty() {
            self.rng.below(2)
        } else {
            self.rng.below(5)
        };
        let bytes = match kind {
            0 => {
                let mut b = vec![0u8; 1 + self.rng.index(512)];
                self.rng.fill(&mut b);
                b
            }
            1 => {
                let mut b = vec![1u8; MAX_MESSAGE_BYTES + 1 + self.rng.index(1024)];
                self.rng.fill(&mut b[1..64]);
                b
            }
            2 => self.captured[self.rng.index(self.captured.len())].clone(),
            3 => {
                let mut b = self.captured[self.rng.index(self.captured.len())].clone();
                let i = self.rng.index(b.len());
                if let Some(x) = b.get_mut(i) {
                    *x ^= 1 << self.rng.below(8);
                }
                b
            }
            _ => {
                let mut b = self.captured[self.rng.index(self.captured.len())].clone();
                let keep = self.rng.index(b.len());
                b.truncate(keep);
                b
            }
        };
        self.stats.n_hostile_messages += 1;
        let epoch = self.pair(h, to).epoch;
        let at = self.now + self.latency_micros[h][to];
        self.push(
            at,
            Ev::Deliver {
                from: h,
                to,
                epoch,
                bytes,
            },
        );
    }

    fn finish(self) -> Report {
        let mut failures = Vec::new();
        if self.timed_out {
            failures.push(format!(
                "no quiescence within {} s of virtual time after healing",
                QUIESCENCE_LIMIT_MICROS / 1_000_000
            ));
        }
        failures.extend(self.restart_failures.iter().cloned());
        let mut reference: Option<(usize, SceneHash)> = None;
        let all_authored: Vec<OpId> = self
            .honest
            .iter()
            .flat_map(|h| h.authored.iter().copied())
            .collect();
        for (i, h) in self.honest.iter().enumerate() {
            if let Some(p) = &h.panicked {
                failures.push(format!("peer {i} panicked: {p}"));
                continue;
            }
            if h.n_causal_violations > 0 {
                failures.push(format!(
                    "peer {i}: {} ops delivered before their dependencies",
                    h.n_causal_violations
                ));
            }
            let log = h.peer.log();
            if log.n_pending() > 0 {
                failures.push(format!("peer {i}: {} ops still pending", log.n_pending()));
            }
            let n_missing = all_authored.iter().filter(|id| !log.contains(id)).count();
            if n_missing > 0 {
                failures.push(format!("peer {i}: {n_missing} authored ops missing"));
            }
            let fresh = if self.config.sabotage == Sabotage::ReverseFold && i == 1 {
                Some(reversed_fold_hash(log))
            } else {
                Scene::fold(log).ok().map(|s| s.scene_hash())
            };
            let Some(fresh) = fresh else {
                failures.push(format!("peer {i}: its log does not fold"));
                continue;
            };
            if h.scene.scene_hash() != fresh {
                failures.push(format!(
                    "peer {i}: incremental scene {} differs from a fresh fold {}",
                    short_hash(&h.scene.scene_hash()),
                    short_hash(&fresh)
                ));
            }
            match reference {
                None => reference = Some((i, fresh)),
                Some((r, hash)) => {
                    let rlog = self.honest[r].peer.log();
                    if rlog.version_vector() != log.version_vector() {
                        failures.push(format!(
                            "peer {i}: version vector ({} ops) differs from peer {r}'s ({} ops)",
                            log.version_vector().n_ops(),
                            rlog.version_vector().n_ops()
                        ));
                    } else if !rlog.linear_ids().eq(log.linear_ids()) {
                        failures.push(format!("peer {i}: linear order differs from peer {r}'s"));
                    } else if !rlog
                        .entries()
                        .map(|e| e.active)
                        .eq(log.entries().map(|e| e.active))
                    {
                        failures.push(format!(
                            "peer {i}: lease/undo verdicts differ from peer {r}'s"
                        ));
                    }
                    if hash != fresh {
                        failures.push(format!(
                            "peer {i}: scene hash {} differs from peer {r}'s {}",
                            short_hash(&fresh),
                            short_hash(&hash)
                        ));
                    }
                }
            }
        }
        let mean_latency = mean_latency_micros(&self.latency_micros, self.config.n_peers);
        Report {
            config: self.config,
            n_log_ops: self.honest.first().map_or(0, |h| h.peer.log().len()),
            scene_hash: reference.map(|(_, h)| h),
            convergence_micros: self.last_delivery_at.saturating_sub(self.heal_at),
            mean_rtt_micros: 2 * mean_latency + self.config.faults.jitter_micros,
            virtual_end_micros: self.now - START_MICROS,
            trace_hash: self.trace.value(),
            stats: self.stats,
            failures,
        }
    }
}

/// Runs `config` to the end.
pub fn run(config: Config) -> Result<Report, ConfigError> {
    Ok(Simulation::new(config)?.run())
}

/// Records ops as delivered at a peer, checking that each one's deps came first.
fn note_delivered(h: &mut Honest, delivered: &[OpId]) {
    for id in delivered {
        if let Some(op) = h.peer.log().get(id) {
            let early = op.deps().iter().filter(|d| !h.seen.contains(&d.0)).count();
            h.n_causal_violations += early as u64;
        }
        h.seen.insert(id.0);
    }
}

/// Calls into a peer unless it already panicked; a panic is recorded, never propagated.
fn guarded<R>(h: &mut Honest, f: impl FnOnce(&mut Peer<ShapePayload>) -> R) -> Option<R> {
    if h.panicked.is_some() {
        return None;
    }
    match panic::catch_unwind(AssertUnwindSafe(|| f(&mut h.peer))) {
        Ok(r) => Some(r),
        Err(e) => {
            h.panicked = Some(panic_text(e.as_ref()));
            None
        }
    }
}

fn panic_text(e: &(dyn std::any::Any + Send)) -> String {
    e.downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| e.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "non-text panic".into())
}

/// The deliberately wrong fold of [`Sabotage::ReverseFold`]: active entries, last first.
fn reversed_fold_hash(log: &Log<ShapePayload>) -> SceneHash {
    let mut scene = ShapeScene::default();
    let entries: Vec<_> = log.entries().filter(|e| e.active).collect();
    for e in entries.iter().rev() {
        scene.apply(FoldEntry {
            key: OrderKey::of(e.op),
            op: e.op,
        });
    }
    scene.scene_hash()
}

fn mean_latency_micros(latency: &[Vec<u64>], n_honest: usize) -> u64 {
    let mut sum = 0u64;
    let mut n = 0u64;
    for (a, row) in latency.iter().enumerate().take(n_honest) {
        for (b, l) in row.iter().enumerate().take(n_honest) {
            if a != b {
                sum += l;
                n += 1;
            }
        }
    }
    sum.checked_div(n).unwrap_or(0)
}

/// The first 8 bytes of a scene hash in hex.
pub fn short_hash(h: &SceneHash) -> String {
    h.0[..8].iter().map(|b| format!("{b:02x}")).collect()
}
