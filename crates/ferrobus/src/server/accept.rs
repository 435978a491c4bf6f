//! The hardened accept loop every TCP front end shares (the Modbus/TCP server, its TLS
//! variant, the gateway's front, plain and TLS), its limits and its counters.
//!
//! ```text
//!   accept ─▶ source's share? ─▶ a slot? ─────────────▶ served on its own task
//!               │ (per source: connections,   │ (max_connections)
//!               │  handshakes in progress)    └─ none free: the connection least worth
//!               │                                keeping is closed to make room (room.rs)
//!               └── no: accepted and closed at once, counted, logged (a line a second at most)
//! ```
//!
//! What the limits are for, and whom the server closes to make room: see [`TcpLimits`].

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::net::{IpAddr, Ipv6Addr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use tokio::net::{TcpListener, TcpStream};

use self::room::{Activity, Evicted, Slot, Slots, Standing};
pub use self::room::{Tracked, Tracker};
use super::trim::Bursts;
use super::{Closed, ConnectionPolicy};
use crate::log::escape;

/// How long accepting pauses when the process (or system) is out of file descriptors (handles
/// on Windows) or socket buffers.
pub const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// The shortest time between two log lines about refused connections (the ones between
/// are counted, and the next line says how many): a flood of connections is not a flood of
/// log lines.
const REFUSALS_LOGGED_EVERY: Duration = Duration::from_secs(1);

/// Limits of a TCP server.
///
/// No one outsider can take every slot: a source (an IPv4 address; an IPv6 /64, what one
/// host is usually given) may hold at most [`max_per_source`](Self::max_per_source)
/// connections; a TLS server also limits how many of them may still be in their handshake
/// (`ServerTls::with_max_handshakes_per_source`, until the handshake is finished, refused or
/// timed out). A host that opens handshakes and never finishes them so holds a few slots,
/// each for the handshake timeout at most, and every other host keeps getting in.
///
/// The per-source limits alone do not keep the cap: many sources (11 addresses with 100
/// idle connections each, 70 with 16 unfinished handshakes) fill it. So when
/// [`max_connections`](Self::max_connections) are open, a new connection is served and the
/// connection least worth keeping is closed to make room: first one still in its TLS
/// handshake (the oldest first), then one never answered (the oldest first), then the one
/// idle longest; within each, one from the source holding the most connections first. A
/// client that polls keeps its session while anyone fills the cap with connections that do
/// nothing; each such close is logged and counted ([`TcpCounts::evicted_handshakes`],
/// [`TcpCounts::evicted_unanswered`], [`TcpCounts::evicted_idle`]).
#[derive(Clone, Debug)]
pub struct TcpLimits {
    /// Connections served at once, those still in their handshake included; past it a new
    /// connection is served and the one least worth keeping is closed to make room (see
    /// above), logged and counted. 0 refuses every connection.
    pub max_connections: usize,
    /// Connections served at once from one source (an IPv4 address, an IPv6 /64); past it
    /// a new one from there is accepted and closed at once, logged and counted.
    pub max_per_source: usize,
    /// When each connection is closed (idle, a frame unfinished) and how many requests it
    /// may have outstanding, unless its
    /// [`ServerOptions::connection`](super::ServerOptions::connection) is set.
    pub connection: ConnectionPolicy,
    /// After a burst of connections (see `server/trim.rs`), ask the allocator to give their
    /// freed memory back to the system (glibc's `malloc_trim`; elsewhere nothing). The
    /// application's decision, off by default: the `ferrobus` binary's servers turn it on.
    pub release_memory_after_bursts: bool,
    /// Counts what happened, shared with whoever reports it.
    pub stats: Arc<TcpStats>,
}

impl Default for TcpLimits {
    /// 1,000 connections (fits the common descriptor limit of 1,024), 100 from one source,
    /// [`ConnectionPolicy::TCP`] (60 s idle, 5 s for a frame), freed memory left to the
    /// allocator.
    fn default() -> Self {
        TcpLimits {
            max_connections: 1000,
            max_per_source: 100,
            connection: ConnectionPolicy::TCP,
            release_memory_after_bursts: false,
            stats: Arc::default(),
        }
    }
}

/// What a TCP server has seen, counted as it runs.
#[derive(Debug, Default)]
pub struct TcpStats {
    accepted: AtomicU64,
    open: AtomicU64,
    sources: AtomicU64,
    refused: AtomicU64,
    refused_source: AtomicU64,
    refused_handshakes: AtomicU64,
    descriptor_waits: AtomicU64,
    accept_errors: AtomicU64,
    socket_errors: AtomicU64,
    closed_idle: AtomicU64,
    closed_unfinished: AtomicU64,
    closed_bad_header: AtomicU64,
    tls_refused: AtomicU64,
    evicted_handshakes: AtomicU64,
    evicted_unanswered: AtomicU64,
    evicted_idle: AtomicU64,
    denied: Arc<AtomicU64>,
}

/// A snapshot of [`TcpStats`].
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[non_exhaustive]
pub struct TcpCounts {
    /// Connections accepted and served.
    pub accepted: u64,
    /// Connections open now.
    pub open: u64,
    /// Sources (IPv4 addresses, IPv6 /64s) with a connection open now.
    pub sources: u64,
    /// Connections closed at once because [`TcpLimits::max_connections`] were open (only
    /// when it is 0: otherwise a connection is closed to make room).
    pub refused: u64,
    /// Connections closed at once because [`TcpLimits::max_per_source`] were open from
    /// their source.
    pub refused_source: u64,
    /// TLS connections closed at once because as many from their source as the server's
    /// TLS setup allows were still in their handshake.
    pub refused_handshakes: u64,
    /// Times accepting paused because no socket could be made: descriptors or handles ran
    /// out, or the kernel's buffers for sockets (EMFILE, ENFILE, ENOBUFS, ENOMEM on Unix;
    /// WSAEMFILE, ERROR_TOO_MANY_OPEN_FILES, WSAENOBUFS on Windows).
    pub descriptor_waits: u64,
    /// Other accept errors.
    pub accept_errors: u64,
    /// Errors setting a socket option on an accepted connection (it is served anyway).
    pub socket_errors: u64,
    /// Connections closed for being idle.
    pub closed_idle: u64,
    /// Connections closed for a frame begun and never finished.
    pub closed_unfinished: u64,
    /// Connections closed for a bad MBAP header.
    pub closed_bad_header: u64,
    /// TLS connections whose handshake was refused (no client certificate, an untrusted
    /// one, a role refused, a timeout).
    pub tls_refused: u64,
    /// Requests denied by the roles' rights (answered with exception 01).
    pub denied: u64,
    /// Connections still in their TLS handshake closed to make room for a new one.
    pub evicted_handshakes: u64,
    /// Connections never answered closed to make room for a new one.
    pub evicted_unanswered: u64,
    /// Connections answered before, the one idle longest, closed to make room for a new one.
    pub evicted_idle: u64,
}

impl TcpStats {
    /// The counts now.
    pub fn counts(&self) -> TcpCounts {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        TcpCounts {
            accepted: get(&self.accepted),
            open: get(&self.open),
            sources: get(&self.sources),
            refused: get(&self.refused),
            refused_source: get(&self.refused_source),
            refused_handshakes: get(&self.refused_handshakes),
            descriptor_waits: get(&self.descriptor_waits),
            accept_errors: get(&self.accept_errors),
            socket_errors: get(&self.socket_errors),
            closed_idle: get(&self.closed_idle),
            closed_unfinished: get(&self.closed_unfinished),
            closed_bad_header: get(&self.closed_bad_header),
            tls_refused: get(&self.tls_refused),
            denied: get(&self.denied),
            evicted_handshakes: get(&self.evicted_handshakes),
            evicted_unanswered: get(&self.evicted_unanswered),
            evicted_idle: get(&self.evicted_idle),
        }
    }
}

#[cfg(feature = "tls")]
impl TcpStats {
    /// Counts a refused TLS handshake.
    pub(crate) fn note_tls_refused(&self) {
        bump(&self.tls_refused);
    }

    /// The counter of requests denied by the roles' rights, to share with the checks.
    pub(crate) fn denied_counter(&self) -> Arc<AtomicU64> {
        Arc::clone(&self.denied)
    }
}

fn bump(counter: &AtomicU64) {
    counter.fetch_add(1, Ordering::Relaxed);
}

impl Evicted {
    fn count(&self, stats: &TcpStats) {
        bump(match self.standing {
            Standing::Handshaking => &stats.evicted_handshakes,
            Standing::Unanswered => &stats.evicted_unanswered,
            Standing::Idle => &stats.evicted_idle,
        });
    }
}

/// Where connections come from, as the per-source limits count them: an IPv4 address (an
/// IPv4-mapped IPv6 one too), or the /64 prefix of an IPv6 address.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
struct Source(IpAddr);

impl Source {
    fn of(peer: SocketAddr) -> Source {
        match peer.ip() {
            IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
                Some(v4) => Source(IpAddr::V4(v4)),
                None => Source(IpAddr::V6(Ipv6Addr::from(u128::from(v6) & !u128::from(u64::MAX)))),
            },
            IpAddr::V4(v4) => Source(IpAddr::V4(v4)),
        }
    }
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            IpAddr::V4(v4) => write!(f, "{v4}"),
            IpAddr::V6(v6) => write!(f, "{v6}/64"),
        }
    }
}

