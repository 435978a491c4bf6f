//! The gateway end to end in one process, with paused time: Modbus/TCP clients on in-memory
//! streams, an RTU line that is an in-memory stream to a slave engine serving simulated
//! devices. Each test asserts what the clients were answered and what reached the line.

use std::collections::BTreeMap;
use std::time::Duration;

use ferrobus::port::{BoxPort, ConnectWith, Framing};
use ferrobus::server::{Answering, ConnectionPolicy, Fate, ReplyFilter, ServerOptions, Shared, serve};
use ferrobus::{ClientConfig, Timer, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig as Line, LineTiming};
use ferrobus_proto::pdu::Request;
use ferrobus_proto::slave::{Admission, Handler, Slave, SlaveConfig, UnitSet};
use ferrobus_tools::gateway::stats::Malformed;
use ferrobus_tools::gateway::{
    AllowAll, Authorize, Gateway, GatewayConfig, GatewayLine, Inbound, Route, Routes, Rules,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

/// Devices on the line: 100 holding registers each, every request counted by unit; the
/// units in `dead` never answer, and no unit answers a function code the spec does not
/// define (as libmodbus's server, silent on codes it does not know).
#[derive(Default)]
struct Bus {
    registers: BTreeMap<u8, [u16; 100]>,
    seen: BTreeMap<u8, u32>,
    dead: Vec<u8>,
    /// Broadcasts admitted, once per unit served.
    broadcasts: u32,
}

impl Handler for Bus {
    fn admit(&mut self, unit: u8, broadcast: bool, request: &Request<'_>) -> Admission {
        if broadcast {
            self.broadcasts += 1;
            return Admission::Serve;
        }
        *self.seen.entry(unit).or_default() += 1;
        let ignored = matches!(request, Request::Custom(_));
        if ignored || self.dead.contains(&unit) { Admission::Ignore } else { Admission::Serve }
    }
    fn read_holding_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        let regs = self.registers.entry(unit).or_insert([0; 100]);
        let start = usize::from(start);
        let from = regs.get(start..start + out.len()).ok_or(ExceptionCode::IllegalDataAddress)?;
        out.copy_from_slice(from);
        Ok(())
    }
    fn write_single_register(&mut self, unit: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        let regs = self.registers.entry(unit).or_insert([0; 100]);
        *regs.get_mut(usize::from(address)).ok_or(ExceptionCode::IllegalDataAddress)? = value;
        Ok(())
    }
}

/// What the line's devices do to their replies: corrupt the CRC of a unit's, or hold the
/// first reply of a unit back.
#[derive(Clone, Default)]
struct Faults {
    corrupt: Option<u8>,
    delay_first: Option<(u8, Duration)>,
}

struct Filter(Faults);

impl ReplyFilter for Filter {
    fn filter(&mut self, answering: Option<&Answering>, frame: &mut Vec<u8>) -> Fate {
        let unit = answering.map(|a| a.unit);
        if unit.is_some()
            && unit == self.0.corrupt
            && let Some(last) = frame.last_mut()
        {
            *last ^= 0xFF;
        }
        if let Some((u, d)) = self.0.delay_first
            && unit == Some(u)
        {
            self.0.delay_first = None;
            return Fate::Delay(d);
        }
        Fate::Send
    }
}

const UNITS: [u8; 4] = [1, 2, 3, 7];

fn timing() -> LineTiming {
    LineTiming::new(&Line::new(19_200).unwrap())
}

/// A line whose port is an in-memory stream to the slave engine serving `bus`.
fn line(bus: &Shared<Bus>, faults: Faults) -> Transport {
    let bus = bus.clone();
    let connector = ConnectWith::new("test line", move || {
        let (ours, theirs) = tokio::io::duplex(4096);
        let mut bus = bus.clone();
        let faults = faults.clone();
        tokio::spawn(async move {
            let mut units = UnitSet::EMPTY;
            for unit in UNITS {
                units.insert(unit);
            }
            let slave = Slave::new(
                RtuCodec::new(timing(), Expect::Requests),
                SlaveConfig { units, response_wait: Duration::ZERO },
            );
            let mut options = ServerOptions::new(timing(), Timer::Tokio);
            options.filter = Some(Box::new(Filter(faults)));
            let _ = serve(slave, Box::new(theirs) as BoxPort, &mut bus, &mut options).await;
        });
        Box::pin(async move { Ok(Box::new(ours) as BoxPort) })
    });
    Transport::custom(Framing::Rtu, timing(), connector).with_timer(Timer::Tokio)
}

