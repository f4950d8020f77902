//! Snapshots: the materialised scene and the lease/undo state at a stable cut of the linear
//! order, so a new peer joins from a snapshot plus the ops after the cut instead of replaying
//! (and verifying) all of history.
//!
//! A cut at Lamport time `L` holds exactly the ops with Lamport time `L` or less; it must be
//! at or below [`Log::stable_lamport`], so no op outside it can sort before it later (except
//! from an author the producer never heard of: the joined log refuses such an op with
//! [`crate::log::InsertError::BeforeBase`], and the peer must rebuild from full history).
//!
//! What a snapshot keeps of the ops before the cut: every op id (later ops name them as
//! dependencies), each op's author and whether it is an edit and effective (undo and redo
//! rules read these), the effective edits whole (a later undo or redo may toggle them, and
//! the scene must then re-fold their object), the DAG's heads, and the scene's own snapshot.
//! Leases, chat, rejected edits and undo/redo ops are dropped. Full history stays in the
//! producer's log and store, and any full peer serves it over sync.
//!
//! **Trust.** A snapshot's content cannot be checked against signatures (the ops are gone);
//! its checksum only catches corruption. Join only from a snapshot you made yourself or got
//! from a peer you trust; compare [`crate::materialize::SceneHash`]es with other peers later.
//!
//! Format (version 2), integers as varints: `SCULPTSNAP [1] [cut lamport] [max timestamp]`
//! `[n ≤ MAX_SNAPSHOT_AUTHORS][author 32][seq][lamport]*` (sorted) `[n][id 32][author idx][kind 0/1/2]*`
//! (sorted by id) `[n][head id 32]*` `[fold state]` `[n][len][op]*` (the effective edits in
//! linear order) `[len][scene snapshot]` `[blake3 of everything before, 32]`. Version 1 is the
//! same without the fold state's live leases per author ([`FoldState::encode`]); a log joined
//! from it counts only the leases taken after its cut towards
//! [`crate::lease::MAX_LIVE_LEASES_PER_AUTHOR`].

use crate::causal::VersionVector;
use crate::codec::{DecodeError, Reader, put_bytes, put_varint};
use crate::identity::{OpId, PeerId};
use crate::lease::FoldState;
use crate::log::{Base, CutError, Log, OrderKey};
use crate::log::{BaseAuthor, BaseKind, BaseOp};
use crate::materialize::{MAX_SCENE_SNAPSHOT_BYTES, Materialize, Materialized};
use crate::op::{MAX_LOG_OPS, MAX_OP_BYTES, Op};
use crate::payload::{Effect, ObjectId, Payload};
use crate::pending::PendingLimits;
use crate::time::Timestamp;
use std::collections::BTreeMap;

/// Magic bytes that open an encoded snapshot.
pub const SNAPSHOT_MAGIC: &[u8; 10] = b"SCULPTSNAP";
/// The snapshot format version (2: the fold state names each author's live leases; version 1,
/// without them, still decodes).
pub const SNAPSHOT_FORMAT_VERSION: u8 = 2;
/// Largest encoded snapshot accepted or produced, in bytes (256 MiB).
pub const MAX_SNAPSHOT_BYTES: usize = 256 * 1024 * 1024;
/// Bytes of checksum at the end of a snapshot.
pub const SNAPSHOT_CHECKSUM_BYTES: usize = 32;
/// Most authors a snapshot names: as many as a log can hold (every author has at least one op
/// in it), so any log can be captured whatever its number of authors (within
/// [`MAX_SNAPSHOT_BYTES`]).
pub const MAX_SNAPSHOT_AUTHORS: usize = MAX_LOG_OPS;
/// The fewest bytes an author entry takes: id, seq and Lamport time of one byte each.
const MIN_AUTHOR_BYTES: usize = 32 + 1 + 1;
// Ops name their author by a `u32` index.
const _: () = assert!(MAX_SNAPSHOT_AUTHORS <= u32::MAX as usize);

