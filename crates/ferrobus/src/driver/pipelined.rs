//! The driver of a Modbus/TCP connection with several requests in flight
//! ([`ClientConfig::in_flight`](crate::ClientConfig::in_flight) past 1).
//!
//! It is the one-at-a-time [`Driver`](super::Driver)'s twin: it takes commands from the
//! client's channel and hands back completions, with the same retries, per-unit backoff,
//! reconnection and counters (the [`Link`] both keep). It does not wait for a reply before it
//! sends the next request: up to the limit are outstanding on the connection at once, each
//! matched to its reply by its transaction id by the core's [`Pipeline`]. Requests that come
//! together go out in one write, and replies that come together are taken from one read.
//!
//! - **Retries.** A retry is a new request under a new transaction id, sent as soon as its
//!   attempt has ended; it goes before the requests that wait in the channel.
//! - **A lost connection** (the device closed it, a read or a write failed) ends every request
//!   in flight: those with retries left are sent again on the next connection, made after the
//!   IO backoff; the others fail with the IO error. The backoff counts the loss once, not once
//!   per request it ended.
//! - **A stalled connection** (a timeout that left part of a reply behind while nothing else
//!   was outstanding, or [`STALLED_AFTER_TIMEOUTS`](super::STALLED_AFTER_TIMEOUTS) in a row
//!   with no reply between) is closed and made again, as the one-at-a-time driver does; the
//!   requests still in flight on it go again on the new one if they have retries left.
//! - **Backoff.** A unit in backoff is refused before anything is sent, as on any line; its
//!   probe goes without retries.
//!
//! Whether a device takes pipelined requests is the device's affair: one that reads its
//! connection in order and answers each request (libmodbus's server) serves them back to back,
//! so pipelining hides the round trip; one that takes a single request at a time and drops
//! the rest (pymodbus's server, 3.16, answers only the first of those one read brings) makes
//! the others time out, and wants `in_flight` 1.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use ferrobus_proto::master::pipeline::{MAX_IN_FLIGHT, Pipeline};
use ferrobus_proto::master::{HeardInstead, MAX_TX_LEN};
use ferrobus_proto::pdu::Request;
use ferrobus_proto::retry::should_retry;
use tokio::sync::mpsc;

use super::{Between, ClientStats, Command, Link, Reply, Turn, convert, outcome};
use crate::config::ClientConfig;
use crate::error::Error;
use crate::port::{BoxPort, Transport};
use crate::pump::{Pump, write_frame};

/// A request and its attempts so far.
struct Pending {
    command: Command,
    /// Attempts sent, this one included.
    attempts: u32,
    /// Resends allowed (none for a unit's probe).
    retries: u32,
    /// What tells most about the unit over all attempts that timed out.
    heard: Option<HeardInstead>,
    /// When its attempt was sent.
    sent: ferrobus_proto::Instant,
}

pub(crate) struct Pipelined {
    engine: Pipeline,
    link: Link,
    pump: Pump,
    /// When the last reply (any but a timeout) came on the connection.
    last_reply: Option<ferrobus_proto::Instant>,
    /// The requests in flight, by their ticket's slot.
    flying: [Option<Pending>; MAX_IN_FLIGHT],
    /// Requests to send before any new one: retries, and those a lost connection ended.
    again: VecDeque<Pending>,
    frame: Box<[u8; MAX_TX_LEN]>,
    /// The frames of one write.
    batch: Vec<u8>,
}

impl Pipelined {
    pub(crate) fn new(transport: Transport, config: ClientConfig, port: Option<BoxPort>) -> Self {
        let mut engine = Pipeline::new(Transport::mbap_codec(), config.in_flight);
        engine.set_late_window(config.late_window);
        Pipelined {
            engine,
            pump: Pump::new(transport.timer().sleeper()),
            link: Link::new(transport, config, port),
            last_reply: None,
            flying: std::array::from_fn(|_| None),
            again: VecDeque::new(),
            frame: Box::new([0; MAX_TX_LEN]),
            batch: Vec::new(),
        }
    }

    /// The counters the driver keeps up to date for its clients.
    pub(crate) fn stats(&self) -> Arc<Mutex<ClientStats>> {
        self.link.stats()
    }

