//! Discovery wire messages (version 2), one per UDP datagram.
//!
//! Every message opens with `"SCD"`, the version byte and a tag:
//!
//! - Register (tag 1): `[discovery id 16][peer id 32][QUIC port u16 BE][cookie 16]`
//!   `[ed25519 signature 64]`, then zero padding up to exactly [`REGISTER_BYTES`]. The padding
//!   makes every request at least as large as any reply, so a spoofed source address cannot
//!   turn the server into an amplifier. The server lists the datagram's source IP with the
//!   claimed port: right for a separate socket on a host with a public address, useless
//!   behind a NAT (the port is not the mapped one).
//! - Peers (tag 2): `[n ≤ MAX_PEERS_PER_REPLY]` then per peer `[peer id 32][family 4|6]`
//!   `[IPv4 4 | IPv6 16][port u16 BE]`.
//! - Announce (tag 3, the retired LAN multicast announcement, replaced by DNS-SD; still
//!   decoded so that servers count it as unexpected): `[discovery id 16][peer id 32]`
//!   `[QUIC port u16 BE]`.
//! - RegisterMapped (tag 4): `[discovery id 16][peer id 32][cookie 16][ed25519 signature 64]`,
//!   zero-padded to exactly [`REGISTER_BYTES`] like Register. Sent from the QUIC endpoint's
//!   own socket, so the server lists the datagram's whole source address, which behind a NAT
//!   is the router's public address and the port it mapped for that socket: the address
//!   other peers must dial. The server answers with Peers and introduces the sender to peers
//!   already registered this way (Introduce).
//! - Introduce (tag 5): `[discovery id 16][peer id 32][family 4|6][IPv4 4 | IPv6 16]`
//!   `[port u16 BE]`, at most [`INTRODUCE_BYTES`]: from the server to a peer registered with
//!   RegisterMapped, naming a peer that just registered (or refreshed) in its session, so both
//!   dial each other at once and each NAT sees outgoing packets before the other's arrive
//!   (hole punching). The server sends them only within the bytes of the request that caused
//!   them (see `registry`).
//! - Challenge (tag 6): `[cookie 16]`, [`CHALLENGE_BYTES`] in all: the server's answer to a
//!   registration whose cookie is missing (all zero), stale or made for another address. The
//!   client sends the registration again with this cookie, which proves that it receives
//!   at the address it registers from (a stateless, keyed MAC of that address and a time
//!   window, like a QUIC retry token).
//!
//! A registration's signature is the peer's ed25519 signature over [`REGISTER_CONTEXT`], the
//! tag, the discovery id, the peer id, the port (zero for RegisterMapped) and the cookie: it
//! proves that the registrant owns the peer id, for this address (through the cookie) and
//! session.
//!
//! Version 2 added the cookie, the signature and Challenge; a server or client of version 1
//! counts the other's messages as another version and stays silent, which the other sees as
//! no answer.
//!
//! Decoding never panics and checks every length before use.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};

use crate::codec::{DecodeError, Reader};
use crate::identity::{Keypair, PeerId, SIGNATURE_BYTES, Signature};
use crate::net::session::DiscoveryId;

/// The bytes that open every discovery message.
pub const MAGIC: &[u8; 3] = b"SCD";
/// The discovery wire version.
pub const DISCOVERY_WIRE_VERSION: u8 = 2;
/// Length of the address cookie a server issues in a Challenge.
pub const COOKIE_BYTES: usize = 16;
/// The cookie a first registration carries, before the server issued one.
pub const NO_COOKIE: Cookie = [0; COOKIE_BYTES];
/// What a registration's signature covers, first.
pub const REGISTER_CONTEXT: &[u8] = b"sculpt/discovery/register/v2";
/// Largest datagram a discovery endpoint reads; anything longer is refused.
pub const MAX_DATAGRAM_BYTES: usize = 1200;
/// Most peers in one reply.
pub const MAX_PEERS_PER_REPLY: usize = 16;
/// Header bytes: magic, version, tag.
const HEADER_BYTES: usize = MAGIC.len() + 2;
/// Bytes of one peer in a Peers list or an Introduce, at most: id, family, IPv6 address, port.
const MAX_PEER_ENTRY_BYTES: usize = 32 + 1 + 16 + 2;
/// Largest reply: header, count, and [`MAX_PEERS_PER_REPLY`] IPv6 entries.
pub const MAX_REPLY_BYTES: usize = HEADER_BYTES + 1 + MAX_PEERS_PER_REPLY * MAX_PEER_ENTRY_BYTES;
/// Exact size of a register request (padded), either kind.
pub const REGISTER_BYTES: usize = 1024;
/// Largest introduction: header, discovery id and one IPv6 peer entry.
pub const INTRODUCE_BYTES: usize = HEADER_BYTES + 16 + MAX_PEER_ENTRY_BYTES;
/// Exact size of a Challenge.
pub const CHALLENGE_BYTES: usize = HEADER_BYTES + COOKIE_BYTES;

