//! Evidence of equivocation: an author that signed two different ops with one seq.
//!
//! A log keeps one op per author and seq, so it refuses the second op of a fork
//! ([`crate::log::InsertError::Equivocation`]). What it keeps instead is a [`ForkProof`]: both
//! ops' signed bytes, which anyone can check on their own. Sync passes each proof a peer holds
//! to its connections once (`Message::Forked`), so every member learns of a fork that any one
//! of them saw, and the app marks the author. Proofs change no verdict and no order: they are
//! for people (an honest identity running as two copies, or a store restored from an old
//! backup, forks too, and its user must be told).

use std::collections::BTreeMap;

use crate::codec::DecodeError;
use crate::identity::{PeerId, VerifyError};
use crate::op::{Envelope, Op, OpId};

/// Most fork proofs a log keeps (one per author); later ones are counted and dropped.
pub const MAX_FORK_PROOFS: usize = 1024;
/// Most bytes of ops the kept fork proofs hold, in all.
pub const MAX_FORK_PROOF_BYTES: usize = 8 * 1024 * 1024;

/// Why bytes offered as a fork proof are not one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProofError {
    /// One of the two ops does not decode.
    #[error("op {index} of the proof: {error}")]
    Decode {
        /// Which op (0 or 1).
        index: usize,
        /// The decoder's error, with its offset in that op.
        error: DecodeError,
    },
    /// One of the two ops is not signed by its author.
    #[error("op {index} of the proof: {error}")]
    Verify {
        /// Which op (0 or 1).
        index: usize,
        /// The signature check's error.
        error: VerifyError,
    },
    /// The two ops are not two different ops of one author with one seq.
    #[error("the two ops are not a fork (authors, seqs or ids do not differ as a fork's do)")]
    NotAFork,
}

/// Two different ops signed by one author with one seq, in id order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ForkProof {
    author: PeerId,
    seq: u64,
    ops: [Box<[u8]>; 2],
}

impl ForkProof {
    /// Checks untrusted bytes: both decode as ops, both signatures hold, and they are two
    /// different ops of one author with one seq.
    pub fn check(a: &[u8], b: &[u8]) -> Result<Self, ProofError> {
        let parse = |index, bytes| {
            let envelope =
                Envelope::parse(bytes).map_err(|error| ProofError::Decode { index, error })?;
            envelope
                .verify()
                .map_err(|error| ProofError::Verify { index, error })?;
            Ok(envelope)
        };
        let (ea, eb) = (parse(0, a)?, parse(1, b)?);
        if ea.author() != eb.author() || ea.seq() != eb.seq() || ea.id() == eb.id() {
            return Err(ProofError::NotAFork);
        }
        Ok(Self::ordered(
            ea.author(),
            ea.seq(),
            (ea.id(), a),
            (eb.id(), b),
        ))
    }

    /// The proof two verified ops make (the caller checked they are a fork).
    pub(crate) fn of_ops<P>(a: &Op<P>, b: &Op<P>) -> Self {
        debug_assert!(a.author() == b.author() && a.seq() == b.seq() && a.id() != b.id());
        Self::ordered(
            a.author(),
            a.seq(),
            (a.id(), a.encoded()),
            (b.id(), b.encoded()),
        )
    }

    fn ordered(author: PeerId, seq: u64, a: (OpId, &[u8]), b: (OpId, &[u8])) -> Self {
        let (first, second) = if a.0 < b.0 { (a, b) } else { (b, a) };
        Self {
            author,
            seq,
            ops: [first.1.into(), second.1.into()],
        }
    }

    /// The author that equivocated.
    pub fn author(&self) -> PeerId {
        self.author
    }

    /// The seq it signed twice.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// The two ops' encodings, in id order.
    pub fn ops(&self) -> [&[u8]; 2] {
        [&self.ops[0], &self.ops[1]]
    }

    fn n_bytes(&self) -> usize {
        self.ops[0].len() + self.ops[1].len()
    }
}

/// The fork proofs a log holds: at most one per author, in the order they were learnt, within
/// [`MAX_FORK_PROOFS`] and [`MAX_FORK_PROOF_BYTES`].
#[derive(Debug, Clone, Default)]
pub struct Forks {
    proofs: Vec<ForkProof>,
    by_author: BTreeMap<PeerId, usize>,
    n_bytes: usize,
    n_dropped: u64,
}

