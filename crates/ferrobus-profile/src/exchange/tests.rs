use std::fmt::Write as _;

use proptest::prelude::*;

use super::{Format, ImportError, ImportOptions, Imported, export_csv, import};
use crate::model::{Access, Order, Table, ValueType};
use crate::{BUILTIN, Point, Profile};

fn imported(text: &str, format: Format, options: &ImportOptions) -> (Profile, Imported) {
    let imported = import(text, "test-map", format, options).unwrap_or_else(|e| panic!("import: {e}"));
    let profile = Profile::parse(&imported.toml, "imported").unwrap_or_else(|e| panic!("{e}\n{}", imported.toml));
    (profile, imported)
}

fn point<'a>(profile: &'a Profile, code: &str) -> &'a Point {
    profile.point(code).unwrap_or_else(|| {
        let codes: Vec<&str> = profile.points().iter().map(|p| p.code.as_str()).collect();
        panic!("no point {code}; the points are {codes:?}")
    })
}

/// Whether `imported.unmapped` lists `field` at a place starting with `place`, for a reason
/// containing `why`.
fn lists(imported: &Imported, place: &str, field: &str, why: &str) -> bool {
    imported.unmapped.iter().any(|u| u.place.starts_with(place) && u.field == field && u.why.contains(why))
}

/// What a CSV row carries of a point: everything but what only a profile file says
/// (while_running, depends_on, backup, source, confirmed).
fn carried(p: &Point) -> impl PartialEq + std::fmt::Debug + use<> {
    (
        (p.table, p.address, p.code.clone(), p.label.clone(), p.description.clone()),
        (p.value_type, p.width, if p.width > 1 && p.value_type != ValueType::String { Some(p.order) } else { None }),
        (p.scale, p.offset, p.unit.clone(), p.min, p.max, p.access, p.group.clone()),
        // An empty cell is no default: an empty text default reads back as none.
        (
            p.values.clone(),
            p.bits.clone(),
            p.factory_default.clone().filter(|d| *d != crate::Value::Text(String::new())),
        ),
    )
}

#[test]
fn every_builtin_profile_exports_to_csv_and_imports_back_to_the_same_points() {
    for (name, _) in BUILTIN {
        let profile = Profile::builtin(name).unwrap();
        let csv = export_csv(&profile);
        if profile.points().is_empty() {
            // `generic` is tables without named points: its CSV is the header alone.
            assert_eq!(csv.lines().count(), 1, "{name}");
            let err = import(&csv, name, Format::Csv, &ImportOptions::default()).unwrap_err();
            assert!(matches!(err, ImportError::Nothing { unmapped: 0, .. }), "{err}");
            continue;
        }
        let (back, imported) = imported(&csv, Format::Csv, &ImportOptions::default());
        // A profile may give two points of a table one code (sdp-servo's two runs named
        // `parameter`); the import keeps codes unique, and says so.
        let twice = |p: &Point| profile.points().iter().filter(|q| q.table == p.table && q.code == p.code).count() > 1;
        for u in &imported.unmapped {
            assert!(u.field == "name" && u.why.contains("written as"), "{name}: {u}");
        }
        assert_eq!(back.points().len(), profile.points().len(), "{name}");
        for (a, b) in profile.points().iter().zip(back.points()) {
            if twice(a) && a.code != b.code {
                assert!(b.code.starts_with(&a.code), "{name}: {} became {}", a.code, b.code);
                let b = Point { code: a.code.clone(), ..b.clone() };
                assert_eq!(carried(a), carried(&b), "{name}: {}", a.code);
            } else {
                assert_eq!(carried(a), carried(b), "{name}: {}", a.code);
            }
        }
        // And the profile written exports to the CSV it came from, but for those codes.
        if imported.unmapped.is_empty() {
            assert_eq!(export_csv(&back), csv, "{name}");
        }
    }
}

