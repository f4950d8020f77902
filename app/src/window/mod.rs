//! The desktop window (`sculpt`, `sculpt demo`): options, the display check and
//! `eframe::run_native` with the wgpu renderer.

mod app;
mod hooks;
mod mesher;
mod panel;
mod viewport;

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use eframe::egui;

use crate::clock;
use crate::session::Session;
use app::SculptApp;
use hooks::Hooks;
use viewport::ViewportResources;

/// Octree depth of implicit objects in the window unless `--depth` says otherwise.
pub const DEFAULT_DEPTH: u8 = 6;
/// Deepest octree `--depth` accepts (render's own limit may be lower).
pub const DEPTH_MAX: u8 = 9;
/// The window's inner size unless `--size` says otherwise, in points.
pub const DEFAULT_SIZE_POINTS: [f32; 2] = [1280.0, 800.0];
/// Largest window side `--size` accepts, in points.
pub const SIZE_POINTS_MAX: f32 = 8192.0;

/// What the user tells the headless subcommands apart by, for the no-display message.
const HEADLESS_HINT: &str = "\
Without a display, use the headless subcommands:
  sculpt render <scene.wrl> --out DIR   picture a scene as PNG files (offscreen)
  sculpt slice <formula> [Z]            print a cross-section as text
  sculpt help                           list every subcommand";

/// How to run the window.
pub struct WindowOptions {
    /// The store directory.
    pub store: PathBuf,
    /// Octree depth for implicit objects.
    pub depth: u8,
    /// Inner size in points.
    pub size_points: [f32; 2],
    /// Test hooks.
    hooks: Hooks,
}

/// The default store: `$XDG_DATA_HOME/sculpt`, else `~/.local/share/sculpt`.
pub fn default_store() -> Option<PathBuf> {
    let non_empty = |name| std::env::var_os(name).filter(|v| !v.is_empty());
    if let Some(data) = non_empty("XDG_DATA_HOME") {
        return Some(PathBuf::from(data).join("sculpt"));
    }
    non_empty("HOME").map(|home| PathBuf::from(home).join(".local/share/sculpt"))
}

/// Reads the window's options (everything after `sculpt` or `sculpt demo`).
pub fn parse_options(args: &[String]) -> anyhow::Result<WindowOptions> {
    let mut store = None;
    let mut depth = DEFAULT_DEPTH;
    let mut size_points = DEFAULT_SIZE_POINTS;
    let mut hooks = Hooks::default();
    let mut rest = args.iter();
    while let Some(arg) = rest.next() {
        let mut value = |name: &str| rest.next().with_context(|| format!("{name} needs a value"));
        match arg.as_str() {
            "--store" => store = Some(PathBuf::from(value("--store")?)),
            "--depth" => {
                let v = value("--depth")?;
                depth = v
                    .parse()
                    .ok()
                    .filter(|d| *d <= DEPTH_MAX)
                    .with_context(|| {
                        format!("--depth `{v}` is not a number from 0 to {DEPTH_MAX}")
                    })?;
            }
            "--size" => {
                let v = value("--size")?;
                let parsed = v.split_once('x').and_then(|(w, h)| {
                    let side = |s: &str| {
                        s.parse::<f32>()
                            .ok()
                            .filter(|x| (1.0..=SIZE_POINTS_MAX).contains(x))
                    };
                    Some([side(w)?, side(h)?])
                });
                size_points = parsed.with_context(|| format!("--size `{v}` is not WxH"))?;
            }
            "--command" => hooks.script.push_back(value("--command")?.clone()),
            "--pick" => {
                let v = value("--pick")?;
                let parsed = v.split_once(',').and_then(|(x, y)| {
                    let fraction =
                        |s: &str| s.parse::<f32>().ok().filter(|f| (0.0..=1.0).contains(f));
                    Some([fraction(x)?, fraction(y)?])
                });
                hooks.pick = Some(parsed.with_context(|| {
                    format!("--pick `{v}` is not X,Y (fractions of the viewport, 0 to 1)")
                })?);
            }
            "--screenshot" => hooks.screenshot = Some(PathBuf::from(value("--screenshot")?)),
            "--exit-when-idle" => hooks.exit_when_idle = true,
            "--exit-after-frames" => {
                let v = value("--exit-after-frames")?;
                hooks.exit_after_frames = Some(
                    v.parse()
                        .with_context(|| format!("bad frame count `{v}`"))?,
                );
            }
            "--dump-state" => hooks.dump_state = Some(PathBuf::from(value("--dump-state")?)),
            other => bail!("unknown option `{other}`\n\n{}", crate::USAGE),
        }
    }
    let store = match store {
        Some(store) => store,
        None => default_store()
            .context("no store directory: set HOME or XDG_DATA_HOME, or give --store DIR")?,
    };
    Ok(WindowOptions {
        store,
        depth,
        size_points,
        hooks,
    })
}

/// Opens the window and runs until it is closed.
pub fn run(options: WindowOptions) -> anyhow::Result<()> {
    let display = std::env::var("DISPLAY").unwrap_or_default();
    let wayland = std::env::var("WAYLAND_DISPLAY").unwrap_or_default();
    if display.is_empty() && wayland.is_empty() {
        bail!(
            "sculpt cannot open its window: there is no display (DISPLAY and WAYLAND_DISPLAY \
             are both unset).\n{HEADLESS_HINT}"
        );
    }
    let WindowOptions {
        store,
        depth,
        size_points,
        hooks,
    } = options;
    let failure = std::sync::Arc::clone(&hooks.failure);
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("sculpt")
            .with_inner_size(size_points),
        ..Default::default()
    };
    eframe::run_native(
        "sculpt",
        native,
        Box::new(move |cc| {
            let state = cc
                .wgpu_render_state
                .as_ref()
                .context("eframe started without its wgpu renderer")?;
            state
                .renderer
                .write()
                .callback_resources
                .insert(ViewportResources::new(&state.device, &state.queue, state.target_format));
            // The store is opened once the window is up, so that a failed start leaves none.
            let session = Session::open(&store, clock::now().wall);
            if let Some(error) = session.store_error() {
                eprintln!("sculpt: store error: {error}");
                eprintln!("sculpt: nothing stored was changed; edits in this window are not saved");
            }
            for notice in session.notices() {
                eprintln!("sculpt: {notice}");
            }
            let ctx = cc.egui_ctx.clone();
            let app = SculptApp::new(session, depth, hooks, move || ctx.request_repaint())?;
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