fn client_config() -> ClientConfig {
    ClientConfig { timeout: Duration::from_millis(50), retries: 1, ..ClientConfig::default() }
}

struct Setup {
    routes: Routes,
    queue: usize,
    faults: Faults,
    broadcast_ack: bool,
    cache: Option<Duration>,
}

impl Default for Setup {
    fn default() -> Self {
        Setup { routes: Routes::all_on(0), queue: 64, faults: Faults::default(), broadcast_ack: false, cache: None }
    }
}

async fn gateway(bus: &Shared<Bus>, setup: Setup) -> Gateway {
    let line = GatewayLine { queue: setup.queue, ..GatewayLine::new(line(bus, setup.faults), client_config()) };
    let config = GatewayConfig {
        lines: vec![line],
        routes: setup.routes,
        broadcast_ack: setup.broadcast_ack,
        cache_max_age: setup.cache,
    };
    Gateway::start(config).await.unwrap()
}

/// A client connection served by `gateway` through `authorize`.
fn connect(gateway: &Gateway, authorize: Box<dyn Authorize>) -> DuplexStream {
    let (client, server) = tokio::io::duplex(4096);
    let gateway = gateway.clone();
    tokio::spawn(async move {
        let mut authorize = authorize;
        gateway.serve_connection(server, "test client", Inbound::Mbap, authorize.as_mut(), ConnectionPolicy::TCP).await
    });
    client
}

fn mbap(t: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = t.to_be_bytes().to_vec();
    frame.extend_from_slice(&[0, 0]);
    frame.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    frame.push(unit);
    frame.extend_from_slice(pdu);
    frame
}

/// Reads one reply: (transaction, unit, PDU).
async fn reply(stream: &mut DuplexStream) -> (u16, u8, Vec<u8>) {
    let mut head = [0u8; 7];
    stream.read_exact(&mut head).await.unwrap();
    let len = usize::from(u16::from_be_bytes([head[4], head[5]])) - 1;
    let mut pdu = vec![0u8; len];
    stream.read_exact(&mut pdu).await.unwrap();
    (u16::from_be_bytes([head[0], head[1]]), head[6], pdu)
}

async fn ask(stream: &mut DuplexStream, t: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    stream.write_all(&mbap(t, unit, pdu)).await.unwrap();
    let (tid, u, reply) = reply(stream).await;
    assert_eq!((tid, u), (t, unit), "the reply's transaction and unit are the request's");
    reply
}

const READ_0_2: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x02];

#[tokio::test(start_paused = true)]
async fn reads_and_writes_go_through_and_a_renumbered_unit_is_asked_under_its_line_address() {
    let bus = Shared::new(Bus::default());
    let mut routes = Routes::all_on(0);
    routes.set(20, Route { line: 0, unit: 3 });
    let gw = gateway(&bus, Setup { routes, ..Setup::default() }).await;
    let mut c = connect(&gw, Box::new(AllowAll));
    assert_eq!(ask(&mut c, 1, 1, &[0x06, 0x00, 0x01, 0x12, 0x34]).await, [0x06, 0x00, 0x01, 0x12, 0x34]);
    assert_eq!(ask(&mut c, 2, 1, &READ_0_2).await, [0x03, 0x04, 0x00, 0x00, 0x12, 0x34]);
    assert_eq!(ask(&mut c, 3, 20, &[0x06, 0x00, 0x00, 0x00, 0x2A]).await, [0x06, 0x00, 0x00, 0x00, 0x2A]);
    // The device's own exception is forwarded as it came.
    assert_eq!(ask(&mut c, 4, 2, &[0x03, 0x00, 0x63, 0x00, 0x02]).await, [0x83, 0x02]);
    let b = bus.lock();
    assert_eq!(b.registers[&3][0], 0x2A, "unit 20 is unit 3 on the line");
    assert_eq!(b.seen.get(&20), None);
    assert_eq!(gw.stats()[0].units[&20].replies, 1, "counted under the client's unit");
}

