//! Signed ops: their canonical, versioned binary encoding, their ids (blake3 of the
//! encoding) and signature checks.

use std::fmt;

use crate::codec::{DecodeError, Reader, put_varint};
use crate::identity::{
    Keypair, OP_ID_BYTES, OpId, PEER_ID_BYTES, PeerId, SESSION_ID_BYTES, SIGNATURE_BYTES,
    SessionId, Signature, VerifyError,
};
use crate::payload::{MAX_PAYLOAD_BYTES, Payload};
use crate::time::Timestamp;

/// Version byte that opens every op signed now: 2, whose signature covers the session's id
/// ([`Op::sign`]), so an op signed for one session never verifies in another.
pub const OP_FORMAT_VERSION: u8 = 2;
/// Version byte of ops signed before signatures named their session: they still decode and
/// verify (their signature covers the op alone), except in a log that binds its authors
/// ([`crate::Log::bind_authors`]), which refuses them.
pub const OP_FORMAT_VERSION_1: u8 = 1;
/// The session a log made without one signs under ([`crate::Log::set_session_id`]): tests and
/// tools that never sync.
pub const UNNAMED_SESSION: SessionId = [0; SESSION_ID_BYTES];
/// Most causal dependencies one op may name.
pub const MAX_DEPS: usize = 32;
/// Most ops one log holds; past it, inserts fail (the store and sync stop growing it). Its
/// slab names them by 4-byte positions, far below `u32::MAX`.
pub const MAX_LOG_OPS: usize = 10_000_000;
/// Largest possible encoded op in bytes: version, author, three varints, deps, payload,
/// signature.
pub const MAX_OP_BYTES: usize = 1
    + PEER_ID_BYTES
    + 3 * 10
    + 10
    + MAX_DEPS * OP_ID_BYTES
    + 10
    + MAX_PAYLOAD_BYTES
    + SIGNATURE_BYTES;
/// Domain separation for op signatures, so they can never be replayed as another message;
/// the session's id follows it in what is signed.
const SIGNING_CONTEXT: &[u8] = b"sculpt/op/v2";
/// What ops of [`OP_FORMAT_VERSION_1`] signed: the context and the op, no session.
const SIGNING_CONTEXT_V1: &[u8] = b"sculpt/op/v1";

/// Ops per chunk of an [`OpSlab`]. A chunk is allocated whole, so at most this many slots
/// less one stand empty (about 7 KiB of `TestPayload` ops).
const SLAB_CHUNK: usize = 64;

/// The latest held ops [`OpSlab::position`] compares before it probes the index.
const RECENT_SLOTS: u32 = 4;

/// Held ops, stored by arrival in chunks of [`SLAB_CHUNK`] and found by id through a hash
/// table of their positions: growing moves no op, only chunk handles and 4-byte index
/// entries, and a log's ops sit in arrival order, near the ops they were delivered with.
///
/// The table holds positions only; a lookup confirms a candidate against the op's own id.
/// Ids are blake3 hashes, so their first eight bytes are already a uniform hash
/// ([`id_hash`]): nothing is hashed, and an entry is 4 bytes where an id and its position
/// were 36. Nothing iterates the table. A member who wants its ops to collide must sign each
/// attempt at an id, about 2^17 signatures per colliding op in a log of 10^5 ops.
#[derive(Clone, Debug)]
pub(crate) struct OpSlab<P> {
    chunks: Vec<Vec<Op<P>>>,
    index: hashbrown::HashTable<u32>,
    len: usize,
}

/// The hash of an op id in an [`OpSlab`]'s table: its first eight bytes.
fn id_hash(id: &OpId) -> u64 {
    let (head, _) = id.0.split_first_chunk::<8>().expect("an id is 32 bytes");
    u64::from_le_bytes(*head)
}

/// The op at position `at` of a slab's chunks (a free function: the slab's table borrows
/// the chunks beside itself while it grows).
fn slot<P>(chunks: &[Vec<Op<P>>], at: u32) -> &Op<P> {
    let at = at as usize;
    &chunks[at / SLAB_CHUNK][at % SLAB_CHUNK]
}

impl<P> Default for OpSlab<P> {
    fn default() -> Self {
        Self {
            chunks: Vec::new(),
            index: hashbrown::HashTable::new(),
            len: 0,
        }
    }
}

impl<P> OpSlab<P> {
    /// The op with id `id`, if held.
    pub(crate) fn get(&self, id: &OpId) -> Option<&Op<P>> {
        Some(self.at(self.position(id)?))
    }

