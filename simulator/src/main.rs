//! The `simulator` command line: runs one seed (or a range of seeds), prints a report per run
//! and the replay command of any failure; `--determinism` runs each seed twice and compares
//! the trace hashes.

use std::process::ExitCode;

use simulator::config::{Config, Faults, Sabotage};

const USAGE: &str = "usage: simulator [--seed N] [--seeds N] [--peers P] [--ops K] \
[--faults none|lan|wan|chaos] [--no-hostile] [--sabotage none|drop-insertions|reverse-fold] \
[--determinism]";

/// Parsed arguments.
struct Args {
    config: Config,
    n_seeds: u64,
    determinism: bool,
}

fn parse(mut args: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut config = Config::new(1, 8, 500, Faults::PRESETS[2]);
    let mut n_seeds = 1;
    let mut determinism = false;
    while let Some(arg) = args.next() {
        let mut value = || args.next().ok_or_else(|| format!("{arg} needs a value"));
        let number = |v: String| v.parse::<u64>().map_err(|e| format!("{v}: {e}"));
        match arg.as_str() {
            "--seed" => config.seed = number(value()?)?,
            "--seeds" => n_seeds = number(value()?)?,
            "--peers" => config.n_peers = number(value()?)? as usize,
            "--ops" => config.n_ops = number(value()?)? as usize,
            "--faults" => {
                let v = value()?;
                config.faults = Faults::named(&v).ok_or(format!("unknown faults {v}"))?;
            }
            "--sabotage" => {
                let v = value()?;
                config.sabotage = Sabotage::named(&v).ok_or(format!("unknown sabotage {v}"))?;
            }
            "--no-hostile" => config.hostile = false,
            "--determinism" => determinism = true,
            "--help" | "-h" => return Err(String::new()),
            other => return Err(format!("unknown argument {other}")),
        }
    }
    config.validate().map_err(|e| e.to_string())?;
    Ok(Args {
        config,
        n_seeds,
        determinism,
    })
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
    let mut n_failed = 0;
    for k in 0..args.n_seeds {
        let config = Config {
            seed: args.config.seed.wrapping_add(k),
            ..args.config
        };
        let report = match simulator::sim::run(config) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(2);
            }
        };
        println!("{report}");
        if !report.passed() {
            n_failed += 1;
        }
        if args.determinism {
            match simulator::sim::run(config) {
                Ok(again) if again.trace_hash == report.trace_hash => {
                    println!("  determinism: second run has the same trace hash");
                }
                Ok(again) => {
                    n_failed += 1;
                    println!(
                        "  determinism FAIL: trace {:016x} then {:016x}; replay: {}",
                        report.trace_hash,
                        again.trace_hash,
                        config.replay_command()
                    );
                }
                Err(e) => eprintln!("{e}"),
            }
        }
    }
    if n_failed > 0 {
        eprintln!("{n_failed} of {} runs failed", args.n_seeds);
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
