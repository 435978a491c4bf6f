//! The virtual RS-485 line's wire, sans-IO: what a half-duplex multidrop line does with the
//! characters its endpoints send, on time the caller gives.
//!
//! Nothing here reads a clock, sleeps or does IO: every call takes `now`, and what each
//! endpoint receives comes back with the instant its last character left the wire. The same
//! inputs at the same instants give the same outputs, faults included (they are drawn from
//! [`LineOptions::seed`]). [`line`](crate::line) runs this model on tokio's clock with
//! in-process endpoints and ptys; tests drive it directly, on explicit time.
//!
//! - Every character takes its character time (1.1458 ms at 9600 8E1) and reaches every
//!   other endpoint (and its sender with [`LineOptions::echo`]) when its last bit has left the
//!   wire. [`Wire::advance`] hands out the characters that have left by `now`, one
//!   [`Delivery`] per endpoint and run of back-to-back characters, stamped with the end of
//!   the last; [`Wire::next_wake`] is the end of the next run, so a caller that wakes then
//!   gets every run whole.
//! - Two endpoints transmitting at once collide: the characters that overlap are garbled and
//!   counted.
//! - The silent intervals are watched: a frame begun less than t3.5 after the wire was last
//!   busy counts against its sender ([`EndpointStats::gap_violations`]).
//! - A sniffer on the wire counts the frames it decodes and the byte runs it throws away.
//! - Faults: bit errors, replaced and lost characters, gaps stretched inside a frame, noise
//!   bursts at random times, and endpoints that are dead (deaf and mute).
//! - The wire carries bits, not the line's bytes: each run keeps its sender's settings
//!   ([`Wire::send_at`]; [`Wire::send`] is at the wire's), its characters take the sender's
//!   character time, and each [`Delivery`] says what they were sent at. A receiver hears them
//!   through a bit-level UART model ([`Delivery::heard_by`], [`heard`]): clean at its
//!   sender's settings, garbage at another baud rate or parity, with parity and framing
//!   errors as a UART has them. Two endpoints at 9600 on a 19200 line understand each other;
//!   one at the line's 19200 hears garbage from them. Collisions and the t3.5 rule are as for
//!   any sender (t3.5 is the wire's).

use std::collections::BTreeMap;
use std::time::Duration;

use ferrobus_proto::Instant;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming, RxEvent, expire, feed};
use rand::rngs::SmallRng;
use rand::{RngExt, SeedableRng};

use crate::uart;

/// What goes wrong on the wire, drawn per character from a seeded generator. A chance
/// outside 0 to 1 is taken as the nearest of them (a `NaN` as 0).
#[derive(Clone, Copy, PartialEq, Debug, Default)]
pub struct LineFaults {
    /// The chance that a bit is flipped (per data bit).
    pub bit_error_rate: f64,
    /// The chance that a character is replaced by a random one.
    pub corrupt_rate: f64,
    /// The chance that a character is lost.
    pub drop_rate: f64,
    /// The chance that a gap of `stretch_by` opens before a character inside a frame.
    pub stretch_rate: f64,
    /// How long a stretched gap is.
    pub stretch_by: Duration,
    /// Noise bursts per second, at random times (at most one per character time).
    pub noise_per_second: f64,
    /// The most characters in one noise burst (each burst has 1 to this many).
    pub noise_len: usize,
}

/// How a line behaves.
#[derive(Clone, Copy, PartialEq, Debug)]
pub struct LineOptions {
    /// Baud, data bits, parity, stop bits: the character time.
    pub config: LineConfig,
    /// Pace characters at the character time. Off, every write reaches the others at once:
    /// a pure software-overhead bench.
    pub paced: bool,
    /// Every endpoint also hears its own transmission (adapters without echo cancellation).
    pub echo: bool,
    /// Faults.
    pub faults: LineFaults,
    /// Seed of the fault generator.
    pub seed: u64,
}

impl LineOptions {
    /// A clean, paced line at `config`.
    pub fn new(config: LineConfig) -> Self {
        LineOptions { config, paced: true, echo: false, faults: LineFaults::default(), seed: 1 }
    }
}

