//! Sleeping until an engine's deadline, to the precision the deadline needs.
//!
//! Tokio's timer wheel fires on 1 ms ticks, rounding every sleep up to the next tick: a reply
//! due in 4.01 ms goes out after 5, and a 115200-baud transaction of 6 ms loses a sixth of its
//! speed to waiting.
//!
//! A driver waits for all its deadlines with one [`Sleeper`]. The far part of a deadline —
//! all but its last [`NEAR`] — is slept on tokio's wheel, in one entry that is re-armed only
//! when a deadline comes earlier than the one it holds: a reply timeout that moves on every
//! pass of the driver costs nothing, and most are cancelled by the reply long before they come.
//! The near part is slept as the [`Timer`] says:
//!
//! - [`Timer::Precise`]: a timerfd in the runtime's own epoll (Linux): the kernel's
//!   high-resolution timer wakes the runtime thread directly, tens of microseconds late and
//!   with no thread in between. Elsewhere, or if the timerfd cannot be made, a timer thread
//!   that wakes the task. On Windows, whose timed waits end on 15.6 ms clock ticks, the thread
//!   finishes each wait with high-resolution sleeps (the standard library's sleep uses a
//!   high-resolution waitable timer there), and [`NEAR`] is longer than a tick.
//! - [`Timer::Spin`]: the same to [`SPIN`] before the deadline, then a busy wait on the
//!   calling thread: a microsecond or two late, for the virtual line, where 2 % of a
//!   115200-baud transaction is 127 µs, and for a simulator alone on its pty. The thread does
//!   nothing else meanwhile: other tasks of a single-threaded runtime wait those
//!   microseconds.
//! - [`Timer::Tokio`]: tokio's timer alone, for streams without a line (TCP) and for tests on
//!   tokio's paused, virtual clock, which the kernel's timers would not follow.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, OnceLock, PoisonError};
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

use crate::sys::THREAD_WAIT_GRAIN;

/// How drivers wait for deadlines.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Timer {
    /// Tokio's timer alone: up to 1 ms late; follows a paused clock.
    #[default]
    Tokio,
    /// The kernel's high-resolution timer: tens of microseconds late.
    Precise,
    /// The kernel's timer, then a busy wait on the calling thread for the last
    /// [`SPIN`]: about a microsecond late, at the price of that thread's time.
    Spin,
}

impl Timer {
    /// A sleeper for the successive deadlines of one task.
    pub fn sleeper(self) -> Sleeper {
        Sleeper { timer: self, coarse: None, precise: Precise::Untried }
    }

    /// Sleeps until `deadline`, or forever for `None`. A task that sleeps again and again
    /// should keep a [`Sleeper`] instead.
    pub async fn sleep_until(self, deadline: Option<tokio::time::Instant>) {
        self.sleeper().sleep_until(deadline).await;
    }
}

/// The part of a deadline slept precisely; the rest is slept on tokio's wheel: 3 ms, and on
/// Windows 20 ms, more than a tick of its clock (15.625 ms), on which tokio's waits there end.
pub const NEAR: Duration = crate::sys::NEAR;

/// The longest high-resolution sleep of the timer thread within [`THREAD_WAIT_GRAIN`] of a
/// deadline: how late a deadline registered during one may be.
const FINE_STEP: Duration = Duration::from_micros(250);

/// Spinning starts this long before a [`Timer::Spin`] deadline: more than the kernel's timer
/// is usually late on a loaded virtual machine.
pub const SPIN: Duration = Duration::from_micros(200);

/// Waits for one task's deadlines, one after the other (see the module documentation).
#[derive(Debug)]
pub struct Sleeper {
    timer: Timer,
    /// The far part of every deadline, on tokio's wheel; made on first use (it needs a runtime).
    coarse: Option<Pin<Box<tokio::time::Sleep>>>,
    /// The kernel timer of the near part ([`Timer::Precise`], and [`Timer::Spin`] up to its
    /// busy wait).
    precise: Precise,
}

/// Which kernel timer a sleeper's near part sleeps on.
#[derive(Debug)]
enum Precise {
    /// Its timerfd is made on the first precise sleep.
    Untried,
    TimerFd(crate::sys::TimerFd),
    /// No timerfd here (not Linux, or the kernel refused one): the timer thread.
    Thread,
}

