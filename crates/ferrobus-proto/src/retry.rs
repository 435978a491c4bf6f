//! A master's policy over many transactions: which outcomes are retried, when a unit that
//! stops answering is skipped, and how long to wait before reopening a port after an IO
//! failure.
//!
//! Sans-IO like the engines: every decision takes `now` and answers with an [`Instant`], so a
//! driver only sleeps until it. The policy is ferrobus's own; the spec says nothing of retries
//! (MODBUS over Serial Line V1.02 §2.4.1 only says a master may resend after its response
//! timeout).
//!
//! ```
//! use core::time::Duration;
//! use ferrobus_proto::Instant;
//! use ferrobus_proto::retry::{Admit, Backoff, Outcome, UnitHealth};
//!
//! // Skip a unit for 1 s after two timeouts in a row.
//! let backoff = Backoff { after: 2, initial: Duration::from_secs(1), max: Duration::from_secs(30) };
//! let mut unit = UnitHealth::default();
//! let t0 = Instant::from_millis(500);
//! unit.record(t0, Outcome::Timeout, &backoff);
//! unit.record(t0, Outcome::Timeout, &backoff);
//! assert_eq!(unit.check(t0), Admit::Skip { until: Instant::from_millis(1500) });
//! assert_eq!(unit.check(Instant::from_millis(1500)), Admit::Probe);
//! ```

use core::time::Duration;

use crate::time::Instant;

/// What became of one attempt, as far as the policy cares.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Outcome {
    /// A usable reply (or a request that gets none, sent).
    Reply,
    /// The device answered with an exception: it is alive, and resending will not change it.
    Exception,
    /// No reply within the response timeout to a request the master checked: a public
    /// function code, parsed.
    Timeout,
    /// No reply within the response timeout to a request the master could not check: a
    /// function code the spec does not define, or a PDU sent raw. Retried like a timeout, but
    /// never held against the unit: a device may ignore a code it does not know, and one
    /// client's odd request must not put a live unit in backoff for every other client.
    UncheckedTimeout,
    /// A reply that was wrong (a mismatch or a malformed PDU).
    BadReply,
    /// The port failed (opening, reading or writing).
    Io,
    /// Anything else (a refused request, a port that is not the same device): not retried and
    /// not held against the unit.
    Other,
}

impl Outcome {
    /// Whether an attempt that ended so is worth another: the line may have lost the request or
    /// the reply.
    pub const fn is_retryable(self) -> bool {
        matches!(self, Outcome::Timeout | Outcome::UncheckedTimeout | Outcome::BadReply | Outcome::Io)
    }
}

/// Whether attempt number `attempts` (1 for the first) that ended in `outcome` is followed by
/// another, with `retries` resends allowed in all.
pub const fn should_retry(outcome: Outcome, attempts: u32, retries: u32) -> bool {
    outcome.is_retryable() && attempts <= retries
}

/// How a unit that stops answering is skipped, so that it does not stall the others.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Backoff {
    /// Consecutive timed-out requests before the unit is skipped (only [`Outcome::Timeout`]
    /// counts: silence to a request the master checked).
    pub after: u32,
    /// How long it is skipped the first time; each failed probe doubles it.
    pub initial: Duration,
    /// The longest it is skipped.
    pub max: Duration,
}

impl Default for Backoff {
    fn default() -> Self {
        Backoff { after: 3, initial: Duration::from_secs(1), max: Duration::from_secs(30) }
    }
}

/// What [`UnitHealth::check`] decides for the next request to a unit.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Admit {
    /// Send it, with its retries.
    Send,
    /// The unit's skip has run out: send it once, without retries, to see if the unit is back.
    Probe,
    /// Skip it: the unit is not tried again before `until`.
    Skip {
        /// When the unit may be probed.
        until: Instant,
    },
}

/// How one unit has been answering, under a [`Backoff`].
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct UnitHealth {
    failures: u32,
    skip_until: Option<Instant>,
    period: Duration,
}