#[test]
fn a_vendor_csv_with_other_column_names_semicolons_and_register_numbers_from_1() {
    let text = "\u{feff}# the vendor's list\n\
        Register;Parameter;Data Type;Word Order;Factor;Unit;R/W;Modbus FC;Colour\n\
        1;Voltage L1;uint16;;0,1;V;R;04;red\n\
        2;Current;int32;word swapped;1/1000;A;R;04;\n\
        0x10;Setpoint;float;big-endian;;Hz;R/W;03;blue\n\
        \n\
        20h;Mode;u16;;;;RW;holding;\n\
        30;Flags;u16;little-endian;;;R;holding;\n\
        ;No address;u16;;;;;;\n\
        99999;Far;u16;;;;;;\n\
        40;Weird;quaternion;;;;;;\n\
        0;Zero;u16;;;;;;\n";
    let options = ImportOptions { base: Some(1), name: Some("meter".into()), ..ImportOptions::default() };
    let (profile, imported) = imported(text, Format::Csv, &options);
    assert_eq!(profile.device.name, "meter");
    let voltage = point(&profile, "Voltage_L1");
    assert_eq!((voltage.table, voltage.address, voltage.scale), (Table::Input, 0, 0.1));
    assert_eq!(
        (voltage.label.as_str(), voltage.unit.as_deref(), voltage.access),
        ("Voltage L1", Some("V"), Access::Ro)
    );
    let current = point(&profile, "Current");
    assert_eq!((current.value_type, current.order, current.address), (ValueType::I32, Order::Cdab, 1));
    assert!((current.scale - 0.001).abs() < 1e-12);
    let setpoint = point(&profile, "Setpoint");
    assert_eq!((setpoint.table, setpoint.address, setpoint.value_type), (Table::Holding, 15, ValueType::F32));
    assert_eq!((setpoint.order, setpoint.access), (Order::Abcd, Access::Rw));
    assert_eq!(point(&profile, "Mode").address, 0x1F);
    // A 16-bit value has no word order; little-endian is ambiguous and not guessed.
    assert!(lists(&imported, "line 8", "order", "ambiguous"), "{:?}", imported.unmapped);
    assert!(lists(&imported, "line 9", "address", "no address"));
    assert!(lists(&imported, "line 10", "address", "beyond the address space"));
    assert!(lists(&imported, "line 11", "type", "not a type"));
    assert!(lists(&imported, "line 12", "address", "of 1 or more"));
    assert_eq!(point(&profile, "Weird").value_type, ValueType::U16);
    assert!(lists(&imported, "header", "Colour", "2 rows"), "{:?}", imported.unmapped);
}

#[test]
fn csv_rows_at_the_same_address_are_one_point_or_listed_and_names_stay_unique() {
    let text = "name,table,address,type,access\n\
        speed,holding,10,u16,ro\n\
        speed_set,holding,10,u16,rw\n\
        speed,holding,11,u16,ro\n\
        wide,holding,20,u32,ro\n\
        inside,holding,21,u16,ro\n\
        bit,coils,5,,ro\n\
        sensor,input,7,,rw\n\
        Speed,input,8,,ro\n\
        wide,input,9,,ro\n";
    let (profile, imported) = imported(text, Format::Csv, &ImportOptions::default());
    // A code is the profile's one, in every table and whatever its case.
    assert_eq!((point(&profile, "Speed_3").table, point(&profile, "Speed_3").address), (Table::Input, 8));
    assert!(lists(&imported, "line 9", "name", "written as Speed_3"));
    assert_eq!(point(&profile, "wide_2").table, Table::Input);
    assert_eq!(point(&profile, "speed").access, Access::Rw, "read in one row, written in another: one rw point");
    assert!(lists(&imported, "line 3", "name", "one point, rw"));
    assert_eq!(point(&profile, "speed_2").address, 11);
    assert!(lists(&imported, "line 4", "name", "written as speed_2"));
    assert!(lists(&imported, "line 6", "address", "shares its address with wide"));
    assert!(profile.point("inside").is_none());
    assert_eq!(point(&profile, "bit").table, Table::Coils);
    assert_eq!(point(&profile, "sensor").access, Access::Ro);
    assert!(lists(&imported, "line 8", "access", "cannot be written"));
}

