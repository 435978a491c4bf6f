//! # ferrobus: Modbus on real ports, with tokio
//!
//! The async layer over [`ferrobus_proto`]'s engines. The engines decide everything that can
//! be decided from bytes and time; this crate owns what they cannot: ports, sleeping,
//! reconnecting, and sharing one bus between tasks.
//!
//! ```text
//!   Client (clone it) ──requests──▶ client session ─┐
//!                                                    ├─▶ pump ─┬─ Engine: Master, or Slave (deferred)
//!   server::serve(Slave engine, port, Service) ─────┘          └─ port: serial, TCP, pty, your stream
//! ```
//!
//! One driver loop, the pump, runs every role: it reads with the arrival time and hands the
//! bytes to the engine (keeping what a blocked engine did not take), sleeps until the earliest
//! of the engine's deadline and the role's own, and writes what the engine hands out through
//! one writer that raises RTS around each frame when asked. An engine is anything with the
//! core's five verbs (`on_bytes`, `poll_timeout`, `handle_timeout`, `poll_transmit`,
//! `poll_event`); the codec a [`Transport`] takes is chosen once for client and server (a
//! server's MBAP receiver is strict). The roles are thin sessions around the pump: the client's
//! command channel, retries, backoff and reopening; the server's reply filter, observer and
//! idle and unfinished-frame timeouts.
//!
//! - [`Client`]: typed async calls for every public function code and raw PDUs, per-request
//!   timeout and retries, broadcast without waiting, per-unit backoff, echo suppression, and a
//!   port that is reopened after it fails.
//! - [`server`]: runs a slave engine over a port, or over each connection of a TCP listener,
//!   with precise reply timing and a hook for fault injection.
//! - [`port`]: serial ports (RS-485 by the adapter, the kernel or RTS; the USB latency timer),
//!   TCP, RTU over TCP, and ptys made in-process.
//! - `tls` (the `tls` feature): Modbus/TCP Security — TLS with mutual authentication, the
//!   role from the client's certificate and a roles file checked on every request, for the
//!   server; `Transport::tls` for the client.
//! - [`wire`]: the virtual RS-485 line's model, sans-IO like the engines: it takes `now` in
//!   every call and says what each endpoint receives and when — character timing, collisions,
//!   the t3.5 rule, seeded faults, a bit-level UART for endpoints at other settings.
//! - [`line`](mod@line): the thin adapter that runs the wire on tokio's clock, for endpoints
//!   in this process or, on Unix, other programs behind ptys.
//! - [`log`](mod@log): [`log::escape`], how every value from outside (a certificate's role, a
//!   metric name, a peer's text) is written into a log line: on one line, controls spelled out.
//! - [`text`]: the one grammar of what people type — durations, sizes (SI and IEC units),
//!   decimal/hex numbers, integers and lists of ranges — for the command line, the simulator,
//!   the bridge and profiles alike (ferrobus-profile's, re-exported).
//!
//! Linux, macOS and Windows: what differs between them — ttys and ptys on Unix, COM ports on
//! Windows, Linux's timerfd and kernel RS-485 — is behind one seam, a folder per platform
//! (`src/sys/unix/`, `src/sys/windows/`); everything else is shared. Windows has no ptys:
//! `Pty` and the virtual line's pty endpoints exist on Unix only.
//!
//! The tools built on this library (the gateway, the poller, the scanner, the sniffer,
//! backup and restore, writing a named point) are the `ferrobus-tools` crate: an application
//! that embeds a client or a server compiles none of them.
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
pub mod log;
pub mod port;
pub mod pump;
mod serial;
pub mod server;
mod sys;
pub mod timer;
#[cfg(feature = "tls")]
pub mod tls;
mod uart;
pub mod wire;

pub use client::{
    Backoff, Client, ClientConfig, ClientStats, DeviceInfo, EventLog, Release, RequestOptions, STALLED_AFTER_TIMEOUTS,
};
pub use error::Error;
/// The one grammar of what people type, from the profile crate, where a profile's keys and an
/// imported map's cells are read with it too.
pub use ferrobus_profile::text;
#[cfg(unix)]
pub use port::Pty;
pub use port::{Framing, Rs485, SerialConfig, TlsAnswer, Transport};
pub use timer::Timer;
