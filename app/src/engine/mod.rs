//! The session engine: the one driver under every face of the program (the window, the
//! headless peer, tests).
//!
//! It owns this peer's identity, the store directory, the QUIC node (`replication::net`)
//! and the fold of the log into a scene. All IO (sockets, fsync) runs on one named thread,
//! `sculpt-engine`, with a current-thread tokio runtime; faces talk to it through
//! [`Engine`] (requests on a bounded queue) and read the published [`View`] under a short
//! lock. The view is folded by the node's observer as each insertion is stored, and names the
//! objects each change touched, so a face re-meshes or re-feels only those.

pub mod presence;
pub mod store;
pub mod view;

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::mpsc as std_mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use replication::membership::FOUNDER_NONCE_BYTES;
use replication::net::admission::AdmissionError;
use replication::net::discovery::dnssd::{self, Announcement, DnsSd, DnsSdConfig, LanSession};
use replication::net::invite::Invite;
use replication::net::node::{DialError, DisconnectReason, NodeConfig, NodeEvent, NodeHandle};
use replication::net::{Node, SessionKeys};
use replication::shape::ShapePayload;
use replication::store::OpStore;
use replication::sync::ephemeral::PRESENCE_CHANNEL;
use replication::sync::state::CloseReason;
use replication::{Keypair, Log, OpId, PeerId, Timestamp};

use replication::sync::ephemeral::presence::Presence;
pub use view::{
    ChatRow, HistoryRow, JoinRow, PeerRow, Rejection, SceneCheckRow, SharedView, View, lock,
};

/// Requests queued from faces to the engine thread before `try_*` calls report it busy.
pub const MAX_QUEUED_REQUESTS: usize = 256;
/// Lines of network news a view keeps (the latest ones).
pub const MAX_NEWS_LINES: usize = 200;
/// How often a `--dial` address that is not connected is dialed again.
pub const DIAL_RETRY_MILLIS: u64 = 2_000;
/// A `--dial` dial still waiting for its handshake after this long (1 s) is begun afresh when
/// the network seems back ([`NodeHandle::resumed`]): QUIC sends a lost first packet again
/// only after about a second (three times its first round-trip guess of 333 ms), then two,
/// four..., while a handshake and admission over a path of round trips under half a second
/// are done by then, so a younger dial is left to finish.
pub const DIAL_AFRESH_AFTER_MILLIS: u64 = 1_000;
/// How often peers' round-trip times and addresses are refreshed in the view.
pub const PEER_REFRESH_MILLIS: u64 = 500;
/// Peers kept in the view after they left (the oldest offline ones are forgotten first).
pub const MAX_PEER_ROWS: usize = 64;
/// How often this peer's presence is sent again even when unchanged (for peers that
/// connected since), in milliseconds.
pub const PRESENCE_REPEAT_MILLIS: u64 = 1_000;
/// How long a shutdown waits for connected peers to receive what they lack.
pub const SHUTDOWN_FLUSH_MILLIS: u64 = 2_000;
/// How long [`Engine::start`] waits for the engine thread to bind its socket.
pub const START_TIMEOUT_SECS: u64 = 20;
/// The engine thread's stack. A backstop only: what it decodes, folds and compiles (ops,
/// snapshots, formulas, scene files from peers) is bounded to fit 256 KiB (fdsl's and
/// replication's small-stack tests), and this margin keeps an unforeseen deep path from
/// aborting every peer at the default 2 MiB (8 MiB, as the main thread has).
pub const ENGINE_STACK_BYTES: usize = 8 << 20;

/// How the engine reaches other peers.
#[derive(Clone, Debug)]
pub struct Network {
    /// The UDP address the QUIC node binds (port 0 picks one).
    pub listen: SocketAddr,
    /// Peers to dial, and dial again whenever not connected.
    pub dial: Vec<SocketAddr>,
    /// A discovery node to register with.
    pub discovery: Option<SocketAddr>,
    /// Announce on and listen to the LAN.
    pub lan: bool,
}

impl Default for Network {
    fn default() -> Self {
        Self {
            listen: (std::net::Ipv4Addr::UNSPECIFIED, 0).into(),
            dial: Vec::new(),
            discovery: None,
            lan: false,
        }
    }
}

/// What the engine needs to start.
#[derive(Clone, Debug)]
pub struct EngineConfig {
    /// The session's store directory.
    pub store: PathBuf,
    /// The session to join; `None` opens the store's own session (or makes a new one). A
    /// store with nothing in it joins from a snapshot of the first peer it meets.
    pub invite: Option<Invite>,
    /// How to reach other peers.
    pub network: Network,
    /// The demo scene to author when this start makes a new session.
    pub demo: Option<&'static crate::demos::Demo>,
    /// When the store cannot be used, run in memory with the error in the view (the window)
    /// instead of failing (a headless peer).
    pub memory_fallback: bool,
    /// The name other peers see (at most
    /// [`replication::sync::ephemeral::presence::MAX_NAME_BYTES`]); `None`: the short id.
    pub name: Option<String>,
    /// The session's name on the LAN (`None`: the store directory's name).
    pub session_name: Option<String>,
}

