//! Ctrl-C (SIGINT) and SIGTERM, for commands that stop early but still write what they did.
//!
//! A command that can run long (`read` of many registers, `bench`, `line`, `get`, `set`,
//! `backup`, `diff`, `restore`) listens before it starts, so that a signal arriving at any
//! moment is caught, not fatal: it then writes what is done (`backup` what it read, `restore`
//! what it wrote and verified and what not) and ends with
//! [`crate::exit::CliError::Interrupted`] (exit 130), or, for `line`, whose normal end is an
//! interruption, with its statistics.
//!
//! Whatever ended the command, a reply may still be on its way: the request of an
//! interrupted command, or one that timed out. On RTU and ASCII the next program on the port
//! would take it for its own reply, so before the process exits [`release_ports`] waits
//! until every client's driver has let its port go ([`ferrobus::Release`]): the reply has
//! come and been dropped, or its late window has passed. It says so when it waits; a second
//! Ctrl-C exits at once. The lines of `gateway` and `bridge` are kept so too.

use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use crate::exit::CliError;

/// The releases of the clients this process opened, waited for before it exits.
static RELEASES: Mutex<Vec<ferrobus::Release>> = Mutex::new(Vec::new());

/// Keeps `client`'s release, so that the process waits for it before it exits
/// ([`release_ports`]). Every client the commands open is kept here.
pub(crate) fn keep_release(client: &ferrobus::Client) {
    keep(client.release());
}

/// Keeps `release` (a client's the command did not open itself: a gateway line's), as
/// [`keep_release`] does.
pub(crate) fn keep(release: ferrobus::Release) {
    RELEASES.lock().unwrap_or_else(PoisonError::into_inner).push(release);
}

/// Waits until no reply is on its way to a client this process opened, saying how long it
/// may take; a second SIGINT or SIGTERM ends the wait at once.
pub(crate) async fn release_ports() {
    let releases = std::mem::take(&mut *RELEASES.lock().unwrap_or_else(PoisonError::into_inner));
    let Some(longest) = releases.iter().filter_map(ferrobus::Release::pending).max() else { return };
    // A listener made before the note, so that a Ctrl-C after it is caught.
    let interrupt = Interrupt::listen();
    eprintln!(
        "waiting up to {} ms for the reply in flight, so that it reaches no one else (Ctrl-C again to exit now)",
        longest.max(Duration::from_millis(1)).as_millis()
    );
    // Each wait ends by its own deadline; awaited in turn they take as long as the longest.
    let settled = async {
        for release in releases {
            release.settled().await;
        }
    };
    match interrupt {
        Ok(mut interrupt) => {
            let _ = interrupt.unless(settled).await;
        }
        Err(_) => settled.await,
    }
}

/// A listener for SIGINT and SIGTERM, installed when made.
pub(crate) struct Interrupt {
    #[cfg(unix)]
    int: tokio::signal::unix::Signal,
    #[cfg(unix)]
    term: tokio::signal::unix::Signal,
    /// Windows: Ctrl-C (there is no SIGTERM).
    #[cfg(windows)]
    ctrl_c: tokio::signal::windows::CtrlC,
}

impl Interrupt {
    /// Starts listening. From here on, SIGINT and SIGTERM no longer end the process.
    pub(crate) fn listen() -> Result<Interrupt, CliError> {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            let failed = |e| CliError::from(ferrobus::Error::io("listening for Ctrl-C and SIGTERM", e));
            Ok(Interrupt {
                int: signal(SignalKind::interrupt()).map_err(failed)?,
                term: signal(SignalKind::terminate()).map_err(failed)?,
            })
        }
        #[cfg(windows)]
        {
            let failed = |e| CliError::from(ferrobus::Error::io("listening for Ctrl-C", e));
            Ok(Interrupt { ctrl_c: tokio::signal::windows::ctrl_c().map_err(failed)? })
        }
    }

    /// Runs `work` unless SIGINT or SIGTERM comes first; `None` if one did (`work` is then
    /// dropped, cancelled where it stood).
    pub(crate) async fn unless<F: Future>(&mut self, work: F) -> Option<F::Output> {
        tokio::select! {
            biased;
            () = self.wait() => None,
            done = work => Some(done),
        }
    }

    /// Waits for the next SIGINT or SIGTERM.
    pub(crate) async fn wait(&mut self) {
        #[cfg(unix)]
        tokio::select! {
            _ = self.int.recv() => {}
            _ = self.term.recv() => {}
        }
        #[cfg(windows)]
        if self.ctrl_c.recv().await.is_none() {
            std::future::pending::<()>().await;
        }
    }
}

/// A listener for SIGHUP, the signal to read the configuration again (`gateway
/// --lines-file`, `bridge`; systemd's `ExecReload`), installed when made. Windows has no
/// SIGHUP: there it never comes.
pub(crate) struct Hangup {
    #[cfg(unix)]
    hup: tokio::signal::unix::Signal,
}

impl Hangup {
    /// Starts listening. From here on, SIGHUP no longer ends the process.
    #[cfg_attr(
        not(unix),
        expect(clippy::unnecessary_wraps, reason = "the signature of every platform's: Unix may fail to listen")
    )]
    pub(crate) fn listen() -> Result<Hangup, CliError> {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            let hup = signal(SignalKind::hangup())
                .map_err(|e| CliError::from(ferrobus::Error::io("listening for SIGHUP", e)))?;
            Ok(Hangup { hup })
        }
        #[cfg(not(unix))]
        Ok(Hangup {})
    }

    /// Waits for the next SIGHUP (for ever on Windows).
    pub(crate) async fn wait(&mut self) {
        #[cfg(unix)]
        if self.hup.recv().await.is_some() {
            return;
        }
        std::future::pending::<()>().await;
    }
}
