//! What the engine publishes to its faces: the folded scene, what changed in it (from the
//! fold's per-object refold reports, never by comparing scenes), the history and chat rows,
//! the undo and redo targets, and the peers with their progress.
//!
//! The view is kept by [`Folder`], the node's [`Observer`]: it runs on the engine thread
//! inside the node's core task, folds each insertion as the log makes it, and refreshes the
//! derived rows once per settled step. Faces read it under a short lock.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex, MutexGuard};

use model::object::{ColorDef, Field, Shape};
use model::scene::{ObjectId, Scene};
use replication::log::{Drained, Insertion, Refold};
use replication::materialize::{Materialize as _, Materialized, SceneHash};
use replication::membership::{FOUNDER_NONCE_BYTES, Membership};
use replication::net::node::{Observer, SnapshotNews};
use replication::payload::LeaseAction;
use replication::shape::{IdSource, ShapePayload, ShapeScene};
use replication::snapshot::{CaptureError, JoinError, Snapshot};
use replication::sync::message::SceneAt;
use replication::sync::scene::{SceneCut, SceneEvent, SceneMismatch};
use replication::{Effect, Log, Mark, OpId, Payload as _, Peer, PeerId, Timestamp};

use crate::clock::time_of_day_utc;
use replication::sync::ephemeral::presence::Presence;

/// Most history rows a view holds (the latest ones).
pub const MAX_HISTORY_ROWS: usize = 500;
/// Most chat rows a view holds (the latest ones).
pub const MAX_CHAT_ROWS: usize = 500;
/// This peer's rejected ops a view lists (the latest ones).
pub const MAX_REJECTIONS_SHOWN: usize = 20;
/// Most characters of a formula or chat text quoted in a history row.
pub const MAX_QUOTE_CHARS: usize = 60;
/// The bit that marks a group's id among the objects a refold names (as `ShapePayload` sets
/// it for group edits): a group change touches every object under it.
const GROUP_BIT: u64 = 1 << 63;

/// One chat line.
#[derive(Clone, Debug, PartialEq)]
pub struct ChatRow {
    /// Short id of the author.
    pub author: String,
    /// `HH:MM:SS` UTC of the op's timestamp.
    pub time: String,
    /// The text.
    pub text: String,
}

/// One of this peer's ops that took no effect.
#[derive(Clone, Debug, PartialEq)]
pub struct Rejection {
    /// The op.
    pub op: OpId,
    /// What it did and why it was rejected.
    pub why: String,
    /// What its author can do about it.
    pub remedy: &'static str,
}

/// One op of the history.
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryRow {
    /// Short id of the author.
    pub author: String,
    /// True when this peer wrote it.
    pub mine: bool,
    /// `HH:MM:SS` UTC of the op's timestamp.
    pub time: String,
    /// What it does, in words.
    pub what: String,
    /// `effective`, `undone` or `rejected: <reason>`.
    pub status: String,
    /// The op.
    pub op: OpId,
    /// This peer's own edit, in effect: it can be undone from the history.
    pub undoable: bool,
}

/// One peer of the session met since start, as the node and its sync state see it.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerRow {
    /// Its id.
    pub peer: PeerId,
    /// Connected now.
    pub online: bool,
    /// The name its user chose (from its presence), else its short id.
    pub name: String,
    /// Its user's colour (from its presence), else one from its id.
    pub colour: [u8; 3],
    /// Its address.
    pub addr: String,
    /// How it was reached: `direct` (dialed by address), `via discovery`, `LAN` or
    /// `it dialed us`.
    pub how: &'static str,
    /// Round-trip time, when the transport has measured one.
    pub rtt_micros: Option<u64>,
    /// Ops this peer holds that the remote is not known to hold.
    pub to_send: u64,
    /// Ops the remote holds that this peer lacks.
    pub to_receive: u64,
    /// Whether its scene hash agreed with this peer's when last compared at one cut (`None`
    /// before the first comparison on this connection).
    pub scene_agrees: Option<bool>,
    /// Scene mismatches with it that were acted on (refolds asked for), since start.
    pub scene_mismatches: u64,
    /// The last such mismatch, in words (both cuts and hashes).
    pub last_mismatch: Option<String>,
}

/// The scene check across peers ([`replication::sync::scene`]), for the faces.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SceneCheckRow {
    /// Mismatches acted on, with every peer, since start.
    pub n_mismatches: u64,
    /// Objects refolded to repair them (an object refolded for two peers counts twice).
    pub n_objects_refolded: u64,
    /// The last mismatch, in words.
    pub last_mismatch: Option<String>,
    /// True when every connected peer's last comparison agreed, false when one differed, and
    /// `None` before any comparison.
    pub agrees: Option<bool>,
}

/// How this peer's join from a snapshot went ([`replication::net::node::SnapshotNews`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct JoinRow {
    /// The peer the snapshot came (or comes) from.
    pub from: String,
    /// Bytes received.
    pub bytes: u64,
    /// Ops it held, once joined.
    pub n_ops: usize,
    /// Time to decode and join it on the engine thread, once joined.
    pub join_micros: Option<u64>,
    /// Ops whose signatures the check verified so far.
    pub checked: usize,
    /// The check passed and the whole log is stored.
    pub verified: bool,
    /// Snapshots refused, with why (the latest [`MAX_REFUSALS_SHOWN`]).
    pub refused: Vec<String>,
    /// Still fetching or checking.
    pub busy: bool,
}

/// Refused snapshots a [`JoinRow`] lists (the latest ones).
pub const MAX_REFUSALS_SHOWN: usize = 8;

impl JoinRow {
    /// Takes a step of the join.
    pub fn note(&mut self, news: &SnapshotNews, label: impl Fn(PeerId) -> String) {
        match news {
            SnapshotNews::Fetching { peer, bytes } => {
                self.from = label(*peer);
                self.bytes = *bytes;
                self.busy = true;
            }
            SnapshotNews::Joined {
                peer,
                n_ops,
                bytes,
                join_micros,
            } => {
                self.from = label(*peer);
                self.bytes = *bytes as u64;
                self.n_ops = *n_ops;
                self.join_micros = Some(*join_micros);
                self.busy = true;
            }
            SnapshotNews::Verifying { checked, .. } => self.checked = *checked,
            SnapshotNews::Verified => {
                self.checked = self.n_ops;
                self.verified = true;
                self.busy = false;
            }
            SnapshotNews::Refused { peer, why } => {
                if self.refused.len() >= MAX_REFUSALS_SHOWN {
                    self.refused.remove(0);
                }
                self.refused.push(format!("from {}: {why}", label(*peer)));
                // A refused join starts over op by op; a refused fetch asks the next peer,
                // whose news comes next.
                self.join_micros = None;
                self.busy = false;
            }
        }
    }

