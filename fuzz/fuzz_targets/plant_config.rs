//! `Plant::parse` on what a user might write: arbitrary text, or one of the shipped examples
//! (`examples/bridge/*.toml`) with a few edits (bytes cut, text or a token of the format put
//! in), so that most inputs get past the TOML reader into the checks behind it.
//!
//! - It never panics.
//! - Every error is somewhere in the text: line 1 to the text's last line and column 1 to one
//!   past that line's last character, or line 0 with column 0 (a whole-file problem, as
//!   `ConfigError` documents); its origin is the one given and its Display starts with it.
//! - A plant that parses keeps the promises the rest of the bridge indexes by: each device
//!   has a deadband per cell of each group, finite and not negative; its groups poll its unit
//!   at a period above zero; metric names are unique in a device, device ids in the plant, line
//!   names in the plant, units on a line; Sparkplug ids pass `check_id`; a plain QoS is 0 to 2.
#![no_main]

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::LazyLock;

use arbitrary::Arbitrary;
use ferrobus_bridge::config::{ConfigErrors, Mode, Plant};
use ferrobus_bridge::sparkplug::topic::check_id;
use ferrobus_proto_fuzz::Edit;
use libfuzzer_sys::fuzz_target;

/// The name errors must carry.
const ORIGIN: &str = "fuzz.toml";

/// The shipped examples, the starting points of [`Input::Edited`].
const EXAMPLES: [&str; 3] = [
    include_str!("../../examples/bridge/demo.toml"),
    include_str!("../../examples/bridge/plant.toml"),
    include_str!("../../examples/bridge/plain.toml"),
];

/// Pieces of the format an edit may put in, beside arbitrary text.
const TOKENS: [&str; 40] = [
    "\n[[line]]\nname = \"l\"\nsimulated = true\n",
    "\n[[line.device]]\nid = \"d\"\nunit = 1\nprofile = \"omron-3g3rx\"\n",
    "\n[[line.device.poll]]\n",
    "\n[[line.device.raw]]\n",
    "\n[broker]\n",
    "\n[broker.tls]\nca = \"ca.pem\"\n",
    "\n[sparkplug]\n",
    "\n[plain]\n",
    "\n[store]\n",
    "profile = \"sdp-servo\"\n",
    "profile = \"generic\"\n",
    "points = [\"F001\", \"d00*\", \"run\"]\n",
    "groups = [\"monitor\", \"status\"]\n",
    "deadbands = { d001 = 0.5, F001 = -1 }\n",
    "deadband = 1e309\n",
    "every = \"0s\"\n",
    "every = \"1.5s\"\n",
    "unit = 0\n",
    "unit = 247\n",
    "unit = 300\n",
    "death_after = 0\n",
    "table = \"coils\"\n",
    "address = 0xFFFF\n",
    "count = 65535\n",
    "type = \"string\"\n",
    "names = [\"a\", \"a\"]\n",
    "name = \"net-weight\"\n",
    "id = \"a/b\"\n",
    "group_id = \"g#\"\n",
    "edge_node_id = \"\"\n",
    "primary_host = \"scada\"\n",
    "qos = 3\n",
    "memory = \"99999999999GiB\"\n",
    "disk = \"1KB\"\n",
    "keep_alive = \"0s\"\n",
    "address = \"[::1]:1883\"\n",
    "tcp = \"127.0.0.1:502\"\n",
    "password_file = \"missing\"\n",
    "baud = 0\n",
    "é\"\u{0}\t=[{",
];

