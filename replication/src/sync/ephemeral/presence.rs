//! [`Presence`]: who a peer is and what it points at, on [`super::PRESENCE_CHANNEL`]: the
//! value the app sends, keeps per peer and draws, and its one encoding.
//!
//! `[3][name len][name][r g b][flags][pointer 3×f32][target 3×f32][orbit 3×f32][selected u64]
//! [tool 3×f32][partner 32][body 4×f32]`, little-endian; the optional parts are present when
//! their flag bit is set (bit 0 the pointer, 1 the selection, 2 the camera, 3 the tool, 4 the
//! partner, 5 the body). A decoder refuses another version, a cut or an overlong value, a name
//! over [`MAX_NAME_BYTES`] or not UTF-8, a number that is not finite and flag bits it does not
//! know.

use super::super::message::MAX_EPHEMERAL_BYTES;

/// Longest display name, in bytes.
pub const MAX_NAME_BYTES: usize = 32;
/// The encoding's version byte (2: with the touch tool; 3: with the shared tool's partner).
const VERSION: u8 = 3;
/// The longest encoding: every optional part present.
const MAX_PACKET_BYTES: usize = 2 + MAX_NAME_BYTES + 3 + 1 + 4 * 9 + 8 + 4 * 3 + 32 + 4 * 4;
// Every presence value fits in an ephemeral message.
const _: () = assert!(MAX_PACKET_BYTES <= MAX_EPHEMERAL_BYTES);

/// One peer's presence as plain data. Points are in the renderer's world (+z up), where the
/// sender's window drew them.
#[derive(Clone, Debug, PartialEq)]
pub struct Presence {
    /// The name the user chose (at most [`MAX_NAME_BYTES`]; encoding cuts a longer one at a
    /// character boundary).
    pub name: String,
    /// The user's colour (sRGB).
    pub colour: [u8; 3],
    /// The surface point under the pointer, if any.
    pub pointer: Option<[f32; 3]>,
    /// The touch tool's point, while the peer's touch is on.
    pub tool: Option<[f32; 3]>,
    /// The selected object's id.
    pub selected: Option<u64>,
    /// The camera.
    pub camera: Option<CameraPose>,
    /// The peer this one holds the touch tool with (its id).
    pub holds_tool_with: Option<[u8; 32]>,
    /// The touch tool's body, while tangible: radius, tension, friction, density (receivers
    /// check the ranges).
    pub tool_body: Option<[f32; 4]>,
}

/// An orbit camera in the renderer's world (+z up): what it looks at and from where.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPose {
    /// The point looked at.
    pub target: [f32; 3],
    /// Yaw and pitch in radians, and the distance from the target.
    pub orbit: [f32; 3],
}

