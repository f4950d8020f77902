//! Admission: after the QUIC handshake, each side proves on the admission stream that it knows the
//! session's invite and owns the ed25519 peer id it claims, both bound to this very connection.
//!
//! Both sides compute the same 32-byte TLS exporter value (RFC 5705/8446) from the
//! connection's secrets. Each sends one [`AdmissionFrame`]:
//!
//! `[ADMISSION_VERSION][role][peer id 32][ed25519 signature 64][MAC 32]`
//!
//! - the MAC is blake3 keyed with the session's admission key over
//!   `"sculpt/admission/v1" || role || peer || exporter`: it proves knowledge of the invite;
//! - the signature is the peer's ed25519 signature over `"sculpt/admission/v1" || role ||
//!   exporter`: it proves the peer id, so no one can join under another peer's id;
//! - the role byte (dialer or acceptor) stops a frame from being reflected back.
//!
//! A man in the middle has two TLS sessions with two different exporters, so it cannot relay
//! a frame; without the invite it cannot make one either. The dialer speaks first and the
//! acceptor answers only after checking it, so a stranger learns nothing, not even the
//! acceptor's peer id. A peer that knows the invite can join under its own id (that is what
//! an invite is for); what it sends afterwards is still checked op by op by the core.

use std::time::Duration;

use crate::identity::{Keypair, PEER_ID_BYTES, PeerId, SIGNATURE_BYTES, Signature};
use crate::net::node::CloseCode;
use crate::net::session::SessionKeys;

/// Version byte that opens an admission frame.
pub const ADMISSION_VERSION: u8 = 1;
/// Length of an admission frame.
pub const ADMISSION_FRAME_BYTES: usize = 2 + PEER_ID_BYTES + SIGNATURE_BYTES + MAC_BYTES;
/// Length of the admission MAC.
pub const MAC_BYTES: usize = 32;
/// Length of the exporter value both sides bind to.
pub const EXPORTER_BYTES: usize = 32;
/// The TLS exporter label.
pub const EXPORTER_LABEL: &[u8] = b"EXPORTER-sculpt-admission-v1";
/// A connection that has not completed the handshake and admission within this long is
/// dropped.
pub const ADMISSION_TIMEOUT_MILLIS: u64 = 5_000;

const CONTEXT: &[u8] = b"sculpt/admission/v1";

/// Which end of the connection a frame comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Role {
    /// The side that dialed (and speaks first).
    Dialer,
    /// The side that accepted.
    Acceptor,
}

impl Role {
    fn byte(self) -> u8 {
        match self {
            Self::Dialer => 1,
            Self::Acceptor => 2,
        }
    }

    fn other(self) -> Self {
        match self {
            Self::Dialer => Self::Acceptor,
            Self::Acceptor => Self::Dialer,
        }
    }
}

/// Why a connection was not admitted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AdmissionError {
    /// The frame is not well formed.
    #[error("malformed admission frame: {0}")]
    Malformed(&'static str),
    /// An admission version this build does not know.
    #[error("unknown admission version {0}")]
    UnknownVersion(u8),
    /// The frame claims the wrong role (a reflected frame).
    #[error("admission frame from the wrong role")]
    WrongRole,
    /// The MAC does not verify: the remote does not know this session's invite.
    #[error("the remote does not know the invite")]
    WrongInvite,
    /// The signature does not verify under the claimed peer id.
    #[error("the remote does not own the peer id it claims")]
    BadSignature,
    /// The handshake or admission took longer than [`ADMISSION_TIMEOUT_MILLIS`].
    #[error("admission timed out")]
    Timeout,
    /// The TLS exporter was not available.
    #[error("TLS exporter unavailable")]
    Exporter,
    /// The QUIC handshake or the stream failed.
    #[error("connection failed during admission: {0}")]
    Connection(String),
    /// The remote closed the connection: it refused our admission.
    #[error("the remote refused admission: {0}")]
    RefusedByRemote(String),
    /// The remote closed the connection because it keeps another one to this peer (both
    /// sides dialed at once): not a refusal, the peers are connected.
    #[error("the remote kept another connection to this peer")]
    Superseded,
}

/// One side's proof.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AdmissionFrame {
    /// The side that made it.
    pub role: Role,
    /// The claimed peer id.
    pub peer: PeerId,
    /// Signature by `peer` over the context, role and exporter.
    pub signature: Signature,
    /// MAC under the admission key over the context, role, peer and exporter.
    pub mac: [u8; MAC_BYTES],
}

fn mac(
    keys: &SessionKeys,
    role: Role,
    peer: &PeerId,
    exporter: &[u8; EXPORTER_BYTES],
) -> blake3::Hash {
    let mut hasher = blake3::Hasher::new_keyed(keys.admission_key());
    hasher.update(CONTEXT);
    hasher.update(&[role.byte()]);
    hasher.update(&peer.0);
    hasher.update(exporter);
    hasher.finalize()
}

fn signed_message(role: Role, exporter: &[u8; EXPORTER_BYTES]) -> Vec<u8> {
    let mut message = CONTEXT.to_vec();
    message.push(role.byte());
    message.extend_from_slice(exporter);
    message
}

