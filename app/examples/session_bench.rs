//! The collaboration path measured end to end: real QUIC on 127.0.0.1 through
//! `app::engine::Engine` (each engine with its own store directory, no LAN, peers connected
//! with `dial`), and the discovery node's memory.
//!
//! 1. Edit to visible: engine A authors `shape:` edits (the `command` module's plan, as the
//!    window and `sculpt peer` author them) of objects created at start; the time until A's
//!    own view, then B's, holds the edit, and until B's scene hash equals A's. Both views
//!    wake one channel through `View::set_waker`.
//! 2. Join: A holds 10^4 ops authored through its engine (nine in ten `shape:` or `colour:`
//!    edits of four objects, one in ten chat); a fresh engine B dials A; the time to B's
//!    connection, its first object, each quarter of the ops, and all ops with A's scene
//!    hash, and the CPU time of B's engine thread; the first object is meshed once as the
//!    window's mesher does.
//! 3. Bytes per op: the same join again, through a UDP relay in this process that counts
//!    every datagram both ways (QUIC headers, TLS, acks, the handshake and presence
//!    included). The engine does not expose the node's counters; the relay sees exactly
//!    what the engine sends.
//! 4. The discovery registry (`replication::net::discovery::registry::Registry`, sans-IO)
//!    fed Register datagrams for 10^4 sessions; its live heap is counted by this program's
//!    global allocator, and `VmRSS` is read as a second figure.
//!
//! `cargo run -p app --release --example session_bench` (about four minutes on the project's
//! 2-core machine, most of it the two joins; `-- --quick` runs 50 edits, 10^3 ops and 10^3
//! sessions in seconds; `-- --ops N` sets the history's length). Every wait is bounded; the
//! program exits non-zero when anything fails to converge in time. The stores live in a
//! fresh directory under the system's temporary directory, removed at the end.

use std::collections::VecDeque;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, sync_channel};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail, ensure};
use app::clock;
use app::command;
use app::engine::{Engine, EngineConfig, Pending, RequestError, Validated, lock, store};
use model::scene::Scene;
use replication::net::discovery::message::{DiscoveryMessage, NO_COOKIE};
use replication::net::discovery::registry::{self, Registry};
use replication::net::invite::Invite;
use replication::{Keypair, Timestamp};
use testkit::alloc::{CountingAlloc, live_bytes};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

/// Objects A creates before the edits (each `shape:` edit goes to the next one in turn).
const N_OBJECTS: usize = 4;
/// The window's default octree depth (`window::DEFAULT_DEPTH`, in the binary).
const WINDOW_DEPTH: u8 = 6;
/// Longest wait for one edit to show on B.
const EDIT_PATIENCE: Duration = Duration::from_secs(20);
/// Longest wait for a join of the whole history.
const JOIN_PATIENCE: Duration = Duration::from_secs(600);
/// Longest wait for authoring the whole history on A.
const AUTHOR_PATIENCE: Duration = Duration::from_secs(1_200);
/// Authoring requests in flight at once (the engine queues at most
/// `MAX_QUEUED_REQUESTS`).
const AUTHOR_WINDOW: usize = 128;
/// The pause between two measured edits, so that each one meets quiet connections.
const EDIT_GAP: Duration = Duration::from_millis(5);

struct Sizes {
    n_edits: usize,
    n_history_ops: usize,
    n_sessions: usize,
}

impl Sizes {
    /// The sizes the arguments ask for: `--quick`, and `--ops N`.
    fn from_args() -> anyhow::Result<Sizes> {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let quick = args.iter().any(|a| a == "--quick");
        let mut sizes = Sizes {
            n_edits: if quick { 50 } else { 500 },
            n_history_ops: if quick { 1_000 } else { 10_000 },
            n_sessions: if quick { 1_000 } else { 10_000 },
        };
        if let Some(i) = args.iter().position(|a| a == "--ops") {
            let n = args.get(i + 1).context("--ops needs a number")?;
            sizes.n_history_ops = n.parse().context("--ops needs a number")?;
        }
        if let Some(other) = args
            .iter()
            .enumerate()
            .find(|(i, a)| *a != "--quick" && *a != "--ops" && (*i == 0 || args[i - 1] != "--ops"))
        {
            bail!("unknown argument {:?}; use --quick and --ops N", other.1);
        }
        Ok(sizes)
    }
}

