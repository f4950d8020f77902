//! [`SharedToolPacket`]: one side of a shared tool's coupling to the other, as wave variables
//! with an energy account (the haptic crate's `WavePacket`; the app converts), on
//! [`super::SHARED_TOOL_CHANNEL`].
//!
//! `[version 1][t][wave x][wave y][wave z][energy sent]`, the numbers little-endian f64s:
//! [`PACKET_BYTES`] long exactly. A decoder refuses another length, another version, a number
//! that is not finite and a negative energy.

/// A packet's encoding version.
const PACKET_VERSION: u8 = 1;
/// A packet's length: the version, then time, the wave's x, y, z and the energy sent, as
/// little-endian f64s.
pub const PACKET_BYTES: usize = 1 + 5 * 8;

/// A shared-tool packet as plain numbers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SharedToolPacket {
    /// The sender's servo time, seconds.
    pub t_secs: f64,
    /// The wave variable `u = (F + b v) / sqrt(2 b)`, device axes.
    pub wave: [f64; 3],
    /// Wave energy the sender has put into the link so far, joules (never negative).
    pub energy_sent_joules: f64,
}

/// Why a packet was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PacketError {
    /// Not [`PACKET_BYTES`] long.
    #[error("a shared-tool packet of {0} bytes; it is {PACKET_BYTES}")]
    Length(usize),
    /// Another version.
    #[error("shared-tool packet version {0} is not {PACKET_VERSION}")]
    Version(u8),
    /// A number that is not finite, or a negative energy.
    #[error("shared-tool packet has a bad number at byte {0}")]
    Number(usize),
}

impl SharedToolPacket {
    /// The packet as [`PACKET_BYTES`] bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(PACKET_BYTES);
        out.push(PACKET_VERSION);
        let [x, y, z] = self.wave;
        for v in [self.t_secs, x, y, z, self.energy_sent_joules] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    /// Reads what [`SharedToolPacket::encode`] wrote; anything else is an error.
    pub fn decode(bytes: &[u8]) -> Result<SharedToolPacket, PacketError> {
        if bytes.len() != PACKET_BYTES {
            return Err(PacketError::Length(bytes.len()));
        }
        if bytes[0] != PACKET_VERSION {
            return Err(PacketError::Version(bytes[0]));
        }
        let mut v = [0.0f64; 5];
        for (i, x) in v.iter_mut().enumerate() {
            let at = 1 + 8 * i;
            let mut b = [0u8; 8];
            b.copy_from_slice(&bytes[at..at + 8]);
            *x = f64::from_le_bytes(b);
            if !x.is_finite() || (i == 4 && *x < 0.0) {
                return Err(PacketError::Number(at));
            }
        }
        Ok(SharedToolPacket {
            t_secs: v[0],
            wave: [v[1], v[2], v[3]],
            energy_sent_joules: v[4],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> SharedToolPacket {
        SharedToolPacket {
            t_secs: 12.5,
            wave: [0.5, -1.0, 2.0],
            energy_sent_joules: 0.75,
        }
    }

    #[test]
    fn packets_round_trip_and_bad_ones_are_refused() {
        let p = sample();
        let bytes = p.encode();
        assert_eq!(bytes.len(), PACKET_BYTES);
        assert_eq!(SharedToolPacket::decode(&bytes), Ok(p));
        for n in 0..bytes.len() {
            assert_eq!(
                SharedToolPacket::decode(&bytes[..n]),
                Err(PacketError::Length(n))
            );
        }
        let mut version = bytes.clone();
        version[0] = 2;
        assert_eq!(
            SharedToolPacket::decode(&version),
            Err(PacketError::Version(2))
        );
        for (at, bad) in [(1, f64::NAN), (17, f64::INFINITY), (33, -1.0)] {
            let mut b = bytes.clone();
            b[at..at + 8].copy_from_slice(&bad.to_le_bytes());
            assert_eq!(
                SharedToolPacket::decode(&b),
                Err(PacketError::Number(at)),
                "{bad}"
            );
        }
    }

    #[test]
    fn bytes_written_by_the_app_before_the_format_moved_here_read_the_same() {
        // `app::touch::shared::encode_packet` of the sample, as it wrote it before this
        // module held the format.
        let old =
            "010000000000002940000000000000e03f000000000000f0bf0000000000000040000000000000e83f";
        let bytes: Vec<u8> = (0..old.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&old[i..i + 2], 16).unwrap())
            .collect();
        assert_eq!(SharedToolPacket::decode(&bytes), Ok(sample()));
        assert_eq!(sample().encode(), bytes);
    }
}
