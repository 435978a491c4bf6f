//! The profile reader's tests: built-ins load, mistakes are named with file, line and field.

use super::*;
use crate::{LABEL_MAX, NAME_MAX, Order, TEXT_MAX, UNIT_MAX, Value};

#[test]
fn every_builtin_profile_loads() {
    for (name, _) in BUILTIN {
        let p = Profile::load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!p.device.name.is_empty());
    }
    let rx = Profile::load("omron-3g3rx").unwrap();
    assert_eq!(rx.limits.read_registers, Some(4));
    assert_eq!(rx.exceptions.out_of_range, 0x21);
    assert_eq!(rx.addressing.base, 1);
}

#[test]
fn an_unknown_name_lists_the_builtins() {
    let e = Profile::load("omron-3g3xx").unwrap_err();
    assert_eq!(
        e.to_string(),
        "no profile named \"omron-3g3xx\": the built-in ones are omron-3g3rx, sdp-servo, generic, sunspec-inverter, or give a path to a .toml file"
    );
}

const DEVICE: &str = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n";

fn error(text: &str) -> String {
    Profile::parse(text, "mine.toml").unwrap_err().to_string()
}

#[test]
fn mistakes_in_a_profile_are_reported_with_the_file_the_line_and_the_field() {
    assert_eq!(
        error(&format!("{DEVICE}colour = 'red'\n")),
        "mine.toml:6:1: [device]: unknown field `colour`, expected one of `name`, `vendor`, \
         `product_code`, `revision`, `vendor_url`, `product_name`, `model_name`, `user_application_name`, \
         `identification`, `server_id` (in `colour = 'red'`)"
    );
    let wrong_type = error(&format!("{DEVICE}[[registers]]\nnumber = 'one'\nname = 'r'\n"));
    assert!(wrong_type.starts_with("mine.toml:7:10: [[registers]] entry 1 (r): invalid type: string"), "{wrong_type}");
    let old = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nsize=2\n"));
    assert!(old.starts_with("mine.toml:9:1: [[registers]] 1 (r): unknown field `size`"), "{old}");
    assert!(old.ends_with("(size, signed and word_order are now type and order: type = \"u32\" or \"i32\", order = \"ABCD\" for high-first or \"CDAB\" for low-first) (in `size=2`)"), "{old}");
    let bad_type = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='u24'\n"));
    assert!(bad_type.starts_with("mine.toml:9:6: [[registers]] 1 (r): unknown variant `u24`"), "{bad_type}");
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='string'\n")),
        "mine.toml:6:1: [[registers]] 1 (r): a string needs length = its registers (1 or more) (in `[[registers]]`)"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nvalues={{ 'x' = 'on' }}\n")),
        "mine.toml:9:1: [[registers]] 1 (r): values key \"x\" is not a raw u16 value (in `values={ 'x' = 'on' }`)"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ndepends_on=['A004']\n")),
        "mine.toml:9:1: [[registers]] 1 (r): depends_on names \"A004\", which the profile does not have \
         (in `depends_on=['A004']`)"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[span]]\ntable='holding'\nfirst=9\nlast=3\n")),
        "mine.toml:6:1: [[span]] holding: first = 9 is above last = 3 (in `[[span]]`)"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nmin=5\nmax=4\n")),
        "mine.toml:10:1: [[registers]] 1 (r): min = 5 is above max = 4 (in `max=4`)"
    );
}

#[test]
fn an_order_is_one_of_the_four_names_or_an_alias_in_any_case_and_defaults_to_the_devices() {
    let pair = |order: &str| {
        format!("[addressing]\norder='CDAB'\n{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='u32'\n{order}")
    };
    let default = Profile::parse(&pair(""), "mine.toml").unwrap();
    assert_eq!(default.points()[0].order, Order::Cdab);
    let own = Profile::parse(&pair("order='BADC'\n"), "mine.toml").unwrap();
    assert_eq!(own.points()[0].order, Order::Badc);
    // The one parser of word orders, as the command line and the bridge take them.
    for (typed, order) in [("cdab", Order::Cdab), ("high-first", Order::Abcd), ("Low-First", Order::Cdab)] {
        let parsed = Profile::parse(&pair(&format!("order='{typed}'\n")), "mine.toml").unwrap();
        assert_eq!(parsed.points()[0].order, order, "{typed}");
    }
    let wrong = error(&pair("order='swap'\n"));
    assert!(
        wrong.starts_with(
            "mine.toml:12:7: [[registers]] 1 (r): \"swap\" is not a word order: use ABCD (or high-first), CDAB (or low-first), BADC, DCBA"
        ),
        "{wrong}"
    );
    let single = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\norder='CDAB'\n"));
    assert_eq!(
        single,
        "mine.toml:9:1: [[registers]] 1 (r): order is for values of more than one register, not u16 (in `order='CDAB'`)"
    );
}

