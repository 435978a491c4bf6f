//! What the bridge's tests that run a peer share: where the repository and the peers are, and
//! what a test does when one is missing — under `CI=true` it fails; elsewhere it passes with a
//! `SKIPPED` line on stderr that names what installs the peer.

// Each test binary uses its part.
#![allow(dead_code)]

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// The repository root.
pub(crate) fn root() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    root.canonicalize().unwrap_or(root)
}

/// Whether `program` is on PATH.
pub(crate) fn on_path(program: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join(program).is_file()))
}

/// pysparkplug's python (its venv) and `decode.py`, both made by `.ci/setup-peers.sh`.
pub(crate) fn pysparkplug() -> (PathBuf, PathBuf) {
    (root().join("target/peers/sparkplug-venv/bin/python"), root().join("tests/peers/sparkplug/decode.py"))
}

/// What of pysparkplug is missing, for [`present`].
pub(crate) fn missing_pysparkplug() -> Vec<String> {
    let (python, script) = pysparkplug();
    let mut missing = Vec::new();
    if !python.is_file() {
        missing.push(format!("{} (pysparkplug 0.6.1: .ci/setup-peers.sh)", python.display()));
    }
    if !script.is_file() {
        missing.push(script.display().to_string());
    }
    missing
}

/// Whether test `test` may run: nothing is `missing`. Otherwise a `SKIPPED` line, past the
/// harness's capture so that it shows with the passing tests.
///
/// # Panics
/// Under `CI=true`, when something is missing.
pub(crate) fn present(test: &str, missing: &[String]) -> bool {
    if missing.is_empty() {
        return true;
    }
    let what = missing.join(", ");
    let ci = matches!(std::env::var("CI").as_deref(), Ok("true" | "TRUE" | "True" | "1" | "yes"));
    assert!(!ci, "{test}: missing {what} (CI=true: a missing peer is a failure)");
    let _ = writeln!(std::io::stderr(), "\nSKIPPED {test}: missing {what}\n");
    false
}
