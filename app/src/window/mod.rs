//! The desktop window (`sculpt`, `sculpt demo`): options, the display check and
//! `eframe::run_native` with the wgpu renderer. `SculptApp` (`app.rs`) coordinates each
//! frame; the other modules each own one concern: its state, its logic and its panel.

mod app;
mod commands;
mod hooks;
mod objects;
mod peers;
mod rows;
mod sculpt;
mod session;
mod side;
mod top;
mod touch;
mod transfer;
mod viewport;

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use eframe::egui;

use self::app::SculptApp;
use ::app::clock;
use ::app::engine::{Engine, EngineConfig, lock};
use ::app::settings::Settings;
use hooks::Hooks;
use viewport::gpu::ViewportResources;

/// Octree depth of implicit objects in the window unless `--depth` says otherwise.
pub const DEFAULT_DEPTH: u8 = 6;
/// Deepest octree `--depth` accepts (render's own limit may be lower).
pub const MAX_DEPTH: u8 = 9;
/// The window's inner size unless `--size` says otherwise, in points.
pub const DEFAULT_SIZE_POINTS: [f32; 2] = [1280.0, 800.0];
/// Largest window side `--size` accepts, in points.
pub const MAX_SIZE_POINTS: f32 = 8192.0;

/// Colour of errors in the panels.
const ERROR_COLOUR: egui::Color32 = egui::Color32::from_rgb(255, 110, 100);
/// Colour of notices in the panels.
const NOTICE_COLOUR: egui::Color32 = egui::Color32::from_rgb(240, 200, 90);

/// What the user tells the headless subcommands apart by, for the no-display message.
const HEADLESS_HINT: &str = "\
Without a display, use the headless subcommands:
  sculpt render <scene.wrl> --out DIR   picture a scene as PNG files (offscreen)
  sculpt slice <formula> [Z]            print a cross-section as text
  sculpt help                           list every subcommand";

/// The window's flags (`sculpt [demo] ...`).
#[derive(clap::Args, Debug)]
pub struct WindowArgs {
    /// The session's store directory (default: the demo's own, $XDG_DATA_HOME/sculpt/sessions/
    /// demo for the watermelon and demo-NAME for the others, or ~/.local/share/sculpt/...).
    #[arg(long, value_name = "DIR")]
    pub store: Option<PathBuf>,
    /// Octree depth for implicit objects.
    #[arg(long, default_value_t = DEFAULT_DEPTH, value_parser = clap::value_parser!(u8).range(0..=i64::from(MAX_DEPTH)))]
    pub depth: u8,
    /// The window's inner size in points.
    #[arg(long, value_name = "WxH", value_parser = parse_size_points)]
    pub size: Option<[f32; 2]>,
    #[command(flatten)]
    pub net: crate::net_args::NetArgs,
    /// Test hook: run LINE as if typed in the command line (repeatable).
    #[arg(long, value_name = "LINE")]
    pub command: Vec<String>,
    /// Test hook: drag across the viewport with the current tool, from X0,Y0 to X1,Y1
    /// (fractions of its size), after the commands (repeatable). A command line
    /// `drag: X0,Y0:X1,Y1` does the same at its place in the script.
    #[arg(long, value_name = "X0,Y0:X1,Y1", value_parser = hooks::steps::parse_drag)]
    pub drag: Vec<[[f32; 2]; 2]>,
    /// Test hook: press a shortcut after the commands (repeatable): undo, redo, sculpt,
    /// navigate, play, pause, space; a command line `key: NAME` does the same at its place in
    /// the script.
    #[arg(long, value_name = "NAME")]
    pub key: Vec<String>,
    /// Test hook: click the viewport at fractions X, Y of its size.
    #[arg(long, value_name = "X,Y", value_parser = parse_fractions)]
    pub pick: Option<[f32; 2]>,
    /// Test hook: save a PNG of the window once everything is drawn, then close.
    #[arg(long, value_name = "PATH")]
    pub screenshot: Option<PathBuf>,
    /// Test hook: close once the commands have run and everything is drawn.
    #[arg(long)]
    pub exit_when_idle: bool,
    /// Test hook: close after N frames (an error if a hook is unfinished).
    #[arg(long, value_name = "N")]
    pub exit_after_frames: Option<u64>,
    /// Test hook: before each scripted step, wait until the session holds at least N ops
    /// (scripted steps also wait while a join from a snapshot is fetched or checked).
    #[arg(long, value_name = "N")]
    pub wait_ops: Option<usize>,
    /// Test hook: before each scripted step, wait until N other peers' presence is known.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub wait_presence: usize,
    /// Test hook: write what the window shows as JSON when a hook closes it.
    #[arg(long, value_name = "PATH")]
    pub dump_state: Option<PathBuf>,
}

fn parse_size_points(text: &str) -> Result<[f32; 2], String> {
    let side = |s: &str| {
        s.parse::<f32>()
            .ok()
            .filter(|x| (1.0..=MAX_SIZE_POINTS).contains(x))
    };
    text.split_once('x')
        .and_then(|(w, h)| Some([side(w)?, side(h)?]))
        .ok_or_else(|| format!("`{text}` is not WxH (each side 1 to {MAX_SIZE_POINTS})"))
}

