//! The client against a server engine on an in-memory line, on tokio's paused clock: what
//! each call returns, and the behaviour the bus needs — retries, broadcast without waiting,
//! echo suppression, backing off a dead unit, reopening a lost port, many tasks on one bus.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ferrobus::port::{BoxPort, ConnectWith, Connecting};
use ferrobus::server::{ServerOptions, Shared, serve};
use ferrobus::{Backoff, Client, ClientConfig, Error, Framing, Transport};
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming};
use ferrobus_proto::pdu::{Bits, Registers};
use ferrobus_proto::slave::{Handler, Slave, SlaveConfig, UnitSet};
use ferrobus_proto::{ExceptionCode, codes::DiagnosticCode};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::Mutex;
use tokio::time::Instant;

/// 100 registers and coils per unit.
#[derive(Default)]
struct Device {
    registers: Vec<u16>,
    coils: Vec<bool>,
    served: u32,
}

impl Device {
    fn new() -> Self {
        Device { registers: (0..100).collect(), coils: vec![false; 100], served: 0 }
    }
}

fn span(len: usize, start: u16, n: usize) -> Result<std::ops::Range<usize>, ExceptionCode> {
    let start = usize::from(start);
    if start + n > len { Err(ExceptionCode::IllegalDataAddress) } else { Ok(start..start + n) }
}

impl Handler for Device {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.served += 1;
        out.copy_from_slice(&self.registers[span(self.registers.len(), start, out.len())?]);
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        let at = span(self.registers.len(), address, 1)?;
        self.registers[at][0] = value;
        Ok(())
    }
    fn write_multiple_registers(&mut self, _: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        let at = span(self.registers.len(), start, values.len())?;
        values.copy_to(&mut self.registers[at]);
        Ok(())
    }
    fn read_coils(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(&self.coils[span(self.coils.len(), start, out.len())?]);
        Ok(())
    }
    fn write_single_coil(&mut self, _: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        let at = span(self.coils.len(), address, 1)?;
        self.coils[at][0] = value;
        Ok(())
    }
    fn write_multiple_coils(&mut self, _: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        let at = span(self.coils.len(), start, values.len())?;
        values.copy_to(&mut self.coils[at]);
        Ok(())
    }
}

fn timing() -> LineTiming {
    LineTiming::new(&LineConfig::new(19_200).unwrap())
}

/// A bus in memory: every connection the client opens is a fresh duplex pipe to a server
/// engine for `units`, sharing one device. The port can be taken away and given back.
struct Bench {
    device: Shared<Device>,
    available: Arc<AtomicBool>,
    /// Kills the current connection when set.
    kill: Arc<Mutex<Option<tokio::sync::oneshot::Sender<()>>>>,
}

impl Bench {
    fn new() -> Self {
        Bench {
            device: Shared::new(Device::new()),
            available: Arc::new(AtomicBool::new(true)),
            kill: Arc::new(Mutex::new(None)),
        }
    }

    /// A transport whose connections lead to a server answering `units`; with `echo`, the
    /// line also returns every byte the client sends, as a half-duplex adapter would.
    fn transport(&self, units: &[u8], echo: bool) -> Transport {
        let device = self.device.clone();
        let available = Arc::clone(&self.available);
        let kill = Arc::clone(&self.kill);
        let units: UnitSet = units.iter().copied().collect();
        let connector = ConnectWith::new("in-memory bus", move || -> Connecting {
            let device = device.clone();
            let available = Arc::clone(&available);
            let kill = Arc::clone(&kill);
            Box::pin(async move {
                if !available.load(Ordering::SeqCst) {
                    return Err(std::io::Error::new(std::io::ErrorKind::NotFound, "unplugged"));
                }
                let (client_end, line_end) = tokio::io::duplex(4096);
                let (stop, stopped) = tokio::sync::oneshot::channel();
                *kill.lock().await = Some(stop);
                tokio::spawn(run_server(line_end, device, units, echo, stopped));
                Ok(Box::new(client_end) as BoxPort)
            })
        });
        Transport::custom(Framing::Rtu, timing(), connector)
    }

    /// Pulls the plug: the current connection dies and new ones fail until `plug_in`.
    async fn unplug(&self) {
        self.available.store(false, Ordering::SeqCst);
        if let Some(kill) = self.kill.lock().await.take() {
            let _ = kill.send(());
        }
    }

    fn plug_in(&self) {
        self.available.store(true, Ordering::SeqCst);
    }
}

