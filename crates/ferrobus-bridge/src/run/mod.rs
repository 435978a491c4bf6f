//! The bridge itself: a poller per line, one MQTT session, the store; the [`Edge`] decides
//! what each sample, connection and command publishes, this module does the IO.
//!
//! ```text
//!   line 0: Client ─▶ Poller ─┐ (line, Event)                 ┌─▶ Session (rumqttc) ─▶ broker
//!   line 1: Client ─▶ Poller ─┼──────────────▶ run: Edge ─────┤        │ Connected, Message, Lost
//!   line 2: virtual line+Sim ─┘        ▲  Action::Write       └─▶ Store (while offline)
//!                                      └─ PollHandle::write_raw ◀─┘ replayed after the births
//! ```
//!
//! "The broker is away" is decided by the session: a failed attempt or a lost session. The
//! samples taken while the first attempt has no outcome yet are held (in order, up to 4096)
//! until it has one: after its CONNACK they are live data behind the births, after its failure
//! they are stored. So a bridge that starts beside a reachable broker never sends its first
//! samples as history because a poll answered before the CONNACK did.
//!
//! One task runs the loop, in this order of priority: stop, the broker's events, the lines'
//! samples, the results of writes, the reconnect timer, and last the replay of stored records
//! (a batch every 10 ms while the client's queue is short, so that live data is never starved
//! and the replay is never put off for ever). Lines run concurrently in their own pollers: one
//! line's failure never stops another. A command's writes ([`Action::Write`]) are checked
//! whole, then, in a task of their own once the device's turn comes (one command of a device at
//! a time), put through the profile's write guard with the drive's run state read first, and
//! written in order (`command.rs`); they come back as results for [`Edge::written`].
//!
//! The broker session: CONNECT with the edge's Will (NDEATH with the bdSeq, kept across
//! restarts in a small file, see [`state`]); on CONNACK subscribe to the edge's topics and
//! publish its births, then replay the store in order ([`Edge::replay_all`], then
//! [`Edge::replayed`] once it is empty); on a lost connection the edge is told (its samples
//! become store records, the next CONNECT takes the next bdSeq) and the next attempt waits the
//! backoff (the configured delay, doubling to 30 s). Stopping publishes NDEATH before the
//! DISCONNECT, stops the pollers, closes the store (what is left is kept on disk for the next
//! run) and returns a [`Report`]. [`run_with`]'s [`Options`] hand out the running lines (their
//! clients, pollers and simulated lines) to a caller that drives a device beside the bridge,
//! and take plants read again ([`Reload`]), each carried out while the bridge runs (`reload.rs`:
//! lines and devices kept, stopped and started, the session kept unless the broker changed).

mod broker;
mod command;
mod lines;
mod listen;
pub mod mqtt;
mod reload;
mod report;
pub mod state;
mod status;

use std::collections::{BTreeMap, VecDeque};
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use ferrobus_tools::poll::{Event, Sample};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::Instant;

pub use lines::{GroupMap, RunningLine, SimulatedLine};
pub use reload::Reload;
pub use report::{LineReport, Report};
pub use status::Status;

use crate::config::{Mode, Plant};
use crate::edge::{Action, DeviceRef, Edge, EdgeError, Liveness, Output, Publish};
use crate::sparkplug::topic::{MessageType, Topic};
use crate::store::{Pushed, Store, StoreError};
use command::{Applied, BusWrite, DeviceWrites};
use mqtt::{Backoff, Session, SessionEvent};
use state::{BdSeqFile, Stored};

/// Records replayed per turn of the loop.
const REPLAY_BATCH: usize = 64;

/// The pause between two replay batches.
const REPLAY_PACE: Duration = Duration::from_millis(10);

/// Replay waits while the client has this many messages queued for the broker.
const REPLAY_QUEUE_LIMIT: usize = 256;

/// The most samples held while the first connection attempt has no outcome yet: past it, the
/// broker counts as away and they go to the edge (and so to the store).
const HOLD_LIMIT: usize = 4096;

/// How long a stop waits for the NDEATH and the DISCONNECT to go out.
const CLOSE_WAIT: Duration = Duration::from_secs(3);