    /// The join in words, for a status line.
    pub fn text(&self) -> String {
        let mb = |b: u64| b as f64 / f64::from(1 << 20);
        match (self.join_micros, self.busy) {
            (None, true) => format!(
                "joining from {}'s snapshot: {:.1} MB received",
                self.from,
                mb(self.bytes)
            ),
            (Some(_), true) => format!(
                "joined {} ops from {}'s snapshot; checking it: {} of {} signatures",
                self.n_ops, self.from, self.checked, self.n_ops
            ),
            (Some(us), false) if self.verified => format!(
                "joined {} ops from {}'s snapshot in {} ms; checked",
                self.n_ops,
                self.from,
                us / 1_000,
            ),
            _ => match self.refused.last() {
                Some(why) => format!("a snapshot was refused ({why}); syncing op by op"),
                None => String::new(),
            },
        }
    }
}

/// Scene hashes take at most one part in this many of the time of the thread that asks for
/// them while the scene keeps changing ([`View::scene_hash_if_due`]).
pub const SCENE_HASH_TIME_SHARE: u32 = 10;
/// Scene hashes of a changing scene are computed at most this often, in milliseconds.
pub const MIN_SCENE_HASH_INTERVAL_MILLIS: u64 = 250;

/// The last scene hash computed, and when the next may be.
struct HashCache {
    generation: u64,
    hash: SceneHash,
    due: std::time::Instant,
}

/// A session announced on the LAN.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LanRow {
    /// Its name.
    pub name: String,
    /// The announcing peer's host.
    pub host: String,
    /// Peers it says it is connected to.
    pub n_peers: u16,
    /// This peer's own session.
    pub ours: bool,
}

/// The engine's published state.
pub struct View {
    me: PeerId,
    scene: Materialized<ShapePayload, ShapeScene>,
    n_ops: usize,
    /// False while the session binds its authors and holds no admission of this peer.
    admitted: bool,
    history: Vec<HistoryRow>,
    chat: Vec<ChatRow>,
    undo: BTreeMap<u64, OpId>,
    redo: BTreeMap<u64, OpId>,
    next_object: IdSource,
    changes: ChangeLog,
    /// The newest timestamp of another peer's op that changed the scene.
    last_remote_edit: Option<replication::Timestamp>,
    leases: BTreeMap<u64, replication::lease::Lease>,
    my_rejections: Vec<Rejection>,
    generation: u64,
    hash: Option<HashCache>,
    pub(super) peers: Vec<PeerRow>,
    pub(super) presence: BTreeMap<PeerId, Presence>,
    pub(super) lan_sessions: Vec<LanRow>,
    pub(super) shared: bool,
    pub(super) n_bad_presence: u64,
    pub(super) notices: Vec<String>,
    pub(super) store_error: Option<String>,
    pub(super) n_loaded: usize,
    /// This start authors the demo scene (a new session, not joined).
    pub(super) authoring_demo: bool,
    /// The session was joined by invite.
    pub(super) joined: bool,
    pub(super) listen: Option<std::net::SocketAddr>,
    /// The founder's nonce, when this peer founded the session (it may expel members).
    pub(super) founder_nonce: Option<[u8; FOUNDER_NONCE_BYTES]>,
    expelled: BTreeSet<PeerId>,
    /// Authors proven to have signed two ops with one seq, and that seq.
    pub(super) forked: BTreeMap<PeerId, u64>,
    /// What the scene check found.
    scene_check: SceneCheckRow,
    /// How the join from a snapshot went, if this peer joined from one.
    pub(super) snapshot: Option<JoinRow>,
    pub(super) waker: Option<Box<dyn Fn() + Send>>,
}

impl View {
    /// The view of `log` for peer `me`.
    pub fn new(me: PeerId, log: &Log<ShapePayload>) -> Result<Self, String> {
        let scene = prepared(Materialized::fold(log));
        let mut view = Self {
            me,
            scene,
            n_ops: 0,
            admitted: true,
            history: Vec::new(),
            chat: Vec::new(),
            undo: BTreeMap::new(),
            redo: BTreeMap::new(),
            next_object: IdSource::first(me),
            changes: ChangeLog::default(),
            last_remote_edit: None,
            leases: BTreeMap::new(),
            my_rejections: Vec::new(),
            generation: 0,
            hash: None,
            peers: Vec::new(),
            presence: BTreeMap::new(),
            lan_sessions: Vec::new(),
            shared: false,
            n_bad_presence: 0,
            notices: Vec::new(),
            store_error: None,
            n_loaded: log.len(),
            authoring_demo: false,
            joined: false,
            listen: None,
            founder_nonce: None,
            expelled: BTreeSet::new(),
            forked: BTreeMap::new(),
            scene_check: SceneCheckRow::default(),
            snapshot: None,
            waker: None,
        };
        view.refresh(log);
        Ok(view)
    }

    /// Folds one insertion and notes the objects it changed.
    pub fn apply(&mut self, log: &Log<ShapePayload>, insertion: &Insertion) {
        if let Some(refold) = &insertion.refold {
            self.apply_refold(log, &insertion.delivered, refold);
        }
    }

    /// Folds what a (merged) refold names and notes the objects it changed.
    pub fn apply_refold(&mut self, log: &Log<ShapePayload>, delivered: &[OpId], refold: &Refold) {
        self.scene.apply_refold(log, delivered, refold);
        self.scene.prepare(refold.object_keys.keys().copied());
        if !refold.object_keys.is_empty() {
            let remote = delivered
                .iter()
                .filter_map(|id| log.get(id))
                .filter(|op| op.author() != self.me)
                .map(|op| op.timestamp())
                .max();
            self.last_remote_edit = self.last_remote_edit.max(remote);
        }
        {
            for object in refold.object_keys.keys() {
                self.changes.push(if object.0 & GROUP_BIT != 0 {
                    Change::All
                } else {
                    Change::Object(ObjectId(object.0))
                });
            }
        }
        self.generation += 1;
    }

