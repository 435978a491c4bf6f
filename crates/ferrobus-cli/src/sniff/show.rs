//! How `ferrobus sniff` prints what it heard: the table's lines, the JSON lines, and the
//! per-unit statistics (counted, filtered and captured by [`ferrobus_tools::sniff`]).

use std::fmt::Write as _;
use std::io::Write;
use std::time::Duration;

use ferrobus_proto::FunctionCode;
use ferrobus_proto::pdu::{Request, Response};
use ferrobus_proto::sniff::{FragmentKind, Role, WireTime};
use ferrobus_tools::sniff::{BusEvent, Filter, SniffCapture, Stats, UnitStats};
use serde_json::{Value, json};

use crate::exit::CliError;
use crate::output;

/// `HH:MM:SS.uuuuuu` (UTC) of nanoseconds since the Unix epoch.
pub(super) fn clock_time(unix_ns: u64) -> String {
    let secs = unix_ns / 1_000_000_000;
    let micros = (unix_ns % 1_000_000_000) / 1_000;
    let day = secs % 86_400;
    format!("{:02}:{:02}:{:02}.{micros:06}", day / 3600, day % 3600 / 60, day % 60)
}

fn head(heard: &BusEvent) -> (u8, u8) {
    heard.unit_function().unwrap_or_default()
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// A capture being written, and what it is called in errors.
pub(super) type Capture = (SniffCapture<Box<dyn Write>>, String);

/// Where the decode goes.
pub(super) struct Sinks {
    pub(super) json: bool,
    /// Whether the decode is printed (not with `--pcap -`).
    pub(super) print: bool,
    pub(super) pcap: Option<Capture>,
    pub(super) char_time: Duration,
    pub(super) filter: Filter,
    pub(super) stats: Stats,
    /// With `--device`: the values heard, printed instead of the frames.
    pub(super) values: Option<super::values::Watch>,
}

impl Sinks {
    fn chars(&self, d: Duration) -> f64 {
        if self.char_time.is_zero() { 0.0 } else { d.as_secs_f64() / self.char_time.as_secs_f64() }
    }

    pub(super) fn take(&mut self, heard: &BusEvent) -> Result<(), CliError> {
        if !self.filter.admits(heard) {
            return Ok(());
        }
        self.stats.count(heard);
        if let Some((pcap, what)) = &mut self.pcap {
            pcap.write(heard).map_err(|source| CliError::Output { what: what.clone(), source })?;
        }
        if let Some(values) = &mut self.values {
            values.take(heard)?;
        } else if self.print {
            let text = if self.json { output::json_line(&self.json_of(heard)) } else { self.line_of(heard) };
            output::print(&text)?;
        }
        Ok(())
    }

    fn time_json(&self, time: &WireTime) -> Value {
        json!({
            "ts_ns": time.end.as_nanos(),
            "start_ns": time.start.as_nanos(),
            "silence_chars": time.silence_before.map(|s| round2(self.chars(s))),
            "longest_gap_chars": round2(self.chars(time.longest_gap)),
            "t3_5_violation": time.t3_5_violation,
            "t1_5_violation": time.t1_5_violation,
        })
    }

    fn json_of(&self, heard: &BusEvent) -> Value {
        match heard {
            BusEvent::Frame { bytes, role, crc_ok, time, response_time } => {
                let (unit, fc) = head(heard);
                let mut doc = json!({
                    "type": "frame",
                    "role": match role { Role::Request => "request", Role::Response => "response" },
                    "unit": unit,
                    "function": fc & !FunctionCode::EXCEPTION_BIT,
                    "crc_ok": crc_ok,
                    "bytes": crate::hex::format(bytes),
                });
                merge(&mut doc, self.time_json(time));
                if *role == Role::Request && unit == 0 {
                    doc["broadcast"] = true.into();
                }
                if let Some(rt) = response_time {
                    doc["response_time_ms"] = round3(ms(*rt)).into();
                }
                let pdu = bytes.get(1..bytes.len().saturating_sub(2)).unwrap_or_default();
                merge(&mut doc, pdu_json(*role, pdu));
                doc
            }
            BusEvent::Fragment { bytes, kind, time } => {
                let mut doc = json!({
                    "type": match kind { FragmentKind::Partial { .. } => "partial", FragmentKind::Noise => "noise" },
                    "bytes": crate::hex::format(bytes),
                });
                if let FragmentKind::Partial { expected: Some(n) } = kind {
                    doc["expected_len"] = (*n).into();
                }
                merge(&mut doc, self.time_json(time));
                doc
            }
            BusEvent::Unanswered { unit, function, request_end } => json!({
                "type": "unanswered", "unit": unit, "function": function, "request_end_ns": request_end.as_nanos(),
            }),
        }
    }

    fn line_of(&self, heard: &BusEvent) -> String {
        let gap = |time: &WireTime| match time.silence_before {
            Some(s) => format!("{:>6.1}ch", self.chars(s)),
            None => "     -  ".to_string(),
        };
        let flags = |time: &WireTime| {
            let mut f = String::new();
            if time.t3_5_violation {
                f.push_str("  t3.5!");
            }
            if time.t1_5_violation {
                let _ = write!(f, "  t1.5! (gap {:.1}ch)", self.chars(time.longest_gap));
            }
            f
        };
        match heard {
            BusEvent::Frame { bytes, role, crc_ok, time, response_time } => {
                let (unit, fc) = head(heard);
                let pdu = bytes.get(1..bytes.len().saturating_sub(2)).unwrap_or_default();
                let decoded = match role {
                    Role::Request => Request::parse(pdu).map(|r| format!("{r:?}")),
                    Role::Response => Response::parse(pdu).map(|r| format!("{r:?}")),
                }
                .unwrap_or_else(|e| format!("(malformed: {e}) {}", crate::hex::format(pdu)));
                let crc = if *crc_ok { "CRC ok ".to_string() } else { "CRC BAD".to_string() };
                let rt = response_time.map(|rt| format!("  {:.3} ms", ms(rt))).unwrap_or_default();
                let who = if *role == Role::Request && unit == 0 { "bcast".to_string() } else { format!("u{unit}") };
                let function = FunctionCode::from_u8(fc & !FunctionCode::EXCEPTION_BIT);
                format!(
                    "{}  {}  {:<4} {:<5} {function}  {crc}{rt}{}  {decoded}\n",
                    clock_time(time.end.as_nanos()),
                    gap(time),
                    match role {
                        Role::Request => "req",
                        Role::Response => "resp",
                    },
                    who,
                    flags(time),
                )
            }
            BusEvent::Fragment { bytes, kind, time } => {
                let what = match kind {
                    FragmentKind::Partial { expected: Some(n) } => {
                        format!("partial frame ({} of {n} bytes)", bytes.len())
                    }
                    FragmentKind::Partial { expected: None } => format!("partial frame ({} bytes)", bytes.len()),
                    FragmentKind::Noise => format!("noise ({} bytes)", bytes.len()),
                };
                format!(
                    "{}  {}  {what}{}  {}\n",
                    clock_time(time.end.as_nanos()),
                    gap(time),
                    flags(time),
                    crate::hex::format(bytes)
                )
            }
            BusEvent::Unanswered { unit, function, request_end } => format!(
                "{}  no response from u{unit} to {} before the next request\n",
                clock_time(request_end.as_nanos()),
                FunctionCode::from_u8(*function)
            ),
        }
    }

    pub(super) fn stats_text(&self) -> String {
        let s = &self.stats;
        let mut rows = output::Rows::new(&[
            ("unit", output::Align::Right),
            ("requests", output::Align::Right),
            ("responses", output::Align::Right),
            ("exceptions", output::Align::Right),
            ("unanswered", output::Align::Right),
            ("crc_errors", output::Align::Right),
            ("t3.5", output::Align::Right),
            ("t1.5", output::Align::Right),
            ("resp_min_ms", output::Align::Right),
            ("resp_avg_ms", output::Align::Right),
            ("resp_max_ms", output::Align::Right),
        ]);
        for (unit, u) in &s.units {
            let (min, avg, max) = spread(u);
            rows.push(vec![
                unit.to_string(),
                u.requests.to_string(),
                u.responses.to_string(),
                u.exceptions.to_string(),
                u.unanswered.to_string(),
                u.crc_errors.to_string(),
                u.t3_5_violations.to_string(),
                u.t1_5_violations.to_string(),
                min.map_or("-".into(), |v| format!("{v:.3}")),
                avg.map_or("-".into(), |v| format!("{v:.3}")),
                max.map_or("-".into(), |v| format!("{v:.3}")),
            ]);
        }
        format!(
            "{}line: {} partial frames, {} noise runs, {} bytes outside frames\n",
            rows.table(),
            s.partial_frames,
            s.noise_runs,
            s.noise_bytes
        )
    }

    pub(super) fn stats_json(&self) -> Value {
        let s = &self.stats;
        let units: Vec<Value> = s
            .units
            .iter()
            .map(|(unit, u)| {
                let (min, avg, max) = spread(u);
                json!({
                    "unit": unit, "requests": u.requests, "responses": u.responses, "exceptions": u.exceptions,
                    "unanswered": u.unanswered, "crc_errors": u.crc_errors, "t3_5_violations": u.t3_5_violations,
                    "t1_5_violations": u.t1_5_violations, "response_time_min_ms": min.map(round3),
                    "response_time_avg_ms": avg.map(round3), "response_time_max_ms": max.map(round3),
                })
            })
            .collect();
        json!({
            "type": "stats", "units": units, "partial_frames": s.partial_frames, "noise_runs": s.noise_runs,
            "noise_bytes": s.noise_bytes,
        })
    }
}

fn merge(doc: &mut Value, more: Value) {
    if let (Value::Object(doc), Value::Object(more)) = (doc, more) {
        doc.extend(more);
    }
}

fn round2(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Min, mean and max response time in milliseconds.
fn spread(unit: &UnitStats) -> (Option<f64>, Option<f64>, Option<f64>) {
    match unit.response_spread() {
        Some((min, mean, max)) => (Some(ms(min)), Some(ms(mean)), Some(ms(max))),
        None => (None, None, None),
    }
}

/// The fields scripts compare with tshark's: exception code, address (reference) and count.
fn pdu_json(role: Role, pdu: &[u8]) -> Value {
    let mut doc = json!({});
    let (address, count): (Option<u16>, Option<u16>) = match role {
        Role::Request => match Request::parse(pdu) {
            Ok(r) => {
                doc["decoded"] = format!("{r:?}").into();
                match r {
                    Request::ReadCoils(b) | Request::ReadDiscreteInputs(b) => (Some(b.start()), Some(b.quantity())),
                    Request::ReadHoldingRegisters(b) | Request::ReadInputRegisters(b) => {
                        (Some(b.start()), Some(b.quantity()))
                    }
                    Request::WriteSingleCoil(c) => (Some(c.address), None),
                    Request::WriteSingleRegister(w) => (Some(w.address), None),
                    Request::WriteMultipleCoils(w) => (Some(w.start()), Some(w.quantity())),
                    Request::WriteMultipleRegisters(w) => (Some(w.start()), Some(w.quantity())),
                    Request::MaskWriteRegister(m) => (Some(m.address), None),
                    Request::ReadWriteMultipleRegisters(rw) => (Some(rw.read().start()), Some(rw.read().quantity())),
                    Request::ReadFifoQueue(f) => (Some(f.address), None),
                    // One sub-request: its record length, as tshark shows it.
                    Request::ReadFileRecord(refs) if refs.len() == 1 => (None, refs.get(0).map(|r| r.length)),
                    Request::WriteFileRecord(w) if w.len() == 1 => (None, file_write_len(&w)),
                    _ => (None, None),
                }
            }
            Err(e) => {
                doc["malformed"] = e.to_string().into();
                (None, None)
            }
        },
        Role::Response => match Response::parse(pdu) {
            Ok(r) => {
                doc["decoded"] = format!("{r:?}").into();
                match r {
                    Response::Exception(e) => {
                        doc["exception"] = e.code().value().into();
                        (None, None)
                    }
                    Response::WriteSingleCoil(c) => (Some(c.address), None),
                    Response::WriteSingleRegister(w) => (Some(w.address), None),
                    Response::WriteMultipleCoils(w) => (Some(w.start()), Some(w.quantity())),
                    Response::WriteMultipleRegisters(w) => (Some(w.start()), Some(w.quantity())),
                    Response::MaskWriteRegister(m) => (Some(m.address), None),
                    Response::WriteFileRecord(w) if w.len() == 1 => (None, file_write_len(&w)),
                    _ => (None, None),
                }
            }
            Err(e) => {
                doc["malformed"] = e.to_string().into();
                (None, None)
            }
        },
    };
    if let Some(a) = address {
        doc["address"] = a.into();
    }
    if let Some(c) = count {
        doc["count"] = c.into();
    }
    doc
}

/// The register count of the one sub-request of a 0x15 request or response.
fn file_write_len(writes: &ferrobus_proto::pdu::FileRecordWrites<'_>) -> Option<u16> {
    writes.iter().next().and_then(|w| u16::try_from(w.data.len()).ok())
}
