//! # ferrobus-sim: whole drives on a simulated bus
//!
//! Device models for the `ferrobus` slave engine, described by profile files: register and
//! coil maps with names, units, ranges and access; function codes, per-request limits,
//! response wait, broadcast rules and vendor exception codes; and physics — an inverter whose
//! output frequency ramps, a servo whose position integrates its speed.
//!
//! ```text
//!   Profile (TOML) ──▶ Device: Memory (the map) + Model (physics) + the profile's rules
//!   Sim: devices by unit ──implements──▶ slave::Handler ──▶ ferrobus::server::serve
//!   Ticker ──▶ a point that counts periods of the wall clock (latency benches)
//!   FaultFilter ──▶ drops, corrupts, delays, cuts, re-addresses and trickles replies on their way out
//! ```
//!
//! Built-in profiles: `omron-3g3rx`, `sdp-servo`, `generic` (see [`profile::BUILTIN`]).

pub mod clock;
pub mod device;
pub mod fault;
pub mod memory;
pub mod model;
pub mod parse;
pub mod profile;
mod reframe;
pub mod rule;
pub mod sim;
pub mod ticker;

pub use clock::{SimClock, tokio_clock};
pub use device::Device;
pub use fault::Faults;
pub use profile::{Profile, ProfileFaults};
pub use rule::Rule;
pub use sim::{FaultFilter, Sim, Unserved};
pub use ticker::{Ticker, TickerError};
