//! `plant.toml`: what the bridge connects to, which devices it polls and how it publishes them.
//!
//! ```text
//!   plant.toml ──DeTable (spans)──▶ raw sections (serde, unknown keys refused)
//!              ──resolve──▶ Plant { broker, mode, store, lines: [ LineSpec { devices } ] }
//! ```
//!
//! Every problem is reported, not just the first, each as `file:line:col: message` saying what
//! was seen and what is allowed: TOML syntax, unknown keys, wrong types, and what only shows
//! once the file has parsed (a Sparkplug id with a `/`, a unit used twice on a line, a point
//! the profile does not have, a metric name used twice by a device). Profiles are loaded once
//! each and shared by the devices that use them; a device's points become read requests
//! through the profile's planner ([`Group::points`]), so the bridge polls what the poller polls.
//!
//! Every key is described in `docs/bridge-config.md`; `examples/bridge/` holds a demo, a real
//! plant to copy from and a plain JSON one.

mod raw;
pub mod reload;
mod resolve;
mod text;

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use ferrobus_profile::Profile;
use ferrobus_profile::source::{self, Place, ReadError};
use ferrobus_tools::poll::Group;

use crate::sparkplug::convert::UintEncoding;
use crate::store::StoreConfig;

/// The demo plant: an inverter and a servo on one simulated RS-485 line.
const DEMO: &str = include_str!("../../../../examples/bridge/demo.toml");

/// A whole plant: the broker, how to publish, where to keep what the broker missed, and the
/// lines with their devices.
#[derive(Clone, Debug)]
pub struct Plant {
    /// Where it was read from (a file's path), as errors name it.
    pub origin: String,
    /// The MQTT broker.
    pub broker: Broker,
    /// Sparkplug B or plain JSON.
    pub mode: Mode,
    /// The store and forward queue's bounds.
    pub store: StoreConfig,
    /// The field buses, in file order.
    pub lines: Vec<LineSpec>,
}

/// The MQTT broker and the session to it.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Broker {
    /// Host name or IP address.
    pub host: String,
    /// TCP port (1883, or 8883 with TLS, unless given).
    pub port: u16,
    /// The MQTT client id (`ferrobus-<edge_node_id>` unless given).
    pub client_id: String,
    /// The user name of CONNECT.
    pub username: Option<String>,
    /// The password of CONNECT (given, read from a file, or from the environment).
    pub password: Option<String>,
    /// TLS to the broker; `None` is plain TCP.
    pub tls: Option<BrokerTls>,
    /// The MQTT keep alive.
    pub keep_alive: Duration,
    /// The first retry delay after the broker is lost, doubling to 30 s.
    pub reconnect: Duration,
}

/// TLS to the broker: the CA that signs its certificate, and our own for mutual TLS.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct BrokerTls {
    /// PEM file of the CA certificates the broker's certificate must chain to.
    pub ca: PathBuf,
    /// PEM file of our certificate chain (mutual TLS), with `key`.
    pub cert: Option<PathBuf>,
    /// PEM file of our private key (mutual TLS), with `cert`.
    pub key: Option<PathBuf>,
    /// The name the broker's certificate must carry, when it is not `host`.
    pub server_name: Option<String>,
}

/// How the bridge publishes.
#[derive(Clone, PartialEq, Eq, Debug)]
pub enum Mode {
    /// Sparkplug B 3.0: births, data by exception with aliases, deaths, commands.
    Sparkplug(SparkplugConfig),
    /// Plain JSON on `prefix/device/metric`.
    Plain(PlainConfig),
}

/// The Sparkplug identity of the edge node.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct SparkplugConfig {
    /// The group id of every topic.
    pub group_id: String,
    /// The edge node id.
    pub edge_node_id: String,
    /// The primary host application whose STATE gates the births, if any.
    pub primary_host: Option<String>,
    /// How integers are laid out in a metric: the specification's way or Tahu's and Ignition's
    /// (`uint_in_long_value` in the file).
    pub uint_encoding: UintEncoding,
}

/// Plain JSON publishing.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct PlainConfig {
    /// The topic prefix: values go to `prefix/device/metric`.
    pub prefix: String,
    /// Publish values retained.
    pub retain: bool,
    /// The QoS of values (0, 1 or 2).
    pub qos: u8,
    /// Home Assistant MQTT discovery: the discovery prefix its configs are published under
    /// (`homeassistant` unless given); `None` when off (`discovery = false`, the default).
    pub discovery: Option<String>,
}

/// One field bus and the devices on it.
#[derive(Clone, Debug)]
pub struct LineSpec {
    /// Its name in logs and status.
    pub name: String,
    /// How it is reached.
    pub connection: Connection,
    /// Timeout, retries and the rest of the client's settings.
    pub client: ferrobus::ClientConfig,
    /// Whether the bridge polls it, or only listens to its own master.
    pub mode: LineMode,
    /// The devices, in file order.
    pub devices: Vec<DeviceSpec>,
}

