//! The sans-IO sync state machine for one connection to one remote peer.
//!
//! Inputs are `handle_*(now, ..)`; outputs are [`SyncState::poll_transmit`],
//! [`SyncState::poll_event`] and [`SyncState::poll_timeout`]. Drain every `poll_*` after each
//! input. The state is rebuilt on every connection: the remote's version vector is learnt from
//! its hello (which names it for a log of at most [`MAX_HELLO_HAVE_AUTHORS`] authors) and the
//! [`Message::Have`] that answers ours (the hello is sent again until one comes, and none of
//! our own ops goes out before the remote's hello or a have, want or ack says how much of them
//! the remote holds), from the changes it announces at most every [`HAVE_EVERY_MICROS`], from
//! acks and from what its wants say it holds, and anything not acknowledged is sent again after
//! a timeout estimated from the round trips of the first hello and of acknowledged batches, or
//! else from the peer's other connections (between [`MIN_RESEND_AFTER_MICROS`] and
//! [`RESEND_AFTER_MICROS`]), backing off to [`MAX_RESEND_AFTER_MICROS`] while the remote stays
//! silent, so a lost or duplicated message can neither stall nor loop a sync. While the resends
//! back off, a [`Message::Ping`] of a few bytes goes out a few times per base interval (for at
//! most [`PING_FOR_MICROS`]); the remote answers it, and the first message after a silence
//! while we ping, with a full have (or, within a have interval of the last, a
//! [`Message::Pong`]), so both ends of a healed partition learn what the other holds, and
//! send again what waits, within about a round trip of hearing each other. Data that overtakes
//! a lost hello is held (at most [`MAX_EARLY_MESSAGES`]) until the hello comes, not dropped.
//!
//! **Bounds.** Every version vector goes out in parts of at most [`MAX_VV_AUTHORS`] authors
//! (a have's first part at once, its others paced like data; wants as control), so no log is
//! too large to announce. What a remote
//! claims is believed only within bounds: of authors the local log does not hold, a connection
//! remembers at most [`MAX_REMOTE_UNKNOWN_AUTHORS`] (the rest are counted in
//! [`SyncStats::n_claims_dropped`]), and a want names only authors the local log holds, so a
//! connection's memory is bounded by the local log plus that constant, whatever the remote
//! sends. An honest remote with more authors than that is not cut short: once most of what
//! was kept has been fetched, the connection sends its hello again, which every peer answers
//! with its full have, and learns the next part.
//!
//! Traffic in a full mesh of n peers: a peer sends its own ops to every remote once it knows
//! what the remote holds, but relays a third peer's ops only when the remote asks with a
//! [`Message::Want`]. The [`Peer`](crate::peer::Peer) asks one connection at a time for what
//! it lacks: the author itself first when it is connected (the want goes on the connection
//! that carries the author's own sends, so nothing crosses twice), a third peer after about a
//! round trip without progress (at most [`RELAY_AFTER_MICROS`]), so each op crosses each link
//! about once instead of once per relaying peer; wants carry what partitions, losses, crashes
//! and absent authors hold back.

use std::cell::Cell;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::marker::PhantomData;
use std::sync::Arc;

use crate::causal::{MAX_VV_AUTHORS, VersionVector};
use crate::codec::DecodeError;
use crate::identity::{OpId, PeerId, SessionId};
use crate::log::{InsertError, Insertion, Log};
use crate::op::{Envelope, MAX_OP_BYTES, Op, ReceiveError};
use crate::payload::Payload;
use crate::pending::{EvictReason, Origin};
use crate::sync::message::{
    DIGEST_BYTES, HelloHave, MAX_BATCH_OPS, MAX_EPHEMERAL_BYTES, MAX_MESSAGE_BYTES, Message,
    PROTOCOL_VERSION, SceneAt, tip,
};
use crate::sync::scene::{ObjectHashes, SceneCheck, SceneEvent, SceneStats};
use crate::time::Timestamp;

/// Most op batches sent and not yet acknowledged (flow control).
pub const MAX_IN_FLIGHT_BATCHES: usize = 4;
/// Most op bytes in one batch we send (well under [`MAX_MESSAGE_BYTES`]).
pub const MAX_BATCH_BYTES: usize = 64 * 1024;
/// Unacknowledged batches and unanswered hellos are first sent again after this long (1 s);
/// batches sooner once round trips have been measured.
pub const RESEND_AFTER_MICROS: u64 = 1_000_000;
/// The shortest batch resend timeout, however short the round trips (100 ms).
pub const MIN_RESEND_AFTER_MICROS: u64 = 100_000;
/// A batch resend timeout is the smoothed round trip of acknowledged batches plus this many
/// of their mean deviations (numerator, denominator: one and a half). RFC 6298 takes four,
/// for TCP's per-segment samples; a sample here spans the sending of the whole batch and of
/// those queued before it, so batch sizes alone spread the samples, and four deviations held
/// a lost batch for two and a half round trips of the link (BENCHMARKS.md, "Resend timeouts
/// of one and a half deviations").
pub const RESEND_DEVIATIONS: (u64, u64) = (3, 2);
/// The resend interval doubles while the remote stays silent, up to this (32 s), so a dead or
/// hostile remote that never answers costs a bounded trickle.
pub const MAX_RESEND_AFTER_MICROS: u64 = 32_000_000;
/// A peer asks a third peer for a connected author's ops only after the author, asked first,
/// sent none for the resend timeout of its connection, when it has one, and at most this long
/// (500 ms): time for the author's own send (or its resend) to arrive.
pub const RELAY_AFTER_MICROS: u64 = 500_000;
/// A remote silent while batches to it wait is pinged ([`Message::Ping`]) this many times per
/// base resend interval ([`PINGS_PER_RESEND`], at most every [`MIN_PING_AFTER_MICROS`]) for at
/// most this long (10 s): a healed partition is found within about a quarter of a resend
/// timeout and a one-way trip, a lost ping costs a quarter, not a whole timeout, and a dead
/// remote costs at most this long's worth of pings of a few bytes (on the 25 ms floor, 400)
/// beside the backed-off resends.
pub const PING_FOR_MICROS: u64 = 10_000_000;
/// Pings per base resend interval while a remote stays silent (see [`PING_FOR_MICROS`]).
pub const PINGS_PER_RESEND: u64 = 4;
/// A remote silent for this many base resend intervals (and at least [`MIN_STALL_MICROS`])
/// while batches to it wait has stalled the connection ([`Event::Stalled`]).
pub const STALL_AFTER_RESENDS: u64 = 3;
/// The shortest silence that stalls a connection (500 ms), however short the round trips:
/// QUIC's own probes find a shorter outage about as soon as a new handshake would.
pub const MIN_STALL_MICROS: u64 = 500_000;
/// The shortest time a dial to the remote of a stalled connection waits for its handshake
/// (250 ms) before a fresh dial replaces it: long enough for a handshake on a loaded machine,
/// short enough that one begun during the outage, whose first packet was lost, gives way soon
/// after the outage ends.
pub const MIN_REDIAL_HANDSHAKE_MICROS: u64 = 250_000;
/// The shortest interval between pings (25 ms), however short the round trips.
pub const MIN_PING_AFTER_MICROS: u64 = 25_000;
/// Most messages one connection holds that came before the remote's hello (data overtaking a
/// lost or late hello), handled once the hello comes; more are dropped as
/// [`RejectKind::BeforeHello`].
pub const MAX_EARLY_MESSAGES: usize = 8;
/// Most bytes of such messages one connection holds (128 KiB).
pub const MAX_EARLY_BYTES: usize = 128 * 1024;
/// Most authors a hello names ([`HelloHave`], about 5 KiB): a larger log's hellos, which go
/// again until answered, say nothing of what it holds, and its haves follow in answer.
pub const MAX_HELLO_HAVE_AUTHORS: usize = 128;
/// A peer tells each remote what it has gained at most this often (1 s), as a delta.
pub const HAVE_EVERY_MICROS: u64 = 1_000_000;
/// ... and everything it holds at most this often (10 s) while that changed, which repairs
/// lost deltas; also, unchanged, while the remote is known to lack ops it holds (repeated
/// only after the remote said something), which repairs a lost last have.
pub const HAVE_FULL_EVERY_MICROS: u64 = 10_000_000;
/// Messages a remote may send per second on average before they are dropped.
pub const MAX_MESSAGES_PER_SEC: u64 = 2_000;
/// Messages a remote may send in a burst.
pub const MAX_MESSAGE_BURST: u64 = 512;
/// Messages this peer sends one remote per second on average, control included: nine tenths
/// of the remote's [`MAX_MESSAGES_PER_SEC`], the rest headroom for control sent on top (a
/// message that must answer goes out at once and is paid back by the data after it). Data
/// takes what control leaves, so a one-way catch-up sends its batches at this rate, and two
/// ways each side's batches and its acks of the other's share it.
pub const MAX_SENT_MESSAGES_PER_SEC: u64 = MAX_MESSAGES_PER_SEC * 9 / 10;
/// The burst of [`MAX_SENT_MESSAGES_PER_SEC`]: half the remote's [`MAX_MESSAGE_BURST`], so
/// that when both sides open with a burst of batches, each side's batches and its acks of
/// the other's (which go out at once) fit in the remote's burst together.
pub const MAX_SENT_MESSAGE_BURST: u64 = MAX_MESSAGE_BURST / 2;
/// Full haves a remote's hellos may cost this peer per second on average: every hello asks
/// for one (it tells the remote what this peer holds, and confirms the hello), so this
/// bounds what hellos make this peer announce, as pings are (a full have a second). A hello
/// beyond it and [`MAX_HELLO_ANSWER_BURST`] is dropped unanswered (counted in
/// [`SyncStats::n_hellos_unanswered`]): an honest remote sends it again until a have comes.
pub const MAX_HELLO_ANSWERS_PER_SEC: u64 = 1;
/// The burst of [`MAX_HELLO_ANSWERS_PER_SEC`]: a connection's first hello, its answer to
/// ours, and resends after a lost have or two.
pub const MAX_HELLO_ANSWER_BURST: u64 = 4;
/// Hellos a remote may send per second on average before they count against it: beyond this
/// and [`MAX_HELLO_BURST`] they are dropped and counted ([`RejectKind::RepeatedHello`]). An
/// honest remote sends one, then again only while no have answers it (at least
/// [`MIN_RESEND_AFTER_MICROS`] apart), and one to relearn or repair now and then: even on a
/// link that loses and duplicates a quarter of its messages that stays well within.
pub const MAX_HELLOS_PER_SEC: u64 = 4;
/// The burst of [`MAX_HELLOS_PER_SEC`].
pub const MAX_HELLO_BURST: u64 = 16;
/// Most ephemeral channels buffered for sending.
pub const MAX_EPHEMERAL_CHANNELS: usize = 64;
/// Bytes of new ops (not held yet) a remote may make this peer take per second on average,
/// counted before their signatures are checked: beyond it and [`MAX_RECEIVED_OP_BYTES_BURST`]
/// a batch's remaining ops are dropped unread and the batch is not acknowledged, so an
/// honest sender's resend brings them later (counted in [`SyncStats::n_ops_over_quota`]).
/// One connection's ops cost this peer bounded CPU and memory per second, whatever it sends
/// (8 MiB: about what one core verifies).
pub const MAX_RECEIVED_OP_BYTES_PER_SEC: u64 = 8 * 1024 * 1024;
/// The burst of [`MAX_RECEIVED_OP_BYTES_PER_SEC`] (32 MiB): a catch-up of 10^5 ops of the
/// usual size (about 160 bytes) fits in it twice.
pub const MAX_RECEIVED_OP_BYTES_BURST: u64 = 32 * 1024 * 1024;
/// Most authors the local log does not hold that one connection remembers from the remote's
/// haves and acks. Such a claim is only good for asking the remote to relay the author's ops,
/// so the excess is dropped (and counted) rather than stored; it is learnt again later.
pub const MAX_REMOTE_UNKNOWN_AUTHORS: usize = MAX_VV_AUTHORS;
/// A claim the remote did not make good (asked for an author's ops, it answered without one
/// for the retry period, at most [`crate::peer::WANT_RETRY_MICROS`]) is withdrawn, and the
/// same claim, up to the same seq, is not learnt again from this remote for this long (60 s):
/// a remote that claims made-up authors costs one ask and one retry period per claim, not a
/// scan every check for the connection's life. A claim to more of that author is learnt at
/// once.
pub const CLAIM_WITHDRAWN_MICROS: u64 = 60_000_000;
/// Most withdrawn claims one connection remembers (the excess is withdrawn but may be learnt
/// again at once).
pub const MAX_WITHDRAWN_CLAIMS: usize = MAX_REMOTE_UNKNOWN_AUTHORS;
/// A connection that dropped some of the remote's claims checks this often (1 s) whether
/// enough of what it kept has arrived to ask for the remote's full have again.
pub const RELEARN_CHECK_MICROS: u64 = HAVE_EVERY_MICROS;
/// How long an op from the remote waits for a dependency, with the log not growing, before
/// this peer asks the remote for it by id ([`Message::WantOps`]): while version vectors bring
/// ops the log grows, so only what they cannot name is asked for, such as the other op of a
/// fork (a full have goes out this often).
pub const STUCK_DEP_MICROS: u64 = HAVE_FULL_EVERY_MICROS;
/// How soon a connection that asked for stuck dependencies looks for more (after a look
/// that found none, it waits [`STUCK_DEP_MICROS`]).
pub const STUCK_CHECK_MICROS: u64 = HAVE_EVERY_MICROS;
/// Most ops one connection asks for by id over its life.
pub const MAX_ASKED_OPS: usize = 1024;
/// Most ops asked for by id that one connection queues to send.
pub const MAX_ASKED_OUT: usize = 4 * MAX_BATCH_OPS;
/// A connection to a member the founder expelled stays open at most this long (5 s) once this
/// peer holds the expel, so that the member learns it too: it is sent what it lacks, the
/// expel among it (its own log then says it was expelled, and it closes every connection
/// with [`CloseReason::Expelled`] naming itself, which its app can show), and none of its
/// ops are taken. The connection closes as soon as the member is known to hold everything
/// this peer holds, or at this deadline.
pub const EXPEL_NOTICE_MICROS: u64 = 5_000_000;

