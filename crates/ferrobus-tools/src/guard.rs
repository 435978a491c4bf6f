//! The write guard with its reading: [`check_write`] reads the profile's running point with a
//! [`Client`] (only when the point written is run-locked) and applies the profile's one guard,
//! [`Profile::guard_write`], so no writer reads the run state its own way.
//!
//! ```text
//!   check_write(client, unit, profile, write)
//!     ├─ profile.check_value(write)             range, access: no request
//!     ├─ run_state(client, unit, profile, point)  one read of [state] running, if run-locked
//!     └─ profile.guard_write(write, state)        Ok | Refusal
//!
//!   check_span(client, unit, profile, table, start, count)   a write by address
//!     ├─ profile.run_locked_in(table, start, count)   the run-locked points it touches
//!     ├─ run_state(...)                               read only when it touches one
//!     └─ profile.guard_span(locked, state)
//!
//!   read_point(client, unit, point)    one point on its own: the run state, a write's read-back
//! ```
//!
//! A broadcast reads nothing: its writer passes [`RunState::Broadcast`] to
//! [`Profile::guard_write`] itself. Writing a named point, guard included, is
//! [`crate::write::write_point`]'s.

use ferrobus_profile::{Point, Profile, Refusal, RunState, Table, Value, ValueError, ValueType, Write};

use ferrobus::client::Client;
use ferrobus::error::Error;

/// Reads what the guard needs to know of the drive before `point` is written: the profile's
/// running point, if `point` is run-locked and the profile names one ([`RunState::NotRead`]
/// otherwise, which the guard then does not look at). A failed read is
/// [`RunState::Unreadable`], with why.
pub async fn run_state(client: &Client, unit: u8, profile: &Profile, point: &Point) -> RunState {
    let Some(state) = profile.run_state_point(point) else { return RunState::NotRead };
    match read_point(client, unit, state).await {
        Ok(value) => RunState::Read(value),
        Err(why) => RunState::Unreadable(why.to_string()),
    }
}

/// The guard for one write to `unit`: the value checked first (nothing is sent if it fails),
/// then, for a run-locked point, the running point read and the run lock applied.
pub async fn check_write(client: &Client, unit: u8, profile: &Profile, write: &Write<'_>) -> Result<(), Refusal> {
    profile.check_value(write)?;
    let state = run_state(client, unit, profile, write.point).await;
    profile.guard_write(write, &state)
}

/// The run lock for a write by address to `unit` (`count` items from `start` in `table`): when
/// the write touches a run-locked point of `profile`, the running point read and
/// [`Profile::guard_span`] applied; nothing is read otherwise.
pub async fn check_span(
    client: &Client,
    unit: u8,
    profile: &Profile,
    table: Table,
    start: u16,
    count: usize,
) -> Result<(), Refusal> {
    let locked = profile.run_locked_in(table, start, count);
    let Some(first) = locked.first() else { return Ok(()) };
    let state = run_state(client, unit, profile, first).await;
    profile.guard_span(&locked, &state)
}

/// Why reading a point failed.
#[derive(Clone, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadFailure {
    /// The request failed or the device refused it.
    #[error("{0}")]
    Bus(#[from] Error),
    /// The reply's registers are no value of the point's type.
    #[error("{0}")]
    Decode(#[from] ValueError),
}

/// One point's value, read on its own.
pub async fn read_point(client: &Client, unit: u8, point: &Point) -> Result<Value, ReadFailure> {
    let (start, count) = (point.address, point.width);
    let bit = |bits: Vec<bool>| Value::Bool(bits.first().copied().unwrap_or(false));
    let words = match point.table {
        Table::Coils => return Ok(client.read_coils(unit, start, count).await.map(bit)?),
        Table::DiscreteInputs => return Ok(client.read_discrete_inputs(unit, start, count).await.map(bit)?),
        Table::Holding => client.read_holding_registers(unit, start, count).await?,
        Table::Input => client.read_input_registers(unit, start, count).await?,
    };
    if point.value_type == ValueType::Bit {
        return Ok(Value::Bool(words.first().is_some_and(|w| *w != 0)));
    }
    Ok(point.decode(&words)?)
}
