//! The built-in profiles say what the drives' manuals say: register numbers, ranges, units,
//! scaling, word order, enumerations, limits and exception meanings from the Omron 3G3RX-V1
//! (I578) and Hitachi SJ700-2 tables and the Shihlin SDP manual's example, and the profiles
//! are consistent: no two entries share an address, every 32-bit pair is in the drive's
//! order, every dependency names an entry, every point has a code of its own.

use std::collections::{BTreeMap, BTreeSet};

use ferrobus_profile::{Access, BUILTIN, ModelSection, Order, Point, Polarity, Profile, Table, Value, ValueType};

fn rx() -> Profile {
    Profile::load("omron-3g3rx").expect("the built-in 3G3RX profile loads")
}

fn sdp() -> Profile {
    Profile::load("sdp-servo").expect("the built-in SDP profile loads")
}

fn point<'a>(profile: &'a Profile, code: &str) -> &'a Point {
    profile.point(code).unwrap_or_else(|| panic!("{code} is in {}", profile.device.name))
}

/// A point's table, manual number, wire address, type, order, min, max and unit.
type Shape<'a> = (Table, u32, u16, ValueType, Order, Option<f64>, Option<f64>, Option<&'a str>);

/// The [`Shape`] of `p`.
fn shape(p: &Point) -> Shape<'_> {
    (p.table, p.number, p.address, p.value_type, p.order, p.min, p.max, p.unit.as_deref())
}

#[test]
fn the_3g3rx_limits_numbering_and_order_are_the_manuals() {
    let rx = rx();
    // 3G3RX-V1 8-4 / SJ700 4-130: 4 registers and 32 coils per message.
    assert_eq!((rx.read_limit(Table::Holding), rx.write_limit(Table::Holding)), (4, 4));
    assert_eq!((rx.read_limit(Table::Coils), rx.write_limit(Table::Coils)), (32, 32));
    // Registers and coils numbered from 1, the frame carrying number - 1; HIGH word first.
    assert_eq!(rx.addressing.base, 1);
    assert_eq!(rx.order(), Order::Abcd);
    assert_eq!(rx.comm.functions.as_deref(), Some(&[0x01, 0x03, 0x05, 0x06, 0x08, 0x0F, 0x10][..]));
}

#[test]
fn f001_and_the_status_registers_are_at_the_3g3rx_v1_numbers() {
    let rx = rx();
    // 8-5-2: 0001h F001 (HIGH), 0002h F001 (LOW), 0 to 40000, 0.01 Hz.
    let f001 = point(&rx, "F001");
    assert_eq!(
        shape(f001),
        (Table::Holding, 0x0001, 0x0000, ValueType::U32, Order::Abcd, Some(0.0), Some(40000.0), Some("Hz"))
    );
    assert_eq!(f001.access, Access::Rw);
    assert_eq!(f001.decode(&[0x0000, 5000]).map(|v| f001.show(&v)), Ok("50.00 Hz".to_string()));
    assert!(f001.prepare_write("400.01Hz").is_err(), "F001 above 400.00 Hz is refused before sending");
    // Status A: 8 = trip, 9 = during UV; status B: 1 = run.
    let a = point(&rx, "status-a");
    assert_eq!((a.number, a.access), (0x0003, Access::Ro));
    assert_eq!(a.show(&Value::Int(8)), "trip");
    assert_eq!(a.show(&Value::Int(3)), "run");
    assert_eq!(point(&rx, "status-b").show(&Value::Int(1)), "run");
    // 0005h is not in the tables read: the drive's map has a hole there.
    assert!(rx.points().iter().all(|p| !(p.table == Table::Holding && p.address == 0x0004)));
}

