//! The slave's communication diagnostics: the counters of 0x08 sub-functions 0x0B–0x12, the
//! comm event counter of 0x0B and the comm event log of 0x0C.
//!
//! Spec: MODBUS Application Protocol V1.1b3 §6.8.1 (counters), §6.9 (event counter: "incremented
//! once for each successful message completion", not for exceptions, polls or fetches of
//! the counter or log) and §6.10 (event log: up to 64 one-byte events, most recent first,
//! with the bit layouts used below).

use crate::codes::{DiagnosticCode, ExceptionCode};

/// The diagnostic counters, each 16 bits as 0x08 returns them (they wrap).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub struct Counters {
    /// 0x0B: messages detected on the bus (any unit, correct checksum).
    pub bus_messages: u16,
    /// 0x0C: checksum errors detected on the bus.
    pub bus_comm_errors: u16,
    /// 0x0D: exception responses sent.
    pub bus_exceptions: u16,
    /// 0x0E: messages addressed to this slave (or broadcast) that it processed.
    pub server_messages: u16,
    /// 0x0F: messages addressed to this slave (or broadcast) that got no response.
    pub server_no_response: u16,
    /// 0x10: negative acknowledgements sent (exception 0x07).
    pub server_nak: u16,
    /// 0x11: busy responses sent (exception 0x06).
    pub server_busy: u16,
    /// 0x12: messages lost because they were longer than a frame.
    pub bus_char_overruns: u16,
}

impl Counters {
    /// The counter a 0x08 sub-function returns, if it returns one.
    pub fn get(&self, sub: DiagnosticCode) -> Option<u16> {
        Some(match sub {
            DiagnosticCode::BusMessageCount => self.bus_messages,
            DiagnosticCode::BusCommErrorCount => self.bus_comm_errors,
            DiagnosticCode::BusExceptionErrorCount => self.bus_exceptions,
            DiagnosticCode::ServerMessageCount => self.server_messages,
            DiagnosticCode::ServerNoResponseCount => self.server_no_response,
            DiagnosticCode::ServerNakCount => self.server_nak,
            DiagnosticCode::ServerBusyCount => self.server_busy,
            DiagnosticCode::BusCharacterOverrunCount => self.bus_char_overruns,
            _ => return None,
        })
    }

    /// Counts an exception response by its code.
    pub(crate) fn count_exception(&mut self, code: ExceptionCode) {
        bump(&mut self.bus_exceptions);
        match code.value() {
            0x06 => bump(&mut self.server_busy),
            0x07 => bump(&mut self.server_nak),
            _ => {}
        }
    }
}

pub(crate) fn bump(counter: &mut u16) {
    *counter = counter.wrapping_add(1);
}

/// The 64-entry comm event log of 0x0C.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct EventLog {
    events: [u8; EventLog::CAPACITY],
    /// Index of the next slot to write.
    next: usize,
    len: usize,
}

impl Default for EventLog {
    fn default() -> Self {
        EventLog { events: [0; EventLog::CAPACITY], next: 0, len: 0 }
    }
}

/// Event bytes (§6.10).
pub mod event {
    /// A receive event: bit 7 set.
    pub const RECEIVE: u8 = 0x80;
    /// Receive: a communication error (checksum) occurred.
    pub const RECEIVE_COMM_ERROR: u8 = 0x02;
    /// Receive: a character overrun occurred.
    pub const RECEIVE_OVERRUN: u8 = 0x10;
    /// Receive: the slave is in listen-only mode.
    pub const RECEIVE_LISTEN_ONLY: u8 = 0x20;
    /// Receive: the message was a broadcast.
    pub const RECEIVE_BROADCAST: u8 = 0x40;
    /// A send event: bit 6 set.
    pub const SEND: u8 = 0x40;
    /// Send: a read exception (codes 1–3) was sent.
    pub const SEND_READ_EXCEPTION: u8 = 0x01;
    /// Send: an abort exception (code 4) was sent.
    pub const SEND_ABORT_EXCEPTION: u8 = 0x02;
    /// Send: a busy exception (codes 5–6) was sent.
    pub const SEND_BUSY_EXCEPTION: u8 = 0x04;
    /// Send: a negative acknowledge (code 7) was sent.
    pub const SEND_NAK_EXCEPTION: u8 = 0x08;
    /// Send: a write timeout error occurred.
    pub const SEND_WRITE_TIMEOUT: u8 = 0x10;
    /// Send: the slave is in listen-only mode.
    pub const SEND_LISTEN_ONLY: u8 = 0x20;
    /// The slave entered listen-only mode.
    pub const ENTERED_LISTEN_ONLY: u8 = 0x04;
    /// The communications were restarted (0x08/0x01).
    pub const RESTART: u8 = 0x00;

