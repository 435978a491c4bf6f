//! The library's reads and writes of parameters ([`ferrobus_tools::backup::device`]), watched by
//! Ctrl-C and shown with a progress bar on a terminal.

use ferrobus_profile::Point;
use ferrobus_tools::backup::Watch;
pub(crate) use ferrobus_tools::backup::device::Readings;
use ferrobus_tools::backup::{Target, View};
use indicatif::ProgressBar;

use crate::connect::Session;
use crate::interrupt::Interrupt;
use crate::progress;

/// Ctrl-C (or SIGTERM) and a progress bar.
pub(crate) struct Watched<'a> {
    interrupt: &'a mut Interrupt,
    bar: ProgressBar,
}

impl<'a> Watched<'a> {
    /// Watches `interrupt`, with a bar of `len` `what` on a terminal.
    pub(crate) fn new(interrupt: &'a mut Interrupt, len: usize, what: &str) -> Watched<'a> {
        Watched { interrupt, bar: progress::bar(len, what) }
    }

    /// Clears the bar.
    pub(crate) fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Watch for Watched<'_> {
    fn stop(&mut self) -> impl Future<Output = ()> {
        self.interrupt.wait()
    }

    fn progress(&mut self, done: u64) {
        self.bar.inc(done);
    }

    fn started(&mut self, code: &str) {
        self.bar.set_message(code.to_string());
    }
}

/// The session's device, as the library names it.
pub(crate) fn target(session: &Session) -> Target<'_> {
    Target { client: &session.client, unit: session.unit }
}

/// Reads `params` ([`ferrobus_tools::backup::device::read`]) with a progress bar on a terminal,
/// stopped by Ctrl-C.
pub(crate) async fn read(session: &Session, view: &View, params: &[&Point], interrupt: &mut Interrupt) -> Readings {
    let mut watched = Watched::new(interrupt, params.len(), "parameters read");
    let readings = ferrobus_tools::backup::device::read(target(session), view, params, &mut watched).await;
    watched.finish();
    readings
}
