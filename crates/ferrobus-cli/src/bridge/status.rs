//! `bridge --metrics`: the bridge on its status endpoint ([`ferrobus_tools::status`]), from
//! its live view ([`Live`], which the bridge makes when a request asks for it, and only then)
//! and its summary ([`Summary`]: the plant as the file applied last describes it, and the
//! reloads).
//!
//! ```text
//!   ferrobus_bridge_published_total{type}   NBIRTH, DBIRTH, DDATA, DDEATH, NDEATH; plain, result
//!   bridge_unsent_total  bridge_stored_total  bridge_replayed_total  bridge_dropped_total
//!   bridge_unreplayable_total  bridge_store_errors_total  bridge_commands_refused_total
//!   bridge_commands_discarded_total  bridge_writes_total  bridge_write_failures_total
//!   bridge_broker_sessions_total  bridge_broker_lost_total
//!   bridge_store_depth  bridge_broker_connected                 gauges
//!   bridge_polls_total{line}  bridge_poll_failures_total{line,kind}  bridge_poll_overruns_total{line}
//! ```

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use ferrobus_bridge::run::{Live, LiveAsk};
use ferrobus_tools::poll::iso8601_ms;
use ferrobus_tools::status::{Family, Health, Labels, Refresh, Source, Status, Summary, Table, View};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::DescriptorEncoder;
use tokio::sync::{mpsc, oneshot};

/// How long a request waits for the bridge's answer. The bridge answers between the samples
/// it takes; one busy carrying out a reload answers after it, and until then a request is
/// answered from the view before.
const ANSWER_WAIT: Duration = Duration::from_secs(1);

/// The bridge as its status endpoint shows it.
pub(super) struct BridgeStatus {
    ask: mpsc::Sender<LiveAsk>,
    /// The bridge's last answer (its readings those of the last page asked for).
    last: Mutex<Live>,
    summary: Arc<Mutex<Summary>>,
}

impl std::fmt::Debug for BridgeStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let summary = self.summary.lock().unwrap_or_else(PoisonError::into_inner).clone();
        f.debug_struct("BridgeStatus").field("summary", &summary).finish_non_exhaustive()
    }
}

impl BridgeStatus {
    /// The status of the bridge that answers on `ask`, with the plant as `summary` has it.
    pub(super) fn new(ask: mpsc::Sender<LiveAsk>, summary: Arc<Mutex<Summary>>) -> Self {
        BridgeStatus { ask, last: Mutex::new(Live::default()), summary }
    }

    fn now(&self) -> MutexGuard<'_, Live> {
        self.last.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Asks the bridge how it is, for `view`: the readings only for a page. No answer in
    /// [`ANSWER_WAIT`] (or a bridge that has stopped) leaves the view before.
    async fn ask(&self, view: View) {
        let readings = view == View::Page;
        let (answer, answered) = oneshot::channel();
        if self.ask.try_send(LiveAsk { readings, answer }).is_err() {
            return;
        }
        let Ok(Ok(mut live)) = tokio::time::timeout(ANSWER_WAIT, answered).await else { return };
        let mut last = self.now();
        if !readings {
            // A page asked for meanwhile still shows what it was answered.
            live.readings = std::mem::take(&mut last.readings);
        }
        *last = live;
    }
}