#[test]
fn a_cell_that_does_not_fit_its_type_costs_that_cell_and_not_the_file() {
    let text = "name,address,type,length,min,max,scale,values,bits,default\n\
        text,0,string,2,0,10,0.1,,,too long for two registers\n\
        small,2,u16,,-5,1.5,,70000=x; 1=one,16=high; 3=low,70000\n\
        upside,3,i16,,10,1,,,,\n\
        real,4,f32,,,,,1=one,0=bit,x\n\
        fine,6,u16,,0,100,,,,7\n";
    let (profile, imported) = imported(text, Format::Csv, &ImportOptions::default());
    let text_point = point(&profile, "text");
    assert_eq!((text_point.min, text_point.max, text_point.scale), (None, None, 1.0));
    assert!(lists(&imported, "line 2", "scale", "a string has no"));
    assert!(lists(&imported, "line 2", "default", "not a string value"));
    let small = point(&profile, "small");
    assert_eq!((small.min, small.max), (None, None), "-5 and 1.5 are no raw u16 values");
    assert_eq!(small.values, vec![(1, "one".to_string())]);
    assert_eq!(small.bits, vec![(3, "low".to_string())]);
    assert!(lists(&imported, "line 3", "values", "70000 is no raw u16 value"));
    assert!(lists(&imported, "line 3", "bits", "16 is no raw u16 value's bit"));
    assert!(lists(&imported, "line 3", "default", "not a value of a u16"));
    assert_eq!((point(&profile, "upside").min, point(&profile, "upside").max), (None, None));
    assert!(lists(&imported, "line 4", "min", "above max"));
    let real = point(&profile, "real");
    assert!(real.values.is_empty() && real.bits.is_empty());
    assert!(lists(&imported, "line 5", "values", "a f32 has no values"));
    let fine = point(&profile, "fine");
    assert_eq!(
        (fine.min, fine.max, fine.factory_default.clone()),
        (Some(0.0), Some(100.0), Some(crate::Value::Int(7)))
    );
}

const HA: &str = r"
homeassistant:
  name: Home
modbus:
  - name: hub
    type: tcp
    host: 10.0.0.2
    port: 502
    sensors:
      - name: Room temperature
        slave: 2
        address: 0x10
        input_type: input
        data_type: int16
        scale: 0.1
        precision: 1
        unit_of_measurement: °C
        device_class: temperature
      - name: Energy
        slave: 2
        address: 20
        data_type: uint32
        swap: word
        unit_of_measurement: kWh
      - name: Power
        slave: 2
        address: 22
        data_type: float32
        swap: word_byte
      - name: Old style
        slave: 2
        address: 30
        data_type: int
        count: 2
      - name: Half
        slave: 2
        address: 40
        data_type: float16
      - name: Swapped bytes
        slave: 2
        address: 41
        data_type: uint16
        swap: byte
      - name: Serial
        slave: 2
        address: 50
        data_type: string
        count: 5
    binary_sensors:
      - name: Alarm
        slave: 2
        address: 3
        input_type: discrete_input
    switches:
      - name: Pump
        slave: 2
        address: 100
        command_on: 5
        command_off: 6
        verify:
          address: 101
          input_type: input
          state_on: 1
          state_off: 0
      - name: Relay
        slave: 2
        address: 7
        write_type: coil
    climates:
      - name: Zone
        slave: 2
        address: 60
        target_temp_register: 61
        data_type: int16
        scale: 0.5
        min_temp: 5
        max_temp: 30
    covers:
      - name: Blind
        slave: 2
        address: 70
        status_register: 71
  - name: other
    type: serial
    port: /dev/ttyUSB0
    sensors:
      - name: Elsewhere
        slave: 9
        address: 1
";

