//! The PDU test suite.
//!
//! - `golden`: an annotated request and response for every function code, from the manuals
//!   and the spec where they print one. Each is parsed, emitted into a buffer pre-filled with
//!   0xA5 and into every shorter one, cut at every length, lengthened by one byte, and fed to
//!   `wire_len` prefix by prefix.
//! - `limits`: every quantity and count at min − 1, min, max and max + 1, and every field with
//!   restricted values, each with the exact `PduError`.
//! - `props`: `parse(emit(x)) == x` for every function code with generated values, and
//!   arbitrary or mutated bytes that must never panic and, when they parse, re-emit exactly.
//! - `views`: `Bits` and `Registers`, wire views against value views.
//! - `bugs`: ignored tests, each showing one bug found while writing this suite.
//!
//! The checks they share live here, so that the goldens and the generated values go through
//! exactly the same assertions.

extern crate std;

use std::vec;
use std::vec::Vec;

use super::*;
use crate::codes::DiagnosticCode;

/// The body of `$pdu` if it is the variant `$variant`, else a panic naming what it was.
macro_rules! body {
    ($pdu:expr, $variant:path) => {
        match $pdu {
            $variant(body) => body,
            other => panic!("expected {}, got {other:?}", stringify!($variant)),
        }
    };
}

mod golden;
mod limits;
mod props;
mod regressions;
mod views;

// ── Requests and responses alike ────────────────────────────────────────────────────────────

/// Which way a PDU travels: it decides how bytes are parsed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Dir {
    Request,
    Response,
}

impl Dir {
    const BOTH: [Dir; 2] = [Dir::Request, Dir::Response];

    fn parse(self, pdu: &[u8]) -> Result<Pdu<'_>, PduError> {
        match self {
            Dir::Request => Request::parse(pdu).map(Pdu::Request),
            Dir::Response => Response::parse(pdu).map(Pdu::Response),
        }
    }

    fn wire_len(self, function: u8, head: &[u8]) -> WireLen {
        match self {
            Dir::Request => Request::wire_len(function, head),
            Dir::Response => Response::wire_len(function, head),
        }
    }
}

/// A request or a response, so that one set of checks serves both.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Pdu<'a> {
    Request(Request<'a>),
    Response(Response<'a>),
}

impl Pdu<'_> {
    fn dir(&self) -> Dir {
        match self {
            Pdu::Request(_) => Dir::Request,
            Pdu::Response(_) => Dir::Response,
        }
    }

    fn function(&self) -> FunctionCode {
        match self {
            Pdu::Request(r) => r.function(),
            Pdu::Response(r) => r.function(),
        }
    }

    fn encoded_len(&self) -> usize {
        match self {
            Pdu::Request(r) => r.encoded_len(),
            Pdu::Response(r) => r.encoded_len(),
        }
    }

    fn emit(&self, out: &mut [u8]) -> Result<usize, BufferTooSmall> {
        match self {
            Pdu::Request(r) => r.emit(out),
            Pdu::Response(r) => r.emit(out),
        }
    }

    /// The bytes `emit` writes into a buffer of exactly `encoded_len` bytes.
    #[track_caller]
    fn to_bytes(self) -> Vec<u8> {
        let mut out = vec![0xA5; self.encoded_len()];
        let n = self.emit(&mut out).unwrap_or_else(|e| panic!("emit of {self:?} into encoded_len bytes: {e}"));
        assert_eq!(n, out.len(), "emit of {self:?} wrote {n} bytes, encoded_len says {}", out.len());
        out
    }
}

// ── What a PDU's layout says about its prefixes and its length ──────────────────────────────

/// How the end of a PDU is found, which decides what its prefixes and extensions parse as.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Layout {
    /// The function code, a fixed layout or a count field tells where the PDU ends: every
    /// strict prefix is truncated and one byte more is trailing.
    Closed,
    /// The data runs to the end of the PDU (0x08 Return Query Data and unnamed sub-functions,
    /// custom codes, MEI types other than 0x0E): a prefix of at least `header` bytes is a
    /// shorter valid PDU, and one byte more a longer one.
    Open { header: usize },
}

