//! What `ferrobus sniff` makes of what it heard: the table's lines, the JSON lines, the
//! pcapng packets with their comments, and the per-unit statistics.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write;
use std::time::Duration;

use ferrobus::pcapng::{Content, Packet, PcapngWriter};
use ferrobus_proto::crc::crc16;
use ferrobus_proto::pdu::{Request, Response};
use ferrobus_proto::sniff::{FragmentKind, Role, SniffEvent, WireTime};
use ferrobus_proto::{FunctionCode, Instant};
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

/// An event, owned, as the decoder gave it.
pub(super) enum Heard {
    Frame { bytes: Vec<u8>, role: Role, crc_ok: bool, time: WireTime, response_time: Option<Duration> },
    Fragment { bytes: Vec<u8>, kind: FragmentKind, time: WireTime },
    Unanswered { unit: u8, function: u8, request_end: Instant },
}

pub(super) fn own(event: SniffEvent<'_>) -> Heard {
    match event {
        SniffEvent::Frame(f) => Heard::Frame {
            bytes: f.adu().to_vec(),
            role: f.role,
            crc_ok: f.crc_ok,
            time: f.time,
            response_time: f.reply.map(|r| r.response_time),
        },
        SniffEvent::Fragment(f) => Heard::Fragment { bytes: f.bytes.to_vec(), kind: f.kind, time: f.time },
        SniffEvent::Unanswered(u) => {
            Heard::Unanswered { unit: u.unit, function: u.function, request_end: u.request_end }
        }
    }
}

/// One unit's figures.
#[derive(Clone, Debug, Default)]
struct UnitStats {
    requests: u64,
    responses: u64,
    exceptions: u64,
    unanswered: u64,
    crc_errors: u64,
    t3_5_violations: u64,
    t1_5_violations: u64,
    response_times: Vec<Duration>,
}

/// Everything counted.
#[derive(Clone, Debug, Default)]
pub(super) struct Stats {
    units: BTreeMap<u8, UnitStats>,
    partial_frames: u64,
    noise_runs: u64,
    noise_bytes: u64,
}

impl Stats {
    fn count(&mut self, heard: &Heard) {
        match heard {
            Heard::Frame { bytes, role, crc_ok, time, response_time } => {
                let (unit, fc) = head(bytes);
                let u = self.units.entry(unit).or_default();
                match role {
                    Role::Request => u.requests += 1,
                    Role::Response => u.responses += 1,
                }
                if *role == Role::Response && fc & FunctionCode::EXCEPTION_BIT != 0 {
                    u.exceptions += 1;
                }
                u.crc_errors += u64::from(!crc_ok);
                u.t3_5_violations += u64::from(time.t3_5_violation);
                u.t1_5_violations += u64::from(time.t1_5_violation);
                u.response_times.extend(*response_time);
            }
            Heard::Fragment { bytes, kind: FragmentKind::Partial { .. }, .. } => {
                self.partial_frames += 1;
                self.noise_bytes += bytes.len() as u64;
            }
            Heard::Fragment { bytes, kind: FragmentKind::Noise, .. } => {
                self.noise_runs += 1;
                self.noise_bytes += bytes.len() as u64;
            }
            Heard::Unanswered { unit, .. } => self.units.entry(*unit).or_default().unanswered += 1,
        }
    }
}

