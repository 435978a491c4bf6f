//! A named point is written in one place: the request that carries a value is chosen by
//! `Point::wire_write` (ferrobus-profile's `write.rs`) and sent by `ferrobus_tools::write`, and every
//! writer of a point (`set`, `restore`, `monitor`, the bridge's commands and its demo, a poll
//! handle) goes through them. No other source file builds a write request of its own.
//!
//! The scan reads the workspace's sources (up to a file's `mod tests {`, comments left out);
//! it builds nothing. The client's own write methods, the core's and the simulator's servers,
//! and the writes by address (`write`, the library demo's fixed registers) are what it allows.

mod sources;

use std::path::{Path, PathBuf};

use sources::{code, rust_files};

/// What builds a write request: the client's write methods, the request's variants, a PDU
/// spelt out by hand.
const BUILDS_A_WRITE: &[&str] = &[
    ".write_single_coil(",
    ".write_single_register(",
    ".write_multiple_coils(",
    ".write_multiple_registers(",
    "Request::WriteSingleCoil(",
    "Request::WriteSingleRegister(",
    "Request::WriteMultipleCoils(",
    "Request::WriteMultipleRegisters(",
    "vec![0x05,",
    "vec![0x06,",
    "vec![0x0F,",
    "vec![0x10,",
];

/// The files that may, and why.
const ALLOWED: &[(&str, &str)] = &[
    ("crates/ferrobus/src/client.rs", "the client's write methods themselves"),
    ("crates/ferrobus-profile/src/write.rs", "the one choice of request for a point's value"),
    ("crates/ferrobus-cli/src/write.rs", "`write`: writes by address, no point"),
    ("crates/ferrobus-cli/src/demo.rs", "the library demo: the client's methods on fixed registers"),
];

/// Each writer of a point and the shared act it must call.
const WRITERS: &[(&str, &str)] = &[
    ("crates/ferrobus-cli/src/set.rs", "write::write_point"),
    ("crates/ferrobus-cli/src/bridge.rs", "write::write_point"),
    ("crates/ferrobus-cli/src/monitor/keys.rs", ".wire_write("),
    ("crates/ferrobus-cli/src/monitor/mod.rs", "write::send"),
    ("crates/ferrobus-tools/src/backup/device.rs", ".wire_write("),
    ("crates/ferrobus-tools/src/poll/mod.rs", "write::write_point"),
    ("crates/ferrobus-tools/src/poll/mod.rs", ".wire_write("),
    ("crates/ferrobus-bridge/src/run/command.rs", ".plan_write("),
];

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The source before its tests, without `//` comments.
fn before_tests(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    code(text.split("mod tests {").next().unwrap_or_default())
}

fn relative(path: &Path) -> String {
    let root = workspace().canonicalize().unwrap();
    path.canonicalize().unwrap().strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/")
}

#[test]
fn no_source_file_but_the_allowed_builds_a_write_request() {
    let mut files = Vec::new();
    for krate in
        ["ferrobus", "ferrobus-tools", "ferrobus-profile", "ferrobus-bridge", "ferrobus-cli", "ferrobus-sunspec"]
    {
        rust_files(&workspace().join("crates").join(krate).join("src"), &mut files);
    }
    assert!(files.len() > 50, "the scan found the sources ({} files)", files.len());
    let mut found = Vec::new();
    for file in &files {
        let name = relative(file);
        if name.ends_with("tests.rs") || name.contains("/tests/") || ALLOWED.iter().any(|(a, _)| *a == name) {
            continue;
        }
        for (n, line) in before_tests(file).lines().enumerate() {
            // A match arm names a variant to read it, not to build one.
            if line.contains("=>") {
                continue;
            }
            if let Some(what) = BUILDS_A_WRITE.iter().find(|w| line.contains(*w)) {
                found.push(format!("{name}:{}: {what} ({})", n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "write requests built outside ferrobus_tools::write and Point::wire_write:\n{}",
        found.join("\n")
    );
}

#[test]
fn every_writer_of_a_point_calls_the_shared_act() {
    for (file, call) in WRITERS {
        let text = before_tests(&workspace().join(file));
        assert!(text.contains(call), "{file} does not call {call}");
    }
    for (file, _) in ALLOWED {
        assert!(workspace().join(file).exists(), "{file} is allowed but gone: take it off the list");
    }
}