impl EngineConfig {
    /// A session of its own in `store`, listening on a free port of the loopback interface,
    /// no demo, no memory fallback, no LAN: what tests and benchmarks start engines with.
    pub fn on_loopback(store: &std::path::Path) -> EngineConfig {
        EngineConfig {
            store: store.to_path_buf(),
            invite: None,
            network: Network {
                listen: (std::net::Ipv4Addr::LOCALHOST, 0).into(),
                ..Network::default()
            },
            demo: None,
            memory_fallback: false,
            name: None,
            session_name: None,
        }
    }
}

/// Why the engine did not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// The store directory cannot be used.
    #[error(transparent)]
    Store(#[from] store::StoreError),
    /// The listening socket could not be bound.
    #[error("cannot listen on {addr}: {reason}")]
    Listen {
        /// The address.
        addr: SocketAddr,
        /// Why (for example: the port is in use).
        reason: String,
    },
    /// The engine thread could not start or did not answer.
    #[error("the engine thread failed: {0}")]
    Thread(String),
}

/// Why a request did not reach the engine.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RequestError {
    /// The engine has stopped.
    #[error("the session engine has stopped")]
    Stopped,
    /// Too many requests are queued.
    #[error("the session engine is busy; try again")]
    Busy,
}

/// A request from a face.
enum Request {
    Author {
        payload: Box<ShapePayload>,
        reply: std_mpsc::Sender<Result<OpId, String>>,
    },
    Ephemeral {
        channel: u32,
        value: Vec<u8>,
    },
    Dial(SocketAddr),
    /// Announce the session on the LAN and dial the peers found there.
    Share,
    Shutdown,
}

/// A payload that passed [`ShapePayload::validate`] (its formulas compile, its numbers are
/// valid, its text is short), so that the engine authors it without building its object
/// again to check it ([`Engine::author_validated`]). Made only by [`Validated::new`].
#[derive(Clone, Debug, PartialEq)]
pub struct Validated(ShapePayload);

impl Validated {
    /// The payload, once it validates; else why it does not.
    pub fn new(payload: ShapePayload) -> Result<Validated, String> {
        payload.validate()?;
        Ok(Validated(payload))
    }

    /// The payload.
    pub fn into_payload(self) -> ShapePayload {
        self.0
    }
}

impl std::ops::Deref for Validated {
    type Target = ShapePayload;
    fn deref(&self) -> &ShapePayload {
        &self.0
    }
}

/// The reply to an authoring request, read once it comes.
pub struct Pending(std_mpsc::Receiver<Result<OpId, String>>);

impl Pending {
    /// The reply if it came (`Some(Err)` also when the engine stopped first).
    pub fn try_take(&self) -> Option<Result<OpId, String>> {
        match self.0.try_recv() {
            Ok(reply) => Some(reply),
            Err(std_mpsc::TryRecvError::Empty) => None,
            Err(std_mpsc::TryRecvError::Disconnected) => {
                Some(Err(RequestError::Stopped.to_string()))
            }
        }
    }

    /// Waits for the reply.
    pub fn wait(self) -> Result<OpId, String> {
        self.0
            .recv()
            .unwrap_or_else(|_| Err(RequestError::Stopped.to_string()))
    }
}

/// What a face does with values another peer sends on an ephemeral channel: called on the
/// engine thread with the sender and the value (at most
/// [`replication::sync::message::MAX_EPHEMERAL_BYTES`]), so it must be quick and never block.
pub type EphemeralListener = Box<dyn Fn(PeerId, &[u8]) + Send>;

/// The listeners faces set, by channel.
type Listeners = Arc<Mutex<std::collections::BTreeMap<u32, EphemeralListener>>>;

/// Sends ephemeral values through an engine from any thread (see
/// [`Engine::ephemeral_sender`]).
#[derive(Clone)]
pub struct EphemeralSender(tokio::sync::mpsc::Sender<Request>);

impl EphemeralSender {
    /// Sends the latest value on `channel` to every connected peer; a full queue drops it
    /// (a newer value follows), a stopped engine is an error.
    pub fn send(&self, channel: u32, value: Vec<u8>) -> Result<(), RequestError> {
        try_request(&self.0, Request::Ephemeral { channel, value })
    }
}

/// Queues `request` for the engine thread without waiting.
fn try_request(
    requests: &tokio::sync::mpsc::Sender<Request>,
    request: Request,
) -> Result<(), RequestError> {
    requests.try_send(request).map_err(|e| match e {
        tokio::sync::mpsc::error::TrySendError::Full(_) => RequestError::Busy,
        tokio::sync::mpsc::error::TrySendError::Closed(_) => RequestError::Stopped,
    })
}

/// A running engine.
pub struct Engine {
    requests: tokio::sync::mpsc::Sender<Request>,
    listeners: Listeners,
    view: SharedView,
    news: Arc<Mutex<News>>,
    invite: Invite,
    store_dir: PathBuf,
    local_presence: Arc<Mutex<Presence>>,
    presence_changed: Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Network news for the faces: lines in order, numbered.
#[derive(Default)]
pub struct News {
    lines: VecDeque<(u64, String)>,
    next: u64,
}

impl News {
    fn push(&mut self, line: String) {
        if self.lines.len() >= MAX_NEWS_LINES {
            self.lines.pop_front();
        }
        self.lines.push_back((self.next, line));
        self.next += 1;
    }

