//! Descriptors on tokio's reactor: the one `unsafe` block of the workspace.

use std::io;
use std::os::fd::{AsRawFd, OwnedFd};

use tokio::io::Interest;
use tokio::io::unix::AsyncFd;

/// Descriptors that stay open and unchanged for as long as their owner lives, as
/// `AsyncFd::register_with_interest` requires.
///
/// # Safety
///
/// An implementor's `as_raw_fd` returns the same open descriptor on every call, from the value's
/// creation until it is dropped, and nothing but its drop closes that descriptor.
#[expect(unsafe_code, reason = "the contract register's unsafe block rests on")]
pub(crate) unsafe trait OwnsFd: AsRawFd {}

// SAFETY: a serial2 port owns its file for its whole life and closes it only when dropped; it
// hands out no way to close or replace it.
#[expect(unsafe_code, reason = "a promise about serial2's port")]
unsafe impl OwnsFd for serial2::SerialPort {}
// SAFETY: an OwnedFd is the owned descriptor itself, closed only by its drop.
#[expect(unsafe_code, reason = "a promise about OwnedFd")]
unsafe impl OwnsFd for OwnedFd {}

/// Registers `inner` with tokio's reactor for `interest`. Needs a tokio runtime.
#[expect(unsafe_code, reason = "this tokio has no safe way to register an owned descriptor")]
pub(crate) fn register<T: OwnsFd>(inner: T, interest: Interest) -> io::Result<AsyncFd<T>> {
    // SAFETY: `inner` moves into the AsyncFd, which owns it until the AsyncFd is dropped; by
    // `OwnsFd`'s contract its descriptor is closed only when `inner` is dropped and is the same
    // on every `as_raw_fd` call.
    let registered = unsafe { AsyncFd::register_with_interest(inner, interest) };
    Ok(registered?)
}
