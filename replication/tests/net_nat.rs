//! Peers behind two NAT routers meet through a discovery server on a "public" host and then
//! talk directly (UDP hole punching over the QUIC socket), inside network namespaces built by
//! `shared/tools/netns-nat` (two private networks behind masquerading routers, a public
//! segment; nothing leaves the machine). And where one router is a symmetric NAT, both
//! sides say so (`Unreachable`) instead of waiting forever.
//!
//! Each side runs on its own named thread moved into its namespace with `setns(2)`, with its
//! own current-thread tokio runtime, so the test reads every node's log, counters and events
//! directly. Without root, `ip`, `nft` or the tool, each test says why and returns early.

#![allow(clippy::unwrap_used, reason = "test helpers")]
#![expect(
    unsafe_code,
    reason = "setns(2) moves a test thread into a network namespace; std has no wrapper"
)]

mod net_support;

use std::collections::BTreeMap;
use std::fs::File;
use std::net::{Ipv4Addr, SocketAddr};
use std::os::fd::AsRawFd;
use std::os::raw::c_int;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use glam::DVec3;
use model::object::{
    ColorDef, Edit, EditOp, Field, Formula, Geometry, ObjectData, Pose, ToolShape,
};
use net_support::{INVITE, PATIENCE, session_keys};
use replication::net::discovery::message::REGISTER_BYTES;
use replication::net::discovery::registry::RegistryStats;
use replication::net::discovery::{DiscoveredPeer, DiscoveryServer, RendezvousEvent};
use replication::net::node::NodeStats;
use replication::net::{Node, NodeConfig};
use replication::payload::LeaseAction;
use replication::shape::ShapePayload;
use replication::{Keypair, Log, OpId, PeerId};

/// Overrides where the netns-nat tool is (by default `shared/tools/netns-nat` beside the
/// repository).
const TOOL_ENV: &str = "SCULPT_NETNS_NAT";

const CLONE_NEWNET: c_int = 0x4000_0000;

unsafe extern "C" {
    /// `setns(2)` from the C library std already links.
    fn setns(fd: c_int, nstype: c_int) -> c_int;
}

fn tool_dir() -> PathBuf {
    std::env::var_os(TOOL_ENV).map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/tools/netns-nat"),
        PathBuf::from,
    )
}

/// Why namespaces cannot be made here, if they cannot.
fn unavailable(tool: &Path) -> Option<String> {
    if !tool.join("up.sh").is_file() {
        return Some(format!("{} is missing (set {TOOL_ENV})", tool.display()));
    }
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let root = status
        .lines()
        .any(|l| l.starts_with("Uid:") && l.split_whitespace().nth(2) == Some("0"));
    if !root {
        return Some("network namespaces need root".into());
    }
    for (program, flag) in [("ip", "-V"), ("nft", "--version")] {
        let runs = Command::new(program)
            .arg(flag)
            .output()
            .is_ok_and(|o| o.status.success());
        if !runs {
            return Some(format!("`{program}` is not installed"));
        }
    }
    None
}

/// The namespaces of one test; torn down on drop, also when the test fails.
struct Internet {
    tool: PathBuf,
    tag: String,
    vars: BTreeMap<String, String>,
}

impl Internet {
    fn up(tool: &Path, tag: &str) -> Result<Self, String> {
        let mut internet = Self {
            tool: tool.to_owned(),
            tag: tag.to_owned(),
            vars: BTreeMap::new(),
        };
        let output = Command::new("bash")
            .arg(tool.join("up.sh"))
            .arg(tag)
            .output()
            .map_err(|e| e.to_string())?;
        if !output.status.success() {
            return Err(String::from_utf8_lossy(&output.stderr).into_owned());
        }
        internet.vars = String::from_utf8_lossy(&output.stdout)
            .split_whitespace()
            .filter_map(|word| word.split_once('='))
            .map(|(k, v)| (k.to_owned(), v.to_owned()))
            .collect();
        Ok(internet)
    }