fn parse_fractions(text: &str) -> Result<[f32; 2], String> {
    let fraction = |s: &str| s.parse::<f32>().ok().filter(|f| (0.0..=1.0).contains(f));
    text.split_once(',')
        .and_then(|(x, y)| Some([fraction(x)?, fraction(y)?]))
        .ok_or_else(|| format!("`{text}` is not X,Y (fractions of the viewport, 0 to 1)"))
}

/// `sculpt demo`: a demo scene in the window, or the list of them.
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// The demo to open (see --list).
    #[arg(id = "demo", value_name = "NAME", default_value = ::app::demos::DEFAULT_DEMO)]
    pub demo: String,
    /// Print the demo scenes, one per line, and exit.
    #[arg(long)]
    pub list: bool,
    #[command(flatten)]
    pub window: WindowArgs,
}

/// `sculpt demo [NAME] [--list]`.
pub fn demo(args: DemoArgs) -> anyhow::Result<()> {
    if args.list {
        print!("{}", ::app::demos::list_text());
        return Ok(());
    }
    let demo = ::app::demos::find(&args.demo).map_err(anyhow::Error::msg)?;
    run(args.window, demo)
}

/// Opens the window on `demo`'s session (unless an invite or a store says otherwise) and
/// runs until it is closed.
pub fn run(args: WindowArgs, demo: &'static ::app::demos::Demo) -> anyhow::Result<()> {
    let display = std::env::var("DISPLAY").unwrap_or_default();
    let wayland = std::env::var("WAYLAND_DISPLAY").unwrap_or_default();
    if display.is_empty() && wayland.is_empty() {
        bail!(
            "sculpt cannot open its window: there is no display (DISPLAY and WAYLAND_DISPLAY \
             are both unset).\n{HEADLESS_HINT}"
        );
    }
    let engine_config = EngineConfig {
        store: store_dir(&args, demo)?,
        invite: args.net.invite.clone(),
        network: args.net.network(),
        demo: Some(demo),
        memory_fallback: true,
        name: args.net.name.clone(),
        session_name: args.net.session_name.clone(),
    };
    // The settings are read before the window opens: it opens at the size it was left at.
    let settings = load_settings();
    let size_points = args
        .size
        .or_else(|| settings.as_ref().and_then(|(s, _)| s.window_points))
        .unwrap_or(DEFAULT_SIZE_POINTS);
    let hooks = Hooks::from_args(&args);
    let failure = std::sync::Arc::clone(&hooks.failure);
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("sculpt")
            .with_inner_size(size_points),
        ..Default::default()
    };
    let depth = args.depth;
    eframe::run_native(
        "sculpt",
        native,
        Box::new(move |cc| {
            let app = open(cc, engine_config, depth, hooks, settings)?;
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| {
        anyhow::anyhow!(
            "sculpt cannot open its window: {e}\n(DISPLAY={display:?}, WAYLAND_DISPLAY={wayland:?}: \
             is a display server running there?)\n{HEADLESS_HINT}"
        )
    })?;
    let failure = failure.lock().ok().and_then(|f| f.clone());
    if let Some(failure) = failure {
        bail!("{failure}");
    }
    Ok(())
}

/// The session's store: `--store`, else the joined session's or the demo's own under the
/// data directory. Each session has its own store.
fn store_dir(args: &WindowArgs, demo: &::app::demos::Demo) -> anyhow::Result<PathBuf> {
    if let Some(store) = &args.store {
        return Ok(store.clone());
    }
    let sessions = ::app::dirs::data_dir()
        .context("no store directory: set HOME or XDG_DATA_HOME, or give --store DIR")?
        .join(::app::dirs::SESSIONS_DIR);
    Ok(match &args.net.invite {
        Some(invite) => sessions.join(::app::engine::store::joined_dir_name(invite)),
        None => sessions.join(demo.store_dir_name()),
    })
}

/// The kept settings and their file, when there is a data directory (a notice on stderr
/// when they could not be read).
fn load_settings() -> Option<(Settings, PathBuf)> {
    ::app::dirs::data_dir().map(|dir| {
        let path = dir.join(::app::settings::SETTINGS_FILE);
        let (settings, notice) = Settings::load(&path);
        if let Some(notice) = notice {
            eprintln!("sculpt: settings: {notice}");
        }
        (settings, path)
    })
}

/// The window's app, once eframe is up: the viewport's GPU resources, then the session's
/// engine (opened only now, so that a failed start leaves no store), then the settings.
fn open(
    cc: &eframe::CreationContext<'_>,
    config: EngineConfig,
    depth: u8,
    hooks: Hooks,
    settings: Option<(Settings, PathBuf)>,
) -> anyhow::Result<SculptApp> {
    let state = cc
        .wgpu_render_state
        .as_ref()
        .context("eframe started without its wgpu renderer")?;
    state
        .renderer
        .write()
        .callback_resources
        .insert(ViewportResources::new(
            &state.device,
            &state.queue,
            state.target_format,
        ));
    let engine = Engine::start(config.clone(), clock::now().wall)?;
    {
        let view = lock(engine.view());
        if let Some(error) = view.store_error() {
            eprintln!("sculpt: store error: {error}");
        }
        for notice in view.notices() {
            eprintln!("sculpt: {notice}");
        }
    }
    let ctx = cc.egui_ctx.clone();
    let wake = std::sync::Arc::new(move || ctx.request_repaint());
    let mut app = SculptApp::new(engine, config, depth, hooks, wake)?;
    if let Some((settings, path)) = settings {
        app.apply_settings(&settings, path);
    }
    Ok(app)
}
