//! Modbus/TCP Security ("mbaps", MB-TCP-Security v36, TCP port [`MBAPS_PORT`]): Modbus/TCP
//! inside TLS, with mutual authentication and roles.
//!
//! ```text
//!   client ──TLS 1.2/1.3, both sides show a certificate──▶ ServerTls::accept
//!                                                             │ role from the client's
//!                                                             │ certificate (role_of)
//!   each request the engine hands out ──▶ RoleCheck (the session's Authorize filter):
//!       Policy::check(role, unit, request)   allowed → the handler;  denied → exception 01, logged
//! ```
//!
//! - The server ([`ServerTls`]) speaks TLS 1.2 or 1.3, never older (R-01, R-32, R-34); it
//!   asks every client for a certificate and refuses the handshake, with a fatal alert, of a
//!   client that shows none or one not issued by the configured CA (R-02, R-06, R-07, R-10,
//!   R-41, R-44). The cipher suites are rustls's with the `ring` provider, chosen in the
//!   client's order of preference: under TLS 1.2, ECDHE with AES-256-GCM-SHA384 (what rustls
//!   and OpenSSL clients ask for first), AES-128-GCM-SHA256 or ChaCha20-Poly1305, among them
//!   the required `TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256` (R-61, R-62) and, with RSA
//!   keys, `TLS_ECDHE_RSA_WITH_AES_128_GCM_SHA256` (R-14); all are AEAD, none uses MD5 or
//!   SHA-1 for its MAC (R-50, R-51).
//! - The role is read from the client certificate's extension 1.3.6.1.4.1.50316.802.1, a DER
//!   `UTF8String` ([`role_of`], R-21, R-22, R-65); without the extension the client has the
//!   NULL role (R-23). A role in another encoding, a malformed one or two role extensions
//!   fail the handshake (a `certificate_unknown` alert), and the server logs why.
//! - A resumed session (R-42) keeps its role: rustls keeps the client's certificate with the
//!   session, and the role is read from it again; a connection without a certificate is
//!   never served.
//! - The rights of each role come from a [`Policy`] (a roles file, R-24–R-28); every request
//!   is checked against it (§6), and a denied one is answered with exception 01 Illegal
//!   Function (R-31) and logged.
//! - The client ([`ClientTls`], [`Transport::tls`](crate::Transport::tls)) trusts the CA it is
//!   given, checks the server's name (its host name or IP address in the certificate's
//!   subject alternative names), and shows its own certificate when it has one.
//!
//! Where rustls makes ferrobus deviate from the specification:
//! - **No Max Fragment Length negotiation** (RFC 6066; R-57, R-58 ask for 512-byte
//!   fragments): rustls does not implement the extension and ignores it in a ClientHello, so
//!   records are up to 16 KiB. A Modbus ADU is at most 260 bytes, so every record that
//!   carries one is below 512 bytes anyway; only the handshake's certificate records are
//!   larger.
//! - **No NULL cipher suites** (R-67, a SHOULD: `TLS_RSA_WITH_NULL_SHA256`, integrity
//!   without encryption): rustls offers none; every connection is encrypted.
//! - Renegotiation (R-60) is not supported by rustls at all; it answers a renegotiation
//!   request with a `no_renegotiation` warning, which the renegotiation indication
//!   extension exists to make safe.

mod authz;
mod policy;
mod role;
mod serve;

use std::fmt;
use std::io;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use rustls::client::danger::HandshakeSignatureValid;
use rustls::crypto::CryptoProvider;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName, UnixTime};
use rustls::server::WebPkiClientVerifier;
use rustls::server::danger::{ClientCertVerified, ClientCertVerifier};
use rustls::{CertificateError, DigitallySignedStruct, DistinguishedName, OtherError, RootCertStore, SignatureScheme};
use tokio::net::TcpStream;

pub use authz::RoleCheck;
pub use policy::{Denied, Policy, PolicyError, READ_FUNCTIONS, Rights};
pub use role::{ROLE_OID, Role, RoleError, parse_utf8_string, role_of};
pub use serve::serve_tls_with;

use crate::log::escape;
use crate::port::{BoxPort, Connecting, Connector, Port};

