//! The byzantine member ([`crate::config::Faults::byzantine`]): the hostile peer holds the
//! invite and runs the real core ([`Peer`]) on its connections, so it learns the session's ops
//! like any member, and uses what it learnt to craft ops signed with its own keys through the
//! public API ([`Op::sign`] with [`OpFields`] it fills in itself) and messages the core would
//! never send:
//!
//! - backdated ops: fresh keys at Lamport 1 stamped at time 0 or [`BACKDATE_MICROS`] ago,
//!   with no dependencies (deletes, edits, chat; with `lease_attacks` strong acquires with
//!   `ttl u64::MAX`), which sort before everything honest;
//! - far-future ops (stamped `u64::MAX - 1`, or a little past the receivers' skew bound) and
//!   far-past ops (stamped 0 after recent dependencies: every peer must refuse those);
//! - Sybil bursts: up to [`SYBIL_BURST`] fresh keys in one batch, at most [`MAX_SYBIL_KEYS`]
//!   in a run;
//! - giant version vectors: a hello, then two haves and a want of
//!   [`MAX_VV_AUTHORS`] made-up authors each;
//! - oversized batches: [`MAX_BATCH_OPS`] + 1 ops in one message;
//! - cost bombs within the limits: a loop that compiles to a large graph, a formula of about
//!   16 KiB, a stroke with as many mirrored poses as a payload holds;
//! - with `lease_attacks`, lease hoarding: strong acquires with `ttl u64::MAX` from a chain
//!   that sees everything (so honest ops authored after them are refused by design, and those
//!   authored concurrently must not be);
//! - id theft: a backdated `Create` (fresh key, Lamport 1) of the object id an honest peer's
//!   user will take next, with or without a counter, named [`STOLEN_NAME`]: no honest scene
//!   may ever hold an object of that name;
//! - refold floods: a fresh key's chain of [`REFOLD_FLOOD`] backdated edits of one object
//!   (Lamport 1 up, no other dependencies), each in a message of its own, so each would make
//!   the receiver refold its whole order; honest peers run with a budget scaled to the
//!   simulator's logs ([`crate::sim::SMALL_REFOLD_BUDGET`]), so they hold and batch them;
//! - with `forks`, equivocation: two ops of one fresh key with sequence number 1, sent to two
//!   different peers;
//! - with `expel`, forged expels: a fresh key's expel of an honest peer, showing the founder's
//!   nonce or a made-up one (neither may count: only the founder's key matches the invite);
//! - hello floods: [`HELLO_FLOOD`] hellos at once (a few answered with full haves, then one a
//!   second; those over the allowance counted);
//! - wrong-id hellos: a hello naming an honest peer's id on the member's own connection, which
//!   the transport admitted under the member's key, so the receiver closes it (the member
//!   then dials again, [`REDIAL_MICROS`] later);
//! - byte floods: [`BYTE_FLOOD_BATCHES`] full batches of fresh keys' large chat ops at once,
//!   over the receiver's quota of op bytes ([`SMALL_OP_BYTE_QUOTA`], scaled to the
//!   simulator's logs), which drops the rest unacknowledged; each chain depends on an op
//!   nobody holds, so what the receiver takes waits in its pending buffer until it expires
//!   (held, never relayed: the flood costs honest links nothing).
//! - Sybil keys it admits itself: its core authors an admission of a fresh key with a grant of
//!   [`SYBIL_GRANT_BYTES`] (in a session that binds its authors, out of its own budget), and the
//!   key sends two chats of about 2 KiB naming it, the second past the grant: every peer must
//!   take the first and refuse the second alike;
//! - a fresh key's admission of itself, with the founder's nonce or a made-up one (in a session
//!   that binds its authors, refused everywhere: only the founder's key proves the founder);
//! - a cap fill: its core authors chats of about 2 KiB until its own budget is spent;
//! - an op signed for another session (its signature covers that session's id): every peer
//!   must refuse it;
//! - with `lease_attacks`, strong acquires of the ids the target's user will create next, and
//!   of every object at once: the first bind nobody (those objects do not exist yet), and of
//!   the second at most [`replication::lease::MAX_LIVE_LEASES_PER_AUTHOR`] count.
//!
//! In a session that binds its authors (even seeds with `expel`, see
//! [`crate::session::SESSION_CAP_BYTES`]), every fresh key above whose first op names no admission
//! is refused by every peer.

use model::object::{Axis, Edit, EditOp, Field, Formula, Geometry, ObjectData, Pose, ToolShape};
use replication::causal::MAX_VV_AUTHORS;
use replication::membership::{Admission, Membership};
use replication::op::{MAX_DEPS, OpFields};
use replication::payload::LeaseAction;
use replication::shape::{IdSource, ShapePayload};
use replication::sync::message::{MAX_BATCH_OPS, Message};
use replication::sync::state::{MAX_HELLO_BURST, OpByteQuota};
use replication::time::MAX_CLOCK_SKEW_MICROS;
use replication::{ConnId, Keypair, Op, OpId, Peer, PeerId, Timestamp, VersionVector};

