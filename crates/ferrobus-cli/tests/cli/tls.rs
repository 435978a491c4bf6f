//! `--tls` (the client) and `sim --tls-cert` (the mbaps server): what they refuse before any
//! connection, with the file and the line at fault, and port 802 for a host without one.

#[path = "../pki/mod.rs"]
mod pki;

use pki::{Pki, UTF8_STRING};

use crate::server::{offline, stderr};

fn path(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn tls_needs_a_ca_and_a_tcp_server() {
    let err = stderr(&offline(&["--tcp", "127.0.0.1:8802", "--tls", "read", "holding", "0"]).code(2));
    assert!(err.contains("--tls needs --ca FILE"), "{err}");
    let err = stderr(&offline(&["--port", "/dev/null", "--tls", "read", "holding", "0"]).code(2));
    assert!(err.contains("--tls is Modbus/TCP Security: it needs --tcp"), "{err}");
    let err = stderr(&offline(&["--tcp", "127.0.0.1:8802", "--ca", "ca.pem", "read", "holding", "0"]).code(2));
    assert!(err.contains("--cert, --key and --ca are for --tls"), "{err}");
}

#[test]
fn a_certificate_without_its_key_is_refused() {
    let err = stderr(&offline(&["--tcp", "h", "--tls", "--ca", "c", "--cert", "c", "read", "holding", "0"]).code(2));
    assert!(err.contains("--key <FILE>"), "{err}");
}

#[test]
fn a_missing_or_broken_certificate_file_is_named() {
    let pki = Pki::new("test CA");
    let missing = pki.dir().join("nope.pem");
    let args = ["--tcp", "127.0.0.1:8802", "--tls", "--ca", path(&missing), "read", "holding", "0"];
    let err = stderr(&offline(&args).code(2));
    assert!(err.contains(&format!("{}: cannot read it", missing.display())), "{err}");
    let junk = pki.dir().join("junk.pem");
    std::fs::write(&junk, "not a certificate\n").unwrap();
    let args = ["--tcp", "127.0.0.1:8802", "--tls", "--ca", path(&junk), "read", "holding", "0"];
    let err = stderr(&offline(&args).code(2));
    assert!(err.contains(&format!("{}: holds no certificate", junk.display())), "{err}");
    // A certificate given as the key.
    let client = pki.client("client", Some((UTF8_STRING, "operator")));
    let ca = pki.ca();
    let args = ["--tcp", "127.0.0.1:8802", "--tls", "--ca", path(&ca), "--cert", path(&client.cert)];
    let err = stderr(&offline(&[&args[..], &["--key", path(&client.cert), "read", "holding", "0"]].concat()).code(2));
    assert!(err.contains(&format!("{}: holds no private key", client.cert.display())), "{err}");
}

#[test]
fn a_tls_host_without_a_port_is_port_802() {
    let pki = Pki::new("test CA");
    let ca = pki.ca();
    // Nothing listens on 127.0.0.1:802 in the tests: the error names the port tried.
    let args = ["--tcp", "127.0.0.1", "--tls", "--ca", path(&ca), "--timeout", "2s", "read", "holding", "0"];
    let err = stderr(&offline(&args).failure());
    assert!(err.contains("127.0.0.1:802"), "{err}");
}

#[test]
fn sim_refuses_the_clients_tls_option_and_tls_off_tcp() {
    let err = stderr(&offline(&["sim", "--profile", "generic", "--tcp", "127.0.0.1:0", "--tls"]).code(2));
    assert!(err.contains("the simulator serves mbaps with --tls-cert"), "{err}");
    let pki = Pki::new("test CA");
    let server = pki.server();
    let ca = pki.ca();
    let tls = ["--tls-cert", path(&server.cert), "--tls-key", path(&server.key), "--tls-ca", path(&ca)];
    let err = stderr(&offline(&[&["sim", "--profile", "generic", "--pty"][..], &tls[..]].concat()).code(2));
    assert!(err.contains("--tls-cert serves Modbus/TCP Security: it needs --tcp"), "{err}");
    let err = stderr(&offline(&["sim", "--profile", "generic", "--tls-cert", "c.pem", "--tcp", "127.0.0.1:0"]).code(2));
    assert!(err.contains("--tls-key <FILE>") && err.contains("--tls-ca <FILE>"), "{err}");
}

#[test]
fn sim_names_the_file_and_line_of_a_bad_roles_file() {
    let pki = Pki::new("test CA");
    let server = pki.server();
    let ca = pki.ca();
    let roles = pki.dir().join("roles.toml");
    std::fs::write(&roles, "[role.operator]\naccess = \"read-write\"\nunits = [\"1-300\"]\n").unwrap();
    let args = [
        "sim",
        "--profile",
        "generic",
        "--tcp",
        "127.0.0.1:0",
        "--tls-cert",
        path(&server.cert),
        "--tls-key",
        path(&server.key),
        "--tls-ca",
        path(&ca),
        "--roles",
        path(&roles),
    ];
    let err = stderr(&offline(&args).code(2));
    assert!(err.contains(&format!("roles file {}:3:10: unit 300 is past the highest, 255", roles.display())), "{err}");
    // The server's key given as its certificate.
    let mut args = args;
    args[6] = path(&server.key);
    let err = stderr(&offline(&args).code(2));
    assert!(err.contains(&format!("{}: holds no certificate", server.key.display())), "{err}");
}

#[test]
fn a_zero_handshake_timeout_and_zero_limits_per_source_are_refused() {
    let err = stderr(
        &offline(&["sim", "--profile", "generic", "--tcp", "127.0.0.1:0", "--tls-handshake-timeout", "0"]).code(2),
    );
    assert!(err.contains("a handshake needs some time: give a duration above 0"), "{err}");
    for option in ["--tls-max-handshakes-per-source", "--max-per-source"] {
        let err = stderr(&offline(&["sim", "--profile", "generic", "--tcp", "127.0.0.1:0", option, "0"]).code(2));
        assert!(err.contains(option) && err.contains("0 is not in 1.."), "{option}: {err}");
    }
}
