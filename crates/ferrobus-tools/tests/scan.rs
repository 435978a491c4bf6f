//! The scanner over an in-process port whose "device" answers only at one line setting, on
//! tokio's paused clock: the one port is reconfigured in place for each setting and lent to a
//! client for each, a device is found only where it answers, a corrupt reply is a lead that gets
//! the second pass, and traffic heard while listening stops the scan before it transmits.

use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use ferrobus::port::Port;
use ferrobus::{Rs485, Timer};
use ferrobus_proto::frame::rtu::encode_pdu;
use ferrobus_proto::frame::{LineConfig, LineTiming};
use ferrobus_proto::scan::{Answer, Lead, LineActivity, Probe};
use ferrobus_tools::scan::{ConfigError, OtherTraffic, Reconfigure, Report, ScanConfig, Scanner};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream, ReadBuf};

/// One end of a duplex stream, recording every line setting it is given.
struct FakePort {
    io: DuplexStream,
    settings: Arc<Mutex<Vec<LineConfig>>>,
}

impl AsyncRead for FakePort {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl AsyncWrite for FakePort {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.io).poll_write(cx, data)
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_flush(cx)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_shutdown(cx)
    }
}

impl Port for FakePort {}

impl Reconfigure for FakePort {
    fn reconfigure(&mut self, line: LineConfig) -> io::Result<()> {
        self.settings.lock().unwrap().push(line);
        Ok(())
    }
}

/// How the fake device answers the probe, at its setting only.
#[derive(Clone, Copy)]
enum Behaviour {
    Reply,
    CorruptReply,
    /// Answers under another address.
    AsUnit(u8),
}

/// A port and a device task on its other end: `unit` answers 8-byte requests while the port's
/// last setting is `at`, `wait` after the request has left the (simulated) wire, and its reply
/// takes its wire time too.
fn fake(unit: u8, at: LineConfig, behaviour: Behaviour, wait: Duration) -> (FakePort, Arc<Mutex<Vec<LineConfig>>>) {
    let (ours, mut device) = tokio::io::duplex(1024);
    let settings = Arc::new(Mutex::new(Vec::new()));
    let seen = Arc::clone(&settings);
    tokio::spawn(async move {
        let mut request = Vec::new();
        let mut buf = [0u8; 64];
        while let Ok(n) = device.read(&mut buf).await {
            if n == 0 {
                return;
            }
            request.extend_from_slice(&buf[..n]);
            while request.len() >= 8 {
                let frame: Vec<u8> = request.drain(..8).collect();
                let current = seen.lock().unwrap().last().copied();
                if frame[0] != unit || current != Some(at) {
                    continue;
                }
                let mut reply = [0u8; 16];
                let from = if let Behaviour::AsUnit(other) = behaviour { other } else { unit };
                let len = encode_pdu(from, &[0x03, 0x02, 0x00, 0x2A], &mut reply).unwrap();
                if let Behaviour::CorruptReply = behaviour {
                    reply[len - 1] ^= 0xFF;
                }
                let timing = LineTiming::new(&at);
                // The request's last byte reaches the device after its wire time; the reply's
                // reaches the scanner after its own.
                tokio::time::sleep(timing.transmit_time(8) + wait + timing.transmit_time(len)).await;
                if device.write_all(&reply[..len]).await.is_err() {
                    return;
                }
            }
        }
    });
    (FakePort { io: ours, settings: Arc::clone(&settings) }, settings)
}

fn config(units: &[u8], lines: &[LineConfig]) -> ScanConfig {
    ScanConfig {
        units: units.to_vec(),
        lines: lines.to_vec(),
        probe: Probe::default(),
        first_byte: Duration::from_millis(100),
        slow_first_byte: Duration::from_secs(1),
        listen: Duration::ZERO,
        force: false,
        identify: false,
        rs485: Rs485::Auto,
        echo_suppression: false,
        timer: Timer::Tokio,
        t1_5: None,
        t3_5: None,
    }
}

fn baud(b: u32) -> LineConfig {
    LineConfig::new(b).unwrap()
}

#[tokio::test(start_paused = true)]
async fn the_one_port_is_reconfigured_for_each_setting_and_the_device_found_only_at_its_own() {
    let (port, settings) = fake(2, baud(9600), Behaviour::Reply, Duration::from_millis(20));
    let mut scanner = Scanner::new(port, "fake", config(&[1, 2, 3], &[baud(19_200), baud(9600)])).unwrap();
    let mut report = Report::default();
    let mut probed = Vec::new();
    scanner
        .run(&mut report, |event| {
            if let ferrobus_tools::scan::Event::Probed { line, unit, .. } = event {
                probed.push((line.baud(), *unit));
            }
        })
        .await
        .unwrap();
    assert!(report.complete);
    assert_eq!(*settings.lock().unwrap(), [baud(19_200), baud(9600)]);
    assert_eq!(probed, [(19_200, 1), (19_200, 2), (19_200, 3), (9600, 1), (9600, 2), (9600, 3)]);
    let found: Vec<(u8, u32)> = report.devices.iter().map(|d| (d.unit, d.line.baud())).collect();
    assert_eq!(found, [(2, 9600)]);
    let device = &report.devices[0];
    assert_eq!(device.answer, Answer::Reply);
    // The device waited 20 ms between the request and its reply: so much is reported, on the
    // paused clock to within the client's own scheduling.
    let response = device.response_time;
    assert!(response >= Duration::from_millis(20) && response < Duration::from_millis(21), "{response:?}");
    assert!(report.leads.is_empty() && report.other_traffic.is_empty());
    assert_eq!(report.probes, 6);
}

