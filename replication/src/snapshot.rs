//! Snapshots: a log's whole history in linear order with the hash of the scene folded from
//! it, so a new peer joins by inserting ops whose signatures the producer checked, instead of
//! verifying them one by one as sync does. The joined log holds every op, so it judges every
//! later op exactly as a peer that synced op by op does: no verdict reads anything a snapshot
//! leaves out.
//!
//! **Cut.** A snapshot names the ops it covers by their [`SceneCut`], the digest of the heads
//! of their DAG (an op's id hashes its deps, so the heads name every op below them), as the
//! scene check does. A join checks that the ops it inserted are exactly that cut, folds them,
//! and checks the fold against the scene hash the snapshot names: a snapshot from a peer
//! whose scene differs from its ops' fold is refused at once.
//!
//! **Why the fold, not the producer's scene.** Folding is the cheap part of a join: the
//! object model compiles an op's formulas and edits when the op decodes, and its fold shares
//! them. Decoding a scene would compile every edit a second time (about ten times a fold's
//! cost at 10^5 edits) and carry every edit twice on the wire.
//!
//! **Trust.** A join checks no signature, so a hostile producer could hand forged ops.
//! [`verify_encoded`] checks every signature over the session, in batches. A peer runs it
//! after joining, off the join's path, and drops the joined state if it fails; until then
//! it stores nothing of it, and forwards nothing its remotes do not verify anyway.
//!
//! Format (version 4), integers as varints: `SCULPTSNAP [4] [n ≤ MAX_LOG_OPS][len][op]*` (the
//! linear order) `[n][head 32]*` (sorted) `[scene hash 32]` `[blake3 of everything before,
//! 32]`. Versions 1 and 2 (a cut of ids without the ops, which could not judge every later
//! op as a full peer does) and 3 (the producer's scene beside its hash) are refused.

use crate::codec::{DecodeError, Reader, put_bytes, put_varint};
use crate::identity::{OpId, SessionId};
use crate::log::LOCAL_ORIGIN;
use crate::log::{InsertError, Log};
use crate::materialize::{Materialize, Materialized, SCENE_HASH_BYTES, SceneHash};
use crate::op::{MAX_LOG_OPS, MAX_OP_BYTES, Op, VerifiedOp};
use crate::payload::Payload;
use crate::sync::scene::SceneCut;
use crate::time::Timestamp;

/// Magic bytes that open an encoded snapshot.
pub const SNAPSHOT_MAGIC: &[u8; 10] = b"SCULPTSNAP";
/// The snapshot format version (4: the ops whole and the scene's hash).
pub const SNAPSHOT_FORMAT_VERSION: u8 = 4;
/// Largest encoded snapshot accepted or produced, in bytes (256 MiB).
pub const MAX_SNAPSHOT_BYTES: usize = 256 * 1024 * 1024;
/// Bytes of checksum at the end of a snapshot.
pub const SNAPSHOT_CHECKSUM_BYTES: usize = 32;
/// Ops whose signatures [`verify`] checks in one batch.
pub const MAX_VERIFY_BATCH_OPS: usize = 1024;
/// The fewest bytes an encoded op takes (a length prefix included): ids, seq, Lamport time,
/// timestamp and signature.
const MIN_OP_BYTES: usize = 64;

/// Why a snapshot could not be captured.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CaptureError {
    /// The encoding would exceed [`MAX_SNAPSHOT_BYTES`].
    #[error("snapshot of {0} bytes is over its limit")]
    TooLarge(usize),
}

/// Why a decoded snapshot could not be joined.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JoinError {
    /// The log to join into already holds ops.
    #[error("a snapshot joins an empty log only (this one holds {0} ops)")]
    NotEmpty(usize),
    /// The log refused an op.
    #[error("op {index} of the snapshot: {error}")]
    Refused {
        /// Its index in the snapshot's order.
        index: usize,
        /// Why.
        error: InsertError,
    },
    /// An op was not delivered when inserted: its deps or its author's previous op come
    /// later in the snapshot, or not at all.
    #[error("op {index} of the snapshot arrives before its causal past")]
    OutOfOrder {
        /// Its index in the snapshot's order.
        index: usize,
    },
    /// The ops give another cut than the snapshot names.
    #[error("the ops give the cut {got}, the snapshot names {named}")]
    Cut {
        /// What the snapshot says.
        named: SceneCut,
        /// What its ops give.
        got: SceneCut,
    },
    /// The ops' fold has another scene hash than the one the snapshot names: the producer's
    /// scene is not its ops' fold.
    #[error("the ops' fold is not the scene the snapshot names")]
    SceneHash,
}