fn head(bytes: &[u8]) -> (u8, u8) {
    (bytes.first().copied().unwrap_or_default(), bytes.get(1).copied().unwrap_or_default())
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// A capture being written, and what it is called in errors.
pub(super) type Capture = (PcapngWriter<Box<dyn Write>>, String);

/// Where the decode goes.
pub(super) struct Sinks {
    pub(super) json: bool,
    /// Whether the decode is printed (not with `--pcap -`).
    pub(super) print: bool,
    pub(super) pcap: Option<Capture>,
    pub(super) char_time: Duration,
    pub(super) units: Vec<u8>,
    pub(super) functions: Vec<u8>,
    pub(super) stats: Stats,
}

impl Sinks {
    fn shown(&self, heard: &Heard) -> bool {
        let (unit, fc) = match heard {
            Heard::Frame { bytes, .. } => head(bytes),
            Heard::Unanswered { unit, function, .. } => (*unit, *function),
            // Bytes that are no frame belong to no unit: shown when nothing is filtered.
            Heard::Fragment { .. } => return self.units.is_empty() && self.functions.is_empty(),
        };
        (self.units.is_empty() || self.units.contains(&unit))
            && (self.functions.is_empty() || self.functions.contains(&(fc & !FunctionCode::EXCEPTION_BIT)))
    }

    fn chars(&self, d: Duration) -> f64 {
        if self.char_time.is_zero() { 0.0 } else { d.as_secs_f64() / self.char_time.as_secs_f64() }
    }

    pub(super) fn take(&mut self, heard: &Heard) -> Result<(), CliError> {
        if !self.shown(heard) {
            return Ok(());
        }
        self.stats.count(heard);
        if let Some((pcap, what)) = &mut self.pcap {
            if let Some(packet) = packet(heard, self.char_time) {
                let comment = packet.1;
                let p = Packet { comment: comment.as_deref(), ..packet.0 };
                pcap.write(&p).map_err(|source| CliError::Output { what: what.clone(), source })?;
            }
        }
        if self.print {
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

    fn json_of(&self, heard: &Heard) -> Value {
        match heard {
            Heard::Frame { bytes, role, crc_ok, time, response_time } => {
                let (unit, fc) = head(bytes);
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
            Heard::Fragment { bytes, kind, time } => {
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
            Heard::Unanswered { unit, function, request_end } => json!({
                "type": "unanswered", "unit": unit, "function": function, "request_end_ns": request_end.as_nanos(),
            }),
        }
    }

    fn line_of(&self, heard: &Heard) -> String {
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
            Heard::Frame { bytes, role, crc_ok, time, response_time } => {
                let (unit, fc) = head(bytes);
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
            Heard::Fragment { bytes, kind, time } => {
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
            Heard::Unanswered { unit, function, request_end } => format!(
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
            let (min, avg, max) = spread(&u.response_times);
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
                let (min, avg, max) = spread(&u.response_times);
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

/// Min, mean and max in milliseconds.
fn spread(times: &[Duration]) -> (Option<f64>, Option<f64>, Option<f64>) {
    let min = times.iter().min().map(|d| ms(*d));
    let max = times.iter().max().map(|d| ms(*d));
    #[expect(clippy::cast_precision_loss, reason = "a count of responses, far below 2^52")]
    let avg = (!times.is_empty()).then(|| times.iter().map(|d| ms(*d)).sum::<f64>() / times.len() as f64);
    (min, avg, max)
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

/// The pcapng packet of what was heard, and its comment (what was wrong on the line).
fn packet(heard: &Heard, char_time: Duration) -> Option<(Packet<'_>, Option<String>)> {
    let chars = |d: Duration| if char_time.is_zero() { 0.0 } else { d.as_secs_f64() / char_time.as_secs_f64() };
    let line_errors = |time: &WireTime, notes: &mut Vec<String>| {
        if let (true, Some(s)) = (time.t3_5_violation, time.silence_before) {
            notes.push(format!("t3.5 violated: {:.1} characters of silence before it", chars(s)));
        }
        if time.t1_5_violation {
            notes.push(format!("t1.5 violated: a gap of {:.1} characters inside it", chars(time.longest_gap)));
        }
    };
    let mut notes = Vec::new();
    let (bytes, content, time) = match heard {
        Heard::Frame { bytes, role, crc_ok, time, .. } => {
            if !crc_ok {
                let body = bytes.get(..bytes.len().saturating_sub(2)).unwrap_or_default();
                let got = bytes.get(bytes.len().saturating_sub(2)..).unwrap_or_default();
                let got = match got {
                    [low, high] => u16::from_le_bytes([*low, *high]),
                    _ => 0,
                };
                notes.push(format!("CRC error: 0x{got:04x}, should be 0x{:04x}", crc16(body)));
            }
            let content = match role {
                Role::Request => Content::Request,
                Role::Response => Content::Response,
            };
            (bytes, content, time)
        }
        Heard::Fragment { bytes, kind, time } => {
            notes.push(match kind {
                FragmentKind::Partial { expected: Some(n) } => format!("partial frame: {} of {n} bytes", bytes.len()),
                FragmentKind::Partial { expected: None } => format!("partial frame: {} bytes", bytes.len()),
                FragmentKind::Noise => format!("noise: {} bytes that start no frame", bytes.len()),
            });
            (bytes, Content::Other, time)
        }
        Heard::Unanswered { .. } => return None,
    };
    line_errors(time, &mut notes);
    let comment = (!notes.is_empty()).then(|| notes.join("; "));
    Some((Packet { timestamp_ns: time.end.as_nanos(), bytes, content, comment: None }, comment))
}