#[tokio::test(start_paused = true)]
async fn a_unit_in_no_route_gets_0a_and_nothing_reaches_the_line() {
    let bus = Shared::new(Bus::default());
    let mut routes = Routes::new();
    routes.set(1, Route { line: 0, unit: 1 });
    let gw = gateway(&bus, Setup { routes, ..Setup::default() }).await;
    let mut c = connect(&gw, Box::new(AllowAll));
    assert_eq!(ask(&mut c, 9, 2, &READ_0_2).await, [0x83, 0x0A]);
    assert_eq!(ask(&mut c, 10, 255, &READ_0_2).await, [0x83, 0x0A]);
    assert!(bus.lock().seen.is_empty(), "{:?}", bus.lock().seen);
    assert_eq!(gw.stats()[0].total.requests, 0);
}

#[tokio::test(start_paused = true)]
async fn a_dead_unit_gets_0b_costs_the_line_only_a_probe_now_and_then_and_never_stalls_a_live_one() {
    let bus = Shared::new(Bus { dead: vec![7], ..Bus::default() });
    let gw = gateway(&bus, Setup::default()).await;
    let mut dead = connect(&gw, Box::new(AllowAll));
    let mut live = connect(&gw, Box::new(AllowAll));
    let started = tokio::time::Instant::now();
    for t in 0..40u16 {
        assert_eq!(ask(&mut dead, t, 7, &READ_0_2).await, [0x83, 0x0B], "request {t}");
        assert_eq!(ask(&mut live, t, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0], "request {t}");
    }
    let elapsed = started.elapsed();
    let seen_dead = bus.lock().seen[&7];
    // Three requests of two attempts each before the backoff (after 3), then probes at most
    // once per second: the 40 requests took well under a second of line time after the first
    // three, so at most one probe.
    assert!(
        seen_dead <= 3 * 2 + 1 + u32::try_from(elapsed.as_secs()).unwrap(),
        "{seen_dead} frames to the dead unit in {elapsed:?}"
    );
    let stats = &gw.stats()[0];
    assert_eq!(stats.units[&7].timeouts + stats.units[&7].skipped, 40);
    assert!(stats.units[&7].skipped >= 36, "{}", stats.units[&7]);
    assert_eq!(stats.units[&1].replies, 40);
}

#[tokio::test(start_paused = true)]
async fn replies_with_a_bad_crc_get_0b_and_are_counted_as_crc_errors_not_timeouts() {
    let bus = Shared::new(Bus::default());
    let gw =
        gateway(&bus, Setup { faults: Faults { corrupt: Some(2), ..Faults::default() }, ..Setup::default() }).await;
    let mut c = connect(&gw, Box::new(AllowAll));
    assert_eq!(ask(&mut c, 1, 2, &READ_0_2).await, [0x83, 0x0B]);
    assert_eq!(ask(&mut c, 2, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0]);
    let unit = &gw.stats()[0].units[&2];
    assert_eq!((unit.crc_errors, unit.timeouts), (1, 0), "{unit}");
    assert_eq!(bus.lock().seen[&2], 2, "retried once");
}

#[tokio::test(start_paused = true)]
async fn a_full_queue_answers_06_at_once_and_the_queued_requests_are_served() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup { queue: 1, ..Setup::default() }).await;
    let mut c = connect(&gw, Box::new(AllowAll));
    let mut burst = Vec::new();
    for t in 0..3 {
        burst.extend(mbap(t, 1, &READ_0_2));
    }
    c.write_all(&burst).await.unwrap();
    let replies = [reply(&mut c).await, reply(&mut c).await, reply(&mut c).await];
    assert_eq!(replies[0], (0, 1, vec![0x03, 0x04, 0, 0, 0, 0]));
    assert_eq!(replies[1], (1, 1, vec![0x83, 0x06]));
    assert_eq!(replies[2], (2, 1, vec![0x83, 0x06]));
    assert_eq!(gw.stats()[0].total.busy, 2);
    assert_eq!(bus.lock().seen[&1], 1);
}

