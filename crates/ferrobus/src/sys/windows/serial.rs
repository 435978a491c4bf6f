//! COM ports as async ports, through serial2-tokio.
//!
//! Why serial2-tokio: the Unix backend is serial2 already, so the settings are translated once
//! for both ([`crate::serial`]); serial2-tokio puts a serial2 port on tokio's own IOCP reactor
//! with overlapped IO — no thread per port, no polling, and none of our code `unsafe` — and it
//! is kept up with serial2 by the same maintainer. tokio-serial (mio-serial over serialport)
//! does the same but brings a second serial stack with its own settings types and, on Linux,
//! libudev; serialport alone is blocking and would need a thread per port.
//!
//! Precise timing needs nothing here: the timer thread ([`crate::timer`]) finishes its waits
//! with high-resolution sleeps (see [`crate::sys::THREAD_WAIT_GRAIN`]).

use std::io;
use std::path::Path;
use std::pin::Pin;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use crate::serial::{PortInUse, Rs485, SerialConfig, settings};

/// Win32's `ERROR_ACCESS_DENIED`, what opening a COM port another handle holds fails with.
const ERROR_ACCESS_DENIED: i32 = 5;

/// A COM port, as an async port.
#[derive(Debug)]
pub struct TtyPort {
    port: serial2_tokio::SerialPort,
}

impl TtyPort {
    /// Sets the RTS line (RS-485 direction control by RTS).
    pub(crate) fn set_rts(&self, on: bool) -> io::Result<()> {
        self.port.set_rts(on)
    }

    /// Whether it is a serial port with a wire: a COM port is (Windows has no ptys).
    #[expect(clippy::unused_self, reason = "the signature of every platform's")]
    pub(crate) fn has_wire(&self) -> bool {
        true
    }

    /// Drops what the port has received and nobody has read yet. Windows' overlapped reads
    /// cannot be tried without waiting, so the bytes are discarded uncounted: 0.
    pub(crate) fn read_buffered(&mut self, _buf: &mut [u8]) -> io::Result<usize> {
        self.port.discard_input_buffer()?;
        Ok(0)
    }

    /// Drops what the port has received and nobody has read yet (bytes that came before it
    /// was opened, say); returns how many, which Windows does not tell: 0.
    pub fn discard_input(&mut self) -> io::Result<usize> {
        crate::serial::discard_input(|buf| self.read_buffered(buf))
    }

    /// Changes the line settings of the open port, in place: the name is not opened again, so
    /// it cannot lead to another adapter meanwhile.
    pub fn reconfigure(&mut self, line: ferrobus_proto::frame::LineConfig) -> io::Result<()> {
        let wanted = settings(line)(self.port.get_configuration()?)?;
        self.port.set_configuration(&wanted)
    }
}

/// Opens the COM port `config.path` (`COM3`, or `\\.\COM12`) with `config`. Needs a tokio
/// runtime.
pub fn open_serial(config: &SerialConfig) -> io::Result<TtyPort> {
    if config.rs485 == Rs485::Kernel {
        // Refused before the port is touched.
        return Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "the kernel's RS-485 mode (TIOCSRS485) is Linux only: use RTS direction control or an adapter that switches itself",
        ));
    }
    let port = match serial2_tokio::SerialPort::open(device_name(&config.path), settings(config.line)) {
        // Windows opens a COM port for one handle only, whatever share mode serial2 asks
        // for: a second open is refused with ERROR_ACCESS_DENIED, and who holds it is not
        // told.
        Err(e) if e.raw_os_error() == Some(ERROR_ACCESS_DENIED) => return Err(PortInUse { holder: None }.into_io()),
        other => other?,
    };
    if config.rs485 == Rs485::Rts {
        port.set_rts(false)?;
    }
    if config.low_latency {
        tracing::info!(
            path = %config.path.display(),
            "the latency timer is set in the adapter driver's properties on Windows; left as it is"
        );
    }
    Ok(TtyPort { port })
}

/// The port's name without the device namespace prefix (`\\.\`), which serial2 adds itself.
fn device_name(path: &Path) -> &Path {
    path.to_str().and_then(|s| s.strip_prefix(r"\\.\")).map_or(path, Path::new)
}

impl AsyncRead for TtyPort {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.port).poll_read(cx, buf)
    }
}

impl AsyncWrite for TtyPort {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.port).poll_write(cx, data)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.port).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.port).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_com_name_is_passed_to_serial2_without_the_device_namespace_prefix() {
        assert_eq!(device_name(Path::new(r"\\.\COM12")), Path::new("COM12"));
        assert_eq!(device_name(Path::new("COM3")), Path::new("COM3"));
    }

    #[test]
    fn a_missing_com_port_fails_to_open_with_an_error_not_a_panic() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let _inside = runtime.enter();
        let line = ferrobus_proto::frame::LineConfig::new(9600).unwrap();
        let e = open_serial(&SerialConfig::new("COM250", line)).unwrap_err();
        assert!(matches!(e.kind(), io::ErrorKind::NotFound | io::ErrorKind::PermissionDenied), "{e:?}");
    }

    #[test]
    fn kernel_rs485_is_refused_as_linux_only_before_the_port_is_opened() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let _inside = runtime.enter();
        let line = ferrobus_proto::frame::LineConfig::new(9600).unwrap();
        let config = SerialConfig { rs485: Rs485::Kernel, ..SerialConfig::new("COM250", line) };
        let e = open_serial(&config).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::Unsupported, "{e}");
        assert!(e.to_string().contains("Linux only") && e.to_string().contains("RTS"), "{e}");
    }
}
