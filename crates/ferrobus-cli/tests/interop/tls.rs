//! Modbus/TCP Security: `ferrobus sim --tls-cert ... --roles FILE` as an mbaps server, met by
//! ferrobus's own `--tls` client and by pymodbus's TLS client; certificates made here with
//! rcgen, and one client certificate made with openssl (the role extension written by
//! openssl's config syntax). Clients with a read-write role, a read-only role (writes get
//! exception 01), a role in the wrong encoding (refused at the handshake, logged), and no
//! certificate (refused, logged); and `ferrobus gateway --tls-cert ...` in front of a serial
//! simulator, its roles checked per request.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

#[path = "../pki/mod.rs"]
mod pki;

use pki::{OCTET_STRING, Pair, Pki, UTF8_STRING};

use crate::support::env::{Need, pymodbus_script, python, require, require_tool};
use crate::support::peers::{free_port, sim_pty};
use crate::support::process::{Proc, Stream, output_within};

/// A bound on how long a client run may take before the test fails (not a timing claim).
const LIMIT: Duration = Duration::from_secs(30);

const ROLES: &str = "\
# Test roles: operators read and write, viewers read.
[role.operator]
access = \"read-write\"

[role.viewer]
access = \"read\"
";

/// `ferrobus sim --profile generic` serving mbaps on a free port with `ROLES`, its clients'
/// certificates issued by `client_ca`.
struct Mbaps {
    proc: Proc,
    addr: String,
}

fn mbaps(pki: &Pki, client_ca: &Path) -> Mbaps {
    let roles = pki.dir().join("roles.toml");
    std::fs::write(&roles, ROLES).unwrap();
    let server = pki.server();
    let addr = format!("127.0.0.1:{}", free_port());
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    // -v: the accepted connections and their roles are logged at info.
    command.args(["-v", "sim", "--profile", "generic", "--tcp", &addr]);
    command.arg("--tls-cert").arg(&server.cert).arg("--tls-key").arg(&server.key);
    command.arg("--tls-ca").arg(client_ca).arg("--roles").arg(&roles);
    let proc = Proc::spawn("ferrobus sim (mbaps)", &mut command);
    let ready = proc.wait_for(Stream::Err, |l| l.starts_with("sim: listening on"), LIMIT);
    assert!(ready.contains("TLS: Modbus/TCP Security"), "{ready}");
    Mbaps { proc, addr }
}

/// Runs `ferrobus --tcp ADDR --tls --ca CA [--cert --key] ARGS`.
fn ferrobus(server: &Mbaps, ca: &Path, identity: Option<&Pair>, args: &[&str]) -> std::process::Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["--tcp", &server.addr, "--tls", "--timeout", "5s", "--ca"]).arg(ca);
    if let Some(pair) = identity {
        command.arg("--cert").arg(&pair.cert).arg("--key").arg(&pair.key);
    }
    command.args(args);
    output_within(&mut command, "", LIMIT)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn ferrobus_tls_client_with_a_read_write_role_reads_and_writes_the_sims_mbaps_server() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let operator = pki.client("operator", Some((UTF8_STRING, "operator")));
    let wrote = ferrobus(&server, &pki.ca(), Some(&operator), &["write", "register", "7", "4660"]);
    assert!(wrote.status.success(), "stderr: {}\nsim:\n{}", text(&wrote.stderr), server.proc.log());
    let read = ferrobus(&server, &pki.ca(), Some(&operator), &["read", "holding", "7", "--json"]);
    assert!(read.status.success(), "stderr: {}", text(&read.stderr));
    assert!(text(&read.stdout).contains("4660"), "stdout: {}", text(&read.stdout));
}

