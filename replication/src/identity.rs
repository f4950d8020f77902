//! Peer identity: ed25519 key pairs, peer ids (public keys) and signatures.

use std::fmt;

use ed25519_dalek::{Signer, SigningKey, VerifyingKey};
use rand_core::CryptoRngCore;

/// Length of a peer id (an ed25519 public key) in bytes.
pub const PEER_ID_BYTES: usize = 32;
/// Length of an ed25519 signature in bytes.
pub const SIGNATURE_BYTES: usize = 64;
/// Number of hex digits in the short display form of a peer id.
pub const SHORT_ID_HEX_DIGITS: usize = 8;

/// A peer's identity: its ed25519 public key.
///
/// Ordering is by key bytes; it is the tie-break after Lamport time in the linear order.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct PeerId(pub [u8; PEER_ID_BYTES]);

/// Byte-wise (lexicographic) order of 32-byte ids, comparing the first 8 bytes as one
/// big-endian integer first: the same order as comparing the arrays, without a `memcmp`
/// call in the common case (ids are hashes or keys, so they differ early).
pub(crate) fn cmp_id_bytes(a: &[u8; 32], b: &[u8; 32]) -> std::cmp::Ordering {
    let head = |x: &[u8; 32]| u64::from_be_bytes([x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]]);
    head(a).cmp(&head(b)).then_with(|| a.cmp(b))
}

impl Ord for PeerId {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        cmp_id_bytes(&self.0, &other.0)
    }
}

impl PartialOrd for PeerId {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// An ed25519 signature over an op's signed body.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Signature(pub [u8; SIGNATURE_BYTES]);

/// Why a signature did not verify.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum VerifyError {
    /// The peer id is not a valid ed25519 point.
    #[error("peer id {0} is not a valid ed25519 public key")]
    BadKey(String),
    /// The signature does not match the message under this key.
    #[error("signature does not verify under {0}")]
    BadSignature(String),
}

/// An ed25519 key pair: signs the ops this peer authors.
pub struct Keypair {
    signing: SigningKey,
}

impl Keypair {
    /// Generates a key pair from the RNG the caller passes in (seeded in tests and simulation).
    pub fn generate(rng: &mut impl CryptoRngCore) -> Self {
        Self {
            signing: SigningKey::generate(rng),
        }
    }

    /// Rebuilds a key pair from its 32-byte secret seed.
    pub fn from_seed(seed: [u8; 32]) -> Self {
        Self {
            signing: SigningKey::from_bytes(&seed),
        }
    }

    /// The 32-byte secret seed, for the app to persist (keep it private).
    pub fn seed(&self) -> [u8; 32] {
        self.signing.to_bytes()
    }

    /// This key pair's public identity.
    pub fn peer_id(&self) -> PeerId {
        PeerId(self.signing.verifying_key().to_bytes())
    }

    /// Signs `message`.
    pub fn sign(&self, message: &[u8]) -> Signature {
        Signature(self.signing.sign(message).to_bytes())
    }
}

impl fmt::Debug for Keypair {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Never print the secret.
        write!(f, "Keypair({})", self.peer_id())
    }
}

impl PeerId {
    /// Verifies `signature` over `message` with strict ed25519 rules (no malleable signatures).
    pub fn verify(&self, message: &[u8], signature: &Signature) -> Result<(), VerifyError> {
        let key =
            VerifyingKey::from_bytes(&self.0).map_err(|_| VerifyError::BadKey(self.short()))?;
        let sig = ed25519_dalek::Signature::from_bytes(&signature.0);
        key.verify_strict(message, &sig)
            .map_err(|_| VerifyError::BadSignature(self.short()))
    }

    /// The short display form: the first [`SHORT_ID_HEX_DIGITS`] hex digits of the key.
    pub fn short(&self) -> String {
        hex(&self.0[..SHORT_ID_HEX_DIGITS / 2])
    }
}

impl fmt::Display for PeerId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.short())
    }
}

impl fmt::Debug for PeerId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PeerId({})", self.short())
    }
}

impl fmt::Debug for Signature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Signature({}..)", hex(&self.0[..4]))
    }
}

/// Lower-case hex of `bytes`.
pub(crate) fn hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut out = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        out.push(char::from(DIGITS[usize::from(b >> 4)]));
        out.push(char::from(DIGITS[usize::from(b & 0x0f)]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand_chacha::ChaCha20Rng;
    use rand_core::SeedableRng;

    #[test]
    fn same_seed_gives_same_key_and_different_seeds_differ() {
        let a = Keypair::generate(&mut ChaCha20Rng::seed_from_u64(7));
        let b = Keypair::generate(&mut ChaCha20Rng::seed_from_u64(7));
        let c = Keypair::generate(&mut ChaCha20Rng::seed_from_u64(8));
        assert_eq!(a.peer_id(), b.peer_id());
        assert_ne!(a.peer_id(), c.peer_id());
        assert_eq!(Keypair::from_seed(a.seed()).peer_id(), a.peer_id());
    }

    #[test]
    fn short_form_is_hex_prefix() {
        let id = PeerId([0xab; 32]);
        assert_eq!(id.short(), "abababab");
        assert_eq!(format!("{id}"), "abababab");
        assert_eq!(id.short().len(), SHORT_ID_HEX_DIGITS);
    }

    #[test]
    fn debug_does_not_leak_secret() {
        let k = Keypair::from_seed([3; 32]);
        let text = format!("{k:?}");
        assert!(!text.contains(&hex(&k.seed())), "{text}");
    }

    proptest! {
        #![proptest_config(crate::test_config(32))]
        #[test]
        fn sign_verify_and_tamper(seed in any::<u64>(), msg in proptest::collection::vec(any::<u8>(), 0..64), flip in any::<usize>()) {
            let k = Keypair::generate(&mut ChaCha20Rng::seed_from_u64(seed));
            let sig = k.sign(&msg);
            prop_assert!(k.peer_id().verify(&msg, &sig).is_ok());
            let mut bad = sig;
            bad.0[flip % SIGNATURE_BYTES] ^= 1;
            prop_assert!(k.peer_id().verify(&msg, &bad).is_err());
            let other = Keypair::generate(&mut ChaCha20Rng::seed_from_u64(seed.wrapping_add(1)));
            prop_assert!(other.peer_id().verify(&msg, &sig).is_err());
        }
    }
}
