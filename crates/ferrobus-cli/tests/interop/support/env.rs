//! What the interop tests need on this machine, and what happens when it is missing.
//!
//! The peers are built by `.ci/setup-peers.sh` into `target/peers/` of the repository (whatever
//! `CARGO_TARGET_DIR` says: the script does not know about it). Under `CI=true` a missing
//! peer fails the test that needs it; elsewhere the test passes, so that `cargo test` works on
//! a machine without the peers, but says so loudly: a `SKIPPED` line on the process's stderr
//! (past the test harness's capture, so it shows with passing tests) that names what is
//! missing and what installs it.
//!
//! Every test also holds a lock while it runs: shared for ordinary tests, exclusive for the
//! timing test, so that nothing else loads the two cores while it measures.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{OnceLock, PoisonError, RwLock, RwLockReadGuard, RwLockWriteGuard};

/// One thing a test needs.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Need {
    /// `socat`, for pty pairs.
    Socat,
    /// `mbpoll`.
    Mbpoll,
    /// `target/peers/libmodbus_server` and `libmodbus_client`.
    Libmodbus,
    /// python3 with pymodbus and pyserial, and the two fixture scripts.
    Pymodbus,
    /// `target/peers/tokio-modbus-peer/release/tokio-modbus-peer`.
    TokioModbus,
    /// python3 with pysunspec2 (the SunSpec Alliance's client), and `sunspec_client.py`.
    Pysunspec2,
}

/// The repository root.
pub(crate) fn root() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    root.canonicalize().unwrap_or(root)
}

/// `target/peers/<name>`: where `.ci/setup-peers.sh` builds the peers.
pub(crate) fn peer_path(name: &str) -> PathBuf {
    root().join("target/peers").join(name)
}

/// The tokio-modbus peer binary.
pub(crate) fn tokio_peer() -> PathBuf {
    peer_path("tokio-modbus-peer/release/tokio-modbus-peer")
}

/// A pymodbus fixture script, `tests/peers/<name>`.
pub(crate) fn pymodbus_script(name: &str) -> PathBuf {
    root().join("tests/peers").join(name)
}

/// The Python interpreter (`PYTHON`, as in the setup script, or `python3`).
pub(crate) fn python() -> String {
    std::env::var("PYTHON").unwrap_or_else(|_| "python3".into())
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| is_executable(&dir.join(program))))
}

fn is_executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    path.metadata().is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