/// Why the bridge could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// The store could not be opened.
    #[error("the store: {0}")]
    Store(#[from] StoreError),
    /// The broker's TLS files or settings.
    #[error("the broker's TLS: {0}")]
    Tls(String),
    /// A line could not be set up (a simulated line's devices).
    #[error("line {line:?}: {detail}")]
    Line {
        /// The line's name.
        line: String,
        /// What failed.
        detail: String,
    },
}

/// What a caller may ask of [`run_with`] beside the plant.
#[derive(Debug, Default)]
pub struct Options {
    /// Receives the running lines once they are started: their clients (to command a device
    /// beside the poller, as `bridge --demo` does), pollers and simulated lines. These are the
    /// lines started with the bridge: a line a reload stops is stopped under whoever holds it,
    /// and the lines a reload starts are not handed out (the bridge awaits the reply one of
    /// them is owed at the stop itself).
    pub running: Option<oneshot::Sender<Vec<RunningLine>>>,
    /// Questions to the running bridge, each answered with how it is then ([`Live`]): what a
    /// status endpoint shows (`bridge --metrics`), made only when it is asked for.
    pub live: Option<mpsc::Receiver<LiveAsk>>,
    /// Plant files read again, each carried out while the bridge runs ([`Reload`]): its plan
    /// from the running plant, the answer what was done or why nothing was.
    pub reload: Option<mpsc::Receiver<Reload>>,
}

/// A question to the running bridge ([`Options::live`]): how it is now.
#[derive(Debug)]
pub struct LiveAsk {
    /// Whether the answer carries every point's latest reading (a status page) or leaves
    /// them out (the metrics and the health, which count).
    pub readings: bool,
    /// Where the answer goes.
    pub answer: oneshot::Sender<Live>,
}

/// A running bridge as it is now ([`Options::live`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Live {
    /// What it has done so far, its lines' polls included.
    pub report: Report,
    /// Records waiting in the store.
    pub stored_now: u64,
    /// Whether a session with the broker is up.
    pub online: bool,
    /// Every point's latest reading, if they were asked for ([`LiveAsk::readings`]).
    pub readings: Vec<crate::edge::Reading>,
}

/// Runs the bridge of `plant` until `stop` completes; `events`, if given, hears what happens
/// as it happens (never waited for: a full channel loses the status, not the bridge's time).
pub async fn run(
    plant: Plant,
    stop: impl Future<Output = ()>,
    events: Option<mpsc::Sender<Status>>,
) -> Result<Report, RunError> {
    run_with(plant, stop, events, Options::default()).await
}

/// [`run`], with [`Options`].
pub async fn run_with(
    plant: Plant,
    stop: impl Future<Output = ()>,
    events: Option<mpsc::Sender<Status>>,
    options: Options,
) -> Result<Report, RunError> {
    let mut bridge = Bridge::start(plant, events).await?;
    if let Some(running) = options.running {
        let _ = running.send(bridge.lines.iter().map(|l| l.running.clone()).collect());
    }
    bridge.live = options.live;
    bridge.reloads = options.reload;
    bridge.serve(stop).await;
    Ok(bridge.finish().await)
}

/// A started line and what the bridge keeps of its devices.
struct LineState {
    running: RunningLine,
    map: GroupMap,
    /// Each device's writes waiting for the bus.
    writes: Vec<DeviceWrites>,
    /// What its events are tagged with: never another line's in the bridge's life.
    tag: usize,
    /// Dropped with the line: a listen line stops listening.
    _stop: watch::Sender<()>,
}

/// A write a command asks for: the device's group and cell, the raw value, the value as typed.
type Asked = (usize, usize, ferrobus_tools::poll::Value, String);

