//! The options that bound a TCP server's connections: `--max-connections`,
//! `--max-per-source`, `--idle-timeout` and `--frame-timeout`, shared by `sim` and `gateway`
//! and made into the listener's [`TcpLimits`] with each connection's [`ConnectionPolicy`].

use std::sync::Arc;
use std::time::Duration;

use clap::Args;
use ferrobus::server::{ConnectionPolicy, TcpLimits};

use crate::connect::parse_duration;

/// Options of a TCP server's connections.
#[derive(Args, Clone, Debug)]
#[command(next_help_heading = "TCP connections")]
pub(crate) struct ServerLimitsArgs {
    /// Connections served at once; past it a new one is served and the one least worth
    /// keeping is closed to make room (one in its TLS handshake, then one never answered, then
    /// the one idle longest; from the address holding the most first)
    #[arg(long = "max-connections", value_name = "N", default_value_t = 1000,
          value_parser = clap::value_parser!(u32).range(1..))]
    max_connections: u32,

    /// Connections served at once from one client address (an IPv6 /64); past it a new one
    /// from there is closed at once, so one host cannot take every connection
    #[arg(long = "max-per-source", value_name = "N", default_value_t = 100,
          value_parser = clap::value_parser!(u32).range(1..))]
    max_per_source: u32,

    /// Close a connection when nothing arrives or leaves for this long while no request of
    /// its is outstanding; a reply it does not read within it closes it too (0: never)
    #[arg(long = "idle-timeout", value_name = "DURATION", default_value = "60s", value_parser = parse_duration)]
    idle_timeout: Duration,

    /// Close a connection when a frame begun is not complete this long after its first byte
    /// (0: never)
    #[arg(long = "frame-timeout", value_name = "DURATION", default_value = "5s", value_parser = parse_duration)]
    frame_timeout: Duration,
}

impl ServerLimitsArgs {
    /// The listener's limits, each connection allowed `max_pending` requests outstanding;
    /// memory freed after a burst of connections goes back to the system (the binary's
    /// servers run for months).
    pub(crate) fn limits(&self, max_pending: usize) -> TcpLimits {
        let nonzero = |d: Duration| Some(d).filter(|d| !d.is_zero());
        TcpLimits {
            max_connections: usize::try_from(self.max_connections).unwrap_or(usize::MAX),
            max_per_source: usize::try_from(self.max_per_source).unwrap_or(usize::MAX),
            connection: ConnectionPolicy {
                idle: nonzero(self.idle_timeout),
                frame: nonzero(self.frame_timeout),
                max_pending,
            },
            release_memory_after_bursts: true,
            stats: Arc::default(),
        }
    }
}