    /// How long the driver may hold the connection for a reply: never past its end, since the
    /// transaction ids tell a late reply apart (watched by [`Release`](crate::Release)).
    pub(crate) fn hold(&self) -> tokio::sync::watch::Receiver<Option<tokio::time::Instant>> {
        self.link.hold()
    }

    fn publish_stats(&self) {
        self.link.publish(self.engine.stats());
    }

    pub(crate) async fn run(mut self, mut commands: mpsc::Receiver<Command>) {
        let mut open = true;
        // Bytes were read since the counters were last published (a late reply, say).
        let mut read = false;
        loop {
            if self.deliver() || read {
                self.publish_stats();
                read = false;
            }
            while self.engine.has_room() {
                let Some(pending) = self.again.pop_front() else { break };
                self.send(pending).await;
            }
            self.transmit().await;
            if self.link.port.is_none() {
                if !self.again.is_empty() {
                    continue;
                }
                // Nothing is in flight without a connection: wait for the next request.
                match commands.recv().await {
                    Some(command) => self.start(command).await,
                    None => return,
                }
                continue;
            }
            if !open && self.engine.outstanding() == 0 {
                return;
            }
            let room = open && self.engine.has_room() && self.again.is_empty();
            let Some(port) = self.link.port.as_mut() else { continue };
            match self.pump.run(port, &mut self.engine, &mut Between::new(&mut commands, room)).await {
                Turn::Command(Some(command)) => {
                    self.start(command).await;
                    // Whatever else is waiting goes out in the same write.
                    while self.engine.has_room() && self.link.port.is_some() {
                        let Ok(command) = commands.try_recv() else { break };
                        self.start(command).await;
                    }
                }
                Turn::Command(None) => open = false,
                Turn::Read => read = true,
                // The engine's deadline was handled: its completions are delivered next.
                Turn::Woke => {}
                Turn::Ended(None) => self.lost(&std::io::ErrorKind::UnexpectedEof.into()),
                Turn::Ended(Some(e)) => self.lost(&e),
            }
        }
    }

    /// A new request: refused at once for a unit in backoff, else sent.
    async fn start(&mut self, command: Command) {
        let now = self.pump.clock().now();
        match self.link.check_health(command.unit, now) {
            Err(e) => {
                let _ = command.reply.send(Err(e));
                self.publish_stats();
            }
            Ok(probe) => {
                let retries = if probe { 0 } else { command.options.retries };
                self.send(Pending { command, attempts: 0, retries, heard: None, sent: now }).await;
            }
        }
    }

    /// Sends one attempt of `pending`, connecting first if needed; it waits in `again` while
    /// the requests in flight are at the limit.
    async fn send(&mut self, mut pending: Pending) {
        if !self.engine.has_room() {
            self.again.push_back(pending);
            return;
        }
        pending.attempts = pending.attempts.saturating_add(1);
        match self.link.ensure_open(self.pump.clock()).await {
            // A new connection: nothing said on the old one will be heard on it.
            Ok(true) => self.engine.abort(),
            Ok(false) => {}
            Err(e) => {
                let now = self.pump.clock().now();
                self.ended(pending, Err(e), now);
                // The failed connect is counted now, not at the next completion.
                return self.publish_stats();
            }
        }
        let now = self.pump.clock().now();
        pending.sent = now;
        let command = &pending.command;
        let timeout = command.options.timeout;
        let submitted = if command.raw {
            self.engine.submit_raw(now, command.unit, &command.pdu, timeout)
        } else {
            match Request::parse(&command.pdu) {
                Ok(request) => self.engine.submit(now, command.unit, &request, timeout),
                Err(e) => return self.settle(pending, Err(e.into()), now),
            }
        };
        if let Ok(Some(slot)) = submitted.map(|ticket| self.flying.get_mut(ticket.slot())) {
            *slot = Some(pending);
        } else {
            // Only a PDU longer than 253 bytes cannot be framed.
            let len = pending.command.pdu.len();
            self.settle(pending, Err(Error::InvalidRequest(ferrobus_proto::PduError::TooLong { len })), now);
        }
    }

