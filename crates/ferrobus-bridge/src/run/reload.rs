//! A plant file read again, carried out while the bridge runs ([`Options::reload`](super::Options)):
//! the [`Plan`](crate::config::reload::Plan) from the running plant to the new one, without
//! stopping the edge node's session to the broker (unless a broker or session setting changed).
//!
//! - A line goes on untouched (port, poller, counters) when it is unchanged and has the same
//!   devices, unchanged, in the same order. Any other line of the running plant is stopped: its
//!   poller (a poll in flight finishes) or its listener, and its client dropped; the reload waits
//!   for the reply a stopped line is still owed ([`ferrobus::Release`]) before it starts the new
//!   lines, so a line started again on the same port never takes another's reply. A line of the
//!   new plant that does not go on is started, with a tag no line had: the last events of a
//!   stopped line name no line and are dropped. An unchanged polled line whose devices changed
//!   (not simulated: its simulator is made of its devices) keeps its client, its port open,
//!   under a new poller: the client takes one request at a time, so the new poller's requests
//!   wait behind the old one's last. A line's poll counts add up across its restarts.
//! - The edge is told ([`Edge::reload`](crate::edge::Edge::reload)): a removed or changed device
//!   that is born gets its DDEATH now, an unchanged one keeps its session and aliases, an added
//!   or changed one is born at its first answered poll with aliases never given before.
//! - A broker or session setting changed: NDEATH and DISCONNECT, as at a stop, then a new session
//!   with the new settings (its NBIRTH and the DBIRTHs).
//! - A plan that cannot be carried out (a setting fixed for the bridge's life, the new broker's
//!   TLS files) changes nothing.

use std::collections::BTreeSet;
use std::time::SystemTime;

use tokio::sync::{oneshot, watch};

use super::lines::{self, GroupMap, RunningLine};
use super::mqtt::{Backoff, Session};
use super::{Bridge, LineReport, LineState, Status, broker};
use crate::config::reload::{Fate, plan};
use crate::config::{Connection, LineMode, Plant};
use crate::edge::DeviceRef;

use super::command::DeviceWrites;

/// Reloads whose line moves are kept, for the results of writes begun before them.
const MOVES_KEPT: usize = 16;

/// A plant file read again, for the running bridge to carry out.
#[derive(Debug)]
pub struct Reload {
    /// The plant read and checked.
    pub plant: Plant,
    /// What was done (the plan: `1 device added, 1 changed, 0 removed, 3 unchanged; ...`), or
    /// why nothing was.
    pub done: oneshot::Sender<Result<String, String>>,
}

