//! The discovery server's state, sans-IO: registrations per session with expiry, per-source
//! rate limits and counters. [`super::server`] feeds it datagrams and the time, sends the
//! reply [`Registry::handle_datagram`] returns, then drains [`Registry::poll_transmit`].
//!
//! It sees discovery ids (hashes of invites), peer ids and addresses, never ops or invites.
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
    DiscoveredPeer, DiscoveryMessage, MAX_DATAGRAM_BYTES, MAX_PEERS_PER_REPLY,
};
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
/// Source addresses rate-limited at once; idle ones are forgotten.
pub const MAX_SOURCES: usize = 4096;
/// Requests one source IP may send per second on average.
pub const REQUESTS_PER_SEC_PER_SOURCE: u64 = 5;
/// Requests one source IP may send in a burst.
pub const REQUEST_BURST_PER_SOURCE: u64 = 10;
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
    /// Requests dropped because [`MAX_SOURCES`] sources are active.
    pub n_sources_full: u64,
    /// Registrations not stored because a session or the server is full (still answered).
    pub n_full: u64,
    /// Registrations refused because a live entry of that peer came from another IP.
    pub n_takeovers_refused: u64,
    /// Registrations that expired.
    pub n_expired: u64,
    /// Replies the socket failed to send.
    pub n_send_failures: u64,
    /// Datagrams received, whatever they held.
    pub n_datagrams_received: u64,
    /// Bytes in every datagram received.
    pub n_bytes_received: u64,
    /// Bytes in every reply and introduction handed to the socket.
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

    fn new(now: Timestamp) -> Self {
        Self {
            tokens_micros: Self::CAPACITY,
            last: now,
        }
    }

    fn take(&mut self, now: Timestamp) -> bool {
        let elapsed = now.0.saturating_sub(self.last.0);
        self.last = self.last.max(now);
        self.tokens_micros = self
            .tokens_micros
            .saturating_add(elapsed.saturating_mul(REQUESTS_PER_SEC_PER_SOURCE))
            .min(Self::CAPACITY);
        let ok = self.tokens_micros >= MICROS_PER_SEC;
        if ok {
            self.tokens_micros -= MICROS_PER_SEC;
        }
        ok
    }

    /// Idle long enough that forgetting it changes nothing (it would be full again).
    fn idle(&self, now: Timestamp) -> bool {
        let refill_micros = Self::CAPACITY / REQUESTS_PER_SEC_PER_SOURCE;
        self.last.saturating_add_micros(refill_micros) <= now
    }
}

/// Registrations by session, with expiry, rate limits and counters.
#[derive(Debug, Default)]
pub struct Registry {
    sessions: BTreeMap<DiscoveryId, BTreeMap<PeerId, Registration>>,
    n_registrations: usize,
    sources: BTreeMap<IpAddr, SourceBucket>,
    /// Introductions of the last registration, at most [`MAX_INTRODUCTIONS_PER_REGISTER`].
    introductions: Vec<(SocketAddr, Vec<u8>)>,
    stats: RegistryStats,
}

impl Registry {
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
        if bytes.len() > MAX_DATAGRAM_BYTES {
            self.stats.n_oversized += 1;
            return None;
        }
        if !self.admit_source(now, from.ip()) {
            return None;
        }
        let message = match DiscoveryMessage::decode(bytes) {
            Ok(m) => m,
            Err(DecodeError::UnknownVersion { .. }) => {
                self.stats.n_unknown_version += 1;
                return None;
            }
            Err(_) => {
                self.stats.n_malformed += 1;
                return None;
            }
        };
        let (discovery_id, peer, addr, mapped) = match message {
            // The address is where the request came from: nobody can list a third party's IP.
            DiscoveryMessage::Register {
                discovery_id,
                peer,
                port,
            } => (discovery_id, peer, SocketAddr::new(from.ip(), port), false),
            // The whole source address: the NAT's mapping of the node's QUIC socket.
            DiscoveryMessage::RegisterMapped { discovery_id, peer } => {
                (discovery_id, peer, from, true)
            }
            _ => {
                self.stats.n_unexpected += 1;
                return None;
            }
        };
        let listed = self.register(now, discovery_id, peer, addr, mapped);
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

    fn admit_source(&mut self, now: Timestamp, ip: IpAddr) -> bool {
        if !self.sources.contains_key(&ip) && self.sources.len() >= MAX_SOURCES {
            self.sources.retain(|_, bucket| !bucket.idle(now));
            if self.sources.len() >= MAX_SOURCES {
                self.stats.n_sources_full += 1;
                return false;
            }
        }
        let ok = self
            .sources
            .entry(ip)
            .or_insert_with(|| SourceBucket::new(now))
            .take(now);
        if !ok {
            self.stats.n_rate_limited += 1;
        }
        ok
    }