impl AdmissionFrame {
    /// Makes this side's proof for a connection with exporter value `exporter`.
    pub fn prove(
        keys: &SessionKeys,
        keypair: &Keypair,
        role: Role,
        exporter: &[u8; EXPORTER_BYTES],
    ) -> Self {
        let peer = keypair.peer_id();
        Self {
            role,
            peer,
            signature: keypair.sign(&signed_message(role, exporter)),
            mac: *mac(keys, role, &peer, exporter).as_bytes(),
        }
    }

    /// Checks a remote proof: it must come from the other role, know the invite (the MAC,
    /// compared in constant time) and own its peer id (the signature). Returns the peer id.
    pub fn verify(
        &self,
        keys: &SessionKeys,
        local_role: Role,
        exporter: &[u8; EXPORTER_BYTES],
    ) -> Result<PeerId, AdmissionError> {
        if self.role != local_role.other() {
            return Err(AdmissionError::WrongRole);
        }
        if mac(keys, self.role, &self.peer, exporter) != blake3::Hash::from(self.mac) {
            return Err(AdmissionError::WrongInvite);
        }
        self.peer
            .verify(&signed_message(self.role, exporter), &self.signature)
            .map_err(|_| AdmissionError::BadSignature)?;
        Ok(self.peer)
    }

    /// The encoded frame.
    pub fn encode(&self) -> [u8; ADMISSION_FRAME_BYTES] {
        let mut out = [0; ADMISSION_FRAME_BYTES];
        out[0] = ADMISSION_VERSION;
        out[1] = self.role.byte();
        let (peer, rest) = out[2..].split_at_mut(PEER_ID_BYTES);
        peer.copy_from_slice(&self.peer.0);
        let (signature, mac) = rest.split_at_mut(SIGNATURE_BYTES);
        signature.copy_from_slice(&self.signature.0);
        mac.copy_from_slice(&self.mac);
        out
    }

    /// Decodes a frame from untrusted bytes.
    pub fn decode(bytes: &[u8]) -> Result<Self, AdmissionError> {
        let mut r = crate::codec::Reader::new(bytes);
        let malformed = |_| AdmissionError::Malformed("truncated");
        let version = r.u8().map_err(malformed)?;
        if version != ADMISSION_VERSION {
            return Err(AdmissionError::UnknownVersion(version));
        }
        let role = match r.u8().map_err(malformed)? {
            1 => Role::Dialer,
            2 => Role::Acceptor,
            _ => return Err(AdmissionError::Malformed("role")),
        };
        let frame = Self {
            role,
            peer: PeerId(r.array().map_err(malformed)?),
            signature: Signature(r.array().map_err(malformed)?),
            mac: r.array().map_err(malformed)?,
        };
        r.finish()
            .map_err(|_| AdmissionError::Malformed("trailing bytes"))?;
        Ok(frame)
    }
}

/// The connection's exporter value for admission.
pub fn exporter(connection: &quinn::Connection) -> Result<[u8; EXPORTER_BYTES], AdmissionError> {
    let mut out = [0; EXPORTER_BYTES];
    connection
        .export_keying_material(&mut out, EXPORTER_LABEL, &[])
        .map_err(|_| AdmissionError::Exporter)?;
    Ok(out)
}

/// The admission stream of an admitted connection and the remote's proven peer id. The
/// stream carries nothing after the proofs; either side finishing it ends the connection.
#[derive(Debug)]
pub struct Admitted {
    /// The remote's peer id, proven by its signature.
    pub peer: PeerId,
    /// This side's half of the admission stream.
    pub send: quinn::SendStream,
    /// The remote's half of the admission stream.
    pub recv: quinn::RecvStream,
}

/// Maps a lost connection: a remote that closed it has refused us, unless it closed it as a
/// duplicate of another connection between the same two peers.
fn connection_error(e: &quinn::ConnectionError) -> AdmissionError {
    match e {
        quinn::ConnectionError::ApplicationClosed(close)
            if close.error_code == CloseCode::Duplicate.var_int() =>
        {
            AdmissionError::Superseded
        }
        quinn::ConnectionError::ApplicationClosed(close) => {
            AdmissionError::RefusedByRemote(String::from_utf8_lossy(&close.reason).into_owned())
        }
        e => AdmissionError::Connection(e.to_string()),
    }
}

fn read_error(e: quinn::ReadExactError) -> AdmissionError {
    match e {
        quinn::ReadExactError::ReadError(quinn::ReadError::ConnectionLost(lost)) => {
            connection_error(&lost)
        }
        quinn::ReadExactError::FinishedEarly(_) => AdmissionError::Malformed("stream ended"),
        e => AdmissionError::Connection(e.to_string()),
    }
}

fn write_error(e: quinn::WriteError) -> AdmissionError {
    match e {
        quinn::WriteError::ConnectionLost(lost) => connection_error(&lost),
        e => AdmissionError::Connection(e.to_string()),
    }
}

