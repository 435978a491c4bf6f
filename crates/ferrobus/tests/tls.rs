//! Modbus/TCP Security end to end over loopback TCP: certificates made here with rcgen, the
//! server `serve_tls_with` with a roles policy, the client `Transport::tls`. A client with a
//! role its policy allows writes; a read-only role reads and gets exception 01 for writes;
//! the NULL role (no extension) gets what the policy gives it; a role in another encoding,
//! two role extensions, no certificate or one from another CA fail the handshake, are
//! logged and counted; an untrusted server is refused by the client. A handshake not
//! finished in time is closed; a host holding hundreds of half-open handshakes (from
//! 127.0.0.2) does not lock a certified client (from 127.0.0.1) out.

use std::sync::Arc;
use std::time::Duration;

use ferrobus::server::{ServerOptions, Shared, TcpCounts, TcpLimits, TcpServeConfig};
use ferrobus::tls::{ClientTls, Policy, Role, RoleError, ServerTls, role_of, serve_tls_with};
use ferrobus::{Client, ClientConfig, Error, Timer, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::LineTiming;
use ferrobus_proto::slave::{Handler, SlaveConfig};
use rcgen::{
    BasicConstraints, CertificateParams, CustomExtension, DnType, ExtendedKeyUsagePurpose, IsCa, KeyPair,
    KeyUsagePurpose,
};
use rustls::pki_types::{CertificateDer, PrivateKeyDer, PrivatePkcs8KeyDer};

const ROLE_OID: &[u64] = &[1, 3, 6, 1, 4, 1, 50316, 802, 1];

/// 100 holding registers.
struct Device {
    registers: [u16; 100],
}

impl Handler for Device {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        let start = usize::from(start);
        let from = self.registers.get(start..start + out.len()).ok_or(ExceptionCode::IllegalDataAddress)?;
        out.copy_from_slice(from);
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        *self.registers.get_mut(usize::from(address)).ok_or(ExceptionCode::IllegalDataAddress)? = value;
        Ok(())
    }
}

/// A CA and what it signs.
struct Ca {
    cert: rcgen::Certificate,
    key: KeyPair,
}

type Identity = (Vec<CertificateDer<'static>>, PrivateKeyDer<'static>);

impl Ca {
    fn new(name: &str) -> Ca {
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.distinguished_name.push(DnType::CommonName, name);
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::DigitalSignature];
        let key = KeyPair::generate().unwrap();
        Ca { cert: params.self_signed(&key).unwrap(), key }
    }

    fn der(&self) -> CertificateDer<'static> {
        self.cert.der().clone()
    }

    /// A certificate for 127.0.0.1 and localhost, as a server or a client, with these
    /// extensions (the role's among them, or not).
    fn issue(&self, server: bool, extensions: Vec<CustomExtension>) -> Identity {
        let mut params = CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()]).unwrap();
        params.distinguished_name.push(DnType::CommonName, if server { "server" } else { "client" });
        params.extended_key_usages =
            vec![if server { ExtendedKeyUsagePurpose::ServerAuth } else { ExtendedKeyUsagePurpose::ClientAuth }];
        params.custom_extensions = extensions;
        let key = KeyPair::generate().unwrap();
        let cert = params.signed_by(&key, &self.cert, &self.key).unwrap();
        let key = PrivateKeyDer::Pkcs8(PrivatePkcs8KeyDer::from(key.serialize_der()));
        (vec![cert.der().clone()], key)
    }
}

/// The role extension holding `value` as it is (0x0C for a UTF8String).
fn role_extension(tag: u8, value: &str) -> CustomExtension {
    let mut content = vec![tag, u8::try_from(value.len()).unwrap()];
    content.extend_from_slice(value.as_bytes());
    CustomExtension::from_oid_content(ROLE_OID, content)
}

fn utf8_role(value: &str) -> Vec<CustomExtension> {
    vec![role_extension(0x0C, value)]
}

