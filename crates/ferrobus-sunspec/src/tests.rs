use super::*;

/// A small model of our own: a header, a scaled value, its scale factor, a string, an
/// enumeration, a pad, and a repeating group that fills the length.
const TOY: &str = r#"{"id": 64900, "group": {"name": "toy", "points": [
    {"name": "ID", "type": "uint16", "size": 1, "value": 64900},
    {"name": "L", "type": "uint16", "size": 1},
    {"name": "W", "type": "int16", "size": 1, "sf": "W_SF", "units": "W", "label": "Power"},
    {"name": "W_SF", "type": "sunssf", "size": 1},
    {"name": "Nm", "type": "string", "size": 4},
    {"name": "St", "type": "enum16", "size": 1, "access": "RW",
     "symbols": [{"name": "OFF", "value": 1}, {"name": "ON", "value": 2}]},
    {"name": "Pad", "type": "pad", "size": 1},
    {"name": "WH", "type": "acc32", "size": 2, "sf": 3}
  ],
  "groups": [{"name": "ch", "count": 0, "points": [
    {"name": "V", "type": "uint16", "size": 1, "sf": "W_SF"},
    {"name": "Evt", "type": "bitfield16", "size": 1, "symbols": [{"name": "HOT", "value": 0}, {"name": "COLD", "value": 3}]}
  ]}]}}"#;

fn toy() -> ModelDef {
    ModelDef::parse(TOY, "toy.json").unwrap()
}

#[test]
fn a_model_file_reads_into_points_with_types_sizes_scale_factors_and_symbols() {
    let m = toy();
    assert_eq!(m.id, 64900);
    assert_eq!(m.name(), "toy");
    assert_eq!(m.fixed_length(), 10, "W, W_SF, Nm (4), St, Pad, WH (2)");
    let w = &m.group.points[2];
    assert_eq!(
        (w.kind, w.size, w.sf.clone(), w.units.as_deref()),
        (PointType::Int16, 1, Some(ScaleFactor::Point("W_SF".into())), Some("W"))
    );
    let st = &m.group.points[5];
    assert!(st.writable);
    assert_eq!(st.symbols, vec![(1, "OFF".to_string()), (2, "ON".to_string())]);
    assert_eq!(m.group.points[7].sf, Some(ScaleFactor::Fixed(3)));
    assert_eq!(m.group.groups[0].count, Count::Fill);
}

