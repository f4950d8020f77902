//! The discovery server's state, sans-IO: registrations per session with expiry, per-source
//! rate limits and counters. [`super::server`] feeds it datagrams and the time, sends the
//! reply [`Registry::handle_datagram`] returns, then drains [`Registry::poll_transmit`].
//!
//! It sees discovery ids (hashes of invites), peer ids and addresses, never ops or invites.
//!
//! Who may be listed: a registration is listed only once its source has echoed a cookie the
//! server issued (a Challenge answers any registration without a valid one), and only when
//! it is signed by the peer id it names. The cookie is stateless: a keyed blake3 MAC of the
//! source address (IP and port) and a time window of [`COOKIE_WINDOW_MICROS`], valid in its
//! window and the next, like a QUIC retry token, so a spoofed source cannot be listed and
//! the server keeps nothing for it. The signature means nobody can register another peer's
//! id; so a peer that moves (a NAT rebinding, a new network, a restart on another port) and
//! registers from its new address moves its entry at once, and nobody can pin a peer to an
//! address it left. One source (an IPv4 address or an IPv6 /64, see [`AddressPrefix`]) may
//! hold at most [`MAX_PEERS_PER_SOURCE_PER_SESSION`] entries of a session, and its requests
//! share one token bucket.
//!
//! Introductions: a registration sent from a node's QUIC socket (RegisterMapped) is answered
//! with the session's other peers, and each of those that registered the same way is sent an
//! Introduce naming the newcomer at its public address, so both sides dial at once and punch
//! through their NATs. Anti-amplification holds for the whole exchange: the reply and every
//! introduction one request causes add up to at most the request's own bytes (1024), and to
//! at most [`MAX_INTRODUCTIONS_PER_REGISTER`] introductions. With IPv4 addresses that
//! introduces every peer of a session of up to 11; in a larger session the peers beyond the
//! budget are not introduced by this registration (they are, in turn, by their own
//! registrations and by later refreshes of either side, which rotate through the session).
//! Every registration introduces, refreshes included, so two peers that lost their
//! connection meet again within one refresh interval of either.

use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};

use crate::codec::DecodeError;
use crate::identity::PeerId;
use crate::net::discovery::message::{
    COOKIE_BYTES, Cookie, DiscoveredPeer, DiscoveryMessage, MAX_DATAGRAM_BYTES,
    MAX_PEERS_PER_REPLY, NO_COOKIE,
};
use crate::net::prefix::AddressPrefix;
use crate::net::session::DiscoveryId;
use crate::time::Timestamp;

/// A registration lives this long unless refreshed (60 s).
pub const REGISTRATION_TTL_MICROS: u64 = 60_000_000;
/// Sessions the server tracks at once.
pub const MAX_SESSIONS: usize = 4096;
/// Peers listed under one session.
pub const MAX_PEERS_PER_SESSION: usize = 64;
/// Registrations across all sessions.
pub const MAX_REGISTRATIONS: usize = 16_384;
/// Token buckets that rate-limit requests by source (IPv4 address, IPv6 /64), in one fixed
/// array: the server keeps no state per source before a request shows the source's cookie,
/// so a spread of sources cannot fill a table and lock the next one out.
pub const SOURCE_BUCKETS: usize = 1 << 16;
/// Buckets each source hashes to (by a keyed hash of its prefix); a request is taken while
/// any of them holds a token, and spends one from each that does. A source is refused only
/// when others drained every one of its buckets: sources at full rate from a whole IPv6 /52
/// (4,096 /64s) drain about 22% of the array, and refuse an unrelated source with a chance
/// of about 0.2%.
pub const BUCKETS_PER_SOURCE: usize = 4;
/// Requests one source may send per second on average.
pub const REQUESTS_PER_SEC_PER_SOURCE: u64 = 5;
/// Requests one source may send in a burst: a registration takes two (the challenge, then
/// the registration), and the members behind one NAT often start together.
pub const REQUEST_BURST_PER_SOURCE: u64 = 20;
/// Entries one source may hold in one session: several members behind one NAT are listed,
/// one member cannot fill the session's [`MAX_PEERS_PER_SESSION`].
pub const MAX_PEERS_PER_SOURCE_PER_SESSION: usize = 8;
/// A cookie is valid in the window it was issued in and the next (60 to 120 s): longer than
/// a client's refresh interval, so a refresh reuses the last cookie and costs one round trip.
pub const COOKIE_WINDOW_MICROS: u64 = 60_000_000;

const COOKIE_CONTEXT: &[u8] = b"sculpt/discovery/cookie/v2";
/// Derives the key of the source hash from the cookie key.
const SOURCE_HASH_CONTEXT: &str = "sculpt/discovery/source-buckets/v1";
/// Introductions one registration may cause (fewer when the request's bytes run out first).
pub const MAX_INTRODUCTIONS_PER_REGISTER: usize = 8;

const MICROS_PER_SEC: u64 = 1_000_000;