    /// Where the op with id `id` is held, if it is: a position [`OpSlab::at`] takes, which
    /// never changes.
    pub(crate) fn position(&self, id: &OpId) -> Option<u32> {
        // A live op names the latest ops as its deps and is asked about right after it is
        // held: the last few slots answer most lookups without a probe of the table.
        let n = u32::try_from(self.len).unwrap_or(u32::MAX);
        let recent = n.saturating_sub(RECENT_SLOTS)..n;
        if let Some(at) = recent.rev().find(|&at| self.at(at).id == *id) {
            return Some(at);
        }
        self.indexed_position(id)
    }

    /// [`OpSlab::position`] from the table alone, without comparing the latest ops first: for
    /// an id that is usually not held (an op arriving), which those comparisons never find.
    pub(crate) fn indexed_position(&self, id: &OpId) -> Option<u32> {
        self.index
            .find(id_hash(id), |&at| self.at(at).id == *id)
            .copied()
    }

    /// True if an op with id `id` is held.
    pub(crate) fn contains_key(&self, id: &OpId) -> bool {
        self.get(id).is_some()
    }

    /// The op held at position `at` (from [`OpSlab::position`] or [`OpSlab::insert`]).
    pub(crate) fn at(&self, at: u32) -> &Op<P> {
        slot(&self.chunks, at)
    }

    /// Holds `op` (not held yet) under its id and returns its position: the number of ops
    /// held before it. A log holds at most [`MAX_LOG_OPS`] ops, far below
    /// `u32::MAX`. Inlined, so that the op moves from its caller into its slot once, not
    /// through this call's argument as well.
    #[inline]
    pub(crate) fn insert(&mut self, id: OpId, op: Op<P>) -> u32 {
        debug_assert!(!self.contains_key(&id), "an op is held once");
        debug_assert!(op.id == id, "an op is held under its own id");
        let at = u32::try_from(self.len).expect("a log holds fewer than 2^32 ops");
        if self.len.is_multiple_of(SLAB_CHUNK) {
            // Allocated whole: a chunk growing by doubling moved each of its ops about once on
            // the way (about 130 instructions per insert), and a chunk this small leaves few
            // slots empty.
            self.chunks.push(Vec::with_capacity(SLAB_CHUNK));
        }
        if let Some(chunk) = self.chunks.last_mut() {
            chunk.push(op);
        }
        self.len += 1;
        let chunks = &self.chunks;
        self.index
            .insert_unique(id_hash(&id), at, |&at| id_hash(&slot(chunks, at).id));
        at
    }

    /// Ops held.
    pub(crate) fn len(&self) -> usize {
        self.len
    }
}

/// The unsigned fields of an op, as its author fills them in.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OpFields<P> {
    /// Per-author sequence number, starting at 1, without gaps.
    pub seq: u64,
    /// Lamport time: greater than the Lamport time of every dependency.
    pub lamport: u64,
    /// Hybrid wall-clock timestamp (display and lease expiry).
    pub timestamp: Timestamp,
    /// Ids of the ops this one depends on (the author's heads); sorted and deduplicated here.
    pub deps: Vec<OpId>,
    /// The object model's content.
    pub payload: P,
}

/// Why an op could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BuildError {
    /// More dependencies than [`MAX_DEPS`].
    #[error("{0} dependencies, over the limit {MAX_DEPS}")]
    TooManyDeps(usize),
    /// The payload does not decode back to itself (it breaks the [`Payload`] contract, for
    /// example by exceeding one of its own limits).
    #[error("payload does not round-trip through its encoding")]
    PayloadNotCanonical,
    /// The payload encodes to more than [`MAX_PAYLOAD_BYTES`].
    #[error("payload is {0} bytes, over the limit {MAX_PAYLOAD_BYTES}")]
    PayloadTooLarge(usize),
    /// Sequence number or Lamport time was 0.
    #[error("seq and lamport start at 1")]
    ZeroCounter,
}

/// A signed op. Immutable: its id and encoding are computed once, when built or decoded.
///
/// A log holds every op of the session, so an op keeps each part once: its dependencies and
/// signature, and its author, are read from the encoding in place, not copied beside it.
#[derive(Clone, PartialEq, Eq)]
pub struct Op<P> {
    seq: u64,
    lamport: u64,
    timestamp: Timestamp,
    payload: P,
    id: OpId,
    encoded: Box<[u8]>,
    deps: DepsAt,
}

/// Where an op's dependencies lie in its encoding: `n` ids from byte `at`. Dependencies start
/// after the version, author and four varints, so `at` is below 100.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct DepsAt {
    at: u8,
    n: u8,
}

impl DepsAt {
    fn new(at: usize, n: usize) -> Self {
        Self {
            at: u8::try_from(at).expect("dependencies start within the op's first 100 bytes"),
            n: u8::try_from(n).expect("an op names at most MAX_DEPS dependencies"),
        }
    }

