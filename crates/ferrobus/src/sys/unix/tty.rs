//! Terminals as ports (Unix): serial ports and pseudo-terminals, read and written straight
//! through their file descriptors.
//!
//! serial2 opens and configures the tty; tokio's reactor watches it for reading only. A frame
//! (at most 256 bytes) fits the tty's output buffer, so a write goes straight to the
//! descriptor. Watching for write readiness as well would wake the runtime each time the other
//! side drained what was written — for nothing, on 40 % of the transactions measured in
//! `bench/PROFILE.md`.

use std::future::Future;
use std::io;
use std::os::unix::ffi::OsStringExt;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::task::{Context, Poll, ready};
use std::time::Duration;

use ferrobus_proto::frame::{DataBits, LineConfig, Parity, StopBits};
use tokio::io::unix::AsyncFd;
use tokio::io::{AsyncRead, AsyncWrite, Interest, ReadBuf};

use super::fd::register;
use crate::serial::{PortHolder, PortInUse, Rs485, SerialConfig, discard_input, settings};

/// How long a write waits before trying again when the tty's output buffer is full (a line
/// that does not drain: hardware flow control held, a stuck adapter).
const WRITE_RETRY: Duration = Duration::from_millis(1);

/// A serial port or the master side of a pseudo-terminal, as an async port.
#[derive(Debug)]
pub struct TtyPort {
    fd: AsyncFd<serial2::SerialPort>,
    /// Whether it is a pseudo-terminal, which may refuse parity (see [`open_serial`]).
    pty: bool,
    /// Armed when the output buffer was full: the write is tried again when it fires.
    retry: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl TtyPort {
    /// Watches `port` (opened non-blocking, as serial2 does) for reading. Needs a tokio runtime.
    fn new(port: serial2::SerialPort, pty: bool) -> io::Result<Self> {
        Ok(TtyPort { fd: register(port, Interest::READABLE)?, pty, retry: None })
    }

    /// Changes the line settings of the open port, in place: the path is not opened again, so
    /// it cannot lead to another device meanwhile. Bytes already received are kept. A pty
    /// that refuses a parity or 7 data bits is set to 8 data bits without parity, as
    /// [`open_serial`] does.
    pub fn reconfigure(&mut self, line: LineConfig) -> io::Result<()> {
        let port = self.fd.get_mut();
        let wanted = settings(line)(port.get_configuration()?)?;
        match port.set_configuration(&wanted) {
            Err(e) if self.pty && (line.parity != Parity::None || line.data_bits != DataBits::Eight) => {
                let plain = line.with_parity(Parity::None).with_data_bits(DataBits::Eight);
                tracing::info!("this pty refuses {line} ({e}); using {plain}");
                let plain = settings(plain)(port.get_configuration()?)?;
                port.set_configuration(&plain)
            }
            other => other,
        }
    }

    /// Sets the RTS line (RS-485 direction control by RTS).
    pub(crate) fn set_rts(&self, on: bool) -> io::Result<()> {
        self.fd.get_ref().set_rts(on)
    }

    /// Whether it is a serial port with a wire, not a pty.
    pub(crate) fn has_wire(&self) -> bool {
        !self.pty
    }

    /// Reads, without waiting, bytes the port has received and nobody has read yet; 0 when
    /// there are none.
    pub(crate) fn read_buffered(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        // The descriptor is non-blocking: an empty buffer says WouldBlock. The reactor's
        // readiness is left as it is; the next read finds out and waits again.
        match retry_interrupted(|| rustix::io::read(self.fd.get_ref(), &mut *buf)) {
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(0),
            other => other,
        }
    }
}

impl TtyPort {
    /// Drops what the port has received and nobody has read yet (bytes that came before it
    /// was opened, say); returns how many.
    pub fn discard_input(&mut self) -> io::Result<usize> {
        discard_input(|buf| self.read_buffered(buf))
    }
}

impl Drop for TtyPort {
    /// Gives up the tty's exclusive mode (the lock goes with the descriptor).
    fn drop(&mut self) {
        if !self.pty {
            let _ = rustix::termios::ioctl_tiocnxcl(self.fd.get_ref());
        }
    }
}

impl AsyncRead for TtyPort {
    fn poll_read(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        loop {
            let mut guard = ready!(self.fd.poll_read_ready(cx))?;
            let unfilled = buf.initialize_unfilled();
            let room = unfilled.len();
            match guard.try_io(|fd| retry_interrupted(|| rustix::io::read(fd.get_ref(), &mut *unfilled))) {
                Ok(Ok(n)) => {
                    if n > 0 && n < room {
                        // The tty is drained: the next read would only say so (EAGAIN). Wait
                        // for the next edge instead, as tokio's own sockets do; one that came
                        // meanwhile is kept.
                        guard.clear_ready();
                    }
                    buf.advance(n);
                    return Poll::Ready(Ok(()));
                }
                Ok(Err(e)) => return Poll::Ready(Err(e)),
                Err(_would_block) => {}
            }
        }
    }
}

impl AsyncWrite for TtyPort {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        loop {
            if let Some(retry) = self.retry.as_mut() {
                ready!(retry.as_mut().poll(cx));
                self.retry = None;
            }
            match retry_interrupted(|| rustix::io::write(self.fd.get_ref(), data)) {
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    self.retry = Some(Box::pin(tokio::time::sleep(WRITE_RETRY)));
                }
                done => return Poll::Ready(done),
            }
        }
    }

    fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