/// What one source holds now.
#[derive(Clone, Copy, Default, Debug)]
struct Load {
    open: usize,
    handshaking: usize,
}

/// Why a connection was closed at once.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Refusal {
    /// [`TcpLimits::max_connections`] are open.
    Full(usize),
    /// [`TcpLimits::max_per_source`] are open from its source.
    Source(Source, usize),
    /// The most handshakes allowed from its source are in progress.
    Handshakes(Source, usize),
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::Full(n) => write!(f, "{n} connections open, the most allowed"),
            Refusal::Source(source, n) => {
                write!(f, "{n} connections open from {source}, the most allowed from one source")
            }
            Refusal::Handshakes(source, n) => {
                write!(f, "{n} handshakes in progress from {source}, the most allowed from one source")
            }
        }
    }
}

impl Refusal {
    fn count(self, stats: &TcpStats) {
        bump(match self {
            Refusal::Full(_) => &stats.refused,
            Refusal::Source(..) => &stats.refused_source,
            Refusal::Handshakes(..) => &stats.refused_handshakes,
        });
    }
}

/// The load of every source with a connection open; a source's entry goes with its last
/// connection.
#[derive(Debug)]
struct Sources {
    loads: Mutex<HashMap<Source, Load>>,
    stats: Arc<TcpStats>,
}

