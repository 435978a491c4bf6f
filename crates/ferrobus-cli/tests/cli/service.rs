//! `ferrobus diag`, `info`, `raw`.

use serde_json::Value;

use crate::server::{Server, Sim, stderr, stdout};

#[test]
fn diag_echo_and_the_word_sub_functions_answer() {
    let server = Server::start();
    assert_eq!(stdout(&server.run(&["diag", "echo"]).success()), "unit 1: echo OK (FC08/00): A5 37\n");
    assert_eq!(
        stdout(&server.run(&["diag", "echo", "--data", "01 02 03"]).success()),
        "unit 1: echo OK (FC08/00): 01 02 03\n"
    );
    let register = stdout(&server.run(&["diag", "register"]).success());
    assert!(register.starts_with("unit 1: diagnostic register 0x"), "{register}");
    assert!(stdout(&server.run(&["diag", "clear"]).success()).contains("(FC08/0A)"));
    assert!(stdout(&server.run(&["diag", "clear-overrun"]).success()).contains("(FC08/14)"));
    assert!(stdout(&server.run(&["diag", "restart", "--clear-log"]).success()).contains("event log cleared"));
    assert!(stdout(&server.run(&["diag", "delimiter", "--delimiter", "\\n"]).success()).contains("0x0A"));
    let counter = stdout(&server.run(&["diag", "counter", "bus-messages"]).success());
    assert!(counter.starts_with("unit 1: 0x000B Return Bus Message Count: "), "{counter}");
    let sub = stdout(&server.run(&["diag", "sub", "0x0E"]).success());
    assert!(sub.starts_with("unit 1: 0x000E Return Server Message Count: "), "{sub}");
}

#[test]
fn diag_counters_reads_all_eight_into_a_table() {
    let server = Server::start();
    let table = stdout(&server.run(&["diag", "counters"]).success());
    assert_eq!(table.lines().count(), 10, "{table}");
    assert!(table.ends_with("(counts as of the first read (0x0B); the tool's own later reads are taken out)\n"));
    assert!(table.lines().next().unwrap().starts_with("sub   counter"), "{table}");
    assert!(table.contains("0x12  Return Bus Character Overrun Count"), "{table}");
    let json: Value = serde_json::from_str(&stdout(&server.run(&["diag", "counters", "--json"]).success())).unwrap();
    let counters = json["counters"].as_object().unwrap();
    assert_eq!(counters.len(), 8);
    assert!(counters.contains_key("bus-messages") && counters.contains_key("overruns"));
}

#[test]
fn diag_counters_are_one_snapshot_the_message_counts_agree() {
    // Every message on this line is addressed to unit 2, so the bus and server message counts
    // must agree; read raw, the server count would be 3 ahead (the reads of 0C, 0D and 0E).
    let sim = Sim::pty(&["--profile", "generic", "--unit", "2"]);
    let run = |args: &[&str]| sim.run(2, args);
    run(&["diag", "echo"]).success();
    let json: Value = serde_json::from_str(&stdout(&run(&["diag", "counters", "--json"]).success())).unwrap();
    let counters = &json["counters"];
    assert_eq!(counters["bus-messages"], counters["server-messages"], "{json}");
    assert!(counters["bus-messages"].as_u64().is_some_and(|n| n >= 1), "{json}");
    assert_eq!(counters["exceptions"], 0, "{json}");
    assert!(json["as_of"].as_str().unwrap().contains("as of the first read"), "{json}");
}

#[test]
fn diag_listen_only_warns_first() {
    let server = Server::start();
    let assert = server.run(&["diag", "listen-only"]).success();
    assert!(stderr(&assert).contains("will stop answering"), "{}", stderr(&assert));
    assert!(stdout(&assert).contains("listen-only mode forced (FC08/04)"));
}

#[test]
fn diag_event_counter_and_log_are_decoded() {
    let server = Server::start();
    let counter = stdout(&server.run(&["diag", "event-counter"]).success());
    assert!(counter.starts_with("unit 1: status 0x0000 (ready), event count "), "{counter}");
    let log = stdout(&server.run(&["diag", "event-log"]).success());
    assert!(log.starts_with("unit 1: status 0x0000 (ready)"), "{log}");
    assert!(log.contains("age  byte  event"), "{log}");
    let json: Value = serde_json::from_str(&stdout(&server.run(&["diag", "event-log", "--json"]).success())).unwrap();
    for event in json["events"].as_array().unwrap() {
        let text = event["event"].as_str().unwrap();
        assert!(["receive", "send", "restart", "entered listen-only"].iter().any(|k| text.starts_with(k)), "{text}");
    }
}

