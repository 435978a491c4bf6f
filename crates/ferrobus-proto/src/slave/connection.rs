//! The policy of a connection the slave serves: how long it may stay quiet, how long a frame
//! begun may take, how many requests it may have outstanding — and why the engine is done
//! with it ([`Closed`]).
//!
//! A server over TCP and a gateway's front both close a connection for the same three
//! reasons, on the same rules, decided here on the engine's explicit time: the engine knows
//! when the last byte came and the last reply left, whether a frame is half received and
//! whether a request is outstanding. A serial line has no connection to close: its policy
//! is [`ConnectionPolicy::NONE`].

use core::fmt;
use core::time::Duration;

use super::{REPLY_QUEUE, Slave};
use crate::frame::Framing;
use crate::time::{Instant, earliest};

/// How long a connection may stay quiet or hold a frame unfinished, and how many requests
/// it may have outstanding.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ConnectionPolicy {
    /// Closed ([`Closed::Idle`]) when nothing arrives or leaves for this long while no
    /// request is outstanding (one waiting for its answer, or its reply for its time), so a
    /// slow device behind a gateway never closes its client. A reply not written within it
    /// (a peer that reads nothing) closes the connection too. `None`: never.
    pub idle: Option<Duration>,
    /// Closed ([`Closed::UnfinishedFrame`]) when a frame begun is not complete this long
    /// after its first byte; the time counts only while the engine reads (a client held back
    /// by its own outstanding requests is not timed). Framings that end frames by time never
    /// are. `None`: never.
    pub frame: Option<Duration>,
    /// Requests that may be outstanding at once over a framing without broadcast: past it
    /// the engine takes no more bytes ([`Slave::is_blocked`]) until a reply has gone out, so
    /// a client that floods is held back by TCP. 1 to [`REPLY_QUEUE`]; a serial line holds
    /// one whatever this says.
    pub max_pending: usize,
}

impl ConnectionPolicy {
    /// Never closed; [`REPLY_QUEUE`] requests outstanding. A serial line's, and the engine's
    /// until told otherwise.
    pub const NONE: ConnectionPolicy = ConnectionPolicy { idle: None, frame: None, max_pending: REPLY_QUEUE };

    /// A TCP server's: closed after 60 s idle or 5 s into an unfinished frame;
    /// [`REPLY_QUEUE`] requests outstanding.
    pub const TCP: ConnectionPolicy = ConnectionPolicy {
        idle: Some(Duration::from_secs(60)),
        frame: Some(Duration::from_secs(5)),
        max_pending: REPLY_QUEUE,
    };
}

impl Default for ConnectionPolicy {
    /// [`ConnectionPolicy::NONE`].
    fn default() -> Self {
        ConnectionPolicy::NONE
    }
}

/// Why the engine is done with a connection ([`Slave::closed`]). Exhaustive, so that every
/// user that counts the reasons counts a new one.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Closed {
    /// Nothing arrived or left for [`ConnectionPolicy::idle`].
    Idle(Duration),
    /// A frame begun was not complete [`ConnectionPolicy::frame`] after its first byte.
    UnfinishedFrame(Duration),
    /// An MBAP header with a protocol id other than 0 or a length outside 2..=254: the
    /// stream's framing is lost. The replies to the requests before it are still owed.
    BadHeader,
}

impl fmt::Display for Closed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Closed::Idle(d) => write!(f, "idle for {d:?}: connection closed"),
            Closed::UnfinishedFrame(d) => write!(f, "a frame begun was not finished within {d:?}: connection closed"),
            Closed::BadHeader => f.write_str("invalid MBAP header (framing lost): connection closed"),
        }
    }
}

impl core::error::Error for Closed {}

/// What the engine keeps to apply its connection policy.
#[derive(Clone, Copy, Debug)]
pub(super) struct Watch {
    pub(super) policy: ConnectionPolicy,
    /// When the last byte arrived or the last reply left (the connection's start before).
    last_activity: Instant,
    /// When the frame now half received began, while the engine reads.
    frame_began: Option<Instant>,
    pub(super) closed: Option<Closed>,
}

impl Watch {
    pub(super) const fn new() -> Self {
        Watch { policy: ConnectionPolicy::NONE, last_activity: Instant::ZERO, frame_began: None, closed: None }
    }

    /// Something arrived or left at `now`.
    pub(super) fn active(&mut self, now: Instant) {
        self.last_activity = self.last_activity.max(now);
    }

    /// The receiver holds a frame begun (`mid_frame`) after bytes at `now`, or the engine
    /// reads again at `now` after it was held back (`resumed`).
    pub(super) fn track_frame(&mut self, mid_frame: bool, now: Instant, resumed: bool) {
        self.frame_began = match (mid_frame, self.frame_began) {
            (false, _) => None,
            (true, Some(began)) if !resumed => Some(began),
            (true, _) => Some(now),
        };
    }

    /// When the connection is due to close, given whether a request is outstanding and
    /// whether the engine reads.
    fn due(&self, outstanding: bool, reading: bool) -> (Option<Instant>, Option<Instant>) {
        if self.closed.is_some() {
            return (None, None);
        }
        // A timeout too long to add to an instant is no deadline at all.
        let idle = self.policy.idle.filter(|_| !outstanding).and_then(|d| self.last_activity.checked_add(d));
        let frame = self.policy.frame.zip(self.frame_began.filter(|_| reading)).and_then(|(d, at)| at.checked_add(d));
        (idle, frame)
    }
}

impl<F: Framing> Slave<F> {
    /// Applies `policy` to the connection, counting its quiet time from `now` (when it was
    /// opened).
    pub fn set_connection_policy(&mut self, policy: ConnectionPolicy, now: Instant) {
        let watch = &mut self.core.watch;
        watch.policy = ConnectionPolicy { max_pending: policy.max_pending.clamp(1, REPLY_QUEUE), ..policy };
        watch.last_activity = now;
    }

    /// The connection's policy ([`ConnectionPolicy::NONE`] unless set).
    pub fn connection_policy(&self) -> ConnectionPolicy {
        self.core.watch.policy
    }

    /// Why the engine is done with the connection, once it is: its quiet time or a frame
    /// begun ran out (seen by [`Slave::handle_timeout`] or [`Slave::wake`] at its deadline,
    /// part of [`Slave::poll_timeout`]), or its MBAP framing was lost. It stays so.
    pub fn closed(&self) -> Option<Closed> {
        self.core.watch.closed
    }

    /// The earliest of the connection's deadlines.
    pub(super) fn connection_deadline(&self) -> Option<Instant> {
        let (idle, frame) = self.core.watch.due(self.pending_replies() > 0, !self.is_blocked());
        earliest(idle, frame)
    }

    /// Closes the connection if a deadline of its policy has passed at `now`.
    pub(super) fn check_connection(&mut self, now: Instant) {
        let (idle, frame) = self.core.watch.due(self.pending_replies() > 0, !self.is_blocked());
        let policy = self.core.watch.policy;
        let passed = |at: Option<Instant>| at.is_some_and(|at| now >= at);
        let closed = match (policy.idle, policy.frame) {
            (Some(d), _) if passed(idle) => Some(Closed::Idle(d)),
            (_, Some(d)) if passed(frame) => Some(Closed::UnfinishedFrame(d)),
            _ => None,
        };
        if closed.is_some() {
            self.core.watch.closed = closed;
        }
    }
}
