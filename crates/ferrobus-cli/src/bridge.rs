//! `ferrobus bridge`: the plant's devices published to an MQTT broker as Sparkplug B (or plain
//! JSON), commands written back, nothing lost while the broker is away — the library
//! ([`ferrobus_bridge`]) does the work; this file reads the plant, prints what happens and the
//! summary, and in `--demo` keeps the simulated inverter moving.
//!
//! The plant file is the global `--config FILE` (for this command it is the plant, not the
//! settings file: the bridge reads no connection settings, each line has its own).

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use clap::Args;
use ferrobus::Client;
use ferrobus_bridge::config::{ConfigErrors, Mode, Plant};
use ferrobus_bridge::run::{Options, RunningLine, Status, run_with};
use ferrobus_profile::{Point, Profile};
use tokio::sync::{Notify, mpsc, oneshot};

use crate::connect::parse_duration;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output;

/// The demo's broker when none is given.
const DEMO_BROKER: &str = "127.0.0.1:1883";

/// The demo's acceleration time (F002): 20 s from 0 to the maximum frequency.
const DEMO_RAMP: &str = "20s";

/// The set frequencies the demo cycles through, and how long it stays at each.
const DEMO_FREQUENCIES: [&str; 4] = ["60 Hz", "35 Hz", "50 Hz", "20 Hz"];
const DEMO_STEP: Duration = Duration::from_secs(20);

/// Long help of `ferrobus bridge`.
const AFTER_HELP: &str = "\
The plant file (--config plant.toml) names the broker (address, TLS, credentials, client id), \
the Sparkplug group and edge node ids (or plain JSON topics), and the lines with their devices, \
points, poll rates and deadbands; examples/bridge/demo.toml is one to copy from. Status lines go \
to stderr as things happen; the summary goes to stdout at the end (Ctrl-C, SIGTERM or \
--duration), after the NDEATH.

--demo runs that file against simulated drives (an Omron 3G3RX and an SDP servo on an in-process \
virtual RS-485 line): after the births it sets the inverter's acceleration time (F002 = 20 s), runs \
it (coil `run` on, F001 set) and changes its set frequency every 20 s (60, 35, 50, 20 Hz), so its \
output frequency d001 ramps in the DDATA.

Examples:
  ferrobus bridge --demo                                   # broker on 127.0.0.1:1883
  mosquitto_sub -t 'spBv1.0/#' -v                          # in another terminal: the traffic
  ferrobus bridge --config plant.toml --check              # file:line:col errors, exit 2
  ferrobus bridge --config plant.toml --broker 10.0.0.5:1883 --duration 1h";

/// Arguments of `ferrobus bridge`.
#[derive(Args, Clone, Debug)]
#[command(after_help = AFTER_HELP)]
pub(crate) struct BridgeArgs {
    /// Check the plant file (--config) and exit: every error as file:line:col (exit 2), or a summary
    #[arg(long)]
    check: bool,

    /// Run the shipped example plant against simulated drives (no hardware; see below)
    #[arg(long)]
    demo: bool,

    /// The broker, HOST:PORT, instead of the plant file's (the demo's default: 127.0.0.1:1883)
    #[arg(long, value_name = "HOST:PORT")]
    broker: Option<String>,

    /// Stop after this long (NDEATH, then the summary), instead of running until interrupted
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    duration: Option<Duration>,

    /// No status lines: only errors and the summary
    #[arg(long, short)]
    quiet: bool,
}

/// Runs `ferrobus bridge`; `plant_file` is the global `--config`.
pub(crate) async fn run(plant_file: Option<&Path>, args: &BridgeArgs) -> Result<(), CliError> {
    let (plant, origin) = load(plant_file, args)?;
    if args.check {
        return output::print(&format!("{}\n", summary(&origin, &plant)));
    }
    let mut interrupt = Interrupt::listen()?;
    if args.demo && !args.quiet {
        let (host, port) = (&plant.broker.host, plant.broker.port);
        eprintln!("bridge: the demo plant: a simulated 3G3RX and SDP servo on a virtual line, to {host}:{port}");
        eprintln!("bridge: to see it: mosquitto_sub -h {host} -p {port} -t 'spBv1.0/#' -v");
    }
    let inverter = if args.demo { inverter(&plant) } else { None };
    let (status_tx, statuses) = mpsc::channel(1024);
    let born = Arc::new(Notify::new());
    let printer = tokio::spawn(print_statuses(statuses, args.quiet, Arc::clone(&born)));
    let (running_tx, running) = oneshot::channel();
    let demo = inverter.map(|target| tokio::spawn(drive_inverter(target, running, born, args.quiet)));
    let duration = args.duration;
    let stop = async move {
        tokio::select! {
            () = interrupt.wait() => {}
            () = until(duration) => {}
        }
    };
    let options = Options { running: Some(running_tx) };
    let report = run_with(plant, stop, Some(status_tx), options).await;
    if let Some(demo) = demo {
        demo.abort();
    }
    let _ = printer.await;
    let report = report.map_err(|e| CliError::Usage(e.to_string()))?;
    output::print(&report.to_string())
}