    /// The lines numbered `from` and later (as many as are still kept), and the next number.
    pub fn since(&self, from: u64) -> (Vec<String>, u64) {
        let lines = self
            .lines
            .iter()
            .filter(|(n, _)| *n >= from)
            .map(|(_, l)| l.clone())
            .collect();
        (lines, self.next)
    }
}

impl Engine {
    /// Opens the store, starts the node on the engine thread and waits until it listens.
    pub fn start(config: EngineConfig, now: Timestamp) -> Result<Engine, StartError> {
        let opening = Opening::open(&config, now)?;
        let me = opening.keypair.peer_id();
        let mut view = View::new(me, &opening.log).map_err(StartError::Thread)?;
        view.notices = opening.notices;
        view.founder_nonce = opening.founder_nonce;
        view.store_error = opening.store_error;
        let view: SharedView = Arc::new(Mutex::new(view));
        let founding = founding_payload(opening.founder_nonce, &opening.log, me);
        let demo = config
            .demo
            .filter(|_| opening.new_session && opening.log.is_empty())
            .map(|demo| demo.payloads(lock(&view).next_object()));
        {
            let mut view = lock(&view);
            view.authoring_demo = matches!(demo, Some(Ok(_)));
            view.joined = config.invite.is_some();
        }
        let (requests, inbox) = tokio::sync::mpsc::channel(MAX_QUEUED_REQUESTS);
        // The discovery id takes a slow derivation (argon2id): once per start.
        let keys = SessionKeys::from_invite(&opening.invite);
        let discovery_id = keys.discovery_id();
        let node_config = NodeConfig {
            keypair: opening.keypair,
            keys,
            listen: config.network.listen,
            join_from_snapshot: config.invite.is_some() && opening.log.is_empty(),
            log: opening.log,
            store: opening.store,
        };
        let local_presence = Arc::new(Mutex::new(Presence::named(
            config.name.clone().unwrap_or_else(|| me.short()),
            presence::default_colour(&me.0),
        )));
        let presence_changed = Arc::new(std::sync::atomic::AtomicBool::new(true));
        let listeners = Listeners::default();
        let worker = Worker {
            listeners: listeners.clone(),
            presence_changed: presence_changed.clone(),
            view: view.clone(),
            news: Arc::new(Mutex::new(News::default())),
            network: config.network.clone(),
            discovery_id,
            presence: local_presence.clone(),
            dialed: Arc::default(),
            shared: tokio::sync::watch::channel(
                config.invite.is_some()
                    || !config.network.dial.is_empty()
                    || config.network.discovery.is_some(),
            )
            .0,
            session_name: session_name(&config),
            lan: Mutex::new(None),
            founding,
        };
        let news = worker.news.clone();
        let (thread, listen) = worker.spawn(node_config, demo, inbox)?;
        lock(&view).listen = Some(listen);
        Ok(Engine {
            requests,
            listeners,
            view,
            news,
            invite: opening.invite,
            store_dir: config.store,
            local_presence,
            presence_changed,
            thread: Some(thread),
        })
    }

    /// The published view.
    pub fn view(&self) -> &SharedView {
        &self.view
    }

    /// Network news since line `from`, and the number to ask from next time.
    pub fn news_since(&self, from: u64) -> (Vec<String>, u64) {
        self.news
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .since(from)
    }

    /// The session's invite (a secret: show it only to the user who asks to share).
    pub fn invite(&self) -> &Invite {
        &self.invite
    }

    /// The store directory.
    pub fn store_dir(&self) -> &std::path::Path {
        &self.store_dir
    }

    /// This peer's id.
    pub fn peer_id(&self) -> PeerId {
        lock(&self.view).peer_id()
    }

    fn request(&self, request: Request) -> Result<(), RequestError> {
        try_request(&self.requests, request)
    }

    /// Authors an op (validated, stored, then sent); the reply comes on the returned
    /// [`Pending`]. The view shows the op once it is stored.
    /// A payload that does not validate is answered at once with the reason.
    pub fn author(&self, payload: ShapePayload) -> Result<Pending, RequestError> {
        match Validated::new(payload) {
            Ok(payload) => self.author_validated(payload),
            Err(e) => {
                let (reply, answer) = std_mpsc::channel();
                let _ = reply.send(Err(e));
                Ok(Pending(answer))
            }
        }
    }

    /// Authors an op already validated (a planned command's), without building its object
    /// again to check it: see [`Engine::author`].
    pub fn author_validated(&self, payload: Validated) -> Result<Pending, RequestError> {
        let (reply, answer) = std_mpsc::channel();
        self.request(Request::Author {
            payload: Box::new(payload.0),
            reply,
        })?;
        Ok(Pending(answer))
    }

    /// Calls `listener` with every value another peer sends on `channel` (replacing the
    /// channel's listener; `None` removes it). Presence's channel is the engine's own.
    pub fn listen_ephemeral(&self, channel: u32, listener: Option<EphemeralListener>) {
        let mut listeners = self
            .listeners
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match listener {
            Some(l) if channel != PRESENCE_CHANNEL => {
                listeners.insert(channel, l);
            }
            _ => {
                listeners.remove(&channel);
            }
        }
    }

    /// A handle that sends ephemeral values from another thread.
    pub fn ephemeral_sender(&self) -> EphemeralSender {
        EphemeralSender(self.requests.clone())
    }

    /// Sends the latest value on an ephemeral channel to every connected peer (never
    /// stored; latest value wins).
    pub fn send_ephemeral(&self, channel: u32, value: Vec<u8>) -> Result<(), RequestError> {
        self.request(Request::Ephemeral { channel, value })
    }

