//! `ferrobus bridge`: the plant's devices published to an MQTT broker as Sparkplug B (or plain
//! JSON), commands written back, nothing lost while the broker is away — the library
//! ([`ferrobus_bridge`]) does the work; this file reads the plant, prints what happens and the
//! summary, and in `--demo` keeps the simulated inverter moving.
//!
//! The plant file is the global `--config FILE` (for this command it is the plant, not the
//! settings file: the bridge reads no connection settings, each line has its own).
//!
//! SIGHUP reads the plant file again and checks it whole, as at the start: a mistake is logged
//! at error level, each problem at its place, and counted, and the running plant stays;
//! otherwise the running bridge carries out the plan ([`ferrobus_bridge::config::reload::plan`],
//! [`ferrobus_bridge::run::Reload`]) without stopping its MQTT session, and what it did is
//! logged (Unix only: Windows has no SIGHUP).

use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, SystemTime};

use clap::Args;
use ferrobus::Client;
use ferrobus_bridge::config::{ConfigErrors, Mode, Plant};
use ferrobus_bridge::run::{Options, RunningLine, Status, run_with};
use ferrobus_profile::{Point, Profile};
use ferrobus_tools::status::Summary;
use tokio::sync::{Notify, mpsc, oneshot};

use crate::connect::parse_duration;
use crate::exit::CliError;
use crate::interrupt::{Hangup, Interrupt};
use crate::metrics::{self, MetricsArgs};
use crate::output;

mod status;

use status::BridgeStatus;

/// The demo's broker when none is given.
const DEMO_BROKER: &str = "127.0.0.1:1883";

/// The demo's acceleration and deceleration times (F002, F003), from 0 to the maximum
/// frequency (A004, 60 Hz) and back: a few seconds between two set frequencies.
const DEMO_RAMP: &str = "9s";

/// The set frequencies the demo cycles through, and how long it stays at each.
const DEMO_FREQUENCIES: [&str; 4] = ["60 Hz", "35 Hz", "50 Hz", "20 Hz"];
const DEMO_STEP: Duration = Duration::from_secs(20);

/// Long help of `ferrobus bridge`.
const AFTER_HELP: &str = "\
Here --config FILE is the plant file (no settings file is read, and the connection options are \
refused: each line of the plant has its own). The plant file names the broker (address, TLS, credentials, client id), \
the Sparkplug group and edge node ids (or plain JSON topics), and the lines with their devices, \
points, poll rates and deadbands; examples/bridge/demo.toml is one to copy from. Status lines go \
to stderr as things happen; the summary goes to stdout at the end (Ctrl-C, SIGTERM or \
--duration), after the NDEATH.

SIGHUP (systemctl reload) reads the plant file again and checks it: a mistake is logged and \
changes nothing; a good file is applied while the bridge runs, without a new MQTT session: \
unchanged lines and devices go on (no new DBIRTH), removed devices get their DDEATH, added and \
changed ones are (re)born; a broker or session setting changed reconnects (NDEATH, then NBIRTH). \
The ids of the edge node, the mode, the plain prefix and the store need a restart. Windows has no \
SIGHUP.

--demo runs that file against simulated drives (an Omron 3G3RX and an SDP servo on an in-process \
virtual RS-485 line): after the births it sets the inverter's ramps (F002, F003 = 60 s for 400 Hz), \
runs it (coil `run` on, F001 set) and changes its set frequency every 20 s (60, 35, 50, 20 Hz), so \
its output frequency d001 and current d002 ramp in the DDATA.

Examples:
  ferrobus bridge --demo                                   # broker on 127.0.0.1:1883
  mosquitto_sub -t 'spBv1.0/#' -v                          # in another terminal: the traffic
  ferrobus bridge --config plant.toml --check              # file:line:col errors, exit 2
  ferrobus bridge --config plant.toml --broker 10.0.0.5:1883 --duration 30min";

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

    /// The broker, HOST[:PORT], instead of the plant file's (the demo's default: 127.0.0.1:1883)
    #[arg(long, value_name = "HOST[:PORT]")]
    broker: Option<String>,

    /// Stop after this long (NDEATH, then the summary), instead of running until interrupted
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    duration: Option<Duration>,

    /// No status lines: only errors and the summary
    #[arg(long, short)]
    quiet: bool,

    #[command(flatten)]
    metrics: MetricsArgs,
}