    /// The flag bits of a receive event, with what each says.
    pub const RECEIVE_FLAGS: [(u8, &str); 4] = [
        (RECEIVE_BROADCAST, "broadcast"),
        (RECEIVE_COMM_ERROR, "communication error"),
        (RECEIVE_OVERRUN, "character overrun"),
        (RECEIVE_LISTEN_ONLY, "in listen-only mode"),
    ];

    /// The flag bits of a send event, with what each says.
    pub const SEND_FLAGS: [(u8, &str); 6] = [
        (SEND_READ_EXCEPTION, "read exception"),
        (SEND_ABORT_EXCEPTION, "abort exception"),
        (SEND_BUSY_EXCEPTION, "busy exception"),
        (SEND_NAK_EXCEPTION, "NAK exception"),
        (SEND_WRITE_TIMEOUT, "write timeout"),
        (SEND_LISTEN_ONLY, "in listen-only mode"),
    ];

    /// Which of the four kinds of §6.10 an event byte is.
    #[derive(Clone, Copy, PartialEq, Eq, Debug)]
    pub enum Kind {
        /// Bit 7 set: a message was received; its flags are in [`RECEIVE_FLAGS`].
        Receive,
        /// Bit 6 set (bit 7 clear): a reply was sent; its flags are in [`SEND_FLAGS`].
        Send,
        /// 0x04: the slave entered listen-only mode.
        EnteredListenOnly,
        /// 0x00: the communications were restarted.
        Restart,
        /// Any other byte: not an event the spec defines.
        Unknown,
    }

    /// The kind of event `byte` is.
    pub const fn kind(byte: u8) -> Kind {
        if byte & RECEIVE != 0 {
            Kind::Receive
        } else if byte & SEND != 0 {
            Kind::Send
        } else if byte == ENTERED_LISTEN_ONLY {
            Kind::EnteredListenOnly
        } else if byte == RESTART {
            Kind::Restart
        } else {
            Kind::Unknown
        }
    }

    /// What the flag bits of event `byte` say, in table order (none for the kinds that have
    /// no flags).
    pub fn flags(byte: u8) -> impl Iterator<Item = &'static str> {
        let table: &'static [(u8, &'static str)] = match kind(byte) {
            Kind::Receive => &RECEIVE_FLAGS,
            Kind::Send => &SEND_FLAGS,
            Kind::EnteredListenOnly | Kind::Restart | Kind::Unknown => &[],
        };
        table.iter().filter(move |(bit, _)| byte & bit != 0).map(|&(_, name)| name)
    }
}

impl EventLog {
    /// Events kept.
    pub const CAPACITY: usize = 64;

    /// Records an event.
    pub fn push(&mut self, event: u8) {
        if let Some(slot) = self.events.get_mut(self.next) {
            *slot = event;
        }
        self.next = self.next.saturating_add(1) % Self::CAPACITY;
        self.len = self.len.saturating_add(1).min(Self::CAPACITY);
    }

    /// Forgets every event.
    pub fn clear(&mut self) {
        *self = EventLog::default();
    }

