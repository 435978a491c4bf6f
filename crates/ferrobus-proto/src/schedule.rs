//! The arithmetic of polling at a fixed rate: when each poll is due, what counts as an
//! overrun, and whether a line can carry a cycle at all.
//!
//! Poll `k` of a [`Schedule`] is due at `start + k × period`: deadlines come from the start,
//! never from the end of the previous poll, so that a late poll does not push every later one
//! (no drift, however long the run). A poll that ends after the next deadline is an overrun;
//! the slots it ran over are skipped and the next poll is due at once, so that a line that
//! cannot keep up is polled as fast as it allows while the phase stays where it was.
//!
//! [`wire_time`] is the time one exchange holds an RTU line: the request's and the reply's
//! characters plus the t3.5 silence each frame needs after it — what a cycle costs at the
//! least, against which a period can be checked before polling starts.

use core::time::Duration;

use crate::frame::LineTiming;
use crate::time::Instant;

/// The deadlines of one poll group: `start + k × period` for k = 0, 1, 2, ...
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Schedule {
    start: Instant,
    period: Duration,
    next: u64,
    overruns: u64,
    skipped: u64,
}

/// What finishing a poll did to the schedule.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Completion {
    /// The poll ended after the next one was due.
    pub overrun: bool,
    /// Slots skipped because the poll ran over them (0 unless `overrun`).
    pub skipped: u64,
}

impl Schedule {
    /// A schedule whose first poll is due at `start`. A zero period polls back to back.
    pub const fn new(start: Instant, period: Duration) -> Self {
        Schedule { start, period, next: 0, overruns: 0, skipped: 0 }
    }

    /// The period.
    pub const fn period(&self) -> Duration {
        self.period
    }

    /// The index of the poll due next (0 for the first).
    pub const fn index(&self) -> u64 {
        self.next
    }

    /// When poll `k` is due (saturating at the end of time).
    pub fn slot(&self, k: u64) -> Instant {
        let nanos = u64::try_from(self.period.as_nanos()).unwrap_or(u64::MAX);
        self.start.saturating_add(Duration::from_nanos(nanos.saturating_mul(k)))
    }

    /// When the next poll is due.
    pub fn deadline(&self) -> Instant {
        self.slot(self.next)
    }

    /// How many polls ended after the next was due.
    pub const fn overruns(&self) -> u64 {
        self.overruns
    }

    /// How many slots overruns skipped.
    pub const fn skipped(&self) -> u64 {
        self.skipped
    }

    /// The poll due at [`deadline`](Self::deadline) ended at `now`: the next is due at the
    /// following slot, or, if `now` is already past that, at the latest slot not after `now`
    /// (that is, at once), the slots between skipped.
    pub fn complete(&mut self, now: Instant) -> Completion {
        let following = self.next.saturating_add(1);
        if now <= self.slot(following) || self.period.is_zero() {
            self.next = following;
            return Completion { overrun: false, skipped: 0 };
        }
        let elapsed = now.saturating_duration_since(self.start).as_nanos();
        let period = self.period.as_nanos();
        // period is not zero here; the quotient of u128s fits u64 for any instant.
        let latest = u64::try_from(elapsed.checked_div(period).unwrap_or(0)).unwrap_or(u64::MAX);
        let latest = latest.max(following);
        let skipped = latest.saturating_sub(following);
        self.next = latest;
        self.overruns = self.overruns.saturating_add(1);
        self.skipped = self.skipped.saturating_add(skipped);
        Completion { overrun: true, skipped }
    }
}

/// The least time one exchange holds an RTU line: `request` and `reply` characters (whole
/// frames: address, PDU, CRC) and the t3.5 silence after each.
pub fn wire_time(timing: &LineTiming, request: usize, reply: usize) -> Duration {
    timing.transmit_time(request.saturating_add(reply)).saturating_add(timing.t3_5()).saturating_add(timing.t3_5())
}

/// Characters of an RTU read request (address, function, start, quantity, CRC).
pub const READ_REQUEST_CHARS: usize = 8;

