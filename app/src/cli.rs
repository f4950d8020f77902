//! The subcommands for headless use: `peer` (a headless peer), `discovery`, `invite`,
//! `sessions`, `import` and `export` (files in and out of a session's store), and `check`,
//! `eval`, `slice`, `render` and `touch` for functions and scenes.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use app::engine::{Engine, EngineConfig, lock, store};
use fdsl::Function;
use fdsl::eval::{BulkEval, PointEval};
use replication::net::invite::Invite;
use replication::shape::{IdSource, ShapePayload};

/// How often a headless peer looks at its view to print what changed.
const PEER_POLL_MILLIS: u64 = 100;

/// `sculpt peer`.
#[derive(clap::Args, Debug)]
pub struct PeerArgs {
    /// The session's store directory (made if missing).
    #[arg(long, value_name = "DIR")]
    pub store: PathBuf,
    #[command(flatten)]
    pub net: crate::net_args::NetArgs,
    /// A line of the window's command language, run once at start (repeatable).
    #[arg(long, value_name = "LINE")]
    pub command: Vec<String>,
    /// Print one JSON object per line whenever the peer's state changes.
    #[arg(long)]
    pub json: bool,
    /// Before the --command lines, wait until the session holds at least N ops (synced from
    /// the others), for at most a minute.
    #[arg(long, value_name = "N")]
    pub wait_ops: Option<usize>,
    /// Show other peers a pointer at X,Y,Z (the renderer's world, +z up), as a window's
    /// pointer on a surface would be (for tests and demonstrations).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point)]
    pub pointer: Option<[f32; 3]>,
    /// Show other peers a touch tool at X,Y,Z (the renderer's world), as a window whose touch
    /// is on shows its tool (for tests and demonstrations).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point)]
    pub tool_at: Option<[f32; 3]>,
}

fn parse_point(text: &str) -> Result<[f32; 3], String> {
    let parts: Vec<f32> = text
        .split(',')
        .map(|p| p.trim().parse::<f32>().map_err(|e| format!("`{p}`: {e}")))
        .collect::<Result<_, _>>()?;
    match parts[..] {
        [x, y, z] if parts.iter().all(|v| v.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("`{text}` is not X,Y,Z")),
    }
}

/// `sculpt discovery`.
#[derive(clap::Args, Debug)]
pub struct DiscoveryArgs {
    /// The UDP address to answer on.
    #[arg(long, value_name = "ADDR")]
    pub listen: SocketAddr,
}

/// `sculpt sessions`.
#[derive(clap::Args, Debug)]
pub struct SessionsArgs {
    /// The directory holding session stores (default: $XDG_DATA_HOME/sculpt/sessions).
    #[arg(long, value_name = "DIR")]
    pub root: Option<PathBuf>,
}

/// `sculpt check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The function's text, or @file.
    pub text: String,
}

/// `sculpt eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// The function's text, or @file.
    pub text: String,
    /// X Y Z and optionally T.
    #[arg(num_args = 3..=4, allow_negative_numbers = true, required = true)]
    pub point: Vec<f64>,
}

/// `sculpt slice`.
#[derive(clap::Args, Debug)]
pub struct SliceArgs {
    /// The function's text, or @file.
    pub text: String,
    /// The height of the section.
    #[arg(allow_negative_numbers = true, default_value_t = 0.0)]
    pub z: f64,
    /// The time.
    #[arg(allow_negative_numbers = true, default_value_t = 0.0)]
    pub t: f64,
}

/// `sculpt render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The FVRML scene file (.wrl).
    pub scene: PathBuf,
    /// The directory to write the PNG files to.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Image size in pixels.
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Octree depth of implicit objects.
    #[arg(long)]
    pub depth: Option<u8>,
    /// The time of the picture, in seconds.
    #[arg(long, value_name = "SECS")]
    pub t: Option<f64>,
    /// Let `Inline` files come from anywhere inside DIR (default: the scene's own folder).
    #[arg(long, value_name = "DIR")]
    pub inline_root: Option<PathBuf>,
}

