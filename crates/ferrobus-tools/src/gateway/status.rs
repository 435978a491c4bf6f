//! The gateway on its status endpoint ([`crate::status`]): the counters it keeps per line
//! and unit, its front end's refusals and its listener's counts as metrics, each unit's
//! health over the last few seconds, and its summary with what reloads did to it
//! ([`Summary`]: the lines as the file applied last names them).
//!
//! Metrics (under `ferrobus_`; `line` is the line's number, `unit` the unit as clients
//! address it):
//!
//! ```text
//!   gateway_requests_total{line,unit}  gateway_replies_total  gateway_timeouts_total
//!   gateway_crc_errors_total  gateway_bad_replies_total  gateway_skipped_total
//!   gateway_line_errors_total  gateway_busy_total  gateway_broadcasts_total
//!   gateway_cached_total  gateway_abandoned_total
//!   gateway_exceptions_total{line,unit,code}          code as 0x02
//!   gateway_response_seconds{line,unit}               a histogram, 5 ms to 10 s
//!   gateway_queue_depth{line}  gateway_queue_max{line}           gauges
//!   gateway_late_replies_total{line}  gateway_early_replies_total  gateway_suspect_replies_total
//!   gateway_connects_total{line}  gateway_connect_failures_total  gateway_disconnects_total
//!   gateway_refused_total{reason}                     the front end's, before any line
//!   tcp_connections_accepted_total  tcp_connections_open  tcp_refused_total{reason}
//!   tcp_closed_total{reason}  tcp_tls_refused_total  tcp_denied_total
//! ```

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use ferrobus::server::TcpStats;
use prometheus_client::collector::Collector;
use prometheus_client::encoding::DescriptorEncoder;

use super::Gateway;
use super::stats::{Counters, LineTraffic};
use crate::status::{self, Family, Health, Labels, Source, Status, Summary, Table};

/// A counter of `T`: its name, its help, and how to read it.
type Count<T> = (&'static str, &'static str, fn(&T) -> u64);

/// How long a unit's health looks back: its requests over at least this long.
const WINDOW: Duration = Duration::from_secs(2);

/// The gateway as its status endpoint shows it.
pub struct GatewayStatus {
    gateway: Gateway,
    tcp: Arc<TcpStats>,
    summary: Arc<Mutex<Summary>>,
    window: Mutex<Window>,
}

/// Each unit's counts at the start of the window, and the health found at its end.
#[derive(Debug, Default)]
struct Window {
    since: Option<Instant>,
    seen: BTreeMap<(usize, u8), Tally>,
    health: BTreeMap<(usize, u8), &'static str>,
}

/// What a unit's counters say of it: requests, answers (data, exceptions, broadcasts) and
/// failures (silence, bad CRCs, bad replies, backoff, a port down).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Tally {
    requests: u64,
    answered: u64,
    failed: u64,
}

impl Tally {
    fn of(c: &Counters) -> Self {
        let exceptions = c.exceptions.values().fold(0u64, |sum, n| sum.saturating_add(*n));
        Tally {
            requests: c.requests,
            answered: c.replies.saturating_add(exceptions).saturating_add(c.broadcasts),
            failed: [c.timeouts, c.crc_errors, c.bad_replies, c.skipped, c.line_errors]
                .iter()
                .fold(0u64, |sum, n| sum.saturating_add(*n)),
        }
    }

    /// The health these counts show since `before`: `ok` (answering), `failing` (answering
    /// some), `silent` (asked, never answering), `idle` (not asked).
    fn health(self, before: Tally) -> &'static str {
        let answered = self.answered.saturating_sub(before.answered);
        let failed = self.failed.saturating_sub(before.failed);
        match (self.requests.saturating_sub(before.requests), answered, failed) {
            (0, _, _) => "idle",
            (_, 0, 1..) => "silent",
            (_, _, 1..) => "failing",
            _ => "ok",
        }
    }
}

impl std::fmt::Debug for GatewayStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let summary = self.summary.lock().unwrap_or_else(PoisonError::into_inner).clone();
        f.debug_struct("GatewayStatus").field("summary", &summary).finish_non_exhaustive()
    }
}

impl GatewayStatus {
    /// `gateway`, with its listener's counts `tcp`, described by `summary` (what it listens on,
    /// its lines), which the gateway's reloads bring up to date.
    pub fn new(gateway: Gateway, tcp: Arc<TcpStats>, summary: Arc<Mutex<Summary>>) -> Self {
        GatewayStatus { gateway, tcp, summary, window: Mutex::new(Window::default()) }
    }

