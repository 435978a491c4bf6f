//! What the edge knows of one device, whatever it publishes as: the latest reading of every
//! cell and the one last published, and whether the device answers.
//!
//! A poll is *answered* when the device replied: with values, or with an exception (or a
//! reply that does not fit the read: something is alive on that unit). It is *silent* when no
//! reply came: a timeout, a bad checksum or garbage, a failed port, the poller's back-off.
//! `death_after` silent polls in a row, any group, and the device is dead; the next answered
//! poll brings it back.

use std::time::SystemTime;

use ferrobus::poll::{FailureKind, Group, Sample};

use super::DeviceRef;
use super::deadband::{Seen, beyond};
use crate::config::DeviceSpec;

/// One cell's latest reading and the one last published.
#[derive(Clone, Debug)]
pub(crate) struct CellState {
    /// The latest reading.
    pub(crate) latest: Seen,
    /// When it was taken.
    pub(crate) time: SystemTime,
    /// The reading last published (or stored while offline).
    pub(crate) published: Seen,
}

/// What a sample did to the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Liveness {
    /// It answered; `back` when it was dead or never answered before.
    Answered {
        /// It was not alive before this poll.
        back: bool,
    },
    /// No reply; `died` when this poll made it dead.
    Silent {
        /// This was the `death_after`-th silent poll in a row.
        died: bool,
    },
}

/// A configured device and what is known of it.
#[derive(Clone, Debug)]
pub(crate) struct Device {
    /// Its id in topics and records.
    pub(crate) id: String,
    /// Where it is in the plant.
    pub(crate) at: DeviceRef,
    /// Its groups, as the plant gives them.
    pub(crate) groups: Vec<Group>,
    /// `[group][cell]`: the engineering change that is published.
    deadbands: Vec<Vec<f64>>,
    /// Silent polls in a row before it is dead.
    death_after: u32,
    /// `[group][cell]`.
    pub(crate) cells: Vec<Vec<CellState>>,
    /// Silent polls in a row.
    silent: u32,
    /// Whether it answers (false until its first answer).
    pub(crate) alive: bool,
    /// Whether it ever answered in this run.
    pub(crate) answered_once: bool,
}

/// Whether a failed poll still got a reply from the device.
fn is_answer(kind: FailureKind) -> bool {
    matches!(kind, FailureKind::Exception | FailureKind::BadReply)
}

impl Device {
    /// The device `spec` at `at`, nothing read yet.
    pub(crate) fn new(spec: &DeviceSpec, at: DeviceRef) -> Device {
        let cells = spec
            .groups
            .iter()
            .map(|g| {
                g.cells
                    .iter()
                    .map(|_| CellState { latest: Seen::Unread, time: SystemTime::UNIX_EPOCH, published: Seen::Unread })
                    .collect()
            })
            .collect();
        Device {
            id: spec.id.clone(),
            at,
            groups: spec.groups.clone(),
            deadbands: spec.deadbands.clone(),
            death_after: spec.death_after.max(1),
            cells,
            silent: 0,
            alive: false,
            answered_once: false,
        }
    }

    /// Takes a poll of group `group`: the cells' latest readings and the device's liveness;
    /// `None` (nothing changes) for a group the device does not have.
    pub(crate) fn apply(&mut self, group: usize, sample: &Sample) -> Option<Liveness> {
        let time = sample.time;
        let cells = self.cells.get_mut(group)?;
        let answered = match &sample.result {
            Ok(readings) => {
                for reading in readings {
                    if let Some(cell) = cells.get_mut(reading.cell) {
                        cell.latest = match &reading.raw {
                            Ok(raw) => Seen::Value(raw.clone()),
                            Err(why) => Seen::Failed(why.clone()),
                        };
                        cell.time = time;
                    }
                }
                true
            }
            Err(failure) if is_answer(failure.kind) => {
                for cell in cells {
                    cell.latest = Seen::Failed(failure.diagnosis.clone());
                    cell.time = time;
                }
                true
            }
            Err(_) => false,
        };
        if !answered {
            return Some(self.silence());
        }
        let back = !self.alive;
        self.alive = true;
        self.answered_once = true;
        self.silent = 0;
        Some(Liveness::Answered { back })
    }

    fn silence(&mut self) -> Liveness {
        self.silent = self.silent.saturating_add(1);
        let died = self.alive && self.silent >= self.death_after;
        if died {
            self.alive = false;
        }
        Liveness::Silent { died }
    }