use crate::config::Faults;
use crate::honest::{MAX_DRAIN, guarded_call};
use crate::rng::SimRng;
use crate::session::{FOUNDER_NONCE, SESSION_ID};

/// Most fresh keys the byzantine member makes in one run.
pub const MAX_SYBIL_KEYS: usize = 512;
/// Fresh keys in one Sybil burst (one batch).
pub const SYBIL_BURST: usize = 32;
/// Most cost bombs in one run.
pub const MAX_COST_BOMBS: usize = 12;
/// Backdated ops in one refold flood, each sent alone.
pub const REFOLD_FLOOD: u64 = 24;
/// How far back a backdated op is stamped when not at time 0.
pub const BACKDATE_MICROS: u64 = 10 * 60 * 1_000_000;
/// The name of the objects id theft creates.
pub const STOLEN_NAME: &str = "stolen id";
/// Hellos in one hello flood.
pub const HELLO_FLOOD: usize = 4 * MAX_HELLO_BURST as usize;
/// Full batches in one byte flood, each of a fresh key's chain of large chat ops.
pub const BYTE_FLOOD_BATCHES: u64 = 12;
/// Bytes of text in each op of a byte flood (about 1 KiB per op, 64 KiB per batch).
pub const BYTE_FLOOD_TEXT_BYTES: usize = 900;
/// Most byte floods in one run.
pub const MAX_BYTE_FLOODS: usize = 3;
/// How long after a receiver closed its connection (not for an expel) the member dials again.
pub const REDIAL_MICROS: u64 = 100_000;
/// The quota of new op bytes per connection where a byzantine member runs, scaled like the
/// refold budget to the simulator's logs of hundreds of ops: a catch-up of a whole run's
/// honest ops and cost bombs fits in the burst, a byte flood does not.
pub const SMALL_OP_BYTE_QUOTA: OpByteQuota = OpByteQuota {
    bytes_per_sec: 128 * 1024,
    burst_bytes: 512 * 1024,
};
/// What the byzantine member grants each Sybil key it admits: more than one of its 2 KiB
/// chats, less than two.
pub const SYBIL_GRANT_BYTES: u64 = 4 * 1024;
/// Chats of about 2 KiB one cap fill authors at most.
pub const CAP_FILL_OPS: usize = 16;
/// The session id the member signs an op for that it sends into this one.
const OTHER_SESSION_ID: replication::identity::SessionId = [0xee; 16];
/// Object ids the byzantine member creates (above every honest user's).
const BOMB_OBJECT_BASE: u64 = 64 << 32;
/// The compile bomb: a short loop, unrolled as far as an object's formula may
/// (`fdsl::limits::formula_node_budget`); the trip count is searched, so it stays at the
/// limit whatever the budget.
fn compile_bomb(trips: usize) -> String {
    format!(
        "s = x; for (i = 0; i < {trips}; i = i + 1) {{ s = sin(s + i*y) * cos(s - i*z) + s; }} s"
    )
}

/// Most loop trips the compile bomb tries.
const MAX_BOMB_TRIPS: usize = fdsl::limits::MAX_LOOP_TRIPS;

/// The compile bomb with the most trips that still compiles (`None` if not even one does).
fn largest_compile_bomb() -> Option<String> {
    // What a receiver checks: the payload's validation (an object's formula budget).
    let compiles = |trips: usize| {
        cost_bomb(0, BOMB_OBJECT_BASE, &compile_bomb(trips)).is_some_and(|p| p.validate().is_ok())
    };
    if !compiles(1) {
        return None;
    }
    let (mut lo, mut hi) = (1, MAX_BOMB_TRIPS);
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if compiles(mid) {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    Some(compile_bomb(lo))
}

/// Poses in a stroke bomb (mirrored), about what one payload holds.
const STROKE_BOMB_POSES: usize = 220;

/// The attacks, as the report counts them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Attack {
    Backdated,
    BackdatedLease,
    Hoard,
    FarFuture,
    FarPast,
    Sybil,
    GiantVersionVectors,
    OversizedBatch,
    CostBomb,
    TakeId,
    RefoldFlood,
    Fork,
    ForgeExpel,
    HelloFlood,
    WrongIdHello,
    ByteFlood,
    AdmittedSybil,
    SelfAdmitted,
    CapFill,
    LeasePredicted,
    LeaseAll,
    OtherSession,
}

impl Attack {
    /// The name the report counts it under.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Attack::Backdated => "backdated",
            Attack::BackdatedLease => "backdated-lease",
            Attack::Hoard => "hoard",
            Attack::FarFuture => "far-future",
            Attack::FarPast => "far-past",
            Attack::Sybil => "sybil",
            Attack::GiantVersionVectors => "giant-vv",
            Attack::OversizedBatch => "oversized-batch",
            Attack::CostBomb => "cost-bomb",
            Attack::TakeId => "take-id",
            Attack::RefoldFlood => "refold-flood",
            Attack::Fork => "fork",
            Attack::ForgeExpel => "forge-expel",
            Attack::HelloFlood => "hello-flood",
            Attack::WrongIdHello => "wrong-id-hello",
            Attack::ByteFlood => "byte-flood",
            Attack::AdmittedSybil => "admitted-sybil",
            Attack::SelfAdmitted => "self-admitted",
            Attack::CapFill => "cap-fill",
            Attack::LeasePredicted => "lease-predicted",
            Attack::LeaseAll => "lease-all",
            Attack::OtherSession => "other-session",
        }
    }
}