/// Runs a system call again when a signal interrupted it.
fn retry_interrupted<T>(mut call: impl FnMut() -> rustix::io::Result<T>) -> io::Result<T> {
    loop {
        match call() {
            Err(rustix::io::Errno::INTR) => {}
            other => return other.map_err(io::Error::from),
        }
    }
}

/// Opens a serial port with `config`, exclusively. Needs a tokio runtime.
///
/// The port is opened without touching its settings and locked before it is configured, so
/// that a port another process holds keeps its line as it is: `flock(LOCK_EX | LOCK_NB)`,
/// which stops root too and holds on a pty, and for a real tty `TIOCEXCL`, which refuses the
/// opens of programs that do not lock (other than root's). A held port fails with an error of
/// kind `ResourceBusy` naming the holder where `/proc` tells it, which the transport turns into
/// [`Error::PortBusy`](crate::Error::PortBusy).
///
/// A pseudo-terminal cannot always hold a parity setting or 7 data bits (Linux refuses them on
/// a pty opened a second time); the port is then opened at 8 data bits without parity and a
/// note is logged — a pty has no wire for parity to protect, and passes 8-bit bytes.
pub fn open_serial(config: &SerialConfig) -> io::Result<TtyPort> {
    let pty = is_pty(&config.path);
    let port = match serial2::SerialPort::open(&config.path, serial2::KeepSettings) {
        // Another process set the tty exclusive.
        Err(e) if e.raw_os_error() == Some(rustix::io::Errno::BUSY.raw_os_error()) => {
            return Err(PortInUse { holder: holder(&config.path) }.into_io());
        }
        other => other?,
    };
    lock(&port, &config.path, pty)?;
    let mut port = TtyPort::new(port, pty)?;
    port.reconfigure(config.line)?;
    let serial = port.fd.get_ref();
    match config.rs485 {
        Rs485::Kernel => kernel_rs485(serial)?,
        Rs485::Rts => serial.set_rts(false)?,
        Rs485::Auto => {}
    }
    if config.low_latency {
        set_low_latency(&config.path);
    }
    Ok(port)
}

/// Takes `port` for this process alone: the advisory lock, then (not on a pty, whose flag
/// would outlive us while the pty's owner keeps it open) the tty's exclusive mode.
fn lock(port: &serial2::SerialPort, path: &Path, pty: bool) -> io::Result<()> {
    use rustix::fs::{FlockOperation, flock};
    match flock(port, FlockOperation::NonBlockingLockExclusive) {
        Err(rustix::io::Errno::WOULDBLOCK) => return Err(PortInUse { holder: holder(path) }.into_io()),
        // A file system without locks (some network mounts): TIOCEXCL still guards a tty.
        Err(e) => tracing::debug!(path = %path.display(), "cannot lock the port: {e}"),
        Ok(()) => {}
    }
    if !pty {
        rustix::termios::ioctl_tiocexcl(port)?;
    }
    Ok(())
}

