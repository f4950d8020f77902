//! What a run found: counters, convergence after healing, memory per peer, op sizes by kind,
//! samples over virtual time (for [`crate::plots`]), hashes, and the checkers' failures with
//! the command that replays them.

use std::collections::BTreeMap;
use std::fmt;

use replication::materialize::SceneHash;

use crate::config::Config;

/// One peer at one sample time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeerSample {
    /// Ops in its log.
    pub n_ops_held: u64,
    /// Messages it sent so far.
    pub n_messages_sent: u64,
    /// Bytes it sent so far.
    pub n_bytes_sent: u64,
    /// Heap bytes its calls hold (0 without the counting allocator).
    pub live_bytes: i64,
}

/// Every honest peer at one virtual time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Sample {
    /// Virtual µs since the start.
    pub at_micros: u64,
    /// Per honest peer.
    pub peers: Vec<PeerSample>,
}

/// Heap bytes held per peer, from [`crate::memory`] (sampled; the peak is over samples).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Memory {
    /// Largest peak of any peer.
    pub peak_bytes_max: i64,
    /// Mean over peers of their peak.
    pub peak_bytes_mean: f64,
    /// Mean over peers at the end.
    pub final_bytes_mean: f64,
    /// Largest ratio of a peer's peak to the ops it held at the end.
    pub peak_bytes_per_op_max: f64,
    /// Mean over peers of final bytes per op held.
    pub final_bytes_per_op_mean: f64,
}

/// Sizes of the ops of one kind in the final log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpKindBytes {
    /// The kind (what the user did).
    pub kind: &'static str,
    /// Ops of this kind.
    pub n_ops: u64,
    /// Their encoded bytes (header, deps, payload, signature).
    pub n_op_bytes: u64,
    /// Their payload bytes.
    pub n_payload_bytes: u64,
}

/// The outcome of one run.
#[derive(Debug, Clone)]
pub struct Report {
    /// The run.
    pub config: Config,
    /// Counters.
    pub stats: Stats,
    /// Ops in peer 0's log at the end.
    pub n_log_ops: usize,
    /// The common scene hash (peer 0's fresh fold).
    pub scene_hash: Option<SceneHash>,
    /// Virtual time from healing to the last op delivered anywhere.
    pub convergence_micros: u64,
    /// Mean round trip of an honest link (twice the mean base latency, plus the jitter range).
    pub mean_rtt_micros: u64,
    /// Virtual time the run lasted.
    pub virtual_end_micros: u64,
    /// Virtual time of healing (since the start).
    pub heal_micros: u64,
    /// FNV-1a over every delivered message and event: equal for two runs of one seed.
    pub trace_hash: u64,
    /// Samples over virtual time, for plots.
    pub samples: Vec<Sample>,
    /// Memory per peer, if the counting allocator is installed.
    pub memory: Option<Memory>,
    /// Op sizes by kind, in peer 0's final log.
    pub op_bytes: Vec<OpKindBytes>,
    /// Lease/undo verdicts compared with the reference rules (summed over peers checked).
    pub n_lease_verdicts_checked: usize,
    /// Ops the reference rules reject (in peer 0's log).
    pub n_lease_rejected: usize,
    /// Ops some peer synced to disk.
    pub n_durable_ops: usize,
    /// Own ops peers lost in crashes before syncing them (so never sent: gone for good).
    pub n_lost_own_ops: usize,
    /// The hostile member's own ops in peer 0's final log.
    pub n_hostile_ops_accepted: usize,
    /// Most messages of one flood an honest peer accepted (the rest were rate limited).
    pub n_flood_accepted_max: u64,
    /// Ops honest peers held back for their refold budget (summed over their final logs).
    pub n_refold_holds: u64,
    /// Ops of expelled members void on peer 0 at the end.
    pub n_void_ops: usize,
    /// The cap on bytes of ops, when the session binds its authors, and the bytes of ops in
    /// peer 0's final log ([`crate::session::SESSION_CAP_BYTES`]).
    pub session_bytes: Option<(u64, u64)>,
    /// How each honest peer caught up after healing, by index.
    pub catch_up: Vec<CatchUp>,
    /// What the checkers found; empty when the run passed.
    pub failures: Vec<String>,
}