/// Why [`verify`] found a joined snapshot wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum VerifyError {
    /// An op's signature does not verify for the session.
    #[error("op {0} is not signed by its author for this session")]
    Unsigned(OpId),
    /// The encoded snapshot did not decode again ([`verify_encoded`]).
    #[error("the snapshot does not decode: {0}")]
    Decode(DecodeError),
}

/// The state of a log, ready to encode or to join from.
#[derive(Debug, Clone)]
pub struct Snapshot<P> {
    /// Every op, in the linear order.
    ops: Vec<Op<P>>,
    /// The DAG's heads, sorted.
    heads: Vec<OpId>,
    scene_hash: SceneHash,
}

impl<P: Payload> Snapshot<P> {
    /// Captures `log` and the hash of its scene as they stand.
    pub fn capture<M: Materialize<P>>(log: &Log<P>, scene: &Materialized<P, M>) -> Self {
        Self {
            ops: log.entries().map(|e| e.op.clone()).collect(),
            // A log's heads come in id order.
            heads: log.heads().copied().collect(),
            scene_hash: scene.scene_hash(),
        }
    }

    /// The ops the snapshot covers.
    pub fn cut(&self) -> SceneCut {
        let mut vv = crate::causal::VersionVector::new();
        for op in &self.ops {
            vv.raise(op.author(), op.seq());
        }
        SceneCut::of_heads(&self.heads, vv.n_ops())
    }

    /// Number of ops.
    pub fn n_ops(&self) -> usize {
        self.ops.len()
    }

    /// The hash of the producer's scene.
    pub fn scene_hash(&self) -> SceneHash {
        self.scene_hash
    }

    /// Inserts every op into `log` (empty, and set up for the session: its id, founder and
    /// binding) without checking signatures, and folds them. Checks the cut and the fold's
    /// hash; see [`verify`] for the signatures.
    pub fn join<M: Materialize<P> + Default>(
        self,
        mut log: Log<P>,
        now: Timestamp,
    ) -> Result<(Log<P>, Materialized<P, M>), JoinError> {
        if !log.is_empty() {
            return Err(JoinError::NotEmpty(log.len()));
        }
        let named = self.cut();
        for (index, op) in self.ops.into_iter().enumerate() {
            let insertion = (log.insert(now, VerifiedOp::trusted(op), LOCAL_ORIGIN))
                .map_err(|error| JoinError::Refused { index, error })?;
            if insertion.delivered.is_empty() {
                return Err(JoinError::OutOfOrder { index });
            }
        }
        let got = SceneCut::of(&log);
        if got.digest != named.digest {
            return Err(JoinError::Cut { named, got });
        }
        let scene = Materialized::<P, M>::fold(&log);
        if scene.scene_hash() != self.scene_hash {
            return Err(JoinError::SceneHash);
        }
        Ok((log, scene))
    }

    /// The encoded snapshot (see the module documentation for the format).
    pub fn encode(&self) -> Result<Vec<u8>, CaptureError> {
        let mut out = SNAPSHOT_MAGIC.to_vec();
        out.push(SNAPSHOT_FORMAT_VERSION);
        put_varint(&mut out, self.ops.len() as u64);
        for op in &self.ops {
            put_bytes(&mut out, op.encoded());
            if out.len() > MAX_SNAPSHOT_BYTES {
                return Err(CaptureError::TooLarge(out.len()));
            }
        }
        put_varint(&mut out, self.heads.len() as u64);
        for head in &self.heads {
            out.extend_from_slice(&head.0);
        }
        out.extend_from_slice(&self.scene_hash.0);
        let checksum = blake3::hash(&out);
        out.extend_from_slice(checksum.as_bytes());
        if out.len() > MAX_SNAPSHOT_BYTES {
            return Err(CaptureError::TooLarge(out.len()));
        }
        Ok(out)
    }

