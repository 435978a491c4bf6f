//! `profile import` on what a user might give it: arbitrary text as each format, or one of
//! the example maps (`examples/maps/*`) with a few edits (bytes cut, text or a token of the
//! formats put in), so that most inputs get past the CSV and YAML readers into the mapping.
//!
//! - It never panics.
//! - A map that imports is a profile that parses, with as many points as the import says,
//!   and its list of what was not mapped shows no control character, and no field or value
//!   longer than 80 characters (and the ellipsis): what comes from a file is shown, never
//!   obeyed.
//! - A map that is refused says where it is from: its Display starts with the origin; it is
//!   never refused for a profile that does not check (what does not fit is listed instead).
#![no_main]

use arbitrary::Arbitrary;
use ferrobus_profile::Profile;
use ferrobus_profile::exchange::{Format, ImportError, ImportOptions, import};
use ferrobus_proto_fuzz::Edit;
use libfuzzer_sys::fuzz_target;

/// The name messages must carry.
const ORIGIN: &str = "fuzz-map";

/// The example maps, the starting points of [`Input::Edited`], with their formats and the
/// `--first-address` each is imported with (none: a Modicon list is recognised).
const EXAMPLES: [(&str, Format, Option<u16>); 8] = [
    (include_str!("../../examples/maps/meter.csv"), Format::Csv, Some(1)),
    (include_str!("../../examples/maps/home-assistant.yaml"), Format::HaYaml, None),
    (include_str!("../../examples/maps/evcc.yaml"), Format::EvccYaml, None),
    (include_str!("../../examples/maps/published/sdm630.csv"), Format::Csv, None),
    (include_str!("../../examples/maps/published/abb-b23.csv"), Format::Csv, None),
    (include_str!("../../examples/maps/published/evcc-meter-and-wallbox.yaml"), Format::EvccYaml, None),
    (include_str!("../../examples/maps/published/sma-sunny-tripower.yaml"), Format::HaYaml, None),
    (include_str!("../../examples/maps/published/ha-config/configuration.yaml"), Format::HaYaml, None),
];

/// Pieces of the formats an edit may put in, beside arbitrary text.
const TOKENS: [&str; 30] = [
    "\n70000;Far;u16;;;;R;;04\n",
    "\n1;Dup;u32;CDAB;1/0;A;RW;;03\n",
    ";string;;;;;;\n",
    "\"quoted;\"\"cell\"\"\"",
    "\t",
    "\n      - name: X\n        address: 65535\n        data_type: uint64\n",
    "\n      - name: Y\n        address: 1\n        data_type: string\n        count: 0\n",
    "        swap: word_byte\n",
    "        slave: 300\n",
    "        input_type: coil\n",
    "        write_type: holdings\n",
    "    covers:\n      - {name: c, address: 9, status_register: 10}\n",
    "    climates:\n      - {name: z, address: 1, target_temp_register: [2, 3]}\n",
    "\n      register: { address: 65534, type: input, decode: float64 }\n",
    "        decode: int32snan\n",
    "      source: calc\n      add:\n",
    "      id: 0\n",
    "      scale: .nan\n",
    "      scale: 1e309\n",
    "!include other.yaml",
    "!secret modbus_slave",
    "!include_dir_merge_list sensors",
    "\n        <<: &m {scale: 2, data_type: int32}\n",
    "\n        <<: [*m, *m]\n        <<: *m\n",
    "\n        address: 7\n        address: 8\n",
    "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[",
    "&a [*a]",
    "{{ .id }}",
    "é\u{0}\u{7}\r",
    "- ",
];

/// Devices `--only-device` may name: those of the evcc examples, an endpoint, and none.
const DEVICES: [&str; 4] = ["grid", "wallbox", "192.168.1.60:502", "pv"];

/// The text of one run and its format.
#[derive(Arbitrary, Debug)]
enum Input {
    /// Any text, as one of the formats.
    Text { text: String, format: u8, unit: Option<u8>, base: u8 },
    /// An example with edits applied in order, and an evcc device picked by one of
    /// [`DEVICES`].
    Edited { example: u8, edits: Vec<Edit>, unit: Option<u8>, device: Option<u8> },
}

impl Input {
    fn run(self) -> (String, Format, ImportOptions) {
        match self {
            Input::Text { text, format, unit, base } => {
                let format = EXAMPLES[usize::from(format) % EXAMPLES.len()].1;
                (
                    text,
                    format,
                    ImportOptions {
                        unit,
                        base: (base % 3 > 0).then(|| u16::from(base % 3 - 1)),
                        ..ImportOptions::default()
                    },
                )
            }
            Input::Edited { example, edits, unit, device } => {
                let (text, format, base) = EXAMPLES[usize::from(example) % EXAMPLES.len()];
                let mut text = text.to_owned();
                for edit in edits {
                    edit.apply(&mut text, &TOKENS);
                }
                let device = device.map(|d| DEVICES[usize::from(d) % DEVICES.len()].to_owned());
                (text, format, ImportOptions { unit, base, device, ..ImportOptions::default() })
            }
        }
    }
}

fuzz_target!(|input: Input| {
    let (text, format, options) = input.run();
    match import(&text, ORIGIN, format, &options) {
        Ok(imported) => {
            let profile = Profile::parse(&imported.toml, ORIGIN)
                .unwrap_or_else(|e| panic!("the profile written does not parse: {e}\n{}", imported.toml));
            assert_eq!(profile.points().len(), imported.points, "{}", imported.toml);
            // The file reads back to the profile the import built.
            assert_eq!(
                format!("{:?}", profile.points()),
                format!("{:?}", imported.profile.points()),
                "{}",
                imported.toml
            );
            for u in &imported.unmapped {
                for shown in [&u.place, &u.field, &u.value, &u.why] {
                    assert!(!shown.chars().any(char::is_control), "a control character shown: {u:?}");
                }
                for shown in [&u.field, &u.value] {
                    assert!(shown.chars().count() <= 81, "a value shown whole: {u:?}");
                }
            }
        }
        Err(e) => {
            assert!(e.to_string().starts_with(ORIGIN), "an error that does not say where from: {e}");
            // What does not fit a profile is listed field by field; a profile that does not
            // check would be the importer's mistake.
            assert!(!matches!(e, ImportError::Invalid { .. }), "{e}");
        }
    }
});
