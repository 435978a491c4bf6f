//! The write guard: the one rule every writer applies before a value goes to the device.
//!
//! A write is refused, with what and why, when the point cannot be written (read-only, or in a
//! read-only table), when the raw value is outside the point's `min`..=`max`, or when the point
//! is run-locked (`while_running = false`) and the profile's `[state] running` point says the
//! drive runs — or cannot say, because it could not be read, was not read, or the write is a
//! broadcast that reads nothing. A profile without a `[state] running` rule cannot tell, so its
//! run-locked points are left to the device (which refuses them itself, e.g. the 3G3RX's 22h).
//!
//! The guard does no IO: the caller reads the point [`Profile::run_state_point`] names (only
//! when it names one) and hands the reading in as a [`RunState`].
//!
//! ```text
//!   Write { point, raw, typed } ──check_value──▶ access, range
//!                               ──run_state_point──▶ the caller reads it ──▶ RunState
//!   guard_write(write, state) = check_value + the run lock  ──▶ Ok | Refusal
//!   guard_span(run_locked_in(table, start, count), state)     the run lock of a write by address
//! ```

use crate::codec::ValueError;
use crate::model::{Point, Profile, Table, Value};

/// One write a writer is about to send: the point, the raw value, and how it was given (the
/// user's text, or the value shown in the point's unit), for the refusal's message.
#[derive(Clone, Copy, Debug)]
pub struct Write<'a> {
    /// The point written.
    pub point: &'a Point,
    /// The raw value (before scaling back: what [`Point::encode`] takes).
    pub raw: &'a Value,
    /// The value as given, for messages.
    pub typed: &'a str,
}

/// Whether the drive runs, as the caller found out from the profile's running point.
#[derive(Clone, Debug, PartialEq)]
pub enum RunState {
    /// The running point was read: its raw value.
    Read(Value),
    /// Reading the running point failed: why.
    Unreadable(String),
    /// The write is a broadcast: no reply, so the running point cannot be read with it.
    Broadcast,
    /// The running point was not read (the writer did not need to, or could not).
    NotRead,
}

/// Why the guard refuses a write.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Refusal {
    /// The value cannot be written to the point at all: read-only, out of range.
    #[error(transparent)]
    Value(#[from] ValueError),
    /// The point is run-locked and the running point says the drive runs.
    #[error("{code} cannot change while the drive runs ({state} = {shown}); stop it first")]
    Running {
        /// The point refused.
        code: String,
        /// The running point.
        state: String,
        /// Its value as read, in its unit or meaning.
        shown: String,
    },
    /// The point is run-locked and reading the running point failed.
    #[error("{code} cannot change while the drive runs, and reading {state} failed: {why}")]
    Unreadable {
        /// The point refused.
        code: String,
        /// The running point.
        state: String,
        /// Why the read failed.
        why: String,
    },
    /// The point is run-locked and the write is a broadcast, which cannot read the running point.
    #[error("{code} cannot change while the drive runs, and a broadcast cannot read whether it runs")]
    Broadcast {
        /// The point refused.
        code: String,
    },
    /// The point is run-locked and the writer did not read the running point.
    #[error("{code} cannot change while the drive runs, and {state} was not read to tell whether it runs")]
    NotRead {
        /// The point refused.
        code: String,
        /// The running point.
        state: String,
    },
    /// The value takes more registers than the device writes in one request; a value is never
    /// split across requests.
    #[error("{code} takes {items} registers, more than the {limit} the device writes in one request")]
    TooWide {
        /// The point refused.
        code: String,
        /// The registers its value takes.
        items: usize,
        /// The device's limit ([`Profile::write_limit`]).
        limit: u16,
    },
    /// The device answers neither function that writes the point's table (its `functions`).
    #[error("{code}: the device answers neither {single:#04x} nor {multiple:#04x}, the functions that write it")]
    NoFunction {
        /// The point refused.
        code: String,
        /// The single write's function code (0x05, 0x06).
        single: u8,
        /// The multiple write's (0x0F, 0x10).
        multiple: u8,
    },
}

impl Refusal {
    /// Whether the refusal is the run lock's (the drive runs, or whether it runs is unknown),
    /// not the value's or the request's.
    pub fn is_run_lock(&self) -> bool {
        matches!(
            self,
            Refusal::Running { .. } | Refusal::Unreadable { .. } | Refusal::Broadcast { .. } | Refusal::NotRead { .. }
        )
    }
}

impl Profile {
    /// The point a writer must read before writing `point`, to tell whether the drive runs:
    /// `Some` only for a run-locked point of a profile whose `[state] running` names a point.
    pub fn run_state_point(&self, point: &Point) -> Option<&Point> {
        if point.while_running {
            return None;
        }
        let rule = self.state.running.as_ref()?;
        self.point(&rule.point)
    }

