//! Sync wire messages and their versioned binary encoding. The only wire types of the crate
//! besides the op encoding.
//!
//! Every message is `[SYNC_WIRE_VERSION][tag][fields...]`, integers as LEB128 varints, byte
//! strings length-prefixed; counts and lengths are checked against named limits before
//! anything is allocated.
//!
//! A version vector names at most [`MAX_VV_AUTHORS`] authors per message, and one that names
//! that many always fits in [`MAX_MESSAGE_BYTES`]. A sender with more to say sends several
//! [`Message::Have`]s or [`Message::Want`]s (the receiver joins them, so they are independent
//! and may arrive in any order); an [`Message::Ack`] names at most a batch's authors.

use crate::causal::{MAX_VV_AUTHORS, VersionVector};
use crate::codec::{DecodeError, MAX_VARINT_BYTES, Reader, put_bytes, put_varint};
use crate::identity::{OpId, PEER_ID_BYTES, PeerId, SESSION_ID_BYTES, SessionId};
use crate::op::MAX_OP_BYTES;

/// Version byte that opens every sync message.
pub const SYNC_WIRE_VERSION: u8 = 1;
/// Protocol version announced in [`Message::Hello`]; peers with another version disconnect.
/// 3: payloads may be authored in parts (`ShapePayload::Part`, `ShapePayload::Assemble`),
/// which a build speaking 2 cannot decode.
/// 4: signatures are checked by the ZIP 215 rules (alone or in batches), which accept some
/// crafted signatures the strict rules of 3 refuse; the two must not share a session, or a
/// member could make them disagree on which ops exist.
/// 5: [`Message::Forked`] carries proofs of equivocation and [`Message::WantOps`] asks for
/// ops by id, which a build speaking 4 refuses.
/// 6: a [`Message::Have`] names the sender's op at each seq it announces (its tip), so two
/// peers holding different sides of a fork find out, and [`Message::Forked`] carries two ops
/// the receiver inserts.
/// 7: a [`Message::Want`] says how much of each author the sender holds, with the tip there,
/// so the receiver relays from there rather than from what it last heard.
/// 8: a [`Message::Hello`] says what the sender holds ([`HelloHave`]), so both ends may send
/// and ask half a round trip after connecting, without waiting for the have that answers it;
/// [`Message::Ping`] probes a silent remote.
/// 9: a ping that a full have does not answer is answered with a [`Message::Pong`], which a
/// build speaking 8 refuses.
/// 10: ops are signed for their session ([`crate::op::OP_FORMAT_VERSION`] 2), which a build
/// speaking 9 cannot decode.
/// 11: peers compare scene hashes at quiescent points ([`Message::SceneHash`]) and, where they
/// differ at one cut, per-object hashes ([`Message::ObjectHashes`]), which a build speaking 10
/// refuses.
pub const PROTOCOL_VERSION: u64 = 11;
/// The last protocol whose hello ends after `hello_seen` (protocol 8 added the hello's have).
const LAST_PROTOCOL_WITHOUT_HELLO_HAVE: u64 = 7;
/// Most ops in one [`Message::Ops`] batch.
pub const MAX_BATCH_OPS: usize = 64;
/// Largest encoded message in bytes.
pub const MAX_MESSAGE_BYTES: usize = 256 * 1024;
/// Largest ephemeral value in bytes (a pose or a presence record).
pub const MAX_EPHEMERAL_BYTES: usize = 1024;
/// Most objects one [`Message::ObjectHashes`] names (a scene with more sends several, each
/// over its own range of ids).
pub const MAX_OBJECT_HASHES: usize = 1024;
/// Bytes of a scene cut's digest, a scene hash and an object's hash.
pub const DIGEST_BYTES: usize = 32;