#[test]
fn a_read_only_role_reads_and_its_write_gets_exception_01_and_is_logged() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let viewer = pki.client("viewer", Some((UTF8_STRING, "viewer")));
    let read = ferrobus(&server, &pki.ca(), Some(&viewer), &["read", "holding", "0", "--count", "2"]);
    assert!(read.status.success(), "stderr: {}", text(&read.stderr));
    let wrote = ferrobus(&server, &pki.ca(), Some(&viewer), &["write", "register", "7", "1"]);
    assert_eq!(wrote.status.code(), Some(1), "stderr: {}", text(&wrote.stderr));
    assert!(text(&wrote.stderr).contains("exception 0x01"), "stderr: {}", text(&wrote.stderr));
    let logged = server.proc.wait_for(Stream::Err, |l| l.contains("denied"), LIMIT);
    assert!(logged.contains("0x06 Write Single Register") && logged.contains("role 'viewer'"), "{logged}");
}

#[test]
fn a_role_holding_a_newline_is_logged_escaped_on_one_line_and_forges_no_line() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let forger = pki.client("forger", Some((UTF8_STRING, "admin\n2026-12-03T00:00:00Z INFO forged")));
    // Not a role of the roles file: every request is denied, and the denial names the role.
    let read = ferrobus(&server, &pki.ca(), Some(&forger), &["read", "holding", "0"]);
    assert_eq!(read.status.code(), Some(1), "stderr: {}", text(&read.stderr));
    let denied = server.proc.wait_for(Stream::Err, |l| l.contains("denied"), LIMIT);
    let log = server.proc.log();
    let escaped = r"role 'admin\n2026-12-03T00:00:00Z INFO forged'";
    assert!(denied.contains(escaped), "{denied}");
    let accepted = log.lines().find(|l| l.contains("TLS connection accepted")).unwrap_or_default();
    assert!(accepted.contains(escaped), "{log}");
    // The "forged" text is never a line of its own: each line holding it holds the whole role.
    assert!(log.lines().filter(|l| l.contains("forged")).all(|l| l.contains(escaped)), "{log}");
}

#[test]
fn a_role_in_the_wrong_encoding_is_refused_at_the_handshake_and_logged() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let octets = pki.client("octets", Some((OCTET_STRING, "operator")));
    let read = ferrobus(&server, &pki.ca(), Some(&octets), &["read", "holding", "0"]);
    assert!(!read.status.success());
    assert!(text(&read.stderr).contains("does not accept our certificate"), "stderr: {}", text(&read.stderr));
    let logged = server.proc.wait_for(Stream::Err, |l| l.contains("client certificate rejected"), LIMIT);
    assert!(logged.contains("holds ASN.1 tag 0x04, not a UTF8String"), "{logged}");
}

#[test]
fn a_client_without_a_certificate_is_refused_at_the_handshake_and_logged() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let read = ferrobus(&server, &pki.ca(), None, &["read", "holding", "0"]);
    assert!(!read.status.success());
    assert!(text(&read.stderr).contains("requires a client certificate"), "stderr: {}", text(&read.stderr));
    let logged = server.proc.wait_for(Stream::Err, |l| l.contains("TLS handshake refused"), LIMIT);
    assert!(logged.contains("peer sent no certificates"), "{logged}");
}

#[test]
fn ferrobus_tls_client_refuses_a_server_whose_certificate_its_ca_did_not_issue() {
    let Some(_turn) = require(&[]) else { return };
    let (pki, other) = (Pki::new("test CA"), Pki::new("another CA"));
    let server = mbaps(&pki, &pki.ca());
    let operator = pki.client("operator", Some((UTF8_STRING, "operator")));
    let read = ferrobus(&server, &other.ca(), Some(&operator), &["read", "holding", "0"]);
    assert!(!read.status.success());
    assert!(text(&read.stderr).contains("not issued by the CA given (--ca)"), "stderr: {}", text(&read.stderr));
}

/// Runs pymodbus's TLS client (tests/peers/pymodbus_client.py --tls) with `script`.
fn pymodbus(server: &Mbaps, ca: &Path, identity: &Pair, script: &str) -> String {
    let port = server.addr.rsplit(':').next().unwrap();
    let mut command = Command::new(python());
    command.arg(pymodbus_script("pymodbus_client.py")).args(["--tls", &format!("localhost:{port}"), "--ca"]).arg(ca);
    command.arg("--cert").arg(&identity.cert).arg("--key").arg(&identity.key);
    command.args(["--timeout-ms", "5000", "script"]);
    let output = output_within(&mut command, script, LIMIT);
    assert!(output.status.success(), "pymodbus: {}\nsim:\n{}", text(&output.stderr), server.proc.log());
    text(&output.stdout)
}