/// Relative paths in an example are taken from its folder.
static BASE_DIR: LazyLock<PathBuf> = LazyLock::new(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/bridge"));

/// The text of one run.
#[derive(Arbitrary, Debug)]
enum Input {
    /// Any text.
    Text(String),
    /// A shipped example with edits applied in order.
    Edited { example: u8, edits: Vec<Edit> },
}

impl Input {
    fn text(self) -> String {
        match self {
            Input::Text(text) => text,
            Input::Edited { example, edits } => {
                let mut text = EXAMPLES[usize::from(example) % EXAMPLES.len()].to_owned();
                for edit in edits {
                    edit.apply(&mut text, &TOKENS);
                }
                text
            }
        }
    }
}

fuzz_target!(|input: Input| {
    let text = input.text();
    match Plant::parse(&text, ORIGIN, &BASE_DIR) {
        Ok(plant) => check_plant(&plant),
        Err(errors) => check_errors(&text, &errors),
    }
});

/// Every error where the text has it, saying where it is from.
fn check_errors(text: &str, errors: &ConfigErrors) {
    assert!(!errors.0.is_empty(), "Plant::parse failed with no error");
    let lines: Vec<&str> = text.split('\n').collect();
    for error in &errors.0 {
        let shown = error.to_string();
        assert_eq!(error.origin, ORIGIN, "{shown}");
        assert!(shown.starts_with(&format!("{ORIGIN}:")), "the error does not start with its origin: {shown}");
        assert!(!error.message.trim().is_empty(), "an error without a message: {shown}");
        // ConfigErrors shows one error a line.
        assert!(!error.message.contains('\n'), "an error of more than one line: {shown}");
        if error.line == 0 {
            assert_eq!(error.column, 0, "a whole-file error with a column: {shown}");
            continue;
        }
        let line = lines.get(error.line - 1).unwrap_or_else(|| {
            panic!("line {} of a text of {} lines: {shown}", error.line, lines.len());
        });
        let width = line.chars().count();
        assert!(
            (1..=width + 1).contains(&error.column),
            "column {} of a line of {width} characters: {shown}",
            error.column
        );
        assert_eq!(shown, format!("{ORIGIN}:{}:{}: {}", error.line, error.column, error.message));
    }
    assert_eq!(errors.to_string().lines().count(), errors.0.len());
}

/// The promises of a plant that parsed.
fn check_plant(plant: &Plant) {
    assert_eq!(plant.origin, ORIGIN);
    match &plant.mode {
        Mode::Sparkplug(sparkplug) => {
            check_id("group", &sparkplug.group_id).unwrap_or_else(|e| panic!("{e}"));
            check_id("edge node", &sparkplug.edge_node_id).unwrap_or_else(|e| panic!("{e}"));
            if let Some(host) = &sparkplug.primary_host {
                check_id("host", host).unwrap_or_else(|e| panic!("{e}"));
            }
        }
        Mode::Plain(plain) => assert!(plain.qos <= 2, "qos {}", plain.qos),
    }
    let mut device_ids = HashSet::new();
    let mut line_names = HashSet::new();
    for line in &plant.lines {
        assert!(line_names.insert(line.name.as_str()), "line name {:?} twice", line.name);
        let mut units = HashSet::new();
        for device in &line.devices {
            assert!(device_ids.insert(device.id.as_str()), "device id {:?} twice", device.id);
            assert!(units.insert(device.unit), "unit {} twice on line {:?}", device.unit, line.name);
            if let Mode::Sparkplug(_) = plant.mode {
                check_id("device", &device.id).unwrap_or_else(|e| panic!("{e}"));
            }
            assert_eq!(device.deadbands.len(), device.groups.len(), "device {:?}: deadbands per group", device.id);
            let mut names = HashSet::new();
            for (group, bands) in device.groups.iter().zip(&device.deadbands) {
                assert_eq!(group.unit, device.unit, "device {:?}: group {:?}", device.id, group.name);
                assert!(!group.every.is_zero(), "device {:?}: group {:?} every 0", device.id, group.name);
                assert_eq!(bands.len(), group.cells.len(), "device {:?}: group {:?} deadbands", device.id, group.name);
                assert!(bands.iter().all(|b| b.is_finite() && *b >= 0.0), "device {:?}: {bands:?}", device.id);
                for cell in &group.cells {
                    assert!(names.insert(cell.name.as_str()), "device {:?}: metric {:?} twice", device.id, cell.name);
                }
            }
        }
    }
}