    /// Refolds `objects` (and with `rest` the chat) from `log`: the repair of a scene found to
    /// differ from a peer's at the same cut.
    pub fn resync(
        &mut self,
        log: &Log<ShapePayload>,
        objects: &[replication::ObjectId],
        rest: bool,
    ) {
        self.scene.resync(log, objects, rest);
        self.scene.prepare(objects.iter().copied());
        for object in objects {
            self.changes.push(if object.0 & GROUP_BIT != 0 {
                Change::All
            } else {
                Change::Object(ObjectId(object.0))
            });
        }
        self.scene_check.n_objects_refolded += objects.len() as u64;
        self.generation += 1;
    }

    /// Forgets `object`'s fold behind the log's back, so that tests can show that peers find
    /// the difference and repair it. Never call it otherwise.
    #[doc(hidden)]
    pub fn plant_scene_difference(&mut self, object: u64) {
        self.scene
            .plant_difference(|scene| scene.reset_object(replication::ObjectId(object)));
        self.changes.push(Change::Object(ObjectId(object)));
        self.generation += 1;
    }

    /// What the scene check found, across peers.
    pub fn scene_check(&self) -> &SceneCheckRow {
        &self.scene_check
    }

    /// How the join from a snapshot went, if this peer joined (or tried to) from one.
    pub fn snapshot(&self) -> Option<&JoinRow> {
        self.snapshot.as_ref()
    }

    /// Puts a scene joined from a snapshot (or folded from scratch) in place of the view's.
    fn adopt(&mut self, scene: Materialized<ShapePayload, ShapeScene>) {
        self.scene = prepared(scene);
        self.changes.push(Change::All);
        self.generation += 1;
    }

    /// Recomputes the rows and targets that depend on the whole log.
    pub fn refresh(&mut self, log: &Log<ShapePayload>) {
        self.n_ops = log.len();
        self.admitted = log.is_admitted(&self.me);
        self.expelled = log.expelled().keys().copied().collect();
        self.forked = log.forks().authors().collect();
        self.history = history(log, self.me, self.scene.scene().scene());
        self.chat = self.chat_rows(log);
        let (undo, redo) = targets(log, self.me);
        self.undo = undo;
        self.redo = redo;
        self.next_object = IdSource::next_in(log, self.me);
        // Every lease as the fold left it; a face compares `expires_at` with its clock.
        let ids: Vec<u64> = self.scene().objects().map(|(id, _)| id.0).collect();
        self.leases = ids
            .into_iter()
            .filter_map(|id| {
                let lease = log.lease(replication::ObjectId(id), Timestamp(0))?;
                Some((id, lease))
            })
            .collect();
        self.my_rejections = log
            .rejected_by(&self.me)
            .into_iter()
            .rev()
            .take(MAX_REJECTIONS_SHOWN)
            .map(|(id, reason)| {
                let what = log
                    .get(&id)
                    .map_or_else(String::new, |op| describe(log, self.scene(), op.payload()));
                Rejection {
                    op: id,
                    why: format!("{what}: {reason}"),
                    remedy: reason.remedy(),
                }
            })
            .collect();
    }

    /// The lease on `object` as the fold left it (it may have expired since: compare
    /// `expires_at` with the clock).
    pub fn lease(&self, object: u64) -> Option<&replication::lease::Lease> {
        self.leases.get(&object)
    }

    /// This peer's latest rejected ops (newest first, at most [`MAX_REJECTIONS_SHOWN`]), with
    /// what they did and why they were rejected.
    pub fn my_rejections(&self) -> &[Rejection] {
        &self.my_rejections
    }

    /// Takes a presence value that arrived from `peer` (the engine calls this): the peer's
    /// row takes its name and colour, and the view's waker is called.
    pub fn note_presence(&mut self, peer: PeerId, presence: Presence) {
        for row in self.peers.iter_mut().filter(|r| r.peer == peer) {
            row.name.clone_from(&presence.name);
            row.colour = presence.colour;
        }
        self.presence.insert(peer, presence);
        if let Some(wake) = &self.waker {
            wake();
        }
    }

    /// Sets what the engine calls after each change of the view (a window asks for a frame).
    pub fn set_waker(&mut self, waker: Box<dyn Fn() + Send>) {
        self.waker = Some(waker);
    }

    /// This peer's id.
    pub fn peer_id(&self) -> PeerId {
        self.me
    }

    /// The founder's nonce, when this peer founded the session: only then may it expel.
    pub fn founder_nonce(&self) -> Option<[u8; FOUNDER_NONCE_BYTES]> {
        self.founder_nonce
    }

    /// The members the founder expelled (and has not readmitted).
    pub fn expelled(&self) -> &BTreeSet<PeerId> {
        &self.expelled
    }

    /// The authors proven to have signed two different ops with one seq, and that seq
    /// ([`replication::fork`]); this peer's own id among them means its identity runs
    /// twice or its store was restored from an older copy.
    pub fn forked(&self) -> &BTreeMap<PeerId, u64> {
        &self.forked
    }

    /// The expel (`expel`) or readmit of the member `who` names (see [`View::find_member`]),
    /// when this peer may author it: only the session's founder may, never of itself, and it
    /// readmits only an expelled member. The error says which rule refused it.
    pub fn membership_change(&self, who: &str, expel: bool) -> Result<Membership, String> {
        let nonce = self.founder_nonce.ok_or(
            "only the session's founder (the peer that made its invite) can expel or readmit",
        )?;
        let member = self.find_member(who)?;
        if member == self.me {
            return Err("the founder cannot expel itself".into());
        }
        if !expel && !self.expelled.contains(&member) {
            return Err(format!("{} is not expelled", member.short()));
        }
        Ok(Membership {
            member,
            expel,
            nonce,
        })
    }

    /// The member a person names: by the name its user chose (any case) or by the start of
    /// its id (at least 4 hex digits), among the peers met and the expelled members. Names
    /// that fit several members, or none, are an error that says so.
    pub fn find_member(&self, text: &str) -> Result<PeerId, String> {
        let text = text.trim();
        if text.is_empty() {
            return Err("name a member: its name or the start of its id".into());
        }
        let hex = text.to_ascii_lowercase();
        let candidates: BTreeSet<PeerId> = self
            .peers
            .iter()
            .map(|r| r.peer)
            .chain(self.presence.keys().copied())
            .chain(self.expelled.iter().copied())
            .collect();
        let name_of = |p: &PeerId| self.presence.get(p).map(|pr| pr.name.as_str());
        let found: Vec<PeerId> = candidates
            .into_iter()
            .filter(|p| {
                name_of(p).is_some_and(|n| n.eq_ignore_ascii_case(text))
                    || (hex.len() >= 4 && p.to_hex().starts_with(&hex))
            })
            .collect();
        match found.as_slice() {
            [one] => Ok(*one),
            [] => Err(format!("no member is called or starts with \"{text}\"")),
            many => Err(format!(
                "\"{text}\" fits {} members; give more of the id",
                many.len()
            )),
        }
    }

