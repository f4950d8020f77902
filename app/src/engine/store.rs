//! A session's store directory: its invite, this peer's identity key and the op log.
//!
//! Layout: `session.invite` (the session's invite code), `identity.key` (the 32-byte ed25519
//! seed), `founder.nonce` (only in the store of the peer that made the session: what proves
//! it the founder, who may expel members) and `ops.sculpt` (the `OpStore`, with its `.lock` file and any torn tail it set
//! aside). The directory is made `0700` and the secret files `0600`; each secret is written
//! to a temporary file, synced, then linked into place, so a crash never leaves half a key.
//! The op store is locked for as long as it is open: a second process gets an error naming
//! the first. What is stored is never deleted or rewritten here.

use std::fs;
use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};

use replication::membership::FOUNDER_NONCE_BYTES;
use replication::net::invite::{Invite, InviteError};
use replication::shape::ShapePayload;
use replication::store::{OpStore, OpenError};
use replication::{Keypair, Log, Timestamp};

/// The session's invite file in a store directory.
pub const INVITE_FILE: &str = "session.invite";
/// The identity key's file name.
pub const KEY_FILE: &str = "identity.key";
/// The op log's file name.
pub const OPS_FILE: &str = "ops.sculpt";
/// The founder's secret nonce, in the store of the peer that made the session: the invite
/// commits to it and the founder's key ([`replication::membership`]), and showing it lets
/// the founder expel members.
pub const FOUNDER_NONCE_FILE: &str = "founder.nonce";
/// Bytes of the identity key file: an ed25519 seed.
pub const KEY_FILE_BYTES: usize = 32;
/// Longest invite file read (an invite is far shorter).
pub const MAX_INVITE_FILE_BYTES: u64 = 1024;

/// Why a store directory cannot be used.
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
    /// A secret file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
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
    /// The invite file does not hold an invite.
    #[error("{path} does not hold a valid invite ({source}); it was left as it is")]
    BadInvite {
        /// The invite file.
        path: PathBuf,
        /// Why.
        source: InviteError,
    },
    /// The store belongs to another session than the invite given.
    #[error(
        "the store {path} belongs to another session than this invite; give another --store \
         directory for this session (`sculpt sessions` lists them)"
    )]
    OtherSession {
        /// The store directory.
        path: PathBuf,
    },
    /// No entropy for a new key or invite.
    #[error("cannot read /dev/urandom: {0}")]
    Entropy(std::io::Error),
    /// Another process holds the op file (its message names the file and the holder).
    #[error("{0}")]
    Locked(OpenError),
    /// The op file could not be opened or loaded.
    #[error("the op store cannot be opened: {0}")]
    Open(OpenError),
}

// Not `#[from]`: the message already holds the cause's, which as the error's source too
// would print twice in a chain (`sculpt: {e:#}`).
impl From<OpenError> for StoreError {
    fn from(e: OpenError) -> StoreError {
        match e {
            OpenError::Locked { .. } => StoreError::Locked(e),
            _ => StoreError::Open(e),
        }
    }
}

/// An opened store directory.
pub struct Opened {
    /// This peer's key pair.
    pub keypair: Keypair,
    /// The session's invite.
    pub invite: Invite,
    /// True when this open made the session (no invite was given or stored).
    pub new_session: bool,
    /// The op store, locked.
    pub store: OpStore<ShapePayload>,
    /// The ops it held.
    pub log: Log<ShapePayload>,
    /// The founder's nonce, when this peer founded the session (it may expel members).
    pub founder_nonce: Option<[u8; FOUNDER_NONCE_BYTES]>,
    /// Things the user should know.
    pub notices: Vec<String>,
}