/// The plant: the demo's, or the file's; with `--broker` over its broker.
fn load(plant_file: Option<&Path>, args: &BridgeArgs) -> Result<(Plant, String), CliError> {
    let (mut plant, origin) = if args.demo {
        if plant_file.is_some() {
            return Err(CliError::Usage("--demo runs the shipped plant: leave --config out".into()));
        }
        let broker = args.broker.as_deref().unwrap_or(DEMO_BROKER);
        (Plant::demo(broker).map_err(|e| config_errors(&e))?, "examples/bridge/demo.toml".to_string())
    } else {
        let Some(path) = plant_file else {
            return Err(CliError::Usage(
                "give the plant: ferrobus bridge --config plant.toml (or --demo for the shipped one)".into(),
            ));
        };
        (Plant::load(path).map_err(|e| config_errors(&e))?, path.display().to_string())
    };
    if let (Some(broker), false) = (&args.broker, args.demo) {
        let (host, port) = host_port(broker)?;
        plant.broker.host = host;
        plant.broker.port = port;
    }
    Ok((plant, origin))
}

/// Prints every error (`file:line:col: message`) and says how many.
fn config_errors(errors: &ConfigErrors) -> CliError {
    for error in &errors.0 {
        eprintln!("{error}");
    }
    let n = errors.0.len();
    let origin = errors.0.first().map_or("the plant file", |e| e.origin.as_str());
    CliError::Usage(format!("{origin}: {n} error{}", if n == 1 { "" } else { "s" }))
}

/// `HOST:PORT` (`[::1]:1883` too).
fn host_port(text: &str) -> Result<(String, u16), CliError> {
    let bad = || CliError::Usage(format!("--broker '{text}': give HOST:PORT, e.g. 127.0.0.1:1883"));
    let (host, port) = text.rsplit_once(':').ok_or_else(bad)?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    let port = port.parse::<u16>().map_err(|_| bad())?;
    if host.is_empty() || port == 0 {
        return Err(bad());
    }
    Ok((host.to_string(), port))
}

/// `plant.toml: 2 lines, 3 devices, 9 groups, 57 metrics; ...; ok`.
fn summary(origin: &str, plant: &Plant) -> String {
    let devices: Vec<_> = plant.lines.iter().flat_map(|l| &l.devices).collect();
    let groups: usize = devices.iter().map(|d| d.groups.len()).sum();
    let metrics: usize = devices.iter().flat_map(|d| &d.groups).map(|g| g.cells.len()).sum();
    let mode = match &plant.mode {
        Mode::Sparkplug(s) => format!("Sparkplug B, group {}, edge node {}", s.group_id, s.edge_node_id),
        Mode::Plain(p) => format!("plain JSON under {}", p.prefix),
    };
    let scheme = if plant.broker.tls.is_some() { "mqtts" } else { "mqtt" };
    format!(
        "{origin}: {}, {}, {}, {}; {mode}; broker {scheme}://{}:{}; ok",
        count(plant.lines.len(), "line"),
        count(devices.len(), "device"),
        count(groups, "group"),
        count(metrics, "metric"),
        plant.broker.host,
        plant.broker.port
    )
}

/// `1 line`, `2 lines`.
fn count(n: usize, what: &str) -> String {
    format!("{n} {what}{}", if n == 1 { "" } else { "s" })
}

async fn until(duration: Option<Duration>) {
    match duration {
        Some(d) => tokio::time::sleep(d).await,
        None => std::future::pending().await,
    }
}