/// The TCP port of Modbus/TCP Security (MB-TCP-Security v36, Appendix A).
pub const MBAPS_PORT: u16 = 802;

/// How long a TLS handshake may take before the connection is closed: a handshake on a
/// loaded link takes well under a second, and a half-open one holds a connection slot
/// (see [`TcpLimits`](crate::server::TcpLimits) for the per-source limits that go with it).
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// How many TLS handshakes one source may have in progress at once by default: a host
/// opening connections in a burst finishes them well within the limit, one that holds
/// handshakes open holds no more than these.
pub const HANDSHAKES_PER_SOURCE: usize = 16;

/// A server-side TLS connection.
pub type ServerStream = tokio_rustls::server::TlsStream<TcpStream>;
/// A client-side TLS connection.
pub type ClientStream = tokio_rustls::client::TlsStream<TcpStream>;

impl Port for ServerStream {}

/// A client connection as a [`Port`]: its errors say what a refused handshake means. (In TLS
/// 1.3 the server checks the client's certificate after the client has finished its part of
/// the handshake, so a refusal arrives as an alert on the first read.)
struct ClientPort(ClientStream);

impl Port for ClientPort {}

impl tokio::io::AsyncRead for ClientPort {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.0).poll_read(cx, buf).map_err(explain)
    }
}

impl tokio::io::AsyncWrite for ClientPort {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.0).poll_write(cx, buf).map_err(explain)
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.0).poll_flush(cx).map_err(explain)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.0).poll_shutdown(cx).map_err(explain)
    }
}

/// Certificates, keys or a TLS configuration that cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TlsError {
    /// A file could not be read.
    #[error("{}: cannot read it: {source}", file.display())]
    Read {
        /// The file.
        file: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// A file is not the PEM it should be.
    #[error("{}: {what}", file.display())]
    Pem {
        /// The file.
        file: PathBuf,
        /// What is wrong, and what was expected.
        what: String,
    },
    /// rustls refused the certificates or keys.
    #[error("{context}: {source}")]
    Config {
        /// What was being set up.
        context: &'static str,
        /// rustls's reason.
        source: rustls::Error,
    },
}

fn provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// TLS 1.2 and 1.3, never older (R-01).
const VERSIONS: &[&rustls::SupportedProtocolVersion] = &[&rustls::version::TLS13, &rustls::version::TLS12];

/// Reads every certificate in the PEM file `path` (a chain: the end entity first).
pub fn load_certificates(path: &Path) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let text = std::fs::read(path).map_err(|source| TlsError::Read { file: path.to_path_buf(), source })?;
    let certs = CertificateDer::pem_slice_iter(&text)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| TlsError::Pem { file: path.to_path_buf(), what: format!("not PEM certificates: {e}") })?;
    if certs.is_empty() {
        return Err(TlsError::Pem {
            file: path.to_path_buf(),
            what: "holds no certificate (no -----BEGIN CERTIFICATE----- section)".into(),
        });
    }
    Ok(certs)
}

/// Reads the private key in the PEM file `path` (PKCS#8, PKCS#1 RSA or SEC1 EC, unencrypted).
pub fn load_private_key(path: &Path) -> Result<PrivateKeyDer<'static>, TlsError> {
    let text = std::fs::read(path).map_err(|source| TlsError::Read { file: path.to_path_buf(), source })?;
    PrivateKeyDer::from_pem_slice(&text).map_err(|e| TlsError::Pem {
        file: path.to_path_buf(),
        what: match e {
            rustls::pki_types::pem::Error::NoItemsFound => {
                "holds no private key (no unencrypted -----BEGIN PRIVATE KEY----- section)".into()
            }
            e => format!("not a PEM private key: {e}"),
        },
    })
}

fn root_store(roots: Vec<CertificateDer<'static>>) -> Result<RootCertStore, TlsError> {
    let mut store = RootCertStore::empty();
    for cert in roots {
        store.add(cert).map_err(|source| TlsError::Config { context: "the CA certificate", source })?;
    }
    Ok(store)
}

