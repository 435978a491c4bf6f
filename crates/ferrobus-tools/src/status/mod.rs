//! The status endpoint of a long-running command (`--metrics ADDR:PORT` on `gateway`, `poll`,
//! `bridge`, `sim`): what it counts as OpenMetrics, whether it is healthy, and a page that
//! shows it live.
//!
//! ```text
//!   GET /metrics      OpenMetrics text (Prometheus scrapes it): the counters the command
//!                     keeps anyway, read at the scrape, so serving costs nothing between
//!   GET /healthz      200 "ok", or 503 with why (container probes)
//!   GET /status.json  the page's data: tables of what runs and the recent warnings
//!   GET /             the status page: plain HTML and a little JS that reads /status.json
//!                     every second; no build step
//! ```
//!
//! A command describes itself with a [`Source`]: its metrics (a prometheus-client
//! [`Collector`]), its [`Status`] and its [`Health`]. The server is axum's on the command's
//! runtime; an accept error (a full descriptor table) pauses accepting and never ends it, and
//! one connection's trouble is that connection's. Every text on the page is set as text, never
//! as HTML, so a value from outside (a device name, a log line) cannot become markup.

mod recent;
mod summary;

use std::fmt::Write as _;
use std::io;
use std::sync::Arc;

use axum::Router;
use axum::http::{StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use ferrobus::server::TcpStats;
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeGaugeValue, EncodeMetric, NoLabelSet};
use prometheus_client::metrics::MetricType;
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::registry::{Registry, Unit};
use serde_json::{Value, json};
use tokio::net::TcpListener;

pub use recent::{RECENT, Recent};
pub use summary::{Reloads, Summary};

/// The page, served as it is.
const PAGE: &str = include_str!("page.html");

/// What a command shows on its status endpoint.
pub trait Source: Collector {
    /// What the page shows now.
    fn status(&self) -> Status;
    /// Whether the command does its job now.
    fn health(&self) -> Health;
    /// Brings what is shown for `view` up to date, before a request for it is answered: for a
    /// command whose view is kept by a task of its own, which is asked then and never between
    /// (the bridge). Nothing to do by default: a command's counters are read where they are.
    fn refresh(&self, view: View) -> Refresh<'_> {
        let _ = view;
        Box::pin(std::future::ready(()))
    }
}

/// What [`Source::refresh`] returns: done once the view is up to date, or as up to date as the
/// source could make it in the time it allows.
pub type Refresh<'a> = std::pin::Pin<Box<dyn Future<Output = ()> + Send + 'a>>;

/// What a request shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// The metrics (`/metrics`) or the health (`/healthz`): the counters.
    Counters,
    /// The page (`/status.json`): the counters and every table, the latest values among them.
    Page,
}

/// Whether a command does its job.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Health {
    /// It does.
    Ok,
    /// It does not, and why (`/healthz` answers 503 with it).
    Failing(String),
}

/// What the status page shows: tables, each with its columns and rows of text.
#[derive(Clone, Debug, Default)]
pub struct Status {
    /// What runs, as the command calls itself (`gateway`, `sim`).
    pub service: String,
    /// One line about it (what it listens on, its lines): after a reload, as applied
    /// ([`Summary`]).
    pub summary: String,
    /// The tables, in order.
    pub tables: Vec<Table>,
}

/// A table of the status page.
#[derive(Clone, Debug, Default)]
pub struct Table {
    /// Its title.
    pub title: String,
    /// Its column heads.
    pub columns: Vec<String>,
    /// Its rows, a text per column.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// A table `title` with `columns` and no rows yet.
    pub fn new(title: &str, columns: &[&str]) -> Self {
        Table { title: title.to_string(), columns: columns.iter().map(ToString::to_string).collect(), rows: Vec::new() }
    }
}

/// Serves `source` on `listener` until dropped: `/metrics`, `/healthz`, `/status.json` and `/`.
pub async fn serve(listener: TcpListener, source: Arc<dyn Source>) -> io::Result<()> {
    let mut registry = Registry::with_prefix("ferrobus");
    registry.register_collector(Box::new(Shared(Arc::clone(&source))));
    let registry = Arc::new(registry);
    let app = Router::new()
        .route(
            "/metrics",
            get({
                let source = Arc::clone(&source);
                move || async move {
                    source.refresh(View::Counters).await;
                    metrics(&registry)
                }
            }),
        )
        .route(
            "/healthz",
            get({
                let source = Arc::clone(&source);
                move || async move {
                    source.refresh(View::Counters).await;
                    healthz(&*source)
                }
            }),
        )
        .route(
            "/status.json",
            get(move || async move {
                source.refresh(View::Page).await;
                status(&*source)
            }),
        )
        .route("/", get(|| std::future::ready(Html(PAGE))));
    axum::serve(listener, app).await
}

