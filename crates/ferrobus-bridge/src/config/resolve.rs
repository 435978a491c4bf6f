//! From the file's text to a [`Plant`]: the sections read one by one (so every mistake is
//! reported, each at its place), then checked and turned into what the bridge runs.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use ferrobus::poll::{Format, Group, GroupError, Layout};
use ferrobus::{ClientConfig, Rs485, SerialConfig};
use ferrobus_profile::{Order, Point, Profile, Table};
use ferrobus_proto::frame::{DataBits, LineConfig, Parity, StopBits};
use serde::Deserialize;
use toml::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use super::raw::{self, Text};
use super::text::{duration, host_port, line_col, size};
use super::{
    Broker, BrokerTls, ConfigError, ConfigErrors, Connection, DeviceSpec, LineSpec, Mode, PlainConfig, Plant,
    SparkplugConfig,
};
use crate::sparkplug::convert::UintEncoding;
use crate::sparkplug::topic::check_id;
use crate::store::StoreConfig;

/// The default poll period of a device.
const DEFAULT_EVERY: Duration = Duration::from_secs(1);
/// Polls without a reply before a device is declared dead, unless `death_after` says.
const DEFAULT_DEATH_AFTER: u32 = 3;
/// The slowest first reconnect delay (the delay doubles up to it).
const MAX_RECONNECT: Duration = Duration::from_secs(30);

/// Reads, checks and resolves a whole file.
pub(super) fn plant(text: &str, origin: &str, base_dir: &Path) -> Result<Plant, ConfigErrors> {
    let mut cx = Cx { text, origin, base_dir, errors: Vec::new(), profiles: HashMap::new() };
    let (doc, syntax) = DeTable::parse_recoverable(text);
    for error in &syntax {
        cx.toml_error(error, 0..0);
    }
    if !cx.errors.is_empty() {
        return Err(ConfigErrors(cx.errors));
    }
    let sections = Sections::split(&mut cx, doc.get_ref());
    let plant = sections.resolve(&mut cx);
    match plant {
        Some(plant) if cx.errors.is_empty() => Ok(plant),
        _ => Err(ConfigErrors(cx.errors)),
    }
}

/// What the checks share: the text (for positions), the errors found so far, and the
/// profiles loaded so far (one `Arc` each).
struct Cx<'a> {
    text: &'a str,
    origin: &'a str,
    base_dir: &'a Path,
    errors: Vec<ConfigError>,
    profiles: HashMap<String, Arc<Profile>>,
}

impl Cx<'_> {
    /// A problem at `span`.
    fn at(&mut self, span: Range<usize>, message: impl Into<String>) {
        let (line, column) = line_col(self.text, span.start);
        self.errors.push(ConfigError { origin: self.origin.to_string(), line, column, message: message.into() });
    }

    /// The line of `span`, for "first at line N".
    fn line_of(&self, span: &Range<usize>) -> usize {
        line_col(self.text, span.start).0
    }

    /// A TOML reader's error, at its span (or `fallback`'s).
    fn toml_error(&mut self, error: &toml::de::Error, fallback: Range<usize>) {
        let span = error.span().unwrap_or(fallback);
        self.at(span, error.message().trim().to_string());
    }

    /// `value` read as `T`; a mistake is reported and gives `None`.
    fn read<'i, T: Deserialize<'i>>(&mut self, value: &Spanned<DeValue<'i>>) -> Option<T> {
        let span = value.span();
        T::deserialize(ValueDeserializer::from(value.clone())).map_err(|e| self.toml_error(&e, span)).ok()
    }

    /// A path of the file, relative to its folder.
    fn path(&self, path: &str) -> PathBuf {
        self.base_dir.join(path)
    }

    /// A path that must name a file.
    fn existing_file(&mut self, key: &str, path: &Text) -> PathBuf {
        let full = self.path(path.get_ref());
        if !full.is_file() {
            self.at(
                path.span(),
                format!(
                    "{key} = {:?}: there is no file {} (paths are relative to the configuration's folder)",
                    path.get_ref(),
                    full.display()
                ),
            );
        }
        full
    }

    /// A duration key's value that must not be zero.
    fn period(&mut self, what: &str, value: &Text) -> Option<Duration> {
        match duration(value.get_ref()) {
            Ok(d) if d.is_zero() => {
                self.at(value.span(), format!("{what} = {:?}: a period must be longer than zero", value.get_ref()));
                None
            }
            Ok(d) => Some(d),
            Err(problem) => {
                self.at(value.span(), format!("{what}: {problem}"));
                None
            }
        }
    }

    /// A deadband that must be a number zero or above.
    fn deadband(&mut self, what: &str, value: &Spanned<f64>) -> f64 {
        let band = *value.get_ref();
        if band.is_finite() && band >= 0.0 {
            band
        } else {
            self.at(value.span(), format!("{what}: a deadband of {band}; it must be 0 (every change) or more"));
            0.0
        }
    }

    /// The profile `name` (built in) or at a path relative to the file, loaded once.
    fn profile(&mut self, name: &Text) -> Option<Arc<Profile>> {
        let given = name.get_ref();
        let key = if ferrobus_profile::BUILTIN.iter().any(|(n, _)| n == given) {
            given.clone()
        } else {
            self.path(given).display().to_string()
        };
        if let Some(profile) = self.profiles.get(&key) {
            return Some(Arc::clone(profile));
        }
        match Profile::load(&key) {
            Ok(profile) => {
                let profile = Arc::new(profile);
                self.profiles.insert(key, Arc::clone(&profile));
                Some(profile)
            }
            Err(e) => {
                let builtin: Vec<&str> = ferrobus_profile::BUILTIN.iter().map(|(n, _)| *n).collect();
                self.at(
                    name.span(),
                    format!(
                        "profile {given:?}: {e} (built in: {}; or a .toml path relative to this file)",
                        builtin.join(", ")
                    ),
                );
                None
            }
        }
    }
}

