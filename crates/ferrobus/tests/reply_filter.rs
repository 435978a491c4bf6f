//! The server's reply filter on an in-memory Modbus/TCP stream, on tokio's paused clock: it is
//! told which request each reply answers, may change the reply's length, and a trickled reply
//! leaves one byte at a time, never sooner than its gap.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use ferrobus::server::{Answering, Fate, ReplyFilter, ServerOptions, serve};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::FunctionCode;
use ferrobus_proto::frame::mbap::MbapCodec;
use ferrobus_proto::frame::{LineConfig, LineTiming};
use ferrobus_proto::pdu::AddressRange;
use ferrobus_proto::slave::{Handler, Slave, SlaveConfig, UnitSet};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

/// Every holding register reads as its address.
struct Addresses;

impl Handler for Addresses {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        for (value, address) in out.iter_mut().zip(start..) {
            *value = address;
        }
        Ok(())
    }
}

/// Records what each reply answers, then does what it was made to.
struct Recorder {
    seen: Arc<Mutex<Vec<Option<Answering>>>>,
    fate: Fate,
    keep: Option<usize>,
}

impl ReplyFilter for Recorder {
    fn filter(&mut self, answering: Option<&Answering>, frame: &mut Vec<u8>) -> Fate {
        self.seen.lock().unwrap().push(answering.copied());
        if let Some(keep) = self.keep {
            frame.truncate(keep);
        }
        self.fate
    }
}

/// Serves `Addresses` at unit 1 through a `Recorder`, sends `request`, and returns each byte
/// that came back within a second with when it came, and what the filter saw.
async fn exchange(request: &[u8], fate: Fate, keep: Option<usize>) -> (Vec<(u8, Instant)>, Vec<Option<Answering>>) {
    let (server_end, mut client_end) = tokio::io::duplex(4096);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let config = SlaveConfig { units: UnitSet::single(1), response_wait: Duration::ZERO };
    let timing = LineTiming::new(&LineConfig::default());
    let mut options = ServerOptions::new(timing, ferrobus::Timer::Tokio);
    options.filter = Some(Box::new(Recorder { seen: Arc::clone(&seen), fate, keep }));
    let server = tokio::spawn(async move {
        let mut handler = Addresses;
        serve(Slave::new(MbapCodec::new(), config), Box::new(server_end), &mut handler, &mut options).await.1
    });
    client_end.write_all(request).await.unwrap();
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(1);
    let mut byte = [0u8; 1];
    while let Ok(Ok(1)) = tokio::time::timeout_at(deadline, client_end.read(&mut byte)).await {
        got.push((byte[0], Instant::now()));
    }
    server.abort();
    let seen = seen.lock().unwrap().clone();
    (got, seen)
}

/// Transaction 0x0102, unit 1, 03: two holding registers from 0x0010.
const READ: [u8; 12] = [0x01, 0x02, 0x00, 0x00, 0x00, 0x06, 0x01, 0x03, 0x00, 0x10, 0x00, 0x02];
/// Its reply: 0x0010 and 0x0011.
const REPLY: [u8; 13] = [0x01, 0x02, 0x00, 0x00, 0x00, 0x07, 0x01, 0x03, 0x04, 0x00, 0x10, 0x00, 0x11];

#[tokio::test(start_paused = true)]
async fn the_filter_is_told_the_unit_function_and_addresses_its_reply_answers() {
    let (got, seen) = exchange(&READ, Fate::Send, None).await;
    assert_eq!(got.iter().map(|(b, _)| *b).collect::<Vec<_>>(), REPLY);
    let expected = Answering {
        unit: 1,
        function: FunctionCode::ReadHoldingRegisters,
        addresses: [AddressRange::new(0x10, 0x11), None],
    };
    assert_eq!(seen, [Some(expected)]);
}

#[tokio::test(start_paused = true)]
async fn a_filter_may_shorten_the_reply() {
    let (got, _) = exchange(&READ, Fate::Send, Some(5)).await;
    assert_eq!(got.iter().map(|(b, _)| *b).collect::<Vec<_>>(), REPLY[..5]);
}

#[tokio::test(start_paused = true)]
async fn a_trickled_reply_leaves_byte_by_byte_never_sooner_than_its_gap() {
    let gap = Duration::from_millis(10);
    let (got, _) = exchange(&READ, Fate::Trickle { gap }, None).await;
    assert_eq!(got.iter().map(|(b, _)| *b).collect::<Vec<_>>(), REPLY);
    for pair in got.windows(2) {
        let apart = pair[1].1 - pair[0].1;
        assert!(apart >= gap, "two bytes {apart:?} apart, under the gap of {gap:?}: {got:?}");
    }
}