    /// The dependencies in `encoded`.
    fn of(self, encoded: &[u8]) -> &[OpId] {
        let start = usize::from(self.at);
        let bytes = &encoded[start..start + usize::from(self.n) * OP_ID_BYTES];
        <OpId as bytemuck::TransparentWrapper<_>>::wrap_slice(bytes.as_chunks::<OP_ID_BYTES>().0)
    }
}

/// An op whose signature has been checked, or that this peer signed itself. Only these
/// enter a [`crate::log::Log`], so each op's signature is checked once.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VerifiedOp<P>(Op<P>);

impl<P> VerifiedOp<P> {
    /// The op.
    pub fn op(&self) -> &Op<P> {
        &self.0
    }

    /// The op, giving up the proof.
    pub fn into_op(self) -> Op<P> {
        self.0
    }

    /// Wraps an op the crate already verified (it is in a log, or was just signed).
    pub(crate) fn trusted(op: Op<P>) -> Self {
        Self(op)
    }
}

impl<P> std::ops::Deref for VerifiedOp<P> {
    type Target = Op<P>;
    fn deref(&self) -> &Op<P> {
        &self.0
    }
}

impl<P: Payload> Op<P> {
    /// Builds and signs an op by `keypair`'s peer for `session` (its signature covers the
    /// session's id, so it verifies in that session only).
    pub fn sign(
        keypair: &Keypair,
        session: &SessionId,
        fields: OpFields<P>,
    ) -> Result<VerifiedOp<P>, BuildError> {
        Self::build(keypair, OP_FORMAT_VERSION, session, fields).map(VerifiedOp)
    }

    /// An op in the layout signed before signatures named their session
    /// ([`OP_FORMAT_VERSION_1`]), for tests of how such ops are still read.
    #[cfg(test)]
    pub(crate) fn sign_v1(
        keypair: &Keypair,
        fields: OpFields<P>,
    ) -> Result<VerifiedOp<P>, BuildError> {
        Self::build(keypair, OP_FORMAT_VERSION_1, &UNNAMED_SESSION, fields).map(VerifiedOp)
    }

    fn build(
        keypair: &Keypair,
        version: u8,
        session: &SessionId,
        mut fields: OpFields<P>,
    ) -> Result<Self, BuildError> {
        fields.deps.sort_unstable();
        fields.deps.dedup();
        if fields.deps.len() > MAX_DEPS {
            return Err(BuildError::TooManyDeps(fields.deps.len()));
        }
        if fields.seq == 0 || fields.lamport == 0 {
            return Err(BuildError::ZeroCounter);
        }
        let author = keypair.peer_id();
        let mut encoded = Vec::new();
        let deps = encode_body(&mut encoded, version, &author, &fields)?;
        let signature = keypair.sign(&signing_message(&encoded, session));
        encoded.extend_from_slice(&signature.0);
        assert!(
            encoded.len() <= MAX_OP_BYTES,
            "op encoding exceeds MAX_OP_BYTES"
        );
        let id = OpId(*blake3::hash(&encoded).as_bytes());
        Ok(Self {
            seq: fields.seq,
            lamport: fields.lamport,
            timestamp: fields.timestamp,
            payload: fields.payload,
            id,
            encoded: encoded.into_boxed_slice(),
            deps,
        })
    }

    /// Decodes an op from untrusted bytes. It checks the format, limits and canonical form,
    /// but not the signature: call [`Op::verify`], or use [`Op::decode_verified`], which checks
    /// the signature before the payload's (costlier) validation.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        Envelope::parse(bytes)?.into_op()
    }

    /// Decodes an op from untrusted bytes, cheapest check first: the envelope (format and
    /// limits), then the signature (for `session`), and only then the payload, whose
    /// validation may compile formulas. A forged op costs a hash and a signature check, never
    /// a compile.
    pub fn decode_verified(
        bytes: &[u8],
        session: &SessionId,
    ) -> Result<VerifiedOp<P>, ReceiveError> {
        Envelope::parse(bytes)?.into_verified(session)
    }

    /// Checks the author's signature over the op's body, for `session` (an op of
    /// [`OP_FORMAT_VERSION_1`] names no session and verifies in any).
    pub fn verify(&self, session: &SessionId) -> Result<(), VerifyError> {
        self.author()
            .verify(&signing_message(self.body(), session), &self.signature())
    }

    /// The signed part of the encoding.
    fn body(&self) -> &[u8] {
        &self.encoded[..self.encoded.len() - SIGNATURE_BYTES]
    }

    /// Checks the signatures of `ops` for `session` in batches (see
    /// [`Envelope::into_verified_all`]): the index of the first op whose signature does not
    /// verify, if any.
    pub fn first_unsigned(ops: &[Self], session: &SessionId) -> Option<usize> {
        let refs: Vec<&Self> = ops.iter().collect();
        Self::first_unsigned_of(&refs, session)
    }

    /// [`Op::first_unsigned`] over ops held elsewhere (a log's, checked in place).
    pub fn first_unsigned_of(ops: &[&Self], session: &SessionId) -> Option<usize> {
        let bodies: Vec<(PeerId, &[u8], Signature)> = ops
            .iter()
            .map(|op| (op.author(), op.body(), op.signature()))
            .collect();
        if all_signed(&bodies, session) {
            None
        } else {
            ops.iter().position(|op| op.verify(session).is_err())
        }
    }

    /// Checks the signature for `session` and returns the op as verified.
    pub fn into_verified(self, session: &SessionId) -> Result<VerifiedOp<P>, VerifyError> {
        self.verify(session)?;
        Ok(VerifiedOp(self))
    }
}