#[test]
fn info_lists_every_category_with_standard_names() {
    let server = Server::start();
    let out = stdout(&server.run(&["info"]).success());
    assert_eq!(
        out,
        "unit 1: conformity 0x83 (extended, stream and individual access)\n\
         id    name                value\n\
         0x00  VendorName          ferrobus\n\
         0x01  ProductCode         FB-TEST\n\
         0x02  MajorMinorRevision  1.2\n\
         0x04  ProductName         Test Drive\n\
         0x05  ModelName           TD-1\n\
         0x80  (extended)          extended object\n"
    );
    let json: Value = serde_json::from_str(&stdout(&server.run(&["info", "--json"]).success())).unwrap();
    assert_eq!(json["objects"].as_array().unwrap().len(), 6);
    assert_eq!(json["objects"][0]["name"], "VendorName");
    assert_eq!(json["conformity"], 0x83);
}

#[test]
fn info_falls_back_to_report_server_id_and_says_so() {
    let server = Server::without_identification();
    let assert = server.run(&["info"]).success();
    assert!(stderr(&assert).contains("does not support FC2B/0E"), "{}", stderr(&assert));
    assert!(stderr(&assert).contains("trying FC11 Report Server ID"));
    let out = stdout(&assert);
    assert!(out.contains("0000  42 FF 46 45 52 52 4F 42 55 53 2D 54 45 53 54"), "{out}");
    assert!(out.contains("|B.FERROBUS-TEST|"), "{out}");
    assert!(out.contains("id 0x42, run indicator ON"), "{out}");
    let direct = stdout(&Server::start().run(&["info", "--server-id"]).success());
    assert_eq!(direct, out);
}

#[test]
fn raw_sends_any_pdu_and_decodes_the_reply() {
    let server = Server::start();
    let want = "request  03 00 02 00 02  (0x03 Read Holding Registers)\n\
                reply    03 04 00 02 00 03\n\
                decoded  ReadHoldingRegisters(RegisterValues { values: [2, 3] })\n";
    assert_eq!(stdout(&server.run(&["raw", "03", "00", "02", "00", "02"]).success()), want);
    assert_eq!(stdout(&server.run(&["raw", "030002", "0002"]).success()), want);
    let exception = server.run(&["raw", "03 03 E8 00 01"]).code(1);
    assert!(stdout(&exception).contains("reply    83 02"), "{}", stdout(&exception));
    assert!(stderr(&exception).contains("exception 0x02 Illegal Data Address"));
    server.run(&["raw", "03 0"]).code(2);
}

#[test]
fn diag_restart_after_listen_only_expects_the_silence_and_confirms_by_an_echo() {
    // Listen-only mode is a serial line's: the simulator on a pty.
    let sim = Sim::pty(&["--profile", "generic", "--unit", "2"]);
    let run = |args: &[&str]| sim.run(2, args);
    run(&["diag", "listen-only"]).success();
    run(&["diag", "echo"]).code(3);
    let assert = run(&["diag", "restart"]).success();
    assert_eq!(
        stdout(&assert),
        "unit 2: communications restarted (FC08/01): no reply, as expected in listen-only mode; it answers the \
         echo (FC08/00) now\n"
    );
    assert!(stderr(&assert).contains("did not answer the restart (FC08/01), as a device in listen-only mode does"));
    // Out of listen-only mode, the restart is answered.
    assert_eq!(stdout(&run(&["diag", "restart"]).success()), "unit 2: communications restarted (FC08/01)\n");
}

#[test]
fn diag_restart_to_a_silent_unit_still_fails_after_the_echo_with_exit_3() {
    let server = Server::start();
    let assert = server.run(&["--unit", "9", "diag", "restart"]).code(3);
    let err = stderr(&assert);
    assert!(err.contains("checking that it answers an echo (FC08/00)"), "{err}");
    assert!(err.contains("no reply from unit 9"), "{err}");
    assert!(stdout(&assert).is_empty());
}