const MICROS_PER_SEC: u64 = 1_000_000;
const _: () = assert!(MAX_BATCH_BYTES + MAX_BATCH_OPS * 10 + 32 <= MAX_MESSAGE_BYTES);
const _: () = assert!(MAX_OP_BYTES <= MAX_BATCH_BYTES);
// An honest catch-up of 10^5 ops of about 160 bytes fits in the op-byte burst twice.
const _: () = assert!(MAX_RECEIVED_OP_BYTES_BURST >= 2 * 100_000 * 160);

/// What kind of bad or unwanted input was dropped. Each is counted and reported.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RejectKind {
    /// Bytes that are not a well-formed message.
    Malformed,
    /// A message or op format version this build does not know.
    UnknownVersion,
    /// A message over [`MAX_MESSAGE_BYTES`] or a count over its limit.
    Oversized,
    /// A hello with another protocol version.
    WrongProtocol,
    /// A hello for another session.
    WrongSession,
    /// A hello from a different peer than earlier on this connection.
    WrongPeer,
    /// A hello over the remote's allowance ([`MAX_HELLOS_PER_SEC`], [`MAX_HELLO_BURST`]).
    RepeatedHello,
    /// Data before the remote's hello.
    BeforeHello,
    /// An op that does not decode.
    MalformedOp,
    /// An op whose signature does not verify under its author (forged or wrong author).
    BadSignature,
    /// An op the log refused (equivocation, bad Lamport time, full).
    RefusedOp,
    /// A pending op from this remote evicted because the buffer was full.
    PendingFull,
    /// A pending op from this remote whose dependencies never came.
    PendingExpired,
    /// A message over the remote's rate limit.
    RateLimited,
    /// An ephemeral value over [`MAX_EPHEMERAL_BYTES`] or too many channels.
    EphemeralTooLarge,
    /// A [`Message::Forked`] whose two ops do not decode, or are not one author's with one seq
    /// and different ids.
    BadForkProof,
}

impl RejectKind {
    /// False for what an honest remote meets too: [`RejectKind::PendingFull`], ops dropped
    /// because this peer's pending buffer was full, which any sender streaming a backlog
    /// larger than the buffer causes. What such ops cost is bounded by the op-byte quota
    /// ([`MAX_RECEIVED_OP_BYTES_PER_SEC`]), and most are dropped before their signatures are
    /// checked ([`Log::pending_drops`]).
    pub fn is_offence(self) -> bool {
        self != RejectKind::PendingFull
    }

    /// The kind of a message that did not decode for `error`.
    fn of_decode_error(error: &DecodeError) -> RejectKind {
        match error {
            DecodeError::UnknownVersion { .. } => RejectKind::UnknownVersion,
            DecodeError::OverLimit { .. } => RejectKind::Oversized,
            _ => RejectKind::Malformed,
        }
    }
}

/// Why the connection closed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CloseReason {
    /// The remote speaks another protocol version.
    WrongProtocol {
        /// The version the remote's hello names.
        remote: u64,
    },
    /// The remote is in another session.
    WrongSession,
    /// The session's founder expelled `peer`: the remote, or this peer itself
    /// ([`crate::membership`]).
    Expelled {
        /// The member expelled.
        peer: PeerId,
    },
    /// The peer needed this connection's slot for another ([`crate::peer::Peer::accept`]).
    Evicted,
    /// The remote's hello named another peer than the one the transport admitted
    /// ([`SyncState::set_admitted`]).
    NotAdmitted {
        /// The id the hello named.
        claimed: PeerId,
    },
}

/// Something the application should know.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// The remote's hello arrived.
    Connected {
        /// The remote's claimed peer id.
        peer: PeerId,
    },
    /// Ops from the remote were inserted; the scene must refold as the insertion says.
    Delivered(Insertion),
    /// Bad input was dropped.
    Rejected {
        /// What kind.
        kind: RejectKind,
        /// A plain description.
        detail: String,
    },
    /// The remote's latest value on an ephemeral channel.
    Ephemeral {
        /// The stream.
        channel: u32,
        /// The value.
        value: Vec<u8>,
    },
    /// This input showed that `author` signed two ops with the seq `seq` (the lowest the log
    /// knows): a fork's two ops came, or an op forked one the log holds ([`crate::fork`]). The
    /// log holds both, and rejects the author's ops from `seq` on.
    Forked {
        /// The author that equivocated.
        author: PeerId,
        /// The seq it signed twice.
        seq: u64,
    },
    /// The remote has acknowledged everything this peer holds.
    UpToDate,
    /// Batches to the remote wait and it has said nothing for a few resend timeouts (at least
    /// [`MIN_STALL_MICROS`]), or it has shown for as long that it hears nothing of ours
    /// (`unheard`): the transport under the connection has stalled, as QUIC's backed-off
    /// probes leave it after an outage, and a new connection to the same remote would resume
    /// sync at its handshake. Said only by the end with the smaller peer id (a
    /// connection it dials replaces the old one at both ends, by the node's rule for two
    /// connections to one peer); again every base resend interval while the silence lasts,
    /// for at most [`PING_FOR_MICROS`] of silence (the transport's idle timeout ends it by
    /// then).
    Stalled {
        /// How long a new connection's handshake may take before a fresh one does better than
        /// the transport's retries of a lost first packet: two base resend intervals, at least
        /// [`MIN_REDIAL_HANDSHAKE_MICROS`].
        handshake_micros: u64,
        /// True from the second of a silence on: the first is for the transport to note what
        /// it has received, so that it dials only if nothing came since (a remote that is
        /// busy, not cut off, still acknowledges packets below the sync).
        again: bool,
        /// True when the remote is heard but shows it hears nothing of ours: its pings keep
        /// coming (it pings only while it hears nothing from us and batches to us wait), or
        /// its hellos say it never saw ours. Our sends wait in the transport (after an outage,
        /// on a backed-off probe) while packets still come in, so the transport dials at once.
        unheard: bool,
    },
    /// The remote spoke after a silence of at least [`MIN_STALL_MICROS`]: the network
    /// between us may be back after an outage or a partition, so the node dials at once the
    /// peers it has no connection to (its lost peers and its finders' rounds), rather than at
    /// its next rounds. Said by both ends, at most once a silence.
    Resumed {
        /// How long the remote was silent.
        silence_micros: u64,
    },
    /// The scene check asks something of the scene's owner ([`crate::sync::scene`]);
    /// [`Peer`](crate::peer::Peer) hands these out on their own queue
    /// ([`Peer::poll_scene_event`](crate::peer::Peer::poll_scene_event)).
    Scene(SceneEvent),
    /// The connection is over; drop this state.
    Closed(CloseReason),
}

/// Why an ephemeral value was not queued.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EphemeralError {
    /// Over [`MAX_EPHEMERAL_BYTES`].
    #[error("ephemeral value of {0} bytes, over the limit {MAX_EPHEMERAL_BYTES}")]
    TooLarge(usize),
    /// Over [`MAX_EPHEMERAL_CHANNELS`].
    #[error("more than {MAX_EPHEMERAL_CHANNELS} ephemeral channels")]
    TooManyChannels,
}

/// Counters for one connection.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SyncStats {
    /// Rejections by kind.
    pub rejected: BTreeMap<RejectKind, u64>,
    /// Messages received (accepted or not).
    pub n_messages_in: u64,
    /// Messages sent.
    pub n_messages_out: u64,
    /// Bytes received.
    pub n_bytes_in: u64,
    /// Bytes sent.
    pub n_bytes_out: u64,
    /// Ops sent (resends included).
    pub n_ops_out: u64,
    /// Ops received (duplicates included).
    pub n_ops_in: u64,
    /// Ops delivered to the log by this connection's input (including pending ops it freed).
    pub n_ops_delivered: u64,
    /// New ops skipped unread, their signatures unchecked, because the full pending buffer
    /// would have dropped them at once ([`Log::pending_drops`]).
    pub n_ops_unread: u64,
    /// Version-vector entries from the remote that were not kept: claims on authors the local
    /// log does not hold beyond [`MAX_REMOTE_UNKNOWN_AUTHORS`], and wants for authors it does
    /// not hold (an honest remote wants only what this peer's haves named).
    pub n_claims_dropped: u64,
    /// Claims withdrawn because the remote, asked, sent nothing ([`CLAIM_WITHDRAWN_MICROS`]).
    pub n_claims_withdrawn: u64,
    /// Ops asked for by id ([`Message::WantOps`], [`STUCK_DEP_MICROS`]).
    pub n_ops_asked: u64,
    /// Ops sent because the remote's have named another op at their seq: a fork
    /// ([`Message::Have`]'s tips).
    pub n_tips_differ: u64,
    /// Ops the remote asked for by id that were not sent: not held, or over [`MAX_ASKED_OUT`].
    pub n_asks_dropped: u64,
    /// New ops from the remote dropped unread over [`MAX_RECEIVED_OP_BYTES_PER_SEC`].
    pub n_ops_over_quota: u64,
    /// Hellos dropped unanswered over [`MAX_HELLO_ANSWERS_PER_SEC`].
    pub n_hellos_unanswered: u64,
    /// What the scene check found ([`crate::sync::scene`]).
    pub scene: SceneStats,
}

impl SyncStats {
    /// Total rejections of every kind.
    pub fn n_rejected(&self) -> u64 {
        self.rejected.values().sum()
    }

    /// Rejections that are offences ([`RejectKind::is_offence`]): what a node cuts a
    /// connection off for.
    pub fn n_offences(&self) -> u64 {
        (self.rejected.iter())
            .filter(|(kind, _)| kind.is_offence())
            .map(|(_, n)| n)
            .sum()
    }
}

/// A token bucket measured in messages, refilled from the `now` passed in. Tokens are kept in
/// millionths so that refill is exact integer arithmetic. What [`TokenBucket::charge`] takes
/// beyond the tokens is owed (at most a full bucket) and paid from the next refills.
#[derive(Clone, Debug)]
struct TokenBucket {
    tokens_micros: u64,
    debt_micros: u64,
    last: Timestamp,
    rate_per_sec: u64,
    capacity: u64,
}

impl TokenBucket {
    fn new(now: Timestamp, rate_per_sec: u64, burst: u64) -> Self {
        let capacity = burst * MICROS_PER_SEC;
        Self {
            tokens_micros: capacity,
            debt_micros: 0,
            last: now,
            rate_per_sec,
            capacity,
        }
    }

