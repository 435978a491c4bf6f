//! What a gateway counts, per line and per unit, and how it is shown; and what its front
//! end refused before any line, by reason.

use std::collections::BTreeMap;
use std::fmt;
use std::time::Duration;

use hdrhistogram::Histogram;

pub use super::screen::Malformed;

/// How one forwarded request ended, for the counters.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Ended {
    /// The unit answered with data (or a write's echo).
    Replied,
    /// The unit answered with this exception code.
    Exception(u8),
    /// A broadcast went out (no reply is awaited).
    Broadcast,
    /// Silence (or bytes that made no usable reply) after every retry: 0x0B.
    Timeout,
    /// Replies came with a bad CRC after every retry: 0x0B, counted apart from silence.
    BadCrc,
    /// A reply came that did not answer the request (wrong length, echo or function) after
    /// every retry: 0x0B.
    BadReply,
    /// The unit is in backoff after failing: skipped without bus time, 0x0B.
    Skipped,
    /// The line's port failed: 0x0A.
    LineDown,
}

/// The counters of a line or of one unit on it.
#[derive(Clone, Debug)]
pub struct Counters {
    /// Requests taken from the queue to the line (skipped ones included).
    pub requests: u64,
    /// Replies with data.
    pub replies: u64,
    /// Exception replies, by code.
    pub exceptions: BTreeMap<u8, u64>,
    /// Broadcasts sent.
    pub broadcasts: u64,
    /// Requests that got silence after their retries.
    pub timeouts: u64,
    /// Requests whose replies had bad CRCs after their retries.
    pub crc_errors: u64,
    /// Requests whose replies did not answer them.
    pub bad_replies: u64,
    /// Requests skipped while their unit was in backoff.
    pub skipped: u64,
    /// Requests failed because the port failed.
    pub line_errors: u64,
    /// Requests answered 0x06 at once because the line's queue was full.
    pub busy: u64,
    /// Reads answered from the cache (not counted in `requests`: they never reach the line).
    pub cached: u64,
    /// Requests dropped because their client had gone before the line got to them.
    pub abandoned: u64,
    /// Response time on the line (from the request's turn to its outcome), in µs.
    pub response_us: Histogram<u64>,
}

impl Default for Counters {
    fn default() -> Self {
        Counters {
            requests: 0,
            replies: 0,
            exceptions: BTreeMap::new(),
            broadcasts: 0,
            timeouts: 0,
            crc_errors: 0,
            bad_replies: 0,
            skipped: 0,
            line_errors: 0,
            busy: 0,
            abandoned: 0,
            cached: 0,
            // 1 µs to 10 min at 2 significant digits: fixed bounds that hdrhistogram accepts.
            response_us: Histogram::new_with_bounds(1, 600_000_000, 2).unwrap_or_else(|_| {
                Histogram::new(2).unwrap_or_else(|_| unreachable!("2 significant digits are within 0 to 5"))
            }),
        }
    }
}

impl Counters {
    /// Counts a request's end after `took` on the line.
    pub(crate) fn count(&mut self, ended: Ended, took: Duration) {
        self.requests = self.requests.saturating_add(1);
        let counter = match ended {
            Ended::Replied => &mut self.replies,
            Ended::Exception(code) => self.exceptions.entry(code).or_insert(0),
            Ended::Broadcast => &mut self.broadcasts,
            Ended::Timeout => &mut self.timeouts,
            Ended::BadCrc => &mut self.crc_errors,
            Ended::BadReply => &mut self.bad_replies,
            Ended::Skipped => &mut self.skipped,
            Ended::LineDown => &mut self.line_errors,
        };
        *counter = counter.saturating_add(1);
        if matches!(ended, Ended::Replied | Ended::Exception(_)) {
            self.response_us.saturating_record(u64::try_from(took.as_micros()).unwrap_or(u64::MAX));
        }
    }
}

impl fmt::Display for Counters {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "requests {} replies {} timeouts {} crc-errors {} bad-replies {} skipped {} line-errors {} busy {} \
             broadcasts {} abandoned {} cached {}",
            self.requests,
            self.replies,
            self.timeouts,
            self.crc_errors,
            self.bad_replies,
            self.skipped,
            self.line_errors,
            self.busy,
            self.broadcasts,
            self.abandoned,
            self.cached
        )?;
        if !self.exceptions.is_empty() {
            f.write_str(" exceptions")?;
            for (code, n) in &self.exceptions {
                write!(f, " {code:02X}h:{n}")?;
            }
        }
        let h = &self.response_us;
        if !h.is_empty() {
            write!(
                f,
                " response-ms p50 {:.1} p99 {:.1} max {:.1}",
                ms(h.value_at_quantile(0.5)),
                ms(h.value_at_quantile(0.99)),
                ms(h.max())
            )?;
        }
        Ok(())
    }
}

#[expect(clippy::cast_precision_loss, reason = "a figure for people: µs well below 2^52")]
fn ms(us: u64) -> f64 {
    us as f64 / 1000.0
}

