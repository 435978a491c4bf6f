//! What the bridge says as it happens: the CLI prints these on stderr, tests wait for them.
//!
//! Each is one line: what came from outside (a topic, a metric name inside a refusal, a value
//! as commanded, what a broker or a bus said) is written through [`ferrobus::log::escape`], so
//! a newline or a NUL in an MQTT message cannot end the line and forge the next.

use std::fmt;
use std::time::Duration;

use ferrobus::log::escape;

/// One thing that happened.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Status {
    /// The lines are polling.
    Started {
        /// Lines started.
        lines: usize,
        /// Devices on them.
        devices: usize,
        /// The broker (`mqtt://host:port`).
        broker: String,
    },
    /// The store held records of a previous run (replayed once connected).
    Recovered {
        /// Records.
        records: u64,
    },
    /// The first CONNECT is on its way.
    Connecting {
        /// The broker.
        broker: String,
    },
    /// The broker accepted the session.
    Connected {
        /// The broker.
        broker: String,
    },
    /// Births went out: an NBIRTH (with every device's DBIRTH), or a device's DBIRTH.
    Births {
        /// Whether an NBIRTH was among them.
        node: bool,
        /// The devices born (DBIRTH).
        devices: Vec<String>,
    },
    /// The connection failed or was lost; the next attempt waits `retry_in`.
    BrokerLost {
        /// The broker.
        broker: String,
        /// Why.
        error: String,
        /// The backoff.
        retry_in: Duration,
        /// Whether a session was up (else an attempt failed).
        was_online: bool,
    },
    /// The first record kept in the store since the last births: the broker is away, or
    /// (`connected`) the births wait for the primary host's STATE.
    Storing {
        /// Whether the broker is connected.
        connected: bool,
    },
    /// The births are out again: records stored meanwhile are replayed after them.
    Replaying {
        /// Records stored since the last births.
        records: u64,
        /// Records in the store now (with older ones).
        queued: u64,
    },
    /// Every stored record has been replayed.
    Replayed {
        /// Records replayed since the broker came back.
        records: u64,
    },
    /// The store was full: new records were dropped (said once per burst).
    Dropped {
        /// Records dropped in the burst.
        records: u64,
    },
    /// The store failed (said at the 1st, 2nd, 4th, 8th, ... failure).
    StoreError {
        /// The error.
        error: String,
        /// Failures so far.
        count: u64,
    },
    /// A device stopped answering.
    DeviceDead {
        /// Its id.
        device: String,
        /// Polls in a row without a reply.
        polls: u32,
        /// The last failure.
        why: String,
        /// It has not answered once in this run (so it was never born).
        never_answered: bool,
    },
    /// A device answers again.
    DeviceBack {
        /// Its id.
        device: String,
        /// Its first reply in this run (it never answered before).
        first: bool,
    },
    /// A command was refused; nothing was written.
    Refused {
        /// Its topic.
        topic: String,
        /// Why.
        error: String,
    },
    /// A message on a subscribed topic was too large to take: discarded unread, the session
    /// goes on.
    Discarded {
        /// Its topic.
        topic: String,
        /// Its size, topic and payload.
        bytes: usize,
        /// The most the bridge takes.
        limit: usize,
    },
    /// A command was written to a device (or failed on the bus).
    Written {
        /// The device.
        device: String,
        /// The metric (cell) written.
        point: String,
        /// The value as commanded.
        value: String,
        /// The bus's answer.
        result: Result<(), String>,
    },
    /// A command's write failed on the bus after others of it were written: the bus cannot
    /// take those back, so this says exactly which were and were not written.
    Incomplete {
        /// The device.
        device: String,
        /// The points written, in order.
        written: Vec<String>,
        /// The point whose write failed.
        failed: String,
        /// Why.
        error: String,
        /// The points not tried.
        not_written: Vec<String>,
    },
    /// A line cannot carry what it was asked to poll.
    Overload {
        /// The line.
        line: String,
        /// The arithmetic.
        detail: String,
    },
    /// Anything else worth a line.
    Note(String),
    /// The bridge is stopping.
    Stopping,
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Status::Started { lines, devices, broker } => {
                let plural = |n: usize| if n == 1 { "" } else { "s" };
                write!(
                    f,
                    "polling {devices} device{} on {lines} line{}; broker {broker}",
                    plural(*devices),
                    plural(*lines)
                )
            }
            Status::Recovered { records } => write!(f, "the store holds {records} records of a previous run"),
            Status::Connecting { broker } => write!(f, "connecting to {broker}"),
            Status::Connected { broker } => write!(f, "connected to {broker}"),
            Status::Births { node, devices } => {
                let mut parts = Vec::new();
                if *node {
                    parts.push("NBIRTH".to_string());
                }
                if !devices.is_empty() {
                    parts.push(format!("DBIRTH {}", devices.join(", ")));
                }
                write!(f, "births: {}", parts.join(", "))
            }
            Status::BrokerLost { broker, error, retry_in, was_online } => {
                let what = if *was_online { "lost" } else { "unreachable" };
                let error = escape(error);
                write!(f, "broker {broker} {what}: {error}; next attempt in {:.1} s", retry_in.as_secs_f64())
            }
            Status::Storing { connected: false } => write!(f, "broker away: samples go to the store"),
            Status::Storing { connected: true } => {
                write!(f, "waiting for the primary host's STATE: samples go to the store")
            }
            Status::Replaying { records, queued } => {
                write!(f, "{records} records stored since the last births; replaying {queued}")
            }
            Status::Replayed { records } => write!(f, "replayed {records} stored records, in order, as historical"),
            Status::Dropped { records } => write!(f, "the store was full: {records} new records dropped"),
            Status::StoreError { error, count } => write!(f, "store error ({count} so far): {error}"),
            Status::DeviceDead { device, polls, why, never_answered: true } => {
                write!(
                    f,
                    "device {device} does not answer ({polls} polls: {}); it is born at its first reply",
                    escape(why)
                )
            }
            Status::DeviceDead { device, polls, why, never_answered: false } => {
                write!(f, "device {device} stopped answering ({polls} polls: {})", escape(why))
            }
            Status::DeviceBack { device, first: false } => write!(f, "device {device} answers again"),
            Status::DeviceBack { device, first: true } => write!(f, "device {device} answers at last"),
            Status::Refused { topic, error } => write!(f, "command refused on {}: {}", escape(topic), escape(error)),
            Status::Discarded { topic, bytes, limit } => {
                let topic = escape(topic);
                write!(f, "discarded a {bytes}-byte message on {topic}: the bridge takes at most {limit} bytes")
            }
            Status::Written { device, point, value, result: Ok(()) } => {
                write!(f, "wrote {device} {point} = {}", escape(value))
            }
            Status::Written { device, point, value, result: Err(e) } => {
                write!(f, "writing {device} {point} = {} failed: {}", escape(value), escape(e))
            }
            Status::Incomplete { device, written, failed, error, not_written } => {
                let list = |points: &[String]| if points.is_empty() { "none".to_string() } else { points.join(", ") };
                write!(
                    f,
                    "command to {device} stopped at {failed}: {error}; written before it (kept: the bus cannot \
                     undo them): {}; not written: {}",
                    list(written),
                    list(not_written),
                    error = escape(error)
                )
            }
            Status::Overload { line, detail } => write!(f, "line {line}: {detail}"),
            Status::Note(note) => write!(f, "{}", escape(note)),
            Status::Stopping => f.write_str("stopping"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refused_metric_name_with_a_newline_and_a_nul_stays_on_one_line() {
        let status = Status::Refused {
            topic: "spBv1.0/g/DCMD/n/d\0".into(),
            error: "DCMD d: F001\nbridge: wrote d F001 = 0.00 Hz: refused: no metric of that name".into(),
        };
        let line = status.to_string();
        assert_eq!(line.lines().count(), 1, "{line}");
        assert!(line.contains(r"F001\nbridge: wrote") && line.contains(r"DCMD/n/d\0"), "{line}");
    }
}
