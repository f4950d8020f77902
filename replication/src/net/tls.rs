//! TLS and QUIC transport settings of the node.
//!
//! Every node makes a fresh self-signed certificate (rcgen, P-256) when it starts. Peers do
//! not verify each other's certificate chain: there is no certificate authority in a
//! peer-to-peer session. TLS 1.3 still gives each connection its confidentiality, integrity
//! and a handshake signature made with the presented key, and [`super::admission`] then binds
//! the connection to a peer's ed25519 identity and to knowledge of the invite, through the
//! connection's TLS exporter (which a man in the middle cannot make equal on both sides).

use std::sync::Arc;
use std::time::Duration;

use quinn::crypto::rustls::{QuicClientConfig, QuicServerConfig};
use quinn::rustls;
use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::crypto::CryptoProvider;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, PrivatePkcs8KeyDer, ServerName, UnixTime};
use rustls::{DigitallySignedStruct, SignatureScheme};

/// The ALPN protocol id of sculpt sync connections: 2 since each sync message travels on a
/// unidirectional stream of its own, which a build speaking 1 (one stream for all) refuses.
pub const ALPN: &[u8] = b"sculpt-sync/2";
/// The TLS server name dialers send (certificates are not checked against it).
pub const SERVER_NAME: &str = "sculpt";
/// Keep-alive period: a silent connection still proves it is alive this often.
pub const KEEP_ALIVE_MILLIS: u64 = 2_000;
/// A connection with no packet for this long is dropped.
pub const IDLE_TIMEOUT_MILLIS: u64 = 10_000;
/// Bytes of received datagrams buffered per connection before older ones are dropped.
pub const DATAGRAM_RECEIVE_BUFFER_BYTES: usize = 256 * 1024;
/// Bidirectional streams a remote may have open at once: the admission stream and one snapshot
/// request ([`crate::net::node::MAX_SNAPSHOTS_SERVED_PER_CONN`] bounds how many in all).
pub const MAX_REMOTE_BIDI_STREAMS: u32 = 2;
/// Unidirectional streams a remote may have open at once, one per sync message not yet read
/// whole: enough for the messages of several round trips on a busy link, so a few lost
/// packets do not hold up the rest.
pub const MAX_REMOTE_UNI_STREAMS: u32 = 512;
/// Bytes a remote may have sent on all of a connection's streams that this side has not read
/// (4 MiB): what QUIC buffers for one connection, however many streams it opens.
pub const MAX_RECEIVE_WINDOW_BYTES: u32 = 4 << 20;

/// Why the TLS or QUIC configuration could not be built.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// The self-signed certificate could not be generated.
    #[error("certificate generation failed: {0}")]
    Certificate(#[from] rcgen::Error),
    /// rustls refused the configuration.
    #[error("TLS configuration refused: {0}")]
    Rustls(#[from] rustls::Error),
    /// The TLS configuration offers no cipher suite QUIC can use.
    #[error("no TLS 1.3 cipher suite usable by QUIC")]
    NoQuicCipherSuite,
}

fn provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// `N` bytes from the operating system's secure random source (through the TLS provider,
/// *ring*): for secrets that the net adapter makes itself, such as a discovery server's
/// cookie key.
pub(crate) fn secure_random<const N: usize>() -> Result<[u8; N], rustls::Error> {
    let mut out = [0; N];
    provider()
        .secure_random
        .fill(&mut out)
        .map_err(|_| rustls::Error::FailedToGetRandomBytes)?;
    Ok(out)
}

/// The QUIC transport settings shared by both sides of a connection: the admission's
/// bidirectional stream and a snapshot request, a unidirectional stream per sync message,
/// sent in the order they were written (no round robin between them), datagrams on,
/// keep-alives and an idle timeout.
pub fn transport_config() -> Arc<quinn::TransportConfig> {
    let mut config = quinn::TransportConfig::default();
    config
        .max_concurrent_bidi_streams(MAX_REMOTE_BIDI_STREAMS.into())
        .max_concurrent_uni_streams(MAX_REMOTE_UNI_STREAMS.into())
        .receive_window(MAX_RECEIVE_WINDOW_BYTES.into())
        .send_fairness(false)
        .keep_alive_interval(Some(Duration::from_millis(KEEP_ALIVE_MILLIS)))
        .max_idle_timeout(Some(quinn::IdleTimeout::from(quinn::VarInt::from_u32(
            IDLE_TIMEOUT_MILLIS as u32,
        ))))
        .datagram_receive_buffer_size(Some(DATAGRAM_RECEIVE_BUFFER_BYTES));
    Arc::new(config)
}

/// A server configuration with a new self-signed certificate.
pub fn server_config() -> Result<quinn::ServerConfig, TlsError> {
    let certified = rcgen::generate_simple_self_signed(vec![SERVER_NAME.to_string()])?;
    let cert = certified.cert.der().clone();
    let key = PrivateKeyDer::Pkcs8(PrivatePkcs8KeyDer::from(
        certified.signing_key.serialize_der(),
    ));
    let mut tls = rustls::ServerConfig::builder_with_provider(provider())
        .with_protocol_versions(&[&rustls::version::TLS13])?
        .with_no_client_auth()
        .with_single_cert(vec![cert], key)?;
    tls.alpn_protocols = vec![ALPN.to_vec()];
    let crypto = QuicServerConfig::try_from(tls).map_err(|_| TlsError::NoQuicCipherSuite)?;
    let mut config = quinn::ServerConfig::with_crypto(Arc::new(crypto));
    config.transport_config(transport_config());
    Ok(config)
}

/// A client configuration that accepts any server certificate (identity is bound later by
/// admission) but still checks the TLS 1.3 handshake signature against it.
pub fn client_config() -> Result<quinn::ClientConfig, TlsError> {
    let provider = provider();
    let mut tls = rustls::ClientConfig::builder_with_provider(provider.clone())
        .with_protocol_versions(&[&rustls::version::TLS13])?
        .dangerous()
        .with_custom_certificate_verifier(Arc::new(AnyCertificate(provider)))
        .with_no_client_auth();
    tls.alpn_protocols = vec![ALPN.to_vec()];
    let crypto = QuicClientConfig::try_from(tls).map_err(|_| TlsError::NoQuicCipherSuite)?;
    let mut config = quinn::ClientConfig::new(Arc::new(crypto));
    config.transport_config(transport_config());
    Ok(config)
}

/// Accepts any certificate; verifies handshake signatures with the presented key.
#[derive(Debug)]
struct AnyCertificate(Arc<CryptoProvider>);

impl ServerCertVerifier for AnyCertificate {
    fn verify_server_cert(
        &self,
        _end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        // No CA in a peer-to-peer session: the peer is authenticated by admission instead.
        Ok(ServerCertVerified::assertion())
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(
            message,
            cert,
            dss,
            &self.0.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(
            message,
            cert,
            dss,
            &self.0.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.0.signature_verification_algorithms.supported_schemes()
    }
}
