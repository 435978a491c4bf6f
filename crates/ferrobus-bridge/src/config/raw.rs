//! The file's sections as written: serde structs that refuse unknown keys and keep the span
//! of every value a later check may need to point at. Nothing is interpreted here.

use std::collections::BTreeMap;

use serde::Deserialize;
use toml::Spanned;

/// A string with where it was written.
pub(super) type Text = Spanned<String>;

/// `[broker]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Broker {
    pub address: Text,
    pub client_id: Option<Text>,
    pub username: Option<String>,
    pub password: Option<Text>,
    pub password_file: Option<Text>,
    pub password_env: Option<Text>,
    pub keep_alive: Option<Text>,
    pub reconnect: Option<Text>,
    pub tls: Option<Spanned<Tls>>,
}

/// `[broker.tls]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Tls {
    pub ca: Text,
    pub cert: Option<Text>,
    pub key: Option<Text>,
    pub server_name: Option<Text>,
}

/// `[sparkplug]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Sparkplug {
    pub group_id: Text,
    pub edge_node_id: Text,
    pub primary_host: Option<Text>,
    #[serde(default)]
    pub uint_in_long_value: bool,
}

/// `[plain]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Plain {
    pub prefix: Text,
    #[serde(default)]
    pub retain: bool,
    pub qos: Option<Spanned<i64>>,
    pub discovery: Option<Spanned<bool>>,
    pub discovery_prefix: Option<Text>,
}

/// `[store]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Store {
    pub memory: Option<Text>,
    pub dir: Option<Text>,
    pub disk: Option<Text>,
}

/// `[[line]]` without its devices (they are read one by one, so that a mistake in one does
/// not hide the others').
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Line {
    pub name: Text,
    pub mode: Option<Text>,
    pub port: Option<Text>,
    pub tcp: Option<Text>,
    pub rtu_tcp: Option<Text>,
    pub simulated: Option<Spanned<bool>>,
    pub baud: Option<Spanned<i64>>,
    pub parity: Option<Text>,
    pub data_bits: Option<Spanned<i64>>,
    pub stop_bits: Option<Spanned<i64>>,
    pub rs485: Option<Text>,
    pub low_latency: Option<Spanned<bool>>,
    pub ascii: Option<Spanned<bool>>,
    pub timeout: Option<Text>,
    pub retries: Option<Spanned<i64>>,
    pub connect_timeout: Option<Text>,
    pub late_window: Option<Text>,
    pub echo_suppression: Option<bool>,
    pub in_flight: Option<Spanned<i64>>,
}

/// `[[line.device]]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Device {
    pub id: Text,
    pub unit: Spanned<i64>,
    pub profile: Option<Text>,
    pub every: Option<Text>,
    pub deadband: Option<Spanned<f64>>,
    pub death_after: Option<Spanned<i64>>,
    #[serde(default)]
    pub points: Vec<Text>,
    #[serde(default)]
    pub groups: Vec<Text>,
    #[serde(default)]
    pub deadbands: BTreeMap<Text, Spanned<f64>>,
    #[serde(default)]
    pub poll: Vec<Spanned<Poll>>,
    #[serde(default)]
    pub raw: Vec<Spanned<Raw>>,
}

/// `[[line.device.poll]]`: more points at another rate.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Poll {
    pub every: Text,
    #[serde(default)]
    pub points: Vec<Text>,
    #[serde(default)]
    pub groups: Vec<Text>,
    pub deadband: Option<Spanned<f64>>,
}

/// `[[line.device.raw]]`: a register or bit range by wire address.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct Raw {
    pub table: Text,
    pub address: Spanned<i64>,
    pub count: Option<Spanned<i64>>,
    #[serde(rename = "type")]
    pub format: Option<Text>,
    pub order: Option<Text>,
    pub name: Option<Text>,
    #[serde(default)]
    pub names: Vec<Text>,
    pub every: Option<Text>,
    pub deadband: Option<Spanned<f64>>,
}