/// The server side of one connection; with `echo`, a line in between also copies the
/// client's bytes back to it.
async fn run_server(
    line_end: tokio::io::DuplexStream,
    mut device: Shared<Device>,
    units: UnitSet,
    echo: bool,
    stopped: tokio::sync::oneshot::Receiver<()>,
) {
    let (server_end, mut server_side) = tokio::io::duplex(4096);
    let (mut line_rd, mut line_wr) = tokio::io::split(line_end);
    // The line: client → server (and back to the client if echoing); server → client.
    let line = async move {
        let (mut srv_rd, mut srv_wr) = tokio::io::split(&mut server_side);
        let mut a = [0u8; 512];
        let mut b = [0u8; 512];
        loop {
            tokio::select! {
                n = line_rd.read(&mut a) => {
                    let Ok(n @ 1..) = n else { return };
                    if echo && line_wr.write_all(&a[..n]).await.is_err() { return }
                    if srv_wr.write_all(&a[..n]).await.is_err() { return }
                }
                n = srv_rd.read(&mut b) => {
                    let Ok(n @ 1..) = n else { return };
                    if line_wr.write_all(&b[..n]).await.is_err() { return }
                }
            }
        }
    };
    let config = SlaveConfig { units, response_wait: Duration::ZERO };
    let slave = Slave::new(RtuCodec::new(timing(), Expect::Both), config);
    let mut options = ServerOptions::new(timing(), ferrobus::Timer::Tokio);
    let server = serve(slave, Box::new(server_end), &mut device, &mut options);
    tokio::select! {
        () = line => {}
        _ = server => {}
        _ = stopped => {}
    }
}

fn config() -> ClientConfig {
    ClientConfig { timeout: Duration::from_millis(200), backoff: None, ..ClientConfig::default() }
}

#[tokio::test(start_paused = true)]
async fn reads_and_writes_go_through_to_the_device() {
    let bench = Bench::new();
    let client = Client::connect(bench.transport(&[1], false), config()).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 10, 3).await.unwrap(), [10, 11, 12]);
    client.write_single_register(1, 10, 0xBEEF).await.unwrap();
    client.write_multiple_registers(1, 20, &[7, 8]).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 10, 1).await.unwrap(), [0xBEEF]);
    assert_eq!(client.read_holding_registers(1, 20, 2).await.unwrap(), [7, 8]);
    client.write_multiple_coils(1, 3, &[true, false, true]).await.unwrap();
    client.write_single_coil(1, 4, true).await.unwrap();
    assert_eq!(client.read_coils(1, 2, 4).await.unwrap(), [false, true, true, true]);
}

#[tokio::test(start_paused = true)]
async fn an_exception_comes_back_with_its_code_and_the_next_request_still_works() {
    let bench = Bench::new();
    let client = Client::connect(bench.transport(&[1], false), config()).await.unwrap();
    let err = client.read_holding_registers(1, 99, 2).await.unwrap_err();
    assert_eq!(err.exception(), Some(ExceptionCode::IllegalDataAddress), "{err}");
    let err = client.read_input_registers(1, 0, 1).await.unwrap_err();
    assert_eq!(err.exception(), Some(ExceptionCode::IllegalFunction), "{err}");
    assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [0]);
}

#[tokio::test(start_paused = true)]
async fn a_silent_unit_times_out_after_each_retry_and_the_error_says_so() {
    let bench = Bench::new();
    let client = Client::connect(bench.transport(&[1], false), config()).await.unwrap().with_retries(2);
    let start = Instant::now();
    let err = client.read_holding_registers(9, 0, 1).await.unwrap_err();
    let Error::Timeout { unit: 9, timeout, attempts: 3, heard: None } = err else { panic!("{err:?}") };
    assert_eq!(timeout, Duration::from_millis(200));
    // Three timeouts, and after the first the late window (twice the timeout) for a reply
    // that may still come; it does not, so the unit is silent and the next attempts owe none.
    let elapsed = start.elapsed();
    assert!(elapsed >= Duration::from_secs(1) && elapsed < Duration::from_millis(1050), "{elapsed:?}");
    assert_eq!(err.to_string(), "no reply from unit 9 within 200 ms (3 attempts)");
}

