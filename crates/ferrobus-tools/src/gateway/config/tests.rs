use std::time::Duration;

use ferrobus_proto::frame::{LineConfig, LineTiming, Parity, StopBits};

use super::{LineDefaults, LinesFile, LinesFileError, parse};
use crate::gateway::{GatewayLine, Route, Routes};
use ferrobus::port::Framing;
use ferrobus::{Backoff, ClientConfig};

/// What a command line without options gives: 19200 8E1, a 1 s timeout, no retries, no
/// backoff, a queue of 64 and a 100 ms late guard.
fn defaults() -> LineDefaults {
    let client = ClientConfig { timeout: Duration::from_secs(1), retries: 0, backoff: None, ..ClientConfig::default() };
    LineDefaults { client, ..LineDefaults::default() }
}

fn lines(text: &str) -> Result<(Vec<GatewayLine>, Routes), LinesFileError> {
    parse("gw.toml", text, &defaults()).map(|LinesFile { lines, routes, .. }| (lines, routes))
}

/// The message `text` is refused with.
fn error(text: &str) -> String {
    match lines(text) {
        Err(e @ LinesFileError::Invalid { .. }) => e.to_string(),
        Err(other) => panic!("not a mistake in the file: {other:?}"),
        Ok(_) => panic!("accepted:\n{text}"),
    }
}

const TWO_LINES: &str = r#"
[[line]]
port = "/dev/ttyA"
baud = 9600
parity = "none"
stop-bits = 2
timeout = "200ms"
response-wait = 300
retries = 2
units = [1, "5-6"]

[[line]]
port = "/dev/ttyB"
baud = 38400
parity = "odd"
t35 = "5ms"
queue = 8
late-guard = "20ms"
late-window = "3500ms"
renumber = { 30 = 3, "41-43" = "1-3", 50 = 9 }
"#;

#[test]
fn each_line_gets_its_own_port_framing_timing_timeout_and_queue() {
    let (lines, _) = lines(TWO_LINES).unwrap();
    assert_eq!(lines.len(), 2);
    let (a, b) = (&lines[0], &lines[1]);
    assert_eq!(a.transport.describe(), "/dev/ttyA at 9600 8N2");
    assert_eq!(b.transport.describe(), "/dev/ttyB at 38400 8O1");
    // t3.5 of 9600 8N2 (3.5 characters of 11 bits, 4.01 ms; 8N1 would be 3.65); above 19200
    // the spec's fixed 1.75 ms, here overridden to 5 ms.
    let framing = LineConfig::new(9600).unwrap().with_parity(Parity::None);
    let at_9600 = LineTiming::new(&framing.with_stop_bits(StopBits::Two));
    assert_eq!(a.transport.timing().t3_5(), at_9600.t3_5());
    assert!(at_9600.t3_5() > Duration::from_millis(4));
    assert_eq!(b.transport.timing().t3_5(), Duration::from_millis(5));
    // The response wait is added to the line's timeout; the other line keeps the default 1 s.
    assert_eq!(a.client.timeout, Duration::from_millis(500));
    assert_eq!(b.client.timeout, Duration::from_secs(1));
    assert_eq!((a.client.retries, b.client.retries), (2, 0));
    assert_eq!((a.queue, b.queue), (64, 8));
    assert_eq!((a.late_guard, b.late_guard), (Duration::from_millis(100), Duration::from_millis(20)));
    // No late window: the client's own (twice the timeout); or the line's.
    assert_eq!((a.client.late_window, b.client.late_window), (None, Some(Duration::from_millis(3500))));
}

#[test]
fn each_line_routes_its_units_and_renumbers_ranges_and_single_units() {
    let (_, routes) = lines(TWO_LINES).unwrap();
    let table: Vec<(u8, Route)> = routes.iter().collect();
    let on = |line, unit| Route { line, unit };
    assert_eq!(
        table,
        [
            (1, on(0, 1)),
            (5, on(0, 5)),
            (6, on(0, 6)),
            (30, on(1, 3)),
            (41, on(1, 1)),
            (42, on(1, 2)),
            (43, on(1, 3)),
            (50, on(1, 9)),
        ]
    );
}

