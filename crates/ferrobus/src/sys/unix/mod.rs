//! Unix: ttys and ptys through their descriptors on tokio's reactor; on Linux, timerfds.

mod fd;
mod identity;
#[cfg(target_os = "linux")]
mod timerfd;
mod tty;

pub(crate) use identity::identify;
#[cfg(target_os = "linux")]
pub(crate) use timerfd::TimerFd;
pub(crate) use tty::{PeerSettings, PtyWriter};
pub use tty::{Pty, TtyPort, open_serial};
