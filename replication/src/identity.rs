//! Identities: ed25519 key pairs, peer ids (public keys) and signatures; op ids (the blake3
//! hash of an op's encoding) and session ids.
//!
//! Signatures are checked by the ZIP 215 rules (`ed25519-zebra`): one signature alone and the
//! same signature in a batch get the same verdict, whatever its author crafted (a small-order
//! or mixed-order key or `R` included). Peers must agree on which ops are signed, and a peer
//! checks a batch of ops or one op depending on how they arrived, so rules under which the two
//! could differ would let a member split the session.

use std::fmt;

use ed25519_zebra::batch;
use ed25519_zebra::{SigningKey, VerificationKey, VerificationKeyBytes};
use rand_core::{CryptoRng, CryptoRngCore, RngCore};

/// Length of a peer id (an ed25519 public key) in bytes.
pub const PEER_ID_BYTES: usize = 32;
/// Length of an ed25519 signature in bytes.
pub const SIGNATURE_BYTES: usize = 64;
/// Number of hex digits in the short display form of a peer id.
pub const SHORT_ID_HEX_DIGITS: usize = 8;
/// Length of an op id in bytes.
pub const OP_ID_BYTES: usize = 32;
/// Length of a session id.
pub const SESSION_ID_BYTES: usize = 16;

/// A session's id (derived from its invite by the transport).
pub type SessionId = [u8; SESSION_ID_BYTES];

/// A peer's identity: its ed25519 public key.
///
/// Ordering is by key bytes; it is the tie-break after Lamport time in the linear order.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct PeerId(pub [u8; PEER_ID_BYTES]);

/// Byte-wise (lexicographic) order of 32-byte ids, compared as four big-endian integers: the
/// same order as comparing the arrays, without a `memcmp` call. Ids are hashes or keys, so
/// unequal ones differ in the first word; equal ones (every lookup that finds its key) cost
/// four integer comparisons.
pub(crate) fn cmp_id_bytes(a: &[u8; 32], b: &[u8; 32]) -> std::cmp::Ordering {
    let (a, b) = (a.as_chunks::<8>().0, b.as_chunks::<8>().0);
    for (x, y) in a.iter().zip(b) {
        let order = u64::from_be_bytes(*x).cmp(&u64::from_be_bytes(*y));
        if order.is_ne() {
            return order;
        }
    }
    std::cmp::Ordering::Equal
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

/// An op's id: the blake3 hash of its canonical encoding (signature included).
///
/// Transparent over its bytes, so an op's dependencies are read in place from its encoding.
#[derive(Clone, Copy, PartialEq, Eq, Hash, bytemuck::TransparentWrapper)]
#[repr(transparent)]
pub struct OpId(pub [u8; OP_ID_BYTES]);

/// Byte-wise order (the fast comparison of ids above).
impl Ord for OpId {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        cmp_id_bytes(&self.0, &other.0)
    }
}

impl PartialOrd for OpId {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl OpId {
    /// Short hex display form.
    pub fn short(&self) -> String {
        hex(&self.0[..4])
    }
}

impl fmt::Debug for OpId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "OpId({})", self.short())
    }
}

