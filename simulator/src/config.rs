//! What one simulation run is: seed, size, fault mix, hostile peer and (for testing the
//! checkers) a deliberate sabotage, plus the command line that replays it. A shrunk run also
//! names the fault kinds it switched off and the workload actions it kept.

use std::fmt;

use crate::rng::SimRng;

/// Fewest honest peers in a run.
pub const MIN_PEERS: usize = 2;
/// Most honest peers in a run (one connection slot of [`replication::peer::MAX_CONNECTIONS`]
/// is left for the hostile peer).
pub const MAX_PEERS: usize = 63;
/// Most user ops in a run.
pub const MAX_OPS: usize = 1_000_000;
/// The stream of the seed that draws a `swarm` run's fault mix.
const SWARM_STREAM: u64 = 77;

/// The network's and the peers' misbehaviour: latency, jitter, loss, duplication,
/// bandwidth, partitions, peers offline, crashes, late joins and the hostile peer's tricks.
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
    /// Bytes per second each directed link carries (0: unlimited); messages queue behind
    /// each other and are dropped when the queue holds more than
    /// [`crate::sim::MAX_LINK_QUEUE_MICROS`] of traffic.
    pub bandwidth_bytes_per_sec: u64,
    /// Whether partitions (some asymmetric) come and go during the workload.
    pub partitions: bool,
    /// Whether peers go offline (all connections dropped) and come back.
    pub offline: bool,
    /// Whether peers crash (losing connections, pending ops, their scene and every op not
    /// yet synced to disk, possibly leaving a torn record) and restart from their store.
    pub crashes: bool,
    /// Whether some peers start late, with an empty log or from a snapshot.
    pub late_joins: bool,
    /// Whether the hostile peer forges ops (bad signatures) and authors well-formed ops of
    /// its own (it is a member: it knows the invite).
    pub forgery: bool,
    /// Whether the hostile peer floods a peer with messages far over the rate limit.
    pub flood: bool,
    /// Whether the hostile member runs the real core and sends crafted ops and messages
    /// ([`crate::byzantine`]): backdated and far-past or far-future ops, Sybil keys, giant
    /// version vectors, oversized batches and cost bombs within the limits.
    pub byzantine: bool,
    /// Whether it also hoards leases: strong acquires with `ttl u64::MAX`, some backdated to
    /// Lamport 1 under fresh keys.
    pub lease_attacks: bool,
    /// Whether it also equivocates: two ops under one key with one sequence number.
    pub forks: bool,
    /// Whether peer 0 founded the session and expels the hostile member's key late in the
    /// run ([`replication::membership`]), while the member forges expels of honest peers.
    pub expel: bool,
    /// Whether connections behave as the product's QUIC ones do (`crate::sim`'s stream
    /// model): a loss is a retransmission after a loss detection time, not a lost message;
    /// no duplicates; each message on a stream of its own, so a loss delays only its message;
    /// a partition stalls the connection, closing it if it outlasts the idle timeout. Off: every message is a datagram of its own, lost,
    /// duplicated and reordered independently (the old model, kept as a stress case).
    pub streams: bool,
    /// Whether the last third of the workload runs in one partition between the two halves
    /// of the honest peers, lifted at healing: each half then lacks a third of the work's
    /// ops from the other, a backlog of many round trips at the links' rate (issue 53's
    /// bandwidth-bound goal). It stays when the random partitions are switched off.
    pub backlog: bool,
}

/// One kind of fault, as `--without` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum FaultKind {
    /// Jitter (and so reordering).
    Jitter,
    /// Random loss.
    Loss,
    /// Duplicates.
    Duplication,
    /// Bandwidth limits.
    Bandwidth,
    /// Partitions.
    Partitions,
    /// Peers offline.
    Offline,
    /// Crashes and restarts.
    Crashes,
    /// Late joins.
    LateJoins,
    /// Forged and hostile-authored ops.
    Forgery,
    /// Floods.
    Flood,
    /// Crafted ops and messages of a hostile member running the core.
    Byzantine,
    /// Lease hoarding, backdated or not.
    LeaseAttacks,
    /// Equivocation (forks).
    Forks,
    /// The founder expelling the hostile member, and the member forging expels.
    Expel,
}