/// `sculpt touch`.
#[derive(clap::Args, Debug)]
pub struct TouchArgs {
    /// The FVRML scene file (.wrl).
    pub scene: PathBuf,
    /// The path to follow: CSV with the header `t,x,y,z,button` (seconds; the haptic
    /// interface point in the scene's own coordinates; button 0 or 1), rows at any rate,
    /// interpolated to 1 kHz.
    #[arg(long, value_name = "IN.csv")]
    pub trace: PathBuf,
    /// Where to write the forces: CSV with the header `t,fx,fy,fz` (newtons), one row per
    /// tick.
    #[arg(long, value_name = "OUT.csv")]
    pub out: PathBuf,
    /// The device whose limits the forces are rendered for.
    #[arg(long, value_enum, default_value_t = app::touch::DeviceModel::Falcon)]
    pub device: app::touch::DeviceModel,
    /// Scene units per device metre (default: the device's workspace spans the scene's
    /// bounded objects). Stiffness is per device metre, so this scales how hard surfaces
    /// feel.
    #[arg(long, value_name = "S")]
    pub world_per_metre: Option<f64>,
    /// Let `Inline` files come from anywhere inside DIR (default: the scene's own folder).
    #[arg(long, value_name = "DIR")]
    pub inline_root: Option<PathBuf>,
}

/// `sculpt import`.
#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// The session's store directory (made, as a new session, if missing).
    #[arg(long, value_name = "DIR")]
    pub store: PathBuf,
    /// The files to import, in order: FVRML scenes (.wrl; `Inline`s only from the file's own
    /// folder) and meshes (.stl, .obj, .glb; one object each, up to about 170 000 triangles,
    /// authored in parts when larger than one op).
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Let `Inline` files come from anywhere inside DIR (default: each scene's own folder).
    #[arg(long, value_name = "DIR")]
    pub inline_root: Option<PathBuf>,
}

/// `sculpt export`.
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// The session's store directory.
    #[arg(long, value_name = "DIR")]
    pub store: PathBuf,
    /// Export only this object: its id as `sculpt import` prints it, or its number in the
    /// window (`object N`). Default: every object, merged.
    #[arg(long, value_name = "ID")]
    pub object: Option<u64>,
    /// Octree depth for implicit and sculpted objects (2^N cells along a side; default 7).
    #[arg(long, value_name = "N")]
    pub depth: Option<u8>,
    /// The file to write: .stl (binary), .obj, .glb (meshes in scene coordinates, +y up) or
    /// .wrl (FVRML, edit histories included). Written whole or not at all.
    #[arg(value_name = "OUT")]
    pub out: PathBuf,
}

fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text.split_once('x').ok_or("not WxH")?;
    let side = |s: &str| s.parse::<u32>().map_err(|e| format!("`{s}`: {e}"));
    Ok((side(w)?, side(h)?))
}

/// `sculpt invite`: a fresh invite, for a new session (drawn at random: it names no founder).
pub fn invite() -> anyhow::Result<()> {
    let invite = Invite::generate(&mut store::entropy_rng()?);
    println!("{invite}");
    Ok(())
}

/// `sculpt sessions`: the session stores under the root, one line each.
pub fn sessions(args: &SessionsArgs) -> anyhow::Result<()> {
    let root = match &args.root {
        Some(root) => root.clone(),
        None => app::dirs::data_dir()
            .map(|dir| dir.join(app::dirs::SESSIONS_DIR))
            .context("no data directory: set HOME or XDG_DATA_HOME, or give --root DIR")?,
    };
    let found = match store::list_sessions(&root) {
        Ok(found) => found,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(e).with_context(|| format!("cannot list {}", root.display())),
    };
    if found.is_empty() {
        println!("no sessions under {}", root.display());
    }
    for dir in found {
        let ops = std::fs::metadata(dir.join(store::OPS_FILE)).map_or(0, |m| m.len());
        let name = dir
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        println!("{name}\t{}\t{ops} bytes of ops", dir.display());
    }
    Ok(())
}

/// How often `sculpt discovery` says what it has done.
const REPORT_EVERY_MICROS: u64 = 60_000_000;

