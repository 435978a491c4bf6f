//! What was heard, as pcapng: one packet per frame or fragment, with what was wrong on the
//! line (a bad CRC, a silence too short, a gap too long) as the packet's comment.

use std::io::{self, Write};
use std::time::Duration;

use ferrobus_proto::crc::crc16;
use ferrobus_proto::frame::LineTiming;
use ferrobus_proto::sniff::{FragmentKind, Role, WireTime};

use super::BusEvent;
use crate::pcapng::{Content, Packet, PcapngWriter};

/// A capture being written from a sniffer's events.
#[derive(Debug)]
pub struct SniffCapture<W: Write> {
    writer: PcapngWriter<W>,
    /// Silences and gaps are told in characters of this line.
    char_time: Duration,
}

impl<W: Write> SniffCapture<W> {
    /// Writes to `writer`, its headers written already; silences and gaps are told in
    /// characters of `timing`'s line.
    pub fn new(writer: PcapngWriter<W>, timing: &LineTiming) -> Self {
        SniffCapture { writer, char_time: timing.char_time() }
    }

    /// Writes `event`'s packet: a frame or a fragment (an unanswered request is no packet).
    pub fn write(&mut self, event: &BusEvent) -> io::Result<()> {
        let Some((packet, comment)) = packet(event, self.char_time) else { return Ok(()) };
        self.writer.write(&Packet { comment: comment.as_deref(), ..packet })
    }

    /// Flushes what is written.
    pub fn flush(&mut self) -> io::Result<()> {
        self.writer.flush()
    }

    /// The writer.
    pub fn into_inner(self) -> PcapngWriter<W> {
        self.writer
    }
}

/// The pcapng packet of `event` (its comment not set), and the comment: what was wrong on the
/// line.
pub(super) fn packet(event: &BusEvent, char_time: Duration) -> Option<(Packet<'_>, Option<String>)> {
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
    let (bytes, content, time) = match event {
        BusEvent::Frame { bytes, role, crc_ok, time, .. } => {
            if !crc_ok {
                let body = bytes.get(..bytes.len().saturating_sub(2)).unwrap_or_default();
                let got = match bytes.get(bytes.len().saturating_sub(2)..).unwrap_or_default() {
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
        BusEvent::Fragment { bytes, kind, time } => {
            notes.push(match kind {
                FragmentKind::Partial { expected: Some(n) } => format!("partial frame: {} of {n} bytes", bytes.len()),
                FragmentKind::Partial { expected: None } => format!("partial frame: {} bytes", bytes.len()),
                FragmentKind::Noise => format!("noise: {} bytes that start no frame", bytes.len()),
            });
            (bytes, Content::Other, time)
        }
        BusEvent::Unanswered { .. } => return None,
    };
    line_errors(time, &mut notes);
    let comment = (!notes.is_empty()).then(|| notes.join("; "));
    Some((Packet { timestamp_ns: time.end.as_nanos(), bytes, content, comment: None }, comment))
}
