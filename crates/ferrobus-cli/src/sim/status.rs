//! `sim --metrics`: the simulator on its status endpoint ([`ferrobus_tools::status`]).
//!
//! ```text
//!   ferrobus_sim_requests_total  sim_replies_total  sim_exceptions_total  sim_unanswered_total
//!   sim_other_units_total  sim_discarded_total  sim_dropped_replies_total
//!   sim_reply_lateness_seconds   a histogram: how late each reply began after it was due
//!   tcp_*                        the listener's, over TCP
//! ```

use std::sync::{Arc, Mutex, PoisonError};

use ferrobus::server::TcpStats;
use ferrobus_tools::status::{Family, Health, Labels, Source, Status, Table, tcp_metrics};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::DescriptorEncoder;

use super::Counters;

/// Lateness is a matter of microseconds to a few milliseconds: finer buckets than a response's.
const LATENESS_BOUNDS: [f64; 9] = [0.000_1, 0.000_25, 0.000_5, 0.001, 0.002, 0.005, 0.01, 0.05, 0.1];

/// The simulator as its status endpoint shows it.
pub(super) struct SimStatus {
    pub(super) counters: Arc<Mutex<Counters>>,
    /// The listener's counts, over TCP.
    pub(super) tcp: Option<Arc<TcpStats>>,
    pub(super) summary: String,
}

impl std::fmt::Debug for SimStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimStatus").field("summary", &self.summary).finish_non_exhaustive()
    }
}

impl Collector for SimStatus {
    fn encode(&self, mut encoder: DescriptorEncoder<'_>) -> Result<(), std::fmt::Error> {
        let c = self.counters.lock().unwrap_or_else(PoisonError::into_inner);
        let mut out = Family::on(&mut encoder);
        out.counters(&[
            ("sim_requests", "Requests for a simulated unit.", c.requests),
            ("sim_replies", "Replies sent (exceptions included).", c.replies),
            ("sim_exceptions", "Exception replies sent.", c.exceptions),
            ("sim_unanswered", "Requests left unanswered (a broadcast, listen-only, a busy line).", c.silent),
            ("sim_other_units", "Frames for units the simulator does not answer.", c.other_units),
            ("sim_discarded", "Runs of bytes discarded: noise, broken frames, bad CRCs.", c.discarded),
            ("sim_dropped_replies", "Replies dropped by the fault injection.", c.dropped_replies),
        ])?;
        out.seconds_histogram(
            "sim_reply_lateness",
            "How late each reply began after it was due (t3.5 plus the response wait).",
            &LATENESS_BOUNDS,
            [(Labels::none(), &c.lateness_us)],
        )?;
        match &self.tcp {
            Some(tcp) => tcp_metrics(&mut out, tcp),
            None => Ok(()),
        }
    }
}

impl Source for SimStatus {
    fn status(&self) -> Status {
        let c = self.counters.lock().unwrap_or_else(PoisonError::into_inner);
        let mut table = Table::new(
            "Requests",
            &["requests", "replies", "exceptions", "unanswered", "other units", "dropped by faults", "late p99 µs"],
        );
        let late = &c.lateness_us;
        table.rows.push(vec![
            c.requests.to_string(),
            c.replies.to_string(),
            c.exceptions.to_string(),
            c.silent.to_string(),
            c.other_units.to_string(),
            c.dropped_replies.to_string(),
            if late.is_empty() { "-".into() } else { late.value_at_quantile(0.99).to_string() },
        ]);
        let mut tables = vec![table];
        if let Some(tcp) = &self.tcp {
            let t = tcp.counts();
            let mut clients = Table::new("Clients", &["open", "accepted", "closed idle", "closed unfinished frame"]);
            clients.rows.push(vec![
                t.open.to_string(),
                t.accepted.to_string(),
                t.closed_idle.to_string(),
                t.closed_unfinished.to_string(),
            ]);
            tables.push(clients);
        }
        Status { service: "sim".into(), summary: self.summary.clone(), tables }
    }

    /// A simulator that runs does its job.
    fn health(&self) -> Health {
        Health::Ok
    }
}