/// Characters of an RTU reply to a read of `count` items: address, function, byte count, the
/// data (two bytes a register, or a bit each, packed by eight), CRC.
pub const fn read_reply_chars(count: u16, bits: bool) -> usize {
    let count = count as usize;
    let data = if bits { count.div_ceil(8) } else { count.saturating_mul(2) };
    data.saturating_add(5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::LineConfig;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn deadlines_come_from_the_start_whatever_each_poll_took() {
        let mut s = Schedule::new(Instant::from_millis(5), 100 * MS);
        assert_eq!(s.deadline(), Instant::from_millis(5));
        // Each poll ends at a varying time inside its period: the deadlines stay on the grid.
        for k in 0..1000u64 {
            let took = (k * 37) % 90;
            let end = s.deadline().saturating_add(Duration::from_millis(took));
            let c = s.complete(end);
            assert!(!c.overrun);
            assert_eq!(s.deadline(), Instant::from_millis(5 + (k + 1) * 100));
        }
        assert_eq!(s.index(), 1000);
        assert_eq!(s.overruns(), 0);
    }

    #[test]
    fn a_poll_that_ends_exactly_at_the_next_deadline_is_not_an_overrun() {
        let mut s = Schedule::new(Instant::ZERO, 10 * MS);
        assert!(!s.complete(Instant::from_millis(10)).overrun);
        assert_eq!(s.deadline(), Instant::from_millis(10));
    }

    #[test]
    fn an_overrun_skips_the_slots_it_ran_over_and_keeps_the_phase() {
        let mut s = Schedule::new(Instant::ZERO, 10 * MS);
        // Poll 0 ends at 35 ms: slots 1 and 2 are gone, slot 3 (30 ms) is due at once.
        let c = s.complete(Instant::from_millis(35));
        assert_eq!(c, Completion { overrun: true, skipped: 2 });
        assert_eq!(s.deadline(), Instant::from_millis(30));
        // Back on time: the next is 40 ms, on the original grid.
        assert!(!s.complete(Instant::from_millis(31)).overrun);
        assert_eq!(s.deadline(), Instant::from_millis(40));
        assert_eq!((s.overruns(), s.skipped()), (1, 2));
    }

    #[test]
    fn a_line_slower_than_the_period_is_polled_back_to_back_counting_each_overrun() {
        let mut s = Schedule::new(Instant::ZERO, 10 * MS);
        let mut now = Instant::ZERO;
        for _ in 0..100 {
            // Each poll takes 15 ms and starts as soon as it is due or the last one ends.
            now = now.max(s.deadline()).saturating_add(15 * MS);
            s.complete(now);
            assert!(s.deadline() <= now, "the next poll is due at once");
        }
        assert_eq!(now, Instant::from_millis(1500));
        assert_eq!(s.overruns(), 100);
    }

    #[test]
    fn a_zero_period_polls_back_to_back_without_overruns() {
        let mut s = Schedule::new(Instant::from_millis(1), Duration::ZERO);
        assert!(!s.complete(Instant::from_secs(9)).overrun);
        assert_eq!(s.deadline(), Instant::from_millis(1));
    }

    #[test]
    fn the_end_of_time_saturates() {
        let mut s = Schedule::new(Instant::from_nanos(u64::MAX - 1), Duration::from_secs(u64::MAX));
        assert_eq!(s.slot(u64::MAX), Instant::from_nanos(u64::MAX));
        assert!(!s.complete(Instant::from_nanos(u64::MAX)).overrun);
    }

    #[test]
    fn wire_time_counts_both_frames_and_two_silences() {
        // 9600 baud 8E1: 11 bits a character = 1145.83 µs; t3.5 = 4.010 ms.
        let timing = LineTiming::new(&LineConfig::new(9600).expect("a baud rate"));
        let reply = read_reply_chars(4, false);
        assert_eq!(reply, 13);
        let t = wire_time(&timing, READ_REQUEST_CHARS, reply);
        let expected = timing.char_time() * 21 + timing.t3_5() * 2;
        assert_eq!(t, expected);
        assert!(t > Duration::from_millis(32) && t < Duration::from_millis(33), "{t:?}");
        assert_eq!(read_reply_chars(9, true), 7);
    }
}