#[test]
fn keys_not_in_a_line_come_from_the_defaults_and_the_line_beats_them() {
    let text = "[[line]]\nport = \"/dev/ttyA\"\nbaud = 9600\n";
    let mut given = defaults();
    given.framing = LineConfig::new(115_200).unwrap().with_parity(Parity::None);
    given.client.timeout = Duration::from_millis(300);
    given.client.retries = 1;
    given.t3_5 = Some(Duration::from_millis(3));
    let LinesFile { lines, routes, .. } = parse("gw.toml", text, &given).unwrap();
    assert_eq!(lines[0].transport.describe(), "/dev/ttyA at 9600 8N1");
    assert_eq!(lines[0].transport.timing().t3_5(), Duration::from_millis(3));
    assert_eq!(lines[0].client.timeout, Duration::from_millis(300));
    assert_eq!(lines[0].client.retries, 1);
    // One line without units: units 1-247 under their own addresses.
    assert_eq!(routes.get(1), Some(Route { line: 0, unit: 1 }));
    assert_eq!(routes.get(247), Some(Route { line: 0, unit: 247 }));
    assert_eq!(routes.get(248), None);
}

#[test]
fn the_defaults_backoff_goes_to_every_line() {
    let backoff = Backoff { after: 3, initial: Duration::from_secs(5), max: Duration::from_secs(60) };
    let mut given = defaults();
    given.client.backoff = Some(backoff);
    let LinesFile { lines, .. } = parse("gw.toml", TWO_LINES, &given).unwrap();
    assert!(lines.iter().all(|l| l.client.backoff == Some(backoff)));
}

/// Asserts that `text` is refused with an error that starts with `gw.toml:LINE:` and holds
/// every one of `words`.
#[track_caller]
fn refused(text: &str, line: usize, words: &[&str]) {
    let message = error(text);
    let at = format!("gw.toml:{line}:");
    assert!(message.starts_with(&at), "expected {at}: {message}");
    for word in words {
        assert!(message.contains(word), "expected {word:?} in: {message}");
    }
}

#[test]
fn an_unknown_key_is_named_with_its_file_line_and_column() {
    refused("[[line]]\nport = \"/dev/ttyA\"\nbuad = 9600\n", 3, &["gw.toml:3:1:", "buad", "baud"]);
    refused("[[lines]]\nport = \"/dev/ttyA\"\n", 1, &["lines"]);
}

#[test]
fn a_bad_baud_rate_is_named_with_its_line_and_what_a_baud_rate_is() {
    let with = |value: &str| {
        format!(
            "[[line]]\nport = \"/dev/ttyA\"\nunits = [1]\n\n[[line]]\nport = \"/dev/ttyB\"\nunits = [2]\nbaud = {value}\n"
        )
    };
    refused(&with("0"), 8, &["gw.toml:8:8:", "[[line]] 1", "baud", "0 is out of range", "bits per second"]);
    refused(&with("-9600"), 8, &["baud", "-9600"]);
    refused(&with("\"9600\""), 8, &["baud", "not a string"]);
    refused(&with("9600.5"), 8, &["baud", "not a float"]);
    refused(&with("99999999999"), 8, &["baud", "out of range"]);
    assert!(matches!(lines(&with("0")), Err(LinesFileError::Invalid { line: Some(1), .. })));
}

#[test]
fn a_unit_routed_twice_is_named_with_both_places() {
    let across =
        "[[line]]\nport = \"/dev/ttyA\"\nunits = [\"1-5\"]\n\n[[line]]\nport = \"/dev/ttyB\"\nunits = [7, 4]\n";
    refused(across, 7, &["[[line]] 1", "units", "unit 4 is routed twice", "to line 0 already (gw.toml:3:10)"]);
    let renumbered = "[[line]]\nport = \"/dev/ttyA\"\nunits = [3]\nrenumber = { \"2-4\" = 10 }\n";
    refused(renumbered, 4, &["[[line]] 0", "renumber", "unit 3 is routed twice", "to line 0 already (gw.toml:3:10)"]);
}