#[tokio::test(start_paused = true)]
async fn a_broadcast_reaches_the_line_and_gets_no_reply_unless_acknowledged() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let mut c = connect(&gw, Box::new(AllowAll));
    c.write_all(&mbap(1, 0, &[0x06, 0x00, 0x05, 0x00, 0x09])).await.unwrap();
    // The next reply is the next request's: the broadcast got none.
    assert_eq!(ask(&mut c, 2, 1, &[0x03, 0x00, 0x05, 0x00, 0x01]).await, [0x03, 0x02, 0x00, 0x09]);
    // A read to unit 0 has no device to answer it.
    assert_eq!(ask(&mut c, 3, 0, &READ_0_2).await, [0x83, 0x0A]);
    // The slave engine hands a broadcast to the handler once per unit it serves.
    assert_eq!(bus.lock().broadcasts, 4);

    let acked = gateway(&bus, Setup { broadcast_ack: true, ..Setup::default() }).await;
    let mut c = connect(&acked, Box::new(AllowAll));
    assert_eq!(ask(&mut c, 4, 0, &[0x06, 0x00, 0x05, 0x00, 0x0A]).await, [0x06, 0x00, 0x05, 0x00, 0x0A]);
    assert_eq!(bus.lock().broadcasts, 8);
    assert_eq!(bus.lock().registers[&3][5], 0x0A, "every unit executed it");
}

#[tokio::test(start_paused = true)]
async fn read_only_rules_answer_a_write_with_01_and_nothing_reaches_the_line() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let mut c = connect(&gw, Box::new(Rules::new().read_only(true).units([1])));
    assert_eq!(ask(&mut c, 1, 1, &[0x06, 0x00, 0x01, 0x00, 0x01]).await, [0x86, 0x01]);
    assert_eq!(ask(&mut c, 2, 2, &READ_0_2).await, [0x83, 0x0A]);
    assert_eq!(ask(&mut c, 3, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0]);
    assert_eq!(bus.lock().seen.values().sum::<u32>(), 1);
}

#[tokio::test(start_paused = true)]
async fn the_cache_answers_a_repeated_read_and_a_write_makes_the_next_read_go_to_the_line() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup { cache: Some(Duration::from_secs(1)), ..Setup::default() }).await;
    let mut a = connect(&gw, Box::new(AllowAll));
    let mut b = connect(&gw, Box::new(AllowAll));
    assert_eq!(ask(&mut a, 1, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0]);
    assert_eq!(ask(&mut b, 1, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0]);
    assert_eq!(bus.lock().seen[&1], 1, "the second read came from the cache");
    ask(&mut a, 2, 1, &[0x06, 0x00, 0x01, 0x00, 0x07]).await;
    assert_eq!(ask(&mut b, 2, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 7]);
    assert_eq!(bus.lock().seen[&1], 3);
    assert_eq!(gw.stats()[0].units[&1].cached, 1);
}

#[tokio::test(start_paused = true)]
async fn a_late_reply_is_never_given_to_the_next_request() {
    let bus = Shared::new(Bus::default());
    bus.lock().registers.insert(1, [0x1111; 100]);
    // Unit 1's first reply comes 60 ms late: after the 50 ms timeout (and after the retry
    // has gone out), inside the late-reply guard.
    let faults = Faults { delay_first: Some((1, Duration::from_millis(60))), ..Faults::default() };
    let gw = gateway(&bus, Setup { faults, ..Setup::default() }).await;
    let mut a = connect(&gw, Box::new(AllowAll));
    let mut b = connect(&gw, Box::new(AllowAll));
    a.write_all(&mbap(1, 1, &READ_0_2)).await.unwrap();
    ask(&mut b, 5, 1, &[0x06, 0x00, 0x00, 0x22, 0x22]).await;
    // b's write changed register 0; a's request (retried) either got its own reply or 0x0B,
    // and b's read below sees the value b wrote, never a reply meant for another request.
    let (t, _, first) = reply(&mut a).await;
    assert_eq!(t, 1);
    assert!(first == [0x03, 0x04, 0x11, 0x11, 0x11, 0x11] || first == [0x83, 0x0B], "{first:02X?}");
    assert_eq!(ask(&mut b, 6, 1, &READ_0_2).await, [0x03, 0x04, 0x22, 0x22, 0x11, 0x11]);
}

