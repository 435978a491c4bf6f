//! Bus scanning, the decisions: which line settings to try first, what to send, how long to
//! wait, what a probe's outcome says about the unit asked, and what listening to a line heard.
//!
//! Spec: MODBUS over Serial Line V1.02 §2.4.1 (a unit that detects a transmission error sends
//! nothing; a message to a missing unit times out), §2.5.1 (8E1 is the default format, no
//! parity asks for two stop bits), §3.2 (19200 is the required default rate, 9600 required too).
//!
//! - **Order.** [`rank`] puts 19200 8E1 first (the spec's default), then 9600 8E1, then 8N1 at
//!   19200 and 9600, then everything else by how common its rate is.
//! - **The probe.** [`Probe`]: a read of one item (FC03 at address 0 by default). A scanner never
//!   broadcasts and never writes; any reply proves presence, a normal one or *any* exception.
//! - **Timing.** [`ProbeTiming`]: a short wait for the first byte of a reply, lengthened by the
//!   wire time of the reply expected once it has begun (the master engine gives a frame still
//!   arriving at its deadline the time a whole frame takes); a slower wait for the second pass.
//! - **What a probe heard.** [`Answer::from_heard`] sorts what came instead of a reply: bytes
//!   that did not frame are a [`Lead`] (something answers, at other settings or over noise),
//!   another unit's frame is other traffic, nothing is silence.
//! - **Listening.** [`Survey`] takes (now, bytes) from a line it does not transmit on and says
//!   whether another master is active there ([`LineActivity::Traffic`], with the units), whether
//!   something talks at other settings ([`LineActivity::Noise`]), or whether the line is quiet.

use core::time::Duration;

use crate::codes::ExceptionCode;
use crate::error::{DiscardReason, PduError};
use crate::frame::{Direction, Expect, Framing, LineConfig, LineTiming, Parity, RxEvent, StopBits, expire, feed, rtu};
use crate::master::HeardInstead;
use crate::pdu::{ReadBits, ReadRegisters, Request};
use crate::slave::UnitSet;
use crate::time::Instant;

/// The default wait for the first byte of a reply: devices typically answer within 5–45 ms,
/// 60 ms at most (JUMO LOGOSCREEN nt §4.3); a drive with a longer response wait (3G3RX C078
/// above about 95 ms) needs a longer one.
pub const DEFAULT_FIRST_BYTE: Duration = Duration::from_millis(100);

/// The default wait for the first byte in the second pass, for units that gave a lead: the
/// low end of the spec's "1 s to several seconds" response timeout (§2.4.1).
pub const DEFAULT_SLOW_FIRST_BYTE: Duration = Duration::from_secs(1);

/// A character format of an 8-data-bit RTU line.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum CharFormat {
    /// 8 data bits, even parity, one stop bit: the spec's default.
    E1,
    /// 8 data bits, odd parity, one stop bit.
    O1,
    /// 8 data bits, no parity, two stop bits: what the spec asks for without parity.
    N2,
    /// 8 data bits, no parity, one stop bit: common in drives.
    N1,
}

impl CharFormat {
    /// All four, in the order the spec makes likely.
    pub const ALL: [CharFormat; 4] = [CharFormat::E1, CharFormat::O1, CharFormat::N2, CharFormat::N1];

    /// `8E1`, `8o1`, `8N2`, `8n1` (case does not matter); `None` for anything else.
    pub fn parse(text: &str) -> Option<CharFormat> {
        let bytes = text.as_bytes();
        let [b'8', parity, stop] = bytes else { return None };
        match (parity.to_ascii_uppercase(), stop) {
            (b'E', b'1') => Some(CharFormat::E1),
            (b'O', b'1') => Some(CharFormat::O1),
            (b'N', b'2') => Some(CharFormat::N2),
            (b'N', b'1') => Some(CharFormat::N1),
            _ => None,
        }
    }

    /// `line` with this format's parity and stop bits.
    pub const fn apply(self, line: LineConfig) -> LineConfig {
        let (parity, stop) = match self {
            CharFormat::E1 => (Parity::Even, StopBits::One),
            CharFormat::O1 => (Parity::Odd, StopBits::One),
            CharFormat::N2 => (Parity::None, StopBits::Two),
            CharFormat::N1 => (Parity::None, StopBits::One),
        };
        line.with_parity(parity).with_stop_bits(stop)
    }