impl Bridge {
    /// Carries out the plan from the running plant to `new`: what was done, or why nothing was.
    pub(super) async fn reload(&mut self, new: Plant) -> Result<String, String> {
        let plan = plan(&self.plant, &new).map_err(|fixed| fixed.to_string())?;
        let options =
            if plan.reconnect { Some(broker::options(&new.broker).map_err(|e| e.to_string())?) } else { None };
        let keep = kept_lines(&self.plant, &new, &plan.lines, &plan.devices);
        let kept: BTreeSet<usize> = keep.iter().flatten().copied().collect();
        let mut old: Vec<Option<LineState>> = std::mem::take(&mut self.lines).into_iter().map(Some).collect();
        let mut reports: Vec<Option<LineReport>> =
            std::mem::take(&mut self.report.lines).into_iter().map(Some).collect();
        // The running lines that stay open with other devices: by the new line's index.
        let open = open_lines(&self.plant, &new, &plan.lines);
        let reopened: BTreeSet<usize> = open.iter().flatten().copied().collect();
        let mut clients: Vec<Option<RunningLine>> = vec![None; old.len()];
        let mut releases = Vec::new();
        for (i, slot) in old.iter_mut().enumerate() {
            if kept.contains(&i) {
                continue;
            }
            let Some(line) = slot.take() else { continue };
            if let Some(poll) = &line.running.poll {
                poll.stop();
                if let Some(Some(report)) = reports.get_mut(i) {
                    report.add(&poll.counters());
                }
            }
            if reopened.contains(&i) && line.running.client.is_some() {
                // The client goes on (its port open) under a new poller: its requests queue
                // behind the stopped poller's last, so no reply is taken by another.
                if let Some(slot) = clients.get_mut(i) {
                    *slot = Some(RunningLine { poll: None, ..line.running.clone() });
                }
                continue;
            }
            releases.extend(line.running.client.as_ref().map(ferrobus::Client::release));
        }
        if plan.reconnect {
            self.close_session().await;
        }
        let now = SystemTime::now();
        let deaths = self.edge.reload(&new, &plan, now);
        self.publish_all(deaths);
        for release in releases {
            release.settled().await;
        }
        let mut lines = Vec::with_capacity(new.lines.len());
        let mut line_reports = Vec::with_capacity(new.lines.len());
        let mut moves = vec![None; old.len()];
        for (n, spec) in new.lines.iter().enumerate() {
            let was = match plan.lines.get(n) {
                Some(Fate::Unchanged { was } | Fate::Changed { was }) => Some(*was),
                _ => None,
            };
            let report = was.and_then(|w| reports.get_mut(w).and_then(Option::take));
            let report = report.unwrap_or_else(|| LineReport { name: spec.name.clone(), ..LineReport::default() });
            line_reports.push(LineReport { name: spec.name.clone(), ..report });
            if let Some(w) = keep.get(n).copied().flatten()
                && let Some(line) = old.get_mut(w).and_then(Option::take)
            {
                if let Some(slot) = moves.get_mut(w) {
                    *slot = Some(n);
                }
                lines.push(line);
                continue;
            }
            let tag = self.next_tag;
            self.next_tag = self.next_tag.saturating_add(1);
            let (stop, stopped) = watch::channel(());
            let open = open.get(n).copied().flatten().and_then(|w| clients.get_mut(w).and_then(Option::take));
            if let Some(open) = open {
                let (running, map) = lines::poll(tag, spec, open, lines::timing(spec), self.samples_tx.clone());
                let writes = vec![DeviceWrites::default(); spec.devices.len()];
                lines.push(LineState { running, map, writes, tag, _stop: stop });
                continue;
            }
            let (running, map) = match lines::start(tag, spec, self.samples_tx.clone(), stopped).await {
                Ok(started) => started,
                Err(e) => {
                    tracing::error!("reload: {e}: the line is not running");
                    let describe = "not started".to_string();
                    let running =
                        RunningLine { name: spec.name.clone(), describe, client: None, poll: None, sim: None };
                    (running, GroupMap::default())
                }
            };
            let writes = vec![DeviceWrites::default(); spec.devices.len()];
            lines.push(LineState { running, map, writes, tag, _stop: stop });
        }
        self.lines = lines;
        self.report.lines = line_reports;
        self.plant = new;
        self.epoch = self.epoch.wrapping_add(1);
        self.moves.push_back(moves);
        while self.moves.len() > MOVES_KEPT {
            self.moves.pop_front();
        }
        if let Some(options) = options {
            self.start_session(options);
        }
        self.say(Status::Note(format!("reload: {plan}")));
        Ok(plan.to_string())
    }

    /// A session with the new plant's broker, connecting now.
    fn start_session(&mut self, options: rumqttc::MqttOptions) {
        self.session = Session::start(options);
        self.broker = broker::describe(&self.plant.broker);
        self.backoff = Backoff::new(self.plant.broker.reconnect);
        self.reconnect_at = None;
        self.say(Status::Connecting { broker: self.broker.clone() });
        self.connect();
    }

    /// The index now of the running line tagged `tag`.
    pub(super) fn line_of(&self, tag: usize) -> Option<usize> {
        if self.lines.get(tag).is_some_and(|l| l.tag == tag) {
            return Some(tag);
        }
        self.lines.iter().position(|l| l.tag == tag)
    }

