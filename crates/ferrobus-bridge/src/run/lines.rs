//! The lines of a plant, each polled by its own master: a [`Client`] over the line's transport
//! and one [`Poller`] with every group of every device on it, its events forwarded to the
//! bridge tagged with the line's index. A simulated line is a virtual RS-485 line in this
//! process with a simulator of every device on it (from its profile), served as `ferrobus
//! demo` serves its drive.
//!
//! A listen line (`mode = "listen"`) is started by `listen.rs` instead: no client, no poller.
//!
//! A line that cannot be reached is no error here: its polls fail (and its devices die, in
//! Sparkplug's words) while the other lines go on, and the client reopens the port.

use std::time::Duration;

use ferrobus::line::{Line, LineOptions};
use ferrobus::server::{ServerOptions, Shared, serve};
use ferrobus::{Client, Timer, Transport};
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming};
use ferrobus_proto::slave::{Slave, SlaveConfig};
use ferrobus_sim::{Device, Faults, Profile, Sim, tokio_clock};
use ferrobus_tools::poll::{Event, Group, PollConfig, PollHandle, Poller};
use tokio::sync::{mpsc, watch};

use crate::config::{Connection, LineMode, LineSpec};
use crate::edge::DeviceRef;

use super::RunError;

/// The profile a simulated device without one is simulated with (plain memory).
const GENERIC: &str = "generic";

/// A running line.
#[derive(Clone, Debug)]
pub struct RunningLine {
    /// Its name in the plant.
    pub name: String,
    /// What it is (`/dev/ttyUSB0`, `10.0.0.7:502`, `virtual line (drives)`).
    pub describe: String,
    /// Its client, free to use beside the poller (requests are queued one at a time); `None`
    /// on a listen line, which never transmits.
    pub client: Option<Client>,
    /// Its poller's handle; `None` on a listen line, which polls nothing.
    pub poll: Option<PollHandle>,
    /// For a simulated line, the line and its simulators.
    pub sim: Option<SimulatedLine>,
}

/// A simulated line: the virtual line, and the simulator of its devices behind one endpoint.
#[derive(Clone)]
pub struct SimulatedLine {
    /// The virtual line.
    pub line: Line,
    /// The simulators of every device on it.
    pub sim: Shared<Sim>,
    /// The endpoint the simulator answers on ([`Line::set_dead`] silences every device).
    pub endpoint: usize,
}

impl std::fmt::Debug for SimulatedLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimulatedLine").field("endpoint", &self.endpoint).finish_non_exhaustive()
    }
}

/// Which device and group each of a line's poller groups is, and back.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GroupMap {
    /// Poller group index → (device index on the line, the device's group index).
    groups: Vec<(usize, usize)>,
    /// Device index → its first poller group and its number of groups.
    first: Vec<(usize, usize)>,
}

impl GroupMap {
    /// The map of devices with `counts[d]` groups each, in order.
    pub fn new(counts: impl IntoIterator<Item = usize>) -> GroupMap {
        let mut map = GroupMap::default();
        for (device, count) in counts.into_iter().enumerate() {
            map.first.push((map.groups.len(), count));
            map.groups.extend((0..count).map(|g| (device, g)));
        }
        map
    }

    /// The device and its group of poller group `index` on line `line`.
    pub fn device(&self, line: usize, index: usize) -> Option<(DeviceRef, usize)> {
        self.groups.get(index).map(|&(device, group)| (DeviceRef { line, device }, group))
    }

    /// The poller group of a device's group.
    pub fn poller_group(&self, device: usize, group: usize) -> Option<usize> {
        let &(first, count) = self.first.get(device)?;
        (group < count).then_some(first + group)
    }
}

/// Starts line `spec` of the plant: its client (a simulated line's devices too) and its
/// poller, whose events go to `events` tagged with `index` (the line's tag: never another
/// line's in the bridge's life, so that a stopped line's last events name no line) until it
/// stops; a listen line stops when `stop`'s sender is dropped.
pub(super) async fn start(
    index: usize,
    spec: &LineSpec,
    events: mpsc::Sender<(usize, Event)>,
    stop: watch::Receiver<()>,
) -> Result<(RunningLine, GroupMap), RunError> {
    if spec.mode == LineMode::Listen {
        return super::listen::start(index, spec, events, stop);
    }
    let (transport, timing, sim) = match &spec.connection {
        Connection::Serial { config, ascii } => {
            let timing = LineTiming::new(&config.line);
            let transport = if *ascii { Transport::ascii(config.clone()) } else { Transport::rtu(config.clone()) };
            (transport, Some(timing), None)
        }
        Connection::Tcp(addr) => (Transport::tcp(addr.clone()), None, None),
        Connection::RtuTcp(addr) => (Transport::rtu_over_tcp(addr.clone()), None, None),
        Connection::Simulated { line } => {
            let sim = simulate(spec, *line).await?;
            let transport = sim.line.transport(&format!("bridge ({})", spec.name));
            (transport, Some(sim.line.timing()), Some(sim))
        }
    };
    let describe = transport.describe();
    let client = Client::spawn(transport, spec.client);
    Ok(poll(
        index,
        spec,
        RunningLine { name: spec.name.clone(), describe, client: Some(client), poll: None, sim },
        timing,
        events,
    ))
}

