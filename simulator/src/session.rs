//! The session every peer of a run joins: its id, the nonce its founder's invite commits to,
//! and the cap on its bytes of ops when it binds its authors.

/// The session every peer joins.
pub const SESSION_ID: [u8; 16] = *b"sculpt-simulator";
/// The founder's nonce: with [`crate::config::Faults::expel`], the session's invite commits
/// to peer 0's key and this nonce, so peer 0 may expel ([`replication::membership`]).
pub const FOUNDER_NONCE: [u8; 32] = *b"sculpt simulator founder nonce!!";
/// The cap on bytes of ops of a run whose session binds its authors (the founder's budget,
/// [`replication::Log::bind_authors`]): small, so that a member can spend its whole grant
/// within a run. With a founder, even seeds run such a session (every session the app makes
/// now) and odd seeds one that does not (every session made before).
pub const SESSION_CAP_BYTES: u64 = 8 << 20;