/// Why a snapshot could not be captured.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CaptureError {
    /// The cut is not usable.
    #[error(transparent)]
    Cut(#[from] CutError),
    /// The log's own base scene did not decode.
    #[error("base scene: {0}")]
    Scene(DecodeError),
    /// The encoding would exceed [`MAX_SNAPSHOT_BYTES`] (or the scene
    /// [`MAX_SCENE_SNAPSHOT_BYTES`]).
    #[error("snapshot of {0} bytes is over its limit")]
    TooLarge(usize),
}

/// The state of a log at a stable cut, ready to encode or to join from.
#[derive(Debug, Clone)]
pub struct Snapshot<P> {
    base: Base<P>,
}

impl<P: Payload> Snapshot<P> {
    /// Captures `log` at Lamport time `cut_lamport` (at most [`Log::stable_lamport`]), folding
    /// the scene as of the cut with `M`.
    pub fn capture<M: Materialize<P> + Default>(
        log: &Log<P>,
        cut_lamport: u64,
    ) -> Result<Self, CaptureError> {
        let (mut base, n) = log.base_at(cut_lamport)?;
        let scene = match log.base() {
            Some(b) => M::decode_snapshot(&b.scene).map_err(CaptureError::Scene)?,
            None => M::default(),
        };
        let mut materialized = Materialized::from_scene(scene);
        materialized.fold_prefix(log, n, &base.state);
        materialized.scene().encode_snapshot(&mut base.scene);
        if base.scene.len() > MAX_SCENE_SNAPSHOT_BYTES {
            return Err(CaptureError::TooLarge(base.scene.len()));
        }
        Ok(Self { base })
    }

    /// The Lamport time of the cut.
    pub fn cut_lamport(&self) -> u64 {
        self.base.lamport
    }

    /// The ops the snapshot stands for.
    pub fn version_vector(&self) -> VersionVector {
        let mut vv = VersionVector::new();
        for a in &self.base.authors {
            vv.raise(a.author, a.seq);
        }
        vv
    }

    /// Number of ops before the cut.
    pub fn n_ops(&self) -> usize {
        self.base.ops.len()
    }

    /// Number of effective edits kept whole.
    pub fn n_edits(&self) -> usize {
        self.base.edits.len()
    }

    /// The scene at the cut, in the scene's snapshot encoding.
    pub fn scene_bytes(&self) -> &[u8] {
        &self.base.scene
    }

    /// A log that starts at the cut; sync then brings the ops after it.
    pub fn into_log(self, limits: PendingLimits) -> Log<P> {
        Log::from_base(self.base, limits)
    }

    /// A log that starts at the cut and its scene, decoded from the snapshot (not re-folded).
    pub fn join<M: Materialize<P>>(
        self,
        limits: PendingLimits,
    ) -> Result<(Log<P>, Materialized<P, M>), DecodeError> {
        let scene = M::decode_snapshot(&self.base.scene)?;
        Ok((self.into_log(limits), Materialized::from_scene(scene)))
    }

    /// The encoded snapshot (see the module documentation for the format).
    pub fn encode(&self) -> Result<Vec<u8>, CaptureError> {
        let b = &self.base;
        let mut out = SNAPSHOT_MAGIC.to_vec();
        out.push(SNAPSHOT_FORMAT_VERSION);
        put_varint(&mut out, b.lamport);
        put_varint(&mut out, b.max_timestamp.0);
        put_varint(&mut out, b.authors.len() as u64);
        for a in &b.authors {
            out.extend_from_slice(&a.author.0);
            put_varint(&mut out, a.seq);
            put_varint(&mut out, a.lamport);
        }
        put_varint(&mut out, b.ops.len() as u64);
        for op in &b.ops {
            out.extend_from_slice(&op.id.0);
            put_varint(&mut out, u64::from(op.author_idx));
            out.push(match op.kind {
                BaseKind::Other => 0,
                BaseKind::RejectedEdit => 1,
                BaseKind::EffectiveEdit => 2,
            });
        }
        put_varint(&mut out, b.heads.len() as u64);
        for head in &b.heads {
            out.extend_from_slice(&head.0);
        }
        b.state.encode(&mut out);
        let mut edits: Vec<(OrderKey, &Op<P>)> =
            b.edits.values().map(|op| (OrderKey::of(op), op)).collect();
        edits.sort_unstable_by_key(|(k, _)| *k);
        put_varint(&mut out, edits.len() as u64);
        for (_, op) in edits {
            put_bytes(&mut out, op.encoded());
        }
        put_bytes(&mut out, &b.scene);
        let checksum = blake3::hash(&out);
        out.extend_from_slice(checksum.as_bytes());
        if out.len() > MAX_SNAPSHOT_BYTES {
            return Err(CaptureError::TooLarge(out.len()));
        }
        Ok(out)
    }

