//! Session keys: everything the transport and discovery derive from an invite code.
//!
//! One invite yields three independent values (blake3 `derive_key` with distinct contexts,
//! over the invite's canonical text): the sync session id the core checks in every hello, the
//! admission key whose MACs prove knowledge of the invite during the QUIC handshake, and the
//! discovery id that discovery servers and LAN announcements see. None of them reveals
//! another or the invite.

use std::fmt;

use crate::identity::hex;
use crate::net::invite::Invite;
use crate::sync::message::{SESSION_ID_BYTES, SessionId};

/// Length of a [`DiscoveryId`].
pub const DISCOVERY_ID_BYTES: usize = 16;

/// What discovery servers and LAN announcements see of a session: a hash of its invite.
pub type DiscoveryId = [u8; DISCOVERY_ID_BYTES];

const SESSION_ID_CONTEXT: &str = "sculpt 2026 replication session id v1";
const ADMISSION_KEY_CONTEXT: &str = "sculpt 2026 replication admission key v1";
const DISCOVERY_ID_CONTEXT: &str = "sculpt 2026 replication discovery id v1";

/// The keys of one session, derived from its invite code.
#[derive(Clone, PartialEq, Eq)]
pub struct SessionKeys {
    session_id: SessionId,
    admission_key: [u8; 32],
    discovery_id: DiscoveryId,
}

impl SessionKeys {
    /// Derives the keys of the session that `invite` opens, from its canonical text, so that
    /// every accepted spelling of one code gives the same keys.
    ///
    /// The invite is the only secret. A discovery server or a fake listener that sees the
    /// derived values can test guesses offline, which is why an [`Invite`] carries 130 random
    /// bits and refuses codes made up by hand.
    pub fn from_invite(invite: &Invite) -> Self {
        let mut session_id = [0; SESSION_ID_BYTES];
        session_id.copy_from_slice(&invite.derive_key(SESSION_ID_CONTEXT)[..SESSION_ID_BYTES]);
        let mut discovery_id = [0; DISCOVERY_ID_BYTES];
        discovery_id
            .copy_from_slice(&invite.derive_key(DISCOVERY_ID_CONTEXT)[..DISCOVERY_ID_BYTES]);
        Self {
            session_id,
            admission_key: invite.derive_key(ADMISSION_KEY_CONTEXT),
            discovery_id,
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand_chacha::ChaCha20Rng;
    use rand_core::SeedableRng;

    #[test]
    fn keys_are_independent_and_spelling_insensitive() {
        let invite = Invite::generate(&mut ChaCha20Rng::seed_from_u64(1));
        let a = SessionKeys::from_invite(&invite);
        let typed = format!(
            "  {}\n",
            invite.to_string().to_uppercase().replace('-', " ")
        );
        assert_eq!(a, SessionKeys::from_invite(&Invite::parse(&typed).unwrap()));
        let other = Invite::generate(&mut ChaCha20Rng::seed_from_u64(2));
        assert_ne!(a, SessionKeys::from_invite(&other));
        assert_ne!(&a.session_id()[..], &a.discovery_id()[..]);
        assert_ne!(&a.admission_key()[..16], &a.discovery_id()[..]);
        assert!(!format!("{a:?}").contains(&hex(a.admission_key())));
    }
}
