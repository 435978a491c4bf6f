//! The simulator serves every entry of every built-in profile: each point reads back at its
//! address in its width, a read-write register takes its minimum and maximum and refuses one
//! past them with the profile's out-of-range code, and a read-only one refuses a write with
//! the profile's read-only code.

use ferrobus_proto::ExceptionCode;
use ferrobus_proto::pdu::Registers;
use ferrobus_sim::profile::{Access, BUILTIN, Point, Table, Value};
use ferrobus_sim::{Device, Profile};

fn profile(name: &str) -> Profile {
    Profile::load(name).expect("a built-in profile loads")
}

fn read(device: &Device, p: &Point) -> Result<Vec<u16>, ExceptionCode> {
    let mut words = vec![0u16; usize::from(p.width)];
    device.read_registers(p.table, p.address, &mut words).map(|()| words)
}

/// The registers of raw integer `n` for `p`, if its type can hold it.
fn words(p: &Point, n: f64) -> Option<Vec<u16>> {
    #[allow(clippy::cast_possible_truncation)]
    p.encode(&Value::Int(n as i128)).ok()
}

#[test]
fn every_point_of_every_builtin_profile_reads_back_in_its_width() {
    for (name, _) in BUILTIN {
        let device = Device::new(profile(name));
        for p in device.profile().points() {
            if p.table.is_bits() {
                let mut bit = [false];
                assert_eq!(device.read_bits(p.table, p.address, &mut bit), Ok(()), "{name}: {}", p.code);
            } else {
                let got = read(&device, p).unwrap_or_else(|e| panic!("{name}: {} answers {e:?}", p.code));
                assert!(p.decode(&got).is_ok(), "{name}: {} decodes {got:?}", p.code);
            }
        }
    }
}

#[test]
fn every_read_write_register_takes_its_range_and_refuses_past_it() {
    for (name, _) in BUILTIN {
        let profile = profile(name);
        let out_of_range = ExceptionCode::from_u8(profile.exceptions.out_of_range);
        let mut checked = 0;
        for p in profile.points().iter().filter(|p| p.table == Table::Holding && p.access == Access::Rw) {
            let (Some(min), Some(max)) = (p.min, p.max) else { continue };
            checked += 1;
            // A fresh drive for each register: a write may change what the model allows next.
            for bound in [min, max] {
                let mut device = Device::new(profile.clone());
                let value = words(p, bound).unwrap_or_else(|| panic!("{name}: {} holds {bound}", p.code));
                assert_eq!(
                    device.write_registers(p.address, Registers::from_values(&value)),
                    Ok(()),
                    "{name}: {} = {bound}",
                    p.code
                );
                assert_eq!(read(&device, p), Ok(value), "{name}: {} reads back {bound}", p.code);
            }
            if let Some(past) = words(p, max + 1.0) {
                let mut device = Device::new(profile.clone());
                assert_eq!(
                    device.write_registers(p.address, Registers::from_values(&past)),
                    Err(out_of_range),
                    "{name}: {} = {} is out of range",
                    p.code,
                    max + 1.0
                );
            }
        }
        if *name == "omron-3g3rx" {
            assert!(checked >= 60, "the 3G3RX's ranged parameters were all tried ({checked})");
        }
    }
}

#[test]
fn every_read_only_register_refuses_a_write_with_the_profiles_code() {
    for (name, _) in BUILTIN {
        let profile = profile(name);
        let read_only = ExceptionCode::from_u8(profile.exceptions.read_only);
        for p in profile.points().iter().filter(|p| p.table == Table::Holding && p.access == Access::Ro) {
            let mut device = Device::new(profile.clone());
            let zero = vec![0u16; usize::from(p.width)];
            assert_eq!(
                device.write_registers(p.address, Registers::from_values(&zero)),
                Err(read_only),
                "{name}: {} is read-only",
                p.code
            );
        }
    }
}
