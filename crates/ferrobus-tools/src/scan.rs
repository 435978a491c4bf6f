//! The bus scanner: every unit address × every line setting, over one open serial port.
//!
//! The decisions — the order of the settings, the probe, its timeouts, what a probe heard,
//! what listening heard — are made in [`ferrobus_proto::scan`]; this module does the IO:
//!
//! 1. For each line setting (each step below), in the order given (sort with [`rank`](ferrobus_proto::scan::rank)
//!    for the likeliest first), the open port is **reconfigured in place**
//!    ([`Reconfigure`]): it is never closed and opened again, so its path cannot come to name
//!    another device halfway through.
//! 2. **Listen first** (when [`ScanConfig::listen`] is not zero): before anything is sent, the
//!    port is read at every setting in turn without transmitting (the core's listener on the
//!    one loop, [`Pump`], as every other role); CRC-valid frames mean another
//!    master is active at that setting. It is reported with the units it talks to, and then
//!    nothing is transmitted at all unless [`ScanConfig::force`]. (Bytes that never frame are
//!    reported as noise: something talks at other settings.)
//! 3. Each unit gets the probe through an ordinary [`Client`] (the one driver loop and master
//!    engine, its t3.5 gaps and its diagnosis of what came instead of a reply), which is lent
//!    the port for the one setting and gives it back when dropped. Any reply or exception
//!    proves a device; broken bytes are a lead; a unit found is identified (FC2B/0E basic
//!    objects, FC11 as a fallback) at the slow timeout.
//! 4. A **second pass** probes every lead again at its setting with the slow first-byte wait
//!    and one retry.
//!
//! Progress comes as [`Event`]s; the [`Report`] is filled in as the scan goes, so a caller
//! that stops the scan (Ctrl-C) still has what was found. Units are 1–247 only: a scan never
//! broadcasts, and its probe is a read.

use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll};
use std::time::Duration;

use ferrobus_proto::codes::{ExceptionCode, ReadDeviceIdCode, unit as unit_codes};
use ferrobus_proto::frame::{LineConfig, LineTiming, rtu};
use ferrobus_proto::scan::{Answer, Lead, LineActivity, Probe, ProbeTiming, Survey};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::sync::Notify;

use ferrobus::port::{BoxPort, Connecting, Connector, PC_INCOMPLETE_TIMEOUT, Port, TtyPort};
use ferrobus::pump::{Pump, Session};
use ferrobus::{Client, ClientConfig, Error, Framing, Rs485, Timer, Transport};

/// A port whose line settings can be changed while it is open.
pub trait Reconfigure: Port {
    /// Sets `line` on the open port, and drops what it received at the settings before: those
    /// bytes are no traffic of the new ones (a frame that came whole at 19200 is no frame heard
    /// at 9600).
    fn reconfigure(&mut self, line: LineConfig) -> io::Result<()>;
}

impl Reconfigure for TtyPort {
    fn reconfigure(&mut self, line: LineConfig) -> io::Result<()> {
        TtyPort::reconfigure(self, line)?;
        let dropped = self.discard_input()?;
        if dropped > 0 {
            tracing::debug!(dropped, "bytes received before {line} dropped");
        }
        Ok(())
    }
}

/// What to scan and how.
#[derive(Clone, Debug)]
pub struct ScanConfig {
    /// The unit addresses, 1–247 (others are refused by [`Scanner::new`]).
    pub units: Vec<u8>,
    /// The line settings, in the order to try them.
    pub lines: Vec<LineConfig>,
    /// What each unit is sent.
    pub probe: Probe,
    /// The wait for a reply's first byte in the first pass.
    pub first_byte: Duration,
    /// The wait for a reply's first byte in the second pass (leads) and for identification.
    pub slow_first_byte: Duration,
    /// How long to listen before transmitting at each setting (zero: not at all).
    pub listen: Duration,
    /// Transmit even where another master was heard.
    pub force: bool,
    /// Identify each device found (FC2B/0E, FC11).
    pub identify: bool,
    /// Transmitter direction control.
    pub rs485: Rs485,
    /// Drop our own transmission when the adapter hears it.
    pub echo_suppression: bool,
    /// How deadlines are waited for: [`Timer::Precise`] on a real port, [`Timer::Tokio`]
    /// under a paused test clock.
    pub timer: Timer,
    /// t1.5 and t3.5 overrides, for every setting.
    pub t1_5: Option<Duration>,
    /// See `t1_5`.
    pub t3_5: Option<Duration>,
}