    /// Each unit's health, the window moved on if it is old enough.
    fn unit_health(&self, lines: &[LineTraffic]) -> BTreeMap<(usize, u8), &'static str> {
        let mut window = self.window.lock().unwrap_or_else(PoisonError::into_inner);
        let now = Instant::now();
        let due = window.since.is_none_or(|since| now.duration_since(since) >= WINDOW);
        if due {
            let seen: BTreeMap<(usize, u8), Tally> = lines
                .iter()
                .enumerate()
                .flat_map(|(i, line)| line.units.iter().map(move |(unit, c)| ((i, *unit), Tally::of(c))))
                .collect();
            if window.since.is_some() {
                let health = seen
                    .iter()
                    .map(|(key, now)| (*key, now.health(window.seen.get(key).copied().unwrap_or_default())))
                    .collect();
                window.health = health;
            }
            window.since = Some(now);
            window.seen = seen;
        }
        window.health.clone()
    }
}

impl Collector for GatewayStatus {
    fn encode(&self, mut encoder: DescriptorEncoder<'_>) -> Result<(), std::fmt::Error> {
        let lines = self.gateway.stats();
        let names: Vec<String> = (0..lines.len()).map(|i| i.to_string()).collect();
        let units = || {
            lines.iter().zip(&names).flat_map(|(line, name)| {
                line.units.iter().map(move |(unit, c)| (Labels::of(&[("line", name)]).with("unit", unit), c))
            })
        };
        let mut out = Family::on(&mut encoder);
        let per_unit: [Count<Counters>; 11] = [
            ("gateway_requests", "Requests taken from a line's queue to the line.", |c| c.requests),
            ("gateway_replies", "Replies with data.", |c| c.replies),
            ("gateway_timeouts", "Requests that got silence after their retries.", |c| c.timeouts),
            ("gateway_crc_errors", "Requests whose replies had bad CRCs after their retries.", |c| c.crc_errors),
            ("gateway_bad_replies", "Requests whose replies did not answer them.", |c| c.bad_replies),
            ("gateway_skipped", "Requests skipped while their unit was in backoff.", |c| c.skipped),
            ("gateway_line_errors", "Requests failed because the line's port failed.", |c| c.line_errors),
            ("gateway_busy", "Requests answered 0x06 because the line's queue was full.", |c| c.busy),
            ("gateway_broadcasts", "Broadcasts sent.", |c| c.broadcasts),
            ("gateway_cached", "Reads answered from the cache.", |c| c.cached),
            ("gateway_abandoned", "Requests dropped because their client had gone.", |c| c.abandoned),
        ];
        for (name, help, value) in per_unit {
            out.counter(name, help, units().map(|(labels, c)| (labels, value(c))))?;
        }
        out.counter(
            "gateway_exceptions",
            "Exception replies, by code.",
            units().flat_map(|(labels, c)| {
                c.exceptions
                    .iter()
                    .map(move |(code, n)| (Labels(labels.0.clone()).with("code", format!("{code:#04x}")), *n))
            }),
        )?;
        out.seconds_histogram(
            "gateway_response",
            "Response time on the line, from the request's turn to its reply.",
            &status::RESPONSE_BOUNDS,
            units().map(|(labels, c)| (labels, &c.response_us)),
        )?;
        let per_line = || lines.iter().zip(&names).map(|(line, name)| (Labels::of(&[("line", name)]), line));
        let gauge = |n: usize| i64::try_from(n).unwrap_or(i64::MAX);
        out.gauge(
            "gateway_queue_depth",
            "Requests waiting in the line's queue.",
            per_line().map(|(l, t)| (l, gauge(t.queue_depth))),
        )?;
        out.gauge(
            "gateway_queue_max",
            "The deepest the line's queue has been.",
            per_line().map(|(l, t)| (l, gauge(t.queue_max))),
        )?;
        let line_counts: [Count<LineTraffic>; 6] = [
            ("gateway_late_replies", "Replies after their request had timed out, dropped.", |t| t.late_replies),
            ("gateway_early_replies", "Replies sooner than any device answers (stale), dropped.", |t| t.early_replies),
            ("gateway_suspect_replies", "Replies taken for an earlier request's late reply, dropped.", |t| {
                t.suspect_replies
            }),
            ("gateway_connects", "Times the line's port was opened or its connection made.", |t| t.connects),
            ("gateway_connect_failures", "Opens or connection attempts that failed.", |t| t.connect_failures),
            ("gateway_disconnects", "Times an open port or connection was lost.", |t| t.disconnects),
        ];
        for (name, help, value) in line_counts {
            out.counter(name, help, per_line().map(|(labels, t)| (labels, value(t))))?;
        }
        let front = self.gateway.front_stats();
        out.counter(
            "gateway_refused",
            "Requests the front end refused before any line, by reason.",
            front.refused.iter().map(|(reason, n)| (Labels::none().with("reason", reason), *n)),
        )?;
        status::tcp_metrics(&mut out, &self.tcp)
    }
}

