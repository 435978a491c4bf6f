//! The MQTT session (rumqttc, MQTT 3.1.1): one task drives rumqttc's event loop and tells the
//! bridge what happened; the bridge says when to connect, with which Will.
//!
//! ```text
//!   bridge ── connect(Will) ─▶ task: set the Will, CONNECT, poll the event loop
//!          ◀─ Connected / Message / Lost / Closed ──┘
//!   bridge ── publish, subscribe, disconnect ─▶ AsyncClient (a bounded queue) ─▶ event loop
//! ```
//!
//! The task never reconnects by itself: after a lost connection it waits until the bridge has
//! taken the next bdSeq and asks again with its Will (`MqttOptions::set_last_will`, which
//! rumqttc reads at each CONNECT), after the backoff. Before each CONNECT the requests still
//! queued from the old session are dropped (`EventLoop::clean`, then a clean session): what
//! they carried belonged to a session the broker has declared dead. Publishing never waits:
//! a full queue is an error the bridge counts.
//!
//! # Incoming size
//!
//! rumqttc ends the connection on an incoming packet over its `max_incoming_packet_size`
//! (`PayloadSizeLimitExceeded`, a connection error): one big message on a subscribed topic
//! would drop the session, and a retained one would drop every session after it. So rumqttc
//! is told to take anything MQTT 3.1.1 can frame (268,435,455 bytes), and the size is
//! checked here: a message over [`MAX_MESSAGE`] becomes [`SessionEvent::Oversized`] (its
//! topic and size, not its bytes), which the bridge counts and discards while the session
//! goes on. rumqttc holds a packet whole before it hands it over, so the memory such a message
//! costs for a moment is bounded by what the broker lets through (mosquitto's
//! `message_size_limit`, 256 MiB by default).

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use rumqttc::{AsyncClient, Event, EventLoop, LastWill, MqttOptions, Outgoing, Packet, QoS};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::edge::Publish;

/// The MQTT client's queue is full (or its task has ended): the request was not queued.
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum QueueFull {
    /// A publish.
    #[error("the MQTT client's queue is full")]
    Publish,
    /// A subscription, to `filter` (escaped when shown: it comes from the configuration).
    #[error("subscribing to {}: the MQTT client's queue is full", ferrobus::log::escape(.filter))]
    Subscribe {
        /// The topic filter.
        filter: String,
    },
}

/// Requests the client may have queued for the event loop.
const QUEUE: usize = 4096;

/// The largest packet sent (a DBIRTH of a big device, a replayed record).
const MAX_PACKET: usize = 1 << 20;

/// The largest message taken, topic and payload: a command or a STATE is far smaller.
pub const MAX_MESSAGE: usize = 1 << 20;

/// The largest packet MQTT 3.1.1 can frame (the Remaining Length's four bytes, §2.2.3): what
/// rumqttc is told to take, so that no packet a broker delivers ends the session.
const MQTT_MAX_PACKET: usize = 268_435_455;

/// The longest wait between two connection attempts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(30);

/// The shortest: a zero first delay would make a busy loop.
const MIN_BACKOFF: Duration = Duration::from_millis(100);

/// What the session tells the bridge.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SessionEvent {
    /// The broker accepted the CONNECT.
    Connected,
    /// A message on a subscribed topic.
    Message {
        /// Its topic.
        topic: String,
        /// Its payload.
        payload: Vec<u8>,
    },
    /// A message on a subscribed topic over [`MAX_MESSAGE`], discarded (the session goes on).
    Oversized {
        /// Its topic.
        topic: String,
        /// Its size, topic and payload.
        bytes: usize,
    },
    /// The connection failed or was lost, and why.
    Lost(String),
    /// The DISCONNECT asked for has been sent.
    Closed,
}

/// One MQTT session to the broker, reconnected on demand.
#[derive(Debug)]
pub struct Session {
    client: AsyncClient,
    events: mpsc::Receiver<SessionEvent>,
    connect: mpsc::UnboundedSender<Option<LastWill>>,
    queued: Arc<AtomicUsize>,
    task: JoinHandle<()>,
}

impl Session {
    /// Starts the task with `options` (its Will is set at each [`Session::connect`]); nothing
    /// is connected yet.
    pub fn start(mut options: MqttOptions) -> Session {
        options.set_max_packet_size(MQTT_MAX_PACKET, MAX_PACKET);
        options.set_clean_session(true);
        let (client, eventloop) = AsyncClient::new(options, QUEUE);
        let (events_tx, events) = mpsc::channel(256);
        let (connect, connect_rx) = mpsc::unbounded_channel();
        let queued = Arc::new(AtomicUsize::new(0));
        let task = tokio::spawn(drive(eventloop, connect_rx, events_tx, Arc::clone(&queued)));
        Session { client, events, connect, queued, task }
    }

    /// Connects (again), with `will` as the CONNECT's Will.
    pub fn connect(&self, will: Option<&Publish>) {
        let will = will.map(|w| LastWill::new(w.topic.clone(), w.payload.clone(), qos(w.qos), w.retain));
        let _ = self.connect.send(will);
    }