impl Sources {
    fn new(stats: Arc<TcpStats>) -> Arc<Sources> {
        Arc::new(Sources { loads: Mutex::default(), stats })
    }

    /// Admits a connection from `source` within `limits` and `handshakes` (the most in
    /// progress from one source), in its handshake.
    fn admit(
        self: &Arc<Self>,
        source: Source,
        limits: &TcpLimits,
        handshakes: usize,
        activity: &Arc<Activity>,
    ) -> Result<(Share, Handshake), Refusal> {
        let mut loads = self.loads.lock().unwrap_or_else(PoisonError::into_inner);
        let load = loads.entry(source).or_default();
        if load.open >= limits.max_per_source {
            let refusal = Refusal::Source(source, limits.max_per_source);
            self.forget_if_unused(&mut loads, source);
            return Err(refusal);
        }
        if load.handshaking >= handshakes {
            let refusal = Refusal::Handshakes(source, handshakes);
            self.forget_if_unused(&mut loads, source);
            return Err(refusal);
        }
        load.open = load.open.saturating_add(1);
        load.handshaking = load.handshaking.saturating_add(1);
        self.note_len(&loads);
        let share = Share { sources: Arc::clone(self), source };
        Ok((share, Handshake { sources: Arc::clone(self), source, activity: Arc::clone(activity) }))
    }

    /// Takes one off `source`'s load (`open` or `handshaking`, as `take` picks).
    fn release(&self, source: Source, take: fn(&mut Load) -> &mut usize) {
        let mut loads = self.loads.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(load) = loads.get_mut(&source) {
            let n = take(load);
            *n = n.saturating_sub(1);
        }
        self.forget_if_unused(&mut loads, source);
    }

    /// Removes `source`'s entry if it holds nothing.
    fn forget_if_unused(&self, loads: &mut HashMap<Source, Load>, source: Source) {
        if loads.get(&source).is_some_and(|load| load.open == 0 && load.handshaking == 0) {
            loads.remove(&source);
        }
        self.note_len(loads);
    }

    fn note_len(&self, loads: &HashMap<Source, Load>) {
        self.stats.sources.store(u64::try_from(loads.len()).unwrap_or(u64::MAX), Ordering::Relaxed);
    }
}

/// A connection's share of its source's load, given back when it is dropped.
#[derive(Debug)]
struct Share {
    sources: Arc<Sources>,
    source: Source,
}

impl Drop for Share {
    fn drop(&mut self) {
        self.sources.release(self.source, |load| &mut load.open);
    }
}