impl Layout {
    fn of(dir: Dir, pdu: &[u8]) -> Layout {
        match pdu {
            [fc, ..] if dir == Dir::Response && fc & FunctionCode::EXCEPTION_BIT != 0 => Layout::Closed,
            [0x08, hi, lo, ..] => match DiagnosticCode::from_u16(u16::from_be_bytes([*hi, *lo])) {
                DiagnosticCode::ReturnQueryData | DiagnosticCode::Other(_) => Layout::Open { header: 3 },
                // Every other named sub-function carries exactly one word.
                _ => Layout::Closed,
            },
            [0x2B, mei, ..] if *mei != 0x0E => Layout::Open { header: 2 },
            [fc, ..] if !FunctionCode::from_u8(*fc).is_public() => Layout::Open { header: 1 },
            _ => Layout::Closed,
        }
    }
}

/// What `wire_len` may answer for the prefixes of a whole PDU's body.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum WireRule {
    /// `NeedMore` until enough is known, then `Known(body length)` for good.
    Exact(usize),
    /// 0x08 Return Query Data and unnamed sub-functions: `NeedMore` for the sub-function,
    /// then `Probable(4)`.
    Probable4,
    /// `NeedMore` for the first `after` bytes, then `Unknown`: custom codes (`after` = 0),
    /// MEI types other than 0x0E (`after` = 1).
    Unknown { after: usize },
}

impl WireRule {
    fn of(dir: Dir, pdu: &[u8]) -> WireRule {
        let body_len = pdu.len().saturating_sub(1);
        match pdu {
            [fc, ..] if dir == Dir::Response && fc & FunctionCode::EXCEPTION_BIT != 0 => WireRule::Exact(1),
            [0x08, hi, lo, ..] => match DiagnosticCode::from_u16(u16::from_be_bytes([*hi, *lo])) {
                DiagnosticCode::ReturnQueryData | DiagnosticCode::Other(_) => WireRule::Probable4,
                _ => WireRule::Exact(body_len),
            },
            [0x2B, mei, ..] if *mei != 0x0E => WireRule::Unknown { after: 1 },
            [fc, ..] if !FunctionCode::from_u8(*fc).is_public() => WireRule::Unknown { after: 0 },
            _ => WireRule::Exact(body_len),
        }
    }
}

// ── The checks every golden and every generated value goes through ──────────────────────────

/// A PDU from a manual or the spec, and the value it stands for (built by the constructors,
/// never parsed).
struct Golden {
    name: &'static str,
    pdu: Vec<u8>,
    value: Pdu<'static>,
}

/// All of the checks below, on one PDU and the value it encodes.
#[track_caller]
fn assert_golden(value: Pdu<'_>, pdu: &[u8]) {
    let parsed = assert_parses_to(value, pdu);
    assert_emits(value, pdu);
    assert_emits(parsed, pdu);
    assert_short_buffers_fail(value, pdu);
    assert_short_buffers_fail(parsed, pdu);
    assert_prefixes(value.dir(), pdu);
    assert_extra_byte(value.dir(), pdu);
    assert_wire_len(value.dir(), pdu);
}

/// `pdu` parses to `value`, with the function code of its first byte; returns the parsed view.
#[track_caller]
fn assert_parses_to<'p>(value: Pdu<'_>, pdu: &'p [u8]) -> Pdu<'p> {
    let parsed = value.dir().parse(pdu).unwrap_or_else(|e| panic!("{pdu:02X?} does not parse: {e}"));
    assert_eq!(parsed, value, "{pdu:02X?}");
    let fc = pdu[0];
    let is_exception = value.dir() == Dir::Response && fc & FunctionCode::EXCEPTION_BIT != 0;
    let function = if is_exception { fc & !FunctionCode::EXCEPTION_BIT } else { fc };
    assert_eq!(parsed.function().value(), function, "{pdu:02X?}");
    if let Pdu::Response(r) = parsed {
        assert_eq!(r.exception().is_some(), is_exception, "{pdu:02X?}");
    }
    parsed
}

/// `value` emits exactly `pdu` into a larger buffer pre-filled with 0xA5, leaves every byte
/// after it untouched, and says so in `encoded_len`.
#[track_caller]
fn assert_emits(value: Pdu<'_>, pdu: &[u8]) {
    assert_eq!(value.encoded_len(), pdu.len(), "encoded_len of {value:?}");
    let mut buf = [0xA5; MAX_PDU_LEN + 8];
    let n = value.emit(&mut buf).unwrap_or_else(|e| panic!("emit of {value:?}: {e}"));
    assert_eq!(&buf[..n], pdu, "emit of {value:?}");
    assert!(buf[n..].iter().all(|&b| b == 0xA5), "emit of {value:?} wrote past its {n} bytes: {buf:02X?}");
}

