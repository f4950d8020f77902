//! The values the ephemeral channels carry ([`super::message::Message::Ephemeral`]): what each
//! channel's bytes mean, as plain data with its own versioned encoding, beside the sync
//! messages that carry them.
//!
//! Ephemeral values are latest-value-wins and never stored: a peer sends its newest on a
//! channel and a receiver keeps the newest it has heard. They come from peers, so every
//! decoder refuses any length, version or number it does not expect.
//!
//! - [`PRESENCE_CHANNEL`]: [`presence::Presence`], who a peer is and what it points at,
//!   touches, selects and looks from.
//! - [`SHARED_TOOL_CHANNEL`]: [`shared_tool::SharedToolPacket`], a shared tool's wave
//!   variables with their energy account (the haptic crate's `WavePacket` as numbers).

pub mod presence;
pub mod shared_tool;

/// The ephemeral channel presence travels on.
pub const PRESENCE_CHANNEL: u32 = 1;
/// The ephemeral channel the shared tool's wave packets travel on.
pub const SHARED_TOOL_CHANNEL: u32 = 2;
