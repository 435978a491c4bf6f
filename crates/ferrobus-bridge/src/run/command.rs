//! Applying a command's writes to the bus: whole, in order, one command of a device at a time,
//! and bounded.
//!
//! A command (a DCMD, a plain `set`) comes as the [`Action::Write`](crate::edge::Action)s of one
//! message. The bridge resolves and checks every one of them first (the cell, the profile's
//! access and range) and refuses the command whole if one fails, or if the device already has
//! [`MAX_QUEUED_WRITES`] writes waiting: nothing is written. Then one task, once the device's
//! turn is its, puts every write through the profile's write guard ([`guard`]: the one `set`,
//! `restore` and `monitor` apply, with the drive's run state read first when a write is
//! run-locked) and refuses the command whole on one refusal; else it writes them in the
//! command's order, holding the device's turn ([`DeviceWrites`]) so that two commands never
//! interleave, and stops at the first write the bus fails. The bus cannot take a write back:
//! the [`Applied`] outcome says exactly which were written, which failed and which were not
//! tried, and the bridge says it in one status line.

use std::future::Future;
use std::sync::Arc;

use ferrobus::Client;
use ferrobus_profile::{Point, Profile, Refusal, RunState, Write};
use ferrobus_tools::poll::Value;

use crate::edge::DeviceRef;

/// The most writes waiting for one device (the command being written included); a command that
/// would pass it is refused whole. Four full DCMDs ([`crate::edge::MAX_METRICS_PER_COMMAND`]).
pub(super) const MAX_QUEUED_WRITES: usize = 256;

/// One write of a command, resolved and checked.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct BusWrite {
    /// The device's group and cell (the edge's numbering).
    pub(super) group: usize,
    pub(super) cell: usize,
    /// The poller's group of it.
    pub(super) index: usize,
    /// The raw value to write.
    pub(super) raw: Value,
    /// The value as the command gave it, for messages.
    pub(super) typed: String,
    /// The point's name, for messages.
    pub(super) point: String,
    /// The point, for the write guard.
    pub(super) target: Point,
}

/// What a command's task did.
#[derive(Debug, PartialEq)]
pub(super) struct Applied {
    /// The device.
    pub(super) device: DeviceRef,
    /// The writes tried, in order, with the bus's answer: all but the last succeeded.
    pub(super) tried: Vec<(BusWrite, Result<(), String>)>,
    /// The writes not tried because one before them failed (or all of them, when refused).
    pub(super) not_written: Vec<BusWrite>,
    /// The command's topic and why the write guard refused it (then nothing was tried).
    pub(super) refused: Option<(String, String)>,
}

impl Applied {
    /// The points written, the one that failed with why, and the points not tried; `None`
    /// when every write succeeded.
    pub(super) fn incomplete(&self) -> Option<(Vec<String>, String, String, Vec<String>)> {
        let (failed, Err(error)) = self.tried.last()? else { return None };
        let written = self.tried.iter().filter(|(_, r)| r.is_ok()).map(|(w, _)| w.point.clone()).collect();
        let not_written = self.not_written.iter().map(|w| w.point.clone()).collect();
        Some((written, failed.point.clone(), error.clone(), not_written))
    }
}

/// A device's writes: how many wait, and the turn a command holds while it is written.
#[derive(Clone, Debug, Default)]
pub(super) struct DeviceWrites {
    /// Writes of commands accepted and not finished.
    pub(super) queued: usize,
    /// Held by the command being written: the next one waits for it (first come, first served).
    pub(super) turn: Arc<tokio::sync::Mutex<()>>,
}

impl DeviceWrites {
    /// Takes `n` more writes, or says why not (nothing is taken then).
    pub(super) fn admit(&mut self, n: usize) -> Result<(), String> {
        match self.queued.checked_add(n) {
            Some(total) if total <= MAX_QUEUED_WRITES => {
                self.queued = total;
                Ok(())
            }
            _ => Err(format!(
                "{n} writes, with {} already waiting for the device: at most {MAX_QUEUED_WRITES} may wait",
                self.queued
            )),
        }
    }