/// How one honest peer caught up after healing: what its log held then, and when the ops it
/// lacked came (the slowest peer's last delivery is the convergence time).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CatchUp {
    /// Ops in its log at healing.
    pub n_held_at_heal: usize,
    /// Encoded bytes of the ops some honest peer held at healing and it lacked.
    pub n_bytes_lacked: u64,
    /// Ops delivered to it after healing.
    pub n_delivered: usize,
    /// Insertions that delivered them; the fields below mean something only when some did.
    pub n_insertions: usize,
    /// Its first delivery, in virtual microseconds after healing.
    pub first_micros: u64,
    /// Its last delivery, in virtual microseconds after healing.
    pub last_micros: u64,
    /// The node whose connection reported the last delivery: the sender of the message that
    /// caused it (ops released by the clock are reported on the peer's first connection).
    pub last_from: u64,
}

/// Counters a run reports.
#[derive(Debug, Default, Clone)]
pub struct Stats {
    /// Ops the users authored (the hot object's creation included).
    pub n_ops_authored: u64,
    /// Ops the core refused to author.
    pub n_author_errors: u64,
    /// Why, by error.
    pub author_errors: BTreeMap<String, u64>,
    /// Actions of peers that had not joined yet (skipped).
    pub n_actions_skipped: u64,
    /// Messages honest peers sent to honest peers.
    pub n_messages: u64,
    /// Bytes honest peers sent to honest peers.
    pub n_bytes: u64,
    /// Of those, messages and bytes by kind ([`replication::sync::message::kind_of`]; tags
    /// no message has count as "unknown").
    pub bytes_by_kind: BTreeMap<&'static str, (u64, u64)>,
    /// Messages honest peers sent to the hostile peer.
    pub n_messages_to_hostile: u64,
    /// Messages handed to an honest peer.
    pub n_delivered: u64,
    /// Messages lost at random.
    pub n_lost: u64,
    /// Extra copies made.
    pub n_duplicated: u64,
    /// Messages dropped by a partition.
    pub n_partition_drops: u64,
    /// Messages a partition stalled on a stream connection.
    pub n_stalled: u64,
    /// Losses on stream connections, each made good after a loss detection time.
    pub n_retransmitted: u64,
    /// Messages on a stream connection delivered before one sent earlier on it, which a loss
    /// held up (each message is a stream of its own).
    pub n_overtaking: u64,
    /// Dials to replace a stalled stream connection ([`replication::sync::state::Event::Stalled`]).
    pub n_stall_redials: u64,
    /// Stalled stream connections such a dial replaced.
    pub n_stalls_replaced: u64,
    /// Dials of a pair whose stream connection was closed (or never opened) that found both
    /// links open, each admitted 1.5 round trips later at the acceptor and 2 at the dialer.
    pub n_dials: u64,
    /// Rounds of dials a peer made at once on hearing a remote after a silence
    /// ([`replication::sync::state::Event::Resumed`]).
    pub n_resumed_rounds: u64,
    /// Messages dropped because their link's queue was full (bandwidth).
    pub n_queue_drops: u64,
    /// Messages that arrived after their connection was gone.
    pub n_stale_drops: u64,
    /// Messages the hostile peer sent (floods included).
    pub n_hostile_messages: u64,
    /// Forged ops (signature not matching the claimed author) the hostile peer sent.
    pub n_forged_ops: u64,
    /// Well-formed ops the hostile peer authored under its own key.
    pub n_hostile_ops: u64,
    /// Flood messages delivered to an honest peer.
    pub n_flood_delivered: u64,
    /// Flood messages an honest peer accepted (not rate limited).
    pub n_flood_accepted: u64,
    /// Rejections honest peers reported about honest connections, by kind.
    pub honest_rejects: BTreeMap<String, u64>,
    /// Rejections honest peers reported about the hostile connection, by kind.
    pub hostile_rejects: BTreeMap<String, u64>,
    /// Rejections honest peers reported about the hostile connection.
    pub n_hostile_rejects: u64,
    /// Events handled.
    pub n_events: u64,
    /// Crashes and restarts.
    pub n_crashes: u64,
    /// Fsyncs completed.
    pub n_fsyncs: u64,
    /// Ops appended but lost in crashes (not synced); the crashed peer's own among them are
    /// gone for good, the others come back from their authors.
    pub n_lost_unsynced: u64,
    /// Crashes that left a torn record for recovery to cut.
    pub n_torn_tails: u64,
    /// Peers that joined late with an empty log.
    pub n_late_joins: u64,
    /// Peers that joined late from a snapshot.
    pub n_snapshot_joins: u64,
    /// Planted snapshots the joiner's check refused (the joiner then synced op by op).
    pub n_snapshots_refused: u64,
    /// The byzantine member's crafted attacks sent, by kind.
    pub byzantine: BTreeMap<&'static str, u64>,
    /// Expels of the hostile member the founder (peer 0) authored.
    pub n_expels: u64,
    /// Connections honest peers closed because the founder expelled their remote.
    pub n_expel_closes: u64,
    /// Forks honest peers learnt (a proof came, or an op forked a held one).
    pub n_forks_learnt: u64,
}