    /// The format of `line`, if it has 8 data bits and one of the four.
    pub fn of(line: &LineConfig) -> Option<CharFormat> {
        if line.data_bits != crate::frame::DataBits::Eight {
            return None;
        }
        CharFormat::ALL.into_iter().find(|f| f.apply(*line) == *line)
    }

    /// `8E1`.
    pub const fn name(self) -> &'static str {
        match self {
            CharFormat::E1 => "8E1",
            CharFormat::O1 => "8O1",
            CharFormat::N2 => "8N2",
            CharFormat::N1 => "8N1",
        }
    }
}

/// Baud rates by how common they are on Modbus lines (the spec's two required ones first).
const BAUD_LIKELIHOOD: [u32; 8] = [19_200, 9_600, 38_400, 115_200, 57_600, 4_800, 2_400, 1_200];

/// Where a line setting comes in the sweep: lower first. 19200 8E1 (0), 9600 8E1 (1), 19200
/// and 9600 8N1 (2, 3), then the rest by rate (the common rates first, others from the
/// lowest) and by format (8E1, 8N1, 8N2, 8O1). Sort with a stable sort to keep the order given
/// among equals.
pub fn rank(line: &LineConfig) -> u64 {
    let baud = line.baud();
    let format = CharFormat::of(line);
    match (baud, format) {
        (19_200, Some(CharFormat::E1)) => return 0,
        (9_600, Some(CharFormat::E1)) => return 1,
        (19_200, Some(CharFormat::N1)) => return 2,
        (9_600, Some(CharFormat::N1)) => return 3,
        _ => {}
    }
    let by_rate = match BAUD_LIKELIHOOD.iter().position(|&b| b == baud) {
        Some(i) => u64::try_from(i).unwrap_or(u64::MAX),
        None => u64::from(baud).saturating_add(BAUD_LIKELIHOOD.len() as u64),
    };
    let by_format = match format {
        Some(CharFormat::E1) => 0,
        Some(CharFormat::N1) => 1,
        Some(CharFormat::N2) => 2,
        Some(CharFormat::O1) => 3,
        None => 4,
    };
    // 4 + rate × 8 + format: above the four fixed places, rates apart, formats within a rate.
    4u64.saturating_add(by_rate.saturating_mul(8)).saturating_add(by_format)
}

/// The read a probe sends.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum ProbeFunction {
    /// 0x01 Read Coils.
    Coils,
    /// 0x02 Read Discrete Inputs.
    DiscreteInputs,
    /// 0x03 Read Holding Registers: the default.
    HoldingRegisters,
    /// 0x04 Read Input Registers.
    InputRegisters,
}

impl ProbeFunction {
    /// The function for a code, if it is one of the four reads (a probe never writes).
    pub fn from_code(code: u8) -> Option<ProbeFunction> {
        match code {
            0x01 => Some(ProbeFunction::Coils),
            0x02 => Some(ProbeFunction::DiscreteInputs),
            0x03 => Some(ProbeFunction::HoldingRegisters),
            0x04 => Some(ProbeFunction::InputRegisters),
            _ => None,
        }
    }

    /// The function code.
    pub const fn code(self) -> u8 {
        match self {
            ProbeFunction::Coils => 0x01,
            ProbeFunction::DiscreteInputs => 0x02,
            ProbeFunction::HoldingRegisters => 0x03,
            ProbeFunction::InputRegisters => 0x04,
        }
    }
}

/// What a scanner sends to each unit: a read of one item.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Probe {
    /// The read.
    pub function: ProbeFunction,
    /// The address read.
    pub address: u16,
}

impl Default for Probe {
    /// FC03 at address 0, one register.
    fn default() -> Self {
        Probe { function: ProbeFunction::HoldingRegisters, address: 0 }
    }
}

impl Probe {
    /// The request: one item at the address (always valid: one item fits at every address).
    pub fn request(&self) -> Result<Request<'static>, PduError> {
        let a = self.address;
        Ok(match self.function {
            ProbeFunction::Coils => Request::ReadCoils(ReadBits::new(a, 1)?),
            ProbeFunction::DiscreteInputs => Request::ReadDiscreteInputs(ReadBits::new(a, 1)?),
            ProbeFunction::HoldingRegisters => Request::ReadHoldingRegisters(ReadRegisters::new(a, 1)?),
            ProbeFunction::InputRegisters => Request::ReadInputRegisters(ReadRegisters::new(a, 1)?),
        })
    }

    /// The RTU request's length: address, function, start, count, CRC.
    pub const fn request_len(&self) -> usize {
        8
    }

    /// The RTU reply's length: address, function, byte count, one register (2) or one byte of
    /// bits, CRC.
    pub const fn reply_len(&self) -> usize {
        match self.function {
            ProbeFunction::Coils | ProbeFunction::DiscreteInputs => 6,
            ProbeFunction::HoldingRegisters | ProbeFunction::InputRegisters => 7,
        }
    }
}