    /// The folded scene.
    pub fn scene(&self) -> &Scene {
        self.scene.scene().scene()
    }

    /// Ops in the log.
    pub fn n_ops(&self) -> usize {
        self.n_ops
    }

    /// False while this peer waits for a member to admit it (the session binds its
    /// authors): it may author nothing until then.
    pub fn admitted(&self) -> bool {
        self.admitted
    }

    /// Ops loaded from the store at start.
    pub fn n_loaded(&self) -> usize {
        self.n_loaded
    }

    /// What starting found, for the window's first status line: the ops loaded from the
    /// store, or for a new one whether the demo scene was authored or a session joined
    /// (whose objects come from its peers), and whether the session lives in memory because
    /// the store cannot be used.
    pub fn opening_status(&self) -> String {
        let what = match self.n_loaded {
            0 if self.authoring_demo => "the demo scene was authored".to_string(),
            0 if self.joined => "joined the session; its objects come from its peers".to_string(),
            0 => "an empty session".to_string(),
            n => return format!("loaded {n} ops from the store"),
        };
        match self.store_error {
            Some(_) => format!("in memory, the store cannot be used: {what}"),
            None => format!("new store: {what}"),
        }
    }

    /// Counts changes of the scene; equal counts mean an equal scene.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// What changed since `cursor` (0 at first): the objects, or `None` when every object
    /// may have changed (a group edit, or a cursor older than the kept changes), and the
    /// cursor to ask from next time. Each consumer (the window's mesher feed, a haptic feed,
    /// a test) keeps its own cursor.
    pub fn changes_since(&self, cursor: u64) -> (Option<BTreeSet<ObjectId>>, u64) {
        self.changes.since(cursor)
    }

    /// The newest timestamp (its author's clock) of another peer's op that changed the scene
    /// since this view was made, for timing remote edits to the screen.
    pub fn last_remote_edit(&self) -> Option<replication::Timestamp> {
        self.last_remote_edit
    }

    /// The scene hash (equal on every peer with the same ops), computed at most once per
    /// change of the scene.
    pub fn scene_hash(&mut self) -> SceneHash {
        match &self.hash {
            Some(h) if h.generation == self.generation => h.hash,
            _ => self.hash_now(crate::clock::now().instant),
        }
    }

    /// The scene hash when it is current or may be computed now: at most every
    /// [`MIN_SCENE_HASH_INTERVAL_MILLIS`], and never more than one part in
    /// [`SCENE_HASH_TIME_SHARE`] of the caller's time (a hash of a scene carved 10^5 times
    /// takes about 0.1 s). `None` when it is not due; ask again later.
    pub fn scene_hash_if_due(&mut self, now: std::time::Instant) -> Option<SceneHash> {
        match &self.hash {
            Some(h) if h.generation == self.generation => Some(h.hash),
            Some(h) if now < h.due => None,
            _ => Some(self.hash_now(now)),
        }
    }

    fn hash_now(&mut self, now: std::time::Instant) -> SceneHash {
        let hash = self.scene.scene_hash();
        let cost = now.elapsed();
        let pause = (cost * (SCENE_HASH_TIME_SHARE - 1)).max(std::time::Duration::from_millis(
            MIN_SCENE_HASH_INTERVAL_MILLIS,
        ));
        self.hash = Some(HashCache {
            generation: self.generation,
            hash,
            due: now + cost + pause,
        });
        hash
    }

    /// The first bytes of a scene hash in hex, as peers and dumps show it.
    pub fn hash_hex(hash: &SceneHash) -> String {
        short_hex(&hash.0)
    }

    /// [`View::scene_hash`] in hex.
    pub fn scene_hash_hex(&mut self) -> String {
        let hash = self.scene_hash();
        Self::hash_hex(&hash)
    }

    /// The scene hash in hex when due ([`View::scene_hash_if_due`]), else the last one
    /// computed (of an older scene), for a face that polls often.
    pub fn recent_scene_hash_hex(&mut self, now: std::time::Instant) -> String {
        match self.scene_hash_if_due(now) {
            Some(hash) => Self::hash_hex(&hash),
            None => (self.hash.as_ref()).map_or_else(String::new, |h| Self::hash_hex(&h.hash)),
        }
    }

    /// The latest [`MAX_HISTORY_ROWS`] ops, oldest first, with what became of them.
    pub fn history(&self) -> &[HistoryRow] {
        &self.history
    }

    /// The latest [`MAX_CHAT_ROWS`] chat lines, in linear order.
    pub fn chat(&self) -> &[ChatRow] {
        &self.chat
    }

    /// The peers met since start, online or not, in the order they were first met.
    pub fn peers(&self) -> &[PeerRow] {
        &self.peers
    }

    /// Peers connected now.
    pub fn n_online(&self) -> usize {
        self.peers.iter().filter(|p| p.online).count()
    }

    /// Ops still to send to and to receive from the connected peers (the largest over them).
    pub fn progress(&self) -> (u64, u64) {
        let online = || self.peers.iter().filter(|p| p.online);
        let send = online().map(|p| p.to_send).max().unwrap_or(0);
        let receive = online().map(|p| p.to_receive).max().unwrap_or(0);
        (send, receive)
    }

    /// The latest presence of each connected peer.
    pub fn presence(&self) -> &BTreeMap<PeerId, Presence> {
        &self.presence
    }

    /// The sessions announced on the LAN by other peers (this one's own included, marked).
    pub fn lan_sessions(&self) -> &[LanRow] {
        &self.lan_sessions
    }

    /// Whether the session is announced on the LAN.
    pub fn is_shared(&self) -> bool {
        self.shared
    }

    /// Presence values refused as malformed.
    pub fn n_bad_presence(&self) -> u64 {
        self.n_bad_presence
    }

