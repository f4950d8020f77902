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

/// Simulates N peers of the real replication core over a modelled network, from one seed,
/// and checks that they converge. A failure prints the command that replays it.
#[derive(clap::Parser, Debug)]
#[command(name = "simulator", version)]
struct Cli {
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seeds to run, from --seed on (a campaign).
    #[arg(long, default_value_t = 1)]
    seeds: u64,
    /// Honest peers.
    #[arg(long, default_value_t = 8)]
    peers: usize,
    /// User actions in the workload.
    #[arg(long, default_value_t = 500)]
    ops: usize,
    /// The fault preset: none, lan, wan, chaos, swarm, byzantine (chaos plus a hostile member
    /// running the core and crafting attacks) or byzantine-forks (plus equivocation).
    #[arg(long, default_value = "chaos", value_parser = parse_faults)]
    faults: Faults,
    /// Fault kinds to switch off, comma-separated: jitter loss dup bandwidth partitions
    /// offline crashes late-joins forgery flood byzantine lease-attacks forks expel.
    #[arg(long, value_name = "KIND,...", value_delimiter = ',', value_parser = parse_fault_kind)]
    without: Vec<FaultKind>,
    /// No hostile member.
    #[arg(long)]
    no_hostile: bool,
    /// A planted bug, to test the checkers: none, drop-insertions, reverse-fold, flip-lease
    /// or send-unsynced.
    #[arg(long, default_value = "none", value_parser = parse_sabotage)]
    sabotage: Sabotage,
    /// Only these workload actions (ranges such as 0-9,12), as a shrunk replay names them.
    #[arg(long, value_name = "RANGES")]
    actions: Option<String>,
    /// Run each seed twice and compare the trace hashes.
    #[arg(long)]
    determinism: bool,
    /// Shrink each failure to a small replay command.
    #[arg(long)]
    shrink: bool,
    /// Most runs one shrink may take.
    #[arg(long, default_value_t = MAX_SHRINK_RUNS)]
    shrink_runs: usize,
    /// Write PNG plots of convergence, traffic and memory here.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// Print only failures and the campaign summary.
    #[arg(long)]
    quiet: bool,
}

fn parse_faults(name: &str) -> Result<Faults, String> {
    Faults::named(name).ok_or(format!("unknown faults {name}"))
}

fn parse_fault_kind(name: &str) -> Result<FaultKind, String> {
    FaultKind::named(name).ok_or(format!("unknown fault {name}"))
}

fn parse_sabotage(name: &str) -> Result<Sabotage, String> {
    Sabotage::named(name).ok_or(format!("unknown sabotage {name}"))
}

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

fn args(cli: Cli) -> Result<Args, String> {
    let mut config = Config::new(cli.seed, cli.peers, cli.ops, cli.faults);
    for kind in cli.without {
        config.without = config.without.with(kind);
    }
    config.sabotage = cli.sabotage;
    config.hostile = !cli.no_hostile;
    if let Some(text) = &cli.actions {
        config.actions = Some(parse_ranges(text, MAX_OPS)?);
    }
    config.validate().map_err(|e| e.to_string())?;
    Ok(Args {
        config,
        n_seeds: cli.seeds,
        determinism: cli.determinism,
        shrink: cli.shrink,
        shrink_runs: cli.shrink_runs,
        plot_dir: cli.plot,
        quiet: cli.quiet,
    })
}

/// Seeds from which a campaign with late joins must have joined from a snapshot at least
/// once (about half of all late joins are from snapshots).
const MIN_SEEDS_FOR_SNAPSHOT_JOINS: u64 = 20;

/// Figures over a campaign.
#[derive(Default)]
struct Summary {
    n_runs: u64,
    n_failed: u64,
    round_trips: Vec<f64>,
    catch_up_round_trips: Vec<f64>,
    /// Convergence over issue 53's goal (1.5 bandwidth bounds plus 3 round trips), per run.
    over_goal: Vec<f64>,
    /// The bandwidth bound in round trips, per run.
    bound_round_trips: Vec<f64>,
    messages_per_op: Vec<f64>,
    bytes_per_op: Vec<f64>,
    peak_bytes_max: i64,
    peak_bytes_mean: Vec<f64>,
    final_bytes_per_op: Vec<f64>,
    n_crashes: u64,
    n_lost_unsynced: u64,
    n_torn_tails: u64,
    n_snapshot_joins: u64,
    n_snapshots_refused: u64,
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
        self.catch_up_round_trips
            .push(r.mean_catch_up_round_trips());
        if let (Some(bound), Some(ratio)) = (r.bandwidth_bound_micros(), r.convergence_over_goal())
        {
            self.over_goal.push(ratio);
            self.bound_round_trips
                .push(bound as f64 / r.mean_rtt_micros.max(1) as f64);
        }
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
        self.n_snapshots_refused += s.n_snapshots_refused;
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
            "  convergence after healing (round trips): mean {:.1}, p50 {:.1}, p90 {:.1}, p99 {:.1}, max {:.1}; \
             a peer's catch-up, mean {:.2}",
            mean(rt),
            q(rt, 0.5),
            q(rt, 0.9),
            q(rt, 0.99),
            q(rt, 1.0),
            mean(&self.catch_up_round_trips)
        );
        if !self.over_goal.is_empty() {
            println!(
                "  bandwidth bound after healing (round trips): mean {:.2}, max {:.2}; convergence \
                 over 1.5 bounds plus 3 round trips: mean {:.2}, max {:.2}",
                mean(&self.bound_round_trips),
                q(&self.bound_round_trips, 1.0),
                mean(&self.over_goal),
                q(&self.over_goal, 1.0)
            );
        }
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
             snapshots ({} planted snapshots refused), forged ops {}, most flood messages \
             accepted {}, user ops the core refused {}",
            self.n_crashes,
            self.n_lost_unsynced,
            self.n_torn_tails,
            self.n_late_joins,
            self.n_snapshot_joins,
            self.n_snapshots_refused,
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
    let args = match args(<Cli as clap::Parser>::parse()) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("simulator: {e}");
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
    // A campaign whose preset has late joins must show snapshot joins, or it did not test
    // them (issue 50).
    let late_joins = args.config.effective_faults().late_joins;
    if args.n_seeds >= MIN_SEEDS_FOR_SNAPSHOT_JOINS && late_joins && summary.n_snapshot_joins == 0 {
        eprintln!("no run of {} joined from a snapshot", args.n_seeds);
        return ExitCode::FAILURE;
    }
    if n_failed > 0 {
        eprintln!("{n_failed} of {} runs failed", args.n_seeds);
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