/// The largest encoding of a version vector of [`MAX_VV_AUTHORS`] entries (count, then author
/// and seq each).
const MAX_VV_BYTES: usize = MAX_VARINT_BYTES + MAX_VV_AUTHORS * (PEER_ID_BYTES + MAX_VARINT_BYTES);
/// Bytes of one tip ([`Message::Have`]): the first bytes of an op id.
pub const TIP_BYTES: usize = 8;
// A Have of a full version vector with its tips, a Want with its held seqs or an Ack fits in
// a message with room for its header.
const _: () = assert!(
    2 + MAX_VARINT_BYTES + MAX_VV_BYTES + MAX_VARINT_BYTES + MAX_VV_AUTHORS * TIP_BYTES
        <= MAX_MESSAGE_BYTES
);
const _: () = assert!(
    2 + MAX_VV_BYTES + MAX_VARINT_BYTES + MAX_VV_AUTHORS * (MAX_VARINT_BYTES + TIP_BYTES)
        <= MAX_MESSAGE_BYTES
);
// A hello with a whole version vector and its tips fits too.
const _: () = assert!(
    3 + 2 * MAX_VARINT_BYTES
        + SESSION_ID_BYTES
        + PEER_ID_BYTES
        + MAX_VV_BYTES
        + MAX_VV_AUTHORS * TIP_BYTES
        <= MAX_MESSAGE_BYTES
);
// An ack names at most one batch's authors.
const _: () = assert!(MAX_BATCH_OPS <= MAX_VV_AUTHORS);
// Two ops of the largest size offered as a fork fit in a message.
const _: () = assert!(3 + 2 * (MAX_VARINT_BYTES + MAX_OP_BYTES) <= MAX_MESSAGE_BYTES);
// The most object hashes, with their range, cut and rest, fit in a message.
const _: () = assert!(
    2 + 3 * MAX_VARINT_BYTES
        + 2 * DIGEST_BYTES
        + MAX_OBJECT_HASHES * (MAX_VARINT_BYTES + DIGEST_BYTES)
        <= MAX_MESSAGE_BYTES
);

/// The tip of an op id: its first [`TIP_BYTES`] bytes, never 0 (which says "none").
pub fn tip(id: &OpId) -> u64 {
    let mut head = [0; TIP_BYTES];
    head.copy_from_slice(&id.0[..TIP_BYTES]);
    u64::from_le_bytes(head).max(1)
}

/// A hello's version vector: the sender's whole one, each entry with its tip as in a
/// [`Message::Have`].
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct HelloHave {
    /// Every author the sender holds, with the last seq it holds.
    pub vv: VersionVector,
    /// For each entry in order, the tip of the sender's op at that seq, or 0 for none.
    pub tips: Vec<u64>,
}

/// A scene hash at a cut: what a [`Message::SceneHash`] says.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct SceneAt {
    /// The digest of the log's heads ([`crate::sync::scene::SceneCut`]): it names the op set.
    pub cut: [u8; DIGEST_BYTES],
    /// The ops the sender's version vector counts there (for people reading a report).
    pub n_ops: u64,
    /// The hash of the sender's scene folded from that op set.
    pub hash: [u8; DIGEST_BYTES],
}

/// Per-object hashes of the sender's scene at a cut, for the objects whose ids lie in
/// `from..=to`: what a [`Message::ObjectHashes`] says.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct ObjectHashesPart {
    /// The cut ([`SceneAt::cut`]).
    pub cut: [u8; DIGEST_BYTES],
    /// The first object id the part covers.
    pub from: u64,
    /// The last object id the part covers (at least `from`).
    pub to: u64,
    /// The hash of what belongs to no object (the chat).
    pub rest: [u8; DIGEST_BYTES],
    /// Each object in the range the sender's scene holds, in id order, with its hash (at most
    /// [`MAX_OBJECT_HASHES`]).
    pub objects: Vec<(u64, [u8; DIGEST_BYTES])>,
}