/// Why a TLS connection was not served.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Refused {
    /// The handshake failed: no client certificate, an untrusted one, a role refused, a
    /// protocol error.
    #[error("TLS handshake refused: {0}")]
    Handshake(io::Error),
    /// The handshake did not finish in time.
    #[error("TLS handshake not finished within {0:?}")]
    Timeout(Duration),
    /// The handshake finished without a client certificate (never expected: the server
    /// requires one).
    #[error("TLS handshake finished without a client certificate")]
    NoCertificate,
    /// The client certificate's role is refused.
    #[error("{0}")]
    Role(RoleError),
}

impl Refused {
    /// The role error behind a refused handshake, if that was why.
    pub fn role_error(&self) -> Option<&RoleError> {
        match self {
            Refused::Role(e) => Some(e),
            Refused::Handshake(e) => {
                let tls = e.get_ref()?.downcast_ref::<rustls::Error>()?;
                let rustls::Error::InvalidCertificate(CertificateError::Other(other)) = tls else { return None };
                other.0.downcast_ref::<RoleError>()
            }
            _ => None,
        }
    }
}

/// The server side of Modbus/TCP Security: the certificate it shows, the CA its clients'
/// certificates must come from, and the roles' rights.
#[derive(Clone)]
pub struct ServerTls {
    acceptor: tokio_rustls::TlsAcceptor,
    policy: Arc<Policy>,
    handshake_timeout: Duration,
    handshakes_per_source: usize,
}

impl fmt::Debug for ServerTls {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ServerTls").field("policy", &self.policy).finish_non_exhaustive()
    }
}

impl ServerTls {
    /// A server showing `chain` (its certificate first) with `key`, accepting clients whose
    /// certificates chain to one of `client_roots`. Every trusted client may do anything
    /// until [`ServerTls::with_policy`] says otherwise.
    pub fn new(
        chain: Vec<CertificateDer<'static>>,
        key: PrivateKeyDer<'static>,
        client_roots: Vec<CertificateDer<'static>>,
    ) -> Result<Self, TlsError> {
        let provider = provider();
        let webpki = WebPkiClientVerifier::builder_with_provider(Arc::new(root_store(client_roots)?), provider.clone())
            .build()
            .map_err(|e| TlsError::Config {
                context: "the CA certificate",
                source: rustls::Error::General(e.to_string()),
            })?;
        let config = rustls::ServerConfig::builder_with_provider(provider)
            .with_protocol_versions(VERSIONS)
            .map_err(|source| TlsError::Config { context: "the TLS versions", source })?
            .with_client_cert_verifier(Arc::new(RoleVerifier(webpki)))
            .with_single_cert(chain, key)
            .map_err(|source| TlsError::Config { context: "the server certificate and key", source })?;
        Ok(ServerTls {
            acceptor: tokio_rustls::TlsAcceptor::from(Arc::new(config)),
            policy: Arc::new(Policy::allow_all()),
            handshake_timeout: HANDSHAKE_TIMEOUT,
            handshakes_per_source: HANDSHAKES_PER_SOURCE,
        })
    }

    /// [`ServerTls::new`] from PEM files.
    pub fn from_pem_files(cert: &Path, key: &Path, client_ca: &Path) -> Result<Self, TlsError> {
        ServerTls::new(load_certificates(cert)?, load_private_key(key)?, load_certificates(client_ca)?)
    }

    /// The roles' rights, checked on every request.
    #[must_use]
    pub fn with_policy(mut self, policy: Policy) -> Self {
        self.policy = Arc::new(policy);
        self
    }

    /// How long a handshake may take (default [`HANDSHAKE_TIMEOUT`]).
    #[must_use]
    pub fn with_handshake_timeout(mut self, timeout: Duration) -> Self {
        self.handshake_timeout = timeout;
        self
    }

    /// How many handshakes one source (an IPv4 address, an IPv6 /64) may have in progress
    /// at once (default [`HANDSHAKES_PER_SOURCE`]); past it a new connection from there is
    /// accepted and closed at once, logged and counted in
    /// [`TcpCounts::refused_handshakes`](crate::server::TcpCounts::refused_handshakes). With
    /// [`TcpLimits::max_per_source`](crate::server::TcpLimits::max_per_source) it keeps one
    /// host that never finishes its handshakes from locking every other out.
    #[must_use]
    pub fn with_max_handshakes_per_source(mut self, n: usize) -> Self {
        self.handshakes_per_source = n;
        self
    }

