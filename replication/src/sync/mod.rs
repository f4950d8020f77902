//! The sync protocol: wire messages ([`message`]) and the sans-IO per-remote-peer state
//! machine ([`state`]).

pub mod ephemeral;
pub mod message;
pub mod state;
