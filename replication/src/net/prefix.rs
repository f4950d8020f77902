//! Address prefixes: the unit in which the node and the discovery server count what one
//! source may hold.
//!
//! An IPv4 source is its whole address (/32): IPv4 addresses are scarce, and a wider prefix
//! (a /24) would lump together the unrelated users of one carrier-grade NAT or campus. An
//! IPv6 source is its /64: the smallest block a network hands to one link, which one
//! host can fill with as many addresses as it likes. IPv4-mapped IPv6 addresses count as
//! the IPv4 address they carry.

use std::fmt;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};

/// Bytes of an IPv6 address that make its prefix (/64).
const IPV6_PREFIX_BYTES: usize = 8;

/// The part of a source address that per-source limits are keyed by.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum AddressPrefix {
    /// A whole IPv4 address.
    V4([u8; 4]),
    /// The first 64 bits of an IPv6 address.
    V6([u8; IPV6_PREFIX_BYTES]),
}

impl AddressPrefix {
    /// The prefix `ip` belongs to.
    pub fn of(ip: IpAddr) -> Self {
        match ip.to_canonical() {
            IpAddr::V4(v4) => Self::V4(v4.octets()),
            IpAddr::V6(v6) => {
                let mut prefix = [0; IPV6_PREFIX_BYTES];
                prefix.copy_from_slice(&v6.octets()[..IPV6_PREFIX_BYTES]);
                Self::V6(prefix)
            }
        }
    }

    /// A 64-bit name of the prefix (a hash, so no chosen prefix shares another's), for the
    /// core's source groups ([`crate::peer::Peer::accept`]).
    pub fn key(&self) -> u64 {
        let mut hasher = blake3::Hasher::new();
        match self {
            Self::V4(octets) => hasher.update(&[4]).update(octets),
            Self::V6(prefix) => hasher.update(&[6]).update(prefix),
        };
        let mut key = [0; 8];
        key.copy_from_slice(&hasher.finalize().as_bytes()[..8]);
        u64::from_le_bytes(key)
    }
}

impl fmt::Debug for AddressPrefix {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::V4(octets) => write!(f, "{}", Ipv4Addr::from(*octets)),
            Self::V6(prefix) => {
                let mut octets = [0; 16];
                octets[..IPV6_PREFIX_BYTES].copy_from_slice(prefix);
                write!(f, "{}/64", Ipv6Addr::from(octets))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ipv6_sources_count_by_their_64_and_ipv4_by_address() {
        let a: IpAddr = "2001:db8:1:2::1".parse().unwrap();
        let b: IpAddr = "2001:db8:1:2:ffff:1234:5678:9abc".parse().unwrap();
        let c: IpAddr = "2001:db8:1:3::1".parse().unwrap();
        assert_eq!(AddressPrefix::of(a), AddressPrefix::of(b));
        assert_ne!(AddressPrefix::of(a), AddressPrefix::of(c));
        assert_eq!(format!("{:?}", AddressPrefix::of(b)), "2001:db8:1:2::/64");
        let v4: IpAddr = "198.51.100.7".parse().unwrap();
        let mapped: IpAddr = "::ffff:198.51.100.7".parse().unwrap();
        assert_eq!(AddressPrefix::of(v4), AddressPrefix::of(mapped));
        let neighbour: IpAddr = "198.51.100.8".parse().unwrap();
        assert_ne!(AddressPrefix::of(v4), AddressPrefix::of(neighbour));
    }
}