#[test]
fn wrong_values_name_the_key_and_what_it_takes() {
    let line = |extra: &str| format!("[[line]]\nport = \"/dev/ttyA\"\n{extra}\n");
    refused(&line("parity = \"evn\""), 3, &["parity", "'evn' is none of even, odd, none"]);
    refused(&line("rs485 = 1"), 3, &["rs485", "auto, kernel, rts"]);
    refused(&line("data-bits = 7"), 3, &["data-bits", "ascii"]);
    refused(&line("stop-bits = 3"), 3, &["stop-bits", "1 or 2"]);
    refused(&line("timeout = \"0ms\""), 3, &["timeout", "gives up"]);
    refused(&line("t35 = \"fast\""), 3, &["t35", "'fast' is not a duration"]);
    refused(&line("response-wait = -5"), 3, &["response-wait", "negative"]);
    refused(&line("echo = \"yes\""), 3, &["echo", "true or false"]);
    refused(&line("queue = 0"), 3, &["queue", "out of range"]);
    refused(&line("units = [0]"), 3, &["units", "unit 0 is the broadcast"]);
    refused(&line("units = [\"9-3\"]"), 3, &["units", "runs backwards"]);
    refused(&line("units = [256]"), 3, &["units", "256 is no unit"]);
    refused(&line("units = [\"x\"]"), 3, &["units", "'x' is neither a unit nor a range"]);
    refused(&line("renumber = { \"1-3\" = \"5-6\" }"), 3, &["renumber", "3 units (1-3) cannot be renumbered to 2"]);
    refused(&line("renumber = { \"250-255\" = 251 }"), 3, &["renumber", "run past unit 255"]);
}

#[test]
fn names_of_choices_are_taken_in_any_case() {
    let text = "[[line]]\nport = \"/dev/ttyA\"\nparity = \"ODD\"\nrs485 = \"Rts\"\n";
    let (lines, _) = lines(text).unwrap();
    assert_eq!(lines[0].transport.describe(), "/dev/ttyA at 19200 8O1");
}

#[test]
fn a_port_given_twice_a_line_without_a_port_and_a_line_without_units_are_refused() {
    let twice = "[[line]]\nport = \"/dev/ttyA\"\nunits = [1]\n[[line]]\nport = \"/dev/ttyA\"\nunits = [2]\n";
    refused(twice, 5, &["[[line]] 1", "port", "/dev/ttyA is a line already (gw.toml:2:8)"]);
    let no_port = "[[line]]\nbaud = 9600\n";
    assert!(error(no_port).contains("[[line]] 0, no port"), "{}", error(no_port));
    let no_units = "[[line]]\nport = \"/dev/ttyA\"\nunits = [1]\n[[line]]\nport = \"/dev/ttyB\"\n";
    assert!(error(no_units).contains("[[line]] 1, routes no unit"), "{}", error(no_units));
    let no_port_at = error(no_port);
    assert!(no_port_at.starts_with("gw.toml:1:") || no_port_at.starts_with("gw.toml:2:"), "{no_port_at}");
    let empty = "[[line]]\nport = \"/dev/ttyA\"\nunits = []\n";
    assert!(error(empty).contains("[[line]] 0, routes no unit: its units and renumber are empty"), "{}", error(empty));
}

#[test]
fn a_file_without_lines_and_a_syntax_error_are_refused_with_the_file_named() {
    assert!(error("").starts_with("gw.toml: no [[line]] table"), "{}", error(""));
    assert!(matches!(lines(""), Err(LinesFileError::Invalid { line: None, .. })));
    refused("[[line]]\nport = \"/dev/ttyA\n", 2, &["gw.toml:2:"]);
    refused("[[line]]\nport = \"/dev/ttyA\"\nport = \"/dev/ttyB\"\n", 3, &["duplicate key"]);
}

#[test]
fn a_file_that_cannot_be_read_or_is_not_text_is_refused_with_its_name() {
    let missing = std::path::Path::new("/nonexistent/ferrobus-lines.toml");
    let e = super::read(missing, &defaults()).unwrap_err();
    assert!(matches!(&e, LinesFileError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound));
    assert!(e.to_string().starts_with("cannot read the lines file /nonexistent/ferrobus-lines.toml: "), "{e}");
    let dir = std::env::temp_dir().join(format!("ferrobus-lines-{}", std::process::id()));
    std::fs::write(&dir, b"[[line]]\nport = \"\xFF\"\n").unwrap();
    let e = super::read(&dir, &defaults()).unwrap_err();
    let _ = std::fs::remove_file(&dir);
    assert!(e.to_string().starts_with(&format!("{}:2:9: byte 0xFF is not UTF-8", dir.display())), "{e}");
}

