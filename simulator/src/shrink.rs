//! Shrinking a failing run to a small reproducer by re-running it deterministically.
//!
//! A run is a pure function of its [`Config`], and the fault schedule is drawn from its own
//! stream of the seed with the same draws whatever is switched off (see [`crate::sim`]), so
//! a smaller config keeps the faults that remain where they were. The shrinker, within a
//! budget of runs, repeats until nothing changes:
//!
//! 1. switches off the hostile peer, then each [`FaultKind`] in turn;
//! 2. tries fewer peers, from [`MIN_PEERS`] up (actions of a removed peer go to `peer_draw %
//!    n_peers`);
//! 3. cuts the action list with delta debugging (ddmin by complements: remove one of `n`
//!    chunks; on success keep the rest and go coarser, else go finer).
//!
//! A candidate counts as failing only if one of its failures has the same *signature* as one
//! of the original's (the text with every token holding a digit replaced by `#`), so the
//! shrinker does not slide from one bug to another. The result prints as the command that
//! replays it (`--without`, `--actions`).

use crate::config::{Config, ConfigError, FaultKind, MIN_PEERS};
use crate::report::Report;
use crate::sim::run;

/// Runs the shrinker makes at most (by default).
pub const MAX_SHRINK_RUNS: usize = 400;
/// Rounds of the three steps at most.
const MAX_ROUNDS: usize = 4;

/// A shrunk reproducer.
#[derive(Debug, Clone)]
pub struct Shrunk {
    /// The smallest failing config found.
    pub config: Config,
    /// Its report (it fails).
    pub report: Report,
    /// Runs made, the original's included.
    pub n_runs: usize,
}

/// A failure with numbers and hashes blanked, to recognise the same bug in a smaller run.
pub fn signature(failure: &str) -> String {
    failure
        .split_whitespace()
        .map(|t| {
            if t.chars().any(|c| c.is_ascii_digit()) {
                "#"
            } else {
                t
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

struct Shrinker {
    signatures: Vec<String>,
    n_runs: usize,
    max_runs: usize,
    best: Config,
    best_report: Report,
}

impl Shrinker {
    /// Runs `candidate`; if it fails the same way, it becomes the best.
    fn try_config(&mut self, candidate: Config) -> bool {
        if self.n_runs >= self.max_runs || candidate.validate().is_err() {
            return false;
        }
        self.n_runs += 1;
        let Ok(report) = run(candidate.clone()) else {
            return false;
        };
        let same = report
            .failures
            .iter()
            .any(|f| self.signatures.contains(&signature(f)));
        if same {
            self.best = candidate;
            self.best_report = report;
        }
        same
    }

    fn faults_step(&mut self) -> bool {
        let mut changed = false;
        if self.best.hostile {
            let candidate = Config {
                hostile: false,
                ..self.best.clone()
            };
            changed |= self.try_config(candidate);
        }
        for kind in FaultKind::ALL {
            if self.best.effective_faults().has(kind) {
                let candidate = Config {
                    without: self.best.without.with(kind),
                    ..self.best.clone()
                };
                changed |= self.try_config(candidate);
            }
        }
        changed
    }

    fn peers_step(&mut self) -> bool {
        for n_peers in MIN_PEERS..self.best.n_peers {
            let candidate = Config {
                n_peers,
                ..self.best.clone()
            };
            if self.try_config(candidate) {
                return true;
            }
        }
        false
    }

    /// ddmin by complements over the kept actions.
    fn actions_step(&mut self) -> bool {
        let mut list = self.kept_actions();
        let start_len = list.len();
        let mut n = 2;
        while list.len() >= 2 && self.n_runs < self.max_runs {
            let chunk = list.len().div_ceil(n);
            let mut reduced = false;
            for i in 0..n {
                let (lo, hi) = (i * chunk, ((i + 1) * chunk).min(list.len()));
                if lo >= hi {
                    continue;
                }
                let complement: Vec<u32> = list[..lo].iter().chain(&list[hi..]).copied().collect();
                let candidate = Config {
                    actions: Some(complement.clone()),
                    ..self.best.clone()
                };
                if self.try_config(candidate) {
                    list = complement;
                    reduced = true;
                    break;
                }
            }
            if reduced {
                n = (n - 1).max(2);
                continue;
            }
            if n >= list.len() {
                break;
            }
            n = (2 * n).min(list.len());
        }
        // A single action may still be removable (ddmin stops at 2).
        if list.len() == 1 {
            let candidate = Config {
                actions: Some(Vec::new()),
                ..self.best.clone()
            };
            self.try_config(candidate);
        }
        self.kept_actions().len() < start_len
    }

    fn kept_actions(&self) -> Vec<u32> {
        match &self.best.actions {
            Some(a) => a.clone(),
            None => (0..self.best.n_ops as u32).collect(),
        }
    }
}

/// Shrinks `failing` within `max_runs` runs; `Ok(None)` if it does not fail.
pub fn shrink(failing: &Config, max_runs: usize) -> Result<Option<Shrunk>, ConfigError> {
    failing.validate()?;
    let report = run(failing.clone())?;
    if report.passed() {
        return Ok(None);
    }
    let mut s = Shrinker {
        signatures: report.failures.iter().map(|f| signature(f)).collect(),
        n_runs: 1,
        max_runs,
        best: failing.clone(),
        best_report: report,
    };
    for _ in 0..MAX_ROUNDS {
        let mut changed = s.faults_step();
        changed |= s.peers_step();
        changed |= s.actions_step();
        if !changed || s.n_runs >= s.max_runs {
            break;
        }
    }
    Ok(Some(Shrunk {
        config: s.best,
        report: s.best_report,
        n_runs: s.n_runs,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signatures_blank_numbers_and_hashes() {
        assert_eq!(
            signature("peer 3: incremental scene a791c464 differs from a fresh fold 0badf00d"),
            "peer # incremental scene # differs from a fresh fold #"
        );
        assert_eq!(
            signature("peer 1: 4 authored ops missing"),
            signature("peer 0: 9 authored ops missing")
        );
    }
}
