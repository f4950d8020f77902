//! The `simulator` command line: runs one seed or a campaign of consecutive seeds, prints a
//! report per run (or, with `--quiet`, only failures) and a campaign summary; shrinks
//! failures to small reproducers with `--shrink`; draws plots with `--plot DIR`;
//! `--determinism` runs each seed twice and compares the trace hashes.

use std::path::PathBuf;
use std::process::ExitCode;

use simulator::config::{Config, FaultKind, Faults, MAX_OPS, Sabotage, parse_ranges};
use simulator::memory::CountingAlloc;
use simulator::report::Report;
use simulator::shrink::{MAX_SHRINK_RUNS, shrink};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

const USAGE: &str = "usage: simulator [--seed N] [--seeds N] [--peers P] [--ops K] \
[--faults none|lan|wan|chaos|swarm] [--without KIND,...] [--no-hostile] \
[--sabotage none|drop-insertions|reverse-fold|flip-lease] [--actions RANGES] \
[--determinism] [--shrink] [--shrink-runs N] [--plot DIR] [--quiet]
  KIND: jitter loss dup bandwidth partitions offline crashes late-joins forgery flood";

/// Parsed arguments.
struct Args {
    config: Config,
    n_seeds: u64,
    determinism: bool,
    shrink: bool,
    shrink_runs: usize,
    plot_dir: Option<PathBuf>,
    quiet: bool,
}

fn parse(mut args: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut a = Args {
        config: Config::new(1, 8, 500, Faults::PRESETS[2]),
        n_seeds: 1,
        determinism: false,
        shrink: false,
        shrink_runs: MAX_SHRINK_RUNS,
        plot_dir: None,
        quiet: false,
    };
    let mut actions = None;
    while let Some(arg) = args.next() {
        let mut value = || args.next().ok_or_else(|| format!("{arg} needs a value"));
        let number = |v: String| v.parse::<u64>().map_err(|e| format!("{v}: {e}"));
        let c = &mut a.config;
        match arg.as_str() {
            "--seed" => c.seed = number(value()?)?,
            "--seeds" => a.n_seeds = number(value()?)?,
            "--peers" => c.n_peers = number(value()?)? as usize,
            "--ops" => c.n_ops = number(value()?)? as usize,
            "--faults" => {
                let v = value()?;
                c.faults = Faults::named(&v).ok_or(format!("unknown faults {v}"))?;
            }
            "--without" => {
                for name in value()?.split(',').filter(|n| !n.is_empty()) {
                    let kind = FaultKind::named(name).ok_or(format!("unknown fault {name}"))?;
                    c.without = c.without.with(kind);
                }
            }
            "--sabotage" => {
                let v = value()?;
                c.sabotage = Sabotage::named(&v).ok_or(format!("unknown sabotage {v}"))?;
            }
            "--actions" => actions = Some(value()?),
            "--no-hostile" => c.hostile = false,
            "--determinism" => a.determinism = true,
            "--shrink" => a.shrink = true,
            "--shrink-runs" => a.shrink_runs = number(value()?)? as usize,
            "--plot" => a.plot_dir = Some(PathBuf::from(value()?)),
            "--quiet" => a.quiet = true,
            "--help" | "-h" => return Err(String::new()),
            other => return Err(format!("unknown argument {other}")),
        }
    }
    if let Some(text) = actions {
        a.config.actions = Some(parse_ranges(&text, MAX_OPS)?);
    }
    a.config.validate().map_err(|e| e.to_string())?;
    Ok(a)
}

/// Figures over a campaign.
#[derive(Default)]
struct Summary {
    n_runs: u64,
    n_failed: u64,
    round_trips: Vec<f64>,
    messages_per_op: Vec<f64>,
    bytes_per_op: Vec<f64>,
    peak_bytes_max: i64,
    peak_bytes_mean: Vec<f64>,
    final_bytes_per_op: Vec<f64>,
    n_crashes: u64,
    n_lost_unsynced: u64,
    n_torn_tails: u64,
    n_snapshot_joins: u64,
    n_late_joins: u64,
    n_flood_accepted_max: u64,
    n_forged: u64,
    n_author_errors: u64,
}

impl Summary {
    fn add(&mut self, r: &Report) {
        self.n_runs += 1;
        self.n_failed += u64::from(!r.passed());
        self.round_trips.push(r.convergence_round_trips());
        self.messages_per_op.push(r.messages_per_op());
        self.bytes_per_op.push(r.bytes_per_op());
        if let Some(m) = r.memory {
            self.peak_bytes_max = self.peak_bytes_max.max(m.peak_bytes_max);
            self.peak_bytes_mean.push(m.peak_bytes_mean);
            self.final_bytes_per_op.push(m.final_bytes_per_op_mean);
        }
        let s = &r.stats;
        self.n_crashes += s.n_crashes;
        self.n_lost_unsynced += s.n_lost_unsynced;
        self.n_torn_tails += s.n_torn_tails;
        self.n_snapshot_joins += s.n_snapshot_joins;
        self.n_late_joins += s.n_late_joins;
        self.n_forged += s.n_forged_ops;
        self.n_author_errors += s.n_author_errors;
        self.n_flood_accepted_max = self.n_flood_accepted_max.max(r.n_flood_accepted_max);
    }