#[tokio::test(start_paused = true)]
async fn a_corrupt_reply_is_a_lead_that_the_second_pass_probes_again_at_its_setting() {
    let (port, settings) = fake(5, baud(19_200), Behaviour::CorruptReply, Duration::ZERO);
    let mut scanner = Scanner::new(port, "fake", config(&[4, 5], &[baud(19_200), baud(9600)])).unwrap();
    let mut report = Report::default();
    scanner.run(&mut report, |_| {}).await.unwrap();
    assert!(report.devices.is_empty());
    assert_eq!(report.leads.len(), 1);
    let lead = report.leads[0];
    assert_eq!((lead.unit, lead.line), (5, baud(19_200)));
    assert_eq!(lead.lead, Lead::BadChecksum { head: Some((5, 0x03)) });
    assert_eq!(lead.second, Some(Answer::Lead(Lead::BadChecksum { head: Some((5, 0x03)) })));
    // The second pass went back to the lead's setting, on the same port.
    assert_eq!(*settings.lock().unwrap(), [baud(19_200), baud(9600), baud(19_200)]);
    // 2 units × 2 settings, then the lead once.
    assert_eq!(report.probes, 5);
}

#[tokio::test(start_paused = true)]
async fn traffic_heard_while_listening_stops_the_scan_before_it_transmits() {
    let (ours, mut other) = tokio::io::duplex(1024);
    let settings = Arc::new(Mutex::new(Vec::new()));
    let port = FakePort { io: ours, settings: Arc::clone(&settings) };
    // Another master's request to unit 9 and the reply, every 50 ms; what the scanner sends, if
    // anything, is kept in `sent`.
    let sent = Arc::new(Mutex::new(Vec::new()));
    let heard = Arc::clone(&sent);
    let talker = tokio::spawn(async move {
        let mut request = [0u8; 16];
        let n = encode_pdu(9, &[0x03, 0x00, 0x00, 0x00, 0x01], &mut request).unwrap();
        let mut reply = [0u8; 16];
        let m = encode_pdu(9, &[0x03, 0x02, 0x00, 0x01], &mut reply).unwrap();
        loop {
            other.write_all(&request[..n]).await.unwrap();
            tokio::time::sleep(Duration::from_millis(10)).await;
            other.write_all(&reply[..m]).await.unwrap();
            tokio::time::sleep(Duration::from_millis(40)).await;
            let mut buf = [0u8; 64];
            if let Ok(Ok(n)) = tokio::time::timeout(Duration::from_millis(1), other.read(&mut buf)).await {
                heard.lock().unwrap().extend_from_slice(&buf[..n]);
            }
        }
    });
    let mut config = config(&[1, 2, 3], &[baud(19_200), baud(9600)]);
    config.listen = Duration::from_millis(500);
    let mut scanner = Scanner::new(port, "fake", config).unwrap();
    let mut report = Report::default();
    scanner.run(&mut report, |_| {}).await.unwrap();
    assert!(report.held_back);
    assert_eq!(report.probes, 0);
    // The in-process port carries the bytes unchanged at any setting: valid at both.
    let lines: Vec<LineConfig> = report.masters.iter().map(|m| m.line).collect();
    assert_eq!(lines, [baud(19_200), baud(9600)]);
    for master in &report.masters {
        let LineActivity::Traffic { units, requests, responses, .. } = master.heard else { panic!("{master:?}") };
        assert_eq!(units.iter().collect::<Vec<_>>(), [9]);
        assert!(requests >= 5 && responses >= 5, "{requests} requests, {responses} responses in 500 ms");
    }
    // It listened at both settings, then sent nothing (the talker looks twice more).
    assert_eq!(*settings.lock().unwrap(), [baud(19_200), baud(9600)]);
    assert!(report.complete);
    tokio::time::sleep(Duration::from_millis(120)).await;
    assert_eq!(*sent.lock().unwrap(), [0u8; 0], "the scanner transmitted");
    talker.abort();
}

#[tokio::test(start_paused = true)]
async fn a_valid_frame_from_another_unit_is_other_traffic_not_a_device() {
    let (port, _) = fake(3, baud(19_200), Behaviour::AsUnit(9), Duration::ZERO);
    let mut scanner = Scanner::new(port, "fake", config(&[3], &[baud(19_200)])).unwrap();
    let mut report = Report::default();
    scanner.run(&mut report, |_| {}).await.unwrap();
    assert!(report.devices.is_empty() && report.leads.is_empty());
    let expected = OtherTraffic { line: baud(19_200), probed: 3, unit: 9, function: 0x03 };
    assert_eq!(report.other_traffic, [expected]);
}

#[test]
fn units_outside_1_to_247_and_empty_lists_are_refused() {
    let port = || FakePort { io: tokio::io::duplex(8).0, settings: Arc::default() };
    let refused = |units: &[u8], lines: &[LineConfig]| Scanner::new(port(), "fake", config(units, lines)).err();
    assert_eq!(refused(&[1, 0], &[baud(9600)]), Some(ConfigError::Unit(0)));
    assert_eq!(refused(&[248], &[baud(9600)]), Some(ConfigError::Unit(248)));
    assert_eq!(refused(&[], &[baud(9600)]), Some(ConfigError::NoUnits));
    assert_eq!(refused(&[1], &[]), Some(ConfigError::NoLines));
    assert!(refused(&[1, 247], &[baud(9600)]).is_none());
    let text = ConfigError::Unit(0).to_string();
    assert_eq!(text, "unit 0 cannot be scanned: units are 1-247 (0 is a broadcast, which nothing answers)");
    assert!(ConfigError::Unit(250).to_string().contains("248-255 are reserved"));
}