/// What the virtual wire carried and did to it: characters, frames a sniffer decoded,
/// collisions and faults, and each endpoint's share. Per-endpoint figures are indexed by
/// endpoint id. (A gateway's counts of the requests it put on a real line are the tools
/// crate's `gateway::stats::LineTraffic`.)
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct WireStats {
    /// Characters put on the wire (noise included).
    pub characters: u64,
    /// Frames a sniffer on the wire decoded.
    pub frames: u64,
    /// Byte runs the sniffer threw away (noise, broken frames).
    pub discards: u64,
    /// Characters garbled by two endpoints transmitting at once.
    pub collisions: u64,
    /// Bits flipped.
    pub bit_errors: u64,
    /// Characters replaced.
    pub corrupted: u64,
    /// Characters lost.
    pub dropped: u64,
    /// Gaps stretched inside frames.
    pub stretched: u64,
    /// Noise characters injected.
    pub noise: u64,
    /// Each endpoint: name, characters sent, frames begun less than t3.5 after the line was
    /// last busy.
    pub endpoints: Vec<EndpointStats>,
}

/// One endpoint's figures.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct EndpointStats {
    /// Its name (the pty path, or the name given).
    pub name: String,
    /// Characters it sent.
    pub characters: u64,
    /// Frames it began before the line had been silent for t3.5.
    pub gap_violations: u64,
    /// Whether it is dead (deaf and mute).
    pub dead: bool,
    /// Whether it is a tap: it hears everything and transmits nothing.
    pub tap: bool,
    /// Characters it was given to send and did not, being a tap.
    pub refused: u64,
}

/// How a receiver delivers a character that came with a parity or framing error (a
/// terminal's `IGNPAR`, `PARMRK` and `INPCK`).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum OnError {
    /// As the garbled byte (no error checking).
    #[default]
    Keep,
    /// Not at all (`IGNPAR`).
    Drop,
    /// As `FF 00` and the byte (`PARMRK`).
    Mark,
    /// As `00` (`INPCK` without `PARMRK`).
    Zero,
}

/// A receiver's settings: its UART's, and what it does with a character in error.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Receiver {
    /// Baud, data bits, parity, stop bits.
    pub config: LineConfig,
    /// What becomes of a character with a parity or framing error.
    pub on_error: OnError,
}

/// Characters that reach an endpoint: a run of back-to-back characters sent at one setting.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Delivery {
    /// The endpoint's id.
    pub to: usize,
    /// The characters, as the wire carried them (as sent at `tx`, collisions and faults
    /// applied).
    pub bytes: Vec<u8>,
    /// When the last of them left the wire.
    pub at: Instant,
    /// The settings they were sent at (the wire's for [`Wire::send`] and noise).
    pub tx: LineConfig,
}

impl Delivery {
    /// What a receiver at `rx` makes of these characters: the bytes themselves when it is at
    /// `tx` (stop bits aside), garbage otherwise.
    pub fn heard_by(&self, rx: Receiver) -> Vec<u8> {
        heard(self.tx, rx, &self.bytes)
    }
}

/// The sender of injected noise.
const NOISE: usize = usize::MAX;

/// The least time between two noise bursts on an unpaced wire.
const MIN_NOISE_GAP: Duration = Duration::from_micros(1);

/// A character on the wire.
#[derive(Clone, Copy, Debug)]
struct OnWire {
    start: Instant,
    from: usize,
    byte: u8,
    garbled: bool,
    /// The sender's settings.
    tx: LineConfig,
}

/// The wire of a virtual line, and its endpoints. See the [module docs](self).
pub struct Wire {
    options: LineOptions,
    timing: LineTiming,
    char_time: Duration,
    rng: SmallRng,
    stats: WireStats,
    /// Each endpoint: when its last scheduled character leaves the wire.
    busy_until: Vec<Option<Instant>>,
    /// Characters scheduled, by the time their last bit leaves the wire.
    scheduled: BTreeMap<(Instant, u64), OnWire>,
    seq: u64,
    /// The longest character time scheduled so far: how far past a character's end another
    /// that overlaps it can end.
    longest: Duration,
    /// When the wire was last busy (the end of the last character scheduled on it).
    last_end: Option<Instant>,
    next_noise: Option<Instant>,
    sniffer: RtuCodec,
}