struct Bridge {
    plant: Plant,
    edge: Edge,
    store: Store,
    session: Session,
    broker: String,
    bd_seq_file: Option<BdSeqFile>,
    lines: Vec<LineState>,
    /// The lines' events, by line tag.
    samples: mpsc::Receiver<(usize, Event)>,
    /// Kept for the lines a reload starts.
    samples_tx: mpsc::Sender<(usize, Event)>,
    /// The tag of the next line started.
    next_tag: usize,
    /// The lines started with the bridge (tags below this), handed out by [`Options::running`].
    handed: usize,
    /// Reloads carried out so far: a write's result names its device as it was then.
    epoch: u64,
    /// Per reload (the latest last, a few kept): each running line's index after it, if it
    /// went on, so that a write's result finds its device.
    moves: VecDeque<Vec<Option<usize>>>,
    reloads: Option<mpsc::Receiver<Reload>>,
    written_tx: mpsc::Sender<(u64, Applied)>,
    written: mpsc::Receiver<(u64, Applied)>,
    events: Option<mpsc::Sender<Status>>,
    backoff: Backoff,
    reconnect_at: Option<Instant>,
    /// When the next batch of stored records may be replayed.
    replay_at: Instant,
    online: bool,
    /// The births of this session have gone out: stored records may follow.
    born: bool,
    /// The store has been replayed in this session (and the edge told).
    replay_done: bool,
    /// Records pushed since the broker was lost, for the status when it is back.
    stored_offline: u64,
    /// Records replayed since the broker came back.
    replayed_now: u64,
    /// New records dropped in a row because the store is full.
    dropping: u64,
    /// The samples taken while the first connection attempt has no outcome: the broker is not
    /// known to be away, so they wait for the CONNACK (then they are live data) or the failure
    /// (then they are stored). `None` once the first attempt has its outcome.
    held: Option<VecDeque<(usize, Event)>>,
    report: Report,
    /// A status endpoint's questions: how the bridge is now.
    live: Option<mpsc::Receiver<LiveAsk>>,
}

impl Bridge {
    async fn start(plant: Plant, events: Option<mpsc::Sender<Status>>) -> Result<Bridge, RunError> {
        let store = Store::open(plant.store.clone())?;
        let session = Session::start(broker::options(&plant.broker)?);
        let broker = broker::describe(&plant.broker);
        let mut edge = Edge::new(&plant);
        let (samples_tx, samples) = mpsc::channel(1024);
        let (written_tx, written) = mpsc::channel(64);
        let mut lines = Vec::with_capacity(plant.lines.len());
        for (index, spec) in plant.lines.iter().enumerate() {
            let (stop, stopped) = watch::channel(());
            let (running, map) = lines::start(index, spec, samples_tx.clone(), stopped).await?;
            let writes = vec![DeviceWrites::default(); spec.devices.len()];
            lines.push(LineState { running, map, writes, tag: index, _stop: stop });
        }
        let report = Report::new(&plant, store.stats().recovered);
        let (bd_seq_file, note) = restore_bd_seq(&plant, &mut edge);
        let mut bridge = Bridge {
            bd_seq_file,
            backoff: Backoff::new(plant.broker.reconnect),
            plant,
            edge,
            store,
            session,
            broker,
            next_tag: lines.len(),
            handed: lines.len(),
            lines,
            samples,
            samples_tx,
            epoch: 0,
            moves: VecDeque::new(),
            reloads: None,
            written_tx,
            written,
            events,
            reconnect_at: None,
            replay_at: Instant::now(),
            online: false,
            born: false,
            replay_done: false,
            stored_offline: 0,
            replayed_now: 0,
            dropping: 0,
            held: Some(VecDeque::new()),
            report,
            live: None,
        };
        if let Some(note) = note {
            bridge.say(Status::Note(note));
        }
        let devices = bridge.plant.lines.iter().map(|l| l.devices.len()).sum();
        bridge.say(Status::Started { lines: bridge.lines.len(), devices, broker: bridge.broker.clone() });
        if !bridge.store.is_empty() {
            bridge.say(Status::Recovered { records: bridge.store.len() });
        }
        bridge.say(Status::Connecting { broker: bridge.broker.clone() });
        bridge.connect();
        Ok(bridge)
    }

    /// Loops until `stop`.
    async fn serve(&mut self, stop: impl Future<Output = ()>) {
        tokio::pin!(stop);
        loop {
            let reconnect_at = self.reconnect_at;
            let replaying = self.online && self.born && !self.store.is_empty();
            tokio::select! {
                biased;
                () = &mut stop => return,
                event = self.session.next() => match event {
                    Some(event) => self.on_session(event),
                    None => return,
                },
                // Before the samples: a steady flow of them does not keep a question waiting.
                Some(ask) = next_of(&mut self.live) => self.answer_live(ask),
                Some((line, event)) = self.samples.recv() => self.take_poll(line, event),
                Some((epoch, applied)) = self.written.recv() => self.on_applied(epoch, applied),
                Some(reload) = next_of(&mut self.reloads) => {
                    let done = self.reload(reload.plant).await;
                    let _ = reload.done.send(done);
                }
                () = sleep_until(reconnect_at), if reconnect_at.is_some() => {
                    self.reconnect_at = None;
                    self.connect();
                }
                // A deadline kept across turns: a steady flow of samples does not put it off.
                () = tokio::time::sleep_until(self.replay_at), if replaying => {
                    self.replay();
                    self.replay_at = Instant::now() + REPLAY_PACE;
                }
            }
        }
    }