/// Runs `ferrobus bridge`; `plant_file` is the global `--config`.
pub(crate) async fn run(plant_file: Option<&Path>, args: &BridgeArgs) -> Result<(), CliError> {
    let (plant, origin) = load(plant_file, args)?;
    if args.check {
        return output::print(&format!("{}\n", summary(&origin, &plant)));
    }
    let status = args.metrics.bind().await?;
    let mut interrupt = Interrupt::listen()?;
    let hangup = Hangup::listen()?;
    if args.demo && !args.quiet {
        let (host, port) = (&plant.broker.host, plant.broker.port);
        let at = if host.contains(':') { format!("[{host}]:{port}") } else { format!("{host}:{port}") };
        eprintln!("bridge: the demo plant: a simulated 3G3RX and SDP servo on a virtual line, to {at}");
        eprintln!("bridge: to see it: mosquitto_sub -h {host} -p {port} -t 'spBv1.0/#' -v");
    }
    let inverter = if args.demo { inverter(&plant) } else { None };
    let (status_tx, statuses) = mpsc::channel(1024);
    let born = Arc::new(Notify::new());
    let printer = tokio::spawn(print_statuses(statuses, args.quiet, Arc::clone(&born)));
    let (running_tx, running) = oneshot::channel::<Vec<RunningLine>>();
    let (demo_tx, demo_lines) = oneshot::channel();
    // A request a line has in flight when the bridge stops is owed its reply: the process
    // keeps each real line's port until it has come (a simulated line is in-process).
    tokio::spawn(async move {
        let Ok(lines) = running.await else { return };
        let real = lines.iter().filter(|l| l.sim.is_none());
        real.filter_map(|l| l.client.as_ref()).for_each(crate::interrupt::keep_release);
        let watchdog = crate::systemd::ready(&format!("bridge: {} lines running", lines.len()));
        let _ = demo_tx.send(lines);
        watchdog.feed_forever().await;
    });
    let demo = inverter.map(|target| tokio::spawn(drive_inverter(target, demo_lines, born, args.quiet)));
    let duration = args.duration;
    let stop = async move {
        tokio::select! {
            () = interrupt.wait() => {}
            () = until(duration) => {}
        }
    };
    // The demo's plant is never read again (SIGHUP warns): its summary stays.
    let text = summary(&origin, &plant);
    let described = Arc::new(Mutex::new(if args.demo { Summary::fixed(text) } else { Summary::reloadable(text) }));
    let live = status.map(|listener| {
        let (ask, asked) = tokio::sync::mpsc::channel(8);
        metrics::spawn(listener, Arc::new(BridgeStatus::new(ask, Arc::clone(&described))), "bridge");
        asked
    });
    let (reload_tx, reload_rx) = tokio::sync::mpsc::channel(1);
    let options = Options { running: Some(running_tx), live, reload: Some(reload_rx) };
    let watching = tokio::spawn(reload_on_hangup(
        hangup,
        plant_file.map(Path::to_path_buf),
        args.clone(),
        reload_tx,
        Arc::clone(&described),
    ));
    let report = run_with(plant, stop, Some(status_tx), options).await;
    watching.abort();
    crate::systemd::stopping();
    let reloads = described.lock().unwrap_or_else(PoisonError::into_inner).reloads().cloned();
    if let Some(reloads) = reloads.filter(|r| r.checked > 0) {
        eprintln!("bridge: reload: {} files checked, {} refused", reloads.checked, reloads.refused);
    }
    if let Some(demo) = demo {
        demo.abort();
    }
    let _ = printer.await;
    let report = report.map_err(|e| CliError::Usage(e.to_string()))?;
    output::print(&report.to_string())
}

