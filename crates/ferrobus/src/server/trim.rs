//! Giving freed memory back after a burst of connections.
//!
//! A connection's buffers are small allocations, and glibc's allocator keeps the pages of
//! small allocations once they are freed (it returns only a free top of the heap, and one
//! long-lived allocation made during the burst pins it): the memory of 1,000 closed
//! connections stayed in the process, reused by the next ones but never returned. When a
//! burst is over — the open connections fallen to a quarter of their peak, a peak of at least
//! [`BURST`] — the server asks the allocator to return the free pages (glibc's `malloc_trim`,
//! behind the platform seam: [`crate::sys`]) if the application asked for it
//! ([`super::TcpLimits::release_memory_after_bursts`]; off by default, the `ferrobus` binary's
//! servers turn it on). Elsewhere (musl, macOS, Windows) the allocators return
//! memory by themselves, or have no such call, and this is a no-op.

use std::sync::atomic::{AtomicUsize, Ordering};

/// The fewest connections open at once that make a burst worth trimming after.
pub(super) const BURST: usize = 64;

/// The peak of open connections since the last trim.
#[derive(Debug, Default)]
pub(super) struct Bursts {
    peak: AtomicUsize,
}

impl Bursts {
    /// `open` connections are open now, one more than before.
    pub(super) fn opened(&self, open: usize) {
        self.peak.fetch_max(open, Ordering::Relaxed);
    }

    /// `open` connections are left, one fewer than before: the burst is over if they are a
    /// quarter of its peak or fewer, and then the free memory is given back. Returns whether it
    /// was.
    pub(super) fn closed(&self, open: usize) -> bool {
        let peak = self.peak.load(Ordering::Relaxed);
        if peak < BURST || open > peak / 4 {
            return false;
        }
        // One closing task trims; the others see the peak lowered.
        if self.peak.compare_exchange(peak, open, Ordering::Relaxed, Ordering::Relaxed).is_err() {
            return false;
        }
        crate::sys::release_free_memory();
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_burst_is_trimmed_after_once_it_falls_to_a_quarter_of_its_peak() {
        let bursts = Bursts::default();
        for open in 1..=100 {
            bursts.opened(open);
        }
        assert!((26..100).rev().all(|open| !bursts.closed(open)));
        assert!(bursts.closed(25));
        // The peak is now 25: no second trim for the same burst.
        assert!((0..25).rev().all(|open| !bursts.closed(open)));
    }

    #[test]
    fn a_few_connections_are_no_burst() {
        let bursts = Bursts::default();
        for open in 1..BURST {
            bursts.opened(open);
        }
        assert!((0..BURST - 1).rev().all(|open| !bursts.closed(open)));
    }
}