impl Sleeper {
    /// Sleeps until `deadline`, or forever for `None`; never returns before it. Dropping the
    /// future cancels the sleep; the next one may be for any deadline.
    pub async fn sleep_until(&mut self, deadline: Option<tokio::time::Instant>) {
        let Some(deadline) = deadline else {
            return std::future::pending().await;
        };
        let near = if self.timer == Timer::Tokio { Duration::ZERO } else { NEAR };
        while let Some(far) = deadline.checked_sub(near).filter(|far| *far > tokio::time::Instant::now()) {
            self.sleep_coarse(far).await;
        }
        match self.timer {
            Timer::Tokio => {}
            Timer::Precise => self.sleep_precise(deadline).await,
            Timer::Spin => {
                if let Some(before) = deadline.checked_sub(SPIN) {
                    self.sleep_precise(before).await;
                }
                let spinning = Instant::now();
                while tokio::time::Instant::now() < deadline {
                    if spinning.elapsed() > 2 * SPIN {
                        // A clock that does not move with real time (tokio's paused test
                        // clock): wait on it instead of spinning forever.
                        tokio::time::sleep_until(deadline).await;
                        break;
                    }
                    std::hint::spin_loop();
                }
            }
        }
    }

    /// Sleeps on tokio's wheel until `far`, or until the time the entry already held, if that
    /// is earlier: the caller then sleeps again, on an entry re-armed for `far`.
    async fn sleep_coarse(&mut self, far: tokio::time::Instant) {
        let coarse = self.coarse.get_or_insert_with(|| Box::pin(tokio::time::sleep_until(far)));
        if coarse.is_elapsed() || coarse.deadline() > far {
            coarse.as_mut().reset(far);
        }
        coarse.as_mut().await;
    }

    async fn sleep_precise(&mut self, deadline: tokio::time::Instant) {
        if matches!(self.precise, Precise::Untried) {
            self.precise = match crate::sys::TimerFd::new() {
                Ok(fd) => Precise::TimerFd(fd),
                // Not Linux: the timer thread is the way here, nothing to report.
                Err(e) if e.kind() == std::io::ErrorKind::Unsupported => Precise::Thread,
                Err(e) => {
                    tracing::info!("no timerfd ({e}); precise deadlines go through a timer thread");
                    Precise::Thread
                }
            };
        }
        if let Precise::TimerFd(fd) = &mut self.precise {
            match fd.sleep_until(deadline).await {
                Ok(()) => return,
                Err(e) => {
                    tracing::warn!("the timerfd failed ({e}); precise deadlines go through a timer thread");
                    self.precise = Precise::Thread;
                }
            }
        }
        ThreadSleep::new(deadline).await;
    }
}

// The timer thread: precise deadlines where there is no timerfd (not Linux, or the kernel
// refused one). It sleeps with the OS's high-resolution timer and wakes the waiting task,
// without ever blocking a runtime worker.

/// A deadline registered with the timer thread.
struct Entry {
    wake_at: Instant,
    waker: Waker,
    /// Set when the sleep is dropped before its deadline (a `select!` took another branch):
    /// the thread then does not wake anyone.
    cancelled: Arc<AtomicBool>,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.wake_at == other.wake_at
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.wake_at.cmp(&other.wake_at)
    }
}

/// The background thread's queue of deadlines.
struct Wheel {
    queue: Mutex<BinaryHeap<Reverse<Entry>>>,
    changed: Condvar,
}

fn wheel() -> &'static Arc<Wheel> {
    static WHEEL: OnceLock<Arc<Wheel>> = OnceLock::new();
    WHEEL.get_or_init(|| {
        let wheel = Arc::new(Wheel { queue: Mutex::new(BinaryHeap::new()), changed: Condvar::new() });
        let shared = Arc::clone(&wheel);
        std::thread::Builder::new()
            .name("ferrobus-timer".into())
            .spawn(move || shared.run())
            .expect("the OS refused to start the timer thread");
        wheel
    })
}

impl Wheel {
    fn register(&self, entry: Entry) {
        let mut queue = self.queue.lock().unwrap_or_else(PoisonError::into_inner);
        // The thread needs waking only when its next deadline moves earlier.
        let earliest = queue.peek().is_none_or(|Reverse(next)| entry.wake_at < next.wake_at);
        queue.push(Reverse(entry));
        drop(queue);
        if earliest {
            self.changed.notify_one();
        }
    }

    /// Wakes each deadline at its instant, earliest first.
    fn run(&self) {
        let mut queue = self.queue.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            let Some(Reverse(next)) = queue.peek() else {
                queue = self.changed.wait(queue).unwrap_or_else(PoisonError::into_inner);
                continue;
            };
            if next.cancelled.load(Ordering::Relaxed) {
                queue.pop();
                continue;
            }
            let (wake_at, now) = (next.wake_at, Instant::now());
            if wake_at > now {
                let left = wake_at - now;
                if let Some(wait) = left.checked_sub(THREAD_WAIT_GRAIN).filter(|wait| !wait.is_zero()) {
                    // Sleep until then (less what the OS may add to a timed wait), or until an
                    // earlier deadline arrives.
                    queue = self.changed.wait_timeout(queue, wait).unwrap_or_else(PoisonError::into_inner).0;
                } else {
                    // Closer than a timed wait can aim (Windows): high-resolution sleeps, each
                    // short enough that an earlier deadline registered meanwhile is on time.
                    drop(queue);
                    std::thread::sleep(left.min(FINE_STEP));
                    queue = self.queue.lock().unwrap_or_else(PoisonError::into_inner);
                }
                continue;
            }
            if let Some(Reverse(due)) = queue.pop()
                && !due.cancelled.load(Ordering::Relaxed)
            {
                due.waker.wake();
            }
        }
    }
}