/// A key with a chain of ops (the hoarder's), so each op extends the previous one.
struct Chain {
    key: Keypair,
    next_seq: u64,
    lamport: u64,
    timestamp: u64,
}

/// The byzantine member's state.
pub(crate) struct Byzantine {
    /// Its real core: connected to every honest peer it reaches, it learns the session.
    pub(crate) core: Peer<ShapePayload>,
    pub(crate) panicked: Option<String>,
    pub(crate) wake_at: Option<u64>,
    keys: SimRng,
    n_sybil_keys: usize,
    n_bombs: usize,
    n_byte_floods: usize,
    hoarder: Chain,
    /// The compile bomb's text, searched once.
    bomb: Option<Option<String>>,
    /// Ops every honest peer must refuse (stamped before their causal past, or signed for
    /// another session).
    pub(crate) must_refuse: Vec<OpId>,
    /// Pairs of ops that equivocate (same key, same sequence number).
    pub(crate) forks: Vec<(OpId, OpId)>,
    /// Attacks chosen so far, and the menu entry the first one took (see `byzantine_send`).
    n_turns: usize,
    first_turn: usize,
}

/// What the core knows now: its heads (at most [`MAX_DEPS`]) and their highest Lamport time
/// and timestamp.
struct Frontier {
    heads: Vec<OpId>,
    lamport: u64,
    timestamp: u64,
}

impl Byzantine {
    /// The member with key `key`, its fresh keys drawn from `keys`, its core over `log` (of
    /// the run's session: its founder and binding named).
    pub(crate) fn new(
        key: Keypair,
        keys: SimRng,
        log: replication::Log<ShapePayload>,
    ) -> Byzantine {
        let mut keys = keys;
        let hoarder = Chain {
            key: fresh_key(&mut keys),
            next_seq: 1,
            lamport: 0,
            timestamp: 0,
        };
        Byzantine {
            core: Peer::new(key, SESSION_ID, log),
            panicked: None,
            wake_at: None,
            keys,
            n_sybil_keys: 0,
            n_bombs: 0,
            n_byte_floods: 0,
            hoarder,
            bomb: None,
            must_refuse: Vec::new(),
            forks: Vec::new(),
            n_turns: 0,
            first_turn: 0,
        }
    }

    /// The key of its lease hoarder's chain.
    pub(crate) fn hoarder_id(&self) -> PeerId {
        self.hoarder.key.peer_id()
    }

    fn frontier(&self) -> Frontier {
        let log = self.core.log();
        let heads: Vec<OpId> = log.heads().copied().take(MAX_DEPS).collect();
        let ops = || heads.iter().filter_map(|id| log.get(id));
        Frontier {
            lamport: ops().map(|op| op.lamport()).max().unwrap_or(0),
            timestamp: ops().map(|op| op.timestamp().0).max().unwrap_or(0),
            heads: heads.clone(),
        }
    }

    /// Authors `payload` through its core (sent to its connections by the core's sync).
    fn author(&mut self, now: u64, payload: ShapePayload) -> Option<OpId> {
        let authored = guarded_call(&mut self.panicked, &mut self.core, |p| {
            p.author(Timestamp(now), payload)
        })?;
        authored.ok().map(|(op, _)| op.id())
    }

    fn sybil(&mut self) -> Option<Keypair> {
        (self.n_sybil_keys < MAX_SYBIL_KEYS).then(|| {
            self.n_sybil_keys += 1;
            fresh_key(&mut self.keys)
        })
    }
}

fn fresh_key(rng: &mut SimRng) -> Keypair {
    let mut seed = [0u8; 32];
    rng.fill(&mut seed);
    Keypair::from_seed(seed)
}

/// Signs an op with the fields given; `None` if the core's builder refuses them.
fn sign(
    key: &Keypair,
    seq: u64,
    lamport: u64,
    timestamp: u64,
    deps: Vec<OpId>,
    payload: ShapePayload,
) -> Option<(OpId, Vec<u8>)> {
    let fields = OpFields {
        seq,
        lamport,
        timestamp: Timestamp(timestamp),
        deps,
        payload,
    };
    let op = Op::sign(key, &SESSION_ID, fields).ok()?;
    Some((op.id(), op.encoded().to_vec()))
}

fn hello(peer: PeerId) -> Vec<u8> {
    Message::Hello {
        protocol_version: replication::sync::message::PROTOCOL_VERSION,
        session_id: SESSION_ID,
        peer,
        hello_seen: true,
        have: None,
    }
    .encode()
}

fn batch(batch_no: u64, ops: Vec<Vec<u8>>) -> Vec<u8> {
    Message::Ops { batch_no, ops }.encode()
}