#[tokio::test(start_paused = true)]
async fn a_broadcast_returns_after_the_turnaround_without_waiting_for_a_reply() {
    let bench = Bench::new();
    let config =
        ClientConfig { turnaround_delay: Duration::from_millis(50), timeout: Duration::from_secs(5), ..config() };
    let client = Client::connect(bench.transport(&[1], false), config).await.unwrap();
    let start = Instant::now();
    client.write_single_register(0, 5, 1234).await.unwrap();
    let elapsed = start.elapsed();
    // 8 characters at 19200 (4.6 ms) plus the turnaround: far from the 5 s timeout.
    assert!(elapsed >= Duration::from_millis(50) && elapsed < Duration::from_millis(60), "{elapsed:?}");
    assert_eq!(client.read_holding_registers(1, 5, 1).await.unwrap(), [1234], "the slave executed it");
    let err = client.read_holding_registers(0, 0, 1).await.unwrap_err();
    assert!(
        matches!(err, Error::BroadcastRead { function: ferrobus_proto::FunctionCode::ReadHoldingRegisters }),
        "a broadcast read is refused before it is sent, as a broadcast read: {err}"
    );
}

#[tokio::test(start_paused = true)]
async fn echo_suppression_lets_the_reply_through_an_adapter_that_hears_itself() {
    let bench = Bench::new();
    let config = ClientConfig { echo_suppression: true, ..config() };
    let client = Client::connect(bench.transport(&[1], true), config).await.unwrap();
    client.write_single_register(1, 1, 0x1234).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 0, 3).await.unwrap(), [0, 0x1234, 2]);
    // A refused write: the echo (identical to a success) must not be taken for the reply.
    let err = client.write_single_register(1, 500, 1).await.unwrap_err();
    assert_eq!(err.exception(), Some(ExceptionCode::IllegalDataAddress));
}

#[tokio::test(start_paused = true)]
async fn a_dead_unit_is_backed_off_and_does_not_stall_polling_of_the_others() {
    let bench = Bench::new();
    let backoff = Backoff { after: 2, initial: Duration::from_secs(5), max: Duration::from_secs(60) };
    let config = ClientConfig { backoff: Some(backoff), ..config() };
    let client = Client::connect(bench.transport(&[1], false), config).await.unwrap();
    let start = Instant::now();
    let (mut ok, mut timeouts, mut skipped) = (0, 0, 0);
    for _ in 0..20 {
        client.read_holding_registers(1, 0, 1).await.unwrap();
        ok += 1;
        match client.read_holding_registers(7, 0, 1).await {
            Err(Error::Timeout { .. }) => timeouts += 1,
            Err(Error::Backoff { unit: 7, .. }) => skipped += 1,
            other => panic!("{other:?}"),
        }
    }
    assert_eq!((ok, timeouts, skipped), (20, 2, 18));
    // Two timeouts and one late window (400 ms: the unit was silent through it, so its
    // second timeout owed no reply).
    let cost = start.elapsed();
    assert!(cost < Duration::from_secs(1), "dead unit cost only two timeouts and one late window: {cost:?}");
    // After the backoff period, one probe goes out; it fails and the period doubles.
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert!(client.read_holding_registers(7, 0, 1).await.unwrap_err().is_timeout());
    let Err(Error::Backoff { retry_in, .. }) = client.read_holding_registers(7, 0, 1).await else { panic!() };
    assert!(retry_in > Duration::from_secs(9), "{retry_in:?}");
}

#[tokio::test(start_paused = true)]
async fn over_modbus_tcp_unit_0_is_an_ordinary_unit_and_is_backed_off_when_it_stops_answering() {
    // A server that reads every request and answers none.
    let connector = ConnectWith::new("silent server", || -> Connecting {
        Box::pin(async {
            let (client_end, mut server_end) = tokio::io::duplex(4096);
            tokio::spawn(async move {
                let mut buf = [0u8; 512];
                while server_end.read(&mut buf).await.is_ok_and(|n| n > 0) {}
            });
            Ok(Box::new(client_end) as BoxPort)
        })
    });
    let backoff = Backoff { after: 2, initial: Duration::from_secs(5), max: Duration::from_secs(60) };
    let config = ClientConfig { backoff: Some(backoff), ..config() };
    let client = Client::connect(Transport::custom(Framing::Mbap, timing(), connector), config).await.unwrap();
    for _ in 0..2 {
        let err = client.read_holding_registers(0, 0, 1).await.unwrap_err();
        assert!(err.is_timeout(), "a read from unit 0 over TCP is sent and waits for its reply: {err}");
    }
    let err = client.read_holding_registers(0, 0, 1).await.unwrap_err();
    assert!(matches!(err, Error::Backoff { unit: 0, .. }), "after two timeouts unit 0 is skipped: {err}");
}