    fn refill(&mut self, now: Timestamp) {
        let elapsed = now.0.saturating_sub(self.last.0);
        self.last = self.last.max(now);
        let refill = elapsed.saturating_mul(self.rate_per_sec);
        let paid = refill.min(self.debt_micros);
        self.debt_micros -= paid;
        self.tokens_micros = (self.tokens_micros)
            .saturating_add(refill - paid)
            .min(self.capacity);
    }

    /// Refills and takes one token, owing it when there is none (a message that goes out
    /// whatever the budget: the messages after it wait until it is paid).
    fn charge(&mut self, now: Timestamp) {
        self.refill(now);
        match self.tokens_micros.checked_sub(MICROS_PER_SEC) {
            Some(left) => self.tokens_micros = left,
            None => {
                let owed = MICROS_PER_SEC - self.tokens_micros;
                self.tokens_micros = 0;
                self.debt_micros = (self.debt_micros + owed).min(self.capacity);
            }
        }
    }

    fn has_token(&self) -> bool {
        self.tokens_micros >= MICROS_PER_SEC
    }

    /// Refills and takes `n` tokens if there are as many.
    fn take_n(&mut self, now: Timestamp, n: u64) -> bool {
        self.refill(now);
        let cost = n.saturating_mul(MICROS_PER_SEC);
        let ok = self.tokens_micros >= cost;
        if ok {
            self.tokens_micros -= cost;
        }
        ok
    }

    fn spend(&mut self) {
        self.tokens_micros = self.tokens_micros.saturating_sub(MICROS_PER_SEC);
    }

    /// Refills and takes one token if there is one.
    fn take(&mut self, now: Timestamp) -> bool {
        self.refill(now);
        let ok = self.has_token();
        if ok {
            self.spend();
        }
        ok
    }

    /// When the next token is available.
    fn ready_at(&self) -> Timestamp {
        let missing = MICROS_PER_SEC.saturating_sub(self.tokens_micros) + self.debt_micros;
        self.last
            .saturating_add_micros(missing.div_ceil(self.rate_per_sec.max(1)))
    }
}

/// Settings for one connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SyncConfig {
    /// The session both peers must share.
    pub session_id: SessionId,
    /// This peer's id.
    pub local: PeerId,
    /// The origin tag for ops from this remote (unique per connection).
    pub origin: Origin,
}

/// How many bytes of new ops one connection may make this peer take: by default
/// [`MAX_RECEIVED_OP_BYTES_PER_SEC`] and [`MAX_RECEIVED_OP_BYTES_BURST`]; a harness whose logs
/// are small (the simulator) scales it down to match.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OpByteQuota {
    /// Bytes per second on average.
    pub bytes_per_sec: u64,
    /// Bytes in a burst.
    pub burst_bytes: u64,
}

impl Default for OpByteQuota {
    fn default() -> Self {
        Self {
            bytes_per_sec: MAX_RECEIVED_OP_BYTES_PER_SEC,
            burst_bytes: MAX_RECEIVED_OP_BYTES_BURST,
        }
    }
}

/// The tip of the log's op at each entry of `vv`, in order (0 where it holds none).
fn tips_of<P: Payload>(log: &Log<P>, vv: &VersionVector) -> Vec<u64> {
    (vv.iter())
        .map(|(author, seq)| tip_at(log, author, *seq))
        .collect()
}

/// What a hello says the log holds: its whole version vector with tips, for a log of at most
/// [`MAX_HELLO_HAVE_AUTHORS`] authors.
fn hello_have<P: Payload>(log: &Log<P>) -> Option<HelloHave> {
    let vv = log.version_vector();
    (vv.len() <= MAX_HELLO_HAVE_AUTHORS).then(|| HelloHave {
        tips: tips_of(log, vv),
        vv: vv.clone(),
    })
}

/// Sync with one remote peer over one connection.
#[derive(Debug)]
pub struct SyncState<P> {
    config: SyncConfig,
    remote: Option<PeerId>,
    /// The id the transport proved the remote holds, if it did: the hello must name it.
    admitted: Option<PeerId>,
    /// The remote is expelled: when the connection closes at the latest
    /// ([`EXPEL_NOTICE_MICROS`]).
    expel_notice_until: Option<Timestamp>,
    closed: bool,
    /// The remote has confirmed it saw our hello.
    hello_confirmed: bool,
    /// Messages that came before the remote's hello, with their bytes: handled once it comes.
    early: VecDeque<(Message, usize)>,
    /// A have of the remote arrived on this connection (until then the hello is sent again).
    have_learnt: bool,
    /// How much of our own ops the remote holds is known (from a have, or a want or ack that
    /// names our author): until then none of them goes out, since they may be held.
    own_known: bool,
    hello_sent_at: Option<Timestamp>,
    /// When the first hello went out, while no timer sent it again: the remote's first have
    /// answers it, which measures a round trip before any batch is acknowledged.
    hello_first_at: Option<Timestamp>,
    /// Current hello resend interval (doubles while unanswered).
    hello_resend_micros: u64,
    /// The round trip from our first hello to the have that answered it, if measured.
    hello_rtt_micros: Option<u64>,
    /// The hello resend timeout assumed until a round trip is measured here (from the peer's
    /// other connections, see [`SyncState::assume_resend_timeout`]).
    assumed_resend_micros: u64,
    /// When [`SyncState::wake`] last cut a backoff short.
    woken_at: Option<Timestamp>,
    /// What the remote is known to hold (join of its Have and Acks), within the bound on
    /// authors the log does not hold.
    remote_vv: VersionVector,
    /// An upper bound on the entries of `remote_vv` naming authors the log does not hold
    /// (exact when counted; authors only become known), and the log's author count then.
    n_unknown_claimed: usize,
    unknown_counted_at: usize,
    /// Some of the remote's claims were dropped since it last sent its full have.
    claims_dropped: bool,
    /// Claims withdrawn: the author, the seq claimed, and until when it is not learnt again.
    withdrawn: BTreeMap<PeerId, (u64, Timestamp)>,
    /// A hello went out to ask again for the remote's full have and no have came since.
    relearn_asked: bool,
    /// When to next check whether to ask again.
    relearn_check_at: Timestamp,
    /// What we sent on this connection (at least `remote_vv`).
    sent_vv: VersionVector,
    in_flight: BTreeMap<u64, Timestamp>,
    /// When the remote last said anything.
    heard_at: Timestamp,
    /// When we last pinged the remote, while it stays silent ([`Message::Ping`]).
    pinged_at: Option<Timestamp>,
    /// When the connection last said it stalled ([`Event::Stalled`]) in this silence.
    stalled_at: Option<Timestamp>,
    /// Since when, and until when last, the remote has shown it hears nothing of ours
    /// ([`SyncState::note_unheard`]).
    unheard: Option<(Timestamp, Timestamp)>,
    /// When this connection opened, and our first hello went out.
    opened_at: Timestamp,
    /// Current batch resend interval (doubles on each resend without an ack in between).
    resend_micros: u64,
    /// Smoothed round trip and its mean deviation from acked batches (RFC 6298), if measured.
    rtt_micros: Option<(u64, u64)>,
    /// Third peers' ops up to here may be relayed: what the remote asked for.
    relay_vv: VersionVector,
    /// Whether an op may go out, for the log length it was computed at; cleared whenever
    /// `sent_vv` or `relay_vv` change. Polling asks on every event of every connection, and a
    /// scan of the version vectors there dominated a 32-peer simulation.
    sendable_cache: Cell<Option<(usize, bool)>>,
    /// What this peer last told the remote it holds, and how many ops that was.
    have_sent_vv: VersionVector,
    have_sent_len: usize,
    have_sent_at: Timestamp,
    /// The log's length and the time at the last full have.
    full_have_len: usize,
    full_have_at: Timestamp,
    /// Parts of haves after the first not yet sent (each at most [`MAX_VV_AUTHORS`]); at most
    /// one full have's worth, since a have queued behind unsent parts goes out full instead.
    have_out: VecDeque<Message>,
    next_batch_no: u64,
    up_to_date: bool,
    /// Bumped whenever `remote_vv` changes (it keys `lacks_cache`).
    remote_vv_version: u64,
    /// Whether the remote is known to lack an op the log holds, for a log length and a
    /// `remote_vv_version`.
    lacks_cache: Cell<Option<(usize, u64, bool)>>,
    /// Messages received when the last repeated full have went out (see `have_due`): the
    /// next waits until the remote says something, so a silent remote gets one.
    repaired_at_messages_in: Option<u64>,
    /// Ops asked for by id on this connection (at most [`MAX_ASKED_OPS`]).
    asked: BTreeSet<OpId>,
    /// When to next look for stuck dependencies: not before this connection is
    /// [`STUCK_DEP_MICROS`] old, so what the version vectors bring after a reconnection is
    /// never asked for again by id.
    stuck_check_at: Timestamp,
    /// Ops the remote asked for by id, to send.
    asked_out: VecDeque<OpId>,
    /// The log's length when last seen (every input and timer), and since when it was so.
    stuck_log_len: Option<usize>,
    log_still_since: Timestamp,
    /// Per author the log holds, the seq at which a tip of the remote last differed from the
    /// log's op (which then went out).
    tips_answered: BTreeMap<PeerId, u64>,
    /// Per forked author, the lowest forked seq the remote showed it knows (it sent that fork's
    /// two ops, or lower ones). At most one entry per fork the log holds.
    forks_known: BTreeMap<PeerId, u64>,
    /// Per forked author, the seq of the fork last sent, when, and how long to wait for its
    /// answer before sending it again (doubling up to [`MAX_RESEND_AFTER_MICROS`]).
    forks_sent: BTreeMap<PeerId, (u64, Timestamp, u64)>,
    /// Forks whose answer did not come in time: to send again.
    forks_resend: BTreeSet<PeerId>,
    /// Forks the remote sent that await our answer.
    forks_answer: BTreeSet<PeerId>,
    /// Bumped whenever the four fields above change.
    forks_epoch: u64,
    /// The log's fork generation, `remote_vv_version` and `forks_epoch` at which no fork was
    /// left to send.
    forks_idle: Cell<Option<(u64, u64, u64)>>,
    control: VecDeque<Message>,
    events: VecDeque<Event>,
    eph_out: BTreeMap<u32, Vec<u8>>,
    eph_out_seq: u64,
    eph_in: BTreeMap<u32, u64>,
    /// Scene hashes compared with the remote's ([`crate::sync::scene`]).
    scene: SceneCheck,
    /// Limits what the remote may send us.
    bucket: TokenBucket,
    /// Limits the remote's hellos, and the full haves they cost.
    hello_bucket: TokenBucket,
    hello_answer_bucket: TokenBucket,
    /// Limits the bytes of new ops the remote makes us take.
    op_bytes_bucket: TokenBucket,
    /// Paces what we send, control included, within the remote's limit
    /// ([`MAX_SENT_MESSAGES_PER_SEC`]).
    send_bucket: TokenBucket,
    stats: SyncStats,
    payload: PhantomData<P>,
}