fn stamp_edit(rng: &mut SimRng, object: u64) -> ShapePayload {
    ShapePayload::edit(
        object,
        Edit::stamp(
            EditOp::Subtract,
            ToolShape::Sphere {
                radius: rng.range_f64(0.05, 0.3),
            },
            Pose::at([rng.range_f64(-1.0, 1.0), 0.0, 0.0].into()),
        ),
    )
    .expect("a valid edit")
}

fn hoard(object: u64) -> ShapePayload {
    ShapePayload::Lease(LeaseAction::Acquire {
        object,
        strong: true,
        ttl_micros: u64::MAX,
    })
}

/// A version vector of `n` made-up authors with large sequence numbers.
fn made_up_vv(rng: &mut SimRng, n: usize) -> VersionVector {
    let mut vv = VersionVector::new();
    for _ in 0..n {
        let mut id = [0u8; 32];
        rng.fill(&mut id);
        vv.raise(PeerId(id), 1 + rng.below(1 << 40));
    }
    vv
}

/// A formula of about 15 KiB that compiles (a sum of many small terms).
fn long_formula() -> String {
    let mut text = String::from("1");
    let mut i = 0;
    while text.len() < 15_000 {
        text.push_str(&format!("-{}*x*y", 1 + i % 97));
        i += 1;
    }
    text
}

fn stroke_bomb(object: u64) -> ShapePayload {
    let path = (0..STROKE_BOMB_POSES)
        .map(|i| {
            let i = i as f64;
            Pose::at([(i * 0.37).sin(), (i * 0.11).cos(), i * 0.003].into())
        })
        .collect();
    ShapePayload::edit(
        object,
        Edit {
            op: EditOp::Subtract,
            tool: ToolShape::Sphere { radius: 0.2 },
            path,
            blend_radius: 0.05,
            mirror: Some(Axis::X),
        },
    )
    .expect("a valid edit")
}

/// Cost bomb `kind`: 0 creates `object` with the formula `text`, 1 sets its geometry to it,
/// 2 is a stroke bomb on it.
fn cost_bomb(kind: u64, object: u64, text: &str) -> Option<ShapePayload> {
    let geometry = || Some(Geometry::implicit(Formula::new(text).ok()?));
    Some(match kind {
        0 => ShapePayload::Create {
            object,
            counter: None,
            data: std::sync::Arc::new(ObjectData {
                geometry: Some(geometry()?),
                ..ObjectData::default()
            }),
            group: None,
        },
        1 => ShapePayload::Set {
            object,
            field: Box::new(Field::Geometry(Some(Box::new(geometry()?)))),
        },
        _ => stroke_bomb(object),
    })
}

/// Messages for one attack: to a random target, or (forks) one to each of two targets.
pub(crate) type Sends = Vec<(usize, Vec<u8>)>;

/// What the member sees of the run when it crafts an attack on honest peer `to`.
pub(crate) struct Aim<'a> {
    /// Virtual time now.
    pub(crate) now: u64,
    /// The member's own id, which its hellos name.
    pub(crate) me: PeerId,
    /// A fresh batch number for its messages.
    pub(crate) batch_no: u64,
    /// The peer attacked.
    pub(crate) to: usize,
    /// Every honest peer it reaches (`to` among them).
    pub(crate) targets: &'a [usize],
    /// The run's objects.
    pub(crate) objects: &'a [u64],
    /// Where the ids of `to`'s user's next objects come from.
    pub(crate) victim: Option<IdSource>,
    /// `to`'s id.
    pub(crate) victim_key: Option<PeerId>,
    /// Another honest peer's id than `to`'s, if there is one.
    pub(crate) third_key: Option<PeerId>,
}

impl Aim<'_> {
    /// A hello to `to` under the member's own id.
    fn hello(&self) -> (usize, Vec<u8>) {
        (self.to, hello(self.me))
    }

    /// A hello, then a batch of the one op `op` (`None` if it could not be signed).
    fn one(&self, op: Option<(OpId, Vec<u8>)>) -> Option<Sends> {
        let (_, bytes) = op?;
        Some(vec![
            self.hello(),
            (self.to, batch(self.batch_no, vec![bytes])),
        ])
    }
}

impl Attack {
    /// The attacks `faults` switch on, in the order the member takes turns through them.
    pub(crate) fn menu(faults: &Faults) -> Vec<Attack> {
        let mut menu = Vec::new();
        if faults.byzantine {
            menu.extend([
                Attack::Backdated,
                Attack::FarFuture,
                Attack::FarPast,
                Attack::Sybil,
                Attack::GiantVersionVectors,
                Attack::OversizedBatch,
                Attack::CostBomb,
                Attack::TakeId,
                Attack::RefoldFlood,
                Attack::HelloFlood,
                Attack::WrongIdHello,
                Attack::ByteFlood,
                Attack::AdmittedSybil,
                Attack::SelfAdmitted,
                Attack::CapFill,
                Attack::OtherSession,
            ]);
        }
        if faults.lease_attacks {
            menu.extend([
                Attack::BackdatedLease,
                Attack::Hoard,
                Attack::LeasePredicted,
                Attack::LeaseAll,
            ]);
        }
        if faults.forks {
            menu.push(Attack::Fork);
        }
        if faults.expel {
            menu.push(Attack::ForgeExpel);
        }
        menu
    }
}