    fn var(&self, key: &str) -> &str {
        self.vars.get(key).map_or_else(
            || panic!("up.sh did not print {key}: {:?}", self.vars),
            String::as_str,
        )
    }

    fn ip(&self, key: &str) -> Ipv4Addr {
        self.var(key).parse().unwrap()
    }

    /// Runs `nft ARGS` inside the namespace of the host `ns` (for example a router).
    fn nft(&self, ns: &str, args: &[&str]) {
        let output = Command::new("ip")
            .args(["netns", "exec", ns, "nft"])
            .args(args)
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "nft {args:?} in {ns}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
}

impl Drop for Internet {
    fn drop(&mut self) {
        let _ = Command::new("bash")
            .arg(self.tool.join("down.sh"))
            .arg(&self.tag)
            .output();
    }
}

/// Builds the namespaces, or says why not (then the test returns early).
fn internet(suffix: char) -> Option<Internet> {
    let tool = tool_dir();
    if let Some(why) = unavailable(&tool) {
        eprintln!("skipped: {why}, so NAT traversal is untested here");
        return None;
    }
    let tag = format!("n{}{suffix}", std::process::id() % 10_000);
    match Internet::up(&tool, &tag) {
        Ok(internet) => Some(internet),
        Err(e) => {
            eprintln!(
                "skipped: the namespaces could not be made ({e}), so NAT traversal is untested here"
            );
            None
        }
    }
}

/// Starts a named thread inside the network namespace `ns` (every socket it opens lives
/// there) and runs `f` on it.
fn in_namespace<T: Send + 'static>(
    ns: &str,
    name: &str,
    f: impl FnOnce() -> T + Send + 'static,
) -> std::thread::JoinHandle<T> {
    let path = format!("/var/run/netns/{ns}");
    std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            let file = File::open(&path).unwrap();
            // SAFETY: setns(2) only reads the descriptor, which `file` keeps open for the
            // call, and moves this thread (not the process) into that network namespace.
            let rc = unsafe { setns(file.as_raw_fd(), CLONE_NEWNET) };
            assert_eq!(rc, 0, "setns {path}: {}", std::io::Error::last_os_error());
            f()
        })
        .unwrap()
}

/// Runs a discovery server on the public host; returns its address, its shutdown flag and
/// the thread that returns its counters.
fn start_server(
    internet: &Internet,
) -> (
    SocketAddr,
    Arc<AtomicBool>,
    std::thread::JoinHandle<RegistryStats>,
) {
    let bind = SocketAddr::from((internet.ip("PUB_IP"), 0));
    let (addr_tx, addr_rx) = std::sync::mpsc::channel();
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    let thread = in_namespace(internet.var("PUB_NS"), "discovery-server", move || {
        let server = DiscoveryServer::bind(bind).unwrap();
        addr_tx.send(server.local_addr().unwrap()).unwrap();
        server.run(&flag).unwrap()
    });
    let addr = addr_rx.recv_timeout(PATIENCE).unwrap();
    (addr, shutdown, thread)
}

/// What each side of a pair is after.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Goal {
    /// Hold `n` ops over a direct connection.
    Converge(usize),
    /// Hear that the other side cannot be reached.
    Unreachable,
}

/// One side's orders.
struct Plan {
    seed: u8,
    server: SocketAddr,
    goal: Goal,
    /// Register only once this is set (so the other side is registered first).
    after: Option<Arc<AtomicBool>>,
    /// Set once the server answered this side's registration.
    registered: Arc<AtomicBool>,
    /// Sides done; each keeps its node up until both are, so the other can finish.
    n_done: Arc<AtomicUsize>,
    /// Sides that read their outcome; each shuts its node down only after both did, so no
    /// side reads a connection the other already closed.
    n_read: Arc<AtomicUsize>,
}

/// What one side saw.
#[derive(Debug)]
struct Outcome {
    peer_id: PeerId,
    ids: Vec<OpId>,
    n_op_bytes: usize,
    stats: NodeStats,
    events: Vec<RendezvousEvent>,
}

