//! # ferrobus-profile: what a device is, in a file
//!
//! Device profiles in TOML — the register and coil map with codes, labels, types (16-, 32- and
//! 64-bit integers, IEEE floats, strings) in the four word/byte orders, units, scaling,
//! ranges, access, run-state rules, groups, enumerations, bit fields and dependencies; the
//! device's per-request limits, numbering, spans and exception meanings — with no IO but
//! reading the file.
//!
//! ```text
//!   TOML ──Profile::load──▶ Profile ──points()/find()/group()──▶ Point
//!   Point: decode(registers) → Value → show() "50.00 Hz";  parse("45Hz") → Value → encode()
//!   plan(wanted, mapped, spans, limit) → the fewest read requests
//!   guard_write(Write { point, raw, typed }, RunState) → Ok | Refusal (range, access, run lock)
//! ```
//!
//! Built-in profiles: `omron-3g3rx`, `sdp-servo`, `generic`, `sunspec-inverter` (see [`BUILTIN`]).

mod check;
mod codec;
pub mod exchange;
pub mod guard;
mod model;
mod plan;
mod point;
mod read;
pub mod source;
pub mod text;
mod write;

pub use check::text::{LABEL_MAX, NAME_MAX, TEXT_MAX, UNIT_MAX};
pub use codec::{NOT_IMPLEMENTED, ValueError, beyond_deadband};
pub use guard::{Refusal, RunState, Write};
pub use model::{
    Access, Addressing, BUILTIN, BitDef, Comm, DeviceSection, ExceptionMeaning, Exceptions, Fifo, Files, Limits,
    ModelSection, Order, Point, Polarity, Profile, ProfileError, RegisterDef, RunningRule, SpanDef, State, Table,
    Tables, Value, ValueType,
};
pub use plan::{Extent, PlanError, Request, plan};
pub use write::{Takes, WireWrite, WriteRules};