    /// Decodes a snapshot from untrusted bytes: checks size, checksum, format and each op's
    /// encoding, never panicking and allocating only within named limits. Signatures are not
    /// checked (see [`verify`]).
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        if bytes.len() > MAX_SNAPSHOT_BYTES {
            return Err(DecodeError::OverLimit {
                offset: 0,
                what: "snapshot length",
                value: bytes.len() as u64,
                limit: MAX_SNAPSHOT_BYTES as u64,
            });
        }
        let body_len = bytes
            .len()
            .checked_sub(SNAPSHOT_CHECKSUM_BYTES)
            .ok_or(DecodeError::Truncated { offset: 0 })?;
        let (body, checksum) = bytes.split_at(body_len);
        let mut r = Reader::new(body);
        if r.take(SNAPSHOT_MAGIC.len())? != SNAPSHOT_MAGIC {
            return Err(DecodeError::Invalid {
                offset: 0,
                what: "snapshot magic",
            });
        }
        let version_offset = r.offset();
        let version = r.u8()?;
        if version != SNAPSHOT_FORMAT_VERSION {
            return Err(DecodeError::UnknownVersion {
                offset: version_offset,
                version,
            });
        }
        if blake3::hash(body).as_bytes()[..] != checksum[..] {
            return Err(DecodeError::Invalid {
                offset: body_len,
                what: "snapshot checksum",
            });
        }
        let ops = read_ops(&mut r)?;
        let heads = read_heads(&mut r, ops.len())?;
        let scene_hash = SceneHash(r.array::<SCENE_HASH_BYTES>()?);
        r.finish()?;
        Ok(Self {
            ops,
            heads,
            scene_hash,
        })
    }
}

/// Checks what a join took on trust: every op's signature for `session`, in batches of
/// [`MAX_VERIFY_BATCH_OPS`]. `progress` hears how many ops were checked so far.
pub fn verify<P: Payload>(
    log: &Log<P>,
    session: &SessionId,
    progress: impl FnMut(usize),
) -> Result<(), VerifyError> {
    let ops: Vec<&Op<P>> = log.entries().map(|e| e.op).collect();
    verify_ops(&ops, session, progress)
}

/// [`verify`] for an encoded snapshot, before or after it is joined: what a peer that joined
/// from these bytes runs afterwards, off the join's path.
pub fn verify_encoded<P: Payload>(
    bytes: &[u8],
    session: &SessionId,
    progress: impl FnMut(usize),
) -> Result<(), VerifyError> {
    let snapshot = Snapshot::<P>::decode(bytes).map_err(VerifyError::Decode)?;
    let ops: Vec<&Op<P>> = snapshot.ops.iter().collect();
    verify_ops(&ops, session, progress)
}

fn verify_ops<P: Payload>(
    ops: &[&Op<P>],
    session: &SessionId,
    mut progress: impl FnMut(usize),
) -> Result<(), VerifyError> {
    for (i, batch) in ops.chunks(MAX_VERIFY_BATCH_OPS).enumerate() {
        if let Some(bad) = Op::first_unsigned_of(batch, session) {
            return Err(VerifyError::Unsigned(batch[bad].id()));
        }
        progress(i * MAX_VERIFY_BATCH_OPS + batch.len());
    }
    Ok(())
}

fn read_ops<P: Payload>(r: &mut Reader<'_>) -> Result<Vec<Op<P>>, DecodeError> {
    // Bounded by what is left as well, so a hostile count allocates nothing it cannot fill.
    let limit = (r.remaining() / MIN_OP_BYTES).min(MAX_LOG_OPS) as u64;
    let n = r.bounded("snapshot op count", limit)?;
    let mut ops = Vec::with_capacity(n);
    for _ in 0..n {
        let bytes = r.bytes("op length", MAX_OP_BYTES as u64)?;
        let op = Op::<P>::decode(bytes).map_err(|e| e.shifted(r.offset() - bytes.len()))?;
        ops.push(op);
    }
    Ok(ops)
}

fn read_heads(r: &mut Reader<'_>, n_ops: usize) -> Result<Vec<OpId>, DecodeError> {
    let limit = (r.remaining() / 32).min(n_ops) as u64;
    let n = r.bounded("head count", limit)?;
    let mut heads: Vec<OpId> = Vec::with_capacity(n);
    for _ in 0..n {
        let offset = r.offset();
        let id = OpId(r.array()?);
        if heads.last().is_some_and(|h| *h >= id) {
            return Err(DecodeError::Invalid {
                offset,
                what: "snapshot heads out of order",
            });
        }
        heads.push(id);
    }
    Ok(heads)
}

#[cfg(test)]
mod tests;
