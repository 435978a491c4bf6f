//! A real Modbus server in the test process: `ferrobus::server::serve_tcp` over a small
//! handler, on its own thread and runtime, and a helper that runs the binary against it.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use assert_cmd::assert::{Assert, OutputAssertExt};
use ferrobus::server::{ServerOptions, Shared, serve, serve_tcp};
use ferrobus::{Pty, Timer, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::ascii::AsciiCodec;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming, Parity};
use ferrobus_proto::pdu::{Bits, Registers, Request};
use ferrobus_proto::slave::{Admission, Handler, Slave, SlaveConfig};

/// Registers, coils and inputs per table.
pub(crate) const SIZE: usize = 1000;

/// A register the inverter-like handler guards: values above 1000 get vendor exception 0x21.
pub(crate) const GUARDED: u16 = 500;

/// One request as the server saw it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct Seen {
    pub(crate) function: u8,
    pub(crate) start: u16,
    pub(crate) quantity: u16,
}

/// The device: holding[i] = i, input[i] = 1000 + i, coil i on when i % 3 == 0, discrete
/// input i on when i is even.
pub(crate) struct Device {
    pub(crate) holding: Vec<u16>,
    input: Vec<u16>,
    pub(crate) coils: Vec<bool>,
    discrete: Vec<bool>,
    identification: bool,
    pub(crate) requests: Vec<Seen>,
}

impl Device {
    fn new(identification: bool) -> Self {
        let words = |base: usize| (0..SIZE).map(|i| u16::try_from(base + i).unwrap()).collect();
        Device {
            holding: words(0),
            input: words(1000),
            coils: (0..SIZE).map(|i| i % 3 == 0).collect(),
            discrete: (0..SIZE).map(|i| i % 2 == 0).collect(),
            identification,
            requests: Vec::new(),
        }
    }
}

fn span(start: u16, n: usize) -> Result<std::ops::Range<usize>, ExceptionCode> {
    let start = usize::from(start);
    if start + n > SIZE { Err(ExceptionCode::IllegalDataAddress) } else { Ok(start..start + n) }
}

fn guard(address: u16, value: u16) -> Result<(), ExceptionCode> {
    if address == GUARDED && value > 1000 { Err(ExceptionCode::from_u8(0x21)) } else { Ok(()) }
}

impl Handler for Device {
    fn admit(&mut self, _: u8, broadcast: bool, request: &Request<'_>) -> Admission {
        let (start, quantity) = match request {
            Request::ReadCoils(r) | Request::ReadDiscreteInputs(r) => (r.start(), r.quantity()),
            Request::ReadHoldingRegisters(r) | Request::ReadInputRegisters(r) => (r.start(), r.quantity()),
            Request::WriteMultipleRegisters(w) => (w.start(), w.quantity()),
            Request::WriteMultipleCoils(w) => (w.start(), w.quantity()),
            Request::WriteSingleRegister(w) => (w.address, 1),
            Request::WriteSingleCoil(w) => (w.address, 1),
            _ => (0, 0),
        };
        self.requests.push(Seen { function: request.function().value(), start, quantity });
        if broadcast && !request.function().is_write() { Admission::Ignore } else { Admission::Serve }
    }
    fn read_coils(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(&self.coils[span(start, out.len())?]);
        Ok(())
    }
    fn read_discrete_inputs(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(&self.discrete[span(start, out.len())?]);
        Ok(())
    }
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(&self.holding[span(start, out.len())?]);
        Ok(())
    }
    fn read_input_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(&self.input[span(start, out.len())?]);
        Ok(())
    }
    fn write_single_coil(&mut self, _: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        self.coils[span(address, 1)?][0] = value;
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        let at = span(address, 1)?;
        guard(address, value)?;
        self.holding[at][0] = value;
        Ok(())
    }
    fn write_multiple_coils(&mut self, _: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        values.copy_to(&mut self.coils[span(start, values.len())?]);
        Ok(())
    }
    fn write_multiple_registers(&mut self, _: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        let at = span(start, values.len())?;
        for (i, v) in values.iter().enumerate() {
            guard(start + u16::try_from(i).unwrap(), v)?;
        }
        values.copy_to(&mut self.holding[at]);
        Ok(())
    }
    fn report_server_id(&mut self, _: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        let id = b"\x42\xFFFERROBUS-TEST";
        out[..id.len()].copy_from_slice(id);
        Ok(id.len())
    }
    fn device_object(&mut self, _: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        if !self.identification {
            return None;
        }
        let value: &[u8] = match id {
            0x00 => b"ferrobus",
            0x01 => b"FB-TEST",
            0x02 => b"1.2",
            0x04 => b"Test Drive",
            0x05 => b"TD-1",
            0x80 => b"extended object",
            _ => return None,
        };
        out[..value.len()].copy_from_slice(value);
        Some(value.len())
    }
}