/// The process that holds `path`, other than this one (Linux): the one whose lock on it
/// `/proc/locks` lists, else the first with it open under `/proc/*/fd` (a program that set
/// the tty exclusive without locking it). `None` when `/proc` does not tell (another user's
/// processes, without the right to look).
#[cfg(target_os = "linux")]
fn holder(path: &Path) -> Option<PortHolder> {
    let target = std::fs::canonicalize(path).ok()?;
    let ours = std::process::id();
    let pid = locker(&target, ours).or_else(|| opener(&target, ours))?;
    let comm = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
    Some(PortHolder { pid, command: comm.trim_end_matches('\n').to_string() })
}

/// The process holding a `flock` on the file `target`, other than `ours`, from `/proc/locks`
/// (`1: FLOCK ADVISORY WRITE PID MAJOR:MINOR:INODE 0 EOF`, the device numbers in hex).
#[cfg(target_os = "linux")]
fn locker(target: &Path, ours: u32) -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    let meta = std::fs::metadata(target).ok()?;
    let dev = meta.dev();
    let id = format!("{:02x}:{:02x}:{}", rustix::fs::major(dev), rustix::fs::minor(dev), meta.ino());
    let locks = std::fs::read_to_string("/proc/locks").ok()?;
    locks.lines().find_map(|line| {
        let fields: Vec<&str> = line.split_whitespace().collect();
        let (Some(&"FLOCK"), Some(pid), Some(&file)) = (fields.get(1), fields.get(4), fields.get(5)) else {
            return None;
        };
        let pid: u32 = pid.parse().ok()?;
        (file == id && pid != ours).then_some(pid)
    })
}

/// The first process other than `ours` with `target` open, from `/proc/*/fd`.
#[cfg(target_os = "linux")]
fn opener(target: &Path, ours: u32) -> Option<u32> {
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|entry| {
        let pid: u32 = entry.file_name().to_str()?.parse().ok()?;
        let mut fds = std::fs::read_dir(entry.path().join("fd")).ok()?.flatten();
        (pid != ours && fds.any(|fd| std::fs::read_link(fd.path()).is_ok_and(|p| p == target))).then_some(pid)
    })
}

/// Who holds a port cannot be found out here.
#[cfg(not(target_os = "linux"))]
fn holder(_path: &Path) -> Option<PortHolder> {
    None
}

/// Switches the kernel's RS-485 mode on (`TIOCSRS485`), which only Linux has.
#[cfg(target_os = "linux")]
fn kernel_rs485(port: &serial2::SerialPort) -> io::Result<()> {
    port.set_rs4xx_mode(serial2::rs4xx::Rs485Config::new())
}

/// Switches the kernel's RS-485 mode on (`TIOCSRS485`), which only Linux has.
#[cfg(not(target_os = "linux"))]
fn kernel_rs485(_: &serial2::SerialPort) -> io::Result<()> {
    Err(io::Error::new(
        io::ErrorKind::Unsupported,
        "the kernel's RS-485 mode (TIOCSRS485) is Linux only: use RTS direction control or an adapter that switches itself",
    ))
}

fn is_pty(path: &Path) -> bool {
    std::fs::canonicalize(path).is_ok_and(|p| is_pty_path(&p))
}

/// Whether `real` (a canonical path) is the other end of a pseudo-terminal: `/dev/pts/N` on
/// Linux and the BSDs, `/dev/ttysNNN` on macOS (whose serial ports are `/dev/tty.*` and
/// `/dev/cu.*`).
pub(crate) fn is_pty_path(real: &Path) -> bool {
    if real.starts_with("/dev/pts") {
        return true;
    }
    cfg!(target_vendor = "apple")
        && real.parent() == Some(Path::new("/dev"))
        && real.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
            n.strip_prefix("ttys")
                .is_some_and(|digits| !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()))
        })
}