/// Why a received op was refused by [`Op::decode_verified`].
#[derive(Debug, thiserror::Error)]
pub enum ReceiveError {
    /// The bytes are not a valid op.
    #[error(transparent)]
    Decode(#[from] DecodeError),
    /// The signature does not verify against the author.
    #[error(transparent)]
    Verify(#[from] VerifyError),
}

/// An op's envelope read from untrusted bytes: every field but the payload decoded, its
/// format and limits checked, its id computed. Enough to skip a known op or a forged one
/// before the payload is decoded.
#[derive(Debug)]
pub struct Envelope<'a> {
    bytes: &'a [u8],
    id: OpId,
    author: PeerId,
    seq: u64,
    lamport: u64,
    timestamp: Timestamp,
    deps: DepsAt,
    /// Where the payload's length prefix starts, and the payload itself.
    payload_offset: usize,
    payload_start: usize,
    payload_bytes: &'a [u8],
    signature: Signature,
}

impl<'a> Envelope<'a> {
    /// Reads the envelope: version, author, counters, deps, the payload's length and the
    /// signature, with no trailing bytes.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, DecodeError> {
        if bytes.len() > MAX_OP_BYTES {
            return Err(DecodeError::OverLimit {
                offset: 0,
                what: "op length",
                value: bytes.len() as u64,
                limit: MAX_OP_BYTES as u64,
            });
        }
        let mut r = Reader::new(bytes);
        let version = r.u8()?;
        if version != OP_FORMAT_VERSION && version != OP_FORMAT_VERSION_1 {
            return Err(DecodeError::UnknownVersion { offset: 0, version });
        }
        let author = PeerId(r.array()?);
        let counters_offset = r.offset();
        let seq = r.varint()?;
        let lamport = r.varint()?;
        if seq == 0 || lamport == 0 {
            return Err(DecodeError::Invalid {
                offset: counters_offset,
                what: "zero seq or lamport",
            });
        }
        let timestamp = Timestamp(r.varint()?);
        let deps = check_deps(&mut r)?;
        let payload_offset = r.offset();
        let payload_bytes = r.bytes("payload length", MAX_PAYLOAD_BYTES as u64)?;
        let payload_start = r.offset() - payload_bytes.len();
        let signature = Signature(r.array()?);
        r.finish()?;
        Ok(Self {
            bytes,
            id: OpId(*blake3::hash(bytes).as_bytes()),
            author,
            seq,
            lamport,
            timestamp,
            deps,
            payload_offset,
            payload_start,
            payload_bytes,
            signature,
        })
    }

    /// The op's id.
    pub fn id(&self) -> OpId {
        self.id
    }

    /// The claimed author.
    pub fn author(&self) -> PeerId {
        self.author
    }