    /// Whether raw value `raw` of the running point means that the drive runs.
    pub fn means_running(&self, raw: &Value) -> bool {
        let Some(rule) = &self.state.running else { return false };
        raw.as_int().is_some_and(|v| rule.values.iter().any(|r| i128::from(*r) == v))
    }

    /// The value half of the guard, needing no reading: the point is writable and the value in
    /// its range. Writers that check a value early (before they queue it) call this; every
    /// writer calls [`Profile::guard_write`] right before it sends.
    pub fn check_value(&self, write: &Write<'_>) -> Result<(), Refusal> {
        write.point.check_write(write.raw, write.typed)?;
        Ok(())
    }

    /// The write guard: [`Profile::check_value`], then the run lock with `state`, the reading of
    /// [`Profile::run_state_point`] (ignored when it names none).
    pub fn guard_write(&self, write: &Write<'_>, state: &RunState) -> Result<(), Refusal> {
        self.check_value(write)?;
        let Some(running) = self.run_state_point(write.point) else { return Ok(()) };
        self.run_lock(write.point.code.clone(), running, state)
    }

    /// The run-locked points that a write by address of `count` items from `start` in `table`
    /// touches (`write`, `mask`, `raw`: a writer that names no point), in address order; none
    /// when the profile names no running point.
    pub fn run_locked_in(&self, table: Table, start: u16, count: usize) -> Vec<&Point> {
        let end = usize::from(start) + count;
        self.points()
            .iter()
            .filter(|p| p.table == table && self.run_state_point(p).is_some())
            .filter(|p| {
                usize::from(p.address) < end
                    && usize::from(start) < usize::from(p.address) + usize::from(p.width.max(1))
            })
            .collect()
    }

    /// The run lock for a write by address that touches `locked` (from
    /// [`Profile::run_locked_in`]), with `state` the reading of the running point: the one
    /// rule of [`Profile::guard_write`], the refusal naming every point touched. No value is
    /// checked: a write by address is raw.
    pub fn guard_span(&self, locked: &[&Point], state: &RunState) -> Result<(), Refusal> {
        let Some(running) = locked.first().and_then(|p| self.run_state_point(p)) else { return Ok(()) };
        let code = locked.iter().map(|p| p.code.as_str()).collect::<Vec<_>>().join(", ");
        self.run_lock(code, running, state)
    }