/// `sculpt discovery --listen ADDR`: serves until interrupted, saying what it does.
pub fn discovery(args: &DiscoveryArgs) -> anyhow::Result<()> {
    use replication::net::discovery::registry::RegistryStats;
    use replication::net::discovery::server::DiscoveryServer;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let server = DiscoveryServer::bind(args.listen)?;
    let addr = server.local_addr()?;
    println!("discovery node listening on {addr}; it stores no ops and relays none");
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    std::thread::Builder::new()
        .name("sculpt-signals".into())
        .spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build();
            if let Ok(runtime) = runtime {
                runtime.block_on(wait_for_stop());
            }
            flag.store(true, Ordering::Relaxed);
        })?;
    let report = |stats: &RegistryStats, held: usize| {
        println!(
            "discovery node: {held} registrations held; {} registered, {} introductions \
             and replies sent ({} bytes), {} bad datagrams, {} rate-limited, {} refused when full",
            stats.n_registered,
            stats.n_replies,
            stats.n_bytes_sent,
            stats.n_bad_input(),
            stats.n_rate_limited,
            stats.n_full
        );
    };
    let stats = server.run_reporting(&shutdown, REPORT_EVERY_MICROS, report)?;
    println!(
        "discovery node stopped after {} registrations and {} bad datagrams",
        stats.n_registered,
        stats.n_bad_input()
    );
    Ok(())
}

/// Waits for Ctrl-C or SIGTERM.
async fn wait_for_stop() {
    use tokio::signal::unix::{SignalKind, signal};
    match signal(SignalKind::terminate()) {
        Ok(mut term) => {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
            }
        }
        Err(_) => {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

/// `sculpt peer`: a headless peer. Runs its `--command` lines once, then syncs until
/// interrupted (Ctrl-C or SIGTERM: a clean stop with every op on disk).
pub fn peer(args: PeerArgs) -> anyhow::Result<()> {
    let config = EngineConfig {
        store: args.store.clone(),
        invite: args.net.invite.clone(),
        network: args.net.network(),
        demo: None,
        memory_fallback: false,
        name: args.net.name.clone(),
        session_name: args.net.session_name.clone(),
    };
    let engine = Engine::start(config, app::clock::now().wall)?;
    for notice in lock(engine.view()).notices() {
        log::warn!("{notice}");
    }
    if let Some(n) = args.wait_ops {
        wait_for_ops(&engine, n)?;
    }
    if !args.command.is_empty() {
        wait_for_admission(&engine)?;
    }
    run_commands(&engine, &args.command)?;
    if args.pointer.is_some() || args.tool_at.is_some() {
        let mut presence = engine.presence();
        presence.pointer = args.pointer;
        presence.tool = args.tool_at;
        engine.set_presence(presence)?;
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let mut printed = None;
        let mut tick = tokio::time::interval(std::time::Duration::from_millis(PEER_POLL_MILLIS));
        let stop = wait_for_stop();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                () = &mut stop => break,
                _ = tick.tick() => {
                    let state = peer_state(&engine);
                    if args.json && printed.as_ref() != Some(&state) {
                        println!("{state}");
                        printed = Some(state);
                    }
                }
            }
        }
    });
    engine.shutdown();
    Ok(())
}

/// Longest `--wait-ops` waits.
const MAX_WAIT_OPS_SECS: u64 = 60;