/// A formula whose text makes an op of a few KiB, so op bytes dwarf registrations.
fn long_formula() -> Formula {
    Formula::new(format!("1 - x^2 - y^2 - z^2{}", " + 0*x".repeat(400))).unwrap()
}

/// The ops one side authors on its own object: a creation with a long formula, a lease, a
/// carve and a colour.
fn workload(seed: u8) -> Vec<ShapePayload> {
    let object = u64::from(seed);
    vec![
        ShapePayload::Create {
            object,
            counter: None,
            data: std::sync::Arc::new(ObjectData {
                name: format!("ball {seed}"),
                geometry: Some(Geometry::implicit(long_formula())),
                ..ObjectData::default()
            }),
            group: None,
        },
        ShapePayload::Lease(LeaseAction::Acquire {
            object,
            strong: false,
            ttl_micros: 60_000_000,
        }),
        ShapePayload::edit(
            object,
            Edit::stamp(
                EditOp::Subtract,
                ToolShape::Sphere { radius: 0.2 },
                Pose::at(DVec3::new(0.5, 0.0, 0.0)),
            ),
        )
        .expect("a valid edit"),
        ShapePayload::Set {
            object,
            field: Box::new(Field::Diffuse(Some(ColorDef::Constant([0.8, 0.2, 0.1])))),
        },
    ]
}

const N_OPS_PER_SIDE: usize = 4;

/// Polls `check` until true; panics with `what` after [`PATIENCE`].
async fn wait_until(what: &str, mut check: impl FnMut() -> bool) {
    let polling = async {
        while !check() {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    };
    if tokio::time::timeout(PATIENCE, polling).await.is_err() {
        panic!("timed out waiting until {what}");
    }
}

/// One side: a node with the fdsl payload, its ops, registration through its own socket,
/// then waiting for its goal while it records the rendezvous events.
async fn run_side(plan: Plan) -> Outcome {
    let keys = session_keys(INVITE);
    let node = Node::<ShapePayload>::spawn(NodeConfig {
        keypair: Keypair::from_seed([plan.seed; 32]),
        keys: keys.clone(),
        listen: SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)),
        log: Log::default(),
        store: None,
        join_from_snapshot: false,
    })
    .unwrap();
    let handle = node.handle;
    for payload in workload(plan.seed) {
        handle.author(payload).await.unwrap();
    }
    if let Some(first) = &plan.after {
        wait_until("the other side registered", || {
            first.load(Ordering::Relaxed)
        })
        .await;
    }
    let mut rendezvous = handle
        .register_with(plan.server, keys.discovery_id())
        .unwrap();
    let mut events = Vec::new();
    let mut reached = false;
    let pursuing = async {
        loop {
            tokio::select! {
                event = rendezvous.events.recv() => {
                    let event = event.expect("the node runs");
                    if matches!(event, RendezvousEvent::Registered { .. }) {
                        plan.registered.store(true, Ordering::Relaxed);
                    }
                    events.push(event);
                }
                () = tokio::time::sleep(Duration::from_millis(20)) => {}
            }
            if !reached {
                reached = match plan.goal {
                    Goal::Converge(n) => {
                        let n_ops = handle.with_peer(|p| p.log().len()).await.unwrap();
                        let n_conns = handle.connected_peers().await.unwrap().len();
                        n_ops == n && n_conns == 1
                    }
                    Goal::Unreachable => events
                        .iter()
                        .any(|e| matches!(e, RendezvousEvent::Unreachable(_))),
                };
                if reached {
                    plan.n_done.fetch_add(1, Ordering::Relaxed);
                }
            }
            if plan.n_done.load(Ordering::Relaxed) == 2 {
                return;
            }
        }
    };
    if tokio::time::timeout(PATIENCE, pursuing).await.is_err() {
        let stats = handle.stats().await.unwrap();
        panic!(
            "peer {} timed out pursuing {:?}; events {events:?}; stats {stats:?}",
            plan.seed, plan.goal
        );
    }
    let (ids, n_op_bytes) = handle
        .with_peer(|p| {
            let entries = p.log().entries();
            let ids: Vec<OpId> = p.log().entries().map(|e| e.op.id()).collect();
            (ids, entries.map(|e| e.op.encoded().len()).sum())
        })
        .await
        .unwrap();
    let stats = handle.stats().await.unwrap();
    plan.n_read.fetch_add(1, Ordering::Relaxed);
    wait_until("both sides read their outcome", || {
        plan.n_read.load(Ordering::Relaxed) == 2
    })
    .await;
    handle.shutdown().await.unwrap();
    Outcome {
        peer_id: handle.peer_id(),
        ids,
        n_op_bytes,
        stats,
        events,
    }
}