/// A server's proof-of-address cookie (see [`DiscoveryMessage::Challenge`]).
pub type Cookie = [u8; COOKIE_BYTES];

const _: () = assert!(REGISTER_BYTES >= MAX_REPLY_BYTES);
const _: () = assert!(REGISTER_BYTES <= MAX_DATAGRAM_BYTES);
const _: () = assert!(REGISTER_BYTES >= CHALLENGE_BYTES);
const _: () =
    assert!(HEADER_BYTES + 16 + 32 + 2 + COOKIE_BYTES + SIGNATURE_BYTES <= REGISTER_BYTES);

const TAG_REGISTER: u8 = 1;
const TAG_PEERS: u8 = 2;
const TAG_ANNOUNCE: u8 = 3;
const TAG_REGISTER_MAPPED: u8 = 4;
const TAG_INTRODUCE: u8 = 5;
const TAG_CHALLENGE: u8 = 6;

/// A peer found by discovery: whom to dial, and where.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct DiscoveredPeer {
    /// The peer's claimed id (proven only at admission).
    pub peer: PeerId,
    /// Its QUIC address.
    pub addr: SocketAddr,
}

/// One discovery message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DiscoveryMessage {
    /// A peer asks the server to list it under a session and to name the others.
    Register {
        /// The session.
        discovery_id: DiscoveryId,
        /// The registering peer.
        peer: PeerId,
        /// Its QUIC port (the address is the datagram's source address).
        port: u16,
        /// The cookie of the server's last Challenge to this address, or [`NO_COOKIE`].
        cookie: Cookie,
        /// The peer's signature (see the module's documentation).
        signature: Signature,
    },
    /// The server's answer: the other peers of the session.
    Peers(Vec<DiscoveredPeer>),
    /// A LAN announcement.
    Announce {
        /// The session.
        discovery_id: DiscoveryId,
        /// The announcing peer.
        peer: PeerId,
        /// Its QUIC port (the address is the datagram's source address).
        port: u16,
    },
    /// A peer asks the server to list it at the datagram's source address (IP and port, as
    /// its NAT mapped them), which must be its QUIC socket, and to name the others.
    RegisterMapped {
        /// The session.
        discovery_id: DiscoveryId,
        /// The registering peer.
        peer: PeerId,
        /// The cookie of the server's last Challenge to this address, or [`NO_COOKIE`].
        cookie: Cookie,
        /// The peer's signature (see the module's documentation).
        signature: Signature,
    },
    /// The server tells a registered peer about another peer of its session that just
    /// registered (or refreshed), so that both dial each other at once.
    Introduce {
        /// The session.
        discovery_id: DiscoveryId,
        /// The newcomer and its public address.
        peer: DiscoveredPeer,
    },
    /// The server asks a registrant to prove its address: register again with this cookie.
    Challenge {
        /// The cookie to echo.
        cookie: Cookie,
    },
}

impl DiscoveryMessage {
    /// True for the messages a server sends to peers (Peers, Introduce, Challenge): what a
    /// node's socket takes out of the QUIC traffic for its discovery client.
    pub fn is_reply(&self) -> bool {
        matches!(
            self,
            Self::Peers(_) | Self::Introduce { .. } | Self::Challenge { .. }
        )
    }