#[test]
fn the_d_monitors_have_the_sj700_numbers_scaling_and_meanings() {
    let rx = rx();
    // SJ700-2 B-36.
    let d001 = point(&rx, "d001");
    assert_eq!(
        shape(d001),
        (Table::Holding, 0x1001, 0x1000, ValueType::U32, Order::Abcd, Some(0.0), Some(40000.0), Some("Hz"))
    );
    assert!((d001.scale - 0.01).abs() < 1e-12, "d001 is in 0.01 Hz");
    assert_eq!(d001.access, Access::Ro);
    let d002 = point(&rx, "d002");
    assert_eq!((d002.number, d002.unit.as_deref(), d002.max), (0x1003, Some("A"), Some(9999.0)));
    assert_eq!(d002.show(&Value::Int(1234)), "12.34 A");
    let d003 = point(&rx, "d003");
    assert_eq!((d003.number, d003.show(&Value::Int(2))), (0x1004, "reverse".to_string()));
    // d005: bit 0 = terminal [1] ... bit 7 = [8].
    let d005 = point(&rx, "d005");
    assert_eq!(d005.number, 0x1007);
    assert_eq!(d005.show(&Value::Int(0b1000_0001)), "terminal [1], terminal [8]");
    // d008 is signed: -40000 to +40000 (0.01 Hz).
    let d008 = point(&rx, "d008");
    assert_eq!(
        shape(d008),
        (Table::Holding, 0x100B, 0x100A, ValueType::I32, Order::Abcd, Some(-40000.0), Some(40000.0), Some("Hz"))
    );
    assert_eq!(d008.decode(&[0xFFFF, 0xFC18]).map(|v| d008.show(&v)), Ok("-10.00 Hz".to_string()));
    assert_eq!(point(&rx, "d013").number, 0x1011);
    // 100Fh is reserved.
    assert!(rx.points().iter().all(|p| p.number != 0x100F || p.table != Table::Holding));
}

#[test]
fn f002_and_a003_match_the_manuals_example_frames() {
    let rx = rx();
    // I560 p.4-173: F002 = 3000.00 s is 300000 = 0x000493E0 to 1103h/1104h, high word first.
    let f002 = point(&rx, "F002");
    assert_eq!((f002.number, f002.address, f002.unit.as_deref()), (0x1103, 0x1102, Some("s")));
    let raw = f002.prepare_write("3000s").expect("3000 s is within F002's range");
    assert_eq!(f002.encode(&raw), Ok(vec![0x0004, 0x93E0]));
    // 3G3RX-V1 p.8-14: "the holding register 1203 hex for the 1st Base Frequency (A003) has a
    // data resolution of 1 Hz"; the FC06 example writes 50 (0032h) to register address 1202h.
    let a003 = point(&rx, "A003");
    assert_eq!((a003.number, a003.address, a003.value_type), (0x1203, 0x1202, ValueType::U16));
    assert_eq!(a003.prepare_write("50Hz").and_then(|v| a003.encode(&v)), Ok(vec![0x0032]));
    assert!(!a003.while_running, "the base frequency cannot be changed while running");
    assert!(a003.prepare_write("29").is_err(), "below 30 Hz");
}

#[test]
fn the_a_b_c_and_h_groups_have_the_sj700_2_numbers_and_ranges() {
    let rx = rx();
    let at = |code: &str| {
        let p = point(&rx, code);
        (p.number, p.value_type, p.min, p.max)
    };
    // B-44, B-48, B-52 (A group).
    assert_eq!(at("A011"), (0x120B, ValueType::U32, Some(0.0), Some(40000.0)));
    assert_eq!(at("A020"), (0x1216, ValueType::U32, Some(0.0), Some(40000.0)));
    assert_eq!(at("A220"), (0x2216, ValueType::U32, Some(0.0), Some(40000.0)));
    assert_eq!(at("A320"), (0x3216, ValueType::U32, Some(0.0), Some(40000.0)));
    assert_eq!(at("A062"), (0x1251, ValueType::U32, Some(0.0), Some(40000.0)));
    assert_eq!(at("A070"), (0x125E, ValueType::U16, Some(0.0), Some(600.0)));
    assert_eq!(at("A153"), (0x12BC, ValueType::U16, Some(0.0), Some(50.0)));
    assert_eq!(point(&rx, "A146").show(&Value::Int(1)), "minus");
    // B-52 (b group): b002 is 0.3-25.0 s in 0.1 s.
    assert_eq!(at("b002"), (0x1302, ValueType::U16, Some(3.0), Some(250.0)));
    assert_eq!(point(&rx, "b002").show(&Value::Int(250)), "25.0 s");
    // B-60 (C group): terminal functions from 1401h, active states from 140Bh.
    assert_eq!(point(&rx, "C008").number, 0x1408);
    assert_eq!(point(&rx, "C019").number, 0x1413);
    assert_eq!(point(&rx, "C011").show(&Value::Int(1)), "normally closed");
    assert_eq!(at("C029"), (0x141D, ValueType::U16, Some(0.0), Some(12.0)));
    // B-66 (H group).
    assert_eq!(point(&rx, "H004").show(&Value::Int(1)), "4 poles");
    // H003: the capacity codes of the 3G3RX (I560) p.4-158 table.
    assert_eq!(point(&rx, "H003").show(&Value::Int(13)), "11 kW");
    assert_eq!(point(&rx, "H003").number, 0x1503);
    assert_eq!(at("H005"), (0x1505, ValueType::U32, Some(0.0), Some(80000.0)));
    assert_eq!(at("H020"), (0x1515, ValueType::U32, Some(1.0), Some(65530.0)));
    assert_eq!(point(&rx, "H306").number, 0x3507);
    // Reserved in the tables: no entry there.
    for reserved in [0x1207, 0x120A, 0x1214, 0x12B6, 0x12BD, 0x1409, 0x140A, 0x1414, 0x1508, 0x1514, 0x2508] {
        assert!(
            rx.points()
                .iter()
                .all(|p| p.table != Table::Holding
                    || !(p.number <= reserved && reserved < p.number + u32::from(p.width))),
            "{reserved:#06x} is reserved"
        );
    }
}

