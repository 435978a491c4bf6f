//! The gateway's back end (the [`front`](super::front) is the clients' side): one serial line
//! behind the gateway, its bounded queue, served round-robin per client connection, and the
//! worker that is the line's one master. (The virtual RS-485 line is [`ferrobus::line`].)
//!
//! The worker takes one request at a time (on a pipelined Modbus/TCP line, up to
//! [`Worker::in_flight`] at once) and hands it to the line's [`Client`], which keeps
//! t3.5 before every frame, waits the reply timeout, retries, skips a unit in backoff and
//! waits the turnaround after a broadcast. A reply is matched to its request by the client's
//! master engine (unit, function code, and for a parsed request its length and echo), and the
//! worker starts the next request only once the last has ended.
//!
//! Late replies (RTU has no transaction id): after a request timed out, the client's master
//! engine owes it its reply and keeps the line closed — for a retry and for the next job
//! alike — until that reply has come and been dropped, or the late window (twice the reply
//! timeout, [`ferrobus::ClientConfig::late_window`]) has passed; so a same-shape next request
//! cannot take it. On top, after any request that got no usable reply, the worker keeps the
//! line quiet for the late-reply guard ([`super::GatewayLine::late_guard`]), for what else a
//! confused device may still send. The replies dropped are counted in [`LineTraffic`]
//! (`late_replies`, and `early_replies` for stale ones already on their way when a request
//! left).

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use ferrobus_proto::master::HeardInstead;
use ferrobus_proto::pdu::Request;
use ferrobus_proto::retry::io_backoff_wait;
use ferrobus_proto::{ExceptionCode, FunctionCode};
use futures_util::StreamExt;
use futures_util::stream::FuturesUnordered;
use tokio::sync::{Notify, oneshot};

use super::cache::Cache;
use super::stats::{Ended, LineTraffic};
use ferrobus::{Client, Error};

/// A request waiting for the line.
pub(crate) struct Job {
    /// The unit as the client addressed it (for the counters).
    pub(crate) unit_in: u8,
    /// The unit on the line.
    pub(crate) unit_out: u8,
    /// The request PDU, function code first.
    pub(crate) pdu: Vec<u8>,
    /// Where the reply PDU goes (`None`: a broadcast, no reply).
    pub(crate) reply: oneshot::Sender<Option<Vec<u8>>>,
    /// A serial line's broadcast (unit 0 there): it goes out even with nobody waiting.
    pub(crate) broadcast: bool,
}

/// The queue's state: a FIFO per connection and the order in which connections take turns.
struct Queues {
    per_connection: HashMap<u64, VecDeque<Job>>,
    /// Connections with waiting requests, in turn order.
    turns: VecDeque<u64>,
    len: usize,
    capacity: usize,
    closed: bool,
}

/// The bounded queue of one line.
pub(crate) struct LineQueue {
    queues: Mutex<Queues>,
    ready: Notify,
    stats: Arc<Mutex<LineTraffic>>,
}

/// Why a request was not queued.
#[derive(Debug)]
pub(crate) enum Full {
    /// The queue holds its capacity: answer 0x06.
    Busy,
}

impl LineQueue {
    pub(crate) fn new(capacity: usize, stats: Arc<Mutex<LineTraffic>>) -> Self {
        LineQueue {
            queues: Mutex::new(Queues {
                per_connection: HashMap::new(),
                turns: VecDeque::new(),
                len: 0,
                capacity: capacity.max(1),
                closed: false,
            }),
            ready: Notify::new(),
            stats,
        }
    }

    fn lock(&self) -> MutexGuard<'_, Queues> {
        self.queues.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub(crate) fn stats(&self) -> MutexGuard<'_, LineTraffic> {
        self.stats.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Queues `job` for `connection`, or refuses it at once when the queue is full.
    pub(crate) fn submit(&self, connection: u64, job: Job) -> Result<(), Full> {
        let depth = {
            let mut q = self.lock();
            if q.len >= q.capacity {
                drop(q);
                let mut stats = self.stats();
                stats.total.busy = stats.total.busy.saturating_add(1);
                let unit = stats.units.entry(job.unit_in).or_default();
                unit.busy = unit.busy.saturating_add(1);
                return Err(Full::Busy);
            }
            let fifo = q.per_connection.entry(connection).or_default();
            let first = fifo.is_empty();
            fifo.push_back(job);
            if first {
                q.turns.push_back(connection);
            }
            q.len = q.len.saturating_add(1);
            q.len
        };
        let mut stats = self.stats();
        stats.queue_depth = depth;
        stats.queue_max = stats.queue_max.max(depth);
        drop(stats);
        self.ready.notify_one();
        Ok(())
    }