    /// A signed Register of `keypair`'s peer id, reachable on `port` at the source IP.
    pub fn register(
        keypair: &Keypair,
        discovery_id: DiscoveryId,
        port: u16,
        cookie: Cookie,
    ) -> Self {
        let peer = keypair.peer_id();
        let signed = signed_bytes(TAG_REGISTER, &discovery_id, &peer, port, &cookie);
        Self::Register {
            discovery_id,
            peer,
            port,
            cookie,
            signature: keypair.sign(&signed),
        }
    }

    /// A signed RegisterMapped of `keypair`'s peer id.
    pub fn register_mapped(keypair: &Keypair, discovery_id: DiscoveryId, cookie: Cookie) -> Self {
        let peer = keypair.peer_id();
        let signed = signed_bytes(TAG_REGISTER_MAPPED, &discovery_id, &peer, 0, &cookie);
        Self::RegisterMapped {
            discovery_id,
            peer,
            cookie,
            signature: keypair.sign(&signed),
        }
    }

    /// True when this is a registration signed by the peer it names.
    pub fn signature_holds(&self) -> bool {
        let (tag, discovery_id, peer, port, cookie, signature) = match self {
            Self::Register {
                discovery_id,
                peer,
                port,
                cookie,
                signature,
            } => (TAG_REGISTER, discovery_id, peer, *port, cookie, signature),
            Self::RegisterMapped {
                discovery_id,
                peer,
                cookie,
                signature,
            } => (
                TAG_REGISTER_MAPPED,
                discovery_id,
                peer,
                0,
                cookie,
                signature,
            ),
            _ => return false,
        };
        let signed = signed_bytes(tag, discovery_id, peer, port, cookie);
        peer.verify(&signed, signature).is_ok()
    }
}

/// What a registration's signature covers.
fn signed_bytes(
    tag: u8,
    discovery_id: &DiscoveryId,
    peer: &PeerId,
    port: u16,
    cookie: &Cookie,
) -> Vec<u8> {
    let mut out = REGISTER_CONTEXT.to_vec();
    out.push(tag);
    out.extend_from_slice(discovery_id);
    out.extend_from_slice(&peer.0);
    out.extend_from_slice(&port.to_be_bytes());
    out.extend_from_slice(cookie);
    out
}