#[test]
fn the_3g3rx_groups_select_what_the_manual_groups() {
    let rx = rx();
    for group in ["monitor", "F", "A", "b", "C", "H", "trip", "status", "command"] {
        assert!(!rx.group(group).is_empty(), "group {group}");
    }
    assert!(rx.group("monitor").iter().all(|p| p.code.starts_with('d') && p.access == Access::Ro));
    assert!(rx.group("A").iter().all(|p| p.code.starts_with('A')));
    assert_eq!(rx.find("d00*").len(), 9, "d001 to d009");
}

#[test]
fn the_3g3rx_coils_are_the_sj700_2_list_and_commands_are_not_backed_up() {
    let rx = rx();
    let coil = |code: &str| {
        let p = point(&rx, code);
        assert_eq!(p.table, Table::Coils, "{code} is a coil");
        (p.number, p.access, p.backup)
    };
    // B-33: 0001h operation command ... 0017h OD; 0005h, 0006h and 0012h reserved.
    assert_eq!(coil("run"), (0x0001, Access::Rw, false));
    assert_eq!(coil("trip-reset"), (0x0004, Access::Rw, false));
    assert_eq!(coil("input1"), (0x0007, Access::Rw, false));
    assert_eq!(coil("input8"), (0x000E, Access::Rw, false));
    assert_eq!(coil("running").0, 0x000F);
    assert_eq!(coil("ready").0, 0x0011);
    assert_eq!(coil("pid-deviation"), (0x0017, Access::Ro, false));
    let numbers: BTreeSet<u32> = rx.points().iter().filter(|p| p.table == Table::Coils).map(|p| p.number).collect();
    assert!(numbers.is_disjoint(&BTreeSet::from([0x0000, 0x0005, 0x0006, 0x0012])));
    // The run state a client checks before writing a run-locked parameter: coil 000Fh = 1.
    let running = rx.state.running.as_ref().expect("the 3G3RX says how it shows that it runs");
    assert_eq!(point(&rx, &running.point).number, 0x000F);
}

#[test]
fn the_3g3rx_explains_its_exceptions_in_the_manuals_words() {
    let rx = rx();
    assert_eq!(rx.exception_meaning(0x21), Some("data to be written to a register is outside the inverter's range"));
    assert!(rx.exception_meaning(0x22).is_some_and(|m| m.contains("cannot be changed while running")));
    assert!(rx.exception_meaning(0x02).is_some_and(|m| m.contains("address")));
    assert_eq!(rx.exceptions.out_of_range, 0x21);
}

#[test]
fn the_sdp_limit_and_the_manuals_fc10_example_are_kept() {
    let sdp = sdp();
    // p.413: "The maximum allowable data in one single access is 10"; p.405: 03, 04, 06, 10.
    assert_eq!((sdp.read_limit(Table::Holding), sdp.write_limit(Table::Holding)), (10, 10));
    assert_eq!(sdp.comm.functions.as_deref(), Some(&[0x03, 0x04, 0x06, 0x10][..]));
    // 0BB8H to 0112H and 0000H to 0113H: 3000 with the low word first.
    let speed = point(&sdp, "speed-command");
    assert_eq!((speed.address, speed.order), (0x0112, Order::Cdab));
    assert_eq!(speed.encode(&Value::Int(3000)), Ok(vec![0x0BB8, 0x0000]));
    // The SDE sibling's words (p.180).
    assert_eq!(sdp.exception_meaning(0x02), Some("parameter address error"));
    // What the manual does not give is marked as such.
    assert!(sdp.points().iter().all(|p| !p.confirmed));
}