/// A device found.
#[derive(Clone, Debug)]
pub struct Device {
    /// Its address.
    pub unit: u8,
    /// The line setting it answered at.
    pub line: LineConfig,
    /// What it answered the probe: a reply, an exception, or a frame that does not answer it.
    pub answer: Answer,
    /// From the end of the request to the start of the reply, as the PC saw it: the device's
    /// t3.5 and response wait, plus the adapter's and the OS's latency.
    pub response_time: Duration,
    /// Whether it was found only in the second pass.
    pub second_pass: bool,
    /// Its identification, if asked for.
    pub identification: Option<Identification>,
}

/// What a device said about itself.
#[derive(Clone, PartialEq, Eq, Debug)]
pub enum Identification {
    /// FC2B/0E basic objects (0x00 VendorName, 0x01 ProductCode, 0x02 MajorMinorRevision).
    Objects(Vec<(u8, Vec<u8>)>),
    /// FC11 Report Server ID data (FC2B/0E was refused).
    ServerId(Vec<u8>),
    /// Neither: why, for each.
    Refused {
        /// What FC2B/0E got.
        device_id: String,
        /// What FC11 got.
        server_id: String,
    },
}

impl Identification {
    /// An object's value as text, if it is printable UTF-8.
    pub fn object(&self, id: u8) -> Option<&str> {
        let Identification::Objects(objects) = self else { return None };
        let (_, value) = objects.iter().find(|(i, _)| *i == id)?;
        let text = std::str::from_utf8(value).ok()?;
        text.chars().all(|c| !c.is_control()).then_some(text)
    }
}

/// A unit that gave a lead: bytes that did not frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct LeadFound {
    /// The unit probed.
    pub unit: u8,
    /// The setting.
    pub line: LineConfig,
    /// What came in the first pass.
    pub lead: Lead,
    /// What the second, slower pass heard (`None` until it ran).
    pub second: Option<Answer>,
}

/// A valid frame from another unit, heard while probing one: another master, or a device that
/// answers for another address.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct OtherTraffic {
    /// The setting.
    pub line: LineConfig,
    /// The unit probed.
    pub probed: u8,
    /// The unit whose frame came.
    pub unit: u8,
    /// Its function code.
    pub function: u8,
}

/// Another master heard while listening.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct OtherMaster {
    /// The setting its frames were valid at.
    pub line: LineConfig,
    /// What was heard (always [`LineActivity::Traffic`]).
    pub heard: LineActivity,
}

/// What a scan found so far.
#[derive(Clone, Debug, Default)]
pub struct Report {
    /// Devices, in the order found.
    pub devices: Vec<Device>,
    /// Leads, in the order found.
    pub leads: Vec<LeadFound>,
    /// Valid frames from other units heard while probing.
    pub other_traffic: Vec<OtherTraffic>,
    /// Other masters heard while listening.
    pub masters: Vec<OtherMaster>,
    /// Settings where listening heard only bytes that did not frame.
    pub noise: Vec<(LineConfig, LineActivity)>,
    /// Settings probed.
    pub settings_done: usize,
    /// Probes sent.
    pub probes: u64,
    /// Whether nothing was transmitted because another master was heard.
    pub held_back: bool,
    /// Whether the scan ran to its end, held back or not (false while running, and when
    /// stopped early).
    pub complete: bool,
}

/// Progress, for a progress bar or a log.
#[derive(Clone, Copy, Debug)]
pub enum Event {
    /// Listening at a setting, or probing there, begins.
    Setting {
        /// It.
        line: LineConfig,
        /// How many came before it.
        index: usize,
    },
    /// Listening at a setting ended.
    Listened {
        /// The setting.
        line: LineConfig,
        /// What was heard.
        heard: LineActivity,
    },
    /// One probe ended.
    Probed {
        /// The setting.
        line: LineConfig,
        /// The unit.
        unit: u8,
        /// What it heard.
        answer: Answer,
        /// Whether in the second pass.
        second_pass: bool,
    },
    /// The second pass begins, over this many leads.
    SecondPass {
        /// How many.
        leads: usize,
    },
}