#[test]
fn overlapping_registers_are_refused_naming_both_and_their_lines() {
    let text = format!(
        "{DEVICE}[[registers]]\nnumber=10\nname='a'\ncount=4\n\n[[registers]]\nnumber=20\nname='b'\n\n\
         [[registers]]\nnumber=12\nname='c'\ntype='u32'\n"
    );
    assert_eq!(error(&text), "mine.toml:15:1: [[registers]] 12 (c) overlaps 10 (a) on line 6 (in `[[registers]]`)");
    let duplicate = format!("{DEVICE}[[coils]]\nnumber=3\nname='a'\n[[coils]]\nnumber=3\nname='b'\n");
    assert_eq!(
        error(&duplicate),
        "mine.toml:9:1: [[coils]] 3 (b) is at the same number as 3 (a) on line 6 (in `[[coils]]`)"
    );
    // A 32-bit pair takes two numbers; the next one may follow it.
    let pairs = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\ntype='i32'\n[[inputs]]\nnumber=3\nname='b'\n");
    assert!(Profile::parse(&pairs, "mine.toml").is_ok());
    let clash = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\ntype='f32'\n[[inputs]]\nnumber=2\nname='b'\n");
    assert_eq!(error(&clash), "mine.toml:10:1: [[inputs]] 2 (b) overlaps 1 (a) on line 6 (in `[[inputs]]`)");
    // The same number in two tables is no overlap: coils and registers are apart.
    let apart = format!("{DEVICE}[[coils]]\nnumber=1\nname='a'\n[[registers]]\nnumber=1\nname='b'\n");
    assert!(Profile::parse(&apart, "mine.toml").is_ok());
}

#[test]
fn a_missing_file_says_so_and_a_bare_unknown_name_lists_the_builtins() {
    assert_eq!(Profile::load("./nope.toml").unwrap_err().to_string(), "profile ./nope.toml: no such file");
    assert_eq!(Profile::load("drives/nope").unwrap_err().to_string(), "profile drives/nope: no such file");
    assert_eq!(Profile::load("nope.toml").unwrap_err().to_string(), "profile nope.toml: no such file");
    assert!(
        Profile::load("nope").unwrap_err().to_string().starts_with("no profile named \"nope\": the built-in ones are")
    );
}

#[test]
fn parse_all_lists_every_mistake_of_a_profile_in_the_files_order_each_with_its_place() {
    let text = format!(
        "{DEVICE}[[registers]]\nnumber=1\nname='a'\nmin=5\nmax=4\n\n[[registers]]\nnumber=2\nname='b'\n\
         type='string'\n\n[[coils]]\nnumber=3\nname='c'\n[[coils]]\nnumber=3\nname='d'\n"
    );
    let mistakes: Vec<String> =
        Profile::parse_all(&text, "mine.toml").unwrap_err().iter().map(ToString::to_string).collect();
    assert_eq!(
        mistakes,
        [
            "mine.toml:10:1: [[registers]] 1 (a): min = 5 is above max = 4 (in `max=4`)",
            "mine.toml:12:1: [[registers]] 2 (b): a string needs length = its registers (1 or more) (in `[[registers]]`)",
            "mine.toml:20:1: [[coils]] 3 (d) is at the same number as 3 (c) on line 17 (in `[[coils]]`)",
        ]
    );
    // One mistake at a time, where a single error is wanted: the first.
    assert_eq!(error(&text), mistakes[0]);
}

#[test]
fn a_10_mb_line_gives_an_error_of_a_few_hundred_bytes_with_an_excerpt_around_the_column() {
    let long = "x".repeat(10 << 20);
    for text in [format!("{DEVICE}name2 = '{long}'\n"), format!("{DEVICE}[[registers]]\nnumber = '{long}'\n")] {
        let e = error(&text);
        assert!(e.len() < 1_000, "{} bytes: {}…", e.len(), e.get(..300).unwrap_or(&e));
        assert!(e.starts_with("mine.toml:"), "{e}");
        assert!(e.contains('…'), "{e}");
    }
}

