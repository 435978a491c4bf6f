//! `gateway --lines-file FILE`: the gateway's lines (serial ports, devices over TCP), each with
//! its own settings and the units it serves, from a TOML file of `[[line]]` tables, read and
//! checked by the library ([`ferrobus_tools::gateway::config`], which documents the keys and every
//! mistake it names).
//!
//! The keys are the line options of the command line under their long names (`port`, `tcp`,
//! `rtu-tcp`, `data-bits`), the gateway's `queue`, `late-guard` and `in-flight` (a `tcp` line's
//! only), and `response-wait`, which the line options lack.
//!
//! Precedence: a key of a `[[line]]` beats the same option given on the command line (or from
//! the settings file's `[defaults]` or `--conn`), which is what every line of the file starts
//! from. The lines themselves and their routes come from the file alone: `--port`, `--line`
//! and `--route` are refused beside it, so the command line and the file cannot name two
//! different sets of lines or send a unit two ways. A mistake in the file is a usage error
//! (exit 2) that names the file, the line and column, the `[[line]]` and the key.

use std::path::Path;
use std::time::Duration;

use ferrobus::Backoff;
use ferrobus_tools::gateway::config::{self, LineDefaults, LinesFile};

use crate::connect::{ConnectArgs, Rs485Arg};
use crate::exit::CliError;

/// What every line of the file takes from the gateway's own options.
#[derive(Clone, Copy, Debug)]
pub(super) struct Base {
    /// `--backoff-after`, `--backoff-skip`, `--backoff-max`.
    pub(super) backoff: Option<Backoff>,
    /// `--queue`, unless the line says `queue`.
    pub(super) queue: usize,
    /// `--late-guard`, unless the line says `late-guard`.
    pub(super) late_guard: Duration,
    /// `--in-flight`, for each Modbus/TCP line that does not say `in-flight`.
    pub(super) in_flight: usize,
}

/// What every line starts from: the connection options and `base`.
fn defaults(connection: &ConnectArgs, base: Base) -> LineDefaults {
    let client =
        ferrobus::ClientConfig { backoff: base.backoff, in_flight: base.in_flight, ..connection.client_config() };
    LineDefaults {
        framing: connection.line(),
        ascii: connection.ascii,
        rs485: match connection.rs485 {
            Rs485Arg::Auto => ferrobus::Rs485::Auto,
            Rs485Arg::Kernel => ferrobus::Rs485::Kernel,
            Rs485Arg::Rts => ferrobus::Rs485::Rts,
        },
        low_latency: connection.low_latency,
        t1_5: connection.t15,
        t3_5: connection.t35,
        reopen: !connection.no_reopen,
        client,
        queue: base.queue,
        late_guard: base.late_guard,
    }
}

/// Reads `path`: the lines, with their settings on top of `connection`'s and `base`'s, and
/// the routes. Nothing is opened.
pub(super) fn read(path: &Path, connection: &ConnectArgs, base: Base) -> Result<LinesFile, CliError> {
    config::read(path, &defaults(connection, base)).map_err(|e| CliError::Usage(e.to_string()))
}

#[cfg(test)]
mod tests;
