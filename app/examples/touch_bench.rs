//! The servo in the running app under load: the `sculpt` window touching a 64-object scene
//! with the mouse device (`app::touch::live`), while it draws and a peer streams edits.
//!
//! Engine A (this process, loopback QUIC) authors 64 balls with tension in a 4x4x4 grid, then
//! a `sculpt` window process joins A's session by invite and `--dial`, turns touch on, puts
//! the tool into one ball's surface zone and waits; meanwhile A changes the tension of a
//! random ball every `EDIT_EVERY_MILLIS` (each change is a new snapshot for the window's
//! servo: the feed rebuilds that ball only). At the end the window's state dump gives the
//! servo's tick count, period and compute percentiles, its late ticks, the snapshots taken,
//! and the window's frame times; this program prints them.
//!
//! `cargo build -p app --release --bin sculpt --example touch_bench && \
//!  cargo run -p app --release --example touch_bench` with a display (`DISPLAY`, e.g. Xvfb)
//! and `XDG_RUNTIME_DIR` set; `-- --secs N` sets how long the window touches (default 20).

use std::io::BufRead as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context as _, bail, ensure};
use app::clock;
use app::engine::{Engine, EngineConfig, lock};
use glam::DVec3;
use model::object::{Domain, Formula, Geometry, ObjectData, Physics, Property, Transform};
use rand_core::{RngCore, SeedableRng};
use replication::shape::{IdSource, ShapePayload};

/// Balls per side of the grid (64 in all).
const GRID: usize = 4;
/// Distance between the balls' centres.
const SPACING: f64 = 1.0;
/// Their radius.
const RADIUS: f64 = 0.4;
/// A's tension edits, one every this many milliseconds.
const EDIT_EVERY_MILLIS: u64 = 50;

fn main() -> anyhow::Result<()> {
    let secs: u64 = match std::env::args().skip_while(|a| a != "--secs").nth(1) {
        Some(s) => s.parse().context("--secs N")?,
        None => 20,
    };
    ensure!(
        std::env::var_os("DISPLAY").is_some(),
        "set DISPLAY (for example run Xvfb :95 and DISPLAY=:95)"
    );
    let root = std::env::temp_dir().join(format!("sculpt-touch-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let result = run(&root, secs);
    let _ = std::fs::remove_dir_all(&root);
    result
}

fn ball(i: usize) -> ObjectData {
    let f = |s: &str| Formula::new(s).expect("a fixed formula");
    let (x, y, z) = (i % GRID, i / GRID % GRID, i / (GRID * GRID));
    let centre = DVec3::new(x as f64, y as f64, z as f64) * SPACING;
    ObjectData {
        name: format!("ball {i}"),
        geometry: Some(Geometry::implicit_in(
            f(&format!("{RADIUS}-sqrt(x^2+y^2+z^2)")),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2 * RADIUS)),
        )),
        physics: Physics {
            tension: Some(Property::new(f("0.8"))),
            zone_depth: Some(Property::new(f("0.05"))),
            density: Some(Property::new(f("0.3"))),
            ..Physics::default()
        }
        .into(),
        transform: Transform::translate(centre),
        ..ObjectData::default()
    }
}