/// One sync message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Message {
    /// Opens a connection; resent until the remote's hello arrives.
    Hello {
        /// The sender's [`PROTOCOL_VERSION`].
        protocol_version: u64,
        /// The session both sides must share.
        session_id: SessionId,
        /// The sender's peer id.
        peer: PeerId,
        /// True if the sender has already received the receiver's hello.
        hello_seen: bool,
        /// What the sender held when it sent this hello, for a log of at most
        /// [`MAX_HELLO_HAVE_AUTHORS`](crate::sync::state::MAX_HELLO_HAVE_AUTHORS) authors;
        /// `None` for a larger log (the haves that answer hellos name it) and in hellos of
        /// builds speaking 7 or older.
        have: Option<HelloHave>,
    },
    /// What the sender holds, so the receiver sends only what it lacks: all of it in answer
    /// to a hello, later only the entries that grew since the sender's previous have (the
    /// receiver joins them, so a lost or stale have only costs a redundant send).
    Have {
        /// The entries.
        vv: VersionVector,
        /// For each entry in order, the tip of the sender's op at that seq ([`tip`]), or 0
        /// where it holds none; empty when not said. A receiver
        /// holding another op there sends its own: the two are a fork ([`crate::fork`]).
        tips: Vec<u64>,
    },
    /// A batch of encoded ops, in the sender's linear order.
    Ops {
        /// Sender's batch number, echoed by [`Message::Ack`].
        batch_no: u64,
        /// Encoded ops ([`crate::op::Op::encoded`]), each decoded and checked on its own.
        ops: Vec<Vec<u8>>,
    },
    /// Acknowledges a batch with what the receiver now holds of the batch's authors.
    Ack {
        /// The batch acknowledged.
        batch_no: u64,
        /// The receiver's version-vector entries for the batch's authors after the batch.
        have: VersionVector,
    },
    /// Asks the receiver to relay third peers' ops up to these entries (the sender lacks them
    /// and chose this receiver among those whose haves show them).
    Want {
        /// Up to where each author's ops are wanted.
        vv: VersionVector,
        /// For each entry in order, the seq of the author the sender holds (it holds that
        /// author's ops up to there) and the tip of its op at that seq (0 for none), which the
        /// receiver learns as from a have, tips compared as a have's: after a partition its
        /// picture of the sender may be old, and it would relay from there.
        held: Vec<(u64, u64)>,
    },
    /// A latest-value-wins ephemeral value (pose, presence); never stored.
    Ephemeral {
        /// The stream.
        channel: u32,
        /// Sender's sequence number on this connection; older values are dropped.
        seq: u64,
        /// The value.
        value: Vec<u8>,
    },
    /// Two different ops an author signed with one seq ([`crate::fork`]), which the receiver
    /// inserts like any ops. Sent when the remote holds ops of that author, until it answers
    /// with the same message (`answer` set), which is not answered.
    Forked {
        /// The two encoded ops.
        ops: [Vec<u8>; 2],
        /// True for an answer to the remote's.
        answer: bool,
    },
    /// Asks for ops by id (at most [`MAX_BATCH_OPS`]): dependencies that ops this remote sent
    /// have waited for too long. The receiver sends those it holds in an ops batch.
    WantOps(Vec<OpId>),
    /// Asks a remote that stayed silent while batches to it went unacknowledged whether the
    /// link carries messages again (say a partition healed): answered with a full have, or a
    /// [`Message::Pong`] within a have interval of the last. Sent a few times per base resend
    /// interval while the batches' own resends back off, so a healed link is found within
    /// about a round trip of hearing each other at the cost of a few bytes.
    Ping,
    /// Answers a [`Message::Ping`] that a full have does not (one went out less than a have
    /// interval ago): the link carries messages, so what waits for the remote goes again now.
    Pong,
    /// The sender's scene hash, sent at a quiescent point of the connection (nothing to send,
    /// nothing unacknowledged, both sides holding the same ops) once per change of it: a
    /// receiver at the same cut compares ([`crate::sync::scene`]).
    SceneHash(SceneAt),
    /// Part of the sender's per-object hashes, sent after the two scene hashes differed at one
    /// cut, so that each side finds and refolds the objects whose states differ.
    ObjectHashes(ObjectHashesPart),
}

const TAG_HELLO: u8 = 1;
const TAG_HAVE: u8 = 2;
const TAG_OPS: u8 = 3;
const TAG_ACK: u8 = 4;
const TAG_EPHEMERAL: u8 = 5;
const TAG_WANT: u8 = 6;
const TAG_FORKED: u8 = 7;
const TAG_WANT_OPS: u8 = 8;
const TAG_PING: u8 = 9;
const TAG_PONG: u8 = 10;
const TAG_SCENE_HASH: u8 = 11;
const TAG_OBJECT_HASHES: u8 = 12;

/// The kind of an encoded message, read from its version byte and tag alone (to count traffic
/// without decoding it); `None` for another wire version or a tag no message has.
pub fn kind_of(bytes: &[u8]) -> Option<&'static str> {
    if bytes.first() != Some(&SYNC_WIRE_VERSION) {
        return None;
    }
    Some(match *bytes.get(1)? {
        TAG_HELLO => "hello",
        TAG_HAVE => "have",
        TAG_OPS => "ops",
        TAG_ACK => "ack",
        TAG_EPHEMERAL => "ephemeral",
        TAG_WANT => "want",
        TAG_FORKED => "forked",
        TAG_WANT_OPS => "want_ops",
        TAG_PING => "ping",
        TAG_PONG => "pong",
        TAG_SCENE_HASH => "scene_hash",
        TAG_OBJECT_HASHES => "object_hashes",
        _ => return None,
    })
}

impl Message {
    /// A have without tips.
    pub fn have(vv: VersionVector) -> Self {
        Self::Have {
            vv,
            tips: Vec::new(),
        }
    }

    /// A want that says nothing of what the sender holds.
    pub fn want(vv: VersionVector) -> Self {
        let held = vec![(0, 0); vv.len()];
        Self::Want { vv, held }
    }