impl DiscoveryMessage {
    /// The encoded message (a Peers list is cut at [`MAX_PEERS_PER_REPLY`]).
    pub fn encode(&self) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.push(DISCOVERY_WIRE_VERSION);
        match self {
            Self::Register {
                discovery_id,
                peer,
                port,
                cookie,
                signature,
            } => {
                out.push(TAG_REGISTER);
                put_entry(&mut out, discovery_id, peer, *port);
                out.extend_from_slice(cookie);
                out.extend_from_slice(&signature.0);
                out.resize(REGISTER_BYTES, 0);
            }
            Self::Peers(peers) => {
                out.push(TAG_PEERS);
                let peers = &peers[..peers.len().min(MAX_PEERS_PER_REPLY)];
                out.push(peers.len() as u8);
                for d in peers {
                    put_peer(&mut out, d);
                }
            }
            Self::Announce {
                discovery_id,
                peer,
                port,
            } => {
                out.push(TAG_ANNOUNCE);
                put_entry(&mut out, discovery_id, peer, *port);
            }
            Self::RegisterMapped {
                discovery_id,
                peer,
                cookie,
                signature,
            } => {
                out.push(TAG_REGISTER_MAPPED);
                out.extend_from_slice(discovery_id);
                out.extend_from_slice(&peer.0);
                out.extend_from_slice(cookie);
                out.extend_from_slice(&signature.0);
                out.resize(REGISTER_BYTES, 0);
            }
            Self::Introduce { discovery_id, peer } => {
                out.push(TAG_INTRODUCE);
                out.extend_from_slice(discovery_id);
                put_peer(&mut out, peer);
            }
            Self::Challenge { cookie } => {
                out.push(TAG_CHALLENGE);
                out.extend_from_slice(cookie);
            }
        }
        out
    }

    /// Decodes one message from untrusted bytes.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        if bytes.len() > MAX_DATAGRAM_BYTES {
            return Err(DecodeError::OverLimit {
                offset: 0,
                what: "discovery datagram length",
                value: bytes.len() as u64,
                limit: MAX_DATAGRAM_BYTES as u64,
            });
        }
        let mut r = Reader::new(bytes);
        if r.array::<3>()? != *MAGIC {
            return Err(DecodeError::Invalid {
                offset: 0,
                what: "discovery magic",
            });
        }
        let version = r.u8()?;
        if version != DISCOVERY_WIRE_VERSION {
            return Err(DecodeError::UnknownVersion {
                offset: MAGIC.len(),
                version,
            });
        }
        let tag_offset = r.offset();
        let message = match r.u8()? {
            TAG_REGISTER => {
                check_register_length(bytes)?;
                read_register(&mut r)?
            }
            TAG_PEERS => Self::Peers(read_peers(&mut r)?),
            TAG_ANNOUNCE => {
                let (discovery_id, peer, port) = read_entry(&mut r)?;
                Self::Announce {
                    discovery_id,
                    peer,
                    port,
                }
            }
            TAG_REGISTER_MAPPED => {
                check_register_length(bytes)?;
                read_register_mapped(&mut r)?
            }
            TAG_INTRODUCE => {
                let discovery_id = r.array()?;
                let peer = read_peer(&mut r)?;
                Self::Introduce { discovery_id, peer }
            }
            TAG_CHALLENGE => Self::Challenge { cookie: r.array()? },
            _ => {
                return Err(DecodeError::Invalid {
                    offset: tag_offset,
                    what: "discovery tag",
                });
            }
        };
        r.finish()?;
        Ok(message)
    }
}

/// Reads a register's fields (after its tag), padding included.
fn read_register(r: &mut Reader<'_>) -> Result<DiscoveryMessage, DecodeError> {
    let (discovery_id, peer, port) = read_entry(r)?;
    let cookie = r.array()?;
    let signature = Signature(r.array()?);
    read_padding(r)?;
    Ok(DiscoveryMessage::Register {
        discovery_id,
        peer,
        port,
        cookie,
        signature,
    })
}

/// Reads a mapped register's fields (after its tag), padding included.
fn read_register_mapped(r: &mut Reader<'_>) -> Result<DiscoveryMessage, DecodeError> {
    let discovery_id = r.array()?;
    let peer = PeerId(r.array()?);
    let cookie = r.array()?;
    let signature = Signature(r.array()?);
    read_padding(r)?;
    Ok(DiscoveryMessage::RegisterMapped {
        discovery_id,
        peer,
        cookie,
        signature,
    })
}

fn check_register_length(bytes: &[u8]) -> Result<(), DecodeError> {
    if bytes.len() != REGISTER_BYTES {
        return Err(DecodeError::Invalid {
            offset: 0,
            what: "register length",
        });
    }
    Ok(())
}

fn read_padding(r: &mut Reader<'_>) -> Result<(), DecodeError> {
    let padding_offset = r.offset();
    if r.take(r.remaining())?.iter().any(|&b| b != 0) {
        return Err(DecodeError::Invalid {
            offset: padding_offset,
            what: "register padding",
        });
    }
    Ok(())
}

fn put_peer(out: &mut Vec<u8>, d: &DiscoveredPeer) {
    out.extend_from_slice(&d.peer.0);
    match d.addr.ip() {
        IpAddr::V4(ip) => {
            out.push(4);
            out.extend_from_slice(&ip.octets());
        }
        IpAddr::V6(ip) => {
            out.push(6);
            out.extend_from_slice(&ip.octets());
        }
    }
    out.extend_from_slice(&d.addr.port().to_be_bytes());
}

fn put_entry(out: &mut Vec<u8>, discovery_id: &DiscoveryId, peer: &PeerId, port: u16) {
    out.extend_from_slice(discovery_id);
    out.extend_from_slice(&peer.0);
    out.extend_from_slice(&port.to_be_bytes());
}