/// The server's counters.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RegistryStats {
    /// Registrations accepted (new or refreshed).
    pub n_registered: u64,
    /// Replies sent.
    pub n_replies: u64,
    /// Datagrams that are not discovery messages.
    pub n_malformed: u64,
    /// Messages of another discovery version.
    pub n_unknown_version: u64,
    /// Datagrams over [`MAX_DATAGRAM_BYTES`].
    pub n_oversized: u64,
    /// Well-formed messages a server does not take (replies, announcements).
    pub n_unexpected: u64,
    /// Requests over their source's rate limit.
    pub n_rate_limited: u64,
    /// Registrations not stored because a session or the server is full (still answered).
    pub n_full: u64,
    /// Registrations answered with a Challenge (no cookie, or a stale or foreign one).
    pub n_challenged: u64,
    /// Registrations with a valid cookie whose signature does not hold (dropped).
    pub n_bad_signatures: u64,
    /// Entries moved to a new address by their peer's proven registration.
    pub n_moved: u64,
    /// Registrations not stored because their source holds
    /// [`MAX_PEERS_PER_SOURCE_PER_SESSION`] entries of the session (still answered).
    pub n_over_source_share: u64,
    /// Registrations that expired.
    pub n_expired: u64,
    /// Replies the socket failed to send.
    pub n_send_failures: u64,
    /// Datagrams received, whatever they held.
    pub n_datagrams_received: u64,
    /// Bytes in every datagram received.
    pub n_bytes_received: u64,
    /// Bytes in every reply, challenge and introduction handed to the socket.
    pub n_bytes_sent: u64,
    /// Introductions handed to the socket.
    pub n_introductions: u64,
    /// Peers not introduced because the request's byte budget or
    /// [`MAX_INTRODUCTIONS_PER_REGISTER`] ran out.
    pub n_introductions_over_budget: u64,
    /// Introductions dropped because the caller did not drain them before the next datagram.
    pub n_introductions_undrained: u64,
}

impl RegistryStats {
    /// Every datagram dropped as bad input.
    pub fn n_bad_input(&self) -> u64 {
        self.n_malformed + self.n_unknown_version + self.n_oversized + self.n_unexpected
    }
}

#[derive(Clone, Copy, Debug)]
struct Registration {
    addr: SocketAddr,
    expires: Timestamp,
    /// Registered from its QUIC socket (RegisterMapped): it reads introductions there.
    mapped: bool,
}

/// A token bucket in millionths of a request, refilled from the `now` passed in.
#[derive(Clone, Copy, Debug)]
struct SourceBucket {
    tokens_micros: u64,
    last: Timestamp,
}

impl SourceBucket {
    const CAPACITY: u64 = REQUEST_BURST_PER_SOURCE * MICROS_PER_SEC;
    const FULL: Self = Self {
        tokens_micros: Self::CAPACITY,
        last: Timestamp(0),
    };

    fn refill(&mut self, now: Timestamp) {
        let elapsed = now.0.saturating_sub(self.last.0);
        self.last = self.last.max(now);
        self.tokens_micros = self
            .tokens_micros
            .saturating_add(elapsed.saturating_mul(REQUESTS_PER_SEC_PER_SOURCE))
            .min(Self::CAPACITY);
    }

    fn has_token(&self) -> bool {
        self.tokens_micros >= MICROS_PER_SEC
    }
}

/// The rate limit of every source, in [`SOURCE_BUCKETS`] buckets shared by hash.
struct SourceLimits {
    buckets: Vec<SourceBucket>,
    /// The key of the source hash (secret, so nobody can pick sources that share buckets).
    key: [u8; 32],
}

impl SourceLimits {
    fn new(cookie_key: &[u8; 32]) -> Self {
        Self {
            buckets: vec![SourceBucket::FULL; SOURCE_BUCKETS],
            key: blake3::derive_key(SOURCE_HASH_CONTEXT, cookie_key),
        }
    }

    /// The buckets of `source`.
    fn indexes(&self, source: AddressPrefix) -> [usize; BUCKETS_PER_SOURCE] {
        let bytes = match source {
            AddressPrefix::V4(octets) => [&[4u8][..], &octets[..]].concat(),
            AddressPrefix::V6(prefix) => [&[6u8][..], &prefix[..]].concat(),
        };
        let hash = blake3::keyed_hash(&self.key, &bytes);
        let mut indexes = [0; BUCKETS_PER_SOURCE];
        for (index, chunk) in indexes.iter_mut().zip(hash.as_bytes().chunks_exact(4)) {
            let word = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
            *index = word as usize % SOURCE_BUCKETS;
        }
        indexes
    }

    /// Takes a request of `source` if any of its buckets holds a token.
    fn take(&mut self, now: Timestamp, source: AddressPrefix) -> bool {
        let mut ok = false;
        for index in self.indexes(source) {
            let bucket = &mut self.buckets[index];
            bucket.refill(now);
            if bucket.has_token() {
                bucket.tokens_micros -= MICROS_PER_SEC;
                ok = true;
            }
        }
        ok
    }
}

