//! What every platform's serial port shares: its settings, and how they become serial2's.
//!
//! The ports themselves are platform code, in [`sys`](crate::sys): a tty on Unix, a COM port
//! on Windows. Both are opened and configured through serial2, so the translation of a
//! [`LineConfig`] is written once, here.

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