    /// Writes every request that is due, in one write.
    async fn transmit(&mut self) {
        let now = self.pump.clock().now();
        self.batch.clear();
        while let Some(n) = self.engine.poll_transmit(now, &mut self.frame[..]) {
            self.batch.extend_from_slice(self.frame.get(..n).unwrap_or_default());
        }
        if self.batch.is_empty() {
            return;
        }
        let Some(port) = self.link.port.as_mut() else { return self.lost(&std::io::ErrorKind::NotConnected.into()) };
        let transport = &self.link.transport;
        if let Err(e) = write_frame(port, &self.batch, transport.rs485(), transport.timing()).await {
            self.lost(&e);
        }
    }

    /// Hands each completion the engine has to its request; returns whether there was any.
    fn deliver(&mut self) -> bool {
        let mut any = false;
        // The completions of one turn end at one instant: the clock is read once for them.
        let mut now = None;
        while let Some((ticket, completion)) = self.engine.poll_event() {
            let Some(pending) = self.flying.get_mut(ticket.slot()).and_then(Option::take) else { continue };
            let result = convert(&pending.command, completion);
            let now = *now.get_or_insert_with(|| self.pump.clock().now());
            self.ended(pending, result, now);
            any = true;
        }
        any
    }

    /// The connection is gone under the requests in flight: each is sent again on the next
    /// one if it has retries left, or fails.
    fn lost(&mut self, error: &std::io::Error) {
        let describe = self.link.transport.describe();
        tracing::warn!(port = %describe, "the connection was lost ({error}); it will be made again");
        self.link.lose_port();
        self.link.io_failed(self.pump.clock().now());
        self.abandon(error);
    }

    /// Ends every request in flight on a connection that is gone (each sent again on the
    /// next one if it has retries left, or failed with `error`).
    fn abandon(&mut self, error: &std::io::Error) {
        let describe = self.link.transport.describe();
        self.engine.abort();
        let now = self.pump.clock().now();
        for slot in 0..MAX_IN_FLIGHT {
            let Some(pending) = self.flying.get_mut(slot).and_then(Option::take) else { continue };
            let error = std::io::Error::new(error.kind(), error.to_string());
            self.settle(pending, Err(Error::io(format!("reading from {describe}"), error)), now);
        }
        self.publish_stats();
    }

    /// One attempt ended with `result` at `now`: counted for the IO backoff, then settled; a
    /// connection it shows stalled is closed (the others in flight on it go again, or fail).
    /// Only a timeout of a request sent after the last reply says the connection may have
    /// stalled: one a device dropped while it answered others (pymodbus's server takes one
    /// of the requests a read brings) does not.
    fn ended(&mut self, pending: Pending, result: Result<Reply, Error>, now: ferrobus_proto::Instant) {
        self.link.attempt_ended(&result, now);
        let stalled = match &result {
            Err(Error::Timeout { .. }) if self.last_reply.is_some_and(|last| pending.sent <= last) => false,
            Err(Error::Timeout { .. }) => {
                let framing = self.engine.framing();
                let mid_frame = self.engine.outstanding() == 0 && ferrobus_proto::frame::Framing::is_mid_frame(framing);
                self.link.check_stall(&result, mid_frame)
            }
            Ok(_) | Err(Error::Exception { .. } | Error::BadReply { .. }) => {
                self.last_reply = Some(now);
                self.link.check_stall(&result, false)
            }
            _ => false,
        };
        self.settle(pending, result, now);
        if stalled {
            self.abandon(&std::io::Error::new(std::io::ErrorKind::TimedOut, "the connection stalled"));
            self.publish_stats();
        }
    }

    /// Sends `pending` again if the retry policy says so; else records the unit's health (at
    /// `now`) and answers its client.
    fn settle(&mut self, mut pending: Pending, result: Result<Reply, Error>, now: ferrobus_proto::Instant) {
        if let Err(Error::Timeout { heard: Some(heard), .. }) = result
            && pending.heard.is_none_or(|kept| heard.weight() >= kept.weight())
        {
            pending.heard = Some(heard);
        }
        let command = &pending.command;
        if should_retry(outcome(command, &result), pending.attempts, pending.retries) {
            tracing::debug!(unit = command.unit, attempts = pending.attempts, "retrying: {:?}", result);
            self.again.push_back(pending);
            return;
        }
        self.link.record_health(command, &result, now);
        let result = match result {
            Err(Error::Timeout { unit, timeout, .. }) => {
                Err(Error::Timeout { unit, timeout, attempts: pending.attempts, heard: pending.heard })
            }
            other => other,
        };
        let _ = pending.command.reply.send(result);
    }
}