/// At each SIGHUP, reads the plant file again (with `--broker` over it, as at the start) and
/// hands it to the running bridge, which carries out its plan: a mistake, or a setting that
/// cannot change while the bridge runs, is logged at error level and changes nothing; what was
/// done is logged at info, and the plant applied becomes `described`'s summary. Either is
/// counted in `described`. Tells systemd it reloads, and when it is done.
async fn reload_on_hangup(
    mut hangup: Hangup,
    plant_file: Option<std::path::PathBuf>,
    args: BridgeArgs,
    bridge: tokio::sync::mpsc::Sender<ferrobus_bridge::run::Reload>,
    described: Arc<Mutex<Summary>>,
) {
    loop {
        hangup.wait().await;
        let Some(path) = plant_file.as_deref().filter(|_| !args.demo) else {
            tracing::warn!("SIGHUP: the bridge runs the demo's plant, so there is no file to read again");
            continue;
        };
        crate::systemd::reloading();
        let outcome = match load_file(path, &args) {
            Err(errors) => {
                for error in &errors.0 {
                    tracing::error!("reload refused, the running plant stays: {error}");
                }
                Err(format!("{} errors in the plant file", errors.0.len()))
            }
            Ok(new) => {
                let text = summary(&path.display().to_string(), &new);
                let (done, answer) = tokio::sync::oneshot::channel();
                let asked = bridge.send(ferrobus_bridge::run::Reload { plant: new, done }).await;
                match (asked, answer.await) {
                    // The bridge says what it did, as a status line.
                    (Ok(()), Ok(Ok(done))) => Ok((text, done)),
                    (Ok(()), Ok(Err(why))) => {
                        tracing::error!("reload refused: {why}");
                        Err(why)
                    }
                    _ => {
                        tracing::warn!("reload: the bridge is stopping");
                        Err("the bridge is stopping".to_string())
                    }
                }
            }
        };
        let mut now = described.lock().unwrap_or_else(PoisonError::into_inner);
        let status = match outcome {
            Ok((text, done)) => {
                let status = format!("reloaded: {done}");
                now.applied(text, done, SystemTime::now());
                status
            }
            Err(why) => {
                now.refused(SystemTime::now());
                format!("reload refused: {why}")
            }
        };
        drop(now);
        crate::systemd::reloaded(&status);
    }
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
        (plant.broker.host, plant.broker.port) = broker_over(broker, &plant)?;
    }
    Ok((plant, origin))
}

/// The plant file at `path` with `--broker` over its broker: what a reload reads.
fn load_file(path: &Path, args: &BridgeArgs) -> Result<Plant, ConfigErrors> {
    let mut plant = Plant::load(path)?;
    if let Some(broker) = &args.broker {
        // The same --broker was taken at the start: it parses.
        if let Ok((host, port)) = broker_over(broker, &plant) {
            (plant.broker.host, plant.broker.port) = (host, port);
        }
    }
    Ok(plant)
}

/// `--broker`'s host and port, the port by the plant's TLS when left out.
fn broker_over(broker: &str, plant: &Plant) -> Result<(String, u16), CliError> {
    host_port(broker, if plant.broker.tls.is_some() { 8883 } else { 1883 })
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

/// `HOST[:PORT]` (`[::1]:1883` too), the port `default_port` when left out.
fn host_port(text: &str, default_port: u16) -> Result<(String, u16), CliError> {
    let bad = || CliError::Usage(format!("--broker '{text}': give HOST[:PORT], e.g. 127.0.0.1:1883"));
    let (host, port) = match text.strip_prefix('[') {
        Some(rest) => {
            let (host, after) = rest.split_once(']').ok_or_else(bad)?;
            (host, after.strip_prefix(':'))
        }
        None => match text.rsplit_once(':') {
            Some((host, _)) if host.contains(':') => (text, None), // a bare IPv6 address
            Some((host, port)) => (host, Some(port)),
            None => (text, None),
        },
    };
    let port = match port {
        Some(port) => port.parse::<u16>().map_err(|_| bad())?,
        None => default_port,
    };
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
    /// The profile, whose write guard every demo write goes through.
    profile: Arc<Profile>,
    run: Point,
    frequency: Point,
    /// F002 and F003, the acceleration and deceleration times: set long enough to watch the
    /// ramps.
    ramps: Vec<Point>,
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
                profile: Arc::clone(d.profile.as_ref()?),
                run: profile.point("run")?.clone(),
                frequency: profile.point("F001")?.clone(),
                ramps: ["F002", "F003"].iter().filter_map(|code| profile.point(code).cloned()).collect(),
            })
        })
    })
}