    /// The next job, taking connections in turn: one request of each connection that has one.
    fn take(&self) -> Option<Job> {
        let mut q = self.lock();
        let connection = q.turns.pop_front()?;
        let fifo = q.per_connection.get_mut(&connection)?;
        let job = fifo.pop_front();
        if fifo.is_empty() {
            q.per_connection.remove(&connection);
        } else {
            q.turns.push_back(connection);
        }
        if job.is_some() {
            q.len = q.len.saturating_sub(1);
        }
        let depth = q.len;
        drop(q);
        self.stats().queue_depth = depth;
        job
    }

    /// Waits for the next job; `None` once the queue is closed.
    async fn next(&self) -> Option<Job> {
        loop {
            let notified = self.ready.notified();
            if let Some(job) = self.take() {
                return Some(job);
            }
            if self.lock().closed {
                return None;
            }
            notified.await;
        }
    }

    /// Stops the worker once the jobs queued are done.
    pub(crate) fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_one();
    }
}

/// A line found down (its port failed, its device unreachable or gone): until when the
/// requests that come are answered 0x0A at once, and how many times in a row it was found so.
#[derive(Clone, Copy, Debug)]
struct Down {
    retry_at: tokio::time::Instant,
    times: u32,
}

impl Down {
    /// The line found down at `now`, after `before`: held for the driver's own reconnect
    /// backoff (10 ms, doubling with each time in a row, at most 500 ms), after which the
    /// next request tries the line again.
    fn after(before: Option<Down>, now: tokio::time::Instant) -> Down {
        let times = before.map_or(1, |d| d.times.saturating_add(1));
        Down { retry_at: now + io_backoff_wait(times), times }
    }
}

/// What the worker does with the requests it takes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Worker {
    /// How many requests may be on the line at once: 1 but on a pipelined Modbus/TCP line
    /// ([`ferrobus::ClientConfig::in_flight`]).
    pub(crate) in_flight: usize,
    /// How long the line stays quiet after a request that got no usable reply (none on a
    /// Modbus/TCP line).
    pub(crate) late_guard: Duration,
}

/// A request the worker has handed to the line, with how it ended.
struct Flown {
    job: Job,
    reply: Option<Vec<u8>>,
    ended: Ended,
    took: Duration,
}

/// The line's one master: takes jobs in turn and forwards each through `client`, keeping up
/// to [`Worker::in_flight`] on the line at once once it has answered (one on a serial line:
/// the next request goes only once the last has ended). While the line is down, the requests
/// that come are answered 0x0A at once instead of each waiting out a reconnect (a device that
/// is unreachable costs a whole connect timeout per attempt): one request tries the line again
/// when the hold has passed, alone.
pub(crate) async fn run(queue: Arc<LineQueue>, client: Client, cache: Option<Arc<Cache>>, worker: Worker) {
    let mut down: Option<Down> = None;
    // Whether the line answered since it started or was last found down: until then one
    // request at a time finds out (a connect that fails is tried once, not once per request in
    // flight).
    let mut up = false;
    let mut flying = FuturesUnordered::new();
    // After a request without a usable reply: the line is quiet until then.
    let mut quiet: Option<tokio::time::Instant> = None;
    let mut closed = false;
    loop {
        let in_flight = if up { worker.in_flight.max(1) } else { 1 };
        let room = !closed && quiet.is_none() && flying.len() < in_flight;
        tokio::select! {
            job = queue.next(), if room => match job {
                None => closed = true,
                Some(job) => {
                    if let Some(job) = take(&queue, job, down) {
                        flying.push(fly(&client, job));
                    }
                }
            },
            Some(flown) = flying.next(), if !flying.is_empty() => {
                let ended = flown.ended;
                land(&queue, &client, cache.as_deref(), flown);
                let now = tokio::time::Instant::now();
                down = match down {
                    // The other requests in flight when the line went down end the same way:
                    // one loss, held once.
                    Some(d) if ended == Ended::LineDown && now < d.retry_at => Some(d),
                    _ => (ended == Ended::LineDown).then(|| Down::after(down, now)),
                };
                up = ended != Ended::LineDown;
                if matches!(ended, Ended::Timeout | Ended::BadCrc | Ended::BadReply) && !worker.late_guard.is_zero() {
                    // The engine keeps the line closed for a reply owed to a timed-out
                    // request; what else a device confused by this one may send meanwhile is
                    // awaited by nobody and dropped.
                    quiet = Some(now + worker.late_guard);
                }
            },
            () = tokio::time::sleep_until(quiet.unwrap_or_else(tokio::time::Instant::now)), if quiet.is_some() => {
                quiet = None;
            },
        }
        if closed && flying.is_empty() {
            return;
        }
    }
}