/// Why [`Scanner::new`] refused a configuration.
#[derive(Clone, Copy, PartialEq, Eq, Debug, thiserror::Error)]
pub enum ConfigError {
    /// A unit outside 1–247: 0 is a broadcast, 248–255 are reserved.
    #[error("unit {0} cannot be scanned: units are 1-247 ({why})", why = unit_refusal(*.0))]
    Unit(u8),
    /// No units.
    #[error("no units to scan")]
    NoUnits,
    /// No line settings.
    #[error("no line settings to scan")]
    NoLines,
}

fn unit_refusal(unit: u8) -> &'static str {
    if unit == unit_codes::BROADCAST { "0 is a broadcast, which nothing answers" } else { "248-255 are reserved" }
}

/// The open port, lent to one client at a time and given back when the client's driver drops
/// it.
struct Home<P> {
    slot: Mutex<Option<P>>,
    back: Notify,
}

/// How long to wait for a client's driver to give the port back after the client is dropped.
const RETURN_WAIT: Duration = Duration::from_secs(5);

/// A scan over one open port.
pub struct Scanner<P> {
    config: ScanConfig,
    home: Arc<Home<P>>,
    name: String,
}

impl<P: Reconfigure> Scanner<P> {
    /// A scanner of `port` (named `name` in errors) with `config`. Refuses units outside
    /// 1–247 (0 is a broadcast, 248–255 reserved) and an empty list of units or settings.
    pub fn new(port: P, name: impl Into<String>, config: ScanConfig) -> Result<Self, ConfigError> {
        if let Some(&bad) = config.units.iter().find(|&&u| !(unit_codes::MIN..=unit_codes::MAX).contains(&u)) {
            return Err(ConfigError::Unit(bad));
        }
        if config.units.is_empty() {
            return Err(ConfigError::NoUnits);
        }
        if config.lines.is_empty() {
            return Err(ConfigError::NoLines);
        }
        let home = Arc::new(Home { slot: Mutex::new(Some(port)), back: Notify::new() });
        Ok(Scanner { config, home, name: name.into() })
    }

    /// The settings.
    pub fn config(&self) -> &ScanConfig {
        &self.config
    }

    /// How many probes the first pass sends (without the second pass, which depends on leads).
    pub fn first_pass_probes(&self) -> u64 {
        let n = self.config.units.len().saturating_mul(self.config.lines.len());
        u64::try_from(n).unwrap_or(u64::MAX)
    }

    /// A client over the scanner's port at `line`, waiting `timeout` for a reply, with one
    /// retry: for going on with a device the scan found (walking its SunSpec models, say)
    /// without closing the port. The port comes back to the scanner when the client is
    /// dropped; a second client waits for that.
    pub async fn client_at(&self, line: LineConfig, timeout: Duration) -> Result<Client, Error> {
        self.reconfigure(line).await?;
        self.lend(line, timeout, 1).await
    }

    /// Runs the scan, filling in `report` as it goes and telling `on_event` each step. An IO
    /// error on the port ends it (the report keeps what was found).
    pub async fn run(&mut self, report: &mut Report, mut on_event: impl FnMut(&Event)) -> Result<(), Error> {
        let lines = self.config.lines.clone();
        if !self.config.listen.is_zero() {
            for (index, &line) in lines.iter().enumerate() {
                on_event(&Event::Setting { line, index });
                self.reconfigure(line).await?;
                let heard = self.listen(line).await?;
                on_event(&Event::Listened { line, heard });
                match heard {
                    LineActivity::Traffic { .. } => report.masters.push(OtherMaster { line, heard }),
                    LineActivity::Noise { .. } => report.noise.push((line, heard)),
                    LineActivity::Quiet => {}
                }
            }
            if !report.masters.is_empty() && !self.config.force {
                report.held_back = true;
                report.complete = true;
                return Ok(());
            }
        }
        for (index, &line) in lines.iter().enumerate() {
            on_event(&Event::Setting { line, index });
            self.reconfigure(line).await?;
            self.sweep(line, report, &mut on_event).await?;
            report.settings_done = report.settings_done.saturating_add(1);
        }
        self.second_pass(report, &mut on_event).await?;
        report.complete = true;
        Ok(())
    }

