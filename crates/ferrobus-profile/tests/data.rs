//! A profile is data as well as a file: built with [`Profile::new`] and the entries'
//! constructors, checked with [`Profile::build`] by the one reader of profiles, and written
//! with [`Profile::to_toml`] as a file that reads back to the same profile.

use ferrobus_profile::{Access, BUILTIN, BitDef, DeviceSection, Profile, ProfileError, RegisterDef, Table, ValueType};

/// Everything a profile is, but where it came from: its sections and its resolved points.
fn shape(profile: &Profile) -> String {
    let mut profile = profile.clone();
    profile.origin.clear();
    profile.faults_place = None;
    profile.fault_rule_places.clear();
    format!("{profile:?}\n{:?}", profile.points())
}

#[test]
fn every_built_in_profile_written_with_to_toml_reads_back_to_the_same_profile() {
    for (name, _) in BUILTIN {
        let profile = Profile::builtin(name).unwrap();
        let text = profile.to_toml();
        let again = Profile::parse(&text, name).unwrap_or_else(|e| panic!("{name}: {e}\n{text}"));
        assert_eq!(shape(&again), shape(&profile), "{name}:\n{text}");
        assert_eq!(again.to_toml(), text, "{name}: writing is stable");
    }
}

#[test]
fn a_profile_built_as_data_is_checked_resolved_and_written_as_a_file_would_be() {
    let mut profile = Profile::new(DeviceSection::new("A meter", "ACME", "M1", "1.0"));
    profile.limits.read_registers = Some(4);
    let mut power = RegisterDef::new(0x10, "power", ValueType::F32);
    power.unit = Some("W".into());
    power.label = Some("active power".into());
    let mut mode = RegisterDef::new(0x20, "mode", ValueType::U16);
    mode.access = Access::Rw;
    mode.values = [("0".to_string(), "off".to_string()), ("1".to_string(), "on".to_string())].into();
    profile.inputs.push(power);
    profile.registers.push(mode);
    profile.coils.push(BitDef::new(1, "relay"));
    let built = profile.build("a meter of mine").unwrap();
    let codes: Vec<(&str, Table)> = built.points().iter().map(|p| (p.code.as_str(), p.table)).collect();
    assert_eq!(codes, [("relay", Table::Coils), ("mode", Table::Holding), ("power", Table::Input)]);
    assert_eq!(built.point("power").unwrap().unit.as_deref(), Some("W"));
    assert_eq!(built.origin, "a meter of mine");
    let text = built.to_toml();
    assert!(text.contains("[[inputs]]") && text.contains("read_registers = 4"), "{text}");
    assert!(!text.contains("confirmed") && !text.contains("while_running"), "defaults are left out:\n{text}");
    assert_eq!(shape(&Profile::parse(&text, "a meter of mine").unwrap()), shape(&built));
}

#[test]
fn a_profile_built_wrong_gets_every_mistake_a_file_would() {
    let mut profile = Profile::new(DeviceSection::new("Two mistakes", "ACME", "M2", "1.0"));
    profile.registers.push(RegisterDef::new(0x10, "a", ValueType::U32));
    profile.registers.push(RegisterDef::new(0x11, "b", ValueType::U16));
    let mut bad = RegisterDef::new(0x30, "c\u{1b}[2J", ValueType::U16);
    bad.min = Some(10.0);
    bad.max = Some(5.0);
    profile.registers.push(bad);
    let mistakes = profile.build("built").unwrap_err();
    let text: Vec<String> = mistakes.iter().map(ProfileError::to_string).collect();
    assert_eq!(mistakes.len(), 3, "{text:#?}");
    assert!(text[0].contains("(b) overlaps 16 (a)"), "{text:#?}");
    assert!(text[1].contains("control character \\u{1b}"), "{text:#?}");
    assert!(text.iter().all(|m| !m.contains('\u{1b}')), "escaped: {text:#?}");
}