    /// Queues `message`; an error if the queue is full or the task has ended.
    pub fn publish(&self, message: Publish) -> Result<(), QueueFull> {
        self.client
            .try_publish(message.topic, qos(message.qos), message.retain, message.payload)
            .map_err(|_| QueueFull::Publish)?;
        self.queued.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// Subscribes to `filter`.
    pub fn subscribe(&self, filter: &str, qos_level: u8) -> Result<(), QueueFull> {
        self.client
            .try_subscribe(filter, qos(qos_level))
            .map_err(|_| QueueFull::Subscribe { filter: filter.to_string() })
    }

    /// Asks for a DISCONNECT after what is queued; [`SessionEvent::Closed`] says it went.
    pub fn disconnect(&self) {
        let _ = self.client.try_disconnect();
    }

    /// Publishes queued and not yet written to the broker.
    pub fn queued(&self) -> usize {
        self.queued.load(Ordering::Relaxed)
    }

    /// The next event; `None` once the task has ended.
    pub async fn next(&mut self) -> Option<SessionEvent> {
        self.events.recv().await
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// The event loop's task: waits to be told to connect, then polls until the session ends.
async fn drive(
    mut eventloop: EventLoop,
    mut connect: mpsc::UnboundedReceiver<Option<LastWill>>,
    events: mpsc::Sender<SessionEvent>,
    queued: Arc<AtomicUsize>,
) {
    while let Some(will) = connect.recv().await {
        eventloop.clean();
        eventloop.pending.clear();
        queued.store(0, Ordering::Relaxed);
        if let Some(will) = will {
            eventloop.mqtt_options.set_last_will(will);
        }
        loop {
            let event = match eventloop.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => SessionEvent::Connected,
                Ok(Event::Incoming(Packet::Publish(p))) => incoming(p),
                Ok(Event::Outgoing(Outgoing::Publish(_))) => {
                    let _ = queued.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| Some(n.saturating_sub(1)));
                    continue;
                }
                Ok(Event::Outgoing(Outgoing::Disconnect)) => SessionEvent::Closed,
                Ok(_) => continue,
                Err(e) => SessionEvent::Lost(e.to_string()),
            };
            let ended = matches!(event, SessionEvent::Closed | SessionEvent::Lost(_));
            if events.send(event).await.is_err() {
                return;
            }
            if ended {
                break;
            }
        }
    }
}

/// What an incoming PUBLISH tells the bridge: the message, or only its size when it is over
/// [`MAX_MESSAGE`] (rumqttc has acknowledged it already, at QoS 1 and 2).
fn incoming(publish: rumqttc::Publish) -> SessionEvent {
    let bytes = publish.topic.len().saturating_add(publish.payload.len());
    if bytes > MAX_MESSAGE {
        return SessionEvent::Oversized { topic: publish.topic, bytes };
    }
    SessionEvent::Message { topic: publish.topic, payload: publish.payload.to_vec() }
}

/// The QoS of a level (2 and above are 2).
pub fn qos(level: u8) -> QoS {
    match level {
        0 => QoS::AtMostOnce,
        1 => QoS::AtLeastOnce,
        _ => QoS::ExactlyOnce,
    }
}

/// The waits between connection attempts: the configured first delay, doubling up to
/// [`MAX_BACKOFF`]; back to the first once connected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Backoff {
    first: Duration,
    next: Duration,
}

impl Backoff {
    /// Starting at `first` (at least 100 ms, at most [`MAX_BACKOFF`]).
    pub fn new(first: Duration) -> Backoff {
        let first = first.clamp(MIN_BACKOFF, MAX_BACKOFF);
        Backoff { first, next: first }
    }

    /// The wait before the next attempt; the one after is twice as long.
    pub fn delay(&mut self) -> Duration {
        let delay = self.next;
        self.next = self.next.saturating_mul(2).min(MAX_BACKOFF);
        delay
    }

    /// Connected: the next loss waits the first delay again.
    pub fn reset(&mut self) {
        self.next = self.first;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_backoff_doubles_to_30_s_and_starts_again_once_connected() {
        let mut b = Backoff::new(Duration::from_secs(1));
        let waits: Vec<u64> = (0..8).map(|_| b.delay().as_secs()).collect();
        assert_eq!(waits, [1, 2, 4, 8, 16, 30, 30, 30]);
        b.reset();
        assert_eq!(b.delay(), Duration::from_secs(1));
    }

    #[test]
    fn a_zero_first_delay_is_not_a_busy_loop_and_a_long_one_is_capped() {
        assert_eq!(Backoff::new(Duration::ZERO).delay(), MIN_BACKOFF);
        assert_eq!(Backoff::new(Duration::from_secs(600)).delay(), MAX_BACKOFF);
    }

    #[test]
    fn a_message_over_the_limit_is_only_its_topic_and_size_and_one_at_the_limit_is_taken() {
        let publish = |payload: Vec<u8>| rumqttc::Publish::new("spBv1.0/g/DCMD/n/d", QoS::AtLeastOnce, payload);
        let topic_len = "spBv1.0/g/DCMD/n/d".len();
        let at_limit = publish(vec![0; MAX_MESSAGE - topic_len]);
        assert!(
            matches!(incoming(at_limit), SessionEvent::Message { payload, .. } if payload.len() == MAX_MESSAGE - topic_len)
        );
        let over = publish(vec![0; MAX_MESSAGE - topic_len + 1]);
        assert_eq!(
            incoming(over),
            SessionEvent::Oversized { topic: "spBv1.0/g/DCMD/n/d".into(), bytes: MAX_MESSAGE + 1 }
        );
    }

    #[test]
    fn qos_levels_map_to_rumqttc() {
        assert_eq!(qos(0), QoS::AtMostOnce);
        assert_eq!(qos(1), QoS::AtLeastOnce);
        assert_eq!(qos(2), QoS::ExactlyOnce);
        assert_eq!(qos(9), QoS::ExactlyOnce);
    }

    #[test]
    fn a_refused_subscription_names_its_filter_on_one_line() {
        let e = QueueFull::Subscribe { filter: "spBv1.0/plant\n/#".into() };
        let shown = e.to_string();
        assert!(shown.starts_with("subscribing to spBv1.0/plant"), "{shown}");
        assert!(!shown.contains('\n'), "{shown}");
        assert_eq!(QueueFull::Publish.to_string(), "the MQTT client's queue is full");
    }
}