/// A future that completes at `deadline`, woken by the timer thread.
struct ThreadSleep {
    deadline: Instant,
    /// The cancellation flag of its registered entry, once registered.
    entry: Option<Arc<AtomicBool>>,
}

impl ThreadSleep {
    fn new(deadline: tokio::time::Instant) -> Self {
        ThreadSleep { deadline: deadline.into_std(), entry: None }
    }
}

impl Drop for ThreadSleep {
    fn drop(&mut self) {
        if let Some(cancelled) = &self.entry {
            cancelled.store(true, Ordering::Relaxed);
        }
    }
}

impl Future for ThreadSleep {
    type Output = ();

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        if Instant::now() >= self.deadline {
            return Poll::Ready(());
        }
        if self.entry.is_none() {
            // One registration per sleep: a spurious poll before the deadline keeps waiting on
            // the same entry (its waker is the task's, which does not change under tokio).
            let cancelled = Arc::new(AtomicBool::new(false));
            self.entry = Some(Arc::clone(&cancelled));
            wheel().register(Entry { wake_at: self.deadline, waker: cx.waker().clone(), cancelled });
        }
        Poll::Pending
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 21 sleeps on one sleeper, near and far (past [`NEAR`]), spread across tokio's 1 ms
    /// ticks; how late each woke, sorted.
    async fn lateness(timer: Timer) -> Vec<Duration> {
        let mut sleeper = timer.sleeper();
        let mut late = Vec::new();
        for i in 0..21u64 {
            let deadline = tokio::time::Instant::now() + Duration::from_micros(1_500 + i * 237);
            sleeper.sleep_until(Some(deadline)).await;
            let now = tokio::time::Instant::now();
            assert!(now >= deadline, "woke early");
            late.push(now - deadline);
        }
        late.sort();
        late
    }

    // Lateness is a figure, measured by `ferrobus sim` (its counters) and the benchmarks and
    // printed here, not asserted: a shared CI machine can delay any thread. What is asserted
    // is the contract — never early — and, on tokio's paused clock, exact behaviour.

    #[tokio::test]
    async fn a_precise_sleep_is_never_early() {
        let late = lateness(Timer::Precise).await;
        eprintln!("precise timer: median lateness {:?}, max {:?}", late[10], late[20]);
    }

