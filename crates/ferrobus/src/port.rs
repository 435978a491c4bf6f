//! Byte streams and how to open them: serial ports (any tty, a socat pty included), TCP,
//! and streams a program provides (the virtual line, tests).
//!
//! A [`Transport`] says which framing runs over which stream and how to (re)open it. The
//! drivers open it when they start and again after an IO error: a lost port is reopened, not
//! fatal ([`Transport::with_reopen`] turns that off). A serial port is reopened only if its
//! path still names the device first opened: a symlink (`/dev/serial/by-id/...`, a socat
//! `link=`) is a name chosen for a device and is always reopened; a raw pty (`/dev/pts/N`)
//! never is, its number going to the next pty made; a USB adapter must have the same vendor,
//! product and serial number, another device in sysfs the same place in the device tree.
//! Otherwise opening fails with [`Error::NotSameDevice`](crate::Error::NotSameDevice).

use std::fmt;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use ferrobus_proto::frame::ascii::AsciiCodec;
use ferrobus_proto::frame::mbap::MbapCodec;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineTiming};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::TcpStream;

use crate::identity::Identity;
use crate::serial::PortInUse;
pub use crate::serial::{Rs485, SerialConfig};
#[cfg(unix)]
pub use crate::sys::Pty;
pub use crate::sys::{PortFault, TtyPort, open_serial};
use crate::timer::Timer;

mod tls_answer;

use tls_answer::FirstBytes;
pub use tls_answer::TlsAnswer;

/// A byte stream a driver runs an engine over.
pub trait Port: AsyncRead + AsyncWrite + Unpin + Send + 'static {
    /// Drives the RS-485 transmitter by RTS: `true` just before a transmission, `false` once
    /// it has left the wire. Streams without the line do nothing.
    fn set_rts(&mut self, _on: bool) -> io::Result<()> {
        Ok(())
    }

    /// When the bytes of the last read arrived, if the port knows better than the moment the
    /// reading task got them (the virtual line knows the instant they left the wire). The
    /// engines time silent intervals from it.
    fn last_arrival(&self) -> Option<tokio::time::Instant> {
        None
    }

    /// Reads, without waiting, bytes already received and not read yet (a serial port's
    /// buffer); 0 when there are none, or for a stream that cannot tell.
    fn read_buffered(&mut self, _buf: &mut [u8]) -> io::Result<usize> {
        Ok(0)
    }

    /// Whether bytes cross a wire at the line's baud, so that no reply can begin before our
    /// request has left: a serial port, not a pty (which delivers at once), nor TCP.
    fn has_wire(&self) -> bool {
        false
    }
}

impl Port for TcpStream {}
impl Port for FirstBytes<TcpStream> {}
impl Port for tokio::io::DuplexStream {}

/// A serial port drives RTS itself.
impl Port for TtyPort {
    fn set_rts(&mut self, on: bool) -> io::Result<()> {
        TtyPort::set_rts(self, on)
    }

    fn read_buffered(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        TtyPort::read_buffered(self, buf)
    }

    fn has_wire(&self) -> bool {
        TtyPort::has_wire(self)
    }
}

/// A whole pty is a port too: reading and writing go to our end, and the other end stays open
/// as long as it lives.
#[cfg(unix)]
impl Port for Pty {}

/// A boxed port.
pub type BoxPort = Box<dyn Port>;

/// A future that opens a port.
pub type Connecting = Pin<Box<dyn Future<Output = io::Result<BoxPort>> + Send>>;

/// Opens a port, as many times as the driver needs it.
pub trait Connector: Send + Sync + 'static {
    /// Opens the port.
    fn connect(&self) -> Connecting;
    /// What is being opened, for errors and logs (`/dev/ttyUSB0`, `127.0.0.1:502`).
    fn describe(&self) -> String;
}