/// A server on 127.0.0.1, serving unit 1.
pub(crate) struct Server {
    port: u16,
    device: Shared<Device>,
    rtu: bool,
}

impl Server {
    /// Modbus/TCP, with device identification.
    pub(crate) fn start() -> Server {
        Self::spawn(false, true)
    }

    /// RTU over TCP.
    pub(crate) fn rtu_over_tcp() -> Server {
        Self::spawn(true, true)
    }

    /// Modbus/TCP, without device identification (FC2B answers exception 01).
    pub(crate) fn without_identification() -> Server {
        Self::spawn(false, false)
    }

    fn spawn(rtu: bool, identification: bool) -> Server {
        let device = Shared::new(Device::new(identification));
        let shared = device.clone();
        let (tx, rx) = mpsc::channel();
        thread::spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
            runtime.block_on(async move {
                let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
                tx.send(listener.local_addr().unwrap().port()).unwrap();
                let transport = if rtu { Transport::rtu_over_tcp("test") } else { Transport::tcp("test") };
                let options = {
                    let transport = transport.clone();
                    move || ferrobus::server::ServerOptions::for_transport(&transport)
                };
                let _ = serve_tcp(listener, transport, SlaveConfig::unit(1), shared, options).await;
            });
        });
        Server { port: rx.recv().unwrap(), device, rtu }
    }

    /// `--tcp 127.0.0.1:PORT` (or `--rtu-tcp`).
    pub(crate) fn target(&self) -> [String; 2] {
        let flag = if self.rtu { "--rtu-tcp" } else { "--tcp" };
        [flag.to_string(), format!("127.0.0.1:{}", self.port)]
    }

    /// Runs `ferrobus` against this server with a short timeout.
    pub(crate) fn run(&self, args: &[&str]) -> Assert {
        ferrobus().args(self.target()).args(["--timeout", "500ms"]).args(args).assert()
    }

    /// The requests seen so far, and forgets them.
    pub(crate) fn take_requests(&self) -> Vec<Seen> {
        std::mem::take(&mut self.device.lock().requests)
    }

    /// The device, to look at or preset.
    pub(crate) fn device(&self) -> std::sync::MutexGuard<'_, Device> {
        self.device.lock()
    }
}

/// A serial line without a wire: a pty made in this process, served as unit 1 in RTU (or
/// ASCII) framing. Returns the path for `--port`.
pub(crate) fn pty_server(ascii: bool) -> String {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        runtime.block_on(async move {
            let pty = Pty::open().unwrap();
            tx.send(pty.path.display().to_string()).unwrap();
            // A pty cannot hold parity; the client is run with --parity none.
            let timing = LineTiming::new(&LineConfig::new(19_200).unwrap().with_parity(Parity::None));
            let mut options = ServerOptions::new(timing, Timer::Tokio);
            let mut handler = Shared::new(Device::new(true));
            let config = SlaveConfig::unit(1);
            let port = Box::new(pty.port);
            let result = if ascii {
                serve(Slave::new(AsciiCodec::new(timing), config), port, &mut handler, &mut options).await.1
            } else {
                let codec = RtuCodec::new(timing, Expect::Requests);
                serve(Slave::new(codec, config), port, &mut handler, &mut options).await.1
            };
            result.unwrap();
        });
    });
    rx.recv().unwrap()
}

/// The binary under test.
pub(crate) fn ferrobus() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.env("XDG_CONFIG_HOME", no_settings());
    command
}

/// An `XDG_CONFIG_HOME` without a settings file: the tests do not read the developer's (a test
/// that wants one sets its own).
pub(crate) fn no_settings() -> std::path::PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join("no-settings")
}

/// Runs the binary without a server.
pub(crate) fn offline(args: &[&str]) -> Assert {
    ferrobus().args(args).assert()
}

/// A Modbus/TCP server that answers every request with `reply` (a PDU), keeping the
/// transaction id: for replies a real server would never send.
pub(crate) fn misbehaving_server(reply: &'static [u8]) -> u16 {
    misbehaving_server_with(reply, 0)
}