impl<P: Payload> SyncState<P> {
    /// Starts a connection: queues our hello.
    // tidy:table: every field's starting value.
    pub fn new(now: Timestamp, config: SyncConfig) -> Self {
        let mut state = Self {
            config,
            remote: None,
            admitted: None,
            expel_notice_until: None,
            closed: false,
            hello_confirmed: false,
            early: VecDeque::new(),
            have_learnt: false,
            own_known: false,
            hello_sent_at: None,
            hello_first_at: Some(now),
            hello_resend_micros: RESEND_AFTER_MICROS,
            hello_rtt_micros: None,
            assumed_resend_micros: RESEND_AFTER_MICROS,
            woken_at: None,
            remote_vv: VersionVector::new(),
            n_unknown_claimed: 0,
            unknown_counted_at: 0,
            claims_dropped: false,
            withdrawn: BTreeMap::new(),
            relearn_asked: false,
            relearn_check_at: now,
            sent_vv: VersionVector::new(),
            in_flight: BTreeMap::new(),
            heard_at: now,
            pinged_at: None,
            stalled_at: None,
            unheard: None,
            opened_at: now,
            resend_micros: RESEND_AFTER_MICROS,
            rtt_micros: None,
            relay_vv: VersionVector::new(),
            sendable_cache: Cell::new(None),
            have_sent_vv: VersionVector::new(),
            have_sent_len: 0,
            have_sent_at: now,
            full_have_len: 0,
            full_have_at: now,
            have_out: VecDeque::new(),
            next_batch_no: 1,
            up_to_date: false,
            remote_vv_version: 0,
            lacks_cache: Cell::new(None),
            repaired_at_messages_in: None,
            asked: BTreeSet::new(),
            stuck_check_at: now.saturating_add_micros(STUCK_DEP_MICROS),
            asked_out: VecDeque::new(),
            stuck_log_len: None,
            log_still_since: now,
            forks_known: BTreeMap::new(),
            forks_sent: BTreeMap::new(),
            forks_resend: BTreeSet::new(),
            forks_answer: BTreeSet::new(),
            tips_answered: BTreeMap::new(),
            forks_epoch: 0,
            forks_idle: Cell::new(None),
            control: VecDeque::new(),
            events: VecDeque::new(),
            eph_out: BTreeMap::new(),
            eph_out_seq: 0,
            eph_in: BTreeMap::new(),
            scene: SceneCheck::default(),
            bucket: TokenBucket::new(now, MAX_MESSAGES_PER_SEC, MAX_MESSAGE_BURST),
            hello_bucket: TokenBucket::new(now, MAX_HELLOS_PER_SEC, MAX_HELLO_BURST),
            hello_answer_bucket: TokenBucket::new(
                now,
                MAX_HELLO_ANSWERS_PER_SEC,
                MAX_HELLO_ANSWER_BURST,
            ),
            op_bytes_bucket: TokenBucket::new(
                now,
                MAX_RECEIVED_OP_BYTES_PER_SEC,
                MAX_RECEIVED_OP_BYTES_BURST,
            ),
            send_bucket: TokenBucket::new(now, MAX_SENT_MESSAGES_PER_SEC, MAX_SENT_MESSAGE_BURST),
            stats: SyncStats::default(),
            payload: PhantomData,
        };
        state.queue_hello(now);
        state
    }

    /// The remote's peer id, once its hello arrived.
    pub fn remote(&self) -> Option<PeerId> {
        self.remote
    }

    /// The transport proved that the remote holds `peer` (its admission): a hello naming
    /// another id closes the connection ([`CloseReason::NotAdmitted`]) before anything the
    /// remote sent is handled, the data it sent ahead of its hello included. Call it before
    /// any input.
    pub fn set_admitted(&mut self, peer: PeerId) {
        self.admitted = Some(peer);
    }

    /// Replaces the connection's quota of new op bytes (full again from `now`).
    pub fn set_op_byte_quota(&mut self, now: Timestamp, quota: OpByteQuota) {
        self.op_bytes_bucket = TokenBucket::new(now, quota.bytes_per_sec, quota.burst_bytes);
    }

    /// True once the connection was closed.
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// What the remote is known to hold.
    pub fn remote_version_vector(&self) -> &VersionVector {
        &self.remote_vv
    }

    /// Counters for this connection.
    pub fn stats(&self) -> &SyncStats {
        &self.stats
    }

    /// How long an answer is waited for on this connection before acting without it, once a
    /// round trip was measured here: [`RESEND_DEVIATIONS`] above the smoothed round trip of
    /// acknowledged batches or, before the first, the same from the round trip of the first
    /// hello taken as RFC 6298's first sample (1.75 times it), between
    /// [`MIN_RESEND_AFTER_MICROS`] and [`RESEND_AFTER_MICROS`]; `None` before.
    pub fn resend_timeout(&self) -> Option<u64> {
        // The smoothed round trip and twice its mean deviation; RFC 6298's first sample is
        // the round trip, and half of it as the deviation.
        let first = || self.hello_rtt_micros.map(|rtt| (rtt, rtt));
        let (srtt, twice_var) = (self.rtt_micros)
            .map(|(srtt, var)| (srtt, var.saturating_mul(2)))
            .or_else(first)?;
        let (n, d) = RESEND_DEVIATIONS;
        let timeout = srtt.saturating_add(twice_var.saturating_mul(n) / (2 * d));
        Some(timeout.clamp(MIN_RESEND_AFTER_MICROS, RESEND_AFTER_MICROS))
    }

    /// How long a batch or an unanswered hello waits before it goes again (before any
    /// backoff): [`SyncState::resend_timeout`] or, before a round trip was measured here, what
    /// the peer's other connections measured ([`SyncState::assume_resend_timeout`];
    /// [`RESEND_AFTER_MICROS`] without any). The first batches of a connection often carry
    /// what a peer back from a partition or a crash lacks, and one lost there would otherwise
    /// cost a whole second.
    fn base_resend_micros(&self) -> u64 {
        self.resend_timeout().unwrap_or(self.assumed_resend_micros)
    }

    /// Until a round trip is measured here, waits `micros` (clamped to the resend bounds)
    /// instead of [`RESEND_AFTER_MICROS`] before sending the hello again: a peer passes what
    /// its other connections measured, so a lost hello on a new connection costs about a
    /// round trip, not a second. A hello timeout that backed off keeps its backoff.
    pub fn assume_resend_timeout(&mut self, micros: u64) {
        let micros = micros.clamp(MIN_RESEND_AFTER_MICROS, RESEND_AFTER_MICROS);
        if self.resend_timeout().is_some() {
            return;
        }
        if self.hello_resend_micros == self.assumed_resend_micros {
            self.hello_resend_micros = micros;
        }
        if self.resend_micros == self.assumed_resend_micros {
            self.resend_micros = micros;
        }
        self.assumed_resend_micros = micros;
    }

    fn queue_hello(&mut self, now: Timestamp) {
        self.control.push_back(Message::Hello {
            protocol_version: PROTOCOL_VERSION,
            session_id: self.config.session_id,
            peer: self.config.local,
            hello_seen: self.remote.is_some(),
            // Filled in with what the log holds when it goes out (`next_message`).
            have: None,
        });
        self.hello_sent_at = Some(now);
    }

    /// Counts an op of the remote's dropped because the pending buffer was full: no offence
    /// ([`RejectKind::is_offence`]), so no event either, which a backlog's stream would raise
    /// by the thousand.
    fn count_dropped_full(&mut self) {
        *self
            .stats
            .rejected
            .entry(RejectKind::PendingFull)
            .or_insert(0) += 1;
    }

    fn reject(&mut self, kind: RejectKind, detail: String) {
        *self.stats.rejected.entry(kind).or_insert(0) += 1;
        self.events.push_back(Event::Rejected { kind, detail });
    }

    fn close(&mut self, reason: CloseReason) {
        self.closed = true;
        self.control.clear();
        self.events.push_back(Event::Closed(reason));
    }

    /// What the remote is known to hold that `log` lacks: what a lone connection would
    /// [`SyncState::want`] ([`Peer`](crate::peer::Peer) chooses among its connections instead).
    pub fn lacking(&self, log: &Log<P>) -> VersionVector {
        let mut lacking = VersionVector::new();
        for (author, seq) in self.remote_vv.iter() {
            if *seq > log.version_vector().get(author) {
                lacking.raise(*author, *seq);
            }
        }
        lacking
    }

    /// Asks the remote to relay third peers' ops up to `vv`, in as many wants as it takes,
    /// each saying how much of those authors `log` holds.
    pub fn want(&mut self, vv: VersionVector, log: &Log<P>) {
        if self.remote.is_some() && !self.closed && !vv.is_empty() {
            let with_held = |vv: VersionVector| {
                let held = (vv.iter())
                    .map(|(author, _)| {
                        let seq = log.version_vector().get(author);
                        (seq, tip_at(log, author, seq))
                    })
                    .collect();
                Message::Want { vv, held }
            };
            (self.control).extend(vv.split(MAX_VV_AUTHORS).into_iter().map(with_held));
        }
    }

    /// The scene's owner folded the log to the cut named `at` ([`crate::sync::scene`]): the
    /// hash goes to the remote at the next quiescent point, and is compared with the remote's
    /// at the next timeout.
    pub fn set_local_scene(&mut self, at: SceneAt) {
        self.scene.set_local(at);
    }

    /// The owner's per-object hashes at `cut`, after a mismatch there
    /// ([`SceneEvent::Mismatch`]).
    pub fn set_local_object_hashes(&mut self, cut: [u8; DIGEST_BYTES], hashes: &Arc<ObjectHashes>) {
        self.scene.set_local_objects(cut, hashes, &mut self.events);
        self.stats.scene.clone_from(&self.scene.stats);
    }

    /// Queues the latest value on an ephemeral channel, replacing any unsent older value.
    pub fn send_ephemeral(&mut self, channel: u32, value: Vec<u8>) -> Result<(), EphemeralError> {
        if value.len() > MAX_EPHEMERAL_BYTES {
            return Err(EphemeralError::TooLarge(value.len()));
        }
        if !self.eph_out.contains_key(&channel) && self.eph_out.len() >= MAX_EPHEMERAL_CHANNELS {
            return Err(EphemeralError::TooManyChannels);
        }
        self.eph_out.insert(channel, value);
        Ok(())
    }

    /// News that the network carries ops again (the log grew through another connection, say
    /// after a partition healed): an unanswered hello that backed off while the remote was
    /// silent goes out again on the base interval instead of waiting up to
    /// [`MAX_RESEND_AFTER_MICROS`]. Both ends of a connection whose hellos were lost back off
    /// alike, and nothing else would wake them. At most once per [`RESEND_AFTER_MICROS`], so a
    /// dead remote still costs a bounded trickle of hellos however busy the other connections
    /// are. (Batches are left to back off: the remote's next have resets them, and resending
    /// them into a partition costs far more than a hello.)
    pub fn wake(&mut self, now: Timestamp) {
        let base = self.base_resend_micros();
        let stalled = self.hello_due().is_some() && self.hello_resend_micros > base;
        let rested =
            (self.woken_at).is_none_or(|t| now.0 >= t.0.saturating_add(RESEND_AFTER_MICROS));
        if self.closed || !stalled || !rested {
            return;
        }
        self.woken_at = Some(now);
        self.hello_resend_micros = base;
    }

    /// Handles one message received from the remote.
    pub fn handle_input(&mut self, now: Timestamp, bytes: &[u8], log: &mut Log<P>) {
        self.close_if_expelled(now, log);
        let generation = log.forks().generation();
        self.read_input(now, bytes, log);
        self.observe_log(now, log);
        // Forks this input revealed or lowered: two ops it carried as a fork, or an op that
        // forks a held one.
        if log.forks().generation() != generation {
            for (author, seq) in log.forks().changed_since(generation) {
                self.events.push_back(Event::Forked { author, seq });
            }
            // An op refused before its author's fork was known (checked against the wrong
            // side's previous op) that the log no longer keeps may be delivered now: it can be
            // asked for again.
            self.asked.clear();
        }
        self.close_if_expelled(now, log);
    }

    /// Closes the connection when `log` says the founder expelled this peer (at once: it
    /// syncs with nobody) or the remote: then once the remote is known to hold everything
    /// `log` holds, the expel among it, or [`EXPEL_NOTICE_MICROS`] after this peer first
    /// saw the expel here, whichever comes first (its ops after the expel are void anyway).
    pub fn close_if_expelled(&mut self, now: Timestamp, log: &Log<P>) {
        if self.closed || log.expelled().is_empty() {
            return;
        }
        let local = self.config.local;
        if log.is_expelled(&local) {
            return self.close(CloseReason::Expelled { peer: local });
        }
        let Some(remote) = self.remote.filter(|r| log.is_expelled(r)) else {
            return;
        };
        let until = *(self.expel_notice_until)
            .get_or_insert_with(|| now.saturating_add_micros(EXPEL_NOTICE_MICROS));
        if now >= until || self.remote_vv.dominates(log.version_vector()) {
            self.close(CloseReason::Expelled { peer: remote });
        }
    }

