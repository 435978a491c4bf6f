//! The library's reads and writes of parameters ([`ferrobus::backup::device`]), watched by
//! Ctrl-C and shown with a progress bar on a terminal.

use ferrobus::backup::Watch;
pub(crate) use ferrobus::backup::device::{Readings, describe};
use ferrobus::backup::{Target, View};
use ferrobus_profile::Point;
use indicatif::ProgressBar;

use crate::connect::Session;
use crate::interrupt::Interrupt;
use crate::progress;

/// Ctrl-C (or SIGTERM) and a progress bar.
struct Watched<'a> {
    interrupt: &'a mut Interrupt,
    bar: ProgressBar,
}

impl Watch for Watched<'_> {
    fn stop(&mut self) -> impl Future<Output = ()> {
        self.interrupt.wait()
    }

    fn progress(&mut self, done: u64) {
        self.bar.inc(done);
    }
}

/// The session's device, as the library names it.
pub(crate) fn target(session: &Session) -> Target<'_> {
    Target { client: &session.client, unit: session.unit }
}

/// Reads `params` ([`ferrobus::backup::device::read`]) with a progress bar on a terminal,
/// stopped by Ctrl-C.
pub(crate) async fn read(session: &Session, view: &View, params: &[&Point], interrupt: &mut Interrupt) -> Readings {
    let mut watched = Watched { interrupt, bar: progress::bar(params.len(), "parameters read") };
    let readings = ferrobus::backup::device::read(target(session), view, params, &mut watched).await;
    watched.bar.finish_and_clear();
    readings
}

/// Writes `words` to `point` ([`ferrobus::backup::device::write`]).
pub(crate) async fn write(session: &Session, point: &Point, words: &[u16]) -> Result<(), ferrobus::Error> {
    ferrobus::backup::device::write(target(session), point, words).await
}
