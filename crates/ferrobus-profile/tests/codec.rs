//! The value codec: what `show` prints, `parse` reads back to the same raw value, and what
//! `encode` lays over registers, `decode` reads back, for random values of every type.

use ferrobus_profile::{Order, Profile, Value};
use proptest::prelude::*;

fn point(spec: &str) -> ferrobus_profile::Point {
    let text = format!(
        "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n[[registers]]\nnumber=0\nname='p'\naccess='rw'\n{spec}\n"
    );
    Profile::parse(&text, "codec.toml").unwrap().points()[0].clone()
}

proptest! {
    #[test]
    fn a_shown_scaled_value_parses_back_to_the_same_raw_value(
        raw in any::<u32>(),
        scale in prop_oneof![Just(0.01), Just(0.1), Just(1.0), Just(0.5), Just(10.0)],
        offset in prop_oneof![Just(0.0), Just(-40.0), Just(0.5)],
        unit in prop_oneof![Just(""), Just("unit='Hz'"), Just("unit='°C'")],
    ) {
        let p = point(&format!("type='u32'\nscale={scale:?}\noffset={offset:?}\n{unit}"));
        let shown = p.show(&Value::Int(i128::from(raw)));
        prop_assert_eq!(p.parse(&shown), Ok(Value::Int(i128::from(raw))), "{}", shown);
    }

    #[test]
    fn every_integer_type_and_order_round_trips_through_registers(
        raw in any::<i64>(),
        ty in prop_oneof![Just("u16"), Just("i16"), Just("u32"), Just("i32"), Just("u64"), Just("i64")],
        order in prop_oneof![Just(Order::Abcd), Just(Order::Cdab), Just(Order::Badc), Just(Order::Dcba)],
    ) {
        let p = point(&format!("type='{ty}'{}", if ty.ends_with("16") { String::new() } else { format!("\norder='{}'", order.name()) }));
        let (lo, hi) = p.value_type.integer_range();
        let raw = i128::from(raw).clamp(lo, hi);
        let words = p.encode(&Value::Int(raw)).unwrap();
        prop_assert_eq!(words.len(), usize::from(p.width));
        prop_assert_eq!(p.decode(&words), Ok(Value::Int(raw)));
    }

    #[test]
    fn floats_round_trip_in_every_order(x in any::<f64>().prop_filter("finite", |x| x.is_finite()), order in 0usize..4) {
        let order = Order::ALL[order].name();
        let p64 = point(&format!("type='f64'\norder='{order}'"));
        prop_assert_eq!(p64.decode(&p64.encode(&Value::Float(x)).unwrap()), Ok(Value::Float(x)));
        #[allow(clippy::cast_possible_truncation)]
        let single = f64::from(x as f32);
        let p32 = point(&format!("type='f32'\norder='{order}'"));
        if single.is_finite() {
            prop_assert_eq!(p32.decode(&p32.encode(&Value::Float(single)).unwrap()), Ok(Value::Float(single)));
        }
    }
}
