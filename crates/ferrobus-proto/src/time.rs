//! Time as the engines see it: an [`Instant`] handed in by the caller.
//!
//! The core never reads a clock. Every method that depends on time takes `now: Instant`, and
//! every timer an engine runs is visible through its `poll_timeout()`. The driver picks the
//! epoch (process start, a test's zero, a hardware timer) and converts its clock to an
//! `Instant`; only differences between instants carry meaning.
//!
//! Resolution is one nanosecond in a `u64`, which spans 584 years — enough that arithmetic
//! here saturates instead of wrapping, and never panics.

use core::fmt;
use core::time::Duration;

/// A point in time, in nanoseconds since an epoch chosen by the driver.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Instant {
    nanos: u64,
}

impl Instant {
    /// The epoch.
    pub const ZERO: Instant = Instant { nanos: 0 };

    /// The instant `nanos` nanoseconds after the epoch.
    pub const fn from_nanos(nanos: u64) -> Self {
        Instant { nanos }
    }

    /// The instant `micros` microseconds after the epoch (saturating).
    pub const fn from_micros(micros: u64) -> Self {
        Instant { nanos: micros.saturating_mul(1_000) }
    }

    /// The instant `millis` milliseconds after the epoch (saturating).
    pub const fn from_millis(millis: u64) -> Self {
        Instant { nanos: millis.saturating_mul(1_000_000) }
    }

    /// The instant `secs` seconds after the epoch (saturating).
    pub const fn from_secs(secs: u64) -> Self {
        Instant { nanos: secs.saturating_mul(1_000_000_000) }
    }

    /// Nanoseconds since the epoch.
    pub const fn as_nanos(self) -> u64 {
        self.nanos
    }

    /// The time since the epoch.
    pub const fn since_epoch(self) -> Duration {
        Duration::from_nanos(self.nanos)
    }

    /// `self + d`, or `None` past the end of representable time.
    #[must_use]
    pub fn checked_add(self, d: Duration) -> Option<Instant> {
        let d = u64::try_from(d.as_nanos()).ok()?;
        self.nanos.checked_add(d).map(Instant::from_nanos)
    }

    /// `self + d`, clamped to the last representable instant.
    #[must_use]
    pub fn saturating_add(self, d: Duration) -> Instant {
        self.checked_add(d).unwrap_or(Instant { nanos: u64::MAX })
    }

    /// `self - d`, clamped to the epoch.
    #[must_use]
    pub fn saturating_sub(self, d: Duration) -> Instant {
        let d = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        Instant { nanos: self.nanos.saturating_sub(d) }
    }

    /// The time from `earlier` to `self`, or zero if `earlier` is later.
    #[must_use]
    pub const fn saturating_duration_since(self, earlier: Instant) -> Duration {
        Duration::from_nanos(self.nanos.saturating_sub(earlier.nanos))
    }
}

impl fmt::Debug for Instant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// Shown as seconds with nanosecond precision, e.g. `t=0.024010417s`.
impl fmt::Display for Instant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let secs = self.nanos / 1_000_000_000;
        let frac = self.nanos % 1_000_000_000;
        write!(f, "t={secs}.{frac:09}s")
    }
}

/// The earlier of two optional deadlines; `None` means "no deadline".
pub(crate) fn earliest(a: Option<Instant>, b: Option<Instant>) -> Option<Instant> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, None) => a,
        (None, b) => b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_saturates_instead_of_panicking() {
        let end = Instant::from_nanos(u64::MAX);
        assert_eq!(end.checked_add(Duration::from_nanos(1)), None);
        assert_eq!(end.saturating_add(Duration::MAX), end);
        assert_eq!(Instant::ZERO.saturating_sub(Duration::from_secs(1)), Instant::ZERO);
        assert_eq!(Instant::ZERO.saturating_duration_since(end), Duration::ZERO);
        assert_eq!(Instant::from_millis(u64::MAX).as_nanos(), u64::MAX);
    }

    #[test]
    fn constructors_agree_on_units() {
        assert_eq!(Instant::from_millis(24), Instant::from_micros(24_000));
        assert_eq!(Instant::from_micros(1), Instant::from_nanos(1_000));
        assert_eq!(
            Instant::from_millis(5).saturating_duration_since(Instant::from_millis(2)),
            Duration::from_millis(3)
        );
    }

    #[test]
    fn earliest_ignores_missing_deadlines() {
        let a = Some(Instant::from_nanos(5));
        let b = Some(Instant::from_nanos(3));
        assert_eq!(earliest(a, b), b);
        assert_eq!(earliest(a, None), a);
        assert_eq!(earliest(None, b), b);
        assert_eq!(earliest(None, None), None);
    }

    #[test]
    fn display_shows_seconds_with_nanoseconds() {
        extern crate std;
        use std::format;
        assert_eq!(format!("{}", Instant::from_nanos(24_010_417)), "t=0.024010417s");
    }
}