/// After the births (or 5 s), runs the inverter and changes its set frequency every 20 s,
/// through the line's own client, as started ([`Options::running`]): the demo's plant is never
/// read again (SIGHUP only warns), so no reload stops that line under the demo.
async fn drive_inverter(
    inverter: Inverter,
    running: oneshot::Receiver<Vec<RunningLine>>,
    born: Arc<Notify>,
    quiet: bool,
) {
    let Ok(lines) = running.await else { return };
    let Some(client) = lines.get(inverter.line).and_then(|l| l.client.clone()) else { return };
    let _ = tokio::time::timeout(Duration::from_secs(5), born.notified()).await;
    let say = |text: String| {
        if !quiet {
            eprintln!("demo: {text}");
        }
    };
    for ramp in &inverter.ramps {
        match set(&client, &inverter, ramp, DEMO_RAMP).await {
            Ok(()) => say(format!("{} {} = {DEMO_RAMP} ({})", inverter.id, ramp.code, ramp.label)),
            Err(e) => say(format!("{} {} = {DEMO_RAMP}: {e}", inverter.id, ramp.code)),
        }
    }
    for (step, text) in DEMO_FREQUENCIES.iter().cycle().enumerate() {
        match set(&client, &inverter, &inverter.frequency, text).await {
            Ok(()) => say(format!("{} F001 = {text}", inverter.id)),
            Err(e) => say(format!("{} F001 = {text}: {e}", inverter.id)),
        }
        if step == 0 {
            match set(&client, &inverter, &inverter.run, "1").await {
                Ok(()) => say(format!("{} run: the output frequency ramps to F001", inverter.id)),
                Err(e) => say(format!("{} run: {e}", inverter.id)),
            }
        }
        tokio::time::sleep(DEMO_STEP).await;
    }
}

/// Writes `text` to `point` of the inverter as every writer writes a point
/// ([`ferrobus_tools::write::write_point`]: its profile's guard, the running point read for a
/// run-locked point, the request the drive takes), not read back.
async fn set(client: &Client, inverter: &Inverter, point: &Point, text: &str) -> Result<(), String> {
    let raw = point.prepare_write(text).map_err(|e| e.to_string())?;
    let write = ferrobus_profile::Write { point, raw: &raw, typed: text };
    ferrobus_tools::write::write_point(client, inverter.unit, Some(&inverter.profile), &write, false)
        .await
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_sums_up_the_plant_in_words() {
        let plant = Plant::demo("10.0.0.5:1884").unwrap();
        let text = summary("demo.toml", &plant);
        assert!(text.starts_with("demo.toml: 1 line, 2 devices, "), "{text}");
        assert!(
            text.ends_with("; Sparkplug B, group ferrobus-demo, edge node demo-edge; broker mqtt://10.0.0.5:1884; ok"),
            "{text}"
        );
        assert_eq!(count(1, "metric"), "1 metric");
        assert_eq!(count(11, "metric"), "11 metrics");
    }

    #[test]
    fn the_demo_drives_the_inverter_by_its_profiles_points() {
        let plant = Plant::demo("127.0.0.1").unwrap();
        let inverter = inverter(&plant).expect("the demo has a 3G3RX");
        assert_eq!((inverter.id.as_str(), inverter.unit), ("inverter", 1));
        assert_eq!(inverter.run.table, ferrobus_profile::Table::Coils);
        assert!(inverter.frequency.prepare_write(DEMO_FREQUENCIES[0]).is_ok());
        let ramps: Vec<&str> = inverter.ramps.iter().map(|p| p.code.as_str()).collect();
        assert_eq!(ramps, ["F002", "F003"]);
        for ramp in &inverter.ramps {
            assert!(ramp.prepare_write(DEMO_RAMP).is_ok(), "{} takes {DEMO_RAMP}", ramp.code);
        }
    }

    #[test]
    fn a_broker_is_host_and_port() {
        let ok = |text: &str| host_port(text, 1883).unwrap();
        assert_eq!(ok("127.0.0.1:1884"), ("127.0.0.1".to_string(), 1884));
        assert_eq!(ok("broker.plant"), ("broker.plant".to_string(), 1883));
        assert_eq!(host_port("broker.plant", 8883).unwrap().1, 8883, "the TLS port when the plant has TLS");
        assert_eq!(ok("[::1]:8883"), ("::1".to_string(), 8883));
        assert_eq!(ok("[::1]"), ("::1".to_string(), 1883));
        assert_eq!(ok("::1"), ("::1".to_string(), 1883));
        for bad in ["", ":1883", "host:0", "host:x", "host:70000", "[::1", "[]:1883"] {
            assert!(host_port(bad, 1883).is_err(), "{bad}");
        }
    }
}