    fn read_input(&mut self, now: Timestamp, bytes: &[u8], log: &mut Log<P>) {
        if self.closed {
            return;
        }
        self.stats.n_messages_in += 1;
        self.stats.n_bytes_in += bytes.len() as u64;
        let silence = now.0.saturating_sub(self.heard_at.0);
        self.heard_at = now;
        if !self.bucket.take(now) {
            self.reject(
                RejectKind::RateLimited,
                format!("{} bytes dropped", bytes.len()),
            );
            return;
        }
        if silence >= MIN_STALL_MICROS {
            let event = Event::Resumed {
                silence_micros: silence,
            };
            self.events.push_back(event);
        }
        let message = match Message::decode(bytes) {
            Ok(m) => m,
            Err(e) => {
                self.reject(RejectKind::of_decode_error(&e), e.to_string());
                return;
            }
        };
        match message {
            Message::Hello { .. } if !self.hello_bucket.take(now) => {
                self.reject(
                    RejectKind::RepeatedHello,
                    format!("a hello over {MAX_HELLOS_PER_SEC} a second"),
                );
            }
            // Every hello costs a full have: past the allowance none is answered, and the
            // remote, if honest, sends it again.
            Message::Hello { .. } if !self.hello_answer_bucket.take(now) => {
                self.stats.n_hellos_unanswered += 1;
            }
            Message::Hello {
                protocol_version,
                session_id,
                peer,
                hello_seen,
                have,
            } => {
                self.on_hello(now, protocol_version, session_id, peer, hello_seen, log);
                self.after_hello(now, peer, have, log);
            }
            message if self.remote.is_none() => self.hold_early(message, bytes.len()),
            message => self.on_message(now, silence, message, log),
        }
    }

    /// After the remote's hello (from `peer`, with `have`) was handled: what it held then is
    /// learnt as from a have once the hello is accepted, so our own ops and wants may go at
    /// once, not a round trip later when its answer to our hello comes (it does not stop our
    /// hello: only a have says the remote saw that); then the messages held for the hello.
    fn after_hello(
        &mut self,
        now: Timestamp,
        peer: PeerId,
        have: Option<HelloHave>,
        log: &mut Log<P>,
    ) {
        if let Some(have) = have
            && !self.closed
            && self.remote == Some(peer)
        {
            self.own_known = true;
            self.learn_remote(now, &have.vv, log);
            self.compare_tips(&have.vv, &have.tips, log);
        }
        while self.remote.is_some()
            && !self.closed
            && let Some((message, _)) = self.early.pop_front()
        {
            self.on_message(now, 0, message, log);
        }
    }

    /// A message of `n_bytes` before the remote's hello: held until the hello comes (a lost
    /// hello is sent again; data sent behind it need not be), within bounds; the rest is
    /// dropped.
    fn hold_early(&mut self, message: Message, n_bytes: usize) {
        let held: usize = self.early.iter().map(|(_, n)| n).sum();
        if self.early.len() < MAX_EARLY_MESSAGES && held + n_bytes <= MAX_EARLY_BYTES {
            self.early.push_back((message, n_bytes));
        } else {
            self.reject(RejectKind::BeforeHello, "data before hello".into());
        }
        // The remote answers a hello of ours whose own hello was lost, maybe during a
        // partition: ours goes out again on the base interval (it answers with its own), not
        // a backed-off one.
        self.hello_resend_micros = self.base_resend_micros();
    }

    /// A message other than a hello, once the remote's hello has arrived, after `silence`.
    fn on_message(&mut self, now: Timestamp, silence: u64, message: Message, log: &mut Log<P>) {
        match message {
            Message::Ping => self.note_unheard(now),
            // Answers to what we sent: the remote hears us.
            Message::Ack { .. } | Message::Pong | Message::Want { .. } => self.unheard = None,
            _ => {}
        }
        // A ping, or the first word after a silence while we pinged: the link carries
        // messages again, and what each end holds may have moved on while it did not
        // (a partition). At most one full have per `HAVE_EVERY_MICROS`, and none for a
        // remote that talks without acknowledging, so neither pings nor chatter can
        // make us send more than a trickle.
        let base = self.base_resend_micros();
        let pinged = self.pinged_at.take().is_some() && silence >= base;
        let rested = now.0 >= (self.full_have_at.0).saturating_add(HAVE_EVERY_MICROS);
        if (matches!(message, Message::Ping) || pinged) && rested {
            self.send_full_have(now, log);
        } else if matches!(message, Message::Ping) {
            // A have went out less than an interval ago: the pinger only needs to
            // hear that the link carries messages again.
            self.control.push_back(Message::Pong);
        }
        self.handle_message(now, message, log);
        // The remote speaks, maybe again after a partition healed: what it has not
        // acknowledged, our hello included, goes out again on the base interval, not
        // a backed-off one (measured with what this message taught, such as the round
        // trip of a have answering our hello).
        self.resend_micros = self.base_resend_micros();
        self.hello_resend_micros = self.base_resend_micros();
    }

    /// Handles a decoded message other than a hello, once the remote's hello has arrived.
    fn handle_message(&mut self, now: Timestamp, message: Message, log: &mut Log<P>) {
        match message {
            // Hellos are handled by `handle_input` before the remote is known.
            Message::Hello { .. } => {}
            Message::Have { vv, tips } => self.on_have(now, &vv, &tips, log),
            Message::Want { vv, held } => {
                self.hello_confirmed = true;
                self.on_want(now, &vv, &held, log);
            }
            // An expelled remote is only told (see `EXPEL_NOTICE_MICROS`): its ops are void.
            Message::Ops { .. } | Message::Forked { .. } if self.expel_notice_until.is_some() => {
                self.hello_confirmed = true;
            }
            Message::Ops { batch_no, ops } => {
                self.hello_confirmed = true;
                self.on_ops(now, batch_no, ops, log);
            }
            Message::Ack { batch_no, have } => self.on_ack(now, batch_no, &have, log),
            Message::Ephemeral {
                channel,
                seq,
                value,
            } => self.on_ephemeral(channel, seq, value),
            Message::Forked { ops, answer } => {
                self.hello_confirmed = true;
                self.on_forked(now, ops, answer, log);
            }
            Message::Ping | Message::Pong => self.hello_confirmed = true,
            Message::SceneHash(at) => {
                self.scene.on_remote_hash(now, at, &mut self.events);
                self.stats.scene.clone_from(&self.scene.stats);
            }
            Message::ObjectHashes(part) => {
                self.scene.on_part(now, part, &mut self.events);
                self.stats.scene.clone_from(&self.scene.stats);
            }
            Message::WantOps(ids) => {
                self.hello_confirmed = true;
                for id in ids {
                    if log.contains(&id)
                        && self.asked_out.len() < MAX_ASKED_OUT
                        && !self.asked_out.contains(&id)
                    {
                        self.asked_out.push_back(id);
                    } else {
                        self.stats.n_asks_dropped += 1;
                    }
                }
            }
        }
    }

    /// A have: the remote's version vector `vv` with its `tips`.
    fn on_have(&mut self, now: Timestamp, vv: &VersionVector, tips: &[u64], log: &mut Log<P>) {
        self.hello_confirmed = true;
        self.have_learnt = true;
        self.own_known = true;
        // The first have answers our first hello, unless a timer sent that again: then which
        // one it answers is unknown (Karn's rule), and nothing is measured.
        if let Some(at) = self.hello_first_at.take() {
            self.hello_rtt_micros = Some(now.0.saturating_sub(at.0));
        }
        // Taken as the answer to a hello sent to relearn (a have crossing it on the way only
        // delays the relearning until the remote's next full have).
        self.relearn_asked = false;
        self.learn_remote(now, vv, log);
        self.compare_tips(vv, tips, log);
    }

    /// An ack of our batch `batch_no`, with what the remote holds now.
    fn on_ack(&mut self, now: Timestamp, batch_no: u64, have: &VersionVector, log: &mut Log<P>) {
        self.hello_confirmed = true;
        self.own_known |= have.get(&self.config.local) > 0;
        if let Some(sent_at) = self.in_flight.remove(&batch_no) {
            self.measure_rtt(now.0.saturating_sub(sent_at.0));
            self.resend_micros = self.base_resend_micros();
        }
        self.learn_remote(now, have, log);
    }

    /// An ephemeral value: latest wins per channel, within [`MAX_EPHEMERAL_CHANNELS`].
    fn on_ephemeral(&mut self, channel: u32, seq: u64, value: Vec<u8>) {
        let last = self.eph_in.get(&channel).copied();
        let fresh = last.is_none_or(|l| seq > l);
        if fresh && (last.is_some() || self.eph_in.len() < MAX_EPHEMERAL_CHANNELS) {
            self.eph_in.insert(channel, seq);
            self.events.push_back(Event::Ephemeral { channel, value });
        } else if !fresh {
            // An older or duplicated value: latest wins, so it is simply dropped.
        } else {
            self.reject(
                RejectKind::EphemeralTooLarge,
                "too many ephemeral channels".into(),
            );
        }
    }

    /// Two ops offered as a fork ([`crate::fork`]): if they are one (an author, a seq, two
    /// ids) of an author the log holds, and lower than any fork of it the log holds, both are
    /// inserted like any received ops (their signatures checked there), so this peer holds
    /// both sides and reaches the same verdicts. A repeated or irrelevant one costs two hashes.
    /// It is answered (unless it is an answer) with the log's fork of that author, so the
    /// sender knows it arrived.
    fn on_forked(&mut self, now: Timestamp, ops: [Vec<u8>; 2], answer: bool, log: &mut Log<P>) {
        let (author, seq) = match (Envelope::parse(&ops[0]), Envelope::parse(&ops[1])) {
            (Ok(a), Ok(b))
                if a.author() == b.author() && a.seq() == b.seq() && a.id() != b.id() =>
            {
                (a.author(), a.seq())
            }
            (Err(e), _) | (_, Err(e)) => {
                return self.reject(RejectKind::BadForkProof, e.to_string());
            }
            _ => {
                return self.reject(
                    RejectKind::BadForkProof,
                    "the two ops are not one author's with one seq".into(),
                );
            }
        };
        if log.version_vector().get(&author) == 0 {
            return;
        }
        if !log.forks().covers(&author, seq) {
            self.insert_received(now, &ops, log, &mut Vec::new());
        }
        // Whoever sent two good ops knows that fork. Only authors with a fork here are noted,
        // so the maps stay within the log's forks.
        if log.forks().contains(&author) {
            let known = self.forks_known.entry(author).or_insert(seq);
            *known = (*known).min(seq);
            if !answer {
                self.forks_answer.insert(author);
            }
            self.forks_epoch += 1;
        }
    }

    fn on_hello(
        &mut self,
        now: Timestamp,
        protocol_version: u64,
        session_id: SessionId,
        peer: PeerId,
        hello_seen: bool,
        log: &Log<P>,
    ) {
        if protocol_version != PROTOCOL_VERSION {
            self.reject(
                RejectKind::WrongProtocol,
                format!("protocol {protocol_version}"),
            );
            self.close(CloseReason::WrongProtocol {
                remote: protocol_version,
            });
            return;
        }
        if session_id != self.config.session_id {
            self.reject(RejectKind::WrongSession, "another session".into());
            self.close(CloseReason::WrongSession);
            return;
        }
        if let Some(admitted) = self.admitted
            && peer != admitted
        {
            self.reject(
                RejectKind::WrongPeer,
                format!("{peer}, admitted {admitted}"),
            );
            self.close(CloseReason::NotAdmitted { claimed: peer });
            return;
        }
        match self.remote {
            Some(known) if known != peer => {
                self.reject(RejectKind::WrongPeer, format!("{peer} after {known}"));
                return;
            }
            Some(_) => {}
            None => {
                self.remote = Some(peer);
                self.events.push_back(Event::Connected { peer });
            }
        }
        // Every hello is answered with a full Have: it tells the remote what we hold and
        // confirms we saw its hello (so it stops resending). A Have is never answered, so this
        // cannot loop, and the full haves hellos cost are limited (`MAX_HELLO_ANSWERS_PER_SEC`).
        self.send_full_have(now, log);
        self.hello_confirmed |= hello_seen;
        let answerable = (self.opened_at).saturating_add_micros(2 * self.base_resend_micros());
        if hello_seen {
            self.unheard = None;
        } else if now >= answerable {
            self.note_unheard(now);
        }
        let hello_queued = (self.control.iter()).any(|m| matches!(m, Message::Hello { .. }));
        if !hello_seen && !hello_queued {
            // The remote has not seen our hello yet: answer once (its resend timer repeats).
            self.queue_hello(now);
        }
    }

    /// Queues everything the log holds as a have (replacing parts not yet sent).
    fn send_full_have(&mut self, now: Timestamp, log: &Log<P>) {
        self.queue_have(log.version_vector(), true, log);
        self.have_sent_vv = log.version_vector().clone();
        self.have_sent_len = log.len();
        self.have_sent_at = now;
        self.full_have_len = log.len();
        self.full_have_at = now;
    }