const ROLES: &str = "\
[role.operator]
access = \"read-write\"

[role.viewer]
access = \"read\"

[null-role]
access = \"read\"
units = [1]
addresses = [\"0-9\"]
";

/// A server on a loopback port with `ROLES`; returns its address and its counters.
async fn server(ca: &Ca) -> (String, Arc<ferrobus::server::TcpStats>) {
    server_within(ca, TcpLimits::default(), |tls| tls).await
}

/// As [`server`], within `limits`, its TLS setup changed by `tune`.
async fn server_within(
    ca: &Ca,
    limits: TcpLimits,
    tune: impl FnOnce(ServerTls) -> ServerTls,
) -> (String, Arc<ferrobus::server::TcpStats>) {
    let (chain, key) = ca.issue(true, Vec::new());
    let tls = ServerTls::new(chain, key, vec![ca.der()]).unwrap().with_policy(Policy::parse(ROLES).unwrap());
    let tls = tune(tls);
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let stats = Arc::clone(&limits.stats);
    let handler = Shared::new(Device { registers: [7; 100] });
    let options = || ServerOptions::new(LineTiming::unpaced(), Timer::Tokio);
    let transport = Transport::tcp(addr.clone());
    let serve = TcpServeConfig { limits, ..TcpServeConfig::new(transport, SlaveConfig::unit(1)) };
    tokio::spawn(serve_tls_with(listener, serve, handler, options, tls));
    (addr, stats)
}

fn config() -> ClientConfig {
    ClientConfig { timeout: Duration::from_secs(5), retries: 0, backoff: None, ..Default::default() }
}

async fn client(addr: &str, trusted: &Ca, identity: Option<Identity>) -> Result<Client, Error> {
    let tls = ClientTls::new(vec![trusted.der()], identity).unwrap();
    Client::connect(Transport::tls(addr, tls).with_reopen(false), config()).await
}

fn counts(stats: &ferrobus::server::TcpStats) -> TcpCounts {
    stats.counts()
}

#[tokio::test]
async fn a_role_allowed_to_write_reads_and_writes() {
    let ca = Ca::new("test CA");
    let (addr, stats) = server(&ca).await;
    let client = client(&addr, &ca, Some(ca.issue(false, utf8_role("operator")))).await.unwrap();
    client.write_single_register(1, 3, 0x1234).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 2, 3).await.unwrap(), vec![7, 0x1234, 7]);
    assert_eq!(counts(&stats).denied, 0);
    assert_eq!(counts(&stats).tls_refused, 0);
}

#[tokio::test]
async fn a_read_only_role_reads_and_its_writes_get_exception_01() {
    let ca = Ca::new("test CA");
    let (addr, stats) = server(&ca).await;
    let client = client(&addr, &ca, Some(ca.issue(false, utf8_role("viewer")))).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 0, 2).await.unwrap(), vec![7, 7]);
    let denied = client.write_single_register(1, 3, 1).await.unwrap_err();
    assert_eq!(denied.exception(), Some(ExceptionCode::IllegalFunction), "{denied}");
    // The write was not made, and the connection goes on.
    assert_eq!(client.read_holding_registers(1, 3, 1).await.unwrap(), vec![7]);
    assert_eq!(counts(&stats).denied, 1);
}

#[tokio::test]
async fn a_certificate_without_a_role_has_the_null_roles_rights() {
    let ca = Ca::new("test CA");
    let (addr, stats) = server(&ca).await;
    let client = client(&addr, &ca, Some(ca.issue(false, Vec::new()))).await.unwrap();
    // The NULL role may read unit 1's addresses 0-9, nothing else.
    assert_eq!(client.read_holding_registers(1, 0, 10).await.unwrap(), vec![7; 10]);
    for denied in [
        client.read_holding_registers(1, 5, 10).await.unwrap_err(),
        client.write_single_register(1, 0, 1).await.unwrap_err(),
    ] {
        assert_eq!(denied.exception(), Some(ExceptionCode::IllegalFunction), "{denied}");
    }
    assert_eq!(counts(&stats).denied, 2);
}

