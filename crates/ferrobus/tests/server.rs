//! The server driver over Modbus/TCP framing, with paused time: connections closed when idle,
//! on an unfinished frame and on a bad MBAP header, and pipelined requests answered in order
//! to a client that reads nothing until it has written them all; every request one call of the
//! service, an owned or a shared handler, and the authorization filter before it.

use std::time::Duration;

use ferrobus::Timer;
use ferrobus::server::{
    Answering, Closed, ConnectionPolicy, Fate, ReplyFilter, ServerOptions, Service, Shared, close_reason, serve,
};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::mbap::MbapCodec;
use ferrobus_proto::frame::{Framing, LineConfig, LineTiming};
use ferrobus_proto::slave::{Handler, RequestId, Slave, SlaveConfig};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::time::Instant;

/// 100 holding registers, counting the writes.
struct Device {
    registers: [u16; 100],
    writes: u32,
}

impl Handler for Device {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        let start = usize::from(start);
        let from = self.registers.get(start..start + out.len()).ok_or(ExceptionCode::IllegalDataAddress)?;
        out.copy_from_slice(from);
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        *self.registers.get_mut(usize::from(address)).ok_or(ExceptionCode::IllegalDataAddress)? = value;
        self.writes += 1;
        Ok(())
    }
}

fn mbap(t: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = t.to_be_bytes().to_vec();
    frame.extend_from_slice(&[0, 0]);
    frame.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    frame.push(unit);
    frame.extend_from_slice(pdu);
    frame
}

fn options(idle: Option<Duration>, frame: Option<Duration>) -> ServerOptions {
    let mut options = ServerOptions::new(LineTiming::new(&LineConfig::new(19_200).unwrap()), Timer::Tokio);
    options.connection = Some(ConnectionPolicy { idle, frame, ..ConnectionPolicy::NONE });
    options
}

/// Serves one connection of `buffer` bytes each way; returns the client's end and the server.
fn start(
    buffer: usize,
    mut options: ServerOptions,
) -> (DuplexStream, tokio::task::JoinHandle<(std::io::Result<()>, Device, Duration)>) {
    let (client, server_end) = tokio::io::duplex(buffer);
    let server = tokio::spawn(async move {
        let mut device = Device { registers: [0; 100], writes: 0 };
        let slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
        let began = Instant::now();
        let (_, ended) = serve(slave, Box::new(server_end), &mut device, &mut options).await;
        (ended, device, began.elapsed())
    });
    (client, server)
}

#[tokio::test(start_paused = true)]
async fn an_idle_connection_is_closed_after_the_idle_timeout_and_not_before() {
    let (_client, server) = start(1024, options(Some(Duration::from_secs(60)), Some(Duration::from_secs(5))));
    let (ended, _, after) = server.await.unwrap();
    let err = ended.expect_err("closed");
    assert_eq!(close_reason(&err), Some(Closed::Idle(Duration::from_secs(60))), "{err}");
    assert!(after >= Duration::from_secs(60) && after < Duration::from_secs(61), "closed after {after:?}");
}

