//! `poll --metrics`: the poller on its status endpoint ([`ferrobus_tools::status`]), an
//! exporter of the values it reads.
//!
//! ```text
//!   ferrobus_poll_polls_total{group,unit}  poll_failures_total{group,unit,kind}
//!   poll_overruns_total{group,unit}  poll_skipped_total{group,unit}
//!   poll_sent_bytes_total{group,unit}  poll_received_bytes_total{group,unit}
//!   poll_response_seconds{unit}        a histogram: the polls a reply ended
//!   poll_up{group,unit}                1 if the group's last poll gave values, 0 if it failed
//!   poll_value{group,unit,point}       the engineering value of each numeric point, while up
//! ```
//!
//! A value is exported only while its group's last poll gave it: a group that fails drops
//! out of `poll_value` (Prometheus marks the series stale) and its `poll_up` says 0. The page
//! keeps showing the last value read, with when, marked stale.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::SystemTime;

use ferrobus_tools::poll::{Failure, FailureKind, Group, PollHandle, Reading, Sample, iso8601_ms};
use ferrobus_tools::status::{Family, Health, Labels, RESPONSE_BOUNDS, Source, Status, Table};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::DescriptorEncoder;

/// What each group's polls last gave.
#[derive(Clone, Debug, Default)]
pub(super) struct Latest {
    groups: Vec<GroupLatest>,
}

#[derive(Clone, Debug, Default)]
struct GroupLatest {
    /// The last values read, and when.
    values: Option<(SystemTime, Vec<Reading>)>,
    /// Whether the last poll failed, and how; `None` before the first poll.
    last: Option<Result<(), Failure>>,
}

impl Latest {
    /// Nothing polled yet, of `groups` groups.
    pub(super) fn new(groups: usize) -> Self {
        Latest { groups: vec![GroupLatest::default(); groups] }
    }

    /// What `sample` gave.
    pub(super) fn update(&mut self, sample: &Sample) {
        let Some(g) = self.groups.get_mut(sample.group) else { return };
        match &sample.result {
            Ok(readings) => {
                g.values = Some((sample.time, readings.clone()));
                g.last = Some(Ok(()));
            }
            Err(failure) => g.last = Some(Err(failure.clone())),
        }
    }

    /// The group's status (`ok`, a failure kind, or empty before its first poll) and its
    /// cells' last values as shown.
    pub(super) fn shown(&self, group: usize) -> (String, Vec<String>) {
        let Some(g) = self.groups.get(group) else { return Default::default() };
        let values = g.values.as_ref().map(|(_, r)| r.iter().map(|r| r.shown.clone()).collect()).unwrap_or_default();
        (status_name(g.last.as_ref()).to_string(), values)
    }
}

fn status_name(last: Option<&Result<(), Failure>>) -> &'static str {
    match last {
        None => "",
        Some(Ok(())) => "ok",
        Some(Err(f)) => f.kind.name(),
    }
}

/// The poller as its status endpoint shows it.
pub(super) struct PollStatus {
    pub(super) handle: PollHandle,
    pub(super) groups: Vec<Group>,
    pub(super) latest: Arc<Mutex<Latest>>,
    pub(super) summary: String,
}

impl std::fmt::Debug for PollStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PollStatus").field("summary", &self.summary).finish_non_exhaustive()
    }
}