/// A connection's handshake in progress: counted against its source's handshakes until
/// dropped (when the handshake is over, whatever its outcome).
#[derive(Debug)]
pub struct Handshake {
    sources: Arc<Sources>,
    source: Source,
    activity: Arc<Activity>,
}

impl Handshake {
    /// What notes the use of the connection's stream once its handshake is over (whom to
    /// close to make room is chosen by it).
    pub fn tracker(&self) -> Tracker {
        Tracker(Arc::clone(&self.activity))
    }
}

impl Drop for Handshake {
    fn drop(&mut self) {
        self.activity.handshake_over();
        self.sources.release(self.source, |load| &mut load.handshaking);
    }
}

/// An accepted connection's place: its slot, its source's share, and the count of open
/// connections, all given back when it is dropped (however its task ends).
struct Place {
    slot: Slot,
    _share: Share,
    stats: Arc<TcpStats>,
    bursts: Option<Arc<Bursts>>,
}

impl Place {
    fn new(slot: Slot, share: Share, stats: &Arc<TcpStats>, bursts: Option<&Arc<Bursts>>) -> Place {
        let open = stats.open.fetch_add(1, Ordering::Relaxed).saturating_add(1);
        if let Some(bursts) = bursts {
            bursts.opened(usize::try_from(open).unwrap_or(usize::MAX));
        }
        Place { slot, _share: share, stats: Arc::clone(stats), bursts: bursts.map(Arc::clone) }
    }
}

impl Drop for Place {
    /// Gives the place back, and after a burst of connections their freed memory if
    /// [`TcpLimits::release_memory_after_bursts`].
    fn drop(&mut self) {
        let open = self.stats.open.fetch_sub(1, Ordering::Relaxed).saturating_sub(1);
        if let Some(bursts) = &self.bursts {
            bursts.closed(usize::try_from(open).unwrap_or(usize::MAX));
        }
    }
}

/// Log lines about refused connections, one per [`REFUSALS_LOGGED_EVERY`] at most.
#[derive(Default)]
struct Throttle {
    next: Option<tokio::time::Instant>,
    unlogged: u64,
}

impl Throttle {
    /// Whether to log a refusal now, and how many went unlogged since the last line.
    fn pass(&mut self) -> Option<u64> {
        let now = tokio::time::Instant::now();
        if self.next.is_some_and(|next| now < next) {
            self.unlogged = self.unlogged.saturating_add(1);
            return None;
        }
        self.next = now.checked_add(REFUSALS_LOGGED_EVERY);
        Some(std::mem::take(&mut self.unlogged))
    }
}

/// The accept loop for front ends without a handshake: as [`accept_handshaking`], the
/// handshake over as soon as the connection is accepted, its stream [`Tracked`].
pub async fn accept_connections<S, Fut>(listener: TcpListener, limits: &TcpLimits, serve: S) -> io::Result<()>
where
    S: Fn(Tracked<TcpStream>, SocketAddr) -> Fut,
    Fut: Future<Output = io::Result<()>> + Send + 'static,
{
    accept_handshaking(listener, limits, usize::MAX, |stream, peer, handshake| {
        let stream = handshake.tracker().track(stream);
        drop(handshake);
        serve(stream, peer)
    })
    .await
}