#[tokio::test(start_paused = true)]
async fn a_frame_begun_and_never_finished_is_closed_after_the_frame_timeout() {
    let (mut client, server) = start(1024, options(Some(Duration::from_secs(60)), Some(Duration::from_secs(5))));
    // One byte a second: never idle, the frame never complete.
    for byte in [0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x01] {
        if client.write_all(&[byte]).await.is_err() {
            break;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    let (ended, _, after) = server.await.unwrap();
    let err = ended.expect_err("closed");
    assert_eq!(close_reason(&err), Some(Closed::UnfinishedFrame(Duration::from_secs(5))), "{err}");
    assert!(after >= Duration::from_secs(5) && after < Duration::from_secs(6), "closed after {after:?}");
}

#[tokio::test(start_paused = true)]
async fn a_bad_mbap_header_closes_the_connection_and_the_write_behind_it_is_not_executed() {
    let (mut client, server) = start(1024, options(None, None));
    let mut input = vec![0x00, 0x31, 0x00, 0x00, 0xFF, 0xFF, 0x01];
    input.extend(mbap(0x0032, 1, &[0x06, 0x00, 0x05, 0x12, 0x34]));
    client.write_all(&input).await.unwrap();
    let (ended, device, _) = server.await.unwrap();
    let err = ended.expect_err("closed");
    assert_eq!(close_reason(&err), Some(Closed::BadHeader), "{err}");
    assert_eq!((device.writes, device.registers[5]), (0, 0), "nothing executed");
    let mut rest = Vec::new();
    client.read_to_end(&mut rest).await.unwrap();
    assert!(rest.is_empty(), "nothing answered: {rest:02X?}");
}

/// Transaction `t` writes 0x4000 + t to register `t`; its reply is its echo.
fn write_request(t: u16) -> Vec<u8> {
    let [hi, lo] = (0x4000 + t).to_be_bytes();
    mbap(t, 1, &[0x06, 0x00, u8::try_from(t).unwrap(), hi, lo])
}

#[tokio::test(start_paused = true)]
async fn a_hundred_pipelined_requests_to_a_client_that_reads_late_are_all_answered_in_order() {
    // A 64-byte pipe: the server's replies fill it long before the client reads.
    let (client, server) = start(64, options(None, None));
    let (mut rd, mut wr) = tokio::io::split(client);
    let writer = tokio::spawn(async move {
        for t in 0..100u16 {
            wr.write_all(&write_request(t)).await.unwrap();
        }
        wr
    });
    // Held back by the full pipe, the writer cannot finish until replies are read.
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert!(!writer.is_finished(), "the server stopped reading while its replies were not read");
    let mut reply = [0u8; 12];
    for t in 0..100u16 {
        rd.read_exact(&mut reply).await.unwrap();
        assert_eq!(reply.as_slice(), write_request(t).as_slice(), "reply {t}: the echo of request {t}");
    }
    drop(writer.await.unwrap());
    drop(rd);
    let (ended, device, _) = server.await.unwrap();
    assert!(ended.is_ok(), "{ended:?}");
    assert_eq!(device.writes, 100);
}

/// Delays the first reply by 100 ms, sends the others at once.
struct DelayFirst(bool);

impl ReplyFilter for DelayFirst {
    fn filter(&mut self, _answering: Option<&Answering>, _frame: &mut Vec<u8>) -> Fate {
        if std::mem::replace(&mut self.0, true) { Fate::Send } else { Fate::Delay(Duration::from_millis(100)) }
    }
}

#[tokio::test(start_paused = true)]
async fn replies_behind_a_delayed_one_wait_for_it_and_none_is_lost() {
    let mut options = options(None, None);
    options.filter = Some(Box::new(DelayFirst(false)));
    let (mut client, _server) = start(1024, options);
    let burst: Vec<u8> = (0..3).flat_map(write_request).collect();
    client.write_all(&burst).await.unwrap();
    let began = Instant::now();
    let mut reply = [0u8; 12];
    for t in 0..3u16 {
        client.read_exact(&mut reply).await.unwrap();
        assert_eq!(reply.as_slice(), write_request(t).as_slice(), "reply {t} in order");
        assert!(began.elapsed() >= Duration::from_millis(100), "reply {t} before the delayed first one");
    }
}

#[tokio::test]
async fn a_connections_future_holds_the_engine_by_pointer_not_inline() {
    // What a TCP server's task keeps per connection: the engine (its reply queue is most of
    // it) once on the heap, not copied into the future as the argument and again as the
    // engine. The bound is the engine's own size: the future holds less than one engine.
    let (_client, server_end) = tokio::io::duplex(64);
    let mut device = Device { registers: [0; 100], writes: 0 };
    let mut options = options(None, None);
    let slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    let engine = std::mem::size_of_val(&slave);
    let future = serve(slave, Box::new(server_end), &mut device, &mut options);
    assert!(
        std::mem::size_of_val(&future) < engine / 2,
        "{} bytes of future, {engine} of engine",
        std::mem::size_of_val(&future)
    );
}

/// Answers through `device`, counting its calls: one per request handed out.
struct Counting {
    device: Device,
    calls: u32,
}

impl Service for Counting {
    fn answer<F: Framing>(&mut self, slave: &mut Slave<F>, id: RequestId) {
        self.calls += 1;
        slave.answer_with(id, &mut self.device).unwrap();
    }
}

#[tokio::test(start_paused = true)]
async fn every_request_is_one_call_of_the_service_and_the_replies_keep_request_order() {
    let (mut client, server_end) = tokio::io::duplex(4096);
    let server = tokio::spawn(async move {
        let mut service = Counting { device: Device { registers: [0; 100], writes: 0 }, calls: 0 };
        let slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
        let (_, ended) = serve(slave, Box::new(server_end), &mut service, &mut options(None, None)).await;
        (ended, service)
    });
    let input: Vec<u8> = (0..20u16).flat_map(write_request).collect();
    client.write_all(&input).await.unwrap();
    let mut reply = [0u8; 12];
    for t in 0..20u16 {
        client.read_exact(&mut reply).await.unwrap();
        assert_eq!(reply.as_slice(), write_request(t).as_slice(), "reply {t}");
    }
    drop(client);
    let (ended, service) = server.await.unwrap();
    assert!(ended.is_ok(), "{ended:?}");
    assert_eq!((service.calls, service.device.writes), (20, 20), "one call per request, no more");
}

#[tokio::test(start_paused = true)]
async fn a_shared_handler_serves_through_the_same_session_as_an_owned_one() {
    let (mut client, server_end) = tokio::io::duplex(1024);
    let shared = Shared::new(Device { registers: [7; 100], writes: 0 });
    let mut handler = shared.clone();
    let server = tokio::spawn(async move {
        let slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
        serve(slave, Box::new(server_end), &mut handler, &mut options(None, None)).await.1
    });
    client.write_all(&write_request(3)).await.unwrap();
    client.write_all(&mbap(9, 1, &[0x03, 0x00, 0x03, 0x00, 0x02])).await.unwrap();
    let mut reply = [0u8; 12];
    client.read_exact(&mut reply).await.unwrap();
    assert_eq!(reply.as_slice(), write_request(3).as_slice());
    let mut read = [0u8; 13];
    client.read_exact(&mut read).await.unwrap();
    assert_eq!(read.as_slice(), mbap(9, 1, &[0x03, 0x04, 0x40, 0x03, 0x00, 0x07]).as_slice());
    drop(client);
    assert!(server.await.unwrap().is_ok());
    assert_eq!(shared.lock().writes, 1);
}

#[tokio::test(start_paused = true)]
async fn the_authorize_filter_answers_a_refused_request_itself_and_the_handler_never_sees_it() {
    let mut options = options(None, None);
    // Writes refused with exception 01, reads through.
    options.authorize =
        Some(Box::new(
            |_unit: u8, pdu: &[u8]| {
                if pdu.first() == Some(&0x06) { Err(ExceptionCode::IllegalFunction) } else { Ok(()) }
            },
        ));
    let (mut client, server) = start(1024, options);
    client.write_all(&write_request(4)).await.unwrap();
    let mut refused = [0u8; 9];
    client.read_exact(&mut refused).await.unwrap();
    assert_eq!(refused.as_slice(), mbap(4, 1, &[0x86, 0x01]).as_slice());
    client.write_all(&mbap(5, 1, &[0x03, 0x00, 0x04, 0x00, 0x01])).await.unwrap();
    let mut read = [0u8; 11];
    client.read_exact(&mut read).await.unwrap();
    assert_eq!(read.as_slice(), mbap(5, 1, &[0x03, 0x02, 0x00, 0x00]).as_slice(), "the read was not served");
    drop(client);
    let (ended, device, _) = server.await.unwrap();
    assert!(ended.is_ok(), "{ended:?}");
    assert_eq!((device.writes, device.registers[4]), (0, 0), "a refused write reached the handler");
}
