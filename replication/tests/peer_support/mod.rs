//! A whole [`Peer`] driven by a script read from bytes: connections opened and lost, time
//! passing, and remotes that say hello as anyone, claim made-up haves, want what does not exist,
//! ack batches never sent, send ephemeral floods, raw garbage, and batches of ops signed by
//! hostile keys with any counters, timestamps, dependencies and payloads (creates, sets, edits,
//! leases of any TTL, undo and redo of ops they know, deletes). The local user authors ops
//! meanwhile.
//!
//! After every step the peer must hold every op its user authored, keep pending ops and
//! outgoing messages within their limits, and drain its outputs in a bounded number of polls.
//! Shared by the fuzz target (`fuzz/fuzz_targets/peer.rs`, which includes this file) and the
//! property test in `tests/peer_script.rs`, so CI runs what the fuzzer explores.

use model::object::{Edit, EditOp, Field, Formula, Geometry, ObjectData, Pose, ToolShape};
use replication::Payload as _;
use replication::identity::SessionId;
use replication::op::OpFields;
use replication::payload::LeaseAction;
use replication::pending::MAX_PENDING_OPS;
use replication::shape::ShapePayload;
use replication::shape::parts::part_hash;
use replication::sync::message::{HelloHave, MAX_MESSAGE_BYTES, Message, PROTOCOL_VERSION};
use replication::{ConnId, Event, Keypair, Log, Op, OpId, Peer, PeerId, Timestamp, VersionVector};

const SESSION: SessionId = [7; 16];
/// Connections the script uses (ids 0..).
const N_CONNS: u64 = 5;
/// Hostile keys the script signs with.
const N_KEYS: u8 = 4;
/// Most polls one drain may take before the peer is said to be stuck.
const MAX_POLLS_PER_STEP: usize = 10_000;
/// Most steps one script runs.
const MAX_STEPS: usize = 400;

/// Reads the script's bytes; past the end it reads zeros, so every script ends.
struct Bytes<'a> {
    data: &'a [u8],
    at: usize,
}

impl Bytes<'_> {
    fn done(&self) -> bool {
        self.at >= self.data.len()
    }

    fn u8(&mut self) -> u8 {
        let b = self.data.get(self.at).copied().unwrap_or(0);
        self.at += 1;
        b
    }

    fn pick(&mut self, n: u64) -> u64 {
        u64::from(self.u8()) % n.max(1)
    }

    /// A counter or time: small, near a boundary, or anything.
    fn number(&mut self, now: u64) -> u64 {
        match self.u8() % 8 {
            0 => 0,
            1 => 1,
            2 => u64::from(self.u8()),
            3 => u64::MAX - u64::from(self.u8()),
            4 => now,
            5 => now.saturating_add(u64::from(self.u8()) << 24),
            6 => now.saturating_sub(u64::from(self.u8()) << 24),
            _ => u64::from_le_bytes(std::array::from_fn(|_| self.u8())),
        }
    }
}

/// What a script made the peer do.
#[derive(Debug, Default)]
pub struct Stats {
    /// Steps run.
    pub steps: usize,
    /// Hellos the peer accepted.
    pub connected: usize,
    /// Remote ops the peer inserted.
    pub delivered: usize,
    /// Inputs the peer dropped as bad.
    pub rejected: usize,
    /// Messages the peer sent.
    pub sent: usize,
    /// Ops the local user authored.
    pub authored: usize,
}

/// The peer under test and what the script has done to it.
struct World {
    peer: Peer<ShapePayload>,
    keys: Vec<Keypair>,
    /// Per hostile key: the next seq it signs, and the lamport it reached.
    counters: Vec<(u64, u64)>,
    /// Ops the local user authored.
    mine: Vec<OpId>,
    /// Ids of ops seen (local and hostile), for dependencies, undo and redo.
    known: Vec<OpId>,
    now: u64,
    stats: Stats,
}