#[test]
fn pymodbus_tls_client_reads_and_writes_with_a_role_and_gets_exception_01_read_only() {
    let Some(_turn) = require(&[Need::Pymodbus]) else { return };
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let operator = pki.client("operator", Some((UTF8_STRING, "operator")));
    let out = pymodbus(&server, &pki.ca(), &operator, "write_register 5 4242\nread_holding 5 1\n");
    assert_eq!(out.lines().collect::<Vec<_>>(), ["ok", "ok 4242"], "{out}");
    let viewer = pki.client("viewer", Some((UTF8_STRING, "viewer")));
    let out = pymodbus(&server, &pki.ca(), &viewer, "read_holding 5 1\nwrite_register 5 1\n");
    assert_eq!(out.lines().collect::<Vec<_>>(), ["ok 4242", "exception 1"], "{out}");
}

fn openssl(args: &[&str], dir: &Path) {
    let output = output_within(Command::new("openssl").args(args).current_dir(dir), "", LIMIT);
    assert!(output.status.success(), "openssl {args:?}: {}", text(&output.stderr));
}

#[test]
fn an_openssl_made_client_certificate_with_the_role_extension_is_accepted_and_its_role_applied() {
    let Some(_turn) = require(&[]) else { return };
    let present = Command::new("openssl").arg("version").output().is_ok_and(|o| o.status.success());
    if !require_tool(present, "openssl", "apt install openssl (or .ci/setup-peers.sh)") {
        return;
    }
    let pki = Pki::new("test CA");
    let dir = pki.dir();
    // An openssl CA, and a client certificate with the role as openssl's config writes it.
    let ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes"];
    openssl(
        &[
            &["req", "-x509"],
            &ec[..],
            &["-keyout", "ossl-ca.key", "-out", "ossl-ca.pem", "-subj", "/CN=openssl CA", "-days", "1"],
        ]
        .concat(),
        dir,
    );
    openssl(
        &[&["req"], &ec[..], &["-keyout", "ossl.key", "-out", "ossl.csr", "-subj", "/CN=DO NOT USE"]].concat(),
        dir,
    );
    std::fs::write(
        dir.join("ext.cnf"),
        "basicConstraints = CA:FALSE\nextendedKeyUsage = clientAuth\n1.3.6.1.4.1.50316.802.1 = ASN1:UTF8String:viewer\n",
    )
    .unwrap();
    openssl(
        &[
            "x509",
            "-req",
            "-in",
            "ossl.csr",
            "-CA",
            "ossl-ca.pem",
            "-CAkey",
            "ossl-ca.key",
            "-CAcreateserial",
            "-out",
            "ossl.pem",
            "-days",
            "1",
            "-extfile",
            "ext.cnf",
        ],
        dir,
    );
    // The server trusts both CAs.
    let cas = dir.join("client-cas.pem");
    let both = [std::fs::read(pki.ca()).unwrap(), std::fs::read(dir.join("ossl-ca.pem")).unwrap()].concat();
    std::fs::write(&cas, both).unwrap();
    let server = mbaps(&pki, &cas);
    let identity = Pair { cert: dir.join("ossl.pem"), key: dir.join("ossl.key") };
    let read = ferrobus(&server, &pki.ca(), Some(&identity), &["read", "holding", "0"]);
    assert!(read.status.success(), "stderr: {}\nsim:\n{}", text(&read.stderr), server.proc.log());
    // The role is read: a viewer may not write.
    let wrote = ferrobus(&server, &pki.ca(), Some(&identity), &["write", "register", "0", "1"]);
    assert!(text(&wrote.stderr).contains("exception 0x01"), "stderr: {}", text(&wrote.stderr));
    server.proc.wait_for(Stream::Err, |l| l.contains("TLS connection accepted (role 'viewer')"), LIMIT);
}