    /// Answers a question of [`Options::live`]: the report so far with the lines' polls, and
    /// the readings if asked for (formatting every point's value is the costly part).
    fn answer_live(&self, ask: LiveAsk) {
        let mut report = self.report.clone();
        report.finish(&self.counters(), &self.store);
        let readings = if ask.readings { self.edge.readings() } else { Vec::new() };
        let now = Live { report, stored_now: self.store.len(), online: self.online, readings };
        // Whoever asked may have stopped waiting.
        let _ = ask.answer.send(now);
    }

    /// Each line's poll counters, group by group (none for a listen line).
    fn counters(&self) -> Vec<Vec<ferrobus_tools::poll::Counters>> {
        self.lines
            .iter()
            .map(|l| l.running.poll.as_ref().map(ferrobus_tools::poll::PollHandle::counters).unwrap_or_default())
            .collect()
    }

    /// Ends the session (NDEATH, DISCONNECT, waiting a while for it to go out): at a stop,
    /// and when a reload changes the broker.
    async fn close_session(&mut self) {
        self.release_held();
        if self.online {
            if let Some(death) = self.edge.shutdown(SystemTime::now()) {
                self.publish(death);
            }
            self.session.disconnect();
            let closed = tokio::time::timeout(CLOSE_WAIT, async {
                while let Some(event) = self.session.next().await {
                    if matches!(event, SessionEvent::Closed | SessionEvent::Lost(_)) {
                        return;
                    }
                }
            });
            if closed.await.is_err() {
                tracing::warn!("the broker did not take the DISCONNECT within {CLOSE_WAIT:?}");
            }
        }
        self.went_offline();
    }

    /// Stops: NDEATH, DISCONNECT, the pollers; the report.
    async fn finish(mut self) -> Report {
        self.say(Status::Stopping);
        self.close_session().await;
        for poll in self.lines.iter().filter_map(|l| l.running.poll.as_ref()) {
            poll.stop();
        }
        // The lines a reload started were never handed out ([`Options::running`]): the reply
        // one of them is still owed is awaited here, so that it reaches no one else.
        let started = self.lines.iter().filter(|l| l.tag >= self.handed && l.running.sim.is_none());
        let releases: Vec<ferrobus::Release> =
            started.filter_map(|l| l.running.client.as_ref().map(ferrobus::Client::release)).collect();
        for release in releases {
            release.settled().await;
        }
        self.end_drop_burst();
        let mut report = std::mem::take(&mut self.report);
        report.finish(&self.counters(), &self.store);
        // What is left in memory goes to disk for the next run (if the store has a folder).
        if let Err(e) = self.store.close() {
            report.store_errors += 1;
            tracing::warn!("closing the store: {e}");
        }
        report
    }

    /// Asks the session to connect with the edge's Will, keeping its bdSeq first.
    fn connect(&mut self) {
        let will = self.edge.will();
        if let Some(file) = &self.bd_seq_file {
            let bd_seq = self.edge.bd_seq();
            if let Err(e) = file.write(bd_seq) {
                tracing::warn!("keeping bdSeq {bd_seq} in {}: {e}", file.path().display());
            }
        }
        self.session.connect(will.as_ref());
    }

    fn on_session(&mut self, event: SessionEvent) {
        match event {
            SessionEvent::Connected => self.on_connected(),
            SessionEvent::Message { topic, payload } => self.on_message(&topic, &payload),
            SessionEvent::Oversized { topic, bytes } => {
                self.report.discarded += 1;
                self.say(Status::Discarded { topic, bytes, limit: mqtt::MAX_MESSAGE });
            }
            SessionEvent::Lost(error) => self.on_lost(error),
            SessionEvent::Closed => {
                // A Reconnect action's DISCONNECT: connect again at once with the next bdSeq.
                self.went_offline();
                self.connect();
            }
        }
    }

