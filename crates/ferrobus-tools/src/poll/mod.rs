//! The poller: read groups at their own rates over one [`Client`], for ever, and say what
//! each poll gave.
//!
//! ```text
//!   Group (unit, table, start, count, every, cells) ──┐
//!   Group ... ────────────────────────────────────────┼─▶ Poller ──▶ Event::Sample / Event::Overload
//!                         PollHandle: pause, resume, ─┘      │
//!                         reset, counters, write, stop       └─▶ Client (Client::in_flight requests at a time)
//! ```
//!
//! One task runs every group: it sleeps until the earliest deadline, reads, and hands out a
//! [`Sample`] — the decoded cells, or a [`Failure`] with its [`FailureKind`] and the
//! diagnosis. Nothing ends the polling but [`PollHandle::stop`] or dropping the [`Poller`]:
//! a timeout, an exception, a CRC error or a lost port is a sample like any other, and the
//! client reopens the port. Deadlines are kept by the core's
//! [`Schedule`]: from the start, not from the last poll,
//! so the rate does not drift; a poll that runs over the next deadline is an overrun and the
//! next one goes at once. A connection that carries several requests at once (a pipelined
//! Modbus/TCP one, [`Client::in_flight`]) gets that many groups under way, never two polls of
//! one group; on every other line one group is read at a time. When the line cannot carry
//! what was asked — predicted from the wire time of each request if the line's timing is
//! known, else seen at the first overrun — an [`Event::Overload`] says so once, with the
//! arithmetic. The t3.5 gaps are the client's pump's business; the poller never writes to the
//! port itself.

mod group;
pub mod session;
mod stats;

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, SystemTime};

use ferrobus_proto::frame::LineTiming;
use ferrobus_proto::pdu::{ReadBits, ReadRegisters, Request, Response};
use ferrobus_proto::schedule::{Completion, READ_REQUEST_CHARS, Schedule, read_reply_chars, wire_time};
use ferrobus_proto::time::Instant as CoreInstant;
use futures_util::StreamExt;
use futures_util::stream::FuturesUnordered;
use hdrhistogram::Histogram;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

pub use ferrobus_profile::{Order, Point, Profile, Table, Value};
pub(crate) use group::name_of;
pub use group::{Cell, Format, Group, GroupError, Layout, RawRange, max_count};
pub use stats::{Counters, FailureKind, UnitTimes};

use ferrobus::client::Client;
use ferrobus::error::Error;
use stats::Stats;

/// What one poll gave.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// The group polled (its index in the poller's groups).
    pub group: usize,
    /// The group's poll number, from 0.
    pub seq: u64,
    /// The wall-clock time the poll ended.
    pub time: SystemTime,
    /// When it was due, from the poller's start.
    pub due: Duration,
    /// When it started, from the poller's start (after `due` when the bus was busy).
    pub started: Duration,
    /// From the request to its outcome.
    pub response_time: Duration,
    /// Whether it ended after the group's next poll was due.
    pub overrun: bool,
    /// The cells, or why there are none.
    pub result: Result<Vec<Reading>, Failure>,
    /// The request and the reply.
    pub traffic: Traffic,
}

/// One cell's value in a sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Reading {
    /// The cell (its index in the group's cells).
    pub cell: usize,
    /// The raw value, or why the registers decode to none.
    pub raw: Result<Value, String>,
    /// The engineering value (raw × scale + offset), for a number.
    pub scaled: Option<f64>,
    /// The value as shown (`50.00 Hz`, `0x01F4`, `run`).
    pub shown: String,
}

/// The bytes of one transaction: the unit and the PDU each way (without the CRC or MBAP
/// header the framing adds).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Unit, then the request PDU.
    pub tx: Vec<u8>,
    /// Unit, then the reply PDU (an exception reply too); `None` when none came.
    pub rx: Option<Vec<u8>>,
}

/// A poll that gave no values.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Failure {
    /// What kind of failure.
    pub kind: FailureKind,
    /// The exception code, for [`FailureKind::Exception`].
    pub exception: Option<u8>,
    /// What was seen, in words (the client's error).
    pub diagnosis: String,
}

impl Failure {
    /// The failure of a client's error.
    pub fn of(error: &Error) -> Failure {
        Failure {
            kind: FailureKind::of(error),
            exception: error.exception().map(ferrobus_proto::ExceptionCode::value),
            diagnosis: error.to_string(),
        }
    }
}