    /// Things the user should know (a damaged store tail kept aside, a new identity).
    pub fn notices(&self) -> &[String] {
        &self.notices
    }

    /// Why edits are not being saved, if they are not.
    pub fn store_error(&self) -> Option<&str> {
        self.store_error.as_deref()
    }

    /// The address the node listens on.
    pub fn listen_addr(&self) -> Option<std::net::SocketAddr> {
        self.listen
    }

    /// The latest of this peer's changes to `object` that is in effect: what `undo` undoes.
    /// Its creation is not one (undoing it would make the object vanish).
    pub fn undo_target(&self, object: u64) -> Option<OpId> {
        self.undo.get(&object).copied()
    }

    /// The edit of `object` that this peer's latest effective undo took back and that is
    /// still undone: what `redo` redoes.
    pub fn redo_target(&self, object: u64) -> Option<OpId> {
        self.redo.get(&object).copied()
    }

    /// Where this peer's fresh object ids start: its key and one more than its highest
    /// counter ([`IdSource::next_in`]).
    pub fn next_object(&self) -> IdSource {
        self.next_object
    }

    /// A peer's display name, or its short id when it gave none.
    pub fn peer_label(&self, peer: PeerId) -> String {
        self.peers
            .iter()
            .find(|r| r.peer == peer && !r.name.is_empty())
            .map_or_else(|| peer.short(), |r| r.name.clone())
    }

    /// An object's name, or `object N` when it has none (or is gone).
    pub fn object_label(&self, object: u64) -> String {
        object_label(self.scene(), object)
    }

    fn chat_rows(&self, log: &Log<ShapePayload>) -> Vec<ChatRow> {
        let lines = self.scene.scene().chat();
        let skip = lines.len().saturating_sub(MAX_CHAT_ROWS);
        lines[skip..]
            .iter()
            .map(|line| {
                let author = PeerId(line.author);
                let time = log
                    .by_seq(&author, line.seq)
                    .map_or_else(String::new, |op| time_of_day_utc(op.timestamp()));
                ChatRow {
                    author: author.short(),
                    time,
                    text: line.text.clone(),
                }
            })
            .collect()
    }
}

/// One change of the scene, as the refold reports name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Change {
    /// One object must be looked at again.
    Object(ObjectId),
    /// Every object (a group changed).
    All,
}

/// The latest [`MAX_CHANGES`] changes, numbered from 1; cursor 0 means "nothing seen yet",
/// which reads as "everything changed".
#[derive(Default)]
struct ChangeLog {
    /// The number of the first kept change.
    first: u64,
    kept: std::collections::VecDeque<Change>,
}

/// Changes a view keeps for consumers that read them late; one further behind sees
/// "everything changed".
pub const MAX_CHANGES: usize = 4096;

impl ChangeLog {
    fn push(&mut self, change: Change) {
        if self.first == 0 {
            self.first = 1;
        }
        if self.kept.len() >= MAX_CHANGES {
            self.kept.pop_front();
            self.first += 1;
        }
        self.kept.push_back(change);
    }

    fn next(&self) -> u64 {
        self.first.max(1) + self.kept.len() as u64
    }

    fn since(&self, cursor: u64) -> (Option<BTreeSet<ObjectId>>, u64) {
        let next = self.next();
        if cursor == 0 || cursor < self.first {
            return (None, next);
        }
        let skip = usize::try_from(cursor - self.first.max(1)).unwrap_or(usize::MAX);
        let mut objects = BTreeSet::new();
        for change in self.kept.iter().skip(skip) {
            match change {
                Change::Object(id) => {
                    objects.insert(*id);
                }
                Change::All => return (None, next),
            }
        }
        (Some(objects), next)
    }
}

/// The view shared between the engine thread and its faces.
pub type SharedView = Arc<Mutex<View>>;

/// Locks a shared view; a face that panicked while holding it leaves the view as it was,
/// which is still consistent (every update is applied whole under the lock).
pub fn lock(view: &SharedView) -> MutexGuard<'_, View> {
    view.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The node's observer: keeps a [`SharedView`] folded.
///
/// The node shows each insertion of a received batch only once the whole batch is in the log,
/// so folding them one by one would apply an object's later edits at its first insertion and
/// then re-fold the object from its creation at each next one (a 10^4-op join took a minute).
/// The insertions of a step are merged instead (each object from its earliest changed entry)
/// and folded once when the step settles.
pub struct Folder {
    pub(super) view: SharedView,
    /// The step's insertions, not folded yet.
    pub(super) pending: Drained,
    /// Where mismatches of the scene check are said.
    news: Option<Arc<Mutex<super::News>>>,
    /// The view's generation and the cut whose scene hash the peer was last told.
    announced: Option<(u64, SceneCut)>,
}

impl Folder {
    /// A folder of `view`.
    pub fn new(view: SharedView) -> Folder {
        Folder {
            view,
            pending: Drained::default(),
            news: None,
            announced: None,
        }
    }

    /// A folder of `view` that says what the scene check finds in `news`.
    pub fn with_news(view: SharedView, news: Arc<Mutex<super::News>>) -> Folder {
        Folder {
            news: Some(news),
            ..Folder::new(view)
        }
    }

    /// Answers the scene check ([`replication::sync::scene`]): a mismatch is said and answered
    /// with this scene's per-object hashes, a resync refolds what differs, and the scene's
    /// hash goes to the peer once the fold is at a new cut or changed, while some connection
    /// is in step (a hash computed mid-sync would only be at another cut than every remote's,
    /// and a remote that stays out of step must not keep the others from comparing), at most
    /// as often as [`View::scene_hash_if_due`] allows: a peer sculpting live on a large scene
    /// costs this thread one hash per interval, not one per stroke. A hash not due yet goes
    /// at a later step (the engine asks the node for its statistics every
    /// [`super::PEER_REFRESH_MILLIS`], which is a step).
    fn check_scene(&mut self, view: &mut View, peer: &mut Peer<ShapePayload>) {
        let cut = SceneCut::of(peer.log());
        while let Some((conn, event)) = peer.poll_scene_event() {
            let remote = (peer.connections())
                .find(|(c, _)| **c == conn)
                .and_then(|(_, sync)| sync.remote());
            match event {
                SceneEvent::Mismatch(mismatch) => {
                    self.note_mismatch(view, remote, &mismatch);
                    if mismatch.ours.cut == cut.digest && !peer.reuse_object_hashes(cut) {
                        peer.set_object_hashes(cut, view.scene.object_hashes());
                    }
                }
                SceneEvent::Resync(resync) if resync.cut == cut.digest => {
                    view.resync(peer.log(), &resync.objects, resync.rest);
                    let who = remote.map_or_else(|| "a peer".into(), |r| view.peer_label(r));
                    self.say(format!(
                        "refolded {} object(s){} whose state differed from {who}'s",
                        resync.objects.len(),
                        if resync.rest { " and the chat" } else { "" },
                    ));
                }
                SceneEvent::Resync(_) => {}
            }
        }
        let in_step = (peer.connections())
            .any(|(_, sync)| sync.remote_version_vector() == peer.log().version_vector());
        let now = (view.generation, cut);
        if in_step
            && self.announced != Some(now)
            && let Some(hash) = view.scene_hash_if_due(crate::clock::now().instant)
        {
            peer.set_scene_hash(cut, hash.0);
            self.announced = Some(now);
        }
    }

