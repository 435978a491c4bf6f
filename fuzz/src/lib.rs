//! Shared pieces of the ferrobus-proto fuzz targets.
//!
//! - [`Step`]: one chunk of bytes and the silence before it, the input of every receiver and
//!   engine target. Gaps are `u16` microseconds (up to 65 ms), so that one input mixes gaps
//!   shorter than t1.5 at 9600 baud (1.72 ms), between t1.5 and t3.5 (4.01 ms), and longer.
//! - [`drive_receiver`]: feeds steps to any [`Framing`] the way an IO layer would (sleeping
//!   until `poll_timeout()` whenever it comes before the next chunk) and checks the receiver
//!   contract after every call: frames are well formed, deadlines never lie in the past,
//!   and the statistics agree with the events handed out.
//! - [`MemoryHandler`]: a slave [`Handler`] over small in-memory tables that implements every
//!   data method, so the slave engine can serve every function code.
//! - [`Edit`]: a cut and an insertion in a text a user might write (a shipped example), so that
//!   the targets of configuration readers start from files that mostly parse.
//! - [`request_from`]: the request a master target submits, from the input's bytes, and
//!   [`assert_response_is`]: that a master's parsed response is the frame it came in.
//!
//! Built by cargo-fuzz, ferrobus-proto sees `cfg(fuzzing)`: its `crc_ok` then accepts every
//! frame (and the ASCII receiver skips its LRC), so random bytes reach the parsers. CRC
//! correctness can therefore not be asserted on received frames; it is asserted on what the
//! engines transmit, which they checksum with the real [`ferrobus_proto::crc::crc16`].

use core::time::Duration;

use arbitrary::Arbitrary;
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::{Adu, Framing, LineConfig, LineTiming, RxEvent, expire, feed};
use ferrobus_proto::pdu::{
    Bits, MAX_PDU_LEN, MaskWrite, ReadRegisters, ReadWriteRegisters, Registers, Request, Response,
};
use ferrobus_proto::slave::Handler;
use ferrobus_proto::time::Instant;

/// One chunk of received bytes after `gap_us` microseconds of silence.
#[derive(Arbitrary, Clone, Debug)]
pub struct Step {
    /// Silence before the chunk, in microseconds.
    pub gap_us: u16,
    /// The bytes, arriving together (one timestamp).
    pub bytes: Vec<u8>,
}

impl Step {
    /// The instant this step's bytes arrive, `t` being the previous arrival.
    pub fn arrival(&self, t: Instant) -> Instant {
        t.saturating_add(Duration::from_micros(u64::from(self.gap_us)))
    }
}

/// 9600 baud 8E1: t1.5 = 1.71875 ms, t3.5 = 4.010417 ms.
pub fn line_9600_8e1() -> LineTiming {
    LineTiming::new(&LineConfig::new(9600).expect("9600 is not zero"))
}

/// How many timeouts one wait may handle before the engine counts as spinning: each timeout
/// settles at least one buffered byte, and no buffer holds more than a few hundred.
pub const MAX_TIMEOUTS_PER_WAIT: usize = 4096;

/// The request a master target submits from `bytes`: sent as they are (`submit_raw`, the
/// request `None`) when `raw` and they fit a PDU, else parsed, a read of 10 holding
/// registers where they do not parse; with the PDU that goes out either way.
pub fn request_from(raw: bool, bytes: &[u8]) -> (Option<Request<'_>>, Vec<u8>) {
    if raw && !bytes.is_empty() && bytes.len() <= MAX_PDU_LEN {
        return (None, bytes.to_vec());
    }
    let fallback = Request::ReadHoldingRegisters(ReadRegisters::new(0, 10).expect("valid"));
    let request = Request::parse(bytes).unwrap_or(fallback);
    let mut out = [0u8; MAX_PDU_LEN];
    let n = request.emit(&mut out).expect("fits");
    (Some(request), out[..n].to_vec())
}

/// Asserts that `response`, which a master handed for `request`, is `frame` (the PDU of the
/// frame it came in): for 0x01/0x02 trimmed to the quantity asked, the bits past it zero; for
/// 0x03/0x04 with the register count asked.
pub fn assert_response_is(request: &Request<'_>, response: &Response<'_>, frame: &[u8]) {
    assert_eq!(response.function(), request.function(), "response to another function");
    assert_eq!(frame.first().copied(), Some(request.function().value()));
    let mut out = [0u8; MAX_PDU_LEN];
    let n = response.emit(&mut out).expect("a response fits");
    match request {
        Request::ReadCoils(q) | Request::ReadDiscreteInputs(q) => {
            // Trimmed to the quantity asked: the bits past it go out as zeros.
            assert_eq!(n, 2 + q.response_byte_count(), "bit reply not trimmed to the request");
            let mut want = frame[..n].to_vec();
            let used = q.quantity() % 8;
            if used != 0 {
                want[n - 1] &= (1u8 << used) - 1;
            }
            assert_eq!(&out[..n], want.as_slice(), "the bits are not the frame's");
        }
        _ => assert_eq!(&out[..n], frame, "the response is not the frame received"),
    }
    if let (
        Request::ReadHoldingRegisters(q) | Request::ReadInputRegisters(q),
        Response::ReadHoldingRegisters(r) | Response::ReadInputRegisters(r),
    ) = (request, response)
    {
        assert_eq!(r.values().len(), usize::from(q.quantity()), "register count not checked");
    }
}