/// Runs the two sides (A registers first, then B) in their private namespaces.
fn run_pair(internet: &Internet, server: SocketAddr, goal: Goal) -> (Outcome, Outcome) {
    let a_registered = Arc::new(AtomicBool::new(false));
    let n_done = Arc::new(AtomicUsize::new(0));
    let n_read = Arc::new(AtomicUsize::new(0));
    let side = |seed: u8, after: Option<Arc<AtomicBool>>, registered: Arc<AtomicBool>| {
        let plan = Plan {
            seed,
            server,
            goal,
            after,
            registered,
            n_done: n_done.clone(),
            n_read: n_read.clone(),
        };
        move || {
            tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap()
                .block_on(run_side(plan))
        }
    };
    let a = in_namespace(
        internet.var("A_NS"),
        "peer-a",
        side(1, None, a_registered.clone()),
    );
    let b = in_namespace(
        internet.var("B_NS"),
        "peer-b",
        side(2, Some(a_registered), Arc::new(AtomicBool::new(false))),
    );
    (a.join().unwrap(), b.join().unwrap())
}

fn introduced(events: &[RendezvousEvent]) -> Vec<DiscoveredPeer> {
    events
        .iter()
        .filter_map(|e| match e {
            RendezvousEvent::Introduced { peer } => Some(*peer),
            _ => None,
        })
        .collect()
}

fn found(events: &[RendezvousEvent]) -> Vec<DiscoveredPeer> {
    events
        .iter()
        .filter_map(|e| match e {
            RendezvousEvent::Registered { found, .. } => Some(found.clone()),
            _ => None,
        })
        .flatten()
        .collect()
}

