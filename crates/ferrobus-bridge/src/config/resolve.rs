//! From the file's text to a [`Plant`]: the sections read one by one (so every mistake is
//! reported, each at its place), then checked and turned into what the bridge runs.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use ferrobus_profile::Profile;
use ferrobus_profile::source::{Place, bounded};
use serde::Deserialize;
use toml::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use super::raw::{self, Text};
use super::text::{duration, host_port, size};
use super::{Broker, BrokerTls, ConfigError, ConfigErrors, Mode, PlainConfig, Plant, SparkplugConfig};
use crate::sparkplug::convert::UintEncoding;
use crate::sparkplug::topic::check_id;
use crate::store::StoreConfig;

mod device;
mod line;

/// Home Assistant's default discovery prefix.
const DISCOVERY_PREFIX: &str = "homeassistant";

/// The slowest first reconnect delay (the delay doubles up to it).
const MAX_RECONNECT: Duration = Duration::from_secs(30);

/// Reads, checks and resolves a whole file.
pub(super) fn plant(text: &str, origin: &str, base_dir: &Path) -> Result<Plant, ConfigErrors> {
    let mut cx = Cx { text, origin, base_dir, errors: Vec::new(), profiles: HashMap::new(), plain: false };
    let (doc, syntax) = DeTable::parse_recoverable(text);
    for error in &syntax {
        cx.toml_error(error, 0..0);
    }
    // After a syntax error the rest of the tree cannot be trusted: report the syntax only.
    let plant = if cx.errors.is_empty() { Sections::split(&mut cx, doc.get_ref()).resolve(&mut cx) } else { None };
    match plant {
        Some(plant) if cx.errors.is_empty() => Ok(plant),
        _ => {
            cx.errors.sort_by_key(|e| (e.line, e.column));
            Err(ConfigErrors(cx.errors))
        }
    }
}

/// serde's type names as a configuration's reader knows them.
fn plain_words(message: &str) -> String {
    [
        ("expected i64", "expected a whole number"),
        ("expected f64", "expected a number"),
        ("expected a sequence", "expected an array such as [\"a\", \"b\"]"),
        ("expected a map", "expected a table"),
        ("missing field", "missing key"),
        ("unknown field", "unknown key"),
    ]
    .iter()
    .fold(message.to_string(), |m, (serde, ours)| m.replace(serde, ours))
}

/// What the checks share: the text (for positions), the errors found so far, and the
/// profiles loaded so far (one `Arc` each).
struct Cx<'a> {
    text: &'a str,
    origin: &'a str,
    base_dir: &'a Path,
    errors: Vec<ConfigError>,
    profiles: HashMap<String, Arc<Profile>>,
    /// Plain mode: metric names are topic levels (no `/`).
    plain: bool,
}

impl Cx<'_> {
    /// A problem at `span`; the message is bounded, as every message quoting the file is.
    fn at(&mut self, span: Range<usize>, message: impl Into<String>) {
        let Place { line, column } = Place::of(self.text, span.start);
        let message = bounded(&message.into());
        self.errors.push(ConfigError { origin: self.origin.to_string(), line, column, message });
    }

    /// The line of `span`, for "first at line N".
    fn line_of(&self, span: &Range<usize>) -> usize {
        Place::of(self.text, span.start).line
    }

    /// A TOML reader's error, at its span (or `fallback`'s), in the file's words.
    fn toml_error(&mut self, error: &toml::de::Error, fallback: Range<usize>) {
        let span = error.span().unwrap_or(fallback);
        self.at(span, plain_words(error.message().trim()));
    }

    /// `value` read as `T`; a mistake is reported and gives `None`.
    fn read<'i, T: Deserialize<'i>>(&mut self, value: &Spanned<DeValue<'i>>) -> Option<T> {
        let span = value.span();
        T::deserialize(ValueDeserializer::from(value.clone())).map_err(|e| self.toml_error(&e, span)).ok()
    }

    /// What a metric name may not hold: MQTT's wildcards, and in plain mode the topic
    /// separator (there a name is a topic level; in Sparkplug it is inside the payload).
    fn unfit_metric_name(&self, name: &str) -> Option<String> {
        let refused: &[char] = if self.plain { &['/', '+', '#'] } else { &['+', '#'] };
        (name.is_empty() || name.contains(refused)).then(|| {
            let mode = if self.plain { "in plain mode a metric name is a topic level: " } else { "" };
            let list: Vec<String> = refused.iter().map(char::to_string).collect();
            format!("metric name {name:?}: {mode}it is not empty and has no {}", list.join(", "))
        })
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
        let is_path = given.contains(['/', '\\']) || Path::new(given).extension().is_some();
        let key = if is_path { self.path(given).display().to_string() } else { given.clone() };
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
                let hint = if is_path { " (paths are relative to the configuration's folder)" } else { "" };
                self.at(name.span(), format!("profile {given:?}: {e}{hint}"));
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
    /// The devices of lines that could not be read: checked all the same.
    orphans: Vec<raw::Device>,
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
            match line {
                Some(line) => self.lines.push((line, devices)),
                None => self.orphans.extend(devices),
            }
        }
    }

    /// The plant, when every section resolved (the errors are in `cx`).
    fn resolve(self, cx: &mut Cx<'_>) -> Option<Plant> {
        let mode = self.mode(cx);
        cx.plain = matches!(mode, Some(Mode::Plain(_)));
        let store = self.store.map_or_else(StoreConfig::default, |s| resolve_store(cx, &s));
        let mut ids = line::Ids::default();
        let mut lines = Vec::new();
        for (line, devices) in self.lines {
            if let Some(line) = line::resolve(cx, &line, &devices, &mut ids) {
                lines.push(line);
            }
        }
        for orphan in &self.orphans {
            device::resolve(cx, orphan);
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
            cx.at(id.span(), problem.to_string());
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
    let discovery = resolve_discovery(cx, p);
    ok &= discovery.is_ok();
    ok.then(|| PlainConfig { prefix: prefix.clone(), retain: p.retain, qos, discovery: discovery.ok().flatten() })
}

/// Home Assistant's discovery prefix when `discovery = true` (`homeassistant` by default);
/// `discovery_prefix` without it is a mistake (nothing would be discovered).
fn resolve_discovery(cx: &mut Cx<'_>, p: &raw::Plain) -> Result<Option<String>, ()> {
    let on = p.discovery.as_ref().is_some_and(|d| *d.get_ref());
    let Some(given) = &p.discovery_prefix else { return Ok(on.then(|| DISCOVERY_PREFIX.to_string())) };
    let prefix = given.get_ref();
    if !on {
        cx.at(
            given.span(),
            format!(
                "discovery_prefix = {prefix:?} without discovery = true: nothing is discovered; add discovery = true"
            ),
        );
        return Err(());
    }
    if prefix.is_empty() || prefix.contains(['+', '#']) || prefix.starts_with('/') || prefix.ends_with('/') {
        cx.at(
            given.span(),
            format!(
                "discovery_prefix = {prefix:?}: a topic prefix is not empty, has no + or #, and neither starts nor ends with / (Home Assistant's is \"homeassistant\")"
            ),
        );
        return Err(());
    }
    Ok(Some(prefix.clone()))
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
