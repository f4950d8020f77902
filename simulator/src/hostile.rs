//! The hostile peer: connected to every honest peer, it never runs the protocol honestly.
//!
//! It captures what honest peers send it and sends back random garbage, messages over
//! `MAX_MESSAGE_BYTES`, verbatim replays (another peer's hello or op batches) and bit-flipped
//! or truncated replays. With [`crate::config::Faults::forgery`] it also speaks the protocol:
//! a hello under its own id followed by
//!
//! - forged ops: well-formed, signed by its key, with the author field set to an honest peer's
//!   id, so the signature does not match the claimed author (every honest peer must refuse
//!   them: they must never enter a log);
//! - ops of its own, well-formed and signed by its own key, with Lamport times it picks low
//!   (a member with a stale clock) and lease fights on the hot object. The hostile peer knows
//!   the invite, so admission lets it in: these are a member's ops, accepted and replicated
//!   like any other, and the checkers require every honest peer to agree on them (at most
//!   [`MAX_HOSTILE_OPS`], all resent every time, so none waits on a lost predecessor). With a
//!   byzantine core, which authors under the member's connection key, these are signed with a
//!   second key of the member's (in a session that binds its authors, one nobody admitted:
//!   refused by every peer).
//!
//! With [`crate::config::Faults::flood`] it sends a burst of [`FLOOD_MESSAGES`] at one
//! instant to one peer, far over the per-connection rate limit, which must hold.

use replication::op::OpFields;
use replication::payload::LeaseAction;
use replication::shape::ShapePayload;
use replication::sync::message::{MAX_MESSAGE_BYTES, Message, PROTOCOL_VERSION};
use replication::sync::state::MAX_MESSAGE_BURST;
use replication::{Keypair, Op, OpId, PeerId, Timestamp};

use crate::byzantine::Byzantine;
use crate::honest::Honest;
use crate::report::Stats;
use crate::rng::SimRng;
use crate::session::SESSION_ID;
use crate::workload::{HOT_OBJECT, User};

/// Most messages the hostile peer keeps for replays.
pub const MAX_CAPTURED_MESSAGES: usize = 256;
/// Most ops the hostile peer authors under its own key.
pub const MAX_HOSTILE_OPS: usize = 32;
/// Messages in one flood: three times the burst the rate limit allows.
pub const FLOOD_MESSAGES: usize = 3 * MAX_MESSAGE_BURST as usize;
/// The workload index the hostile's user acts as (its object ids do not clash).
const HOSTILE_USER_IDX: usize = 62;

/// The hostile peer's state.
pub(crate) struct Hostile {
    key: Keypair,
    /// The key of its own ops: its connection key, or with a byzantine core (which authors
    /// under the connection key) a second key of the member's, so that the two never sign
    /// one seq twice ([`Hostile::own_ops_under`]).
    own_key: Keypair,
    captured: Vec<Vec<u8>>,
    /// Its own ops, encoded, in seq order.
    own: Vec<Vec<u8>>,
    pub(crate) own_ids: Vec<OpId>,
    own_lamport: u64,
    user: User,
    next_batch_no: u64,
    /// Ids of the forged ops it sent.
    pub(crate) forged: Vec<OpId>,
    /// Its core and crafted attacks, with [`crate::config::Faults::byzantine`].
    pub(crate) byzantine: Option<Byzantine>,
}

impl Hostile {
    pub(crate) fn new(key: Keypair) -> Hostile {
        Hostile {
            user: User::new(key.peer_id()),
            own_key: Keypair::from_seed(key.seed()),
            key,
            captured: Vec::new(),
            own: Vec::new(),
            own_ids: Vec::new(),
            own_lamport: 0,
            next_batch_no: 1,
            forged: Vec::new(),
            byzantine: None,
        }
    }

    /// Its peer id.
    pub(crate) fn peer_id(&self) -> PeerId {
        self.key.peer_id()
    }

    /// Signs its own ops with `key` from now on (before it authors any).
    pub(crate) fn own_ops_under(&mut self, key: Keypair) {
        assert!(
            self.own.is_empty(),
            "the own ops' key is chosen before the first"
        );
        self.user = User::new(key.peer_id());
        self.own_key = key;
    }

    /// A fresh batch number for a message of its own.
    pub(crate) fn next_batch_no(&mut self) -> u64 {
        self.next_batch_no += 1;
        self.next_batch_no
    }

    /// Keeps a message an honest peer sent it (a random one is replaced when full).
    pub(crate) fn capture(&mut self, bytes: Vec<u8>, rng: &mut SimRng) {
        if self.captured.len() < MAX_CAPTURED_MESSAGES {
            self.captured.push(bytes);
        } else {
            let slot = rng.index(MAX_CAPTURED_MESSAGES);
            self.captured[slot] = bytes;
        }
    }