    /// Number of events kept.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no event is kept.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Copies the events into `out`, most recent first, and returns how many.
    pub fn copy_recent_first(&self, out: &mut [u8; EventLog::CAPACITY]) -> usize {
        let mut idx = self.next;
        for slot in out.iter_mut().take(self.len) {
            idx = idx.checked_sub(1).unwrap_or(Self::CAPACITY - 1);
            *slot = self.events.get(idx).copied().unwrap_or_default();
        }
        self.len
    }

    /// The send-event byte for a response with `exception`, if any.
    pub(crate) fn send_event(exception: Option<ExceptionCode>, listen_only: bool) -> u8 {
        let mut byte = event::SEND;
        if listen_only {
            byte |= event::SEND_LISTEN_ONLY;
        }
        byte |= match exception.map(ExceptionCode::value) {
            Some(1..=3) => event::SEND_READ_EXCEPTION,
            Some(4) => event::SEND_ABORT_EXCEPTION,
            Some(5 | 6) => event::SEND_BUSY_EXCEPTION,
            Some(7) => event::SEND_NAK_EXCEPTION,
            _ => 0,
        };
        byte
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_event_byte_has_one_kind_and_names_exactly_its_flag_bits_over_all_256_values() {
        extern crate std;
        use std::vec::Vec;
        for byte in 0..=u8::MAX {
            let expected = match byte {
                0x80..=0xFF => event::Kind::Receive,
                0x40..=0x7F => event::Kind::Send,
                0x04 => event::Kind::EnteredListenOnly,
                0x00 => event::Kind::Restart,
                _ => event::Kind::Unknown,
            };
            assert_eq!(event::kind(byte), expected, "{byte:#04x}");
            let named: Vec<&str> = event::flags(byte).collect();
            let (table, bits): (&[(u8, &str)], u8) = match expected {
                event::Kind::Receive => (&event::RECEIVE_FLAGS, 0x72),
                event::Kind::Send => (&event::SEND_FLAGS, 0x3F),
                _ => (&[], 0x00),
            };
            let wanted: Vec<&str> = table.iter().filter(|(bit, _)| byte & bit != 0).map(|(_, n)| *n).collect();
            assert_eq!(named, wanted, "{byte:#04x}");
            assert_eq!(table.iter().fold(0, |all, (bit, _)| all | bit), bits, "the flag bits of {expected:?}");
        }
    }

    #[test]
    fn the_log_keeps_the_last_64_events_most_recent_first() {
        let mut log = EventLog::default();
        for i in 0..70u8 {
            log.push(i);
        }
        let mut out = [0xA5; EventLog::CAPACITY];
        assert_eq!(log.copy_recent_first(&mut out), 64);
        assert_eq!(out[0], 69);
        assert_eq!(out[63], 6);
        log.clear();
        assert!(log.is_empty());
    }

    #[test]
    fn send_events_classify_exceptions_as_the_spec_does() {
        assert_eq!(EventLog::send_event(None, false), 0x40);
        assert_eq!(EventLog::send_event(Some(ExceptionCode::IllegalDataAddress), false), 0x41);
        assert_eq!(EventLog::send_event(Some(ExceptionCode::ServerDeviceFailure), false), 0x42);
        assert_eq!(EventLog::send_event(Some(ExceptionCode::ServerDeviceBusy), true), 0x64);
        assert_eq!(EventLog::send_event(Some(ExceptionCode::Vendor(0x07)), false), 0x48);
        assert_eq!(EventLog::send_event(Some(ExceptionCode::Vendor(0x21)), false), 0x40);
    }

    #[test]
    fn busy_and_nak_exceptions_have_their_own_counters() {
        let mut c = Counters::default();
        c.count_exception(ExceptionCode::ServerDeviceBusy);
        c.count_exception(ExceptionCode::Vendor(0x07));
        c.count_exception(ExceptionCode::IllegalFunction);
        assert_eq!((c.bus_exceptions, c.server_busy, c.server_nak), (3, 1, 1));
        assert_eq!(c.get(DiagnosticCode::ServerBusyCount), Some(1));
        assert_eq!(c.get(DiagnosticCode::ReturnQueryData), None);
    }
}