/// The line cannot carry what was asked.
#[derive(Clone, Debug, PartialEq)]
pub struct Overload {
    /// Wire time (predicted) or response time (seen) of one cycle of the groups, per second
    /// of polling: more than 1 s means the line cannot keep up.
    pub load: Duration,
    /// The arithmetic, in words.
    pub detail: String,
    /// Whether it was seen (an overrun) rather than predicted from the line's timing.
    pub seen: bool,
}

/// What the poller hands out.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A poll's outcome.
    Sample(Sample),
    /// Said once: the line cannot carry what was asked; polling goes on as fast as it can.
    Overload(Overload),
}

/// Settings of a poller.
#[derive(Clone, Copy, Debug, Default)]
pub struct PollConfig {
    /// The line's timing, when it is a serial line: the wire time of each group is checked
    /// against its period before polling starts.
    pub line: Option<LineTiming>,
    /// Hand out each cell's raw value only ([`Reading::scaled`] `None`, [`Reading::shown`]
    /// empty), for a consumer that scales and shows through the group's cells itself, and
    /// only what it needs (the bridge: a deadband's comparison, the latest value on its
    /// status page): showing every cell of every poll is a large share of a fast poller's
    /// own cost (`bench/BRIDGE.md`).
    pub raw_only: bool,
}

/// A handle to a running poller. Clone it freely.
#[derive(Clone, Debug)]
pub struct PollHandle {
    shared: Arc<Shared>,
    client: Client,
}

#[derive(Debug)]
struct Shared {
    groups: Vec<Group>,
    stats: Mutex<Stats>,
    paused: watch::Sender<bool>,
    stop: watch::Sender<bool>,
}

/// The running poller: its events, and a handle.
#[derive(Debug)]
pub struct Poller {
    events: mpsc::Receiver<Event>,
    handle: PollHandle,
}

pub use crate::write::WriteError;

impl Poller {
    /// Starts polling `groups` through `client` on the current tokio runtime.
    /// [`PollHandle::stop`] ends it before the next deadline; dropping the poller ends it at
    /// the next poll, whose sample has nowhere to go.
    pub fn start(client: Client, groups: Vec<Group>, config: PollConfig) -> Poller {
        let (events_tx, events) = mpsc::channel(1024);
        let (paused, _) = watch::channel(false);
        let (stop, _) = watch::channel(false);
        let shared = Arc::new(Shared { stats: Mutex::new(Stats::new(&groups)), groups, paused, stop });
        let handle = PollHandle { shared, client };
        tokio::spawn(run(handle.clone(), config, events_tx));
        Poller { events, handle }
    }

    /// The next event; `None` once the poller has stopped and every event was taken.
    pub async fn next(&mut self) -> Option<Event> {
        self.events.recv().await
    }

    /// An event if one is ready.
    pub fn try_next(&mut self) -> Option<Event> {
        self.events.try_recv().ok()
    }

    /// A handle for control and counters.
    pub fn handle(&self) -> PollHandle {
        self.handle.clone()
    }
}

impl PollHandle {
    /// The groups polled.
    pub fn groups(&self) -> &[Group] {
        &self.shared.groups
    }

    /// Stops polling before the next deadline (a poll in flight is abandoned, not reported).
    pub fn stop(&self) {
        self.shared.stop.send_replace(true);
    }

    /// Stops polling until [`resume`](Self::resume); a poll in flight finishes.
    pub fn pause(&self) {
        self.shared.paused.send_replace(true);
    }

    /// Polls again, every group at once and then on a schedule from now.
    pub fn resume(&self) {
        self.shared.paused.send_replace(false);
    }

    /// Whether it is paused.
    pub fn is_paused(&self) -> bool {
        *self.shared.paused.borrow()
    }

    /// Sets every counter and response time to zero.
    pub fn reset(&self) {
        self.stats().reset();
    }

    /// The counters of each group, in group order.
    pub fn counters(&self) -> Vec<Counters> {
        self.stats().counters.clone()
    }

    /// Response times per unit (successful polls and exceptions: the polls a reply ended).
    pub fn response_times(&self) -> Vec<UnitTimes> {
        self.stats().unit_times()
    }