/// The first 8 bytes of a scene hash in hex.
pub fn short_hash(h: &SceneHash) -> String {
    h.0[..8].iter().map(|b| format!("{b:02x}")).collect()
}

/// Peers named in the report's line on catching up, slowest first.
const N_SLOWEST_SHOWN: usize = 3;

impl Report {
    /// Whether every checker passed.
    pub fn passed(&self) -> bool {
        self.failures.is_empty()
    }

    /// Bytes honest peers sent each other per authored op.
    pub fn bytes_per_op(&self) -> f64 {
        self.stats.n_bytes as f64 / self.stats.n_ops_authored.max(1) as f64
    }

    /// Messages honest peers sent each other per authored op.
    pub fn messages_per_op(&self) -> f64 {
        self.stats.n_messages as f64 / self.stats.n_ops_authored.max(1) as f64
    }

    /// Convergence time in mean round trips.
    pub fn convergence_round_trips(&self) -> f64 {
        self.convergence_micros as f64 / self.mean_rtt_micros.max(1) as f64
    }

    /// When an honest peer had caught up after healing (its last delivery, or healing itself
    /// for a peer that lacked nothing), in mean round trips, averaged over the honest peers.
    /// The convergence time is the slowest peer's, a maximum: this mean moves far less from
    /// seed to seed, so a change to the sync shows in fewer runs.
    pub fn mean_catch_up_round_trips(&self) -> f64 {
        let total: f64 = (self.catch_up.iter())
            .filter(|c| c.n_insertions > 0)
            .map(|c| c.last_micros as f64)
            .sum();
        total / self.catch_up.len().max(1) as f64 / self.mean_rtt_micros.max(1) as f64
    }

    /// The bandwidth bound after healing, as issue 53 states it: the most op bytes an honest
    /// peer lacked, over one link's rate (what must cross the link it syncs them over); None
    /// on links without a rate.
    pub fn bandwidth_bound_micros(&self) -> Option<u64> {
        let rate = self.config.effective_faults().bandwidth_bytes_per_sec;
        let most = self.catch_up.iter().map(|c| c.n_bytes_lacked).max()?;
        (rate > 0).then(|| most.saturating_mul(1_000_000) / rate)
    }

    /// Convergence after healing over issue 53's goal for it: 1.5 times the bandwidth bound
    /// plus 3 round trips (at most 1 meets it).
    pub fn convergence_over_goal(&self) -> Option<f64> {
        let goal = 1.5 * self.bandwidth_bound_micros()? as f64 + 3.0 * self.mean_rtt_micros as f64;
        Some(self.convergence_micros as f64 / goal.max(1.0))
    }