    /// The most handshakes in progress from one source.
    pub fn max_handshakes_per_source(&self) -> usize {
        self.handshakes_per_source
    }

    /// The roles' rights.
    pub fn policy(&self) -> &Arc<Policy> {
        &self.policy
    }

    /// Runs the handshake on `stream` and reads the client's role.
    pub async fn accept(&self, stream: TcpStream) -> Result<(ServerStream, Role), Refused> {
        let tls = tokio::time::timeout(self.handshake_timeout, self.acceptor.accept(stream))
            .await
            .map_err(|_| Refused::Timeout(self.handshake_timeout))?
            .map_err(Refused::Handshake)?;
        // The verifier checked the role already; a resumed session carries the certificate
        // too. Without one the connection is refused, never served as the NULL role.
        let cert = tls.get_ref().1.peer_certificates().and_then(<[_]>::first).ok_or(Refused::NoCertificate)?;
        let role = role_of(cert).map_err(Refused::Role)?;
        Ok((tls, role))
    }
}

/// The client verifier: the CA's check (webpki), then the role's (a role the server would
/// refuse fails the handshake with a `certificate_unknown` alert rather than a silent close).
#[derive(Debug)]
struct RoleVerifier(Arc<dyn ClientCertVerifier>);

impl ClientCertVerifier for RoleVerifier {
    fn offer_client_auth(&self) -> bool {
        true
    }
    fn client_auth_mandatory(&self) -> bool {
        true
    }
    fn root_hint_subjects(&self) -> &[DistinguishedName] {
        self.0.root_hint_subjects()
    }
    fn verify_client_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        now: UnixTime,
    ) -> Result<ClientCertVerified, rustls::Error> {
        let verified = self.0.verify_client_cert(end_entity, intermediates, now)?;
        role_of(end_entity).map_err(|e| CertificateError::Other(OtherError(Arc::new(e))))?;
        Ok(verified)
    }
    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.0.verify_tls12_signature(message, cert, dss)
    }
    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.0.verify_tls13_signature(message, cert, dss)
    }
    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.0.supported_verify_schemes()
    }
}

/// The client side: the CA the server's certificate must come from, and the certificate to
/// show (an mbaps server requires one).
#[derive(Clone)]
pub struct ClientTls {
    connector: tokio_rustls::TlsConnector,
}

impl fmt::Debug for ClientTls {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ClientTls").finish_non_exhaustive()
    }
}

impl ClientTls {
    /// A client trusting `server_roots`, showing `identity` (a chain, its certificate first,
    /// and its key) if given.
    pub fn new(
        server_roots: Vec<CertificateDer<'static>>,
        identity: Option<(Vec<CertificateDer<'static>>, PrivateKeyDer<'static>)>,
    ) -> Result<Self, TlsError> {
        let builder = client_config()?.with_root_certificates(root_store(server_roots)?);
        ClientTls::showing(builder, identity)
    }

    /// [`ClientTls::new`] from PEM files.
    pub fn from_pem_files(ca: &Path, identity: Option<(&Path, &Path)>) -> Result<Self, TlsError> {
        ClientTls::new(load_certificates(ca)?, load_identity(identity)?)
    }

    /// [`ClientTls::from_pem_files`], but the server's certificate must name `server_name`
    /// whatever host is connected to (a server reached by its IP address, or through a
    /// tunnel, whose certificate names it otherwise). The chain is checked as always.
    pub fn from_pem_files_naming(
        ca: &Path,
        identity: Option<(&Path, &Path)>,
        server_name: &str,
    ) -> Result<Self, TlsError> {
        let general = |context, detail: String| TlsError::Config { context, source: rustls::Error::General(detail) };
        let name = ServerName::try_from(server_name.to_string()).map_err(|_| {
            general("the server name", format!("'{server_name}' is neither a host name nor an IP address"))
        })?;
        let roots = Arc::new(root_store(load_certificates(ca)?)?);
        let inner = rustls::client::WebPkiServerVerifier::builder_with_provider(roots, provider())
            .build()
            .map_err(|e| general("the CA certificate", e.to_string()))?;
        let builder =
            client_config()?.dangerous().with_custom_certificate_verifier(Arc::new(NamedServer { inner, name }));
        ClientTls::showing(builder, load_identity(identity)?)
    }