    fn print(&self, wall_secs: f64) {
        let q = |v: &[f64], p: f64| {
            let mut s = v.to_vec();
            s.sort_by(f64::total_cmp);
            s.get(((s.len() as f64 - 1.0) * p).round() as usize)
                .copied()
                .unwrap_or(0.0)
        };
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        println!(
            "summary: {} runs, {} failed, {:.1} s wall ({:.2} runs/s)",
            self.n_runs,
            self.n_failed,
            wall_secs,
            self.n_runs as f64 / wall_secs.max(1e-9)
        );
        let rt = &self.round_trips;
        println!(
            "  convergence after healing (round trips): mean {:.1}, p50 {:.1}, p90 {:.1}, p99 {:.1}, max {:.1}",
            mean(rt),
            q(rt, 0.5),
            q(rt, 0.9),
            q(rt, 0.99),
            q(rt, 1.0)
        );
        println!(
            "  messages/op: mean {:.1}, max {:.1}; bytes/op: mean {:.0}, max {:.0}",
            mean(&self.messages_per_op),
            q(&self.messages_per_op, 1.0),
            mean(&self.bytes_per_op),
            q(&self.bytes_per_op, 1.0)
        );
        println!(
            "  memory per peer: peak max {:.1} KiB, mean of peaks {:.1} KiB, final {:.0} bytes/op held (mean)",
            self.peak_bytes_max as f64 / 1024.0,
            mean(&self.peak_bytes_mean) / 1024.0,
            mean(&self.final_bytes_per_op)
        );
        println!(
            "  crashes {} (unsynced ops lost {}, torn tails cut {}), late joins {} + {} from \
             snapshots, forged ops {}, most flood messages accepted {}, user ops the core \
             refused {}",
            self.n_crashes,
            self.n_lost_unsynced,
            self.n_torn_tails,
            self.n_late_joins,
            self.n_snapshot_joins,
            self.n_forged,
            self.n_flood_accepted_max,
            self.n_author_errors
        );
    }
}

#[expect(
    clippy::disallowed_methods,
    reason = "the campaign summary reports wall time; nothing simulated reads it"
)]
fn wall_clock() -> std::time::Instant {
    std::time::Instant::now()
}

/// Runs one seed: report, determinism check, shrink, plots. Returns whether it passed.
fn one(args: &Args, config: Config, summary: &mut Summary) -> Result<bool, String> {
    let report = simulator::sim::run(config.clone()).map_err(|e| e.to_string())?;
    summary.add(&report);
    let mut passed = report.passed();
    if !args.quiet || !passed {
        println!("{report}");
    }
    if args.determinism {
        let again = simulator::sim::run(config.clone()).map_err(|e| e.to_string())?;
        if again.trace_hash != report.trace_hash {
            passed = false;
            println!(
                "  determinism FAIL: trace {:016x} then {:016x}; replay: {}",
                report.trace_hash,
                again.trace_hash,
                config.replay_command()
            );
        } else if !args.quiet {
            println!("  determinism: second run has the same trace hash");
        }
    }
    if let Some(dir) = &args.plot_dir {
        let dir = if args.n_seeds > 1 {
            dir.join(format!("seed-{}", config.seed))
        } else {
            dir.clone()
        };
        let paths = simulator::plots::write_plots(&report, &dir).map_err(|e| e.to_string())?;
        for p in paths {
            println!("  plot: {}", p.display());
        }
    }
    if args.shrink && !report.passed() {
        match shrink(&config, args.shrink_runs).map_err(|e| e.to_string())? {
            Some(s) => println!(
                "  shrunk in {} runs to {} peers, {} actions, without [{}], hostile {}: {}\n  \
                 shrunk failures: {:?}",
                s.n_runs,
                s.config.n_peers,
                s.config.n_actions(),
                s.config
                    .without
                    .iter()
                    .map(FaultKind::name)
                    .collect::<Vec<_>>()
                    .join(","),
                s.config.hostile,
                s.config.replay_command(),
                s.report.failures
            ),
            None => println!("  shrink: the run passed when run again"),
        }
    }
    Ok(passed)
}

fn main() -> ExitCode {
    let args = match parse(std::env::args().skip(1)) {
        Ok(a) => a,
        Err(e) => {
            if !e.is_empty() {
                eprintln!("{e}");
            }
            eprintln!("{USAGE}");
            return ExitCode::from(2);
        }
    };
    let started = wall_clock();
    let mut summary = Summary::default();
    let mut n_failed = 0;
    for k in 0..args.n_seeds {
        let config = Config {
            seed: args.config.seed.wrapping_add(k),
            ..args.config.clone()
        };
        match one(&args, config, &mut summary) {
            Ok(passed) => n_failed += u64::from(!passed),
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(2);
            }
        }
    }
    if args.n_seeds > 1 {
        summary.print(started.elapsed().as_secs_f64());
    }
    if n_failed > 0 {
        eprintln!("{n_failed} of {} runs failed", args.n_seeds);
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