impl PollStatus {
    fn latest(&self) -> Latest {
        self.latest.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

/// A group's labels: its name and its unit.
fn of(g: &Group) -> Labels<'_> {
    Labels::of(&[("group", g.name.as_str())]).with("unit", g.unit)
}

impl Collector for PollStatus {
    fn encode(&self, mut encoder: DescriptorEncoder<'_>) -> Result<(), std::fmt::Error> {
        let counters = self.handle.counters();
        let latest = self.latest();
        let mut out = Family::on(&mut encoder);
        let each = |get: fn(&ferrobus_tools::poll::Counters) -> u64| {
            self.groups.iter().zip(&counters).map(move |(g, c)| (of(g), get(c)))
        };
        out.counter("poll_polls", "Polls made.", each(|c| c.polls))?;
        out.counter(
            "poll_failures",
            "Polls that gave no values, by kind.",
            self.groups
                .iter()
                .zip(&counters)
                .flat_map(|(g, c)| FailureKind::ALL.iter().map(move |k| (of(g).with("kind", k.name()), c.of(*k)))),
        )?;
        out.counter("poll_overruns", "Polls that ended after their next was due.", each(|c| c.overruns))?;
        out.counter("poll_skipped", "Poll slots the overruns skipped.", each(|c| c.skipped))?;
        out.counter("poll_sent_bytes", "Bytes sent (unit and PDU).", each(|c| c.tx_bytes))?;
        out.counter("poll_received_bytes", "Bytes received (unit and PDU).", each(|c| c.rx_bytes))?;
        let histograms = self.handle.response_histograms();
        out.seconds_histogram(
            "poll_response",
            "From a request to its reply, for the polls a reply ended (values or an exception).",
            &RESPONSE_BOUNDS,
            histograms.iter().map(|(unit, h)| (Labels::none().with("unit", unit), h)),
        )?;
        let polled = || self.groups.iter().zip(&latest.groups).filter(|(_, l)| l.last.is_some());
        out.gauge(
            "poll_up",
            "1 if the group's last poll gave values, 0 if it failed.",
            polled().map(|(g, l)| (of(g), i64::from(matches!(l.last, Some(Ok(())))))),
        )?;
        out.gauge(
            "poll_value",
            "The engineering value of a numeric point, as its group's last poll read it.",
            polled().filter(|(_, l)| matches!(l.last, Some(Ok(())))).flat_map(|(g, l)| {
                let readings = l.values.as_ref().map(|(_, r)| r.as_slice()).unwrap_or_default();
                readings.iter().filter_map(move |r| {
                    let cell = g.cells.get(r.cell)?;
                    Some((of(g).with("point", &cell.name), r.scaled?))
                })
            }),
        )
    }
}

impl Source for PollStatus {
    fn status(&self) -> Status {
        let counters = self.handle.counters();
        let latest = self.latest();
        let mut groups = Table::new("Groups", &["group", "unit", "every", "status", "polls", "failed", "last ms"]);
        let mut values = Table::new("Values", &["group", "point", "value", "read at", "state"]);
        for ((g, c), l) in self.groups.iter().zip(&counters).zip(&latest.groups) {
            let status = match &l.last {
                Some(Err(f)) => format!("{}: {}", f.kind.name(), f.diagnosis),
                last => status_name(last.as_ref()).to_string(),
            };
            groups.rows.push(vec![
                g.name.clone(),
                g.unit.to_string(),
                format!("{:?}", g.every),
                status,
                c.polls.to_string(),
                c.failed().to_string(),
                c.last_response.map(|t| format!("{:.1}", t.as_secs_f64() * 1e3)).unwrap_or_default(),
            ]);
            let Some((at, readings)) = &l.values else { continue };
            let state = if matches!(l.last, Some(Ok(()))) { "ok" } else { "stale" };
            for r in readings {
                let Some(cell) = g.cells.get(r.cell) else { continue };
                values.rows.push(vec![
                    g.name.clone(),
                    cell.name.clone(),
                    r.shown.clone(),
                    iso8601_ms(*at),
                    state.to_string(),
                ]);
            }
        }
        Status { service: "poll".into(), summary: self.summary.clone(), tables: vec![groups, values] }
    }

    /// Failing while no group's last poll gave values (once every group has polled): the bus
    /// or the device is away.
    fn health(&self) -> Health {
        let latest = self.latest();
        let mut lasts = latest.groups.iter().map(|g| g.last.as_ref());
        if lasts.clone().any(|l| matches!(l, None | Some(Ok(())))) {
            return Health::Ok;
        }
        match lasts.find_map(|l| l.and_then(|r| r.as_ref().err())) {
            Some(f) => Health::Failing(format!("no group's last poll gave values ({})", f.diagnosis)),
            None => Health::Ok,
        }
    }
}
