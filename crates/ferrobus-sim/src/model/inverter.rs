//! A frequency inverter: run/stop and direction coils and a frequency reference drive an
//! output frequency that ramps with the acceleration and deceleration times.
//!
//! Names are the 3G3RX profile's: coils `run`, `direction`, `external-trip`, `trip-reset`;
//! registers `F001` (reference), `F002`/`F003` (ramp times: from 0 to the maximum frequency),
//! `A001`/`A002` (reference and run sources: 3 = Modbus); outputs `d001`, `d002`, `d003`,
//! `d013`, `d102`, `status-a`, `status-b`, the status coils and the trip monitor.
//! A model over a profile without some of these names still works: missing inputs read 0.

use std::time::Duration;

use super::Model;
use crate::memory::{Denial, Item, Memory};
use crate::profile::Polarity;

/// Trip factor of an external trip (E12).
pub const EXTERNAL_TRIP: u16 = 12;

/// Modbus as the source of the run command and the frequency reference.
const SOURCE_MODBUS: i64 = 3;

/// An inverter's ratings, in the units of its profile's `[model]` (see
/// [`ModelSection::Inverter`](crate::profile::ModelSection::Inverter)).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct InverterRatings {
    /// How the direction coil reads.
    pub polarity: Polarity,
    /// A004, the highest output frequency, in 0.01 Hz.
    pub max_frequency: u32,
    /// The rated current, in 0.01 A.
    pub rated_current: u32,
    /// The rated output voltage, in 0.1 V.
    pub rated_voltage: u32,
    /// The DC bus voltage at rest, in 0.1 V.
    pub dc_bus_voltage: u32,
}

/// The inverter.
#[derive(Debug)]
pub struct Inverter {
    polarity: Polarity,
    max_frequency: f64,
    rated_current: f64,
    rated_voltage: f64,
    dc_bus_voltage: f64,
    /// Output frequency in 0.01 Hz, signed: negative is reverse.
    frequency: f64,
    /// Trip factor while tripped.
    trip: Option<u16>,
    /// Whether the last step changed the frequency (for the current and the bus voltage).
    ramping: i8,
}

impl Inverter {
    /// An inverter at rest with `ratings`, its outputs written into `memory`.
    pub fn new(ratings: InverterRatings, memory: &mut Memory) -> Self {
        let InverterRatings { polarity, max_frequency, rated_current, rated_voltage, dc_bus_voltage } = ratings;
        let inverter = Inverter {
            polarity,
            max_frequency: f64::from(max_frequency.max(1)),
            rated_current: f64::from(rated_current),
            rated_voltage: f64::from(rated_voltage),
            dc_bus_voltage: f64::from(dc_bus_voltage),
            frequency: 0.0,
            trip: None,
            ramping: 0,
        };
        inverter.write_outputs(memory, 0.0);
        inverter
    }

    fn running_command(&self, memory: &Memory) -> bool {
        memory.get("run") != 0 && memory.get("A002") == SOURCE_MODBUS && self.trip.is_none()
    }

    fn reverse_command(&self, memory: &Memory) -> bool {
        let bit = memory.get("direction") != 0;
        match self.polarity {
            Polarity::OneIsReverse => bit,
            Polarity::OneIsForward => !bit,
        }
    }

    fn target(&self, memory: &Memory) -> f64 {
        if !self.running_command(memory) || memory.get("A001") != SOURCE_MODBUS {
            return 0.0;
        }
        let reference = (memory.get("F001") as f64).clamp(0.0, self.top(memory));
        if self.reverse_command(memory) { -reference } else { reference }
    }

    /// The maximum frequency set, in 0.01 Hz: A004 (in Hz) where the profile has it, within the
    /// frame's rating; the rating otherwise.
    fn top(&self, memory: &Memory) -> f64 {
        match memory.get("A004") {
            hz if hz > 0 => (hz as f64 * 100.0).min(self.max_frequency),
            _ => self.max_frequency,
        }
    }

    /// Ramp slope in 0.01 Hz per second for a ramp time register (0.01 s units): the time from
    /// 0 to the maximum frequency set (A004), as on the drive.
    fn slope(&self, memory: &Memory, register: &str) -> f64 {
        let seconds = (memory.get(register) as f64 / 100.0).max(0.01);
        self.top(memory) / seconds
    }

    fn do_trip(&mut self, memory: &mut Memory, code: u16) {
        if self.trip.is_some() {
            return;
        }
        let status_before = memory.get("status-a");
        memory.set("trip-count", memory.get("trip-count").wrapping_add(1) & 0xFFFF);
        memory.set("trip1-factor", i64::from(code));
        memory.set("trip1-status", status_before);
        memory.set("trip1-frequency", self.frequency.abs().round() as i64);
        memory.set("trip1-current", memory.get("d002"));
        memory.set("trip1-voltage", memory.get("d102"));
        self.trip = Some(code);
        // The output is cut: the motor coasts (free-run stop).
        self.frequency = 0.0;
    }