/// Why a presence value was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PresenceError {
    /// Another version of the encoding.
    #[error("presence version {0} is not {VERSION}")]
    Version(u8),
    /// The bytes end early.
    #[error("presence value cut short at byte {0}")]
    Short(usize),
    /// A name over the limit or not UTF-8.
    #[error("presence name at byte {0} is over {MAX_NAME_BYTES} bytes or not UTF-8")]
    Name(usize),
    /// A coordinate that is not finite.
    #[error("presence value has a non-finite number at byte {0}")]
    NotFinite(usize),
    /// Bytes after the value.
    #[error("presence value has {0} extra bytes")]
    Trailing(usize),
    /// Flag bits this version does not know.
    #[error("presence flags {0:#010b} name parts this version does not know")]
    Flags(u8),
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

    /// The value as bytes (see the module documentation).
    pub fn encode(&self) -> Vec<u8> {
        let name = truncate(&self.name, MAX_NAME_BYTES);
        let mut out = Vec::with_capacity(64 + name.len());
        out.push(VERSION);
        out.push(name.len() as u8);
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(&self.colour);
        let flags = u8::from(self.pointer.is_some())
            | u8::from(self.selected.is_some()) << 1
            | u8::from(self.camera.is_some()) << 2
            | u8::from(self.tool.is_some()) << 3
            | u8::from(self.holds_tool_with.is_some()) << 4
            | u8::from(self.tool_body.is_some()) << 5;
        out.push(flags);
        let mut put = |v: &[f32; 3]| v.iter().for_each(|x| out.extend(x.to_le_bytes()));
        if let Some(p) = &self.pointer {
            put(p);
        }
        if let Some(c) = &self.camera {
            put(&c.target);
            put(&c.orbit);
        }
        if let Some(s) = self.selected {
            out.extend(s.to_le_bytes());
        }
        if let Some(t) = &self.tool {
            t.iter().for_each(|x| out.extend(x.to_le_bytes()));
        }
        if let Some(p) = &self.holds_tool_with {
            out.extend_from_slice(p);
        }
        if let Some(b) = &self.tool_body {
            b.iter().for_each(|x| out.extend(x.to_le_bytes()));
        }
        out
    }

    /// Reads what [`Presence::encode`] wrote; anything else is an error.
    pub fn decode(bytes: &[u8]) -> Result<Self, PresenceError> {
        let mut r = Reader { bytes, at: 0 };
        let version = r.byte()?;
        if version != VERSION {
            return Err(PresenceError::Version(version));
        }
        let len = usize::from(r.byte()?);
        let at = r.at;
        let name = std::str::from_utf8(r.take(len)?)
            .ok()
            .filter(|_| len <= MAX_NAME_BYTES)
            .ok_or(PresenceError::Name(at))?
            .to_string();
        let colour = [r.byte()?, r.byte()?, r.byte()?];
        let flags = r.byte()?;
        let pointer = (flags & 1 != 0).then(|| r.vec3()).transpose()?;
        let camera = if flags & 4 != 0 {
            Some(CameraPose {
                target: r.vec3()?,
                orbit: r.vec3()?,
            })
        } else {
            None
        };
        let selected = if flags & 2 != 0 {
            let mut b = [0u8; 8];
            b.copy_from_slice(r.take(8)?);
            Some(u64::from_le_bytes(b))
        } else {
            None
        };
        let tool = (flags & 8 != 0).then(|| r.vec3()).transpose()?;
        let holds_tool_with = if flags & 16 != 0 {
            let mut p = [0u8; 32];
            p.copy_from_slice(r.take(32)?);
            Some(p)
        } else {
            None
        };
        let tool_body = if flags & 32 != 0 {
            let [a, b, c] = r.vec3()?;
            let [d, ..] = r.vec3_part(1)?;
            Some([a, b, c, d])
        } else {
            None
        };
        if flags >> 6 != 0 {
            return Err(PresenceError::Flags(flags));
        }
        if r.at != bytes.len() {
            return Err(PresenceError::Trailing(bytes.len() - r.at));
        }
        Ok(Self {
            name,
            colour,
            pointer,
            tool,
            selected,
            camera,
            holds_tool_with,
            tool_body,
        })
    }
}

