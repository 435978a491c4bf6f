//! systemd's notify protocol for the commands a plant runs as services (`gateway`, `bridge`):
//! `READY=1` once they serve ([`ready`]), `WATCHDOG=1` at half the unit's `WatchdogSec` from
//! the command's runtime ([`Watchdog`]: a process whose runtime stops turning is restarted),
//! `RELOADING=1` with `MONOTONIC_USEC` when SIGHUP has it read its file again ([`reloading`],
//! and `READY=1` once that is done or refused, [`reloaded`]), `STOPPING=1` at the end
//! ([`stopping`]). The units are `scripts/systemd/*.service`, shipped
//! in the deb.
//!
//! Outside systemd (no `NOTIFY_SOCKET`), and on Windows, every call does nothing.

use std::time::Duration;

/// The unit's watchdog, fed at half its timeout.
#[derive(Debug)]
pub(crate) struct Watchdog {
    /// Half the watchdog's timeout, when the unit has one.
    every: Option<Duration>,
}

/// Tells systemd the service is ready, saying `status`; returns its watchdog.
pub(crate) fn ready(status: &str) -> Watchdog {
    #[cfg(unix)]
    {
        send(&[sd_notify::NotifyState::Ready, sd_notify::NotifyState::Status(status)]);
        let mut usec = 0;
        let every = sd_notify::watchdog_enabled(false, &mut usec).then(|| Duration::from_micros(usec / 2));
        Watchdog { every: every.filter(|d| !d.is_zero()) }
    }
    #[cfg(not(unix))]
    {
        let _ = status;
        Watchdog { every: None }
    }
}

/// Tells systemd the service is reading its configuration again: `RELOADING=1` with the
/// monotonic clock's time, as systemd asks of a reload (`Type=notify-reload`); [`reloaded`]
/// follows.
pub(crate) fn reloading() {
    #[cfg(unix)]
    match sd_notify::NotifyState::monotonic_usec_now() {
        Ok(now) => send(&[sd_notify::NotifyState::Reloading, now]),
        Err(e) => {
            tracing::warn!("reading the monotonic clock for systemd: {e}");
            send(&[sd_notify::NotifyState::Reloading]);
        }
    }
}

/// Tells systemd the reload is over (done or refused) and the service ready, saying `status`.
pub(crate) fn reloaded(status: &str) {
    #[cfg(unix)]
    send(&[sd_notify::NotifyState::Ready, sd_notify::NotifyState::Status(status)]);
    #[cfg(not(unix))]
    let _ = status;
}

/// Tells systemd the service is stopping.
pub(crate) fn stopping() {
    #[cfg(unix)]
    send(&[sd_notify::NotifyState::Stopping]);
}

impl Watchdog {
    /// Comes every half watchdog period; never without a watchdog.
    pub(crate) async fn tick(&self) {
        match self.every {
            Some(every) => tokio::time::sleep(every).await,
            None => std::future::pending().await,
        }
    }

    /// Feeds the watchdog.
    pub(crate) fn feed(&self) {
        let due = self.every.is_some();
        #[cfg(unix)]
        if due {
            send(&[sd_notify::NotifyState::Watchdog]);
        }
        #[cfg(not(unix))]
        let _ = due;
    }

    /// Runs `work` (a reload that waits for a line's reply owed, say), feeding the watchdog
    /// meanwhile.
    pub(crate) async fn feeding<T>(&self, work: impl std::future::Future<Output = T>) -> T {
        tokio::pin!(work);
        loop {
            tokio::select! {
                out = &mut work => return out,
                () = self.tick() => self.feed(),
            }
        }
    }

    /// Feeds it at every tick, for as long as the runtime turns.
    pub(crate) async fn feed_forever(self) {
        loop {
            self.tick().await;
            self.feed();
        }
    }
}

/// Sends `states`; a socket that cannot be written is logged, never fatal.
#[cfg(unix)]
fn send(states: &[sd_notify::NotifyState<'_>]) {
    if let Err(e) = sd_notify::notify(false, states) {
        tracing::warn!("telling systemd ({:?}): {e}", states.first());
    }
}