    fn write_outputs(&self, memory: &mut Memory, target: f64) {
        let f = self.frequency.abs();
        let running = f > 0.0 || target != 0.0;
        let base = (memory.get("A003").max(1) * 100) as f64;
        let load = 0.3 + 0.5 * (f / self.top(memory)).min(1.0);
        let accel = if self.ramping > 0 { 0.4 } else { 0.0 };
        let current = if f > 0.0 { self.rated_current * (load + accel) } else { 0.0 };
        let bus = self.dc_bus_voltage * if self.ramping < 0 { 1.08 } else { 1.0 };
        memory.set("d001", f.round() as i64);
        memory.set("d002", current.round() as i64);
        memory.set(
            "d003",
            if f == 0.0 {
                0
            } else if self.frequency < 0.0 {
                2
            } else {
                1
            },
        );
        memory.set("d013", (self.rated_voltage * (f / base).min(1.0)).round() as i64);
        memory.set("d102", bus.round() as i64);
        let (a, b) = match self.trip {
            Some(_) => (8, 2),
            None if running => (3, 1),
            None => (2, 0),
        };
        memory.set("status-a", a);
        memory.set("status-b", b);
        memory.set("running", i64::from(running));
        memory.set("reverse", i64::from(self.frequency < 0.0 || (f == 0.0 && target < 0.0)));
        memory.set("ready", i64::from(self.trip.is_none()));
        memory.set("run-signal", i64::from(f > 0.0));
        let at_speed = running && target != 0.0 && (self.frequency - target).abs() < 0.5;
        memory.set("at-speed", i64::from(at_speed));
        memory.set("above-setting", i64::from(running && f + 0.5 >= memory.get("F001") as f64 && f > 0.0));
        memory.set("overload", i64::from(current > self.rated_current * 1.5));
    }
}

impl Model for Inverter {
    fn advance(&mut self, memory: &mut Memory, dt: Duration) {
        if memory.get("external-trip") != 0 {
            self.do_trip(memory, EXTERNAL_TRIP);
        }
        if memory.get("trip-reset") != 0 {
            // The reset input is momentary: it clears the trip and itself.
            memory.set("trip-reset", 0);
            memory.set("external-trip", 0);
            self.trip = None;
        }
        let target = self.target(memory);
        let dt = dt.as_secs_f64();
        let before = self.frequency;
        // Towards zero by the deceleration ramp, away from zero by the acceleration ramp; a
        // change of direction decelerates through zero first.
        let mut left = dt;
        while left > 0.0 && self.frequency != target {
            let speeding_up = self.frequency == 0.0
                || (self.frequency.signum() == target.signum() && target.abs() > self.frequency.abs());
            let slope = self.slope(memory, if speeding_up { "F002" } else { "F003" });
            let goal = if speeding_up || self.frequency.signum() == target.signum() { target } else { 0.0 };
            let step = slope * left;
            let gap = goal - self.frequency;
            if gap.abs() <= step {
                self.frequency = goal;
                left -= gap.abs() / slope;
            } else {
                self.frequency += step * gap.signum();
                left = 0.0;
            }
        }
        self.ramping = if self.frequency.abs() > before.abs() {
            1
        } else if self.frequency.abs() < before.abs() {
            -1
        } else {
            0
        };
        self.write_outputs(memory, target);
    }

    fn check_write(&self, item: &Item, _value: i64) -> Result<(), Denial> {
        let running = self.frequency != 0.0;
        if running && !item.while_running {
            return Err(Denial::NotAllowed);
        }
        Ok(())
    }

    fn trip(&mut self, memory: &mut Memory, code: u16) {
        self.do_trip(memory, code);
        self.write_outputs(memory, 0.0);
    }