/// How the bridge reads a line's devices (`mode` in the file).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum LineMode {
    /// The bridge is the line's master: it polls its devices (the default).
    #[default]
    Poll,
    /// The line has a master of its own (a PLC): the bridge opens the port read-only, never
    /// transmits, and publishes what the replies it hears say of its devices' points
    /// (`mode = "listen"`; a serial RTU port only).
    Listen,
}

/// How a line is reached.
#[derive(Clone, PartialEq, Debug)]
pub enum Connection {
    /// A serial port, RTU or (with `ascii`) ASCII framing.
    Serial {
        /// The port and its settings.
        config: ferrobus::SerialConfig,
        /// Modbus ASCII instead of RTU.
        ascii: bool,
    },
    /// Modbus/TCP to `host:port`.
    Tcp(String),
    /// RTU frames over TCP (a serial device server) to `host:port`.
    RtuTcp(String),
    /// An in-process virtual RS-485 line at that baud; the bridge simulates every device on
    /// it from its profile (the demo's lines; also handy to try a config without hardware).
    Simulated {
        /// The virtual line's settings.
        line: ferrobus_proto::frame::LineConfig,
    },
}

/// One device on a line: what is polled, how often, and what change is worth publishing.
#[derive(Clone, Debug)]
pub struct DeviceSpec {
    /// The device id (the Sparkplug device id, the plain topic's device level).
    pub id: String,
    /// The Modbus unit.
    pub unit: u8,
    /// Its profile, shared with the other devices that use it; `None` for raw ranges only.
    pub profile: Option<Arc<Profile>>,
    /// The read requests, from [`Group::points`] (the planner) and [`Group::raw`].
    pub groups: Vec<Group>,
    /// `[group][cell]`: the engineering change that is published (0: any change).
    pub deadbands: Vec<Vec<f64>>,
    /// Consecutive polls without a reply before DDEATH (default 3).
    pub death_after: u32,
}

impl DeviceSpec {
    /// Every metric name of the device (the cells' names), group by group.
    pub fn metric_names(&self) -> impl Iterator<Item = &str> {
        self.groups.iter().flat_map(|g| g.cells.iter().map(|c| c.name.as_str()))
    }
}

impl Plant {
    /// Reads and resolves `path`; relative paths in it are taken from its folder.
    pub fn load(path: &Path) -> Result<Plant, ConfigErrors> {
        let origin = path.display().to_string();
        let text = source::read(path).map_err(|e| {
            let error = match &e {
                ReadError::Io(e) => ConfigError::whole(&origin, format!("cannot read the configuration: {e}")),
                ReadError::NotText(not_text) => {
                    let Place { line, column } = not_text.place;
                    ConfigError { origin: origin.clone(), line, column, message: e.located().message }
                }
            };
            ConfigErrors(vec![error])
        })?;
        let base_dir = path.parent().map_or_else(|| PathBuf::from("."), Path::to_path_buf);
        Plant::parse(&text, &origin, &base_dir)
    }

    /// Parses and resolves `text`; `origin` names it in errors, `base_dir` anchors its
    /// relative paths (profiles, the store's folder, TLS files, password files).
    pub fn parse(text: &str, origin: &str, base_dir: &Path) -> Result<Plant, ConfigErrors> {
        resolve::plant(text, origin, base_dir)
    }

    /// The demo plant (`examples/bridge/demo.toml`) with the broker at `broker`
    /// (`host[:port]`).
    pub fn demo(broker: &str) -> Result<Plant, ConfigErrors> {
        let mut plant = Plant::parse(DEMO, "demo.toml", Path::new("."))?;
        let (host, port) = text::host_port(broker, 1883)
            .map_err(|problem| ConfigErrors(vec![ConfigError::whole("--broker", problem)]))?;
        plant.broker.host = host;
        plant.broker.port = port;
        Ok(plant)
    }

    /// Every device with the line it is on.
    pub fn devices(&self) -> impl Iterator<Item = (&LineSpec, &DeviceSpec)> {
        self.lines.iter().flat_map(|line| line.devices.iter().map(move |d| (line, d)))
    }
}

/// Every problem found in a configuration.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct ConfigErrors(pub Vec<ConfigError>);

impl fmt::Display for ConfigErrors {
    /// One problem a line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, error) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{error}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ConfigErrors {}

/// One problem, where it is.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct ConfigError {
    /// The file (or `--broker`, `demo.toml`).
    pub origin: String,
    /// The line, from 1; 0 when the problem is the whole file (it cannot be read).
    pub line: usize,
    /// The column in characters, from 1; 0 with line 0.
    pub column: usize,
    /// What was seen and what is allowed.
    pub message: String,
}

impl ConfigError {
    /// A problem of the whole input, at no line.
    fn whole(origin: &str, message: String) -> ConfigError {
        ConfigError { origin: origin.to_string(), line: 0, column: 0, message }
    }
}

impl fmt::Display for ConfigError {
    /// `plant.toml:12:5: device "drive1": omron-3g3rx has no parameter "F00x"`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}", self.origin, self.message)
        } else {
            write!(f, "{}:{}:{}: {}", self.origin, self.line, self.column, self.message)
        }
    }
}

impl std::error::Error for ConfigError {}