    /// A mismatch with `remote`: logged and said with both cuts, counted in its row.
    fn note_mismatch(&self, view: &mut View, remote: Option<PeerId>, m: &SceneMismatch) {
        let who = remote.map_or_else(|| "a peer".into(), |r| view.peer_label(r));
        let line = format!(
            "the scene differs from {who}'s: ours {}, theirs {}; refolding the objects that \
             differ",
            scene_at_text(&m.ours),
            scene_at_text(&m.theirs)
        );
        log::warn!("{line}");
        if let Some(news) = &self.news {
            news.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push(line.clone());
        }
        view.scene_check.n_mismatches += 1;
        view.scene_check.last_mismatch = Some(line.clone());
        if let Some(row) = view.peers.iter_mut().find(|r| Some(r.peer) == remote) {
            row.scene_mismatches += 1;
            row.last_mismatch = Some(line);
        }
    }

    fn say(&self, line: String) {
        log::info!("{line}");
        if let Some(news) = &self.news {
            news.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push(line);
        }
    }
}

/// A scene hash at a cut in words: the hash, the cut's digest and its ops (first bytes in
/// hex, as the peers panel shows hashes).
fn scene_at_text(at: &SceneAt) -> String {
    format!(
        "{} at cut {} ({} ops)",
        short_hex(&at.hash),
        short_hex(&at.cut),
        at.n_ops
    )
}

/// The first 8 bytes of a digest in hex, as the peers panel, dumps and news show digests.
fn short_hex(bytes: &[u8]) -> String {
    bytes.iter().take(8).map(|b| format!("{b:02x}")).collect()
}

impl Observer<ShapePayload> for Folder {
    fn inserted(&mut self, _log: &Log<ShapePayload>, insertion: &Insertion) {
        self.pending.add(insertion);
    }

    fn capture_snapshot(
        &mut self,
        log: &Log<ShapePayload>,
    ) -> Option<Result<Vec<u8>, CaptureError>> {
        let view = lock(&self.view);
        Some(Snapshot::capture(log, &view.scene).encode())
    }

    fn join_snapshot(
        &mut self,
        snapshot: Snapshot<ShapePayload>,
        log: Log<ShapePayload>,
        now: Timestamp,
    ) -> Option<Result<Log<ShapePayload>, JoinError>> {
        Some(snapshot.join::<ShapeScene>(log, now).map(|(log, scene)| {
            self.pending = Drained::default();
            lock(&self.view).adopt(scene);
            log
        }))
    }

    fn refold(&mut self, log: &Log<ShapePayload>) {
        self.pending = Drained::default();
        lock(&self.view).adopt(Materialized::fold(log));
    }

    fn settled(&mut self, peer: &mut Peer<ShapePayload>, changed: bool) {
        let view_arc = Arc::clone(&self.view);
        let mut view = lock(&view_arc);
        let drained = std::mem::take(&mut self.pending);
        if let Some(refold) = &drained.refold {
            view.apply_refold(peer.log(), &drained.delivered, refold);
        }
        self.check_scene(&mut view, peer);
        if changed {
            view.refresh(peer.log());
            if let Some(wake) = &view.waker {
                wake();
            }
        }
        let mine = peer.log().version_vector();
        for row in view.peers.iter_mut().filter(|r| r.online) {
            let Some((_, sync)) = peer
                .connections()
                .find(|(_, s)| s.remote() == Some(row.peer))
            else {
                continue;
            };
            let theirs = sync.remote_version_vector();
            row.scene_agrees = sync.stats().scene.agrees;
            row.to_send = mine
                .iter()
                .map(|(a, seq)| seq.saturating_sub(theirs.get(a)))
                .sum();
            row.to_receive = theirs
                .iter()
                .map(|(a, seq)| seq.saturating_sub(mine.get(a)))
                .sum();
        }
        let agrees = (view.peers.iter().filter(|r| r.online)).filter_map(|r| r.scene_agrees);
        view.scene_check.agrees = agrees.reduce(|a, b| a && b);
    }
}

/// `scene` with every object's edits indexed: the view's objects are what the mesher, the
/// servo and picking sample, each from its own copy, which shares the index only when the
/// view's object holds it (otherwise every copy indexes the whole history again).
fn prepared(
    mut scene: Materialized<ShapePayload, ShapeScene>,
) -> Materialized<ShapePayload, ShapeScene> {
    let objects = scene.scene().scene().objects();
    let ids: Vec<replication::ObjectId> =
        objects.map(|(id, _)| replication::ObjectId(id.0)).collect();
    scene.prepare(ids);
    scene
}

/// The latest [`MAX_HISTORY_ROWS`] ops of `log`, oldest first.
fn history(log: &Log<ShapePayload>, me: PeerId, scene: &Scene) -> Vec<HistoryRow> {
    // Parts are how a large change travels; its `Assemble` is the row that says what it did.
    let mut last = std::collections::VecDeque::with_capacity(MAX_HISTORY_ROWS);
    for entry in log
        .entries()
        .filter(|e| !matches!(e.op.payload(), ShapePayload::Part { .. }))
    {
        if last.len() == MAX_HISTORY_ROWS {
            last.pop_front();
        }
        last.push_back(entry);
    }
    last.into_iter()
        .map(|entry| {
            let payload = entry.op.payload();
            let status = match entry.mark {
                _ if log.is_void(&entry.op.id()) => "void: its author was expelled".to_string(),
                Mark::Rejected(reason) => format!("rejected: {reason}"),
                Mark::Effective
                    if !entry.active && matches!(payload.effect(), Effect::Edit { .. }) =>
                {
                    "undone".to_string()
                }
                Mark::Effective => "effective".to_string(),
            };
            let mine = entry.op.author() == me;
            let edits = matches!(payload.effect(), Effect::Edit { .. }) && !undo_skips(payload);
            HistoryRow {
                author: entry.op.author().short(),
                mine,
                op: entry.op.id(),
                undoable: mine && edits && entry.active,
                time: time_of_day_utc(entry.op.timestamp()),
                what: describe(log, scene, payload),
                status,
            }
        })
        .collect()
}