    /// `device` as it was named at reload `epoch`, named now: `None` once a reload stopped it.
    pub(super) fn moved(&self, epoch: u64, device: DeviceRef) -> Option<DeviceRef> {
        let behind = usize::try_from(self.epoch.checked_sub(epoch)?).ok()?;
        if behind > self.moves.len() {
            return None;
        }
        let start = self.moves.len() - behind;
        let mut line = device.line;
        for moves in self.moves.range(start..) {
            line = moves.get(line).copied().flatten()?;
        }
        Some(DeviceRef { line, device: device.device })
    }
}

/// For each line of `new`: the running line whose client stays open for it with other devices,
/// if any: an unchanged polled line that is neither simulated (its simulator is made of its
/// devices) nor listened to (no client).
fn open_lines(running: &Plant, new: &Plant, lines: &[Fate]) -> Vec<Option<usize>> {
    lines
        .iter()
        .enumerate()
        .map(|(n, fate)| {
            let Fate::Unchanged { was } = *fate else { return None };
            let spec = new.lines.get(n)?;
            let polled = spec.mode == LineMode::Poll && !matches!(spec.connection, Connection::Simulated { .. });
            (polled && running.lines.get(was).is_some()).then_some(was)
        })
        .collect()
}

/// For each line of `new`: the running line that goes on as it is, if any: unchanged, with the
/// same devices, unchanged, in the same order (so its poller's groups are the new line's).
fn kept_lines(running: &Plant, new: &Plant, lines: &[Fate], devices: &[Fate]) -> Vec<Option<usize>> {
    let firsts = |plant: &Plant| -> Vec<usize> {
        plant
            .lines
            .iter()
            .scan(0, |first, l| {
                let at = *first;
                *first += l.devices.len();
                Some(at)
            })
            .collect()
    };
    let (old_first, new_first) = (firsts(running), firsts(new));
    lines
        .iter()
        .enumerate()
        .map(|(n, fate)| {
            let Fate::Unchanged { was } = *fate else { return None };
            let count = new.lines.get(n)?.devices.len();
            let (o, f) = (*old_first.get(was)?, *new_first.get(n)?);
            let same = running.lines.get(was)?.devices.len() == count
                && (0..count).all(|d| devices.get(f + d) == Some(&Fate::Unchanged { was: o + d }));
            same.then_some(was)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::kept_lines;
    use crate::config::reload::plan;
    use crate::config::reload::tests::{RUNNING, plant};

    fn kept(new: &str) -> Vec<Option<usize>> {
        let (running, new) = (plant(RUNNING), plant(new));
        let plan = plan(&running, &new).unwrap();
        kept_lines(&running, &new, &plan.lines, &plan.devices)
    }

    #[test]
    fn a_line_goes_on_only_unchanged_with_the_same_devices_unchanged_in_the_same_order() {
        assert_eq!(kept(RUNNING), [Some(0), Some(1)]);
        // The lines swapped in the file: each goes on, at its new place.
        let (a, b) = RUNNING.split_at(RUNNING.find("[[line]]\nname = \"b\"").unwrap());
        let head = a.find("[[line]]").unwrap();
        assert_eq!(kept(&format!("{}{b}\n{}", &a[..head], &a[head..])), [Some(1), Some(0)]);
        // A device changed on line b: b starts again, a goes on.
        assert_eq!(kept(&RUNNING.replace("points = [\"d003\"]", "points = [\"d003\", \"d001\"]")), [Some(0), None]);
        // A device gone from line a: a starts again.
        let servo = RUNNING.find("[[line.device]]\nid = \"servo\"").unwrap();
        let end = RUNNING.find("[[line]]\nname = \"b\"").unwrap();
        assert_eq!(kept(&format!("{}{}", &RUNNING[..servo], &RUNNING[end..])), [None, Some(1)]);
        // A line's setting changed: it starts again.
        assert_eq!(kept(&RUNNING.replacen("simulated = true", "simulated = true\nbaud = 9600", 1)), [None, Some(1)]);
    }
}