impl UnitHealth {
    /// Whether and how the next request to the unit goes out at `now`.
    pub fn check(&self, now: Instant) -> Admit {
        match self.skip_until {
            Some(until) if now < until => Admit::Skip { until },
            Some(_) => Admit::Probe,
            None => Admit::Send,
        }
    }

    /// Records the final outcome of a request at `now`. Returns `true` when the unit is
    /// healthy again (the caller may forget this record), else `false`.
    pub fn record(&mut self, now: Instant, outcome: Outcome, backoff: &Backoff) -> bool {
        match outcome {
            // A reply, even an exception, shows the unit is alive.
            Outcome::Reply | Outcome::Exception => {
                *self = UnitHealth::default();
                true
            }
            Outcome::Timeout => {
                self.failures = self.failures.saturating_add(1);
                if self.failures >= backoff.after {
                    self.period = if self.skip_until.is_some() {
                        self.period.saturating_mul(2).min(backoff.max)
                    } else {
                        backoff.initial.min(backoff.max)
                    };
                    self.skip_until = Some(now.saturating_add(self.period));
                }
                false
            }
            Outcome::UncheckedTimeout | Outcome::BadReply | Outcome::Io | Outcome::Other => false,
        }
    }

    /// How long the unit is skipped each time now (zero before the first skip).
    pub fn period(&self) -> Duration {
        self.period
    }
}

/// The wait before reopening after the first IO failure in a row.
pub const IO_BACKOFF_INITIAL: Duration = Duration::from_millis(10);

/// The longest wait before reopening, however many IO failures came in a row.
pub const IO_BACKOFF_MAX: Duration = Duration::from_millis(500);

/// The wait before the next open after `failures` IO failures in a row (1 or more):
/// [`IO_BACKOFF_INITIAL`], doubling with each, up to [`IO_BACKOFF_MAX`].
pub fn io_backoff_wait(failures: u32) -> Duration {
    let doublings = failures.saturating_sub(1).min(16);
    IO_BACKOFF_INITIAL.saturating_mul(1 << doublings).min(IO_BACKOFF_MAX)
}

/// IO failures in a row and when the port may be opened next: after each failed open, read
/// or write the next open waits [`IO_BACKOFF_INITIAL`], doubling up to [`IO_BACKOFF_MAX`].
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct IoBackoff {
    failures: u32,
    reopen_at: Option<Instant>,
}

impl IoBackoff {
    /// Counts an IO failure at `now`; returns when the port may be opened next.
    pub fn failed(&mut self, now: Instant) -> Instant {
        self.failures = self.failures.saturating_add(1);
        let at = now.saturating_add(io_backoff_wait(self.failures));
        self.reopen_at = Some(at);
        at
    }

    /// A transaction got through: the count starts again.
    pub fn succeeded(&mut self) {
        self.failures = 0;
    }