#[test]
fn home_assistant_entities_become_points_and_the_rest_is_listed() {
    let err = import(HA, "ha.yaml", Format::HaYaml, &ImportOptions::default()).unwrap_err();
    assert!(matches!(&err, ImportError::SeveralUnits { units, .. } if units == "2, 9"), "{err}");
    let options = ImportOptions { unit: Some(2), ..ImportOptions::default() };
    let (profile, imported) = imported(HA, Format::HaYaml, &options);
    let room = point(&profile, "Room_temperature");
    assert_eq!((room.table, room.address, room.value_type, room.scale), (Table::Input, 16, ValueType::I16, 0.1));
    assert_eq!((room.unit.as_deref(), room.access), (Some("°C"), Access::Ro));
    assert_eq!((point(&profile, "Energy").value_type, point(&profile, "Energy").order), (ValueType::U32, Order::Cdab));
    assert_eq!(point(&profile, "Power").order, Order::Dcba);
    assert_eq!(point(&profile, "Old_style").value_type, ValueType::I32);
    assert!(profile.point("Half").is_none());
    assert!(lists(&imported, "modbus[0].sensors[4]", "data_type", "half-precision"));
    assert!(lists(&imported, "modbus[0].sensors[5]", "swap", "16-bit"));
    assert_eq!((point(&profile, "Serial").value_type, point(&profile, "Serial").width), (ValueType::String, 5));
    assert_eq!(point(&profile, "Alarm").table, Table::DiscreteInputs);
    let pump = point(&profile, "Pump");
    assert_eq!((pump.table, pump.access), (Table::Holding, Access::Rw));
    assert_eq!(pump.values, vec![(5, "on".to_string()), (6, "off".to_string())]);
    let state = point(&profile, "Pump_state");
    assert_eq!((state.table, state.address, state.access), (Table::Input, 101, Access::Ro));
    assert_eq!((point(&profile, "Relay").table, point(&profile, "Relay").access), (Table::Coils, Access::Rw));
    let target = point(&profile, "Zone_target");
    assert_eq!((target.address, target.access, target.scale), (61, Access::Rw, 0.5));
    assert_eq!((target.min, target.max), (Some(10.0), Some(60.0)), "5-30 °C at 0.5 °C a step, as raw values");
    assert_eq!(point(&profile, "Zone_current").unit.as_deref(), Some("°C"));
    assert_eq!(point(&profile, "Blind").values.len(), 4);
    assert_eq!(point(&profile, "Blind_status").access, Access::Ro);
    assert!(lists(&imported, "modbus[0]", "host", "connection setting"));
    assert!(lists(&imported, "modbus[0].sensors[0]", "precision", "shows or polls"));
    assert!(lists(&imported, "modbus[1].sensors[0]", "slave", "not of unit 2"));
    // Nothing of the source is lost without a line: the profile's points plus what is listed.
    assert!(imported.toml.contains("from test-map"));
}

#[test]
fn a_home_assistant_list_of_hubs_and_a_bare_hub_are_read_too() {
    let list = "- name: hub\n  type: tcp\n  host: h\n  port: 502\n  sensors:\n    - name: a\n      address: 1\n";
    let (profile, _) = imported(list, Format::HaYaml, &ImportOptions::default());
    assert_eq!(point(&profile, "a").table, Table::Holding);
    let hub = "switches:\n  - name: s\n    address: 2\n    write_type: coil\n";
    let (profile, _) = imported(hub, Format::HaYaml, &ImportOptions::default());
    assert_eq!(point(&profile, "s").table, Table::Coils);
}

const EVCC: &str = r"
site:
  title: Home
meters:
  - name: grid
    type: custom
    power:
      source: modbus
      uri: 10.0.0.3:502
      id: 1
      register: { address: 100, type: input, decode: int32s }
      scale: -1
    currents:
      - source: modbus
        uri: 10.0.0.3:502
        id: 1
        register: { address: 110, type: input, decode: float32 }
      - source: modbus
        uri: 10.0.0.3:502
        id: 1
        register: { address: 112, type: input, decode: float32nan }
    energy:
      source: calc
      add:
        - source: modbus
          id: 1
          register: { address: 120, type: holding, decode: uint64 }
        - source: modbus
          id: 1
          model: sunspec
          value: 160:1:DCWH
  - name: sdm
    type: custom
    power:
      source: modbus
      id: 2
      model: sdm
      value: Power
chargers:
  - name: box
    type: custom
    enable:
      source: modbus
      id: 1
      register: { address: 5, type: writecoil }
    enabled:
      source: modbus
      id: 1
      register: { address: 5, type: coil }
    maxcurrent:
      source: modbus
      id: 1
      register: { address: 200, type: writesingle, decode: uint16 }
    status:
      source: mqtt
      topic: box/status