async fn read_admission(recv: &mut quinn::RecvStream) -> Result<AdmissionFrame, AdmissionError> {
    let mut bytes = [0; ADMISSION_FRAME_BYTES];
    recv.read_exact(&mut bytes).await.map_err(read_error)?;
    AdmissionFrame::decode(&bytes)
}

/// The dialer's half: opens the admission stream, sends its proof, checks the acceptor's.
/// The caller applies [`ADMISSION_TIMEOUT_MILLIS`] and closes the connection on error.
pub async fn admit_dialer(
    connection: &quinn::Connection,
    keys: &SessionKeys,
    keypair: &Keypair,
) -> Result<Admitted, AdmissionError> {
    let exporter = exporter(connection)?;
    let (mut send, mut recv) = connection
        .open_bi()
        .await
        .map_err(|e| connection_error(&e))?;
    let proof = AdmissionFrame::prove(keys, keypair, Role::Dialer, &exporter);
    send.write_all(&proof.encode()).await.map_err(write_error)?;
    let peer = read_admission(&mut recv)
        .await?
        .verify(keys, Role::Dialer, &exporter)?;
    Ok(Admitted { peer, send, recv })
}

/// The acceptor's half: accepts the admission stream, checks the dialer's proof, then answers.
/// The caller applies [`ADMISSION_TIMEOUT_MILLIS`] and closes the connection on error.
pub async fn admit_acceptor(
    connection: &quinn::Connection,
    keys: &SessionKeys,
    keypair: &Keypair,
) -> Result<Admitted, AdmissionError> {
    let exporter = exporter(connection)?;
    let (mut send, mut recv) = connection
        .accept_bi()
        .await
        .map_err(|e| connection_error(&e))?;
    let peer = read_admission(&mut recv)
        .await?
        .verify(keys, Role::Acceptor, &exporter)?;
    let proof = AdmissionFrame::prove(keys, keypair, Role::Acceptor, &exporter);
    send.write_all(&proof.encode()).await.map_err(write_error)?;
    Ok(Admitted { peer, send, recv })
}

/// The admission timeout as a duration.
pub fn admission_timeout() -> Duration {
    Duration::from_millis(ADMISSION_TIMEOUT_MILLIS)
}

#[cfg(test)]
mod tests {
    use rand_chacha::ChaCha20Rng;
    use rand_core::SeedableRng;

    use super::*;
    use crate::net::invite::Invite;

    /// The keys of the session of the invite drawn from seed `seed`.
    fn keys(seed: u64) -> SessionKeys {
        SessionKeys::from_invite(&Invite::generate(&mut ChaCha20Rng::seed_from_u64(seed)))
    }

    #[test]
    fn proofs_verify_only_with_the_invite_the_exporter_and_the_role() {
        let alice = Keypair::from_seed([1; 32]);
        let session = keys(1);
        let exporter = [7; EXPORTER_BYTES];
        let proof = AdmissionFrame::prove(&session, &alice, Role::Dialer, &exporter);
        let decoded = AdmissionFrame::decode(&proof.encode()).unwrap();
        assert_eq!(decoded, proof);
        assert_eq!(
            decoded.verify(&session, Role::Acceptor, &exporter),
            Ok(alice.peer_id())
        );
        // Reflected back to its own role.
        assert_eq!(
            decoded.verify(&session, Role::Dialer, &exporter),
            Err(AdmissionError::WrongRole)
        );
        // Another session, or a relayed proof from another connection.
        assert_eq!(
            decoded.verify(&keys(2), Role::Acceptor, &exporter),
            Err(AdmissionError::WrongInvite)
        );
        assert_eq!(
            decoded.verify(&session, Role::Acceptor, &[8; EXPORTER_BYTES]),
            Err(AdmissionError::WrongInvite)
        );
        // Someone with the invite claiming another peer's id: the MAC is right, the
        // signature is not.
        let mallory = Keypair::from_seed([2; 32]);
        let mut forged = AdmissionFrame::prove(&session, &mallory, Role::Dialer, &exporter);
        forged.peer = alice.peer_id();
        forged.mac = *mac(&session, Role::Dialer, &alice.peer_id(), &exporter).as_bytes();
        assert_eq!(
            forged.verify(&session, Role::Acceptor, &exporter),
            Err(AdmissionError::BadSignature)
        );
    }

    #[test]
    fn decode_refuses_bad_frames() {
        let frame = AdmissionFrame::prove(
            &keys(3),
            &Keypair::from_seed([1; 32]),
            Role::Acceptor,
            &[0; 32],
        )
        .encode();
        let mut bad = frame;
        bad[0] = 9;
        assert_eq!(
            AdmissionFrame::decode(&bad),
            Err(AdmissionError::UnknownVersion(9))
        );
        let mut bad = frame;
        bad[1] = 3;
        assert_eq!(
            AdmissionFrame::decode(&bad),
            Err(AdmissionError::Malformed("role"))
        );
        assert!(AdmissionFrame::decode(&frame[..ADMISSION_FRAME_BYTES - 1]).is_err());
        let mut long = frame.to_vec();
        long.push(0);
        assert!(AdmissionFrame::decode(&long).is_err());
    }
}