/// Sets the latency timer of a USB serial adapter to 1 ms through sysfs, if it has one.
#[cfg(not(target_os = "linux"))]
fn set_low_latency(path: &Path) {
    tracing::info!(path = %path.display(), "the latency timer is set through Linux's sysfs; left as it is here");
}

/// Sets the latency timer of a USB serial adapter to 1 ms through sysfs, if it has one.
#[cfg(target_os = "linux")]
fn set_low_latency(path: &Path) {
    let Some(name) = std::fs::canonicalize(path).ok().and_then(|p| p.file_name().map(ToOwned::to_owned)) else {
        return;
    };
    let timer = Path::new("/sys/class/tty").join(&name).join("device/latency_timer");
    match std::fs::write(&timer, b"1") {
        Ok(()) => tracing::debug!(path = %timer.display(), "latency timer set to 1 ms"),
        Err(e) => tracing::warn!(path = %timer.display(), "cannot set the adapter's latency timer: {e}"),
    }
}

/// A pseudo-terminal pair made in this process: a port for us, and the path of its other
/// end for another program (a client, a peer stack) to open, as a serial port would be.
#[derive(Debug)]
pub struct Pty {
    /// Our end (the pty master).
    pub port: TtyPort,
    /// The path of the other end, e.g. `/dev/pts/7`.
    pub path: PathBuf,
    /// The other end, kept open so that the pty survives its user closing it.
    _peer: serial2::SerialPort,
}

impl Pty {
    /// Makes a pty pair. Needs a tokio runtime.
    pub fn open() -> io::Result<Pty> {
        let (ours, peer) = serial2::SerialPort::pair()?;
        // ptsname asks the kernel (TIOCGPTN on Linux, TIOCPTYGNAME on macOS): no /proc needed.
        let name = rustix::pty::ptsname(&ours, Vec::new())?;
        let path = PathBuf::from(std::ffi::OsString::from_vec(name.into_bytes()));
        Ok(Pty { port: TtyPort::new(ours, true)?, path, _peer: peer })
    }
}

/// What the program on the other end of a pty has set: its line settings, and what its
/// terminal does with a character received with a parity or framing error.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct PeerSettings {
    /// Baud, data bits (5 and 6 read as 7), parity, stop bits.
    pub(crate) line: LineConfig,
    /// `IGNPAR`: such a character is dropped.
    pub(crate) ignore_errors: bool,
    /// `PARMRK`: it is read as `FF 00 c`.
    pub(crate) mark_errors: bool,
    /// `INPCK`: it is read as `00` (without `PARMRK`); without it the garbled byte itself.
    pub(crate) check_parity: bool,
}

impl Pty {
    /// The other end's settings, read from our end (Linux and macOS give a pty master's
    /// `tcgetattr` the slave's termios). `None` if they cannot be read or the baud rate is 0.
    pub(crate) fn peer_settings(&self) -> Option<PeerSettings> {
        peer_settings(self.port.fd.get_ref())
    }

    /// A second handle on our end, for another task to write to without waiting.
    pub(crate) fn writer(&self) -> io::Result<PtyWriter> {
        Ok(PtyWriter { fd: rustix::io::dup(self.port.fd.get_ref())? })
    }
}

/// A second handle on a pty's our end ([`Pty::writer`]): it writes what the pty's buffer takes
/// at once and never waits (the descriptor is non-blocking, as the pty's own).
#[derive(Debug)]
pub(crate) struct PtyWriter {
    fd: rustix::fd::OwnedFd,
}

impl PtyWriter {
    /// Writes as much of `data` as the pty's buffer takes now; `WouldBlock` if it takes none.
    pub(crate) fn try_write(&self, data: &[u8]) -> io::Result<usize> {
        retry_interrupted(|| rustix::io::write(&self.fd, data))
    }

    /// The other end's settings, as [`Pty::peer_settings`].
    pub(crate) fn peer_settings(&self) -> Option<PeerSettings> {
        peer_settings(&self.fd)
    }
}

