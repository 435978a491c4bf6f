//! Interop tests: ferrobus against real peers, and peers against ferrobus.
//!
//! The peers are the fixtures of tests/peers/ (libmodbus, pymodbus and tokio-modbus servers
//! and clients, pysunspec2's client) and mbpoll, built and installed by `.ci/setup-peers.sh`.
//! Serial lines are socat pty pairs or the simulator's own pty. Outside CI a test whose peer is missing passes
//! with a `SKIPPED ...` line on stderr (shown even for passing tests) naming what installs it;
//! under `CI=true` it fails ([`skips`] shows both).
//!
//! - [`bridge`]: `ferrobus bridge` against mosquitto, its Sparkplug B checked by pysparkplug
//!   and protoc, with the broker, the bridge and the drives stopped and started under it.
//! - [`cli_vs_servers`]: the `ferrobus` binary against each peer server, RTU and TCP.
//! - [`clients_vs_sim`]: each peer client and mbpoll against `ferrobus sim --profile generic`.
//! - [`custom_profile`]: a profile file for the peer servers' data map, used with backup, diff
//!   and restore against libmodbus and pymodbus.
//! - [`drive_profiles`]: peer clients and raw manual frames against the 3G3RX and SDP profiles.
//! - [`fault_rules`]: fault rules aimed at requests, each met by pymodbus and libmodbus clients.
//! - [`gateway`]: the peer clients through `ferrobus gateway` to the sim, the client through it
//!   to the peer RTU servers, and the TCP server's hostile-input tests against the gateway.
//! - [`gateway_tcp`]: `ferrobus gateway --tcp` as a multiplexer in front of the libmodbus and
//!   pymodbus TCP servers: many clients, read-only, the cache, a device down at start or
//!   restarted mid-run, and a lines file with two TCP lines.
//! - [`port_reopen`]: a serial port that disappears and comes back, through `ferrobus::Client`.
//! - [`reply_timing`]: when the simulator's reply starts, with a 20 ms response wait.
//! - [`skips`]: what a test whose peer is missing does, in and outside CI.
//! - [`stale_reply`]: a reply left in the port by an interrupted command, dropped by the next.
//! - [`status`]: `gateway --metrics`: `/metrics` parsed by Prometheus's Python client, and the
//!   status page run in headless Chromium.
//! - [`sunspec`]: pysunspec2, the SunSpec Alliance's client, against the simulated inverter,
//!   beside `scan --sunspec` and `get --device sunspec`.
//! - [`tcp_server`]: `ferrobus sim --tcp` under pipelining, corrupt headers, unit ids over TCP,
//!   its connection cap and timeouts, and a lowered descriptor limit.
//! - [`tls`]: `ferrobus sim` as a Modbus/TCP Security server with roles, met by ferrobus's
//!   `--tls` client, pymodbus's TLS client and an openssl-made certificate.
//!
//! Run: `cargo test -p ferrobus-cli --test interop`.
#![cfg(unix)] // the peers run on Linux, over ptys

mod bridge;
mod cli_vs_servers;
mod clients_vs_sim;
mod custom_profile;
mod device_profile;
mod drive_profiles;
mod fault_rules;
mod gateway;
mod gateway_tcp;
mod mbpoll_vs_sim;
mod port_reopen;
mod reply_timing;
mod skips;
mod stale_reply;
mod status;
mod sunspec;
mod support;
mod tcp_server;
mod tls;