/// The hardened accept loop: accepts on `listener` within `limits` (past
/// [`TcpLimits::max_per_source`] from its source or past `handshakes` from its source in
/// their handshake, a connection is accepted and closed at once; past
/// [`TcpLimits::max_connections`] the connection least worth keeping is closed to make room
/// (its task aborted; see [`TcpLimits`]); out of sockets (descriptors, handles, socket buffers), accepting pauses for
/// [`ACCEPT_BACKOFF`]; TCP_NODELAY set) and runs `serve` for each connection on its own
/// task, counting how it ended in [`TcpLimits::stats`] (a [`Closed`] error is the server's
/// own close). `serve` is given the connection's [`Handshake`], to drop when its handshake
/// is over, and whose [`Handshake::tracker`] should wrap the stream served after it (or the
/// connection is never seen answered). No error of a connection or of accepting one ends it: it runs until dropped.
pub async fn accept_handshaking<S, Fut>(
    listener: TcpListener,
    limits: &TcpLimits,
    handshakes: usize,
    serve: S,
) -> io::Result<()>
where
    S: Fn(TcpStream, SocketAddr, Handshake) -> Fut,
    Fut: Future<Output = io::Result<()>> + Send + 'static,
{
    let slots = Slots::new(limits.max_connections);
    let stats = Arc::clone(&limits.stats);
    let sources = Sources::new(Arc::clone(&stats));
    let bursts = limits.release_memory_after_bursts.then(|| Arc::new(Bursts::default()));
    let (mut refusals, mut evictions) = (Throttle::default(), Throttle::default());
    loop {
        let Some((stream, peer)) = accept(&listener, &stats).await else { continue };
        let (source, activity) = (Source::of(peer), Activity::new());
        let admitted = sources.admit(source, limits, handshakes, &activity).and_then(|(share, handshake)| {
            let (slot, evicted) = slots.take(peer, source, &activity).ok_or(Refusal::Full(limits.max_connections))?;
            Ok((Place::new(slot, share, &stats, bursts.as_ref()), handshake, evicted))
        });
        let (place, handshake, evicted) = match admitted {
            Ok(admitted) => admitted,
            Err(refusal) => {
                refusal.count(&stats);
                if let Some(unlogged) = refusals.pass() {
                    let more = if unlogged > 0 {
                        format!(" ({unlogged} more refused since the last such line)")
                    } else {
                        String::new()
                    };
                    tracing::warn!(%peer, "refused: {refusal}{more}");
                }
                drop(stream);
                continue;
            }
        };
        if let Some(evicted) = evicted {
            evicted.count(&stats);
            if let Some(unlogged) = evictions.pass() {
                let more = if unlogged > 0 {
                    format!(" ({unlogged} more closed to make room since the last such line)")
                } else {
                    String::new()
                };
                let Evicted { peer: closed, source, held, standing } = evicted;
                let (closed, source) = (closed.to_string(), source.to_string());
                tracing::warn!(
                    %peer,
                    "{} connections open, the most allowed: closed the connection from {} ({standing}; {} held {held}) \
                     to make room{more}",
                    limits.max_connections,
                    escape(&closed),
                    escape(&source)
                );
            }
        }
        if let Err(e) = stream.set_nodelay(true) {
            bump(&stats.socket_errors);
            tracing::warn!(%peer, "setting TCP_NODELAY: {e}; serving the connection anyway");
        }
        bump(&stats.accepted);
        tracing::debug!(%peer, "connection accepted");
        // Pinned on the heap before it is spawned: awaited inside the task's future, a future
        // captured by value would be stored in it twice (as the capture and as the awaited).
        let served = Box::pin(serve(stream, peer, handshake));
        let id = place.slot.id;
        let task = tokio::spawn(async move {
            let ended = served.await;
            report(peer, ended, &place.stats);
            drop(place);
        });
        slots.spawned(id, task.abort_handle());
    }
}

/// The next connection, or `None` after an accept error (counted, logged, and waited out).
async fn accept(listener: &TcpListener, stats: &TcpStats) -> Option<(TcpStream, SocketAddr)> {
    match listener.accept().await {
        Ok(accepted) => Some(accepted),
        Err(e) => {
            wait_out(&e, stats).await;
            None
        }
    }
}

/// Counts, logs and waits out an accept error: [`ACCEPT_BACKOFF`] when no socket can be made
/// now (the platform says which errors mean that), a short pause for any other.
async fn wait_out(e: &io::Error, stats: &TcpStats) {
    if crate::sys::out_of_sockets(e) {
        bump(&stats.descriptor_waits);
        let open = stats.open.load(Ordering::Relaxed);
        tracing::warn!("accepting: {e}; pausing {ACCEPT_BACKOFF:?}, still serving the {open} open connections");
        tokio::time::sleep(ACCEPT_BACKOFF).await;
    } else {
        bump(&stats.accept_errors);
        tracing::warn!("accepting: {e}; going on");
        // Not a spin if the error repeats.
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Counts and logs how the connection from `peer` ended.
fn report(peer: SocketAddr, ended: io::Result<()>, stats: &TcpStats) {
    let e = match ended {
        Ok(()) => return tracing::debug!(%peer, "connection closed"),
        Err(e) => e,
    };
    // A front end's error may quote what the peer sent: escaped.
    let Some(closed) = super::close_reason(&e) else {
        return tracing::debug!(%peer, "connection failed: {}", escape(&e.to_string()));
    };
    bump(match closed {
        Closed::Idle(_) => &stats.closed_idle,
        Closed::UnfinishedFrame(_) => &stats.closed_unfinished,
        Closed::BadHeader => &stats.closed_bad_header,
    });
    tracing::info!(%peer, "{e}");
}

mod room;
#[cfg(test)]
mod tests;