#[test]
fn the_readme_example_reads_as_it_says() {
    let readme = include_str!("../../../../../docs/gateway.md");
    let start = readme.find("# ferrobus gateway --lines-file lines.toml").expect("the example in docs/gateway.md");
    let example = readme.get(start..).and_then(|rest| rest.split("```").next()).unwrap();
    let (lines, routes) = lines(example).unwrap();
    assert_eq!(lines[0].transport.describe(), "/dev/ttyUSB0 at 9600 8E1");
    assert_eq!(lines[0].client.timeout, Duration::from_millis(320));
    assert_eq!(lines[1].transport.describe(), "/dev/ttyUSB1 at 115200 8N1");
    assert_eq!(lines[1].transport.timing().t3_5(), Duration::from_millis(2));
    assert_eq!(lines[1].client.retries, 1);
    let on = |line, unit| Some(Route { line, unit });
    assert_eq!((routes.get(2), routes.get(15), routes.get(21)), (on(0, 2), on(0, 15), None));
    assert_eq!((routes.get(30), routes.get(41), routes.get(50)), (on(1, 3), on(1, 1), on(1, 10)));
    assert_eq!(lines[2].transport.describe(), "192.168.1.50:502");
    assert_eq!((lines[2].transport.framing(), lines[2].client.timeout), (Framing::Mbap, Duration::from_secs(1)));
    assert_eq!((lines[0].client.in_flight, lines[2].client.in_flight), (1, 4));
    assert_eq!(routes.get(100), on(2, 1));
}

#[test]
fn a_mistake_on_a_10_mb_line_is_told_in_a_few_hundred_bytes_with_its_place() {
    let huge = format!("[[line]]\nport = \"/dev/ttyUSB0\"\nunits = [1]\nparity = \"{}\"\n", "p".repeat(10 << 20));
    let e = error(&huge);
    assert!(e.len() < 2_000, "{} bytes", e.len());
    assert!(e.contains(":4:") && e.contains('…'), "{}", e.get(..300).unwrap_or(&e));
}

const MIXED: &str = r#"
[[line]]
port = "/dev/ttyA"
units = ["1-9"]

[[line]]
tcp = "10.0.0.7"
timeout = "700ms"
retries = 1
reopen = false
renumber = { 100 = 1 }

[[line]]
rtu-tcp = "10.0.0.8:4001"
t35 = "4ms"
units = ["20-29"]

[[line]]
tcp = "[::1]:1502"
units = [30]
"#;

#[test]
fn tcp_and_rtu_tcp_lines_mix_with_serial_ones_each_with_its_routes_and_settings() {
    let (lines, routes) = lines(MIXED).unwrap();
    let names: Vec<String> = lines.iter().map(|l| l.transport.describe()).collect();
    assert_eq!(names, ["/dev/ttyA at 19200 8E1", "10.0.0.7:502", "10.0.0.8:4001", "[::1]:1502"]);
    let framings: Vec<_> = lines.iter().map(|l| l.transport.framing()).collect();
    assert_eq!(framings, [Framing::Rtu, Framing::Mbap, Framing::Rtu, Framing::Mbap]);
    let remote: Vec<bool> = lines.iter().map(|l| l.transport.is_remote()).collect();
    assert_eq!(remote, [false, true, true, true]);
    assert_eq!((lines[1].client.timeout, lines[1].client.retries), (Duration::from_millis(700), 1));
    assert!(!lines[1].transport.reopens() && lines[2].transport.reopens());
    assert_eq!(lines[2].transport.timing().t3_5(), Duration::from_millis(4));
    let on = |line, unit| Some(Route { line, unit });
    assert_eq!(
        (routes.get(5), routes.get(100), routes.get(25), routes.get(30)),
        (on(0, 5), on(1, 1), on(2, 25), on(3, 30))
    );
    assert_eq!(routes.get(10), None);
}

#[test]
fn a_line_is_exactly_one_of_port_tcp_and_rtu_tcp() {
    refused(
        "[[line]]\nport = \"/dev/ttyA\"\ntcp = \"10.0.0.7\"\n",
        3,
        &["[[line]] 0", "tcp: a line is one of port, tcp and rtu-tcp, and this one has port already"],
    );
    refused(
        "[[line]]\ntcp = \"10.0.0.7\"\nrtu-tcp = \"10.0.0.7:4001\"\n",
        3,
        &["rtu-tcp: a line is one of port, tcp and rtu-tcp, and this one has tcp already"],
    );
    let none = error("[[line]]\ntimeout = \"1s\"\n");
    assert!(none.contains("[[line]] 0, no port: give the serial port") && none.contains("tcp = "), "{none}");
    refused("[[line]]\ntcp = \"\"\n", 2, &["tcp: the address is empty"]);
    refused("[[line]]\ntcp = 502\n", 2, &["tcp: HOST:PORT in quotes, not a integer"]);
    refused("[[line]]\nrtu-tcp = \"10.0.0.8\"\n", 2, &["rtu-tcp: '10.0.0.8' needs its port, HOST:PORT"]);
}