    /// The histogram of those response times per unit, in µs (two significant figures), for
    /// an exporter's buckets.
    pub fn response_histograms(&self) -> Vec<(u8, Histogram<u64>)> {
        self.stats().histograms()
    }

    /// Writes `text` to a cell, as its point parses it (`45 Hz`, `run`, `0x10`), with
    /// [`crate::write::write_point`] and `profile`, the one the cells' points came from: the
    /// point's range and access, the device's functions and write limit, and for a run-locked
    /// point the drive's running point read first. `None` for cells of raw ranges, which have
    /// no profile: range and access only, the spec's functions. Returns the raw value written.
    pub async fn write(
        &self,
        profile: Option<&Profile>,
        group: usize,
        cell: usize,
        text: &str,
    ) -> Result<Value, WriteError> {
        let raw = self.prepare_write(group, cell, text)?;
        let (g, c) = self.cell(group, cell)?;
        let write = ferrobus_profile::Write { point: &c.point, raw: &raw, typed: text };
        crate::write::write_point(&self.client, g.unit, profile, &write, false).await?;
        Ok(raw)
    }

    /// The raw value that writing `text` to a cell would write, checked against the point's
    /// range and access; nothing is sent.
    pub fn prepare_write(&self, group: usize, cell: usize, text: &str) -> Result<Value, WriteError> {
        let (_, c) = self.cell(group, cell)?;
        Ok(c.point.prepare_write(text)?)
    }

    /// Writes the raw value `raw` to a cell in the one request [`Point::wire_write`] chooses
    /// with `profile`'s functions and write limit (the spec's without one). The write guard is
    /// the caller's to apply first ([`Profile::plan_write`] with the run state it read, as a
    /// bridge command does for all its writes at once); a value that does not fit the point's
    /// type or one request is refused.
    ///
    /// [`Point::wire_write`]: ferrobus_profile::Point::wire_write
    pub async fn write_raw(
        &self,
        profile: Option<&Profile>,
        group: usize,
        cell: usize,
        raw: &Value,
    ) -> Result<(), WriteError> {
        let (g, c) = self.cell(group, cell)?;
        let rules = profile.map_or(ferrobus_profile::WriteRules::SPEC, Profile::write_rules);
        let request = c.point.wire_write(raw, &rules)?;
        crate::write::send(&self.client, g.unit, &request).await?;
        Ok(())
    }

    fn cell(&self, group: usize, cell: usize) -> Result<(&Group, &Cell), WriteError> {
        let g = self.shared.groups.get(group).ok_or(WriteError::NoSuchCell { group, cell })?;
        let c = g.cells.get(cell).ok_or(WriteError::NoSuchCell { group, cell })?;
        Ok((g, c))
    }