    fn on_connected(&mut self) {
        self.online = true;
        self.born = false;
        self.backoff.reset();
        self.report.connections += 1;
        self.say(Status::Connected { broker: self.broker.clone() });
        for (filter, qos) in self.edge.subscriptions() {
            if let Err(e) = self.session.subscribe(&filter, qos) {
                tracing::warn!("{e}");
            }
        }
        self.replayed_now = 0;
        let births = self.edge.connected(SystemTime::now());
        if matches!(self.plant.mode, Mode::Plain(_)) {
            self.born = true;
            self.announce_replay();
        }
        self.replay_done = false;
        self.publish_all(births);
        self.release_held();
    }

    fn on_lost(&mut self, error: String) {
        let was_online = self.online;
        self.went_offline();
        self.release_held();
        let retry_in = self.backoff.delay();
        self.reconnect_at = Some(Instant::now() + retry_in);
        if was_online {
            self.report.broker_lost += 1;
        }
        self.say(Status::BrokerLost { broker: self.broker.clone(), error, retry_in, was_online });
    }

    fn went_offline(&mut self) {
        if self.online {
            self.edge.disconnected();
        }
        self.online = false;
        self.born = false;
    }

    fn on_message(&mut self, topic: &str, payload: &[u8]) {
        let (publishes, actions, errors) = self.edge.message(topic, payload, SystemTime::now());
        for error in errors {
            self.report.refused += 1;
            self.say(Status::Refused { topic: topic.to_string(), error: error.to_string() });
        }
        self.publish_all(publishes);
        let mut commands: BTreeMap<DeviceRef, Vec<Asked>> = BTreeMap::new();
        for action in actions {
            match action {
                Action::Write { device, group, cell, raw, typed } => {
                    commands.entry(device).or_default().push((group, cell, raw, typed));
                }
                Action::Reconnect => self.reconnect(),
            }
        }
        for (device, writes) in commands {
            let cells: Vec<(usize, usize)> = writes.iter().map(|&(group, cell, ..)| (group, cell)).collect();
            if let Err(error) = self.command(device, writes, topic) {
                self.report.refused += 1;
                // Plain mode answers each `set` on its result topic (Sparkplug publishes nothing).
                let results: Vec<Publish> = cells
                    .into_iter()
                    .flat_map(|(group, cell)| self.edge.written(device, group, cell, Err(error.clone())))
                    .collect();
                self.say(Status::Refused { topic: topic.to_string(), error });
                self.publish_all(results);
            }
        }
    }

    /// The primary host went offline: NDEATH, DISCONNECT, then connect again.
    fn reconnect(&mut self) {
        self.say(Status::Note("the primary host is offline: reconnecting".into()));
        if let Some(death) = self.edge.shutdown(SystemTime::now()) {
            self.publish(death);
        }
        self.session.disconnect();
    }