/// [`misbehaving_server`], answering under the request's transaction id plus `shift`.
pub(crate) fn misbehaving_server_with(reply: &'static [u8], shift: u16) -> u16 {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { return };
            let mut header = [0u8; 7];
            while stream.read_exact(&mut header).is_ok() {
                let len = usize::from(u16::from_be_bytes([header[4], header[5]]));
                let mut pdu = vec![0u8; len.saturating_sub(1)];
                if stream.read_exact(&mut pdu).is_err() {
                    break;
                }
                let transaction = u16::from_be_bytes([header[0], header[1]]).wrapping_add(shift);
                let mut frame = transaction.to_be_bytes().to_vec();
                frame.extend(&header[2..4]);
                frame.extend(u16::try_from(reply.len() + 1).unwrap().to_be_bytes());
                frame.push(header[6]);
                frame.extend(reply);
                let _ = stream.write_all(&frame);
            }
        }
    });
    port
}

/// A port on which nothing listens.
pub(crate) fn closed_port() -> u16 {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap().port()
}

/// The assertion's stdout as text.
pub(crate) fn stdout(assert: &Assert) -> String {
    String::from_utf8_lossy(&assert.get_output().stdout).into_owned()
}

/// The assertion's stderr as text.
pub(crate) fn stderr(assert: &Assert) -> String {
    String::from_utf8_lossy(&assert.get_output().stderr).into_owned()
}

/// `ferrobus sim --pty ARGS`, stopped when dropped; `path` is the pty it serves.
pub(crate) struct Sim {
    child: std::process::Child,
    /// The pty.
    pub(crate) path: String,
}

impl Sim {
    /// Starts it with `ARGS` and waits for its pty path.
    pub(crate) fn pty(args: &[&str]) -> Sim {
        use std::io::BufRead;
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_ferrobus"))
            .env("XDG_CONFIG_HOME", no_settings())
            .args(["sim", "--pty", "--duration", "60s"])
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("ferrobus sim starts");
        let mut line = String::new();
        let stdout = child.stdout.take().expect("piped stdout");
        std::io::BufReader::new(stdout).read_line(&mut line).expect("the sim prints its pty");
        let path = line.trim().to_string();
        assert!(path.starts_with('/'), "the sim printed {line:?}, not a pty path");
        Sim { child, path }
    }

    /// Runs the CLI with `args` against unit `unit` of this simulator (no parity: a pty takes
    /// none), with a 300 ms timeout.
    pub(crate) fn run(&self, unit: u8, args: &[&str]) -> Assert {
        ferrobus()
            .args(["--port", &self.path, "--parity", "none", "--unit", &unit.to_string(), "--timeout", "300ms"])
            .args(args)
            .assert()
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A `ferrobus sim --tcp` serving `profile` (a built-in name or TOML text written to a file).
pub(crate) struct TcpSim {
    child: Child,
    /// HOST:PORT it listens on.
    pub(crate) addr: String,
    file: Option<PathBuf>,
}

impl TcpSim {
    /// The built-in profile `name`.
    pub(crate) fn builtin(name: &str) -> TcpSim {
        TcpSim::start(name, None)
    }

    /// The profile `text`, written to a temporary file named after `name` (removed on drop).
    pub(crate) fn text(name: &str, text: &str) -> TcpSim {
        let path = std::env::temp_dir().join(format!("ferrobus-sim-{}-{name}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        TcpSim::start(path.to_str().unwrap(), Some(path.clone()))
    }

    /// The profile `profile` (a built-in name or a path); `file` is removed on drop.
    pub(crate) fn start(profile: &str, file: Option<PathBuf>) -> TcpSim {
        let port = TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).unwrap().port();
        let addr = format!("127.0.0.1:{port}");
        let child = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
            .env("XDG_CONFIG_HOME", no_settings())
            .args(["--tcp", &addr, "sim", "--profile", profile, "--duration", "60s"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let started = Instant::now();
        while TcpStream::connect(&addr).is_err() {
            assert!(started.elapsed() < Duration::from_secs(10), "the sim listens on {addr}");
            std::thread::sleep(Duration::from_millis(20));
        }
        TcpSim { child, addr, file }
    }

    /// `ferrobus --tcp ADDR --timeout 500ms ARGS...`.
    pub(crate) fn run(&self, args: &[&str]) -> Assert {
        ferrobus().args(["--tcp", &self.addr, "--timeout", "500ms"]).args(args).assert()
    }
}

impl Drop for TcpSim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        if let Some(file) = &self.file {
            let _ = std::fs::remove_file(file);
        }
    }
}