impl Byzantine {
    /// The next attack of `menu` (not empty): each in turn from the one `first` names at the
    /// member's first turn, so every kind is sent about as often whatever the network's draws
    /// (a random pick each time left one kind out of some short runs when an unrelated change
    /// moved those draws).
    pub(crate) fn next_attack(&mut self, menu: &[Attack], first: usize) -> Attack {
        if self.n_turns == 0 {
            self.first_turn = first;
        }
        let attack = menu[(self.first_turn + self.n_turns) % menu.len()];
        self.n_turns += 1;
        attack
    }

    /// The messages of `attack` on `aim.to` (`None` if it has nothing to send); ops its core
    /// authors go out through the core's sync instead.
    pub(crate) fn craft(&mut self, attack: Attack, aim: &Aim, rng: &mut SimRng) -> Option<Sends> {
        let f = self.frontier();
        let object = aim.objects[rng.index(aim.objects.len())];
        match attack {
            Attack::Backdated | Attack::BackdatedLease => {
                self.backdated(aim, rng, object, attack == Attack::BackdatedLease)
            }
            Attack::RefoldFlood => self.refold_flood(aim, rng, object),
            Attack::Hoard => self.hoard_chain(aim, f, object),
            Attack::FarFuture => self.far_future(aim, rng, f, object),
            Attack::FarPast => self.far_past(aim, rng, f, object),
            Attack::Sybil => self.sybil_burst(aim, rng, f, object),
            Attack::GiantVersionVectors => Some(giant_version_vectors(aim, rng)),
            Attack::OversizedBatch => self.oversized_batch(aim, f),
            Attack::CostBomb => self.cost_bomb(aim, rng, f, object),
            Attack::TakeId => self.take_id(aim, rng),
            Attack::ForgeExpel => self.forge_expel(aim, rng, f),
            Attack::HelloFlood => Some((0..HELLO_FLOOD).map(|_| aim.hello()).collect()),
            Attack::WrongIdHello => Some(vec![(aim.to, hello(aim.third_key.or(aim.victim_key)?))]),
            Attack::ByteFlood => self.byte_flood(aim, rng, f),
            Attack::AdmittedSybil => self.admitted_sybil(aim),
            Attack::SelfAdmitted => self.self_admitted(aim, rng, f),
            Attack::CapFill => {
                let text = "f".repeat(2_000);
                let n_authored = (0..CAP_FILL_OPS)
                    .map_while(|_| self.author(aim.now, ShapePayload::Chat(text.clone())))
                    .count();
                (n_authored > 0).then(Vec::new)
            }
            Attack::LeasePredicted => {
                let next = aim.victim?;
                for n in 0..3 {
                    self.author(aim.now, hoard(next.skip(n)?.id()))?;
                }
                Some(Vec::new())
            }
            Attack::OtherSession => self.other_session(aim, f),
            Attack::LeaseAll => {
                for &object in aim.objects {
                    self.author(aim.now, hoard(object))?;
                }
                Some(Vec::new())
            }
            Attack::Fork => self.fork(aim, rng, f),
        }
    }

    /// A fresh key's op at Lamport 1 with no dependencies, stamped at time 0 or
    /// [`BACKDATE_MICROS`] ago: a delete, an edit or a chat, or with `lease` a hoard.
    fn backdated(
        &mut self,
        aim: &Aim,
        rng: &mut SimRng,
        object: u64,
        lease: bool,
    ) -> Option<Sends> {
        let key = self.sybil()?;
        let at = if rng.chance(500) {
            0
        } else {
            aim.now.saturating_sub(BACKDATE_MICROS)
        };
        let payload = match (lease, rng.below(3)) {
            (true, _) => hoard(object),
            (_, 0) => ShapePayload::Delete { object },
            (_, 1) => stamp_edit(rng, object),
            _ => ShapePayload::Chat("backdated".into()),
        };
        aim.one(sign(&key, 1, 1, at, Vec::new(), payload))
    }

    /// A fresh key's chain of [`REFOLD_FLOOD`] backdated edits, each in a message of its own.
    fn refold_flood(&mut self, aim: &Aim, rng: &mut SimRng, object: u64) -> Option<Sends> {
        let key = self.sybil()?;
        let start = aim.now.saturating_sub(BACKDATE_MICROS);
        let mut out = vec![aim.hello()];
        for i in 0..REFOLD_FLOOD {
            let edit = stamp_edit(rng, object);
            let (_, bytes) = sign(&key, i + 1, i + 1, start + i, Vec::new(), edit)?;
            out.push((aim.to, batch(aim.batch_no + i, vec![bytes])));
        }
        Some(out)
    }