impl Source for GatewayStatus {
    fn status(&self) -> Status {
        let lines = self.gateway.stats();
        let health = self.unit_health(&lines);
        let mut line_table =
            Table::new("Lines", &["line", "device", "queue", "requests", "replies", "late", "connects", "disconnects"]);
        let mut unit_table = Table::new(
            "Units",
            &[
                "line",
                "unit",
                "health",
                "requests",
                "replies",
                "exceptions",
                "timeouts",
                "crc errors",
                "response p50 ms",
                "p99 ms",
            ],
        );
        for (i, line) in lines.iter().enumerate() {
            line_table.rows.push(vec![
                i.to_string(),
                line.name.clone(),
                line.queue_depth.to_string(),
                line.total.requests.to_string(),
                line.total.replies.to_string(),
                line.late_replies.to_string(),
                line.connects.to_string(),
                line.disconnects.to_string(),
            ]);
            for (unit, c) in &line.units {
                let exceptions = c.exceptions.values().fold(0u64, |sum, n| sum.saturating_add(*n));
                let h = &c.response_us;
                let ms = |q: f64| {
                    if h.is_empty() { "-".to_string() } else { format!("{:.1}", millis(h.value_at_quantile(q))) }
                };
                unit_table.rows.push(vec![
                    i.to_string(),
                    unit.to_string(),
                    health.get(&(i, *unit)).copied().unwrap_or("idle").to_string(),
                    c.requests.to_string(),
                    c.replies.to_string(),
                    exceptions.to_string(),
                    c.timeouts.to_string(),
                    c.crc_errors.to_string(),
                    ms(0.5),
                    ms(0.99),
                ]);
            }
        }
        let tcp = self.tcp.counts();
        let mut front = Table::new("Clients", &["open", "accepted", "refused invalid requests", "closed idle"]);
        front.rows.push(vec![
            tcp.open.to_string(),
            tcp.accepted.to_string(),
            self.gateway.front_stats().total().to_string(),
            tcp.closed_idle.to_string(),
        ]);
        let summary = self.summary.lock().unwrap_or_else(PoisonError::into_inner);
        let mut tables = vec![line_table, unit_table, front];
        tables.extend(summary.table());
        Status { service: "gateway".into(), summary: summary.text().to_string(), tables }
    }

    /// Failing while every unit asked in the last window stayed silent: no device answers.
    fn health(&self) -> Health {
        let health = self.unit_health(&self.gateway.stats());
        let asked: Vec<_> = health.values().filter(|h| **h != "idle").collect();
        if !asked.is_empty() && asked.iter().all(|h| **h == "silent") {
            return Health::Failing(format!("no unit answered in the last {}s", WINDOW.as_secs()));
        }
        Health::Ok
    }
}

#[expect(clippy::cast_precision_loss, reason = "a figure for people: µs well below 2^52")]
fn millis(us: u64) -> f64 {
    us as f64 / 1000.0
}

#[cfg(test)]
mod tests {
    use super::Tally;

    #[test]
    fn a_units_health_is_what_its_counts_did_in_the_window() {
        let before = Tally { requests: 10, answered: 8, failed: 2 };
        assert_eq!(before.health(before), "idle");
        assert_eq!(Tally { requests: 12, answered: 10, failed: 2 }.health(before), "ok");
        assert_eq!(Tally { requests: 12, answered: 9, failed: 3 }.health(before), "failing");
        assert_eq!(Tally { requests: 12, answered: 8, failed: 4 }.health(before), "silent");
    }
}