/// How long a probe waits.
///
/// The reply timeout handed to the master engine is [`ProbeTiming::timeout`]: the wait for
/// the first byte plus the wire time of the expected reply, so a reply that begins just
/// before the first-byte wait ends still arrives whole. A longer reply still arriving then is
/// given the time of a whole frame by the engine. Silence costs the timeout, so the sweep's
/// length is about units × (request wire time + t3.5 + timeout) per line setting.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ProbeTiming {
    /// How long the first byte of a reply may take, from the end of the request.
    pub first_byte: Duration,
    /// The expected reply's wire time at the line's settings.
    pub reply: Duration,
}

impl ProbeTiming {
    /// The timing of `probe` on a line with `timing`, waiting `first_byte` for a reply to begin.
    pub fn new(timing: &LineTiming, probe: &Probe, first_byte: Duration) -> Self {
        ProbeTiming { first_byte, reply: timing.transmit_time(probe.reply_len()) }
    }

    /// The reply timeout: first byte, then the reply's wire time.
    pub fn timeout(&self) -> Duration {
        self.first_byte.saturating_add(self.reply)
    }

    /// The least one silent probe takes: the request on the wire, the t3.5 before it, and the
    /// timeout. What a sweep of `n` silent units takes at least is `n` times this.
    pub fn silent_probe(&self, timing: &LineTiming, probe: &Probe) -> Duration {
        timing.transmit_time(probe.request_len()).saturating_add(timing.t3_5()).saturating_add(self.timeout())
    }
}

/// Bytes that came instead of a reply and made no good frame: something answers, but the
/// line settings or the line itself are wrong.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Lead {
    /// A frame with a wrong CRC; its address and function code, if it had them (they may be
    /// damaged too).
    BadChecksum {
        /// Address and function code at its start.
        head: Option<(u8, u8)>,
    },
    /// Bytes that made no frame.
    Garbage {
        /// How many.
        bytes: usize,
        /// Why.
        reason: DiscardReason,
    },
}

/// What one probe heard, for the unit asked.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Answer {
    /// A normal reply: present.
    Reply,
    /// An exception reply: present, it refused the probe.
    Exception(ExceptionCode),
    /// A valid frame from the unit that does not answer the probe (another function code, a
    /// wrong byte count): present, but it misreads the request.
    Mismatch,
    /// Bytes that did not frame: a lead, not a presence.
    Lead(Lead),
    /// A valid frame from another unit: other traffic on the line.
    OtherTraffic {
        /// Its address.
        unit: u8,
        /// Its function code.
        function: u8,
    },
    /// Nothing came.
    Silence,
}

impl Answer {
    /// What a probe that got no usable reply heard, from the master's diagnosis of its
    /// timeout (`None`: silence).
    pub fn from_heard(heard: Option<HeardInstead>) -> Answer {
        match heard {
            None => Answer::Silence,
            Some(HeardInstead::BadChecksum { head, .. }) => Answer::Lead(Lead::BadChecksum { head }),
            Some(HeardInstead::Garbage { bytes, reason }) => Answer::Lead(Lead::Garbage { bytes, reason }),
            Some(HeardInstead::OtherUnit { unit, function }) => Answer::OtherTraffic { unit, function },
            Some(
                HeardInstead::OtherTransaction { .. }
                | HeardInstead::WrongFunction { .. }
                | HeardInstead::TooEarly { .. }
                | HeardInstead::Suspect { .. },
            ) => Answer::Mismatch,
        }
    }

    /// Whether it proves a device answers at the unit's address: any valid frame from it.
    pub fn proves_presence(&self) -> bool {
        matches!(self, Answer::Reply | Answer::Exception(_) | Answer::Mismatch)
    }

    /// Whether it is a lead for the second, slower pass.
    pub fn is_lead(&self) -> bool {
        matches!(self, Answer::Lead(_))
    }
}