/// `openssl s_client` against `server` with `args`, stdin closed: its stdout and stderr.
fn s_client(server: &Mbaps, pki: &Pki, identity: &Pair, args: &[&str]) -> String {
    let mut command = Command::new("openssl");
    command.args(["s_client", "-connect", &server.addr, "-servername", "localhost", "-CAfile"]).arg(pki.ca());
    command.arg("-cert").arg(&identity.cert).arg("-key").arg(&identity.key).args(args);
    let output = output_within(&mut command, "", LIMIT);
    format!("{}{}", text(&output.stdout), text(&output.stderr))
}

#[test]
fn openssl_negotiates_tls_1_2_with_the_ecdsa_aes_128_gcm_suite_and_is_refused_tls_1_1() {
    let Some(_turn) = require(&[]) else { return };
    let present = Command::new("openssl").arg("version").output().is_ok_and(|o| o.status.success());
    if !require_tool(present, "openssl", "apt install openssl (or .ci/setup-peers.sh)") {
        return;
    }
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let operator = pki.client("operator", Some((UTF8_STRING, "operator")));
    // R-62: TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256 with an ECC (P-256) certificate.
    let tls12 = s_client(&server, &pki, &operator, &["-tls1_2", "-cipher", "ECDHE-ECDSA-AES128-GCM-SHA256"]);
    assert!(tls12.contains("Protocol  : TLSv1.2"), "{tls12}");
    assert!(tls12.contains("Cipher    : ECDHE-ECDSA-AES128-GCM-SHA256"), "{tls12}");
    assert!(tls12.contains("Verify return code: 0 (ok)"), "{tls12}");
    // R-01: never TLS 1.1 (openssl's security level 0 lets it offer 1.1 at all).
    let tls11 = s_client(&server, &pki, &operator, &["-tls1_1", "-cipher", "DEFAULT@SECLEVEL=0"]);
    // rustls answers a ClientHello without 1.2 or 1.3 with a handshake_failure alert.
    assert!(tls11.contains("alert handshake failure") && tls11.contains("Cipher is (NONE)"), "{tls11}");
    let logged = server.proc.wait_for(Stream::Err, |l| l.contains("TLS handshake refused"), LIMIT);
    assert!(logged.contains("peer is incompatible"), "{logged}");
}

/// `ferrobus -v gateway` serving Modbus/TCP Security with `ROLES` in front of the serial line
/// at `pty`.
fn mbaps_gateway(pki: &Pki, pty: &Path) -> Mbaps {
    let roles = pki.dir().join("roles.toml");
    std::fs::write(&roles, ROLES).unwrap();
    let server = pki.server();
    let addr = format!("127.0.0.1:{}", free_port());
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["-v", "--port"]).arg(pty).args(["gateway", "--listen", &addr]);
    command.arg("--tls-cert").arg(&server.cert).arg("--tls-key").arg(&server.key);
    command.arg("--tls-ca").arg(pki.ca()).arg("--roles").arg(&roles);
    let proc = Proc::spawn("ferrobus gateway (mbaps)", &mut command);
    let ready = proc.wait_for(Stream::Err, |l| l.starts_with("gateway: listening on"), LIMIT);
    assert!(ready.contains("Modbus/TCP Security"), "{ready}");
    Mbaps { proc, addr }
}