/// Emitting into any buffer shorter than `pdu` is `BufferTooSmall`, naming a field that ends
/// past the buffer but within the PDU.
#[track_caller]
fn assert_short_buffers_fail(value: Pdu<'_>, pdu: &[u8]) {
    for available in 0..pdu.len() {
        let mut buf = vec![0xA5; available];
        match value.emit(&mut buf) {
            Err(e) => {
                assert_eq!(e.available, available, "emit of {value:?}");
                assert!(
                    e.needed > available && e.needed <= pdu.len(),
                    "emit of {value:?} into {available} bytes: {e:?}"
                );
            }
            Ok(n) => panic!("emit of {value:?} into {available} bytes returned Ok({n})"),
        }
    }
}

/// Every strict prefix of `pdu` is an error: `Empty`, then `Truncated` with the prefix's length
/// available and a need within the whole PDU; except past the header of an open layout,
/// where a prefix is a shorter PDU that re-emits to itself.
#[track_caller]
fn assert_prefixes(dir: Dir, pdu: &[u8]) {
    let layout = Layout::of(dir, pdu);
    assert_eq!(dir.parse(&[]), Err(PduError::Empty));
    for len in 1..pdu.len() {
        let prefix = &pdu[..len];
        let result = dir.parse(prefix);
        match (layout, result) {
            (Layout::Open { header }, result) if len >= header => {
                assert_eq!(result.map(|p| p.to_bytes()), Ok(prefix.to_vec()), "{dir:?} prefix of {pdu:02X?}");
            }
            (_, Err(PduError::Truncated { needed, available })) => {
                assert_eq!(available, len, "{dir:?} prefix {prefix:02X?} of {pdu:02X?}");
                assert!(needed > len && needed <= pdu.len(), "{dir:?} prefix {prefix:02X?}: needed {needed}");
            }
            (_, other) => panic!("{dir:?} prefix {prefix:02X?} of {pdu:02X?} ({layout:?}): {other:?}"),
        }
    }
}

/// One byte more is `TrailingBytes { extra: 1 }` (or `TooLong` past 253 bytes), except for an
/// open layout, where it is a longer PDU that re-emits to itself.
#[track_caller]
fn assert_extra_byte(dir: Dir, pdu: &[u8]) {
    for extra in [0x00, 0xFF] {
        let longer = [pdu, &[extra]].concat();
        let result = dir.parse(&longer);
        if longer.len() > MAX_PDU_LEN {
            assert_eq!(result, Err(PduError::TooLong { len: longer.len() }));
            continue;
        }
        match (Layout::of(dir, pdu), result) {
            (Layout::Closed, result) => {
                assert_eq!(result, Err(PduError::TrailingBytes { extra: 1 }), "{dir:?} {longer:02X?}");
            }
            (Layout::Open { .. }, Ok(p)) => assert_eq!(p.to_bytes(), longer),
            (layout, Err(e)) => panic!("{dir:?} {longer:02X?} ({layout:?}): {e}"),
        }
    }
}

/// `wire_len`, asked about every prefix of the body (the bytes after the function code),
/// follows the rule for the PDU's function code: for a closed layout, `NeedMore` and then
/// `Known(body length)` for good, never another number.
#[track_caller]
fn assert_wire_len(dir: Dir, pdu: &[u8]) {
    let (&fc, body) = pdu.split_first().expect("a PDU has a function code");
    let rule = WireRule::of(dir, pdu);
    let mut known = false;
    for len in 0..=body.len() {
        let got = dir.wire_len(fc, &body[..len]);
        let ok = match rule {
            WireRule::Exact(n) => match got {
                WireLen::Known(m) => {
                    known = true;
                    m == n
                }
                WireLen::NeedMore => !known,
                WireLen::Probable(_) | WireLen::Unknown => false,
            },
            WireRule::Probable4 => got == if len < 2 { WireLen::NeedMore } else { WireLen::Probable(4) },
            WireRule::Unknown { after } => got == if len < after { WireLen::NeedMore } else { WireLen::Unknown },
        };
        assert!(
            ok,
            "{dir:?} wire_len(0x{fc:02X}, {:02X?}) = {got:?}; the whole PDU is {pdu:02X?} ({rule:?})",
            &body[..len]
        );
    }
    if let WireRule::Exact(n) = rule {
        assert!(known, "{dir:?} wire_len(0x{fc:02X}, whole body) never said Known({n})");
    }
}

