//! The `sculpt` program: with no subcommand (or `demo`) the desktop window on the demo scene,
//! solo, with an embedded local store; otherwise a subcommand (a headless peer, the discovery
//! node, invites, pictures and checks of functions).

mod cli;
mod net_args;
mod window;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// sculpt: sculpt 3D objects defined by functions, together.
#[derive(Parser, Debug)]
#[command(name = "sculpt", version, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Cmd>,
    #[command(flatten)]
    window: window::WindowArgs,
    /// Log level on stderr: off, error, warn, info, debug or trace.
    #[arg(long, global = true, default_value = "info", value_name = "LEVEL")]
    log: log::LevelFilter,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Open the window on a demo scene (`sculpt` alone opens the watermelon); --list names
    /// them all.
    Demo(window::DemoArgs),
    /// Run a headless peer that keeps a session's store and syncs with its peers.
    Peer(cli::PeerArgs),
    /// Run a discovery node: it introduces peers to each other and never sees an op.
    Discovery(cli::DiscoveryArgs),
    /// Print a fresh invite code for a new session. A session started from it has no
    /// founder, so nobody can expel members; start `sculpt` without `--invite` to found one.
    Invite,
    /// List the session stores under a directory.
    Sessions(cli::SessionsArgs),
    /// Compile a function and report problems with their location.
    Check(cli::CheckArgs),
    /// Print every output of a function at a point.
    Eval(cli::EvalArgs),
    /// Draw the solid's cross-section at height Z as text.
    Slice(cli::SliceArgs),
    /// Picture an FVRML scene offscreen as PNG files, one per view.
    Render(cli::RenderArgs),
    /// Run the haptic servo headless over a scene along a recorded or scripted path (CSV)
    /// and write the force of every 1 kHz tick (CSV).
    Touch(cli::TouchArgs),
    /// Add the objects of scene (.wrl) and mesh (.stl, .obj, .glb) files to a session's store.
    Import(cli::ImportArgs),
    /// Write a session's objects, or one, as a mesh (.stl, .obj, .glb) or FVRML (.wrl).
    Export(cli::ExportArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    env_logger::Builder::new()
        .filter_level(cli.log)
        .format_target(false)
        .init();
    let result = match cli.command {
        None => app::demos::find(app::demos::DEFAULT_DEMO)
            .map_err(anyhow::Error::msg)
            .and_then(|demo| window::run(cli.window, demo)),
        Some(Cmd::Demo(args)) => window::demo(args),
        Some(Cmd::Peer(args)) => cli::peer(args),
        Some(Cmd::Discovery(args)) => cli::discovery(&args),
        Some(Cmd::Invite) => cli::invite(),
        Some(Cmd::Sessions(args)) => cli::sessions(&args),
        Some(Cmd::Check(args)) => cli::check(&args),
        Some(Cmd::Eval(args)) => cli::eval(&args),
        Some(Cmd::Slice(args)) => cli::slice_command(&args),
        Some(Cmd::Render(args)) => cli::render_command(&args),
        Some(Cmd::Touch(args)) => cli::touch_command(&args),
        Some(Cmd::Import(args)) => cli::import_command(&args),
        Some(Cmd::Export(args)) => cli::export_command(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sculpt: {e:#}");
            ExitCode::FAILURE
        }
    }
}