#[tokio::test(start_paused = true)]
async fn a_lost_port_fails_requests_clearly_and_is_reopened_when_it_returns() {
    let bench = Bench::new();
    let client = Client::connect(bench.transport(&[1], false), config()).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 3, 1).await.unwrap(), [3]);
    bench.unplug().await;
    tokio::time::sleep(Duration::from_millis(10)).await;
    let err = client.read_holding_registers(1, 3, 1).await.unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    let err = client.read_holding_registers(1, 3, 1).await.unwrap_err();
    assert_eq!(err.to_string(), "opening in-memory bus: unplugged");
    bench.plug_in();
    assert_eq!(client.read_holding_registers(1, 3, 1).await.unwrap(), [3], "reopened");
}

#[tokio::test(start_paused = true)]
async fn many_tasks_share_one_client_and_their_requests_take_turns() {
    let bench = Bench::new();
    let client = Client::connect(bench.transport(&[1, 2], false), config()).await.unwrap();
    let tasks: Vec<_> = (0..10u16)
        .map(|t| {
            let client = client.clone();
            tokio::spawn(async move {
                for i in 0..20u16 {
                    let unit = 1 + u8::try_from(t % 2).unwrap();
                    let start = (t * 7 + i) % 90;
                    assert_eq!(client.read_holding_registers(unit, start, 2).await.unwrap(), [start, start + 1]);
                }
            })
        })
        .collect();
    for task in tasks {
        task.await.unwrap();
    }
    assert_eq!(bench.device.lock().served, 200);
}

#[tokio::test(start_paused = true)]
async fn raw_requests_reach_the_device_unchecked_and_diagnostics_echo() {
    let bench = Bench::new();
    let client = Client::connect(bench.transport(&[1], false), config()).await.unwrap();
    let err = client.raw(1, &[0x03, 0x00, 0x00, 0x00, 0x00]).await.unwrap_err();
    assert_eq!(err.exception(), Some(ExceptionCode::IllegalDataValue), "quantity 0");
    assert_eq!(client.raw(1, &[0x03, 0x00, 0x02, 0x00, 0x01]).await.unwrap(), Some(vec![0x03, 0x02, 0x00, 0x02]));
    assert_eq!(client.diagnostics(1, DiagnosticCode::ReturnQueryData, &[0xA5, 0x37]).await.unwrap(), [0xA5, 0x37]);
    assert_eq!(client.diagnostic_word(1, DiagnosticCode::BusMessageCount, 0).await.unwrap(), 4);
}

#[tokio::test]
async fn over_tcp_a_server_answers_each_connection() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let device = Shared::new(Device::new());
    let transport = Transport::tcp(&addr);
    let options = {
        let transport = transport.clone();
        move || ServerOptions::for_transport(&transport)
    };
    let server = tokio::spawn(ferrobus::server::serve_tcp(listener, transport, SlaveConfig::unit(1), device, options));
    for _ in 0..2 {
        let client = Client::connect(Transport::tcp(&addr), config()).await.unwrap();
        client.write_single_register(1, 2, 77).await.unwrap();
        assert_eq!(client.read_holding_registers(1, 1, 2).await.unwrap(), [1, 77]);
    }
    let err = Client::connect(Transport::tcp("127.0.0.1:1"), config()).await.unwrap_err();
    assert!(err.to_string().starts_with("opening 127.0.0.1:1: "), "{err}");
    server.abort();
}

#[tokio::test(start_paused = true)]
async fn a_late_rtu_reply_between_requests_is_counted_as_it_comes_not_at_the_next_request() {
    use ferrobus_proto::crc::crc16_wire;
    let (client_end, mut device) = tokio::io::duplex(4096);
    let port = Arc::new(std::sync::Mutex::new(Some(client_end)));
    let connector = ConnectWith::new("a slow device", move || -> Connecting {
        let port = port.lock().unwrap().take();
        Box::pin(async move { port.map(|p| Box::new(p) as BoxPort).ok_or_else(|| std::io::ErrorKind::NotFound.into()) })
    });
    let client = Client::connect(Transport::custom(Framing::Rtu, timing(), connector), config()).await.unwrap();
    let replying = tokio::spawn(async move {
        let mut request = [0u8; 8];
        device.read_exact(&mut request).await.unwrap();
        // Past the client's 200 ms: the reply is late.
        tokio::time::sleep(Duration::from_millis(300)).await;
        let mut reply = vec![1, 0x03, 2, 0x12, 0x34];
        reply.extend(crc16_wire(&reply));
        device.write_all(&reply).await.unwrap();
        device
    });
    let err = client.read_holding_registers(1, 0, 1).await.unwrap_err();
    assert!(matches!(err, Error::Timeout { .. }), "{err}");
    let _device = replying.await.unwrap();
    // No request follows: the driver, between requests, reads and publishes what it heard.
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert_eq!(client.stats().master.late_replies, 1, "{:?}", client.stats());
}