impl Forks {
    /// Keeps `proof` if its author has none yet and there is room; true if kept.
    pub fn record(&mut self, proof: ForkProof) -> bool {
        if self.by_author.contains_key(&proof.author) {
            return false;
        }
        if self.proofs.len() >= MAX_FORK_PROOFS
            || self.n_bytes + proof.n_bytes() > MAX_FORK_PROOF_BYTES
        {
            self.n_dropped += 1;
            return false;
        }
        self.n_bytes += proof.n_bytes();
        self.by_author.insert(proof.author, self.proofs.len());
        self.proofs.push(proof);
        true
    }

    /// The seq `author` signed twice, if a proof of it is held.
    pub fn seq_of(&self, author: &PeerId) -> Option<u64> {
        self.by_author.get(author).map(|&i| self.proofs[i].seq)
    }

    /// True if a proof of `author` is held.
    pub fn contains(&self, author: &PeerId) -> bool {
        self.by_author.contains_key(author)
    }

    /// The proofs, in the order they were learnt (a list that only grows).
    pub fn proofs(&self) -> &[ForkProof] {
        &self.proofs
    }

    /// The authors with a proof, and the seq each signed twice.
    pub fn authors(&self) -> impl Iterator<Item = (PeerId, u64)> + '_ {
        self.proofs.iter().map(|p| (p.author, p.seq))
    }

    /// Proofs dropped for want of room.
    pub fn n_dropped(&self) -> u64 {
        self.n_dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Keypair;
    use crate::op::OpFields;
    use crate::payload::test_payload::TestPayload;
    use crate::time::Timestamp;

    fn op(key: &Keypair, seq: u64, text: &str) -> Op<TestPayload> {
        let fields = OpFields {
            seq,
            lamport: seq,
            timestamp: Timestamp(seq),
            deps: Vec::new(),
            payload: TestPayload::Chat(text.into()),
        };
        Op::sign(key, fields).expect("signs").into_op()
    }

    #[test]
    fn a_proof_is_two_signed_ops_of_one_author_and_seq() {
        let key = Keypair::from_seed([7; 32]);
        let (a, b) = (op(&key, 3, "left"), op(&key, 3, "right"));
        let proof = ForkProof::check(a.encoded(), b.encoded()).expect("a fork");
        assert_eq!((proof.author(), proof.seq()), (key.peer_id(), 3));
        // The same proof whichever order the ops come in, and from held ops.
        assert_eq!(
            ForkProof::check(b.encoded(), a.encoded()),
            Ok(proof.clone())
        );
        assert_eq!(ForkProof::of_ops(&a, &b), proof);
    }

    #[test]
    fn what_is_not_a_fork_is_refused_with_its_reason() {
        let key = Keypair::from_seed([7; 32]);
        let other = Keypair::from_seed([8; 32]);
        let a = op(&key, 3, "left");
        let not_a_fork = [
            op(&key, 3, "left"),  // the same op
            op(&key, 4, "right"), // another seq
            op(&other, 3, "right"),
        ];
        for b in &not_a_fork {
            assert_eq!(
                ForkProof::check(a.encoded(), b.encoded()),
                Err(ProofError::NotAFork)
            );
        }
        // A forged signature: the last byte of the signature flipped.
        let mut forged = op(&key, 3, "right").encoded().to_vec();
        *forged.last_mut().expect("bytes") ^= 1;
        assert!(matches!(
            ForkProof::check(a.encoded(), &forged),
            Err(ProofError::Verify { index: 1, .. })
        ));
        assert!(matches!(
            ForkProof::check(&a.encoded()[..10], &forged),
            Err(ProofError::Decode { index: 0, .. })
        ));
    }

    #[test]
    fn one_proof_per_author_within_the_limits() {
        let mut forks = Forks::default();
        let key = Keypair::from_seed([7; 32]);
        let proof = |seq| ForkProof::of_ops(&op(&key, seq, "a"), &op(&key, seq, "b"));
        assert!(forks.record(proof(5)));
        assert!(!forks.record(proof(2)), "one proof per author");
        assert_eq!(forks.seq_of(&key.peer_id()), Some(5));
        for i in 0..MAX_FORK_PROOFS as u64 + 3 {
            let mut seed = [0; 32];
            seed[..8].copy_from_slice(&i.to_le_bytes());
            seed[31] = 1;
            let k = Keypair::from_seed(seed);
            forks.record(ForkProof::of_ops(&op(&k, 1, "a"), &op(&k, 1, "b")));
        }
        assert_eq!(forks.proofs().len(), MAX_FORK_PROOFS);
        assert_eq!(forks.n_dropped(), 4);
    }
}