    /// Decodes a snapshot from untrusted bytes: checks size, checksum, format and internal
    /// consistency, never panicking and allocating only within named limits. Signatures of
    /// the kept edits are not checked (see the module's note on trust).
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
        if version != SNAPSHOT_FORMAT_VERSION && version != 1 {
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
        let lamport = r.varint()?;
        let max_timestamp = Timestamp(r.varint()?);
        let authors = read_authors(&mut r, lamport)?;
        let ops = read_ops(&mut r, &authors)?;
        let heads = read_heads(&mut r, &ops)?;
        let state = FoldState::decode(&mut r, version >= 2)?;
        let (edits, edits_by_object) = read_edits::<P>(&mut r, lamport, &authors, &ops)?;
        let scene = r
            .bytes("scene length", MAX_SCENE_SNAPSHOT_BYTES as u64)?
            .to_vec();
        r.finish()?;
        Ok(Self {
            base: Base {
                lamport,
                authors,
                ops,
                edits,
                edits_by_object,
                heads,
                max_timestamp,
                state,
                scene,
            },
        })
    }
}

impl<P: Payload> Log<P> {
    /// A log that starts from a snapshot's cut (see [`Snapshot::into_log`]).
    pub fn from_snapshot(snapshot: Snapshot<P>, limits: PendingLimits) -> Self {
        snapshot.into_log(limits)
    }
}

fn read_authors(r: &mut Reader<'_>, cut: u64) -> Result<Vec<BaseAuthor>, DecodeError> {
    // Bounded by what is left as well, so a hostile count allocates nothing it cannot fill.
    let limit = (r.remaining() / MIN_AUTHOR_BYTES).min(MAX_SNAPSHOT_AUTHORS) as u64;
    let n = r.bounded("author count", limit)?;
    let mut authors: Vec<BaseAuthor> = Vec::with_capacity(n);
    for _ in 0..n {
        let offset = r.offset();
        let author = PeerId(r.array()?);
        let seq = r.varint()?;
        let lamport = r.varint()?;
        let sorted = authors.last().is_none_or(|a| a.author < author);
        if !sorted || seq == 0 || lamport == 0 || lamport > cut {
            return Err(DecodeError::Invalid {
                offset,
                what: "snapshot author",
            });
        }
        authors.push(BaseAuthor {
            author,
            seq,
            lamport,
        });
    }
    Ok(authors)
}

