//! What a bridge scenario is made of: simulated drives as separate processes ([`Drive`]:
//! `ferrobus sim --tcp` on a port of its own, stopped and started again on it), a plant.toml
//! written for the test ([`Plant`]), and `ferrobus bridge --config` itself ([`Bridge`]), whose
//! output is kept next to the recording when it ends.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::support::cli::Link;
use crate::support::peers::free_port;
use crate::support::process::{Proc, Stream};
use crate::support::{Ferrobus, ferrobus};

/// How long a sim may take to listen.
const SIM_READY: Duration = Duration::from_secs(20);

/// `ferrobus sim ARGS --tcp 127.0.0.1:PORT`, on the same port each time it is started.
pub(crate) struct Drive {
    args: Vec<String>,
    address: String,
    proc: Option<Proc>,
}

impl Drive {
    /// Starts `ferrobus sim ARGS` on a free port, once it listens.
    pub(crate) fn start(args: &[&str]) -> Drive {
        let address = format!("127.0.0.1:{}", free_port());
        let mut drive = Drive { args: args.iter().map(|s| (*s).to_string()).collect(), address, proc: None };
        drive.start_again();
        drive
    }

    /// Its Modbus/TCP address.
    pub(crate) fn address(&self) -> &str {
        &self.address
    }

    /// The `ferrobus` client for unit `unit` of it.
    pub(crate) fn client(&self, unit: u8) -> Ferrobus {
        ferrobus(&Link::Tcp(self.address.clone())).unit(unit)
    }

    /// Stops it (SIGTERM): the bridge's polls get no answer.
    pub(crate) fn stop(&mut self) {
        if let Some(mut proc) = self.proc.take() {
            proc.terminate();
        }
    }

    /// Starts it again on the same port (its registers start from the profile's values).
    ///
    /// # Panics
    /// If it is running, or does not listen within 20 s.
    pub(crate) fn start_again(&mut self) {
        assert!(self.proc.is_none(), "the sim on {} is already running", self.address);
        let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
        command.arg("sim").args(&self.args).args(["--tcp", &self.address]);
        let proc = Proc::spawn(&format!("ferrobus sim on {}", self.address), &mut command);
        proc.wait_for(Stream::Err, |l| l.starts_with("sim: listening on"), SIM_READY);
        self.proc = Some(proc);
    }
}

/// A plant.toml for a test: a broker, Sparkplug or plain, and Modbus/TCP lines.
pub(crate) struct Plant {
    text: String,
}

impl Plant {
    /// Sparkplug B as group `group`, edge node `node`, on the broker at 127.0.0.1:`port`;
    /// the first reconnection 200 ms after a loss, a keep-alive of 5 s.
    pub(crate) fn sparkplug(port: u16, group: &str, node: &str) -> Plant {
        Plant {
            text: format!(
                "[broker]\naddress = \"127.0.0.1:{port}\"\nclient_id = \"ferrobus-test-{node}\"\n\
                 keep_alive = \"5s\"\nreconnect = \"200ms\"\n\n\
                 [sparkplug]\ngroup_id = \"{group}\"\nedge_node_id = \"{node}\"\n"
            ),
        }
    }

    /// Plain JSON under `prefix`, retained when `retain`.
    pub(crate) fn plain(port: u16, prefix: &str, retain: bool) -> Plant {
        Plant {
            text: format!(
                "[broker]\naddress = \"127.0.0.1:{port}\"\nclient_id = \"ferrobus-test-plain\"\n\
                 keep_alive = \"5s\"\nreconnect = \"200ms\"\n\n\
                 [plain]\nprefix = \"{prefix}\"\nretain = {retain}\nqos = 1\n"
            ),
        }
    }

    /// Makes the births wait for the Sparkplug host application `host` (its STATE online).
    #[must_use]
    pub(crate) fn primary_host(mut self, host: &str) -> Plant {
        self.text = self.text.replacen("[sparkplug]\n", &format!("[sparkplug]\nprimary_host = \"{host}\"\n"), 1);
        self
    }

    /// Turns Home Assistant discovery on in `[plain]` (under `homeassistant/`).
    #[must_use]
    pub(crate) fn discovery(mut self) -> Plant {
        self.text = self.text.replacen("[plain]\n", "[plain]\ndiscovery = true\n", 1);
        self
    }

    /// Adds TOML as written (a `[store]` section, ...).
    #[must_use]
    pub(crate) fn with(mut self, toml: &str) -> Plant {
        let _ = write!(self.text, "\n{toml}\n");
        self
    }

    /// Adds a Modbus/TCP line to `address` with a 300 ms reply timeout and no retries,
    /// followed by `devices` (`[[line.device]]` tables as written).
    #[must_use]
    pub(crate) fn tcp_line(mut self, name: &str, address: &str, devices: &str) -> Plant {
        let _ = write!(
            self.text,
            "\n[[line]]\nname = \"{name}\"\ntcp = \"{address}\"\ntimeout = \"300ms\"\nretries = 0\n\n{devices}\n"
        );
        self
    }

    /// Adds an RTU line on the serial port (a pty) `path` at 19200 baud 8E1, 300 ms reply
    /// timeout, no retries, followed by `devices`.
    #[must_use]
    pub(crate) fn rtu_line(mut self, name: &str, path: &Path, devices: &str) -> Plant {
        let _ = write!(
            self.text,
            "\n[[line]]\nname = \"{name}\"\nport = \"{}\"\nbaud = 19200\nparity = \"even\"\n\
             timeout = \"300ms\"\nretries = 0\n\n{devices}\n",
            path.display()
        );
        self
    }

    /// Writes it as `dir/plant.toml` and returns the path.
    pub(crate) fn write(&self, dir: &Path) -> PathBuf {
        let path = dir.join("plant.toml");
        std::fs::write(&path, &self.text).unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
        path
    }
}

/// `ferrobus bridge --config FILE`, killed (SIGKILL) on drop; its output goes to
/// `bridge.log` beside the config when it ends.
pub(crate) struct Bridge {
    proc: Option<Proc>,
    log: PathBuf,
}

impl Bridge {
    /// Starts `ferrobus bridge --config CONFIG ARGS`.
    pub(crate) fn start(config: &Path, args: &[&str]) -> Bridge {
        let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
        command.arg("bridge").arg("--config").arg(config).args(args);
        let proc = Proc::spawn("ferrobus bridge", &mut command);
        let log = config.with_file_name("bridge.log");
        Bridge { proc: Some(proc), log }
    }

    /// What it has printed so far.
    pub(crate) fn output(&self) -> String {
        self.proc.as_ref().map(Proc::log).unwrap_or_default()
    }

    /// Sends it SIGHUP: it reads its plant file again.
    pub(crate) fn hangup(&self) {
        let Some(proc) = &self.proc else { return };
        let status = Command::new("kill").args(["-HUP", &proc.id().to_string()]).status();
        assert!(status.is_ok_and(|s| s.success()), "kill -HUP {}", proc.id());
    }

    /// Kills it with SIGKILL, as a power cut would: no NDEATH of its own.
    pub(crate) fn kill(&mut self) {
        if let Some(proc) = self.proc.take() {
            self.keep(&proc);
            drop(proc);
        }
    }

    /// Stops it with SIGTERM (a clean stop: NDEATH, then DISCONNECT) and waits.
    pub(crate) fn terminate(&mut self) {
        if let Some(mut proc) = self.proc.take() {
            proc.terminate();
            self.keep(&proc);
        }
    }

    fn keep(&self, proc: &Proc) {
        let _ = std::fs::write(&self.log, proc.log());
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        self.kill();
    }
}
