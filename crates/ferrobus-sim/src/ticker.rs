//! A point whose value is a known function of the wall clock, for latency measurements.
//!
//! A [`Ticker`] makes one named integer point of every simulated device hold the number of
//! whole periods since the Unix epoch, counting from 0 and wrapping past the largest value its
//! type holds (65535 for a `u16`). Anyone who reads the same clock then knows the instant each
//! value began — value `v` began at the last instant `k × period` with `k ≡ v` modulo the
//! wrap — without the simulator telling them: what receives a value at time `t` knows how old
//! it is. `bench/bridge.sh` takes the bridge's end-to-end latency so (the instant an MQTT
//! message with a new value arrives, minus the instant that value began in the simulator).
//!
//! Like the model, the ticker is applied before each request is served, so the value is the
//! one of the request's instant and nothing runs in the background.

use std::fmt;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::clock::SimClock;
use crate::memory::{Item, Memory};
use crate::parse::parse_duration;

/// Why a ticker was refused.
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TickerError {
    /// A period of zero counts nothing.
    #[error("ticker {point}: the period must be longer than zero")]
    ZeroPeriod {
        /// The point.
        point: String,
    },
    /// Not `POINT:PERIOD`.
    #[error("ticker {spec:?}: expected POINT:PERIOD, e.g. d005:1.1s")]
    Spec {
        /// What was given.
        spec: String,
    },
    /// The period is no duration.
    #[error("ticker {spec:?}: {reason}")]
    Period {
        /// What was given.
        spec: String,
        /// What is wrong with the period.
        reason: ferrobus::text::TextError,
    },
    /// The point is not an integer register.
    #[error("ticker {point}: not an integer register")]
    NotInteger {
        /// The point.
        point: String,
    },
    /// The profile has no point by that name.
    #[error("ticker {point}: the profile has no point by that name")]
    NoPoint {
        /// The point.
        point: String,
    },
    /// One unit of a simulator cannot carry the ticker.
    #[error("unit {unit}: {error}")]
    Unit {
        /// The unit.
        unit: u8,
        /// Why.
        error: Box<TickerError>,
    },
}

/// A point that counts periods of a clock (see the module docs).
#[derive(Clone)]
pub struct Ticker {
    point: String,
    period: Duration,
    /// The time since the Unix epoch.
    wall: SimClock,
}

impl fmt::Debug for Ticker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Ticker").field("point", &self.point).field("period", &self.period).finish_non_exhaustive()
    }
}

impl Ticker {
    /// `point` counts `period`s of `wall`, a clock of the time since the Unix epoch; a zero
    /// period is refused.
    pub fn new(point: &str, period: Duration, wall: SimClock) -> Result<Ticker, TickerError> {
        if period.is_zero() {
            return Err(TickerError::ZeroPeriod { point: point.to_string() });
        }
        Ok(Ticker { point: point.to_string(), period, wall })
    }

    /// `point` counts `period`s of the system clock since the Unix epoch.
    pub fn system(point: &str, period: Duration) -> Result<Ticker, TickerError> {
        Ticker::new(
            point,
            period,
            std::sync::Arc::new(|| SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default()),
        )
    }

    /// Parses `POINT:PERIOD` (e.g. `d005:1.1s`; the period as [`parse_duration`] takes it), on
    /// the system clock.
    pub fn parse(spec: &str) -> Result<Ticker, TickerError> {
        let (point, period) = spec
            .rsplit_once(':')
            .filter(|(p, _)| !p.is_empty())
            .ok_or_else(|| TickerError::Spec { spec: spec.to_string() })?;
        let period = parse_duration(period).map_err(|reason| TickerError::Period { spec: spec.to_string(), reason })?;
        Ticker::system(point, period)
    }

    /// The point's name.
    pub fn point(&self) -> &str {
        &self.point
    }

    /// The period.
    pub fn period(&self) -> Duration {
        self.period
    }

    /// Whole periods from the Unix epoch to `since_epoch`.
    pub fn ticks_at(&self, since_epoch: Duration) -> u128 {
        since_epoch.as_nanos() / self.period.as_nanos()
    }

    /// Why `memory` cannot carry this ticker, if it cannot: it has no integer register by the
    /// point's name.
    pub fn check(&self, memory: &Memory) -> Result<(), TickerError> {
        let integer =
            |item: &Item| !item.table.is_bits() && item.point.as_ref().is_some_and(|p| p.value_type.is_integer());
        match memory.item(&self.point) {
            Some(item) if integer(item) => Ok(()),
            Some(_) => Err(TickerError::NotInteger { point: self.point.clone() }),
            None => Err(TickerError::NoPoint { point: self.point.clone() }),
        }
    }

