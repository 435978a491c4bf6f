//! Exit codes and error messages: exceptions, timeouts, IO, bad replies, bad usage, and that
//! no input makes the binary panic.

use crate::server::{
    Server, Sim, closed_port, ferrobus, misbehaving_server, misbehaving_server_with, offline, pty_server, stderr,
};
use assert_cmd::assert::OutputAssertExt;
use predicates::prelude::*;

#[test]
fn an_exception_exits_1_with_its_name_and_a_hint() {
    let server = Server::start();
    server
        .run(&["read", "holding", "999", "--count", "2"])
        .code(1)
        .stdout(predicate::str::is_empty())
        .stderr(predicate::str::contains(
            "unit 1 answered 0x03 Read Holding Registers with exception 0x02 Illegal Data Address",
        ))
        .stderr(predicate::str::contains("--one-based"));
}

#[test]
fn a_silent_unit_exits_3_saying_how_long_and_what_to_check() {
    let server = Server::start();
    let assert =
        ferrobus().args(server.target()).args(["--unit", "2", "--timeout", "100ms", "read", "holding", "0"]).assert();
    let err = stderr(&assert.code(3));
    // The library reports the time it measured: at least the timeout.
    assert!(err.contains("no reply from unit 2 within 1"), "{err}");
    assert!(err.contains(" ms (1 attempt)"), "{err}");
    assert!(err.contains("check:"), "{err}");
    assert!(err.contains("--unit 2"), "{err}");
    assert!(err.contains("8E1 vs 8N1"), "{err}");
    assert!(err.contains("--timeout"), "{err}");
}

#[test]
fn a_silent_unit_on_a_serial_line_names_the_line_settings() {
    let path = pty_server(false);
    let assert = ferrobus()
        .args(["--port", &path, "--parity", "none", "--baud", "9600", "--unit", "7", "--timeout", "100ms"])
        .args(["read", "holding", "0"])
        .assert();
    let err = stderr(&assert.code(3));
    assert!(err.contains(&format!("on {path} at 9600 8N1 (RTU)")), "{err}");
    assert!(err.contains("--unit 7 must match the device's station number"), "{err}");
    assert!(err.contains("this is 9600 8N1; the device must use the same (e.g. 8E1 vs 8N1)"), "{err}");
    assert!(err.contains("swap A and B"), "{err}");
    assert!(err.contains("termination"), "{err}");
}

#[test]
fn retries_are_counted_in_the_timeout_message() {
    let server = Server::start();
    let assert = ferrobus()
        .args(server.target())
        .args(["--unit", "9", "--timeout", "50ms", "--retries", "1", "read", "input", "0"])
        .assert();
    let err = stderr(&assert.code(3));
    assert!(err.contains("no reply from unit 9 within") && err.contains(" ms (2 attempts)"), "{err}");
}

#[test]
fn an_unreachable_server_exits_4_naming_it() {
    let port = closed_port().to_string();
    let target = format!("127.0.0.1:{port}");
    let err = stderr(&ferrobus().args(["--tcp", &target, "read", "holding", "0"]).assert().code(4));
    assert!(err.contains(&format!("opening {target}")), "{err}");
    assert!(err.contains("nothing listens there"), "{err}");
}

#[test]
fn a_missing_serial_port_exits_4_with_a_path_hint() {
    let err = stderr(&offline(&["--port", "/dev/ferrobus-test-nonexistent", "read", "holding", "0"]).code(4));
    assert!(err.contains("/dev/ferrobus-test-nonexistent"), "{err}");
    assert!(err.contains("is the adapter plugged in?"), "{err}");
}

#[test]
fn a_reply_that_does_not_answer_the_request_exits_5() {
    // Two registers asked, one given.
    let port = misbehaving_server(&[0x03, 0x02, 0x00, 0x01]).to_string();
    let target = format!("127.0.0.1:{port}");
    let err =
        stderr(&offline(&["--tcp", &target, "--timeout", "300ms", "read", "holding", "0", "--count", "2"]).code(5));
    assert!(err.contains("bad reply from unit 1"), "{err}");
}

#[test]
fn usage_errors_exit_2() {
    let none = stderr(&offline(&["read", "holding", "0"]).code(2));
    assert!(none.contains("one of --port PATH, --tcp HOST[:PORT] or --rtu-tcp HOST:PORT is required"), "{none}");
    offline(&["--tcp", "a:1", "--port", "/dev/null", "read", "holding", "0"]).code(2);
    offline(&["read", "registers", "0"]).code(2);
    offline(&["--tcp", "a:1", "read", "holding", "0", "--bogus"]).code(2);
    offline(&["--timeout", "soon", "--tcp", "a:1", "read", "holding", "0"]).code(2);
    offline(&["--rtu-tcp", "gateway", "read", "holding", "0"]).code(2);
    offline(&["--port", "/dev/null", "--data-bits", "7", "read", "holding", "0"]).code(2);
}