    /// The encoded message.
    // tidy:table: one arm per message kind.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = vec![SYNC_WIRE_VERSION];
        match self {
            Self::Hello {
                protocol_version,
                session_id,
                peer,
                hello_seen,
                have,
            } => {
                out.push(TAG_HELLO);
                put_hello(
                    &mut out,
                    *protocol_version,
                    session_id,
                    peer,
                    *hello_seen,
                    have,
                );
            }
            Self::Have { vv, tips } => {
                out.push(TAG_HAVE);
                put_have(&mut out, vv, tips);
            }
            Self::Ops { batch_no, ops } => {
                out.push(TAG_OPS);
                put_varint(&mut out, *batch_no);
                put_varint(&mut out, ops.len() as u64);
                for op in ops {
                    put_bytes(&mut out, op);
                }
            }
            Self::Ack { batch_no, have } => {
                out.push(TAG_ACK);
                put_varint(&mut out, *batch_no);
                put_vv(&mut out, have);
            }
            Self::Want { vv, held } => {
                out.push(TAG_WANT);
                put_vv(&mut out, vv);
                put_varint(&mut out, held.len() as u64);
                for (seq, tip) in held {
                    put_varint(&mut out, *seq);
                    out.extend_from_slice(&tip.to_le_bytes());
                }
            }
            Self::Ephemeral {
                channel,
                seq,
                value,
            } => {
                out.push(TAG_EPHEMERAL);
                put_varint(&mut out, u64::from(*channel));
                put_varint(&mut out, *seq);
                put_bytes(&mut out, value);
            }
            Self::Forked { ops, answer } => {
                out.push(TAG_FORKED);
                for op in ops {
                    put_bytes(&mut out, op);
                }
                out.push(u8::from(*answer));
            }
            Self::Ping => out.push(TAG_PING),
            Self::Pong => out.push(TAG_PONG),
            Self::SceneHash(at) => {
                out.push(TAG_SCENE_HASH);
                out.extend_from_slice(&at.cut);
                put_varint(&mut out, at.n_ops);
                out.extend_from_slice(&at.hash);
            }
            Self::ObjectHashes(part) => {
                out.push(TAG_OBJECT_HASHES);
                put_object_hashes(&mut out, part);
            }
            Self::WantOps(ids) => {
                out.push(TAG_WANT_OPS);
                put_varint(&mut out, ids.len() as u64);
                for id in ids {
                    out.extend_from_slice(&id.0);
                }
            }
        }
        out
    }

    /// Decodes one message from untrusted bytes, never panicking and never allocating past
    /// the named limits.
    // tidy:table: one arm per message tag.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        if bytes.len() > MAX_MESSAGE_BYTES {
            return Err(DecodeError::OverLimit {
                offset: 0,
                what: "message length",
                value: bytes.len() as u64,
                limit: MAX_MESSAGE_BYTES as u64,
            });
        }
        let mut r = Reader::new(bytes);
        let version = r.u8()?;
        if version != SYNC_WIRE_VERSION {
            return Err(DecodeError::UnknownVersion { offset: 0, version });
        }
        let tag_offset = r.offset();
        let message = match r.u8()? {
            TAG_HELLO => read_hello(&mut r)?,
            TAG_HAVE => {
                let (vv, tips) = read_have(&mut r)?;
                Self::Have { vv, tips }
            }
            TAG_WANT => read_want(&mut r)?,
            TAG_OPS => {
                let batch_no = r.varint()?;
                let n_ops = r.bounded("batch op count", MAX_BATCH_OPS as u64)?;
                let mut ops = Vec::with_capacity(n_ops);
                for _ in 0..n_ops {
                    ops.push(r.bytes("op length", MAX_OP_BYTES as u64)?.to_vec());
                }
                Self::Ops { batch_no, ops }
            }
            TAG_ACK => Self::Ack {
                batch_no: r.varint()?,
                have: read_vv(&mut r)?,
            },
            TAG_EPHEMERAL => {
                let channel = r.bounded("channel", u64::from(u32::MAX))? as u32;
                let seq = r.varint()?;
                let value = r
                    .bytes("ephemeral length", MAX_EPHEMERAL_BYTES as u64)?
                    .to_vec();
                Self::Ephemeral {
                    channel,
                    seq,
                    value,
                }
            }
            TAG_FORKED => {
                let a = r.bytes("op length", MAX_OP_BYTES as u64)?.to_vec();
                let b = r.bytes("op length", MAX_OP_BYTES as u64)?.to_vec();
                let answer = r.flag()?;
                Self::Forked {
                    ops: [a, b],
                    answer,
                }
            }
            TAG_WANT_OPS => {
                let n = r.bounded("wanted op count", MAX_BATCH_OPS as u64)?;
                let mut ids = Vec::with_capacity(n);
                for _ in 0..n {
                    ids.push(OpId(r.array()?));
                }
                Self::WantOps(ids)
            }
            TAG_PING => Self::Ping,
            TAG_PONG => Self::Pong,
            TAG_SCENE_HASH => Self::SceneHash(SceneAt {
                cut: r.array()?,
                n_ops: r.varint()?,
                hash: r.array()?,
            }),
            TAG_OBJECT_HASHES => Self::ObjectHashes(read_object_hashes(&mut r)?),
            _ => {
                return Err(DecodeError::Invalid {
                    offset: tag_offset,
                    what: "message tag",
                });
            }
        };
        r.finish()?;
        Ok(message)
    }
}