/// Registrations by session, with expiry, rate limits and counters.
pub struct Registry {
    sessions: BTreeMap<DiscoveryId, BTreeMap<PeerId, Registration>>,
    n_registrations: usize,
    sources: SourceLimits,
    /// Introductions of the last registration, at most [`MAX_INTRODUCTIONS_PER_REGISTER`].
    introductions: Vec<(SocketAddr, Vec<u8>)>,
    stats: RegistryStats,
    /// The key of the address cookies (secret).
    cookie_key: [u8; 32],
}

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never print the cookie key.
        f.debug_struct("Registry")
            .field("n_sessions", &self.sessions.len())
            .field("n_registrations", &self.n_registrations)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl Registry {
    /// An empty registry whose address cookies are keyed by `cookie_key`, a secret the caller
    /// draws at random ([`super::server`] does, once per run).
    pub fn new(cookie_key: [u8; 32]) -> Self {
        Self {
            sessions: BTreeMap::new(),
            n_registrations: 0,
            sources: SourceLimits::new(&cookie_key),
            introductions: Vec::new(),
            stats: RegistryStats::default(),
            cookie_key,
        }
    }

    /// The counters.
    pub fn stats(&self) -> &RegistryStats {
        &self.stats
    }

    /// Registrations held now (expired ones included until [`Registry::expire`]).
    pub fn n_registrations(&self) -> usize {
        self.n_registrations
    }

    /// Counts a reply the socket could not send.
    pub fn count_send_failure(&mut self) {
        self.stats.n_send_failures += 1;
    }

    /// Handles one datagram from `from`; returns the reply to send back, if any. The
    /// introductions it causes wait in [`Registry::poll_transmit`] until the next datagram.
    pub fn handle_datagram(
        &mut self,
        now: Timestamp,
        from: SocketAddr,
        bytes: &[u8],
    ) -> Option<Vec<u8>> {
        self.stats.n_datagrams_received += 1;
        self.stats.n_bytes_received += bytes.len() as u64;
        self.stats.n_introductions_undrained += self.introductions.len() as u64;
        self.introductions.clear();
        let source = AddressPrefix::of(from.ip());
        let message = self.accept(now, source, bytes)?;
        let Some((discovery_id, peer, addr, mapped, cookie)) = registration(&message, from) else {
            self.stats.n_unexpected += 1;
            return None;
        };
        // The source must show that it receives at its address before anything is listed;
        // the challenge is smaller than the request, so a spoofed one amplifies nothing.
        if !self.cookie_holds(now, from, &cookie) {
            self.stats.n_challenged += 1;
            let challenge = DiscoveryMessage::Challenge {
                cookie: self.cookie(now.0 / COOKIE_WINDOW_MICROS, from),
            }
            .encode();
            self.stats.n_bytes_sent += challenge.len() as u64;
            return Some(challenge);
        }
        if !message.signature_holds() {
            self.stats.n_bad_signatures += 1;
            return None;
        }
        let listed = self.register(now, discovery_id, peer, addr, mapped, source);
        let others = self.others(now, &discovery_id, &peer);
        let reply = DiscoveryMessage::Peers(others.clone()).encode();
        if listed && mapped {
            let budget = bytes.len().saturating_sub(reply.len());
            self.introduce(
                now,
                discovery_id,
                DiscoveredPeer { peer, addr },
                &others,
                budget,
            );
        }
        self.stats.n_replies += 1;
        self.stats.n_bytes_sent += reply.len() as u64;
        Some(reply)
    }

    /// The message `bytes` from `source` decode to, unless they are over the size limit, the
    /// source is over its rate, or they do not decode (each counted).
    fn accept(
        &mut self,
        now: Timestamp,
        source: AddressPrefix,
        bytes: &[u8],
    ) -> Option<DiscoveryMessage> {
        if bytes.len() > MAX_DATAGRAM_BYTES {
            self.stats.n_oversized += 1;
            return None;
        }
        if !self.admit_source(now, source) {
            return None;
        }
        match DiscoveryMessage::decode(bytes) {
            Ok(m) => Some(m),
            Err(DecodeError::UnknownVersion { .. }) => {
                self.stats.n_unknown_version += 1;
                None
            }
            Err(_) => {
                self.stats.n_malformed += 1;
                None
            }
        }
    }

    /// Queues introductions of `newcomer` to the peers of `others` that registered from their
    /// QUIC sockets, in order, within `budget_bytes` and [`MAX_INTRODUCTIONS_PER_REGISTER`].
    fn introduce(
        &mut self,
        now: Timestamp,
        discovery_id: DiscoveryId,
        newcomer: DiscoveredPeer,
        others: &[DiscoveredPeer],
        budget_bytes: usize,
    ) {
        let introduction = DiscoveryMessage::Introduce {
            discovery_id,
            peer: newcomer,
        }
        .encode();
        let Some(peers) = self.sessions.get(&discovery_id) else {
            return;
        };
        let mut left_bytes = budget_bytes;
        for other in others {
            let Some(registration) = peers.get(&other.peer) else {
                continue;
            };
            if !registration.mapped || registration.expires <= now {
                continue;
            }
            let fits = introduction.len() <= left_bytes;
            if !fits || self.introductions.len() >= MAX_INTRODUCTIONS_PER_REGISTER {
                self.stats.n_introductions_over_budget += 1;
                continue;
            }
            left_bytes -= introduction.len();
            self.introductions
                .push((registration.addr, introduction.clone()));
        }
    }

    /// The next introduction to send: its destination and bytes. Drain after every
    /// [`Registry::handle_datagram`].
    pub fn poll_transmit(&mut self) -> Option<(SocketAddr, Vec<u8>)> {
        if self.introductions.is_empty() {
            return None;
        }
        let (to, bytes) = self.introductions.remove(0);
        self.stats.n_introductions += 1;
        self.stats.n_bytes_sent += bytes.len() as u64;
        Some((to, bytes))
    }

    /// The cookie of `from` in time window `window`.
    fn cookie(&self, window: u64, from: SocketAddr) -> Cookie {
        let ip = match from.ip().to_canonical() {
            IpAddr::V4(v4) => v4.to_ipv6_mapped(),
            IpAddr::V6(v6) => v6,
        };
        let mut mac = blake3::Hasher::new_keyed(&self.cookie_key);
        mac.update(COOKIE_CONTEXT);
        mac.update(&window.to_be_bytes());
        mac.update(&ip.octets());
        mac.update(&from.port().to_be_bytes());
        let mut cookie = [0; COOKIE_BYTES];
        cookie.copy_from_slice(&mac.finalize().as_bytes()[..COOKIE_BYTES]);
        cookie
    }

    /// True when `cookie` was issued to `from` in this time window or the one before.
    fn cookie_holds(&self, now: Timestamp, from: SocketAddr, cookie: &Cookie) -> bool {
        if *cookie == NO_COOKIE {
            return false;
        }
        let window = now.0 / COOKIE_WINDOW_MICROS;
        [Some(window), window.checked_sub(1)]
            .into_iter()
            .flatten()
            .any(|w| constant_time_eq(&self.cookie(w, from), cookie))
    }

    fn admit_source(&mut self, now: Timestamp, source: AddressPrefix) -> bool {
        let ok = self.sources.take(now, source);
        if !ok {
            self.stats.n_rate_limited += 1;
        }
        ok
    }

    /// Lists `peer` at `addr`, registered (proven) from `source`; false when it is not
    /// listed (the server, the session or the source's share of it is full). An entry of
    /// `peer` elsewhere moves: the registration is signed by the peer and its address proven.
    fn register(
        &mut self,
        now: Timestamp,
        id: DiscoveryId,
        peer: PeerId,
        addr: SocketAddr,
        mapped: bool,
        source: AddressPrefix,
    ) -> bool {
        let expires = now.saturating_add_micros(REGISTRATION_TTL_MICROS);
        let session_full = !self.sessions.contains_key(&id) && self.sessions.len() >= MAX_SESSIONS;
        if session_full {
            self.stats.n_full += 1;
            return false;
        }
        let n_registrations = self.n_registrations;
        let peers = self.sessions.entry(id).or_default();
        let full = peers.len() >= MAX_PEERS_PER_SESSION || n_registrations >= MAX_REGISTRATIONS;
        let registration = Registration {
            addr,
            expires,
            mapped,
        };
        let n_from_source = peers
            .iter()
            .filter(|(p, r)| **p != peer && AddressPrefix::of(r.addr.ip()) == source)
            .count();
        let listed = match peers.get_mut(&peer) {
            _ if n_from_source >= MAX_PEERS_PER_SOURCE_PER_SESSION => {
                self.stats.n_over_source_share += 1;
                false
            }
            Some(old) => {
                if old.addr != addr {
                    self.stats.n_moved += 1;
                }
                *old = registration;
                self.stats.n_registered += 1;
                true
            }
            None if full => {
                self.stats.n_full += 1;
                false
            }
            None => {
                peers.insert(peer, registration);
                self.n_registrations += 1;
                self.stats.n_registered += 1;
                true
            }
        };
        if peers.is_empty() {
            self.sessions.remove(&id);
        }
        listed
    }

    /// Up to [`MAX_PEERS_PER_REPLY`] live peers of the session other than `me`, starting
    /// after `me` in id order and wrapping around, so that in a large session different
    /// peers learn different subsets.
    fn others(&self, now: Timestamp, id: &DiscoveryId, me: &PeerId) -> Vec<DiscoveredPeer> {
        let Some(peers) = self.sessions.get(id) else {
            return Vec::new();
        };
        let after = peers.range((std::ops::Bound::Excluded(*me), std::ops::Bound::Unbounded));
        let before = peers.range(..*me);
        after
            .chain(before)
            .filter(|(_, r)| r.expires > now)
            .take(MAX_PEERS_PER_REPLY)
            .map(|(peer, r)| DiscoveredPeer {
                peer: *peer,
                addr: r.addr,
            })
            .collect()
    }

    /// Drops expired registrations.
    pub fn expire(&mut self, now: Timestamp) {
        let mut n_expired = 0;
        self.sessions.retain(|_, peers| {
            let before = peers.len();
            peers.retain(|_, r| r.expires > now);
            n_expired += before - peers.len();
            !peers.is_empty()
        });
        self.n_registrations -= n_expired;
        self.stats.n_expired += n_expired as u64;
    }
}

