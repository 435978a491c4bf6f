//! The bridge between tokio's clock and the core's [`Instant`].
//!
//! The core counts nanoseconds from an epoch its driver chooses; a driver takes the tokio
//! instant at which it starts. Under `tokio::time::pause()` the clock is virtual, so timing
//! tests in this crate run without sleeping.

use ferrobus_proto::Instant;

/// A clock with its epoch.
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    epoch: tokio::time::Instant,
}

impl Clock {
    /// A clock whose epoch is now.
    pub fn new() -> Self {
        Clock { epoch: tokio::time::Instant::now() }
    }

    /// A clock with the given epoch, to share one timeline between drivers.
    pub fn with_epoch(epoch: tokio::time::Instant) -> Self {
        Clock { epoch }
    }

    /// Now, as the core counts it.
    pub fn now(&self) -> Instant {
        self.from_tokio(tokio::time::Instant::now())
    }

    /// A tokio instant as the core counts it (the epoch, if it is earlier).
    pub fn from_tokio(&self, t: tokio::time::Instant) -> Instant {
        let nanos = t.saturating_duration_since(self.epoch).as_nanos();
        Instant::from_nanos(u64::try_from(nanos).unwrap_or(u64::MAX))
    }

    /// A core instant as a tokio instant.
    pub fn to_tokio(&self, t: Instant) -> tokio::time::Instant {
        self.epoch + t.since_epoch()
    }
}

impl Default for Clock {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[tokio::test(start_paused = true)]
    async fn core_and_tokio_instants_convert_both_ways() {
        let clock = Clock::new();
        tokio::time::advance(Duration::from_micros(1500)).await;
        let now = clock.now();
        assert_eq!(now, Instant::from_micros(1500));
        assert_eq!(clock.to_tokio(now), tokio::time::Instant::now());
        assert_eq!(clock.from_tokio(clock.to_tokio(Instant::from_nanos(7))), Instant::from_nanos(7));
    }
}