    /// The claimed seq.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// The op's dependencies, sorted.
    pub fn deps(&self) -> &'a [OpId] {
        self.deps.of(self.bytes)
    }

    /// Checks the author's signature over the body, for `session`.
    pub fn verify(&self, session: &SessionId) -> Result<(), VerifyError> {
        self.author
            .verify(&signing_message(self.body(), session), &self.signature)
    }

    /// Checks the signature for `session`, then decodes the payload: the op, verified.
    pub fn into_verified<P: Payload>(
        self,
        session: &SessionId,
    ) -> Result<VerifiedOp<P>, ReceiveError> {
        self.verify(session)?;
        Ok(VerifiedOp(self.into_op()?))
    }

    /// [`Envelope::into_verified`] for many envelopes, with their signatures checked in
    /// batches ([`crate::identity::verify_batch`]): the same verdicts, in the same order, at
    /// about a third of the cost when few authors signed them. A batch holding a forged
    /// signature is checked again one by one, so forged ops cost their sender, not the others.
    pub fn into_verified_all<P: Payload>(
        envelopes: Vec<Self>,
        session: &SessionId,
    ) -> Vec<Result<VerifiedOp<P>, ReceiveError>> {
        let bodies: Vec<(PeerId, &[u8], Signature)> = envelopes
            .iter()
            .map(|e| (e.author, e.body(), e.signature))
            .collect();
        let all_signed = all_signed(&bodies, session);
        envelopes
            .into_iter()
            .map(|e| {
                if all_signed {
                    Ok(VerifiedOp(e.into_op()?))
                } else {
                    e.into_verified(session)
                }
            })
            .collect()
    }

    /// The signed part of the op's bytes.
    fn body(&self) -> &'a [u8] {
        &self.bytes[..self.bytes.len() - SIGNATURE_BYTES]
    }

    /// Decodes and validates the payload (which must be in canonical form) into the op.
    pub fn into_op<P: Payload>(self) -> Result<Op<P>, DecodeError> {
        let payload = P::decode(self.payload_bytes).map_err(|e| e.shifted(self.payload_start))?;
        if !payload.is_canonical(self.payload_bytes) {
            return Err(DecodeError::Invalid {
                offset: self.payload_offset,
                what: "non-canonical payload",
            });
        }
        Ok(Op {
            seq: self.seq,
            lamport: self.lamport,
            timestamp: self.timestamp,
            payload,
            id: self.id,
            encoded: self.bytes.into(),
            deps: self.deps,
        })
    }
}

impl<P> Op<P> {
    /// The op's id, where the op holds it.
    pub(crate) fn id_ref(&self) -> &OpId {
        &self.id
    }

    /// The op's id (blake3 of [`Op::encoded`]).
    pub fn id(&self) -> OpId {
        self.id
    }
    /// The author's peer id (the encoding's bytes after its version).
    pub fn author(&self) -> PeerId {
        PeerId(
            *self.encoded[1..]
                .first_chunk()
                .expect("an op's encoding starts with its version and author"),
        )
    }
    /// Per-author sequence number.
    pub fn seq(&self) -> u64 {
        self.seq
    }
    /// Lamport time.
    pub fn lamport(&self) -> u64 {
        self.lamport
    }
    /// Hybrid wall-clock timestamp.
    pub fn timestamp(&self) -> Timestamp {
        self.timestamp
    }
    /// Causal dependencies, sorted.
    pub fn deps(&self) -> &[OpId] {
        self.deps.of(&self.encoded)
    }
    /// The payload.
    pub fn payload(&self) -> &P {
        &self.payload
    }
    /// The signature (the encoding's last bytes).
    pub fn signature(&self) -> Signature {
        Signature(
            *self
                .encoded
                .last_chunk()
                .expect("an op's encoding ends with its signature"),
        )
    }
    /// The canonical encoding (what is sent, stored and hashed).
    pub fn encoded(&self) -> &[u8] {
        &self.encoded
    }
    /// The format version the op was signed in ([`OP_FORMAT_VERSION`], or
    /// [`OP_FORMAT_VERSION_1`] for an op signed before signatures named their session).
    pub fn version(&self) -> u8 {
        self.encoded[0]
    }
}

impl<P: fmt::Debug> fmt::Debug for Op<P> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Op")
            .field("id", &self.id)
            .field("author", &self.author())
            .field("seq", &self.seq)
            .field("lamport", &self.lamport)
            .field("timestamp", &self.timestamp)
            .field("deps", &self.deps())
            .field("payload", &self.payload)
            .finish()
    }
}

/// Appends the op's body (everything but the signature); returns where its deps lie.
fn encode_body<P: Payload>(
    out: &mut Vec<u8>,
    version: u8,
    author: &PeerId,
    fields: &OpFields<P>,
) -> Result<DepsAt, BuildError> {
    out.push(version);
    out.extend_from_slice(&author.0);
    put_varint(out, fields.seq);
    put_varint(out, fields.lamport);
    put_varint(out, fields.timestamp.0);
    put_varint(out, fields.deps.len() as u64);
    let deps = DepsAt::new(out.len(), fields.deps.len());
    for dep in &fields.deps {
        out.extend_from_slice(&dep.0);
    }
    let mut payload = Vec::new();
    fields.payload.encode(&mut payload);
    if payload.len() > MAX_PAYLOAD_BYTES {
        return Err(BuildError::PayloadTooLarge(payload.len()));
    }
    // What we sign must be what every peer will decode.
    if P::decode(&payload).as_ref() != Ok(&fields.payload) {
        return Err(BuildError::PayloadNotCanonical);
    }
    put_varint(out, payload.len() as u64);
    out.extend_from_slice(&payload);
    Ok(deps)
}