impl Wire {
    /// A silent wire at `now`, without endpoints.
    pub fn new(options: LineOptions, now: Instant) -> Self {
        let timing = LineTiming::new(&options.config);
        let char_time = if options.paced { timing.char_time() } else { Duration::ZERO };
        let mut wire = Wire {
            options,
            timing,
            char_time,
            rng: SmallRng::seed_from_u64(options.seed),
            stats: WireStats::default(),
            busy_until: Vec::new(),
            scheduled: BTreeMap::new(),
            seq: 0,
            longest: char_time,
            last_end: None,
            next_noise: None,
            sniffer: RtuCodec::new(timing, Expect::Both),
        };
        wire.schedule_noise(now);
        wire
    }

    /// The options the wire was made with.
    pub fn options(&self) -> &LineOptions {
        &self.options
    }

    /// The line timing (character time, t1.5, t3.5); all zero on an unpaced line.
    pub fn timing(&self) -> LineTiming {
        if self.options.paced { self.timing } else { LineTiming::unpaced() }
    }

    /// A new endpoint named `name`; returns its id (an index into [`WireStats::endpoints`]).
    pub fn attach(&mut self, name: impl Into<String>) -> usize {
        self.busy_until.push(None);
        self.stats.endpoints.push(EndpointStats { name: name.into(), ..EndpointStats::default() });
        self.stats.endpoints.len() - 1
    }

    /// A new tap named `name`: an endpoint that hears every character on the wire and
    /// transmits nothing (what it is given to send is counted in
    /// [`EndpointStats::refused`]). Returns its id.
    pub fn attach_tap(&mut self, name: impl Into<String>) -> usize {
        let id = self.attach(name);
        if let Some(e) = self.stats.endpoints.get_mut(id) {
            e.tap = true;
        }
        id
    }

    /// Makes endpoint `id` dead (it neither sends nor hears) or alive again. An unknown id
    /// is ignored.
    pub fn set_dead(&mut self, id: usize, dead: bool) {
        if let Some(e) = self.stats.endpoints.get_mut(id) {
            e.dead = dead;
        }
    }

    /// What the wire has seen so far.
    pub fn stats(&self) -> &WireStats {
        &self.stats
    }

    /// Endpoint `from` sends `bytes` at the wire's settings at `now`: they go on the wire back
    /// to back from `now`, or from the end of what it is already sending. Nothing from a dead
    /// or unknown endpoint, nor from a tap.
    pub fn send(&mut self, from: usize, bytes: &[u8], now: Instant) {
        self.send_at(from, self.options.config, bytes, now);
    }

    /// Endpoint `from` sends `bytes` at its own settings `tx` at `now`: the wire carries them
    /// as sent, each taking `tx`'s character time, and its receivers hear them through the
    /// UART model ([`Delivery::heard_by`]). Nothing from a dead or unknown endpoint, nor from
    /// a tap.
    pub fn send_at(&mut self, from: usize, tx: LineConfig, bytes: &[u8], now: Instant) {
        match self.stats.endpoints.get_mut(from) {
            Some(e) if e.tap => e.refused = e.refused.saturating_add(bytes.len() as u64),
            Some(e) if !e.dead => self.schedule(from, tx, bytes, now),
            _ => {}
        }
    }

    /// What a receiver at `rx` makes of `bytes` sent back to back at the wire's settings.
    pub fn heard_by(&self, rx: Receiver, bytes: &[u8]) -> Vec<u8> {
        heard(self.options.config, rx, bytes)
    }

    /// The next instant at which [`advance`](Self::advance) has something to do: the end of
    /// the first run of characters on the wire, or the next noise burst.
    pub fn next_wake(&self) -> Option<Instant> {
        let mut run_end: Option<Instant> = None;
        for ((end, _), w) in &self.scheduled {
            match run_end {
                Some(r) if w.start > r => break,
                _ => run_end = Some(run_end.map_or(*end, |r| r.max(*end))),
            }
        }
        [run_end, self.next_noise].into_iter().flatten().min()
    }

