//! The profile reader's tests: built-ins load, mistakes are named with file, line and field.

use super::*;

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
        "no profile named \"omron-3g3xx\": the built-in ones are omron-3g3rx, sdp-servo, generic, or give a path to a .toml file"
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
        "in mine.toml, line 6 (colour = 'red'): unknown field `colour`, expected one of `name`, `vendor`, \
         `product_code`, `revision`, `vendor_url`, `product_name`, `model_name`, `user_application_name`, \
         `identification`, `server_id`"
    );
    let wrong_type = error(&format!("{DEVICE}[[registers]]\nnumber = 'one'\nname = 'r'\n"));
    assert!(wrong_type.starts_with("in mine.toml, line 7 (number = 'one'): invalid type: string"), "{wrong_type}");
    let old = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nsize=2\n"));
    assert!(old.starts_with("in mine.toml, line 9 (size=2): unknown field `size`"), "{old}");
    assert!(old.ends_with("(size, signed and word_order are now type and order: type = \"u32\" or \"i32\", order = \"ABCD\" for high-first or \"CDAB\" for low-first)"), "{old}");
    let bad_type = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='u24'\n"));
    assert!(bad_type.starts_with("in mine.toml, line 9 (type='u24'): unknown variant `u24`"), "{bad_type}");
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='string'\n")),
        "in mine.toml, line 6: [[registers]] 1 (r): a string needs length = its registers (1 or more)"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nvalues={{ 'x' = 'on' }}\n")),
        "in mine.toml, line 9: [[registers]] 1 (r): values key \"x\" is not a raw u16 value"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ndepends_on=['A004']\n")),
        "in mine.toml, line 9: [[registers]] 1 (r): depends_on names \"A004\", which the profile does not have"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[span]]\ntable='holding'\nfirst=9\nlast=3\n")),
        "in mine.toml, line 6: [[span]] holding: first = 9 is above last = 3"
    );
    assert_eq!(
        error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nmin=5\nmax=4\n")),
        "in mine.toml, line 10: [[registers]] 1 (r): min = 5 is above max = 4"
    );
}

#[test]
fn an_order_is_one_of_the_four_names_and_defaults_to_the_devices() {
    let pair = |order: &str| {
        format!("[addressing]\norder='CDAB'\n{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='u32'\n{order}")
    };
    let default = Profile::parse(&pair(""), "mine.toml").unwrap();
    assert_eq!(default.points()[0].order, Order::Cdab);
    let own = Profile::parse(&pair("order='BADC'\n"), "mine.toml").unwrap();
    assert_eq!(own.points()[0].order, Order::Badc);
    let wrong = error(&pair("order='cdab'\n"));
    assert!(wrong.starts_with("in mine.toml, line 12 (order='cdab'): unknown variant `cdab`"), "{wrong}");
    let single = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\norder='CDAB'\n"));
    assert_eq!(
        single,
        "in mine.toml, line 9: [[registers]] 1 (r): order is for values of more than one register, not u16"
    );
}

#[test]
fn overlapping_registers_are_refused_naming_both_and_their_lines() {
    let text = format!(
        "{DEVICE}[[registers]]\nnumber=10\nname='a'\ncount=4\n\n[[registers]]\nnumber=20\nname='b'\n\n\
         [[registers]]\nnumber=12\nname='c'\ntype='u32'\n"
    );
    assert_eq!(error(&text), "in mine.toml, line 15: [[registers]] 12 (c) overlaps 10 (a) on line 6");
    let duplicate = format!("{DEVICE}[[coils]]\nnumber=3\nname='a'\n[[coils]]\nnumber=3\nname='b'\n");
    assert_eq!(error(&duplicate), "in mine.toml, line 9: [[coils]] 3 (b) is at the same number as 3 (a) on line 6");
    // A 32-bit pair takes two numbers; the next one may follow it.
    let pairs = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\ntype='i32'\n[[inputs]]\nnumber=3\nname='b'\n");
    assert!(Profile::parse(&pairs, "mine.toml").is_ok());
    let clash = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\ntype='f32'\n[[inputs]]\nnumber=2\nname='b'\n");
    assert_eq!(error(&clash), "in mine.toml, line 10: [[inputs]] 2 (b) overlaps 1 (a) on line 6");
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