/// Appends a hello's fields (after its tag).
fn put_hello(
    out: &mut Vec<u8>,
    protocol_version: u64,
    session_id: &SessionId,
    peer: &PeerId,
    hello_seen: bool,
    have: &Option<HelloHave>,
) {
    put_varint(out, protocol_version);
    out.extend_from_slice(session_id);
    out.extend_from_slice(&peer.0);
    out.push(u8::from(hello_seen));
    // A hello of a protocol before hellos named haves ends here (see `read_hello`).
    if protocol_version > LAST_PROTOCOL_WITHOUT_HELLO_HAVE || have.is_some() {
        out.push(u8::from(have.is_some()));
    }
    if let Some(have) = have {
        put_have(out, &have.vv, &have.tips);
    }
}

/// Reads a hello's fields (after its tag).
fn read_hello(r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    let protocol_version = r.varint()?;
    let session_id = r.array()?;
    let peer = PeerId(r.array()?);
    let hello_seen = r.flag()?;
    // A hello of protocol 7 or older ends here; its version is refused later, with
    // a reason, rather than as a malformed message. Later hellos always carry the
    // flag, older ones only to say that a have follows, so every message has one
    // encoding.
    let old = protocol_version <= LAST_PROTOCOL_WITHOUT_HELLO_HAVE;
    let flag_offset = r.offset();
    let has_have = if old && r.remaining() == 0 {
        false
    } else {
        let flag = r.flag()?;
        if old && !flag {
            return Err(DecodeError::Invalid {
                offset: flag_offset,
                what: "an old hello's have flag that names no have",
            });
        }
        flag
    };
    let have = if has_have {
        let (vv, tips) = read_have(r)?;
        Some(HelloHave { vv, tips })
    } else {
        None
    };
    Ok(Message::Hello {
        protocol_version,
        session_id,
        peer,
        hello_seen,
        have,
    })
}

/// Reads a want's fields (after its tag): a version vector, then the sender's held seq and
/// tip for each of its entries.
fn read_want(r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    let vv = read_vv(r)?;
    let offset = r.offset();
    let n = r.bounded("held count", MAX_VV_AUTHORS as u64)?;
    if n != vv.len() {
        return Err(DecodeError::Invalid {
            offset,
            what: "held count differs from the version vector's",
        });
    }
    let held = (0..n)
        .map(|_| Ok((r.varint()?, u64::from_le_bytes(r.array()?))))
        .collect::<Result<_, DecodeError>>()?;
    Ok(Message::Want { vv, held })
}

/// Appends an object-hashes part's fields (after its tag).
fn put_object_hashes(out: &mut Vec<u8>, part: &ObjectHashesPart) {
    out.extend_from_slice(&part.cut);
    put_varint(out, part.from);
    put_varint(out, part.to);
    out.extend_from_slice(&part.rest);
    put_varint(out, part.objects.len() as u64);
    for (object, hash) in &part.objects {
        put_varint(out, *object);
        out.extend_from_slice(hash);
    }
}

/// Reads an object-hashes part's fields (after its tag): a range, then objects inside it in
/// strictly increasing id order.
fn read_object_hashes(r: &mut Reader<'_>) -> Result<ObjectHashesPart, DecodeError> {
    let cut = r.array()?;
    let from = r.varint()?;
    let to_offset = r.offset();
    let to = r.varint()?;
    if to < from {
        return Err(DecodeError::Invalid {
            offset: to_offset,
            what: "object range ends before it starts",
        });
    }
    let rest = r.array()?;
    let n = r.bounded("object hash count", MAX_OBJECT_HASHES as u64)?;
    let mut objects: Vec<(u64, [u8; DIGEST_BYTES])> = Vec::with_capacity(n);
    for _ in 0..n {
        let offset = r.offset();
        let object = r.varint()?;
        let after_last = objects.last().is_none_or(|(last, _)| object > *last);
        if !after_last || !(from..=to).contains(&object) {
            return Err(DecodeError::Invalid {
                offset,
                what: "object outside the range or out of order",
            });
        }
        objects.push((object, r.array()?));
    }
    Ok(ObjectHashesPart {
        cut,
        from,
        to,
        rest,
        objects,
    })
}

