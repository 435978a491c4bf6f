//! Writing a named point: the one act `set`, `restore`, `monitor`, the bridge and
//! [`PollHandle::write`](crate::poll::PollHandle::write) call, so one value is written the same
//! way by every one of them.
//!
//! ```text
//!   write_point(client, unit, profile, write, read_back)
//!     ├─ prepare                      nothing is sent until it passes
//!     │    ├─ check_value               access, range: no request
//!     │    ├─ point.wire_write(rules)   the function, the limit (never split)
//!     │    ├─ guard::run_state          one read of [state] running, if run-locked
//!     │    └─ guard_write               the run lock
//!     ├─ send(wire)                   the one request, its reply checked
//!     └─ guard::read_point            read back, if asked (not after a broadcast)
//! ```
//!
//! A writer that writes many points under one reading of the run state (`restore`, a bridge
//! command) plans each with [`Profile::plan_write`] and sends each with [`send`]; the monitor,
//! which shows its traffic and guards a raw cell as the parameter under it, plans with
//! `Point::wire_write` and sends with [`send`]. No writer builds a write request of its own.

use ferrobus_profile::{Profile, Refusal, RunState, Table, Value, ValueError, WireWrite, WriteRules};

use crate::guard::{self, ReadFailure};
use ferrobus::client::Client;
use ferrobus::error::Error;

/// Why a write was not done.
#[derive(Clone, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// No such group or cell (of a [`PollHandle`](crate::poll::PollHandle)).
    #[error("no cell {cell} in group {group}")]
    NoSuchCell {
        /// The group index.
        group: usize,
        /// The cell index.
        cell: usize,
    },
    /// The value does not parse, is out of the point's range, or the point is read-only.
    #[error("{0}")]
    Value(#[from] ValueError),
    /// The write was refused before anything was sent: by the profile's guard (range, access,
    /// the run lock), or because no request the device takes can carry it.
    #[error("{0}")]
    Refused(#[from] Refusal),
    /// The bus refused or failed.
    #[error("{0}")]
    Bus(#[from] Error),
}

/// What a write that was sent came to.
#[derive(Clone, Debug)]
pub struct Written {
    /// The request that carried it.
    pub request: WireWrite,
    /// The point read back, when it was asked for and can be: not after a broadcast, and not
    /// of a point that cannot be read.
    pub read_back: Option<Result<Value, ReadFailure>>,
}

/// Writes `write` to `unit`: [`prepare`]d (the guard and the request), [`send`], and read back
/// when `read_back` says so and the point can be. `profile` is `None` for a point no profile
/// describes (a raw range): its own access and range, the spec's functions and limits, no run
/// lock.
pub async fn write_point(
    client: &Client,
    unit: u8,
    profile: Option<&Profile>,
    write: &ferrobus_profile::Write<'_>,
    read_back: bool,
) -> Result<Written, WriteError> {
    let request = prepare(client, unit, profile, write).await?;
    send(client, unit, &request).await?;
    let point = write.point;
    let readable = point.readable() && matches!(point.table, Table::Holding | Table::Coils);
    let read_back = if read_back && readable && !client.is_broadcast(unit) {
        Some(guard::read_point(client, unit, point).await)
    } else {
        None
    };
    Ok(Written { request, read_back })
}

/// Everything before a write is sent: the value's access and range, the request that carries
/// it with the device's [`WriteRules`], and, for a run-locked point, the running point read and
/// the run lock applied (a broadcast reads nothing: such a point is refused). Nothing is sent
/// when a check fails, and the running point is read only once the value has passed.
pub async fn prepare(
    client: &Client,
    unit: u8,
    profile: Option<&Profile>,
    write: &ferrobus_profile::Write<'_>,
) -> Result<WireWrite, WriteError> {
    let point = write.point;
    let Some(profile) = profile else {
        point.check_write(write.raw, write.typed)?;
        return Ok(point.wire_write(write.raw, &WriteRules::SPEC)?);
    };
    profile.check_value(write)?;
    let request = point.wire_write(write.raw, &profile.write_rules())?;
    let state = if !client.is_broadcast(unit) {
        guard::run_state(client, unit, profile, point).await
    } else if profile.run_state_point(point).is_some() {
        RunState::Broadcast
    } else {
        RunState::NotRead
    };
    profile.guard_write(write, &state)?;
    Ok(request)
}

/// Sends the one request of a write and returns the reply PDU, checked against the request
/// (`None` after a broadcast, which gets none).
pub async fn send(client: &Client, unit: u8, request: &WireWrite) -> Result<Option<Vec<u8>>, Error> {
    let pdu = request.request().map_err(Error::InvalidRequest)?;
    client.request(unit, &pdu).await
}