fn read_entry(r: &mut Reader<'_>) -> Result<(DiscoveryId, PeerId, u16), DecodeError> {
    let discovery_id = r.array()?;
    let peer = PeerId(r.array()?);
    let port = u16::from_be_bytes(r.array()?);
    Ok((discovery_id, peer, port))
}

fn read_peers(r: &mut Reader<'_>) -> Result<Vec<DiscoveredPeer>, DecodeError> {
    let count_offset = r.offset();
    let n = usize::from(r.u8()?);
    if n > MAX_PEERS_PER_REPLY {
        return Err(DecodeError::OverLimit {
            offset: count_offset,
            what: "peers in a reply",
            value: n as u64,
            limit: MAX_PEERS_PER_REPLY as u64,
        });
    }
    let mut peers = Vec::with_capacity(n);
    for _ in 0..n {
        peers.push(read_peer(r)?);
    }
    Ok(peers)
}

fn read_peer(r: &mut Reader<'_>) -> Result<DiscoveredPeer, DecodeError> {
    let peer = PeerId(r.array()?);
    let family_offset = r.offset();
    let ip = match r.u8()? {
        4 => IpAddr::V4(Ipv4Addr::from(r.array::<4>()?)),
        6 => IpAddr::V6(Ipv6Addr::from(r.array::<16>()?)),
        _ => {
            return Err(DecodeError::Invalid {
                offset: family_offset,
                what: "address family",
            });
        }
    };
    let port = u16::from_be_bytes(r.array()?);
    Ok(DiscoveredPeer {
        peer,
        addr: SocketAddr::new(ip, port),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn messages_round_trip_and_replies_fit_in_a_request() {
        let peers: Vec<DiscoveredPeer> = (0..MAX_PEERS_PER_REPLY as u8)
            .map(|i| DiscoveredPeer {
                peer: PeerId([i; 32]),
                addr: SocketAddr::new(IpAddr::V6(Ipv6Addr::LOCALHOST), 1000 + u16::from(i)),
            })
            .collect();
        let reply = DiscoveryMessage::Peers(peers);
        let bytes = reply.encode();
        assert_eq!(bytes.len(), MAX_REPLY_BYTES);
        assert_eq!(DiscoveryMessage::decode(&bytes), Ok(reply));
        let keypair = Keypair::from_seed([4; 32]);
        let register = DiscoveryMessage::register(&keypair, [3; 16], 4433, [5; COOKIE_BYTES]);
        assert!(register.signature_holds());
        let bytes = register.encode();
        assert_eq!(bytes.len(), REGISTER_BYTES);
        assert_eq!(DiscoveryMessage::decode(&bytes), Ok(register));
        // Unpadded or dirty-padded registrations are refused.
        assert!(DiscoveryMessage::decode(&bytes[..REGISTER_BYTES - 1]).is_err());
        let mut dirty = bytes.clone();
        dirty[REGISTER_BYTES - 1] = 1;
        assert!(DiscoveryMessage::decode(&dirty).is_err());
        let mut newer = bytes;
        newer[3] = 3;
        assert!(matches!(
            DiscoveryMessage::decode(&newer),
            Err(DecodeError::UnknownVersion { version: 3, .. })
        ));
        let announce = DiscoveryMessage::Announce {
            discovery_id: [5; 16],
            peer: PeerId([6; 32]),
            port: 1,
        };
        assert_eq!(DiscoveryMessage::decode(&announce.encode()), Ok(announce));
    }

    #[test]
    fn mapped_registrations_and_introductions_round_trip() {
        let register =
            DiscoveryMessage::register_mapped(&Keypair::from_seed([8; 32]), [7; 16], NO_COOKIE);
        assert!(register.signature_holds());
        let bytes = register.encode();
        assert_eq!(bytes.len(), REGISTER_BYTES);
        assert_eq!(DiscoveryMessage::decode(&bytes), Ok(register));
        assert!(!DiscoveryMessage::decode(&bytes).unwrap().is_reply());
        assert!(DiscoveryMessage::decode(&bytes[..REGISTER_BYTES - 1]).is_err());
        let mut dirty = bytes;
        dirty[REGISTER_BYTES - 1] = 1;
        assert!(DiscoveryMessage::decode(&dirty).is_err());
        for ip in [
            IpAddr::V6(Ipv6Addr::LOCALHOST),
            IpAddr::V4(Ipv4Addr::new(198, 51, 100, 1)),
        ] {
            let introduce = DiscoveryMessage::Introduce {
                discovery_id: [9; 16],
                peer: DiscoveredPeer {
                    peer: PeerId([10; 32]),
                    addr: SocketAddr::new(ip, 40_000),
                },
            };
            let bytes = introduce.encode();
            assert!(bytes.len() <= INTRODUCE_BYTES);
            assert_eq!(DiscoveryMessage::decode(&bytes), Ok(introduce.clone()));
            assert!(introduce.is_reply());
            // Truncated or extended introductions are refused.
            assert!(DiscoveryMessage::decode(&bytes[..bytes.len() - 1]).is_err());
            let mut longer = bytes;
            longer.push(0);
            assert!(DiscoveryMessage::decode(&longer).is_err());
        }
        assert_eq!(
            DiscoveryMessage::Introduce {
                discovery_id: [0; 16],
                peer: DiscoveredPeer {
                    peer: PeerId([0; 32]),
                    addr: SocketAddr::new(IpAddr::V6(Ipv6Addr::LOCALHOST), 1),
                },
            }
            .encode()
            .len(),
            INTRODUCE_BYTES
        );
    }

    #[test]
    fn challenges_are_small_and_signatures_bind_every_field() {
        let challenge = DiscoveryMessage::Challenge {
            cookie: [7; COOKIE_BYTES],
        };
        let bytes = challenge.encode();
        assert_eq!(bytes.len(), CHALLENGE_BYTES);
        assert!(bytes.len() < REGISTER_BYTES);
        assert_eq!(DiscoveryMessage::decode(&bytes), Ok(challenge.clone()));
        assert!(challenge.is_reply());
        assert!(DiscoveryMessage::decode(&bytes[..CHALLENGE_BYTES - 1]).is_err());
        let keypair = Keypair::from_seed([1; 32]);
        let mallory = Keypair::from_seed([2; 32]);
        let cookie = [3; COOKIE_BYTES];
        let signed = DiscoveryMessage::register_mapped(&keypair, [4; 16], cookie);
        // Another cookie, session or peer id under the same signature does not hold.
        let DiscoveryMessage::RegisterMapped { signature, .. } = signed.clone() else {
            unreachable!()
        };
        for (discovery_id, peer, cookie) in [
            ([4; 16], keypair.peer_id(), [9; COOKIE_BYTES]),
            ([5; 16], keypair.peer_id(), cookie),
            ([4; 16], mallory.peer_id(), cookie),
        ] {
            let forged = DiscoveryMessage::RegisterMapped {
                discovery_id,
                peer,
                cookie,
                signature,
            };
            assert!(!forged.signature_holds());
        }
        // A mapped registration's signature does not hold as a plain one.
        let plain = DiscoveryMessage::Register {
            discovery_id: [4; 16],
            peer: keypair.peer_id(),
            port: 0,
            cookie,
            signature,
        };
        assert!(!plain.signature_holds());
        assert!(signed.signature_holds());
        assert!(!challenge.signature_holds());
    }

    proptest! {
        #![proptest_config(crate::test_config(256))]
        #[test]
        fn arbitrary_bytes_never_panic(mut bytes in proptest::collection::vec(any::<u8>(), 0..1300), tag in 1u8..8) {
            if bytes.len() >= 5 {
                bytes[..3].copy_from_slice(MAGIC);
                bytes[3] = DISCOVERY_WIRE_VERSION;
                bytes[4] = tag;
            }
            if let Ok(m) = DiscoveryMessage::decode(&bytes) {
                prop_assert_eq!(m.encode(), bytes);
            }
        }
    }
}
