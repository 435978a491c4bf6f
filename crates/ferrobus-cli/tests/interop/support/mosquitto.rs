//! An MQTT broker of the test's own: mosquitto on 127.0.0.1 and a free port.
//!
//! [`Broker::start`] writes a config file into a fresh directory (one listener on 127.0.0.1,
//! anonymous clients allowed, the log in a file there) and waits until the port accepts
//! connections. [`Broker::stop`] ends it with SIGTERM, as an operator would, and
//! [`Broker::start_again`] brings it back on the same port: that is how a test takes the
//! broker away from a client and gives it back. The broker is a [`Proc`], so it dies with its
//! test, on panic too.
//!
//! Persistence is off unless asked for ([`Broker::start_persistent`]): then the broker saves
//! its clients' sessions when stopped and restores them when started again, so a recorder
//! with a persistent session misses nothing published between the restart and its own
//! reconnection.

use std::fmt::Write as _;
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::thread;
use std::time::{Duration, Instant};

use super::env::{self, Turn};
use super::peers::free_port;
use super::process::Proc;
use super::serial::TempDir;

/// Where Debian's package puts the broker.
const DEBIAN_PATH: &str = "/usr/sbin/mosquitto";

/// How long a broker may take to accept connections.
const READY_WITHIN: Duration = Duration::from_secs(10);

/// The mosquitto program: `MOSQUITTO`, Debian's `/usr/sbin/mosquitto`, or `mosquitto` on PATH.
pub(crate) fn program() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("MOSQUITTO") {
        return Some(PathBuf::from(path));
    }
    if Path::new(DEBIAN_PATH).is_file() {
        return Some(PathBuf::from(DEBIAN_PATH));
    }
    let paths = std::env::var_os("PATH")?;
    std::env::split_paths(&paths).map(|dir| dir.join("mosquitto")).find(|p| p.is_file())
}

/// The test's turn on the machine when mosquitto is installed; `None` (after a `SKIPPED`
/// line) when it is not, outside CI.
///
/// # Panics
/// Under `CI=true`, when mosquitto is missing.
pub(crate) fn require() -> Option<Turn> {
    env::require_tool(program().is_some(), "mosquitto", "apt install mosquitto (or .ci/setup-peers.sh)")
        .then(|| env::require(&[]))
        .flatten()
}

/// A mosquitto broker on 127.0.0.1, killed on drop.
pub(crate) struct Broker {
    port: u16,
    dir: TempDir,
    proc: Option<Proc>,
}

impl Broker {
    /// A broker on a free port, without persistence.
    ///
    /// # Panics
    /// If mosquitto cannot be started or does not accept connections within 10 s.
    pub(crate) fn start() -> Broker {
        Broker::with_persistence(false)
    }

    /// A broker that keeps its clients' sessions across [`Broker::stop`] and
    /// [`Broker::start_again`].
    ///
    /// # Panics
    /// As [`Broker::start`].
    pub(crate) fn start_persistent() -> Broker {
        Broker::with_persistence(true)
    }

    fn with_persistence(persistent: bool) -> Broker {
        let dir = TempDir::new();
        let port = free_port();
        let log = dir.path().join("mosquitto.log");
        let mut config = format!(
            "# written by the interop tests (support/mosquitto.rs)\n\
             # as root, stay root: the log and the database are in the test's directory\n\
             user root\n\
             listener {port} 127.0.0.1\n\
             allow_anonymous true\n\
             log_dest file {}\n\
             log_type all\n\
             log_timestamp_format %H:%M:%S\n",
            log.display()
        );
        if persistent {
            // Sessions are saved on SIGTERM and restored at start; QoS 0 messages for a
            // client that is away are queued too (the Sparkplug data is QoS 0).
            let _ = write!(
                config,
                "persistence true\npersistence_location {}/\nautosave_interval 0\nqueue_qos0_messages true\n",
                dir.path().display()
            );
        } else {
            config.push_str("persistence false\n");
        }
        let conf = dir.path().join("mosquitto.conf");
        std::fs::write(&conf, config).unwrap_or_else(|e| panic!("writing {}: {e}", conf.display()));
        let mut broker = Broker { port, dir, proc: None };
        broker.start_again();
        broker
    }

    /// Its port on 127.0.0.1.
    pub(crate) fn port(&self) -> u16 {
        self.port
    }

    /// `127.0.0.1:PORT`.
    pub(crate) fn address(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    /// Starts the broker (again) on its port and waits until it accepts connections.
    ///
    /// # Panics
    /// If it cannot be started, or is not accepting within 10 s.
    pub(crate) fn start_again(&mut self) {
        assert!(self.proc.is_none(), "the broker on port {} is already running", self.port);
        let Some(program) = program() else { panic!("mosquitto is not installed") };
        let conf = self.dir.path().join("mosquitto.conf");
        let mut command = Command::new(program);
        command.arg("-c").arg(&conf);
        let mut proc = Proc::spawn(&format!("mosquitto on port {}", self.port), &mut command);
        let deadline = Instant::now() + READY_WITHIN;
        while TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(
                proc.running() && Instant::now() < deadline,
                "mosquitto on port {} is not accepting connections (running: {}); its log:\n{}\n{}",
                self.port,
                proc.running(),
                self.log(),
                proc.log()
            );
            thread::sleep(Duration::from_millis(20));
        }
        self.proc = Some(proc);
    }

    /// Stops the broker with SIGTERM and waits until it has exited.
    pub(crate) fn stop(&mut self) {
        if let Some(mut proc) = self.proc.take() {
            proc.terminate();
        }
    }

    /// Its log file, so far (for failure messages).
    pub(crate) fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("mosquitto.log")).unwrap_or_default()
    }
}