/// Whatever `bytes` are, parse and `wire_len` do not panic; whatever parses re-emits to exactly
/// `bytes` (the encoding is canonical) and agrees with `wire_len`.
#[track_caller]
fn assert_parse_is_canonical(bytes: &[u8]) {
    for dir in Dir::BOTH {
        if let Some((&fc, body)) = bytes.split_first() {
            for len in 0..=body.len() {
                let _ = dir.wire_len(fc, &body[..len]);
            }
        }
        if let Ok(p) = dir.parse(bytes) {
            let canonical = canonical(dir, bytes);
            assert_eq!(p.encoded_len(), canonical.len(), "{dir:?} {bytes:02X?} parsed to {p:?}");
            assert_eq!(p.to_bytes(), canonical, "{dir:?} {bytes:02X?} parsed to {p:?}");
            assert_wire_len(dir, bytes);
        }
    }
}

/// The bytes an accepted PDU re-emits as: the same, but for a 0x0F request, whose coil data
/// goes out padded with zero bits and without the word padding the Hitachi/Omron inverters
/// add to its byte count.
fn canonical(dir: Dir, bytes: &[u8]) -> Vec<u8> {
    let (Dir::Request, [0x0F, s0, s1, q0, q1, _count, data @ ..]) = (dir, bytes) else { return bytes.to_vec() };
    let quantity = usize::from(u16::from_be_bytes([*q0, *q1]));
    let n = quantity.div_ceil(8);
    let mut out = vec![0x0F, *s0, *s1, *q0, *q1, u8::try_from(n).unwrap()];
    out.extend_from_slice(&data[..n]);
    if quantity % 8 != 0 {
        *out.last_mut().unwrap() &= (1u8 << (quantity % 8)) - 1;
    }
    out
}

/// Everything a generated value must satisfy: it fits in a PDU, emits, parses back to itself,
/// re-emits the same bytes from the parsed view, and its bytes pass every golden check.
#[track_caller]
fn assert_round_trip(value: Pdu<'_>) {
    assert!(value.encoded_len() <= MAX_PDU_LEN, "{value:?} is {} bytes", value.encoded_len());
    let bytes = value.to_bytes();
    assert_golden(value, &bytes);
}

// ── Building PDUs field by field ────────────────────────────────────────────────────────────

/// A PDU written field by field, for the tests that need malformed ones.
#[derive(Clone, Debug)]
struct Fields(Vec<u8>);

impl Fields {
    fn new(function: u8) -> Self {
        Fields(vec![function])
    }

    #[must_use]
    #[track_caller]
    fn byte(mut self, v: usize) -> Self {
        self.0.push(u8::try_from(v).expect("a byte field"));
        self
    }

    #[must_use]
    fn word(mut self, v: usize) -> Self {
        self.0.extend_from_slice(&word(v).to_be_bytes());
        self
    }

    #[must_use]
    fn bytes(mut self, b: &[u8]) -> Self {
        self.0.extend_from_slice(b);
        self
    }

    #[must_use]
    fn fill(mut self, n: usize, byte: u8) -> Self {
        self.0.resize(self.0.len() + n, byte);
        self
    }
}

impl core::ops::Deref for Fields {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        &self.0
    }
}

/// `v` as a 16-bit field.
#[track_caller]
fn word(v: usize) -> u16 {
    u16::try_from(v).expect("a 16-bit field")
}

/// `pdu` parses to a value that re-emits to it (`None`), or fails with exactly `expected`.
#[track_caller]
fn assert_parse(dir: Dir, pdu: &[u8], expected: Option<PduError>) {
    match (dir.parse(pdu), expected) {
        (Ok(p), None) => assert_eq!(p.to_bytes(), pdu, "{dir:?} {pdu:02X?}"),
        (result, expected) => assert_eq!(result.err(), expected, "{dir:?} {pdu:02X?}"),
    }
}
