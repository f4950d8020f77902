//! The sync protocol: wire messages ([`message`]), the sans-IO per-remote-peer state
//! machine ([`state`]) and its scene check ([`scene`]).

pub mod ephemeral;
pub mod message;
pub mod scene;
pub mod state;
