//! `plant.toml`: the shipped examples resolve, and every kind of mistake is reported at its
//! line and column, all of them at once.

use std::path::Path;
use std::time::Duration;

use ferrobus_bridge::config::{Connection, LineMode, Mode, Plant};
use ferrobus_bridge::sparkplug::convert::UintEncoding;
use ferrobus_profile::Profile;
use ferrobus_tools::poll::Group;

/// The folder of the shipped examples.
fn examples() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/bridge")
}

#[test]
fn the_demo_resolves_to_the_planners_groups() {
    let plant = Plant::demo("broker.local:1884").expect("the demo resolves");
    assert_eq!((plant.broker.host.as_str(), plant.broker.port), ("broker.local", 1884));
    assert_eq!(plant.broker.client_id, "ferrobus-demo-edge");
    let Mode::Sparkplug(spb) = &plant.mode else { panic!("the demo is Sparkplug") };
    assert_eq!((spb.group_id.as_str(), spb.edge_node_id.as_str()), ("ferrobus-demo", "demo-edge"));
    assert_eq!(spb.uint_encoding, UintEncoding::Spec);
    let [line] = plant.lines.as_slice() else { panic!("one line") };
    assert_eq!(line.name, "rs485-demo");
    let Connection::Simulated { line: settings } = line.connection else { panic!("a simulated line") };
    assert_eq!(settings.baud(), 19_200);
    let [inverter, servo] = line.devices.as_slice() else { panic!("two devices") };
    assert_eq!((inverter.id.as_str(), inverter.unit, servo.id.as_str(), servo.unit), ("inverter", 1, "servo", 2));

    // The planner's own groups for the same points, at the same rates.
    let rx = Profile::builtin("omron-3g3rx").unwrap();
    let names = |n: &[&str]| n.iter().map(ToString::to_string).collect::<Vec<_>>();
    let mut expected =
        Group::points(&rx, 1, &names(&["d001", "d002", "d003"]), &[], Duration::from_millis(250)).unwrap();
    expected.extend(
        Group::points(&rx, 1, &names(&["F001", "status-a", "status-b", "running"]), &[], Duration::from_secs(1))
            .unwrap(),
    );
    assert_eq!(inverter.groups, expected);
    let sdp = Profile::builtin("sdp-servo").unwrap();
    assert_eq!(servo.groups, Group::points(&sdp, 2, &[], &names(&["monitor"]), Duration::from_millis(500)).unwrap());

    // Deadbands line up with the cells: the device's, a point's own, 0 by default.
    for device in [inverter, servo] {
        let shape: Vec<usize> = device.groups.iter().map(|g| g.cells.len()).collect();
        assert_eq!(device.deadbands.iter().map(Vec::len).collect::<Vec<_>>(), shape, "{}", device.id);
    }
    assert_eq!(inverter.deadbands[0], [0.05, 0.05, 0.0]);
    let servo_bands: Vec<(&str, f64)> =
        servo.groups[0].cells.iter().map(|c| c.name.as_str()).zip(servo.deadbands[0].iter().copied()).collect();
    assert_eq!(servo_bands, [("motor-speed", 1.0), ("position", 10.0), ("torque", 0.0), ("servo-status", 0.0)]);
    assert_eq!(
        inverter.metric_names().collect::<Vec<_>>(),
        ["d001", "d002", "d003", "running", "F001", "status-a", "status-b"]
    );
    assert_eq!(inverter.death_after, 3);
}

#[test]
fn a_profile_is_loaded_once_and_shared() {
    let plant = Plant::load(&examples().join("plant.toml")).unwrap_or_else(|e| panic!("{e}"));
    let rx: Vec<_> =
        plant.devices().filter_map(|(_, d)| d.profile.as_ref()).filter(|p| p.origin == "omron-3g3rx").collect();
    assert!(rx.len() >= 2, "plant.toml has two 3G3RX");
    assert!(rx.windows(2).all(|w| std::sync::Arc::ptr_eq(w[0], w[1])));
}