impl FaultKind {
    /// Every kind, in the order the shrinker tries switching them off.
    pub const ALL: [FaultKind; 14] = [
        FaultKind::Crashes,
        FaultKind::LateJoins,
        FaultKind::Partitions,
        FaultKind::Offline,
        FaultKind::Forgery,
        FaultKind::Flood,
        FaultKind::Bandwidth,
        FaultKind::Loss,
        FaultKind::Duplication,
        FaultKind::Jitter,
        // Last, so `swarm`'s draws for the kinds above do not move.
        FaultKind::Forks,
        FaultKind::LeaseAttacks,
        FaultKind::Byzantine,
        FaultKind::Expel,
    ];

    /// The name `--without` takes.
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::Jitter => "jitter",
            FaultKind::Loss => "loss",
            FaultKind::Duplication => "dup",
            FaultKind::Bandwidth => "bandwidth",
            FaultKind::Partitions => "partitions",
            FaultKind::Offline => "offline",
            FaultKind::Crashes => "crashes",
            FaultKind::LateJoins => "late-joins",
            FaultKind::Forgery => "forgery",
            FaultKind::Flood => "flood",
            FaultKind::Byzantine => "byzantine",
            FaultKind::LeaseAttacks => "lease-attacks",
            FaultKind::Forks => "forks",
            FaultKind::Expel => "expel",
        }
    }

    /// The kind called `name`.
    pub fn named(name: &str) -> Option<FaultKind> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    fn bit(self) -> u32 {
        1 << (self as u32)
    }
}

/// A set of [`FaultKind`]s (what a run switched off).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultSet(u32);

impl FaultSet {
    /// True if `kind` is in the set.
    pub fn contains(self, kind: FaultKind) -> bool {
        self.0 & kind.bit() != 0
    }

    /// The set with `kind` added.
    pub fn with(self, kind: FaultKind) -> FaultSet {
        FaultSet(self.0 | kind.bit())
    }

    /// True if empty.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The kinds in the set.
    pub fn iter(self) -> impl Iterator<Item = FaultKind> {
        FaultKind::ALL
            .into_iter()
            .filter(move |k| self.contains(*k))
    }
}

/// Everything at once: slow, jittery, lossy links, partitions, peers offline, crashes,
/// late joins, forgery and floods.
const CHAOS: Faults = Faults {
    name: "chaos",
    latency_micros: 60_000,
    jitter_micros: 50_000,
    loss_per_mille: 150,
    dup_per_mille: 50,
    bandwidth_bytes_per_sec: 250_000,
    partitions: true,
    offline: true,
    crashes: true,
    late_joins: true,
    forgery: true,
    flood: true,
    byzantine: false,
    lease_attacks: false,
    forks: false,
    expel: false,
    streams: false,
    backlog: false,
};

/// Chaos plus every hostile-member attack that replication is meant to withstand today
/// (issue 17): crafted ops, Sybil keys, giant version vectors, cost bombs, lease hoarding.
const BYZANTINE: Faults = Faults {
    name: "byzantine",
    byzantine: true,
    lease_attacks: true,
    expel: true,
    ..CHAOS
};

impl Faults {
    /// Every preset, mildest first (`swarm` draws a mix per seed from `chaos`;
    /// `byzantine-forks` is `byzantine` with equivocation; `quic` is `chaos` over stream
    /// connections, and `quic-backlog` that with a long partition before healing).
    pub const PRESETS: [Faults; 9] = [
        Faults {
            name: "none",
            latency_micros: 20_000,
            jitter_micros: 0,
            loss_per_mille: 0,
            dup_per_mille: 0,
            bandwidth_bytes_per_sec: 0,
            partitions: false,
            offline: false,
            crashes: false,
            late_joins: false,
            forgery: false,
            flood: false,
            byzantine: false,
            lease_attacks: false,
            forks: false,
            expel: false,
            streams: false,
            backlog: false,
        },
        Faults {
            name: "lan",
            latency_micros: 2_000,
            jitter_micros: 1_000,
            loss_per_mille: 10,
            dup_per_mille: 10,
            bandwidth_bytes_per_sec: 12_500_000,
            partitions: false,
            offline: false,
            crashes: false,
            late_joins: false,
            forgery: true,
            flood: true,
            byzantine: false,
            lease_attacks: false,
            forks: false,
            expel: false,
            streams: false,
            backlog: false,
        },
        Faults {
            name: "wan",
            latency_micros: 40_000,
            jitter_micros: 30_000,
            loss_per_mille: 50,
            dup_per_mille: 20,
            bandwidth_bytes_per_sec: 1_000_000,
            partitions: true,
            offline: false,
            crashes: false,
            late_joins: true,
            forgery: true,
            flood: true,
            byzantine: false,
            lease_attacks: false,
            forks: false,
            expel: false,
            streams: false,
            backlog: false,
        },
        CHAOS,
        // A mix of chaos's fault kinds drawn per seed (see `Config::effective_faults`).
        Faults {
            name: "swarm",
            ..CHAOS
        },
        BYZANTINE,
        Faults {
            name: "byzantine-forks",
            forks: true,
            ..BYZANTINE
        },
        // Chaos over connections as the product's transport gives them: its losses are
        // delays.
        Faults {
            name: "quic",
            streams: true,
            ..CHAOS
        },
        // `quic` with a large backlog at healing: the last third of the work split in two.
        Faults {
            name: "quic-backlog",
            streams: true,
            backlog: true,
            ..CHAOS
        },
    ];

