//! What the edge knows of one device, whatever it publishes as: the latest reading of every
//! cell and the one last published, and whether the device answers.
//!
//! A poll is *answered* when the device replied: with values, or with an exception (or a
//! reply that does not fit the read: something is alive on that unit). It is *silent* when no
//! reply came: a timeout, a bad checksum or garbage, a failed port, the poller's back-off.
//! `death_after` silent polls in a row, any group, and the device is dead; the next answered
//! poll brings it back. That rule is [`Health`], the bridge's only one: the Sparkplug and plain
//! publishers follow it through [`Device::apply`], the bridge's status lines directly.

use std::time::SystemTime;

use ferrobus_tools::poll::{FailureKind, Group, Sample};

use super::deadband::{Seen, beyond};
use super::{DeviceRef, Reading};
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

/// Whether a device answers: the one liveness rule of the bridge. Every publisher
/// (Sparkplug's DBIRTH and DDEATH, plain mode's device status) and the bridge's status lines
/// follow it, each through [`Health::observe`].
///
/// A device is alive from its first answered poll; `death_after` silent polls in a row make
/// it dead (*died* when it had answered before, *given up* when it never had), and its next
/// answered poll brings it back.
#[derive(Clone, Debug, Default)]
pub(crate) struct Health {
    /// Silent polls in a row.
    silent: u32,
    /// It answers: answered, and not `death_after` silent polls in a row since.
    alive: bool,
    /// It is dead or given up: `death_after` silent polls in a row, no answer since.
    dead: bool,
    /// It answered at least once in this run.
    answered_once: bool,
}

/// What one poll did to a device's [`Health`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Liveness {
    /// It answered.
    Answered {
        /// It was not alive before this poll (its first answer in this run, or back from
        /// dead): it is born again.
        back: bool,
        /// It had died or been given up: it answers again (at last, when `first`).
        revived: bool,
        /// Its first answer in this run.
        first: bool,
    },
    /// No reply.
    Silent {
        /// It was alive and this is the `death_after`-th silent poll in a row: it is dead.
        died: bool,
        /// It never answered in this run and this is the `death_after`-th silent poll in a
        /// row: it is given up (never born, so nothing of it is published).
        given_up: bool,
        /// Silent polls in a row.
        polls: u32,
    },
}

impl Health {
    /// One poll: `answered` (a reply came: values, an exception, a reply that does not fit;
    /// see [`answered`]) or not, `death_after` (at least 1) silent polls in a row being
    /// death.
    pub(crate) fn observe(&mut self, answered: bool, death_after: u32) -> Liveness {
        if answered {
            let liveness = Liveness::Answered { back: !self.alive, revived: self.dead, first: !self.answered_once };
            self.silent = 0;
            self.alive = true;
            self.dead = false;
            self.answered_once = true;
            return liveness;
        }
        self.silent = self.silent.saturating_add(1);
        let dies = !self.dead && self.silent >= death_after.max(1);
        if dies {
            self.dead = true;
            self.alive = false;
        }
        Liveness::Silent { died: dies && self.answered_once, given_up: dies && !self.answered_once, polls: self.silent }
    }

    /// Whether it answers now.
    pub(crate) fn alive(&self) -> bool {
        self.alive
    }

    /// Whether it answered at least once in this run.
    pub(crate) fn answered_once(&self) -> bool {
        self.answered_once
    }
}

/// Whether a poll that ended with `result` heard the device: values, or a failure that is a
/// reply (an exception, a reply that does not fit the read: something is alive on that unit).
pub(crate) fn answered<T>(result: &Result<T, ferrobus_tools::poll::Failure>) -> bool {
    match result {
        Ok(_) => true,
        Err(failure) => matches!(failure.kind, FailureKind::Exception | FailureKind::BadReply),
    }
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
    /// Whether it answers.
    health: Health,
    /// What the last poll applied did to its health (`None` before the first, or when the
    /// last sample named no group of it): what the bridge's status lines say.
    last: Option<Liveness>,
}