    /// The cells of `group` whose latest reading is to be published (beyond the deadband).
    pub(crate) fn changes(&self, group: usize) -> Vec<usize> {
        let (Some(cells), Some(spec)) = (self.cells.get(group), self.groups.get(group)) else { return Vec::new() };
        let deadbands = self.deadbands.get(group);
        cells
            .iter()
            .zip(&spec.cells)
            .enumerate()
            .filter(|(i, (state, cell))| {
                let deadband = deadbands.and_then(|d| d.get(*i)).copied().unwrap_or(0.0);
                beyond(cell, &state.published, &state.latest, deadband)
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// Marks these cells of `group` as published.
    pub(crate) fn mark_published(&mut self, group: usize, cells: &[usize]) {
        for &i in cells {
            if let Some(state) = self.cells.get_mut(group).and_then(|g| g.get_mut(i)) {
                state.published = state.latest.clone();
            }
        }
    }

    /// Marks every cell as published (a birth carries them all).
    pub(crate) fn mark_all_published(&mut self) {
        for state in self.cells.iter_mut().flatten() {
            state.published = state.latest.clone();
        }
    }

    /// The `(group, cell)` named `name`, the first if several groups hold it.
    pub(crate) fn find(&self, name: &str) -> Option<(usize, usize)> {
        self.groups
            .iter()
            .enumerate()
            .find_map(|(g, group)| group.cells.iter().position(|c| c.name == name).map(|c| (g, c)))
    }

    /// The cell at `(group, cell)`.
    pub(crate) fn cell(&self, group: usize, cell: usize) -> Option<&ferrobus::poll::Cell> {
        self.groups.get(group).and_then(|g| g.cells.get(cell))
    }

    /// The state of the cell at `(group, cell)`.
    pub(crate) fn state(&self, group: usize, cell: usize) -> Option<&CellState> {
        self.cells.get(group).and_then(|g| g.get(cell))
    }
}

/// The plant's devices, in line and device order.
pub(crate) fn devices_of(plant: &crate::config::Plant) -> Vec<Device> {
    plant
        .lines
        .iter()
        .enumerate()
        .flat_map(|(line, spec)| {
            spec.devices.iter().enumerate().map(move |(device, d)| Device::new(d, DeviceRef { line, device }))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use ferrobus::poll::{Failure, Layout, Reading, Table, Traffic};
    use ferrobus_profile::Value;

    use super::*;

    fn device(death_after: u32) -> Device {
        let group = Group::raw(
            "g",
            ferrobus::poll::RawRange { table: Table::Holding, ..Default::default() },
            &Layout::default(),
        )
        .unwrap();
        let spec = DeviceSpec {
            id: "d".into(),
            unit: 1,
            profile: None,
            groups: vec![group],
            deadbands: vec![vec![0.0]],
            death_after,
        };
        Device::new(&spec, DeviceRef { line: 0, device: 0 })
    }

    fn sample(result: Result<Vec<Reading>, Failure>) -> Sample {
        Sample {
            group: 0,
            seq: 0,
            time: SystemTime::UNIX_EPOCH,
            due: Duration::ZERO,
            started: Duration::ZERO,
            response_time: Duration::ZERO,
            overrun: false,
            result,
            traffic: Traffic::default(),
        }
    }

    fn failure(kind: FailureKind) -> Sample {
        sample(Err(Failure { kind, exception: None, diagnosis: format!("{kind:?}") }))
    }

    fn value(n: i128) -> Sample {
        sample(Ok(vec![Reading { cell: 0, raw: Ok(Value::Int(n)), scaled: None, shown: String::new() }]))
    }

    #[test]
    fn an_exception_or_a_reply_that_does_not_fit_is_an_answer_noise_and_silence_are_not() {
        for kind in [FailureKind::Exception, FailureKind::BadReply] {
            let mut d = device(1);
            assert_eq!(d.apply(0, &failure(kind)), Some(Liveness::Answered { back: true }), "{kind:?}");
            assert!(matches!(d.state(0, 0).map(|s| &s.latest), Some(Seen::Failed(_))));
        }
        for kind in
            [FailureKind::Timeout, FailureKind::Crc, FailureKind::Garbage, FailureKind::Port, FailureKind::Backoff]
        {
            let mut d = device(1);
            d.apply(0, &value(1));
            assert_eq!(d.apply(0, &failure(kind)), Some(Liveness::Silent { died: true }), "{kind:?}");
            assert_eq!(d.state(0, 0).map(|s| &s.latest), Some(&Seen::Value(Value::Int(1))), "the value is kept");
        }
    }

    #[test]
    fn a_device_that_never_answered_does_not_die_and_death_after_0_counts_as_1() {
        let mut d = device(0);
        assert_eq!(d.apply(0, &failure(FailureKind::Timeout)), Some(Liveness::Silent { died: false }));
        assert_eq!(d.apply(0, &value(1)), Some(Liveness::Answered { back: true }));
        assert_eq!(d.apply(0, &value(1)), Some(Liveness::Answered { back: false }));
        assert_eq!(d.apply(0, &failure(FailureKind::Timeout)), Some(Liveness::Silent { died: true }));
    }

    #[test]
    fn a_sample_of_a_group_the_device_does_not_have_changes_nothing() {
        let mut d = device(1);
        assert_eq!(d.apply(7, &value(1)), None);
        assert_eq!(d.apply(7, &failure(FailureKind::Timeout)), None);
        assert!(d.changes(7).is_empty());
        assert!(!d.answered_once);
    }
}
