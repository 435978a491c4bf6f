//! Which events are shown, and what is counted of them.

use std::collections::BTreeMap;
use std::time::Duration;

use ferrobus_proto::FunctionCode;
use ferrobus_proto::sniff::{FragmentKind, Role};

use super::BusEvent;

/// The units and function codes to show; empty lists show everything.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct Filter {
    /// Show only these units (none: every unit).
    pub units: Vec<u8>,
    /// Show only these function codes (none: every code); an exception counts as its function.
    pub functions: Vec<u8>,
}

impl Filter {
    /// Whether `event` passes. Bytes that are no frame belong to no unit: they pass only when
    /// nothing is filtered.
    pub fn admits(&self, event: &BusEvent) -> bool {
        let Some((unit, fc)) = event.unit_function() else {
            return self.units.is_empty() && self.functions.is_empty();
        };
        (self.units.is_empty() || self.units.contains(&unit))
            && (self.functions.is_empty() || self.functions.contains(&(fc & !FunctionCode::EXCEPTION_BIT)))
    }
}

/// One unit's figures.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct UnitStats {
    /// Requests to it.
    pub requests: u64,
    /// Responses from it, exceptions included.
    pub responses: u64,
    /// Responses that are exceptions.
    pub exceptions: u64,
    /// Requests to it answered by nothing before the next request.
    pub unanswered: u64,
    /// Its frames (either way) with a bad CRC.
    pub crc_errors: u64,
    /// Its frames with less than t3.5 of silence before them.
    pub t3_5_violations: u64,
    /// Its frames with a gap over t1.5 inside them.
    pub t1_5_violations: u64,
    /// The response time of each response paired with its request.
    pub response_times: Vec<Duration>,
}

impl UnitStats {
    /// The shortest, mean and longest response time; `None` without a response.
    pub fn response_spread(&self) -> Option<(Duration, Duration, Duration)> {
        let min = self.response_times.iter().min()?;
        let max = self.response_times.iter().max()?;
        let total: Duration = self.response_times.iter().sum();
        let count = u32::try_from(self.response_times.len()).unwrap_or(u32::MAX);
        Some((*min, total / count, *max))
    }
}

/// Everything counted: per unit, and the bytes that made no frame.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct Stats {
    /// Each unit heard, in order.
    pub units: BTreeMap<u8, UnitStats>,
    /// Frames cut short.
    pub partial_frames: u64,
    /// Runs of bytes that start no frame.
    pub noise_runs: u64,
    /// Bytes outside frames: the partial frames' and the noise's.
    pub noise_bytes: u64,
}

impl Stats {
    /// Counts `event`.
    pub fn count(&mut self, event: &BusEvent) {
        match event {
            BusEvent::Frame { role, crc_ok, time, response_time, .. } => {
                let (unit, fc) = event.unit_function().unwrap_or_default();
                let u = self.units.entry(unit).or_default();
                match role {
                    Role::Request => u.requests += 1,
                    Role::Response => u.responses += 1,
                }
                if *role == Role::Response && fc & FunctionCode::EXCEPTION_BIT != 0 {
                    u.exceptions += 1;
                }
                u.crc_errors += u64::from(!crc_ok);
                u.t3_5_violations += u64::from(time.t3_5_violation);
                u.t1_5_violations += u64::from(time.t1_5_violation);
                u.response_times.extend(*response_time);
            }
            BusEvent::Fragment { bytes, kind, .. } => {
                match kind {
                    FragmentKind::Partial { .. } => self.partial_frames += 1,
                    FragmentKind::Noise => self.noise_runs += 1,
                }
                self.noise_bytes += bytes.len() as u64;
            }
            BusEvent::Unanswered { unit, .. } => self.units.entry(*unit).or_default().unanswered += 1,
        }
    }
}