    async fn sweep(
        &self,
        line: LineConfig,
        report: &mut Report,
        on_event: &mut impl FnMut(&Event),
    ) -> Result<(), Error> {
        let timing = self.timing(line);
        let probe = self.config.probe;
        let wait = ProbeTiming::new(&timing, &probe, self.config.first_byte);
        let client = self.lend(line, wait.timeout(), 0).await?;
        let mut found = Vec::new();
        for &unit in &self.config.units {
            let (answer, response_time) = self.probe(&client, &timing, unit).await?;
            report.probes = report.probes.saturating_add(1);
            on_event(&Event::Probed { line, unit, answer, second_pass: false });
            match answer {
                Answer::Lead(lead) => report.leads.push(LeadFound { unit, line, lead, second: None }),
                Answer::OtherTraffic { unit: heard, function } => {
                    report.other_traffic.push(OtherTraffic { line, probed: unit, unit: heard, function });
                }
                a if a.proves_presence() => {
                    tracing::info!(unit, %line, "unit {unit} answers at {line}");
                    report.devices.push(Device {
                        unit,
                        line,
                        answer,
                        response_time,
                        second_pass: false,
                        identification: None,
                    });
                    found.push(report.devices.len().saturating_sub(1));
                }
                _ => {}
            }
        }
        self.identify(&client, &timing, report, &found).await;
        drop(client);
        Ok(())
    }

    async fn second_pass(&self, report: &mut Report, on_event: &mut impl FnMut(&Event)) -> Result<(), Error> {
        let pending: Vec<usize> = (0..report.leads.len())
            .filter(|&i| {
                report
                    .leads
                    .get(i)
                    .is_some_and(|lead| !report.devices.iter().any(|d| d.unit == lead.unit && d.line == lead.line))
            })
            .collect();
        if pending.is_empty() {
            return Ok(());
        }
        on_event(&Event::SecondPass { leads: pending.len() });
        let mut lines: Vec<LineConfig> = Vec::new();
        for &i in &pending {
            if let Some(lead) = report.leads.get(i)
                && !lines.contains(&lead.line)
            {
                lines.push(lead.line);
            }
        }
        for line in lines {
            self.reconfigure(line).await?;
            let timing = self.timing(line);
            let wait = ProbeTiming::new(&timing, &self.config.probe, self.config.slow_first_byte);
            let client = self.lend(line, wait.timeout(), 1).await?;
            let mut found = Vec::new();
            for &i in &pending {
                let Some(unit) = report.leads.get(i).filter(|l| l.line == line).map(|l| l.unit) else { continue };
                let (answer, response_time) = self.probe(&client, &timing, unit).await?;
                report.probes = report.probes.saturating_add(1);
                on_event(&Event::Probed { line, unit, answer, second_pass: true });
                if let Some(lead) = report.leads.get_mut(i) {
                    lead.second = Some(answer);
                }
                if answer.proves_presence() {
                    report.devices.push(Device {
                        unit,
                        line,
                        answer,
                        response_time,
                        second_pass: true,
                        identification: None,
                    });
                    found.push(report.devices.len().saturating_sub(1));
                }
            }
            self.identify(&client, &timing, report, &found).await;
        }
        Ok(())
    }

    /// Probes `unit` once: what it heard, and the response time of a reply.
    async fn probe(&self, client: &Client, timing: &LineTiming, unit: u8) -> Result<(Answer, Duration), Error> {
        let request = self.config.probe.request().map_err(Error::InvalidRequest)?;
        let started = tokio::time::Instant::now();
        let result = client.request(unit, &request).await;
        let round_trip = started.elapsed();
        let (answer, reply_len) = match result {
            Ok(Some(pdu)) => (Answer::Reply, pdu.len().saturating_add(3)),
            Ok(None) => (Answer::Silence, 0),
            Err(Error::Exception { code, .. }) => (Answer::Exception(code), 5),
            Err(Error::BadReply { .. }) => (Answer::Mismatch, self.config.probe.reply_len()),
            Err(Error::Timeout { heard, .. }) => (Answer::from_heard(heard), 0),
            Err(e) => return Err(e),
        };
        let wires =
            timing.transmit_time(self.config.probe.request_len()).saturating_add(timing.transmit_time(reply_len));
        Ok((answer, round_trip.saturating_sub(wires)))
    }