/// Whether `python()` imports `module`.
fn importable(module: &str) -> bool {
    Command::new(python())
        .args(["-c", &format!("import {module}")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn pymodbus_importable() -> bool {
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(|| importable("pymodbus, serial"))
}

impl Need {
    /// What is missing, if anything.
    fn missing(self) -> Vec<String> {
        let file = |path: PathBuf| (!is_executable(&path)).then(|| path.display().to_string());
        match self {
            Need::Socat => (!on_path("socat")).then(|| "socat (not on PATH)".to_string()).into_iter().collect(),
            Need::Mbpoll => (!on_path("mbpoll")).then(|| "mbpoll (not on PATH)".to_string()).into_iter().collect(),
            Need::Libmodbus => {
                [peer_path("libmodbus_server"), peer_path("libmodbus_client")].into_iter().filter_map(file).collect()
            }
            Need::TokioModbus => file(tokio_peer()).into_iter().collect(),
            Need::Pysunspec2 => {
                static OK: OnceLock<bool> = OnceLock::new();
                let mut missing: Vec<String> = [pymodbus_script("sunspec_client.py")]
                    .into_iter()
                    .filter(|p| !p.is_file())
                    .map(|p| p.display().to_string())
                    .collect();
                if !*OK.get_or_init(|| importable("sunspec2.modbus.client")) {
                    missing.push(format!("pysunspec2 for {}", python()));
                }
                missing
            }
            Need::Pymodbus => {
                let mut missing: Vec<String> = ["pymodbus_server.py", "pymodbus_client.py"]
                    .iter()
                    .map(|s| pymodbus_script(s))
                    .filter(|p| !p.is_file())
                    .map(|p| p.display().to_string())
                    .collect();
                if !pymodbus_importable() {
                    missing.push(format!("pymodbus and pyserial for {}", python()));
                }
                missing
            }
        }
    }

    /// What installs it.
    fn install(self) -> &'static str {
        match self {
            Need::Socat => "apt install socat",
            Need::Mbpoll => "apt install mbpoll",
            Need::Libmodbus => "apt install libmodbus-dev pkg-config gcc, then .ci/setup-peers.sh builds the fixtures",
            Need::Pymodbus => "pip install pymodbus==3.16.1 pyserial==3.5 (or .ci/setup-peers.sh)",
            Need::TokioModbus => ".ci/setup-peers.sh (cargo builds tests/peers/tokio-modbus-peer)",
            Need::Pysunspec2 => "pip install pysunspec2==1.3.7 (or .ci/setup-peers.sh)",
        }
    }
}

/// Says on the process's stderr, past the test harness's capture, that `test` did not run
/// and why. `eprintln!` would be captured and shown only for failing tests, so a skip would
/// pass in silence.
pub(crate) fn skipped(test: &str, why: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "\nSKIPPED {test}: {why}\n");
}

fn in_ci() -> bool {
    matches!(std::env::var("CI").as_deref(), Ok("true" | "TRUE" | "True" | "1" | "yes"))
}

static MACHINE: RwLock<()> = RwLock::new(());

/// Held while a test runs; see the module documentation.
#[allow(dead_code, reason = "held for its Drop")]
pub(crate) enum Turn {
    /// Other tests may run at the same time.
    Shared(RwLockReadGuard<'static, ()>),
    /// Nothing else runs.
    Alone(RwLockWriteGuard<'static, ()>),
}

/// Checks that everything in `needs` is there. Returns the test's turn on the machine, or
/// `None` (after printing `skipped: ...`) when something is missing outside CI.
///
/// # Panics
/// Under `CI=true`, when something is missing.
pub(crate) fn require(needs: &[Need]) -> Option<Turn> {
    check(needs).then(|| Turn::Shared(MACHINE.read().unwrap_or_else(PoisonError::into_inner)))
}

/// As [`require`], but the test runs alone (timing measurements).
pub(crate) fn require_alone(needs: &[Need]) -> Option<Turn> {
    check(needs).then(|| Turn::Alone(MACHINE.write().unwrap_or_else(PoisonError::into_inner)))
}

fn check(needs: &[Need]) -> bool {
    let absent: Vec<(Need, Vec<String>)> =
        needs.iter().map(|&n| (n, n.missing())).filter(|(_, missing)| !missing.is_empty()).collect();
    if absent.is_empty() {
        return true;
    }
    let test = std::thread::current().name().unwrap_or("this test").to_string();
    let what = absent.iter().flat_map(|(_, missing)| missing.iter().cloned()).collect::<Vec<_>>().join(", ");
    let install = absent.iter().map(|(n, _)| n.install()).collect::<Vec<_>>().join("; ");
    assert!(!in_ci(), "{test}: missing {what}; install: {install} (CI=true: a missing peer is a failure)");
    skipped(&test, &format!("missing {what}; install: {install}"));
    false
}

/// Where a test that needs something outside [`Need`] stops: under `CI=true` a failure naming
/// `what` and `install`, elsewhere a loud [`skipped`] line and `false`. `true` when `present`.
///
/// # Panics
/// Under `CI=true`, when not `present`.
pub(crate) fn require_tool(present: bool, what: &str, install: &str) -> bool {
    if present {
        return true;
    }
    let test = std::thread::current().name().unwrap_or("this test").to_string();
    assert!(!in_ci(), "{test}: missing {what}; install: {install} (CI=true: a missing tool is a failure)");
    skipped(&test, &format!("missing {what}; install: {install}"));
    false
}