    /// IO failures since the last transaction that got through.
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// When the port may be opened next, once: the wait is taken by the next open.
    pub fn take_reopen_at(&mut self) -> Option<Instant> {
        self.reopen_at.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const B: Backoff = Backoff { after: 2, initial: Duration::from_secs(5), max: Duration::from_secs(12) };

    #[test]
    fn timeouts_bad_replies_and_io_failures_are_retried_until_the_retries_are_spent() {
        for outcome in [Outcome::Timeout, Outcome::UncheckedTimeout, Outcome::BadReply, Outcome::Io] {
            assert!(should_retry(outcome, 1, 2));
            assert!(should_retry(outcome, 2, 2));
            assert!(!should_retry(outcome, 3, 2));
            assert!(!should_retry(outcome, 1, 0));
        }
        for outcome in [Outcome::Reply, Outcome::Exception, Outcome::Other] {
            assert!(!should_retry(outcome, 1, 5));
        }
    }

    #[test]
    fn a_unit_is_skipped_after_the_set_timeouts_in_a_row_until_exactly_initial_later() {
        let mut health = UnitHealth::default();
        let t0 = Instant::from_secs(100);
        assert!(!health.record(t0, Outcome::Timeout, &B));
        assert_eq!(health.check(t0), Admit::Send);
        assert!(!health.record(t0, Outcome::Timeout, &B));
        let until = Instant::from_secs(105);
        assert_eq!(health.check(t0), Admit::Skip { until });
        assert_eq!(health.check(Instant::from_nanos(until.as_nanos() - 1)), Admit::Skip { until });
        assert_eq!(health.check(until), Admit::Probe);
    }

    #[test]
    fn each_failed_probe_doubles_the_skip_up_to_max() {
        let mut health = UnitHealth::default();
        let t = Instant::from_secs(0);
        health.record(t, Outcome::Timeout, &B);
        health.record(t, Outcome::Timeout, &B);
        assert_eq!(health.period(), Duration::from_secs(5));
        let t = Instant::from_secs(5);
        health.record(t, Outcome::Timeout, &B);
        assert_eq!(health.period(), Duration::from_secs(10));
        assert_eq!(health.check(t), Admit::Skip { until: Instant::from_secs(15) });
        health.record(Instant::from_secs(15), Outcome::Timeout, &B);
        assert_eq!(health.period(), Duration::from_secs(12));
        assert_eq!(health.check(Instant::from_secs(15)), Admit::Skip { until: Instant::from_secs(27) });
    }

    #[test]
    fn a_reply_or_an_exception_clears_the_record_and_other_failures_leave_it() {
        for alive in [Outcome::Reply, Outcome::Exception] {
            let mut health = UnitHealth::default();
            health.record(Instant::from_secs(0), Outcome::Timeout, &B);
            health.record(Instant::from_secs(0), Outcome::Timeout, &B);
            assert!(health.record(Instant::from_secs(5), alive, &B));
            assert_eq!(health, UnitHealth::default());
        }
        let mut health = UnitHealth::default();
        health.record(Instant::from_secs(0), Outcome::Timeout, &B);
        for other in [Outcome::BadReply, Outcome::Io, Outcome::Other] {
            assert!(!health.record(Instant::from_secs(0), other, &B));
        }
        // Still one timeout counted: the next makes two.
        health.record(Instant::from_secs(0), Outcome::Timeout, &B);
        assert_eq!(health.check(Instant::from_secs(0)), Admit::Skip { until: Instant::from_secs(5) });
    }

    #[test]
    fn silence_to_unchecked_requests_never_puts_a_unit_in_backoff_nor_clears_its_record() {
        let mut health = UnitHealth::default();
        let t = Instant::from_secs(0);
        for _ in 0..10 {
            assert!(!health.record(t, Outcome::UncheckedTimeout, &B));
        }
        assert_eq!(health, UnitHealth::default(), "ten unchecked timeouts count for nothing");
        health.record(t, Outcome::Timeout, &B);
        health.record(t, Outcome::UncheckedTimeout, &B);
        health.record(t, Outcome::Timeout, &B);
        assert_eq!(health.check(t), Admit::Skip { until: Instant::from_secs(5) }, "two checked ones still do");
    }

    #[test]
    fn a_skip_near_the_end_of_time_saturates_instead_of_overflowing() {
        let mut health = UnitHealth::default();
        let end = Instant::from_nanos(u64::MAX);
        health.record(end, Outcome::Timeout, &B);
        health.record(end, Outcome::Timeout, &B);
        assert_eq!(health.check(Instant::from_secs(0)), Admit::Skip { until: end });
    }

    #[test]
    fn io_backoff_doubles_from_initial_to_max_and_restarts_after_success() {
        let mut io = IoBackoff::default();
        let now = Instant::from_secs(1);
        let waits: [u64; 8] = [10, 20, 40, 80, 160, 320, 500, 500];
        for ms in waits {
            assert_eq!(io.failed(now), Instant::from_millis(1000 + ms));
        }
        assert_eq!(io.failures(), 8);
        assert_eq!(io.take_reopen_at(), Some(Instant::from_millis(1500)));
        assert_eq!(io.take_reopen_at(), None);
        io.succeeded();
        assert_eq!(io.failed(now), Instant::from_millis(1010));
        for _ in 0..100 {
            io.failed(now);
        }
        assert_eq!(io.failed(now), Instant::from_millis(1500));
    }
}
