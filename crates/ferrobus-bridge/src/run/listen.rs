//! A listen line (`mode = "listen"`): the bus has a master of its own, and the bridge is a
//! passive second master. The port is opened read-only through the sniffer's [`Listener`]
//! (nothing is ever written to it); each read reply and acknowledged write heard is decoded by
//! [`Pairing`] and [`Heard::sample`] into the samples a poll of the devices' groups would
//! give, sent to the bridge on the same channel as a poller's, tagged with the line's index,
//! so the publishing path (Sparkplug or plain JSON, deadbands, store and forward) is the
//! polled lines'. A sample's time is the reply's on the wire.
//!
//! - A group's sample holds the cells the reply holds wholly; the others keep what they had.
//! - A request of the master that its device leaves unanswered is a silent poll of each of
//!   the device's groups: `death_after` of them in a row and the device is dead, as on a
//!   polled line.
//! - A port that cannot be opened, or that fails, is opened again every [`REOPEN`], until the
//!   bridge stops, while its path names the device first opened ([`SameDevice`]): a raw pty
//!   that went away is never opened again (its number goes to the next pty made), and the
//!   line stops listening, saying so.
//!
//! [`Heard::sample`]: ferrobus_tools::sniff::Heard::sample

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use ferrobus::SerialConfig;
use ferrobus::port::SameDevice;
use ferrobus_proto::frame::LineTiming;
use ferrobus_tools::poll::{Event, Failure, FailureKind, Group, Sample, Traffic};
use ferrobus_tools::sniff::{BusEvent, Listener, Pairing};
use tokio::sync::{mpsc, watch};

use crate::config::{Connection, LineSpec};

use super::RunError;
use super::lines::{GroupMap, RunningLine};

/// How long a port that could not be opened, or failed, waits before it is opened again.
pub(super) const REOPEN: Duration = Duration::from_secs(2);

/// The groups of a line's devices, each with its poller group index: what the samples name.
#[derive(Clone, Debug, Default)]
struct Devices {
    /// Per device: its unit and its groups with their indices on the line.
    devices: Vec<(u8, Vec<(usize, Group)>)>,
    /// Per group index on the line: the samples given of it so far (their `seq`).
    seqs: Vec<u64>,
}

impl Devices {
    fn new(spec: &LineSpec, map: &GroupMap) -> Devices {
        let devices: Vec<(u8, Vec<(usize, Group)>)> = spec
            .devices
            .iter()
            .enumerate()
            .map(|(d, device)| {
                let groups = device.groups.iter().enumerate();
                let indexed = groups.filter_map(|(g, group)| Some((map.poller_group(d, g)?, group.clone()))).collect();
                (device.unit, indexed)
            })
            .collect();
        let count = devices.iter().map(|(_, groups)| groups.len()).sum();
        Devices { devices, seqs: vec![0; count] }
    }

    /// The samples given of group `index` so far: the next one's `seq`.
    fn seq(&self, index: usize) -> u64 {
        self.seqs.get(index).copied().unwrap_or(0)
    }

    /// The samples an event heard gives: a group's for each group of the unit that answered
    /// holding some of its cells; a silent poll of each group of a unit that did not answer.
    fn samples(&mut self, pairing: &mut Pairing, event: &BusEvent) -> Vec<Sample> {
        let samples: Vec<Sample> = if let BusEvent::Unanswered { unit, function, request_end } = event {
            let time = UNIX_EPOCH + Duration::from_nanos(request_end.as_nanos());
            let diagnosis = format!("unit {unit} left its master's request (function {function:#04x}) unanswered");
            self.of(*unit).map(|(index, _)| silent(*index, self.seq(*index), time, &diagnosis)).collect()
        } else {
            let Some(heard) = pairing.take(event) else { return Vec::new() };
            self.of(heard.unit).filter_map(|(index, group)| heard.sample(*index, self.seq(*index), group)).collect()
        };
        for sample in &samples {
            if let Some(seq) = self.seqs.get_mut(sample.group) {
                *seq = seq.saturating_add(1);
            }
        }
        samples
    }