impl fmt::Display for OpId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.short())
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
        let mut seed = [0; 32];
        rng.fill_bytes(&mut seed);
        Self::from_seed(seed)
    }

    /// Rebuilds a key pair from its 32-byte secret seed.
    pub fn from_seed(seed: [u8; 32]) -> Self {
        Self {
            signing: SigningKey::from(seed),
        }
    }

    /// The 32-byte secret seed, for the app to persist (keep it private).
    pub fn seed(&self) -> [u8; 32] {
        self.signing.to_bytes()
    }

    /// This key pair's public identity.
    pub fn peer_id(&self) -> PeerId {
        PeerId(VerificationKeyBytes::from(&self.signing).into())
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
    /// Verifies `signature` over `message` by the ZIP 215 rules (the same verdict as in a
    /// batch, [`verify_batch`]; `s` must be canonical, so a signature cannot be altered into
    /// another valid one).
    pub fn verify(&self, message: &[u8], signature: &Signature) -> Result<(), VerifyError> {
        let key =
            VerificationKey::try_from(self.0).map_err(|_| VerifyError::BadKey(self.short()))?;
        key.verify(&ed25519_zebra::Signature::from_bytes(&signature.0), message)
            .map_err(|_| VerifyError::BadSignature(self.short()))
    }

    /// The short display form: the first [`SHORT_ID_HEX_DIGITS`] hex digits of the key.
    pub fn short(&self) -> String {
        hex(&self.0[..SHORT_ID_HEX_DIGITS / 2])
    }

    /// The whole key in lowercase hex.
    pub fn to_hex(&self) -> String {
        hex(&self.0)
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

/// Most signatures [`verify_batch`] checks in one equation; a longer slice is checked in
/// runs of this many (one sync batch of ops).
pub const MAX_BATCH_SIGNATURES: usize = 64;
/// Fewest signatures each thread of [`verify_batch`] takes (a batch of fewer is checked on
/// the caller's thread): starting a thread costs about what checking a few signatures does.
pub const MIN_SIGNATURES_PER_THREAD: usize = 16;
/// Most threads one [`verify_batch`] call uses, the caller's included.
pub const MAX_VERIFY_THREADS: usize = 8;
/// The stack of a thread that checks signatures (the batch equation needs little).
const VERIFY_STACK_BYTES: usize = 256 * 1024;

/// Checks many signatures at once: true if every one of them verifies, by the same rules as
/// [`PeerId::verify`] (ZIP 215), so a false answer means at least one would fail alone and the
/// caller checks them one by one to find it. Signatures by one author share their key's work,
/// so a batch of ops from few authors costs about a third of checking each.
///
/// The equation's random coefficients are drawn from a hash of everything in the batch (keys,
/// signatures and messages), never from the system: the core takes no randomness it is not
/// given, and an author cannot choose a signature knowing the coefficients it will meet.
///
/// A batch of at least twice [`MIN_SIGNATURES_PER_THREAD`] is split over up to
/// [`MAX_VERIFY_THREADS`] threads (the machine's cores), each checking its part as above: a
/// sync batch of ops, or a snapshot's every op, costs its checks' time divided by the cores,
/// and the verdict is the same (an honest part passes whatever its coefficients). A thread
/// the system refuses is done on the caller's.
pub fn verify_batch(items: &[(PeerId, &[u8], Signature)]) -> bool {
    verify_split(items, verify_threads())
}

/// [`verify_batch`] on at most `max_threads` threads.
fn verify_split(items: &[(PeerId, &[u8], Signature)], max_threads: usize) -> bool {
    let n_threads = max_threads.min(items.len() / MIN_SIGNATURES_PER_THREAD);
    if n_threads < 2 {
        return verify_runs(items);
    }
    let part = items.len().div_ceil(n_threads);
    let (own, others) = items.split_at(part);
    std::thread::scope(|scope| {
        let helpers: Vec<_> = others
            .chunks(part)
            .map(|items| {
                let helper = std::thread::Builder::new()
                    .name("verify".into())
                    .stack_size(VERIFY_STACK_BYTES)
                    .spawn_scoped(scope, move || verify_runs(items));
                helper.map_err(|_| items)
            })
            .collect();
        let mut all = verify_runs(own);
        for helper in helpers {
            all &= match helper {
                Ok(thread) => thread.join().unwrap_or(false),
                Err(items) => verify_runs(items),
            };
        }
        all
    })
}

/// How many threads [`verify_batch`] may use: the machine's cores, at most
/// [`MAX_VERIFY_THREADS`] (looked up once).
fn verify_threads() -> usize {
    static THREADS: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *THREADS.get_or_init(|| {
        std::thread::available_parallelism().map_or(1, |n| n.get().min(MAX_VERIFY_THREADS))
    })
}

/// [`verify_batch`] on the caller's thread, in runs of [`MAX_BATCH_SIGNATURES`].
fn verify_runs(items: &[(PeerId, &[u8], Signature)]) -> bool {
    items.chunks(MAX_BATCH_SIGNATURES).all(|run| {
        let mut transcript =
            blake3::Hasher::new_derive_key("sculpt/identity/batch-coefficients/v1");
        let mut verifier = batch::Verifier::new();
        for (author, message, signature) in run {
            transcript.update(&author.0);
            transcript.update(&signature.0);
            transcript.update(&(message.len() as u64).to_le_bytes());
            transcript.update(message);
            let sig = ed25519_zebra::Signature::from_bytes(&signature.0);
            verifier.queue((VerificationKeyBytes::from(author.0), sig, message));
        }
        verifier
            .verify(TranscriptRng(transcript.finalize_xof()))
            .is_ok()
    })
}

/// A stream of coefficient bytes read from a hash of a batch (see [`verify_batch`]).
struct TranscriptRng(blake3::OutputReader);

impl RngCore for TranscriptRng {
    fn next_u32(&mut self) -> u32 {
        let mut b = [0; 4];
        self.0.fill(&mut b);
        u32::from_le_bytes(b)
    }

    fn next_u64(&mut self) -> u64 {
        let mut b = [0; 8];
        self.0.fill(&mut b);
        u64::from_le_bytes(b)
    }

    fn fill_bytes(&mut self, dest: &mut [u8]) {
        self.0.fill(dest);
    }

    fn try_fill_bytes(&mut self, dest: &mut [u8]) -> Result<(), rand_core::Error> {
        self.0.fill(dest);
        Ok(())
    }
}

/// A hash-derived stream: unpredictable to anyone who cannot choose the whole batch after
/// seeing it, which is what the batch equation needs.
impl CryptoRng for TranscriptRng {}

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

    /// A signature by a key with a torsion part (`A = aB + T`), optionally with a torsion part
    /// in `R` too: valid under the cofactored (ZIP 215) equation, invalid under the strict one
    /// for most messages. A member can make these at will; they are where batch and single
    /// checks disagree in libraries that mix the two equations.
    fn mixed_order_signature(
        a: u64,
        torsion_a: usize,
        torsion_r: usize,
        message: &[u8],
    ) -> (PeerId, Signature) {
        use curve25519_dalek::constants::{ED25519_BASEPOINT_POINT as B, EIGHT_TORSION};
        use curve25519_dalek::scalar::Scalar;
        use sha2::{Digest, Sha512};
        let a = Scalar::from(a);
        let key = (a * B + EIGHT_TORSION[torsion_a]).compress();
        let r = Scalar::from(0x5eed_u64 + message.len() as u64);
        let big_r = (r * B + EIGHT_TORSION[torsion_r]).compress();
        let hash: [u8; 64] = Sha512::new()
            .chain_update(big_r.as_bytes())
            .chain_update(key.as_bytes())
            .chain_update(message)
            .finalize()
            .into();
        let k = Scalar::from_bytes_mod_order_wide(&hash);
        let s = r + k * a;
        let mut signature = [0; SIGNATURE_BYTES];
        signature[..32].copy_from_slice(big_r.as_bytes());
        signature[32..].copy_from_slice(s.as_bytes());
        (PeerId(key.to_bytes()), Signature(signature))
    }

    #[test]
    fn batch_and_single_checks_agree_on_mixed_order_keys_and_nonces() {
        let honest = Keypair::from_seed([5; 32]);
        let mut n_valid = 0;
        for torsion_a in 0..8 {
            for torsion_r in 0..8 {
                let message = vec![7; torsion_a * 8 + torsion_r];
                let (key, signature) =
                    mixed_order_signature(1000 + torsion_a as u64, torsion_a, torsion_r, &message);
                let alone = key.verify(&message, &signature).is_ok();
                n_valid += usize::from(alone);
                let honest_sig = honest.sign(b"honest");
                let batch = [
                    (honest.peer_id(), &b"honest"[..], honest_sig),
                    (key, &message[..], signature),
                ];
                assert_eq!(verify_batch(&batch[1..]), alone, "{torsion_a} {torsion_r}");
                assert_eq!(verify_batch(&batch), alone, "{torsion_a} {torsion_r}");
            }
        }
        // The cofactored rules accept them all: the strict ones would refuse most, and then a
        // batch (cofactored) and a single check (strict) would split peers.
        assert_eq!(n_valid, 64);
    }

    #[test]
    fn a_forged_signature_fails_its_batch_wherever_it_sits() {
        let keys: Vec<Keypair> = (0..3).map(|i| Keypair::from_seed([i; 32])).collect();
        let messages: Vec<Vec<u8>> = (0..150u32).map(|i| i.to_le_bytes().to_vec()).collect();
        let items: Vec<(PeerId, &[u8], Signature)> = messages
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let k = &keys[i % keys.len()];
                (k.peer_id(), m.as_slice(), k.sign(m))
            })
            .collect();
        // Every split the machine's cores can give: the caller's thread alone, and parts
        // of 75, 50, 38 and 19 signatures (a forgery in each part, on each side of a cut).
        for threads in [1, 2, 3, 4, MAX_VERIFY_THREADS] {
            assert!(verify_split(&items, threads));
            assert!(verify_split(&[], threads));
            for at in [0, 18, 19, 37, 38, 63, 64, 74, 75, 100, 149] {
                let mut forged = items.clone();
                forged[at].2.0[40] ^= 1;
                assert!(!verify_split(&forged, threads), "{at} of {threads}");
                let mut swapped = items.clone();
                swapped[at].0 = keys[(at + 1) % keys.len()].peer_id();
                assert!(!verify_split(&swapped, threads), "{at} of {threads}");
            }
        }
        assert!(verify_batch(&items));
    }

    proptest! {
        #![proptest_config(crate::test_config(32))]
        #[test]
        fn a_batch_verifies_exactly_when_each_of_its_signatures_does(
            seed in any::<u64>(),
            flips in proptest::collection::vec(proptest::option::weighted(0.2, any::<usize>()), 1..12),
        ) {
            let keys: Vec<Keypair> = (0..2)
                .map(|i| Keypair::generate(&mut ChaCha20Rng::seed_from_u64(seed.wrapping_add(i))))
                .collect();
            let messages: Vec<Vec<u8>> = (0..flips.len()).map(|i| vec![i as u8; i]).collect();
            let items: Vec<(PeerId, &[u8], Signature)> = flips
                .iter()
                .enumerate()
                .map(|(i, flip)| {
                    let k = &keys[i % 2];
                    let mut sig = k.sign(&messages[i]);
                    if let Some(bit) = flip {
                        sig.0[bit % SIGNATURE_BYTES] ^= 1 << (bit % 8);
                    }
                    (k.peer_id(), messages[i].as_slice(), sig)
                })
                .collect();
            let each = items.iter().all(|(key, m, sig)| key.verify(m, sig).is_ok());
            prop_assert_eq!(verify_batch(&items), each);
        }
    }

    proptest! {
        #![proptest_config(crate::test_config(256))]
        /// Ids sort as byte arrays: the linear order's tie-break depends on it. The second id
        /// shares a prefix of any length with the first, so every word decides some cases.
        #[test]
        fn ids_compare_as_byte_arrays(
            a in any::<[u8; 32]>(),
            tail in any::<[u8; 32]>(),
            shared in 0usize..=32,
        ) {
            let mut b = a;
            b[shared..].copy_from_slice(&tail[shared..]);
            prop_assert_eq!(cmp_id_bytes(&a, &b), a.cmp(&b));
            prop_assert_eq!(cmp_id_bytes(&b, &a), b.cmp(&a));
            prop_assert_eq!(PeerId(a).cmp(&PeerId(b)), a.cmp(&b));
        }
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