/// The source, shared with the registry.
#[derive(Clone)]
struct Shared(Arc<dyn Source>);

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("status source")
    }
}

impl Collector for Shared {
    fn encode(&self, encoder: DescriptorEncoder<'_>) -> Result<(), std::fmt::Error> {
        self.0.encode(encoder)
    }
}

fn metrics(registry: &Registry) -> Response {
    let mut text = String::new();
    match prometheus_client::encoding::text::encode(&mut text, registry) {
        Ok(()) => ([(header::CONTENT_TYPE, "application/openmetrics-text; version=1.0.0; charset=utf-8")], text)
            .into_response(),
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "the metrics could not be written\n").into_response(),
    }
}

fn healthz(source: &dyn Source) -> Response {
    match source.health() {
        Health::Ok => (StatusCode::OK, "ok\n").into_response(),
        Health::Failing(why) => (StatusCode::SERVICE_UNAVAILABLE, format!("failing: {why}\n")).into_response(),
    }
}

fn status(source: &dyn Source) -> Response {
    let status = source.status();
    let health = match source.health() {
        Health::Ok => json!({"ok": true}),
        Health::Failing(why) => json!({"ok": false, "why": why}),
    };
    let tables: Vec<Value> =
        status.tables.iter().map(|t| json!({"title": t.title, "columns": t.columns, "rows": t.rows})).collect();
    let body = json!({
        "service": status.service,
        "summary": status.summary,
        "version": env!("CARGO_PKG_VERSION"),
        "health": health,
        "tables": tables,
        "recent": RECENT.list(),
    });
    let headers = [(header::CONTENT_TYPE, "application/json"), (header::CACHE_CONTROL, "no-store")];
    (headers, body.to_string()).into_response()
}

/// Writes one metric family: its name (under the `ferrobus_` prefix), help and type, then a
/// sample per label set. Counters take the `_total` suffix from the encoder. A sample without
/// labels is its family's only one (what follows it is not written).
pub struct Family<'e, 'd> {
    encoder: &'e mut DescriptorEncoder<'d>,
}

impl<'e, 'd> Family<'e, 'd> {
    /// A writer of families on `encoder`.
    pub fn on(encoder: &'e mut DescriptorEncoder<'d>) -> Self {
        Family { encoder }
    }

    /// A counter `name` with a sample per `(labels, value)`.
    pub fn counter<'l>(
        &mut self,
        name: &str,
        help: &str,
        samples: impl IntoIterator<Item = (Labels<'l>, u64)>,
    ) -> Result<(), std::fmt::Error> {
        let mut family = self.encoder.encode_descriptor(name, help, None, MetricType::Counter)?;
        for (labels, value) in samples {
            if labels.0.is_empty() {
                return ConstCounter::new(value).encode(family);
            }
            ConstCounter::new(value).encode(family.encode_family(&labels.0)?)?;
        }
        Ok(())
    }

    /// A counter without labels per `(name, help, value)`: the totals a command keeps.
    pub fn counters(&mut self, counts: &[(&str, &str, u64)]) -> Result<(), std::fmt::Error> {
        for &(name, help, value) in counts {
            self.counter(name, help, [(Labels::none(), value)])?;
        }
        Ok(())
    }

    /// A gauge `name` with a sample per `(labels, value)`: a count (`i64`) or a measured
    /// value (`f64`).
    pub fn gauge<'l, N: EncodeGaugeValue>(
        &mut self,
        name: &str,
        help: &str,
        samples: impl IntoIterator<Item = (Labels<'l>, N)>,
    ) -> Result<(), std::fmt::Error> {
        let mut family = self.encoder.encode_descriptor(name, help, None, MetricType::Gauge)?;
        for (labels, value) in samples {
            if labels.0.is_empty() {
                return ConstGauge::new(value).encode(family);
            }
            ConstGauge::new(value).encode(family.encode_family(&labels.0)?)?;
        }
        Ok(())
    }