/// `line`'s client (open) polling `spec`'s devices in a new poller, whose events go to `events`
/// tagged with `index`: a line started, or one a reload keeps open with other devices.
pub(super) fn poll(
    index: usize,
    spec: &LineSpec,
    mut line: RunningLine,
    timing: Option<LineTiming>,
    events: mpsc::Sender<(usize, Event)>,
) -> (RunningLine, GroupMap) {
    let groups: Vec<Group> = spec.devices.iter().flat_map(|d| d.groups.iter().cloned()).collect();
    let map = GroupMap::new(spec.devices.iter().map(|d| d.groups.len()));
    let Some(client) = line.client.clone() else { return (line, GroupMap::default()) };
    let mut poller = Poller::start(client, groups, PollConfig { line: timing, raw_only: true });
    line.poll = Some(poller.handle());
    tokio::spawn(async move {
        while let Some(event) = poller.next().await {
            if events.send((index, event)).await.is_err() {
                return;
            }
        }
    });
    (line, map)
}

/// The line timing a poller of `spec` keeps to: a serial line's (none over TCP).
pub(super) fn timing(spec: &LineSpec) -> Option<LineTiming> {
    match &spec.connection {
        Connection::Serial { config, .. } => Some(LineTiming::new(&config.line)),
        _ => None,
    }
}

/// A virtual line at `config` with a simulator of every device of `spec` behind one endpoint.
async fn simulate(spec: &LineSpec, config: LineConfig) -> Result<SimulatedLine, RunError> {
    let line = Line::start(LineOptions::new(config));
    let timing = line.timing();
    let mut sim = Sim::new(tokio_clock(), 1);
    for device in &spec.devices {
        let profile = match &device.profile {
            Some(profile) => Profile::clone(profile),
            None => Profile::load(GENERIC).map_err(|e| RunError::Line {
                line: spec.name.clone(),
                detail: format!("simulating {} without a profile: {e}", device.id),
            })?,
        };
        sim.add(device.unit, Device::new(profile), Faults::default());
    }
    let units = sim.unit_set();
    let sim = Shared::new(sim);
    let port = line.endpoint(format!("simulated devices ({})", spec.name)).await.map_err(|e| RunError::Line {
        line: spec.name.clone(),
        detail: format!("attaching the simulated devices: {e}"),
    })?;
    let endpoint = port.id();
    let mut handler = sim.clone();
    tokio::spawn(async move {
        let slave =
            Slave::new(RtuCodec::new(timing, Expect::Both), SlaveConfig { units, response_wait: Duration::ZERO });
        serve(slave, Box::new(port), &mut handler, &mut ServerOptions::new(timing, Timer::Spin)).await
    });
    Ok(SimulatedLine { line, sim, endpoint })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poller_groups_map_to_devices_and_back() {
        let counts = [2, 0, 3];
        let map = GroupMap::new(counts);
        assert_eq!(map.device(4, 0), Some((DeviceRef { line: 4, device: 0 }, 0)));
        assert_eq!(map.device(4, 1), Some((DeviceRef { line: 4, device: 0 }, 1)));
        assert_eq!(map.device(4, 2), Some((DeviceRef { line: 4, device: 2 }, 0)));
        assert_eq!(map.device(4, 4), Some((DeviceRef { line: 4, device: 2 }, 2)));
        assert_eq!(map.device(4, 5), None);
        assert_eq!(map.poller_group(2, 2), Some(4));
        assert_eq!(map.poller_group(0, 1), Some(1));
        assert_eq!(map.poller_group(1, 0), None, "device 1 has no groups");
        assert_eq!(map.poller_group(0, 2), None);
        assert_eq!(map.poller_group(7, 0), None);
    }
}
