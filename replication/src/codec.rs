//! Wire primitives shared by every encoding: LEB128 varints, fixed arrays, length-prefixed
//! bytes, and a bounds-checked reader whose errors carry the byte offset.

/// Longest LEB128 encoding of a `u64`.
pub const MAX_VARINT_BYTES: usize = 10;

/// Why bytes could not be decoded; every variant carries the offset where decoding stopped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The input ended before the field was complete.
    #[error("unexpected end of input at byte {offset}")]
    Truncated {
        /// Byte offset of the incomplete field.
        offset: usize,
    },
    /// A varint was longer than [`MAX_VARINT_BYTES`], overflowed or was not minimal.
    #[error("malformed varint at byte {offset}")]
    BadVarint {
        /// Byte offset of the varint.
        offset: usize,
    },
    /// The version byte names a format this build does not know.
    #[error("unknown format version {version} at byte {offset}")]
    UnknownVersion {
        /// Byte offset of the version byte.
        offset: usize,
        /// The version found.
        version: u8,
    },
    /// A count or length exceeded its named limit.
    #[error("{what} is {value}, over the limit {limit}, at byte {offset}")]
    OverLimit {
        /// Byte offset of the count or length.
        offset: usize,
        /// Which field.
        what: &'static str,
        /// The value found.
        value: u64,
        /// The limit it exceeded.
        limit: u64,
    },
    /// A tag, flag or field value is not allowed here.
    #[error("invalid {what} at byte {offset}")]
    Invalid {
        /// Byte offset of the field.
        offset: usize,
        /// Which field.
        what: &'static str,
    },
    /// Bytes were left over after a complete value.
    #[error("{extra} trailing bytes at byte {offset}")]
    Trailing {
        /// Byte offset of the first extra byte.
        offset: usize,
        /// How many bytes were left over.
        extra: usize,
    },
}

impl DecodeError {
    /// The byte offset at which decoding stopped.
    pub fn offset(&self) -> usize {
        match self {
            Self::Truncated { offset }
            | Self::BadVarint { offset }
            | Self::UnknownVersion { offset, .. }
            | Self::OverLimit { offset, .. }
            | Self::Invalid { offset, .. }
            | Self::Trailing { offset, .. } => *offset,
        }
    }

    /// The same error with its offset moved by `base` (for a field decoded from a sub-slice).
    pub fn shifted(self, base: usize) -> Self {
        match self {
            Self::Truncated { offset } => Self::Truncated {
                offset: offset + base,
            },
            Self::BadVarint { offset } => Self::BadVarint {
                offset: offset + base,
            },
            Self::UnknownVersion { offset, version } => Self::UnknownVersion {
                offset: offset + base,
                version,
            },
            Self::OverLimit {
                offset,
                what,
                value,
                limit,
            } => Self::OverLimit {
                offset: offset + base,
                what,
                value,
                limit,
            },
            Self::Invalid { offset, what } => Self::Invalid {
                offset: offset + base,
                what,
            },
            Self::Trailing { offset, extra } => Self::Trailing {
                offset: offset + base,
                extra,
            },
        }
    }
}

/// Appends a LEB128 varint.
pub fn put_varint(out: &mut Vec<u8>, mut value: u64) {
    loop {
        let low = (value & 0x7f) as u8;
        value >>= 7;
        if value == 0 {
            out.push(low);
            return;
        }
        out.push(low | 0x80);
    }
}

/// Appends a varint length followed by the bytes.
pub fn put_bytes(out: &mut Vec<u8>, bytes: &[u8]) {
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// A bounds-checked cursor over untrusted bytes. It never panics and never allocates more
/// than the caller's limits allow.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    bytes: &'a [u8],
    offset: usize,
}