/// Waits until the engine's view holds at least `n` ops.
fn wait_for_ops(engine: &Engine, n: usize) -> anyhow::Result<()> {
    let start = app::clock::now().instant;
    while lock(engine.view()).n_ops() < n {
        if start.elapsed().as_secs() >= MAX_WAIT_OPS_SECS {
            bail!(
                "--wait-ops {n}: only {} ops after {MAX_WAIT_OPS_SECS} s",
                lock(engine.view()).n_ops()
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(PEER_POLL_MILLIS / 4));
    }
    Ok(())
}

/// Longest a peer with `--command` lines waits for a member to admit it.
const MAX_WAIT_ADMISSION_SECS: u64 = 60;

/// Waits until this peer may author: at once unless the session binds its authors and no
/// member has admitted this peer yet.
fn wait_for_admission(engine: &Engine) -> anyhow::Result<()> {
    let start = app::clock::now().instant;
    while !lock(engine.view()).admitted() {
        if start.elapsed().as_secs() >= MAX_WAIT_ADMISSION_SECS {
            bail!("no member admitted this peer within {MAX_WAIT_ADMISSION_SECS} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(PEER_POLL_MILLIS / 4));
    }
    Ok(())
}

/// Runs command lines as the window would, each after the previous one is stored; a line
/// that fails stops the peer with its error.
fn run_commands(engine: &Engine, lines: &[String]) -> anyhow::Result<()> {
    let mut selected = lock(engine.view())
        .scene()
        .objects()
        .last()
        .map(|(id, _)| id.0);
    for line in lines {
        let Some(command) = app::command::parse(line) else {
            continue;
        };
        let planned = app::command::plan(command, &lock(engine.view()), selected)
            .map_err(|e| anyhow::anyhow!("--command `{line}`: {e}"))?;
        engine
            .author_validated(planned.payload)?
            .wait()
            .map_err(|e| anyhow::anyhow!("--command `{line}`: {e}"))?;
        if planned.select.is_some() {
            selected = planned.select;
        }
        log::info!("{}", planned.summary);
    }
    Ok(())
}

/// The peer's state as one JSON object.
fn peer_state(engine: &Engine) -> serde_json::Value {
    let mut view = lock(engine.view());
    let (to_send, to_receive) = view.progress();
    let check = view.scene_check().clone();
    serde_json::json!({
        "peer": view.peer_id().short(),
        "listen": view.listen_addr().map(|a| a.to_string()),
        "ops": view.n_ops(),
        "objects": view.scene().len(),
        // Polled every PEER_POLL_MILLIS: a large scene changing fast is hashed only as often as
        // the view allows, so this line may name a hash of a slightly older scene.
        "scene_hash": view.recent_scene_hash_hex(app::clock::now().instant),
        "peers": view.peers().len(),
        "to_send": to_send,
        "to_receive": to_receive,
        "store_error": view.store_error(),
        "lan": view.lan_sessions().iter().map(|s| s.name.clone()).collect::<Vec<_>>(),
        "rejected": view.history().iter().filter(|h| h.status.starts_with("rejected")).count(),
        "scene_check": {
            "agrees": check.agrees,
            "mismatches": check.n_mismatches,
            "objects_refolded": check.n_objects_refolded,
            "last_mismatch": check.last_mismatch,
        },
        "snapshot": join_json(view.snapshot()),
    })
}

/// How the peer's join from a snapshot went, as JSON (`null` when it joined none).
pub(crate) fn join_json(row: Option<&app::engine::JoinRow>) -> serde_json::Value {
    row.map_or(serde_json::Value::Null, |r| {
        serde_json::json!({
            "from": r.from,
            "bytes": r.bytes,
            "ops": r.n_ops,
            "join_ms": r.join_micros.map(|us| us as f64 / 1e3),
            "checked": r.checked,
            "verified": r.verified,
            "refused": r.refused,
            "busy": r.busy,
            "text": r.text(),
        })
    })
}

/// `sculpt check`.
pub fn check(args: &CheckArgs) -> anyhow::Result<()> {
    let text = source(&args.text)?;
    let compiled = Function::compile(&text);
    for d in &compiled.diagnostics {
        eprint!("{}", d.render(&text));
    }
    match compiled.function {
        Some(f) => {
            let names: Vec<&str> = f.output_names().collect();
            println!(
                "ok: outputs {}; {} operations",
                names.join(", "),
                f.graph_len()
            );
            Ok(())
        }
        None => bail!("the function does not compile"),
    }
}

/// `sculpt eval`.
pub fn eval(args: &EvalArgs) -> anyhow::Result<()> {
    let function = Function::parse(&source(&args.text)?)?;
    let mut p = [0.0; 4];
    for (slot, v) in args.point.iter().take(4).enumerate() {
        p[slot] = *v;
    }
    for name in function.output_names() {
        let tape = function.tape_for(&[name])?;
        println!("{name} = {}", PointEval::new(&tape).eval(p));
    }
    Ok(())
}

/// `sculpt slice`.
pub fn slice_command(args: &SliceArgs) -> anyhow::Result<()> {
    let function = Function::parse(&source(&args.text)?)?;
    print!("{}", slice(&function, args.z, args.t, 64, 32));
    Ok(())
}

/// The text of a function: the argument itself, or the file named after `@`.
fn source(arg: &str) -> anyhow::Result<String> {
    match arg.strip_prefix('@') {
        Some(path) => {
            let bytes =
                app::files::read_bounded(Path::new(path), fdsl::limits::MAX_SOURCE_BYTES as u64)
                    .map_err(anyhow::Error::msg)?;
            String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{path}: not UTF-8 text"))
        }
        None => Ok(arg.to_string()),
    }
}

/// A text picture of the solid's section at height `z` over [-1.2, 1.2]^2.
fn slice(function: &Function, z: f64, t: f64, width: usize, height: usize) -> String {
    let mut eval = BulkEval::new(&function.tape());
    let mut out = String::new();
    let mut row = vec![0.0f32; width];
    let xs: Vec<f32> = (0..width)
        .map(|i| (-1.2 + 2.4 * (i as f64 + 0.5) / width as f64) as f32)
        .collect();
    let zs = vec![z as f32; width];
    for j in 0..height {
        let y = (1.2 - 2.4 * (j as f64 + 0.5) / height as f64) as f32;
        let ys = vec![y; width];
        eval.eval(&xs, &ys, &zs, t as f32, &mut row);
        out.extend(row.iter().map(|&v| if v >= 0.0 { '#' } else { '.' }));
        out.push('\n');
    }
    out
}

/// `sculpt render <scene.wrl> --out <dir> [--size WxH] [--depth N] [--t SECS]`: loads the
/// FVRML file (local `Inline`s relative to it), pictures it from the default views with
/// `render::snapshot` and writes `<dir>/<file stem>_<view>.png`, printing what it drew and
/// wrote. Load errors are reported with their file, line and column.
pub fn render_command(args: &RenderArgs) -> anyhow::Result<()> {
    use render::snapshot::{SnapshotSettings, snapshot};

    let mut settings = SnapshotSettings {
        // Nothing else runs beside a command's meshing.
        mesh_threads: render::mesher::remesh_threads(0),
        ..SnapshotSettings::default()
    };
    if let Some((w, h)) = args.size {
        settings.width = w;
        settings.height = h;
    }
    if let Some(depth) = args.depth {
        settings.depth = depth;
    }
    if let Some(t) = args.t {
        settings.t_secs = t;
    }
    let (scene_path, out_dir) = (&args.scene, &args.out);
    let scene = load_scene(scene_path, args.inline_root.as_deref())?;
    let (images, objects) = snapshot(&scene, &settings)?;
    for o in &objects {
        let name = if o.name.is_empty() {
            "(unnamed)"
        } else {
            &o.name
        };
        let drawn = format!("{} triangles, {} force arrows", o.n_triangles, o.n_arrows);
        match &o.skipped {
            Some(why) => println!("object {} {name}: {drawn}; not drawn: {why}", o.id.0),
            None => println!("object {} {name}: {drawn}", o.id.0),
        }
    }
    if objects.is_empty() {
        println!("the scene has no objects to draw");
    }
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    let stem = scene_path
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy());
    for (view, image) in images {
        let path = out_dir.join(format!("{stem}_{view}.png"));
        image.save_png(&path)?;
        println!(
            "wrote {} ({}x{}, view {view}, t = {:?} s)",
            path.display(),
            image.width,
            image.height,
            settings.t_secs
        );
    }
    Ok(())
}

/// Loads an FVRML scene file (local `Inline`s from its folder, or from `inline_root`),
/// printing warnings on stderr; errors name their file, line and column.
fn load_scene(
    scene_path: &std::path::Path,
    inline_root: Option<&std::path::Path>,
) -> anyhow::Result<model::scene::Scene> {
    use formats::fvrml::{self, LoadOptions};
    use std::path::Path;

    let text = app::files::read_scene_text(scene_path).map_err(anyhow::Error::msg)?;
    let dir = scene_path.parent().unwrap_or(Path::new("")).to_path_buf();
    let root = inline_root.map_or_else(|| dir.clone(), Path::to_path_buf);
    let inlines = app::files::InlineResolver::new(&dir, &root).map_err(anyhow::Error::msg)?;
    let mut resolve = |inline: &str| inlines.read(inline);
    let shown = scene_path.display().to_string();
    let located = |issue: &fvrml::Issue| {
        let file = issue.location.file.as_deref().unwrap_or(&shown);
        let severity = if issue.is_error() { "error" } else { "warning" };
        let (line, column) = (issue.location.line, issue.location.column);
        format!("{file}:{line}:{column}: {severity}: {}", issue.message)
    };
    let loaded = fvrml::load(&text, &LoadOptions::default(), &mut resolve).map_err(|e| {
        let errors: Vec<String> = e.errors().map(located).collect();
        anyhow::anyhow!("{}\n{shown}: cannot load the scene", errors.join("\n"))
    })?;
    for w in &loaded.warnings {
        eprintln!("{}", located(w));
    }
    Ok(loaded.scene)
}

/// `sculpt touch <scene.wrl> --trace IN.csv --out OUT.csv [--device D] [--world-per-metre
/// S]`: the haptic servo run headless over the scene along the path, one force per tick.
/// A bad scene or path is an error naming its file, line and column, and writes nothing.
pub fn touch_command(args: &TouchArgs) -> anyhow::Result<()> {
    use app::touch::path::{MAX_PATH_FILE_BYTES, TouchPath};
    use haptic::container::object::ObjectContainer;

    if let Some(s) = args.world_per_metre
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--world-per-metre must be positive and finite, got {s}");
    }
    let scene = load_scene(&args.scene, args.inline_root.as_deref())?;
    let trace = &args.trace;
    let bytes = app::files::read_bounded(trace, MAX_PATH_FILE_BYTES).map_err(anyhow::Error::msg)?;
    let text = String::from_utf8(bytes)
        .map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", trace.display()))?;
    let path = TouchPath::parse(&text).map_err(|e| anyhow::anyhow!("{}:{e}", trace.display()))?;
    let (containers, refused) = ObjectContainer::from_scene(&scene);
    for (id, why) in &refused {
        eprintln!("{}: object {}: not felt: {why}", args.scene.display(), id.0);
    }
    let caps = args.device.capabilities();
    let zone = app::touch::zone_for(
        &caps,
        app::touch::bounds_of(&containers),
        args.world_per_metre,
    );
    let n_felt = containers.len();
    let replay = app::touch::replay(containers, app::touch::rig(args.device, zone), path);
    std::fs::write(&args.out, replay.to_csv())
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let peak = replay
        .forces_newtons
        .iter()
        .map(|f| f.length())
        .fold(0.0, f64::max);
    let c = zone.center_world;
    println!(
        "device {:?}: {} N, {} N/m; zone: {} scene units per device metre around ({}, {}, {})",
        args.device,
        caps.force_newtons_max,
        caps.stiffness_newtons_per_metre_max,
        zone.world_per_device_metre,
        c.x,
        c.y,
        c.z
    );
    println!("{}", app::touch::zone_depth_text(&caps, &zone));
    println!(
        "{n_felt} objects felt; wrote {} ({} ticks, peak {peak:.3} N)",
        args.out.display(),
        replay.forces_newtons.len()
    );
    Ok(())
}

/// An engine on `store` that reaches no one: loopback, no dialing, no discovery, no LAN.
fn local_engine(store: &std::path::Path) -> anyhow::Result<Engine> {
    let engine = Engine::start(EngineConfig::on_loopback(store), app::clock::now().wall)?;
    for notice in lock(engine.view()).notices() {
        log::warn!("{notice}");
    }
    Ok(engine)
}

/// `sculpt import --store DIR FILE...`: every file is read and planned before anything is
/// authored (the first time before the store is even opened), so a bad file leaves the store
/// as it was; then each op is authored in order and waited for, and what it made printed.
pub fn import_command(args: &ImportArgs) -> anyhow::Result<()> {
    use app::transfer;
    let plan = |path: &PathBuf, next| match &args.inline_root {
        Some(root) => transfer::import_within(path, next, root),
        None => transfer::import(path, next),
    };
    // A dry run with provisional ids: a bad file is refused without opening the store.
    for path in &args.files {
        plan(path, IdSource::first(replication::PeerId([0; 32])))?;
    }
    let engine = local_engine(&args.store)?;
    let mut next = lock(engine.view()).next_object();
    let mut planned = Vec::with_capacity(args.files.len());
    for path in &args.files {
        // Dropping the engine on an error shuts it down, every op on disk.
        let imported = plan(path, next)?;
        next = imported.next;
        planned.push((path, imported));
    }
    let result = author_imports(&engine, planned);
    engine.shutdown();
    result
}

fn author_imports(
    engine: &Engine,
    planned: Vec<(&PathBuf, app::transfer::Imported)>,
) -> anyhow::Result<()> {
    for (path, imported) in planned {
        for warning in &imported.warnings {
            eprintln!("{warning}");
        }
        for (payload, made) in imported.payloads.into_iter().zip(&imported.made) {
            let part = matches!(payload, ShapePayload::Part { .. });
            engine
                .author(payload)?
                .wait()
                .map_err(|e| anyhow::anyhow!("{}: {made}: {e}", path.display()))?;
            // A part is progress, not a result: the object's line follows its last part.
            if !part {
                println!("{}: {made}", path.display());
            }
        }
    }
    Ok(())
}

/// `sculpt export --store DIR [--object ID] [--depth N] OUT`: reads the session's scene
/// through the engine (nothing is authored) and writes it, or one object, to OUT.
pub fn export_command(args: &ExportArgs) -> anyhow::Result<()> {
    use app::transfer;
    if !args.store.join(store::OPS_FILE).is_file() {
        bail!(
            "{} is not a session store (it holds no {}); give the --store of a session",
            args.store.display(),
            store::OPS_FILE
        );
    }
    if formats::registry::FileFormat::of(&args.out).is_none() {
        bail!(
            "{}: unknown file type; export writes .stl, .obj, .glb and .wrl",
            args.out.display()
        );
    }
    let engine = local_engine(&args.store)?;
    let scene = lock(engine.view()).scene().clone();
    engine.shutdown();
    let object = args
        .object
        .map(|id| object_by_number(&scene, id))
        .transpose()?;
    let depth = args
        .depth
        .unwrap_or(render::snapshot::SnapshotSettings::default().depth);
    let report = transfer::export(&scene, object, &args.out, depth)?;
    print!("{report}");
    Ok(())
}

/// The object `id` names: its full id, or the number the window shows (`object N`: the id's
/// low 32 bits, or the N of an object `new:` named `object N`) when exactly one object has it.
fn object_by_number(
    scene: &model::scene::Scene,
    id: u64,
) -> anyhow::Result<model::scene::ObjectId> {
    use model::scene::ObjectId;
    if scene.object(ObjectId(id)).is_some() {
        return Ok(ObjectId(id));
    }
    let matching: Vec<ObjectId> = scene
        .objects()
        .filter(|(o, entry)| {
            o.0 & 0xffff_ffff == id || entry.object.data().name == format!("object {id}")
        })
        .map(|(o, _)| o)
        .collect();
    match matching[..] {
        [one] => Ok(one),
        [] => {
            let known: Vec<String> = scene
                .objects()
                .take(20)
                .map(|(o, entry)| format!("{} \"{}\"", o.0, entry.object.data().name))
                .collect();
            bail!(
                "no object {id} in the session; its objects: {}",
                if known.is_empty() {
                    "none".into()
                } else {
                    known.join(", ")
                }
            )
        }
        _ => bail!("several objects are numbered {id}; give the full id"),
    }
}