    #[tokio::test]
    async fn a_spinning_sleep_is_never_early() {
        let late = lateness(Timer::Spin).await;
        eprintln!("spinning timer: median lateness {:?}, max {:?}", late[10], late[20]);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_near_precise_or_spinning_sleep_gives_the_thread_back_instead_of_blocking_it() {
        // Polled once with its deadline [`NEAR`] ahead (no part of it on tokio's wheel), a sleep
        // that blocked the runtime's only thread would return ready, at its deadline; one that
        // waits on a kernel timer returns pending. A stall of the machine past the deadline
        // makes a trial ready too: one pending trial out of five is the proof.
        for timer in [Timer::Precise, Timer::Spin] {
            let mut readies = Vec::new();
            let pending = (0..5).any(|_| {
                let deadline = tokio::time::Instant::now() + NEAR;
                let mut sleep = std::pin::pin!(timer.sleep_until(Some(deadline)));
                let polled = sleep.as_mut().poll(&mut Context::from_waker(Waker::noop()));
                readies.push(tokio::time::Instant::now().saturating_duration_since(deadline));
                polled.is_pending()
            });
            assert!(pending, "{timer:?}: ready at every first poll, this long after the deadline: {readies:?}");
            // And two sleeps on the one thread both end, never early.
            let deadline = tokio::time::Instant::now() + Duration::from_millis(5);
            tokio::join!(timer.sleep_until(Some(deadline)), Timer::Precise.sleep_until(Some(deadline)));
            assert!(tokio::time::Instant::now() >= deadline, "{timer:?} woke early");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_sleep_cancelled_for_a_later_deadline_ends_exactly_at_an_earlier_one() {
        // The driver's pattern: a reply timeout armed on every pass, then a near deadline. The
        // far part of every timer is this entry on tokio's wheel, exact on the paused clock.
        let mut sleeper = Timer::Tokio.sleeper();
        let start = tokio::time::Instant::now();
        for pass in 1..=3u64 {
            let far = Some(start + Duration::from_secs(pass));
            let cancelled = tokio::time::timeout(Duration::from_millis(2), sleeper.sleep_until(far)).await;
            assert!(cancelled.is_err(), "a {pass} s sleep ended within 2 ms");
        }
        let near = start + Duration::from_millis(20);
        sleeper.sleep_until(Some(near)).await;
        assert_eq!(tokio::time::Instant::now(), near, "held back by a cancelled later deadline");
    }

    #[tokio::test]
    async fn smoke_a_precise_or_spinning_sleep_cancelled_for_later_deadlines_ends_at_an_earlier_one_in_real_time() {
        // The one real-time smoke test of the timers: the kernel's timers, which the paused
        // clock does not drive, under the driver's pattern. Held back, a sleep would end at a
        // far deadline an hour away; the bound, a minute, is one no loaded machine breaks.
        for timer in [Timer::Precise, Timer::Spin] {
            let mut sleeper = timer.sleeper();
            let start = tokio::time::Instant::now();
            for pass in 1..=3u32 {
                let far = Some(start + Duration::from_secs(3600) * pass);
                let cancelled = tokio::time::timeout(Duration::from_millis(2), sleeper.sleep_until(far)).await;
                assert!(cancelled.is_err(), "{timer:?}: a sleep of an hour ended within 2 ms");
            }
            let near = start + Duration::from_millis(20);
            let ended = tokio::time::timeout_at(start + Duration::from_secs(60), sleeper.sleep_until(Some(near))).await;
            let now = tokio::time::Instant::now();
            assert!(ended.is_ok(), "{timer:?} held back by a cancelled later deadline: {:?}", now - start);
            assert!(now >= near, "{timer:?} woke early");
            eprintln!("{timer:?}: 20 ms after three cancelled sleeps, {:?} late", now - near);
        }
    }

    #[tokio::test]
    async fn a_precise_sleep_cancelled_and_made_again_for_the_same_deadline_ends_at_it() {
        // The server's pattern: bytes arrive while a reply is due, and the sleep is made anew.
        // The clock is real: on a loaded machine a 1 ms timeout may itself outlast the deadline,
        // and then the sleep has ended, which is only wrong if it ended early ("never early" is
        // the property; lateness is not asserted).
        let mut sleeper = Timer::Precise.sleeper();
        let due = tokio::time::Instant::now() + Duration::from_millis(10);
        for _ in 0..3 {
            if tokio::time::timeout(Duration::from_millis(1), sleeper.sleep_until(Some(due))).await.is_ok() {
                assert!(tokio::time::Instant::now() >= due, "a remade sleep ended early");
            }
        }
        sleeper.sleep_until(Some(due)).await;
        assert!(tokio::time::Instant::now() >= due);
        // An expiry nobody waited for does not end the next, later sleep early.
        let first = tokio::time::Instant::now() + Duration::from_millis(5);
        if tokio::time::timeout(Duration::from_millis(1), sleeper.sleep_until(Some(first))).await.is_ok() {
            assert!(tokio::time::Instant::now() >= first, "a sleep ended early");
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
        let later = tokio::time::Instant::now() + Duration::from_millis(15);
        sleeper.sleep_until(Some(later)).await;
        assert!(tokio::time::Instant::now() >= later, "woke at the stale expiry");
    }

    #[tokio::test(start_paused = true)]
    async fn a_spinning_sleep_on_a_paused_clock_ends_instead_of_spinning_forever() {
        let start = tokio::time::Instant::now();
        Timer::Spin.sleeper().sleep_until(Some(start + Duration::from_millis(1))).await;
        assert!(tokio::time::Instant::now() >= start + Duration::from_millis(1));
    }

    #[tokio::test(start_paused = true)]
    async fn the_tokio_timer_follows_a_paused_clock() {
        let start = tokio::time::Instant::now();
        Timer::Tokio.sleep_until(Some(start + Duration::from_secs(3600))).await;
        assert_eq!(tokio::time::Instant::now() - start, Duration::from_secs(3600));
        // A sleeper too, whose entry was armed for a later deadline first.
        let mut sleeper = Timer::Tokio.sleeper();
        let start = tokio::time::Instant::now();
        let far = Some(start + Duration::from_secs(60));
        assert!(tokio::time::timeout(Duration::from_secs(1), sleeper.sleep_until(far)).await.is_err());
        sleeper.sleep_until(Some(start + Duration::from_secs(5))).await;
        assert_eq!(tokio::time::Instant::now() - start, Duration::from_secs(5));
    }
}
