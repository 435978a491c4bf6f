//! Sleeping until an engine's deadline, to the precision the deadline needs.
//!
//! Tokio's timer wheel fires on 1 ms ticks, rounding every sleep up to the next tick: a reply
//! due in 4.01 ms goes out after 5, and a 115200-baud transaction of 3 ms loses a third of its
//! speed to waiting. [`Timer::Precise`] sleeps with tokio until 2 ms before the deadline, then
//! blocks the worker thread for the rest with the OS's high-resolution sleep (tens of
//! microseconds late at most). That briefly holds one runtime worker — the price of honest
//! line timing. [`Timer::Tokio`] is for streams without a line (TCP), and for tests that run
//! on tokio's paused, virtual clock, which a thread sleep would not follow.

use std::time::Duration;

/// How drivers wait for deadlines.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Timer {
    /// Tokio's timer alone: up to 1 ms late; follows a paused clock.
    #[default]
    Tokio,
    /// Tokio's timer, then a thread sleep for the last stretch: tens of microseconds late.
    Precise,
}

/// Below this, the last stretch of a precise sleep is a thread sleep.
const COARSE: Duration = Duration::from_millis(2);

impl Timer {
    /// Sleeps until `deadline`, or forever for `None`.
    pub async fn sleep_until(self, deadline: Option<tokio::time::Instant>) {
        let Some(deadline) = deadline else {
            return std::future::pending().await;
        };
        match self {
            Timer::Tokio => tokio::time::sleep_until(deadline).await,
            Timer::Precise => {
                if deadline.saturating_duration_since(tokio::time::Instant::now()) > COARSE {
                    tokio::time::sleep_until(deadline - COARSE).await;
                }
                let rest = deadline.saturating_duration_since(tokio::time::Instant::now());
                if !rest.is_zero() {
                    std::thread::sleep(rest);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_precise_sleep_is_never_early_and_usually_well_under_a_tick_late() {
        let mut late = Vec::new();
        for i in 0..21u64 {
            // Deadlines spread across tokio's 1 ms ticks.
            let deadline = tokio::time::Instant::now() + Duration::from_micros(3_000 + i * 137);
            Timer::Precise.sleep_until(Some(deadline)).await;
            let now = tokio::time::Instant::now();
            assert!(now >= deadline, "woke early");
            late.push(now - deadline);
        }
        late.sort();
        // Tokio's timer alone is ~500 µs late at the median; a thread sleep, tens of µs. The
        // bound leaves room for a loaded CI machine.
        assert!(late[10] < Duration::from_micros(400), "median lateness {:?}", late[10]);
    }

    #[tokio::test(start_paused = true)]
    async fn the_tokio_timer_follows_a_paused_clock() {
        let start = tokio::time::Instant::now();
        Timer::Tokio.sleep_until(Some(start + Duration::from_secs(3600))).await;
        assert_eq!(tokio::time::Instant::now() - start, Duration::from_secs(3600));
    }
}
