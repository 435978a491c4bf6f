//! Making room when every slot is taken: the connection least worth keeping is closed, so
//! that a new client always gets in while [`TcpLimits::max_connections`](super::TcpLimits)
//! holds.
//!
//! Which one, in this order:
//!
//! 1. one still in its TLS handshake, the oldest first;
//! 2. one that has never been answered (no reply ever went out on it: it has never sent a
//!    complete request, or its first one is still being served), the oldest first;
//! 3. the one idle longest (nothing read or written).
//!
//! Within each, a connection of the source (an IPv4 address, an IPv6 /64) holding the most
//! connections goes first: many sources that each hold many connections are emptied before a
//! source holding one loses it, so an operator's single session outlives a flood from many
//! addresses unless every flooding address holds as few as it does.

use std::collections::HashMap;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::task::AbortHandle;
use tokio::time::Instant;

use super::Source;
use crate::port::Port;

/// What the accept loop knows of one connection's use, to choose whom to close when full.
#[derive(Debug)]
pub(super) struct Activity {
    opened: Instant,
    handshaking: AtomicBool,
    answered: AtomicBool,
    /// Microseconds from `opened` to the last byte read or written.
    last: AtomicU64,
}

impl Activity {
    pub(super) fn new() -> Arc<Activity> {
        Arc::new(Activity {
            opened: Instant::now(),
            handshaking: AtomicBool::new(true),
            answered: AtomicBool::new(false),
            last: AtomicU64::new(0),
        })
    }

    pub(super) fn handshake_over(&self) {
        self.handshaking.store(false, Ordering::Relaxed);
    }

    fn touch(&self) {
        let since = u64::try_from(self.opened.elapsed().as_micros()).unwrap_or(u64::MAX);
        self.last.fetch_max(since, Ordering::Relaxed);
    }

    fn last(&self) -> Instant {
        let since = std::time::Duration::from_micros(self.last.load(Ordering::Relaxed));
        self.opened.checked_add(since).unwrap_or(self.opened)
    }

    fn standing(&self) -> Standing {
        if self.handshaking.load(Ordering::Relaxed) {
            Standing::Handshaking
        } else if !self.answered.load(Ordering::Relaxed) {
            Standing::Unanswered
        } else {
            Standing::Idle
        }
    }
}

/// Wraps a connection's stream (after its handshake) to note when it is used.
#[derive(Clone, Debug)]
pub struct Tracker(pub(super) Arc<Activity>);

impl Tracker {
    /// `stream`, its reads and writes noted.
    pub fn track<S>(self, stream: S) -> Tracked<S> {
        Tracked { inner: stream, activity: self.0 }
    }
}

/// A connection's stream whose reads and writes are noted for the choice of whom to close
/// when every slot is taken: a write is a reply, so a connection written to has been
/// answered.
#[derive(Debug)]
pub struct Tracked<S> {
    inner: S,
    activity: Arc<Activity>,
}

impl<S: AsyncRead + Unpin> AsyncRead for Tracked<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let polled = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(polled, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.activity.touch();
        }
        polled
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Tracked<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write(cx, buf);
        if matches!(polled, Poll::Ready(Ok(n)) if n > 0) {
            self.activity.answered.store(true, Ordering::Relaxed);
            self.activity.touch();
        }
        polled
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

impl<S: Port> Port for Tracked<S> {
    fn set_rts(&mut self, on: bool) -> io::Result<()> {
        self.inner.set_rts(on)
    }

    fn last_arrival(&self) -> Option<Instant> {
        self.inner.last_arrival()
    }

    fn read_buffered(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.inner.read_buffered(buf)
    }

    fn has_wire(&self) -> bool {
        self.inner.has_wire()
    }
}

/// How far along a connection is, the first the first to be closed to make room.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub(super) enum Standing {
    /// Still in its TLS handshake.
    Handshaking,
    /// Never answered.
    Unanswered,
    /// Answered at least once.
    Idle,
}

impl std::fmt::Display for Standing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Standing::Handshaking => "still in its TLS handshake",
            Standing::Unanswered => "never answered",
            Standing::Idle => "the one idle longest",
        })
    }
}

/// A connection closed to make room.
#[derive(Clone, Copy, Debug)]
pub(super) struct Evicted {
    pub(super) peer: SocketAddr,
    pub(super) source: Source,
    /// How many connections its source held, it included.
    pub(super) held: usize,
    pub(super) standing: Standing,
}

#[derive(Debug)]
struct Entry {
    peer: SocketAddr,
    source: Source,
    activity: Arc<Activity>,
    abort: Option<AbortHandle>,
}

/// The connection slots: at most `max` connections hold one; a connection closed to make
/// room gives its slot up at once (its task is aborted, its socket closed when the task is
/// dropped).
#[derive(Debug)]
pub(super) struct Slots {
    max: usize,
    entries: Mutex<HashMap<u64, Entry>>,
    next: AtomicU64,
}

impl Slots {
    pub(super) fn new(max: usize) -> Arc<Slots> {
        Arc::new(Slots { max, entries: Mutex::default(), next: AtomicU64::new(0) })
    }

    /// A slot for the connection from `peer`, making room if every slot is taken (and saying
    /// whom it closed); `None` only if there are no slots at all.
    pub(super) fn take(
        self: &Arc<Self>,
        peer: SocketAddr,
        source: Source,
        activity: &Arc<Activity>,
    ) -> Option<(Slot, Option<Evicted>)> {
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        let mut evicted = None;
        if entries.len() >= self.max {
            let (id, held) = least_worth_keeping(&entries)?;
            let entry = entries.remove(&id)?;
            if let Some(abort) = &entry.abort {
                abort.abort();
            }
            let standing = entry.activity.standing();
            evicted = Some(Evicted { peer: entry.peer, source: entry.source, held, standing });
        }
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        entries.insert(id, Entry { peer, source, activity: Arc::clone(activity), abort: None });
        Some((Slot { slots: Arc::clone(self), id }, evicted))
    }

    /// The task serving slot `id` is `abort`, to abort if it is closed to make room.
    pub(super) fn spawned(&self, id: u64, abort: AbortHandle) {
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(entry) = entries.get_mut(&id) {
            entry.abort = Some(abort);
        }
    }
}

/// The connection to close to make room (see the module's doc), with how many its source
/// holds.
fn least_worth_keeping(entries: &HashMap<u64, Entry>) -> Option<(u64, usize)> {
    let mut held: HashMap<Source, usize> = HashMap::new();
    for entry in entries.values() {
        *held.entry(entry.source).or_default() += 1;
    }
    let held_by = |source: &Source| held.get(source).copied().unwrap_or(0);
    entries
        .iter()
        .map(|(id, entry)| {
            let standing = entry.activity.standing();
            let since = match standing {
                Standing::Handshaking | Standing::Unanswered => entry.activity.opened,
                Standing::Idle => entry.activity.last(),
            };
            ((standing, std::cmp::Reverse(held_by(&entry.source)), since, *id), *id)
        })
        .min_by_key(|(key, _)| *key)
        .map(|(_, id)| (id, entries.get(&id).map_or(0, |entry| held_by(&entry.source))))
}

/// A connection's slot, given back when it is dropped (unless it was closed to make room,
/// which gave it back then).
#[derive(Debug)]
pub(super) struct Slot {
    slots: Arc<Slots>,
    pub(super) id: u64,
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.slots.entries.lock().unwrap_or_else(PoisonError::into_inner).remove(&self.id);
    }
}