#[tokio::test(start_paused = true)]
async fn rtu_over_tcp_in_a_framed_request_gets_a_framed_reply_with_its_crc() {
    use ferrobus_proto::crc::{crc_ok, crc16_wire};
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let (mut client, server) = tokio::io::duplex(4096);
    let front = gw.clone();
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        front.serve_connection(server, "rtu client", Inbound::RtuOverTcp, &mut authorize, ConnectionPolicy::TCP).await
    });
    let mut request = vec![0x02, 0x06, 0x00, 0x03, 0x00, 0x2A];
    request.extend(crc16_wire(&request));
    client.write_all(&request).await.unwrap();
    let mut reply = [0u8; 8];
    client.read_exact(&mut reply).await.unwrap();
    assert_eq!(reply, request.as_slice(), "a write's echo, framed");
    assert!(crc_ok(&reply));
    assert_eq!(bus.lock().registers[&2][3], 0x2A);
}

#[tokio::test(start_paused = true)]
async fn invalid_function_codes_and_malformed_pdus_get_01_or_03_at_once_and_never_reach_the_line() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let mut junk = connect(&gw, Box::new(AllowAll));
    let cases: [(&[u8], [u8; 2]); 9] = [
        (&[0x00, 0x00, 0x00, 0x00, 0x01], [0x80, 0x01]),
        (&[0x83, 0x00, 0x00, 0x00, 0x01], [0x83, 0x01]),
        (&[0xFF, 0x00, 0x00, 0x00, 0x01], [0xFF, 0x01]),
        // Reserved by the spec (0x09, 0x5A) and unassigned (0x30): no device's to take.
        (&[0x09, 0x00, 0x00], [0x89, 0x01]),
        (&[0x5A, 0x00], [0xDA, 0x01]),
        (&[0x30], [0xB0, 0x01]),
        // Public codes with their fields missing, a count out of range, a byte count that
        // disagrees.
        (&[0x03, 0x00, 0x00], [0x83, 0x03]),
        (&[0x03, 0x00, 0x00, 0x00, 0x00], [0x83, 0x03]),
        (&[0x10, 0x00, 0x00, 0x00, 0x01, 0x04, 0x00, 0x01], [0x90, 0x03]),
    ];
    let started = tokio::time::Instant::now();
    for (t, (pdu, answer)) in (1..).zip(cases) {
        assert_eq!(ask(&mut junk, t, 1, pdu).await, answer, "{pdu:02X?}");
    }
    assert!(started.elapsed() < Duration::from_millis(1), "answered at once, not after {:?}", started.elapsed());
    assert!(bus.lock().seen.is_empty(), "nothing reached the line: {:?}", bus.lock().seen);
    assert_eq!(gw.stats()[0].total.requests, 0);
    let front = gw.front_stats();
    assert_eq!(
        (front.refused(Malformed::NotARequest), front.refused(Malformed::Reserved), front.total()),
        (3, 3, 9),
        "{front}"
    );
    assert_eq!((front.refused(Malformed::Truncated), front.refused(Malformed::Quantity)), (1, 1), "{front}");
    assert_eq!(front.refused(Malformed::ByteCount), 1, "{front}");
    // The unit is as alive as before, for this client and another.
    let mut other = connect(&gw, Box::new(AllowAll));
    assert_eq!(ask(&mut other, 1, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0]);
    assert_eq!(ask(&mut junk, 99, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0]);
}