    /// Publishes this peer's presence (name, colour, pointer, selection, camera); it is sent
    /// to every connected peer at most [`presence::PRESENCE_RATE_HZ`] times a second.
    pub fn set_presence(&self, presence: Presence) -> Result<(), RequestError> {
        if self.requests.is_closed() {
            return Err(RequestError::Stopped);
        }
        *self
            .local_presence
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = presence;
        // A flag, not a request: a pointer moving every frame must never fill the queue that
        // carries edits.
        self.presence_changed
            .store(true, std::sync::atomic::Ordering::Release);
        Ok(())
    }

    /// This peer's presence as last set (its name and colour at start).
    pub fn presence(&self) -> Presence {
        self.local_presence
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// Announces the session on the LAN (DNS-SD) and dials its peers found there; a session
    /// started with an invite, a dial or a discovery node is shared from the start.
    pub fn share(&self) -> Result<(), RequestError> {
        self.request(Request::Share)
    }

    /// Dials a peer once.
    pub fn dial(&self, addr: SocketAddr) -> Result<(), RequestError> {
        self.request(Request::Dial(addr))
    }

    /// Closes every connection, syncs the store and stops the engine thread.
    pub fn shutdown(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        let _ = self.requests.try_send(Request::Shutdown);
        // Drop this handle's sender too: should the queue be full, the engine thread still
        // ends once it has drained it, instead of waiting for a request that cannot come.
        let (closed, _) = tokio::sync::mpsc::channel(1);
        drop(std::mem::replace(&mut self.requests, closed));
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for Engine {
    fn drop(&mut self) {
        self.stop();
    }
}

/// What a session starts from: its store, or (when that cannot be opened and the config
/// allows it) memory, where nothing is stored.
struct Opening {
    keypair: Keypair,
    invite: Invite,
    /// True when this start made the session.
    new_session: bool,
    /// `None` in memory.
    store: Option<OpStore<ShapePayload>>,
    log: Log<ShapePayload>,
    founder_nonce: Option<[u8; FOUNDER_NONCE_BYTES]>,
    notices: Vec<String>,
    /// Why the session is in memory.
    store_error: Option<String>,
}

impl Opening {
    /// The config's store, or memory when it cannot be opened and the config allows it.
    fn open(config: &EngineConfig, now: Timestamp) -> Result<Opening, StartError> {
        match store::open(&config.store, config.invite.as_ref(), now) {
            Ok(o) => Ok(Opening {
                keypair: o.keypair,
                invite: o.invite,
                new_session: o.new_session,
                store: Some(o.store),
                log: o.log,
                founder_nonce: o.founder_nonce,
                notices: o.notices,
                store_error: None,
            }),
            Err(e) if config.memory_fallback => Opening::in_memory(config, now, &e),
            Err(e) => Err(e.into()),
        }
    }

    /// A session in memory, for a store that failed with `error`: the config's invite, or a
    /// new session founded by a new key.
    fn in_memory(
        config: &EngineConfig,
        now: Timestamp,
        error: &store::StoreError,
    ) -> Result<Opening, StartError> {
        let keypair = store::memory_keypair(now);
        let (invite, founder_nonce) = match &config.invite {
            Some(i) => (i.clone(), None),
            None => {
                let nonce = store::entropy_seed().map_err(store::StoreError::Entropy)?;
                (Invite::for_founder(&keypair.peer_id(), &nonce), Some(nonce))
            }
        };
        let log = store::founded_log(&invite);
        Ok(Opening {
            keypair,
            invite,
            // A session joined by invite is the others': it gets no demo of ours.
            new_session: config.invite.is_none(),
            store: None,
            log,
            founder_nonce,
            notices: Vec::new(),
            store_error: Some(format!(
                "{error}; nothing stored was changed, and edits are not saved"
            )),
        })
    }
}

/// The founder's admission of itself (`me`), which a new session that binds its authors
/// needs first: when this peer holds the founder's nonce and has authored nothing in `log`.
pub(crate) fn founding_payload(
    founder_nonce: Option<[u8; FOUNDER_NONCE_BYTES]>,
    log: &Log<ShapePayload>,
    me: PeerId,
) -> Option<ShapePayload> {
    founder_nonce
        .filter(|_| log.binds_authors() && log.version_vector().get(&me) == 0)
        .map(|nonce| {
            ShapePayload::Admit(Box::new(replication::membership::Admission {
                key: me,
                grant_bytes: 0,
                nonce: Some(nonce),
            }))
        })
}

/// The session's name on the LAN: the config's, else its store directory's.
fn session_name(config: &EngineConfig) -> String {
    config.session_name.clone().unwrap_or_else(|| {
        config.store.file_name().map_or_else(
            || "sculpt".to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    })
}

/// When this peer's presence was last sent, and whether it is due again before the repeat.
struct PresenceSent {
    due: bool,
    at: tokio::time::Instant,
}

/// The engine thread's state.
struct Worker {
    view: SharedView,
    news: Arc<Mutex<News>>,
    network: Network,
    discovery_id: replication::net::session::DiscoveryId,
    /// This peer's presence, as the faces last set it.
    presence: Arc<Mutex<Presence>>,
    /// Set by a face when the presence changed.
    presence_changed: Arc<std::sync::atomic::AtomicBool>,
    /// How this engine reached the addresses it dialed (for the peers panel).
    dialed: Dialed,
    /// Whether the session is announced on the LAN.
    shared: tokio::sync::watch::Sender<bool>,
    /// The session's name on the LAN.
    session_name: String,
    /// The LAN's sessions, as DNS-SD lists them.
    lan: Mutex<Option<tokio::sync::watch::Receiver<Vec<LanSession>>>>,
    /// The faces' ephemeral listeners.
    listeners: Listeners,
    /// The founder's admission of itself, authored first in a new session that binds its
    /// authors (no other op of anyone counts before it).
    founding: Option<ShapePayload>,
}

/// How this engine reached the addresses it dialed (at most [`MAX_DIALED`] are kept).
type Dialed = Arc<Mutex<std::collections::BTreeMap<SocketAddr, &'static str>>>;

/// Addresses whose way of dialing is remembered for the peers panel.
pub const MAX_DIALED: usize = 256;

fn note_dialed(dialed: &Dialed, addr: SocketAddr, how: &'static str) {
    let mut map = dialed
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if map.len() < MAX_DIALED || map.contains_key(&addr) {
        map.insert(addr, how);
    }
}

impl Worker {
    /// Runs the worker on the named engine thread, and waits until its node listens (the
    /// address it listens on) or fails to.
    fn spawn(
        self,
        node_config: NodeConfig<ShapePayload>,
        demo: Option<Result<Vec<ShapePayload>, String>>,
        inbox: tokio::sync::mpsc::Receiver<Request>,
    ) -> Result<(std::thread::JoinHandle<()>, SocketAddr), StartError> {
        let (ready_tx, ready_rx) = std_mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("sculpt-engine".into())
            .stack_size(ENGINE_STACK_BYTES)
            .spawn(move || self.run(node_config, demo, inbox, ready_tx))
            .map_err(|e| StartError::Thread(e.to_string()))?;
        match ready_rx.recv_timeout(Duration::from_secs(START_TIMEOUT_SECS)) {
            Ok(Ok(addr)) => Ok((thread, addr)),
            Ok(Err(e)) => {
                let _ = thread.join();
                Err(e)
            }
            Err(_) => Err(StartError::Thread(
                "no answer from the engine thread".into(),
            )),
        }
    }

    fn run(
        self,
        node_config: NodeConfig<ShapePayload>,
        demo: Option<Result<Vec<ShapePayload>, String>>,
        inbox: tokio::sync::mpsc::Receiver<Request>,
        ready: std_mpsc::Sender<Result<SocketAddr, StartError>>,
    ) {
        let runtime = match tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
        {
            Ok(r) => r,
            Err(e) => {
                let _ = ready.send(Err(StartError::Thread(e.to_string())));
                return;
            }
        };
        runtime.block_on(self.serve(node_config, demo, inbox, ready));
    }

    fn say(&self, line: String) {
        NewsSink {
            news: self.news.clone(),
        }
        .say(line);
    }

    async fn serve(
        self,
        node_config: NodeConfig<ShapePayload>,
        demo: Option<Result<Vec<ShapePayload>, String>>,
        mut inbox: tokio::sync::mpsc::Receiver<Request>,
        ready: std_mpsc::Sender<Result<SocketAddr, StartError>>,
    ) {
        let listen = node_config.listen;
        let folder = view::Folder::with_news(self.view.clone(), self.news.clone());
        let node = match Node::spawn_observed(node_config, Some(Box::new(folder))) {
            Ok(node) => node,
            Err(e) => {
                let reason = listen_failure(&e);
                let _ = ready.send(Err(StartError::Listen {
                    addr: listen,
                    reason,
                }));
                return;
            }
        };
        let Node { handle, mut events } = node;
        let _ = ready.send(Ok(handle.local_addr()));
        self.say(format!(
            "peer {} listening on {}",
            handle.peer_id().short(),
            handle.local_addr()
        ));
        self.author_opening(&handle, demo).await;
        let news = NewsSink {
            news: self.news.clone(),
        };
        self.start_finders(&handle, &news);
        let mut refresh = tokio::time::interval(Duration::from_millis(PEER_REFRESH_MILLIS));
        let mut presence_tick =
            tokio::time::interval(Duration::from_millis(1_000 / presence::PRESENCE_RATE_HZ));
        let mut presence_sent = PresenceSent {
            due: true,
            at: tokio::time::Instant::now(),
        };
        loop {
            tokio::select! {
                request = inbox.recv() => match request {
                    Some(Request::Shutdown) | None => break,
                    Some(request) => self.on_request(request, &handle, &news).await,
                },
                Some(event) = events.recv() => {
                    // A new peer hears this peer's presence at once.
                    presence_sent.due |= matches!(event, NodeEvent::Connected { .. });
                    self.on_event(event);
                }
                _ = refresh.tick() => self.refresh_peers(&handle).await,
                _ = presence_tick.tick() => self.send_presence(&handle, &mut presence_sent).await,
            }
        }
        // Give connected peers what they lack first (bounded): closing a window right after
        // an edit should not leave the edit behind until the next meeting.
        let deadline = tokio::time::Instant::now() + Duration::from_millis(SHUTDOWN_FLUSH_MILLIS);
        while lock(&self.view).progress().0 > 0 && tokio::time::Instant::now() < deadline {
            tokio::select! {
                Some(event) = events.recv() => self.on_event(event),
                () = tokio::time::sleep(Duration::from_millis(20)) => {}
            }
        }
        let _ = handle.shutdown().await;
        self.say("stopped; every op is on disk".into());
    }

    /// Authors what a session starts with, before anything else: the founder's admission of
    /// itself, then the demo scene.
    async fn author_opening(
        &self,
        handle: &NodeHandle<ShapePayload>,
        demo: Option<Result<Vec<ShapePayload>, String>>,
    ) {
        if let Some(founding) = self.founding.clone()
            && let Err(e) = handle.author(founding).await
        {
            self.say(format!(
                "the session's founding op could not be authored: {e}"
            ));
        }
        match demo {
            Some(Ok(payloads)) => {
                for payload in payloads {
                    if let Err(e) = handle.author(payload).await {
                        self.say(format!("the demo scene could not be authored: {e}"));
                    }
                }
            }
            Some(Err(e)) => self.say(format!("the demo scene could not be authored: {e}")),
            None => {}
        }
    }

    /// Does what a face asked (the serving loop itself ends on [`Request::Shutdown`]).
    async fn on_request(
        &self,
        request: Request,
        handle: &NodeHandle<ShapePayload>,
        news: &NewsSink,
    ) {
        match request {
            Request::Author { payload, reply } => {
                let result = handle.author(*payload).await.map_err(|e| e.to_string());
                let _ = reply.send(result);
            }
            Request::Ephemeral { channel, value } => {
                let _ = handle.send_ephemeral(channel, value).await;
            }
            Request::Share => {
                self.shared.send_replace(true);
            }
            Request::Dial(addr) => {
                self.note_dialed(addr, "direct");
                let handle = handle.clone();
                let news = news.clone();
                tokio::spawn(async move {
                    if let Err(e) = handle.dial(addr).await {
                        news.say(dial_failure(addr, &e));
                    }
                });
            }
            Request::Shutdown => {}
        }
    }

    /// Sends this peer's presence when it changed, a peer connected, or it was last sent
    /// [`PRESENCE_REPEAT_MILLIS`] ago.
    async fn send_presence(&self, handle: &NodeHandle<ShapePayload>, sent: &mut PresenceSent) {
        let repeat = sent.at.elapsed() >= Duration::from_millis(PRESENCE_REPEAT_MILLIS);
        sent.due |= self
            .presence_changed
            .swap(false, std::sync::atomic::Ordering::AcqRel);
        if sent.due || repeat {
            let value = self
                .presence
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .encode();
            let _ = handle.send_ephemeral(PRESENCE_CHANNEL, value).await;
            sent.due = false;
            sent.at = tokio::time::Instant::now();
        }
    }

    /// Starts the tasks that find and dial peers: `--dial` addresses, a discovery node, the LAN.
    fn start_finders(&self, handle: &NodeHandle<ShapePayload>, news: &NewsSink) {
        for addr in self.network.dial.clone() {
            self.note_dialed(addr, "direct");
            tokio::spawn(keep_dialing(handle.clone(), addr, news.clone()));
        }
        if let Some(server) = self.network.discovery {
            stay_registered(
                server,
                self.discovery_id,
                handle,
                news.clone(),
                self.dialed.clone(),
            );
        }
        if self.network.lan {
            match DnsSd::start(DnsSdConfig::default()) {
                Ok(finder) => {
                    let announcement = Announcement {
                        discovery_id: self.discovery_id,
                        session_name: self.session_name.clone(),
                        peer: handle.peer_id(),
                        quic_addr: handle.local_addr(),
                        n_peers: 0,
                    };
                    let (sessions, listed) = tokio::sync::watch::channel(Vec::new());
                    *self
                        .lan
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(listed);
                    let (handle, shared, news) =
                        (handle.clone(), self.shared.subscribe(), news.clone());
                    tokio::spawn(async move {
                        let driving = dnssd::announce_and_dial(
                            finder,
                            handle,
                            announcement,
                            shared,
                            sessions,
                        );
                        if let Err(e) = driving.await {
                            news.say(format!("LAN discovery stopped: {e}"));
                        }
                    });
                }
                Err(e) => news.say(format!("LAN discovery is off: {e}")),
            }
        }
    }

    fn on_event(&self, event: NodeEvent) {
        match event {
            NodeEvent::Connected {
                peer, addr, role, ..
            } => self.on_connected(peer, addr, role),
            NodeEvent::Disconnected { peer, reason, .. } => {
                if reason == DisconnectReason::Duplicate {
                    return;
                }
                self.say(format!(
                    "{} left: {}",
                    peer.short(),
                    disconnect_text(&reason)
                ));
                let mut view = lock(&self.view);
                view.presence.remove(&peer);
                for row in view.peers.iter_mut().filter(|p| p.peer == peer) {
                    row.online = false;
                    row.rtt_micros = None;
                }
            }
            NodeEvent::Ephemeral {
                peer,
                channel,
                value,
                ..
            } => self.on_ephemeral(peer, channel, &value),
            NodeEvent::Forked { author, seq, .. } => self.on_forked(author, seq),
            NodeEvent::AdmissionFailed { addr, error } => {
                self.say(format!(
                    "a connection with {addr} was refused: {}",
                    admission_text(&error)
                ));
            }
            NodeEvent::Stopped { error } => {
                let line = format!("the store failed, so the node stopped: {error}");
                log::error!("{line}");
                lock(&self.view).store_error = Some(line);
            }
            NodeEvent::Snapshot(news) => self.on_snapshot(&news),
            NodeEvent::Rejected { peer, detail, .. } => {
                log::debug!("dropped bad input from {}: {detail}", peer.short());
            }
            NodeEvent::Delivered { .. } | NodeEvent::UpToDate { .. } => {}
        }
    }

    /// A peer connected: its row in the view, online, saying how it was reached.
    fn on_connected(
        &self,
        peer: PeerId,
        addr: SocketAddr,
        role: replication::net::admission::Role,
    ) {
        let how = match role {
            replication::net::admission::Role::Dialer => self
                .dialed
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .get(&addr)
                .copied()
                .unwrap_or("LAN"),
            _ => "it dialed us",
        };
        self.say(format!("connected to {} at {addr} ({how})", peer.short()));
        let mut view = lock(&self.view);
        let row = PeerRow {
            peer,
            online: true,
            name: peer.short(),
            colour: presence::default_colour(&peer.0),
            addr: addr.to_string(),
            how,
            rtt_micros: None,
            to_send: 0,
            to_receive: 0,
            scene_agrees: None,
            scene_mismatches: 0,
            last_mismatch: None,
        };
        match view.peers.iter_mut().find(|p| p.peer == peer) {
            Some(old) => {
                *old = PeerRow {
                    name: old.name.clone(),
                    colour: old.colour,
                    scene_mismatches: old.scene_mismatches,
                    last_mismatch: old.last_mismatch.take(),
                    ..row
                };
            }
            None => view.peers.push(row),
        }
        if view.peers.len() > MAX_PEER_ROWS
            && let Some(i) = view.peers.iter().position(|p| !p.online)
        {
            view.peers.remove(i);
        }
    }

    /// A value a peer sent on an ephemeral channel: its presence, or a face's channel.
    fn on_ephemeral(&self, peer: PeerId, channel: u32, value: &[u8]) {
        if channel == PRESENCE_CHANNEL {
            let mut view = lock(&self.view);
            match Presence::decode(value) {
                Ok(p) => view.note_presence(peer, p),
                Err(e) => {
                    view.n_bad_presence += 1;
                    log::debug!("bad presence from {}: {e}", peer.short());
                }
            }
            return;
        }
        let listeners = self
            .listeners
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(listener) = listeners.get(&channel) {
            listener(peer, value);
        }
    }

    /// A step of this peer's join from a snapshot: in the view, and said when it ends.
    fn on_snapshot(&self, news: &replication::net::node::SnapshotNews) {
        use replication::net::node::SnapshotNews;
        let mut view = lock(&self.view);
        let label = |p: PeerId| view.peer_label(p);
        let mut row = view.snapshot.clone().unwrap_or_default();
        row.note(news, label);
        let line = matches!(
            news,
            SnapshotNews::Joined { .. } | SnapshotNews::Verified | SnapshotNews::Refused { .. }
        )
        .then(|| row.text());
        view.snapshot = Some(row);
        if let Some(wake) = &view.waker {
            wake();
        }
        drop(view);
        if let Some(line) = line {
            self.say(line);
        }
    }

    /// `author` signed two different ops as its `seq`th: marked in the view, and said.
    fn on_forked(&self, author: PeerId, seq: u64) {
        let mut view = lock(&self.view);
        let who = if author == view.peer_id() {
            "this identity".to_string()
        } else {
            view.peers
                .iter()
                .find(|p| p.peer == author)
                .map_or_else(|| author.short(), |p| p.name.clone())
        };
        view.forked.insert(author, seq);
        drop(view);
        self.say(format!(
            "{who} signed two different edits as #{seq} (a fork): its edits from \
             #{seq} on count for nothing"
        ));
    }

    fn note_dialed(&self, addr: SocketAddr, how: &'static str) {
        note_dialed(&self.dialed, addr, how);
    }

    async fn refresh_peers(&self, handle: &NodeHandle<ShapePayload>) {
        let Ok(stats) = handle.stats().await else {
            return;
        };
        let lan: Option<Vec<LanSession>> = self
            .lan
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .as_ref()
            .map(|r| r.borrow().clone());
        let mut view = lock(&self.view);
        if let Some(lan) = lan {
            view.lan_sessions = lan
                .into_iter()
                .filter(|s| s.peer != handle.peer_id())
                .map(|s| view::LanRow {
                    ours: s.discovery_id == self.discovery_id,
                    name: s.name,
                    host: s.host,
                    n_peers: s.n_peers,
                })
                .collect();
        }
        view.shared = *self.shared.borrow();
        for row in &mut view.peers {
            if let Some(c) = stats.connections.iter().find(|c| c.peer == row.peer) {
                row.rtt_micros = Some(c.rtt_micros);
                row.addr = c.addr.to_string();
            }
        }
    }
}

/// Where background tasks put their news.
#[derive(Clone)]
struct NewsSink {
    news: Arc<Mutex<News>>,
}

impl NewsSink {
    fn say(&self, line: String) {
        log::info!("{line}");
        self.news
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(line);
    }
}

/// Dials `addr` whenever no connection to it is open, every [`DIAL_RETRY_MILLIS`] and at once
/// when the node hears a remote after a silence ([`NodeHandle::resumed`]: the network may be
/// back, and a dial that has waited [`DIAL_AFRESH_AFTER_MILLIS`] for its handshake is begun
/// afresh), until the node stops; says so when the outcome changes.
async fn keep_dialing(handle: NodeHandle<ShapePayload>, addr: SocketAddr, news: NewsSink) {
    let mut last_failure = None;
    let mut resumed = handle.resumed();
    let afresh = Duration::from_millis(DIAL_AFRESH_AFTER_MILLIS);
    loop {
        let Ok(stats) = handle.stats().await else {
            return;
        };
        if !stats.connections.iter().any(|c| c.addr == addr) {
            let began = tokio::time::Instant::now();
            let dial = handle.dial(addr);
            tokio::pin!(dial);
            let outcome = loop {
                tokio::select! {
                    outcome = &mut dial => break Some(outcome),
                    // A younger dial is left alone: its path may be slow, not cut.
                    Ok(()) = resumed.changed() => if began.elapsed() >= afresh {
                        break None;
                    }
                }
            };
            let Some(outcome) = outcome else {
                continue;
            };
            match outcome {
                Ok(_) => last_failure = None,
                Err(DialError::Gone) => return,
                Err(e) => {
                    let line = dial_failure(addr, &e);
                    if last_failure.as_ref() != Some(&line) {
                        news.say(line.clone());
                        last_failure = Some(line);
                    }
                }
            }
        }
        tokio::select! {
            () = tokio::time::sleep(Duration::from_millis(DIAL_RETRY_MILLIS)) => {}
            Ok(()) = resumed.changed() => {}
        }
    }
}

/// Keeps the node registered with a discovery server through the node's own socket (so the
/// server sees its public address), punches through NATs to whom it learns, and says when the
/// server cannot be reached (LAN and direct dialing go on meanwhile) or a peer cannot be
/// reached directly.
fn stay_registered(
    server: SocketAddr,
    discovery_id: replication::net::session::DiscoveryId,
    handle: &NodeHandle<ShapePayload>,
    news: NewsSink,
    dialed: Dialed,
) {
    use replication::net::discovery::RendezvousEvent;
    let mut rendezvous = match handle.register_with(server, discovery_id) {
        Ok(r) => r,
        Err(e) => return news.say(format!("discovery is off: {e}")),
    };
    tokio::spawn(async move {
        let mut reachable = None;
        while let Some(event) = rendezvous.events.recv().await {
            match event {
                RendezvousEvent::Registered { server, found } => {
                    for peer in &found {
                        note_dialed(&dialed, peer.addr, "via discovery");
                    }
                    if reachable != Some(true) {
                        news.say(format!("registered with the discovery node {server}"));
                        reachable = Some(true);
                    }
                }
                RendezvousEvent::NoAnswer { server, .. } => {
                    if reachable != Some(false) {
                        news.say(format!(
                            "the discovery node {server} is unreachable; LAN and direct dialing \
                             still work, and it is tried again"
                        ));
                        reachable = Some(false);
                    }
                }
                RendezvousEvent::Introduced { peer } => {
                    note_dialed(&dialed, peer.addr, "via discovery");
                }
                RendezvousEvent::Connected { .. } => {}
                RendezvousEvent::Unreachable(u) => news.say(u.to_string()),
                RendezvousEvent::DialFailed { peer, error } => {
                    news.say(dial_failure(peer.addr, &error));
                }
            }
        }
    });
}

/// A dial failure in words a person can act on.
fn dial_failure(addr: SocketAddr, e: &DialError) -> String {
    match e {
        DialError::Admission(a) => format!("{addr} refused the connection: {}", admission_text(a)),
        DialError::SelfConnection => format!("{addr} is this peer itself"),
        other => format!("cannot connect to {addr}: {other}"),
    }
}

/// An admission failure in words a person can act on.
fn admission_text(e: &AdmissionError) -> String {
    match e {
        AdmissionError::WrongInvite | AdmissionError::RefusedByRemote(_) => {
            format!("{e}: the invites differ (a mistyped code, or another session's invite)")
        }
        AdmissionError::Timeout | AdmissionError::Connection(_) => {
            format!("{e}: is a sculpt peer listening there?")
        }
        other => other.to_string(),
    }
}

/// Why the node could not listen, as a user reads it.
fn listen_failure(e: &replication::net::node::NodeError) -> String {
    match e {
        replication::net::node::NodeError::Bind { source, .. }
            if source.kind() == std::io::ErrorKind::AddrInUse =>
        {
            "the port is in use (another sculpt peer?); give another --listen address, or \
             port 0 to pick a free one"
                .to_string()
        }
        other => other.to_string(),
    }
}

/// A disconnection reason in words.
fn disconnect_text(reason: &DisconnectReason) -> String {
    match reason {
        DisconnectReason::Sync(CloseReason::WrongProtocol { remote }) => format!(
            "it runs sync protocol {remote}, this build speaks {}; update the older one",
            replication::sync::message::PROTOCOL_VERSION
        ),
        DisconnectReason::Sync(CloseReason::WrongSession) => "it is in another session".into(),
        DisconnectReason::Sync(CloseReason::Expelled { peer }) => {
            format!("the session's founder expelled {}", peer.short())
        }
        DisconnectReason::Lost(why) => format!("connection lost ({why})"),
        DisconnectReason::SnapshotRefused => {
            "a snapshot this peer joined from held a forged op: the joined session was dropped \
             and is synced again op by op"
                .into()
        }
        other => format!("{other:?}"),
    }
}

#[cfg(test)]
mod tests;