#[test]
fn profile_paths_are_relative_to_the_file() {
    let dir = std::env::temp_dir().join(format!("ferrobus-plantcfg-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("drives")).unwrap();
    let generic = ferrobus_profile::BUILTIN.iter().find(|(n, _)| *n == "generic").unwrap().1;
    std::fs::write(dir.join("drives/mine.toml"), generic).unwrap();
    let text = format!(
        "{HEAD}[[line.device]]\nid = \"a\"\nunit = 1\nprofile = \"drives/mine.toml\"\n\
         [[line.device.raw]]\ntable = \"holding\"\naddress = 0\n\
         [[line.device]]\nid = \"b\"\nunit = 2\nprofile = \"drives/mine.toml\"\n\
         [[line.device.raw]]\ntable = \"coils\"\naddress = 0\ncount = 3\nname = \"lamp\"\n"
    );
    let plant = Plant::parse(&text, "plant.toml", &dir).unwrap_or_else(|e| panic!("{e}"));
    let _ = std::fs::remove_dir_all(&dir);
    let [a, b] = plant.lines[0].devices.as_slice() else { panic!("two devices") };
    let (pa, pb) = (a.profile.as_ref().unwrap(), b.profile.as_ref().unwrap());
    assert!(std::sync::Arc::ptr_eq(pa, pb), "one profile, shared");
    assert_eq!(a.metric_names().collect::<Vec<_>>(), ["0x0000"]);
    assert_eq!(b.metric_names().collect::<Vec<_>>(), ["lamp.0", "lamp.1", "lamp.2"]);
    assert_eq!(b.groups[0].count, 3);
}

#[test]
fn a_missing_file_and_a_bad_broker_are_errors_without_a_line() {
    let missing = Plant::load(Path::new("/nonexistent/plant.toml")).unwrap_err();
    let [error] = missing.0.as_slice() else { panic!("one error") };
    assert_eq!(error.line, 0);
    assert!(error.to_string().starts_with("/nonexistent/plant.toml: cannot read the configuration"), "{error}");
    let bad = Plant::demo("broker:99999").unwrap_err();
    assert!(bad.to_string().starts_with("--broker: \"broker:99999\" is not an address"), "{bad}");
    assert_eq!(Plant::demo("10.0.0.5").unwrap().broker.port, 1883);
}

#[test]
fn a_mistake_on_a_10_mb_line_is_a_bounded_message_and_a_binary_file_is_named_at_its_line() {
    let huge = format!("{HEAD}[[line.device]]\nid = \"{}\"\nunit = 1\n", "x/".repeat(5_000_000));
    let errors = errors_of(&huge);
    let printed = errors.join("\n");
    assert!(printed.len() < 2_000, "{} bytes of errors for one 10 MB line", printed.len());
    assert!(printed.starts_with("plant.toml:12:6: device id"), "{}", printed.get(..200).unwrap_or(&printed));
    let dir = std::env::temp_dir().join(format!("ferrobus-bridge-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let binary = dir.join("plant.toml");
    std::fs::write(&binary, b"[broker]\nhost = \"a\"\n\0\xff\xfe").unwrap();
    let error = Plant::load(&binary).unwrap_err().to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(error.contains("plant.toml:3:2: byte 0xFF is not UTF-8 text"), "{error}");
    assert!(error.contains("binary"), "{error}");
}

#[test]
fn errors_print_one_a_line() {
    let text =
        format!("{HEAD}[[line.device]]\nid = \"a/b\"\nunit = 300\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n");
    let errors = Plant::parse(&text, "plant.toml", Path::new(".")).unwrap_err();
    assert_eq!(
        errors.to_string(),
        "plant.toml:12:6: device id \"a/b\" contains '/', which separates topic levels\n\
         plant.toml:13:8: device \"a/b\": unit 300; a device's unit is 1 to 247 (0 is broadcast)"
    );
}

#[test]
fn every_example_parses() {
    let mut seen = 0;
    for entry in std::fs::read_dir(examples()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let plant = Plant::load(&path).unwrap_or_else(|e| panic!("{}:\n{e}", path.display()));
            assert!(plant.devices().count() > 0, "{}", path.display());
            seen += 1;
        }
    }
    assert!(seen >= 3, "demo, plant and plain");
}

#[test]
fn the_real_plant_example_says_what_a_plant_has() {
    let plant = Plant::load(&examples().join("plant.toml")).unwrap_or_else(|e| panic!("{e}"));
    let kinds: Vec<&str> = plant
        .lines
        .iter()
        .map(|l| match &l.connection {
            Connection::Serial { .. } => "serial",
            Connection::Tcp(_) => "tcp",
            Connection::RtuTcp(_) => "rtu_tcp",
            Connection::Simulated { .. } => "simulated",
        })
        .collect();
    assert_eq!(kinds, ["serial", "serial", "tcp"]);
    let Connection::Serial { config: press, ascii: false } = &plant.lines[0].connection else { panic!("RTU") };
    assert_eq!((press.path.to_str(), press.line.to_string().as_str()), (Some("/dev/ttyUSB0"), "19200 8E1"));
    let Connection::Serial { config: packaging, .. } = &plant.lines[1].connection else { panic!("serial") };
    assert_eq!(packaging.line.to_string(), "9600 8N1");
    assert_eq!((plant.lines[0].client.timeout, plant.lines[0].client.retries), (Duration::from_millis(200), 2));
    // The press line's late window is its own; the others' is twice their timeout.
    assert_eq!(plant.lines[0].client.late_window, Some(Duration::from_secs(1)));
    assert_eq!(plant.lines[1].client.late_window, None);
    assert_eq!(plant.lines[2].connection, Connection::Tcp("192.168.10.20:502".into()));
    let in_flight: Vec<usize> = plant.lines.iter().map(|l| l.client.in_flight).collect();
    assert_eq!(in_flight, [1, 1, 4], "the TCP line's own; one request at a time on the serial lines");
    let scale = &plant.lines[1].devices[1];
    assert_eq!(scale.metric_names().collect::<Vec<_>>(), ["net-weight", "tare-mode", "filter"]);
    assert_eq!(scale.deadbands, [vec![0.01], vec![0.0, 0.0]]);
    assert_eq!(plant.broker.password.as_deref(), Some("change-me"));
    assert_eq!(plant.store.memory, 4 << 20);
    assert!(matches!(plant.mode, Mode::Sparkplug(_)));
    assert!(
        plant.store.dir.as_ref().is_some_and(|d| d.starts_with(examples())),
        "the store's dir is relative to the file"
    );
    let plain = Plant::load(&examples().join("plain.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert!(matches!(&plain.mode, Mode::Plain(p) if p.discovery.is_none()), "discovery is off by default");
}

#[test]
fn home_assistant_discovery_is_off_by_default_and_under_homeassistant_when_on() {
    let text = std::fs::read_to_string(examples().join("plain.toml")).expect("the plain example");
    let discovery = |keys: &str| {
        let text = text.replacen("[plain]\n", &format!("[plain]\n{keys}"), 1);
        match Plant::parse(&text, "plain.toml", &examples()).unwrap_or_else(|e| panic!("{keys}: {e}")).mode {
            Mode::Plain(p) => p.discovery,
            Mode::Sparkplug(_) => panic!("plain"),
        }
    };
    assert_eq!(discovery(""), None);
    assert_eq!(discovery("discovery = false\n"), None);
    assert_eq!(discovery("discovery = true\n").as_deref(), Some("homeassistant"));
    assert_eq!(discovery("discovery = true\ndiscovery_prefix = \"ha/site-2\"\n").as_deref(), Some("ha/site-2"));
}

/// The start of every test plant: a broker, Sparkplug, one simulated line.
const HEAD: &str = r#"[broker]
address = "127.0.0.1"

[sparkplug]
group_id = "g"
edge_node_id = "e"

[[line]]
name = "bus"
simulated = true
"#;

/// A device that resolves, to put beside a broken one.
const GOOD: &str = r#"
[[line.device]]
id = "ok"
unit = 9
profile = "omron-3g3rx"
points = ["d001"]
"#;

/// `case` with its `»` markers taken out, and where each marker was (line:col).
fn marked(case: &str) -> (String, Vec<String>) {
    let mut text = String::new();
    let mut marks = Vec::new();
    let (mut line, mut column) = (1, 1);
    for c in case.chars() {
        match c {
            '»' => marks.push(format!("{line}:{column}")),
            '\n' => {
                text.push(c);
                line += 1;
                column = 1;
            }
            _ => {
                text.push(c);
                column += 1;
            }
        }
    }
    (text, marks)
}

/// Whole files: the text (`»` where each error must point) and a word of each message.
const FILE_CASES: &[(&str, &str, &[&str])] = &[
    ("syntax", "[broker]\naddress = \"127.0.0.1»\n", &["invalid basic string"]),
    (
        "several syntax errors",
        "[broker]\naddress = \"h»\nkeep = »= 3\n[sparkplug»\n",
        &["invalid basic string", "extra `=`", "unclosed table"],
    ),
    (
        "a device without an id",
        "[[line]]\nname = \"a\"\nsimulated = true\n»[[line.device]]\nunit = 1\n",
        &["missing key `id`"],
    ),
    ("unknown top-level key", "»colour = 1\n", &["unknown key `colour`"]),
    (
        "unknown broker key",
        "[broker]\naddress = \"h\"\n»kep_alive = \"1s\"\n[sparkplug]\ngroup_id = \"g\"\nedge_node_id = \"e\"\n",
        &["unknown key `kep_alive`"],
    ),
    (
        "everything missing",
        "»»»[store]\nmemory = \"1MiB\"\n",
        &["no [broker] section", "no [sparkplug] or [plain]", "no devices"],
    ),
    (
        "a Sparkplug id with a /",
        "[sparkplug]\ngroup_id = »\"plant/1\"\nedge_node_id = \"e\"\n",
        &["group id \"plant/1\" contains '/'"],
    ),
    (
        "Sparkplug and plain",
        "[broker]\naddress = \"h\"\n[sparkplug]\ngroup_id = \"g\"\nedge_node_id = \"e\"\n[»plain]\nprefix = \"p\"\n",
        &["both [sparkplug] and [plain]"],
    ),
    ("a plain prefix with +", "[plain]\nprefix = »\"plant/+\"\nqos = »3\n", &["has no + or #", "QoS is 0, 1 or 2"]),
    (
        "a discovery prefix without discovery",
        "[plain]\nprefix = \"p\"\ndiscovery_prefix = »\"ha\"\n",
        &["discovery_prefix = \"ha\" without discovery = true: nothing is discovered"],
    ),
    ("discovery not a boolean", "[plain]\nprefix = \"p\"\ndiscovery = »\"yes\"\n", &["expected a boolean"]),
    (
        "a discovery prefix ending with /",
        "[plain]\nprefix = \"p\"\ndiscovery = true\ndiscovery_prefix = »\"homeassistant/\"\n",
        &["discovery_prefix = \"homeassistant/\": a topic prefix is not empty"],
    ),
    (
        "a bad broker address",
        "[broker]\naddress = »\"mqtt://h\"\nkeep_alive = »\"0.5s\"\n",
        &["give no scheme", "1s to 65535s"],
    ),
    ("a password without a user", "[broker]\naddress = »\"h\"\npassword = \"x\"\n", &["a password needs a username"]),
    (
        "two passwords",
        "[broker]\naddress = \"h\"\nusername = \"u\"\npassword = \"x\"\npassword_env = »\"FERROBUS_NO_SUCH_VARIABLE\"\n",
        &["give one of password, password_file and password_env"],
    ),
    ("a bad store size", "[store]\nmemory = »\"4 megs\"\ndisk = »\"1TB\"\n", &["is not a size", "is not a size"]),
    (
        "a device id used on two lines",
        "[[line]]\nname = \"a\"\nsimulated = true\n[[line.device]]\nid = \"x\"\nunit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n\
         [[line]]\nname = »\"a\"\ntcp = \"plc:502\"\n[[line.device]]\nid = »\"x\"\nunit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n",
        &["line name \"a\" is used twice (first at line 2)", "device id \"x\" is used twice (first at line 5)"],
    ),
    (
        "a line with two connections",
        "[[line]]\nname = \"a\"\nport = \"/dev/ttyUSB0\"\ntcp = »\"plc\"\n",
        &["has both port and tcp"],
    ),
    ("a line with none", "[[line]]\nname = »\"a\"\nbaud = 9600\n", &["has no connection"]),
    (
        "a serial key on a TCP line",
        "[[line]]\nname = \"a\"\ntcp = \"plc\"\nparity = »\"odd\"\n",
        &["parity is a serial port's setting"],
    ),
    (
        "bad serial settings",
        "[[line]]\nname = \"a\"\nport = \"/dev/ttyS0\"\nbaud = »0\nparity = »\"mark\"\ndata_bits = »9\nrs485 = »\"yes\"\ntimeout = »\"0ms\"\n",
        &["baud = 0", "even, odd or none", "8 (RTU) or 7", "auto (the adapter), kernel or rts", "longer than zero"],
    ),
    (
        "an unknown TLS key",
        "[broker]\naddress = \"h\"\n[broker.tls]\nca = \"ca.pem\"\n»cafile = \"x\"\n",
        &["unknown key `cafile`, expected one of `ca`, `cert`, `key`, `server_name`"],
    ),
    (
        "TLS files that are not there",
        "[broker]\naddress = \"h\"\n»[broker.tls]\nca = »\"no-such-ca.pem\"\ncert = »\"no-such.pem\"\n",
        &["one of cert and key", "there is no file", "there is no file"],
    ),
    (
        "mistakes in every section at once",
        "[broker]\naddress = »\"h:0\"\n[sparkplug]\ngroup_id = »\"#\"\nedge_node_id = \"e\"\n[store]\ndisk = »\"lots\"\n\
         [[line]]\nname = \"a\"\nsimulated = true\n[[line.device]]\nid = \"x\"\nunit = »0\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n\
         [[line.device]]\nid = \"y\"\nunit = 2\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n[[line.device.poll]]\nevery = \"1s\"\n»pionts = []\n",
        &["the port is not 1 to 65535", "contains '#'", "is not a size", "unit 0", "unknown key `pionts`"],
    ),
    (
        "a metric name with / in plain mode",
        "[plain]\nprefix = \"p\"\n[[line]]\nname = \"a\"\ntcp = \"plc\"\n[[line.device]]\nid = \"x\"\nunit = 1\n\
         [[line.device.raw]]\ntable = \"coils\"\naddress = 0\nname = »\"door/left\"\n",
        &["in plain mode a metric name is a topic level: it is not empty and has no /, +, #"],
    ),
    (
        "an unknown line mode",
        "[[line]]\nname = \"a\"\nport = \"/dev/ttyS0\"\nmode = »\"sniff\"\n",
        &["poll (the default) or listen"],
    ),
    (
        "a listen line that would transmit: the client's timing and poll rates",
        "[[line]]\nname = \"plc\"\nport = \"/dev/ttyS0\"\nmode = \"listen\"\ntimeout = »\"1s\"\nretries = »2\n\
         [[line.device]]\nid = \"x\"\nunit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\nevery = »\"1s\"\n\
         »[[line.device.poll]]\nevery = \"5s\"\npoints = [\"F002\"]\n",
        &[
            "a listen line never transmits, so it has no timeout",
            "no retries",
            "at the master's pace",
            "at the master's pace",
        ],
    ),
    (
        "a listen line on TCP, and one in ASCII",
        "[[line]]\nname = \"a\"\ntcp = \"plc\"\nmode = »\"listen\"\n\
         [[line]]\nname = \"b\"\nport = \"/dev/ttyS0\"\nascii = »true\nmode = \"listen\"\n",
        &["give port", "decodes RTU only"],
    ),
    (
        "requests in flight: out of range on TCP, and on lines without transaction ids",
        "[[line]]\nname = \"a\"\ntcp = \"plc\"\nin_flight = »17\n\
         [[line]]\nname = \"b\"\nrtu_tcp = \"server\"\nin_flight = »4\n\
         [[line]]\nname = \"c\"\nport = \"/dev/ttyS0\"\nmode = \"listen\"\nin_flight = »1\n",
        &["in_flight = 17: it is 1 to 16", "by transaction id", "by transaction id"],
    ),
    (
        "an unknown line key, and its devices still checked",
        "[[line]]\nname = \"a\"\nsimulated = true\n»speed = 9600\n[[line.device]]\nid = \"x\"\nunit = »0\n",
        &["unknown key `speed`", "unit 0"],
    ),
];

/// Device cases, after `HEAD` and a good device: the text (`»` where each error must point)
/// and a word of each message.
const DEVICE_CASES: &[(&str, &str, &[&str])] = &[
    ("type error", "unit = »\"one\"\n", &["invalid type: string \"one\", expected a whole number"]),
    ("a string for an array", "unit = 1\nprofile = \"omron-3g3rx\"\npoints = »\"d001\"\n", &["expected an array"]),
    ("unknown device key", "unit = 1\nprofile = \"omron-3g3rx\"\n»point = [\"d001\"]\n", &["unknown key `point`"]),
    ("unit 0", "unit = »0\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n", &["unit 0; a device's unit is 1 to 247"]),
    ("unit 248", "unit = »248\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n", &["unit 248"]),
    (
        "duplicate unit",
        "unit = »9\nprofile = \"omron-3g3rx\"\npoints = [\"d002\"]\n",
        &["unit 9 is used twice (first at line 14)"],
    ),
    (
        "unknown profile",
        "unit = 1\nprofile = »\"omron-4g\"\npoints = [\"d001\"]\n",
        &["the built-in ones are omron-3g3rx"],
    ),
    (
        "unknown points, all of them",
        "unit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\", »\"F00x\", »\"zz*\"]\n",
        &["omron-3g3rx has no parameter \"F00x\"", "no parameter \"zz*\""],
    ),
    (
        "unknown group",
        "unit = 1\nprofile = \"omron-3g3rx\"\ngroups = [»\"monitr\"]\n",
        &["has no group \"monitr\" (its groups:"],
    ),
    (
        "raw address out of range",
        "unit = 1\n[[line.device.raw]]\ntable = \"holding\"\naddress = »70000\n",
        &["address = 70000: a wire address is 0 to 65535"],
    ),
    (
        "raw range past the end",
        "unit = 1\n»[[line.device.raw]]\ntable = \"holding\"\naddress = 0xFFFF\ntype = \"u32\"\n",
        &["run past 0xFFFF"],
    ),
    (
        "zero period",
        "unit = 1\nprofile = \"omron-3g3rx\"\nevery = »\"0s\"\npoints = [\"d001\"]\n",
        &["longer than zero"],
    ),
    (
        "bad duration",
        "unit = 1\nprofile = \"omron-3g3rx\"\nevery = »\"fast\"\npoints = [\"d001\"]\n",
        &["not a duration"],
    ),
    (
        "negative deadband",
        "unit = 1\nprofile = \"omron-3g3rx\"\ndeadband = »-1.0\npoints = [\"d001\"]\n",
        &["deadband of -1"],
    ),
    (
        "deadband of a point not polled",
        "unit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\ndeadbands = { »d002 = 1 }\n",
        &["polls no \"d002\"; it polls d001"],
    ),
    (
        "metric polled twice",
        "unit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n[[line.device.poll]]\nevery = \"1s\"\npoints = [»\"d001\"]\n",
        &["metric \"d001\" is polled twice (first at line"],
    ),
    (
        "a raw alias clashes with a point",
        "unit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n[[line.device.raw]]\ntable = \"holding\"\naddress = 0x2000\nname = »\"d001\"\n",
        &["metric \"d001\" is polled twice"],
    ),
    (
        "two raw names alike",
        "unit = 1\n[[line.device.raw]]\ntable = \"coils\"\naddress = 0\ncount = 2\nnames = [\"a\", \"b\"]\n\
         [[line.device.raw]]\ntable = \"holding\"\naddress = 0\ncount = 3\nnames = [\"c\", »\"a\", \"d\"]\n",
        &["metric \"a\" is polled twice"],
    ),
    (
        "raw names that do not fit",
        "unit = 1\n[[line.device.raw]]\ntable = \"holding\"\naddress = 0\ncount = 4\ntype = \"f32\"\nnames = [»\"a\"]\n\
         [[line.device.raw]]\ntable = »\"holdings\"\naddress = 0\ntype = »\"u128\"\norder = »\"ABDC\"\nname = »\"a+b\"\n",
        &[
            "1 names for 2 cells of f32",
            "it is coils, discrete, holding or input",
            "it is one of u16, i16",
            "it is ABCD, CDAB",
            "has no +, #",
        ],
    ),
    (
        "bad counts and periods",
        "unit = 1\nprofile = \"omron-3g3rx\"\ndeath_after = »0\npoints = [\"d001\"]\ndeadbands = { d001 = »-0.5 }\n\
         [[line.device.poll]]\nevery = »\"0ms\"\npoints = [\"d002\"]\ndeadband = »-1\n",
        &[
            "death_after = 0: it is 1 or more polls",
            "deadbands.d001: a deadband of -0.5",
            "longer than zero",
            "a deadband of -1",
        ],
    ),
    ("polls nothing", "id = »\"dev\"\nunit = 1\nprofile = \"omron-3g3rx\"\n", &["polls nothing"]),
    (
        "a poll with nothing",
        "unit = 1\nprofile = \"omron-3g3rx\"\npoints = [\"d001\"]\n»[[line.device.poll]]\nevery = \"1s\"\n",
        &["names no points and no groups"],
    ),
    ("points without a profile", "unit = 1\npoints = [»\"d001\"]\n", &["has no profile"]),
];

/// Runs a device case: `HEAD`, a good device, then `[[line.device]]`, `id = "dev"` (unless
/// the case gives the id) and the case.
fn device_errors(case: &str) -> (Vec<String>, Vec<String>) {
    let id = if case.starts_with("id =") { "" } else { "id = \"dev\"\n" };
    let head = format!("{HEAD}{GOOD}\n[[line.device]]\n{id}");
    let (text, marks) = marked(&format!("{head}{case}"));
    (errors_of(&text), marks)
}

/// Every error of `text`, as printed.
fn errors_of(text: &str) -> Vec<String> {
    match Plant::parse(text, "plant.toml", Path::new(".")) {
        Ok(_) => Vec::new(),
        Err(e) => e.0.iter().map(ToString::to_string).collect(),
    }
}

#[test]
fn a_listen_line_is_a_serial_port_whose_devices_have_the_planners_groups() {
    let text = format!(
        "{}[[line]]\nname = \"plc\"\nport = \"/dev/ttyS0\"\nbaud = 9600\nmode = \"listen\"\n{}",
        HEAD.split("[[line]]").next().unwrap(),
        GOOD
    );
    let plant = Plant::parse(&text, "plant.toml", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
    let [line] = plant.lines.as_slice() else { panic!("one line") };
    assert_eq!(line.mode, LineMode::Listen);
    assert!(matches!(&line.connection, Connection::Serial { ascii: false, .. }));
    assert_eq!(line.devices[0].groups[0].cells[0].name, "d001");
    let polled = Plant::parse(&text.replace("mode = \"listen\"\n", ""), "plant.toml", Path::new(".")).unwrap();
    assert_eq!(polled.lines[0].mode, LineMode::Poll, "poll is the default");
}

#[test]
fn every_mistake_is_reported_at_its_place() {
    let mut failures = Vec::new();
    let files = FILE_CASES.iter().map(|(name, case, words)| {
        let (text, marks) = marked(case);
        (name, errors_of(&text), marks, words)
    });
    let devices = DEVICE_CASES.iter().map(|(name, case, words)| {
        let (errors, marks) = device_errors(case);
        (name, errors, marks, words)
    });
    for (name, errors, marks, words) in files.chain(devices) {
        assert_eq!(marks.len(), words.len(), "{name}: a word for each mark");
        for (mark, word) in marks.iter().zip(words.iter()) {
            let wanted = format!("plant.toml:{mark}: ");
            if !errors.iter().any(|e| e.starts_with(&wanted) && e.contains(word)) {
                failures.push(format!("{name}: no error at {mark} saying {word:?}; got:\n  {}", errors.join("\n  ")));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_raw_cells_order_is_the_one_word_order_and_decodes_the_four_order_table() {
    // 0x11223344 as A=11 B=22 C=33 D=44: the table of ferrobus_proto::words, read/write, poll and get/set.
    for (typed, registers) in [
        ("ABCD", [0x1122, 0x3344]),
        ("low-first", [0x3344, 0x1122]),
        ("badc", [0x2211, 0x4433]),
        ("DCBA", [0x4433, 0x2211]),
    ] {
        let text = format!(
            "{HEAD}[[line.device]]\nid = \"dev\"\nunit = 1\nprofile = \"generic\"\n[[line.device.raw]]\ntable = \"holding\"\naddress = 0\n\
             type = \"u32\"\norder = \"{typed}\"\nname = \"v\"\n"
        );
        let plant = Plant::parse(&text, "plant.toml", Path::new(".")).unwrap_or_else(|e| panic!("{typed}: {e}"));
        let (_, device) = plant.devices().next().expect("one device");
        assert_eq!(device.groups[0].decode(&registers), [Ok(ferrobus_profile::Value::Int(0x1122_3344))], "{typed}");
    }
}

#[test]
fn durations_and_sizes_in_a_plant_file_are_the_one_grammar() {
    // The inputs every user of ferrobus::text is tested with: a plain number is milliseconds,
    // MB is 10^6 bytes and MiB 2^20.
    let text = format!(
        "{HEAD}[store]\nmemory = \"10MB\"\ndir = \"/tmp/ferrobus-grammar\"\ndisk = \"10MiB\"\n{GOOD}\
         [[line.device.poll]]\nevery = \"250\"\npoints = [\"d002\"]\n"
    );
    let plant = Plant::parse(&text, "plant.toml", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((plant.store.memory, plant.store.disk), (10_000_000, 10 << 20));
    let (_, device) = plant.devices().next().expect("one device");
    assert_eq!(device.groups.last().map(|g| g.every), Some(Duration::from_millis(250)));
}