/// The top-level sections, found and read.
#[derive(Default)]
struct Sections {
    /// The top-level keys written, with their spans (read or not).
    given: HashMap<&'static str, Range<usize>>,
    broker: Option<raw::Broker>,
    sparkplug: Option<raw::Sparkplug>,
    plain: Option<raw::Plain>,
    store: Option<raw::Store>,
    lines: Vec<(raw::Line, Vec<raw::Device>)>,
    /// `[[line.device]]` entries written (read or not).
    devices_given: usize,
}

impl Sections {
    /// Each top-level key read as its section; unknown keys reported.
    fn split(cx: &mut Cx<'_>, doc: &DeTable<'_>) -> Sections {
        let mut s = Sections::default();
        for (key, value) in doc {
            let span = key.span();
            let name = key.get_ref().as_ref();
            if let Some(known) = ["broker", "sparkplug", "plain", "store", "line"].into_iter().find(|k| *k == name) {
                s.given.insert(known, span.clone());
            }
            match name {
                "broker" => s.broker = cx.read(value),
                "sparkplug" => s.sparkplug = cx.read(value),
                "plain" => s.plain = cx.read(value),
                "store" => s.store = cx.read(value),
                "line" => s.read_lines(cx, value),
                other => cx.at(
                    span,
                    format!(
                        "unknown key `{other}`; the file holds [broker], [sparkplug] or [plain], [store] and [[line]]"
                    ),
                ),
            }
        }
        s
    }

    /// Exactly one of `[sparkplug]` and `[plain]`.
    fn mode(&self, cx: &mut Cx<'_>) -> Option<Mode> {
        match (self.given.get("sparkplug"), self.given.get("plain")) {
            (Some(s), Some(p)) => {
                let (second, first) = if s.start > p.start { (s, "[plain]") } else { (p, "[sparkplug]") };
                cx.at(
                    second.clone(),
                    format!("both [sparkplug] and [plain]; a bridge publishes one way ({first} came first)"),
                );
                None
            }
            (None, None) => {
                cx.at(0..0, "no [sparkplug] or [plain] section; give one (group_id and edge_node_id, or prefix)");
                None
            }
            _ => match (&self.sparkplug, &self.plain) {
                (Some(s), _) => resolve_sparkplug(cx, s).map(Mode::Sparkplug),
                (_, Some(p)) => resolve_plain(cx, p).map(Mode::Plain),
                _ => None,
            },
        }
    }

    /// `[[line]]` entries, each with its `[[line.device]]` entries read one by one.
    fn read_lines(&mut self, cx: &mut Cx<'_>, value: &Spanned<DeValue<'_>>) {
        let Some(entries) = value.get_ref().as_array() else {
            cx.at(value.span(), "`line` must be an array of tables: write [[line]], once per line");
            return;
        };
        for entry in &**entries {
            let Some(table) = entry.get_ref().as_table() else {
                cx.at(entry.span(), "a line must be a table ([[line]])");
                continue;
            };
            let mut rest = DeTable::new();
            let mut devices = Vec::new();
            for (key, value) in table {
                if key.get_ref() == "device" {
                    self.devices_given += value.get_ref().as_array().map_or(1, |a| a.len());
                    devices = read_devices(cx, value);
                } else {
                    rest.insert(key.clone(), value.clone());
                }
            }
            let line: Option<raw::Line> = cx.read(&Spanned::new(entry.span(), DeValue::Table(rest)));
            if let Some(line) = line {
                self.lines.push((line, devices));
            }
        }
    }

    /// The plant, when every section resolved (the errors are in `cx`).
    fn resolve(self, cx: &mut Cx<'_>) -> Option<Plant> {
        let mode = self.mode(cx);
        let store = self.store.map_or_else(StoreConfig::default, |s| resolve_store(cx, &s));
        let mut ids = Ids::default();
        let mut lines = Vec::new();
        for (line, devices) in self.lines {
            if let Some(line) = resolve_line(cx, &line, &devices, &mut ids) {
                lines.push(line);
            }
        }
        if self.devices_given == 0 {
            let span = self.given.get("line").cloned().unwrap_or(0..0);
            cx.at(span, "no devices: add a [[line]] (name and a connection) with a [[line.device]] under it");
        }
        if !self.given.contains_key("broker") {
            cx.at(0..0, "no [broker] section; the bridge needs one with address = \"host:port\"");
        }
        let broker = self.broker.and_then(|b| resolve_broker(cx, &b, mode.as_ref()));
        Some(Plant { origin: cx.origin.to_string(), broker: broker?, mode: mode?, store, lines })
    }
}