    /// The hoarder's next strong acquire for ever, on a chain that sees everything.
    fn hoard_chain(&mut self, aim: &Aim, f: Frontier, object: u64) -> Option<Sends> {
        let chain = &mut self.hoarder;
        let lamport = f.lamport.max(chain.lamport) + 1;
        let timestamp = aim.now.max(f.timestamp).max(chain.timestamp);
        let op = sign(
            &chain.key,
            chain.next_seq,
            lamport,
            timestamp,
            f.heads,
            hoard(object),
        )?;
        chain.next_seq += 1;
        chain.lamport = lamport;
        chain.timestamp = timestamp;
        aim.one(Some(op))
    }

    /// A fresh key's op stamped far in the future, or a little past the receivers' skew bound.
    fn far_future(
        &mut self,
        aim: &Aim,
        rng: &mut SimRng,
        f: Frontier,
        object: u64,
    ) -> Option<Sends> {
        let key = self.sybil()?;
        let at = if rng.chance(300) {
            u64::MAX - 1
        } else {
            aim.now + MAX_CLOCK_SKEW_MICROS + 1 + rng.below(2 * MAX_CLOCK_SKEW_MICROS)
        };
        let payload = if rng.chance(500) {
            stamp_edit(rng, object)
        } else {
            ShapePayload::Chat("from the future".into())
        };
        aim.one(sign(&key, 1, f.lamport + 1, at, f.heads, payload))
    }

    /// A fresh key's edit stamped at time 0 after recent dependencies: every peer must refuse it.
    fn far_past(&mut self, aim: &Aim, rng: &mut SimRng, f: Frontier, object: u64) -> Option<Sends> {
        if f.timestamp == 0 {
            return None;
        }
        let key = self.sybil()?;
        let op = sign(&key, 1, f.lamport + 1, 0, f.heads, stamp_edit(rng, object))?;
        self.must_refuse.push(op.0);
        aim.one(Some(op))
    }

    /// Up to [`SYBIL_BURST`] fresh keys' ops in one batch.
    fn sybil_burst(
        &mut self,
        aim: &Aim,
        rng: &mut SimRng,
        f: Frontier,
        object: u64,
    ) -> Option<Sends> {
        let mut ops = Vec::new();
        for _ in 0..SYBIL_BURST {
            let Some(key) = self.sybil() else { break };
            let payload = if rng.chance(500) {
                stamp_edit(rng, object)
            } else {
                ShapePayload::Chat("sybil".into())
            };
            let timestamp = aim.now.max(f.timestamp);
            let deps = f.heads.clone();
            if let Some((_, bytes)) = sign(&key, 1, f.lamport + 1, timestamp, deps, payload) {
                ops.push(bytes);
            }
        }
        (!ops.is_empty()).then(|| vec![aim.hello(), (aim.to, batch(aim.batch_no, ops))])
    }

    /// [`MAX_BATCH_OPS`] + 1 ops of a fresh key's chain in one message.
    fn oversized_batch(&mut self, aim: &Aim, f: Frontier) -> Option<Sends> {
        let key = self.sybil()?;
        let timestamp = aim.now.max(f.timestamp);
        let mut ops = Vec::new();
        let mut deps = f.heads.clone();
        for seq in 1..=MAX_BATCH_OPS as u64 + 1 {
            let payload = ShapePayload::Chat(format!("batch {seq}"));
            let (id, bytes) = sign(&key, seq, f.lamport + seq, timestamp, deps, payload)?;
            deps = vec![id];
            ops.push(bytes);
        }
        Some(vec![aim.hello(), (aim.to, batch(aim.batch_no, ops))])
    }

    /// One of at most [`MAX_COST_BOMBS`]: the compile bomb, a long formula or a stroke bomb.
    fn cost_bomb(
        &mut self,
        aim: &Aim,
        rng: &mut SimRng,
        f: Frontier,
        object: u64,
    ) -> Option<Sends> {
        if self.n_bombs >= MAX_COST_BOMBS {
            return None;
        }
        self.n_bombs += 1;
        let key = self.sybil()?;
        let payload = match rng.below(3) {
            0 => {
                let text = self.bomb.get_or_insert_with(largest_compile_bomb).clone()?;
                cost_bomb(0, BOMB_OBJECT_BASE + self.n_bombs as u64, &text)?
            }
            1 => cost_bomb(1, object, &long_formula())?,
            _ => cost_bomb(2, object, "")?,
        };
        let timestamp = aim.now.max(f.timestamp);
        aim.one(sign(&key, 1, f.lamport + 1, timestamp, f.heads, payload))
    }

    /// A backdated `Create` of an id `to`'s user takes soon, named [`STOLEN_NAME`].
    fn take_id(&mut self, aim: &Aim, rng: &mut SimRng) -> Option<Sends> {
        let key = self.sybil()?;
        let victim = aim.victim?.skip(rng.below(3))?;
        let payload = ShapePayload::Create {
            object: victim.id(),
            counter: rng.chance(500).then_some(victim.counter),
            data: std::sync::Arc::new(ObjectData {
                name: STOLEN_NAME.into(),
                geometry: Some(Geometry::implicit(Formula::new("1-x^2-y^2-z^2").ok()?)),
                ..ObjectData::default()
            }),
            group: None,
        };
        aim.one(sign(
            &key,
            1,
            1,
            aim.now.saturating_sub(BACKDATE_MICROS),
            Vec::new(),
            payload,
        ))
    }