impl Device {
    /// Each of its points' latest reading, in group and cell order (a point never read: none).
    pub(crate) fn readings(&self) -> impl Iterator<Item = Reading> + '_ {
        self.groups.iter().zip(&self.cells).flat_map(move |(group, cells)| {
            group.cells.iter().zip(cells).filter_map(move |(cell, state)| {
                let (shown, failed) = match &state.latest {
                    Seen::Unread => return None,
                    Seen::Value(value) => (cell.show(value), false),
                    Seen::Failed(why) => (why.clone(), true),
                };
                Some(Reading { device: self.id.clone(), point: cell.name.clone(), shown, time: state.time, failed })
            })
        })
    }

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
            health: Health::default(),
            last: None,
        }
    }

    /// Takes a poll of group `group`: the cells' latest readings and the device's liveness;
    /// `None` (nothing changes) for a group the device does not have.
    pub(crate) fn apply(&mut self, group: usize, sample: &Sample) -> Option<Liveness> {
        self.last = None;
        let time = sample.time;
        let cells = self.cells.get_mut(group)?;
        let answered = answered(&sample.result);
        match &sample.result {
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
            }
            // A reply, but no values: every cell of the group failed with it.
            Err(failure) if answered => {
                for cell in cells {
                    cell.latest = Seen::Failed(failure.diagnosis.clone());
                    cell.time = time;
                }
            }
            // Silence: the cells keep what they last read.
            Err(_) => {}
        }
        let liveness = self.health.observe(answered, self.death_after);
        self.last = Some(liveness);
        Some(liveness)
    }

    /// What the last sample [`Device::apply`] took did to its health.
    pub(crate) fn last_liveness(&self) -> Option<Liveness> {
        self.last
    }

    /// Whether it answers now.
    pub(crate) fn alive(&self) -> bool {
        self.health.alive()
    }

    /// Whether it answered at least once in this run.
    pub(crate) fn answered_once(&self) -> bool {
        self.health.answered_once()
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
    pub(crate) fn cell(&self, group: usize, cell: usize) -> Option<&ferrobus_tools::poll::Cell> {
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

    use ferrobus_profile::Value;
    use ferrobus_tools::poll::{Failure, Layout, Reading, Table, Traffic};

    use super::*;

    fn device(death_after: u32) -> Device {
        let group = Group::raw(
            "g",
            ferrobus_tools::poll::RawRange { table: Table::Holding, ..Default::default() },
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
            assert_eq!(
                d.apply(0, &failure(kind)),
                Some(Liveness::Answered { back: true, revived: false, first: true }),
                "{kind:?}"
            );
            assert!(matches!(d.state(0, 0).map(|s| &s.latest), Some(Seen::Failed(_))));
        }
        for kind in
            [FailureKind::Timeout, FailureKind::Crc, FailureKind::Garbage, FailureKind::Port, FailureKind::Backoff]
        {
            let mut d = device(1);
            d.apply(0, &value(1));
            assert_eq!(
                d.apply(0, &failure(kind)),
                Some(Liveness::Silent { died: true, given_up: false, polls: 1 }),
                "{kind:?}"
            );
            assert_eq!(d.state(0, 0).map(|s| &s.latest), Some(&Seen::Value(Value::Int(1))), "the value is kept");
        }
    }

    #[test]
    fn a_device_that_never_answered_is_given_up_not_dead_and_death_after_0_counts_as_1() {
        let mut d = device(0);
        let given_up = Liveness::Silent { died: false, given_up: true, polls: 1 };
        assert_eq!(d.apply(0, &failure(FailureKind::Timeout)), Some(given_up));
        assert_eq!(d.apply(0, &value(1)), Some(Liveness::Answered { back: true, revived: true, first: true }));
        assert_eq!(d.apply(0, &value(1)), Some(Liveness::Answered { back: false, revived: false, first: false }));
        assert_eq!(
            d.apply(0, &failure(FailureKind::Timeout)),
            Some(Liveness::Silent { died: true, given_up: false, polls: 1 })
        );
        assert!(!d.alive() && d.answered_once());
    }

    #[test]
    fn death_after_silent_polls_in_a_row_kill_once_an_answer_resets_the_count_and_brings_it_back() {
        let mut health = Health::default();
        let silent = |died, polls| Liveness::Silent { died, given_up: false, polls };
        assert_eq!(health.observe(true, 3), Liveness::Answered { back: true, revived: false, first: true });
        assert_eq!(health.observe(false, 3), silent(false, 1));
        assert_eq!(health.observe(false, 3), silent(false, 2));
        assert_eq!(health.observe(true, 3), Liveness::Answered { back: false, revived: false, first: false }, "reset");
        assert_eq!(health.observe(false, 3), silent(false, 1));
        assert_eq!(health.observe(false, 3), silent(false, 2));
        assert_eq!(health.observe(false, 3), silent(true, 3), "the third silent poll in a row");
        assert!(!health.alive());
        assert_eq!(health.observe(false, 3), silent(false, 4), "dead once");
        assert_eq!(health.observe(true, 3), Liveness::Answered { back: true, revived: true, first: false });
        assert!(health.alive());
    }

    #[test]
    fn values_an_exception_and_a_reply_that_does_not_fit_are_answers_silence_and_noise_are_not() {
        let answered_by = |kind| answered::<()>(&Err(Failure { kind, exception: None, diagnosis: String::new() }));
        assert!(answered::<()>(&Ok(())));
        assert!(answered_by(FailureKind::Exception) && answered_by(FailureKind::BadReply));
        for kind in
            [FailureKind::Timeout, FailureKind::Crc, FailureKind::Garbage, FailureKind::Port, FailureKind::Backoff]
        {
            assert!(!answered_by(kind), "{kind:?}");
        }
    }

    #[test]
    fn a_sample_of_a_group_the_device_does_not_have_changes_nothing() {
        let mut d = device(1);
        assert_eq!(d.apply(7, &value(1)), None);
        assert_eq!(d.apply(7, &failure(FailureKind::Timeout)), None);
        assert!(d.changes(7).is_empty());
        assert!(!d.answered_once());
    }
}
