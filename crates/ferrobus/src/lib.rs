//! # ferrobus: Modbus on real ports, with tokio
//!
//! The async layer over [`ferrobus_proto`]'s engines. The engines decide everything that can
//! be decided from bytes and time; this crate owns what they cannot: ports, sleeping,
//! reconnecting, and sharing one bus between tasks.
//!
//! ```text
//!   Client (clone it) ──requests──▶ driver task ─┬─ Master engine (ferrobus-proto)
//!                                                └─ port: serial (serial2), TCP, pty, your stream
//!   server::serve(Slave engine, port, Handler)        the same, for the other side
//! ```
//!
//! - [`Client`]: typed async calls for every public function code and raw PDUs, per-request
//!   timeout and retries, broadcast without waiting, per-unit backoff, echo suppression, and a
//!   port that is reopened after it fails.
//! - [`server`]: runs a slave engine over a port, or over each connection of a TCP listener,
//!   with precise reply timing and a hook for fault injection.
//! - [`port`]: serial ports (RS-485 by the adapter, the kernel or RTS; the USB latency timer),
//!   TCP, RTU over TCP, and ptys made in-process.
//! - [`wire`]: the virtual RS-485 line's model, sans-IO like the engines: it takes `now` in
//!   every call and says what each endpoint receives and when — character timing, collisions,
//!   the t3.5 rule, seeded faults, a bit-level UART for endpoints at other settings.
//! - [`line`](mod@line): the thin adapter that runs the wire on tokio's clock, for endpoints
//!   in this process or other programs behind ptys.
//!
//! Errors are one flat [`Error`], where a device's exception is kept apart from timeouts and
//! IO failures.

pub mod client;
pub mod clock;
mod config;
mod driver;
pub mod error;
mod identity;
pub mod line;
pub mod port;
mod pump;
pub mod server;
pub mod timer;
mod tty;
mod uart;
pub mod wire;

pub use client::{Backoff, Client, ClientConfig, DeviceInfo, EventLog, RequestOptions};
pub use error::Error;
pub use port::{Framing, Pty, Rs485, SerialConfig, Transport};
pub use timer::Timer;