    /// The preset called `name`.
    pub fn named(name: &str) -> Option<Faults> {
        Self::PRESETS.iter().copied().find(|f| f.name == name)
    }

    /// These faults with `kind` switched off.
    pub fn without(mut self, kind: FaultKind) -> Faults {
        match kind {
            FaultKind::Jitter => self.jitter_micros = 0,
            FaultKind::Loss => self.loss_per_mille = 0,
            FaultKind::Duplication => self.dup_per_mille = 0,
            FaultKind::Bandwidth => self.bandwidth_bytes_per_sec = 0,
            FaultKind::Partitions => self.partitions = false,
            FaultKind::Offline => self.offline = false,
            FaultKind::Crashes => self.crashes = false,
            FaultKind::LateJoins => self.late_joins = false,
            FaultKind::Forgery => self.forgery = false,
            FaultKind::Flood => self.flood = false,
            FaultKind::Byzantine => self.byzantine = false,
            FaultKind::LeaseAttacks => self.lease_attacks = false,
            FaultKind::Forks => self.forks = false,
            FaultKind::Expel => self.expel = false,
        }
        self
    }

    /// True if `kind` is on.
    pub fn has(&self, kind: FaultKind) -> bool {
        self.without(kind) != *self
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
    /// The checkers read peer 0's first lease-rejected op as effective.
    FlipLeaseVerdict,
    /// Peers send before what they appended is synced (breaking the store rule).
    SendUnsynced,
}

impl Sabotage {
    /// Every sabotage.
    pub const ALL: [Sabotage; 5] = [
        Sabotage::None,
        Sabotage::DropEveryTenthInsertion,
        Sabotage::ReverseFold,
        Sabotage::FlipLeaseVerdict,
        Sabotage::SendUnsynced,
    ];

    /// The name `--sabotage` takes.
    pub fn name(self) -> &'static str {
        match self {
            Sabotage::None => "none",
            Sabotage::DropEveryTenthInsertion => "drop-insertions",
            Sabotage::ReverseFold => "reverse-fold",
            Sabotage::FlipLeaseVerdict => "flip-lease",
            Sabotage::SendUnsynced => "send-unsynced",
        }
    }

    /// The sabotage called `name`.
    pub fn named(name: &str) -> Option<Sabotage> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// One run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Config {
    /// Seeds the run's RNG streams (keys, workload, fault schedule, network).
    pub seed: u64,
    /// Honest peers.
    pub n_peers: usize,
    /// User actions the workload draws (over all peers); each authors one op.
    pub n_ops: usize,
    /// The fault preset.
    pub faults: Faults,
    /// Fault kinds switched off (by `--without` or the shrinker).
    pub without: FaultSet,
    /// Whether a hostile peer sends malformed, oversized, replayed, forged and flooding
    /// messages.
    pub hostile: bool,
    /// A planted bug (tests of the checkers only).
    pub sabotage: Sabotage,
    /// The indices of the workload's actions that run, ascending (`None`: all of them).
    pub actions: Option<Vec<u32>>,
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
    /// An action index out of range or out of order.
    #[error("action list: index {0} out of range or not ascending")]
    Actions(u32),
}