/// Which framing runs over the stream.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Framing {
    /// RTU: binary frames with a CRC, separated by silence.
    Rtu,
    /// ASCII: `:` hex LRC CR LF.
    Ascii,
    /// Modbus/TCP: MBAP header, no CRC.
    Mbap,
}

/// A framing over a stream, with its line timing.
#[derive(Clone)]
pub struct Transport {
    framing: Framing,
    rs485: Rs485,
    timer: Timer,
    timing: LineTiming,
    frame_gap: Duration,
    incomplete_timeout: Duration,
    reopen: bool,
    remote: bool,
    connector: Arc<dyn Connector>,
}

/// The PC-side RTU timeouts, decided in the core.
pub use ferrobus_proto::frame::timing::{PC_INCOMPLETE_TIMEOUT, STREAM_FRAME_GAP};

impl Transport {
    /// RTU over a serial port.
    pub fn rtu(config: SerialConfig) -> Self {
        Transport::serial(Framing::Rtu, config)
    }

    /// ASCII over a serial port.
    pub fn ascii(config: SerialConfig) -> Self {
        Transport::serial(Framing::Ascii, config)
    }

    fn serial(framing: Framing, config: SerialConfig) -> Self {
        let timing = LineTiming::new(&config.line);
        Transport {
            framing,
            rs485: config.rs485,
            timer: Timer::Precise,
            timing,
            frame_gap: timing.t3_5(),
            incomplete_timeout: PC_INCOMPLETE_TIMEOUT,
            reopen: true,
            remote: false,
            connector: Arc::new(SerialTarget { same: Mutex::new(SameDevice::new(config.path.clone())), config }),
        }
    }

    /// Modbus/TCP to `addr` (`host:port`).
    pub fn tcp(addr: impl Into<String>) -> Self {
        Transport::stream(Framing::Mbap, TcpTarget { addr: addr.into(), mbap: true })
    }

    /// `framing` over TCP connections to `target`.
    fn stream(framing: Framing, target: TcpTarget) -> Self {
        Transport {
            framing,
            rs485: Rs485::Auto,
            timer: Timer::Tokio,
            timing: LineTiming::unpaced(),
            frame_gap: STREAM_FRAME_GAP,
            incomplete_timeout: STREAM_FRAME_GAP,
            reopen: true,
            remote: true,
            connector: Arc::new(target),
        }
    }

    /// The same transport, its streams opened by `connector` (TLS over TCP, for one).
    #[cfg(feature = "tls")]
    pub(crate) fn with_connector(self, connector: Arc<dyn Connector>) -> Self {
        Transport { connector, ..self }
    }

    /// RTU frames carried over TCP to `addr` (a serial gateway or a device that speaks it).
    pub fn rtu_over_tcp(addr: impl Into<String>) -> Self {
        Transport::stream(Framing::Rtu, TcpTarget { addr: addr.into(), mbap: false })
    }

    /// `framing` over streams opened by `connector`, with `timing` (exact: nothing is
    /// stretched for OS latency — right for the virtual line and for tests), waiting with
    /// tokio's timer (see [`Transport::with_timer`]).
    pub fn custom(framing: Framing, timing: LineTiming, connector: impl Connector) -> Self {
        Transport {
            framing,
            rs485: Rs485::Auto,
            timer: Timer::Tokio,
            timing,
            frame_gap: timing.t3_5(),
            incomplete_timeout: timing.t3_5(),
            reopen: true,
            remote: false,
            connector: Arc::new(connector),
        }
    }

    /// Overrides t1.5.
    #[must_use]
    pub fn with_t1_5(mut self, t1_5: Duration) -> Self {
        self.timing = self.timing.with_t1_5(t1_5);
        self
    }

    /// Overrides t3.5: the silence before each transmission and the one that ends a frame of
    /// unknown length.
    #[must_use]
    pub fn with_t3_5(mut self, t3_5: Duration) -> Self {
        self.timing = self.timing.with_t3_5(t3_5);
        self.frame_gap = t3_5;
        self
    }

