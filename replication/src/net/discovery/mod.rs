//! Discovery: how peers of a session find each other's addresses. It introduces peers and
//! nothing more: it never sees ops or invites, and what it says is checked by admission.
//!
//! - [`server`]: a tiny UDP discovery server (`sculpt discovery --listen ADDR` calls
//!   [`serve`]). Nodes register `(discovery id, peer id)` from their QUIC socket and the
//!   server lists the request's source address (behind a NAT: the router's public address
//!   and the port it mapped), answers with the session's other peers, and introduces the
//!   newcomer to them so that both sides dial at once (hole punching), once the source has
//!   echoed the server's address cookie and signed with its peer key. The older
//!   registration `(discovery id, peer id, QUIC port)` from a separate socket is still
//!   answered (source IP with that port). Entries expire after
//!   [`registry::REGISTRATION_TTL_MICROS`]; sources are rate-limited; the reply and the
//!   introductions one request causes never add up to more bytes than the request; every
//!   limit is a named constant and every bad datagram is counted.
//! - [`rendezvous`]: the node-integrated client behind
//!   [`crate::net::NodeHandle::register_with`]: registers through the node's own socket,
//!   keeps registered, punches every peer it learns, reports [`RendezvousEvent`]s.
//! - [`client`]: [`register`] (the older registration, from a separate socket: right only
//!   where the host's address is public) and [`client::stay_registered`].
//! - [`dnssd`]: LAN sessions by DNS-SD over multicast DNS (`_sculpt._udp`), which standard
//!   browsers (avahi-browse) see too: announce this peer, list the sessions, dial our own.
//! - [`message`]: the versioned, size-limited wire format shared by all three.
//!
//! Who is listed: a registration is listed only after its source echoed the server's
//! address cookie (a Challenge answers it first) and only when it is signed by the peer id it
//! names, so nobody lists a third party's address or another peer's id, and a peer that
//! moves re-registers from its new address at once. One source (an IPv4 address or an IPv6
//! /64) holds at most [`registry::MAX_PEERS_PER_SOURCE_PER_SESSION`] entries of a session.
//!
//! Non-guarantees: registrations and announcements prove an address and a peer id, not
//! membership (the server cannot check an invite it never sees). Someone who learns a
//! session's discovery id can list peer ids of its own in it, up to
//! [`registry::MAX_PEERS_PER_SOURCE_PER_SESSION`] per source, which wastes dials but admits
//! no one. Hole punching needs NATs that map one socket to one public port whatever the
//! destination; behind a symmetric NAT on both sides (or a NAT that drops the pair's
//! packets) no direct connection forms, which is reported as
//! [`crate::net::node::Unreachable`]; nothing relays.
//! Two peers behind the same NAT are told each other's public address, which works only if
//! the router loops packets back (hairpinning); LAN discovery finds them directly.

pub mod client;
pub mod dnssd;
pub mod message;
pub mod registry;
pub mod rendezvous;
pub mod server;

pub use client::{DiscoveryError, register};
pub use message::DiscoveredPeer;
pub use rendezvous::{RegisterError, Rendezvous, RendezvousEvent};
pub use server::{DiscoveryServer, ServeError, serve};