#[test]
fn a_serial_key_on_a_tcp_line_is_named_and_so_is_a_device_given_twice() {
    for key in [
        "baud = 9600",
        "parity = \"even\"",
        "ascii = true",
        "rs485 = \"rts\"",
        "low-latency = true",
        "echo = true",
        "t35 = \"2ms\"",
        "turnaround = \"5ms\"",
    ] {
        let name = key.split_once(' ').unwrap().0;
        refused(
            &format!("[[line]]\ntcp = \"10.0.0.7\"\n{key}\n"),
            3,
            &[&format!(
                "[[line]] 0, {name}: a serial port's setting, and a Modbus/TCP line (tcp = \"10.0.0.7:502\") has none"
            )],
        );
    }
    refused(
        "[[line]]\nrtu-tcp = \"h:4001\"\nstop-bits = 2\n",
        3,
        &["stop-bits: a serial port's setting, and an RTU-over-TCP line (rtu-tcp = \"h:4001\") has none"],
    );
    // RTU over TCP keeps its frame gap: t35 is taken there.
    assert!(lines("[[line]]\nrtu-tcp = \"h:4001\"\nt35 = \"3ms\"\n").is_ok());
    // "h" is "h:502": the same device twice.
    let twice = "[[line]]\ntcp = \"h:502\"\nunits = [1]\n[[line]]\ntcp = \"h\"\nunits = [2]\n";
    refused(twice, 5, &["[[line]] 1", "tcp: h:502 is a line already (gw.toml:2:7)"]);
}

#[test]
fn in_flight_is_a_modbus_tcp_lines_own_and_the_callers_default_reaches_only_those() {
    let text = "[[line]]\ntcp = \"10.0.0.7\"\nin-flight = 8\nunits = [1]\n\n[[line]]\ntcp = \"10.0.0.8\"\nunits = [2]\n\n\
                [[line]]\nport = \"/dev/ttyA\"\nunits = [3]\n\n[[line]]\nrtu-tcp = \"h:4001\"\nunits = [4]\n";
    let four = ClientConfig { in_flight: 4, ..defaults().client };
    let LinesFile { lines, .. } = parse("gw.toml", text, &LineDefaults { client: four, ..defaults() }).unwrap();
    let in_flight: Vec<usize> = lines.iter().map(|l| l.client.in_flight).collect();
    assert_eq!(in_flight, [8, 4, 1, 1], "the line's own, the default, and one on the lines without transaction ids");
    for line in ["port = \"/dev/ttyA\"", "rtu-tcp = \"h:4001\""] {
        refused(
            &format!("[[line]]\n{line}\nin-flight = 2\n"),
            3,
            &["[[line]] 0, in-flight: only a Modbus/TCP line (tcp = ...) keeps several requests in flight"],
        );
    }
    refused(
        "[[line]]\ntcp = \"h\"\nin-flight = 17\n",
        3,
        &["in-flight: 17 is out of range (the requests outstanding at once, 1 to 16)"],
    );
    refused("[[line]]\ntcp = \"h\"\nin-flight = 0\n", 3, &["in-flight: 0 is out of range"]);
}

#[test]
fn a_tcp_line_alone_takes_every_unit_id_and_a_serial_or_rtu_over_tcp_line_alone_units_1_to_247() {
    let (_, routes) = lines("[[line]]\ntcp = \"10.0.0.7\"\n").unwrap();
    let on = |unit| Some(Route { line: 0, unit });
    assert_eq!((routes.get(0), routes.get(1), routes.get(248), routes.get(255)), (on(0), on(1), on(248), on(255)));
    for line in ["port = \"/dev/ttyA\"", "rtu-tcp = \"h:4001\""] {
        let (_, routes) = lines(&format!("[[line]]\n{line}\n")).unwrap();
        assert_eq!((routes.get(0), routes.get(1), routes.get(247), routes.get(248)), (None, on(1), on(247), None));
    }
}