/// Compares two cookies in time independent of where they differ.
fn constant_time_eq(a: &Cookie, b: &Cookie) -> bool {
    a.iter().zip(b).fold(0, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// What a register from `from` asks to list: its discovery id, peer, address, whether the
/// address is a NAT's mapping, and its cookie; `None` for any other message.
fn registration(
    message: &DiscoveryMessage,
    from: SocketAddr,
) -> Option<(DiscoveryId, PeerId, SocketAddr, bool, Cookie)> {
    match message {
        // The address is where the request came from: nobody can list a third party's IP.
        DiscoveryMessage::Register {
            discovery_id,
            peer,
            port,
            cookie,
            ..
        } => Some((
            *discovery_id,
            *peer,
            SocketAddr::new(from.ip(), *port),
            false,
            *cookie,
        )),
        // The whole source address: the NAT's mapping of the node's QUIC socket.
        DiscoveryMessage::RegisterMapped {
            discovery_id,
            peer,
            cookie,
            ..
        } => Some((*discovery_id, *peer, from, true, *cookie)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identity::Keypair;
    use std::net::{Ipv4Addr, Ipv6Addr};

    fn registry() -> Registry {
        Registry::new([42; 32])
    }

    fn from(last: u8, port: u16) -> SocketAddr {
        SocketAddr::new(IpAddr::V4(Ipv4Addr::new(10, 0, 0, last)), port)
    }

    fn keypair(peer: u8) -> Keypair {
        Keypair::from_seed([peer; 32])
    }

    fn id(peer: u8) -> PeerId {
        keypair(peer).peer_id()
    }

    fn decode(reply: Option<Vec<u8>>) -> DiscoveryMessage {
        DiscoveryMessage::decode(&reply.expect("an answer")).unwrap()
    }

    /// The cookie the registry issues to `from` now (costs `from` one request).
    fn cookie_for(r: &mut Registry, t: Timestamp, from: SocketAddr) -> Cookie {
        let probe = DiscoveryMessage::register(&keypair(0), [0; 16], 0, NO_COOKIE).encode();
        match decode(r.handle_datagram(t, from, &probe)) {
            DiscoveryMessage::Challenge { cookie } => cookie,
            other => panic!("{other:?}"),
        }
    }

    /// A Register round trip from `from`: challenged, then sent again with the cookie.
    fn register_at(
        r: &mut Registry,
        t: Timestamp,
        from: SocketAddr,
        session: u8,
        peer: u8,
        port: u16,
    ) -> Option<Vec<u8>> {
        let cookie = cookie_for(r, t, from);
        let request = DiscoveryMessage::register(&keypair(peer), [session; 16], port, cookie);
        r.handle_datagram(t, from, &request.encode())
    }

    /// A RegisterMapped round trip from `from`.
    fn register_mapped_at(
        r: &mut Registry,
        t: Timestamp,
        from: SocketAddr,
        session: u8,
        peer: u8,
    ) -> Option<Vec<u8>> {
        let cookie = cookie_for(r, t, from);
        let request = DiscoveryMessage::register_mapped(&keypair(peer), [session; 16], cookie);
        r.handle_datagram(t, from, &request.encode())
    }

    fn peers(reply: Option<Vec<u8>>) -> Vec<DiscoveredPeer> {
        match decode(reply) {
            DiscoveryMessage::Peers(p) => p,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn peers_of_a_session_learn_each_other_and_entries_expire() {
        let mut r = registry();
        let t = Timestamp(1_000_000);
        assert!(peers(register_at(&mut r, t, from(1, 5000), 1, 1, 4001)).is_empty());
        let found = peers(register_at(&mut r, t, from(2, 5000), 1, 2, 4002));
        // The listed address is the source IP with the announced QUIC port.
        assert_eq!(
            found,
            vec![DiscoveredPeer {
                peer: id(1),
                addr: from(1, 4001)
            }]
        );
        // Another session sees neither.
        assert!(peers(register_at(&mut r, t, from(3, 5000), 2, 3, 4003)).is_empty());
        assert_eq!(r.n_registrations(), 3);
        // Peer 1 refreshes; peer 2 does not and expires.
        let later = t.saturating_add_micros(REGISTRATION_TTL_MICROS - 1);
        register_at(&mut r, later, from(1, 5000), 1, 1, 4001);
        let expired = t.saturating_add_micros(REGISTRATION_TTL_MICROS);
        r.expire(expired);
        assert_eq!(r.n_registrations(), 1);
        assert_eq!(r.stats().n_expired, 2);
        assert!(peers(register_at(&mut r, expired, from(1, 5000), 1, 1, 4001)).is_empty());
    }

    #[test]
    fn registrations_are_listed_only_after_the_source_echoes_its_cookie() {
        let mut r = registry();
        let t = Timestamp(10 * COOKIE_WINDOW_MICROS);
        let session = [1; 16];
        let send = |r: &mut Registry, t, from, cookie| {
            let request = DiscoveryMessage::register_mapped(&keypair(1), session, cookie);
            let bytes = request.encode();
            let reply = r.handle_datagram(t, from, &bytes);
            assert!(reply.as_ref().is_none_or(|b| b.len() <= bytes.len()));
            reply.map(|b| DiscoveryMessage::decode(&b).unwrap())
        };
        // No cookie: a challenge, smaller than the request, and nothing listed.
        let Some(DiscoveryMessage::Challenge { cookie }) = send(&mut r, t, from(1, 7), NO_COOKIE)
        else {
            panic!("a challenge")
        };
        assert_eq!(r.n_registrations(), 0);
        // Another address (a spoofer who read the cookie, or another port) is challenged.
        for other in [from(2, 7), from(1, 8)] {
            let reply = send(&mut r, t, other, cookie);
            assert!(matches!(reply, Some(DiscoveryMessage::Challenge { .. })));
        }
        // A made-up cookie is challenged too.
        let reply = send(&mut r, t, from(1, 7), [9; COOKIE_BYTES]);
        assert!(matches!(reply, Some(DiscoveryMessage::Challenge { .. })));
        assert_eq!(r.n_registrations(), 0);
        assert_eq!(r.stats().n_challenged, 4);
        // The echo from the address it was issued to is listed, in this window and the next.
        assert!(matches!(
            send(&mut r, t, from(1, 7), cookie),
            Some(DiscoveryMessage::Peers(_))
        ));
        assert_eq!(r.n_registrations(), 1);
        let next = t.saturating_add_micros(COOKIE_WINDOW_MICROS);
        assert!(matches!(
            send(&mut r, next, from(1, 7), cookie),
            Some(DiscoveryMessage::Peers(_))
        ));
        let stale = t.saturating_add_micros(2 * COOKIE_WINDOW_MICROS);
        assert!(matches!(
            send(&mut r, stale, from(1, 7), cookie),
            Some(DiscoveryMessage::Challenge { .. })
        ));
        // Another server (another key) does not take this server's cookie.
        let mut other = Registry::new([43; 32]);
        assert!(matches!(
            send(&mut other, t, from(1, 7), cookie),
            Some(DiscoveryMessage::Challenge { .. })
        ));
        assert!(!format!("{r:?}").contains("42, 42"));
    }

    #[test]
    fn only_the_peer_can_register_its_id_and_a_proven_peer_moves_at_once() {
        let mut r = registry();
        let t = Timestamp(0);
        register_mapped_at(&mut r, t, from(1, 4001), 1, 1);
        // Mallory, with a valid cookie of her own, claims peer 1's id: the signature fails.
        let cookie = cookie_for(&mut r, t, from(66, 1));
        let DiscoveryMessage::RegisterMapped { signature, .. } =
            DiscoveryMessage::register_mapped(&keypair(66), [1; 16], cookie)
        else {
            unreachable!()
        };
        let forged = DiscoveryMessage::RegisterMapped {
            discovery_id: [1; 16],
            peer: id(1),
            cookie,
            signature,
        };
        assert_eq!(r.handle_datagram(t, from(66, 1), &forged.encode()), None);
        assert_eq!(r.stats().n_bad_signatures, 1);
        let listed = peers(register_mapped_at(&mut r, t, from(3, 1), 1, 3));
        assert_eq!(listed[0].addr, from(1, 4001));
        // Peer 1 itself, from a new network, moves its live entry at once.
        peers(register_mapped_at(&mut r, t, from(2, 5000), 1, 1));
        let listed = peers(register_mapped_at(&mut r, t, from(3, 1), 1, 3));
        assert_eq!(
            listed,
            vec![DiscoveredPeer {
                peer: id(1),
                addr: from(2, 5000)
            }]
        );
        assert_eq!(r.stats().n_moved, 1);
    }

    #[test]
    fn bad_input_is_counted_and_unanswered() {
        let mut r = registry();
        let t = Timestamp(0);
        assert_eq!(r.handle_datagram(t, from(1, 1), b"hello"), None);
        let mut older = DiscoveryMessage::register(&keypair(1), [1; 16], 1, NO_COOKIE).encode();
        older[3] = 1;
        assert_eq!(r.handle_datagram(t, from(1, 1), &older), None);
        assert_eq!(
            r.handle_datagram(t, from(1, 1), &vec![0; MAX_DATAGRAM_BYTES + 1]),
            None
        );
        let reply = DiscoveryMessage::Peers(Vec::new()).encode();
        assert_eq!(r.handle_datagram(t, from(1, 1), &reply), None);
        let challenge = DiscoveryMessage::Challenge { cookie: [1; 16] }.encode();
        assert_eq!(r.handle_datagram(t, from(1, 1), &challenge), None);
        let s = r.stats();
        assert_eq!(
            (
                s.n_malformed,
                s.n_unknown_version,
                s.n_oversized,
                s.n_unexpected
            ),
            (1, 1, 1, 2)
        );
        assert_eq!(r.n_registrations(), 0);
    }

    #[test]
    fn sources_are_rate_limited() {
        let mut r = registry();
        let t = Timestamp(0);
        let n_answered = (0..REQUEST_BURST_PER_SOURCE + 5)
            .filter(|_| {
                let probe = DiscoveryMessage::register(&keypair(1), [1; 16], 1, NO_COOKIE);
                r.handle_datagram(t, from(1, 1), &probe.encode()).is_some()
            })
            .count();
        assert_eq!(n_answered as u64, REQUEST_BURST_PER_SOURCE);
        assert_eq!(r.stats().n_rate_limited, 5);
        // One request's worth of tokens comes back after 1 / rate seconds.
        let refill = Timestamp(MICROS_PER_SEC / REQUESTS_PER_SEC_PER_SOURCE);
        let probe = DiscoveryMessage::register(&keypair(1), [1; 16], 1, NO_COOKIE);
        assert!(
            r.handle_datagram(refill, from(1, 1), &probe.encode())
                .is_some()
        );
    }

    #[test]
    fn one_ipv6_64_shares_its_rate_limit() {
        let mut r = registry();
        let t = Timestamp(0);
        // Many addresses, all in 2001:db8:0:1::/64.
        let mut n_answered = 0;
        for host in 0..5000u32 {
            let ip = Ipv6Addr::new(0x2001, 0xdb8, 0, 1, 0, 0, (host >> 16) as u16, host as u16);
            let probe = DiscoveryMessage::register(&keypair(1), [1; 16], 1, NO_COOKIE);
            if r.handle_datagram(t, SocketAddr::new(ip.into(), 1), &probe.encode())
                .is_some()
            {
                n_answered += 1;
            }
        }
        // They share one bucket, and everyone else has room.
        assert_eq!(n_answered, REQUEST_BURST_PER_SOURCE);
        assert!(peers(register_at(&mut r, t, from(1, 1), 1, 1, 1)).is_empty());
        let other_64 = SocketAddr::new(Ipv6Addr::new(0x2001, 0xdb8, 0, 2, 0, 0, 0, 1).into(), 1);
        assert!(peers(register_mapped_at(&mut r, t, other_64, 1, 2)).len() == 1);
    }

    /// Issue 49: the rate limit kept a bucket per source before decoding anything, in a table
    /// of 4,096 sources, so 1-byte datagrams from the 4,096 /64s of one /52 filled it and the
    /// next honest registration was dropped unanswered. The buckets are a fixed array shared
    /// by hash now: nothing is kept per source, and the honest source still gets through.
    #[test]
    fn datagrams_from_a_whole_52_leave_honest_sources_registering() {
        let mut r = registry();
        let t = Timestamp(0);
        let n_flood = 2 * REQUEST_BURST_PER_SOURCE;
        for subnet in 0..4096u16 {
            let ip = Ipv6Addr::new(0x2001, 0xdb8, 0xa000, subnet, 0, 0, 0, 1);
            for _ in 0..n_flood {
                r.handle_datagram(t, SocketAddr::new(ip.into(), 1), &[0]);
            }
        }
        assert!(r.stats().n_rate_limited >= 4096 * REQUEST_BURST_PER_SOURCE);
        for (peer, addr) in [
            (1, from(1, 1)),
            (2, "198.51.100.7:9".parse().unwrap()),
            (3, "[2001:db8:77::5]:9".parse().unwrap()),
        ] {
            let limited = r.stats().n_rate_limited;
            assert!(
                matches!(
                    decode(register_at(&mut r, t, addr, 1, peer, 1)),
                    DiscoveryMessage::Peers(_)
                ),
                "{addr} was not registered"
            );
            assert_eq!(r.stats().n_rate_limited, limited, "{addr}");
        }
        assert_eq!(r.n_registrations(), 3);
    }

    #[test]
    fn one_source_cannot_fill_a_session() {
        let mut r = registry();
        let mut t = Timestamp(0);
        // One member makes up peer ids and registers them from many addresses of its /64,
        // slowly enough for the rate limit, within one registration lifetime.
        let n_fakes = MAX_PEERS_PER_SESSION as u8;
        for fake in 0..n_fakes {
            let ip = Ipv6Addr::new(0x2001, 0xdb8, 0, 1, 0, 0, 0, u16::from(fake) + 1);
            register_mapped_at(&mut r, t, SocketAddr::new(ip.into(), 1), 1, 100 + fake);
            // Two requests each (challenge, registration) refill in 0.4 s; all stay live.
            t = t.saturating_add_micros(MICROS_PER_SEC / 2);
        }
        assert_eq!(r.n_registrations(), MAX_PEERS_PER_SOURCE_PER_SESSION);
        assert_eq!(
            r.stats().n_over_source_share,
            (MAX_PEERS_PER_SESSION - MAX_PEERS_PER_SOURCE_PER_SESSION) as u64
        );
        // Honest members from elsewhere are still listed.
        let found = peers(register_mapped_at(&mut r, t, from(1, 1), 1, 1));
        assert_eq!(found.len(), MAX_PEERS_PER_SOURCE_PER_SESSION);
        assert_eq!(r.n_registrations(), MAX_PEERS_PER_SOURCE_PER_SESSION + 1);
        // A listed fake refreshes (and may move within its source) without growing its share.
        let ip = Ipv6Addr::new(0x2001, 0xdb8, 0, 1, 0, 0, 0, 99);
        register_mapped_at(&mut r, t, SocketAddr::new(ip.into(), 1), 1, 100);
        assert_eq!(r.n_registrations(), MAX_PEERS_PER_SOURCE_PER_SESSION + 1);
    }

    fn drain(r: &mut Registry) -> Vec<(SocketAddr, DiscoveryMessage)> {
        std::iter::from_fn(|| r.poll_transmit())
            .map(|(to, bytes)| (to, DiscoveryMessage::decode(&bytes).unwrap()))
            .collect()
    }

    #[test]
    fn mapped_registrations_list_the_source_and_introduce_the_newcomer() {
        let mut r = registry();
        let t = Timestamp(0);
        // An old-style registration (claimed port, separate socket) is listed but never
        // introduced: its QUIC socket would not read introductions.
        register_at(&mut r, t, from(9, 5000), 1, 9, 4009);
        assert!(drain(&mut r).is_empty());
        let first = peers(register_mapped_at(&mut r, t, from(1, 40_001), 1, 1));
        assert_eq!(first.len(), 1);
        assert!(drain(&mut r).is_empty());
        // The newcomer learns both, each at the address it registered from.
        let mut found = peers(register_mapped_at(&mut r, t, from(2, 40_002), 1, 2));
        found.sort();
        let mut expected = vec![
            DiscoveredPeer {
                peer: id(9),
                addr: from(9, 4009),
            },
            DiscoveredPeer {
                peer: id(1),
                addr: from(1, 40_001),
            },
        ];
        expected.sort();
        assert_eq!(found, expected);
        // And the mapped peer hears of the newcomer at the newcomer's source address.
        let newcomer = DiscoveredPeer {
            peer: id(2),
            addr: from(2, 40_002),
        };
        assert_eq!(
            drain(&mut r),
            vec![(
                from(1, 40_001),
                DiscoveryMessage::Introduce {
                    discovery_id: [1; 16],
                    peer: newcomer
                }
            )]
        );
        // A refresh introduces again (peers that lost each other meet again); another
        // session's peer introduces nobody here.
        register_mapped_at(&mut r, t, from(2, 40_002), 1, 2);
        assert_eq!(drain(&mut r).len(), 1);
        register_mapped_at(&mut r, t, from(3, 40_003), 2, 3);
        assert!(drain(&mut r).is_empty());
        // Undrained introductions are dropped at the next datagram, and counted.
        register_mapped_at(&mut r, t, from(2, 40_002), 1, 2);
        r.handle_datagram(t, from(4, 1), b"noise");
        assert!(drain(&mut r).is_empty());
        let s = r.stats();
        assert_eq!((s.n_introductions, s.n_introductions_undrained), (2, 1));
        assert!(s.n_bytes_sent <= s.n_bytes_received, "{s:?}");
    }

    #[test]
    fn introductions_never_amplify_a_request() {
        for ipv6 in [false, true] {
            let mut r = registry();
            let t = Timestamp(0);
            let source = |peer: u8| {
                let ip = if ipv6 {
                    // One /64 per peer, so that no source's share of the session is in play.
                    IpAddr::V6(Ipv6Addr::new(0x2001, 0xdb8, 0, peer.into(), 0, 0, 0, 1))
                } else {
                    IpAddr::V4(Ipv4Addr::new(10, 0, 0, peer))
                };
                SocketAddr::new(ip, 40_000)
            };
            let n_peers = MAX_PEERS_PER_REPLY as u8 + 4;
            for peer in 0..n_peers {
                register_mapped_at(&mut r, t, source(peer), 1, peer);
                drain(&mut r);
            }
            let before = r.stats().clone();
            let cookie = cookie_for(&mut r, t, source(0));
            let request = DiscoveryMessage::register_mapped(&keypair(0), [1; 16], cookie).encode();
            let reply = r.handle_datagram(t, source(0), &request).unwrap();
            let introductions = drain(&mut r);
            let sent: usize = reply.len()
                + introductions
                    .iter()
                    .map(|(_, m)| m.encode().len())
                    .sum::<usize>();
            assert!(
                sent <= request.len(),
                "ipv6 {ipv6}: {sent} > {}",
                request.len()
            );
            assert!(!introductions.is_empty());
            assert!(introductions.len() <= MAX_INTRODUCTIONS_PER_REGISTER);
            // Those left out are counted; every introduced peer was named in the reply.
            let listed = peers(Some(reply));
            let over = r.stats().n_introductions_over_budget - before.n_introductions_over_budget;
            assert_eq!(introductions.len() as u64 + over, listed.len() as u64);
            for (to, _) in &introductions {
                assert!(listed.iter().any(|d| d.addr == *to));
            }
        }
    }

    #[test]
    fn sessions_are_bounded_and_replies_rotate() {
        let mut r = registry();
        let t = Timestamp(0);
        for peer in 0..MAX_PEERS_PER_SESSION as u8 + 3 {
            // One source per peer keeps the rate limit and the source share out of the way.
            register_at(&mut r, t, from(peer, 1), 1, peer, 1);
        }
        assert_eq!(r.n_registrations(), MAX_PEERS_PER_SESSION);
        assert_eq!(r.stats().n_full, 3);
        // Replies start after the asker in id order and wrap around.
        let mut listed: Vec<PeerId> = (0..MAX_PEERS_PER_SESSION as u8).map(id).collect();
        listed.sort();
        let asker = listed[0];
        let asker_seed = (0..=255u8).find(|s| id(*s) == asker).unwrap();
        let a = peers(register_at(
            &mut r,
            t,
            from(asker_seed, 1),
            1,
            asker_seed,
            1,
        ));
        assert_eq!(a.len(), MAX_PEERS_PER_REPLY);
        assert_eq!(a[0].peer, listed[1]);
        assert!(a.iter().all(|d| d.peer != asker));
        let last = listed[MAX_PEERS_PER_SESSION - 1];
        let last_seed = (0..=255u8).find(|s| id(*s) == last).unwrap();
        let b = peers(register_at(&mut r, t, from(last_seed, 1), 1, last_seed, 1));
        assert_eq!(b[0].peer, listed[0]);
    }
}