/// Runs the script in `data` against a fresh peer; panics when an invariant breaks.
pub fn run(data: &[u8]) -> Stats {
    let me = Keypair::from_seed([1; 32]);
    let mut world = World {
        peer: Peer::new(me, SESSION, Log::default()),
        keys: (0..N_KEYS)
            .map(|k| Keypair::from_seed([k + 2; 32]))
            .collect(),
        counters: vec![(1, 1); usize::from(N_KEYS)],
        mine: Vec::new(),
        known: Vec::new(),
        now: 1_000_000,
        stats: Stats::default(),
    };
    // Three remotes start connected, each saying hello as a hostile key; the script may drop
    // them, reconnect and say hello as anyone.
    for c in 0..3u8 {
        let conn = ConnId(c.into());
        let _ = world.peer.connect(Timestamp(world.now), conn);
        let hello = Message::Hello {
            protocol_version: PROTOCOL_VERSION,
            session_id: SESSION,
            peer: world.keys[usize::from(c)].peer_id(),
            hello_seen: true,
            have: None,
        };
        world.send(conn, &hello);
        world.drain();
    }
    let mut bytes = Bytes { data, at: 0 };
    for _ in 0..MAX_STEPS {
        if bytes.done() {
            break;
        }
        world.step(&mut bytes);
        world.check();
        world.stats.steps += 1;
    }
    world.stats.authored = world.mine.len();
    world.stats
}

impl World {
    fn conn(&self, bytes: &mut Bytes<'_>) -> ConnId {
        ConnId(bytes.pick(N_CONNS))
    }

    fn someone(&self, bytes: &mut Bytes<'_>) -> PeerId {
        match bytes.u8() % 4 {
            0 => self.peer.peer_id(),
            1 | 2 => self.keys[usize::from(bytes.u8() % N_KEYS)].peer_id(),
            _ => PeerId(std::array::from_fn(|_| bytes.u8())),
        }
    }

    fn version_vector(&self, bytes: &mut Bytes<'_>) -> VersionVector {
        let mut vv = VersionVector::new();
        let n = match bytes.u8() % 4 {
            3 => 2_000 + usize::from(bytes.u8()) * 9,
            k => usize::from(k) * 3,
        };
        for i in 0..n {
            if i < 4 {
                let author = self.someone(bytes);
                vv.set(author, bytes.number(self.now).max(1));
            } else {
                // Many made-up authors cost the script nothing.
                let mut id = [0u8; 32];
                id[..8].copy_from_slice(&(i as u64).to_le_bytes());
                vv.set(PeerId(id), i as u64 % 7 + 1);
            }
        }
        vv
    }