#[tokio::test]
async fn a_role_not_in_the_roles_file_may_do_nothing() {
    let ca = Ca::new("test CA");
    let (addr, _) = server(&ca).await;
    let client = client(&addr, &ca, Some(ca.issue(false, utf8_role("intruder")))).await.unwrap();
    let denied = client.read_holding_registers(1, 0, 1).await.unwrap_err();
    assert_eq!(denied.exception(), Some(ExceptionCode::IllegalFunction), "{denied}");
}

/// Runs one read as a client that the server should refuse at the handshake; returns the
/// error it got (at the connect or, in TLS 1.3, at the first request).
async fn refused(addr: &str, trusted: &Ca, identity: Option<Identity>) -> Error {
    match client(addr, trusted, identity).await {
        Err(e) => e,
        Ok(client) => client.read_holding_registers(1, 0, 1).await.expect_err("served"),
    }
}

/// Waits (a bounded number of turns, no clock) for the server to count a refusal.
async fn refusals(stats: &ferrobus::server::TcpStats, want: u64) -> u64 {
    for _ in 0..1000 {
        if stats.counts().tls_refused >= want {
            break;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    stats.counts().tls_refused
}

#[tokio::test]
async fn a_role_in_another_encoding_is_refused_at_the_handshake() {
    let ca = Ca::new("test CA");
    let (addr, stats) = server(&ca).await;
    // An OCTET STRING and a PrintableString, as some examples write the role.
    for tag in [0x04, 0x13] {
        let error = refused(&addr, &ca, Some(ca.issue(false, vec![role_extension(tag, "operator")]))).await;
        assert!(
            error.to_string().contains("does not accept our certificate (received fatal alert: CertificateUnknown)"),
            "{error}"
        );
    }
    assert_eq!(refusals(&stats, 2).await, 2);
}

#[tokio::test]
async fn two_role_extensions_are_refused_at_the_handshake() {
    let ca = Ca::new("test CA");
    let (addr, stats) = server(&ca).await;
    let two = vec![role_extension(0x0C, "viewer"), role_extension(0x0C, "operator")];
    let error = refused(&addr, &ca, Some(ca.issue(false, two))).await;
    assert!(error.to_string().contains("received fatal alert: CertificateUnknown"), "{error}");
    assert_eq!(refusals(&stats, 1).await, 1);
}

#[tokio::test]
async fn a_client_without_a_certificate_is_refused_at_the_handshake() {
    let ca = Ca::new("test CA");
    let (addr, stats) = server(&ca).await;
    let error = refused(&addr, &ca, None).await;
    assert!(error.to_string().contains("requires a client certificate"), "{error}");
    assert_eq!(refusals(&stats, 1).await, 1);
}

#[tokio::test]
async fn a_client_certificate_from_another_ca_is_refused() {
    let (ca, other) = (Ca::new("test CA"), Ca::new("another CA"));
    let (addr, stats) = server(&ca).await;
    let error = refused(&addr, &ca, Some(other.issue(false, utf8_role("operator")))).await;
    assert!(error.to_string().contains("does not accept our certificate"), "{error}");
    assert_eq!(refusals(&stats, 1).await, 1);
}

#[tokio::test]
async fn the_client_refuses_a_server_its_ca_did_not_issue() {
    let (ca, other) = (Ca::new("test CA"), Ca::new("another CA"));
    let (addr, _) = server(&ca).await;
    let error = client(&addr, &other, Some(other.issue(false, utf8_role("operator")))).await.unwrap_err();
    assert!(error.to_string().contains("not issued by the CA given"), "{error}");
}

#[test]
fn the_role_is_read_from_an_rcgen_certificate() {
    let ca = Ca::new("test CA");
    let (chain, _) = ca.issue(false, utf8_role("Operator"));
    assert_eq!(role_of(&chain[0]), Ok(Role::Named("Operator".into())));
    let (chain, _) = ca.issue(false, Vec::new());
    assert_eq!(role_of(&chain[0]), Ok(Role::Null));
    let (chain, _) = ca.issue(false, vec![role_extension(0x04, "Operator")]);
    assert_eq!(role_of(&chain[0]), Err(RoleError::NotUtf8String(0x04)));
    let (chain, _) = ca.issue(false, vec![role_extension(0x0C, "a"), role_extension(0x0C, "b")]);
    let several = role_of(&chain[0]);
    assert_eq!(several, Err(RoleError::Several(2)));
}

/// One MBAP request and its reply, raw, over `stream`.
async fn ask(stream: &mut ferrobus::tls::ClientStream, t: u8, pdu: &[u8]) -> Vec<u8> {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut frame = vec![0, t, 0, 0, 0, u8::try_from(pdu.len() + 1).unwrap(), 1];
    frame.extend_from_slice(pdu);
    stream.write_all(&frame).await.unwrap();
    let mut header = [0u8; 7];
    stream.read_exact(&mut header).await.unwrap();
    let mut rest = vec![0u8; usize::from(header[5]) - 1];
    stream.read_exact(&mut rest).await.unwrap();
    assert_eq!(header[1], t, "the transaction id is echoed");
    rest
}

#[tokio::test]
async fn a_resumed_session_keeps_the_clients_role() {
    let ca = Ca::new("test CA");
    let (addr, stats) = server(&ca).await;
    let tls = ClientTls::new(vec![ca.der()], Some(ca.issue(false, utf8_role("viewer")))).unwrap();
    let mut kinds = Vec::new();
    for t in 0..2 {
        let mut stream = tls.connect(&addr).await.unwrap();
        assert_eq!(ask(&mut stream, t, &[0x03, 0x00, 0x00, 0x00, 0x01]).await, [0x03, 0x02, 0x00, 0x07]);
        // Still a viewer: the write is denied.
        assert_eq!(ask(&mut stream, t, &[0x06, 0x00, 0x00, 0x00, 0x01]).await, [0x86, 0x01]);
        kinds.push(stream.get_ref().1.handshake_kind());
    }
    assert_eq!(kinds, [Some(rustls::HandshakeKind::Full), Some(rustls::HandshakeKind::Resumed)]);
    assert_eq!(counts(&stats).denied, 2);
}

/// A TCP connection to `addr` from `source` (an address of the loopback) that begins a TLS
/// handshake and never finishes it: a record header and part of a ClientHello.
async fn half_open(source: &str, addr: &str) -> tokio::net::TcpStream {
    use tokio::io::AsyncWriteExt;
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(format!("{source}:0").parse().unwrap()).unwrap();
    let mut stream = socket.connect(addr.parse().unwrap()).await.unwrap();
    stream.write_all(&[0x16, 0x03, 0x01, 0x01, 0x00, 0x01]).await.unwrap();
    stream
}

#[tokio::test(start_paused = true)]
async fn a_handshake_not_finished_within_the_timeout_is_closed_then_and_not_before() {
    use tokio::io::AsyncReadExt;
    let ca = Ca::new("test CA");
    let timeout = Duration::from_secs(5);
    let (addr, stats) = server_within(&ca, TcpLimits::default(), |tls| tls.with_handshake_timeout(timeout)).await;
    let began = tokio::time::Instant::now();
    let mut stream = half_open("127.0.0.1", &addr).await;
    let mut byte = [0u8; 1];
    // Paused time: the clock moves only to the server's next deadline, the timeout's.
    let read = stream.read(&mut byte).await;
    assert!(matches!(read, Ok(0) | Err(_)), "{read:?}");
    assert!(began.elapsed() >= timeout, "closed after {:?}", began.elapsed());
    assert_eq!(refusals(&stats, 1).await, 1);
    let counts = counts(&stats);
    assert_eq!((counts.open, counts.sources), (0, 0), "{counts:?}");
}

#[tokio::test]
async fn a_certified_client_gets_in_while_another_host_holds_hundreds_of_half_open_handshakes() {
    // 300 half-open handshakes against a cap of 64: without the per-source bound they would
    // take every slot. Nothing times out during the test (the timeout is long), so the
    // figures are exact on a loaded machine too.
    const ATTACK: usize = 300;
    let ca = Ca::new("test CA");
    let limits = TcpLimits { max_connections: 64, ..TcpLimits::default() };
    let tune = |tls: ServerTls| tls.with_handshake_timeout(Duration::from_secs(600));
    let (addr, stats) = server_within(&ca, limits, tune).await;
    let mut attacker = Vec::with_capacity(ATTACK);
    for _ in 0..ATTACK {
        attacker.push(half_open("127.0.0.2", &addr).await);
    }
    for _ in 0..10_000 {
        let c = counts(&stats);
        if c.accepted + c.refused_handshakes + c.refused_source >= ATTACK as u64 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    let held = ferrobus::tls::HANDSHAKES_PER_SOURCE;
    let c = counts(&stats);
    assert_eq!((c.accepted, c.refused_handshakes, c.refused), (held as u64, (ATTACK - held) as u64, 0), "{c:?}");
    // A certified client from another address gets in, again and again.
    for _ in 0..3 {
        let client = client(&addr, &ca, Some(ca.issue(false, utf8_role("operator")))).await.unwrap();
        assert_eq!(client.read_holding_registers(1, 0, 2).await.unwrap(), vec![7, 7]);
    }
    assert_eq!(counts(&stats).tls_refused, 0);
}

#[tokio::test]
async fn a_certified_client_gets_in_while_many_hosts_fill_the_cap_with_half_open_handshakes() {
    // 5 addresses with 16 half-open handshakes each (their share): 80 against a cap of 64.
    // Each past the cap closes the oldest handshake of a source holding the most; the
    // certified client's own connection, in its handshake, is the newest of a source
    // holding one, so it is never the one closed.
    const HOSTS: usize = 5;
    let ca = Ca::new("test CA");
    let limits = TcpLimits { max_connections: 64, ..TcpLimits::default() };
    let tune = |tls: ServerTls| tls.with_handshake_timeout(Duration::from_secs(600));
    let (addr, stats) = server_within(&ca, limits, tune).await;
    let held = ferrobus::tls::HANDSHAKES_PER_SOURCE;
    let mut attacker = Vec::new();
    for host in 0..HOSTS {
        for _ in 0..held {
            attacker.push(half_open(&format!("127.0.0.{}", 10 + host), &addr).await);
        }
    }
    let attack = (HOSTS * held) as u64;
    for _ in 0..10_000 {
        if counts(&stats).accepted >= attack {
            break;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    let c = counts(&stats);
    assert_eq!(
        (c.accepted, c.evicted_handshakes, c.refused, c.refused_handshakes),
        (attack, attack - 64, 0, 0),
        "{c:?}"
    );
    // Three clients kept open: each makes room for itself.
    let mut clients = Vec::new();
    for _ in 0..3 {
        let client = client(&addr, &ca, Some(ca.issue(false, utf8_role("operator")))).await.unwrap();
        assert_eq!(client.read_holding_registers(1, 0, 2).await.unwrap(), vec![7, 7]);
        clients.push(client);
    }
    for client in &clients {
        assert_eq!(client.read_holding_registers(1, 0, 2).await.unwrap(), vec![7, 7]);
    }
    let c = counts(&stats);
    assert_eq!(
        (c.tls_refused, c.evicted_handshakes, c.evicted_unanswered, c.evicted_idle),
        (0, attack - 61, 0, 0),
        "{c:?}"
    );
}