    fn hello(&self) -> Vec<u8> {
        Message::Hello {
            protocol_version: PROTOCOL_VERSION,
            session_id: SESSION_ID,
            peer: self.key.peer_id(),
            hello_seen: true,
            have: None,
        }
        .encode()
    }

    fn batch(&mut self, ops: Vec<Vec<u8>>) -> Vec<u8> {
        self.next_batch_no += 1;
        Message::Ops {
            batch_no: self.next_batch_no,
            ops,
        }
        .encode()
    }

    /// An op signed by its key whose author field names `victim` instead.
    fn forge(&mut self, rng: &mut SimRng, victim: PeerId, now: u64) -> Option<Vec<u8>> {
        let fields = OpFields {
            seq: 1 + rng.below(1000),
            lamport: 1 + rng.below(1000),
            timestamp: Timestamp(now),
            deps: Vec::new(),
            payload: ShapePayload::Chat("forged".into()),
        };
        let op = Op::sign(&self.key, &SESSION_ID, fields).ok()?;
        let mut bytes = op.encoded().to_vec();
        bytes.get_mut(1..33)?.copy_from_slice(&victim.0);
        let forged = Op::<ShapePayload>::decode(&bytes).ok()?;
        self.forged.push(forged.id());
        Some(bytes)
    }

    /// Authors its next own op (a member with a stale Lamport clock); false when it is done.
    fn author(&mut self, rng: &mut SimRng, now: u64) -> bool {
        if self.own.len() >= MAX_HOSTILE_OPS {
            return false;
        }
        let payload = if rng.chance(500) {
            ShapePayload::Lease(LeaseAction::Acquire {
                object: HOT_OBJECT,
                strong: rng.chance(500),
                ttl_micros: 1 + rng.below(5_000_000),
            })
        } else {
            match self.user.next(rng, HOSTILE_USER_IDX, &[HOT_OBJECT]) {
                Some(p) => p,
                None => return false,
            }
        };
        self.own_lamport += 1 + rng.below(50);
        let fields = OpFields {
            seq: self.own.len() as u64 + 1,
            lamport: self.own_lamport,
            timestamp: Timestamp(now),
            deps: Vec::new(),
            payload: payload.clone(),
        };
        let Ok(op) = Op::sign(&self.own_key, &SESSION_ID, fields) else {
            return false;
        };
        self.user.authored(&payload, op.id());
        self.own_ids.push(op.id());
        self.own.push(op.encoded().to_vec());
        true
    }

    /// The messages of trick `kind` (`None` if it has nothing for that trick yet), to one of
    /// the `honest` peers; forged and own ops it makes are counted in `stats`.
    pub(crate) fn messages(
        &mut self,
        kind: u64,
        rng: &mut SimRng,
        honest: &[Honest],
        now: u64,
        stats: &mut Stats,
    ) -> Option<Vec<Vec<u8>>> {
        let n_captured = self.captured.len();
        let captured = |rng: &mut SimRng, hostile: &Hostile| {
            (n_captured > 0).then(|| hostile.captured[rng.index(n_captured)].clone())
        };
        Some(match kind {
            0 => return None,
            1 => {
                let mut b = vec![1u8; MAX_MESSAGE_BYTES + 1 + rng.index(1024)];
                rng.fill(&mut b[1..64]);
                vec![b]
            }
            2 => vec![captured(rng, self)?],
            3 => {
                let mut b = captured(rng, self)?;
                let i = rng.index(b.len());
                if let Some(x) = b.get_mut(i) {
                    *x ^= 1 << rng.below(8);
                }
                vec![b]
            }
            4 => {
                let mut b = captured(rng, self)?;
                b.truncate(rng.index(b.len()));
                vec![b]
            }
            5 => {
                let victim = honest[rng.index(honest.len())].peer.peer_id();
                let op = self.forge(rng, victim, now)?;
                stats.n_forged_ops += 1;
                vec![self.hello(), self.batch(vec![op])]
            }
            _ => {
                if self.author(rng, now) {
                    stats.n_hostile_ops += 1;
                }
                let ops = self.own.clone();
                vec![self.hello(), self.batch(ops)]
            }
        })
    }
}

/// Random bytes, 1 to 512 of them.
pub(crate) fn garbage(rng: &mut SimRng) -> Vec<u8> {
    let mut b = vec![0u8; 1 + rng.index(512)];
    rng.fill(&mut b);
    b
}