#[test]
fn arguments_are_checked_before_the_port_is_opened() {
    let err = stderr(&offline(&["--port", "/dev/ferrobus-test-nonexistent", "read", "holding", "70000"]).code(2));
    assert!(err.contains("address 70000 is out of range"), "{err}");
    offline(&["--port", "/dev/ferrobus-test-nonexistent", "write", "register", "0", "x"]).code(2);
    offline(&["--port", "/dev/ferrobus-test-nonexistent", "diag", "echo", "--data", "1"]).code(2);
}

#[test]
fn no_input_panics() {
    let server = Server::start();
    let cases: &[&[&str]] = &[
        &["read", "holding", "0", "--count", "0"],
        &["read", "holding", "0", "--count", "70000"],
        &["read", "holding", "70000"],
        &["read", "holding", "65535", "--count", "2"],
        &["read", "holding", "0", "--type", "u32", "--count", "40000"],
        &["read", "holding", "0", "--count", "200", "--max-per-request", "200"],
        &["read", "holding", "0", "--type", "u32", "--max-per-request", "1"],
        &["read", "holding", "0", "--max-per-request", "0"],
        &["read", "coils", "0", "--type", "u32"],
        &["read", "holding", "0x"],
        &["read", "holding", "-5"],
        &["read", "holding", "4294967296"],
        &["write", "register", "0", "banana"],
        &["write", "register", "0", "70000"],
        &["write", "register", "0", "-1"],
        &["write", "register", "0", "1e99", "--type", "f32"],
        &["write", "registers", "65535", "1", "2"],
        &["write", "coil", "0", "maybe"],
        &["write", "coils", "65535", "1", "1"],
        &["mask", "0", "0x1FFFF", "0"],
        &["readwrite", "--read", "0", "--count", "0", "--write", "0", "1"],
        &["diag", "echo", "--data", "zz"],
        &["diag", "sub", "0x1FFFF"],
        &["diag", "delimiter", "--delimiter", "too long"],
        &["raw", "g"],
    ];
    for case in cases {
        let assert = server.run(case).code(2);
        let err = stderr(&assert);
        assert!(!err.contains("panicked"), "{case:?}: {err}");
        assert!(err.starts_with("error"), "{case:?}: {err}");
    }
    let zero = stderr(&server.run(&["read", "holding", "0", "--count", "0"]).code(2));
    assert!(zero.contains("a count of 0 is out of range: one request carries 1 to 125"), "{zero}");
    let max = stderr(&server.run(&["read", "holding", "0", "--count", "200", "--max-per-request", "200"]).code(2));
    assert!(max.contains("--max-per-request 200 is above the spec's 125 per request"), "{max}");
    // Checked by the library's request constructors (PduError), in plain words.
    let fc17 = stderr(&server.run(&["readwrite", "--read", "0", "--count", "200", "--write", "0", "1"]).code(2));
    assert!(fc17.contains("invalid request: a count of 200 is out of range: one request carries 1 to 125"), "{fc17}");
    assert!(server.take_requests().is_empty(), "nothing invalid reached the device");
    let _ = ferrobus().arg("--version").assert().success();
}

#[test]
fn sim_refuses_a_unit_given_twice_before_it_listens() {
    let err = stderr(
        &offline(&["--tcp", "127.0.0.1:1", "--unit", "1", "--unit", "1", "sim", "--profile", "generic"]).code(2),
    );
    assert!(err.contains("--unit 1 is given twice: one simulated device per address"), "{err}");
}

#[test]
fn sim_says_no_such_file_for_a_missing_profile_path_and_lists_the_builtins_for_a_bare_name() {
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "sim", "--profile", "./nope.toml"]).code(2));
    assert!(err.contains("profile ./nope.toml: no such file"), "{err}");
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "sim", "--profile", "omron"]).code(2));
    assert!(err.contains("no profile named \"omron\": the built-in ones are omron-3g3rx, sdp-servo, generic"), "{err}");
}

#[test]
fn sim_names_the_file_and_line_of_overlapping_profile_registers() {
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-overlap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("overlap.toml");
    std::fs::write(
        &path,
        "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\n[[registers]]\nnumber=1\nname='a'\ntype='u32'\n\n[[registers]]\nnumber=2\nname='b'\n",
    )
    .unwrap();
    let shown = path.display().to_string();
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "sim", "--profile", &shown]).code(2));
    let _ = std::fs::remove_dir_all(&dir);
    assert!(err.contains(&format!("{shown}:12:1: [[registers]] 2 (b) overlaps 1 (a) on line 7")), "{err}");
}

