//! Unix: ttys and ptys through their descriptors on tokio's reactor; on Linux, timerfds, and
//! with glibc, giving freed memory back.

mod errors;
mod fd;
#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod heap;
mod identity;
#[cfg(target_os = "linux")]
mod timerfd;
mod tty;

#[cfg(test)]
pub(crate) use errors::descriptor_table_full;
pub(crate) use errors::{out_of_sockets, port_fault};
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub(crate) use heap::release_free_memory;
pub(crate) use identity::identify;
#[cfg(target_os = "linux")]
pub(crate) use timerfd::TimerFd;
pub(crate) use tty::{PeerSettings, PtyWriter};
pub use tty::{Pty, TtyPort, open_serial};