    /// Brings the wire to `now`: injects the noise bursts due by then, and returns what every
    /// endpoint has received, one delivery per endpoint and run of back-to-back characters,
    /// in the order the runs ended.
    pub fn advance(&mut self, now: Instant) -> Vec<Delivery> {
        while let Some(at) = self.next_noise.filter(|t| *t <= now) {
            self.noise(at);
        }
        let mut out = Vec::new();
        let mut chunks: Vec<Vec<u8>> = vec![Vec::new(); self.stats.endpoints.len()];
        let mut run_end: Option<Instant> = None;
        let mut run_tx = self.options.config;
        while let Some(entry) = self.scheduled.first_entry() {
            let end = entry.key().0;
            if end > now {
                break;
            }
            let w = *entry.get();
            // A run ends at a gap, or where the sender's settings change.
            if let Some(r) = run_end.filter(|r| w.start > *r || w.tx != run_tx) {
                Self::flush(&mut chunks, r, run_tx, &mut out);
            }
            run_end = Some(run_end.map_or(end, |r| r.max(end)));
            run_tx = w.tx;
            entry.remove();
            let Some(byte) = self.on_the_wire(w) else { continue };
            // The sniffer listens at the wire's settings.
            let wire_rx = Receiver { config: self.options.config, on_error: OnError::Keep };
            let sniffed = if w.tx == wire_rx.config { vec![byte] } else { heard(w.tx, wire_rx, &[byte]) };
            let local = &mut self.stats;
            feed(&mut self.sniffer, end, &sniffed, |event| count(local, &event));
            for (id, chunk) in chunks.iter_mut().enumerate() {
                let hears = id != w.from || self.options.echo;
                let dead = self.stats.endpoints.get(id).is_some_and(|e| e.dead);
                if hears && !dead {
                    chunk.push(byte);
                }
            }
        }
        if let Some(r) = run_end {
            Self::flush(&mut chunks, r, run_tx, &mut out);
        }
        let local = &mut self.stats;
        expire(&mut self.sniffer, now, |event| count(local, &event));
        out
    }

    fn flush(chunks: &mut [Vec<u8>], at: Instant, tx: LineConfig, out: &mut Vec<Delivery>) {
        for (to, chunk) in chunks.iter_mut().enumerate() {
            if !chunk.is_empty() {
                out.push(Delivery { to, bytes: std::mem::take(chunk), at, tx });
            }
        }
    }

    /// Puts `bytes` from `from` at `tx` on the wire, back to back from `now` or from the end
    /// of what it is already sending, each taking `tx`'s character time, with stretched gaps
    /// drawn; marks collisions; checks the gap before a new frame.
    fn schedule(&mut self, from: usize, tx: LineConfig, bytes: &[u8], now: Instant) {
        let c = if !self.options.paced {
            Duration::ZERO
        } else if tx == self.options.config {
            self.char_time
        } else {
            LineTiming::new(&tx).char_time()
        };
        self.longest = self.longest.max(c);
        let busy_until = self.busy_until.get(from).copied().flatten();
        let mut start = busy_until.filter(|t| *t > now).unwrap_or(now);
        // A frame begins when this sender was not already transmitting (or within t1.5 of
        // its last character): the line must then have been silent for t3.5.
        let continuing = busy_until.is_some_and(|t| t.saturating_add(self.timing.t1_5()) > now);
        if !continuing
            && self.options.paced
            && from != NOISE
            && let Some(last) = self.last_end
            && start < last.saturating_add(self.timing.t3_5())
            && let Some(e) = self.stats.endpoints.get_mut(from)
        {
            e.gap_violations += 1;
        }
        for (i, &byte) in bytes.iter().enumerate() {
            if i > 0 && chance(&mut self.rng, self.options.faults.stretch_rate) {
                start = start.saturating_add(self.options.faults.stretch_by);
                self.stats.stretched += 1;
            }
            let end = start.saturating_add(c);
            // Another sender's character overlapping this one: both are garbled.
            let mut garbled = false;
            // Those that end after this one starts and no later than the longest character
            // time after it ends, and start before it ends.
            let overlapping = self.scheduled.range((start, 0)..(end.saturating_add(self.longest), u64::MAX));
            let hits: Vec<(Instant, u64)> = overlapping
                .filter(|((w_end, _), w)| w.from != from && w.start < end && start < *w_end)
                .map(|(k, _)| *k)
                .collect();
            for key in hits {
                if let Some(w) = self.scheduled.get_mut(&key) {
                    if !w.garbled {
                        w.garbled = true;
                        self.stats.collisions += 1;
                    }
                    garbled = true;
                }
            }
            if garbled {
                self.stats.collisions += 1;
            }
            self.seq += 1;
            self.scheduled.insert((end, self.seq), OnWire { start, from, byte, garbled, tx });
            self.last_end = Some(self.last_end.map_or(end, |l| l.max(end)));
            start = end;
            self.stats.characters += 1;
            if let Some(e) = self.stats.endpoints.get_mut(from) {
                e.characters += 1;
            }
        }
        if let Some(busy) = self.busy_until.get_mut(from) {
            *busy = Some(start);
        }
    }

