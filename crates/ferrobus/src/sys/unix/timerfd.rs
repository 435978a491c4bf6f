//! Linux's timerfd in the runtime's own epoll: the kernel's high-resolution timer wakes the
//! runtime thread directly, tens of microseconds late and with no thread in between.

use std::io;
use std::os::fd::OwnedFd;

use rustix::time::{ClockId, Itimerspec, TimerfdClockId, TimerfdFlags, TimerfdTimerFlags, Timespec};
use tokio::io::Interest;
use tokio::io::unix::AsyncFd;

/// A timerfd watched by the runtime's reactor.
#[derive(Debug)]
pub(crate) struct TimerFd {
    fd: AsyncFd<OwnedFd>,
    /// The deadline it is armed for: a sleep that is cancelled and made again for the same
    /// deadline (bytes arrived meanwhile) costs no system call.
    armed: Option<tokio::time::Instant>,
}

impl TimerFd {
    pub(crate) fn new() -> io::Result<Self> {
        let flags = TimerfdFlags::NONBLOCK | TimerfdFlags::CLOEXEC;
        let fd = rustix::time::timerfd_create(TimerfdClockId::Monotonic, flags)?;
        Ok(TimerFd { fd: super::fd::register(fd, Interest::READABLE)?, armed: None })
    }

    pub(crate) async fn sleep_until(&mut self, deadline: tokio::time::Instant) -> io::Result<()> {
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            if left.is_zero() {
                return Ok(());
            }
            if self.armed != Some(deadline) {
                // Re-arming also clears an expiry nobody read (a cancelled sleep's).
                let at = rustix::time::clock_gettime(ClockId::Monotonic)
                    .checked_add(Timespec::try_from(left).map_err(io::Error::other)?)
                    .ok_or_else(|| io::Error::other("a deadline past the end of time"))?;
                let zero = Timespec { tv_sec: 0, tv_nsec: 0 };
                let spec = Itimerspec { it_interval: zero, it_value: at };
                rustix::time::timerfd_settime(self.fd.get_ref(), TimerfdTimerFlags::ABSTIME, &spec)?;
                self.armed = Some(deadline);
            }
            let mut guard = self.fd.readable().await?;
            let mut expirations = [0u8; 8];
            match guard.try_io(|fd| rustix::io::read(fd.get_ref(), &mut expirations).map_err(io::Error::from)) {
                Ok(Ok(_)) => {
                    self.armed = None;
                    return Ok(());
                }
                Ok(Err(e)) if e.kind() == io::ErrorKind::Interrupted => {}
                Ok(Err(e)) => return Err(e),
                Err(_would_block) => {}
            }
        }
    }
}