/// Per object, this peer's latest active change (what `undo` undoes; creations excluded),
/// and the edit its latest effective undo still holds back (what `redo` redoes).
fn targets(log: &Log<ShapePayload>, me: PeerId) -> (BTreeMap<u64, OpId>, BTreeMap<u64, OpId>) {
    let mut undo = BTreeMap::new();
    let mut redo = BTreeMap::new();
    let entries: Vec<_> = log.entries().filter(|e| e.op.author() == me).collect();
    for e in entries.iter().rev() {
        match e.op.payload() {
            payload if undo_skips(payload) => {}
            ShapePayload::Undo(target) => {
                let Some(object) = log.get(target).and_then(|op| edited_object(op.payload()))
                else {
                    continue;
                };
                // The latest effective undo whose edit is still held back names the target.
                let held_back = !log.is_active(target) && log.mark(target) == Some(Mark::Effective);
                if e.mark == Mark::Effective && held_back {
                    redo.entry(object).or_insert(*target);
                }
            }
            payload => {
                if let Some(object) = edited_object(payload)
                    && e.active
                {
                    undo.entry(object).or_insert_with(|| e.op.id());
                }
            }
        }
    }
    (undo, redo)
}

/// Whether `undo` leaves `payload` alone: it makes an object, or it is a piece of a large
/// change (undoing a part would take the whole change back at the next refold).
fn undo_skips(payload: &ShapePayload) -> bool {
    matches!(
        payload,
        ShapePayload::Create { .. } | ShapePayload::Part { .. } | ShapePayload::Assemble { .. }
    )
}

/// The object an edit changes, if the payload is an edit of an object.
fn edited_object(payload: &ShapePayload) -> Option<u64> {
    match payload.effect() {
        Effect::Edit { object } if object.0 & GROUP_BIT == 0 => Some(object.0),
        _ => None,
    }
}

/// An object's name, or `object N` when it has none (or is gone).
pub fn object_label(scene: &Scene, object: u64) -> String {
    match scene.object(ObjectId(object)) {
        Some(o) if !o.data().name.is_empty() => o.data().name.clone(),
        _ => format!("object {}", object & 0xffff_ffff),
    }
}

/// What a payload does, in words.
fn describe(log: &Log<ShapePayload>, scene: &Scene, payload: &ShapePayload) -> String {
    let label = |object: u64| object_label(scene, object);
    let describe_op = |id: &OpId| match log.get(id) {
        // An undo names an edit, never another undo: one level of description is enough.
        Some(op) => match op.payload() {
            ShapePayload::Undo(_) | ShapePayload::Redo(_) => format!("op {}", id.short()),
            other => describe(log, scene, other),
        },
        None => format!("op {}", id.short()),
    };
    match payload {
        ShapePayload::Create { object, data, .. } => {
            let name = if data.name.is_empty() {
                format!("object {}", object & 0xffff_ffff)
            } else {
                data.name.clone()
            };
            format!("created {name}")
        }
        ShapePayload::Delete { object } => format!("deleted {}", label(*object)),
        ShapePayload::Set { object, field } => format!(
            "set the {} of {}{}",
            field.slot(),
            label(*object),
            field_text(field)
        ),
        ShapePayload::Edit { object, .. } => format!("sculpted {}", label(*object)),
        ShapePayload::SetGroup { value: Some(g), .. } if !g.name.is_empty() => {
            format!("set group \"{}\"", quote(&g.name))
        }
        ShapePayload::SetGroup { value: Some(_), .. } => "set a group".into(),
        ShapePayload::SetGroup { value: None, .. } => "removed a group".into(),
        ShapePayload::Move { object, .. } => format!("moved {}", label(*object)),
        ShapePayload::Lease(LeaseAction::Acquire { object, .. }) => {
            format!("took the lease of {}", label(*object))
        }
        ShapePayload::Lease(LeaseAction::Release { object }) => {
            format!("released {}", label(*object))
        }
        ShapePayload::Undo(target) => format!("undo: {}", describe_op(target)),
        ShapePayload::Redo(target) => format!("redo: {}", describe_op(target)),
        ShapePayload::Chat(text) => format!("said \"{}\"", quote(text)),
        ShapePayload::Part { object, bytes } => {
            format!(
                "sent {} bytes of a change to {}",
                bytes.len(),
                label(*object)
            )
        }
        ShapePayload::Assemble { object, parts } => format!(
            "put together a change to {} from {} parts",
            label(*object),
            parts.len()
        ),
        ShapePayload::Member(m) if m.expel => format!("expelled {}", m.member.short()),
        ShapePayload::Member(m) => format!("readmitted {}", m.member.short()),
        ShapePayload::Admit(a) if a.nonce.is_some() => "founded the session".into(),
        ShapePayload::Admit(a) => format!("admitted {}", a.key.short()),
    }
}

/// The text a history row quotes for a property.
fn field_text(field: &Field) -> String {
    match field {
        Field::Geometry(Some(g)) => match &g.shape {
            Shape::Implicit(f) => format!(" to {}", quote(f.as_str())),
            Shape::Parametric { formula, .. } => format!(" to {}", quote(formula.as_str())),
            Shape::Mesh(_) => " to a mesh".into(),
        },
        Field::Diffuse(Some(ColorDef::Constant(c))) => format!(" to {c:?}"),
        Field::Diffuse(Some(ColorDef::Rgb(f))) => format!(" to {}", quote(f.as_str())),
        Field::Diffuse(Some(ColorDef::Map { formula, .. })) => {
            format!(" to {} through its map", quote(formula.as_str()))
        }
        _ => String::new(),
    }
}