impl Collector for BridgeStatus {
    fn encode(&self, mut encoder: DescriptorEncoder<'_>) -> Result<(), std::fmt::Error> {
        let live = self.now();
        let r = &live.report;
        let mut out = Family::on(&mut encoder);
        out.counter(
            "bridge_published",
            "Messages handed to the MQTT client, by type.",
            r.published.iter().map(|(kind, n)| (Labels::none().with("type", kind), *n)),
        )?;
        out.counters(&[
            ("bridge_unsent", "Messages the MQTT client could not take (its queue was full).", r.unsent),
            ("bridge_stored", "Records kept in the store while the broker was away.", r.stored),
            ("bridge_replayed", "Records replayed from the store.", r.replayed),
            ("bridge_unreplayable", "Stored records passed over: they no longer map to the plant.", r.unreplayable),
            ("bridge_dropped", "New records dropped because the store was full.", r.dropped),
            ("bridge_store_errors", "Store errors.", r.store_errors),
            ("bridge_commands_refused", "Commands refused, nothing written.", r.refused),
            ("bridge_commands_discarded", "Incoming messages discarded unread: too large.", r.discarded),
            ("bridge_writes", "Writes done.", r.writes),
            ("bridge_write_failures", "Writes the bus failed.", r.write_failures),
            ("bridge_broker_sessions", "Sessions the broker accepted.", r.connections),
            ("bridge_broker_lost", "Sessions lost.", r.broker_lost),
        ])?;
        let gauge = |n: u64| i64::try_from(n).unwrap_or(i64::MAX);
        out.gauge(
            "bridge_store_depth",
            "Records waiting in the store now.",
            [(Labels::none(), gauge(live.stored_now))],
        )?;
        out.gauge(
            "bridge_broker_connected",
            "1 while a session with the broker is up.",
            [(Labels::none(), i64::from(live.online))],
        )?;
        let lines = || r.lines.iter().map(|l| (Labels::of(&[("line", l.name.as_str())]), l));
        out.counter("bridge_polls", "Polls of the line's devices.", lines().map(|(labels, l)| (labels, l.polls)))?;
        out.counter(
            "bridge_poll_failures",
            "Failed polls, by kind.",
            lines().flat_map(|(labels, l)| {
                l.failures.iter().map(move |(kind, n)| (Labels(labels.0.clone()).with("kind", format!("{kind:?}")), *n))
            }),
        )?;
        out.counter(
            "bridge_poll_overruns",
            "Polls that ended after their next was due.",
            lines().map(|(labels, l)| (labels, l.overruns)),
        )
    }
}

impl Source for BridgeStatus {
    fn status(&self) -> Status {
        let live = self.now();
        let r = &live.report;
        let mut broker = Table::new("Broker", &["state", "sessions", "lost", "published", "not sent"]);
        broker.rows.push(vec![
            if live.online { "ok" } else { "failing" }.to_string(),
            r.connections.to_string(),
            r.broker_lost.to_string(),
            r.published.values().sum::<u64>().to_string(),
            r.unsent.to_string(),
        ]);
        let mut store = Table::new("Store", &["waiting", "stored", "replayed", "dropped", "errors"]);
        store.rows.push(vec![
            live.stored_now.to_string(),
            r.stored.to_string(),
            r.replayed.to_string(),
            r.dropped.to_string(),
            r.store_errors.to_string(),
        ]);
        let mut lines = Table::new("Lines", &["line", "polls", "ok", "failed", "overruns"]);
        for l in &r.lines {
            let failed: u64 = l.failures.values().sum();
            lines.rows.push(vec![
                l.name.clone(),
                l.polls.to_string(),
                l.ok.to_string(),
                failed.to_string(),
                l.overruns.to_string(),
            ]);
        }
        let mut commands = Table::new("Commands", &["writes", "write failures", "refused", "discarded"]);
        commands.rows.push(vec![
            r.writes.to_string(),
            r.write_failures.to_string(),
            r.refused.to_string(),
            r.discarded.to_string(),
        ]);
        let mut values = Table::new("Values", &["device", "point", "value", "read at", "state"]);
        for r in &live.readings {
            let state = if r.failed { "failed" } else { "ok" };
            values.rows.push(vec![
                r.device.clone(),
                r.point.clone(),
                r.shown.clone(),
                iso8601_ms(r.time),
                state.into(),
            ]);
        }
        let summary = self.summary.lock().unwrap_or_else(PoisonError::into_inner);
        // Reloads before the values: a table of every point, the longest.
        let mut tables = vec![broker, store, lines, commands];
        tables.extend(summary.table());
        tables.push(values);
        Status { service: "bridge".into(), summary: summary.text().to_string(), tables }
    }

    /// Failing while no session with the broker is up: what is read goes to the store.
    fn health(&self) -> Health {
        if self.now().online {
            Health::Ok
        } else {
            Health::Failing("not connected to the broker (storing what is read)".into())
        }
    }

    fn refresh(&self, view: View) -> Refresh<'_> {
        Box::pin(self.ask(view))
    }
}