    /// A histogram `name` in seconds, with buckets up to each of `bounds` (and `+Inf`), from
    /// samples in µs (an hdrhistogram each).
    pub fn seconds_histogram<'l, 'h>(
        &mut self,
        name: &str,
        help: &str,
        bounds: &[f64],
        samples: impl IntoIterator<Item = (Labels<'l>, &'h hdrhistogram::Histogram<u64>)>,
    ) -> Result<(), std::fmt::Error> {
        let mut family = self.encoder.encode_descriptor(name, help, Some(&Unit::Seconds), MetricType::Histogram)?;
        for (labels, h) in samples {
            let mut below = 0u64;
            let mut buckets = Vec::with_capacity(bounds.len() + 1);
            for &bound in bounds {
                let up_to = h.count_between(0, micros(bound));
                buckets.push((bound, up_to.saturating_sub(below)));
                below = up_to;
            }
            buckets.push((f64::MAX, h.len().saturating_sub(below)));
            let sum = mean_seconds(h) * count_f64(h.len());
            if labels.0.is_empty() {
                return family.encode_histogram::<NoLabelSet>(sum, h.len(), &buckets, None);
            }
            family.encode_family(&labels.0)?.encode_histogram::<NoLabelSet>(sum, h.len(), &buckets, None)?;
        }
        Ok(())
    }
}

/// A TCP listener's counts as metrics (`tcp_*`): what it accepted, holds, refused and
/// closed, by why.
pub fn tcp_metrics(out: &mut Family<'_, '_>, tcp: &TcpStats) -> Result<(), std::fmt::Error> {
    let c = tcp.counts();
    out.counter("tcp_connections_accepted", "Connections accepted and served.", [(Labels::none(), c.accepted)])?;
    out.gauge(
        "tcp_connections_open",
        "Connections open now.",
        [(Labels::none(), i64::try_from(c.open).unwrap_or(i64::MAX))],
    )?;
    let refused = [("cap", c.refused), ("source", c.refused_source), ("handshakes", c.refused_handshakes)];
    out.counter(
        "tcp_refused",
        "Connections closed at once, by the limit they met.",
        refused.map(|(reason, n)| (Labels::none().with("reason", reason), n)),
    )?;
    let closed = [
        ("idle", c.closed_idle),
        ("unfinished_frame", c.closed_unfinished),
        ("bad_header", c.closed_bad_header),
        ("evicted_handshake", c.evicted_handshakes),
        ("evicted_unanswered", c.evicted_unanswered),
        ("evicted_idle", c.evicted_idle),
    ];
    out.counter(
        "tcp_closed",
        "Connections the server closed, by why.",
        closed.map(|(reason, n)| (Labels::none().with("reason", reason), n)),
    )?;
    out.counter("tcp_tls_refused", "TLS handshakes refused.", [(Labels::none(), c.tls_refused)])?;
    out.counter("tcp_denied", "Requests a TLS client's role did not allow.", [(Labels::none(), c.denied)])?;
    out.counter(
        "tcp_descriptor_waits",
        "Times accepting paused out of descriptors or buffers.",
        [(Labels::none(), c.descriptor_waits)],
    )
}

/// The buckets Prometheus gives a response time by default: 5 ms to 10 s.
pub const RESPONSE_BOUNDS: [f64; 11] = [0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0];

/// The labels of one sample, as (name, value) pairs.
pub struct Labels<'l>(pub Vec<(&'static str, std::borrow::Cow<'l, str>)>);

impl<'l> Labels<'l> {
    /// No labels.
    pub fn none() -> Self {
        Labels(Vec::new())
    }

    /// These labels.
    pub fn of(pairs: &[(&'static str, &'l str)]) -> Self {
        Labels(pairs.iter().map(|&(k, v)| (k, std::borrow::Cow::Borrowed(v))).collect())
    }

    /// These labels and one more, owned.
    #[must_use]
    pub fn with(mut self, key: &'static str, value: impl std::fmt::Display) -> Self {
        let mut text = String::new();
        let _ = write!(text, "{value}");
        self.0.push((key, std::borrow::Cow::Owned(text)));
        self
    }
}

#[expect(clippy::cast_possible_truncation, clippy::cast_sign_loss, reason = "bounds of a few seconds, in µs")]
fn micros(seconds: f64) -> u64 {
    (seconds * 1e6) as u64
}

#[expect(clippy::cast_precision_loss, reason = "a count of requests, far below 2^52")]
fn count_f64(n: u64) -> f64 {
    n as f64
}

fn mean_seconds(h: &hdrhistogram::Histogram<u64>) -> f64 {
    if h.is_empty() { 0.0 } else { h.mean() / 1e6 }
}

#[cfg(test)]
mod tests;
