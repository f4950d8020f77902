//! The network adapters of replication: a QUIC transport that runs a [`Peer`] between real
//! sockets, and discovery of a session's peers. The sans-IO core never imports this module;
//! the simulator drives the core without it.
//!
//! It is **not** a relay or a server of ops: every node holds the full log, and a discovery
//! server only introduces peers.
//!
//! # Key types
//!
//! - [`Invite`]: an invite code, the session's one secret: 130 random bits in 7 groups of 5
//!   characters a person can read aloud, with a check character per group so that a typo is
//!   reported at its group ([`Invite::generate`] makes one, [`Invite::parse`] reads one).
//! - [`SessionKeys`]: derived from an [`Invite`]: the sync session id, the admission key and
//!   the discovery id.
//! - [`Node`] / [`NodeHandle`] / [`NodeEvent`]: one QUIC endpoint (quinn, rustls with *ring*)
//!   that accepts and dials, admits peers that prove the invite and their ed25519 id, and runs
//!   the peer's sans-IO core on one tokio task, the only place that reads the wall clock.
//!   Reliable sync messages go as length-prefixed [`frame`]s, each on a unidirectional stream
//!   of its own, so a lost packet holds up only its own message (the sync core takes messages
//!   in any order); ephemeral values go as unreliable datagrams.
//! - [`discovery`]: a tiny UDP discovery server ([`discovery::serve`]), its client, and LAN
//!   multicast announcements.
//!
//! # Trust model
//!
//! Certificates are self-signed and not verified: TLS 1.3 gives each connection secrecy and
//! integrity, and [`admission`] authenticates it. Over the connection's TLS exporter each side
//! sends a MAC keyed by the invite (it knows the session's secret) and an ed25519 signature
//! (it owns the peer id it claims); a man in the middle has two different exporters and can
//! relay neither. An admitted peer is trusted with nothing else: the core verifies every op's
//! signature, rate-limits and bounds every message, and the node cuts off a connection after
//! [`node::MAX_REJECTIONS_PER_CONN`] rejections or one oversized frame. Anyone who holds the
//! invite can join under their own id, so an invite is a bearer secret: it must be random, as
//! discovery servers and fake listeners can test guesses offline, and [`Invite::parse`]
//! refuses codes made up by hand.
//!
//! # Example
//!
//! ```no_run
//! use replication::net::{Invite, Node, NodeConfig, SessionKeys};
//! use replication::payload::test_payload::TestPayload;
//! use replication::{Keypair, Log};
//!
//! # async fn demo() -> Result<(), Box<dyn std::error::Error>> {
//! # use rand_core::SeedableRng;
//! # let code = Invite::generate(&mut rand_chacha::ChaCha20Rng::seed_from_u64(1)).to_string();
//! // `code` is an invite as a person typed it.
//! let keys = SessionKeys::from_invite(&Invite::parse(&code)?);
//! let config = |seed| NodeConfig::<TestPayload> {
//!     keypair: Keypair::from_seed([seed; 32]),
//!     keys: keys.clone(),
//!     listen: "127.0.0.1:0".parse().unwrap(),
//!     log: Log::default(),
//!     store: None,
//!     join_from_snapshot: false,
//! };
//! let alice = Node::spawn(config(1))?;
//! let bob = Node::spawn(config(2))?;
//! alice.handle.author(TestPayload::Chat("hello".into())).await?;
//! bob.handle.dial(alice.handle.local_addr()).await?;
//! # Ok(())
//! # }
//! ```
//!
//! [`Peer`]: crate::Peer

pub mod admission;
mod clock;
pub mod discovery;
pub mod frame;
pub mod invite;
pub mod node;
pub mod prefix;
pub mod session;
pub mod socket;
pub mod tls;

pub use invite::{Invite, InviteError};
pub use node::{Node, NodeConfig, NodeEvent, NodeHandle, NodeStats};
pub use session::SessionKeys;
