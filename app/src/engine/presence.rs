//! Presence: who is here and what they point at, sent on the ephemeral channel (never stored,
//! latest value wins).
//!
//! Each peer sends its display name and colour, the point of the surface under its pointer,
//! its touch tool's point while it touches, its selected object and its camera, whenever one
//! of them changes (at most [`PRESENCE_RATE_HZ`] times a second). Receivers draw the pointer,
//! the tool (a crosshair in a box, as the thesis shows other users' tools) and outline the
//! selection in the sender's colour, and may follow its camera. On the wire a presence is a
//! [`PresencePacket`] on `replication::sync::ephemeral::PRESENCE_CHANNEL`: its format is
//! replication's, with the other ephemeral values, and its decoder bounds every length and
//! refuses non-finite numbers; this module converts.

use replication::sync::ephemeral::presence::{PresenceError, PresencePacket};

/// Most presence values a peer sends per second.
pub const PRESENCE_RATE_HZ: u64 = 20;

/// An orbit camera in the renderer's world (+z up): what it looks at and from where.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPose {
    /// The point looked at.
    pub target: [f32; 3],
    /// Yaw and pitch in radians, and the distance from the target.
    pub orbit: [f32; 3],
}

/// One peer's presence.
#[derive(Clone, Debug, PartialEq)]
pub struct Presence {
    /// The name the user chose (at most
    /// `replication::sync::ephemeral::presence::MAX_NAME_BYTES`).
    pub name: String,
    /// The user's colour (sRGB).
    pub colour: [u8; 3],
    /// The surface point under the pointer (the renderer's world, +z up), if any.
    pub pointer: Option<[f32; 3]>,
    /// The touch tool's point (the renderer's world), while the peer's touch is on.
    pub tool: Option<[f32; 3]>,
    /// The selected object.
    pub selected: Option<u64>,
    /// The camera.
    pub camera: Option<CameraPose>,
    /// The peer this one holds the touch tool with (`app::touch::shared`): the two are
    /// coupled when each names the other.
    pub holds_tool_with: Option<[u8; 32]>,
    /// The touch tool's body, while tangible: radius, tension, friction, density
    /// (`app::touch::body::ToolBody`, which receivers check).
    pub tool_body: Option<[f32; 4]>,
}

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

impl Presence {
    /// A user's name and colour, with nothing pointed at, touched, selected or held.
    pub fn named(name: String, colour: [u8; 3]) -> Self {
        Self {
            name,
            colour,
            pointer: None,
            tool: None,
            selected: None,
            camera: None,
            holds_tool_with: None,
            tool_body: None,
        }
    }

    /// The value as sent on presence's channel ([`PresencePacket::encode`]; a name over the
    /// limit is cut at a character boundary).
    pub fn encode(&self) -> Vec<u8> {
        PresencePacket::from(self).encode()
    }

    /// Reads a value another peer sent ([`PresencePacket::decode`]).
    pub fn decode(bytes: &[u8]) -> Result<Self, PresenceError> {
        PresencePacket::decode(bytes).map(Presence::from)
    }
}

impl From<&Presence> for PresencePacket {
    fn from(p: &Presence) -> Self {
        PresencePacket {
            name: p.name.clone(),
            colour: p.colour,
            pointer: p.pointer,
            tool: p.tool,
            selected: p.selected,
            camera: p.camera.map(|c| [c.target, c.orbit]),
            holds_tool_with: p.holds_tool_with,
            tool_body: p.tool_body,
        }
    }
}

impl From<PresencePacket> for Presence {
    fn from(p: PresencePacket) -> Self {
        Presence {
            name: p.name,
            colour: p.colour,
            pointer: p.pointer,
            tool: p.tool,
            selected: p.selected,
            camera: p.camera.map(|[target, orbit]| CameraPose { target, orbit }),
            holds_tool_with: p.holds_tool_with,
            tool_body: p.tool_body,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presence_travels_as_its_packet_and_back_whole() {
        let full = Presence {
            name: "Ada".into(),
            colour: [10, 20, 30],
            pointer: Some([0.5, -1.0, 2.0]),
            tool: Some([0.25, 0.5, -0.75]),
            selected: Some(0x1234_5678_9abc),
            camera: Some(CameraPose {
                target: [0.0, 1.0, 0.0],
                orbit: [0.7, 0.4, 5.0],
            }),
            holds_tool_with: Some([7; 32]),
            tool_body: Some([0.1, 0.8, 0.0, 2.0]),
        };
        assert_eq!(Presence::decode(&full.encode()), Ok(full.clone()));
        let bare = Presence::named(full.name.clone(), full.colour);
        assert_eq!(Presence::decode(&bare.encode()), Ok(bare));
        let packet = PresencePacket::from(&full);
        assert_eq!(packet.camera, Some([[0.0, 1.0, 0.0], [0.7, 0.4, 5.0]]));
        assert_eq!(Presence::from(packet), full);
    }
}