/// The requests the gateway put on one of its lines and how they ended, per unit, with the
/// line's queue and the replies its master dropped. (What a virtual wire carried, character by
/// character, is [`WireStats`](ferrobus::wire::WireStats).)
#[derive(Clone, Debug, Default)]
pub struct LineTraffic {
    /// The line, as its transport describes it.
    pub name: String,
    /// Every request on the line.
    pub total: Counters,
    /// Per unit, as the client addressed it.
    pub units: BTreeMap<u8, Counters>,
    /// Requests waiting in its queue now.
    pub queue_depth: usize,
    /// The deepest the queue has been.
    pub queue_max: usize,
    /// After a timeout, how long its reply is still awaited, the line kept closed
    /// ([`ClientConfig::late_window`](ferrobus::ClientConfig::late_window)); `None` on Modbus/TCP,
    /// whose transaction ids tell a late reply apart.
    pub late_window: Option<std::time::Duration>,
    /// Replies that came after their request had timed out, dropped by the line's master
    /// (never handed to the next request).
    pub late_replies: u64,
    /// Replies that began sooner after their request than any device may answer (stale
    /// ones), dropped.
    pub early_replies: u64,
    /// Replies far later than their unit usually answers, after an earlier reply of it never
    /// came, dropped as that late reply (never handed to the request waiting).
    pub suspect_replies: u64,
    /// Bytes found waiting in the port before a request, dropped.
    pub flushed_bytes: u64,
    /// Times the line's port was opened, or its TCP connection made (the first included).
    pub connects: u64,
    /// Opens or connection attempts that failed (a device down, a port missing).
    pub connect_failures: u64,
    /// Times an open port or connection was lost (closed by the device, a failed read).
    pub disconnects: u64,
    /// Times a device's TCP connection stalled (a timeout left half a reply behind, or
    /// [`STALLED_AFTER_TIMEOUTS`](ferrobus::STALLED_AFTER_TIMEOUTS) in a row) and was closed and
    /// made again.
    pub stalled: u64,
}

impl LineTraffic {
    /// Takes the line's client's counters of what it dropped.
    pub(crate) fn dropped(&mut self, seen: &ferrobus::ClientStats) {
        self.late_replies = u64::from(seen.master.late_replies);
        self.early_replies = u64::from(seen.master.early_replies);
        self.suspect_replies = u64::from(seen.master.suspect_replies);
        self.flushed_bytes = seen.flushed_bytes;
        self.connects = seen.connects;
        self.connect_failures = seen.connect_failures;
        self.disconnects = seen.disconnects;
        self.stalled = seen.stalled;
    }
}

impl fmt::Display for LineTraffic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "line {}: queue {} (max {}); {}; late-window {} late-replies {} early-replies {} suspect-replies {} \
             flushed-bytes {}; connects {} connect-failures {} disconnects {} stalled {}",
            self.name,
            self.queue_depth,
            self.queue_max,
            self.total,
            self.late_window.map_or_else(|| "none".to_string(), |w| format!("{w:?}")),
            self.late_replies,
            self.early_replies,
            self.suspect_replies,
            self.flushed_bytes,
            self.connects,
            self.connect_failures,
            self.disconnects,
            self.stalled
        )?;
        for (unit, counters) in &self.units {
            writeln!(f, "  unit {unit}: {counters}")?;
        }
        Ok(())
    }
}

/// What the front end refused before any line saw it ([`Malformed`]: why), over every
/// connection.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FrontStats {
    /// Requests refused, by reason.
    pub refused: BTreeMap<Malformed, u64>,
}

impl FrontStats {
    /// Counts one refusal.
    pub(crate) fn count(&mut self, reason: Malformed) {
        let n = self.refused.entry(reason).or_insert(0);
        *n = n.saturating_add(1);
    }

    /// Requests refused for `reason`.
    pub fn refused(&self, reason: Malformed) -> u64 {
        self.refused.get(&reason).copied().unwrap_or(0)
    }

    /// Requests refused in all.
    pub fn total(&self) -> u64 {
        self.refused.values().fold(0, |sum, n| sum.saturating_add(*n))
    }
}

/// `front: refused 3 (not-a-request 1, truncated 2)`, one line.
impl fmt::Display for FrontStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "front: refused {} invalid requests", self.total())?;
        let reasons: Vec<String> = self.refused.iter().map(|(reason, n)| format!("{reason} {n}")).collect();
        if !reasons.is_empty() {
            write!(f, " ({})", reasons.join(", "))?;
        }
        writeln!(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn front_stats_count_by_reason_and_show_each_with_the_total() {
        let mut front = FrontStats::default();
        assert_eq!(front.to_string(), "front: refused 0 invalid requests\n");
        front.count(Malformed::Truncated);
        front.count(Malformed::NotARequest);
        front.count(Malformed::Truncated);
        assert_eq!((front.refused(Malformed::Truncated), front.refused(Malformed::Reserved), front.total()), (2, 0, 3));
        assert_eq!(front.to_string(), "front: refused 3 invalid requests (not-a-request 1, truncated 2)\n");
    }
}
