//! Who may expel a member: the session's founder, proven by the invite itself.
//!
//! An invite made for a founder ([`FounderCommitment::of`]) is not drawn at random: its 130
//! random bits are a hash of the founder's key and a secret nonce. A membership op
//! ([`Membership`]) shows that nonce; every member holds the invite, so every member checks the
//! op's author against it the same way, and only the founder can pass (anyone else would need a
//! second preimage of 130 bits). Sessions whose invite was drawn at random have no founder, and
//! nobody can expel anyone in them.
//!
//! What an expel does is judged like every other verdict, from the log's content alone (see
//! [`crate::log`]): the ops of the member that are not in the expel's causal past are void
//! everywhere (no effect on the scene, no lease), and a readmit by the founder cancels every
//! expel of that member it saw.
//!
//! Who may write at all, in a session that binds its authors ([`crate::Log::bind_authors`]):
//! a key whose first op names an [`Admission`] of it among its deps, authored by a key already
//! admitted, which gives it a budget of bytes out of its own. The root is the founder, whose
//! first op is its admission of itself showing the nonce, and whose budget is the session's cap
//! on bytes of ops: every author's spending (its ops' bytes and the grants it gave) is counted
//! along its chain and held within its budget by every peer alike, so the log as a whole never
//! passes the cap, and a key minted offline writes nothing.

use crate::identity::PeerId;

/// Bytes of the secret nonce a founder keeps beside its invite.
pub const FOUNDER_NONCE_BYTES: usize = 32;
/// Symbols of a [`FounderCommitment`]: an invite's random characters, 5 bits each (130 bits).
pub const COMMITMENT_SYMBOLS: usize = 26;

/// A founder's key committed to in an invite: the invite's random characters, each below 32.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FounderCommitment(pub [u8; COMMITMENT_SYMBOLS]);

impl FounderCommitment {
    /// The commitment to `founder` with `nonce`: the low 5 bits of the first 26 bytes of a
    /// keyed blake3 hash of both (each byte's low bits are uniform, so 130 uniform bits).
    pub fn of(founder: &PeerId, nonce: &[u8; FOUNDER_NONCE_BYTES]) -> Self {
        let mut hasher = blake3::Hasher::new_derive_key("sculpt 2026-11-27 founder commitment v1");
        hasher.update(&founder.0);
        hasher.update(nonce);
        let hash = hasher.finalize();
        let mut symbols = [0; COMMITMENT_SYMBOLS];
        for (s, b) in symbols.iter_mut().zip(hash.as_bytes()) {
            *s = b & 0x1f;
        }
        Self(symbols)
    }

    /// True if `author` showing `nonce` is the founder this commits to.
    pub fn is_founder(&self, author: &PeerId, nonce: &[u8; FOUNDER_NONCE_BYTES]) -> bool {
        Self::of(author, nonce) == *self
    }
}

/// An admission op's meaning: its author lets `key` write, with `grant_bytes` of its own
/// budget (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Admission {
    /// The newcomer's key.
    pub key: PeerId,
    /// Bytes of ops (and grants of its own) the newcomer may spend; counted against the
    /// admitter's budget whether or not the newcomer ever writes.
    pub grant_bytes: u64,
    /// The founder's nonce, in the founder's admission of itself (which makes its budget the
    /// session's cap); `None` in every other admission.
    pub nonce: Option<[u8; FOUNDER_NONCE_BYTES]>,
}

/// A membership op's meaning: the founder expels `member`, or readmits it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Membership {
    /// The member expelled or readmitted.
    pub member: PeerId,
    /// True to expel; false to readmit (cancels every expel of `member` the op saw).
    pub expel: bool,
    /// The founder's nonce: what makes the op count (see [`FounderCommitment`]).
    pub nonce: [u8; FOUNDER_NONCE_BYTES],
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identity::Keypair;

    #[test]
    fn only_the_founder_with_its_nonce_matches_the_commitment() {
        let founder = Keypair::from_seed([1; 32]).peer_id();
        let other = Keypair::from_seed([2; 32]).peer_id();
        let commitment = FounderCommitment::of(&founder, &[7; 32]);
        assert!(commitment.0.iter().all(|s| *s < 32));
        assert!(commitment.is_founder(&founder, &[7; 32]));
        assert!(!commitment.is_founder(&founder, &[8; 32]));
        assert!(!commitment.is_founder(&other, &[7; 32]));
        assert_ne!(commitment, FounderCommitment::of(&founder, &[8; 32]));
    }
}