#[tokio::test(start_paused = true)]
async fn user_defined_codes_a_device_ignores_never_put_a_live_unit_in_backoff_for_another_client() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let mut odd = connect(&gw, Box::new(AllowAll));
    let mut reader = connect(&gw, Box::new(AllowAll));
    // Five in a row, more than the backoff's three, with nobody else asking meanwhile.
    for t in 0..5u16 {
        assert_eq!(ask(&mut odd, t, 1, &[0x41, 0x01, 0x02]).await, [0xC1, 0x0B], "user code {t}: silence is 0x0B");
    }
    for t in 0..10u16 {
        assert_eq!(ask(&mut reader, t, 1, &READ_0_2).await, [0x03, 0x04, 0, 0, 0, 0], "read {t}");
        assert_eq!(ask(&mut odd, 100 + t, 1, &[0x64]).await, [0xE4, 0x0B]);
    }
    let unit = &gw.stats()[0].units[&1];
    assert_eq!((unit.replies, unit.timeouts, unit.skipped), (10, 15, 0), "{unit}");
    assert_eq!(bus.lock().seen[&1], 10 + 15 * 2, "every user code forwarded, with its retry");
    assert_eq!(gw.front_stats().total(), 0);
}

#[tokio::test(start_paused = true)]
async fn a_client_that_writes_200_requests_at_once_never_has_more_than_its_pipeline_outstanding() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let (mut client, server) = tokio::io::duplex(8192);
    let front = gw.clone();
    let connection = ConnectionPolicy { max_pending: 16, ..ConnectionPolicy::TCP };
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        front.serve_connection(server, "flood", Inbound::Mbap, &mut authorize, connection).await
    });
    let burst: Vec<u8> = (0..200u16).flat_map(|t| mbap(t, 1, &READ_0_2)).collect();
    client.write_all(&burst).await.unwrap();
    for t in 0..200u16 {
        assert_eq!(reply(&mut client).await, (t, 1, vec![0x03, 0x04, 0, 0, 0, 0]), "reply {t}, in order, served");
    }
    let stats = &gw.stats()[0];
    // Sixteen outstanding at most, on the line or in its queue (all sixteen in the queue while
    // the worker is between two requests).
    assert!(stats.queue_max <= 16, "{} requests of one connection queued at once", stats.queue_max);
    assert_eq!((stats.total.replies, stats.total.busy), (200, 0), "{}", stats.total);
}

/// A connection served on `connection`'s policy, and the task serving it.
fn connect_with(
    gateway: &Gateway,
    connection: ConnectionPolicy,
) -> (DuplexStream, tokio::task::JoinHandle<std::io::Result<()>>) {
    let (client, server) = tokio::io::duplex(4096);
    let gateway = gateway.clone();
    let task = tokio::spawn(async move {
        gateway.serve_connection(server, "test client", Inbound::Mbap, &mut AllowAll, connection).await
    });
    (client, task)
}

#[tokio::test(start_paused = true)]
async fn a_bad_mbap_header_closes_the_connection_after_the_request_before_it_is_answered_and_the_write_after_it_never_runs()
 {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let (mut client, task) = connect_with(&gw, ConnectionPolicy::TCP);
    let mut input = mbap(1, 1, &READ_0_2);
    input.extend([0x00, 0x02, 0x00, 0x07, 0x00, 0x06, 0x01]);
    input.extend(mbap(3, 1, &[0x06, 0x00, 0x05, 0x12, 0x34]));
    client.write_all(&input).await.unwrap();
    assert_eq!(reply(&mut client).await, (1, 1, vec![0x03, 0x04, 0, 0, 0, 0]), "the request before the header");
    let err = task.await.unwrap().expect_err("closed");
    assert_eq!(ferrobus::server::close_reason(&err), Some(ferrobus::server::Closed::BadHeader), "{err}");
    let mut rest = Vec::new();
    client.read_to_end(&mut rest).await.unwrap();
    assert!(rest.is_empty(), "answered after the bad header: {rest:02X?}");
    assert_eq!(bus.lock().registers.get(&1).map_or(0, |r| r[5]), 0, "the write behind the header ran");
}

