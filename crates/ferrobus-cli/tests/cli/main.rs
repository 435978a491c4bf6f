//! End-to-end tests of the `ferrobus` binary: each test starts a real Modbus server in this
//! process (`ferrobus::server::serve_tcp` over a small handler) and runs the binary against
//! it, checking stdout, stderr, exit codes and the requests the server saw.
#![cfg(unix)] // the servers of these tests sit on ptys as well as TCP

mod backup;
mod backup_safety;
mod bench_failures;
mod bridge_reload;
mod completions;
mod config;
mod container;
mod defaults;
mod device;
mod errors;
mod gateway;
mod gateway_lines;
mod gateway_reload;
mod guard;
mod interrupted;
mod line_settings;
mod maps;
mod monitor;
mod offline;
mod output;
mod package;
mod poll;
mod ports;
mod read;
mod readme;
mod reopen;
mod scan;
mod server;
mod service;
mod sniff;
mod sniff_device;
mod stderr;
mod sunspec;
mod systemd;
mod tls;
mod values;
mod word_order;
mod write;
mod write_point;