";

#[test]
fn evcc_modbus_blocks_become_points_named_after_the_device_and_attribute() {
    let err = import(EVCC, "evcc.yaml", Format::EvccYaml, &ImportOptions::default()).unwrap_err();
    assert!(matches!(&err, ImportError::SeveralUnits { units, .. } if units == "1, 2"), "{err}");
    let options = ImportOptions { unit: Some(1), ..ImportOptions::default() };
    let (profile, imported) = imported(EVCC, Format::EvccYaml, &options);
    let power = point(&profile, "grid.power");
    assert_eq!(
        (power.table, power.address, power.value_type, power.order),
        (Table::Input, 100, ValueType::I32, Order::Cdab)
    );
    assert_eq!((power.scale, power.unit.as_deref()), (-1.0, Some("W")));
    assert_eq!(point(&profile, "grid.currents_1").unit.as_deref(), Some("A"));
    assert_eq!(point(&profile, "grid.currents_2").value_type, ValueType::F32);
    assert!(lists(&imported, "meters[0].currents[1].register", "decode", "no value"));
    assert_eq!(point(&profile, "grid.energy.add_1").value_type, ValueType::U64);
    assert!(lists(&imported, "meters[0].energy", "source", "arithmetic"));
    assert!(lists(&imported, "meters[0].energy.add[1]", "value", "SunSpec"));
    assert!(lists(&imported, "meters[1].power", "id", "not of unit 1"));
    let enable = point(&profile, "box.enable");
    assert_eq!((enable.table, enable.access), (Table::Coils, Access::Rw));
    assert!(lists(&imported, "chargers[0].enabled", "name", "one point, rw"));
    assert_eq!(point(&profile, "box.maxcurrent").access, Access::Rw);
    assert!(lists(&imported, "chargers[0].status", "source", "other than Modbus"));
    // The connection, the same in every block, is listed once.
    let uris: Vec<_> = imported.unmapped.iter().filter(|u| u.field == "uri").collect();
    assert_eq!(uris.len(), 1, "{uris:?}");
    assert!(uris[0].place.ends_with("(and 2 more)"), "{}", uris[0].place);
}

#[test]
fn files_that_are_not_maps_are_refused_with_the_place() {
    let err = import("modbus:\n  - name: [\n", "bad.yaml", Format::HaYaml, &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().starts_with("bad.yaml: not YAML: ") && err.to_string().contains("line 3"), "{err}");
    let err = import("site: {}\n", "x.yaml", Format::HaYaml, &ImportOptions::default()).unwrap_err();
    assert!(matches!(err, ImportError::Malformed { .. }), "{err}");
    let err = import("site: {}\n", "x.yaml", Format::EvccYaml, &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("no `source: modbus` block"), "{err}");
    let err = import("name,unit\nspeed,Hz\n", "x.csv", Format::Csv, &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("no address column"), "{err}");
    let err = import("# only a comment\n", "x.csv", Format::Csv, &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("no header line"), "{err}");
    let err = import("address,name\nx,y\n", "x.csv", Format::Csv, &ImportOptions::default()).unwrap_err();
    assert!(matches!(&err, ImportError::Nothing { list, .. } if list.len() == 1), "{err}");
}

#[test]
fn names_and_values_from_a_file_are_escaped_in_the_profile_and_the_list() {
    let text = "address,name,unit,description,values\n\
        1,\"a \"\"quoted\"\"\tname\",\"°C\",\"line\nbreak\",\"0=off; 1=on \\\"x\\\"\"\n\
        2,\"bell\u{7}\",,,nonsense\n";
    let (profile, imported) = imported(text, Format::Csv, &ImportOptions::default());
    assert_eq!(point(&profile, "a_\"quoted\"_name").label, "a \"quoted\"\tname");
    assert_eq!(point(&profile, "a_\"quoted\"_name").description, "line\nbreak");
    assert!(imported.unmapped.iter().all(|u| !u.value.contains('\u{7}') && !u.field.contains('\u{7}')));
    assert!(lists(&imported, "line 4", "values", "not a list"), "{:?}", imported.unmapped);
}