fn main() -> anyhow::Result<()> {
    let sizes = Sizes::from_args()?;
    let started = clock::now().instant;
    // Before any engine starts: the allocator and VmRSS then see the registry alone.
    discovery_memory(sizes.n_sessions)?;
    let root = Scratch::new()?;
    sessions(&root.0, &sizes)?;
    println!(
        "session_bench: done in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Removes its directory when dropped, also on failure.
struct Scratch(PathBuf);

impl Scratch {
    fn new() -> anyhow::Result<Scratch> {
        let dir = std::env::temp_dir().join(format!("sculpt-session-bench-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Scratch(dir))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Parts 1 to 3: one engine A, then three engines B in turn.
fn sessions(root: &Path, sizes: &Sizes) -> anyhow::Result<()> {
    let a = start(&root.join("a"), None, Vec::new())?;
    let a_addr = lock(a.view())
        .listen_addr()
        .context("A has no listening address")?;
    let objects = create_objects(&a)?;
    edit_latency(&a, a_addr, &root.join("b-edits"), &objects, sizes.n_edits)?;
    fill_history(&a, &objects, sizes.n_history_ops)?;
    let n_ops = lock(a.view()).n_ops();
    let hash = lock(a.view()).scene_hash_hex();
    let direct = join(&a, &root.join("b-join"), a_addr, n_ops, &hash)?;
    println!(
        "join {n_ops} ops, B dials A: {}",
        join_times(&direct, n_ops)
    );
    direct.engine.shutdown();
    mesh_first_object(&direct.first_scene)?;
    let op_bytes = mean_stored_op_bytes(&root.join("a"), n_ops)?;
    let relay = Relay::start(a_addr)?;
    let relayed = join(&a, &root.join("b-relay"), relay.front, n_ops, &hash)?;
    // The catch-up ends when A knows B holds everything (B's acks reached A), as in
    // replication's own catch-up figure.
    let b_id = relayed.engine.peer_id();
    wait_view(&a, "A to hear B's acks", JOIN_PATIENCE, |v| {
        v.peers()
            .iter()
            .any(|p| p.peer == b_id && p.online && p.to_send == 0)
    })?;
    let acked = relayed.t0.elapsed();
    let (to_a, to_b) = (relay.to_a.read(), relay.to_b.read());
    println!(
        "join {n_ops} ops through a counting UDP relay: {}",
        join_times(&relayed, n_ops)
    );
    relayed.engine.shutdown();
    relay.stop();
    let total = to_a.1 + to_b.1;
    println!(
        "UDP payload bytes of that join until A heard B's last ack ({:.0} ms): B->A {} ({} \
         datagrams), A->B {} ({} datagrams); {:.1} bytes per op both ways, {:.3} per byte of \
         encoded op (mean op {:.1} B in A's store)",
        ms(acked),
        to_a.1,
        to_a.0,
        to_b.1,
        to_b.0,
        total as f64 / n_ops as f64,
        total as f64 / (op_bytes * n_ops as f64),
        op_bytes,
    );
    a.shutdown();
    Ok(())
}

fn start(dir: &Path, invite: Option<Invite>, dial: Vec<SocketAddr>) -> anyhow::Result<Engine> {
    let mut config = EngineConfig::on_loopback(dir);
    config.invite = invite;
    config.network.dial = dial;
    Ok(Engine::start(config, clock::now().wall)?)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Waits, at most `patience`, until `done` holds for the engine's view, polling.
fn wait_view(
    engine: &Engine,
    what: &str,
    patience: Duration,
    mut done: impl FnMut(&mut app::engine::View) -> bool,
) -> anyhow::Result<()> {
    let deadline = clock::now().instant + patience;
    while !done(&mut lock(engine.view())) {
        if clock::now().instant > deadline {
            bail!("timed out after {patience:?} waiting for {what}");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(())
}

/// Waits, at most until `deadline`, for the engine's reply to an authoring request.
fn reply(pending: &Pending, deadline: Instant) -> anyhow::Result<()> {
    loop {
        match pending.try_take() {
            Some(Ok(_)) => return Ok(()),
            Some(Err(e)) => bail!("authoring failed: {e}"),
            None if clock::now().instant > deadline => bail!("no authoring reply in time"),
            None => std::thread::sleep(Duration::from_micros(200)),
        }
    }
}

/// Plans one command line against A's view, as `sculpt peer --command` does.
fn plan(engine: &Engine, line: &str, selected: Option<u64>) -> anyhow::Result<Validated> {
    let parsed = command::parse(line).context("an empty line")?;
    let view = lock(engine.view());
    command::plan(parsed, &view, selected)
        .map(|p| p.payload)
        .map_err(|e| anyhow::anyhow!("{line}: {e}"))
}

/// `new:` objects on A, each waited for (the next object id comes from the view).
fn create_objects(a: &Engine) -> anyhow::Result<Vec<u64>> {
    for i in 0..N_OBJECTS {
        let line = format!("new: 0.{}-sqrt(x^2+y^2+z^2)", 5 + i);
        let payload = plan(a, &line, None)?;
        reply(
            &a.author_validated(payload)?,
            clock::now().instant + EDIT_PATIENCE,
        )?;
        wait_view(a, "A's new object", EDIT_PATIENCE, |v| v.n_ops() == i + 1)?;
    }
    let objects: Vec<u64> = lock(a.view())
        .scene()
        .objects()
        .map(|(id, _)| id.0)
        .collect();
    ensure!(
        objects.len() == N_OBJECTS,
        "A has {} objects",
        objects.len()
    );
    Ok(objects)
}

/// A channel woken by each engine after each change of its view (coalesced: at most one
/// signal waits), so that a wait ends as soon as either view changes.
fn wake_on_change(engines: &[&Engine]) -> Receiver<()> {
    let (tx, rx) = sync_channel(1);
    for engine in engines {
        let tx = tx.clone();
        lock(engine.view()).set_waker(Box::new(move || {
            let _ = tx.try_send(());
        }));
    }
    rx
}

/// Waits for the next wake, but at most `poll` (for changes no waker reports, such as a
/// new connection); false when `deadline` passed.
fn next_wake(wakes: &Receiver<()>, deadline: Instant, poll: Duration) -> anyhow::Result<bool> {
    let now = clock::now().instant;
    if now > deadline {
        return Ok(false);
    }
    match wakes.recv_timeout(poll.min(deadline - now)) {
        Ok(()) | Err(RecvTimeoutError::Timeout) => Ok(true),
        Err(RecvTimeoutError::Disconnected) => bail!("the engine stopped"),
    }
}

/// Nearest-rank percentiles and the maximum, in milliseconds.
fn summary(mut samples: Vec<Duration>) -> String {
    samples.sort();
    let n = samples.len();
    let rank = |p: f64| samples[((p * n as f64).ceil() as usize).clamp(1, n) - 1];
    format!(
        "p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        ms(rank(0.50)),
        ms(rank(0.99)),
        ms(samples[n - 1]),
    )
}

#[derive(Default)]
struct EditTimes {
    on_a: Vec<Duration>,
    on_b: Vec<Duration>,
    same_hash: Vec<Duration>,
}

/// Part 1: `n_edits` geometry edits on A, each timed until B shows it.
fn edit_latency(
    a: &Engine,
    a_addr: SocketAddr,
    dir: &Path,
    objects: &[u64],
    n_edits: usize,
) -> anyhow::Result<()> {
    let b = start(dir, Some(a.invite().clone()), vec![a_addr])?;
    let first = lock(a.view()).scene_hash_hex();
    wait_view(&b, "B to hold A's objects", JOIN_PATIENCE, |v| {
        v.n_ops() == N_OBJECTS && v.scene_hash_hex() == first
    })?;
    let wakes = wake_on_change(&[a, &b]);
    let mut times = EditTimes::default();
    for edit_idx in 0..n_edits {
        let object = objects[edit_idx % objects.len()];
        let line = format!("shape: 0.{:03}-sqrt(x^2+y^2+z^2)", 400 + edit_idx % 500);
        let payload = plan(a, &line, Some(object))?;
        one_edit(a, &b, &wakes, payload, &mut times)?;
        std::thread::sleep(EDIT_GAP);
    }
    println!(
        "edit to visible on B ({n_edits} shape: edits; B's view holds the op): {}",
        summary(times.on_b)
    );
    println!(
        "edit to the same scene hash on B as on A ({n_edits} edits): {}",
        summary(times.same_hash)
    );
    println!(
        "edit to visible on A itself (validated, signed, fsynced, folded; {n_edits} edits): {}",
        summary(times.on_a)
    );
    b.shutdown();
    Ok(())
}

/// One edit: authored on A, timed until A's view, then B's view, hold it, and until B's
/// scene hash equals A's.
fn one_edit(
    a: &Engine,
    b: &Engine,
    wakes: &Receiver<()>,
    payload: Validated,
    times: &mut EditTimes,
) -> anyhow::Result<()> {
    let (a_before, b_before) = (lock(a.view()).n_ops(), lock(b.view()).n_ops());
    while wakes.try_recv().is_ok() {}
    let t0 = clock::now().instant;
    let deadline = t0 + EDIT_PATIENCE;
    let pending = a.author_validated(payload)?;
    let (mut on_a, mut on_b) = (None, None);
    loop {
        if on_a.is_none() && lock(a.view()).n_ops() > a_before {
            on_a = Some(t0.elapsed());
        }
        if on_b.is_none() && lock(b.view()).n_ops() > b_before {
            on_b = Some(t0.elapsed());
        }
        if let (Some(on_a), Some(on_b)) = (on_a, on_b) {
            times.on_a.push(on_a);
            times.on_b.push(on_b);
            break;
        }
        ensure!(
            next_wake(wakes, deadline, EDIT_PATIENCE)?,
            "an edit did not reach both views in time"
        );
    }
    reply(&pending, deadline)?;
    let target = lock(a.view()).scene_hash_hex();
    while lock(b.view()).scene_hash_hex() != target {
        ensure!(
            next_wake(wakes, deadline, EDIT_PATIENCE)?,
            "B's scene hash did not reach A's in time"
        );
    }
    times.same_hash.push(t0.elapsed());
    Ok(())
}

/// Authors ops on A until it holds `n_total`: nine in ten are `shape:` or `colour:` edits of
/// the objects in turn, one in ten a chat line; up to [`AUTHOR_WINDOW`] requests in flight.
fn fill_history(a: &Engine, objects: &[u64], n_total: usize) -> anyhow::Result<()> {
    let n_have = lock(a.view()).n_ops();
    let t0 = clock::now().instant;
    let deadline = t0 + AUTHOR_PATIENCE;
    let mut in_flight = VecDeque::with_capacity(AUTHOR_WINDOW);
    for op_idx in n_have..n_total {
        let line = match op_idx % 10 {
            9 => format!("line {op_idx} of the chat, about the handle on the left"),
            4 => format!("colour: 0.{}, 0.3, 0.2", op_idx % 10),
            _ => format!("shape: 0.{:03}-sqrt(x^2+y^2+z^2)", 400 + op_idx % 500),
        };
        let payload = plan(a, &line, Some(objects[op_idx % objects.len()]))?;
        if in_flight.len() == AUTHOR_WINDOW
            && let Some(oldest) = in_flight.pop_front()
        {
            reply(&oldest, deadline)?;
        }
        match a.author_validated(payload) {
            Ok(pending) => in_flight.push_back(pending),
            Err(RequestError::Busy) => bail!("the engine's queue is full"),
            Err(e) => bail!("{e}"),
        }
    }
    for pending in in_flight {
        reply(&pending, deadline)?;
    }
    wait_view(a, "A's history", EDIT_PATIENCE, |v| v.n_ops() == n_total)?;
    let secs = t0.elapsed().as_secs_f64();
    let n_authored = n_total - n_have;
    println!(
        "authoring {n_authored} ops through A's engine (plan, validate, sign, fsync, fold): \
         {secs:.1} s, {:.0} ops/s",
        n_authored as f64 / secs
    );
    Ok(())
}

/// The mean encoded op in A's store file: its size less the file header (`SCULPTOPS` and a
/// version byte) and each record's head (`[u32 len][blake3/16]`), per op.
fn mean_stored_op_bytes(dir: &Path, n_ops: usize) -> anyhow::Result<f64> {
    const FILE_HEADER_BYTES: u64 = 10;
    const RECORD_HEAD_BYTES: u64 = 20;
    let path = dir.join(store::OPS_FILE);
    let len = std::fs::metadata(&path)
        .with_context(|| format!("reading {}", path.display()))?
        .len();
    let ops = len - FILE_HEADER_BYTES - RECORD_HEAD_BYTES * n_ops as u64;
    Ok(ops as f64 / n_ops as f64)
}

struct Joined {
    engine: Engine,
    /// When B was started.
    t0: Instant,
    started: Duration,
    connected: Duration,
    first_object: Duration,
    first_scene: Scene,
    /// When B held a quarter, half and three quarters of the ops.
    quarters: [Duration; 3],
    all: Duration,
    /// CPU seconds of B's engine thread during the join (Linux).
    cpu_secs: Option<f64>,
}

/// Parts 2 and 3: a fresh engine B dials `dial` (A, or the relay in front of it); times to
/// its first object and to A's whole history with A's scene hash. B is returned running.
fn join(
    a: &Engine,
    dir: &Path,
    dial: SocketAddr,
    n_ops: usize,
    hash: &str,
) -> anyhow::Result<Joined> {
    let engine_threads = engine_thread_cpu();
    let t0 = clock::now().instant;
    let deadline = t0 + JOIN_PATIENCE;
    let b = start(dir, Some(a.invite().clone()), vec![dial])?;
    let started = t0.elapsed();
    let wakes = wake_on_change(&[&b]);
    let (mut connected, mut first) = (None, None);
    let mut quarters = [None; 3];
    let all = loop {
        {
            let mut view = lock(b.view());
            if connected.is_none() && view.n_online() > 0 {
                connected = Some(t0.elapsed());
            }
            if first.is_none() && !view.scene().is_empty() {
                first = Some((t0.elapsed(), view.scene().clone()));
            }
            for (quarter_idx, at) in quarters.iter_mut().enumerate() {
                if at.is_none() && view.n_ops() * 4 >= n_ops * (quarter_idx + 1) {
                    *at = Some(t0.elapsed());
                }
            }
            // The hash only once every op is there: it would hold B's view lock meanwhile.
            if view.n_ops() == n_ops && view.scene_hash_hex() == hash {
                break t0.elapsed();
            }
        }
        // The waker reports scene changes, not the connection: poll for that every ms.
        ensure!(
            next_wake(&wakes, deadline, Duration::from_millis(1))?,
            "B did not catch up within {JOIN_PATIENCE:?}"
        );
    };
    // B's engine thread is the one that was not there before.
    let cpu_secs = engine_thread_cpu()
        .into_iter()
        .find(|(tid, _)| !engine_threads.iter().any(|(old, _)| old == tid))
        .map(|(_, secs)| secs);
    let (first_object, first_scene) = first.context("B never showed an object")?;
    Ok(Joined {
        engine: b,
        t0,
        started,
        connected: connected.context("B never showed a connection")?,
        first_object,
        first_scene,
        quarters: quarters.map(|q| q.unwrap_or(all)),
        all,
        cpu_secs,
    })
}

/// A join in words: its times, and the CPU its engine thread used.
fn join_times(joined: &Joined, n_ops: usize) -> String {
    let [q1, q2, q3] = joined.quarters.map(ms);
    let cpu = joined.cpu_secs.map_or_else(String::new, |s| {
        format!("; B's engine thread used {s:.1} s of CPU")
    });
    format!(
        "engine started {:.1} ms, connected {:.1} ms, first object {:.1} ms, 1/4 of the ops \
         {q1:.0} ms, 1/2 {q2:.0} ms, 3/4 {q3:.0} ms, all ops with A's scene hash {:.0} ms \
         ({:.0} ops/s){cpu}",
        ms(joined.started),
        ms(joined.connected),
        ms(joined.first_object),
        ms(joined.all),
        n_ops as f64 / joined.all.as_secs_f64(),
    )
}

/// Meshes one object of the first scene B showed, as the window's mesher does (a one-object
/// scene through `render::snapshot::build` at the window's default depth).
fn mesh_first_object(scene: &Scene) -> anyhow::Result<()> {
    let (id, entry) = scene.objects().next().context("no object to mesh")?;
    let mut object = entry.object.clone();
    let t0 = clock::now().instant;
    object.prepare();
    let mut one = Scene::new();
    one.insert_object(id, object, None)?;
    let settings = render::snapshot::SnapshotSettings {
        depth: WINDOW_DEPTH,
        ..render::snapshot::SnapshotSettings::default()
    };
    let built = render::snapshot::build(&one, &settings)?;
    let secs = t0.elapsed().as_secs_f64();
    let n_triangles: usize = built.objects.iter().map(|o| o.n_triangles).sum();
    ensure!(n_triangles > 0, "the first object meshed to nothing");
    println!(
        "meshing B's first object at depth {WINDOW_DEPTH} (render::snapshot::build, as the \
         window's mesher): {:.1} ms, {n_triangles} triangles",
        secs * 1e3
    );
    Ok(())
}

/// Datagrams and bytes one way through the relay.
#[derive(Default)]
struct Count {
    datagrams: AtomicU64,
    bytes: AtomicU64,
}

impl Count {
    fn add(&self, bytes: usize) {
        self.datagrams.fetch_add(1, Ordering::Relaxed);
        self.bytes.fetch_add(bytes as u64, Ordering::Relaxed);
    }

    fn read(&self) -> (u64, u64) {
        (
            self.datagrams.load(Ordering::Relaxed),
            self.bytes.load(Ordering::Relaxed),
        )
    }
}

/// A UDP relay on 127.0.0.1 in front of A for one client: what reaches `front` goes to A
/// from `upstream`, and A's answers go back to the client; every datagram is counted.
struct Relay {
    front: SocketAddr,
    to_a: Arc<Count>,
    to_b: Arc<Count>,
    stop: Arc<AtomicBool>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

/// How often a relay thread looks at its stop flag.
const RELAY_POLL: Duration = Duration::from_millis(50);
/// Larger than any UDP datagram.
const RELAY_BUFFER_BYTES: usize = 65_536;

impl Relay {
    fn start(a: SocketAddr) -> anyhow::Result<Relay> {
        let front = UdpSocket::bind("127.0.0.1:0")?;
        let upstream = UdpSocket::bind("127.0.0.1:0")?;
        upstream.connect(a)?;
        for socket in [&front, &upstream] {
            socket.set_read_timeout(Some(RELAY_POLL))?;
        }
        let client = Arc::new(std::sync::Mutex::new(None::<SocketAddr>));
        let (to_a, to_b) = (Arc::new(Count::default()), Arc::new(Count::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let forward_up = {
            let (front, upstream) = (front.try_clone()?, upstream.try_clone()?);
            let (client, count, stop) = (client.clone(), to_a.clone(), stop.clone());
            move || {
                let mut buf = vec![0; RELAY_BUFFER_BYTES];
                while !stop.load(Ordering::Relaxed) {
                    if let Ok((n, from)) = front.recv_from(&mut buf) {
                        *client.lock().unwrap_or_else(|e| e.into_inner()) = Some(from);
                        count.add(n);
                        let _ = upstream.send(&buf[..n]);
                    }
                }
            }
        };
        let forward_down = {
            let front_send = front.try_clone()?;
            let (count, stop) = (to_b.clone(), stop.clone());
            move || {
                let mut buf = vec![0; RELAY_BUFFER_BYTES];
                while !stop.load(Ordering::Relaxed) {
                    if let Ok(n) = upstream.recv(&mut buf) {
                        let to = *client.lock().unwrap_or_else(|e| e.into_inner());
                        if let Some(to) = to {
                            count.add(n);
                            let _ = front_send.send_to(&buf[..n], to);
                        }
                    }
                }
            }
        };
        let threads = vec![
            std::thread::Builder::new()
                .name("relay-to-a".into())
                .spawn(forward_up)?,
            std::thread::Builder::new()
                .name("relay-to-b".into())
                .spawn(forward_down)?,
        ];
        Ok(Relay {
            front: front.local_addr()?,
            to_a,
            to_b,
            stop,
            threads,
        })
    }

    fn stop(self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads {
            let _ = thread.join();
        }
    }
}

/// Resident memory of this process in KiB, from `/proc/self/status` (Linux).
fn vm_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// The first timestamp the registry sees.
const REGISTRY_T0: Timestamp = Timestamp(1_795_355_107_000_000);
/// Between two Register datagrams.
const REGISTER_GAP_MICROS: u64 = 1_000;

/// Registers `n_sessions` sessions (one peer, or two in every other session), each
/// registration from its own source IP and in two datagrams, [`REGISTER_GAP_MICROS`] apart:
/// the first draws the server's Challenge, the second echoes its cookie, signed by the peer.
/// Returns the datagrams sent.
fn register_sessions(registry: &mut Registry, n_sessions: usize) -> anyhow::Result<u32> {
    let mut n_datagrams: u32 = 0;
    let mut n_registrations: u32 = 0;
    for session_idx in 0..n_sessions {
        let mut discovery_id = [0xd1; 16];
        discovery_id[..8].copy_from_slice(&(session_idx as u64).to_le_bytes());
        for peer_idx in 0..1 + session_idx % 2 {
            let mut seed = [0x5e; 32];
            seed[..8].copy_from_slice(&(session_idx as u64).to_be_bytes());
            seed[8] = peer_idx as u8;
            let key = Keypair::from_seed(seed);
            let port = 7_000 + peer_idx as u16;
            // 10.0.0.1 and up: one source per registration, so no source's limit is reached.
            let from = SocketAddr::from((
                std::net::Ipv4Addr::from(0x0a00_0001 + n_registrations),
                40_000,
            ));
            n_registrations += 1;
            let mut cookie = NO_COOKIE;
            for attempt in 0..2 {
                let datagram =
                    DiscoveryMessage::register(&key, discovery_id, port, cookie).encode();
                let now =
                    REGISTRY_T0.saturating_add_micros(u64::from(n_datagrams) * REGISTER_GAP_MICROS);
                n_datagrams += 1;
                let reply = registry.handle_datagram(now, from, &datagram);
                while registry.poll_transmit().is_some() {}
                let reply = reply
                    .as_deref()
                    .map(DiscoveryMessage::decode)
                    .transpose()
                    .map_err(|e| anyhow::anyhow!("a reply that does not decode: {e}"))?;
                match (attempt, reply) {
                    (0, Some(DiscoveryMessage::Challenge { cookie: c })) => cookie = c,
                    (1, Some(DiscoveryMessage::Peers(_))) => {}
                    (_, reply) => anyhow::bail!(
                        "the registry answered {reply:?} to registration attempt {attempt} ({:?})",
                        registry.stats()
                    ),
                }
            }
        }
    }
    Ok(n_datagrams)
}

/// Part 4: a discovery registry fed `n_sessions` sessions; its heap and the process's
/// resident memory before and after.
fn discovery_memory(n_sessions: usize) -> anyhow::Result<()> {
    // A fixed cookie key: the figures do not depend on it.
    let mut registry = Registry::new([0x42; 32]);
    let (heap_before, rss_before) = (live_bytes(), vm_rss_kib());
    let n_datagrams = register_sessions(&mut registry, n_sessions)?;
    let end = REGISTRY_T0.saturating_add_micros(u64::from(n_datagrams) * REGISTER_GAP_MICROS);
    let heap_held = live_bytes() - heap_before;
    let rss_held = vm_rss_kib()
        .zip(rss_before)
        .map(|(after, before)| after - before);
    let n_held = n_sessions.min(registry::MAX_SESSIONS);
    let n_registrations: usize = (0..n_held).map(|i| 1 + i % 2).sum();
    let stats = registry.stats().clone();
    ensure!(
        registry.n_registrations() == n_registrations,
        "the registry holds {} registrations, not {n_registrations} ({stats:?})",
        registry.n_registrations()
    );
    // Registrations live 60 s (the rate limit is a fixed array, allocated with the registry).
    registry.expire(end.saturating_add_micros(3_000_000));
    let heap_sessions = live_bytes() - heap_before;
    println!(
        "discovery registry: {n_sessions} sessions offered ({n_datagrams} Register datagrams: \
         a cookie round trip per registration, each from its own source IP), {n_held} sessions held (MAX_SESSIONS = {}), \
         {n_registrations} registrations; {} registrations refused as full (answered), {} rate \
         limited",
        registry::MAX_SESSIONS,
        stats.n_full,
        stats.n_rate_limited,
    );
    println!(
        "discovery registry heap: {heap_held} bytes while registering = {:.0} \
         bytes per held session; {heap_sessions} bytes after an expiry pass = {:.0} \
         bytes per held session ({:.0} per registration); VmRSS grew {} KiB = {:.0} bytes per \
         held session",
        heap_held as f64 / n_held as f64,
        heap_sessions as f64 / n_held as f64,
        heap_sessions as f64 / n_registrations as f64,
        rss_held.map_or_else(|| "?".into(), |k| k.to_string()),
        rss_held.map_or(f64::NAN, |k| k as f64 * 1024.0 / n_held as f64),
    );
    Ok(())
}

/// CPU seconds used so far by each thread named `sculpt-engine`, by thread id, from
/// `/proc/self/task/*/stat` (user and system time in the kernel's fixed 100 Hz ticks);
/// empty where that is not readable.
fn engine_thread_cpu() -> Vec<(String, f64)> {
    const TICKS_PER_SEC: f64 = 100.0;
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for task in tasks.flatten() {
        let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
            continue;
        };
        // `pid (comm) state ...`: the name may hold spaces, so split after its last ')'.
        let Some((head, rest)) = stat.rsplit_once(')') else {
            continue;
        };
        if !head.ends_with("(sculpt-engine") {
            continue;
        }
        let fields: Vec<&str> = rest.split_whitespace().collect();
        let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<u64>().ok());
        // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name.
        if let (Some(user), Some(system)) = (ticks(11), ticks(12)) {
            let tid = task.file_name().to_string_lossy().into_owned();
            out.push((tid, (user + system) as f64 / TICKS_PER_SEC));
        }
    }
    out
}
