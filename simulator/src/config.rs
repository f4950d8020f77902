//! What one simulation run is: seed, size, fault mix, hostile peer and (for testing the
//! checkers) a deliberate sabotage, plus the command line that replays it.

use std::fmt;

/// Fewest honest peers in a run.
pub const MIN_PEERS: usize = 2;
/// Most honest peers in a run (one connection slot of [`replication::peer::MAX_CONNECTIONS`]
/// is left for the hostile peer).
pub const MAX_PEERS: usize = 63;
/// Most user ops in a run.
pub const MAX_OPS: usize = 1_000_000;

/// The network's behaviour: latency, jitter, loss, duplication, partitions, peers offline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Faults {
    /// The preset's name (what `--faults` takes).
    pub name: &'static str,
    /// Mean one-way latency; each directed link draws its own from half to 1.5 times this.
    pub latency_micros: u64,
    /// Extra delay drawn uniformly from `0..=jitter_micros` per message (this reorders).
    pub jitter_micros: u64,
    /// Messages lost, per thousand.
    pub loss_per_mille: u64,
    /// Messages delivered twice, per thousand.
    pub dup_per_mille: u64,
    /// Whether partitions (some asymmetric) come and go during the workload.
    pub partitions: bool,
    /// Whether peers go offline (all connections dropped) and come back.
    pub offline: bool,
    /// Whether peers crash (losing connections, pending ops and their scene) and restart
    /// from their store.
    pub crashes: bool,
}

impl Faults {
    /// Every preset, mildest first.
    pub const PRESETS: [Faults; 4] = [
        Faults {
            name: "none",
            latency_micros: 20_000,
            jitter_micros: 0,
            loss_per_mille: 0,
            dup_per_mille: 0,
            partitions: false,
            offline: false,
            crashes: false,
        },
        Faults {
            name: "lan",
            latency_micros: 2_000,
            jitter_micros: 1_000,
            loss_per_mille: 10,
            dup_per_mille: 10,
            partitions: false,
            offline: false,
            crashes: false,
        },
        Faults {
            name: "wan",
            latency_micros: 40_000,
            jitter_micros: 30_000,
            loss_per_mille: 50,
            dup_per_mille: 20,
            partitions: true,
            offline: false,
            crashes: false,
        },
        Faults {
            name: "chaos",
            latency_micros: 60_000,
            jitter_micros: 50_000,
            loss_per_mille: 150,
            dup_per_mille: 50,
            partitions: true,
            offline: true,
            crashes: true,
        },
    ];

    /// The preset called `name`.
    pub fn named(name: &str) -> Option<Faults> {
        Self::PRESETS.iter().copied().find(|f| f.name == name)
    }
}

/// A deliberate bug planted in the harness, to show that the checkers catch it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sabotage {
    /// No bug.
    None,
    /// Peer 0's incremental scene skips every 10th insertion it receives from the network.
    DropEveryTenthInsertion,
    /// Peer 1's scene is folded in reverse linear order.
    ReverseFold,
}

impl Sabotage {
    /// The name `--sabotage` takes.
    pub fn name(self) -> &'static str {
        match self {
            Sabotage::None => "none",
            Sabotage::DropEveryTenthInsertion => "drop-insertions",
            Sabotage::ReverseFold => "reverse-fold",
        }
    }

    /// The sabotage called `name`.
    pub fn named(name: &str) -> Option<Sabotage> {
        [
            Sabotage::None,
            Sabotage::DropEveryTenthInsertion,
            Sabotage::ReverseFold,
        ]
        .into_iter()
        .find(|s| s.name() == name)
    }
}

/// One run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config {
    /// Seeds the one RNG everything draws from.
    pub seed: u64,
    /// Honest peers.
    pub n_peers: usize,
    /// User ops to author, over all peers.
    pub n_ops: usize,
    /// The network.
    pub faults: Faults,
    /// Whether a hostile peer sends malformed, oversized and replayed messages.
    pub hostile: bool,
    /// A planted bug (tests of the checkers only).
    pub sabotage: Sabotage,
}

/// Why a [`Config`] is not runnable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// Peers out of range.
    #[error("{0} peers: must be {MIN_PEERS}..={MAX_PEERS}")]
    Peers(usize),
    /// Too many ops.
    #[error("{0} ops: at most {MAX_OPS}")]
    Ops(usize),
}

impl Config {
    /// A run of `n_peers` peers and `n_ops` ops under `faults`, with the hostile peer.
    pub fn new(seed: u64, n_peers: usize, n_ops: usize, faults: Faults) -> Config {
        Config {
            seed,
            n_peers,
            n_ops,
            faults,
            hostile: true,
            sabotage: Sabotage::None,
        }
    }

    /// Checks the limits.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(MIN_PEERS..=MAX_PEERS).contains(&self.n_peers) {
            return Err(ConfigError::Peers(self.n_peers));
        }
        if self.n_ops > MAX_OPS {
            return Err(ConfigError::Ops(self.n_ops));
        }
        Ok(())
    }

    /// The command that replays this run exactly.
    pub fn replay_command(&self) -> String {
        self.to_string()
    }
}

impl fmt::Display for Config {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "cargo run -p simulator --release -- --seed {} --peers {} --ops {} --faults {}",
            self.seed, self.n_peers, self.n_ops, self.faults.name
        )?;
        if !self.hostile {
            write!(f, " --no-hostile")?;
        }
        if self.sabotage != Sabotage::None {
            write!(f, " --sabotage {}", self.sabotage.name())?;
        }
        Ok(())
    }
}