    /// A fresh key's expel of `to`, posing as the founder.
    fn forge_expel(&mut self, aim: &Aim, rng: &mut SimRng, f: Frontier) -> Option<Sends> {
        // With the founder's nonce (as if it leaked, and it does once the founder expels) or a
        // made-up one.
        let key = self.sybil()?;
        let mut nonce = FOUNDER_NONCE;
        if rng.chance(500) {
            rng.fill(&mut nonce);
        }
        let expel = Membership {
            member: aim.victim_key?,
            expel: true,
            nonce,
        };
        let payload = ShapePayload::Member(Box::new(expel));
        let timestamp = aim.now.max(f.timestamp);
        aim.one(sign(&key, 1, f.lamport + 1, timestamp, f.heads, payload))
    }

    /// One of at most [`MAX_BYTE_FLOODS`]: [`BYTE_FLOOD_BATCHES`] full batches of fresh keys'
    /// large chats, each chain waiting on an op nobody holds.
    fn byte_flood(&mut self, aim: &Aim, rng: &mut SimRng, f: Frontier) -> Option<Sends> {
        if self.n_byte_floods >= MAX_BYTE_FLOODS {
            return None;
        }
        self.n_byte_floods += 1;
        let text = "x".repeat(BYTE_FLOOD_TEXT_BYTES);
        let timestamp = aim.now.max(f.timestamp);
        let mut out = vec![aim.hello()];
        for batch_idx in 0..BYTE_FLOOD_BATCHES {
            let key = self.sybil()?;
            let mut missing = [0; 32];
            rng.fill(&mut missing);
            let (mut deps, mut ops) = (vec![OpId(missing)], Vec::new());
            for seq in 1..=MAX_BATCH_OPS as u64 {
                let payload = ShapePayload::Chat(text.clone());
                let (id, bytes) = sign(&key, seq, f.lamport + seq, timestamp, deps, payload)?;
                deps = vec![id];
                ops.push(bytes);
            }
            out.push((aim.to, batch(aim.batch_no + batch_idx, ops)));
        }
        Some(out)
    }

    /// A fresh key its core admits with [`SYBIL_GRANT_BYTES`], and two chats of the key's, the
    /// second past the grant.
    fn admitted_sybil(&mut self, aim: &Aim) -> Option<Sends> {
        let key = self.sybil()?;
        let admission = Admission {
            key: key.peer_id(),
            grant_bytes: SYBIL_GRANT_BYTES,
            nonce: None,
        };
        self.author(aim.now, ShapePayload::Admit(Box::new(admission)))?;
        // After the admission, so its first op names it (the core's only head now).
        let f = self.frontier();
        let timestamp = aim.now.max(f.timestamp);
        let chat = |i: u64| ShapePayload::Chat(format!("{i}{}", "s".repeat(2_000)));
        let (first, within) = sign(&key, 1, f.lamport + 1, timestamp, f.heads, chat(1))?;
        let (_, past) = sign(&key, 2, f.lamport + 2, timestamp, vec![first], chat(2))?;
        Some(vec![
            aim.hello(),
            (aim.to, batch(aim.batch_no, vec![within, past])),
        ])
    }

    /// A fresh key's admission of itself, with the founder's nonce or a made-up one.
    fn self_admitted(&mut self, aim: &Aim, rng: &mut SimRng, f: Frontier) -> Option<Sends> {
        let key = self.sybil()?;
        let mut nonce = FOUNDER_NONCE;
        if rng.chance(500) {
            rng.fill(&mut nonce);
        }
        let admission = Admission {
            key: key.peer_id(),
            grant_bytes: u64::MAX,
            nonce: Some(nonce),
        };
        let payload = ShapePayload::Admit(Box::new(admission));
        let timestamp = aim.now.max(f.timestamp);
        aim.one(sign(&key, 1, f.lamport + 1, timestamp, f.heads, payload))
    }

    /// A fresh key's op, well formed, but signed for another session's id.
    fn other_session(&mut self, aim: &Aim, f: Frontier) -> Option<Sends> {
        let fields = OpFields {
            seq: 1,
            lamport: f.lamport + 1,
            timestamp: Timestamp(aim.now.max(f.timestamp)),
            deps: f.heads,
            payload: ShapePayload::Chat("from another session".into()),
        };
        let key = self.sybil()?;
        let op = Op::sign(&key, &OTHER_SESSION_ID, fields).ok()?;
        self.must_refuse.push(op.id());
        aim.one(Some((op.id(), op.encoded().to_vec())))
    }

