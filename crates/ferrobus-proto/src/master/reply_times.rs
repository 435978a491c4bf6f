//! How soon each unit answers, learned from its replies, so that a reply far outside a unit's
//! own habit can be told for what it likely is: a late reply to an earlier request.
//!
//! RTU and ASCII carry no transaction id, and a late reply of the same unit, function and
//! length looks exactly like the reply to the next request. After the late window has passed
//! in silence the master has to send again, and a reply later than the window then arrives
//! during the next request's wait. What the line still knows is *when* it arrived: a unit that
//! has answered in 8 ms a hundred times does not answer this once in 100 ms by chance. The
//! master keeps, per unit, a histogram of the delays from the end of a request to the start of
//! its reply (buckets doubling from 250 µs), aged by halving, and takes its 99th percentile
//! as the unit's usual delay; a reply that begins well past it, to a unit whose last owed reply
//! never came, is dropped as suspect.
//!
//! No allocation: a fixed table of [`UNITS`] units, the least recently answering one making
//! room for a new one.

use core::time::Duration;

/// Units whose reply times are kept; past that, the one heard least recently is forgotten.
pub(super) const UNITS: usize = 8;

/// Buckets: the first holds delays under 250 µs, bucket `k` those under 250 µs × 2^k.
const BUCKETS: usize = 26;

/// The width of the first bucket.
const BASE: Duration = Duration::from_micros(250);

/// Replies a unit must have given before its habit is judged by.
pub(super) const MIN_SAMPLES: u16 = 20;

/// Past this many samples every count is halved, so that the habit follows the device.
const AGE_AT: u16 = 1000;

/// A reply is suspect once it begins later than this many times the usual delay...
const FACTOR: u32 = 4;

/// ...plus this, so that a fast unit's jitter (an OS, a USB adapter) is not suspect.
const MARGIN: Duration = Duration::from_millis(10);

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Unit {
    id: u8,
    /// When it last answered, in replies recorded by the table (0: the slot is free).
    used: u32,
    counts: [u16; BUCKETS],
    total: u16,
}

impl Unit {
    const EMPTY: Unit = Unit { id: 0, used: 0, counts: [0; BUCKETS], total: 0 };

    /// The upper bound of the bucket that holds the 99th percentile.
    fn p99(&self) -> Option<Duration> {
        if self.total < MIN_SAMPLES {
            return None;
        }
        let want = u32::from(self.total).saturating_mul(99).div_ceil(100);
        let mut seen = 0u32;
        for (k, &count) in self.counts.iter().enumerate() {
            seen = seen.saturating_add(u32::from(count));
            if seen >= want {
                return Some(upper_bound(k));
            }
        }
        Some(upper_bound(BUCKETS - 1))
    }
}

/// The delay below which bucket `k` lies.
fn upper_bound(k: usize) -> Duration {
    BASE.saturating_mul(1u32.checked_shl(u32::try_from(k).unwrap_or(u32::MAX)).unwrap_or(u32::MAX))
}

/// The bucket of `delay`.
fn bucket(delay: Duration) -> usize {
    (0..BUCKETS).find(|&k| delay < upper_bound(k)).unwrap_or(BUCKETS - 1)
}

/// The reply delays of the units a master has heard.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(super) struct ReplyTimes {
    units: [Unit; UNITS],
    /// Replies recorded, for the least recently used order.
    clock: u32,
}

impl ReplyTimes {
    pub(super) const fn new() -> Self {
        ReplyTimes { units: [Unit::EMPTY; UNITS], clock: 0 }
    }