    /// One command's writes to `device`: every one resolved and checked, and the device's
    /// queue bound kept, before any is written (else the command is refused whole, with why);
    /// then, in a task of its own, the write guard ([`command::guard`], which reads the run
    /// state for a run-locked point) over all of them, and written in order unless it refuses,
    /// each in the one request [`PollHandle::write_raw`](ferrobus_tools::poll::PollHandle::write_raw)
    /// chooses with the profile's functions and limit;
    /// the task's [`Applied`] comes back on `written`.
    fn command(&mut self, device: DeviceRef, writes: Vec<Asked>, topic: &str) -> Result<(), String> {
        let name = self.device_name(device);
        let spec = self.plant.lines.get(device.line).and_then(|l| l.devices.get(device.device));
        let guarded = spec.and_then(|d| Some((d.profile.clone()?, d.unit)));
        let line = self.lines.get_mut(device.line).ok_or_else(|| format!("{name}: no such line"))?;
        let (Some(poll), Some(client)) = (line.running.poll.clone(), line.running.client.clone()) else {
            return Err(format!(
                "{name} is on line {:?}, which only listens (mode = \"listen\"): it never transmits, so nothing is written",
                line.running.name
            ));
        };
        let mut resolved = Vec::with_capacity(writes.len());
        for (group, cell, raw, typed) in writes {
            let index = line.map.poller_group(device.device, group);
            let found = index.and_then(|i| Some((i, poll.groups().get(i)?.cells.get(cell)?.clone())));
            let Some((index, target)) = found else {
                return Err(format!("{name}: no cell {cell} in group {group}: nothing written"));
            };
            target.point.check_write(&raw, &typed).map_err(|e| format!("{name}: {e}: nothing written"))?;
            resolved.push(BusWrite { group, cell, index, raw, typed, point: target.name, target: target.point });
        }
        let queue = line.writes.get_mut(device.device).ok_or_else(|| format!("{name}: no such device"))?;
        queue.admit(resolved.len()).map_err(|why| format!("{name}: {why}: nothing written"))?;
        let (turn, tx, topic) = (Arc::clone(&queue.turn), self.written_tx.clone(), topic.to_string());
        let epoch = self.epoch;
        tokio::spawn(async move {
            let _turn = turn.lock().await;
            if let Some((profile, unit)) = &guarded
                && let Err(refusal) = command::guard(&client, *unit, profile, &resolved).await
            {
                let why = format!("{name}: {refusal}: nothing written");
                let refused = Applied { device, tried: Vec::new(), not_written: resolved, refused: Some((topic, why)) };
                let _ = tx.send((epoch, refused)).await;
                return;
            }
            let profile = guarded.map(|(profile, _)| profile);
            let applied = command::apply(device, resolved, |w| {
                let (poll, index, cell, raw, profile) = (poll.clone(), w.index, w.cell, w.raw.clone(), profile.clone());
                async move { poll.write_raw(profile.as_deref(), index, cell, &raw).await.map_err(|e| e.to_string()) }
            })
            .await;
            let _ = tx.send((epoch, applied)).await;
        });
        Ok(())
    }

    /// A command's writes are done: a status line per write tried, the edge told of each (plain
    /// mode's results; a write not tried as failed), and one line saying exactly what was and
    /// was not written if the bus failed one midway.
    fn on_applied(&mut self, epoch: u64, mut applied: Applied) {
        let Some(device) = self.moved(epoch, applied.device) else {
            tracing::info!("a write's result came after a reload stopped its device: {} writes", applied.tried.len());
            return;
        };
        applied.device = device;
        let name = self.device_name(device);
        let count = applied.tried.len() + applied.not_written.len();
        if let Some(queue) = self.lines.get_mut(device.line).and_then(|l| l.writes.get_mut(device.device)) {
            queue.done(count);
        }
        if let Some((topic, error)) = applied.refused {
            self.report.refused += 1;
            let results: Vec<Publish> = applied
                .not_written
                .iter()
                .flat_map(|w| self.edge.written(device, w.group, w.cell, Err(error.clone())))
                .collect();
            self.say(Status::Refused { topic, error });
            self.publish_all(results);
            return;
        }
        let incomplete = applied.incomplete();
        let mut publishes = Vec::new();
        for (w, result) in applied.tried {
            if result.is_ok() {
                self.report.writes += 1;
            } else {
                self.report.write_failures += 1;
            }
            self.say(Status::Written { device: name.clone(), point: w.point, value: w.typed, result: result.clone() });
            publishes.extend(self.edge.written(device, w.group, w.cell, result));
        }
        for w in applied.not_written {
            let why = "not written: an earlier write of the same command failed".to_string();
            publishes.extend(self.edge.written(device, w.group, w.cell, Err(why)));
        }
        if let Some((written, failed, error, not_written)) = incomplete {
            self.say(Status::Incomplete { device: name, written, failed, error, not_written });
        }
        self.publish_all(publishes);
    }

    /// A poller's event: held while the first connection attempt has no outcome (up to
    /// [`HOLD_LIMIT`]), else handled.
    fn take_poll(&mut self, line: usize, event: Event) {
        match &mut self.held {
            Some(held) if held.len() < HOLD_LIMIT => held.push_back((line, event)),
            Some(_) => {
                self.release_held();
                self.on_poll(line, event);
            }
            None => self.on_poll(line, event),
        }
    }

    /// The first connection attempt has its outcome (or is taking too long, or the bridge
    /// stops): the held samples are handled in order, live after a CONNACK, stored otherwise.
    fn release_held(&mut self) {
        for (line, event) in self.held.take().unwrap_or_default() {
            self.on_poll(line, event);
        }
    }

