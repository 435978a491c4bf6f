//! Ctrl-C (SIGINT) and SIGTERM, for commands that stop early but still write what they did.
//!
//! A command that can run long (`read` of many registers, `bench`, `line`, `get`, `set`,
//! `backup`, `diff`, `restore`) listens before it starts, so that a signal arriving at any
//! moment is caught, not fatal: it then writes what is done (`backup` what it read, `restore`
//! what it wrote and verified and what not) and ends with
//! [`crate::exit::CliError::Interrupted`] (exit 130), or, for `line`, whose normal end is an
//! interruption, with its statistics.

use crate::exit::CliError;

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