fn read_ops(r: &mut Reader<'_>, authors: &[BaseAuthor]) -> Result<Vec<BaseOp>, DecodeError> {
    let n_expected = authors
        .iter()
        .fold(0u64, |acc, a| acc.saturating_add(a.seq));
    let offset = r.offset();
    // Each op takes at least 34 bytes: bound the count by what is left as well.
    let limit = (r.remaining() / 34).min(MAX_LOG_OPS) as u64;
    let n = r.bounded("snapshot op count", limit)?;
    if n as u64 != n_expected {
        return Err(DecodeError::Invalid {
            offset,
            what: "snapshot op count",
        });
    }
    let mut ops: Vec<BaseOp> = Vec::with_capacity(n);
    for _ in 0..n {
        let offset = r.offset();
        let id = OpId(r.array()?);
        let author_idx = r.bounded("author index", authors.len().saturating_sub(1) as u64)?;
        let kind = match r.u8()? {
            0 => BaseKind::Other,
            1 => BaseKind::RejectedEdit,
            2 => BaseKind::EffectiveEdit,
            _ => {
                return Err(DecodeError::Invalid {
                    offset,
                    what: "snapshot op kind",
                });
            }
        };
        if authors.is_empty() || ops.last().is_some_and(|o| o.id >= id) {
            return Err(DecodeError::Invalid {
                offset,
                what: "snapshot op",
            });
        }
        ops.push(BaseOp {
            id,
            author_idx: author_idx as u32,
            kind,
        });
    }
    Ok(ops)
}

fn read_heads(r: &mut Reader<'_>, ops: &[BaseOp]) -> Result<Vec<OpId>, DecodeError> {
    let limit = (r.remaining() / 32).min(ops.len()) as u64;
    let n = r.bounded("head count", limit)?;
    let mut heads: Vec<OpId> = Vec::with_capacity(n);
    for _ in 0..n {
        let offset = r.offset();
        let id = OpId(r.array()?);
        let known = ops.binary_search_by(|o| o.id.cmp(&id)).is_ok();
        if !known || heads.last().is_some_and(|h| *h >= id) {
            return Err(DecodeError::Invalid {
                offset,
                what: "snapshot head",
            });
        }
        heads.push(id);
    }
    Ok(heads)
}

type Edits<P> = (
    BTreeMap<OpId, Op<P>>,
    BTreeMap<ObjectId, Vec<(OrderKey, OpId)>>,
);

fn read_edits<P: Payload>(
    r: &mut Reader<'_>,
    cut: u64,
    authors: &[BaseAuthor],
    ops: &[BaseOp],
) -> Result<Edits<P>, DecodeError> {
    let n_expected = ops
        .iter()
        .filter(|o| o.kind == BaseKind::EffectiveEdit)
        .count();
    let offset = r.offset();
    let n = r.bounded("snapshot edit count", n_expected as u64)?;
    if n != n_expected {
        return Err(DecodeError::Invalid {
            offset,
            what: "snapshot edit count",
        });
    }
    let mut edits = BTreeMap::new();
    let mut by_object: BTreeMap<ObjectId, Vec<(OrderKey, OpId)>> = BTreeMap::new();
    let mut last: Option<OrderKey> = None;
    for _ in 0..n {
        let offset = r.offset();
        let bytes = r.bytes("op length", MAX_OP_BYTES as u64)?;
        let op = Op::<P>::decode(bytes).map_err(|e| e.shifted(r.offset() - bytes.len()))?;
        let key = OrderKey::of(&op);
        let listed = ops
            .binary_search_by(|o| o.id.cmp(&op.id()))
            .ok()
            .and_then(|i| ops.get(i))
            .is_some_and(|o| {
                o.kind == BaseKind::EffectiveEdit
                    && authors.get(o.author_idx as usize).map(|a| a.author) == Some(op.author())
            });
        let in_vv = authors
            .binary_search_by(|a| a.author.cmp(&op.author()))
            .is_ok_and(|i| authors[i].seq >= op.seq());
        let Effect::Edit { object } = op.payload().effect() else {
            return Err(DecodeError::Invalid {
                offset,
                what: "snapshot edit is not an edit",
            });
        };
        if !listed || !in_vv || op.lamport() > cut || last.is_some_and(|l| l >= key) {
            return Err(DecodeError::Invalid {
                offset,
                what: "snapshot edit",
            });
        }
        last = Some(key);
        by_object.entry(object).or_default().push((key, op.id()));
        edits.insert(op.id(), op);
    }
    Ok((edits, by_object))
}

#[cfg(test)]
mod tests;