    fn on_poll(&mut self, tag: usize, event: Event) {
        // A line a reload stopped names no line now.
        let Some(line) = self.line_of(tag) else { return };
        match event {
            Event::Sample(sample) => self.on_sample(line, &sample),
            Event::Overload(overload) => {
                let name = self.lines.get(line).map(|l| l.running.name.clone()).unwrap_or_default();
                self.say(Status::Overload { line: name, detail: overload.detail });
            }
        }
    }

    fn on_sample(&mut self, line: usize, sample: &Sample) {
        let Some((device, group)) = self.lines.get(line).and_then(|l| l.map.device(line, sample.group)) else {
            return;
        };
        let outputs = self.edge.sample(device, group, sample);
        self.say_health(device, sample);
        let mut messages = Vec::new();
        for output in outputs {
            match output {
                Output::Publish(message) => messages.push(message),
                Output::Store(record) => self.keep(record),
            }
        }
        if !messages.is_empty() {
            self.publish_all(messages);
        }
    }

    /// Says when a device stops answering (`death_after` polls in a row without a reply)
    /// and when it is back: what the edge's one liveness state made of the sample it took.
    fn say_health(&mut self, device: DeviceRef, sample: &Sample) {
        let Some(liveness) = self.edge.liveness(device) else { return };
        if let Some(status) = health_status(liveness, sample, || self.device_name(device)) {
            self.say(status);
        }
    }

    fn device_name(&self, device: DeviceRef) -> String {
        self.plant
            .lines
            .get(device.line)
            .and_then(|l| l.devices.get(device.device))
            .map_or_else(|| format!("device {}/{}", device.line, device.device), |d| d.id.clone())
    }

    /// Keeps a record for the broker's return.
    fn keep(&mut self, record: Vec<u8>) {
        match self.store.push(record) {
            Ok(Pushed::Dropped) => {
                if self.dropping == 0 {
                    tracing::warn!("the store is full: new samples are dropped until the broker is back");
                }
                self.dropping += 1;
            }
            Ok(_) => {
                self.end_drop_burst();
                if self.stored_offline == 0 {
                    self.say(Status::Storing { connected: self.online });
                }
                self.stored_offline += 1;
                self.report.stored += 1;
            }
            Err(e) => self.store_error(&e),
        }
    }

    /// Says how many records a burst of drops lost, once it is over.
    fn end_drop_burst(&mut self) {
        if self.dropping > 0 {
            let records = std::mem::take(&mut self.dropping);
            self.report.dropped += records;
            self.say(Status::Dropped { records });
        }
    }

    fn store_error(&mut self, error: &StoreError) {
        self.report.store_errors += 1;
        if self.report.store_errors.is_power_of_two() {
            self.say(Status::StoreError { error: error.to_string(), count: self.report.store_errors });
        }
    }

    /// Publishes the oldest stored records, as historical data, a batch at a time.
    fn replay(&mut self) {
        self.end_drop_burst();
        for _ in 0..REPLAY_BATCH {
            if self.session.queued() >= REPLAY_QUEUE_LIMIT {
                return;
            }
            let record = match self.store.front() {
                Ok(Some(record)) => record,
                Ok(None) => break,
                Err(e) => {
                    self.store_error(&e);
                    // A record that cannot be read is passed over, not retried for ever.
                    if let Err(e) = self.store.pop() {
                        self.store_error(&e);
                        return;
                    }
                    continue;
                }
            };
            match self.edge.replay_all(&record, SystemTime::now()) {
                Ok(messages) if messages.is_empty() => self.report.unreplayable += 1,
                Ok(messages) => {
                    self.report.replayed += 1;
                    self.replayed_now += 1;
                    self.publish_all(messages);
                }
                // Births not out (a primary host went away meanwhile): keep it for later.
                Err(EdgeError::Offline) => return,
                Err(e) => {
                    self.report.unreplayable += 1;
                    tracing::warn!("a stored record cannot be replayed: {}", ferrobus::log::escape(&e.to_string()));
                }
            }
            if let Err(e) = self.store.pop() {
                self.store_error(&e);
                return;
            }
        }
        self.check_replayed();
    }