/// At most [`MAX_QUOTE_CHARS`] characters of `text`, with an ellipsis when cut.
pub fn quote(text: &str) -> String {
    let mut out: String = text.chars().take(MAX_QUOTE_CHARS).collect();
    if text.chars().count() > MAX_QUOTE_CHARS {
        out.push('…');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_changing_scene_is_hashed_at_most_as_often_as_its_interval_allows() {
        let me = replication::Keypair::from_seed([3; 32]).peer_id();
        let mut view = View::new(me, &Log::default()).unwrap();
        let t0 = crate::clock::now().instant;
        let first = view.scene_hash_if_due(t0).expect("never hashed: due");
        assert_eq!(
            view.scene_hash_if_due(t0),
            Some(first),
            "current: no new hash"
        );
        // The scene changes right after: not due until the interval has passed.
        view.plant_scene_difference(1);
        view.plant_scene_difference(2);
        assert_eq!(view.scene_hash_if_due(t0), None);
        let stale = view.recent_scene_hash_hex(t0);
        assert_eq!(
            stale,
            View::hash_hex(&first),
            "the last one, of an older scene"
        );
        let later = t0 + std::time::Duration::from_millis(MIN_SCENE_HASH_INTERVAL_MILLIS + 1);
        let second = view.scene_hash_if_due(later).expect("due");
        assert_eq!(second, view.scene_hash(), "due means current");
        // What a test or a dump asks for is always current.
        view.plant_scene_difference(3);
        assert_eq!(view.scene_hash_if_due(later), None);
        assert_eq!(view.scene_hash(), view.scene.scene_hash());
    }

    #[test]
    fn each_consumer_reads_the_changes_since_its_own_cursor() {
        let mut log = ChangeLog::default();
        let (all, start) = log.since(0);
        assert_eq!(all, None, "a new consumer sees everything");
        log.push(Change::Object(ObjectId(1)));
        log.push(Change::Object(ObjectId(2)));
        let (first, a) = log.since(start);
        assert_eq!(first, Some([ObjectId(1), ObjectId(2)].into()));
        log.push(Change::Object(ObjectId(2)));
        assert_eq!(log.since(a).0, Some([ObjectId(2)].into()));
        assert_eq!(
            log.since(start).0.map(|s| s.len()),
            Some(2),
            "another cursor"
        );
        log.push(Change::All);
        assert_eq!(log.since(a).0, None, "a group change touches everything");
        let (_, end) = log.since(a);
        assert_eq!(log.since(end).0, Some(BTreeSet::new()));
        for i in 0..MAX_CHANGES as u64 + 10 {
            log.push(Change::Object(ObjectId(i)));
        }
        assert_eq!(log.since(end).0, None, "a cursor older than what is kept");
        let (_, now) = log.since(0);
        log.push(Change::Object(ObjectId(7)));
        assert_eq!(log.since(now).0, Some([ObjectId(7)].into()));
    }

    #[test]
    fn only_the_founder_plans_an_expel_of_a_member_named_by_name_or_id() {
        use replication::membership::FounderCommitment;
        let founder = replication::Keypair::from_seed([3; 32]);
        let member = replication::Keypair::from_seed([4; 32]).peer_id();
        let nonce = [7; FOUNDER_NONCE_BYTES];
        let mut log = replication::Log::default();
        log.set_founder(FounderCommitment::of(&founder.peer_id(), &nonce))
            .unwrap();
        let mut view = View::new(founder.peer_id(), &log).unwrap();
        view.note_presence(member, Presence::named("Ada".into(), [1, 2, 3]));
        let err = view.membership_change("Ada", true).unwrap_err();
        assert!(err.contains("founder"), "{err}");
        view.founder_nonce = Some(nonce);
        for who in ["ada", &member.to_hex()[..6]] {
            let planned = view.membership_change(who, true);
            assert_eq!(planned.map(|m| (m.member, m.expel)), Ok((member, true)));
        }
        assert!(
            view.membership_change("Bob", true)
                .unwrap_err()
                .contains("no member")
        );
        assert!(
            view.membership_change(&founder.peer_id().to_hex()[..8], true)
                .is_err()
        );
        assert!(
            view.membership_change("Ada", false)
                .unwrap_err()
                .contains("not expelled")
        );
        // Authored, the expel counts: the view lists the member as expelled, and a readmit
        // is planned.
        let expel = view.membership_change("Ada", true).unwrap();
        log.author(
            &founder,
            Timestamp(1_000),
            ShapePayload::Member(Box::new(expel)),
        )
        .unwrap();
        view.refresh(&log);
        assert!(view.expelled().contains(&member));
        let readmit = view.membership_change("Ada", false).unwrap();
        assert!(!readmit.expel);
    }

    #[test]
    fn a_fork_the_log_saw_marks_its_author_in_the_view() {
        use replication::op::{Op, OpFields};
        let me = replication::Keypair::from_seed([3; 32]);
        let mut log = replication::Log::default();
        let mut view = View::new(me.peer_id(), &log).unwrap();
        let op = |text: &str| {
            let fields = OpFields {
                seq: 1,
                lamport: 1,
                timestamp: replication::Timestamp(1),
                deps: Vec::new(),
                payload: ShapePayload::Chat(text.into()),
            };
            Op::sign(&me, &replication::op::UNNAMED_SESSION, fields).unwrap()
        };
        log.insert(
            replication::Timestamp(2),
            op("here"),
            replication::log::LOCAL_ORIGIN,
        )
        .unwrap();
        view.refresh(&log);
        assert!(view.forked().is_empty());
        // The same identity, run twice, signed another op as #1: both are held, neither counts.
        let other = log.insert(
            replication::Timestamp(2),
            op("there"),
            replication::pending::Origin(1),
        );
        assert!(other.is_ok_and(|i| i.delivered.len() == 1));
        assert_eq!(log.len(), 2);
        assert!(log.entries().all(|e| !e.active));
        view.refresh(&log);
        assert_eq!(view.forked().get(&me.peer_id()), Some(&1));
        // Both are this peer's rejected ops, and the advice is about the fork, not a lease.
        let rejections = view.my_rejections();
        assert_eq!(rejections.len(), 2);
        for r in rejections {
            assert!(r.why.contains("forked"), "{}", r.why);
            assert!(r.remedy.contains("new identity"), "{}", r.remedy);
            assert!(!r.remedy.contains("lease"), "{}", r.remedy);
        }
    }
}