/// A job taken from the queue: `None` if it needs the line no more — its client has gone,
/// or it was answered 0x0A at once because the line is held down.
fn take(queue: &LineQueue, job: Job, down: Option<Down>) -> Option<Job> {
    // A broadcast goes out even with nobody waiting for its end (no acknowledgement).
    if job.reply.is_closed() && !job.broadcast {
        let mut stats = queue.stats();
        stats.total.abandoned = stats.total.abandoned.saturating_add(1);
        return None;
    }
    if down.is_some_and(|d| tokio::time::Instant::now() < d.retry_at) {
        let function = job.pdu.first().copied().unwrap_or_default();
        let reply = Some(exception(function, ExceptionCode::GatewayPathUnavailable.value()));
        let mut stats = queue.stats();
        stats.total.count(Ended::LineDown, Duration::ZERO);
        stats.units.entry(job.unit_in).or_default().count(Ended::LineDown, Duration::ZERO);
        drop(stats);
        tracing::debug!(unit = job.unit_in, line_unit = job.unit_out, "the line is down: 0x0A at once");
        let _ = job.reply.send(reply);
        return None;
    }
    Some(job)
}

/// Forwards `job` through `client`, timed.
async fn fly(client: &Client, job: Job) -> Flown {
    let started = tokio::time::Instant::now();
    let (reply, ended) = forward(client, job.unit_out, &job.pdu).await;
    Flown { job, reply, ended, took: started.elapsed() }
}

/// Counts how a request ended, keeps a reply in the cache and sends it to its client.
fn land(queue: &LineQueue, client: &Client, cache: Option<&Cache>, flown: Flown) {
    let Flown { job, reply, ended, took } = flown;
    {
        let mut stats = queue.stats();
        stats.total.count(ended, took);
        stats.units.entry(job.unit_in).or_default().count(ended, took);
        stats.dropped(&client.stats());
    }
    if let (Some(cache), Some(reply), Ended::Replied) = (cache, &reply, ended) {
        cache.update(job.unit_in, &job.pdu, reply);
    }
    tracing::debug!(unit = job.unit_in, line_unit = job.unit_out, ?ended, "after {took:?}");
    // The client may have gone meanwhile: nothing to answer.
    let _ = job.reply.send(reply);
}

/// Forwards one request; the reply PDU for the client (`None` for a broadcast) and how it
/// ended.
async fn forward(client: &Client, unit: u8, pdu: &[u8]) -> (Option<Vec<u8>>, Ended) {
    // A request the core can parse is checked against its reply in full (length, echo);
    // any other (a vendor's function code, a malformed request the device is to judge) is
    // matched by unit and function code.
    let result = match Request::parse(pdu) {
        Ok(request) => client.request(unit, &request).await,
        Err(_) => client.raw(unit, pdu).await,
    };
    let function = pdu.first().copied().unwrap_or_default();
    match result {
        Ok(Some(reply)) => (Some(reply), Ended::Replied),
        Ok(None) => (None, Ended::Broadcast),
        Err(error) => {
            let (code, ended) = failure(&error);
            let code = code.value();
            let ended = if ended == Ended::Replied { Ended::Exception(code) } else { ended };
            (Some(exception(function, code)), ended)
        }
    }
}