    fn fmt_traffic(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = &self.stats;
        writeln!(
            f,
            "  convergence after healing: {:.1} virtual ms = {:.1} round trips (mean RTT {:.1} ms); \
             a peer caught up after {:.2} round trips on average",
            self.convergence_micros as f64 / 1e3,
            self.convergence_round_trips(),
            self.mean_rtt_micros as f64 / 1e3,
            self.mean_catch_up_round_trips()
        )?;
        if let (Some(bound), Some(ratio)) =
            (self.bandwidth_bound_micros(), self.convergence_over_goal())
        {
            let most = self
                .catch_up
                .iter()
                .map(|c| c.n_bytes_lacked)
                .max()
                .unwrap_or(0);
            writeln!(
                f,
                "  bandwidth bound after healing: {:.1} virtual ms ({most} op bytes lacked by one \
                 peer at most); convergence is {ratio:.2} of 1.5 bounds plus 3 round trips",
                bound as f64 / 1e3,
            )?;
        }
        writeln!(
            f,
            "  sent {} messages ({:.1}/op), {} bytes ({:.0} bytes/op); delivered {}, lost {}, \
             duplicated {}, partitioned {}, queue-dropped {}, stale {}; as streams: \
             retransmitted {} (overtaken {}), stalled {}, stall redials {} ({} replaced), \
             dials {} ({} rounds on a sign of the network's return)",
            s.n_messages,
            self.messages_per_op(),
            s.n_bytes,
            self.bytes_per_op(),
            s.n_delivered,
            s.n_lost,
            s.n_duplicated,
            s.n_partition_drops,
            s.n_queue_drops,
            s.n_stale_drops,
            s.n_retransmitted,
            s.n_overtaking,
            s.n_stalled,
            s.n_stall_redials,
            s.n_stalls_replaced,
            s.n_dials,
            s.n_resumed_rounds
        )?;
        self.fmt_slowest(f)?;
        let mut kinds: Vec<_> = s.bytes_by_kind.iter().collect();
        kinds.sort_by_key(|(kind, (_, n_bytes))| (std::cmp::Reverse(*n_bytes), *kind));
        let kinds: Vec<String> = (kinds.iter())
            .map(|(kind, (n, n_bytes))| {
                let share = 100.0 * *n_bytes as f64 / s.n_bytes.max(1) as f64;
                format!("{kind} {share:.1}% ({n} messages)")
            })
            .collect();
        writeln!(f, "  bytes by message kind: {}", kinds.join(", "))?;
        self.fmt_hostile(f)
    }

    /// The peers slowest to catch up after healing.
    fn fmt_slowest(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut slowest: Vec<(usize, &CatchUp)> = (self.catch_up.iter().enumerate())
            .filter(|(_, c)| c.n_insertions > 0)
            .collect();
        slowest.sort_by_key(|(i, c)| (std::cmp::Reverse(c.last_micros), *i));
        if !slowest.is_empty() {
            let shown: Vec<String> = (slowest.iter().take(N_SLOWEST_SHOWN))
                .map(|(i, c)| {
                    format!(
                        "peer {i} got {} ops in {} insertions, {:.1} to {:.1} ms from node {}",
                        c.n_delivered,
                        c.n_insertions,
                        c.first_micros as f64 / 1e3,
                        c.last_micros as f64 / 1e3,
                        c.last_from
                    )
                })
                .collect();
            writeln!(
                f,
                "  slowest to catch up after healing: {}",
                shown.join("; ")
            )?;
        }
        Ok(())
    }