fn put_vv(out: &mut Vec<u8>, vv: &VersionVector) {
    put_varint(out, vv.len() as u64);
    for (author, seq) in vv.iter() {
        out.extend_from_slice(&author.0);
        put_varint(out, *seq);
    }
}

/// A version vector and its tips (none, or one per entry), as a have and a hello carry them.
fn put_have(out: &mut Vec<u8>, vv: &VersionVector, tips: &[u64]) {
    put_vv(out, vv);
    put_varint(out, tips.len() as u64);
    for tip in tips {
        out.extend_from_slice(&tip.to_le_bytes());
    }
}

fn read_have(r: &mut Reader<'_>) -> Result<(VersionVector, Vec<u64>), DecodeError> {
    let vv = read_vv(r)?;
    let offset = r.offset();
    let n = r.bounded("tip count", MAX_VV_AUTHORS as u64)?;
    if n != 0 && n != vv.len() {
        return Err(DecodeError::Invalid {
            offset,
            what: "tip count differs from the version vector's",
        });
    }
    let tips = (0..n)
        .map(|_| r.array().map(u64::from_le_bytes))
        .collect::<Result<_, _>>()?;
    Ok((vv, tips))
}

fn read_vv(r: &mut Reader<'_>) -> Result<VersionVector, DecodeError> {
    let n = r.bounded("version vector length", MAX_VV_AUTHORS as u64)?;
    let mut vv = VersionVector::new();
    let mut last: Option<PeerId> = None;
    for _ in 0..n {
        let offset = r.offset();
        let author = PeerId(r.array()?);
        if last.is_some_and(|l| l >= author) {
            return Err(DecodeError::Invalid {
                offset,
                what: "unsorted version vector",
            });
        }
        let seq_offset = r.offset();
        let seq = r.varint()?;
        if seq == 0 {
            return Err(DecodeError::Invalid {
                offset: seq_offset,
                what: "zero seq",
            });
        }
        vv.raise(author, seq);
        last = Some(author);
    }
    Ok(vv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Found by the `decode` fuzz target: a hello of a newer protocol without its have flag
    /// decoded, and encoded one byte longer.
    #[test]
    fn every_hello_that_decodes_has_one_encoding() {
        let hex = "01017a000001030801030800ffffffffffffff00ffffffffff0000000000000000000000\
                   00000000a5a5a5a50000003d00000000";
        let bytes: Vec<u8> = (0..hex.len() / 2)
            .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
            .collect();
        assert!(
            Message::decode(&bytes).is_err(),
            "protocol 122 without the flag"
        );
        let hello = |protocol_version, have| Message::Hello {
            protocol_version,
            session_id: [1; 16],
            peer: PeerId([2; 32]),
            hello_seen: true,
            have,
        };
        let some_have = || {
            let mut vv = VersionVector::new();
            vv.raise(PeerId([3; 32]), 4);
            Some(HelloHave {
                tips: vec![5; vv.len()],
                vv,
            })
        };
        for message in [
            hello(7, None),
            hello(7, some_have()),
            hello(9, None),
            hello(9, some_have()),
        ] {
            let encoded = message.encode();
            let decoded = Message::decode(&encoded).unwrap();
            assert_eq!(decoded.encode(), encoded);
        }
        // A protocol 7 hello with a flag that names no have has a shorter form: refused.
        let mut old = hello(7, None).encode();
        old.push(0);
        assert!(Message::decode(&old).is_err());
    }

    fn message_strategy() -> impl Strategy<Value = Message> {
        let vv = proptest::collection::btree_map(any::<[u8; 32]>(), 1u64.., 0..4).prop_map(|m| {
            let mut vv = VersionVector::new();
            for (a, s) in m {
                vv.raise(PeerId(a), s);
            }
            vv
        });
        prop_oneof![
            (
                any::<u64>(),
                any::<[u8; 16]>(),
                any::<[u8; 32]>(),
                any::<bool>(),
                proptest::option::of((vv.clone(), any::<u64>())),
            )
                .prop_map(|(protocol_version, session_id, p, hello_seen, have)| {
                    Message::Hello {
                        protocol_version,
                        session_id,
                        peer: PeerId(p),
                        hello_seen,
                        have: have.map(|(vv, tip)| HelloHave {
                            tips: vec![tip.max(1); vv.len()],
                            vv,
                        }),
                    }
                }),
            (vv.clone(), any::<u64>()).prop_map(|(vv, tip)| {
                let tips = if tip % 2 == 0 {
                    Vec::new()
                } else {
                    vec![tip; vv.len()]
                };
                Message::Have { vv, tips }
            }),
            (vv.clone(), any::<u64>()).prop_map(|(vv, seq)| {
                let held = vec![(seq, seq.rotate_left(7)); vv.len()];
                Message::Want { vv, held }
            }),
            (
                any::<u64>(),
                proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 0..5)
            )
                .prop_map(|(batch_no, ops)| Message::Ops { batch_no, ops }),
            (
                proptest::collection::vec(any::<u8>(), 0..40),
                proptest::collection::vec(any::<u8>(), 0..40),
                any::<bool>()
            )
                .prop_map(|(a, b, answer)| Message::Forked {
                    ops: [a, b],
                    answer
                }),
            proptest::collection::vec(any::<[u8; 32]>(), 0..5)
                .prop_map(|ids| Message::WantOps(ids.into_iter().map(OpId).collect())),
            Just(Message::Ping),
            Just(Message::Pong),
            (any::<[u8; 32]>(), any::<u64>(), any::<[u8; 32]>()).prop_map(|(cut, n_ops, hash)| {
                Message::SceneHash(SceneAt { cut, n_ops, hash })
            }),
            (
                any::<[u8; 32]>(),
                any::<u64>(),
                proptest::collection::btree_map(any::<u64>(), any::<[u8; 32]>(), 0..5)
            )
                .prop_map(|(cut, from, hashes)| {
                    let objects: Vec<_> = hashes.into_iter().filter(|(o, _)| *o >= from).collect();
                    let to = objects.last().map_or(from, |(o, _)| *o);
                    Message::ObjectHashes(ObjectHashesPart {
                        cut,
                        from,
                        to,
                        rest: cut,
                        objects,
                    })
                }),
            (any::<u64>(), vv).prop_map(|(batch_no, have)| Message::Ack { batch_no, have }),
            (
                any::<u32>(),
                any::<u64>(),
                proptest::collection::vec(any::<u8>(), 0..40)
            )
                .prop_map(|(channel, seq, value)| Message::Ephemeral {
                    channel,
                    seq,
                    value
                }),
        ]
    }

    #[test]
    fn hostile_counts_are_refused_before_allocating() {
        let mut bytes = vec![SYNC_WIRE_VERSION, TAG_OPS, 0];
        put_varint(&mut bytes, MAX_BATCH_OPS as u64 + 1);
        let err = Message::decode(&bytes).unwrap_err();
        assert!(
            matches!(err, DecodeError::OverLimit { offset: 3, .. }),
            "{err:?}"
        );
        let mut bytes = vec![SYNC_WIRE_VERSION, TAG_HAVE];
        put_varint(&mut bytes, u64::MAX);
        assert!(matches!(
            Message::decode(&bytes),
            Err(DecodeError::OverLimit { offset: 2, .. })
        ));
        assert_eq!(
            Message::decode(&[7, TAG_HAVE, 0]),
            Err(DecodeError::UnknownVersion {
                offset: 0,
                version: 7
            })
        );
        assert!(Message::decode(&vec![SYNC_WIRE_VERSION; MAX_MESSAGE_BYTES + 1]).is_err());
    }

    #[test]
    fn the_largest_version_vector_fits_in_a_message_and_one_more_author_is_refused() {
        let mut vv = VersionVector::new();
        for i in 0..=MAX_VV_AUTHORS as u32 {
            let mut author = [0xff; 32];
            author[..4].copy_from_slice(&i.to_be_bytes());
            vv.raise(PeerId(author), u64::MAX);
        }
        let parts = vv.split(MAX_VV_AUTHORS);
        assert_eq!(parts.len(), 2);
        let (full, batch_no) = (&parts[0], u64::MAX);
        let tips = vec![u64::MAX; full.len()];
        for m in [
            Message::Have {
                vv: full.clone(),
                tips,
            },
            Message::Want {
                vv: full.clone(),
                held: vec![(u64::MAX, u64::MAX); full.len()],
            },
            Message::Ack {
                batch_no,
                have: full.clone(),
            },
        ] {
            let bytes = m.encode();
            assert!(bytes.len() <= MAX_MESSAGE_BYTES, "{} bytes", bytes.len());
            assert_eq!(Message::decode(&bytes), Ok(m));
        }
        assert!(matches!(
            Message::decode(&Message::have(vv).encode()),
            Err(DecodeError::OverLimit {
                what: "version vector length",
                ..
            })
        ));
    }

    /// A part of `n` object hashes over `from..=to`, ids from `first` up.
    fn object_hashes(from: u64, to: u64, first: u64, n: usize) -> Message {
        Message::ObjectHashes(ObjectHashesPart {
            cut: [1; 32],
            from,
            to,
            rest: [2; 32],
            objects: (0..n as u64).map(|i| (first + i, [3; 32])).collect(),
        })
    }

    #[test]
    fn the_most_object_hashes_fit_in_a_message_and_bad_parts_are_refused() {
        let full = object_hashes(
            u64::MAX - MAX_OBJECT_HASHES as u64,
            u64::MAX,
            u64::MAX - MAX_OBJECT_HASHES as u64 + 1,
            MAX_OBJECT_HASHES,
        );
        let bytes = full.encode();
        assert!(bytes.len() <= MAX_MESSAGE_BYTES, "{} bytes", bytes.len());
        assert_eq!(Message::decode(&bytes), Ok(full));
        let too_many = object_hashes(0, u64::MAX, 0, MAX_OBJECT_HASHES + 1);
        assert!(matches!(
            Message::decode(&too_many.encode()),
            Err(DecodeError::OverLimit {
                what: "object hash count",
                ..
            })
        ));
        // A range that ends before it starts, an object outside the range, and objects out of
        // order or repeated are refused, so every part that decodes has one meaning.
        for bad in [
            object_hashes(5, 4, 5, 0),
            object_hashes(5, 9, 3, 1),
            object_hashes(5, 9, 9, 2),
        ] {
            assert!(Message::decode(&bad.encode()).is_err(), "{bad:?}");
        }
        let Message::ObjectHashes(mut part) = object_hashes(0, 9, 1, 2) else {
            unreachable!()
        };
        part.objects.swap(0, 1);
        assert!(Message::decode(&Message::ObjectHashes(part.clone()).encode()).is_err());
        part.objects[1].0 = part.objects[0].0;
        assert!(Message::decode(&Message::ObjectHashes(part).encode()).is_err());
        // Cut short anywhere, a scene hash or a part is refused, not read past its end.
        let scene = Message::SceneHash(SceneAt {
            cut: [4; 32],
            n_ops: 300,
            hash: [5; 32],
        })
        .encode();
        let part = object_hashes(0, 99, 7, 3).encode();
        for bytes in [scene, part] {
            for len in 0..bytes.len() {
                assert!(Message::decode(&bytes[..len]).is_err(), "{len} bytes");
            }
        }
    }

    #[test]
    fn the_scene_messages_decode_on_a_small_stack() {
        let largest = object_hashes(0, u64::MAX, 0, MAX_OBJECT_HASHES).encode();
        let decoded = testkit::stack::on_small_stack(|| {
            let mut junk = largest.clone();
            junk[40] ^= 0xff;
            let _ = Message::decode(&junk);
            Message::decode(&largest)
        });
        assert_eq!(decoded.map(|m| m.encode()), Ok(largest));
    }

    #[test]
    fn bytes_without_a_known_tag_have_no_kind() {
        assert_eq!(kind_of(&[]), None);
        assert_eq!(kind_of(&[SYNC_WIRE_VERSION]), None);
        assert_eq!(kind_of(&[SYNC_WIRE_VERSION, 0]), None);
        assert_eq!(kind_of(&[SYNC_WIRE_VERSION, 200]), None);
        assert_eq!(
            kind_of(&[SYNC_WIRE_VERSION.wrapping_add(1), TAG_PING]),
            None
        );
    }

    proptest! {
        #![proptest_config(crate::test_config(128))]
        #[test]
        fn round_trips(m in message_strategy()) {
            prop_assert_eq!(Message::decode(&m.encode()), Ok(m));
        }

        #[test]
        fn every_message_is_counted_under_its_kind(m in message_strategy()) {
            let kind = match &m {
                Message::Hello { .. } => "hello",
                Message::Have { .. } => "have",
                Message::Ops { .. } => "ops",
                Message::Ack { .. } => "ack",
                Message::Ephemeral { .. } => "ephemeral",
                Message::Want { .. } => "want",
                Message::Forked { .. } => "forked",
                Message::WantOps(_) => "want_ops",
                Message::Ping => "ping",
                Message::Pong => "pong",
                Message::SceneHash(_) => "scene_hash",
                Message::ObjectHashes(_) => "object_hashes",
            };
            prop_assert_eq!(kind_of(&m.encode()), Some(kind));
        }

        #[test]
        fn arbitrary_bytes_never_panic(mut bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            if !bytes.is_empty() { bytes[0] = SYNC_WIRE_VERSION; }
            if let Ok(m) = Message::decode(&bytes) {
                prop_assert_eq!(m.encode(), bytes);
            }
        }
    }
}