/// The exception code a failure is answered with, and how it is counted (`Replied` stands
/// for the device's own exception).
pub(super) fn failure(error: &Error) -> (ExceptionCode, Ended) {
    const TARGET: ExceptionCode = ExceptionCode::GatewayTargetDeviceFailedToRespond;
    match error {
        Error::Exception { code, .. } => (*code, Ended::Replied),
        Error::Timeout { heard: Some(HeardInstead::BadChecksum { .. }), .. } => (TARGET, Ended::BadCrc),
        Error::Timeout { .. } | Error::NoReply { .. } => (TARGET, Ended::Timeout),
        Error::BadReply { .. } => (TARGET, Ended::BadReply),
        Error::Backoff { .. } => (TARGET, Ended::Skipped),
        Error::InvalidRequest(_) | Error::BroadcastRead { .. } => (ExceptionCode::IllegalDataValue, Ended::Replied),
        _ => (ExceptionCode::GatewayPathUnavailable, Ended::LineDown),
    }
}

/// The exception PDU for `function` with `code`.
pub(crate) fn exception(function: u8, code: u8) -> Vec<u8> {
    vec![function | FunctionCode::EXCEPTION_BIT, code]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(unit: u8) -> (Job, oneshot::Receiver<Option<Vec<u8>>>) {
        let (reply, rx) = oneshot::channel();
        (Job { unit_in: unit, unit_out: unit, pdu: vec![3, 0, 0, 0, 1], reply, broadcast: false }, rx)
    }

    fn queue(capacity: usize) -> LineQueue {
        LineQueue::new(capacity, Arc::default())
    }

    #[test]
    fn connections_take_turns_so_one_with_many_requests_cannot_starve_another() {
        let q = queue(10);
        let mut keep = Vec::new();
        for unit in [1, 2, 3] {
            let (j, rx) = job(unit);
            keep.push(rx);
            q.submit(7, j).unwrap();
        }
        let (j, rx) = job(9);
        keep.push(rx);
        q.submit(8, j).unwrap();
        let order: Vec<u8> = std::iter::from_fn(|| q.take()).map(|j| j.unit_in).collect();
        assert_eq!(order, [1, 9, 2, 3]);
    }

    #[test]
    fn a_full_queue_refuses_at_once_and_counts_it_busy() {
        let q = queue(2);
        let mut keep = Vec::new();
        for _ in 0..2 {
            let (j, rx) = job(1);
            keep.push(rx);
            q.submit(1, j).unwrap();
        }
        let (j, _rx) = job(4);
        assert!(matches!(q.submit(2, j), Err(Full::Busy)));
        let stats = q.stats();
        assert_eq!((stats.total.busy, stats.units[&4].busy, stats.queue_depth, stats.queue_max), (1, 1, 2, 2));
    }

    #[test]
    fn a_line_found_down_is_held_10_ms_doubling_to_500_ms_from_when_it_was_last_tried() {
        let now = tokio::time::Instant::now();
        let mut down = None;
        let mut holds = Vec::new();
        for _ in 0..8 {
            let d = Down::after(down, now);
            holds.push(d.retry_at.duration_since(now).as_millis());
            down = Some(d);
        }
        assert_eq!(holds, [10, 20, 40, 80, 160, 320, 500, 500]);
    }

    #[test]
    fn failures_map_to_the_gateway_exceptions_and_are_counted_apart() {
        let timeout = |heard| Error::Timeout { unit: 1, timeout: Duration::from_millis(5), attempts: 2, heard };
        let crc = HeardInstead::BadChecksum { head: Some((1, 3)), expected: (1, 3) };
        let target = ExceptionCode::GatewayTargetDeviceFailedToRespond;
        assert_eq!(failure(&timeout(None)), (target, Ended::Timeout));
        assert_eq!(failure(&timeout(Some(crc))), (target, Ended::BadCrc));
        assert_eq!(failure(&Error::Backoff { unit: 1, retry_in: Duration::from_secs(1) }), (target, Ended::Skipped));
        assert_eq!(
            failure(&Error::io("reading", std::io::Error::other("gone"))),
            (ExceptionCode::GatewayPathUnavailable, Ended::LineDown)
        );
        assert_eq!(exception(0x03, 0x0B), [0x83, 0x0B]);
    }
}
