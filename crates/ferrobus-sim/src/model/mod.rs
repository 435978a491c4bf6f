//! Device physics: what a drive does between requests.
//!
//! A model reads its inputs (run coil, frequency reference, ramp times) from the device's
//! memory, advances its state by the time that has passed, and writes its outputs (output
//! frequency, current, status words) back. The device advances it before serving each
//! request, so the state is always current at the instant of the request and nothing runs in
//! the background: with a paused clock, a test sees exact values.
//!
//! Physics is done in `f64` and converted to the registers' integers at the edges: every raw
//! value is within a 32-bit register pair, which `f64` holds exactly, and results are rounded
//! before they are stored, so the casts below cannot lose anything that matters.
#![allow(clippy::cast_possible_truncation, clippy::cast_precision_loss, clippy::float_cmp)]

mod inverter;
mod servo;

use std::time::Duration;

pub use inverter::{EXTERNAL_TRIP, Inverter, InverterRatings};
pub use servo::Servo;

use crate::memory::{Denial, Item, Memory};
use crate::profile::ModelSection;

/// A device's physics.
pub trait Model: Send {
    /// `dt` has passed: update the state and the outputs in `memory`.
    fn advance(&mut self, memory: &mut Memory, dt: Duration);

    /// Whether a write of `value` to `item` is allowed in the present state.
    fn check_write(&self, item: &Item, value: i64) -> Result<(), Denial> {
        let _ = (item, value);
        Ok(())
    }

    /// Trips the drive with a fault code (fault injection); a model without trips ignores it.
    fn trip(&mut self, memory: &mut Memory, code: u16) {
        let _ = (memory, code);
    }

    /// A one-line summary of the state, for logs.
    fn summary(&self, memory: &Memory) -> String;
}

/// The model a profile asks for.
pub fn build(section: &ModelSection, memory: &mut Memory) -> Box<dyn Model> {
    match section {
        ModelSection::Inverter { direction, max_frequency, rated_current, rated_voltage, dc_bus_voltage } => {
            let ratings = InverterRatings {
                polarity: *direction,
                max_frequency: *max_frequency,
                rated_current: *rated_current,
                rated_voltage: *rated_voltage,
                dc_bus_voltage: *dc_bus_voltage,
            };
            Box::new(Inverter::new(ratings, memory))
        }
        ModelSection::Servo { rated_speed, pulses_per_revolution } => {
            Box::new(Servo::new(*rated_speed, *pulses_per_revolution))
        }
    }
}
