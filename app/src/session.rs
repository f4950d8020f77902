//! The solo session: one `replication::Peer<ShapePayload>` (a key pair generated once and kept
//! next to the store), its log folded into a `ShapeScene`, and the embedded local store
//! (`replication::store::OpStore`) every authored op is appended to before it counts.
//!
//! Store layout, in the store directory: `identity.key` (the 32-byte ed25519 seed, mode 0600)
//! and `ops.sculpt` (the op log). What is stored is never deleted: the op file is copied
//! before it is opened, because opening cuts off a damaged tail; when something was cut the
//! copy is kept as `ops.damaged-<micros>.sculpt`, and when opening fails the copy is put back.
//! A store that cannot be used leaves the session in memory, with the reason in
//! [`Session::store_error`], and its files untouched.

use std::fs;
use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};

use fdsl::fvrml::{LoadOptions, load};
use fdsl::object::{ColorDef, Field, Shape};
use replication::log::AuthorError;
use replication::materialize::Materialized;
use replication::shape::{ShapePayload, ShapeScene};
use replication::store::{OpStore, OpenError, record::RecordError};
use replication::sync::message::SessionId;
use replication::{Effect, Keypair, Log, Mark, OpId, Payload as _, Peer, PeerId, Timestamp};

use crate::clock::time_of_day_utc;

/// The identity key's file name in the store directory.
pub const KEY_FILE: &str = "identity.key";
/// The op log's file name in the store directory.
pub const OPS_FILE: &str = "ops.sculpt";
/// Bytes of the identity key file: an ed25519 seed.
pub const KEY_FILE_BYTES: usize = 32;
/// Most history rows the UI is given (the latest ones).
pub const HISTORY_ROWS_MAX: usize = 500;
/// Most characters of a formula or chat text quoted in a history row.
pub const QUOTE_CHARS_MAX: usize = 60;
/// The sync session of a solo peer (no connection is ever made with it).
const SOLO_SESSION: SessionId = *b"sculpt-solo-v1\0\0";
/// The demo scene authored into an empty store: the thesis's watermelon.
pub const DEMO_SCENE: &str = include_str!("../../tests/data/scenes/watermelon.wrl");

