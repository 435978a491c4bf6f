//! The one error type of the async layer.
//!
//! It is flat on purpose: match on it once. "The device answered with an exception" is
//! [`Error::Exception`], kept apart from everything that means "no usable answer came" —
//! timeouts, broken frames, IO failures — so a caller can tell a refusing device from a
//! silent one.

use std::io;
use std::sync::Arc;
use std::time::Duration;

use ferrobus_proto::master::{HeardInstead, MasterError};
use ferrobus_proto::{ExceptionCode, FunctionCode, PduError};

/// Everything that can go wrong with a request. New variants may come: match with a `_` arm.
#[derive(Clone, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The device refused the request with an exception code.
    #[error("unit {unit} answered {function} with exception {code}")]
    Exception {
        /// The unit that answered.
        unit: u8,
        /// The function code of the request.
        function: FunctionCode,
        /// The exception code (named, or a vendor code such as 0x21).
        code: ExceptionCode,
    },
    /// No reply came in time, after every retry. `heard` tells silence from a unit that
    /// answered with a broken frame, bytes that made no frame, another unit's frame, a reply
    /// under another transaction id or with another function code.
    #[error(
        "no {}reply from unit {unit} within {} ms ({attempts} attempt{s}){}",
        if heard.is_some() { "valid " } else { "" },
        timeout.as_millis(),
        heard.map(|h| format!(": {h}")).unwrap_or_default(),
        s = if *.attempts == 1 { "" } else { "s" },
    )]
    Timeout {
        /// The unit asked.
        unit: u8,
        /// The timeout of each attempt, counted from the end of the request.
        timeout: Duration,
        /// How many times the request was sent.
        attempts: u32,
        /// What came instead of a reply, over all attempts (the most telling, see
        /// [`HeardInstead::weight`]); `None` is silence.
        heard: Option<HeardInstead>,
    },
    /// A reply came but it was malformed, or did not answer the request.
    #[error("bad reply from unit {unit}: {error}")]
    BadReply {
        /// The unit that answered.
        unit: u8,
        /// What was wrong with it.
        error: MasterError,
    },
    /// The request itself is not valid Modbus (a quantity out of range, a value too big).
    #[error("invalid request: {0}")]
    InvalidRequest(PduError),
    /// A read (a request whose answer carries data) to the broadcast address, unit 0 on a
    /// serial line: every device executes a broadcast and none answers, so there would be
    /// nothing to read. Refused before anything is sent.
    #[error("{function} to unit 0 is a broadcast: no device answers it, so there is nothing to read")]
    BroadcastRead {
        /// The function code of the request.
        function: FunctionCode,
    },
    /// A request that must be answered went out as one that gets no reply (0x08/0x04 Force
    /// Listen Only, say), so there is no answer to return.
    #[error("unit {unit} sends no reply to {function}, so there is nothing to return")]
    NoReply {
        /// The unit asked.
        unit: u8,
        /// The function code of the request.
        function: FunctionCode,
    },
    /// The unit failed repeatedly and is being skipped for a while so that it does not stall
    /// the others; a probe goes out again when the time has passed.
    #[error("unit {unit} is not answering; skipped for another {} ms", retry_in.as_millis())]
    Backoff {
        /// The unit.
        unit: u8,
        /// When the next probe may go out.
        retry_in: Duration,
    },
    /// The port or connection failed (it is reopened on the next request).
    #[error("{context}: {source}")]
    Io {
        /// What was being done, e.g. `"opening /dev/ttyUSB0"`.
        context: String,
        /// The OS error.
        #[source]
        source: Arc<io::Error>,
    },
    /// A lost serial port is not reopened: its path no longer names the device first opened,
    /// or cannot be shown to (a raw pty's number is reused by the next pty). See
    /// [`port`](crate::port) for what counts as the same device.
    #[error("not reopening {port}: {reason}")]
    NotSameDevice {
        /// The port, as [`Transport::describe`](crate::Transport::describe) names it.
        port: String,
        /// What was first opened and what the path names now.
        reason: String,
        /// Whether no later attempt can succeed either (a raw pty), rather than the right
        /// device possibly coming back (an adapter plugged in again).
        lasting: bool,
    },
    /// The serial port is held by another process (ours opens ports exclusively: two
    /// masters on one port would take each other's replies).
    #[error("{port} is in use: {}", holder.as_ref().map_or_else(|| "held by another process".to_string(), |h| format!("held by {h}")))]
    PortBusy {
        /// The port, as [`Transport::describe`](crate::Transport::describe) names it.
        port: String,
        /// Who holds it, when that can be found out (Linux, through `/proc`).
        holder: Option<PortHolder>,
    },
    /// The client's driver has stopped (its runtime shut down).
    #[error("the connection task has stopped")]
    Closed,
}

pub use crate::serial::PortHolder;

impl Error {
    /// The exception code, if the device refused the request.
    pub fn exception(&self) -> Option<ExceptionCode> {
        match self {
            Error::Exception { code, .. } => Some(*code),
            _ => None,
        }
    }

    /// Whether the error is a timeout.
    pub fn is_timeout(&self) -> bool {
        matches!(self, Error::Timeout { .. })
    }

    /// An IO error, with what was being done.
    pub fn io(context: impl Into<String>, source: io::Error) -> Self {
        Error::Io { context: context.into(), source: Arc::new(source) }
    }
}

impl From<PduError> for Error {
    fn from(e: PduError) -> Self {
        Error::InvalidRequest(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_unit_and_what_happened() {
        let e = Error::Exception {
            unit: 5,
            function: FunctionCode::ReadHoldingRegisters,
            code: ExceptionCode::from_u8(0x21),
        };
        assert_eq!(e.to_string(), "unit 5 answered 0x03 Read Holding Registers with exception 0x21 (vendor-specific)");
        assert_eq!(e.exception(), Some(ExceptionCode::Vendor(0x21)));
        let b = Error::BroadcastRead { function: FunctionCode::ReadHoldingRegisters };
        assert_eq!(
            b.to_string(),
            "0x03 Read Holding Registers to unit 0 is a broadcast: no device answers it, so there is nothing to read"
        );
        let n = Error::NoReply { unit: 4, function: FunctionCode::Diagnostics };
        assert_eq!(n.to_string(), "unit 4 sends no reply to 0x08 Diagnostics, so there is nothing to return");
        let t = Error::Timeout { unit: 1, timeout: Duration::from_millis(500), attempts: 3, heard: None };
        assert_eq!(t.to_string(), "no reply from unit 1 within 500 ms (3 attempts)");
        assert!(t.is_timeout());
        let heard = Some(HeardInstead::WrongFunction { function: 0x80, expected: 0x03 });
        let t = Error::Timeout { unit: 1, timeout: Duration::from_millis(500), attempts: 1, heard };
        assert_eq!(
            t.to_string(),
            "no valid reply from unit 1 within 500 ms (1 attempt): the unit sent a frame with function code 0x80 \
             instead of 0x03, ignored"
        );
        let heard = Some(HeardInstead::BadChecksum { head: Some((2, 0x1E)), expected: (2, 0x44) });
        let t = Error::Timeout { unit: 2, timeout: Duration::from_millis(300), attempts: 1, heard };
        assert_eq!(
            t.to_string(),
            "no valid reply from unit 2 within 300 ms (1 attempt): unit 2 answered, but the checksum was wrong \
             (function code 0x1E, expected 0x44)"
        );
    }
}