/// A meter's register list as its manual gives it (Eastron's SDM630 columns and numbers).
const MODICON_CSV: &str = "Modbus Register,Parameter Name,Units,Data Format\n\
    30001,Phase 1 line to neutral volts,V,Float\n\
    30007,Phase 1 current,A,Float\n\
    30053,Total system power,W,Float\n\
    30343,Total kWh,kWh,Float\n\
    40013,Demand period,minutes,Float\n";

#[test]
fn modicon_register_numbers_are_read_as_their_table_and_address_with_a_note() {
    let (profile, imported) = imported(MODICON_CSV, Format::Csv, &ImportOptions::default());
    let volts = point(&profile, "Phase_1_line_to_neutral_volts");
    assert_eq!((volts.table, volts.address, volts.value_type), (Table::Input, 0, ValueType::F32));
    assert_eq!(volts.unit.as_deref(), Some("V"));
    assert_eq!((point(&profile, "Total_kWh").table, point(&profile, "Total_kWh").address), (Table::Input, 342));
    let period = point(&profile, "Demand_period");
    assert_eq!((period.table, period.address, period.access), (Table::Holding, 12, Access::Rw));
    assert!(imported.unmapped.is_empty(), "{:?}", imported.unmapped);
    assert!(imported.notes.iter().any(|n| n.contains("Modicon register number")), "{:?}", imported.notes);
    assert!(imported.toml.contains("# Every address is a Modicon register number"), "{}", imported.toml);
    // --first-address says how the file numbers: then the numbers are addresses.
    let plain = ImportOptions { base: Some(0), ..ImportOptions::default() };
    let (profile, imported) = self::imported(MODICON_CSV, Format::Csv, &plain);
    assert_eq!(point(&profile, "Demand_period").address, 40013);
    assert!(imported.notes.is_empty());
    // One address that is no Modicon number: the file numbers from 0.
    let mixed = format!("{MODICON_CSV}7,Serial number,,Float\n");
    let (profile, _) = self::imported(&mixed, Format::Csv, &ImportOptions::default());
    assert_eq!((point(&profile, "Total_kWh").table, point(&profile, "Total_kWh").address), (Table::Holding, 30343));
    // A table column that disagrees with the number is listed; the number's table is read.
    let table = "Register;Table;Name\n30001;holding;volts\n40001;holding;setpoint\n";
    let (profile, imported) = self::imported(table, Format::Csv, &ImportOptions::default());
    assert_eq!((point(&profile, "volts").table, point(&profile, "volts").address), (Table::Input, 0));
    assert!(lists(&imported, "line 2", "table", "the Modicon number 30001 is a input"), "{:?}", imported.unmapped);
    // Padded coil numbers alone may be plain numbers: not Modicon.
    let coils = "Address,Name\n00001,a\n00002,b\n";
    assert_eq!(point(&self::imported(coils, Format::Csv, &ImportOptions::default()).0, "b").address, 2);
}

#[test]
fn a_meter_list_with_a_hex_address_column_sizes_and_resolutions_is_read_as_the_vendor_means() {
    // ABB's meter lists: the quantity measured, the start register in hex, its size in
    // registers, the resolution with its unit, a type without its width.
    let text = "Quantity;Details;Start reg (Hex);Size;Res.;Unit;Data type\n\
        Active import;Total;5000;4;0,01 kWh;kWh;Unsigned\n\
        Voltage L1-N;;5B00;2;0,1 V;V;Unsigned\n\
        Active power;Total;5B14;2;0,01 W;W;Signed\n\
        Frequency;;5B2C;1;0,01 Hz;Hz;Unsigned\n";
    let (profile, imported) = imported(text, Format::Csv, &ImportOptions::default());
    let energy = point(&profile, "Active_import");
    assert_eq!((energy.table, energy.address, energy.value_type), (Table::Holding, 0x5000, ValueType::U64));
    assert!((energy.scale - 0.01).abs() < 1e-12 && energy.unit.as_deref() == Some("kWh"));
    assert_eq!(energy.description, "Total");
    let volts = point(&profile, "Voltage_L1-N");
    assert_eq!((volts.address, volts.value_type), (0x5B00, ValueType::U32));
    assert!((volts.scale - 0.1).abs() < 1e-12);
    assert_eq!(point(&profile, "Active_power").value_type, ValueType::I32);
    assert_eq!(
        (point(&profile, "Frequency").address, point(&profile, "Frequency").value_type),
        (0x5B2C, ValueType::U16)
    );
    assert!(imported.unmapped.is_empty(), "{:?}", imported.unmapped);
    assert!(imported.notes.is_empty());
    // Without a name column, the description names the row.
    let described = "Address;Description;Unit\n0;Heating flow temperature;°C\n";
    let (profile, _) = self::imported(described, Format::Csv, &ImportOptions::default());
    let flow = point(&profile, "Heating_flow_temperature");
    assert_eq!((flow.label.as_str(), flow.description.as_str()), ("Heating flow temperature", ""));
}

