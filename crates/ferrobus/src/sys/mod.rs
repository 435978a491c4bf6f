//! The platform seam: everything that differs between operating systems, one folder per
//! platform, the same names in each.
//!
//! | item | Unix (`unix/`) | Windows (`windows/`) |
//! |---|---|---|
//! | [`TtyPort`], [`open_serial`] | a tty through serial2, read on tokio's reactor | a COM port through serial2-tokio (overlapped IO on tokio's IOCP) |
//! | `Pty`, `PeerSettings` | pseudo-terminals (ptsname; termios of the other end) | none: ptys are Unix's |
//! | `identify` | symlink, pty, sysfs USB ids, device number | a COM name is the device's |
//! | `TimerFd` | Linux: a timerfd in the runtime's epoll; macOS: none | none: the timer thread ([`crate::timer`]) |
//! | `NEAR` | 3 ms | 20 ms, more than a clock tick |
//! | `release_free_memory` | Linux with glibc: `malloc_trim`; elsewhere nothing | nothing: the allocator returns memory itself |
//! | `out_of_sockets` | EMFILE, ENFILE, ENOBUFS, ENOMEM (by name, through rustix) | WSAEMFILE, ERROR_TOO_MANY_OPEN_FILES, WSAENOBUFS |
//! | [`PortFault::of`] | EBUSY, ENOTTY, EIO, ENXIO, ENODEV (by name) | ERROR_ACCESS_DENIED, ERROR_BAD_COMMAND, ERROR_GEN_FAILURE, ERROR_DEVICE_NOT_CONNECTED |
//! | [`THREAD_WAIT_GRAIN`] | zero: timed waits are precise | about a tick of the system clock |
//!
//! Everything else — settings ([`crate::serial`]), transports, drivers, timing — is shared.

use std::io;
use std::time::Duration;

#[cfg(unix)]
mod unix;
#[cfg(target_os = "linux")]
pub(crate) use unix::TimerFd;
#[cfg(all(unix, test))]
pub(crate) use unix::descriptor_table_full;
#[cfg(unix)]
pub(crate) use unix::{PeerSettings, PtyWriter, identify, out_of_sockets, port_fault};
#[cfg(unix)]
pub use unix::{Pty, TtyPort, open_serial};

#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub(crate) use unix::release_free_memory;

/// Returns the heap's free pages to the OS: here the allocator does so by itself (musl,
/// macOS, Windows), or has no call for it.
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub(crate) fn release_free_memory() {}

#[cfg(windows)]
mod windows;
#[cfg(all(windows, test))]
pub(crate) use windows::descriptor_table_full;
#[cfg(windows)]
pub use windows::{TtyPort, open_serial};
#[cfg(windows)]
pub(crate) use windows::{identify, out_of_sockets, port_fault};

/// What an IO error of a serial port means, where the platform's error code says more than
/// its [`io::ErrorKind`]: the same trouble has other numbers on each OS (an unplugged adapter
/// is EIO on Linux, ERROR_BAD_COMMAND or ERROR_GEN_FAILURE on Windows).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[non_exhaustive]
pub enum PortFault {
    /// Another program has the port open (Unix: EBUSY; Windows: ERROR_ACCESS_DENIED, a COM
    /// port being one program's at a time).
    Busy,
    /// The path is not a serial port (Unix: ENOTTY, the terminal calls refused).
    NotSerial,
    /// The port went away, as an unplugged USB adapter does (Unix: EIO, ENXIO, ENODEV;
    /// Windows: ERROR_BAD_COMMAND, ERROR_GEN_FAILURE, ERROR_DEVICE_NOT_CONNECTED).
    Gone,
}

impl PortFault {
    /// What `e`, from opening, setting, reading or writing a serial port, means; `None` when
    /// its code says nothing more than its kind.
    pub fn of(e: &io::Error) -> Option<PortFault> {
        port_fault(e)
    }
}

/// How late the OS may end a thread's timed wait on a condition variable: the timer thread
/// waits that much less, then finishes with high-resolution sleeps.
#[cfg(not(windows))]
pub(crate) const THREAD_WAIT_GRAIN: Duration = Duration::ZERO;

/// How late the OS may end a thread's timed wait on a condition variable: the timer thread
/// waits that much less, then finishes with high-resolution sleeps. Windows ends such waits
/// on its clock's ticks, 15.625 ms apart unless a program asked for finer ones; the standard
/// library's `thread::sleep` is a high-resolution waitable timer there (since Rust 1.75, on
/// Windows 10 1803 and later; before, it falls back to those ticks).
#[cfg(windows)]
pub(crate) const THREAD_WAIT_GRAIN: Duration = Duration::from_millis(16);

/// The part of a deadline slept precisely ([`crate::timer::NEAR`]).
#[cfg(not(windows))]
pub(crate) const NEAR: Duration = Duration::from_millis(3);

/// The part of a deadline slept precisely ([`crate::timer::NEAR`]): more than a tick of
/// Windows' clock (15.625 ms), on which tokio's waits there end.
#[cfg(windows)]
pub(crate) const NEAR: Duration = Duration::from_millis(20);

/// No timerfd outside Linux: making one fails, and precise deadlines go through the timer
/// thread.
#[cfg(not(target_os = "linux"))]
#[derive(Debug)]
pub(crate) enum TimerFd {}

#[cfg(not(target_os = "linux"))]
impl TimerFd {
    pub(crate) fn new() -> std::io::Result<Self> {
        Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "timerfds are Linux's"))
    }

    #[expect(clippy::unused_async, reason = "the signature of Linux's")]
    pub(crate) async fn sleep_until(&mut self, _: tokio::time::Instant) -> std::io::Result<()> {
        match *self {}
    }
}