    fn payload(&self, bytes: &mut Bytes<'_>) -> ShapePayload {
        let object = bytes.pick(4) + 1;
        let known = |bytes: &mut Bytes<'_>| {
            let n = self.known.len() as u64;
            if n == 0 {
                OpId([bytes.u8(); 32])
            } else {
                self.known[bytes.pick(n) as usize]
            }
        };
        match bytes.u8() % 11 {
            0 => ShapePayload::Create {
                object,
                counter: None,
                data: std::sync::Arc::new(ObjectData {
                    geometry: Some(Geometry::implicit(
                        Formula::new(["1-x^2-y^2-z^2", "x", "min(x,y)"][bytes.pick(3) as usize])
                            .expect("short"),
                    )),
                    ..ObjectData::default()
                }),
                group: None,
            },
            1 => ShapePayload::Set {
                object,
                field: Box::new(Field::Name(format!("n{}", bytes.u8()))),
            },
            2 => ShapePayload::edit(
                object,
                Edit {
                    op: EditOp::Subtract,
                    tool: ToolShape::Sphere { radius: 0.1 },
                    path: vec![Pose::at([f64::from(bytes.u8()) / 255.0, 0.0, 0.0].into())],
                    blend_radius: 0.0,
                    mirror: None,
                },
            )
            .expect("a valid edit"),
            3 => ShapePayload::Lease(LeaseAction::Acquire {
                object,
                strong: bytes.u8().is_multiple_of(2),
                ttl_micros: bytes.number(self.now),
            }),
            4 => ShapePayload::Lease(LeaseAction::Release { object }),
            5 => ShapePayload::Undo(known(bytes)),
            6 => ShapePayload::Redo(known(bytes)),
            7 => ShapePayload::Delete { object },
            // A creation in two parts: either part, or an assembly of them in either order or
            // of a made-up part.
            9 | 10 => {
                let mut whole = Vec::new();
                ShapePayload::Create {
                    object,
                    counter: None,
                    data: Default::default(),
                    group: None,
                }
                .encode(&mut whole);
                let halves = whole.split_at(whole.len() / 2);
                let (first, second) = (part_hash(halves.0), part_hash(halves.1));
                match bytes.u8() % 5 {
                    0 => ShapePayload::Part {
                        object,
                        bytes: halves.0.to_vec(),
                    },
                    1 => ShapePayload::Part {
                        object,
                        bytes: halves.1.to_vec(),
                    },
                    2 => ShapePayload::Assemble {
                        object,
                        parts: vec![first, second],
                    },
                    3 => ShapePayload::Assemble {
                        object,
                        parts: vec![second, first],
                    },
                    _ => ShapePayload::Assemble {
                        object,
                        parts: vec![first, [bytes.u8(); 32]],
                    },
                }
            }
            _ => ShapePayload::Chat("hi".into()),
        }
    }

    /// An op signed by hostile key `k` with counters that follow on or jump.
    fn hostile_op(&mut self, bytes: &mut Bytes<'_>) -> Option<Vec<u8>> {
        let k = usize::from(bytes.u8() % N_KEYS);
        let (next_seq, lamport) = self.counters[k];
        // Usually the op the peer can take next: after what it holds of this key, on its heads.
        let held = self
            .peer
            .log()
            .version_vector()
            .get(&self.keys[k].peer_id());
        let seq = match bytes.u8() % 4 {
            0 => next_seq,
            1 => held.saturating_add(1),
            2 => next_seq.saturating_sub(1).max(1),
            _ => bytes.number(self.now).max(1),
        };
        let lamport = match bytes.u8() % 3 {
            0 => {
                let log = self.peer.log();
                let heads = log
                    .heads()
                    .filter_map(|h| log.get(h))
                    .map(|op| op.lamport());
                heads.fold(lamport, u64::max).saturating_add(1)
            }
            _ => bytes.number(self.now).max(1),
        };
        let timestamp = Timestamp(match bytes.u8() % 2 {
            0 => self.now,
            _ => bytes.number(self.now),
        });
        let deps = match bytes.u8() % 3 {
            0 => self.peer.log().heads().copied().collect(),
            1 => Vec::new(),
            _ => (0..bytes.pick(3))
                .map(|_| {
                    if bytes.u8().is_multiple_of(2) && !self.known.is_empty() {
                        self.known[bytes.pick(self.known.len() as u64) as usize]
                    } else {
                        OpId([bytes.u8(); 32])
                    }
                })
                .collect(),
        };
        let payload = self.payload(bytes);
        let op = Op::sign(
            &self.keys[k],
            &SESSION,
            OpFields {
                seq,
                lamport,
                timestamp,
                deps,
                payload,
            },
        )
        .ok()?;
        if seq == next_seq {
            self.counters[k] = (next_seq.saturating_add(1), lamport.max(self.counters[k].1));
        }
        self.known.push(op.id());
        let mut encoded = op.encoded().to_vec();
        if bytes.u8().is_multiple_of(16) {
            // A flipped bit: a bad signature or a bad encoding.
            let i = bytes.pick(encoded.len() as u64) as usize;
            encoded[i] ^= 1 << bytes.pick(8);
        }
        Some(encoded)
    }

    fn send(&mut self, conn: ConnId, message: &Message) {
        self.peer
            .handle_input(Timestamp(self.now), conn, &message.encode());
    }

    fn step(&mut self, bytes: &mut Bytes<'_>) {
        let conn = self.conn(bytes);
        match bytes.u8() % 14 {
            0 => {
                let _ = self.peer.connect(Timestamp(self.now), conn);
                if !bytes.u8().is_multiple_of(4) {
                    let hello = Message::Hello {
                        protocol_version: PROTOCOL_VERSION,
                        session_id: SESSION,
                        peer: self.someone(bytes),
                        hello_seen: true,
                        have: None,
                    };
                    self.send(conn, &hello);
                }
            }
            1 => self.peer.disconnect(conn),
            2 => {
                self.now = self
                    .now
                    .saturating_add(u64::from(bytes.u8()) << (bytes.pick(5) * 6));
                self.peer.handle_timeout(Timestamp(self.now));
            }
            3 => {
                let hello = Message::Hello {
                    protocol_version: if bytes.u8().is_multiple_of(8) {
                        PROTOCOL_VERSION + 1
                    } else {
                        PROTOCOL_VERSION
                    },
                    session_id: if bytes.u8().is_multiple_of(8) {
                        [0; 16]
                    } else {
                        SESSION
                    },
                    peer: self.someone(bytes),
                    hello_seen: bytes.u8().is_multiple_of(2),
                    have: bytes.u8().is_multiple_of(2).then(|| HelloHave {
                        vv: self.version_vector(bytes),
                        tips: Vec::new(),
                    }),
                };
                self.send(conn, &hello);
            }
            4 => {
                let have = Message::have(self.version_vector(bytes));
                self.send(conn, &have);
            }
            5 => {
                let want = Message::want(self.version_vector(bytes));
                self.send(conn, &want);
            }
            6 | 7 => {
                let ops = (0..=bytes.pick(6))
                    .filter_map(|_| self.hostile_op(bytes))
                    .collect();
                let batch = Message::Ops {
                    batch_no: bytes.number(self.now),
                    ops,
                };
                self.send(conn, &batch);
            }
            8 => {
                let ack = Message::Ack {
                    batch_no: bytes.number(self.now),
                    have: self.version_vector(bytes),
                };
                self.send(conn, &ack);
            }
            9 if bytes.u8().is_multiple_of(4) => self.send(conn, &Message::Ping),
            9 => {
                let ephemeral = Message::Ephemeral {
                    channel: bytes.u8().into(),
                    seq: bytes.number(self.now),
                    value: vec![bytes.u8(); usize::from(bytes.u8()) * 8],
                };
                self.send(conn, &ephemeral);
            }
            10 => {
                let raw: Vec<u8> = (0..bytes.u8()).map(|_| bytes.u8()).collect();
                self.peer.handle_input(Timestamp(self.now), conn, &raw);
            }
            11 => {
                // A fork proof: two hostile ops, a real fork when they share key and seq.
                if let (Some(a), Some(b)) = (self.hostile_op(bytes), self.hostile_op(bytes)) {
                    self.send(
                        conn,
                        &Message::Forked {
                            ops: [a, b],
                            answer: false,
                        },
                    );
                }
            }
            12 => {
                let ids = (0..=bytes.pick(6))
                    .map(|_| match self.known.len() {
                        n if n > 0 && bytes.u8().is_multiple_of(2) => {
                            self.known[bytes.pick(n as u64) as usize]
                        }
                        _ => OpId([bytes.u8(); 32]),
                    })
                    .collect();
                self.send(conn, &Message::WantOps(ids));
            }
            _ => {
                let payload = self.payload(bytes);
                if let Ok((op, _)) = self.peer.author(Timestamp(self.now), payload) {
                    self.mine.push(op.id());
                    self.known.push(op.id());
                }
            }
        }
        self.drain();
    }

    /// Takes every output; a peer that keeps producing is stuck.
    fn drain(&mut self) {
        let now = Timestamp(self.now);
        for _ in 0..MAX_POLLS_PER_STEP {
            match self.peer.poll_transmit(now) {
                Some((_, bytes)) => {
                    assert!(
                        bytes.len() <= MAX_MESSAGE_BYTES,
                        "a message of {} bytes",
                        bytes.len()
                    );
                    self.stats.sent += 1;
                }
                None => break,
            }
        }
        assert!(
            self.peer.poll_transmit(now).is_none(),
            "more than {MAX_POLLS_PER_STEP} messages in one step"
        );
        for _ in 0..MAX_POLLS_PER_STEP {
            match self.peer.poll_event() {
                None => return,
                Some((_, Event::Connected { .. })) => self.stats.connected += 1,
                Some((_, Event::Delivered(insertion))) => {
                    self.stats.delivered += insertion.delivered.len();
                }
                Some((_, Event::Rejected { .. })) => self.stats.rejected += 1,
                Some(_) => {}
            }
        }
        panic!("more than {MAX_POLLS_PER_STEP} events in one step");
    }

    fn check(&self) {
        let log = self.peer.log();
        for id in &self.mine {
            assert!(log.contains(id), "the user's op {id:?} is gone");
        }
        assert!(
            log.n_pending() <= MAX_PENDING_OPS,
            "{} pending",
            log.n_pending()
        );
    }
}