const EVCC_TWO: &str = "
meters:
  - name: grid
    type: custom
    power:
      source: modbus
      uri: 192.168.1.50:502
      id: 1
      register: { address: 0, type: input, decode: int32 }
chargers:
  - name: wallbox
    type: custom
    maxcurrent:
      source: modbus
      uri: 192.168.1.60:502
      id: 1
      register: { address: 0, type: writesingle, decode: uint16 }
  - name: garage
    type: template
    template: abl
";

#[test]
fn an_evcc_file_of_two_devices_is_one_profile_each_and_a_template_is_named() {
    let err = import(EVCC_TWO, "evcc.yaml", Format::EvccYaml, &ImportOptions::default()).unwrap_err();
    assert!(matches!(&err, ImportError::SeveralDevices { count: 2, .. }), "{err}");
    let shown = err.to_string();
    assert!(shown.contains("grid at 192.168.1.50:502, wallbox at 192.168.1.60:502"), "{shown}");
    assert!(shown.contains("--only-device NAME"), "{shown}");
    for (device, code, table) in
        [("wallbox", "wallbox.maxcurrent", Table::Holding), ("grid", "grid.power", Table::Input)]
    {
        let options = ImportOptions { device: Some(device.into()), ..ImportOptions::default() };
        let (profile, imported) = imported(EVCC_TWO, Format::EvccYaml, &options);
        assert_eq!(profile.device.name, device);
        assert_eq!(profile.points().len(), 1, "{}", imported.toml);
        assert_eq!((point(&profile, code).table, point(&profile, code).address), (table, 0));
        assert!(lists(&imported, "", "device", "another device"), "{:?}", imported.unmapped);
        assert!(lists(&imported, "chargers[1]", "template", "an evcc template"), "{:?}", imported.unmapped);
    }
    // By its endpoint too; an unknown name says which there are.
    let options = ImportOptions { device: Some("192.168.1.60:502".into()), ..ImportOptions::default() };
    assert_eq!(imported(EVCC_TWO, Format::EvccYaml, &options).0.device.name, "wallbox");
    let options = ImportOptions { device: Some("pv".into()), ..ImportOptions::default() };
    let err = import(EVCC_TWO, "evcc.yaml", Format::EvccYaml, &options).unwrap_err().to_string();
    assert!(err.contains("no device named \"pv\": the file's devices are grid at"), "{err}");
}

#[test]
fn an_evcc_file_whose_registers_are_evccs_own_says_where_they_are() {
    let templates = "
meters:
  - name: grid
    type: template
    template: sdm630
    usage: grid
    modbus: rs485serial
    id: 2
  - name: pv
    type: modbus
    model: sdm
    uri: 192.168.1.70:502
    power: Power
";
    let err = import(templates, "evcc.yaml", Format::EvccYaml, &ImportOptions::default()).unwrap_err().to_string();
    assert!(err.contains("no `source: modbus` block"), "{err}");
    assert!(err.contains("meters[0] (grid) is template sdm630: an evcc template"), "{err}");
    assert!(err.contains("meters[1] (pv) is model sdm: a `type: modbus` meter"), "{err}");
    let definition = "
template: sdm630
products:
  - brand: Eastron
params:
  - name: usage
render: |
  type: custom
  power:
    source: modbus
    id: {{ .id }}
";
    let err = import(definition, "sdm630.yaml", Format::EvccYaml, &ImportOptions::default()).unwrap_err().to_string();
    assert!(err.contains("the file is render: an evcc template definition"), "{err}");
    let bare = import("meters: []\n", "evcc.yaml", Format::EvccYaml, &ImportOptions::default()).unwrap_err();
    assert!(bare.to_string().contains("a `type: custom` device's attributes"), "{bare}");
}