/// Reads past the dependencies, checking they are sorted and distinct; returns where they lie.
fn check_deps(r: &mut Reader<'_>) -> Result<DepsAt, DecodeError> {
    let n_deps = r.bounded("dependency count", MAX_DEPS as u64)?;
    let deps = DepsAt::new(r.offset(), n_deps);
    let mut last: Option<OpId> = None;
    for _ in 0..n_deps {
        let offset = r.offset();
        let dep = OpId(r.array()?);
        if last.is_some_and(|last| last >= dep) {
            return Err(DecodeError::Invalid {
                offset,
                what: "unsorted or repeated dependency",
            });
        }
        last = Some(dep);
    }
    Ok(deps)
}

/// True if every `(author, body, signature)` verifies for `session`, checked in batches
/// ([`crate::identity::verify_batch`]).
fn all_signed(bodies: &[(PeerId, &[u8], Signature)], session: &SessionId) -> bool {
    let messages: Vec<Vec<u8>> = bodies
        .iter()
        .map(|(_, body, _)| signing_message(body, session))
        .collect();
    let items: Vec<(PeerId, &[u8], Signature)> = bodies
        .iter()
        .zip(&messages)
        .map(|((author, _, signature), message)| (*author, message.as_slice(), *signature))
        .collect();
    crate::identity::verify_batch(&items)
}