/// `[[line.device]]` entries, each read on its own.
fn read_devices(cx: &mut Cx<'_>, value: &Spanned<DeValue<'_>>) -> Vec<raw::Device> {
    let Some(entries) = value.get_ref().as_array() else {
        cx.at(value.span(), "`device` must be an array of tables: write [[line.device]], once per device");
        return Vec::new();
    };
    entries.iter().filter_map(|entry| cx.read(entry)).collect()
}

/// A Sparkplug id key: no `/`, `+` or `#`, not empty.
fn sparkplug_id(cx: &mut Cx<'_>, what: &str, id: &Text) -> bool {
    match check_id(what, id.get_ref()) {
        Ok(()) => true,
        Err(problem) => {
            cx.at(id.span(), problem);
            false
        }
    }
}

fn resolve_sparkplug(cx: &mut Cx<'_>, s: &raw::Sparkplug) -> Option<SparkplugConfig> {
    let mut ok = sparkplug_id(cx, "group", &s.group_id);
    ok &= sparkplug_id(cx, "edge node", &s.edge_node_id);
    if let Some(host) = &s.primary_host {
        ok &= sparkplug_id(cx, "primary host", host);
    }
    ok.then(|| SparkplugConfig {
        group_id: s.group_id.get_ref().clone(),
        edge_node_id: s.edge_node_id.get_ref().clone(),
        primary_host: s.primary_host.as_ref().map(|h| h.get_ref().clone()),
        uint_encoding: if s.uint_in_long_value { UintEncoding::LongValue } else { UintEncoding::Spec },
    })
}

fn resolve_plain(cx: &mut Cx<'_>, p: &raw::Plain) -> Option<PlainConfig> {
    let prefix = p.prefix.get_ref();
    let mut ok = true;
    if prefix.is_empty() || prefix.contains(['+', '#']) || prefix.starts_with('/') || prefix.ends_with('/') {
        cx.at(
            p.prefix.span(),
            format!(
                "prefix = {prefix:?}: a topic prefix is not empty, has no + or #, and neither starts nor ends with /"
            ),
        );
        ok = false;
    }
    let qos = match &p.qos {
        None => 1,
        Some(q) => {
            if let Ok(q @ 0..=2) = u8::try_from(*q.get_ref()) {
                q
            } else {
                cx.at(q.span(), format!("qos = {}: MQTT's QoS is 0, 1 or 2", q.get_ref()));
                ok = false;
                0
            }
        }
    };
    ok.then(|| PlainConfig { prefix: prefix.clone(), retain: p.retain, qos })
}

fn resolve_store(cx: &mut Cx<'_>, s: &raw::Store) -> StoreConfig {
    let mut config = StoreConfig::default();
    let bytes = |cx: &mut Cx<'_>, what: &str, value: &Text| match size(value.get_ref()) {
        Ok(n) => Some(n),
        Err(problem) => {
            cx.at(value.span(), format!("{what}: {problem}"));
            None
        }
    };
    if let Some(memory) = s.memory.as_ref().and_then(|m| bytes(cx, "memory", m)) {
        match usize::try_from(memory) {
            Ok(m) => config.memory = m,
            Err(_) => cx.at(s.memory.as_ref().map_or(0..0, Spanned::span), "memory: more than this machine addresses"),
        }
    }
    if let Some(disk) = s.disk.as_ref().and_then(|d| bytes(cx, "disk", d)) {
        config.disk = disk;
    }
    config.dir = s.dir.as_ref().map(|d| cx.path(d.get_ref()));
    config
}

/// The broker; `mode` (when it resolved) names the default client id.
fn resolve_broker(cx: &mut Cx<'_>, b: &raw::Broker, mode: Option<&Mode>) -> Option<Broker> {
    let errors = cx.errors.len();
    let tls = b.tls.as_ref().map(|t| resolve_tls(cx, t));
    let default_port = if tls.is_some() { 8883 } else { 1883 };
    let (host, port) = host_port(b.address.get_ref(), default_port)
        .map_err(|problem| cx.at(b.address.span(), format!("address: {problem}")))
        .unwrap_or_default();
    let client_id = match &b.client_id {
        Some(id) if id.get_ref().trim().is_empty() => {
            cx.at(id.span(), "client_id is empty; leave it out for ferrobus-<edge_node_id>");
            String::new()
        }
        Some(id) => id.get_ref().clone(),
        None => mode.map(default_client_id).unwrap_or_default(),
    };
    let password = resolve_password(cx, b);
    let keep_alive = b.keep_alive.as_ref().map_or(Some(Duration::from_secs(30)), |k| cx.period("keep_alive", k));
    if let (Some(k), Some(given)) = (keep_alive, &b.keep_alive)
        && (k < Duration::from_secs(1) || k > Duration::from_secs(65_535))
    {
        cx.at(given.span(), format!("keep_alive = {:?}: MQTT's keep alive is 1s to 65535s", given.get_ref()));
    }
    let reconnect = b.reconnect.as_ref().map_or(Some(Duration::from_secs(1)), |r| cx.period("reconnect", r));
    if let (Some(r), Some(given)) = (reconnect, &b.reconnect)
        && r > MAX_RECONNECT
    {
        cx.at(
            given.span(),
            format!("reconnect = {:?}: the first retry delay is at most 30s (it doubles to 30s)", given.get_ref()),
        );
    }
    if password.is_some() && b.username.is_none() {
        cx.at(b.address.span(), "a password needs a username (MQTT sends none without one); add username");
    }
    if cx.errors.len() > errors {
        return None;
    }
    Some(Broker {
        host,
        port,
        client_id,
        username: b.username.clone(),
        password,
        tls: tls.flatten(),
        keep_alive: keep_alive.unwrap_or_default(),
        reconnect: reconnect.unwrap_or_default(),
    })
}