/// Why the store cannot be used; the session then runs in memory.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The directory could not be created.
    #[error("cannot create the store directory {path}: {source}")]
    CreateDir {
        /// The directory.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The identity key could not be read or written.
    #[error("identity key {path}: {source}")]
    KeyIo {
        /// The key file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The identity key has the wrong length.
    #[error("identity key {path} is {len} bytes, not {KEY_FILE_BYTES}; it was left as it is")]
    BadKey {
        /// The key file.
        path: PathBuf,
        /// Its length.
        len: u64,
    },
    /// No entropy for a new key.
    #[error("cannot read /dev/urandom for a new identity key: {0}")]
    Entropy(std::io::Error),
    /// The op file could not be copied before opening.
    #[error("cannot copy {path} before opening it: {source}")]
    Copy {
        /// The op file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The op file could not be opened or loaded.
    #[error("op store {path} cannot be opened: {source}; it was left as it was")]
    Open {
        /// The op file.
        path: PathBuf,
        /// Why.
        source: OpenError,
    },
    /// The stored ops do not fold into a scene.
    #[error("the stored ops do not fold into a scene: {0}")]
    Fold(String),
}

/// Why a command's op was not authored.
#[derive(Debug, thiserror::Error)]
pub enum AuthorFailure {
    /// The payload is not valid (a formula does not compile, a text is too long).
    #[error("{0}")]
    Invalid(String),
    /// The log refused it.
    #[error(transparent)]
    Log(#[from] AuthorError),
}

/// One chat line for the UI.
#[derive(Clone, Debug, PartialEq)]
pub struct ChatRow {
    /// Short id of the author.
    pub author: String,
    /// `HH:MM:SS` UTC of the op's timestamp.
    pub time: String,
    /// The text.
    pub text: String,
}

/// One op of the history for the UI.
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryRow {
    /// Short id of the author.
    pub author: String,
    /// `HH:MM:SS` UTC of the op's timestamp.
    pub time: String,
    /// What it does, in words.
    pub what: String,
    /// `effective`, `undone` or `rejected: <reason>`.
    pub status: String,
}

/// The solo peer with its scene and store.
pub struct Session {
    peer: Peer<ShapePayload>,
    scene: Materialized<ShapePayload, ShapeScene>,
    store: Option<OpStore<ShapePayload>>,
    dir: PathBuf,
    store_error: Option<String>,
    notices: Vec<String>,
    n_loaded: usize,
}

/// What opening the store directory gave.
struct Persisted {
    keypair: Keypair,
    store: OpStore<ShapePayload>,
    log: Log<ShapePayload>,
    notices: Vec<String>,
}

impl Session {
    /// Opens the store in `dir` (creating it), loads its ops and, when it holds none, authors
    /// the demo scene. Never fails: a store that cannot be used gives an in-memory session
    /// whose [`Session::store_error`] says why, with the store's files left as they were.
    pub fn open(dir: &Path, now: Timestamp) -> Session {
        let (peer, store, mut notices, store_error) = match open_persisted(dir, now) {
            Ok(p) => (
                Peer::new(p.keypair, SOLO_SESSION, p.log),
                Some(p.store),
                p.notices,
                None,
            ),
            Err(e) => (
                Peer::new(memory_keypair(now), SOLO_SESSION, Log::default()),
                None,
                Vec::new(),
                Some(e.to_string()),
            ),
        };
        let (mut peer, mut store, mut store_error) = (peer, store, store_error);
        // Only a log joined from a snapshot can fail to fold (its base scene is decoded), and
        // a log read from a store never is; still, should it fail, work in memory from an
        // empty log (whose fold cannot fail), leaving the file alone.
        let scene = loop {
            match Materialized::fold(peer.log()) {
                Ok(scene) => break scene,
                Err(e) => {
                    store = None;
                    store_error = Some(StoreError::Fold(e.to_string()).to_string());
                    peer = Peer::new(memory_keypair(now), SOLO_SESSION, Log::default());
                }
            }
        };
        let n_loaded = peer.log().len();
        let mut session = Session {
            peer,
            scene,
            store,
            dir: dir.to_path_buf(),
            store_error,
            notices: Vec::new(),
            n_loaded,
        };
        if session.peer.log().is_empty()
            && let Err(e) = session.author_demo(now)
        {
            notices.push(format!("the demo scene could not be authored: {e}"));
        }
        session.notices.extend(notices);
        session
    }

    fn author_demo(&mut self, now: Timestamp) -> Result<(), String> {
        let first = self.next_object_id();
        for payload in demo_payloads(first)? {
            self.author(now, payload).map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// Validates, authors and stores a local op, then folds it into the scene. A store that
    /// fails here stops being written (the reason goes to [`Session::store_error`]); the op
    /// stays in the session.
    pub fn author(&mut self, now: Timestamp, payload: ShapePayload) -> Result<OpId, AuthorFailure> {
        payload.validate().map_err(AuthorFailure::Invalid)?;
        let (op, insertion) = self.peer.author(now, payload)?;
        if let Some(store) = &mut self.store {
            let log = self.peer.log();
            let ops: Vec<_> = insertion
                .delivered
                .iter()
                .filter_map(|id| log.get(id))
                .collect();
            if let Err(e) = store.append(&ops) {
                self.store_error = Some(append_error(&self.dir, &e));
                self.store = None;
            }
        }
        self.scene.apply_insertion(self.peer.log(), &insertion);
        Ok(op.id())
    }

    /// This peer's id.
    pub fn peer_id(&self) -> PeerId {
        self.peer.peer_id()
    }

    /// The store directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Why edits are not being saved, if they are not.
    pub fn store_error(&self) -> Option<&str> {
        self.store_error.as_deref()
    }

    /// Things the user should know about the store (a damaged tail cut off and kept).
    pub fn notices(&self) -> &[String] {
        &self.notices
    }

    /// Ops loaded from the store at open.
    pub fn n_loaded(&self) -> usize {
        self.n_loaded
    }

    /// Ops in the log.
    pub fn n_ops(&self) -> usize {
        self.peer.log().len()
    }

    /// The materialised scene.
    pub fn scene(&self) -> &fdsl::scene::Scene {
        self.scene.scene().scene()
    }

    /// The scene hash (equal on every peer with the same ops).
    pub fn scene_hash_hex(&self) -> String {
        self.scene
            .scene_hash()
            .0
            .iter()
            .take(8)
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// The chat, in linear order.
    pub fn chat(&self) -> Vec<ChatRow> {
        let log = self.peer.log();
        self.scene
            .scene()
            .chat()
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

    /// The latest [`HISTORY_ROWS_MAX`] ops, oldest first, with what became of them.
    pub fn history(&self) -> Vec<HistoryRow> {
        let log = self.peer.log();
        let skip = log.len().saturating_sub(HISTORY_ROWS_MAX);
        log.entries()
            .skip(skip)
            .map(|entry| {
                let payload = entry.op.payload();
                let status = match entry.mark {
                    Mark::Rejected(reason) => format!("rejected: {reason}"),
                    Mark::Effective
                        if !entry.active && matches!(payload.effect(), Effect::Edit { .. }) =>
                    {
                        "undone".to_string()
                    }
                    Mark::Effective => "effective".to_string(),
                };
                HistoryRow {
                    author: entry.op.author().short(),
                    time: time_of_day_utc(entry.op.timestamp()),
                    what: self.describe(payload),
                    status,
                }
            })
            .collect()
    }

    /// What a payload does, in words.
    fn describe(&self, payload: &ShapePayload) -> String {
        let label = |object: u64| self.object_label(object);
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
            ShapePayload::Set { object, field } => {
                format!(
                    "set the {} of {}{}",
                    field.slot(),
                    label(*object),
                    field_text(field)
                )
            }
            ShapePayload::Edit { object, .. } => format!("sculpted {}", label(*object)),
            ShapePayload::SetGroup { group, .. } => format!("changed group {group}"),
            ShapePayload::Move { object, .. } => format!("moved {}", label(*object)),
            ShapePayload::Acquire { object, .. } => format!("took the lease of {}", label(*object)),
            ShapePayload::Release { object } => format!("released {}", label(*object)),
            ShapePayload::Undo(target) => format!("undo: {}", self.describe_op(target)),
            ShapePayload::Redo(target) => format!("redo: {}", self.describe_op(target)),
            ShapePayload::Chat(text) => format!("said \"{}\"", quote(text)),
        }
    }

    fn describe_op(&self, id: &OpId) -> String {
        match self.peer.log().get(id) {
            Some(op) => self.describe(op.payload()),
            None => format!("op {}", id.short()),
        }
    }

    /// An object's name, or `object N` when it has none (or is gone).
    pub fn object_label(&self, object: u64) -> String {
        match self.scene().object(fdsl::scene::ObjectId(object)) {
            Some(o) if !o.data().name.is_empty() => o.data().name.clone(),
            _ => format!("object {}", object & 0xffff_ffff),
        }
    }

    /// The latest of this peer's changes to `object` that is in effect: what `undo` undoes.
    /// Its creation is not one (undoing it would make the object vanish).
    pub fn undo_target(&self, object: u64) -> Option<OpId> {
        let me = self.peer_id();
        let log = self.peer.log();
        let entries: Vec<_> = log.entries().collect();
        entries.iter().rev().find_map(|e| {
            let payload = e.op.payload();
            let mine = e.op.author() == me;
            let edits = matches!(payload.effect(), Effect::Edit { object: o } if o.0 == object)
                && !matches!(payload, ShapePayload::Create { .. });
            (mine && edits && e.active).then(|| e.op.id())
        })
    }

    /// The edit of `object` that this peer's latest effective undo took back and that is still
    /// undone: what `redo` redoes.
    pub fn redo_target(&self, object: u64) -> Option<OpId> {
        let me = self.peer_id();
        let log = self.peer.log();
        let entries: Vec<_> = log.entries().collect();
        entries.iter().rev().find_map(|e| {
            let ShapePayload::Undo(target) = e.op.payload() else {
                return None;
            };
            if e.op.author() != me || e.mark != Mark::Effective || log.is_active(target) {
                return None;
            }
            let undone = log.get(target)?;
            let edits =
                matches!(undone.payload().effect(), Effect::Edit { object: o } if o.0 == object);
            (edits && log.mark(target) == Some(Mark::Effective)).then_some(*target)
        })
    }

    /// A fresh object id: this peer's 31-bit prefix, then one more than its highest counter.
    pub fn next_object_id(&self) -> u64 {
        let me = self.peer_id().0;
        let prefix =
            u64::from(u32::from_le_bytes([me[0], me[1], me[2], me[3]]) & 0x7fff_ffff) << 32;
        let highest = self
            .peer
            .log()
            .entries()
            .filter_map(|e| match e.op.payload() {
                ShapePayload::Create { object, .. } if object & !0xffff_ffff == prefix => {
                    Some(object & 0xffff_ffff)
                }
                _ => None,
            })
            .max()
            .unwrap_or(0);
        prefix | (highest + 1).min(0xffff_ffff)
    }
}

fn append_error(dir: &Path, e: &RecordError) -> String {
    format!(
        "cannot save to {}: {e}; edits from now on are not saved",
        dir.join(OPS_FILE).display()
    )
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

/// At most [`QUOTE_CHARS_MAX`] characters of `text`, with an ellipsis when cut.
pub fn quote(text: &str) -> String {
    let mut out: String = text.chars().take(QUOTE_CHARS_MAX).collect();
    if text.chars().count() > QUOTE_CHARS_MAX {
        out.push('…');
    }
    out
}

/// The demo scene's objects as create ops with ids from `first_id` on.
pub fn demo_payloads(first_id: u64) -> Result<Vec<ShapePayload>, String> {
    let mut no_inline = |url: &str| Err(format!("the demo scene has no inline files ({url})"));
    let loaded = load(DEMO_SCENE, &LoadOptions::default(), &mut no_inline)
        .map_err(|e| format!("the demo scene does not load: {e}"))?;
    Ok(loaded
        .scene
        .objects()
        .zip(first_id..)
        .map(|((_, entry), object)| ShapePayload::Create {
            object,
            data: Box::new(entry.object.data().clone()),
            group: None,
        })
        .collect())
}

fn open_persisted(dir: &Path, now: Timestamp) -> Result<Persisted, StoreError> {
    fs::create_dir_all(dir).map_err(|source| StoreError::CreateDir {
        path: dir.to_path_buf(),
        source,
    })?;
    let ops_path = dir.join(OPS_FILE);
    let had_ops = fs::metadata(&ops_path).is_ok_and(|m| m.len() > 0);
    let (keypair, key_notice) = load_or_create_key(&dir.join(KEY_FILE), had_ops)?;
    let mut log = Log::default();
    let (store, store_notice) = open_ops(dir, &ops_path, now, &mut log)?;
    Ok(Persisted {
        keypair,
        store,
        log,
        notices: key_notice.into_iter().chain(store_notice).collect(),
    })
}

/// Opens the op file, keeping a copy of it until it is known that opening cut nothing.
fn open_ops(
    dir: &Path,
    path: &Path,
    now: Timestamp,
    log: &mut Log<ShapePayload>,
) -> Result<(OpStore<ShapePayload>, Option<String>), StoreError> {
    let copy = dir.join(format!("{OPS_FILE}.opening"));
    let existed = path.exists();
    if existed {
        fs::copy(path, &copy).map_err(|source| StoreError::Copy {
            path: path.to_path_buf(),
            source,
        })?;
    }
    match OpStore::open_into_trusted(path, now, log) {
        Ok((store, recovery)) if recovery.n_truncated_bytes > 0 && existed => {
            let kept = dir.join(format!("ops.damaged-{}.sculpt", now.0));
            let notice = match fs::rename(&copy, &kept) {
                Ok(()) => format!(
                    "the store's last {} bytes were damaged (an interrupted write?) and were cut \
                     off after {} good ops; the file as it was is kept at {}",
                    recovery.n_truncated_bytes,
                    recovery.n_records,
                    kept.display()
                ),
                Err(e) => format!(
                    "the store's last {} bytes were damaged and cut off; the copy of the file \
                     as it was is at {} (renaming it failed: {e})",
                    recovery.n_truncated_bytes,
                    copy.display()
                ),
            };
            Ok((store, Some(notice)))
        }
        Ok((store, _)) => {
            // The copy equals what is on disk now: removing it loses nothing.
            if existed {
                let _ = fs::remove_file(&copy);
            }
            Ok((store, None))
        }
        Err(source) => {
            if existed {
                // Opening may have cut a tail before it failed: put the file back as it was.
                let _ = fs::rename(&copy, path);
            }
            Err(StoreError::Open {
                path: path.to_path_buf(),
                source,
            })
        }
    }
}

/// Reads the identity key, or makes one when there is none.
fn load_or_create_key(path: &Path, had_ops: bool) -> Result<(Keypair, Option<String>), StoreError> {
    let io = |source| StoreError::KeyIo {
        path: path.to_path_buf(),
        source,
    };
    match fs::File::open(path) {
        Ok(mut file) => {
            let len = file.metadata().map_err(io)?.len();
            if len != KEY_FILE_BYTES as u64 {
                return Err(StoreError::BadKey {
                    path: path.to_path_buf(),
                    len,
                });
            }
            let mut seed = [0u8; KEY_FILE_BYTES];
            file.read_exact(&mut seed).map_err(io)?;
            Ok((Keypair::from_seed(seed), None))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let seed = entropy_seed().map_err(StoreError::Entropy)?;
            write_key(path, &seed).map_err(io)?;
            let notice = had_ops.then(|| {
                format!(
                    "no identity key was found beside the stored ops, so a new one was made at {}; \
                     edits made under the old identity cannot be undone by this one",
                    path.display()
                )
            });
            Ok((Keypair::from_seed(seed), notice))
        }
        Err(e) => Err(io(e)),
    }
}

fn write_key(path: &Path, seed: &[u8; KEY_FILE_BYTES]) -> std::io::Result<()> {
    let mut options = fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.mode(0o600);
    }
    let mut file = options.open(path)?;
    file.write_all(seed)?;
    file.sync_all()
}

/// 32 unpredictable bytes for a new identity key: the app's one draw of OS entropy (an
/// identity must not be guessable, so a seeded RNG will not do here). Read once, then kept.
fn entropy_seed() -> std::io::Result<[u8; KEY_FILE_BYTES]> {
    let mut seed = [0u8; KEY_FILE_BYTES];
    fs::File::open("/dev/urandom")?.read_exact(&mut seed)?;
    Ok(seed)
}

/// A throwaway key for a session that cannot use its store (nothing it signs is kept).
fn memory_keypair(now: Timestamp) -> Keypair {
    match entropy_seed() {
        Ok(seed) => Keypair::from_seed(seed),
        Err(_) => {
            let mut seed = [7u8; KEY_FILE_BYTES];
            seed[..8].copy_from_slice(&now.0.to_le_bytes());
            Keypair::from_seed(seed)
        }
    }
}

#[cfg(test)]
mod tests;
