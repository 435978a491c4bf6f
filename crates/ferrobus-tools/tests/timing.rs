//! The one reply timing of every role on the pump, on paused time: the plain server, the
//! reverse gateway and the gateway front answer an RTU request no earlier than t3.5 after its
//! last byte (the slave engine's rule, not one of their own), and the reverse gateway keeps
//! reading the line while a TCP answer is awaited.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ferrobus::port::{BoxPort, ConnectWith, Framing};
use ferrobus::server::{Answering, ConnectionPolicy, Fate, ReplyFilter, ServerOptions, serve};
use ferrobus::{Client, ClientConfig, Timer, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::crc::crc16_wire;
use ferrobus_proto::frame::mbap::MbapCodec;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming};
use ferrobus_proto::slave::{Handler, Slave, SlaveConfig};
use ferrobus_tools::gateway::{
    AllowAll, Gateway, GatewayConfig, GatewayLine, Inbound, OnFailure, Routes, Upstream, serve_reverse,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::time::Instant;

/// Holding register `i` holds `i`; every request is counted.
#[derive(Clone, Default)]
struct Device {
    requests: Arc<Mutex<u32>>,
}

impl Handler for Device {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        *self.requests.lock().unwrap() += 1;
        for (i, r) in out.iter_mut().enumerate() {
            *r = start + u16::try_from(i).unwrap();
        }
        Ok(())
    }
}

fn timing() -> LineTiming {
    LineTiming::new(&LineConfig::new(9600).unwrap())
}

fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = vec![unit];
    frame.extend_from_slice(pdu);
    frame.extend_from_slice(&crc16_wire(&frame));
    frame
}

const READ: [u8; 5] = [0x03, 0x00, 0x04, 0x00, 0x01];

fn read_reply(unit: u8) -> Vec<u8> {
    rtu(unit, &[0x03, 0x02, 0x00, 0x04])
}

/// Delays every reply by its duration (none: sent at once).
struct Delay(Duration);

impl ReplyFilter for Delay {
    fn filter(&mut self, _: Option<&Answering>, _: &mut Vec<u8>) -> Fate {
        if self.0.is_zero() { Fate::Send } else { Fate::Delay(self.0) }
    }
}

/// A client of a Modbus/TCP server (in memory) serving `device` as unit 1, its replies delayed
/// by `delay`.
fn tcp_upstream(device: &Device, delay: Duration) -> Client {
    let device = device.clone();
    let connector = ConnectWith::new("test server", move || {
        let (ours, theirs) = tokio::io::duplex(4096);
        let mut device = device.clone();
        tokio::spawn(async move {
            let mut options = ServerOptions::new(timing(), Timer::Tokio);
            options.filter = Some(Box::new(Delay(delay)));
            let slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
            let _ = serve(slave, Box::new(theirs) as BoxPort, &mut device, &mut options).await;
        });
        Box::pin(async move { Ok(Box::new(ours) as BoxPort) })
    });
    let transport = Transport::custom(Framing::Mbap, timing(), connector).with_timer(Timer::Tokio);
    Client::spawn(transport, ClientConfig { timeout: Duration::from_secs(1), retries: 0, ..ClientConfig::default() })
}

/// A serial line to the reverse gateway, unit 5 standing for unit 1 of a TCP server.
fn reverse(device: &Device, delay: Duration) -> DuplexStream {
    let (master, line) = tokio::io::duplex(4096);
    let upstreams = BTreeMap::from([(5, Upstream { client: tcp_upstream(device, delay), unit: 1 })]);
    tokio::spawn(async move {
        let transport = Transport::custom(
            Framing::Rtu,
            timing(),
            ConnectWith::new("unused", || {
                Box::pin(async { Err::<BoxPort, _>(std::io::Error::other("the line is given")) })
            }),
        )
        .with_timer(Timer::Tokio);
        serve_reverse(&transport, Box::new(line), &upstreams, OnFailure::Silent).await
    });
    master
}

/// A serial line to the plain server, serving `device` as unit 5.
fn plain(device: &Device) -> DuplexStream {
    let (master, line) = tokio::io::duplex(4096);
    let mut device = device.clone();
    tokio::spawn(async move {
        let slave = Slave::new(RtuCodec::new(timing(), Expect::Requests), SlaveConfig::unit(5));
        serve(slave, Box::new(line), &mut device, &mut ServerOptions::new(timing(), Timer::Tokio)).await.1
    });
    master
}

/// Sends `request` and returns the reply with how long after the request's last byte it came.
async fn exchange(line: &mut DuplexStream, request: &[u8], reply_len: usize) -> (Vec<u8>, Duration) {
    line.write_all(request).await.unwrap();
    let sent = Instant::now();
    let mut reply = vec![0u8; reply_len];
    line.read_exact(&mut reply).await.unwrap();
    (reply, sent.elapsed())
}

