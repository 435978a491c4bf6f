//! # ferrobus-proto: the Modbus protocol core
//!
//! Everything about Modbus that can be decided from bytes and time, and nothing else: no IO,
//! no clock, no allocation, no `unsafe`, no `std`. It runs as well on a Cortex-M as on a PC,
//! and every timing rule in it can be tested without sleeping.
//!
//! ```text
//!   bytes + now ──▶ ┌──────────────────────────────────────────────┐ ──▶ bytes to send
//!                   │ policy    retry.rs  retries, unit backoff,   │
//!                   │           IO backoff, each at `now`          │
//!                   ├──────────────────────────────────────────────┤
//!                   │ engines   master.rs  slave/                  │ ──▶ poll_timeout()
//!                   │           one request in flight, t3.5 gaps,  │ ──▶ events
//!                   │           unit filter, counters, reply wait  │
//!                   ├──────────────────────────────────────────────┤
//!                   │ framing   frame/  RTU (length + gap), ASCII, │
//!                   │           MBAP; line timing (t1.5, t3.5)     │
//!                   ├──────────────────────────────────────────────┤
//!                   │ PDUs      pdu/  every public function code,  │
//!                   │           parse / emit / encoded_len         │
//!                   ├──────────────────────────────────────────────┤
//!                   │ tables    codes.rs crc.rs time.rs error.rs   │
//!                   │           words.rs (32-bit word orders)      │
//!                   └──────────────────────────────────────────────┘
//! ```
//!
//! - [`pdu`]: a request or response for every public function code of the MODBUS
//!   Application Protocol V1.1b3, plus raw custom codes. Parsing never panics and borrows
//!   from the input; values with invariants are built by checking constructors.
//! - [`frame`]: the three ADU formats. The RTU receiver completes a frame as soon as its
//!   function code tells the length, falls back to the t3.5 silent interval where it cannot,
//!   and treats line noise as something to count and skip, never as an end.
//! - [`retry`]: what a master does over many transactions — which outcomes it resends, when it
//!   skips a unit that stopped answering, how long it waits to reopen a failed port — decided
//!   from outcomes and `now`, so that a driver only sleeps until the instant it is given.
//! - [`scan`]: the decisions of a bus scanner — which line settings first, the probe and its
//!   timeouts, what a probe's outcome proves, and what listening to a line heard.
//! - [`master`] and [`slave`]: the two engines, in the style of `quinn-proto` and `smoltcp`.
//!   The caller feeds bytes with the time they arrived, sleeps until `poll_timeout()`, calls
//!   `handle_timeout(now)`, and writes what `poll_transmit(now, …)` returns. The engines
//!   decide everything else: when the line has been silent long enough to transmit, when a
//!   reply is due, which frames to ignore. Over Modbus/TCP, [`master::pipeline`] keeps
//!   several requests in flight on one connection, each matched to its reply by its
//!   transaction id.
//! - [`schedule`]: polling at a fixed rate — deadlines from the start, overruns, and the
//!   wire time of an exchange to check a period against.
//! - [`sniff`]: the passive decoder of a listener that never transmits: frames with good and
//!   bad CRCs, partial frames and noise, request or response told from the bytes, pairs with
//!   response times, the silence before each frame and t1.5/t3.5 violations, all from
//!   (bytes, arrival time).
//!
//! The `ferrobus` crate drives these engines over serial ports and TCP with tokio.
//!
//! ## Example: a request on the wire
//!
//! ```
//! use ferrobus_proto::frame::rtu;
//! use ferrobus_proto::pdu::{Registers, Request, WriteRegisters};
//!
//! // SDP servo manual p.413: write 0x0BB8, 0x0000 to 0x0112 of unit 1.
//! let values = [0x0BB8, 0x0000];
//! let request = Request::WriteMultipleRegisters(WriteRegisters::new(0x0112, Registers::from_values(&values))?);
//! let mut adu = [0u8; rtu::MAX_ADU_LEN];
//! let n = rtu::encode_request(1, &request, &mut adu)?;
//! assert_eq!(&adu[..n], [0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00, 0xFC, 0xEB]);
//! # Ok::<(), Box<dyn core::error::Error>>(())
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![cfg_attr(
    not(test),
    deny(
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects,
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]

pub mod codes;
pub mod crc;
mod cursor;
pub mod error;
pub mod frame;
pub mod master;
pub mod pdu;
pub mod retry;
pub mod scan;
pub mod schedule;
pub mod slave;
pub mod sniff;
pub mod time;
pub mod words;

pub use codes::{ExceptionCode, FunctionCode};
pub use error::{BufferTooSmall, DiscardReason, PduError};
pub use time::Instant;