    /// Identifies the devices at `found` (indexes into the report), at the slow timeout.
    async fn identify(&self, client: &Client, timing: &LineTiming, report: &mut Report, found: &[usize]) {
        if !self.config.identify {
            return;
        }
        let slow = self.config.slow_first_byte.saturating_add(timing.transmit_time(rtu::MAX_ADU_LEN));
        let client = client.with_timeout(slow);
        for &i in found {
            let Some(unit) = report.devices.get(i).map(|d| d.unit) else { continue };
            let identification = identify(&client, unit).await;
            if let Some(device) = report.devices.get_mut(i) {
                device.identification = Some(identification);
            }
        }
    }

    fn timing(&self, line: LineConfig) -> LineTiming {
        let mut timing = LineTiming::new(&line);
        if let Some(t) = self.config.t1_5 {
            timing = timing.with_t1_5(t);
        }
        if let Some(t) = self.config.t3_5 {
            timing = timing.with_t3_5(t);
        }
        timing
    }

    /// Waits for the port to come home, then sets `line` on it.
    async fn reconfigure(&self, line: LineConfig) -> Result<(), Error> {
        let context = || format!("setting {line} on {}", self.name);
        let mut port = self.take().await?;
        let result = port.reconfigure(line);
        self.put(port);
        result.map_err(|e| Error::io(context(), e))
    }

    /// Listens for the configured time without transmitting: the core's listener driven by
    /// the one loop ([`Pump::run`]), as every other role is.
    async fn listen(&self, line: LineConfig) -> Result<LineActivity, Error> {
        let timing = self.timing(line);
        let mut listener = Survey::new(timing).with_frame_gap(timing.t3_5().max(PC_INCOMPLETE_TIMEOUT));
        // Lent, so that the port comes home when listening ends, whatever ended it.
        let mut port: BoxPort = Box::new(Lent { port: Some(self.take().await?), home: Arc::clone(&self.home) });
        let mut pump = Pump::new(self.config.timer.sleeper());
        let mut session = Listening { end: tokio::time::Instant::now() + self.config.listen };
        let result = pump.run(&mut port, &mut listener, &mut session).await;
        drop(port);
        result.map_err(|e| Error::io(format!("listening on {} at {line}", self.name), e))?;
        // A frame still open is decided as if the silence had come.
        if let Some(due) = listener.poll_timeout() {
            listener.handle_timeout(due);
        }
        Ok(listener.heard())
    }

    /// A client at `line` over the port, with `timeout` and `retries`.
    async fn lend(&self, line: LineConfig, timeout: Duration, retries: u32) -> Result<Client, Error> {
        // The port is home (reconfigure or listen gave it back); the connector takes it.
        let connector = Lend { home: Arc::clone(&self.home), name: format!("{} at {line}", self.name) };
        let mut transport = Transport::custom(Framing::Rtu, LineTiming::new(&line), connector)
            .with_rs485(self.config.rs485)
            .with_timer(self.config.timer)
            .with_incomplete_timeout(PC_INCOMPLETE_TIMEOUT)
            .with_reopen(false);
        if let Some(t) = self.config.t1_5 {
            transport = transport.with_t1_5(t);
        }
        if let Some(t) = self.config.t3_5 {
            transport = transport.with_t3_5(t);
        }
        let config = ClientConfig {
            timeout,
            retries,
            backoff: None,
            echo_suppression: self.config.echo_suppression,
            // Probes go to one unit after another: a late reply is another unit's and cannot
            // pass for the probe's, so no line time is spent awaiting it (a late window per
            // absent unit would triple the scan).
            late_window: Some(std::time::Duration::ZERO),
            ..ClientConfig::default()
        };
        Client::connect(transport, config).await
    }

    /// The port, once the last client's driver has given it back.
    async fn take(&self) -> Result<P, Error> {
        let deadline = tokio::time::Instant::now() + RETURN_WAIT;
        loop {
            let notified = self.home.back.notified();
            if let Some(port) = self.home.slot.lock().unwrap_or_else(PoisonError::into_inner).take() {
                return Ok(port);
            }
            if tokio::time::timeout_at(deadline, notified).await.is_err() {
                return Err(Error::io(
                    format!("taking back {}", self.name),
                    io::Error::new(io::ErrorKind::TimedOut, "the client's driver did not give the port back"),
                ));
            }
        }
    }

