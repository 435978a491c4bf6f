//! One write guard for every writer: `set` and `restore --apply` against a simulated 3G3RX
//! (`ferrobus sim --profile omron-3g3rx` over Modbus/TCP) take the run-locked A003 while the
//! drive is stopped, and refuse it with the same refusal, writing nothing, once the run command
//! makes it run; `write`, `readwrite`, `mask` and `raw` with `--device` refuse a write by
//! address over it while running unless `--force`. (The monitor's edit is shown the same in `monitor.rs`, the bridge's DCMD and
//! plain `set` in the interop tests.)

use std::time::{Duration, Instant};

use assert_cmd::assert::OutputAssertExt;

use crate::backup::{TcpSim, change, temp};
use crate::server::{ferrobus, stderr, stdout};

/// The profile's write guard's words for A003 while the simulated 3G3RX runs.
pub(crate) const REFUSAL: &str = "A003 cannot change while the drive runs (running = 1); stop it first";

/// Sets F001 to 10 Hz and gives the run command (coil 0001h); waits for the running coil
/// (000Fh) to say that the drive runs (a deadline for failing, not a timing figure).
pub(crate) fn make_it_run(address: &str) {
    let tcp = ["--tcp", address];
    ferrobus()
        .args(tcp)
        .args(["write", "register", "--one-based", "0x0001", "1000", "--multiple", "--type", "u32"])
        .assert()
        .success();
    ferrobus().args(tcp).args(["write", "coil", "--one-based", "1", "on"]).assert().success();
    let deadline = Instant::now() + Duration::from_secs(10);
    while !stdout(&ferrobus().args(tcp).args(["read", "coils", "--one-based", "0x000F"]).assert().success())
        .contains(" ON")
    {
        assert!(Instant::now() < deadline, "the drive never ran");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn a003(sim: &TcpSim) -> String {
    let out = stdout(&sim.run("omron-3g3rx", &["get", "A003", "--json"]).success());
    let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
    doc.pointer("/points/0/value").and_then(serde_json::Value::as_str).unwrap_or_default().to_string()
}

#[test]
fn set_and_restore_take_a_run_locked_parameter_stopped_and_refuse_it_running_with_the_same_refusal() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    let path = temp("guard.toml");
    let file = path.to_str().unwrap();

    // Stopped: set writes A003, restore writes it back.
    sim.run("omron-3g3rx", &["set", "A003", "50Hz"]).success();
    sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    sim.run("omron-3g3rx", &["set", "A003", "55Hz"]).success();
    sim.run("omron-3g3rx", &["restore", file, "--apply"]).success();
    assert_eq!(a003(&sim), "50 Hz", "restore wrote A003 back while stopped");
    change(&sim, "0x1203", "55", "u16");

    // Running: both refuse A003 with the guard's words, and nothing is written.
    make_it_run(&sim.addr);
    let writes = sim.writes();
    let set = stderr(&sim.run("omron-3g3rx", &["set", "A003", "60Hz"]).code(2));
    assert_eq!(set.trim(), format!("error: not sent: {REFUSAL}"));
    let restore = stderr(&sim.run("omron-3g3rx", &["restore", file, "--apply"]).code(7));
    assert!(restore.contains(&format!("{REFUSAL}; nothing was written")), "{restore}");
    let dry = stderr(&sim.run("omron-3g3rx", &["restore", file]).success());
    assert!(dry.contains(&format!("note: --apply would refuse now: {REFUSAL}")), "{dry}");
    assert_eq!(sim.writes(), writes, "no write went out");
    assert_eq!(a003(&sim), "55 Hz");
    // A parameter that may change while running is still taken.
    sim.run("omron-3g3rx", &["set", "F001", "12Hz"]).success();
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn writes_by_address_over_a_run_locked_parameter_are_refused_while_running_unless_forced() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    // Stopped: a write by address or by name to A003 (register 1203h) goes out.
    sim.run("omron-3g3rx", &["write", "register", "--one-based", "0x1203", "50"]).success();
    assert_eq!(a003(&sim), "50 Hz");

    make_it_run(&sim.addr);
    let writes = sim.writes();
    let hint = format!("error: not sent: {REFUSAL} (--force writes it anyway)");
    for args in [
        &["write", "register", "--one-based", "0x1203", "60"][..],
        &["write", "register", "A003", "60"],
        &["mask", "--one-based", "0x1203", "0x0000", "0x003C"],
        &["readwrite", "--read", "1", "--write", "0x1203", "60"],
        &["raw", "06", "12", "02", "00", "3C"],
    ] {
        let refused = stderr(&sim.run("omron-3g3rx", args).code(2));
        assert_eq!(refused.trim(), hint, "{args:?}");
    }
    let both = stderr(&sim.run("omron-3g3rx", &["write", "registers", "--one-based", "0x1202", "3", "60"]).code(2));
    assert!(both.contains("not sent: A002, A003 cannot change while the drive runs"), "every point touched: {both}");
    assert_eq!(sim.writes(), writes, "no write went out");
    assert_eq!(a003(&sim), "50 Hz");

    // Forced: sent, with the refusal said as a warning; the simulated 3G3RX itself refuses it
    // with 22h, as the drive does.
    let said = stderr(&sim.run("omron-3g3rx", &["write", "register", "A003", "60", "--force"]));
    assert!(said.contains(&format!("write: {REFUSAL}; written anyway (--force)")), "{said}");
    assert!(said.contains("answered 0x06 Write Single Register with exception 0x22"), "it went out: {said}");
    // A register no run-locked point holds is written without a question (F001, 0001h-0002h).
    sim.run("omron-3g3rx", &["write", "register", "--one-based", "0x0001", "1200", "--multiple", "--type", "u32"])
        .success();
}
