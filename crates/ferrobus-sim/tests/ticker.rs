//! A ticker's point, read over the handler the engine calls, holds the periods of the wall
//! clock at the instant of each request, on every unit; a unit whose profile cannot carry it
//! is named in the refusal.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use ferrobus_proto::slave::Handler;
use ferrobus_sim::{Device, Faults, Profile, Sim, SimClock, Ticker, TickerError};

fn device(profile: &str) -> Device {
    Device::new(Profile::load(profile).expect("a built-in profile"))
}

/// A clock the test sets, in milliseconds.
fn clock() -> (SimClock, Arc<AtomicU64>) {
    let now = Arc::new(AtomicU64::new(0));
    let read = Arc::clone(&now);
    (Arc::new(move || Duration::from_millis(read.load(Ordering::SeqCst))), now)
}

/// d005 of the 3G3RX: holding register 0x1007 on the wire (the profile numbers from 1).
fn read_d005(sim: &mut Sim, unit: u8) -> u16 {
    let mut out = [0u16];
    sim.read_holding_registers(unit, 0x1006, &mut out).expect("d005 reads");
    out[0]
}

#[test]
fn every_unit_reads_the_periods_of_the_instant_of_its_request() {
    let (sim_clock, _) = clock();
    let mut sim = Sim::new(sim_clock, 1);
    sim.add(1, device("omron-3g3rx"), Faults::default());
    sim.add(2, device("omron-3g3rx"), Faults::default());
    let (wall, now) = clock();
    sim.add_ticker(Ticker::new("d005", Duration::from_millis(1100), wall).expect("a period")).expect("d005 counts");
    now.store(1_700_000_000_000, Ordering::SeqCst);
    let ticks = 1_700_000_000_000u64 / 1100;
    let expected = u16::try_from(ticks % 65_536).expect("wrapped");
    assert_eq!(read_d005(&mut sim, 1), expected);
    assert_eq!(read_d005(&mut sim, 2), expected);
    // 1.1 s later, one period more, on both.
    now.fetch_add(1100, Ordering::SeqCst);
    assert_eq!(read_d005(&mut sim, 1), expected.wrapping_add(1));
    assert_eq!(read_d005(&mut sim, 2), expected.wrapping_add(1));
}

#[test]
fn a_unit_without_the_point_is_named() {
    let (sim_clock, _) = clock();
    let mut sim = Sim::new(sim_clock, 1);
    sim.add(1, device("omron-3g3rx"), Faults::default());
    sim.add(7, device("generic"), Faults::default());
    let (wall, _) = clock();
    let refused = sim.add_ticker(Ticker::new("d005", Duration::from_secs(1), wall).expect("a period"));
    let refused = refused.unwrap_err();
    assert!(matches!(&refused, TickerError::Unit { unit: 7, error } if matches!(**error, TickerError::NoPoint { .. })));
    assert_eq!(refused.to_string(), "unit 7: ticker d005: the profile has no point by that name");
}