/// Opens (or makes) the store directory `dir` for the session of `invite` (a new session
/// when `None` and the directory holds none).
pub fn open(dir: &Path, invite: Option<&Invite>, now: Timestamp) -> Result<Opened, StoreError> {
    make_private_dir(dir)?;
    let ops_path = dir.join(OPS_FILE);
    let had_ops = fs::metadata(&ops_path).is_ok_and(|m| m.len() > 0);
    // The key and the invite before the ops: a new session's invite commits to its founder,
    // and the log judges expels against it from the first op on. Both are only ever created
    // (linked into place, never overwritten), so a second process racing here fails at the
    // link or at the op store's lock below.
    let (keypair, key_notice) = load_or_create_key(&dir.join(KEY_FILE), had_ops)?;
    let (invite, new_session) = session_invite(dir, invite, &keypair)?;
    let founder_nonce = read_founder_nonce(dir, &keypair, &invite)?;
    let mut log = founded_log(&invite);
    let (store, recovery) = OpStore::open_into_trusted(&ops_path, now, &mut log)?;
    let mut notices = Vec::new();
    if recovery.n_truncated_bytes > 0 {
        let kept = recovery.torn_tail.as_ref().map_or_else(String::new, |p| {
            format!("; the cut bytes are kept at {}", p.display())
        });
        notices.push(format!(
            "the store's last {} bytes were an interrupted write and were cut off after {} \
             good ops{kept}",
            recovery.n_truncated_bytes, recovery.n_records
        ));
    }
    notices.extend(key_notice);
    Ok(Opened {
        keypair,
        invite,
        new_session,
        store,
        log,
        founder_nonce,
        notices,
    })
}

/// An empty log of the session of `invite`: one whose founder's expels count, and which binds
/// its authors to their admissions when the invite says so (every session made now).
pub fn founded_log(invite: &Invite) -> Log<ShapePayload> {
    let mut log = Log::default();
    log.set_founder(invite.founder_commitment())
        .expect("an empty log takes a founder");
    if invite.binds_authors() {
        log.bind_authors(replication::log::MAX_LOG_BYTES)
            .expect("an empty founded log binds");
    }
    log
}