    /// The groups of the devices at `unit`.
    fn of(&self, unit: u8) -> impl Iterator<Item = &(usize, Group)> {
        self.devices.iter().filter(move |(u, _)| *u == unit).flat_map(|(_, groups)| groups)
    }
}

/// A poll of group `index` that heard nothing.
fn silent(index: usize, seq: u64, time: SystemTime, diagnosis: &str) -> Sample {
    Sample {
        group: index,
        seq,
        time,
        due: Duration::ZERO,
        started: Duration::ZERO,
        response_time: Duration::ZERO,
        overrun: false,
        result: Err(Failure { kind: FailureKind::Timeout, exception: None, diagnosis: diagnosis.to_string() }),
        traffic: Traffic::default(),
    }
}

/// Starts listen line `index` of the plant, `spec` (a serial port): the listener, in a task of
/// its own, sends its devices' samples to `events` tagged with `index` until the bridge drops
/// the channel's receiver or `stop`'s sender (a reload that removes or changes the line). The
/// running line has no client and no poller.
pub(super) fn start(
    index: usize,
    spec: &LineSpec,
    events: mpsc::Sender<(usize, Event)>,
    stop: watch::Receiver<()>,
) -> Result<(RunningLine, GroupMap), RunError> {
    let Connection::Serial { config, .. } = &spec.connection else {
        return Err(RunError::Line { line: spec.name.clone(), detail: "a listen line is a serial port".into() });
    };
    let map = GroupMap::new(spec.devices.iter().map(|d| d.groups.len()));
    let devices = Devices::new(spec, &map);
    let describe = format!("{} (listening, transmitting nothing)", config.path.display());
    let running = RunningLine { name: spec.name.clone(), describe, client: None, poll: None, sim: None };
    tokio::spawn(listen(index, spec.name.clone(), config.clone(), devices, events, stop));
    Ok((running, map))
}