/// At most `max` bytes of `text`, cut at a character boundary.
fn truncate(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], PresenceError> {
        let end = self.at.checked_add(n).filter(|e| *e <= self.bytes.len());
        let end = end.ok_or(PresenceError::Short(self.at))?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn byte(&mut self) -> Result<u8, PresenceError> {
        Ok(self.take(1)?[0])
    }

    fn vec3(&mut self) -> Result<[f32; 3], PresenceError> {
        self.vec3_part(3)
    }

    /// The next `n` (at most 3) finite f32s, the rest zero.
    fn vec3_part(&mut self, n: usize) -> Result<[f32; 3], PresenceError> {
        let mut v = [0.0f32; 3];
        for x in v.iter_mut().take(n) {
            let at = self.at;
            let mut b = [0u8; 4];
            b.copy_from_slice(self.take(4)?);
            *x = f32::from_le_bytes(b);
            if !x.is_finite() {
                return Err(PresenceError::NotFinite(at));
            }
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Presence {
        Presence {
            name: "Ada".into(),
            colour: [10, 20, 30],
            pointer: Some([0.5, -1.0, 2.0]),
            tool: Some([0.25, 0.5, -0.75]),
            selected: Some(0x1234_5678_9abc),
            camera: Some(CameraPose {
                target: [0.0, 0.0, 0.0],
                orbit: [0.7, 0.4, 5.0],
            }),
            holds_tool_with: Some([7; 32]),
            tool_body: Some([0.1, 0.8, 0.0, 2.0]),
        }
    }

    fn bare() -> Presence {
        Presence::named("Ada".into(), [10, 20, 30])
    }

    fn from_hex(hex: &str) -> Vec<u8> {
        (0..hex.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
            .collect()
    }

    #[test]
    fn values_round_trip_with_and_without_their_optional_parts() {
        let full = sample();
        assert_eq!(Presence::decode(&full.encode()), Ok(full.clone()));
        assert_eq!(Presence::decode(&bare().encode()), Ok(bare()));
    }

    #[test]
    fn bytes_written_by_the_app_before_the_format_moved_here_read_the_same() {
        // `app::engine::presence::Presence::encode` of these values, as it wrote them before
        // this module held the format.
        let full = from_hex(concat!(
            "03034164610a141e3f0000003f000080bf000000400000000000000000000000003333333f",
            "cdcccc3e0000a040bc9a7856341200000000803e0000003f000040bf07070707070707070707",
            "07070707070707070707070707070707070707070707cdcccc3dcdcc4c3f0000000000000040",
        ));
        assert_eq!(Presence::decode(&full), Ok(sample()));
        assert_eq!(sample().encode(), full);
        let bare_bytes = from_hex("03034164610a141e00");
        assert_eq!(Presence::decode(&bare_bytes), Ok(bare()));
        assert_eq!(bare().encode(), bare_bytes);
    }

    #[test]
    fn the_longest_value_is_as_long_as_the_limit_says() {
        let longest = Presence {
            name: "n".repeat(MAX_NAME_BYTES),
            ..sample()
        };
        assert_eq!(longest.encode().len(), MAX_PACKET_BYTES);
    }

    #[test]
    fn long_names_are_cut_at_a_character_boundary() {
        let long = Presence {
            name: "é".repeat(40),
            ..sample()
        };
        let back = Presence::decode(&long.encode()).unwrap();
        assert_eq!(back.name, "é".repeat(16));
    }

    #[test]
    fn every_truncation_and_bad_value_is_an_error() {
        let bytes = sample().encode();
        for n in 0..bytes.len() {
            assert!(Presence::decode(&bytes[..n]).is_err(), "cut at {n}");
        }
        let mut extra = bytes.clone();
        extra.push(0);
        assert_eq!(Presence::decode(&extra), Err(PresenceError::Trailing(1)));
        let mut nan = bytes.clone();
        let at = 2 + 3 + 3 + 1;
        nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(Presence::decode(&nan), Err(PresenceError::NotFinite(at)));
        let mut version = bytes.clone();
        version[0] = 9;
        assert_eq!(Presence::decode(&version), Err(PresenceError::Version(9)));
        let mut long_name = bytes.clone();
        long_name[1] = 200;
        assert!(Presence::decode(&long_name).is_err());
        let mut tool_nan = bytes.clone();
        let at = bytes.len() - 16 - 32 - 4;
        tool_nan[at..at + 4].copy_from_slice(&f32::INFINITY.to_le_bytes());
        assert_eq!(
            Presence::decode(&tool_nan),
            Err(PresenceError::NotFinite(at))
        );
        let mut unknown = bytes;
        unknown[2 + 3 + 3] |= 0x40;
        assert_eq!(
            Presence::decode(&unknown),
            Err(PresenceError::Flags(unknown[2 + 3 + 3]))
        );
    }
}
