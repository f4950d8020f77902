//! Session keys: everything the transport and discovery derive from an invite code.
//!
//! One invite yields three independent values (blake3 `derive_key` with distinct contexts):
//! the sync session id the core checks in every hello, the admission key whose MACs prove
//! knowledge of the invite during the QUIC handshake, and the discovery id that discovery
//! servers and LAN announcements see. None of them reveals another or the invite.

use std::fmt;

use rand_core::CryptoRngCore;

use crate::identity::hex;
use crate::sync::message::{SESSION_ID_BYTES, SessionId};

/// Longest invite code accepted, in bytes (after trimming surrounding whitespace).
pub const MAX_INVITE_BYTES: usize = 256;
/// Random bytes in an invite made by [`generate_invite`] (128 bits).
pub const INVITE_RANDOM_BYTES: usize = 16;
/// Length of a [`DiscoveryId`].
pub const DISCOVERY_ID_BYTES: usize = 16;

/// What discovery servers and LAN announcements see of a session: a hash of its invite.
pub type DiscoveryId = [u8; DISCOVERY_ID_BYTES];

const SESSION_ID_CONTEXT: &str = "sculpt 2026 replication session id v1";
const ADMISSION_KEY_CONTEXT: &str = "sculpt 2026 replication admission key v1";
const DISCOVERY_ID_CONTEXT: &str = "sculpt 2026 replication discovery id v1";

/// Why an invite code was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InviteError {
    /// Nothing but whitespace.
    #[error("the invite code is empty")]
    Empty,
    /// Over [`MAX_INVITE_BYTES`].
    #[error("the invite code is {0} bytes, over the limit {MAX_INVITE_BYTES}")]
    TooLong(usize),
}

/// The keys of one session, derived from its invite code.
#[derive(Clone, PartialEq, Eq)]
pub struct SessionKeys {
    session_id: SessionId,
    admission_key: [u8; 32],
    discovery_id: DiscoveryId,
}

impl SessionKeys {
    /// Derives the keys of the session that `invite` opens. Surrounding whitespace is ignored
    /// so that a code pasted with a newline still works.
    ///
    /// The invite is the only secret: it should be long and random (see [`generate_invite`]),
    /// because a discovery server or a fake listener that sees the derived values can test
    /// guesses offline.
    pub fn from_invite(invite: &str) -> Result<Self, InviteError> {
        let invite = invite.trim();
        if invite.is_empty() {
            return Err(InviteError::Empty);
        }
        if invite.len() > MAX_INVITE_BYTES {
            return Err(InviteError::TooLong(invite.len()));
        }
        let derive = |context| blake3::derive_key(context, invite.as_bytes());
        let mut session_id = [0; SESSION_ID_BYTES];
        session_id.copy_from_slice(&derive(SESSION_ID_CONTEXT)[..SESSION_ID_BYTES]);
        let mut discovery_id = [0; DISCOVERY_ID_BYTES];
        discovery_id.copy_from_slice(&derive(DISCOVERY_ID_CONTEXT)[..DISCOVERY_ID_BYTES]);
        Ok(Self {
            session_id,
            admission_key: derive(ADMISSION_KEY_CONTEXT),
            discovery_id,
        })
    }

    /// The session id every sync hello carries.
    pub fn session_id(&self) -> SessionId {
        self.session_id
    }

    /// The id under which discovery servers and LAN announcements know this session.
    pub fn discovery_id(&self) -> DiscoveryId {
        self.discovery_id
    }

    /// The key of the admission MACs (secret).
    pub(crate) fn admission_key(&self) -> &[u8; 32] {
        &self.admission_key
    }
}

impl fmt::Debug for SessionKeys {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Never print the admission key.
        write!(f, "SessionKeys(discovery {})", hex(&self.discovery_id[..4]))
    }
}

/// A new random invite code, `xxxx-xxxx-...` (32 hex digits, 128 bits), from the RNG the
/// caller passes in.
pub fn generate_invite(rng: &mut impl CryptoRngCore) -> String {
    let mut bytes = [0; INVITE_RANDOM_BYTES];
    rng.fill_bytes(&mut bytes);
    bytes.chunks(2).map(hex).collect::<Vec<_>>().join("-")
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_chacha::ChaCha20Rng;
    use rand_core::SeedableRng;

    #[test]
    fn keys_are_independent_and_whitespace_insensitive() {
        let a = SessionKeys::from_invite("abcd-efgh").unwrap();
        assert_eq!(a, SessionKeys::from_invite("  abcd-efgh\n").unwrap());
        assert_ne!(a, SessionKeys::from_invite("abcd-efgi").unwrap());
        assert_ne!(&a.session_id()[..], &a.discovery_id()[..]);
        assert_ne!(&a.admission_key()[..16], &a.discovery_id()[..]);
        assert!(!format!("{a:?}").contains(&hex(a.admission_key())));
        assert_eq!(SessionKeys::from_invite(" \t"), Err(InviteError::Empty));
        let long = "x".repeat(MAX_INVITE_BYTES + 1);
        assert_eq!(
            SessionKeys::from_invite(&long),
            Err(InviteError::TooLong(MAX_INVITE_BYTES + 1))
        );
    }

    #[test]
    fn generated_invites_are_random_and_well_formed() {
        let mut rng = ChaCha20Rng::seed_from_u64(1);
        let a = generate_invite(&mut rng);
        let b = generate_invite(&mut rng);
        assert_ne!(a, b);
        assert_eq!(a.len(), 32 + 7, "{a}");
        assert!(SessionKeys::from_invite(&a).is_ok());
    }
}