fn run(root: &Path, secs: u64) -> anyhow::Result<()> {
    let mut config = EngineConfig::on_loopback(&root.join("a"));
    config.name = Some("streamer".into());
    let a = Engine::start(config, clock::now().wall)?;
    let n = GRID * GRID * GRID;
    let first = lock(a.view()).next_object();
    let sources: Vec<IdSource> = (0..n as u64)
        .map(|k| first.skip(k))
        .collect::<Option<_>>()
        .context("object ids")?;
    let ids: Vec<u64> = sources.iter().map(IdSource::id).collect();
    for (i, source) in sources.iter().enumerate() {
        let payload = source.create(ball(i), None);
        a.author(payload)?
            .wait()
            .map_err(|e| anyhow::anyhow!("create: {e}"))?;
    }
    let addr = lock(a.view()).listen_addr().context("A's address")?;
    let invite = a.invite().to_string();
    let dump = root.join("window.json");
    let sculpt = sculpt_binary()?;
    // The tool rests 0.02 into ball 0's surface zone, from above.
    let at = format!("touch-at: 0,{},0", RADIUS - 0.02);
    let mut window = Command::new(&sculpt)
        .args(["--store", path_str(&root.join("b"))?, "--invite", &invite])
        .args(["--dial", &addr.to_string(), "--no-lan", "--wait-ops"])
        .arg(n.to_string())
        .args(["--command", "touch: on", "--command", &at])
        .args(["--command", &format!("wait-secs: {secs}")])
        .args(["--dump-state", path_str(&dump)?, "--exit-when-idle"])
        .args(["--size", "1280x800"])
        .stdout(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start {}", sculpt.display()))?;
    // The window's scripted steps wait for it to be idle, so the stream runs only while its
    // last step (the wait) does: from its start, for `secs` seconds.
    let stdout = window.stdout.take().context("the window's stdout")?;
    let (started_tx, started) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("window-stdout".into())
        .spawn(move || {
            for line in std::io::BufReader::new(stdout)
                .lines()
                .map_while(Result::ok)
            {
                if line.starts_with("sculpt: scripted wait:") {
                    let _ = started_tx.send(());
                }
            }
        })?;
    started
        .recv_timeout(Duration::from_secs(120))
        .context("the window never reached its wait")?;
    let stop_at = clock::now().instant + Duration::from_secs(secs);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut n_edits = 0u64;
    while clock::now().instant < stop_at {
        let object = ids[(rng.next_u64() % n as u64) as usize];
        let tension = 0.2 + 0.6 * (rng.next_u64() % 1000) as f64 / 1000.0;
        let payload = ShapePayload::Set {
            object,
            field: Box::new(model::object::Field::Tension(Some(Property::new(
                Formula::new(format!("{tension:.3}")).context("a tension")?,
            )))),
        };
        a.author(payload)?
            .wait()
            .map_err(|e| anyhow::anyhow!("edit: {e}"))?;
        n_edits += 1;
        std::thread::sleep(Duration::from_millis(EDIT_EVERY_MILLIS));
    }
    let status = window.wait()?;
    ensure!(status.success(), "the window failed: {status}");
    let state: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&dump)?)?;
    let touch = &state["touch"];
    if !touch.is_object() {
        bail!("the window's dump has no touch state: {state}");
    }
    println!(
        "{n} objects, {n_edits} tension edits streamed by the peer (one every {EDIT_EVERY_MILLIS} ms), {secs} s touched"
    );
    println!(
        "servo: {} ticks, {} late, {} snapshots taken; touching object {}; force {}",
        touch["n_ticks"],
        touch["n_overruns"],
        touch["n_scenes_taken"],
        touch["top_id"],
        touch["force"]
    );
    println!(
        "servo period µs (p50, p99, p99.9, max): {}",
        touch["period_micros"]
    );
    println!(
        "servo tick compute µs (p50, p99, p99.9, max): {}",
        touch["compute_micros"]
    );
    println!(
        "window: {} frames, frame interval ms {}",
        state["frames"], state["frame_interval_ms"]
    );
    a.shutdown();
    Ok(())
}

fn path_str(p: &Path) -> anyhow::Result<&str> {
    p.to_str().context("a non-UTF-8 temporary path")
}

/// The `sculpt` binary built beside this example (same profile).
fn sculpt_binary() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .context("the example's directory")?;
    let sculpt = dir.join("sculpt");
    ensure!(
        sculpt.exists(),
        "{} is missing: build it first (cargo build -p app --release --bin sculpt)",
        sculpt.display()
    );
    Ok(sculpt)
}