#[test]
fn the_gateway_serves_mbaps_to_a_serial_sim_with_roles_checked_per_request() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let (_sim, pty) = sim_pty(&["--profile", "generic"]);
    let gateway = mbaps_gateway(&pki, &pty);
    // An operator writes through to the simulated device and reads it back.
    let operator = pki.client("operator", Some((UTF8_STRING, "operator")));
    let wrote = ferrobus(&gateway, &pki.ca(), Some(&operator), &["write", "register", "9", "321"]);
    assert!(wrote.status.success(), "stderr: {}\ngateway:\n{}", text(&wrote.stderr), gateway.proc.log());
    // A viewer reads what the operator wrote; its write gets exception 01 and changes nothing.
    let viewer = pki.client("viewer", Some((UTF8_STRING, "viewer")));
    let wrote = ferrobus(&gateway, &pki.ca(), Some(&viewer), &["write", "register", "9", "1"]);
    assert_eq!(wrote.status.code(), Some(1), "stderr: {}", text(&wrote.stderr));
    assert!(text(&wrote.stderr).contains("exception 0x01"), "stderr: {}", text(&wrote.stderr));
    let read = ferrobus(&gateway, &pki.ca(), Some(&viewer), &["read", "holding", "9", "--json"]);
    assert!(read.status.success(), "stderr: {}", text(&read.stderr));
    assert!(text(&read.stdout).contains("321"), "stdout: {}", text(&read.stdout));
    gateway.proc.wait_for(Stream::Err, |l| l.contains("denied") && l.contains("role 'viewer'"), LIMIT);
    // No certificate: refused at the handshake.
    let refused = ferrobus(&gateway, &pki.ca(), None, &["read", "holding", "9"]);
    assert!(text(&refused.stderr).contains("requires a client certificate"), "stderr: {}", text(&refused.stderr));
}

#[test]
fn a_write_the_gateway_refuses_for_a_role_gets_a_hint_naming_the_role_setting_and_following_it_works() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let (_sim, pty) = sim_pty(&["--profile", "generic"]);
    let gateway = mbaps_gateway(&pki, &pty);
    let viewer = pki.client("viewer", Some((UTF8_STRING, "viewer")));
    let refused = ferrobus(&gateway, &pki.ca(), Some(&viewer), &["write", "register", "9", "5"]);
    let hint = text(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "stderr: {hint}");
    // The role that may not write FC06 may not write FC10 either: no other request is offered.
    assert!(!hint.contains("--multiple"), "{hint}");
    assert!(hint.contains("access = \"read-write\", function 6"), "{hint}");
    let multiple = ferrobus(&gateway, &pki.ca(), Some(&viewer), &["write", "register", "9", "5", "--multiple"]);
    assert_eq!(multiple.status.code(), Some(1), "FC10 is refused the viewer too: {}", text(&multiple.stderr));
    // Following the hint: a certificate whose role has access = "read-write" (ROLES' operator).
    let operator = pki.client("operator", Some((UTF8_STRING, "operator")));
    let wrote = ferrobus(&gateway, &pki.ca(), Some(&operator), &["write", "register", "9", "5"]);
    assert!(wrote.status.success(), "stderr: {}", text(&wrote.stderr));
    let read = ferrobus(&gateway, &pki.ca(), Some(&viewer), &["read", "holding", "9", "--json"]);
    assert!(text(&read.stdout).contains('5'), "stdout: {}", text(&read.stdout));
}

#[test]
fn a_plain_modbus_tcp_client_on_a_tls_port_is_told_to_use_tls() {
    let Some(_turn) = require(&[]) else { return };
    let pki = Pki::new("test CA");
    let server = mbaps(&pki, &pki.ca());
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["--tcp", &server.addr, "--timeout", "2s", "read", "holding", "0"]);
    let read = output_within(&mut command, "", LIMIT);
    assert!(!read.status.success());
    let err = text(&read.stderr);
    assert!(err.contains("the server answered with a TLS record (an alert)"), "stderr: {err}");
    assert!(err.contains("hint: connect with --tls and --ca FILE"), "stderr: {err}");
    // RTU over TCP has no such check (`15 03 04 ...` is an RTU reply): it hears garbage.
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["--rtu-tcp", &server.addr, "--timeout", "1s", "read", "holding", "0"]);
    let rtu = output_within(&mut command, "", LIMIT);
    assert!(!rtu.status.success() && !text(&rtu.stderr).contains("TLS record"), "{}", text(&rtu.stderr));
}