#[tokio::test(start_paused = true)]
async fn the_plain_server_and_the_reverse_gateway_answer_no_earlier_than_t3_5_after_the_request() {
    let t3_5 = timing().t3_5();
    let device = Device::default();
    for (role, mut line) in
        [("the plain server", plain(&device)), ("the reverse gateway", reverse(&device, Duration::ZERO))]
    {
        let (reply, after) = exchange(&mut line, &rtu(5, &READ), 7).await;
        assert_eq!(reply, read_reply(5), "{role}'s reply");
        // tokio's timer has millisecond steps: never early is the rule, at most one step late.
        assert!(after >= t3_5, "{role} answered {after:?} after the request, before t3.5 ({t3_5:?})");
        assert!(after <= t3_5 + Duration::from_millis(1), "{role} answered {after:?} after the request");
    }
    assert_eq!(*device.requests.lock().unwrap(), 2);
}

#[tokio::test(start_paused = true)]
async fn the_reverse_gateway_reads_the_line_while_it_awaits_the_tcp_answer_and_a_master_that_does_not_wait_gets_nothing()
 {
    let device = Device::default();
    let mut line = reverse(&device, Duration::from_millis(100));
    line.write_all(&rtu(5, &READ)).await.unwrap();
    let first = Instant::now();
    // 20 ms later, with the first answer still on its way: a second request.
    tokio::time::sleep(Duration::from_millis(20)).await;
    line.write_all(&rtu(5, &[0x03, 0x00, 0x09, 0x00, 0x01])).await.unwrap();
    let mut reply = [0u8; 7];
    line.read_exact(&mut reply).await.unwrap();
    assert_eq!(reply.as_slice(), read_reply(5).as_slice(), "the first request's reply");
    assert!(first.elapsed() >= Duration::from_millis(100), "answered before the TCP side did");
    // The second was read while the first was forwarded, and refused by the one-at-a-time
    // rule: it is never answered, nor forwarded.
    let mut more = [0u8; 1];
    let late = tokio::time::timeout(Duration::from_secs(2), line.read(&mut more)).await;
    assert!(late.is_err(), "the request sent while one was forwarded got a reply");
    assert_eq!(*device.requests.lock().unwrap(), 1, "the second request was forwarded");
}

/// A gateway whose one line is an in-memory stream to the plain server of `device` (unit 5),
/// with a read cache.
async fn gateway(device: &Device) -> Gateway {
    let device = device.clone();
    let connector = ConnectWith::new("test line", move || {
        let (ours, theirs) = tokio::io::duplex(4096);
        let mut device = device.clone();
        tokio::spawn(async move {
            let slave = Slave::new(RtuCodec::new(timing(), Expect::Requests), SlaveConfig::unit(5));
            let options = &mut ServerOptions::new(timing(), Timer::Tokio);
            let _ = serve(slave, Box::new(theirs) as BoxPort, &mut device, options).await;
        });
        Box::pin(async move { Ok(Box::new(ours) as BoxPort) })
    });
    let line = Transport::custom(Framing::Rtu, timing(), connector).with_timer(Timer::Tokio);
    let client = ClientConfig { timeout: Duration::from_secs(1), retries: 0, ..ClientConfig::default() };
    let config = GatewayConfig {
        lines: vec![GatewayLine::new(line, client)],
        routes: Routes::all_on(0),
        broadcast_ack: false,
        cache_max_age: Some(Duration::from_secs(60)),
    };
    Gateway::start(config).await.unwrap()
}

#[tokio::test(start_paused = true)]
async fn the_gateway_front_answers_rtu_over_tcp_no_earlier_than_t3_5_even_from_its_cache() {
    let device = Device::default();
    let gw = gateway(&device).await;
    let (mut client, server) = tokio::io::duplex(4096);
    tokio::spawn(async move {
        gw.serve_connection(server, "rtu client", Inbound::RtuOverTcp, &mut AllowAll, ConnectionPolicy::TCP).await
    });
    let t3_5 = *Transport::rtu_over_tcp("the gateway's clients").timing();
    let t3_5 = t3_5.t3_5();
    let (first, _) = exchange(&mut client, &rtu(5, &READ), 7).await;
    assert_eq!(first, read_reply(5), "the line's reply");
    // The same read again: the cache has it, and the engine still holds it for t3.5.
    let (cached, after) = exchange(&mut client, &rtu(5, &READ), 7).await;
    assert_eq!(cached, read_reply(5), "the cached reply");
    assert_eq!(*device.requests.lock().unwrap(), 1, "the second read reached the line");
    assert!(after >= t3_5, "the cached reply went out {after:?} after the request, before t3.5 ({t3_5:?})");
    assert!(after <= t3_5 + Duration::from_millis(1), "the cached reply went out {after:?} after the request");
}