    /// Queues a have in parts, each entry with the tip of the log's op there; a full one
    /// replaces parts not yet sent. The first part goes out at once as control (it may confirm
    /// a hello); the others are paced like data, so a log of any size is announced within the
    /// remote's rate limit.
    fn queue_have(&mut self, have: &VersionVector, full: bool, log: &Log<P>) {
        if full {
            self.control.retain(|m| !matches!(m, Message::Have { .. }));
            self.have_out.clear();
        }
        let with_tips = |vv: VersionVector| Message::Have {
            tips: tips_of(log, &vv),
            vv,
        };
        let mut parts = have.split(MAX_VV_AUTHORS).into_iter().map(with_tips);
        if let Some(first) = parts.next() {
            self.control.push_back(first);
        }
        self.have_out.extend(parts);
    }

    /// Compares the tips of a have with the log's ops at the same seqs: where the log holds
    /// another op, the two are a fork nobody may have built on (so nobody would ask for
    /// either), and the log's op goes to the remote as if asked for. The remote then holds
    /// both, and sends the fork back ([`crate::fork`]). Seqs at or past a fork the log knows
    /// are skipped: that fork goes out anyway.
    fn compare_tips(&mut self, vv: &VersionVector, tips: &[u64], log: &Log<P>) {
        for ((author, seq), their) in vv.iter().zip(tips) {
            if *their == 0 || log.forks().covers(author, *seq) {
                continue;
            }
            let Some(op) = log.by_seq(author, *seq) else {
                continue;
            };
            let id = op.id();
            // Once per author and seq: a remote repeating a wrong tip gets nothing more.
            if tip(&id) != *their
                && self.tips_answered.get(author) != Some(seq)
                && self.asked_out.len() < MAX_ASKED_OUT
            {
                self.stats.n_tips_differ += 1;
                self.tips_answered.insert(*author, *seq);
                self.asked_out.push_back(id);
            }
        }
    }

    /// Joins what the remote says it holds into what it is known to hold, keeping at most
    /// [`MAX_REMOTE_UNKNOWN_AUTHORS`] authors the log does not hold.
    fn learn_remote(&mut self, now: Timestamp, vv: &VersionVector, log: &Log<P>) {
        let held = log.version_vector();
        let mut n_dropped = 0u64;
        for (author, seq) in vv.iter() {
            if let Some((claimed, until)) = self.withdrawn.get(author) {
                if now < *until && seq <= claimed {
                    n_dropped += 1;
                    continue;
                }
                self.withdrawn.remove(author);
            }
            let unknown = held.get(author) == 0 && self.remote_vv.get(author) == 0;
            if unknown && !self.room_for_unknown(held) {
                n_dropped += 1;
                continue;
            }
            self.n_unknown_claimed += usize::from(unknown);
            self.remote_vv.raise(*author, *seq);
            self.remote_vv_version += 1;
            self.sent_vv.raise(*author, *seq);
        }
        if n_dropped > 0 {
            self.stats.n_claims_dropped += n_dropped;
            if !self.claims_dropped {
                self.claims_dropped = true;
                self.relearn_check_at = now.saturating_add_micros(RELEARN_CHECK_MICROS);
            }
        }
        self.sendable_cache.set(None);
        self.update_up_to_date(log);
    }

    /// Withdraws the remote's claim to hold more of `author` than the log does: the remote
    /// was asked for those ops and sent none (see [`CLAIM_WITHDRAWN_MICROS`]). What it is
    /// known to hold of that author becomes what the log holds, so nothing more is asked of it
    /// or waited for on its account; nothing is sent either, since that is no more than the
    /// remote holds.
    pub fn withdraw_claim(&mut self, now: Timestamp, author: &PeerId, log: &Log<P>) {
        let held = log.version_vector().get(author);
        let claimed = self.remote_vv.get(author);
        if claimed <= held {
            return;
        }
        self.remote_vv.set(*author, held);
        self.remote_vv_version += 1;
        self.sent_vv
            .set(*author, self.sent_vv.get(author).min(held));
        if held == 0 {
            self.n_unknown_claimed = self.n_unknown_claimed.saturating_sub(1);
        }
        self.stats.n_claims_withdrawn += 1;
        if self.withdrawn.len() < MAX_WITHDRAWN_CLAIMS || self.withdrawn.contains_key(author) {
            let until = now.saturating_add_micros(CLAIM_WITHDRAWN_MICROS);
            self.withdrawn.insert(*author, (claimed, until));
        } else {
            // Full: forget the expired entries to make room next time.
            self.withdrawn.retain(|_, (_, until)| now < *until);
        }
        self.sendable_cache.set(None);
        self.update_up_to_date(log);
    }

    /// True if `remote_vv` may name one more author the log does not hold. Recounts only when
    /// the log gained authors since the last count (only that can lower the count), so a
    /// remote that keeps claiming strangers costs one scan per author the log gains.
    fn room_for_unknown(&mut self, held: &VersionVector) -> bool {
        if self.n_unknown_claimed >= MAX_REMOTE_UNKNOWN_AUTHORS
            && self.unknown_counted_at != held.len()
        {
            self.unknown_counted_at = held.len();
            self.n_unknown_claimed = self
                .remote_vv
                .iter()
                .filter(|(author, _)| held.get(author) == 0)
                .count();
        }
        self.n_unknown_claimed < MAX_REMOTE_UNKNOWN_AUTHORS
    }

    /// The remote asks for third peers' ops. Only authors the log holds are kept: those are
    /// all an honest remote asks for (it saw them in this peer's haves). What it says it holds
    /// of them is learnt first, so the relay starts there.
    fn on_want(&mut self, now: Timestamp, vv: &VersionVector, held: &[(u64, u64)], log: &Log<P>) {
        let mut holds = VersionVector::new();
        let mut tips = Vec::new();
        for ((author, _), (seq, tip)) in vv.iter().zip(held) {
            if *seq > 0 && log.version_vector().get(author) > 0 {
                holds.raise(*author, *seq);
                tips.push(*tip);
            }
        }
        if !holds.is_empty() {
            // As for a have: where the remote holds another op at a seq than the log does,
            // the two are a fork, and the log's goes out.
            self.learn_remote(now, &holds, log);
            self.compare_tips(&holds, &tips, log);
        }
        if vv.get(&self.config.local) > 0 {
            self.own_known = true;
        }
        for (author, seq) in vv.iter() {
            if log.version_vector().get(author) == 0 {
                self.stats.n_claims_dropped += 1;
                continue;
            }
            // Asking for what was sent means it did not arrive: that author's ops go out
            // again from what the remote holds (and only that author's).
            let remote_held = self.remote_vv.get(author);
            if self.sent_vv.get(author) >= *seq && remote_held < *seq {
                self.sent_vv.set(*author, remote_held);
            }
            self.relay_vv.raise(*author, *seq);
        }
        self.sendable_cache.set(None);
    }

    /// After dropping claims, once at most half of [`MAX_REMOTE_UNKNOWN_AUTHORS`] kept claims
    /// are still missing here, asks for the remote's full have again by sending a hello (every
    /// hello is answered with one), and asks again each check until a have comes.
    fn relearn(&mut self, now: Timestamp, log: &Log<P>) {
        self.relearn_check_at = now.saturating_add_micros(RELEARN_CHECK_MICROS);
        let mut ask = self.relearn_asked;
        if self.claims_dropped {
            // Counting here finds what arrived; a later claim may then need a recount.
            let held = log.version_vector();
            self.room_for_unknown(held);
            if self.n_unknown_claimed <= MAX_REMOTE_UNKNOWN_AUTHORS / 2 {
                self.claims_dropped = false;
                ask = true;
            }
        }
        if ask {
            self.relearn_asked = true;
            self.queue_hello(now);
        }
    }

    fn relearn_due(&self) -> Option<Timestamp> {
        (self.claims_dropped || self.relearn_asked).then_some(self.relearn_check_at)
    }

    fn update_up_to_date(&mut self, log: &Log<P>) {
        let now_up_to_date = self.remote_vv.dominates(log.version_vector());
        if now_up_to_date && !self.up_to_date {
            self.events.push_back(Event::UpToDate);
        }
        self.up_to_date = now_up_to_date;
    }

    fn on_ops(&mut self, now: Timestamp, batch_no: u64, ops: Vec<Vec<u8>>, log: &mut Log<P>) {
        // The ack names only the batch's authors: what the sender needs to move on, in
        // bytes that do not grow with the number of peers.
        let mut authors = Vec::new();
        let whole = self.insert_received(now, &ops, log, &mut authors);
        // A batch cut short by the quota is not acknowledged: its sender sends it again after
        // its resend timeout, when what this peer took of it is skipped as held.
        if whole {
            let mut have = VersionVector::new();
            for author in authors {
                have.raise(author, log.version_vector().get(&author));
            }
            self.control.push_back(Message::Ack { batch_no, have });
        }
        self.update_up_to_date(log);
    }

    /// Inserts received ops into `log`, noting in `authors` the authors of those held or
    /// signed; false when [`MAX_RECEIVED_OP_BYTES_PER_SEC`] cut the ops short (the rest are
    /// dropped unread).
    fn insert_received(
        &mut self,
        now: Timestamp,
        ops: &[Vec<u8>],
        log: &mut Log<P>,
        authors: &mut Vec<PeerId>,
    ) -> bool {
        // Cheapest check first: each envelope and its id (a hash), then known ops are skipped,
        // then the signatures of the rest in one batch, and only a signed op's payload is
        // decoded and validated (which may compile formulas). A forged or replayed op never
        // costs a compile.
        let origin = self.config.origin;
        let mut fresh: Vec<Envelope<'_>> = Vec::with_capacity(ops.len());
        let mut fresh_bytes: Vec<usize> = Vec::with_capacity(ops.len());
        for bytes in ops {
            self.stats.n_ops_in += 1;
            let envelope = match Envelope::parse(bytes) {
                Ok(envelope) => envelope,
                Err(e) => {
                    self.reject(decode_reject_kind(&e), e.to_string());
                    continue;
                }
            };
            if log.contains(&envelope.id()) {
                if !authors.contains(&envelope.author()) {
                    authors.push(envelope.author());
                }
            } else if log.pending_drops(origin, &envelope.author(), envelope.seq(), envelope.id()) {
                // The full pending buffer would drop it once its signature was checked: it is
                // skipped unread and comes again, as after any eviction.
                self.stats.n_ops_unread += 1;
                self.count_dropped_full();
            } else if fresh.iter().all(|other| other.id() != envelope.id()) {
                fresh.push(envelope);
                fresh_bytes.push(bytes.len());
            }
        }
        // Only new ops cost the quota, in order: past it, the rest wait for a resend.
        let mut whole = true;
        let mut n_fresh = 0;
        for n_bytes in fresh_bytes {
            if !self.op_bytes_bucket.take_n(now, n_bytes as u64) {
                whole = false;
                break;
            }
            n_fresh += 1;
        }
        if !whole {
            self.stats.n_ops_over_quota += (fresh.len() - n_fresh) as u64;
            fresh.truncate(n_fresh);
        }
        for op in Envelope::into_verified_all::<P>(fresh, &log.session_id()) {
            match op {
                Ok(op) => {
                    if !authors.contains(&op.author()) {
                        authors.push(op.author());
                    }
                    match log.insert(now, op, self.config.origin) {
                        Ok(insertion) => self.on_insertion(insertion),
                        Err(e) => self.reject_refused(&e),
                    }
                }
                Err(ReceiveError::Verify(e)) => {
                    self.reject(RejectKind::BadSignature, e.to_string())
                }
                Err(ReceiveError::Decode(e)) => self.reject(decode_reject_kind(&e), e.to_string()),
            }
        }
        whole
    }

    /// Counts an op the log refused against the remote ([`is_offence`]).
    fn reject_refused(&mut self, e: &InsertError) {
        if is_offence(e) {
            self.reject(RejectKind::RefusedOp, e.to_string());
        }
    }

    fn on_insertion(&mut self, insertion: Insertion) {
        self.charge(&insertion);
        if !insertion.delivered.is_empty() {
            self.stats.n_ops_delivered += insertion.delivered.len() as u64;
            self.events.push_back(Event::Delivered(insertion));
        }
    }