/// The founder's nonce stored in `dir`, if there is one and it makes this peer the founder
/// of `invite`'s session.
fn read_founder_nonce(
    dir: &Path,
    keypair: &Keypair,
    invite: &Invite,
) -> Result<Option<[u8; FOUNDER_NONCE_BYTES]>, StoreError> {
    let path = dir.join(FOUNDER_NONCE_FILE);
    let mut nonce = [0; FOUNDER_NONCE_BYTES];
    match fs::File::open(&path) {
        Ok(file) => {
            let mut bytes = Vec::new();
            file.take(FOUNDER_NONCE_BYTES as u64 + 1)
                .read_to_end(&mut bytes)
                .map_err(|source| StoreError::Io {
                    path: path.clone(),
                    source,
                })?;
            if bytes.len() != FOUNDER_NONCE_BYTES {
                return Ok(None);
            }
            nonce.copy_from_slice(&bytes);
            let founder = invite.founder_commitment();
            Ok(founder
                .is_founder(&keypair.peer_id(), &nonce)
                .then_some(nonce))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(StoreError::Io { path, source }),
    }
}

/// The invite stored in `dir`, checked against the one given; or the one given (or a new
/// one) written there.
fn session_invite(
    dir: &Path,
    given: Option<&Invite>,
    keypair: &Keypair,
) -> Result<(Invite, bool), StoreError> {
    let path = dir.join(INVITE_FILE);
    let io = |source| StoreError::Io {
        path: path.clone(),
        source,
    };
    match fs::File::open(&path) {
        Ok(file) => {
            let mut text = String::new();
            file.take(MAX_INVITE_FILE_BYTES)
                .read_to_string(&mut text)
                .map_err(io)?;
            let stored = Invite::parse(&text).map_err(|source| StoreError::BadInvite {
                path: path.clone(),
                source,
            })?;
            match given {
                Some(given) if given != &stored => Err(StoreError::OtherSession {
                    path: dir.to_path_buf(),
                }),
                _ => Ok((stored, false)),
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let (invite, new) = match given {
                Some(given) => (given.clone(), false),
                None => {
                    // The nonce first: an invite whose nonce was lost founds a session
                    // nobody can expel from.
                    let nonce = entropy_seed().map_err(StoreError::Entropy)?;
                    let nonce_path = dir.join(FOUNDER_NONCE_FILE);
                    write_secret(&nonce_path, &nonce).map_err(|source| StoreError::Io {
                        path: nonce_path,
                        source,
                    })?;
                    (Invite::for_founder(&keypair.peer_id(), &nonce), true)
                }
            };
            write_secret(&path, format!("{invite}\n").as_bytes()).map_err(io)?;
            Ok((invite, new))
        }
        Err(e) => Err(io(e)),
    }
}

/// Reads the identity key, or makes one when there is none.
fn load_or_create_key(path: &Path, had_ops: bool) -> Result<(Keypair, Option<String>), StoreError> {
    let io = |source| StoreError::Io {
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
            write_secret(path, &seed).map_err(io)?;
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

/// Makes `dir` (and its parents) with mode 0700 for what this call creates.
fn make_private_dir(dir: &Path) -> Result<(), StoreError> {
    let mut builder = fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt as _;
        builder.mode(0o700);
    }
    builder.create(dir).map_err(|source| StoreError::CreateDir {
        path: dir.to_path_buf(),
        source,
    })
}

/// Writes a secret file that must not exist yet: to a temporary file (0600), synced, then
/// linked into place (which fails rather than replace an existing file), then the directory
/// synced. A crash leaves either no file or the whole one.
pub fn write_secret(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .map_or_else(Default::default, |n| n.to_os_string());
    let mut tmp_name = name.clone();
    tmp_name.push(format!(".tmp-{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let _ = fs::remove_file(&tmp);
    let mut options = fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.mode(0o600);
    }
    let written = (|| {
        let mut file = options.open(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        fs::hard_link(&tmp, path)
    })();
    let _ = fs::remove_file(&tmp);
    written?;
    if let Some(parent) = path.parent() {
        fs::File::open(parent)?.sync_all()?;
    }
    Ok(())
}

/// 32 unpredictable bytes: the app's draw of OS entropy for identities and invites (they
/// must not be guessable, so a seeded RNG will not do here).
pub fn entropy_seed() -> std::io::Result<[u8; KEY_FILE_BYTES]> {
    let mut seed = [0u8; KEY_FILE_BYTES];
    fs::File::open("/dev/urandom")?.read_exact(&mut seed)?;
    Ok(seed)
}

/// A cryptographic RNG seeded from the OS, for invites.
pub fn entropy_rng() -> Result<rand_chacha::ChaCha20Rng, StoreError> {
    use rand_core::SeedableRng as _;
    let seed = entropy_seed().map_err(StoreError::Entropy)?;
    Ok(rand_chacha::ChaCha20Rng::from_seed(seed))
}

/// A throwaway key for a session that cannot use its store (nothing it signs is kept).
pub fn memory_keypair(now: Timestamp) -> Keypair {
    match entropy_seed() {
        Ok(seed) => Keypair::from_seed(seed),
        Err(_) => {
            let mut seed = [7u8; KEY_FILE_BYTES];
            seed[..8].copy_from_slice(&now.0.to_le_bytes());
            Keypair::from_seed(seed)
        }
    }
}

/// The name of the store directory a joined session gets by default: `joined-` and the first
/// bytes of a hash of its invite under a context of its own, so each session has its own. It
/// is not the discovery id, which takes a slow derivation (about 0.1 s and 64 MiB) to compute;
/// a directory name is only ever local, and the directory holds the invite anyway.
pub fn joined_dir_name(invite: &Invite) -> String {
    let hash = blake3::derive_key(
        "sculpt 2026-11-24 the store directory of a joined session",
        invite.to_string().as_bytes(),
    );
    let hex: String = hash[..6].iter().map(|b| format!("{b:02x}")).collect();
    format!("joined-{hex}")
}

/// The session store directories under `root` (each holding an invite file), sorted.
pub fn list_sessions(root: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut found: Vec<PathBuf> = fs::read_dir(root)?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.join(INVITE_FILE).is_file())
        .collect();
    found.sort();
    Ok(found)
}