#[test]
fn peers_behind_two_nats_punch_through_and_converge_directly() {
    let Some(internet) = internet('p') else {
        return;
    };
    let (server, shutdown, serving) = start_server(&internet);
    let (a, b) = run_pair(&internet, server, Goal::Converge(2 * N_OPS_PER_SIDE));
    shutdown.store(true, Ordering::Relaxed);
    let server_stats = serving.join().unwrap();
    let (nat1, nat2) = (internet.ip("NAT1_PUB"), internet.ip("NAT2_PUB"));

    // Both hold the same log, in the same order.
    assert_eq!(a.ids.len(), 2 * N_OPS_PER_SIDE);
    assert_eq!(a.ids, b.ids);

    // A registered first and learnt nobody; the server introduced B to it at once, at B's
    // router's public address, and B learnt A at A's router's public address.
    let a_found = found(&a.events);
    assert!(a_found.is_empty(), "{:?}", a.events);
    let b_at = introduced(&a.events);
    assert_eq!(b_at.len(), 1, "{:?}", a.events);
    assert_eq!((b_at[0].peer, b_at[0].addr.ip()), (b.peer_id, nat2.into()));
    let a_at = found(&b.events);
    assert_eq!(a_at.len(), 1, "{:?}", b.events);
    assert_eq!((a_at[0].peer, a_at[0].addr.ip()), (a.peer_id, nat1.into()));

    // The one connection each keeps runs between the two routers' public addresses: a
    // direct path through both NATs, nothing relayed by the discovery host.
    assert_eq!(a.stats.connections.len(), 1, "{:?}", a.stats);
    assert_eq!(b.stats.connections.len(), 1, "{:?}", b.stats);
    assert_eq!(a.stats.connections[0].addr, b_at[0].addr);
    assert_eq!(b.stats.connections[0].addr, a_at[0].addr);
    for (side, stats) in [("A", &a.stats), ("B", &b.stats)] {
        assert_eq!(stats.n_unreachable, 0, "{side}: {stats:?}");
        assert!(stats.n_registrations >= 1, "{side}: {stats:?}");
        assert_eq!(stats.n_stray_discovery, 0, "{side}: {stats:?}");
        assert_eq!(stats.n_discovery_replies_dropped, 0, "{side}: {stats:?}");
    }
    assert!(a.stats.n_introductions >= 1, "{:?}", a.stats);
    assert!(a.stats.n_punched + b.stats.n_punched >= 1);

    // The server saw registrations and nothing else: every datagram it received was a
    // well-formed request of exactly REGISTER_BYTES, which it challenged (the first of each
    // side) or accepted; it never sent more than it received; and all it saw is less than
    // the ops each peer now holds.
    let s = &server_stats;
    assert_eq!(s.n_bad_input(), 0, "{s:?}");
    assert!(s.n_datagrams_received >= 4, "{s:?}");
    assert!(s.n_challenged >= 2, "{s:?}");
    assert_eq!(
        s.n_registered + s.n_challenged,
        s.n_datagrams_received,
        "{s:?}"
    );
    assert_eq!(
        s.n_bytes_received,
        s.n_datagrams_received * REGISTER_BYTES as u64,
        "{s:?}"
    );
    assert!(s.n_introductions >= 1, "{s:?}");
    assert!(s.n_bytes_sent <= s.n_bytes_received, "{s:?}");
    assert!(
        (s.n_bytes_received as usize) < a.n_op_bytes,
        "the server received {} bytes, the ops are {} bytes",
        s.n_bytes_received,
        a.n_op_bytes
    );
    eprintln!(
        "direct path {} <-> {}; server received {} bytes in {} datagrams and sent {}; \
         ops {} bytes; the connection carried {} bytes from A",
        a_at[0].addr,
        b_at[0].addr,
        s.n_bytes_received,
        s.n_datagrams_received,
        s.n_bytes_sent,
        a.n_op_bytes,
        a.stats.connections[0].udp_bytes_sent
    );
}

#[test]
fn a_symmetric_nat_is_reported_as_unreachable_not_waited_on() {
    let Some(internet) = internet('s') else {
        return;
    };
    // Router 2 becomes a symmetric NAT: a fresh random public port per destination, so the
    // port the server saw is not the one B's packets to A come from.
    let router = format!("{}-r2", internet.tag);
    internet.nft(&router, &["flush", "chain", "ip", "nat", "post"]);
    internet.nft(
        &router,
        &[
            "add",
            "rule",
            "ip",
            "nat",
            "post",
            "oifname",
            "wan",
            "masquerade",
            "fully-random",
        ],
    );
    let (server, shutdown, serving) = start_server(&internet);
    let (a, b) = run_pair(&internet, server, Goal::Unreachable);
    shutdown.store(true, Ordering::Relaxed);
    let server_stats = serving.join().unwrap();
    for (side, outcome) in [("A", &a), ("B", &b)] {
        let unreachable: Vec<_> = outcome
            .events
            .iter()
            .filter_map(|e| match e {
                RendezvousEvent::Unreachable(u) => Some(u),
                _ => None,
            })
            .collect();
        assert_eq!(unreachable.len(), 1, "{side}: {:?}", outcome.events);
        let text = unreachable[0].to_string();
        assert!(
            text.contains("symmetric NAT") && text.contains("--listen and --dial"),
            "{side}: {text}"
        );
        assert!(
            outcome.stats.n_unreachable >= 1,
            "{side}: {:?}",
            outcome.stats
        );
        assert_eq!(outcome.stats.n_punched, 0, "{side}: {:?}", outcome.stats);
        assert!(outcome.stats.connections.is_empty(), "{side}");
        assert_eq!(outcome.ids.len(), N_OPS_PER_SIDE, "{side}: nothing crossed");
        eprintln!("{side} says: {text}");
    }
    assert_eq!(server_stats.n_bad_input(), 0, "{server_stats:?}");
}