    /// Counts against the remote what `insertion` evicted or refused of the ops it sent,
    /// whichever connection's input caused the insertion ([`crate::Peer`] hands every
    /// insertion to every connection): an op parked from this remote may be freed, and
    /// refused, by an op from another.
    pub fn charge(&mut self, insertion: &Insertion) {
        for evicted in &insertion.evicted {
            if evicted.origin == self.config.origin {
                match evicted.reason {
                    EvictReason::Full => self.count_dropped_full(),
                    EvictReason::Expired => self.reject(
                        RejectKind::PendingExpired,
                        format!("pending op {} evicted", evicted.id),
                    ),
                }
            }
        }
        for (id, origin, e) in &insertion.refused {
            if *origin == self.config.origin && is_offence(e) {
                self.reject(RejectKind::RefusedOp, format!("{id}: {e}"));
            }
        }
    }

    /// Handles the passing of time: resends unanswered hellos and unacknowledged batches,
    /// and expires pending ops whose dependencies never came.
    pub fn handle_timeout(&mut self, now: Timestamp, log: &mut Log<P>) {
        self.timeout(now, log);
        self.close_if_expelled(now, log);
    }

    fn timeout(&mut self, now: Timestamp, log: &mut Log<P>) {
        if self.closed {
            return;
        }
        for evicted in log.expire_pending(now) {
            if evicted.origin == self.config.origin {
                self.reject(
                    RejectKind::PendingExpired,
                    format!("pending op {} expired", evicted.id),
                );
            }
        }
        if self.hello_due().is_some_and(|d| d <= now) {
            self.hello_first_at = None;
            self.queue_hello(now);
            self.hello_resend_micros = (self.hello_resend_micros * 2).min(MAX_RESEND_AFTER_MICROS);
        }
        if self.resend_due().is_some_and(|d| d <= now) {
            // Rewind to what the remote acknowledged; everything after it goes out again.
            self.in_flight.clear();
            self.sent_vv = self.remote_vv.clone();
            self.sendable_cache.set(None);
            self.resend_micros = (self.resend_micros * 2).min(MAX_RESEND_AFTER_MICROS);
        }
        if self.ping_due().is_some_and(|d| d <= now) {
            self.pinged_at = Some(now);
            self.control.push_back(Message::Ping);
        }
        if self.stall_due().is_some_and(|d| d <= now) {
            let again = self.stalled_at.is_some_and(|at| at > self.heard_at);
            self.stalled_at = Some(now);
            let base = self.base_resend_micros();
            let handshake_micros = (2 * base).max(MIN_REDIAL_HANDSHAKE_MICROS);
            let event = Event::Stalled {
                handshake_micros,
                again,
                unheard: self.unheard_at(now),
            };
            self.events.push_back(event);
        }
        if self.relearn_due().is_some_and(|d| d <= now) {
            self.relearn(now, log);
        }
        self.observe_log(now, log);
        if self.stuck_due(log).is_some_and(|d| d <= now) {
            self.ask_stuck(now, log);
        }
        if self.forks_due().is_some_and(|d| d <= now) {
            let late: Vec<PeerId> = (self.forks_awaited())
                .filter(|(_, due)| *due <= now)
                .map(|(author, _)| *author)
                .collect();
            self.forks_resend.extend(late);
            self.forks_epoch += 1;
        }
        if self.have_due(log).is_some_and(|d| d <= now) {
            self.send_have(now, log);
        }
        if self.scene.due().is_some_and(|d| d <= now) {
            self.scene.timeout(now, &mut self.events);
            self.stats.scene.clone_from(&self.scene.stats);
        }
    }

    /// Queues the have that is due: the entries that moved since the last one, or a full
    /// one now and then.
    fn send_have(&mut self, now: Timestamp, log: &Log<P>) {
        // Parts of an earlier have still queued: a full have replaces them, so the queue
        // never holds more than one full have.
        let full = !self.have_out.is_empty()
            || self
                .full_have_at
                .saturating_add_micros(HAVE_FULL_EVERY_MICROS)
                <= now;
        let mut have = VersionVector::new();
        for (author, seq) in log.version_vector().iter() {
            // The remote learns what it holds of its own from its acks.
            if Some(*author) != self.remote && (full || self.have_sent_vv.get(author) < *seq) {
                have.raise(*author, *seq);
            }
        }
        self.queue_have(&have, full, log);
        self.have_sent_vv = log.version_vector().clone();
        self.have_sent_len = log.len();
        self.have_sent_at = now;
        if full {
            if self.full_have_len == log.len() {
                // A repeat while the remote seems to lack something (see `have_due`): if
                // it is our picture of the remote that is stale, its answer to a hello,
                // a full have, puts it right.
                self.queue_hello(now);
                self.repaired_at_messages_in = Some(self.stats.n_messages_in);
            } else {
                self.repaired_at_messages_in = None;
            }
            self.full_have_len = log.len();
            self.full_have_at = now;
        }
    }

    /// Notes whether the log grew since last seen (on every input and timer): a log that
    /// grows is still being brought what it lacks.
    fn observe_log(&mut self, now: Timestamp, log: &Log<P>) {
        if self.stuck_log_len != Some(log.len()) {
            self.stuck_log_len = Some(log.len());
            self.log_still_since = now;
        }
    }

    /// When to look for stuck dependencies: while ops from the remote wait, there is room to
    /// ask, and the log has not grown for [`STUCK_DEP_MICROS`] as last seen.
    fn stuck_due(&self, log: &Log<P>) -> Option<Timestamp> {
        let waiting = self.remote.is_some()
            && self.asked.len() < MAX_ASKED_OPS
            && log.n_pending_from(self.config.origin) > 0;
        let still = self.log_still_since.saturating_add_micros(STUCK_DEP_MICROS);
        waiting.then_some(self.stuck_check_at.max(still))
    }

    /// Asks the remote by id for the dependencies its ops waited for since
    /// [`STUCK_DEP_MICROS`] ago, each once on this connection (which is at least that old),
    /// once the log has not grown for as long.
    fn ask_stuck(&mut self, now: Timestamp, log: &Log<P>) {
        self.observe_log(now, log);
        let still = self.log_still_since.saturating_add_micros(STUCK_DEP_MICROS);
        let Some(before) = now.0.checked_sub(STUCK_DEP_MICROS) else {
            return;
        };
        if now < still {
            // The log grows: what it waits for may still come by the version vectors.
            return;
        }
        let room = MAX_ASKED_OPS - self.asked.len();
        let mut ids = log.stuck_deps(self.config.origin, Timestamp(before), MAX_BATCH_OPS);
        ids.retain(|id| !self.asked.contains(id));
        ids.truncate(room);
        if ids.is_empty() {
            // Nothing new to ask: look again after as long (a split stays quiet).
            self.stuck_check_at = now.saturating_add_micros(STUCK_DEP_MICROS);
            return;
        }
        self.stuck_check_at = now.saturating_add_micros(STUCK_CHECK_MICROS);
        self.stats.n_ops_asked += ids.len() as u64;
        self.asked.extend(ids.iter().copied());
        self.control.push_back(Message::WantOps(ids));
    }

    /// Folds one round-trip sample into the estimate (a batch acked without a resend in
    /// between: resends clear what is in flight, so later acks of old batches are not found).
    fn measure_rtt(&mut self, sample: u64) {
        self.rtt_micros = Some(match self.rtt_micros {
            None => (sample, sample / 2),
            Some((srtt, var)) => (
                (7 * srtt + sample) / 8,
                (3 * var + srtt.abs_diff(sample)) / 4,
            ),
        });
    }

    /// A hello goes out again until the remote's have arrives: every hello is answered with
    /// one, and until then what the remote holds is unknown.
    fn hello_due(&self) -> Option<Timestamp> {
        self.hello_sent_at
            .filter(|_| self.remote.is_none() || !self.have_learnt)
            .map(|t| t.saturating_add_micros(self.hello_resend_micros))
    }

    /// While batches wait for acknowledgement and their resends have backed off (the remote
    /// said nothing for a resend timeout or more), a ping goes out [`PINGS_PER_RESEND`] times
    /// per base interval, for at most [`PING_FOR_MICROS`] of silence.
    fn ping_due(&self) -> Option<Timestamp> {
        if self.remote.is_none() || self.in_flight.is_empty() {
            return None;
        }
        let base = self.base_resend_micros();
        if self.resend_micros <= base {
            return None;
        }
        let last = self
            .pinged_at
            .map_or(self.heard_at, |p| p.max(self.heard_at));
        let due = last.saturating_add_micros(ping_interval(base));
        (due.0 <= self.heard_at.0.saturating_add(PING_FOR_MICROS)).then_some(due)
    }

    /// The remote showed it hears nothing of ours: it pinged, or its hello says it never saw
    /// ours though ours went out two base intervals ago. Evidence more than a stall's wait
    /// after the last starts a new run.
    fn note_unheard(&mut self, now: Timestamp) {
        let after = self.stall_after_micros();
        self.unheard = match self.unheard {
            Some((since, last)) if now <= last.saturating_add_micros(after) => Some((since, now)),
            _ => Some((now, now)),
        };
    }

    /// How long a silence, or evidence that the remote hears nothing of ours, lasts before
    /// the connection stalls: [`STALL_AFTER_RESENDS`] base intervals, at least
    /// [`MIN_STALL_MICROS`].
    fn stall_after_micros(&self) -> u64 {
        (STALL_AFTER_RESENDS * self.base_resend_micros()).max(MIN_STALL_MICROS)
    }

    /// Whether the remote has shown for a stall's wait, and within a base interval of `now`,
    /// that it hears nothing of ours.
    fn unheard_at(&self, now: Timestamp) -> bool {
        let (after, base) = (self.stall_after_micros(), self.base_resend_micros());
        self.unheard.is_some_and(|(since, last)| {
            last >= since.saturating_add_micros(after) && now <= last.saturating_add_micros(base)
        })
    }

    /// When the connection next says it stalled ([`Event::Stalled`]), if the remote's id is
    /// above ours: while batches wait for acknowledgement and the remote has been silent for
    /// a stall's wait ([`SyncState::stall_after_micros`]), then every base interval, for at
    /// most [`PING_FOR_MICROS`] of silence; or once the remote's evidence that it hears nothing
    /// of ours ([`SyncState::note_unheard`]) spans a stall's wait, then every base interval
    /// while it goes on.
    fn stall_due(&self) -> Option<Timestamp> {
        let remote = self.remote?;
        if remote <= self.config.local {
            return None;
        }
        let base = self.base_resend_micros();
        let after = self.stall_after_micros();
        let next = |first: Timestamp| match self.stalled_at {
            Some(at) if at >= first => at.saturating_add_micros(base),
            _ => first,
        };
        let silent = (!self.in_flight.is_empty())
            .then(|| next(self.heard_at.saturating_add_micros(after)))
            .filter(|due| due.0 <= self.heard_at.0.saturating_add(PING_FOR_MICROS));
        let unheard = (self.unheard)
            .map(|(since, _)| next(since.saturating_add_micros(after)))
            .filter(|due| self.unheard_at(*due));
        silent.into_iter().chain(unheard).min()
    }

    fn resend_due(&self) -> Option<Timestamp> {
        self.in_flight
            .values()
            .min()
            .map(|t| t.saturating_add_micros(self.resend_micros))
    }

    /// When to announce what this peer gained since its last have, if it gained anything.
    fn have_due(&self, log: &Log<P>) -> Option<Timestamp> {
        if self.remote.is_none() || !self.hello_confirmed {
            None
        } else if self.have_sent_len < log.len() {
            Some(self.have_sent_at.saturating_add_micros(HAVE_EVERY_MICROS))
        } else if self.full_have_len < log.len() || self.repair_due(log) {
            // Also repeated, unchanged, while the remote is known to lack ops the log holds:
            // it asks for third peers' ops only when a have names them, and the have that
            // did may have been lost after the log last grew.
            Some(
                self.full_have_at
                    .saturating_add_micros(HAVE_FULL_EVERY_MICROS),
            )
        } else {
            None
        }
    }

    /// True if an unchanged full have should go out again: the remote is known to lack ops
    /// the log holds, and it said something since the last repeat (or there was none).
    fn repair_due(&self, log: &Log<P>) -> bool {
        let heard = self
            .repaired_at_messages_in
            .is_none_or(|n| self.stats.n_messages_in > n);
        heard && self.remote_lacks(log)
    }

    /// True if the remote is known to lack an op the log holds (cached per log length and
    /// change of what the remote is known to hold).
    fn remote_lacks(&self, log: &Log<P>) -> bool {
        let key = (log.len(), self.remote_vv_version);
        if let Some((len, version, lacks)) = self.lacks_cache.get()
            && (len, version) == key
        {
            return lacks;
        }
        let lacks = !self.remote_vv.dominates(log.version_vector());
        self.lacks_cache.set(Some((key.0, key.1, lacks)));
        lacks
    }

