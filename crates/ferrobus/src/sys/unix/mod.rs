//! Unix: ttys and ptys through their descriptors on tokio's reactor; on Linux, timerfds, and
//! with glibc, giving freed memory back.

mod fd;
#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod heap;
mod identity;
#[cfg(target_os = "linux")]
mod timerfd;
mod tty;

#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub(crate) use heap::release_free_memory;
pub(crate) use identity::identify;
#[cfg(target_os = "linux")]
pub(crate) use timerfd::TimerFd;
pub(crate) use tty::{PeerSettings, PtyWriter};
pub use tty::{Pty, TtyPort, open_serial};