    /// What the hostile member sent and what came of it.
    fn fmt_hostile(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = &self.stats;
        writeln!(
            f,
            "  hostile sent {} (forged ops {}, own ops {} of which {} accepted, flood {} \
             delivered / {} accepted), rejected {:?}; honest peers sent it {}; rejects on \
             honest links {:?}",
            s.n_hostile_messages,
            s.n_forged_ops,
            s.n_hostile_ops,
            self.n_hostile_ops_accepted,
            s.n_flood_delivered,
            s.n_flood_accepted,
            s.hostile_rejects,
            s.n_messages_to_hostile,
            s.honest_rejects
        )?;
        if !s.byzantine.is_empty() {
            writeln!(
                f,
                "  byzantine attacks sent: {:?}; ops held for the refold budget {}; \
                 expels {}, void ops {}, connections closed by expels {}; forks learnt by \
                 honest peers {}",
                s.byzantine,
                self.n_refold_holds,
                s.n_expels,
                self.n_void_ops,
                s.n_expel_closes,
                s.n_forks_learnt
            )?;
        }
        if let Some((cap, n_bytes)) = self.session_bytes {
            writeln!(
                f,
                "  the session binds its authors: peer 0 holds {n_bytes} bytes of ops of the \
                 cap's {cap}"
            )?;
        }
        Ok(())
    }

    fn fmt_sizes(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.memory {
            Some(m) => writeln!(
                f,
                "  memory per peer: peak max {:.1} KiB, peak mean {:.1} KiB, final mean {:.1} \
                 KiB ({:.0} bytes/op held; peak max {:.0} bytes/op)",
                m.peak_bytes_max as f64 / 1024.0,
                m.peak_bytes_mean / 1024.0,
                m.final_bytes_mean / 1024.0,
                m.final_bytes_per_op_mean,
                m.peak_bytes_per_op_max
            )?,
            None => writeln!(f, "  memory per peer: not measured (no counting allocator)")?,
        }
        write!(
            f,
            "  op bytes by kind (n, mean op bytes, mean payload bytes):"
        )?;
        for k in &self.op_bytes {
            let n = k.n_ops.max(1) as f64;
            write!(
                f,
                " {} {} {:.0} {:.0};",
                k.kind,
                k.n_ops,
                k.n_op_bytes as f64 / n,
                k.n_payload_bytes as f64 / n
            )?;
        }
        writeln!(f)
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.config;
        let s = &self.stats;
        writeln!(
            f,
            "seed {} | {} peers | {} actions of {} | faults {} | hostile {} | sabotage {}",
            c.seed,
            c.n_peers,
            c.n_actions(),
            c.n_ops,
            c.faults.name,
            c.hostile,
            c.sabotage.name()
        )?;
        writeln!(
            f,
            "  ops authored {} (refused {} {:?}, skipped {}), log {} ops, scene {}; lease \
             verdicts checked {} ({} rejected by the rules)",
            s.n_ops_authored,
            s.n_author_errors,
            s.author_errors,
            s.n_actions_skipped,
            self.n_log_ops,
            self.scene_hash.as_ref().map_or("-".into(), short_hash),
            self.n_lease_verdicts_checked,
            self.n_lease_rejected
        )?;
        self.fmt_traffic(f)?;
        writeln!(
            f,
            "  crashes {} (lost unsynced ops {}, {} of them own, torn tails cut {}), fsyncs {}, \
             durable ops {}, late joins {} + {} from snapshots ({} planted snapshots refused)",
            s.n_crashes,
            s.n_lost_unsynced,
            self.n_lost_own_ops,
            s.n_torn_tails,
            s.n_fsyncs,
            self.n_durable_ops,
            s.n_late_joins,
            s.n_snapshot_joins,
            s.n_snapshots_refused
        )?;
        self.fmt_sizes(f)?;
        writeln!(
            f,
            "  virtual time {:.1} s, {} events, trace {:016x}",
            self.virtual_end_micros as f64 / 1e6,
            s.n_events,
            self.trace_hash
        )?;
        if self.passed() {
            write!(f, "  PASS")
        } else {
            writeln!(f, "  FAIL:")?;
            for failure in &self.failures {
                writeln!(f, "    {failure}")?;
            }
            write!(f, "  replay: {}", c.replay_command())
        }
    }
}