    fn stats(&self) -> std::sync::MutexGuard<'_, Stats> {
        self.shared.stats.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The predicted overload of `groups` on a line with `timing`, if their wire time per second
/// exceeds a second.
pub fn predict_overload(groups: &[Group], timing: &LineTiming) -> Option<Overload> {
    let mut load = Duration::ZERO;
    let mut parts = Vec::new();
    for g in groups {
        let reply = read_reply_chars(g.count, g.table.is_bits());
        let wire = wire_time(timing, READ_REQUEST_CHARS, reply);
        let per_second = if g.every.is_zero() {
            Duration::MAX
        } else {
            Duration::from_secs_f64(wire.as_secs_f64() / g.every.as_secs_f64())
        };
        load = load.saturating_add(per_second);
        parts.push(format!(
            "{}: ({READ_REQUEST_CHARS} + {reply}) characters × {:.3} ms + 2 × t3.5 {:.3} ms = {:.3} ms of wire time every {:.3} ms",
            g.name,
            ms(timing.char_time()),
            ms(timing.t3_5()),
            ms(wire),
            ms(g.every)
        ));
    }
    (load > Duration::from_secs(1)).then(|| Overload {
        load,
        detail: format!(
            "the line cannot carry this: {}; that is {:.1} ms of wire time per second of polling; \
             polling as fast as the line allows and counting overruns",
            parts.join("; "),
            ms(load)
        ),
        seen: false,
    })
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn core(epoch: Instant, t: Instant) -> CoreInstant {
    CoreInstant::from_nanos(u64::try_from(t.saturating_duration_since(epoch).as_nanos()).unwrap_or(u64::MAX))
}

fn tokio_at(epoch: Instant, t: CoreInstant) -> Instant {
    epoch.checked_add(t.since_epoch()).unwrap_or_else(|| epoch + Duration::from_secs(86_400 * 365 * 30))
}

/// A poll that has ended: its group, when it was due, started and ended, and what it gave.
struct Polled {
    index: usize,
    due: CoreInstant,
    started: Instant,
    ended: Instant,
    result: Result<Vec<Reading>, Failure>,
    traffic: Traffic,
}

async fn run(handle: PollHandle, config: PollConfig, events: mpsc::Sender<Event>) {
    let shared = Arc::clone(&handle.shared);
    let mut stop = shared.stop.subscribe();
    let mut paused = shared.paused.subscribe();
    let epoch = Instant::now();
    let mut schedules: Vec<Schedule> =
        shared.groups.iter().map(|g| Schedule::new(CoreInstant::ZERO, g.every)).collect();
    let mut seqs = vec![0u64; shared.groups.len()];
    let mut said = false;
    if let Some(overload) = config.line.as_ref().and_then(|t| predict_overload(&shared.groups, t)) {
        said = true;
        if events.send(Event::Overload(overload)).await.is_err() {
            return;
        }
    }
    // As many polls under way as the connection carries (one but on a pipelined Modbus/TCP
    // connection), never two of one group: the groups not under way wait in `idle`.
    let in_flight = handle.client.in_flight().max(1);
    let mut idle = by_deadline(&schedules);
    let launch = |index: usize, due: CoreInstant| {
        poll_group(&handle.client, shared.groups.get(index), index, due, config.raw_only)
    };
    let mut flying = FuturesUnordered::new();
    loop {
        if *stop.borrow() {
            return;
        }
        let pausing = *paused.borrow_and_update();
        if pausing && flying.is_empty() {
            tokio::select! {
                _ = paused.changed() => {}
                _ = stop.changed() => return,
            }
            if !*paused.borrow() {
                let now = core(epoch, Instant::now());
                for (s, g) in schedules.iter_mut().zip(&shared.groups) {
                    *s = Schedule::new(now, g.every);
                }
                idle = by_deadline(&schedules);
            }
            continue;
        }
        let next = (!pausing && flying.len() < in_flight).then(|| idle.peek().map(|&Reverse(next)| next)).flatten();
        if next.is_none() && flying.is_empty() {
            // No groups: wait to be stopped.
            let _ = stop.changed().await;
            return;
        }
        let at = next.map(|(due, _)| tokio_at(epoch, due));
        // A group already due starts without a timer: under load, every one is.
        if let Some(((due, index), at)) = next.zip(at)
            && at <= Instant::now()
        {
            idle.pop();
            flying.push(launch(index, due));
            continue;
        }
        let done = tokio::select! {
            Some(done) = flying.next(), if !flying.is_empty() => done,
            () = sleep_until_some(at) => {
                if let Some((due, index)) = next {
                    idle.pop();
                    flying.push(launch(index, due));
                }
                continue;
            }
            _ = stop.changed() => return,
            _ = paused.changed() => continue,
        };
        let (Some(group), Some(schedule)) = (shared.groups.get(done.index), schedules.get_mut(done.index)) else {
            return;
        };
        let completion = schedule.complete(core(epoch, done.ended));
        idle.push(Reverse((schedule.deadline(), done.index)));
        let seq = seqs.get(done.index).copied().unwrap_or(0);
        if let Some(s) = seqs.get_mut(done.index) {
            *s = s.saturating_add(1);
        }
        let sample = done.sample(seq, completion, epoch);
        handle.stats().record(
            sample.group,
            group.unit,
            &sample.result,
            sample.response_time,
            completion,
            &sample.traffic,
        );
        if completion.overrun && !said {
            said = true;
            if events.send(Event::Overload(overrun(group, &sample))).await.is_err() {
                return;
            }
        }
        if events.send(Event::Sample(sample)).await.is_err() {
            return;
        }
    }
}

impl Polled {
    /// The sample of poll `seq` of its group, which did `completion` to the schedule.
    fn sample(self, seq: u64, completion: Completion, epoch: Instant) -> Sample {
        Sample {
            group: self.index,
            seq,
            time: SystemTime::now(),
            due: self.due.since_epoch(),
            started: self.started.saturating_duration_since(epoch),
            response_time: self.ended.saturating_duration_since(self.started),
            overrun: completion.overrun,
            result: self.result,
            traffic: self.traffic,
        }
    }
}

/// The first overrun, said once: `sample` of `group` ended past its next deadline.
fn overrun(group: &Group, sample: &Sample) -> Overload {
    let ended = sample.started.saturating_add(sample.response_time);
    Overload {
        load: sample.response_time,
        detail: format!(
            "the line cannot keep up: poll {} of {} was due at {:.3} ms and ended at {:.3} ms, past the next deadline \
             (period {:.3} ms; its own request took {:.3} ms); polling as fast as the line allows and counting \
             overruns",
            sample.seq,
            group.name,
            ms(sample.due),
            ms(ended),
            ms(group.every),
            ms(sample.response_time)
        ),
        seen: true,
    }
}

/// Every group by its next deadline, the earliest first (the lower index first among equals).
fn by_deadline(schedules: &[Schedule]) -> BinaryHeap<Reverse<(CoreInstant, usize)>> {
    schedules.iter().enumerate().map(|(i, s)| Reverse((s.deadline(), i))).collect()
}

/// Polls `group` (poller group `index`, due at `due`) once.
async fn poll_group(client: &Client, group: Option<&Group>, index: usize, due: CoreInstant, raw_only: bool) -> Polled {
    let started = Instant::now();
    let (result, traffic) = match group {
        Some(group) => poll_once(client, group, raw_only).await,
        None => (Err(Failure::of(&Error::Closed)), Traffic::default()),
    };
    Polled { index, due, started, ended: Instant::now(), result, traffic }
}

/// Sleeps until `at`, or for ever without one.
async fn sleep_until_some(at: Option<Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// Reads a group once: its readings (raw values only, if `raw_only`) or the failure, and the
/// traffic.
async fn poll_once(client: &Client, group: &Group, raw_only: bool) -> (Result<Vec<Reading>, Failure>, Traffic) {
    let request = match group.table {
        Table::Coils => ReadBits::new(group.start, group.count).map(Request::ReadCoils),
        Table::DiscreteInputs => ReadBits::new(group.start, group.count).map(Request::ReadDiscreteInputs),
        Table::Holding => ReadRegisters::new(group.start, group.count).map(Request::ReadHoldingRegisters),
        Table::Input => ReadRegisters::new(group.start, group.count).map(Request::ReadInputRegisters),
    };
    let request = match request {
        Ok(r) => r,
        Err(e) => return (Err(Failure::of(&Error::InvalidRequest(e))), Traffic::default()),
    };
    // The unit, then the request's PDU, encoded in place.
    let mut tx = vec![group.unit; 1 + request.encoded_len()];
    let encoded = tx.get_mut(1..).and_then(|pdu| request.emit(pdu).ok()).unwrap_or(0);
    tx.truncate(1 + encoded);
    let reply = client.request(group.unit, &request).await;
    match reply {
        Ok(Some(reply)) => {
            let mut rx = vec![group.unit];
            rx.extend_from_slice(&reply);
            let traffic = Traffic { tx, rx: Some(rx) };
            let Some(items) = items(&reply, group.count) else {
                let failure = Failure {
                    kind: FailureKind::BadReply,
                    exception: None,
                    diagnosis: format!("the reply to unit {} carried no {} items", group.unit, group.count),
                };
                return (Err(failure), traffic);
            };
            let readings = if raw_only { group.raw_readings(&items) } else { group.readings(&items) };
            (Ok(readings), traffic)
        }
        Ok(None) => {
            let failure = Failure {
                kind: FailureKind::BadReply,
                exception: None,
                diagnosis: format!("unit {} is a broadcast: nothing answers a read", group.unit),
            };
            (Err(failure), Traffic { tx, rx: None })
        }
        Err(e) => {
            let rx = match &e {
                Error::Exception { unit, function, code } => Some(vec![*unit, function.value() | 0x80, code.value()]),
                _ => None,
            };
            (Err(Failure::of(&e)), Traffic { tx, rx })
        }
    }
}

impl Group {
    /// The readings of the items a read returned (registers, or bits as 0/1, from
    /// [`Group::start`]): each cell's raw value decoded ([`Group::decode`]), scaled and shown
    /// as its point says. The one decoding of a poll's reply, and of a reply heard by the
    /// sniffer ([`crate::sniff::Heard`]).
    pub fn readings(&self, items: &[u16]) -> Vec<Reading> {
        self.decoded(items)
            .enumerate()
            .map(|(cell, raw)| {
                let (scaled, shown) = match (&raw, self.cells.get(cell)) {
                    (Ok(v), Some(c)) => (c.scaled(v), c.show(v)),
                    (Err(e), _) => (None, e.clone()),
                    (Ok(v), None) => (None, v.to_string()),
                };
                Reading { cell, raw, scaled, shown }
            })
            .collect()
    }

    /// [`Group::readings`] without the scaling and showing: each cell's raw value, or why its
    /// registers decode to none (in `shown`).
    pub fn raw_readings(&self, items: &[u16]) -> Vec<Reading> {
        let reading = |(cell, raw): (usize, Result<Value, String>)| match raw {
            Ok(v) => Reading { cell, raw: Ok(v), scaled: None, shown: String::new() },
            Err(e) => Reading { cell, shown: e.clone(), raw: Err(e), scaled: None },
        };
        self.decoded(items).enumerate().map(reading).collect()
    }
}

/// The `count` items of a reply to a read (the PDU): registers, or bits as 0/1; `None` for
/// any other reply or another count.
pub(crate) fn items(reply: &[u8], count: u16) -> Option<Vec<u16>> {
    let response = Response::parse(reply).ok()?;
    let count = usize::from(count);
    match response {
        Response::ReadCoils(v) | Response::ReadDiscreteInputs(v) => {
            let bits: Vec<u16> = v.values().iter().take(count).map(u16::from).collect();
            (bits.len() == count).then_some(bits)
        }
        Response::ReadHoldingRegisters(v) | Response::ReadInputRegisters(v) => {
            let words: Vec<u16> = v.values().iter().collect();
            (words.len() == count).then_some(words)
        }
        _ => None,
    }
}

/// `time` in ISO 8601, UTC, to the millisecond: `2026-12-01T22:52:28.123Z`.
pub fn iso8601_ms(time: SystemTime) -> String {
    let since = time.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    format!("{}.{:03}Z", civil(since.as_secs()), since.subsec_millis())
}

/// `time` in ISO 8601, UTC, to the second: `2026-12-01T22:52:28Z`.
pub fn iso8601(time: SystemTime) -> String {
    let since = time.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    format!("{}Z", civil(since.as_secs()))
}

/// Seconds since 1970 as `YYYY-MM-DDTHH:MM:SS` (Howard Hinnant's days-from-civil, inverted).
fn civil(secs: u64) -> String {
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}", rem / 3600, rem % 3600 / 60, rem % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_are_iso_8601_utc_to_the_millisecond_or_the_second() {
        let t = SystemTime::UNIX_EPOCH + Duration::from_millis(1_796_165_548_123);
        assert_eq!(iso8601_ms(t), "2026-12-01T22:52:28.123Z");
        assert_eq!(iso8601_ms(SystemTime::UNIX_EPOCH), "1970-01-01T00:00:00.000Z");
        let leap = SystemTime::UNIX_EPOCH + Duration::from_secs(951_782_400);
        assert_eq!(iso8601_ms(leap), "2000-02-29T00:00:00.000Z");
        assert_eq!(iso8601(t), "2026-12-01T22:52:28Z");
        assert_eq!(iso8601(leap), "2000-02-29T00:00:00Z");
    }

    #[test]
    fn a_period_shorter_than_the_wire_time_is_predicted_with_the_arithmetic() {
        use ferrobus_proto::frame::LineConfig;
        let timing = LineTiming::new(&LineConfig::new(9600).expect("a baud rate"));
        let layout = Layout::default();
        let g =
            Group::raw("g", RawRange { count: 4, every: Duration::from_millis(20), ..RawRange::default() }, &layout)
                .expect("a group");
        let o = predict_overload(std::slice::from_ref(&g), &timing).expect("32 ms of wire time every 20 ms");
        assert!(!o.seen);
        assert!(o.detail.contains("(8 + 13) characters × 1.146 ms + 2 × t3.5 4.010 ms = 32.083 ms"), "{}", o.detail);
        assert!(o.detail.contains("every 20.000 ms"), "{}", o.detail);
        let slow = Group { every: Duration::from_millis(40), ..g };
        assert_eq!(predict_overload(&[slow], &timing), None);
    }
}