    /// Once the births are out and the store is empty: says so, and publishes the DDEATHs the
    /// edge held back for the devices born only so that their history resolves.
    fn check_replayed(&mut self) {
        if !self.born || self.replay_done || !self.store.is_empty() {
            return;
        }
        self.replay_done = true;
        if self.replayed_now > 0 {
            let records = std::mem::take(&mut self.replayed_now);
            self.say(Status::Replayed { records });
        }
        let deaths = self.edge.replayed(SystemTime::now());
        self.publish_all(deaths);
    }

    /// Says, once the births are out, how many records were stored since the last ones.
    fn announce_replay(&mut self) {
        if self.stored_offline > 0 {
            let records = std::mem::take(&mut self.stored_offline);
            self.say(Status::Replaying { records, queued: self.store.len() });
        }
    }

    fn publish_all(&mut self, messages: Vec<Publish>) {
        let mut node = false;
        let mut devices = Vec::new();
        for message in messages {
            match Topic::parse(&message.topic) {
                Some(Topic { kind: MessageType::NBirth, .. }) => node = true,
                Some(Topic { kind: MessageType::DBirth, device: Some(device), .. }) => devices.push(device),
                _ => {}
            }
            self.publish(message);
        }
        if node {
            self.born = true;
        }
        if node || !devices.is_empty() {
            self.say(Status::Births { node, devices });
        }
        if node {
            self.announce_replay();
        }
        self.check_replayed();
    }

    fn publish(&mut self, message: Publish) {
        let kind = kind_of(&message.topic);
        match self.session.publish(message) {
            Ok(()) => *self.report.published.entry(kind).or_default() += 1,
            Err(e) => {
                self.report.unsent += 1;
                if self.report.unsent.is_power_of_two() {
                    tracing::warn!("{kind} not sent: {e} ({} so far)", self.report.unsent);
                }
            }
        }
    }

    fn say(&self, status: Status) {
        tracing::debug!("{status}");
        if let Some(events) = &self.events {
            let _ = events.try_send(status);
        }
    }
}

/// Reads the last run's bdSeq into `edge` (Sparkplug only): the file to keep it in, and a
/// note if the file could not be used.
fn restore_bd_seq(plant: &Plant, edge: &mut Edge) -> (Option<BdSeqFile>, Option<String>) {
    let Mode::Sparkplug(spb) = &plant.mode else { return (None, None) };
    let Some(file) = BdSeqFile::locate(plant.store.dir.as_deref(), &spb.group_id, &spb.edge_node_id) else {
        return (None, Some("no state directory on this platform: bdSeq starts at 0 at each start".into()));
    };
    let note = match file.read() {
        Stored::Last(last) => {
            edge.set_bd_seq(state::next(last));
            None
        }
        Stored::None => None,
        Stored::Unusable(why) => Some(format!("{why}; bdSeq starts again at 0")),
    };
    (Some(file), note)
}

/// The status line, if any, of what `sample` did to the liveness of the device `name` gives:
/// it stopped answering (or never did), or it answers again (or at last).
fn health_status(liveness: Liveness, sample: &Sample, name: impl FnOnce() -> String) -> Option<Status> {
    match liveness {
        Liveness::Silent { died, given_up, polls } if died || given_up => {
            let why = sample.result.as_ref().err().map(|f| f.diagnosis.clone()).unwrap_or_default();
            Some(Status::DeviceDead { device: name(), polls, why, never_answered: given_up })
        }
        Liveness::Answered { revived: true, first, .. } => Some(Status::DeviceBack { device: name(), first }),
        Liveness::Answered { .. } | Liveness::Silent { .. } => None,
    }
}

/// The kind of message on `topic`, for the counts: `NBIRTH`, `DDATA`, ... or `plain`.
fn kind_of(topic: &str) -> String {
    Topic::parse(topic).map_or_else(
        || if topic.ends_with("/result") { "result".into() } else { "plain".into() },
        |t| t.kind.as_str().to_string(),
    )
}

/// The next plant file to carry out or question to answer; never, without a channel (or
/// once it is closed).
async fn next_of<T>(channel: &mut Option<mpsc::Receiver<T>>) -> Option<T> {
    match channel {
        Some(rx) => {
            let next = rx.recv().await;
            if next.is_none() {
                *channel = None;
            }
            next
        }
        None => std::future::pending().await,
    }
}

async fn sleep_until(at: Option<Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

#[cfg(test)]
mod tests;