impl<'a> Reader<'a> {
    /// A reader at the start of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, offset: 0 }
    }

    /// Current byte offset.
    pub fn offset(&self) -> usize {
        self.offset
    }

    /// Bytes not yet read.
    pub fn remaining(&self) -> usize {
        self.bytes.len() - self.offset
    }

    /// Reads one byte.
    pub fn u8(&mut self) -> Result<u8, DecodeError> {
        let b = *self.bytes.get(self.offset).ok_or(DecodeError::Truncated {
            offset: self.offset,
        })?;
        self.offset += 1;
        Ok(b)
    }

    /// Reads a byte that must be 0 (false) or 1 (true).
    pub fn flag(&mut self) -> Result<bool, DecodeError> {
        let offset = self.offset;
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(DecodeError::Invalid {
                offset,
                what: "flag",
            }),
        }
    }

    /// Reads `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        if self.remaining() < n {
            return Err(DecodeError::Truncated {
                offset: self.offset,
            });
        }
        let s = &self.bytes[self.offset..self.offset + n];
        self.offset += n;
        Ok(s)
    }

    /// Reads a fixed-size array.
    pub fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    /// Reads a minimal LEB128 varint.
    pub fn varint(&mut self) -> Result<u64, DecodeError> {
        let start = self.offset;
        let mut value: u64 = 0;
        for i in 0..MAX_VARINT_BYTES {
            let b = self
                .u8()
                .map_err(|_| DecodeError::Truncated { offset: start })?;
            let bits = u64::from(b & 0x7f);
            let shift = 7 * i as u32;
            if shift == 63 && bits > 1 {
                return Err(DecodeError::BadVarint { offset: start });
            }
            value |= bits << shift;
            if b & 0x80 == 0 {
                // A zero final byte after the first is an overlong (non-canonical) encoding.
                if i > 0 && b == 0 {
                    return Err(DecodeError::BadVarint { offset: start });
                }
                return Ok(value);
            }
        }
        Err(DecodeError::BadVarint { offset: start })
    }

    /// Reads a varint count or length and checks it against `limit`.
    pub fn bounded(&mut self, what: &'static str, limit: u64) -> Result<usize, DecodeError> {
        let offset = self.offset;
        let value = self.varint()?;
        if value > limit {
            return Err(DecodeError::OverLimit {
                offset,
                what,
                value,
                limit,
            });
        }
        usize::try_from(value).map_err(|_| DecodeError::OverLimit {
            offset,
            what,
            value,
            limit,
        })
    }

    /// Reads length-prefixed bytes of at most `limit` bytes.
    pub fn bytes(&mut self, what: &'static str, limit: u64) -> Result<&'a [u8], DecodeError> {
        let len = self.bounded(what, limit)?;
        self.take(len)
    }

    /// Fails unless every byte was consumed.
    pub fn finish(&self) -> Result<(), DecodeError> {
        match self.remaining() {
            0 => Ok(()),
            extra => Err(DecodeError::Trailing {
                offset: self.offset,
                extra,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn overlong_and_overflowing_varints_are_rejected() {
        assert_eq!(
            Reader::new(&[0x80, 0x00]).varint(),
            Err(DecodeError::BadVarint { offset: 0 })
        );
        let too_big = [0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x02];
        assert_eq!(
            Reader::new(&too_big).varint(),
            Err(DecodeError::BadVarint { offset: 0 })
        );
        let max = [0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01];
        assert_eq!(Reader::new(&max).varint(), Ok(u64::MAX));
        assert_eq!(
            Reader::new(&[0x80]).varint(),
            Err(DecodeError::Truncated { offset: 0 })
        );
    }

    #[test]
    fn bounded_reports_offset() {
        let mut buf = vec![9];
        put_varint(&mut buf, 1000);
        let mut r = Reader::new(&buf);
        assert_eq!(r.u8(), Ok(9));
        let err = r.bounded("len", 10).unwrap_err();
        assert_eq!(err.offset(), 1);
        assert_eq!(err.shifted(5).offset(), 6);
    }

    proptest! {
        #![proptest_config(crate::test_config(256))]
        #[test]
        fn varint_round_trips(v in any::<u64>()) {
            let mut buf = Vec::new();
            put_varint(&mut buf, v);
            prop_assert!(buf.len() <= MAX_VARINT_BYTES);
            let mut r = Reader::new(&buf);
            prop_assert_eq!(r.varint(), Ok(v));
            prop_assert!(r.finish().is_ok());
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..32)) {
            let mut r = Reader::new(&bytes);
            while r.remaining() > 0 {
                if r.bytes("field", 8).is_err() { break; }
            }
        }
    }
}