    /// The character receivers get, after collisions and faults; `None` if it is lost.
    fn on_the_wire(&mut self, w: OnWire) -> Option<u8> {
        let faults = self.options.faults;
        if chance(&mut self.rng, faults.drop_rate) {
            self.stats.dropped += 1;
            return None;
        }
        let mut byte = if w.garbled { self.rng.random::<u8>() } else { w.byte };
        if chance(&mut self.rng, faults.corrupt_rate) {
            byte ^= self.rng.random_range(1..=u8::MAX);
            self.stats.corrupted += 1;
        }
        for bit in 0..8 {
            if chance(&mut self.rng, faults.bit_error_rate) {
                byte ^= 1 << bit;
                self.stats.bit_errors += 1;
            }
        }
        Some(byte)
    }

    /// A noise burst due at `at`, and the next one drawn from there.
    fn noise(&mut self, at: Instant) {
        let n = self.rng.random_range(1..=self.options.faults.noise_len.max(1));
        let bytes: Vec<u8> = (0..n).map(|_| self.rng.random()).collect();
        self.stats.noise += n as u64;
        self.schedule(NOISE, self.options.config, &bytes, at);
        self.schedule_noise(at);
    }

    fn schedule_noise(&mut self, now: Instant) {
        let rate = self.options.faults.noise_per_second;
        self.next_noise = (rate > 0.0).then(|| {
            // Exponential gaps: a Poisson process of `rate` bursts per second, at most an hour
            // apart and at least a character time (1 µs unpaced): however high the rate, a
            // stretch of time holds a bounded number of bursts.
            let u: f64 = self.rng.random_range(f64::MIN_POSITIVE..1.0);
            let gap = Duration::try_from_secs_f64((-u.ln() / rate).min(3600.0)).unwrap_or(Duration::ZERO);
            now.saturating_add(gap.max(self.char_time).max(MIN_NOISE_GAP))
        });
    }
}

/// Draws an event of chance `p`; a chance of 0 (or `NaN`) draws nothing from `rng`.
fn chance(rng: &mut SmallRng, p: f64) -> bool {
    if p.is_nan() || p <= 0.0 {
        return false;
    }
    rng.random_bool(p.min(1.0))
}

fn count(stats: &mut WireStats, event: &RxEvent<'_>) {
    match event {
        RxEvent::Frame(_) => stats.frames += 1,
        RxEvent::Discarded { .. } => stats.discards += 1,
    }
}

/// What a receiver at `rx` makes of `bytes` sent back to back at `tx`: the bit-level UART
/// model, exact (clean bytes when the settings agree, stop bits aside).
pub fn heard(tx: LineConfig, rx: Receiver, bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    for c in uart::receive(tx, rx.config, bytes) {
        match rx.on_error {
            _ if c.is_clean() => out.push(c.byte),
            OnError::Keep => out.push(c.byte),
            OnError::Drop => {}
            OnError::Mark => out.extend([0xFF, 0x00, c.byte]),
            OnError::Zero => out.push(0x00),
        }
    }
    out
}
