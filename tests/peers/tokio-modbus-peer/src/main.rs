//! tokio-modbus-peer: the tokio-modbus fixture of the ferrobus peer tests.
//!
//! One binary, two roles, the same CLI and line contract as the libmodbus and
//! pymodbus fixtures (tests/peers/README.md):
//!
//! ```text
//! tokio-modbus-peer server (--rtu PATH [serial flags] | --tcp PORT) [--unit U] [--debug]
//! tokio-modbus-peer client (--rtu PATH [serial flags] | --tcp HOST:PORT) [--unit U]
//!                          [--timeout-ms N] [--debug] script | bench --count N ...
//! ```
//!
//! Exit status: 0 on success (server: on SIGTERM/SIGINT), 1 when the port or
//! socket cannot be opened, 2 for bad arguments.

mod args;
mod client;
mod server;

use args::{Command, USAGE};

/// `--debug`: tokio-modbus's `log` records on stderr.
struct StderrLogger;

impl log::Log for StderrLogger {
    fn enabled(&self, _: &log::Metadata<'_>) -> bool {
        true
    }
    fn log(&self, record: &log::Record<'_>) {
        eprintln!("[{} {}] {}", record.level(), record.target(), record.args());
    }
    fn flush(&self) {}
}

static LOGGER: StderrLogger = StderrLogger;

fn main() {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let command = match args::parse(&argv) {
        Ok(command) => command,
        Err(args::UsageError(msg)) => {
            eprintln!("error: {msg}\n{USAGE}");
            std::process::exit(2);
        }
    };
    let debug = match &command {
        Command::Help => {
            println!("{USAGE}");
            return;
        }
        Command::Server(c) | Command::Script(c, _) | Command::Bench(c, _, _) => c.debug,
    };
    // tokio-modbus can panic while decoding hostile input (see server.rs); the
    // task is restarted, so one line on stderr is enough.
    std::panic::set_hook(Box::new(|info| eprintln!("tokio-modbus-peer: panic: {info}")));
    if debug && log::set_logger(&LOGGER).is_ok() {
        log::set_max_level(log::LevelFilter::Trace);
    }

    // One thread: lowest latency for the client, and plenty for a fixture server.
    let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("tokio-modbus-peer: cannot start the runtime: {e}");
            std::process::exit(1);
        }
    };
    let code = runtime.block_on(async move {
        match command {
            Command::Help => 0,
            Command::Server(common) => {
                tokio::select! {
                    code = server::run(common) => code,
                    () = shutdown_signal() => 0,
                }
            }
            Command::Script(common, timeout) => client::script(common, timeout).await,
            Command::Bench(common, timeout, opts) => client::bench(common, timeout, opts).await,
        }
    });
    // Do not wait for tasks still blocked on stdin or a port.
    std::process::exit(code);
}

/// Resolves on SIGTERM or SIGINT.
async fn shutdown_signal() {
    use tokio::signal::unix::{signal, SignalKind};
    match (signal(SignalKind::terminate()), signal(SignalKind::interrupt())) {
        (Ok(mut term), Ok(mut int)) => {
            tokio::select! {
                _ = term.recv() => {}
                _ = int.recv() => {}
            }
        }
        _ => std::future::pending::<()>().await,
    }
}