/// `ferrobus-<edge_node_id>`, or `ferrobus-<prefix>` with `/` as `-`.
fn default_client_id(mode: &Mode) -> String {
    match mode {
        Mode::Sparkplug(s) => format!("ferrobus-{}", s.edge_node_id),
        Mode::Plain(p) => format!("ferrobus-{}", p.prefix.replace('/', "-")),
    }
}

/// At most one of `password`, `password_file` (its first line) and `password_env`.
fn resolve_password(cx: &mut Cx<'_>, b: &raw::Broker) -> Option<String> {
    let given: Vec<&Text> = [&b.password, &b.password_file, &b.password_env].into_iter().flatten().collect();
    if let [_, second, ..] = given.as_slice() {
        cx.at(second.span(), "give one of password, password_file and password_env");
        return None;
    }
    if let Some(p) = &b.password {
        return Some(p.get_ref().clone());
    }
    if let Some(file) = &b.password_file {
        let path = cx.path(file.get_ref());
        return match std::fs::read_to_string(&path) {
            Ok(text) => Some(text.lines().next().unwrap_or_default().to_string()),
            Err(e) => {
                cx.at(
                    file.span(),
                    format!("password_file = {:?}: cannot read {}: {e}", file.get_ref(), path.display()),
                );
                None
            }
        };
    }
    let var = b.password_env.as_ref()?;
    let password = std::env::var(var.get_ref()).ok();
    if password.is_none() {
        cx.at(var.span(), format!("password_env = {:?}: that environment variable is not set", var.get_ref()));
    }
    password
}

/// `[broker.tls]`: the files must exist; `cert` and `key` come together.
fn resolve_tls(cx: &mut Cx<'_>, t: &Spanned<raw::Tls>) -> Option<BrokerTls> {
    let errors = cx.errors.len();
    let tls = t.get_ref();
    let ca = cx.existing_file("ca", &tls.ca);
    let cert = tls.cert.as_ref().map(|c| cx.existing_file("cert", c));
    let key = tls.key.as_ref().map(|k| cx.existing_file("key", k));
    if cert.is_some() != key.is_some() {
        cx.at(t.span(), "[broker.tls] has one of cert and key; mutual TLS needs both, server-only TLS neither");
    }
    (cx.errors.len() == errors).then(|| BrokerTls {
        ca,
        cert,
        key,
        server_name: tls.server_name.as_ref().map(|s| s.get_ref().clone()),
    })
}

/// Device ids (plant-wide) and line names seen so far, with where.
#[derive(Default)]
struct Ids {
    devices: HashMap<String, Range<usize>>,
    lines: HashMap<String, Range<usize>>,
}

/// Registers `name` in `seen`; a name seen before is reported at its second place.
fn first_use(cx: &mut Cx<'_>, seen: &mut HashMap<String, Range<usize>>, what: &str, name: &Text, rule: &str) -> bool {
    if let Some(first) = seen.get(name.get_ref()) {
        let line = cx.line_of(first);
        cx.at(name.span(), format!("{what} {:?} is used twice (first at line {line}); {rule}", name.get_ref()));
        return false;
    }
    seen.insert(name.get_ref().clone(), name.span());
    true
}

fn resolve_line(cx: &mut Cx<'_>, line: &raw::Line, devices: &[raw::Device], ids: &mut Ids) -> Option<LineSpec> {
    first_use(cx, &mut ids.lines, "line name", &line.name, "each line has its own");
    let connection = resolve_connection(cx, line);
    let client = resolve_client(cx, line);
    let simulated = matches!(connection, Some(Connection::Simulated { .. }));
    let mut units: HashMap<String, Range<usize>> = HashMap::new();
    let mut specs = Vec::new();
    for device in devices {
        first_use(cx, &mut ids.devices, "device id", &device.id, "ids are unique in a plant");
        let unit = Spanned::new(device.unit.span(), device.unit.get_ref().to_string());
        first_use(cx, &mut units, "unit", &unit, "each device on a line has its own");
        if let Some(spec) = resolve_device(cx, device) {
            if simulated && spec.profile.is_none() {
                cx.at(
                    device.id.span(),
                    format!(
                        "device {:?}: a simulated line simulates each device from its profile; give it one",
                        spec.id
                    ),
                );
            }
            specs.push(spec);
        }
    }
    Some(LineSpec { name: line.name.get_ref().clone(), connection: connection?, client: client?, devices: specs })
}

