//! What every platform's serial port shares: its settings, how they become serial2's, and
//! what opening one reports when another process holds it.
//!
//! The ports themselves are platform code, in [`sys`](crate::sys): a tty on Unix, a COM port
//! on Windows. Both are opened and configured through serial2, so the translation of a
//! [`LineConfig`] is written once, here.
//!
//! Ports are opened exclusively: two masters on one port would each take the other's replies
//! for their own. Unix takes an advisory lock (`flock`, which root cannot step past either and
//! which holds on a pty too) and sets the tty exclusive (`TIOCEXCL`, which refuses even
//! programs that do not lock); Windows itself lets one handle at a time open a COM port. A
//! port held elsewhere fails to open with [`PortInUse`] inside the `io::Error`, which the
//! transport turns into [`Error::PortBusy`](crate::Error::PortBusy).

use std::fmt;
use std::io;
use std::path::PathBuf;

use ferrobus_proto::frame::{DataBits, LineConfig, Parity, StopBits};

/// How the RS-485 transmitter is switched on and off.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Rs485 {
    /// The adapter does it (most USB RS-485 adapters).
    #[default]
    Auto,
    /// The kernel's RS-485 mode (`TIOCSRS485`) switches RTS around each transmission. Linux
    /// only: opening a port with it fails elsewhere.
    Kernel,
    /// ferrobus raises RTS before writing and drops it once the last character has left.
    Rts,
}

/// A serial port and its settings.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct SerialConfig {
    /// The port: a tty such as `/dev/ttyUSB0` or a socat pty link on Unix, `COM3` on Windows.
    pub path: PathBuf,
    /// Baud, data bits, parity, stop bits.
    pub line: LineConfig,
    /// Transmitter direction control.
    pub rs485: Rs485,
    /// Lower the USB adapter's latency timer to 1 ms (FTDI adapters deliver received bytes
    /// every 16 ms by default, which splits frames and slows every transaction). Linux only
    /// (through sysfs); elsewhere a note is logged and the port opened as it is.
    pub low_latency: bool,
}

impl SerialConfig {
    /// `path` at `line`, with the adapter driving RS-485 and the latency left alone.
    pub fn new(path: impl Into<PathBuf>, line: LineConfig) -> Self {
        SerialConfig { path: path.into(), line, rs485: Rs485::Auto, low_latency: false }
    }
}

/// The serial2 settings for `line`: raw bytes, no flow control.
pub(crate) fn settings(line: LineConfig) -> impl FnOnce(serial2::Settings) -> io::Result<serial2::Settings> {
    move |mut s| {
        s.set_raw();
        s.set_baud_rate(line.baud())?;
        s.set_char_size(match line.data_bits {
            DataBits::Seven => serial2::CharSize::Bits7,
            DataBits::Eight => serial2::CharSize::Bits8,
        });
        s.set_parity(match line.parity {
            Parity::None => serial2::Parity::None,
            Parity::Even => serial2::Parity::Even,
            Parity::Odd => serial2::Parity::Odd,
        });
        s.set_stop_bits(match line.stop_bits {
            StopBits::One => serial2::StopBits::One,
            StopBits::Two => serial2::StopBits::Two,
        });
        s.set_flow_control(serial2::FlowControl::None);
        Ok(s)
    }
}

/// A process that holds a serial port open.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct PortHolder {
    /// Its process id.
    pub pid: u32,
    /// Its command name (Linux's `/proc/PID/comm`), as the system gives it.
    pub command: String,
}

impl fmt::Display for PortHolder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // The name is another program's choice: escaped, so that it cannot forge a log line.
        write!(f, "process {} ({})", self.pid, self.command.escape_debug())
    }
}

/// Why a serial port did not open: another process holds it. Carried inside the platform
/// code's `io::Error` (kind `ResourceBusy`).
#[derive(Clone, PartialEq, Eq, Debug)]
pub(crate) struct PortInUse {
    /// Who, if it could be found out.
    pub(crate) holder: Option<PortHolder>,
}

impl fmt::Display for PortInUse {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.holder {
            Some(holder) => write!(f, "the port is held by {holder}"),
            None => f.write_str("the port is held by another process"),
        }
    }
}

impl std::error::Error for PortInUse {}

impl PortInUse {
    /// The `io::Error` that carries it.
    pub(crate) fn into_io(self) -> io::Error {
        io::Error::new(io::ErrorKind::ResourceBusy, self)
    }

    /// The [`PortInUse`] inside `error`, if that is why it failed.
    pub(crate) fn of(error: &io::Error) -> Option<&PortInUse> {
        error.get_ref().and_then(|inner| inner.downcast_ref::<PortInUse>())
    }
}

/// Reads with `read_buffered` (which never waits) until nothing is left, at most 1 MiB;
/// returns how many bytes were read and dropped.
pub(crate) fn discard_input(mut read_buffered: impl FnMut(&mut [u8]) -> io::Result<usize>) -> io::Result<usize> {
    const MAX: usize = 1 << 20;
    let mut buf = [0u8; 1024];
    let mut total = 0usize;
    while total < MAX {
        match read_buffered(&mut buf)? {
            0 => break,
            n => total = total.saturating_add(n),
        }
    }
    Ok(total)
}