    /// The client of `builder`, showing `identity` if given.
    fn showing(
        builder: rustls::ConfigBuilder<rustls::ClientConfig, rustls::client::WantsClientCert>,
        identity: Option<(Vec<CertificateDer<'static>>, PrivateKeyDer<'static>)>,
    ) -> Result<Self, TlsError> {
        let config = match identity {
            Some((chain, key)) => builder
                .with_client_auth_cert(chain, key)
                .map_err(|source| TlsError::Config { context: "the client certificate and key", source })?,
            None => builder.with_no_client_auth(),
        };
        Ok(ClientTls { connector: tokio_rustls::TlsConnector::from(Arc::new(config)) })
    }

    /// Its rustls configuration, for a client of another protocol over TLS (the bridge's
    /// MQTT connection to its broker) built from the same PEM files.
    pub fn rustls_config(&self) -> Arc<rustls::ClientConfig> {
        Arc::clone(self.connector.config())
    }

    /// Connects to `addr` (`host:port`) and runs the handshake, checking that the server's
    /// certificate names `host`.
    pub async fn connect(&self, addr: &str) -> io::Result<ClientStream> {
        let host = host_of(addr);
        let name = ServerName::try_from(host.to_string()).map_err(|_| {
            io::Error::new(io::ErrorKind::InvalidInput, format!("'{host}' is neither a host name nor an IP address"))
        })?;
        let stream = TcpStream::connect(addr).await?;
        stream.set_nodelay(true)?;
        self.connector.connect(name, stream).await.map_err(explain)
    }
}

/// The usual check of a server's certificate, against a fixed name instead of the host
/// connected to.
#[derive(Debug)]
struct NamedServer {
    inner: Arc<rustls::client::WebPkiServerVerifier>,
    name: ServerName<'static>,
}

impl rustls::client::danger::ServerCertVerifier for NamedServer {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        _connected_to: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<rustls::client::danger::ServerCertVerified, rustls::Error> {
        self.inner.verify_server_cert(end_entity, intermediates, &self.name, ocsp_response, now)
    }
    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.inner.verify_tls12_signature(message, cert, dss)
    }
    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.inner.verify_tls13_signature(message, cert, dss)
    }
    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.inner.supported_verify_schemes()
    }
}

/// A client configuration with our provider and TLS versions, before its verifier.
fn client_config() -> Result<rustls::ConfigBuilder<rustls::ClientConfig, rustls::WantsVerifier>, TlsError> {
    rustls::ClientConfig::builder_with_provider(provider())
        .with_protocol_versions(VERSIONS)
        .map_err(|source| TlsError::Config { context: "the TLS versions", source })
}

/// A client's certificate chain and key from their PEM files, if given.
fn load_identity(
    identity: Option<(&Path, &Path)>,
) -> Result<Option<(Vec<CertificateDer<'static>>, PrivateKeyDer<'static>)>, TlsError> {
    identity.map(|(cert, key)| Ok((load_certificates(cert)?, load_private_key(key)?))).transpose()
}

/// The host of `host:port` (`[::1]:802` → `::1`).
fn host_of(addr: &str) -> &str {
    if let Some(rest) = addr.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    addr.rsplit_once(':').map_or(addr, |(host, _)| host)
}

/// A handshake error said the way a user can act on it.
fn explain(e: io::Error) -> io::Error {
    let Some(tls) = e.get_ref().and_then(|inner| inner.downcast_ref::<rustls::Error>()) else { return e };
    let hint = match tls {
        rustls::Error::InvalidCertificate(CertificateError::UnknownIssuer) => {
            "the server's certificate is not issued by the CA given (--ca)"
        }
        rustls::Error::InvalidCertificate(
            CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. },
        ) => "the server's certificate does not name the host connected to",
        rustls::Error::InvalidCertificate(_) => "the server's certificate is refused",
        rustls::Error::AlertReceived(rustls::AlertDescription::CertificateRequired) => {
            "the server refused the handshake: it requires a client certificate"
        }
        rustls::Error::AlertReceived(
            rustls::AlertDescription::BadCertificate
            | rustls::AlertDescription::UnknownCA
            | rustls::AlertDescription::CertificateUnknown
            | rustls::AlertDescription::AccessDenied,
        ) => "the server refused the handshake: it does not accept our certificate",
        rustls::Error::AlertReceived(_) => "the server refused the handshake",
        _ => "TLS handshake failed",
    };
    // The reason may quote the server's certificate (the names it presents): escaped.
    io::Error::new(e.kind(), format!("{hint} ({})", escape(&tls.to_string())))
}