    /// A command of `n` writes is finished.
    pub(super) fn done(&mut self, n: usize) {
        self.queued = self.queued.saturating_sub(n);
    }
}

/// The write guard over a command's writes to `unit`, before any is written: the drive's run
/// state read once (only when a write is run-locked), then each write planned by
/// [`Profile::plan_write`]: the guard, and a request the device takes (its functions, its write
/// limit). The first refusal.
pub(super) async fn guard(client: &Client, unit: u8, profile: &Profile, writes: &[BusWrite]) -> Result<(), Refusal> {
    let mut state = RunState::NotRead;
    if let Some(locked) = writes.iter().find(|w| profile.run_state_point(&w.target).is_some()) {
        state = ferrobus_tools::guard::run_state(client, unit, profile, &locked.target).await;
    }
    for w in writes {
        profile.plan_write(&Write { point: &w.target, raw: &w.raw, typed: &w.typed }, &state)?;
    }
    Ok(())
}

/// Writes `writes` in order with `write`, stopping at the first failure.
pub(super) async fn apply<F, Fut>(device: DeviceRef, writes: Vec<BusWrite>, mut write: F) -> Applied
where
    F: FnMut(&BusWrite) -> Fut,
    Fut: Future<Output = Result<(), String>>,
{
    let mut tried = Vec::with_capacity(writes.len());
    let mut rest = writes.into_iter();
    for w in rest.by_ref() {
        let result = write(&w).await;
        let failed = result.is_err();
        tried.push((w, result));
        if failed {
            break;
        }
    }
    Applied { device, tried, not_written: rest.collect(), refused: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn writes(n: usize) -> Vec<BusWrite> {
        (0..n)
            .map(|i| BusWrite {
                group: 0,
                cell: i,
                index: 0,
                raw: Value::Int(0),
                typed: "0".into(),
                point: format!("P{i}"),
                target: ferrobus_profile::Point::raw(
                    ferrobus_profile::Table::Holding,
                    0,
                    ferrobus_profile::ValueType::U16,
                ),
            })
            .collect()
    }

    const DEVICE: DeviceRef = DeviceRef { line: 0, device: 0 };

    #[tokio::test(start_paused = true)]
    async fn a_failed_write_stops_the_command_and_says_which_were_written_and_which_not() {
        let applied = apply(DEVICE, writes(5), |w| {
            let result = if w.cell == 2 { Err("timeout: no reply".to_string()) } else { Ok(()) };
            async move { result }
        })
        .await;
        assert_eq!(applied.tried.len(), 3, "P3 and P4 are not tried after P2 failed");
        let (written, failed, error, not_written) = applied.incomplete().expect("incomplete");
        assert_eq!(written, ["P0", "P1"]);
        assert_eq!((failed.as_str(), error.as_str()), ("P2", "timeout: no reply"));
        assert_eq!(not_written, ["P3", "P4"]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_command_whose_writes_all_succeed_is_complete_and_in_order() {
        let mut order = Vec::new();
        let applied = apply(DEVICE, writes(4), |w| {
            order.push(w.cell);
            async { Ok(()) }
        })
        .await;
        assert_eq!(order, [0, 1, 2, 3]);
        assert!(applied.not_written.is_empty() && applied.incomplete().is_none());
    }

    #[test]
    fn a_device_takes_at_most_256_waiting_writes_and_a_refused_command_takes_none() {
        let mut device = DeviceWrites::default();
        for _ in 0..4 {
            device.admit(64).expect("four full commands");
        }
        let refused = device.admit(1).expect_err("the 257th");
        assert!(refused.contains("256 already waiting") && refused.contains("at most 256"), "{refused}");
        assert_eq!(device.queued, 256, "the refused command took nothing");
        device.done(64);
        device.admit(64).expect("room again once a command is done");
        assert!(device.admit(usize::MAX).is_err(), "no overflow");
    }
}
