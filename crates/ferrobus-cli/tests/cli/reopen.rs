//! `ferrobus sim --port` after its port goes away: a raw `/dev/pts/N` is not reopened, even
//! when the next pty gets the number, and `--no-reopen` ends the simulator instead of waiting.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use ferrobus::Pty;

use crate::server::ferrobus;

/// The simulator on `path`, its stderr lines sent to the returned channel.
fn sim(path: &Path, extra: &[&str]) -> (Child, mpsc::Receiver<String>) {
    let mut child = ferrobus()
        .args(["sim", "--profile", "generic", "--parity", "none", "--port"])
        .arg(path)
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (tx, rx) = mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    (child, rx)
}

/// Waits (at most 10 s, a hang) for a stderr line containing `text`; returns every line so far.
fn wait_for(lines: &mpsc::Receiver<String>, text: &str) -> Vec<String> {
    let mut seen = Vec::new();
    while let Ok(line) = lines.recv_timeout(Duration::from_secs(10)) {
        let found = line.contains(text);
        seen.push(line);
        if found {
            return seen;
        }
    }
    panic!("the simulator never said {text:?}; it said {seen:#?}");
}

/// Waits (at most 10 s, a hang) for the simulator to end; its exit code.
fn exit_code(child: &mut Child) -> Option<i32> {
    for _ in 0..1000 {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code();
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    panic!("the simulator did not end");
}

/// Makes ptys until one gets `path`: Linux gives the lowest free number once the kernel has
/// released the closed pty. The ptys holding other numbers are kept meanwhile. `None` if
/// another process (a test beside this one) took the number first.
fn pty_numbered(path: &Path) -> Option<Pty> {
    let mut others = Vec::new();
    for _ in 0..200 {
        let pty = Pty::open().unwrap();
        if pty.path == path {
            return Some(pty);
        }
        others.push(pty);
        std::thread::sleep(Duration::from_millis(10));
    }
    None
}

#[test]
fn the_sim_does_not_reopen_a_reused_pty_number_and_leaves_the_new_pty_alone() {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let _inside = runtime.enter();
    let first = Pty::open().unwrap();
    let path = first.path.clone();
    let (mut child, lines) = sim(&path, &[]);
    wait_for(&lines, "serving on");
    drop(first);
    wait_for(&lines, "reopening");
    // Within the simulator's first second of waiting, another pty takes the number.
    let second = pty_numbered(&path);
    let said = wait_for(&lines, "not reopening");
    assert_eq!(exit_code(&mut child), Some(4), "an IO failure: {said:#?}");
    let refusal = said.last().unwrap();
    assert!(refusal.contains(&format!("{} was a pty", path.display())), "{refusal}");
    let Some(second) = second else {
        // The library's own test (crates/ferrobus/tests/reopen.rs) proves the reuse case alone.
        eprintln!("another process took {} first; the refusal is checked, the reuse is not", path.display());
        return;
    };
    // Nothing was written to the new pty.
    let mut ours = second.port;
    let mut buf = [0u8; 16];
    let got = runtime.block_on(async {
        use tokio::io::AsyncReadExt;
        tokio::time::timeout(Duration::from_millis(50), ours.read(&mut buf)).await
    });
    assert!(got.is_err(), "the new pty was read from or written to: {got:?}");
}

#[test]
fn the_sim_with_no_reopen_ends_when_its_port_goes_away() {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let _inside = runtime.enter();
    let pty = Pty::open().unwrap();
    // Through a symlink, a name that would be reopened.
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-no-reopen-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir(&dir).unwrap();
    let link: PathBuf = dir.join("line");
    std::os::unix::fs::symlink(&pty.path, &link).unwrap();
    let (mut child, lines) = sim(&link, &["--no-reopen"]);
    wait_for(&lines, "serving on");
    drop(pty);
    let code = exit_code(&mut child);
    // The reader thread ends at the end of stderr, the simulator having ended.
    let said: Vec<String> = lines.iter().collect();
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(code, Some(4), "{said:#?}");
    assert!(said.iter().all(|l| !l.contains("reopening")), "{said:#?}");
    let error = format!("error: serving on {}", link.display());
    assert!(said.iter().any(|l| l.starts_with(&error)), "the error names the port: {said:#?}");
}

#[test]
fn a_second_process_on_a_held_port_fails_at_once_saying_which_process_holds_it() {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let _inside = runtime.enter();
    let pty = Pty::open().unwrap();
    let (mut holder, lines) = sim(&pty.path, &[]);
    wait_for(&lines, "serving on");
    // Before, two programs on one port took each other's replies; now the second one is
    // refused before it sends a byte.
    let out = ferrobus()
        .args(["--port", &pty.path.display().to_string(), "--parity", "none", "--timeout", "5s"])
        .args(["read", "holding", "0"])
        .output()
        .unwrap();
    let _ = holder.kill();
    let _ = holder.wait();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "the exit code of a port that cannot be used: {err}");
    let said = format!("is in use: held by process {} (ferrobus)", holder.id());
    assert!(err.contains(&said), "{err}");
    assert!(err.contains("one master per port"), "{err}");
}