/// Prints each status on stderr (unless quiet) and wakes the demo at the first NBIRTH.
async fn print_statuses(mut statuses: mpsc::Receiver<Status>, quiet: bool, born: Arc<Notify>) {
    while let Some(status) = statuses.recv().await {
        if matches!(status, Status::Births { node: true, .. }) {
            born.notify_one();
        }
        let always = matches!(status, Status::Overload { .. } | Status::StoreError { .. } | Status::Dropped { .. });
        if !quiet || always {
            eprintln!("bridge: {status}");
        }
    }
}

/// The demo's inverter: its line, unit, and the points the demo writes.
struct Inverter {
    line: usize,
    unit: u8,
    id: String,
    run: Point,
    frequency: Point,
    /// F002, the acceleration time: set long enough to watch the ramp.
    ramp: Option<Point>,
}

/// The first device of the plant with a `run` coil and an F001 (the 3G3RX).
fn inverter(plant: &Plant) -> Option<Inverter> {
    plant.lines.iter().enumerate().find_map(|(line, spec)| {
        spec.devices.iter().find_map(|d| {
            let profile: &Profile = d.profile.as_deref()?;
            Some(Inverter {
                line,
                unit: d.unit,
                id: d.id.clone(),
                run: profile.point("run")?.clone(),
                frequency: profile.point("F001")?.clone(),
                ramp: profile.point("F002").cloned(),
            })
        })
    })
}

/// After the births (or 5 s), runs the inverter and changes its set frequency every 20 s,
/// through the line's own client.
async fn drive_inverter(
    inverter: Inverter,
    running: oneshot::Receiver<Vec<RunningLine>>,
    born: Arc<Notify>,
    quiet: bool,
) {
    let Ok(lines) = running.await else { return };
    let Some(client) = lines.get(inverter.line).map(|l| l.client.clone()) else { return };
    let _ = tokio::time::timeout(Duration::from_secs(5), born.notified()).await;
    let say = |text: String| {
        if !quiet {
            eprintln!("demo: {text}");
        }
    };
    if let Some(ramp) = &inverter.ramp {
        match set(&client, inverter.unit, ramp, DEMO_RAMP).await {
            Ok(()) => say(format!("{} F002 = {DEMO_RAMP} (the acceleration time)", inverter.id)),
            Err(e) => say(format!("{} F002 = {DEMO_RAMP}: {e}", inverter.id)),
        }
    }
    for (step, text) in DEMO_FREQUENCIES.iter().cycle().enumerate() {
        match set(&client, inverter.unit, &inverter.frequency, text).await {
            Ok(()) => say(format!("{} F001 = {text}", inverter.id)),
            Err(e) => say(format!("{} F001 = {text}: {e}", inverter.id)),
        }
        if step == 0 {
            match set(&client, inverter.unit, &inverter.run, "1").await {
                Ok(()) => say(format!("{} run: the output frequency ramps to F001", inverter.id)),
                Err(e) => say(format!("{} run: {e}", inverter.id)),
            }
        }
        tokio::time::sleep(DEMO_STEP).await;
    }
}

/// Writes `text` to `point` of `unit`, checked by the profile first.
async fn set(client: &Client, unit: u8, point: &Point, text: &str) -> Result<(), String> {
    let raw = point.prepare_write(text).map_err(|e| e.to_string())?;
    if point.table == ferrobus_profile::Table::Coils {
        let on = raw.as_int().is_some_and(|n| n != 0) || matches!(raw, ferrobus_profile::Value::Bool(true));
        return client.write_single_coil(unit, point.address, on).await.map_err(|e| e.to_string());
    }
    let words = point.encode(&raw).map_err(|e| e.to_string())?;
    match words.as_slice() {
        [one] => client.write_single_register(unit, point.address, *one).await,
        many => client.write_multiple_registers(unit, point.address, many).await,
    }
    .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broker_is_host_and_port() {
        assert_eq!(host_port("127.0.0.1:1883").unwrap(), ("127.0.0.1".to_string(), 1883));
        assert_eq!(host_port("[::1]:8883").unwrap(), ("::1".to_string(), 8883));
        for bad in ["localhost", ":1883", "host:0", "host:x", "host:70000"] {
            assert!(host_port(bad).is_err(), "{bad}");
        }
    }
}