    /// Two ops of one fresh key with seq 1, one to `to` and one to another peer.
    fn fork(&mut self, aim: &Aim, rng: &mut SimRng, f: Frontier) -> Option<Sends> {
        let key = self.sybil()?;
        let to = aim.to;
        // Another peer than `to`, when there is one.
        let others: Vec<usize> = aim.targets.iter().copied().filter(|t| *t != to).collect();
        let other = others
            .get(rng.index(others.len().max(1)))
            .copied()
            .unwrap_or(to);
        let timestamp = aim.now.max(f.timestamp);
        let fork = |text: &str| {
            let payload = ShapePayload::Chat(text.into());
            sign(&key, 1, f.lamport + 1, timestamp, f.heads.clone(), payload)
        };
        let (a, b) = (fork("fork a")?, fork("fork b")?);
        self.forks.push((a.0, b.0));
        Some(vec![
            aim.hello(),
            (to, batch(aim.batch_no, vec![a.1])),
            (other, hello(aim.me)),
            (other, batch(aim.batch_no, vec![b.1])),
        ])
    }

    /// Hands its core a message honest peer `from` sent it.
    pub(crate) fn receive(&mut self, now: u64, from: usize, bytes: &[u8]) {
        guarded_call(&mut self.panicked, &mut self.core, |p| {
            p.handle_input(Timestamp(now), ConnId(from as u64), bytes);
        });
    }

    /// Its core's connection to honest peer `other` opened (`true`) or closed.
    pub(crate) fn link(&mut self, now: u64, other: usize, open: bool) {
        guarded_call(&mut self.panicked, &mut self.core, |p| {
            if open {
                // Refused only over the connection limit, which the mesh stays under.
                let _ = p.connect(Timestamp(now), ConnId(other as u64));
            } else {
                p.disconnect(ConnId(other as u64));
            }
        });
    }

    /// Its core's timer.
    pub(crate) fn wake(&mut self, now: u64) {
        if self.wake_at == Some(now) {
            self.wake_at = None;
        }
        guarded_call(&mut self.panicked, &mut self.core, |p| {
            p.handle_timeout(Timestamp(now));
        });
    }

    /// Drains its core's events and transmissions, and arms its timer: what the core sends,
    /// by honest peer, and when it must wake if that is sooner than it was to.
    pub(crate) fn drain(&mut self, now: u64) -> (Sends, Option<u64>) {
        let mut out = Vec::new();
        for _ in 0..MAX_DRAIN {
            match guarded_call(&mut self.panicked, &mut self.core, |p| p.poll_event()) {
                Some(Some(_)) => {}
                _ => break,
            }
        }
        for _ in 0..MAX_DRAIN {
            let sent = guarded_call(&mut self.panicked, &mut self.core, |p| {
                p.poll_transmit(Timestamp(now))
            });
            match sent {
                Some(Some((conn, bytes))) => out.push((conn.0 as usize, bytes)),
                _ => break,
            }
        }
        let next = guarded_call(&mut self.panicked, &mut self.core, |p| p.poll_timeout())
            .flatten()
            .map(|t| t.0.max(now + 1));
        let wake = match next {
            Some(at) if self.wake_at.is_none_or(|w| at < w) => {
                self.wake_at = Some(at);
                Some(at)
            }
            _ => None,
        };
        (out, wake)
    }
}

/// A hello, then two haves and a want of [`MAX_VV_AUTHORS`] made-up authors each.
fn giant_version_vectors(aim: &Aim, rng: &mut SimRng) -> Sends {
    let mut out = vec![aim.hello()];
    for _ in 0..2 {
        let vv = made_up_vv(rng, MAX_VV_AUTHORS);
        out.push((aim.to, Message::have(vv).encode()));
    }
    let vv = made_up_vv(rng, MAX_VV_AUTHORS);
    out.push((aim.to, Message::want(vv).encode()));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use replication::Payload;
    use replication::payload::MAX_PAYLOAD_BYTES;

    #[test]
    fn cost_bombs_sit_at_the_limits_and_validate() {
        let bomb = largest_compile_bomb().expect("a one-trip loop compiles");
        let trips = |text: &str| {
            let digits = text.split("i < ").nth(1).and_then(|t| t.split(';').next());
            digits
                .and_then(|d| d.parse::<usize>().ok())
                .expect("a trip count")
        };
        let n = trips(&bomb);
        // One more trip is refused (unless the loop limit itself was reached).
        let refused = |text: &str| cost_bomb(0, 7, text).is_none_or(|p| p.validate().is_err());
        assert!(n == MAX_BOMB_TRIPS || refused(&compile_bomb(n + 1)), "{n}");
        assert!(n > 1, "{n}");
        for (kind, text) in [(0, bomb.as_str()), (1, &long_formula()), (2, "")] {
            let payload = cost_bomb(kind, 7, text).expect("a bomb within the limits");
            payload.validate().expect("a bomb every peer accepts");
            let mut bytes = Vec::new();
            payload.encode(&mut bytes);
            assert!(bytes.len() <= MAX_PAYLOAD_BYTES, "{kind}: {}", bytes.len());
            if kind > 0 {
                assert!(
                    bytes.len() * 4 > MAX_PAYLOAD_BYTES,
                    "{kind}: {}",
                    bytes.len()
                );
            }
        }
    }
}