#[test]
fn text_too_long_or_unprintable_for_a_profile_costs_its_field_and_not_the_file() {
    let long_name = "Current L1 ".repeat(30);
    let text = format!(
        "address,name,unit,group,description,values\n\
         1,{long_name},Total signed: negative is exported,grid,,\n\
         2,rtl\u{202E}name,V,\"esc\u{1b}[2J\",\"bell\u{7} {}\",\"0=off; 1=\u{202E}on\"\n",
        "x".repeat(5000)
    );
    let (profile, imported) = imported(&text, Format::Csv, &ImportOptions::default());
    let long = profile.points().iter().find(|p| p.address == 1).unwrap();
    assert!(long.code.chars().count() <= 112 && long.code.starts_with("Current_L1_"), "{}", long.code);
    assert_eq!(long.label.chars().count(), 256, "cut, with an ellipsis: {}", long.label);
    assert!(lists(&imported, "line 2", "label", "longer than the 256 characters of a label: cut"));
    assert_eq!(long.unit, None, "a unit of 33 characters is a shifted column, not a unit");
    assert!(lists(&imported, "line 2", "unit", "at most 32 printable characters: left out"));
    assert_eq!(long.group.as_deref(), Some("grid"));
    let rtl = profile.points().iter().find(|p| p.address == 2).unwrap();
    assert_eq!(rtl.code, "rtl_name", "a bidirectional control is no part of a code");
    assert_eq!(rtl.label, "rtl\\u{202e}name");
    assert_eq!(rtl.group, None);
    assert!(lists(&imported, "line 3", "group", "left out"));
    assert!(rtl.description.starts_with("bell\\u{7} xxx") && rtl.description.ends_with('…'));
    assert!(lists(&imported, "line 3", "description", "longer than the 4096 characters"));
    assert_eq!(rtl.values, vec![(0, "off".to_string())]);
    assert!(lists(&imported, "line 3", "values", "a meaning is one line"));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Whatever the text, an import gives a profile that checks or an error: never a panic.
    #[test]
    fn any_text_imports_or_is_refused(text in "[ -~\n\t;,:\\-\\[\\]{}#'\"]{0,400}", which in 0..3usize) {
        let format = [Format::Csv, Format::HaYaml, Format::EvccYaml][which];
        if let Ok(imported) = import(&text, "fuzz", format, &ImportOptions::default()) {
            prop_assert!(Profile::parse(&imported.toml, "fuzz").is_ok());
        }
    }

    /// CSV rows of any address, type and order import, or are listed.
    #[test]
    fn generated_rows_import_or_are_listed(
        rows in proptest::collection::vec((0u32..70_000, 0..12usize, 0..6usize, "[a-z]{1,6}"), 1..30)
    ) {
        let types = ["u16", "i16", "u32", "i32", "u64", "i64", "f32", "f64", "string", "bit", "", "x"];
        let orders = ["", "ABCD", "CDAB", "BADC", "DCBA", "little"];
        let mut text = String::from("address,type,order,name,length\n");
        for (address, t, o, name) in &rows {
            writeln!(text, "{address},{},{},{name},3", types[*t], orders[*o]).unwrap();
        }
        match import(&text, "gen", Format::Csv, &ImportOptions::default()) {
            Ok(imported) => {
                let profile = Profile::parse(&imported.toml, "gen").unwrap();
                prop_assert_eq!(profile.points().len() + imported.unmapped.iter().filter(|u| u.why.contains("skipped") || u.why.contains("shares") || u.why.contains("one point") || u.why.contains("past")).count(), rows.len());
            }
            Err(ImportError::Nothing { .. }) => {}
            Err(e) => prop_assert!(false, "{}", e),
        }
    }
}
