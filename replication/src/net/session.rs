//! Session keys: everything the transport and discovery derive from an invite code.
//!
//! One invite yields three independent values: the sync session id the core checks in every
//! hello and the admission key whose MACs prove knowledge of the invite during the QUIC
//! handshake (blake3 `derive_key` with distinct contexts over the invite's canonical text),
//! and the discovery id that discovery servers and LAN announcements see. None of them
//! reveals another or the invite.
//!
//! The discovery id is the one value anybody can read (a LAN announcement carries it in
//! clear), so it is stretched first: argon2id with [`DISCOVERY_KDF_MEMORY_KIB`] of memory and
//! [`DISCOVERY_KDF_PASSES`] passes (about 0.1 s on a laptop core), then blake3 `derive_key`.
//! Someone who reads it and wants to test guessed invites pays that per guess, on top of the
//! invite's 130 random bits. The session id and the admission key are only seen inside TLS
//! (by admitted peers, or, for the MAC, by an acceptor a dialer chose), and stay fast.

use std::fmt;

use crate::identity::{SESSION_ID_BYTES, SessionId, hex};
use crate::net::invite::Invite;

/// Length of a [`DiscoveryId`].
pub const DISCOVERY_ID_BYTES: usize = 16;

/// What discovery servers and LAN announcements see of a session: a slow hash of its invite.
pub type DiscoveryId = [u8; DISCOVERY_ID_BYTES];

/// Memory of the argon2id stretch that derives a [`DiscoveryId`], in KiB (64 MiB, RFC 9106's
/// second recommended setting).
pub const DISCOVERY_KDF_MEMORY_KIB: u32 = 64 * 1024;
/// Passes of that stretch over its memory.
pub const DISCOVERY_KDF_PASSES: u32 = 3;
/// Lanes of that stretch (one: the derivation runs once per session join, on one core).
pub const DISCOVERY_KDF_LANES: u32 = 1;
/// The stretch's salt: fixed, since the invite is the only input and is itself random.
const DISCOVERY_KDF_SALT: &[u8] = b"sculpt 2026 replication discovery id v2 salt";

const SESSION_ID_CONTEXT: &str = "sculpt 2026 replication session id v1";
const ADMISSION_KEY_CONTEXT: &str = "sculpt 2026 replication admission key v1";
/// Version 2: over the argon2id stretch of the invite (version 1 hashed the invite itself).
const DISCOVERY_ID_CONTEXT: &str = "sculpt 2026 replication discovery id v2";

/// The argon2id stretch of `invite` that the discovery id is derived from.
fn stretch_for_discovery(invite: &Invite) -> [u8; 32] {
    let params = argon2::Params::new(
        DISCOVERY_KDF_MEMORY_KIB,
        DISCOVERY_KDF_PASSES,
        DISCOVERY_KDF_LANES,
        Some(32),
    )
    .unwrap_or_else(|e| panic!("the discovery KDF's parameters are constants: {e}"));
    let argon = argon2::Argon2::new(argon2::Algorithm::Argon2id, argon2::Version::V0x13, params);
    let mut out = [0; 32];
    argon
        .hash_password_into(&invite.canonical(), DISCOVERY_KDF_SALT, &mut out)
        .unwrap_or_else(|e| panic!("the discovery KDF's inputs have fixed, valid sizes: {e}"));
    out
}

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
    /// bits and refuses codes made up by hand, and why the public discovery id costs an
    /// argon2id stretch per guess.
    ///
    /// Slow on purpose (the stretch takes about 0.1 s and 64 MiB): derive once per session and
    /// keep the result.
    pub fn from_invite(invite: &Invite) -> Self {
        let mut session_id = [0; SESSION_ID_BYTES];
        session_id.copy_from_slice(&invite.derive_key(SESSION_ID_CONTEXT)[..SESSION_ID_BYTES]);
        let stretched = stretch_for_discovery(invite);
        let mut discovery_id = [0; DISCOVERY_ID_BYTES];
        discovery_id.copy_from_slice(
            &blake3::derive_key(DISCOVERY_ID_CONTEXT, &stretched)[..DISCOVERY_ID_BYTES],
        );
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

    #[test]
    fn the_discovery_id_is_stretched_with_the_named_argon2id_cost() {
        let invite = Invite::generate(&mut ChaCha20Rng::seed_from_u64(3));
        let id = SessionKeys::from_invite(&invite).discovery_id();
        // Not a fast hash of the invite any more, under either context.
        for context in [
            "sculpt 2026 replication discovery id v1",
            DISCOVERY_ID_CONTEXT,
        ] {
            assert_ne!(&invite.derive_key(context)[..DISCOVERY_ID_BYTES], &id[..]);
        }
        // It is blake3 over argon2id with exactly the named cost; a cheaper stretch differs.
        let stretch = |memory_kib, passes| {
            let params = argon2::Params::new(memory_kib, passes, DISCOVERY_KDF_LANES, Some(32));
            let argon = argon2::Argon2::new(
                argon2::Algorithm::Argon2id,
                argon2::Version::V0x13,
                params.unwrap(),
            );
            let mut out = [0; 32];
            argon
                .hash_password_into(&invite.canonical(), DISCOVERY_KDF_SALT, &mut out)
                .unwrap();
            blake3::derive_key(DISCOVERY_ID_CONTEXT, &out)
        };
        assert_eq!(
            &stretch(DISCOVERY_KDF_MEMORY_KIB, DISCOVERY_KDF_PASSES)[..DISCOVERY_ID_BYTES],
            &id[..]
        );
        assert_ne!(
            &stretch(DISCOVERY_KDF_MEMORY_KIB / 2, DISCOVERY_KDF_PASSES)[..DISCOVERY_ID_BYTES],
            &id[..]
        );
        assert_ne!(
            &stretch(DISCOVERY_KDF_MEMORY_KIB, 1)[..DISCOVERY_ID_BYTES],
            &id[..]
        );
        assert_eq!(
            (DISCOVERY_KDF_MEMORY_KIB, DISCOVERY_KDF_PASSES),
            (65_536, 3)
        );
    }
}