#[tokio::test(start_paused = true)]
async fn an_idle_connection_is_closed_after_the_idle_timeout_but_never_while_a_request_is_outstanding() {
    let bus = Shared::new(Bus { dead: vec![7], ..Bus::default() });
    let gw = gateway(&bus, Setup::default()).await;
    // The dead unit's answer (two attempts of 50 ms) takes longer than the idle timeout.
    let idle = Duration::from_millis(30);
    let (mut client, task) = connect_with(&gw, ConnectionPolicy { idle: Some(idle), ..ConnectionPolicy::TCP });
    let asked = tokio::time::Instant::now();
    assert_eq!(ask(&mut client, 1, 7, &READ_0_2).await, [0x83, 0x0B], "closed while the line was asked");
    let answered = tokio::time::Instant::now();
    assert!(answered - asked > idle, "the answer came within the idle timeout: the test shows nothing");
    let err = task.await.unwrap().expect_err("closed");
    assert_eq!(ferrobus::server::close_reason(&err), Some(ferrobus::server::Closed::Idle(idle)), "{err}");
    let closed = tokio::time::Instant::now() - answered;
    assert!(closed >= idle && closed <= idle + Duration::from_millis(2), "closed {closed:?} after the reply");
}

#[tokio::test(start_paused = true)]
async fn a_frame_begun_and_never_finished_closes_the_connection_after_the_frame_timeout() {
    let bus = Shared::new(Bus::default());
    let gw = gateway(&bus, Setup::default()).await;
    let frame = Duration::from_secs(5);
    let (mut client, server) = tokio::io::duplex(4096);
    let connection = ConnectionPolicy { frame: Some(frame), ..ConnectionPolicy::TCP };
    let front = gw.clone();
    let began = tokio::time::Instant::now();
    let task = tokio::spawn(async move {
        let ended = front.serve_connection(server, "slow", Inbound::Mbap, &mut AllowAll, connection).await;
        (ended, began.elapsed())
    });
    // One byte a second: never idle, the frame never complete.
    for byte in [0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x01] {
        if client.write_all(&[byte]).await.is_err() || task.is_finished() {
            break;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    let (ended, after) = task.await.unwrap();
    let err = ended.expect_err("closed");
    assert_eq!(ferrobus::server::close_reason(&err), Some(ferrobus::server::Closed::UnfinishedFrame(frame)), "{err}");
    assert!(after >= frame && after < frame + Duration::from_secs(1), "closed after {after:?}");
}

#[tokio::test]
async fn a_broadcast_goes_to_the_serial_line_and_not_to_a_modbus_tcp_device_which_would_take_it_as_its_own() {
    let bus = Shared::new(Bus::default());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let device_addr = listener.local_addr().unwrap();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        // The first frame the device hears is the read for unit 100, not the broadcast write.
        let mut head = [0u8; 7];
        device.read_exact(&mut head).await.unwrap();
        let mut pdu = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
        device.read_exact(&mut pdu).await.unwrap();
        let (tid, unit) = (u16::from_be_bytes([head[0], head[1]]), head[6]);
        device.write_all(&mbap(tid, unit, &[0x03, 0x02, 0x00, 0x2A])).await.unwrap();
        (unit, pdu)
    });
    let serial = GatewayLine::new(line(&bus, Faults::default()), client_config());
    let tcp = GatewayLine::new(Transport::tcp(device_addr.to_string()), client_config());
    let mut routes = Routes::all_on(0);
    routes.set(100, Route { line: 1, unit: 1 });
    let config = GatewayConfig { lines: vec![serial, tcp], routes, broadcast_ack: false, cache_max_age: None };
    let gw = Gateway::start(config).await.unwrap();
    let mut c = connect(&gw, Box::new(AllowAll));
    c.write_all(&mbap(1, 0, &[0x06, 0x00, 0x05, 0x00, 0x09])).await.unwrap();
    assert_eq!(
        ask(&mut c, 2, 1, &[0x03, 0x00, 0x05, 0x00, 0x01]).await,
        [0x03, 0x02, 0x00, 0x09],
        "on the serial line"
    );
    assert_eq!(bus.lock().broadcasts, 4);
    assert_eq!(ask(&mut c, 3, 100, &[0x03, 0x00, 0x05, 0x00, 0x01]).await, [0x03, 0x02, 0x00, 0x2A]);
    assert_eq!(device.await.unwrap(), (1, vec![0x03, 0x00, 0x05, 0x00, 0x01]), "the TCP device never got the write");
}