/// What an op's signature covers: for [`OP_FORMAT_VERSION`] the context, the session's id
/// and the body; for [`OP_FORMAT_VERSION_1`] (no session) the old context and the body. The
/// body opens with the version byte, so neither layout's message can pass for the other's.
fn signing_message(body: &[u8], session: &SessionId) -> Vec<u8> {
    let v1 = body.first() == Some(&OP_FORMAT_VERSION_1);
    let context = if v1 {
        SIGNING_CONTEXT_V1
    } else {
        SIGNING_CONTEXT
    };
    let session: &[u8] = if v1 { &[] } else { session };
    let mut message = Vec::with_capacity(context.len() + session.len() + body.len());
    message.extend_from_slice(context);
    message.extend_from_slice(session);
    message.extend_from_slice(body);
    message
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::LeaseAction;
    use crate::payload::test_payload::TestPayload;
    use proptest::prelude::*;

    /// The session the tests sign for.
    const S: SessionId = [5; SESSION_ID_BYTES];

    fn payload_strategy() -> impl Strategy<Value = TestPayload> {
        prop_oneof![
            "[a-z ]{0,40}".prop_map(TestPayload::Chat),
            (any::<u64>(), "[a-z0-9+*() ]{0,60}")
                .prop_map(|(object, value)| TestPayload::Set { object, value }),
            (any::<u64>(), any::<bool>(), any::<u64>()).prop_map(|(object, strong, ttl_micros)| {
                TestPayload::Lease(LeaseAction::Acquire {
                    object,
                    strong,
                    ttl_micros,
                })
            }),
            any::<u64>().prop_map(|object| TestPayload::Lease(LeaseAction::Release { object })),
            any::<[u8; 32]>().prop_map(|b| TestPayload::Undo(OpId(b))),
            any::<[u8; 32]>().prop_map(|b| TestPayload::Redo(OpId(b))),
        ]
    }

    /// Decodes counted, to show which checks run before the payload is decoded.
    static PAYLOAD_DECODES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

    #[derive(Clone, Debug, PartialEq, Eq)]
    struct Counted(TestPayload);

    impl Payload for Counted {
        fn encode(&self, out: &mut Vec<u8>) {
            self.0.encode(out);
        }
        fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
            PAYLOAD_DECODES.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            TestPayload::decode(bytes).map(Counted)
        }
        fn effect(&self) -> crate::payload::Effect {
            self.0.effect()
        }
    }

    #[test]
    fn a_forged_op_is_refused_before_its_payload_is_decoded() {
        let k = Keypair::from_seed([7; 32]);
        let fields = OpFields {
            seq: 1,
            lamport: 1,
            timestamp: Timestamp(5),
            deps: vec![],
            payload: Counted(TestPayload::Chat("a formula to compile".into())),
        };
        let op = Op::sign(&k, &S, fields).unwrap();
        let mut forged = op.encoded().to_vec();
        let last = forged.len() - 1;
        forged[last] ^= 1;
        let before = PAYLOAD_DECODES.load(std::sync::atomic::Ordering::SeqCst);
        let refused = Op::<Counted>::decode_verified(&forged, &S);
        assert!(
            matches!(refused, Err(ReceiveError::Verify(_))),
            "{refused:?}"
        );
        let after = PAYLOAD_DECODES.load(std::sync::atomic::Ordering::SeqCst);
        assert_eq!(after, before, "a forged op's payload was decoded");
        // The honest op decodes (its payload once) and verifies.
        let honest = Op::<Counted>::decode_verified(op.encoded(), &S).unwrap();
        assert_eq!(honest.id(), op.id());
        assert_eq!(
            PAYLOAD_DECODES.load(std::sync::atomic::Ordering::SeqCst),
            after + 1
        );
        // Its envelope alone names it, for the duplicate check, without decoding anything.
        let envelope = Envelope::parse(op.encoded()).unwrap();
        assert_eq!((envelope.id(), envelope.author()), (op.id(), op.author()));
        assert_eq!(
            PAYLOAD_DECODES.load(std::sync::atomic::Ordering::SeqCst),
            after + 1
        );
    }

    fn sample(seed: u8) -> Op<TestPayload> {
        let k = Keypair::from_seed([seed; 32]);
        let fields = OpFields {
            seq: 3,
            lamport: 9,
            timestamp: Timestamp(1_700_000_000_000_000),
            deps: vec![OpId([2; 32]), OpId([1; 32])],
            payload: TestPayload::Set {
                object: 4,
                value: "x*x+y*y-1".into(),
            },
        };
        Op::sign(&k, &S, fields).unwrap().into_op()
    }

    /// The slab's table holds positions hashed by an id's first eight bytes: ids that share
    /// them are told apart by the ops' own ids, through every growth of the table.
    #[test]
    fn a_slab_finds_ops_whose_ids_share_their_hash_bits() {
        let template = sample(1);
        let with_id = |id: [u8; 32]| {
            let mut op = template.clone();
            op.id = OpId(id);
            op
        };
        let twin = |i: u32, tail: u8| {
            let mut id = [tail; 32];
            id[..4].copy_from_slice(&(i % 64).to_le_bytes());
            id[4..8].copy_from_slice(&[0xab; 4]);
            id[8..12].copy_from_slice(&i.to_le_bytes());
            id
        };
        let mut slab = OpSlab::default();
        // 64 hash values, each shared by about 156 ids.
        for i in 0..10_000 {
            slab.insert(OpId(twin(i, 1)), with_id(twin(i, 1)));
        }
        assert_eq!(slab.len(), 10_000);
        for i in 0..10_000 {
            let id = OpId(twin(i, 1));
            assert_eq!(slab.get(&id).map(Op::id), Some(id), "op {i}");
            assert!(
                !slab.contains_key(&OpId(twin(i, 2))),
                "a stranger with the same bits"
            );
        }
        assert_eq!(slab.get(&template.id()), None);
    }

    #[test]
    fn build_sorts_deps_and_verifies() {
        let op = sample(1);
        assert_eq!(op.author(), Keypair::from_seed([1; 32]).peer_id());
        assert_eq!(op.deps(), &[OpId([1; 32]), OpId([2; 32])]);
        assert!(op.verify(&S).is_ok());
        assert_eq!(op.encoded()[0], OP_FORMAT_VERSION);
        assert!(op.encoded().len() < 1024);
    }

    #[test]
    fn an_op_signed_for_one_session_verifies_in_no_other() {
        let op = sample(1);
        let other: SessionId = [6; SESSION_ID_BYTES];
        assert!(op.verify(&S).is_ok());
        assert!(op.verify(&other).is_err());
        let envelope = Envelope::parse(op.encoded()).unwrap();
        assert!(envelope.verify(&other).is_err());
        assert!(matches!(
            Op::<TestPayload>::decode_verified(op.encoded(), &other),
            Err(ReceiveError::Verify(_))
        ));
        let batch = Envelope::into_verified_all::<TestPayload>(vec![envelope], &other);
        assert!(matches!(batch[..], [Err(ReceiveError::Verify(_))]));
        assert_eq!(
            Op::first_unsigned(std::slice::from_ref(&op), &other),
            Some(0)
        );
        assert_eq!(Op::first_unsigned(&[op], &S), None);
    }

    #[test]
    fn an_op_signed_before_ops_named_their_session_still_reads_and_verifies() {
        let k = Keypair::from_seed([4; 32]);
        let fields = OpFields {
            seq: 1,
            lamport: 1,
            timestamp: Timestamp(5),
            deps: vec![],
            payload: TestPayload::Chat("old".into()),
        };
        let old = Op::sign_v1(&k, fields.clone()).unwrap().into_op();
        assert_eq!(old.version(), OP_FORMAT_VERSION_1);
        let read = Op::<TestPayload>::decode(old.encoded()).unwrap();
        assert_eq!(read, old);
        // It names no session, so it verifies under any.
        assert!(read.verify(&S).is_ok() && read.verify(&UNNAMED_SESSION).is_ok());
        // The same fields signed now make another op, which names its session.
        let new = Op::sign(&k, &S, fields).unwrap();
        assert_eq!(new.version(), OP_FORMAT_VERSION);
        assert_ne!(new.id(), old.id());
        // Relabelled as signed now, its signature no longer verifies.
        let mut relabelled = old.encoded().to_vec();
        relabelled[0] = OP_FORMAT_VERSION;
        let relabelled = Op::<TestPayload>::decode(&relabelled).unwrap();
        assert!(relabelled.verify(&S).is_err() && relabelled.verify(&UNNAMED_SESSION).is_err());
    }

    #[test]
    fn tampering_breaks_signature_or_id() {
        let op = sample(1);
        // Swap the author for another peer: the signature no longer verifies.
        let mut bytes = op.encoded().to_vec();
        bytes[1..33].copy_from_slice(&Keypair::from_seed([2; 32]).peer_id().0);
        let forged = Op::<TestPayload>::decode(&bytes).unwrap();
        assert!(forged.verify(&S).is_err());
        assert_ne!(forged.id(), op.id());
    }

    #[test]
    fn hostile_headers_are_rejected_with_offsets() {
        let op = sample(1);
        let mut bytes = op.encoded().to_vec();
        bytes[0] = 9;
        assert_eq!(
            Op::<TestPayload>::decode(&bytes).unwrap_err(),
            DecodeError::UnknownVersion {
                offset: 0,
                version: 9
            }
        );
        let big = vec![1u8; MAX_OP_BYTES + 1];
        assert_eq!(Op::<TestPayload>::decode(&big).unwrap_err().offset(), 0);
        let cut = &op.encoded()[..op.encoded().len() - 1];
        assert!(matches!(
            Op::<TestPayload>::decode(cut),
            Err(DecodeError::Truncated { .. })
        ));
        let mut long = op.encoded().to_vec();
        long.push(0);
        assert!(matches!(
            Op::<TestPayload>::decode(&long),
            Err(DecodeError::Trailing { .. })
        ));
    }

    #[test]
    fn limits_are_enforced_when_building() {
        let k = Keypair::from_seed([1; 32]);
        let deps = (0..=MAX_DEPS as u8).map(|i| OpId([i; 32])).collect();
        let fields = OpFields {
            seq: 1,
            lamport: 1,
            timestamp: Timestamp(0),
            deps,
            payload: TestPayload::Chat(String::new()),
        };
        assert_eq!(
            Op::sign(&k, &S, fields).unwrap_err(),
            BuildError::TooManyDeps(MAX_DEPS + 1)
        );
        let long = OpFields {
            seq: 1,
            lamport: 1,
            timestamp: Timestamp(0),
            deps: vec![],
            payload: TestPayload::Chat("x".repeat(300)),
        };
        assert_eq!(
            Op::sign(&k, &S, long).unwrap_err(),
            BuildError::PayloadNotCanonical
        );
    }

    proptest! {
        #![proptest_config(crate::test_config(64))]
        #[test]
        fn encode_decode_round_trips(
            seed in any::<u8>(), seq in 1u64.., lamport in 1u64.., ts in any::<u64>(),
            deps in proptest::collection::vec(any::<[u8; 32]>(), 0..5),
            payload in payload_strategy(),
        ) {
            let k = Keypair::from_seed([seed; 32]);
            let deps = deps.into_iter().map(OpId).collect();
            let op = Op::sign(&k, &S, OpFields { seq, lamport, timestamp: Timestamp(ts), deps, payload }).unwrap().into_op();
            let back = Op::<TestPayload>::decode(op.encoded()).unwrap();
            prop_assert!(back.verify(&S).is_ok());
            prop_assert_eq!(back.id(), op.id());
            prop_assert_eq!(back, op);
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            if let Ok(op) = Op::<TestPayload>::decode(&bytes) {
                // Whatever decodes is canonical: it re-encodes to the same bytes.
                prop_assert_eq!(op.encoded(), &bytes[..]);
                let _ = op.verify(&S);
            }
        }

        #[test]
        fn mutated_ops_never_panic_and_report_offsets(idx in any::<usize>(), val in any::<u8>(), cut in any::<usize>()) {
            let op = sample(3);
            let mut bytes = op.encoded().to_vec();
            let i = idx % bytes.len();
            bytes[i] = val;
            bytes.truncate(1 + cut % bytes.len());
            match Op::<TestPayload>::decode(&bytes) {
                Ok(decoded) => prop_assert!(decoded.verify(&S).is_err() || decoded == op),
                Err(e) => prop_assert!(e.offset() <= bytes.len()),
            }
        }
    }
}