/// Exactly one of `port`, `tcp`, `rtu_tcp` and `simulated = true`, with the keys it takes.
fn resolve_connection(cx: &mut Cx<'_>, line: &raw::Line) -> Option<Connection> {
    let mut kinds: Vec<(&str, Range<usize>)> = Vec::new();
    if let Some(p) = &line.port {
        kinds.push(("port", p.span()));
    }
    if let Some(t) = &line.tcp {
        kinds.push(("tcp", t.span()));
    }
    if let Some(t) = &line.rtu_tcp {
        kinds.push(("rtu_tcp", t.span()));
    }
    if let Some(s) = line.simulated.as_ref().filter(|s| *s.get_ref()) {
        kinds.push(("simulated", s.span()));
    }
    kinds.sort_by_key(|(_, span)| span.start);
    let name = line.name.get_ref();
    let kind = match kinds.as_slice() {
        [] => {
            cx.at(
                line.name.span(),
                format!("line {name:?} has no connection; give one of port, tcp, rtu_tcp or simulated = true"),
            );
            return None;
        }
        [(kind, _)] => *kind,
        [(first, _), (second, span), ..] => {
            cx.at(span.clone(), format!("line {name:?} has both {first} and {second}; a line has one connection"));
            return None;
        }
    };
    refuse_serial_keys(cx, line, kind);
    match kind {
        "port" => serial(cx, line),
        "simulated" => line_config(cx, line).map(|line| Connection::Simulated { line }),
        "tcp" => tcp_address(cx, "tcp", line.tcp.as_ref()?).map(Connection::Tcp),
        _ => tcp_address(cx, "rtu_tcp", line.rtu_tcp.as_ref()?).map(Connection::RtuTcp),
    }
}

/// The serial keys on a line that is not a port (baud is also a simulated line's).
fn refuse_serial_keys(cx: &mut Cx<'_>, line: &raw::Line, kind: &str) {
    let spans = [
        ("parity", line.parity.as_ref().map(Spanned::span)),
        ("data_bits", line.data_bits.as_ref().map(Spanned::span)),
        ("stop_bits", line.stop_bits.as_ref().map(Spanned::span)),
        ("rs485", line.rs485.as_ref().map(Spanned::span)),
        ("low_latency", line.low_latency.as_ref().map(Spanned::span)),
        ("ascii", line.ascii.as_ref().map(Spanned::span)),
        ("baud", line.baud.as_ref().map(Spanned::span).filter(|_| kind != "simulated")),
    ];
    if kind == "port" {
        return;
    }
    for (key, span) in spans {
        if let Some(span) = span {
            cx.at(span, format!("{key} is a serial port's setting; this line is {kind}"));
        }
    }
}

fn tcp_address(cx: &mut Cx<'_>, key: &str, address: &Text) -> Option<String> {
    match host_port(address.get_ref(), 502) {
        Ok((host, port)) if host.contains(':') => Some(format!("[{host}]:{port}")),
        Ok((host, port)) => Some(format!("{host}:{port}")),
        Err(problem) => {
            cx.at(address.span(), format!("{key}: {problem}"));
            None
        }
    }
}

fn serial(cx: &mut Cx<'_>, line: &raw::Line) -> Option<Connection> {
    let path = line.port.as_ref()?;
    if path.get_ref().trim().is_empty() {
        cx.at(path.span(), "port is empty; name the serial port (\"/dev/ttyUSB0\", \"COM3\")");
    }
    let rs485 = match line.rs485.as_ref() {
        None => Some(Rs485::Auto),
        Some(r) => match r.get_ref().to_ascii_lowercase().as_str() {
            "auto" => Some(Rs485::Auto),
            "kernel" => Some(Rs485::Kernel),
            "rts" => Some(Rs485::Rts),
            _ => {
                cx.at(r.span(), format!("rs485 = {:?}: it is auto (the adapter), kernel or rts", r.get_ref()));
                None
            }
        },
    };
    let config = line_config(cx, line);
    let mut serial = SerialConfig::new(path.get_ref().clone(), config?);
    serial.rs485 = rs485?;
    serial.low_latency = line.low_latency.as_ref().is_some_and(|l| *l.get_ref());
    Some(Connection::Serial { config: serial, ascii: line.ascii.as_ref().is_some_and(|a| *a.get_ref()) })
}