    /// When [`SyncState::handle_timeout`] should next be called.
    pub fn poll_timeout(&self, log: &Log<P>) -> Option<Timestamp> {
        if self.closed {
            return None;
        }
        let pace =
            (self.remote.is_some() && self.data_waiting(log) && !self.send_bucket.has_token())
                .then(|| self.send_bucket.ready_at());
        [
            self.hello_due(),
            self.resend_due(),
            self.ping_due(),
            self.stall_due(),
            self.have_due(log),
            self.relearn_due(),
            self.stuck_due(log),
            self.forks_due(),
            self.expel_notice_until,
            pace,
            log.next_pending_expiry(),
            self.scene.due(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// The next fork to send, and whether as an answer: first the answers owed, then a fork
    /// the remote is not known to know (or a lower one) and that was not sent, or whose answer
    /// is late, of an author the remote holds ops of (a fork of an author it does not hold
    /// would be dropped).
    fn next_fork(&self, log: &Log<P>) -> Option<(PeerId, crate::fork::Fork, bool)> {
        let forks = log.forks();
        if let Some(author) = self.forks_answer.first()
            && let Some(fork) = forks.get(author)
        {
            return Some((*author, *fork, true));
        }
        let key = (forks.generation(), self.remote_vv_version, self.forks_epoch);
        if forks.is_empty() || self.forks_idle.get() == Some(key) {
            return None;
        }
        let next = forks.iter().find(|(author, fork)| {
            let unknown = self.forks_known.get(author).is_none_or(|k| fork.seq < *k);
            let unsent = (self.forks_sent.get(author))
                .is_none_or(|(seq, _, _)| fork.seq < *seq || self.forks_resend.contains(author));
            unknown && unsent && self.remote_vv.get(author) > 0
        });
        if next.is_none() {
            self.forks_idle.set(Some(key));
        }
        next.map(|(author, fork)| (*author, *fork, false))
    }

    /// The forks sent and still awaiting their answer (not yet to be sent again), each with
    /// when it waits no longer.
    fn forks_awaited(&self) -> impl Iterator<Item = (&PeerId, Timestamp)> {
        (self.forks_sent.iter())
            .filter(|(author, (seq, _, _))| {
                !self.forks_resend.contains(*author)
                    && self.forks_known.get(*author).is_none_or(|k| k > seq)
            })
            .map(|(author, (_, at, wait))| (author, at.saturating_add_micros(*wait)))
    }

    /// When the earliest fork sent waits no longer for its answer.
    fn forks_due(&self) -> Option<Timestamp> {
        self.forks_awaited().map(|(_, due)| due).min()
    }

    /// True if haves, ephemeral values, forks or ops wait to be sent and the window has
    /// room.
    fn data_waiting(&self, log: &Log<P>) -> bool {
        !self.have_out.is_empty()
            || !self.eph_out.is_empty()
            || self.next_fork(log).is_some()
            || (self.in_flight.len() < MAX_IN_FLIGHT_BATCHES && !self.asked_out.is_empty())
            || (self.in_flight.len() < MAX_IN_FLIGHT_BATCHES && self.sendable(log))
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// The next message to send, if any: control first, then parts of haves, then ephemeral
    /// values, then op batches within the flow-control window.
    pub fn poll_transmit(&mut self, now: Timestamp, log: &Log<P>) -> Option<Vec<u8>> {
        if self.closed {
            return None;
        }
        let message = self.next_message(now, log)?;
        let bytes = message.encode();
        assert!(
            bytes.len() <= MAX_MESSAGE_BYTES,
            "outgoing message over MAX_MESSAGE_BYTES"
        );
        self.stats.n_messages_out += 1;
        self.stats.n_bytes_out += bytes.len() as u64;
        Some(bytes)
    }

    fn next_message(&mut self, now: Timestamp, log: &Log<P>) -> Option<Message> {
        if let Some(mut m) = self.control.pop_front() {
            if let Message::Hello { have, .. } = &mut m {
                *have = hello_have(log);
            }
            // Control goes out at once, and the data after it pays for it.
            self.send_bucket.charge(now);
            return Some(m);
        }
        // Nothing but control messages goes out before the remote's hello.
        self.remote?;
        // Data is paced so an honest peer stays within the remote's rate limit, control
        // included ([`MAX_SENT_MESSAGES_PER_SEC`]).
        self.send_bucket.refill(now);
        if !self.send_bucket.has_token() {
            return None;
        }
        if let Some(have) = self.have_out.pop_front() {
            self.send_bucket.spend();
            return Some(have);
        }
        if let Some(part) = self.scene.next_part() {
            self.send_bucket.spend();
            return Some(part);
        }
        if let Some((channel, value)) = self.eph_out.pop_first() {
            self.send_bucket.spend();
            self.eph_out_seq += 1;
            return Some(Message::Ephemeral {
                channel,
                seq: self.eph_out_seq,
                value,
            });
        }
        if let Some((author, fork, answer)) = self.next_fork(log) {
            if answer {
                self.forks_answer.remove(&author);
            } else {
                let wait = match self.forks_sent.get(&author) {
                    Some((seq, _, wait)) if *seq == fork.seq => {
                        (wait * 2).min(MAX_RESEND_AFTER_MICROS)
                    }
                    _ => self.base_resend_micros(),
                };
                self.forks_sent.insert(author, (fork.seq, now, wait));
                self.forks_resend.remove(&author);
            }
            self.forks_epoch += 1;
            let [a, b] = fork
                .ids
                .map(|id| log.get(&id).map(|op| op.encoded().to_vec()));
            if let (Some(a), Some(b)) = (a, b) {
                self.send_bucket.spend();
                return Some(Message::Forked {
                    ops: [a, b],
                    answer,
                });
            }
        }
        self.next_batch_or_scene_hash(now, log)
    }

    /// The next op batch within the flow-control window or, with nothing else to say at a
    /// quiescent point, the scene hash if it changed.
    fn next_batch_or_scene_hash(&mut self, now: Timestamp, log: &Log<P>) -> Option<Message> {
        if self.in_flight.len() >= MAX_IN_FLIGHT_BATCHES {
            return None;
        }
        let mut ops = self.asked_batch(log);
        if ops.is_empty() {
            ops = self.next_batch(log);
        }
        if ops.is_empty() {
            let hash = (self.scene.hash_unsent() && self.quiescent(log))
                .then(|| self.scene.take_hash())
                .flatten();
            if hash.is_some() {
                self.send_bucket.spend();
            }
            return hash;
        }
        self.send_bucket.spend();
        let batch_no = self.next_batch_no;
        self.next_batch_no += 1;
        self.in_flight.insert(batch_no, now);
        self.stats.n_ops_out += ops.len() as u64;
        Some(Message::Ops { batch_no, ops })
    }

    /// True at a quiescent point of the connection: nothing waits to be sent or acknowledged,
    /// and the remote holds what the log holds and no more, so the two scenes fold the same
    /// ops.
    fn quiescent(&self, log: &Log<P>) -> bool {
        self.remote.is_some()
            && self.have_learnt
            && self.control.is_empty()
            && self.have_out.is_empty()
            && self.in_flight.is_empty()
            && self.asked_out.is_empty()
            && self.remote_vv == *log.version_vector()
            && !self.sendable(log)
            && self.next_fork(log).is_none()
    }

    /// How far `author`'s ops may go out on this connection: all of our own, a third peer's
    /// up to what the remote asked for.
    fn send_limit(&self, author: &PeerId, held: u64) -> u64 {
        if *author == self.config.local {
            if self.own_known { held } else { 0 }
        } else {
            held.min(self.relay_vv.get(author))
        }
    }

    /// True if some op may go out that the remote is not known to hold or was not sent.
    fn sendable(&self, log: &Log<P>) -> bool {
        let sendable = match self.sendable_cache.get() {
            Some((len, sendable)) if len == log.len() => return sendable,
            // Growth of the log alone cannot take back what may go out, and of the ops it
            // added only our own may go out before the remote asks again (which clears the
            // cache).
            Some((_, true)) => true,
            Some((_, false)) => {
                let me = &self.config.local;
                self.own_known && self.sent_vv.get(me) < log.version_vector().get(me)
            }
            None => log
                .version_vector()
                .iter()
                .any(|(author, seq)| self.sent_vv.get(author) < self.send_limit(author, *seq)),
        };
        self.sendable_cache.set(Some((log.len(), sendable)));
        sendable
    }

    /// Ops the remote asked for by id, in the order asked, bounded like any batch.
    fn asked_batch(&mut self, log: &Log<P>) -> Vec<Vec<u8>> {
        let mut batch = Vec::new();
        let mut n_bytes = 0;
        while let Some(id) = self.asked_out.front() {
            let Some(op) = log.get(id) else {
                self.asked_out.pop_front();
                continue;
            };
            if batch.len() == MAX_BATCH_OPS || n_bytes + op.encoded().len() > MAX_BATCH_BYTES {
                break;
            }
            n_bytes += op.encoded().len();
            batch.push(op.encoded().to_vec());
            self.asked_out.pop_front();
        }
        batch
    }

    /// Ops the remote lacks and we have not sent, in linear order (so causally), bounded.
    fn next_batch(&mut self, log: &Log<P>) -> Vec<Vec<u8>> {
        if !self.sendable(log) {
            return Vec::new();
        }
        self.sendable_cache.set(None);
        // The first unsent op of each author bounds where the scan starts.
        let start = log
            .version_vector()
            .iter()
            .filter(|(author, seq)| self.sent_vv.get(author) < self.send_limit(author, **seq))
            .filter_map(|(author, _)| log.by_seq(author, self.sent_vv.get(author) + 1))
            .map(Op::lamport)
            .min();
        let Some(start) = start else {
            return Vec::new();
        };
        let mut batch = Vec::new();
        let mut n_bytes = 0;
        for op in log.ops_from_lamport(start) {
            let author = op.author();
            if op.seq() <= self.sent_vv.get(&author)
                || op.seq() > self.send_limit(&author, op.seq())
            {
                continue;
            }
            if batch.len() == MAX_BATCH_OPS || n_bytes + op.encoded().len() > MAX_BATCH_BYTES {
                break;
            }
            n_bytes += op.encoded().len();
            batch.push(op.encoded().to_vec());
            self.sent_vv.raise(op.author(), op.seq());
        }
        batch
    }
}

/// How often a silent remote is pinged, given the base resend interval.
fn ping_interval(base_resend_micros: u64) -> u64 {
    (base_resend_micros / PINGS_PER_RESEND).max(MIN_PING_AFTER_MICROS)
}

/// The tip of `log`'s op of `author` at `seq`, or 0 where it holds none: what a have or a
/// want says of the op at a seq it announces.
fn tip_at<P: Payload>(log: &Log<P>, author: &PeerId, seq: u64) -> u64 {
    log.by_seq(author, seq).map_or(0, |op| tip(&op.id()))
}

/// True if the log's refusal of an op counts against the remote that sent it: all do but a
/// full log's (an honest relay's op is refused as much as any: the remote did nothing wrong).
fn is_offence(e: &InsertError) -> bool {
    !matches!(e, InsertError::Full)
}

/// The rejection a received op's decode error counts as.
fn decode_reject_kind(e: &DecodeError) -> RejectKind {
    match e {
        DecodeError::UnknownVersion { .. } => RejectKind::UnknownVersion,
        _ => RejectKind::MalformedOp,
    }
}

#[cfg(test)]
pub(crate) mod tests;

#[cfg(test)]
mod bucket_tests {
    use super::*;

    #[test]
    fn bucket_bursts_then_paces() {
        let mut b = TokenBucket::new(Timestamp(0), 1000, 3);
        assert!((0..3).all(|_| b.take(Timestamp(0))));
        assert!(!b.take(Timestamp(0)));
        // One token per millisecond at 1000 per second.
        assert_eq!(b.ready_at(), Timestamp(1000));
        assert!(!b.take(Timestamp(999)));
        assert!(b.take(Timestamp(1000)));
        // Refill is capped at the burst.
        assert!((0..3).all(|_| b.take(Timestamp(1_000_000))));
        assert!(!b.take(Timestamp(1_000_000)));
    }
}
