//! The `sculpt` program: with no subcommand (or `demo`) the desktop window on the demo scene,
//! solo, with an embedded local store; otherwise a headless subcommand.

mod cli;
mod clock;
mod command;
mod session;
mod window;

use std::process::ExitCode;

const USAGE: &str = "\
sculpt: sculpt 3D objects defined by functions

usage:
  sculpt [demo] [--store DIR] [--depth N] [--size WxH]
                               open the window on the demo scene (the thesis's watermelon),
                               solo, with its ops kept in DIR (default
                               $XDG_DATA_HOME/sculpt or ~/.local/share/sculpt)
  sculpt check <text|@file>    compile a function and report problems with their location
  sculpt eval <text|@file> X Y Z [T]
                               print every output of a function at a point
  sculpt slice <text|@file> [Z] [T]
                               draw the solid's cross-section at height Z as text
  sculpt render <scene.wrl> --out <dir> [--size WxH] [--depth N] [--t SECS]
                               picture an FVRML scene offscreen as PNG files, one per view

window test hooks:
  --command LINE               run LINE as if typed in the command line (repeatable)
  --pick X,Y                   click the viewport at fractions X, Y of its size
  --screenshot PATH            save a PNG of the window once everything is drawn, then close
  --exit-when-idle             close once the commands have run and everything is drawn
  --exit-after-frames N        close after N frames (an error if a hook is unfinished)
  --dump-state PATH            write what the window shows as JSON when a hook closes it
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &[String]) -> anyhow::Result<()> {
    match args.first().map(String::as_str) {
        None => window::run(window::parse_options(&[])?),
        Some("demo") => window::run(window::parse_options(&args[1..])?),
        Some(flag) if flag.starts_with("--") && flag != "--help" => {
            window::run(window::parse_options(args)?)
        }
        Some(_) => cli::run(args),
    }
}