    fn put(&self, port: P) {
        *self.home.slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(port);
        self.home.back.notify_one();
    }
}

/// FC2B/0E basic objects, or FC11 when that fails.
async fn identify(client: &Client, unit: u8) -> Identification {
    let device_id = match client.read_device_identification(unit, ReadDeviceIdCode::Basic, 0).await {
        Ok(info) => return Identification::Objects(info.objects),
        Err(e) => describe(&e),
    };
    match client.report_server_id(unit).await {
        Ok(data) => Identification::ServerId(data),
        Err(e) => Identification::Refused { device_id, server_id: describe(&e) },
    }
}

fn describe(error: &Error) -> String {
    match error {
        Error::Exception { code, .. } => match code {
            ExceptionCode::IllegalFunction => "exception 0x01 Illegal Function (not supported)".into(),
            other => format!("exception {other}"),
        },
        other => other.to_string(),
    }
}

/// The connector that hands the scanner's port to a client.
struct Lend<P> {
    home: Arc<Home<P>>,
    name: String,
}

impl<P: Reconfigure> Connector for Lend<P> {
    fn connect(&self) -> Connecting {
        let port = self.home.slot.lock().unwrap_or_else(PoisonError::into_inner).take();
        let home = Arc::clone(&self.home);
        Box::pin(async move {
            match port {
                Some(port) => Ok(Box::new(Lent { port: Some(port), home }) as BoxPort),
                None => Err(io::Error::other("the scanner's port is in use by another client")),
            }
        })
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}

/// The port while a client has it; it goes home when dropped.
struct Lent<P: Reconfigure> {
    port: Option<P>,
    home: Arc<Home<P>>,
}

impl<P: Reconfigure> Lent<P> {
    fn port(&mut self) -> io::Result<&mut P> {
        self.port.as_mut().ok_or_else(|| io::Error::other("the port was given back"))
    }
}

impl<P: Reconfigure> Drop for Lent<P> {
    fn drop(&mut self) {
        if let Some(port) = self.port.take() {
            *self.home.slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(port);
            self.home.back.notify_one();
        }
    }
}

impl<P: Reconfigure> AsyncRead for Lent<P> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        match self.port() {
            Ok(port) => Pin::new(port).poll_read(cx, buf),
            Err(e) => Poll::Ready(Err(e)),
        }
    }
}

impl<P: Reconfigure> AsyncWrite for Lent<P> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        match self.port() {
            Ok(port) => Pin::new(port).poll_write(cx, data),
            Err(e) => Poll::Ready(Err(e)),
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match self.port() {
            Ok(port) => Pin::new(port).poll_flush(cx),
            Err(e) => Poll::Ready(Err(e)),
        }
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match self.port() {
            Ok(port) => Pin::new(port).poll_shutdown(cx),
            Err(e) => Poll::Ready(Err(e)),
        }
    }
}

impl<P: Reconfigure> Port for Lent<P> {
    fn set_rts(&mut self, on: bool) -> io::Result<()> {
        self.port()?.set_rts(on)
    }

    fn last_arrival(&self) -> Option<tokio::time::Instant> {
        self.port.as_ref().and_then(Port::last_arrival)
    }
}

/// The listen phase's session: nothing to serve, one deadline (the end of listening).
struct Listening {
    end: tokio::time::Instant,
}

impl Session<Survey> for Listening {
    type Output = io::Result<()>;

    async fn serve(&mut self, _: &Pump, _: &mut BoxPort, _: &mut Survey) -> Option<io::Result<()>> {
        None
    }
    fn deadline(&mut self, _: &Survey) -> Option<tokio::time::Instant> {
        Some(self.end)
    }
    fn on_wake(&mut self) -> Option<io::Result<()>> {
        (tokio::time::Instant::now() >= self.end).then_some(Ok(()))
    }
    fn on_end(&mut self, error: Option<io::Error>) -> io::Result<()> {
        Err(error.unwrap_or_else(|| io::Error::new(io::ErrorKind::UnexpectedEof, "the port closed")))
    }
}
