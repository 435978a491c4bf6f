//! The requests a slave has admitted and not yet finished with, in request order: waiting to
//! be handed out, handed out and waiting for an answer, or answered and waiting for their
//! turn on the wire. Fixed capacity, no allocation, never panics.

use crate::codes::{ExceptionCode, FunctionCode};
use crate::frame::AduHeader;
use crate::pdu::{AddressRange, MAX_PDU_LEN};
use crate::time::Instant;

use super::REPLY_QUEUE;

/// Names one request the engine has handed out ([`Slave::poll_request`](super::Slave::poll_request)),
/// for [`Slave::respond`](super::Slave::respond) and its kin. Ids are not reused while the
/// engine holds their request; once it is finished with one, its id is refused.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct RequestId(pub(super) u32);

/// Where a request is on its way through the engine.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum State {
    /// Admitted, not yet handed out.
    Queued,
    /// Handed out; the engine gives up on it at `limit`.
    HandedOut,
    /// Answered: the reply PDU is in the entry, due at `due`.
    Answered { due: Instant, exception: Option<ExceptionCode> },
    /// Finished without a reply; it only holds its place until those before it are sent.
    Finished,
}

/// One request in the engine.
#[derive(Clone, Copy, Debug)]
pub(super) struct Entry {
    pub(super) id: RequestId,
    pub(super) header: AduHeader,
    pub(super) broadcast: bool,
    /// When the request's last byte arrived.
    pub(super) end: Instant,
    pub(super) function: FunctionCode,
    pub(super) addresses: [Option<AddressRange>; 2],
    /// When the engine stops waiting for an answer (`None`: never).
    pub(super) limit: Option<Instant>,
    /// The request's PDU while it waits; the reply's once answered.
    pub(super) pdu: [u8; MAX_PDU_LEN],
    pub(super) len: usize,
    pub(super) state: State,
}

impl Entry {
    /// The PDU held: the request's, or the reply's once answered.
    pub(super) fn pdu(&self) -> &[u8] {
        self.pdu.get(..self.len).unwrap_or_default()
    }

    /// Whether the request still waits for an answer.
    pub(super) fn is_waiting(&self) -> bool {
        matches!(self.state, State::Queued | State::HandedOut)
    }
}

/// Up to [`REPLY_QUEUE`] entries, oldest first.
#[derive(Clone, Copy, Debug)]
pub(super) struct Slots {
    entries: [Option<Entry>; REPLY_QUEUE],
    head: usize,
    len: usize,
}

impl Slots {
    pub(super) const fn new() -> Self {
        Slots { entries: [None; REPLY_QUEUE], head: 0, len: 0 }
    }

    pub(super) const fn len(&self) -> usize {
        self.len
    }

    fn index(&self, i: usize) -> Option<usize> {
        self.head.checked_add(i)?.checked_rem(REPLY_QUEUE)
    }

    /// Appends `entry`; returns whether there was room for it.
    pub(super) fn push(&mut self, entry: &Entry) -> bool {
        if self.len >= REPLY_QUEUE {
            return false;
        }
        let Some(slot) = self.index(self.len).and_then(|i| self.entries.get_mut(i)) else { return false };
        *slot = Some(*entry);
        self.len = self.len.saturating_add(1);
        true
    }

    /// The oldest entry.
    pub(super) fn front(&self) -> Option<&Entry> {
        if self.len == 0 {
            return None;
        }
        self.entries.get(self.head).and_then(Option::as_ref)
    }

    /// Takes the oldest entry.
    pub(super) fn pop(&mut self) -> Option<Entry> {
        if self.len == 0 {
            return None;
        }
        let entry = self.entries.get_mut(self.head).and_then(Option::take);
        self.head = self.head.saturating_add(1).checked_rem(REPLY_QUEUE).unwrap_or(0);
        self.len = self.len.saturating_sub(1);
        entry
    }

    /// The entries, oldest first.
    pub(super) fn iter(&self) -> impl Iterator<Item = &Entry> + '_ {
        (0..self.len).filter_map(|i| self.index(i).and_then(|i| self.entries.get(i)).and_then(Option::as_ref))
    }

    /// The entry of `id`, if the engine still holds it.
    pub(super) fn get_mut(&mut self, id: RequestId) -> Option<&mut Entry> {
        let at = (0..self.len)
            .filter_map(|i| self.index(i))
            .find(|&i| self.entries.get(i).and_then(Option::as_ref).is_some_and(|e| e.id == id))?;
        self.entries.get_mut(at).and_then(Option::as_mut)
    }

    /// The oldest entry in `state`.
    pub(super) fn first_mut(&mut self, state: State) -> Option<&mut Entry> {
        let at = (0..self.len)
            .filter_map(|i| self.index(i))
            .find(|&i| self.entries.get(i).and_then(Option::as_ref).is_some_and(|e| e.state == state))?;
        self.entries.get_mut(at).and_then(Option::as_mut)
    }
}