#[test]
fn a_binary_or_non_utf8_profile_file_is_refused_with_its_line_and_column() {
    let dir = std::env::temp_dir().join(format!("ferrobus-profile-binary-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let latin1 = dir.join("latin1.toml");
    std::fs::write(&latin1, b"[device]\nname = 'Caf\xe9'\n").unwrap();
    let e = Profile::load(latin1.to_str().unwrap()).unwrap_err().to_string();
    assert_eq!(e, format!("{}:2:12: byte 0xE9 is not UTF-8 text", latin1.display()));
    let binary = dir.join("image.toml");
    std::fs::write(&binary, b"\x7fELF\x02\x01\x01\0\0\0\0\0\0\0\0\0\x03\0\x3e\0\xff\xfe").unwrap();
    let e = Profile::load(binary.to_str().unwrap()).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}:1:21: byte 0xFF", binary.display())), "{e}");
    assert!(e.ends_with("(this looks like a binary file, not a TOML text file)"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn seven_type_errors_in_seven_entries_are_all_reported_in_one_run() {
    let text = format!(
        "{DEVICE}[comm]\nresponse_wait_ms = 'soon'\n\
         [[registers]]\nnumber = 'one'\nname = 'a'\n\
         [[registers]]\nnumber = 2\nname = 'b'\ntype = 'u24'\n\
         [[registers]]\nnumber = 3\nname = 'c'\nscale = 'ten'\n\
         [[inputs]]\nnumber = 1\nname = 'd'\ncolour = 'red'\n\
         [[coils]]\nnumber = 1\nname = 'e'\ndefault = 'on'\n\
         [[span]]\ntable = 'holdings'\nfirst = 0\nlast = 9\n\
         [[registers]]\nnumber = 9\nname = 'fine'\n\
         [[registers]]\nnumber = 10\nname = 'f'\nmin = 5\nmax = 4\n"
    );
    let mistakes: Vec<String> =
        Profile::parse_all(&text, "mine.toml").unwrap_err().iter().map(ToString::to_string).collect();
    let lines: Vec<&str> = mistakes.iter().map(|m| m.split(':').nth(1).unwrap_or_default()).collect();
    assert_eq!(lines, ["7", "9", "14", "18", "22", "26", "28", "38"], "{mistakes:#?}");
    for (mistake, said) in mistakes.iter().zip([
        "[comm]: invalid type: string \"soon\"",
        "[[registers]] entry 1 (a): invalid type: string \"one\"",
        "[[registers]] 2 (b): unknown variant `u24`",
        "[[registers]] 3 (c): invalid type: string \"ten\"",
        "[[inputs]] 1 (d): unknown field `colour`",
        "[[coils]] 1 (e): invalid type: string \"on\"",
        "[[span]] entry 1: unknown variant `holdings`",
        "[[registers]] 10 (f): min = 5 is above max = 4",
    ]) {
        assert!(mistake.contains(said), "{mistake:?} says {said:?}");
    }
}

#[test]
fn two_entries_of_one_name_or_two_points_of_one_code_are_refused_naming_both() {
    let same_name = format!("{DEVICE}[[registers]]\nnumber=1\nname='F001'\n[[inputs]]\nnumber=1\nname='f001'\n");
    assert_eq!(
        error(&same_name),
        "mine.toml:9:1: [[inputs]] 1 (f001): the name is also that of [[registers]] 1 (F001) on line 6 (in `[[inputs]]`)"
    );
    // A run's codes are NAME1, NAME2, ...: F01 is the second point of F0.
    let same_code =
        format!("{DEVICE}[[registers]]\nnumber=1\nname='F0'\ncount=3\n[[registers]]\nnumber=9\nname='F02'\n");
    assert_eq!(
        error(&same_code),
        "mine.toml:10:1: [[registers]] 9 (F02): its point F02 has the code of a point of [[registers]] 1 (F0) on \
         line 6 (in `[[registers]]`)"
    );
    let apart = format!("{DEVICE}[[registers]]\nnumber=1\nname='F0'\ncount=3\n[[registers]]\nnumber=9\nname='F04'\n");
    assert!(Profile::parse(&apart, "mine.toml").is_ok());
}

#[test]
fn control_characters_are_refused_with_the_entry_the_field_and_the_character_escaped() {
    let escape = format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nlabel=\"red\\u001b[31m\"\n");
    assert_eq!(
        error(&escape),
        "mine.toml:9:7: [[registers]] 1 (r): label holds the control character \\u{1b} at character 4: a profile's \
         text must be printable (in `label=\"red\\u001b[31m\"`)"
    );
    let nul = format!("{DEVICE}[[coils]]\nnumber=1\nname='c'\ngroup=\"a\\u0000\"\n");
    assert!(
        error(&nul).contains("[[coils]] 1 (c): group holds the control character \\u{0} at character 2"),
        "{}",
        error(&nul)
    );
    let unit = format!("{DEVICE}[[inputs]]\nnumber=1\nname='i'\nunit=\"\\u009b2J\"\n");
    assert!(error(&unit).contains("unit holds the control character \\u{9b}"), "{}", error(&unit));
    let meaning = format!("{DEVICE}[[inputs]]\nnumber=1\nname='i'\nvalues={{ '1' = \"on\\u202e\" }}\n");
    assert!(error(&meaning).contains("values.1 holds the control character \\u{202e}"), "{}", error(&meaning));
    let device = "[device]\nname=\"x\\u0007\"\nvendor='v'\nproduct_code='p'\nrevision='1'\n";
    assert!(
        error(device).starts_with("mine.toml:2:6: [device]: name holds the control character \\u{7}"),
        "{}",
        error(device)
    );
    // A description may break lines; a label may hold a tab.
    let lines = format!("{DEVICE}[[inputs]]\nnumber=1\nname='i'\nlabel=\"a\\tb\"\ndescription=\"one\\ntwo\"\n");
    assert!(Profile::parse(&lines, "mine.toml").is_ok());
}

#[test]
fn names_labels_units_and_texts_are_bounded_with_the_limit_said() {
    let long =
        |field: &str, n: usize| format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\n{field}='{}'\n", "x".repeat(n));
    assert!(Profile::parse(&long("unit", UNIT_MAX), "mine.toml").is_ok());
    assert_eq!(
        error(&long("unit", UNIT_MAX + 1)),
        format!(
            "mine.toml:9:6: [[registers]] 1 (r): unit is 33 characters long, more than the {UNIT_MAX} a unit may \
             have (in `unit='{}'`)",
            "x".repeat(33)
        )
    );
    assert!(error(&long("label", LABEL_MAX + 1)).contains("label is 257 characters long, more than the 256"));
    assert!(error(&long("description", TEXT_MAX + 1)).contains("description is 4097 characters long"));
    // A 100 MB name: refused in a message of a few hundred bytes.
    let name = format!("{DEVICE}[[registers]]\nnumber=1\nname='{}'\n", "n".repeat(100 << 20));
    let e = error(&name);
    assert!(e.len() < 1_000, "{} bytes", e.len());
    assert!(
        e.contains(&format!("name is {} characters long, more than the {NAME_MAX} a name may have", 100 << 20)),
        "{e}"
    );
}

#[test]
fn a_not_implemented_value_reads_as_none_of_a_number_a_meaning_or_a_reading() {
    let text = format!(
        "{DEVICE}[[registers]]\nnumber=1\nname='t'\ntype='i16'\nscale=0.1\nunit='C'\nnot_implemented=-32768\n\
         [[registers]]\nnumber=2\nname='st'\nvalues={{ '1' = 'off' }}\nnot_implemented=0xFFFF\n\
         [[registers]]\nnumber=3\nname='f'\ntype='f32'\nnot_implemented=nan\n\
         [[registers]]\nnumber=5\nname='w'\nscale=10.0\nimplemented=false\n\
         [[registers]]\nnumber=6\nname='e'\ntype='u64'\nnot_implemented='0xFFFFFFFFFFFFFFFF'\n"
    );
    let profile = Profile::parse(&text, "mine.toml").unwrap();
    let point = |code: &str| profile.point(code).unwrap().clone();
    let temp = point("t");
    let raw = temp.decode(&[0x8000]).unwrap();
    assert_eq!((temp.show(&raw), temp.number(&raw), temp.engineering(&raw)), ("n/a".into(), String::new(), None));
    assert_eq!(temp.show(&temp.decode(&[0xFFE2]).unwrap()), "-3.0 C", "any other value is a reading");
    let st = point("st");
    assert_eq!((st.show(&Value::Int(0xFFFF)), st.meaning(&Value::Int(0xFFFF))), ("n/a".into(), None));
    assert_eq!(st.show(&Value::Int(1)), "off");
    let float = point("f");
    let nan = float.decode(&[0x7FC0, 0x0000]).unwrap();
    assert!(!float.implemented(&nan) && float.implemented(&Value::Float(1.5)));
    let unscaled = point("w");
    assert_eq!((unscaled.show(&Value::Int(5)), unscaled.engineering(&Value::Int(5))), ("n/a".into(), None));
    let wide = point("e");
    assert_eq!(wide.show(&wide.decode(&[0xFFFF; 4]).unwrap()), "n/a");
    assert_eq!(wide.show(&wide.decode(&[0xFFFF, 0xFFFF, 0xFFFF, 0xFFFE]).unwrap()), "18446744073709551614");
    let wrong = format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nnot_implemented=70000\n");
    assert!(error(&wrong).contains("not_implemented = 70000 is not a u16 value"), "{}", error(&wrong));
}
