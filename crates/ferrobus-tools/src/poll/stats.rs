//! The poller's counters: per group, by failure kind, and response times per unit.

use std::collections::BTreeMap;
use std::time::Duration;

use ferrobus_proto::master::HeardInstead;
use ferrobus_proto::schedule::Completion;
use hdrhistogram::Histogram;

use super::{Failure, Group, Reading, Traffic};
use ferrobus::error::Error;

/// What kind of failure a poll had.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub enum FailureKind {
    /// Silence, or another unit's or function's frame, until the timeout.
    Timeout,
    /// A reply came with a wrong checksum (CRC or LRC), and no good one.
    Crc,
    /// Bytes came that made no frame, and no good reply.
    Garbage,
    /// The device refused with an exception.
    Exception,
    /// A reply came that did not answer the read.
    BadReply,
    /// The port or connection failed (it is reopened for the next poll).
    Port,
    /// The unit is skipped for a while after failing repeatedly.
    Backoff,
    /// Anything else (the client stopped, an invalid request).
    Other,
}

impl FailureKind {
    /// Every kind, in order.
    pub const ALL: [FailureKind; 8] = [
        FailureKind::Timeout,
        FailureKind::Crc,
        FailureKind::Garbage,
        FailureKind::Exception,
        FailureKind::BadReply,
        FailureKind::Port,
        FailureKind::Backoff,
        FailureKind::Other,
    ];

    /// Its name in records: `timeout`, `crc`, `garbage`, `exception`, `bad-reply`, `port`,
    /// `backoff`, `other`.
    pub const fn name(self) -> &'static str {
        match self {
            FailureKind::Timeout => "timeout",
            FailureKind::Crc => "crc",
            FailureKind::Garbage => "garbage",
            FailureKind::Exception => "exception",
            FailureKind::BadReply => "bad-reply",
            FailureKind::Port => "port",
            FailureKind::Backoff => "backoff",
            FailureKind::Other => "other",
        }
    }

    /// The kind of a client's error.
    pub fn of(error: &Error) -> FailureKind {
        match error {
            Error::Timeout { heard: Some(HeardInstead::BadChecksum { .. }), .. } => FailureKind::Crc,
            Error::Timeout { heard: Some(HeardInstead::Garbage { .. }), .. } => FailureKind::Garbage,
            Error::Timeout { .. } => FailureKind::Timeout,
            Error::Exception { .. } => FailureKind::Exception,
            Error::BadReply { .. } | Error::NoReply { .. } => FailureKind::BadReply,
            Error::Io { .. } | Error::NotSameDevice { .. } => FailureKind::Port,
            Error::Backoff { .. } => FailureKind::Backoff,
            _ => FailureKind::Other,
        }
    }
}

/// The counters of one group.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Polls made.
    pub polls: u64,
    /// Polls that gave values.
    pub ok: u64,
    /// Failed polls by kind (kinds that never happened are absent).
    pub failures: BTreeMap<FailureKind, u64>,
    /// Polls that ended after the next was due.
    pub overruns: u64,
    /// Slots the overruns skipped.
    pub skipped: u64,
    /// The last poll's response time.
    pub last_response: Option<Duration>,
    /// Bytes sent (unit and PDU; the framing adds its own).
    pub tx_bytes: u64,
    /// Bytes received (unit and PDU).
    pub rx_bytes: u64,
}

impl Counters {
    /// Failed polls of every kind.
    pub fn failed(&self) -> u64 {
        self.failures.values().sum()
    }

    /// Failed polls of `kind`.
    pub fn of(&self, kind: FailureKind) -> u64 {
        self.failures.get(&kind).copied().unwrap_or(0)
    }
}

/// Response times of one unit: the polls a reply ended (values or an exception).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnitTimes {
    /// The unit.
    pub unit: u8,
    /// Replies timed.
    pub count: u64,
    /// The median.
    pub p50: Duration,
    /// The 99th percentile.
    pub p99: Duration,
    /// The longest.
    pub max: Duration,
}

#[derive(Debug)]
pub(super) struct Stats {
    pub(super) counters: Vec<Counters>,
    times: BTreeMap<u8, Option<Histogram<u64>>>,
}

impl Stats {
    pub(super) fn new(groups: &[Group]) -> Stats {
        Stats { counters: vec![Counters::default(); groups.len()], times: BTreeMap::new() }
    }

    pub(super) fn reset(&mut self) {
        for c in &mut self.counters {
            *c = Counters::default();
        }
        self.times.clear();
    }

    pub(super) fn record(
        &mut self,
        group: usize,
        unit: u8,
        result: &Result<Vec<Reading>, Failure>,
        response_time: Duration,
        completion: Completion,
        traffic: &Traffic,
    ) {
        let Some(c) = self.counters.get_mut(group) else { return };
        c.polls = c.polls.saturating_add(1);
        c.last_response = Some(response_time);
        c.tx_bytes = c.tx_bytes.saturating_add(traffic.tx.len() as u64);
        c.rx_bytes = c.rx_bytes.saturating_add(traffic.rx.as_ref().map_or(0, |rx| rx.len() as u64));
        if completion.overrun {
            c.overruns = c.overruns.saturating_add(1);
            c.skipped = c.skipped.saturating_add(completion.skipped);
        }
        let replied = match result {
            Ok(_) => {
                c.ok = c.ok.saturating_add(1);
                true
            }
            Err(f) => {
                let n = c.failures.entry(f.kind).or_insert(0);
                *n = n.saturating_add(1);
                f.kind == super::FailureKind::Exception
            }
        };
        if replied {
            let micros = u64::try_from(response_time.as_micros()).unwrap_or(u64::MAX).max(1);
            if let Some(h) = self.times.entry(unit).or_insert_with(new_histogram).as_mut() {
                h.saturating_record(micros);
            }
        }
    }

    pub(super) fn histograms(&self) -> Vec<(u8, Histogram<u64>)> {
        self.times.iter().filter_map(|(unit, h)| Some((*unit, h.clone()?))).collect()
    }

    pub(super) fn unit_times(&self) -> Vec<UnitTimes> {
        self.times
            .iter()
            .filter_map(|(unit, h)| {
                let h = h.as_ref()?;
                let us = |v: u64| Duration::from_micros(v);
                Some(UnitTimes {
                    unit: *unit,
                    count: h.len(),
                    p50: us(h.value_at_quantile(0.5)),
                    p99: us(h.value_at_quantile(0.99)),
                    max: us(h.max()),
                })
            })
            .collect()
    }
}

/// Microseconds from 1 µs to an hour, two significant figures: a p99 within 1 % is all a
/// summary shows, and it keeps a unit's histogram at about 27 KB (three figures took 188 KB,
/// most of a bridge's memory with a hundred units).
fn new_histogram() -> Option<Histogram<u64>> {
    Histogram::new_with_bounds(1, 3_600_000_000, 2).ok()
}