impl Config {
    /// A run of `n_peers` peers and `n_ops` ops under `faults`, with the hostile peer.
    pub fn new(seed: u64, n_peers: usize, n_ops: usize, faults: Faults) -> Config {
        Config {
            seed,
            n_peers,
            n_ops,
            faults,
            without: FaultSet::default(),
            hostile: true,
            sabotage: Sabotage::None,
            actions: None,
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
        if let Some(actions) = &self.actions {
            let mut last = None;
            for &a in actions {
                if a as usize >= self.n_ops || last.is_some_and(|l| l >= a) {
                    return Err(ConfigError::Actions(a));
                }
                last = Some(a);
            }
        }
        Ok(())
    }

    /// The faults in force: the preset (for `swarm`, a mix drawn from the seed) less
    /// [`Config::without`].
    pub fn effective_faults(&self) -> Faults {
        let mut faults = self.faults;
        if faults.name == "swarm" {
            let mut rng = SimRng::stream(self.seed, SWARM_STREAM);
            for kind in FaultKind::ALL {
                if rng.chance(400) {
                    faults = faults.without(kind);
                }
            }
        }
        self.without.iter().fold(faults, Faults::without)
    }

    /// Number of actions that run.
    pub fn n_actions(&self) -> usize {
        self.actions.as_ref().map_or(self.n_ops, Vec::len)
    }

    /// The command that replays this run exactly.
    pub fn replay_command(&self) -> String {
        self.to_string()
    }
}

/// Writes ascending indices compactly: `0-3,7,9-12`.
pub fn format_ranges(indices: &[u32]) -> String {
    let mut out = String::new();
    let mut i = 0;
    while i < indices.len() {
        let start = indices[i];
        let mut end = start;
        while i + 1 < indices.len() && indices[i + 1] == end + 1 {
            i += 1;
            end += 1;
        }
        if !out.is_empty() {
            out.push(',');
        }
        if end == start {
            out.push_str(&start.to_string());
        } else {
            out.push_str(&format!("{start}-{end}"));
        }
        i += 1;
    }
    out
}

/// Reads [`format_ranges`]' output (at most `limit` indices).
pub fn parse_ranges(text: &str, limit: usize) -> Result<Vec<u32>, String> {
    let mut out = Vec::new();
    for part in text.split(',').filter(|p| !p.is_empty()) {
        let number = |s: &str| s.parse::<u32>().map_err(|e| format!("{s}: {e}"));
        let (lo, hi) = match part.split_once('-') {
            Some((lo, hi)) => (number(lo)?, number(hi)?),
            None => (number(part)?, number(part)?),
        };
        if hi < lo || out.len() + (hi - lo) as usize >= limit {
            return Err(format!("bad or too long range {part}"));
        }
        out.extend(lo..=hi);
    }
    Ok(out)
}

impl fmt::Display for Config {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "cargo run -p simulator --release -- --seed {} --peers {} --ops {} --faults {}",
            self.seed, self.n_peers, self.n_ops, self.faults.name
        )?;
        if !self.without.is_empty() {
            let names: Vec<_> = self.without.iter().map(FaultKind::name).collect();
            write!(f, " --without {}", names.join(","))?;
        }
        if !self.hostile {
            write!(f, " --no-hostile")?;
        }
        if self.sabotage != Sabotage::None {
            write!(f, " --sabotage {}", self.sabotage.name())?;
        }
        if let Some(actions) = &self.actions {
            write!(f, " --actions '{}'", format_ranges(actions))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_round_trip_and_faults_switch_off() {
        let xs = vec![0, 1, 2, 3, 7, 9, 10];
        assert_eq!(format_ranges(&xs), "0-3,7,9-10");
        assert_eq!(parse_ranges("0-3,7,9-10", 100).unwrap(), xs);
        assert!(parse_ranges("5-2", 100).is_err());
        assert!(parse_ranges("0-1000", 100).is_err());
        assert_eq!(parse_ranges("", 100).unwrap(), Vec::<u32>::new());
        let chaos = Faults::named("chaos").unwrap();
        let all = Faults::named("byzantine-forks").unwrap();
        for kind in FaultKind::ALL {
            assert!(all.has(kind), "{kind:?}");
            assert!(!all.without(kind).has(kind), "{kind:?}");
            assert_eq!(FaultKind::named(kind.name()), Some(kind));
        }
        let config = Config {
            without: FaultSet::default().with(FaultKind::Crashes),
            actions: Some(vec![1, 2, 5]),
            ..Config::new(3, 2, 10, chaos)
        };
        assert!(!config.effective_faults().crashes);
        assert!(config.validate().is_ok());
        assert!(
            config
                .to_string()
                .ends_with("--without crashes --actions '1-2,5'")
        );
        let swarm = |seed| Config::new(seed, 2, 10, Faults::named("swarm").unwrap());
        let mixes: std::collections::BTreeSet<_> = (0..20)
            .map(|s| format!("{:?}", swarm(s).effective_faults()))
            .collect();
        assert!(mixes.len() > 5, "{mixes:?}");
    }
}