#[test]
fn no_two_entries_of_a_builtin_profile_share_an_address() {
    for (name, _) in BUILTIN {
        let profile = Profile::load(name).expect("a built-in profile loads");
        let mut owner: BTreeMap<(Table, u32), &str> = BTreeMap::new();
        for p in profile.points() {
            for a in u32::from(p.address)..u32::from(p.address) + u32::from(p.width) {
                if let Some(other) = owner.insert((p.table, a), &p.code) {
                    panic!("{name}: {} and {other} share {a:#06x} in {:?}", p.code, p.table);
                }
            }
        }
    }
}

#[test]
fn every_32_bit_pair_of_the_3g3rx_is_high_word_first() {
    let rx = rx();
    let wide: Vec<&Point> = rx.points().iter().filter(|p| p.width == 2).collect();
    assert!(wide.len() >= 20, "the 3G3RX has its 32-bit parameters and monitors ({})", wide.len());
    for p in wide {
        assert_eq!(p.order, Order::Abcd, "{}", p.code);
        assert!(matches!(p.value_type, ValueType::U32 | ValueType::I32), "{}", p.code);
        assert_eq!(p.encode(&Value::Int(0x0001_0002)), Ok(vec![0x0001, 0x0002]), "{}", p.code);
    }
}

#[test]
fn every_dependency_and_run_state_point_of_a_builtin_profile_exists() {
    for (name, _) in BUILTIN {
        let profile = Profile::load(name).expect("a built-in profile loads");
        for p in profile.points() {
            for dep in &p.depends_on {
                assert!(profile.point(dep).is_some(), "{name}: {} depends on {dep}, which is not there", p.code);
            }
        }
        if let Some(rule) = &profile.state.running {
            assert!(profile.point(&rule.point).is_some(), "{name}: [state] running names {}", rule.point);
        }
    }
}

#[test]
fn every_3g3rx_entry_names_its_source_and_labels_are_unique() {
    let rx = rx();
    let mut labels = BTreeSet::new();
    for p in rx.points() {
        assert!(p.source.as_deref().is_some_and(|s| !s.is_empty()), "{} has a source", p.code);
        assert!(!p.label.is_empty(), "{} has a label", p.code);
        // A run of coils shares its label; every other label names one entry.
        if !p.code.starts_with("input") {
            assert!(labels.insert(p.label.to_lowercase()), "label {:?} of {} is not unique", p.label, p.code);
        }
    }
    // The facts that could not be confirmed for the 3G3RX say so.
    for code in ["F003", "A001", "A002", "trip-count", "d102"] {
        assert!(!point(&rx, code).confirmed, "{code} is marked unconfirmed");
    }
    assert!(point(&rx, "d001").confirmed && point(&rx, "A003").confirmed);
}

#[test]
fn the_trip_monitor_and_direction_coil_are_as_the_3g3rx_manuals_show() {
    let rx = rx();
    // I560 p.4-169: reading 0012h-0013h gives 0007h, overvoltage (E07), and 0002h.
    let factor = point(&rx, "trip1-factor");
    assert_eq!((factor.number, factor.address), (0x0012, 0x0011));
    assert_eq!(factor.show(&Value::Int(7)), "E07 overvoltage");
    assert_eq!(point(&rx, "trip1-status").number, 0x0013);
    // 3G3RX-V1 8-5-1: coil 0002h, 1 = reverse, 0 = forward; the simulator's polarity agrees.
    assert_eq!(point(&rx, "direction").number, 0x0002);
    assert!(matches!(rx.model, Some(ModelSection::Inverter { direction: Polarity::OneIsReverse, .. })));
}

#[test]
fn every_start_value_of_a_builtin_profile_is_within_its_range() {
    // A backup of a fresh simulated drive must restore: no register starts out of range.
    for (name, _) in BUILTIN {
        let profile = Profile::load(name).expect("a built-in profile loads");
        for p in profile.points() {
            let Some(x) = p.default.as_f64() else { continue };
            assert!(p.min.is_none_or(|m| x >= m) && p.max.is_none_or(|m| x <= m), "{name}: {} starts at {x}", p.code);
        }
    }
}

#[test]
fn every_point_of_every_built_in_profile_has_a_code_of_its_own() {
    for (name, _) in BUILTIN {
        let profile = Profile::load(name).unwrap();
        let mut seen = BTreeSet::new();
        let twice: Vec<&str> =
            profile.points().iter().map(|p| p.code.as_str()).filter(|code| !seen.insert(*code)).collect();
        assert!(twice.is_empty(), "{name}: codes given to more than one point: {twice:?}");
    }
}
