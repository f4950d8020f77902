//! Presence: who is here and what they point at, sent on the ephemeral channel (never stored,
//! latest value wins).
//!
//! Each peer sends its display name and colour, the point of the surface under its pointer,
//! its touch tool's point while it touches, its selected object and its camera, whenever one
//! of them changes (at most [`PRESENCE_RATE_HZ`] times a second). Receivers draw the pointer,
//! the tool (a crosshair in a box, as the thesis shows other users' tools) and outline the
//! selection in the sender's colour, and may follow its camera. On the wire a presence is a
//! `replication::sync::ephemeral::presence::Presence` on its `PRESENCE_CHANNEL`: its format is
//! replication's, with the other ephemeral values, and its decoder bounds every length and
//! refuses non-finite numbers; this module holds what the app adds: how often it is sent and
//! the colour a peer starts with.

/// Most presence values a peer sends per second.
pub const PRESENCE_RATE_HZ: u64 = 20;

/// The colour a peer gets until its user picks one: from its id, so it is stable.
pub fn default_colour(peer: &[u8; 32]) -> [u8; 3] {
    const PALETTE: [[u8; 3]; 8] = [
        [230, 80, 70],
        [70, 160, 230],
        [90, 200, 110],
        [240, 180, 50],
        [180, 110, 220],
        [60, 200, 200],
        [240, 120, 180],
        [160, 160, 160],
    ];
    PALETTE[usize::from(peer[0]) % PALETTE.len()]
}