    /// Changes how deadlines are waited for: [`Timer::Precise`] for a real line,
    /// [`Timer::Tokio`] for a paused test clock.
    #[must_use]
    pub fn with_timer(mut self, timer: Timer) -> Self {
        self.timer = timer;
        self
    }

    /// How deadlines are waited for.
    pub fn timer(&self) -> Timer {
        self.timer
    }

    /// Overrides how long to wait for the rest of a frame of known length.
    #[must_use]
    pub fn with_incomplete_timeout(mut self, timeout: Duration) -> Self {
        self.incomplete_timeout = timeout;
        self
    }

    /// Whether a lost port is opened again (the default) or stays lost, every later request
    /// failing. Clones of a transport share what their serial port was first opened as.
    #[must_use]
    pub fn with_reopen(mut self, reopen: bool) -> Self {
        self.reopen = reopen;
        self
    }

    /// Whether a lost port is opened again.
    pub fn reopens(&self) -> bool {
        self.reopen
    }

    /// Whether the stream is a network connection to a device (Modbus/TCP, RTU over TCP, TLS)
    /// rather than a port of this machine: one whose other end may not be there yet, and
    /// may come and go.
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The framing.
    pub fn framing(&self) -> Framing {
        self.framing
    }

    /// The line timing.
    pub fn timing(&self) -> &LineTiming {
        &self.timing
    }

    /// Changes the RS-485 direction control (a custom transport over a serial port it opened
    /// itself: the scanner's).
    #[must_use]
    pub fn with_rs485(mut self, rs485: Rs485) -> Self {
        self.rs485 = rs485;
        self
    }

    /// The RS-485 direction control.
    pub fn rs485(&self) -> Rs485 {
        self.rs485
    }

    /// What is being opened.
    pub fn describe(&self) -> String {
        self.connector.describe()
    }

    /// Opens the port, giving up after `timeout`.
    pub async fn open(&self, timeout: Duration) -> Result<BoxPort, crate::Error> {
        let context = || format!("opening {}", self.describe());
        match tokio::time::timeout(timeout, self.connector.connect()).await {
            Ok(Ok(port)) => Ok(port),
            Ok(Err(e)) => {
                if let Some(busy) = PortInUse::of(&e) {
                    return Err(crate::Error::PortBusy { port: self.describe(), holder: busy.holder.clone() });
                }
                match e.get_ref().and_then(|inner| inner.downcast_ref::<NotSame>()) {
                    Some(not_same) => Err(crate::Error::NotSameDevice {
                        port: self.describe(),
                        reason: not_same.reason.clone(),
                        lasting: not_same.lasting,
                    }),
                    None => Err(crate::Error::io(context(), e)),
                }
            }
            Err(_) => Err(crate::Error::io(
                context(),
                io::Error::new(io::ErrorKind::TimedOut, format!("no connection after {} ms", timeout.as_millis())),
            )),
        }
    }

    pub(crate) fn rtu_codec(&self) -> RtuCodec {
        RtuCodec::new(self.timing, Expect::Both)
            .with_frame_gap(self.frame_gap)
            .with_incomplete_timeout(self.incomplete_timeout)
    }

    pub(crate) fn ascii_codec(&self) -> AsciiCodec {
        AsciiCodec::new(self.timing)
    }

    pub(crate) fn mbap_codec() -> MbapCodec {
        MbapCodec::new()
    }
}

impl fmt::Debug for Transport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Transport")
            .field("framing", &self.framing)
            .field("target", &self.connector.describe())
            .field("timing", &self.timing)
            .finish_non_exhaustive()
    }
}

impl Connector for SerialConfig {
    fn connect(&self) -> Connecting {
        let config = self.clone();
        Box::pin(async move { open_serial(&config).map(|p| Box::new(p) as BoxPort) })
    }

    fn describe(&self) -> String {
        format!("{} at {}", self.path.display(), self.line)
    }
}