    /// Lists `peer` at `addr`; false when it is not listed (full, or a refused takeover).
    fn register(
        &mut self,
        now: Timestamp,
        id: DiscoveryId,
        peer: PeerId,
        addr: SocketAddr,
        mapped: bool,
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
        let listed = match peers.get_mut(&peer) {
            Some(old) if old.expires > now && old.addr.ip() != addr.ip() => {
                self.stats.n_takeovers_refused += 1;
                false
            }
            Some(old) => {
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

    /// Drops expired registrations and idle rate-limit state.
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
        self.sources.retain(|_, bucket| !bucket.idle(now));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::Ipv4Addr;

    fn from(last: u8, port: u16) -> SocketAddr {
        SocketAddr::new(IpAddr::V4(Ipv4Addr::new(10, 0, 0, last)), port)
    }

    fn register(id: u8, peer: u8, port: u16) -> Vec<u8> {
        DiscoveryMessage::Register {
            discovery_id: [id; 16],
            peer: PeerId([peer; 32]),
            port,
        }
        .encode()
    }

    fn peers(reply: Option<Vec<u8>>) -> Vec<DiscoveredPeer> {
        match DiscoveryMessage::decode(&reply.unwrap()).unwrap() {
            DiscoveryMessage::Peers(p) => p,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn peers_of_a_session_learn_each_other_and_entries_expire() {
        let mut r = Registry::default();
        let t = Timestamp(1_000_000);
        assert!(peers(r.handle_datagram(t, from(1, 5000), &register(1, 1, 4001))).is_empty());
        let found = peers(r.handle_datagram(t, from(2, 5000), &register(1, 2, 4002)));
        // The listed address is the source IP with the announced QUIC port.
        assert_eq!(
            found,
            vec![DiscoveredPeer {
                peer: PeerId([1; 32]),
                addr: from(1, 4001)
            }]
        );
        // Another session sees neither.
        assert!(peers(r.handle_datagram(t, from(3, 5000), &register(2, 3, 4003))).is_empty());
        assert_eq!(r.n_registrations(), 3);
        // Peer 1 refreshes; peer 2 does not and expires.
        let later = t.saturating_add_micros(REGISTRATION_TTL_MICROS - 1);
        r.handle_datagram(later, from(1, 5000), &register(1, 1, 4001));
        let expired = t.saturating_add_micros(REGISTRATION_TTL_MICROS);
        r.expire(expired);
        assert_eq!(r.n_registrations(), 1);
        assert_eq!(r.stats().n_expired, 2);
        assert!(peers(r.handle_datagram(expired, from(1, 5000), &register(1, 1, 4001))).is_empty());
    }

    #[test]
    fn bad_input_is_counted_and_unanswered() {
        let mut r = Registry::default();
        let t = Timestamp(0);
        assert_eq!(r.handle_datagram(t, from(1, 1), b"hello"), None);
        let mut newer = register(1, 1, 1);
        newer[3] = 9;
        assert_eq!(r.handle_datagram(t, from(1, 1), &newer), None);
        assert_eq!(
            r.handle_datagram(t, from(1, 1), &vec![0; MAX_DATAGRAM_BYTES + 1]),
            None
        );
        let reply = DiscoveryMessage::Peers(Vec::new()).encode();
        assert_eq!(r.handle_datagram(t, from(1, 1), &reply), None);
        let s = r.stats();
        assert_eq!(
            (
                s.n_malformed,
                s.n_unknown_version,
                s.n_oversized,
                s.n_unexpected
            ),
            (1, 1, 1, 1)
        );
        assert_eq!(r.n_registrations(), 0);
    }

    #[test]
    fn sources_are_rate_limited_and_entries_cannot_be_taken_over() {
        let mut r = Registry::default();
        let t = Timestamp(0);
        let n_answered = (0..REQUEST_BURST_PER_SOURCE + 5)
            .filter(|_| {
                r.handle_datagram(t, from(1, 1), &register(1, 1, 1))
                    .is_some()
            })
            .count();
        assert_eq!(n_answered as u64, REQUEST_BURST_PER_SOURCE);
        assert_eq!(r.stats().n_rate_limited, 5);
        // One request's worth of tokens comes back after 1 / rate seconds.
        let refill = Timestamp(MICROS_PER_SEC / REQUESTS_PER_SEC_PER_SOURCE);
        assert!(
            r.handle_datagram(refill, from(1, 1), &register(1, 1, 1))
                .is_some()
        );
        // Another IP cannot move a live entry of peer 1.
        r.handle_datagram(refill, from(2, 1), &register(1, 1, 9));
        assert_eq!(r.stats().n_takeovers_refused, 1);
        let listed = peers(r.handle_datagram(refill, from(3, 1), &register(1, 3, 3)));
        assert_eq!(listed[0].addr, from(1, 1));
    }

    fn register_mapped(id: u8, peer: u8) -> Vec<u8> {
        DiscoveryMessage::RegisterMapped {
            discovery_id: [id; 16],
            peer: PeerId([peer; 32]),
        }
        .encode()
    }

    fn drain(r: &mut Registry) -> Vec<(SocketAddr, DiscoveryMessage)> {
        std::iter::from_fn(|| r.poll_transmit())
            .map(|(to, bytes)| (to, DiscoveryMessage::decode(&bytes).unwrap()))
            .collect()
    }

    #[test]
    fn mapped_registrations_list_the_source_and_introduce_the_newcomer() {
        let mut r = Registry::default();
        let t = Timestamp(0);
        // An old-style registration (claimed port, separate socket) is listed but never
        // introduced: its QUIC socket would not read introductions.
        r.handle_datagram(t, from(9, 5000), &register(1, 9, 4009));
        assert!(drain(&mut r).is_empty());
        let first = peers(r.handle_datagram(t, from(1, 40_001), &register_mapped(1, 1)));
        assert_eq!(first.len(), 1);
        assert!(drain(&mut r).is_empty());
        // The newcomer learns both, each at the address it registered from.
        let found = peers(r.handle_datagram(t, from(2, 40_002), &register_mapped(1, 2)));
        assert_eq!(
            found,
            vec![
                DiscoveredPeer {
                    peer: PeerId([9; 32]),
                    addr: from(9, 4009)
                },
                DiscoveredPeer {
                    peer: PeerId([1; 32]),
                    addr: from(1, 40_001)
                },
            ]
        );
        // And the mapped peer hears of the newcomer at the newcomer's source address.
        let newcomer = DiscoveredPeer {
            peer: PeerId([2; 32]),
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
        r.handle_datagram(t, from(2, 40_002), &register_mapped(1, 2));
        assert_eq!(drain(&mut r).len(), 1);
        r.handle_datagram(t, from(3, 40_003), &register_mapped(2, 3));
        assert!(drain(&mut r).is_empty());
        // Undrained introductions are dropped at the next datagram, and counted.
        r.handle_datagram(t, from(2, 40_002), &register_mapped(1, 2));
        r.handle_datagram(t, from(4, 1), b"noise");
        assert!(drain(&mut r).is_empty());
        let s = r.stats();
        assert_eq!((s.n_introductions, s.n_introductions_undrained), (2, 1));
        assert!(s.n_bytes_sent <= s.n_bytes_received, "{s:?}");
    }

    #[test]
    fn introductions_never_amplify_a_request() {
        for ipv6 in [false, true] {
            let mut r = Registry::default();
            let t = Timestamp(0);
            let source = |peer: u8| {
                let ip = if ipv6 {
                    IpAddr::V6(std::net::Ipv6Addr::new(
                        0x2001,
                        0xdb8,
                        0,
                        0,
                        0,
                        0,
                        0,
                        peer.into(),
                    ))
                } else {
                    IpAddr::V4(Ipv4Addr::new(10, 0, 0, peer))
                };
                SocketAddr::new(ip, 40_000)
            };
            let n_peers = MAX_PEERS_PER_REPLY as u8 + 4;
            for peer in 0..n_peers {
                r.handle_datagram(t, source(peer), &register_mapped(1, peer));
                drain(&mut r);
            }
            let before = r.stats().clone();
            let request = register_mapped(1, 0);
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
        let mut r = Registry::default();
        let t = Timestamp(0);
        for peer in 0..MAX_PEERS_PER_SESSION as u8 + 3 {
            // One source per peer keeps the rate limit out of the way.
            r.handle_datagram(t, from(peer, 1), &register(1, peer, 1));
        }
        assert_eq!(r.n_registrations(), MAX_PEERS_PER_SESSION);
        assert_eq!(r.stats().n_full, 3);
        let a = peers(r.handle_datagram(t, from(1, 1), &register(1, 1, 1)));
        let b = peers(r.handle_datagram(t, from(40, 1), &register(1, 40, 1)));
        assert_eq!(a.len(), MAX_PEERS_PER_REPLY);
        assert_eq!(a[0].peer, PeerId([2; 32]));
        assert_eq!(b[0].peer, PeerId([41; 32]));
        assert!(a.iter().all(|d| d.peer != PeerId([1; 32])));
    }
}