    /// Writes the value of the clock's present instant into `memory`.
    pub fn apply(&self, memory: &mut Memory) {
        let ticks = self.ticks_at((self.wall)());
        let Some(item) = memory.item(&self.point) else { return };
        let top = item.point.as_ref().map_or(i128::from(u16::MAX), |p| p.value_type.integer_range().1);
        // `top` is at least 1 for every integer type, and the remainder is at most `top`, an
        // i64's largest value for the widest types: the conversion cannot fail.
        let wrap = u128::try_from(top).unwrap_or(1).saturating_add(1);
        let value = i64::try_from(ticks % wrap).unwrap_or(0);
        memory.set(&self.point, value);
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicU64, Ordering};

    use super::*;
    use crate::Profile;

    fn inverter() -> Memory {
        Memory::new(&Profile::load("omron-3g3rx").expect("built-in profile"))
    }

    /// A ticker on a clock the test sets, in milliseconds since the epoch.
    fn ticker(point: &str, period_ms: u64) -> (Ticker, Arc<AtomicU64>) {
        let now = Arc::new(AtomicU64::new(0));
        let clock = Arc::clone(&now);
        let wall: SimClock = Arc::new(move || Duration::from_millis(clock.load(Ordering::SeqCst)));
        (Ticker::new(point, Duration::from_millis(period_ms), wall).expect("a period"), now)
    }

    #[test]
    fn the_value_counts_whole_periods_of_the_clock() {
        let mut memory = inverter();
        let (ticker, now) = ticker("d005", 1100);
        for (ms, value) in [(0, 0), (1099, 0), (1100, 1), (2199, 1), (2200, 2), (1_100_000, 1000)] {
            now.store(ms, Ordering::SeqCst);
            ticker.apply(&mut memory);
            assert_eq!(memory.get("d005"), value, "at {ms} ms");
        }
    }

    #[test]
    fn the_value_wraps_past_the_largest_its_type_holds() {
        let mut memory = inverter();
        // d005 is a u16: 65536 periods wrap to 0. d009 is an i16: it counts 0..=32767.
        let (u16_ticker, now) = ticker("d005", 1);
        now.store(65_536 + 7, Ordering::SeqCst);
        u16_ticker.apply(&mut memory);
        assert_eq!(memory.get("d005"), 7);
        let (i16_ticker, now) = ticker("d009", 1);
        now.store(32_768 + 3, Ordering::SeqCst);
        i16_ticker.apply(&mut memory);
        assert_eq!(memory.get("d009"), 3);
        // d004 is a u32 pair: no wrap yet at 1e9 periods.
        let (u32_ticker, now) = ticker("d004", 1);
        now.store(1_000_000_000, Ordering::SeqCst);
        u32_ticker.apply(&mut memory);
        assert_eq!(memory.get("d004"), 1_000_000_000);
    }

    #[test]
    fn a_point_that_cannot_count_is_refused_with_its_name() {
        let memory = inverter();
        let check = |point: &str| ticker(point, 1).0.check(&memory);
        assert_eq!(check("d005"), Ok(()));
        assert_eq!(check("nope"), Err(TickerError::NoPoint { point: "nope".into() }));
        assert_eq!(check("nope").unwrap_err().to_string(), "ticker nope: the profile has no point by that name");
        assert_eq!(check("running"), Err(TickerError::NotInteger { point: "running".into() }));
        assert_eq!(check("running").unwrap_err().to_string(), "ticker running: not an integer register");
    }

    #[test]
    fn specs_parse_and_a_zero_period_is_refused() {
        let t = Ticker::parse("d005:1.1s").expect("a spec");
        assert_eq!((t.point(), t.period()), ("d005", Duration::from_millis(1100)));
        assert_eq!(Ticker::parse("d005").unwrap_err(), TickerError::Spec { spec: "d005".into() });
        assert!(Ticker::parse("d005").unwrap_err().to_string().contains("expected POINT:PERIOD"));
        assert!(matches!(Ticker::parse(":5ms"), Err(TickerError::Spec { .. })));
        let soon = Ticker::parse("d005:soon").unwrap_err();
        assert!(matches!(&soon, TickerError::Period { spec, .. } if spec == "d005:soon"), "{soon:?}");
        assert!(soon.to_string().contains("not a duration"), "{soon}");
        assert_eq!(Ticker::parse("d005:0ms").unwrap_err(), TickerError::ZeroPeriod { point: "d005".into() });
        assert!(Ticker::parse("d005:0ms").unwrap_err().to_string().contains("longer than zero"));
    }
}