    /// The run lock on `code` (one point, or the points a write by address touches).
    fn run_lock(&self, code: String, running: &Point, state: &RunState) -> Result<(), Refusal> {
        match state {
            RunState::Read(value) if self.means_running(value) => {
                Err(Refusal::Running { code, state: running.code.clone(), shown: running.show(value) })
            }
            RunState::Read(_) => Ok(()),
            RunState::Unreadable(why) => {
                Err(Refusal::Unreadable { code, state: running.code.clone(), why: why.clone() })
            }
            RunState::Broadcast => Err(Refusal::Broadcast { code }),
            RunState::NotRead => Err(Refusal::NotRead { code, state: running.code.clone() }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PROFILE: &str = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
        [state]\nrunning = { point = 'running', values = [1, 3] }\n\
        [[registers]]\nnumber=0\nname='F001'\nunit='Hz'\nscale=0.01\nmin=0\nmax=40000\naccess='rw'\n\
        [[registers]]\nnumber=1\nname='A003'\nunit='Hz'\nmin=30\nmax=400\naccess='rw'\nwhile_running=false\n\
        [[registers]]\nnumber=2\nname='running'\nvalues={ '0' = 'stop', '1' = 'run', '3' = 'jog' }\n\
        [[registers]]\nnumber=3\nname='d001'\nwhile_running=false\n";

    fn profile() -> Profile {
        Profile::parse(PROFILE, "guard.toml").unwrap()
    }

    fn guard(profile: &Profile, code: &str, raw: i128, state: &RunState) -> Result<(), Refusal> {
        let point = profile.point(code).unwrap();
        let raw = Value::Int(raw);
        let typed = point.show(&raw);
        profile.guard_write(&Write { point, raw: &raw, typed: &typed }, state)
    }

    #[test]
    fn a_run_locked_point_is_refused_while_the_running_point_reads_any_of_the_running_values() {
        let p = profile();
        for (raw, shown) in [(1, "run"), (3, "jog")] {
            let refusal = guard(&p, "A003", 50, &RunState::Read(Value::Int(raw))).unwrap_err();
            assert_eq!(
                refusal.to_string(),
                format!("A003 cannot change while the drive runs (running = {shown}); stop it first")
            );
            assert!(refusal.is_run_lock());
        }
        assert_eq!(guard(&p, "A003", 50, &RunState::Read(Value::Int(0))), Ok(()), "stopped");
    }

    #[test]
    fn a_run_locked_point_is_refused_when_whether_the_drive_runs_is_unknown() {
        let p = profile();
        let unreadable = guard(&p, "A003", 50, &RunState::Unreadable("timeout".into())).unwrap_err();
        assert_eq!(
            unreadable.to_string(),
            "A003 cannot change while the drive runs, and reading running failed: timeout"
        );
        let broadcast = guard(&p, "A003", 50, &RunState::Broadcast).unwrap_err();
        assert_eq!(
            broadcast.to_string(),
            "A003 cannot change while the drive runs, and a broadcast cannot read whether it runs"
        );
        let not_read = guard(&p, "A003", 50, &RunState::NotRead).unwrap_err();
        assert_eq!(
            not_read.to_string(),
            "A003 cannot change while the drive runs, and running was not read to tell whether it runs"
        );
    }

    #[test]
    fn a_point_that_may_change_while_running_needs_no_reading() {
        let p = profile();
        assert_eq!(p.run_state_point(p.point("F001").unwrap()), None);
        assert_eq!(p.run_state_point(p.point("A003").unwrap()).map(|s| s.code.as_str()), Some("running"));
        for state in [RunState::Read(Value::Int(1)), RunState::Broadcast, RunState::NotRead] {
            assert_eq!(guard(&p, "F001", 4500, &state), Ok(()), "{state:?}");
        }
    }

    #[test]
    fn range_and_access_are_refused_first_whatever_the_run_state() {
        let p = profile();
        let out = guard(&p, "A003", 500, &RunState::Read(Value::Int(0))).unwrap_err();
        assert_eq!(out.to_string(), "A003: 500 Hz is out of range: 30 Hz to 400 Hz");
        assert!(!out.is_run_lock());
        let ro = guard(&p, "d001", 1, &RunState::Read(Value::Int(1))).unwrap_err();
        assert_eq!(ro, Refusal::Value(ValueError::ReadOnly { code: "d001".into() }), "read-only before the run lock");
        let point = p.point("A003").unwrap();
        let raw = Value::Int(500);
        assert_eq!(p.check_value(&Write { point, raw: &raw, typed: "500Hz" }).unwrap_err(), {
            let e = point.check_write(&raw, "500Hz").unwrap_err();
            Refusal::Value(e)
        });
    }

    #[test]
    fn without_a_running_rule_the_run_lock_is_left_to_the_device() {
        let text = PROFILE.replace("[state]\nrunning = { point = 'running', values = [1, 3] }\n", "");
        let p = Profile::parse(&text, "guard.toml").unwrap();
        assert_eq!(p.run_state_point(p.point("A003").unwrap()), None);
        assert_eq!(guard(&p, "A003", 50, &RunState::NotRead), Ok(()));
        assert!(!p.means_running(&Value::Int(1)));
    }

    #[test]
    fn a_coil_running_point_runs_when_on() {
        let text = PROFILE.replace(
            "[[registers]]\nnumber=2\nname='running'\nvalues={ '0' = 'stop', '1' = 'run', '3' = 'jog' }\n",
            "[[coils]]\nnumber=0\nname='running'\n",
        );
        let p = Profile::parse(&text, "guard.toml").unwrap();
        assert!(p.means_running(&Value::Bool(true)));
        assert!(!p.means_running(&Value::Bool(false)));
        let refusal = guard(&p, "A003", 50, &RunState::Read(Value::Bool(true))).unwrap_err();
        assert!(matches!(refusal, Refusal::Running { .. }), "{refusal}");
    }

    #[test]
    fn a_write_by_address_is_run_locked_by_every_run_locked_point_it_touches() {
        let p = profile();
        let codes = |start, count| -> Vec<String> {
            p.run_locked_in(Table::Holding, start, count).iter().map(|q| q.code.clone()).collect()
        };
        assert_eq!(codes(0, 1), Vec::<String>::new());
        assert_eq!(codes(0, 4), ["A003", "d001"]);
        assert_eq!(codes(3, 1), ["d001"]);
        assert!(p.run_locked_in(Table::Coils, 0, 4).is_empty());
        let locked = p.run_locked_in(Table::Holding, 0, 4);
        let refusal = p.guard_span(&locked, &RunState::Read(Value::Int(1))).unwrap_err();
        assert_eq!(refusal.to_string(), "A003, d001 cannot change while the drive runs (running = run); stop it first");
        assert_eq!(p.guard_span(&locked, &RunState::Read(Value::Int(0))), Ok(()));
        assert!(matches!(p.guard_span(&locked, &RunState::Broadcast), Err(Refusal::Broadcast { .. })));
        assert_eq!(p.guard_span(&[], &RunState::NotRead), Ok(()));
    }
}