#[test]
fn sim_refuses_a_fault_rule_without_an_action_saying_what_it_takes() {
    let err = stderr(
        &offline(&["--tcp", "127.0.0.1:1", "sim", "--profile", "generic", "--fault", "1:fc=3,addr=0-9"]).code(2),
    );
    assert!(
        err.contains("a rule needs an action: exception, no-reply, delay, short, malformed, unit, tid or trickle"),
        "{err}"
    );
}

#[test]
fn sim_takes_fault_rules_from_a_profile_and_a_fault_option_adds_up_with_the_next() {
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-rules-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rules.toml");
    std::fs::write(
        &path,
        "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\n[[fault_rule]]\nfc = 3\naddr = '0x10-0x1F'\nexception = 6\n",
    )
    .unwrap();
    let shown = path.display().to_string();
    let from_profile =
        stderr(&offline(&["--tcp", "127.0.0.1:0", "sim", "--profile", &shown, "--duration", "10ms"]).success());
    assert!(from_profile.contains("faults: exception 0x06 for 0x03 at 0x0010-0x001F"), "{from_profile}");
    let options = [
        "--tcp",
        "127.0.0.1:0",
        "sim",
        "--profile",
        &shown,
        "--duration",
        "10ms",
        "--fault",
        "1:fc=4,no-reply",
        "--fault",
        "1:trickle=2ms",
    ];
    let from_options = stderr(&offline(&options).success());
    let _ = std::fs::remove_dir_all(&dir);
    // The options replace the profile's faults, and add up in order.
    assert!(
        from_options.contains("faults: no reply for 0x04, byte by byte, 2ms apart for every request"),
        "{from_options}"
    );
}

#[test]
fn a_reply_with_a_bad_crc_exits_3_saying_the_unit_answered_with_a_wrong_checksum_and_the_line_checklist() {
    let sim = Sim::pty(&["--profile", "generic", "--unit", "2", "--fault", "2:corrupt=100%"]);
    let assert = sim.run(2, &["read", "holding", "0"]);
    let err = stderr(&assert.code(3));
    assert!(
        err.contains(
            "no valid reply from unit 2 within 300 ms (1 attempt): unit 2 answered, but the checksum was wrong \
             (function code 0x03, as asked)"
        ),
        "{err}"
    );
    assert!(err.contains("noise") && err.contains("termination"), "{err}");
    assert!(err.contains("this is 19200 8N1; a device set otherwise (e.g. 8E1 vs 8N1) garbles every frame"), "{err}");
    // Not the silence checklist: the unit did answer.
    assert!(!err.contains("no reply from") && !err.contains("swap A and B") && !err.contains("C078"), "{err}");
}

#[test]
fn a_tcp_reply_under_another_transaction_id_exits_3_naming_both_ids() {
    let target = format!("127.0.0.1:{}", misbehaving_server_with(&[0x03, 0x02, 0x00, 0x2A], 1));
    let err = stderr(&offline(&["--tcp", &target, "--timeout", "300ms", "read", "holding", "0"]).code(3));
    assert!(err.contains("no valid reply from unit 1 within 300 ms (1 attempt)"), "{err}");
    assert!(err.contains("a reply came under transaction id 2, not 1, ignored"), "{err}");
    assert!(err.contains("late reply") && err.contains("transaction ids"), "{err}");
}

#[test]
fn sim_refuses_a_ticker_on_a_point_a_unit_lacks_naming_the_unit() {
    let err = stderr(
        &offline(&["--tcp", "127.0.0.1:1", "--unit", "3", "sim", "--profile", "generic", "--ticker", "d005:1s"])
            .code(2),
    );
    assert!(err.contains("--ticker: unit 3: ticker d005: the profile has no point by that name"), "{err}");
    let err =
        stderr(&offline(&["--tcp", "127.0.0.1:1", "sim", "--profile", "omron-3g3rx", "--ticker", "d005"]).code(2));
    assert!(err.contains("expected POINT:PERIOD, e.g. d005:1.1s"), "{err}");
}

#[test]
fn sim_says_which_point_counts_the_clock_s_periods() {
    let said = stderr(
        &offline(&[
            "--tcp",
            "127.0.0.1:0",
            "sim",
            "--profile",
            "omron-3g3rx",
            "--ticker",
            "d005:1.1s",
            "--duration",
            "10ms",
        ])
        .success(),
    );
    assert!(said.contains("sim: every unit's d005 counts 1.1s periods of the system clock"), "{said}");
}