/// Listens to `config`'s port until `events` is closed or `stop`'s sender dropped, opening it
/// again when it fails.
async fn listen(
    index: usize,
    name: String,
    config: SerialConfig,
    mut devices: Devices,
    events: mpsc::Sender<(usize, Event)>,
    mut stop: watch::Receiver<()>,
) {
    let timing = LineTiming::new(&config.line);
    // Opened again only while the path names the device first opened (never a pty's number
    // given to the next pty).
    let mut same = SameDevice::new(config.path.clone());
    loop {
        match same.open(|| Listener::open(config.clone(), timing)) {
            Err(not_same) if not_same.lasting() => {
                tracing::error!(line = %name, "{}: {not_same}; the line stops listening", config.path.display());
                return;
            }
            Err(not_same) => {
                tracing::warn!(line = %name, "{}: not opened again: {not_same}; trying again in {REOPEN:?}", config.path.display());
            }
            Ok(Ok(mut listener)) => {
                let mut pairing = Pairing::new();
                loop {
                    let heard = tokio::select! {
                        heard = listener.next() => heard,
                        () = events.closed() => return,
                        _ = stop.changed() => return,
                    };
                    let event = match heard {
                        Ok(Some(event)) => event,
                        Ok(None) => {
                            tracing::warn!(line = %name, "the port ended; opening it again in {REOPEN:?}");
                            break;
                        }
                        Err(e) => {
                            tracing::warn!(line = %name, "{e}; opening it again in {REOPEN:?}");
                            break;
                        }
                    };
                    for sample in devices.samples(&mut pairing, &event) {
                        if events.send((index, Event::Sample(sample))).await.is_err() {
                            return;
                        }
                    }
                }
            }
            Ok(Err(e)) => tracing::warn!(line = %name, "{e}; trying again in {REOPEN:?}"),
        }
        tokio::select! {
            () = tokio::time::sleep(REOPEN) => {}
            () = events.closed() => return,
            _ = stop.changed() => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use ferrobus_proto::Instant;
    use ferrobus_proto::crc::crc16;
    use ferrobus_proto::sniff::{Role, WireTime};

    use super::*;
    use crate::config::{LineMode, Plant};

    fn frame(body: &[u8], role: Role, ms: u64, response_time: Option<u64>) -> BusEvent {
        let mut bytes = body.to_vec();
        bytes.extend_from_slice(&crc16(body).to_le_bytes());
        let time = WireTime::at(Instant::from_nanos(ms * 1_000_000));
        BusEvent::Frame { bytes, role, crc_ok: true, time, response_time: response_time.map(Duration::from_millis) }
    }

    fn line() -> LineSpec {
        let text = "[broker]\naddress = 'localhost'\n[sparkplug]\ngroup_id = 'g'\nedge_node_id = 'e'\n\
                    [[line]]\nname = 'plc'\nport = '/dev/null'\nmode = 'listen'\n\
                    [[line.device]]\nid = 'rx'\nunit = 1\nprofile = 'omron-3g3rx'\npoints = ['F002', 'A004', 'd001']\n";
        let plant = Plant::parse(text, "plant.toml", Path::new(".")).expect("a listen plant");
        let line = plant.lines.into_iter().next().expect("one line");
        assert_eq!(line.mode, LineMode::Listen);
        line
    }

    #[test]
    fn a_reply_heard_is_a_sample_of_each_group_holding_some_of_its_cells_and_silence_a_silent_poll_of_each() {
        let spec = line();
        let map = GroupMap::new(spec.devices.iter().map(|d| d.groups.len()));
        let mut devices = Devices::new(&spec, &map);
        let groups = &spec.devices[0].groups;
        let f002 = groups.iter().position(|g| g.cells.iter().any(|c| c.name == "F002")).expect("F002's group");
        let mut pairing = Pairing::new();
        // F002 (u32 at 0x1102, high word first) = 1000 (10.00 s), read by the PLC; unit 2 is no device of the line.
        let ask = frame(&[0x01, 0x03, 0x11, 0x02, 0x00, 0x02], Role::Request, 10, None);
        assert!(devices.samples(&mut pairing, &ask).is_empty());
        let reply = frame(&[0x01, 0x03, 0x04, 0x00, 0x00, 0x03, 0xE8], Role::Response, 20, Some(10));
        let samples = devices.samples(&mut pairing, &reply);
        let [sample] = samples.as_slice() else { panic!("{samples:?}") };
        assert_eq!((sample.group, sample.seq), (f002, 0));
        assert_eq!(sample.time, UNIX_EPOCH + Duration::from_millis(20));
        let readings = sample.result.as_ref().expect("readings");
        assert_eq!(readings.len(), 1);
        assert_eq!(readings[0].shown, "10.00 s");
        let other = frame(&[0x02, 0x03, 0x11, 0x02, 0x00, 0x02], Role::Request, 30, None);
        devices.samples(&mut pairing, &other);
        assert!(
            devices
                .samples(
                    &mut pairing,
                    &frame(&[0x02, 0x03, 0x04, 0x00, 0x00, 0x03, 0xE8], Role::Response, 40, Some(10))
                )
                .is_empty()
        );
        // Unit 1 silent: each of its groups a silent poll.
        let silence = BusEvent::Unanswered { unit: 1, function: 3, request_end: Instant::from_nanos(50_000_000) };
        let silent = devices.samples(&mut pairing, &silence);
        assert_eq!(silent.len(), groups.len());
        assert!(silent.iter().all(|s| matches!(&s.result, Err(f) if f.kind == FailureKind::Timeout)));
        assert_eq!(silent.iter().find(|s| s.group == f002).map(|s| s.seq), Some(1));
    }
}