/// What a receiver handed out, summed over a run.
#[derive(Clone, Copy, Debug, Default)]
pub struct Tally {
    /// Bytes pushed in.
    pub fed: u64,
    /// Frames delivered.
    pub frames: u32,
    /// Sum of the delivered PDUs' lengths.
    pub pdu_bytes: u64,
    /// Discard events delivered.
    pub discard_events: u32,
    /// Sum of the bytes of those events.
    pub discarded: u64,
}

/// Feeds `steps` to `framing`, handling every timeout that falls before the next chunk and all
/// remaining ones at the end, and checks the receiver contract after every call:
///
/// - every frame's PDU is 1–`max_pdu` bytes and its `end` is not in the future;
/// - `poll_timeout()` is never earlier than the last `now` handed in;
/// - `stats().frames` equals the frames delivered, `stats().discarded_bytes` the bytes of the
///   discard events delivered, and `stats().discards` is at least the number of those events
///   (two runs not polled in between are reported as one);
/// - the receiver does not ask for more than [`MAX_TIMEOUTS_PER_WAIT`] timeouts in one wait.
///
/// `on_frame` sees every frame with the time it was delivered.
pub fn drive_receiver<F: Framing>(
    framing: &mut F,
    steps: &[Step],
    max_pdu: usize,
    mut on_frame: impl FnMut(&Adu<'_>, Instant),
) -> Tally {
    let mut tally = Tally::default();
    let mut t = Instant::ZERO;
    for step in steps {
        let next = step.arrival(t);
        run_timeouts(framing, &mut t, Some(next), max_pdu, &mut tally, &mut on_frame);
        t = next;
        tally.fed += step.bytes.len() as u64;
        feed(framing, t, &step.bytes, |ev| on_event(&ev, t, max_pdu, &mut tally, &mut on_frame));
        check_after_call(framing, t, &tally);
    }
    run_timeouts(framing, &mut t, None, max_pdu, &mut tally, &mut on_frame);
    tally
}

fn run_timeouts<F: Framing>(
    framing: &mut F,
    t: &mut Instant,
    until: Option<Instant>,
    max_pdu: usize,
    tally: &mut Tally,
    on_frame: &mut impl FnMut(&Adu<'_>, Instant),
) {
    for round in 0.. {
        let Some(deadline) = framing.poll_timeout() else { return };
        if until.is_some_and(|u| deadline > u) {
            return;
        }
        assert!(round < MAX_TIMEOUTS_PER_WAIT, "receiver keeps asking for timeouts (deadline {deadline}, now {t})");
        assert!(deadline >= *t, "deadline {deadline} is before the last now {t}");
        *t = deadline;
        let now = *t;
        expire(framing, now, |ev| on_event(&ev, now, max_pdu, tally, on_frame));
        check_after_call(framing, now, tally);
    }
}

fn on_event(
    event: &RxEvent<'_>,
    now: Instant,
    max_pdu: usize,
    tally: &mut Tally,
    on_frame: &mut impl FnMut(&Adu<'_>, Instant),
) {
    match event {
        RxEvent::Frame(adu) => {
            assert!(!adu.pdu.is_empty(), "empty PDU delivered: {adu:?}");
            assert!(adu.pdu.len() <= max_pdu, "PDU of {} bytes delivered (max {max_pdu})", adu.pdu.len());
            assert!(adu.end <= now, "frame ends at {} after now {now}", adu.end);
            tally.frames += 1;
            tally.pdu_bytes += adu.pdu.len() as u64;
            on_frame(adu, now);
        }
        RxEvent::Discarded { bytes, at, .. } => {
            assert!(*bytes > 0, "empty discard event");
            assert!(*at <= now, "discard decided at {at} after now {now}");
            tally.discard_events += 1;
            tally.discarded += *bytes as u64;
        }
    }
}

fn check_after_call<F: Framing>(framing: &F, now: Instant, tally: &Tally) {
    if let Some(deadline) = framing.poll_timeout() {
        assert!(deadline >= now, "poll_timeout {deadline} is before the last now {now}");
    }
    let stats = framing.stats();
    assert_eq!(stats.frames, tally.frames, "stats.frames vs frames delivered");
    assert_eq!(u64::from(stats.discarded_bytes), tally.discarded, "stats.discarded_bytes vs discard events");
    assert!(stats.discards >= tally.discard_events, "fewer discards counted than reported: {stats:?} {tally:?}");
    assert!(stats.checksum_errors + stats.overruns <= stats.discards, "discard reasons exceed discards: {stats:?}");
}

/// Coils, discrete inputs, holding and input registers in this many addresses from 0.
pub const TABLE_LEN: usize = 64;

/// A slave handler over small in-memory tables for units 1 and 2. Addresses past
/// [`TABLE_LEN`] answer exception 02 (Illegal Data Address).
#[derive(Clone, Debug)]
pub struct MemoryHandler {
    /// Coils (0x01, 0x05, 0x0F).
    pub coils: [bool; TABLE_LEN],
    /// Discrete inputs (0x02).
    pub inputs: [bool; TABLE_LEN],
    /// Holding registers (0x03, 0x06, 0x10, 0x16, 0x17).
    pub holding: [u16; TABLE_LEN],
    /// Input registers (0x04).
    pub input_registers: [u16; TABLE_LEN],
    /// Two files of [`TABLE_LEN`] records (0x14, 0x15); file numbers 1 and 2.
    pub files: [[u16; TABLE_LEN]; 2],
    /// The wait of unit 2 before it replies (on top of t3.5); unit 1 uses the engine's.
    pub unit2_wait: Duration,
    /// Data calls made, to keep the optimiser honest.
    pub calls: u64,
}

impl MemoryHandler {
    /// Tables filled with a recognisable pattern.
    pub fn new(unit2_wait: Duration) -> Self {
        let mut h = MemoryHandler {
            coils: [false; TABLE_LEN],
            inputs: [false; TABLE_LEN],
            holding: [0; TABLE_LEN],
            input_registers: [0; TABLE_LEN],
            files: [[0; TABLE_LEN]; 2],
            unit2_wait,
            calls: 0,
        };
        for i in 0..TABLE_LEN {
            h.coils[i] = i % 3 == 0;
            h.inputs[i] = i % 5 == 0;
            h.holding[i] = 0x1000 + i as u16;
            h.input_registers[i] = 0x2000 + i as u16;
            h.files[0][i] = 0x3000 + i as u16;
            h.files[1][i] = 0x4000 + i as u16;
        }
        h
    }

    fn range(start: u16, len: usize) -> Result<core::ops::Range<usize>, ExceptionCode> {
        let start = usize::from(start);
        let end = start.checked_add(len).ok_or(ExceptionCode::IllegalDataAddress)?;
        if end > TABLE_LEN { Err(ExceptionCode::IllegalDataAddress) } else { Ok(start..end) }
    }

    fn file(&mut self, file: u16) -> Result<&mut [u16; TABLE_LEN], ExceptionCode> {
        match file {
            1 => Ok(&mut self.files[0]),
            2 => Ok(&mut self.files[1]),
            _ => Err(ExceptionCode::IllegalDataAddress),
        }
    }
}

const VENDOR: &[u8] = b"ferrobus";
const PRODUCT: &[u8] = b"FUZZ-1";
const REVISION: &[u8] = b"V0.1";
/// A long private object, so that a stream of objects needs "more follows".
const LONG_OBJECT: &[u8] = &[b'x'; 200];

impl Handler for MemoryHandler {
    fn response_wait(&self, unit: u8) -> Option<Duration> {
        (unit == 2).then_some(self.unit2_wait)
    }

    fn read_coils(&mut self, _unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.calls += 1;
        out.copy_from_slice(&self.coils[Self::range(start, out.len())?]);
        Ok(())
    }

    fn read_discrete_inputs(&mut self, _unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.calls += 1;
        out.copy_from_slice(&self.inputs[Self::range(start, out.len())?]);
        Ok(())
    }

    fn read_holding_registers(&mut self, _unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.calls += 1;
        out.copy_from_slice(&self.holding[Self::range(start, out.len())?]);
        Ok(())
    }

    fn read_input_registers(&mut self, _unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.calls += 1;
        out.copy_from_slice(&self.input_registers[Self::range(start, out.len())?]);
        Ok(())
    }

    fn write_single_coil(&mut self, _unit: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        self.calls += 1;
        let r = Self::range(address, 1)?;
        self.coils[r.start] = value;
        Ok(())
    }

    fn write_single_register(&mut self, _unit: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        self.calls += 1;
        let r = Self::range(address, 1)?;
        self.holding[r.start] = value;
        Ok(())
    }

    fn write_multiple_coils(&mut self, _unit: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        self.calls += 1;
        let r = Self::range(start, values.len())?;
        let n = values.copy_to(&mut self.coils[r]);
        assert_eq!(n, values.len());
        Ok(())
    }

    fn write_multiple_registers(&mut self, _unit: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        self.calls += 1;
        let r = Self::range(start, values.len())?;
        let n = values.copy_to(&mut self.holding[r]);
        assert_eq!(n, values.len());
        Ok(())
    }

    fn mask_write_register(&mut self, _unit: u8, mask: MaskWrite) -> Result<(), ExceptionCode> {
        self.calls += 1;
        let r = Self::range(mask.address, 1)?;
        self.holding[r.start] = mask.apply(self.holding[r.start]);
        Ok(())
    }

    fn read_write_multiple_registers(
        &mut self,
        unit: u8,
        request: &ReadWriteRegisters<'_>,
        out: &mut [u16],
    ) -> Result<(), ExceptionCode> {
        // Check both ranges before writing, so that a refused request changes nothing.
        let read_start = request.read().start();
        Self::range(read_start, out.len())?;
        self.write_multiple_registers(unit, request.write_start(), request.values())?;
        self.read_holding_registers(unit, read_start, out)
    }

    fn read_exception_status(&mut self, _unit: u8) -> Result<u8, ExceptionCode> {
        self.calls += 1;
        Ok(self.coils[..8].iter().enumerate().fold(0u8, |acc, (i, &on)| acc | (u8::from(on) << i)))
    }

    fn report_server_id(&mut self, unit: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.calls += 1;
        let id = [unit, 0xFF, b'f', b'u', b'z', b'z'];
        out.get_mut(..id.len()).ok_or(ExceptionCode::ServerDeviceFailure)?.copy_from_slice(&id);
        Ok(id.len())
    }

    fn read_file_record(&mut self, _unit: u8, file: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.calls += 1;
        let r = Self::range(record, out.len())?;
        out.copy_from_slice(&self.file(file)?[r]);
        Ok(())
    }

    fn write_file_record(
        &mut self,
        _unit: u8,
        file: u16,
        record: u16,
        values: Registers<'_>,
    ) -> Result<(), ExceptionCode> {
        self.calls += 1;
        let r = Self::range(record, values.len())?;
        values.copy_to(&mut self.file(file)?[r]);
        Ok(())
    }

    fn read_fifo_queue(&mut self, _unit: u8, address: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        self.calls += 1;
        // The FIFO at address A holds A % 32 values (32 and up: exception 02).
        let n = usize::from(address);
        if n > out.len() {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        for (i, slot) in out.iter_mut().take(n).enumerate() {
            *slot = self.holding[i];
        }
        Ok(n)
    }

    fn device_object(&mut self, _unit: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        let value = match id {
            0x00 => VENDOR,
            0x01 => PRODUCT,
            0x02 => REVISION,
            0x80 | 0x81 => LONG_OBJECT,
            _ => return None,
        };
        let n = value.len().min(out.len());
        out[..n].copy_from_slice(&value[..n]);
        Some(n)
    }

    fn encapsulated(&mut self, _unit: u8, mei_type: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.calls += 1;
        if mei_type == 0x0D && data.first() == Some(&0) {
            return Err(ExceptionCode::IllegalDataValue);
        }
        let n = data.len().min(out.len());
        out[..n].copy_from_slice(&data[..n]);
        Ok(n)
    }

    fn custom(&mut self, _unit: u8, function: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.calls += 1;
        if function.is_multiple_of(2) {
            return Err(ExceptionCode::IllegalFunction);
        }
        // Echo the data reversed.
        let n = data.len().min(out.len());
        for (slot, &b) in out.iter_mut().zip(data.iter().rev()) {
            *slot = b;
        }
        Ok(n)
    }
}

/// Cut `cut` bytes at `at` (both moved to character boundaries) and put `put` there.
#[derive(Arbitrary, Debug)]
pub struct Edit {
    /// Where, as an offset wrapped to the text's length.
    pub at: u16,
    /// How many bytes to cut there.
    pub cut: u8,
    /// What to put in their place.
    pub put: Put,
}

/// What an [`Edit`] puts in.
#[derive(Arbitrary, Debug)]
pub enum Put {
    /// Nothing (a cut only).
    Nothing,
    /// Any text.
    Text(String),
    /// One of the target's tokens of its format, by index (wrapped).
    Token(u8),
}

impl Edit {
    /// Applies the edit to `text`; a [`Put::Token`] picks from `tokens`.
    pub fn apply(self, text: &mut String, tokens: &[&str]) {
        let start = text.floor_char_boundary(usize::from(self.at) % (text.len() + 1));
        let end = text.ceil_char_boundary(start + usize::from(self.cut));
        let put = match self.put {
            Put::Nothing => String::new(),
            Put::Text(put) => put,
            Put::Token(i) if !tokens.is_empty() => tokens[usize::from(i) % tokens.len()].to_owned(),
            Put::Token(_) => String::new(),
        };
        text.replace_range(start..end, &put);
    }
}
