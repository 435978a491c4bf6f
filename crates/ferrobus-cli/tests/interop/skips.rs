//! What a test does when its peer is missing: outside CI it passes with a `SKIPPED` line on
//! stderr that shows even though the test passed, naming what is missing and what installs it;
//! under `CI=true` it fails. Shown by running this test binary again, on one test that needs
//! socat, with an empty `PATH`.

use std::process::{Command, Output};

/// A test whose only need is socat.
const NEEDS_SOCAT: &str = "port_reopen::client_fails_with_io_while_the_port_is_gone_and_reopens_it_for_the_sim";

fn run_without_socat(ci: bool) -> Output {
    let exe = std::env::current_exe().expect("the test binary's path");
    let mut command = Command::new(exe);
    command.args([NEEDS_SOCAT, "--exact"]).env("PATH", "").env_remove("CI");
    if ci {
        command.env("CI", "true");
    }
    command.output().expect("the test binary runs again")
}

#[test]
fn outside_ci_a_test_whose_peer_is_missing_passes_saying_skipped_and_what_installs_it() {
    let out = run_without_socat(false);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{}\n{stdout}\n{stderr}", out.status);
    assert!(stdout.contains("1 passed"), "the one test ran and passed:\n{stdout}");
    let line = format!("SKIPPED {NEEDS_SOCAT}: missing socat (not on PATH); install: apt install socat");
    assert!(stderr.contains(&line), "no loud skip line on stderr (wanted {line:?}):\n{stderr}");
}

#[test]
fn under_ci_a_test_whose_peer_is_missing_fails_naming_it_and_what_installs_it() {
    let out = run_without_socat(true);
    let all = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(!out.status.success(), "CI=true: a missing peer must fail the test:\n{all}");
    assert!(all.contains("missing socat (not on PATH); install: apt install socat"), "{all}");
}
