//! Where the simulation's time comes from, shared by the line ([`crate::sim::Sim`]) and the
//! points that follow the wall clock ([`crate::ticker::Ticker`]).

use std::sync::Arc;
use std::time::Duration;

/// Where the simulation's time comes from: the time since it started.
pub type SimClock = Arc<dyn Fn() -> Duration + Send + Sync>;

/// A clock that follows tokio's (and so a paused test clock).
pub fn tokio_clock() -> SimClock {
    let start = tokio::time::Instant::now();
    Arc::new(move || start.elapsed())
}