    /// Notes that `unit` began its reply `delay` after the end of the request.
    pub(super) fn record(&mut self, unit: u8, delay: Duration) {
        self.clock = self.clock.wrapping_add(1).max(1);
        let clock = self.clock;
        let known = self.units.iter().position(|u| u.used != 0 && u.id == unit);
        let slot = known.unwrap_or_else(|| {
            // A free slot, else the one heard least recently.
            let i = self.units.iter().enumerate().min_by_key(|(_, u)| u.used).map_or(0, |(i, _)| i);
            if let Some(slot) = self.units.get_mut(i) {
                *slot = Unit { id: unit, ..Unit::EMPTY };
            }
            i
        });
        let Some(u) = self.units.get_mut(slot) else { return };
        u.used = clock;
        if u.total >= AGE_AT {
            u.total = 0;
            for count in &mut u.counts {
                *count /= 2;
                u.total = u.total.saturating_add(*count);
            }
        }
        if let Some(count) = u.counts.get_mut(bucket(delay)) {
            *count = count.saturating_add(1);
            u.total = u.total.saturating_add(1);
        }
    }

    /// `unit`'s usual reply delay (the 99th percentile, rounded up to its bucket), once it has
    /// answered [`MIN_SAMPLES`] times.
    pub(super) fn usual(&self, unit: u8) -> Option<Duration> {
        self.units.iter().find(|u| u.used != 0 && u.id == unit).and_then(Unit::p99)
    }

    /// If a reply from `unit` that began `delay` after the request is far outside its habit:
    /// its usual delay.
    pub(super) fn suspect(&self, unit: u8, delay: Duration) -> Option<Duration> {
        let usual = self.usual(unit)?;
        (delay > usual.saturating_mul(FACTOR).saturating_add(MARGIN)).then_some(usual)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_usual_delay_is_the_99th_percentile_rounded_up_to_its_bucket() {
        let mut times = ReplyTimes::new();
        for _ in 0..(MIN_SAMPLES - 1) {
            times.record(1, 5 * MS);
        }
        assert_eq!(times.usual(1), None, "judged on too few replies");
        times.record(1, 5 * MS);
        // 5 ms lies in [4 ms, 8 ms).
        assert_eq!(times.usual(1), Some(8 * MS));
        // One slow reply in a hundred is the habit's edge, not its middle.
        for _ in 0..79 {
            times.record(1, 5 * MS);
        }
        times.record(1, 300 * MS);
        assert_eq!(times.usual(1), Some(8 * MS));
        times.record(1, 300 * MS);
        assert_eq!(times.usual(1), Some(512 * MS), "two in 101: past the 99th percentile");
    }

    #[test]
    fn a_reply_far_past_the_units_habit_is_suspect_and_one_near_it_is_not() {
        let mut times = ReplyTimes::new();
        for _ in 0..MIN_SAMPLES {
            times.record(3, 5 * MS);
        }
        // 4 × 8 ms + 10 ms.
        assert_eq!(times.suspect(3, 42 * MS), None);
        assert_eq!(times.suspect(3, 43 * MS), Some(8 * MS));
        assert_eq!(times.suspect(4, 10_000 * MS), None, "an unknown unit has no habit");
    }

    #[test]
    fn the_habit_follows_the_device_and_a_full_table_forgets_the_unit_heard_least_recently() {
        let mut times = ReplyTimes::new();
        for _ in 0..AGE_AT {
            times.record(1, 5 * MS);
        }
        // Aged by halving, new delays outweigh old ones soon.
        for _ in 0..AGE_AT {
            times.record(1, 100 * MS);
        }
        assert_eq!(times.usual(1), Some(128 * MS));
        for unit in 2..=u8::try_from(UNITS).unwrap() {
            for _ in 0..MIN_SAMPLES {
                times.record(unit, MS);
            }
        }
        times.record(1, 100 * MS);
        times.record(200, MS);
        assert_eq!(times.usual(2), None, "unit 2 was heard least recently");
        assert_eq!(times.usual(1), Some(128 * MS));
    }

    #[test]
    fn delays_past_the_last_bucket_and_of_zero_are_kept() {
        let mut times = ReplyTimes::new();
        for _ in 0..MIN_SAMPLES {
            times.record(1, Duration::MAX);
        }
        assert_eq!(times.usual(1), Some(upper_bound(BUCKETS - 1)));
        times.record(2, Duration::ZERO);
        assert_eq!(bucket(Duration::ZERO), 0);
    }
}