/// The settings of the other end of the pty whose our end is `fd`.
fn peer_settings(fd: impl rustix::fd::AsFd) -> Option<PeerSettings> {
    use rustix::termios::{ControlModes, InputModes};
    let termios = rustix::termios::tcgetattr(fd).ok()?;
    let control = termios.control_modes;
    let parity = if !control.contains(ControlModes::PARENB) {
        Parity::None
    } else if control.contains(ControlModes::PARODD) {
        Parity::Odd
    } else {
        Parity::Even
    };
    let data_bits =
        if (control & ControlModes::CSIZE) == ControlModes::CS8 { DataBits::Eight } else { DataBits::Seven };
    let stop_bits = if control.contains(ControlModes::CSTOPB) { StopBits::Two } else { StopBits::One };
    // The speed set last: termios2 leaves the input speed 0 for "as the output".
    let line = LineConfig::new(termios.output_speed())?
        .with_parity(parity)
        .with_data_bits(data_bits)
        .with_stop_bits(stop_bits);
    let input = termios.input_modes;
    Some(PeerSettings {
        line,
        ignore_errors: input.contains(InputModes::IGNPAR),
        mark_errors: input.contains(InputModes::PARMRK),
        check_parity: input.contains(InputModes::INPCK),
    })
}

impl AsyncRead for Pty {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.port).poll_read(cx, buf)
    }
}

impl AsyncWrite for Pty {
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
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    use super::*;

    #[tokio::test]
    async fn a_pty_carries_bytes_both_ways_and_survives_its_user_leaving() {
        let mut pty = Pty::open().unwrap();
        let line = LineConfig::new(9600).unwrap().with_parity(Parity::None);
        let config = SerialConfig::new(&pty.path, line);
        for round in 0..2u8 {
            let mut user = open_serial(&config).unwrap();
            user.write_all(&[0x01, 0x03, round]).await.unwrap();
            let mut got = [0u8; 3];
            pty.read_exact(&mut got).await.unwrap();
            assert_eq!(got, [0x01, 0x03, round]);
            pty.write_all(&[0xAB; 300]).await.unwrap();
            let mut back = [0u8; 300];
            user.read_exact(&mut back).await.unwrap();
            assert_eq!(back, [0xAB; 300]);
            // The user closes its end; the pty stays usable for the next one.
        }
    }

    #[test]
    fn pty_ends_are_told_from_serial_ports_by_their_canonical_path() {
        assert!(is_pty_path(Path::new("/dev/pts/7")));
        assert!(!is_pty_path(Path::new("/dev/ttyUSB0")));
        assert!(!is_pty_path(Path::new("/dev/ttyS0")));
        assert!(!is_pty_path(Path::new("/dev/tty.usbserial-A1")));
        // macOS names the other end of a pty /dev/ttysNNN; elsewhere that is no pty.
        assert_eq!(is_pty_path(Path::new("/dev/ttys003")), cfg!(target_vendor = "apple"));
        assert!(!is_pty_path(Path::new("/dev/ttys")));
    }

    #[tokio::test]
    async fn a_pty_path_comes_from_ptsname_and_names_the_other_end() {
        let pty = Pty::open().unwrap();
        assert!(is_pty_path(&pty.path), "{}", pty.path.display());
        // The path opens the same terminal that the pair holds open: its termios is the one
        // read through our end.
        let line = LineConfig::new(4800).unwrap().with_parity(Parity::None);
        let _user = open_serial(&SerialConfig::new(&pty.path, line)).unwrap();
        assert_eq!(pty.peer_settings().map(|s| s.line.baud()), Some(4800));
    }

    #[cfg(not(target_os = "linux"))]
    #[tokio::test]
    async fn kernel_rs485_is_refused_outside_linux() {
        let pty = Pty::open().unwrap();
        let line = LineConfig::new(9600).unwrap();
        let config = SerialConfig { rs485: Rs485::Kernel, ..SerialConfig::new(&pty.path, line) };
        let e = open_serial(&config).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::Unsupported, "{e}");
    }

    #[test]
    fn a_missing_port_is_not_found() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let _inside = runtime.enter();
        let config = SerialConfig::new("/dev/ferrobus-no-such-port", LineConfig::new(9600).unwrap());
        let e = open_serial(&config).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::NotFound);
    }
}