/// The activity a [`Survey`] found on a line at one setting: another master's traffic,
/// noise, or quiet. (What a master heard instead of the reply it waited for is
/// [`HeardInstead`].)
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum LineActivity {
    /// CRC-valid frames: another master is active at these settings.
    Traffic {
        /// Every unit address seen in a valid frame (0 for broadcasts).
        units: UnitSet,
        /// Valid requests.
        requests: u32,
        /// Valid responses.
        responses: u32,
        /// Valid frames that could be either (a write echo).
        either: u32,
    },
    /// Bytes, but no valid frame: something talks at other settings (or over a bad line).
    Noise {
        /// Frames with a wrong CRC.
        bad_checksums: u32,
        /// Bytes thrown away in all.
        bytes: u32,
    },
    /// Nothing at all.
    Quiet,
}

/// Listens to a line without transmitting: frames requests and responses alike by the
/// function code's length and t3.5, and counts what it finds.
#[derive(Clone, Debug)]
pub struct Survey {
    codec: rtu::RtuCodec,
    units: UnitSet,
    requests: u32,
    responses: u32,
    either: u32,
    bad_checksums: u32,
    discarded: u32,
}

impl Survey {
    /// A listener for a line with `timing`.
    pub fn new(timing: LineTiming) -> Self {
        Survey {
            codec: rtu::RtuCodec::new(timing, Expect::Both),
            units: UnitSet::EMPTY,
            requests: 0,
            responses: 0,
            either: 0,
            bad_checksums: 0,
            discarded: 0,
        }
    }

    /// The same listener with another frame-ending silence (a PC's serial stack delivers bytes
    /// in bursts, so one waits longer for the rest of a frame of unknown length).
    #[must_use]
    pub fn with_frame_gap(mut self, gap: Duration) -> Self {
        self.codec = self.codec.with_frame_gap(gap);
        self
    }

    /// Bytes arrived at `now`.
    pub fn on_bytes(&mut self, now: Instant, bytes: &[u8]) {
        let Survey { codec, .. } = self;
        let mut events = Tally::default();
        feed(codec, now, bytes, |event| events.count(&event));
        self.add(&events);
    }

    /// When [`Survey::handle_timeout`] is next due (the silence that ends a frame).
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.codec.poll_timeout()
    }

    /// `now` has come: a frame whose silence has passed is decided.
    pub fn handle_timeout(&mut self, now: Instant) {
        let Survey { codec, .. } = self;
        let mut events = Tally::default();
        expire(codec, now, |event| events.count(&event));
        self.add(&events);
    }

    /// What was heard so far. Call [`Survey::handle_timeout`] at the end of listening first,
    /// so that a frame still open is decided.
    pub fn heard(&self) -> LineActivity {
        if !self.units.is_empty() {
            return LineActivity::Traffic {
                units: self.units,
                requests: self.requests,
                responses: self.responses,
                either: self.either,
            };
        }
        if self.discarded > 0 {
            return LineActivity::Noise { bad_checksums: self.bad_checksums, bytes: self.discarded };
        }
        LineActivity::Quiet
    }

    fn add(&mut self, tally: &Tally) {
        for unit in tally.units.iter() {
            self.units.insert(unit);
        }
        self.requests = self.requests.saturating_add(tally.requests);
        self.responses = self.responses.saturating_add(tally.responses);
        self.either = self.either.saturating_add(tally.either);
        self.bad_checksums = self.bad_checksums.saturating_add(tally.bad_checksums);
        self.discarded = self.discarded.saturating_add(tally.discarded);
    }
}

/// The events of one call, counted.
#[derive(Default)]
struct Tally {
    units: UnitSet,
    requests: u32,
    responses: u32,
    either: u32,
    bad_checksums: u32,
    discarded: u32,
}

impl Tally {
    fn count(&mut self, event: &RxEvent<'_>) {
        match *event {
            RxEvent::Frame(adu) => {
                self.units.insert(adu.header.unit);
                let counter = match adu.direction {
                    Direction::Request => &mut self.requests,
                    Direction::Response => &mut self.responses,
                    Direction::Either => &mut self.either,
                };
                *counter = counter.saturating_add(1);
            }
            RxEvent::Discarded { bytes, reason, .. } => {
                if reason == DiscardReason::ChecksumMismatch {
                    self.bad_checksums = self.bad_checksums.saturating_add(1);
                }
                self.discarded = self.discarded.saturating_add(u32::try_from(bytes).unwrap_or(u32::MAX));
            }
        }
    }
}

#[cfg(test)]
mod tests;