    fn summary(&self, memory: &Memory) -> String {
        let state = match (self.trip, memory.get("status-b")) {
            (Some(code), _) => format!("tripped E{code:02}"),
            (None, 1) => "running".to_string(),
            _ => "stopped".to_string(),
        };
        format!(
            "{state}, output {:.2} Hz of {:.2} Hz, {:.2} A",
            self.frequency / 100.0,
            memory.get("F001") as f64 / 100.0,
            memory.get("d002") as f64 / 100.0
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::Profile;

    fn drive() -> (Inverter, Memory) {
        let profile = Profile::load("omron-3g3rx").unwrap();
        let mut memory = Memory::new(&profile);
        let ratings = InverterRatings {
            polarity: Polarity::OneIsReverse,
            max_frequency: 40000,
            rated_current: 1540,
            rated_voltage: 2000,
            dc_bus_voltage: 2820,
        };
        let inverter = Inverter::new(ratings, &mut memory);
        (inverter, memory)
    }

    fn step(inv: &mut Inverter, m: &mut Memory, ms: u64) {
        inv.advance(m, Duration::from_millis(ms));
    }

    #[test]
    fn the_output_ramps_to_the_reference_at_the_acceleration_rate() {
        let (mut inv, mut m) = drive();
        m.set("A004", 400); // the maximum frequency: 400 Hz
        m.set("F001", 5000); // 50.00 Hz
        m.set("F002", 400); // 4.00 s from 0 to 400.00 Hz: 100 Hz per second
        m.set("run", 1);
        step(&mut inv, &mut m, 250);
        assert_eq!(m.get("d001"), 2500, "25 Hz after 0.25 s");
        assert_eq!(m.get("status-a"), 3);
        assert_eq!(m.get("at-speed"), 0);
        step(&mut inv, &mut m, 250);
        assert_eq!(m.get("d001"), 5000);
        assert_eq!(m.get("at-speed"), 1);
        assert_eq!(m.get("d003"), 1, "forward");
    }

    #[test]
    fn stop_ramps_down_with_the_deceleration_time_and_reverse_goes_through_zero() {
        let (mut inv, mut m) = drive();
        m.set("A004", 400);
        m.set("F001", 4000);
        m.set("F002", 100); // 1 s to 400 Hz
        m.set("F003", 200); // 2 s to 400 Hz
        m.set("run", 1);
        step(&mut inv, &mut m, 1000);
        assert_eq!(m.get("d001"), 4000);
        m.set("direction", 1);
        step(&mut inv, &mut m, 200); // 40 Hz down at 200 Hz/s: reaches 0 after 0.2 s
        assert_eq!(m.get("d001"), 0);
        step(&mut inv, &mut m, 50); // then 400 Hz/s up, reversed
        assert_eq!(m.get("d001"), 2000);
        assert_eq!(m.get("d003"), 2, "reverse");
        m.set("run", 0);
        step(&mut inv, &mut m, 100);
        assert_eq!(m.get("d001"), 0);
        assert_eq!(m.get("status-a"), 2);
    }

    #[test]
    fn an_external_trip_stops_the_output_and_records_the_fault() {
        let (mut inv, mut m) = drive();
        m.set("F001", 3000);
        m.set("run", 1);
        step(&mut inv, &mut m, 10_000);
        m.set("external-trip", 1);
        step(&mut inv, &mut m, 1);
        assert_eq!(m.get("d001"), 0);
        assert_eq!((m.get("status-a"), m.get("status-b")), (8, 2));
        assert_eq!(m.get("trip-count"), 1);
        assert_eq!(m.get("trip1-factor"), i64::from(EXTERNAL_TRIP));
        assert_eq!(m.get("trip1-frequency"), 3000);
        assert_eq!(m.get("ready"), 0);
        m.set("trip-reset", 1);
        step(&mut inv, &mut m, 1);
        assert_eq!(m.get("ready"), 1);
        assert_eq!(m.get("trip-reset"), 0, "momentary");
    }

    #[test]
    fn parameters_that_cannot_change_while_running_are_refused() {
        let (mut inv, mut m) = drive();
        let a003 = m.item("A003").unwrap().clone();
        assert_eq!(inv.check_write(&a003, 50), Ok(()));
        m.set("F001", 1000);
        m.set("run", 1);
        step(&mut inv, &mut m, 100);
        assert_eq!(inv.check_write(&a003, 50), Err(Denial::NotAllowed));
        let f001 = m.item("F001").unwrap().clone();
        assert_eq!(inv.check_write(&f001, 2000), Ok(()));
    }

    #[test]
    fn without_modbus_as_the_run_source_the_run_coil_does_nothing() {
        let (mut inv, mut m) = drive();
        m.set("A002", 1);
        m.set("F001", 1000);
        m.set("run", 1);
        step(&mut inv, &mut m, 1000);
        assert_eq!(m.get("d001"), 0);
    }

    #[test]
    fn the_ramp_times_are_from_0_to_a004_and_the_output_stops_at_it() {
        let (mut inv, mut m) = drive();
        assert_eq!(m.get("A004"), 60, "60 Hz by default");
        m.set("F001", 5000);
        m.set("F002", 1000); // 10.00 s from 0 to 60 Hz: 6 Hz per second
        m.set("run", 1);
        step(&mut inv, &mut m, 5000);
        assert_eq!(m.get("d001"), 3000, "30 Hz after 5 s, not the 200 Hz a ramp to 400 Hz would give");
        m.set("A004", 50);
        m.set("F001", 40000);
        step(&mut inv, &mut m, 10_000);
        assert_eq!(m.get("d001"), 5000, "F001 above A004: the output stops at 50 Hz");
    }
}