#[test]
fn an_unknown_point_type_is_refused_naming_the_model_and_the_point() {
    let text = TOY.replace(r#""type": "acc32""#, r#""type": "acc128""#);
    let err = ModelDef::parse(&text, "toy.json").unwrap_err().to_string();
    assert!(
        err.starts_with("toy.json: model 64900, group toy, point WH: type \"acc128\" is not a SunSpec point type"),
        "{err}"
    );
}

#[test]
fn a_size_that_does_not_fit_the_type_or_a_missing_scale_factor_is_refused() {
    let text = TOY.replace(r#""type": "acc32", "size": 2"#, r#""type": "acc32", "size": 1"#);
    let err = ModelDef::parse(&text, "t").unwrap_err().to_string();
    assert!(err.contains("point WH: size 1 does not fit type acc32 (2 registers)"), "{err}");
    let text = TOY.replace(r#""sf": "W_SF", "units""#, r#""sf": "X_SF", "units""#);
    let err = ModelDef::parse(&text, "t").unwrap_err().to_string();
    assert!(err.contains("point W: sf names X_SF, which the model does not have"), "{err}");
    let err = ModelDef::parse("{\"id\": 1}", "one.json").unwrap_err().to_string();
    assert!(err.starts_with("one.json: not a SunSpec model file: missing field `group`"), "{err}");
}

#[test]
fn a_model_without_its_id_and_length_header_is_refused() {
    let text = TOY.replace(r#"{"name": "L", "type": "uint16", "size": 1},"#, "");
    let err = ModelDef::parse(&text, "t").unwrap_err().to_string();
    assert!(err.contains("the first two points must be ID and L"), "{err}");
}

#[test]
fn every_built_in_definition_reads_and_names_its_model() {
    let defs = Definitions::builtin();
    if defs.is_empty() {
        // Built without pysunspec2: say so rather than pass in silence.
        eprintln!("{NONE_BUILT_IN} ({})", Definitions::built_from());
        assert!(std::env::var("CI").is_err(), "CI builds embed pysunspec2's models: .ci/setup-peers.sh installs it");
        return;
    }
    let common = defs.get(1).expect("model 1");
    assert_eq!(common.name(), "common");
    assert_eq!(common.fixed_length(), 66, "SunSpec's common model is 66 registers after its header");
    assert_eq!(defs.get(103).map(ModelDef::name), Some("inverter_three_phase"));
    assert_eq!(defs.get(103).map(ModelDef::fixed_length), Some(50));
    assert!(defs.len() >= 100, "{}", defs.len());
}

#[test]
fn a_filling_group_repeats_to_the_length_and_names_its_instances() {
    let m = toy();
    let l = layout(&m, 14, &[]);
    assert!(l.complete && l.mismatch.is_none(), "{l:?}");
    let names: Vec<(&str, u32)> = l.points.iter().map(|p| (p.name.as_str(), p.offset)).collect();
    assert_eq!(&names[..3], &[("ID", 0), ("L", 1), ("W", 2)]);
    assert_eq!(&names[names.len() - 4..], &[("ch1.V", 12), ("ch1.Evt", 13), ("ch2.V", 14), ("ch2.Evt", 15)]);
    assert_eq!(l.points[2].sf, Some(SfAt::Offset(3)));
    assert_eq!(l.points[names.len() - 2].sf, Some(SfAt::Offset(3)), "a group's point finds the enclosing group's sf");
    assert_eq!(l.end, 16);
}

#[test]
fn a_length_that_is_no_whole_number_of_groups_is_a_mismatch_saying_what_was_seen() {
    let m = toy();
    let l = layout(&m, 13, &[]);
    assert_eq!(
        l.mismatch.as_deref(),
        Some("3 registers are left for the repeating group ch, not a whole number of its 2")
    );
    let l = layout(&m, 8, &[]);
    assert!(l.mismatch.is_some(), "{l:?}");
}

#[test]
fn a_group_counted_by_a_point_waits_for_that_point_and_then_repeats_its_value() {
    let text = TOY
        .replace(r#"{"name": "Pad", "type": "pad", "size": 1}"#, r#"{"name": "N", "type": "count", "size": 1}"#)
        .replace(r#""count": 0"#, r#""count": "N""#);
    let m = ModelDef::parse(&text, "t").unwrap();
    let header = [64900, 16];
    let unread = layout(&m, 16, &header);
    assert!(!unread.complete);
    assert_eq!(unread.points.len(), 8, "the fixed points are placed");
    let mut data = vec![0u16; 12];
    data[9] = 3;
    let read = layout(&m, 16, &data);
    assert!(read.complete && read.mismatch.is_none(), "{read:?}");
    assert_eq!(read.points.last().map(|p| p.name.as_str()), Some("ch3.Evt"));
}

fn found(defs: &Definitions, start: u16, registers: Vec<u16>) -> Found {
    let id = registers[0];
    let length = registers[1];
    let def = defs.get(id);
    Found { id, length, start, name: def.map(|d| d.name().to_string()), fits: def.map(|_| Ok(())), registers }
}

#[test]
fn the_profile_names_points_by_model_and_applies_the_scale_factors_read() {
    let mut defs = Definitions::default();
    defs.insert(toy());
    // W = 1234 with W_SF = -1 → 123.4 W; "ab" in Nm; St = 2 (ON); WH = 5 × 10^3; ch1.V = 2300.
    let regs = vec![64900, 14, 1234, 0xFFFF, 0x6162, 0, 0, 0, 2, 0, 0, 5, 2300, 0b1001, 7, 0];
    let discovery = Discovery { base: 40000, models: vec![found(&defs, 40002, regs.clone())] };
    let p = profile(&discovery, &defs, "test device", 100).unwrap();
    let w = p.find("toy.W")[0];
    assert_eq!((w.address, w.scale, w.unit.as_deref(), w.group.as_deref()), (40004, 0.1, Some("W"), Some("toy")));
    let Ok(value) = w.decode(&regs[2..3]) else { panic!() };
    assert_eq!(w.show(&value), "123.4 W");
    let st = p.find("toy.St")[0];
    assert_eq!(st.access, ferrobus_profile::Access::Rw);
    assert_eq!(st.show(&st.decode(&regs[8..9]).unwrap()), "ON");
    assert!(p.find("toy.Pad").is_empty(), "pads are left out");
    let wh = p.find("toy.WH")[0];
    assert_eq!((wh.value_type, wh.scale), (ferrobus_profile::ValueType::U32, 1000.0));
    let evt = p.find("toy.ch1.Evt")[0];
    assert_eq!(evt.show(&evt.decode(&regs[13..14]).unwrap()), "HOT, COLD");
    assert_eq!(p.find("toy.ch2.V")[0].address, 40016);
    assert_eq!(p.find("toy.Nm")[0].width, 4);
    assert_eq!(p.read_limit(ferrobus_profile::Table::Holding), 100);
}

#[test]
fn a_model_whose_length_does_not_fit_or_that_is_unknown_gives_no_points() {
    let mut defs = Definitions::default();
    defs.insert(toy());
    let mut bad = found(&defs, 40002, vec![64900, 13, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
    bad.fits = Some(Err("x".into()));
    let unknown = found(&defs, 40017, vec![64999, 1, 0]);
    let p = profile(&Discovery { base: 40000, models: vec![bad, unknown] }, &defs, "d", 125).unwrap();
    assert!(p.points().is_empty());
}

#[test]
fn not_implemented_values_are_told_by_type() {
    assert!(not_implemented(PointType::Uint16, &[0xFFFF]));
    assert!(!not_implemented(PointType::Uint16, &[0xFFFE]));
    assert!(not_implemented(PointType::Int16, &[0x8000]));
    assert!(not_implemented(PointType::Int32, &[0x8000, 0]));
    assert!(!not_implemented(PointType::Int32, &[0x8000, 1]));
    assert!(not_implemented(PointType::Acc32, &[0, 0]));
    assert!(not_implemented(PointType::String, &[0, 0]));
}

#[test]
fn sunspec_not_implemented_values_and_a_not_implemented_scale_factor_show_as_not_implemented() {
    let mut defs = Definitions::default();
    defs.insert(toy());
    // W = 0x8000 (int16), Nm empty, St = 0xFFFF (enum16), WH = 0 (acc32), ch1.Evt = 0xFFFF.
    let regs = vec![64900, 14, 0x8000, 0xFFFF, 0, 0, 0, 0, 0xFFFF, 0, 0, 0, 2300, 0xFFFF, 7, 0];
    let p =
        profile(&Discovery { base: 40000, models: vec![found(&defs, 40002, regs.clone())] }, &defs, "d", 125).unwrap();
    let shown = |code: &str, at: usize| {
        let point = p.find(code)[0];
        let words = &regs[at..at + usize::from(point.width)];
        let raw = point.decode(words).unwrap();
        (point.show(&raw), point.number(&raw), point.engineering(&raw))
    };
    for (code, at) in [("toy.W", 2), ("toy.Nm", 4), ("toy.St", 8), ("toy.WH", 10), ("toy.ch1.Evt", 13)] {
        assert_eq!(shown(code, at), ("n/a".to_string(), String::new(), None), "{code}");
    }
    assert_eq!(shown("toy.ch1.V", 12).0, "230.0", "a value that is no sentinel is a reading");
    // W_SF itself not implemented: W and ch1.V, which it scales, are not either.
    let mut unscaled = regs.clone();
    unscaled[2] = 1234;
    unscaled[3] = 0x8000;
    let p = profile(&Discovery { base: 40000, models: vec![found(&defs, 40002, unscaled)] }, &defs, "d", 125).unwrap();
    for code in ["toy.W", "toy.ch1.V", "toy.ch2.V"] {
        let point = p.find(code)[0];
        assert!(!point.implemented, "{code}");
        assert_eq!(point.show(&ferrobus_profile::Value::Int(1234)), "n/a", "{code}");
    }
    assert!(p.find("toy.St")[0].implemented);
}

#[test]
fn not_implemented_registers_are_told_by_type_as_pysunspec2_tells_them() {
    assert!(not_implemented(PointType::Eui48, &[0, 0xFFFF, 0xFFFF, 0xFFFF]));
    assert!(!not_implemented(PointType::Eui48, &[0, 0, 0, 0]));
    assert!(not_implemented(PointType::Float32, &[0x7FC0, 0]));
    assert!(!not_implemented(PointType::Float32, &[0x3FC0, 0]));
    assert!(not_implemented(PointType::Uint64, &[0xFFFF; 4]));
    assert!(not_implemented(PointType::String, &[0x0041]), "a string whose first byte is NUL");
    assert!(!not_implemented(PointType::String, &[0x4100]));
    assert_eq!(not_implemented_value(PointType::Int16), Some(toml::Value::Integer(-32768)));
    assert_eq!(not_implemented_value(PointType::Pad), None);
}

#[test]
fn every_built_in_model_makes_a_profile_that_checks() {
    let defs = Definitions::builtin();
    let mut made = 0;
    for id in 0..=u16::MAX {
        let Some(def) = defs.get(id) else { continue };
        let Ok(length) = u16::try_from(def.fixed_length()) else { continue };
        let mut registers = vec![0u16; usize::from(length) + 2];
        registers[0] = id;
        registers[1] = length;
        let discovery = Discovery { base: 40000, models: vec![found(&defs, 40002, registers)] };
        if let Err(e) = profile(&discovery, &defs, "every model", 125) {
            panic!("model {id}: {e}");
        }
        made += 1;
    }
    assert!(made == defs.len(), "{made} of {}", defs.len());
}