impl crate::Transport {
    /// Modbus/TCP Security (mbaps): Modbus/TCP inside TLS to `addr` (`host:port`; the
    /// standard port is [`MBAPS_PORT`], 802), trusting and showing what `tls` holds.
    pub fn tls(addr: impl Into<String>, tls: ClientTls) -> Self {
        let addr = addr.into();
        crate::Transport::tcp(addr.clone()).with_connector(Arc::new(TlsTarget::new(addr, tls)))
    }
}

/// Opens TLS connections for a [`Transport`](crate::Transport).
struct TlsTarget {
    addr: String,
    tls: ClientTls,
}

impl TlsTarget {
    fn new(addr: String, tls: ClientTls) -> Self {
        TlsTarget { addr, tls }
    }
}

impl Connector for TlsTarget {
    fn connect(&self) -> Connecting {
        let (addr, tls) = (self.addr.clone(), self.tls.clone());
        Box::pin(async move { Ok(Box::new(ClientPort(tls.connect(&addr).await?)) as BoxPort) })
    }

    fn describe(&self) -> String {
        format!("{} (TLS)", self.addr)
    }
}

/// The TLS handshake of a server's connection from `peer`: the stream and the check of its
/// role's rights (counting denials in `stats`), or `None` when it was refused — counted, and
/// logged with the reason (a role refused says which and why). `in_progress` counts against
/// the source's handshakes until the handshake is over. [`serve_tls_with`] runs it for each
/// connection; a front end of its own (the gateway's) does too.
pub async fn handshake(
    tls: &ServerTls,
    stream: TcpStream,
    peer: SocketAddr,
    stats: &crate::server::TcpStats,
    in_progress: crate::server::Handshake,
) -> Option<(ServerStream, RoleCheck)> {
    let accepted = tls.accept(stream).await;
    drop(in_progress);
    match accepted {
        Ok((stream, role)) => {
            tracing::info!(%peer, "TLS connection accepted ({role})");
            let check = RoleCheck::new(role, Arc::clone(tls.policy())).with_peer(peer).counting(stats.denied_counter());
            Some((stream, check))
        }
        Err(refused) => {
            stats.note_tls_refused();
            // rustls's reasons may quote the peer's certificate (names, parse errors): escaped.
            if let Some(role) = refused.role_error() {
                let role = role.to_string();
                tracing::warn!(%peer, "TLS connection refused: client certificate rejected: {}", escape(&role));
            } else {
                tracing::warn!(%peer, "{}", escape(&refused.to_string()));
            }
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use rustls::CipherSuite::*;

    use super::*;

    /// The TLS 1.2 suites the module documentation and docs/tls.md name, in rustls's order.
    #[test]
    fn the_tls_1_2_suites_are_the_documented_ones_with_the_required_ones_among_them() {
        let tls12: Vec<_> = provider()
            .cipher_suites
            .iter()
            .filter(|suite| suite.version() == &rustls::version::TLS12)
            .map(rustls::SupportedCipherSuite::suite)
            .collect();
        assert_eq!(
            tls12,
            [
                TLS_ECDHE_ECDSA_WITH_AES_256_GCM_SHA384,
                TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256,
                TLS_ECDHE_ECDSA_WITH_CHACHA20_POLY1305_SHA256,
                TLS_ECDHE_RSA_WITH_AES_256_GCM_SHA384,
                TLS_ECDHE_RSA_WITH_AES_128_GCM_SHA256,
                TLS_ECDHE_RSA_WITH_CHACHA20_POLY1305_SHA256,
            ]
        );
    }
}
