//! # ferrobus-tools: what the `ferrobus` command does, as a library
//!
//! The tools built on [`ferrobus`]'s transport library: each runs clients and servers, none
//! reaches under them. An application that embeds a client or a server depends on `ferrobus`
//! alone and compiles none of this.
//!
//! ```text
//!   ferrobus-cli ──▶ ferrobus-tools ──▶ ferrobus (client, server, pump, ports, tls) ──▶ ferrobus-proto
//!                          └──────────▶ ferrobus-profile (points, guard, write plan) ──┘
//! ```
//!
//! - [`gateway`]: Modbus/TCP clients to RTU lines: routing by unit, one bounded queue per
//!   line served round-robin, the gateway exceptions, per-unit backoff, a read cache, its
//!   front end over TLS (the `tls` feature), and the reverse gateway.
//! - [`poll`]: the poller — read groups (raw ranges, a profile's points) each at its own
//!   rate without drift, samples with each failure's kind, counters, pause and write-through,
//!   and the session file that `poll` and `monitor` share.
//! - [`scan`]: the bus scanner — unit addresses × line settings over one port reconfigured
//!   in place, listening first, a second pass for leads, identification.
//! - [`sniff`]: the passive sniffer of an RTU line — listening without transmitting, the
//!   core's decoder on the shared clock, owned events, a unit filter, per-unit statistics and
//!   pcapng captures.
//! - [`pcapng`]: capture files of an RTU line that tshark and Wireshark decode as Modbus RTU
//!   (exported PDUs with the `mbrtu` dissector and ports telling queries from responses).
//! - [`backup`]: a device's parameters read to a backup file, compared, and restored.
//! - [`write`](mod@write): writing a named point — the guard, the one request the device takes, the
//!   read-back — the one act every writer calls; [`guard`]: the write guard with its reading
//!   of the run state.
//! - [`reload`]: what a reload keeps — each item of a new configuration matched to the
//!   running one's, unchanged, changed or added, and the ones removed.
//! - `status` (the `status` feature): the status endpoint of a long-running command —
//!   OpenMetrics at `/metrics`, `/healthz` and a live status page.

pub mod backup;
pub mod gateway;
pub mod guard;
pub mod pcapng;
pub mod poll;
pub mod reload;
pub mod scan;
pub mod sniff;
#[cfg(feature = "status")]
pub mod status;
pub mod write;