/// A serial port that remembers what its path named when first opened, and reopens only that.
struct SerialTarget {
    config: SerialConfig,
    same: Mutex<SameDevice>,
}

/// Why a serial port is not reopened: its path names another device now, or it was a pty
/// ([`SameDevice`]).
#[derive(Debug)]
pub struct NotSame {
    reason: String,
    lasting: bool,
}

impl NotSame {
    /// Whether it is for good: a pty that went away never comes back, so opening its path
    /// again is never right. Otherwise the device may be plugged back in.
    pub fn lasting(&self) -> bool {
        self.lasting
    }
}

impl fmt::Display for NotSame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.reason)
    }
}

impl std::error::Error for NotSame {}

/// What a serial port's path named when first opened, asked before each reopening (the rule
/// of this module's head). The drivers' serial transport asks it; so does a program that
/// opens a port itself, again and again (a listen-only line of the bridge).
#[derive(Debug)]
pub struct SameDevice {
    path: std::path::PathBuf,
    first: Option<Identity>,
}

impl SameDevice {
    /// Nothing opened at `path` yet.
    pub fn new(path: impl Into<std::path::PathBuf>) -> Self {
        SameDevice { path: path.into(), first: None }
    }

    /// Runs `open` if the path still names the device it named at the first successful
    /// `open` (the first time, whatever it names); else [`NotSame`], and `open` is not run.
    /// The path is identified before `open` runs: opening a tty can change its settings, and
    /// another device's line must not be touched at all.
    pub fn open<T, E>(&mut self, open: impl FnOnce() -> Result<T, E>) -> Result<Result<T, E>, NotSame> {
        let now = crate::sys::identify(&self.path);
        if let Some(first) = self.first.as_ref()
            && let Err(reason) = first.reopen_check(now.as_ref())
        {
            return Err(NotSame { reason, lasting: matches!(first, Identity::Pty(_)) });
        }
        let opened = open();
        if opened.is_ok() && self.first.is_none() {
            self.first = now;
        }
        Ok(opened)
    }
}

impl SerialTarget {
    fn open(&self) -> io::Result<BoxPort> {
        let mut same = self.same.lock().unwrap_or_else(PoisonError::into_inner);
        match same.open(|| open_serial(&self.config)) {
            Ok(opened) => Ok(Box::new(opened?)),
            Err(not_same) => Err(io::Error::other(not_same)),
        }
    }
}

impl Connector for SerialTarget {
    fn connect(&self) -> Connecting {
        let opened = self.open();
        Box::pin(async move { opened })
    }

    fn describe(&self) -> String {
        self.config.describe()
    }
}

struct TcpTarget {
    addr: String,
    /// Modbus/TCP: a TLS record as the server's first bytes is told ([`TlsAnswer`]).
    mbap: bool,
}

impl Connector for TcpTarget {
    fn connect(&self) -> Connecting {
        let (addr, mbap) = (self.addr.clone(), self.mbap);
        Box::pin(async move {
            let stream = TcpStream::connect(&addr).await?;
            stream.set_nodelay(true)?;
            Ok(if mbap { Box::new(FirstBytes::new(stream)) as BoxPort } else { Box::new(stream) as BoxPort })
        })
    }

    fn describe(&self) -> String {
        self.addr.clone()
    }
}

/// A connector from a closure, for streams a program makes itself.
pub struct ConnectWith<F> {
    open: F,
    name: String,
}

impl<F> ConnectWith<F>
where
    F: Fn() -> Connecting + Send + Sync + 'static,
{
    /// A connector named `name` that calls `open`.
    pub fn new(name: impl Into<String>, open: F) -> Self {
        ConnectWith { open, name: name.into() }
    }
}

impl<F> Connector for ConnectWith<F>
where
    F: Fn() -> Connecting + Send + Sync + 'static,
{
    fn connect(&self) -> Connecting {
        (self.open)()
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}