/// Baud (19200 unless given), parity (even), data bits (8, or 7 with ascii) and stop bits
/// (1, or 2 without parity).
fn line_config(cx: &mut Cx<'_>, line: &raw::Line) -> Option<LineConfig> {
    let errors = cx.errors.len();
    let baud = line.baud.as_ref().map_or(Some(19_200), |b| {
        let baud = u32::try_from(*b.get_ref()).ok().filter(|baud| (50..=10_000_000).contains(baud));
        if baud.is_none() {
            cx.at(b.span(), format!("baud = {}: a line's baud is 50 to 10000000", b.get_ref()));
        }
        baud
    });
    let parity = line.parity.as_ref().map_or(Parity::Even, |p| match p.get_ref().to_ascii_lowercase().as_str() {
        "even" | "e" => Parity::Even,
        "odd" | "o" => Parity::Odd,
        "none" | "n" => Parity::None,
        _ => {
            cx.at(p.span(), format!("parity = {:?}: it is even, odd or none", p.get_ref()));
            Parity::Even
        }
    });
    let ascii = line.ascii.as_ref().is_some_and(|a| *a.get_ref());
    let data_bits = match line.data_bits.as_ref().map(|d| (d, *d.get_ref())) {
        None if ascii => DataBits::Seven,
        None | Some((_, 8)) => DataBits::Eight,
        Some((_, 7)) => DataBits::Seven,
        Some((d, n)) => {
            cx.at(d.span(), format!("data_bits = {n}: it is 8 (RTU) or 7 (ASCII)"));
            DataBits::Eight
        }
    };
    let stop_bits = match line.stop_bits.as_ref().map(|s| (s, *s.get_ref())) {
        None if parity == Parity::None => StopBits::Two,
        None | Some((_, 1)) => StopBits::One,
        Some((_, 2)) => StopBits::Two,
        Some((s, n)) => {
            cx.at(s.span(), format!("stop_bits = {n}: it is 1 or 2"));
            StopBits::One
        }
    };
    let config = LineConfig::new(baud?)?.with_parity(parity).with_data_bits(data_bits).with_stop_bits(stop_bits);
    (cx.errors.len() == errors).then_some(config)
}

/// The client's timeout, retries and connect timeout (the library's defaults unless given).
fn resolve_client(cx: &mut Cx<'_>, line: &raw::Line) -> Option<ClientConfig> {
    let errors = cx.errors.len();
    let mut client = ClientConfig::default();
    if let Some(timeout) = line.timeout.as_ref().and_then(|t| cx.period("timeout", t)) {
        client.timeout = timeout;
    }
    if let Some(timeout) = line.connect_timeout.as_ref().and_then(|t| cx.period("connect_timeout", t)) {
        client.connect_timeout = timeout;
    }
    if let Some(retries) = &line.retries {
        match u32::try_from(*retries.get_ref()) {
            Ok(r @ 0..=100) => client.retries = r,
            _ => cx.at(retries.span(), format!("retries = {}: it is 0 to 100", retries.get_ref())),
        }
    }
    if let Some(echo) = line.echo_suppression {
        client.echo_suppression = echo;
    }
    (cx.errors.len() == errors).then_some(client)
}

/// One set of profile points polled at one rate: the device's own, or a `[[line.device.poll]]`.
struct PointSet<'a> {
    span: Range<usize>,
    every: Duration,
    points: &'a [Text],
    groups: &'a [Text],
    deadband: f64,
}

/// Where a group came from, to point at the second use of a metric name.
enum Source<'a> {
    Points(&'a PointSet<'a>),
    Raw(&'a Spanned<raw::Raw>),
}

