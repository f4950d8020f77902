//! What a run found: counters, convergence after healing, hashes, and the checkers' failures
//! with the command that replays them.

use std::fmt;

use replication::materialize::SceneHash;

use crate::config::Config;
use crate::sim::{Stats, short_hash};

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
    /// FNV-1a over every delivered message and event: equal for two runs of one seed.
    pub trace_hash: u64,
    /// What the checkers found; empty when the run passed.
    pub failures: Vec<String>,
}

impl Report {
    /// Whether every checker passed.
    pub fn passed(&self) -> bool {
        self.failures.is_empty()
    }

    /// Bytes honest peers sent each other per authored op.
    pub fn bytes_per_op(&self) -> f64 {
        self.stats.n_bytes as f64 / self.stats.n_ops_authored.max(1) as f64
    }

    /// Convergence time in mean round trips.
    pub fn convergence_round_trips(&self) -> f64 {
        self.convergence_micros as f64 / self.mean_rtt_micros.max(1) as f64
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.config;
        let s = &self.stats;
        writeln!(
            f,
            "seed {} | {} peers | {} ops | faults {} | hostile {} | sabotage {}",
            c.seed,
            c.n_peers,
            c.n_ops,
            c.faults.name,
            c.hostile,
            c.sabotage.name()
        )?;
        writeln!(
            f,
            "  ops authored {} (refused {}), log {} ops, scene {}",
            s.n_ops_authored,
            s.n_author_errors,
            self.n_log_ops,
            self.scene_hash.as_ref().map_or("-".into(), short_hash)
        )?;
        writeln!(
            f,
            "  convergence after healing: {:.1} virtual ms = {:.1} round trips (mean RTT {:.1} ms)",
            self.convergence_micros as f64 / 1e3,
            self.convergence_round_trips(),
            self.mean_rtt_micros as f64 / 1e3
        )?;
        writeln!(
            f,
            "  sent {} messages, {} bytes ({:.0} bytes/op); delivered {}, lost {}, duplicated {}, partitioned {}, stale {}",
            s.n_messages,
            s.n_bytes,
            self.bytes_per_op(),
            s.n_delivered,
            s.n_lost,
            s.n_duplicated,
            s.n_partition_drops,
            s.n_stale_drops
        )?;
        writeln!(
            f,
            "  hostile sent {}, rejected {}; honest peers sent it {}; rejects on honest links {:?}",
            s.n_hostile_messages, s.n_hostile_rejects, s.n_messages_to_hostile, s.honest_rejects
        )?;
        writeln!(
            f,
            "  crashes {}, virtual time {:.1} s, {} events, trace {:016x}",
            s.n_crashes,
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
