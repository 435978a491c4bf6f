//! What the broker sends the edge node: NCMD (`Node Control/Rebirth`), DCMD (writes through
//! the profile's checks, all or nothing), and the primary host's STATE.

use std::time::SystemTime;

use super::{REBIRTH, SparkplugEdge};
use crate::edge::{Action, EdgeError, MAX_METRICS_PER_COMMAND, Reply};
use crate::sparkplug::convert::{self, to_raw};
use crate::sparkplug::payload::{Metric, MetricValue, Payload};
use crate::sparkplug::topic::{MessageType, Topic, parse_state, state_topic};

impl SparkplugEdge {
    pub(crate) fn message(&mut self, topic: &str, payload: &[u8], now: SystemTime) -> Reply {
        if let Some(host) = &self.config.primary_host
            && topic == state_topic(host)
        {
            return self.host_state(topic, payload, now);
        }
        let Some(parsed) = Topic::parse(topic) else { return self.ignore() };
        if parsed.group != self.config.group_id || parsed.node != self.config.edge_node_id {
            return self.ignore();
        }
        match (parsed.kind, parsed.device.as_deref()) {
            (MessageType::NCmd, None) => self.node_command(topic, payload, now),
            (MessageType::DCmd, Some(device)) => {
                let (actions, errors) = self.device_command(topic, device, payload);
                (Vec::new(), actions, errors)
            }
            _ => self.ignore(),
        }
    }

    fn ignore(&mut self) -> Reply {
        self.stats.ignored += 1;
        (Vec::new(), Vec::new(), Vec::new())
    }

    fn host_state(&mut self, topic: &str, payload: &[u8], now: SystemTime) -> Reply {
        let Some(state) = parse_state(payload) else {
            let detail = format!("not a host STATE: {:?}", String::from_utf8_lossy(payload));
            return (Vec::new(), Vec::new(), vec![EdgeError::Malformed { topic: topic.to_string(), detail }]);
        };
        if let (Some(last), Some(t)) = (self.host_timestamp, state.timestamp)
            && t < last
        {
            // An older STATE than the one acted on (the spec: ignore it).
            return self.ignore();
        }
        self.host_timestamp = state.timestamp.or(self.host_timestamp);
        self.host_online = state.online;
        if state.online {
            return (self.births_if_ready(now), Vec::new(), Vec::new());
        }
        if !self.node_born {
            return (Vec::new(), Vec::new(), Vec::new());
        }
        // The host is gone: no more data for it (samples are stored) until the next session.
        self.unborn();
        (Vec::new(), vec![Action::Reconnect], Vec::new())
    }

    fn node_command(&mut self, topic: &str, payload: &[u8], now: SystemTime) -> Reply {
        let payload = match Payload::decode(payload) {
            Ok(p) => p,
            Err(e) => return (Vec::new(), Vec::new(), vec![self.malformed(topic, &e)]),
        };
        let mut rebirth = false;
        let mut errors = Vec::new();
        for metric in &payload.metrics {
            match (metric.name.as_deref(), &metric.value) {
                (Some(REBIRTH), Some(MetricValue::Boolean(b))) => rebirth |= *b,
                (name, value) => {
                    let what = name.map_or_else(|| format!("alias {:?}", metric.alias), str::to_string);
                    let why = match (name, value) {
                        (Some(REBIRTH), Some(v)) => format!("{REBIRTH} takes a Boolean, not {}", convert::describe(v)),
                        (Some(REBIRTH), None) => format!("{REBIRTH} without a value"),
                        _ => format!("the edge node takes only {REBIRTH}"),
                    };
                    errors.push(self.refuse("NCMD", &self.config.edge_node_id.clone(), &what, &why));
                }
            }
        }
        let publishes = if rebirth && self.node_born {
            self.stats.rebirths += 1;
            self.births(now, false)
        } else {
            Vec::new()
        };
        (publishes, Vec::new(), errors)
    }

    fn device_command(&mut self, topic: &str, device: &str, payload: &[u8]) -> (Vec<Action>, Vec<EdgeError>) {
        let Some(i) = self.devices.iter().position(|d| d.device.id == device) else {
            return (Vec::new(), vec![self.refuse("DCMD", device, "the device", "no such device in this edge node")]);
        };
        let payload = match Payload::decode(payload) {
            Ok(p) => p,
            Err(e) => return (Vec::new(), vec![self.malformed(topic, &e)]),
        };
        let count = payload.metrics.len();
        if count > MAX_METRICS_PER_COMMAND {
            let why = format!("{count} metrics, and one DCMD writes at most {MAX_METRICS_PER_COMMAND}");
            return (Vec::new(), vec![self.refuse("DCMD", device, "the command", &why)]);
        }
        let mut actions = Vec::new();
        let mut errors = Vec::new();
        for metric in &payload.metrics {
            match self.write_of(i, metric) {
                Ok(action) => actions.push(action),
                Err((what, why)) => errors.push(self.refuse("DCMD", device, &what, &why)),
            }
        }
        if errors.is_empty() {
            self.stats.writes += actions.len() as u64;
            (actions, errors)
        } else {
            // All or nothing: a command with one refused metric writes none.
            (Vec::new(), errors)
        }
    }

    /// The write a DCMD metric asks for, or (the metric, why it is refused).
    fn write_of(&self, index: usize, metric: &Metric) -> Result<Action, (String, String)> {
        let target = self.devices.get(index).ok_or_else(|| (String::new(), "no such device".to_string()))?;
        let label = metric.name.clone().or_else(|| metric.alias.map(|a| format!("alias {a}"))).unwrap_or_default();
        let by_alias = metric.alias.and_then(|alias| {
            target.aliases.iter().enumerate().find_map(|(g, a)| a.iter().position(|x| *x == alias).map(|c| (g, c)))
        });
        let (group, cell) = match (metric.alias, by_alias) {
            (Some(alias), None) => return Err((label, format!("no metric has alias {alias}"))),
            (_, Some(found)) => found,
            (None, None) => match metric.name.as_deref() {
                Some(name) => {
                    target.device.find(name).ok_or_else(|| (label.clone(), "no metric of that name".to_string()))?
                }
                None => return Err(("a metric".to_string(), "neither a name nor an alias".to_string())),
            },
        };
        let point =
            &target.device.cell(group, cell).ok_or_else(|| (label.clone(), "no such metric".to_string()))?.point;
        let label = point.code.clone();
        let Some(value) = &metric.value else { return Err((label, "no value given (null)".to_string())) };
        let raw = to_raw(point, value).map_err(|e| (label.clone(), e.to_string()))?;
        let typed = point.show(&raw);
        point.check_write(&raw, &typed).map_err(|e| (label.clone(), e.to_string()))?;
        Ok(Action::Write { device: target.device.at, group, cell, raw, typed })
    }

    fn refuse(&mut self, command: &'static str, target: &str, metric: &str, reason: &str) -> EdgeError {
        self.stats.refused += 1;
        EdgeError::refused(command, target, metric, reason)
    }

    fn malformed(&mut self, topic: &str, error: &prost::DecodeError) -> EdgeError {
        self.stats.refused += 1;
        EdgeError::Malformed { topic: topic.to_string(), detail: format!("not a Sparkplug B payload: {error}") }
    }
}