fn resolve_device(cx: &mut Cx<'_>, d: &raw::Device) -> Option<DeviceSpec> {
    let errors = cx.errors.len();
    let id = d.id.get_ref();
    sparkplug_id(cx, "device", &d.id);
    let unit = u8::try_from(*d.unit.get_ref()).ok().filter(|u| (1..=247).contains(u)).unwrap_or_else(|| {
        let seen = d.unit.get_ref();
        cx.at(d.unit.span(), format!("device {id:?}: unit {seen}; a device's unit is 1 to 247 (0 is broadcast)"));
        1
    });
    let profile = d.profile.as_ref().and_then(|p| cx.profile(p));
    let every = d.every.as_ref().map_or(Some(DEFAULT_EVERY), |e| cx.period("every", e)).unwrap_or(DEFAULT_EVERY);
    let deadband = d.deadband.as_ref().map_or(0.0, |b| cx.deadband("deadband", b));
    let death_after = match &d.death_after {
        None => DEFAULT_DEATH_AFTER,
        Some(n) => u32::try_from(*n.get_ref()).ok().filter(|n| *n > 0).unwrap_or_else(|| {
            cx.at(n.span(), format!("death_after = {}: it is 1 or more polls", n.get_ref()));
            DEFAULT_DEATH_AFTER
        }),
    };
    let sets = point_sets(cx, d, every, deadband);
    if d.profile.is_some() && profile.is_none() {
        return None;
    }
    let mut groups: Vec<(Group, f64, Source<'_>)> = Vec::new();
    for set in &sets {
        for group in profile_groups(cx, id, profile.as_deref(), unit, set) {
            groups.push((group, set.deadband, Source::Points(set)));
        }
    }
    for range in &d.raw {
        if let Some(group) = raw_group(cx, id, unit, every, range) {
            let band = range.get_ref().deadband.as_ref().map_or(deadband, |b| cx.deadband("deadband", b));
            groups.push((group, band, Source::Raw(range)));
        }
    }
    if groups.is_empty() && cx.errors.len() == errors {
        cx.at(d.id.span(), format!("device {id:?} polls nothing; give points or groups (with a profile), a [[line.device.poll]] or a [[line.device.raw]]"));
    }
    check_metric_names(cx, id, profile.as_deref(), &groups);
    let deadbands = deadbands(cx, d, &groups);
    (cx.errors.len() == errors).then(|| DeviceSpec {
        id: id.clone(),
        unit,
        profile,
        groups: groups.into_iter().map(|(g, _, _)| g).collect(),
        deadbands,
        death_after,
    })
}

/// The device's own points and groups (if any), then each `[[line.device.poll]]`.
fn point_sets<'a>(cx: &mut Cx<'_>, d: &'a raw::Device, every: Duration, deadband: f64) -> Vec<PointSet<'a>> {
    let mut sets = Vec::new();
    if !d.points.is_empty() || !d.groups.is_empty() {
        let span = d.points.first().or(d.groups.first()).map_or_else(|| d.id.span(), Spanned::span);
        sets.push(PointSet { span, every, points: &d.points, groups: &d.groups, deadband });
    }
    for poll in &d.poll {
        let p = poll.get_ref();
        let every = cx.period("every", &p.every).unwrap_or(every);
        let deadband = p.deadband.as_ref().map_or(deadband, |b| cx.deadband("deadband", b));
        if p.points.is_empty() && p.groups.is_empty() {
            cx.at(poll.span(), "a [[line.device.poll]] names no points and no groups");
        }
        sets.push(PointSet { span: poll.span(), every, points: &p.points, groups: &p.groups, deadband });
    }
    sets
}

/// The planner's groups for one point set; every unknown name is reported, at its place.
fn profile_groups(cx: &mut Cx<'_>, id: &str, profile: Option<&Profile>, unit: u8, set: &PointSet<'_>) -> Vec<Group> {
    let Some(profile) = profile else {
        cx.at(
            set.span.clone(),
            format!("device {id:?} has no profile; points and groups need one (raw ranges do not)"),
        );
        return Vec::new();
    };
    let mut known = true;
    let lookups: [(&[Text], &'static str); 2] = [(set.points, "parameter"), (set.groups, "group")];
    for (names, what) in lookups {
        for name in names {
            let found = if what == "group" { profile.group(name.get_ref()) } else { profile.find(name.get_ref()) };
            if found.is_empty() {
                let error =
                    GroupError::NoSuchPoint { profile: profile.origin.clone(), what, name: name.get_ref().clone() };
                cx.at(name.span(), format!("device {id:?}: {error}{}", suggestion(profile, what)));
                known = false;
            }
        }
    }
    if !known {
        return Vec::new();
    }
    let names: Vec<String> = set.points.iter().map(|p| p.get_ref().clone()).collect();
    let groups: Vec<String> = set.groups.iter().map(|g| g.get_ref().clone()).collect();
    Group::points(profile, unit, &names, &groups, set.every).unwrap_or_else(|e| {
        cx.at(set.span.clone(), format!("device {id:?}: {e}"));
        Vec::new()
    })
}

/// What the profile offers, for an unknown name's message.
fn suggestion(profile: &Profile, what: &str) -> String {
    if what == "group" {
        format!(" (its groups: {})", profile.groups().join(", "))
    } else {
        " (a code, a label or a glob such as \"d0*\")".to_string()
    }
}

/// The table names of a raw range.
fn table(name: &str) -> Option<Table> {
    match name.to_ascii_lowercase().as_str() {
        "coils" | "coil" => Some(Table::Coils),
        "discrete" | "discrete_inputs" | "inputs" => Some(Table::DiscreteInputs),
        "holding" | "holding_registers" => Some(Table::Holding),
        "input" | "input_registers" => Some(Table::Input),
        _ => None,
    }
}

/// A `[[line.device.raw]]` range as one group.
fn raw_group(cx: &mut Cx<'_>, id: &str, unit: u8, every: Duration, range: &Spanned<raw::Raw>) -> Option<Group> {
    let errors = cx.errors.len();
    let r = range.get_ref();
    let table = table(r.table.get_ref()).or_else(|| {
        cx.at(r.table.span(), format!("table = {:?}: it is coils, discrete, holding or input", r.table.get_ref()));
        None
    });
    let address = u16::try_from(*r.address.get_ref()).ok().or_else(|| {
        cx.at(
            r.address.span(),
            format!("address = {}: a wire address is 0 to 65535 (0x0000 to 0xFFFF)", r.address.get_ref()),
        );
        None
    });
    let format = r.format.as_ref().map_or(Some(Format::U16), |f| {
        Format::from_name(f.get_ref()).or_else(|| {
            let all: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
            cx.at(f.span(), format!("type = {:?}: it is one of {}", f.get_ref(), all.join(", ")));
            None
        })
    });
    let order = r.order.as_ref().map_or(Some(Order::default()), |o| {
        Order::from_name(o.get_ref()).or_else(|| {
            cx.at(o.span(), format!("order = {:?}: it is ABCD, CDAB, BADC or DCBA", o.get_ref()));
            None
        })
    });
    let every = r.every.as_ref().map_or(Some(every), |e| cx.period("every", e));
    let (table, address, format, order, every) = (table?, address?, format?, order?, every?);
    let format = if table.is_bits() { Format::Bit } else { format };
    let count = match &r.count {
        None => Some(format.width()),
        Some(c) => u16::try_from(*c.get_ref()).ok().filter(|c| *c > 0).or_else(|| {
            cx.at(c.span(), format!("count = {}: a range reads 1 or more items", c.get_ref()));
            None
        }),
    }?;
    let aliases = raw_names(cx, r, address, count, format)?;
    let layout = Layout { format, order, aliases, ..Layout::default() };
    let name =
        r.name.as_ref().map_or_else(|| format!("u{unit} {}@{address:#06x}", table.name()), |n| n.get_ref().clone());
    let group = Group::raw(&name, unit, table, address, count, every, &layout)
        .map_err(|e| cx.at(range.span(), format!("device {id:?}: {e}")))
        .ok()?;
    (cx.errors.len() == errors).then_some(group)
}

/// The cells' names: `names` in order, or `name` for a single cell, or `name.0`, `name.1`, ...
/// (nothing given: the address, `0x1000`).
fn raw_names(cx: &mut Cx<'_>, r: &raw::Raw, address: u16, count: u16, format: Format) -> Option<Vec<(u16, String)>> {
    let width = format.width().max(1);
    let cells = count / width;
    let at = |i: u16| address.saturating_add(i.saturating_mul(width));
    for name in r.names.iter().chain(&r.name) {
        if name.get_ref().is_empty() || name.get_ref().contains(['+', '#', '/']) {
            cx.at(name.span(), format!("name {:?}: a metric name is not empty and has no /, + or #", name.get_ref()));
            return None;
        }
    }
    if !r.names.is_empty() {
        if r.names.len() != usize::from(cells) {
            let span = r.names.first().map_or(0..0, Spanned::span);
            cx.at(span, format!("{} names for {cells} cells of {}", r.names.len(), format.name()));
            return None;
        }
        return Some((0..cells).zip(&r.names).map(|(i, n)| (at(i), n.get_ref().clone())).collect());
    }
    Some(match &r.name {
        Some(name) if cells == 1 => vec![(address, name.get_ref().clone())],
        Some(name) => (0..cells).map(|i| (at(i), format!("{}.{i}", name.get_ref()))).collect(),
        None => Vec::new(),
    })
}

/// A metric name is used once per device; the second use is reported where it was asked for.
fn check_metric_names(cx: &mut Cx<'_>, id: &str, profile: Option<&Profile>, groups: &[(Group, f64, Source<'_>)]) {
    let mut seen: HashMap<&str, Range<usize>> = HashMap::new();
    for (group, _, source) in groups {
        for cell in &group.cells {
            let span = source_span(profile, source, &cell.point);
            if let Some(first) = seen.get(cell.name.as_str()) {
                let line = cx.line_of(first);
                cx.at(
                    span,
                    format!("device {id:?}: metric {:?} is polled twice (first at line {line}); a device's metric names are unique", cell.name),
                );
            } else {
                seen.insert(&cell.name, span);
            }
        }
    }
}

/// Where a cell was asked for: the name that matched its point, or its range.
fn source_span(profile: Option<&Profile>, source: &Source<'_>, point: &Point) -> Range<usize> {
    match source {
        Source::Raw(range) => range.get_ref().name.as_ref().map_or_else(|| range.span(), Spanned::span),
        Source::Points(set) => {
            let same = |p: &&Point| p.table == point.table && p.address == point.address;
            let by_name = profile.and_then(|profile| {
                set.points
                    .iter()
                    .find(|n| profile.find(n.get_ref()).iter().any(same))
                    .or_else(|| set.groups.iter().find(|g| profile.group(g.get_ref()).iter().any(same)))
            });
            by_name.map_or_else(|| set.span.clone(), Spanned::span)
        }
    }
}

/// `[group][cell]`: the cell's own (`deadbands`), else its poll's or range's, else the
/// device's.
fn deadbands(cx: &mut Cx<'_>, d: &raw::Device, groups: &[(Group, f64, Source<'_>)]) -> Vec<Vec<f64>> {
    let mut own: Vec<(&str, f64)> = Vec::new();
    for (name, band) in &d.deadbands {
        let value = cx.deadband(&format!("deadbands.{}", name.get_ref()), band);
        let polled = groups.iter().flat_map(|(g, _, _)| &g.cells).any(|c| c.name.eq_ignore_ascii_case(name.get_ref()));
        if polled {
            own.push((name.get_ref(), value));
        } else {
            let names: Vec<&str> = groups.iter().flat_map(|(g, _, _)| &g.cells).map(|c| c.name.as_str()).collect();
            cx.at(
                name.span(),
                format!(
                    "deadbands: device {:?} polls no {:?}; it polls {}",
                    d.id.get_ref(),
                    name.get_ref(),
                    names.join(", ")
                ),
            );
        }
    }
    groups
        .iter()
        .map(|(group, band, _)| {
            group
                .cells
                .iter()
                .map(|c| own.iter().find(|(n, _)| c.name.eq_ignore_ascii_case(n)).map_or(*band, |(_, b)| *b))
                .collect()
        })
        .collect()
}
