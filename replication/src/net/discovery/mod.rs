//! Discovery: how peers of a session find each other's addresses. It introduces peers and
//! nothing more: it never sees ops or invites, and what it says is checked by admission.
//!
//! - [`server`]: a tiny UDP discovery server (`sculpt discovery --listen ADDR` calls
//!   [`serve`]). Peers register `(discovery id, peer id, QUIC port)`; the server lists the
//!   source IP with that port and answers with the session's other peers. Entries expire
//!   after [`registry::REGISTRATION_TTL_MICROS`]; sources are rate-limited; every limit is a
//!   named constant and every bad datagram is counted.
//! - [`client`]: [`register`] and the [`client::stay_registered`] loop for a node.
//! - [`lan`]: serverless discovery on a LAN by IPv4 multicast announcements.
//! - [`message`]: the versioned, size-limited wire format shared by all three.
//!
//! Non-guarantees: registrations and announcements are not authenticated (the server cannot
//! check an invite it never sees). Someone who learns a session's discovery id can list
//! fake peers in it, up to [`registry::MAX_PEERS_PER_SESSION`], which wastes dials but
//! admits no one; an entry can only be moved to another IP after it expires.

pub mod client;
pub mod lan;
pub mod message;
pub mod registry;
pub mod server;

pub use client::{DiscoveryError, register};
pub use message::DiscoveredPeer;
pub use server::{DiscoveryServer, ServeError, serve};
