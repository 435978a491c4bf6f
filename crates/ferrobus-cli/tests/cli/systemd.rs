//! `Type=notify`: the gateway tells the service manager it is ready, feeds the watchdog at
//! half its timeout, and says it is stopping — read from a datagram socket of the test's own,
//! as systemd would (`NOTIFY_SOCKET`, `WATCHDOG_USEC`, `WATCHDOG_PID`); on SIGHUP it says it
//! reloads (with the monotonic clock, as systemd wants it) and then that it is ready again.
#![cfg(unix)]

use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::config::Scratch;

/// The service manager's end: a datagram socket in `dir` that hears what ferrobus notifies.
fn manager(dir: &Scratch) -> (std::path::PathBuf, UnixDatagram) {
    let socket = dir.0.join("notify.sock");
    let manager = UnixDatagram::bind(&socket).unwrap();
    manager.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    (socket, manager)
}

#[test]
fn the_gateway_says_ready_feeds_the_watchdog_at_half_its_timeout_and_says_it_is_stopping() {
    let dir = Scratch::new("notify");
    let (socket, manager) = manager(&dir);
    // WATCHDOG_PID is the service's own pid: the shell's, which exec keeps.
    let mut gateway = Command::new("sh");
    gateway.args(["-c", "WATCHDOG_PID=$$ exec \"$0\" \"$@\"", env!("CARGO_BIN_EXE_ferrobus")]);
    gateway.args(["--tcp", "127.0.0.1:1", "gateway", "--listen", "127.0.0.1:0", "--duration", "1500ms"]);
    gateway.env("NOTIFY_SOCKET", &socket).env("WATCHDOG_USEC", "400000").env("XDG_CONFIG_HOME", &dir.0);
    let mut child = gateway.stderr(Stdio::null()).spawn().unwrap();
    let mut heard = Vec::new();
    let mut buf = [0u8; 512];
    while !heard.iter().any(|m: &String| m.contains("STOPPING=1")) {
        let Ok(n) = manager.recv(&mut buf) else { break };
        heard.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    assert!(child.wait().unwrap().success());
    assert!(heard[0].starts_with("READY=1\nSTATUS=gateway: listening on 127.0.0.1:"), "{heard:?}");
    let fed = heard.iter().filter(|m| *m == "WATCHDOG=1\n").count();
    // Every 200 ms for 1.5 s: some 7 (a loaded machine may lose some), never more.
    assert!((1..=8).contains(&fed), "{fed} feeds in 1.5 s at 200 ms: {heard:?}");
    assert_eq!(heard.last().map(String::as_str), Some("STOPPING=1\n"), "{heard:?}");
}

#[test]
fn without_a_watchdog_the_gateway_only_says_ready_and_stopping() {
    let dir = Scratch::new("notify-plain");
    let (socket, manager) = manager(&dir);
    let mut gateway = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    gateway.args(["--tcp", "127.0.0.1:1", "gateway", "--listen", "127.0.0.1:0", "--duration", "500ms"]);
    gateway.env("NOTIFY_SOCKET", &socket).env("XDG_CONFIG_HOME", &dir.0);
    let mut child = gateway.stderr(Stdio::null()).spawn().unwrap();
    let mut heard = Vec::new();
    let mut buf = [0u8; 512];
    while heard.len() < 2 {
        let Ok(n) = manager.recv(&mut buf) else { break };
        heard.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    assert!(child.wait().unwrap().success());
    assert_eq!(heard.len(), 2, "{heard:?}");
    assert!(heard[0].starts_with("READY=1\n") && heard[1] == "STOPPING=1\n", "{heard:?}");
}

#[test]
fn on_sighup_the_gateway_says_reloading_with_the_monotonic_clock_then_ready_again() {
    let dir = Scratch::new("notify-reload");
    let (socket, manager) = manager(&dir);
    let lines = dir.0.join("lines.toml");
    std::fs::write(&lines, "[[line]]\ntcp = \"127.0.0.1:1\"\n").unwrap();
    let mut gateway = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    gateway.args(["gateway", "--lines-file", lines.to_str().unwrap(), "--listen", "127.0.0.1:0", "--duration", "20s"]);
    gateway.env("NOTIFY_SOCKET", &socket).env("XDG_CONFIG_HOME", &dir.0);
    let mut child = gateway.stderr(Stdio::null()).spawn().unwrap();
    let mut buf = [0u8; 512];
    let mut heard = |manager: &UnixDatagram| {
        let n = manager.recv(&mut buf).unwrap();
        String::from_utf8_lossy(&buf[..n]).into_owned()
    };
    assert!(heard(&manager).starts_with("READY=1\n"));
    std::fs::write(&lines, "[[line]]\ntcp = \"127.0.0.1:1\"\ntimeout = \"2s\"\n").unwrap();
    let hup = Command::new("kill").args(["-HUP", &child.id().to_string()]).status().unwrap();
    assert!(hup.success());
    let reloading = heard(&manager);
    let usec = reloading.strip_prefix("RELOADING=1\nMONOTONIC_USEC=").and_then(|rest| rest.strip_suffix('\n'));
    assert!(usec.is_some_and(|u| u.parse::<u64>().is_ok_and(|u| u > 0)), "{reloading:?}");
    let ready = heard(&manager);
    assert!(ready.starts_with("READY=1\nSTATUS=reloaded: 0 lines added, 1 changed"), "{ready:?}");
    child.kill().unwrap();
    child.wait().unwrap();
}
