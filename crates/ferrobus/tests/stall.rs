//! A Modbus/TCP device connection that stalls is made again: a device written here sends half
//! a reply on its first connection (or nothing at all) and then stays silent on it, but serves
//! every later connection ([`support::stalling`]). The client, one request at a time and
//! pipelined, gets right answers again after the timeout(s), not timeouts for as long as the
//! device keeps the dead connection open. (The gateway in front of it is the tools crate's
//! `tcp_line` test.)

use std::time::Duration;

use ferrobus::{Client, ClientConfig, Error, STALLED_AFTER_TIMEOUTS, Transport};

mod support;

use support::stalling::{First, stalling as device};

fn config(in_flight: usize) -> ClientConfig {
    ClientConfig {
        in_flight,
        timeout: Duration::from_millis(200),
        retries: 0,
        backoff: None,
        ..ClientConfig::default()
    }
}

#[tokio::test]
async fn after_half_a_reply_and_silence_the_next_request_goes_on_a_new_connection_and_is_answered() {
    for in_flight in [1, 4] {
        let addr = device(First::HalfReply).await;
        let client = Client::connect(Transport::tcp(addr.to_string()), config(in_flight)).await.unwrap();
        let first = client.read_holding_registers(1, 0, 1).await;
        assert!(matches!(first, Err(Error::Timeout { .. })), "in flight {in_flight}: {first:?}");
        for _ in 0..3 {
            assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [42], "in flight {in_flight}");
        }
        let stats = client.stats();
        assert_eq!((stats.stalled, stats.connects, stats.disconnects), (1, 2, 0), "in flight {in_flight}: {stats:?}");
    }
}

#[tokio::test]
async fn after_timeouts_in_a_row_without_a_reply_the_connection_is_made_again() {
    for in_flight in [1, 4] {
        let addr = device(First::Silent).await;
        let client = Client::connect(Transport::tcp(addr.to_string()), config(in_flight)).await.unwrap();
        for i in 0..STALLED_AFTER_TIMEOUTS {
            let result = client.read_holding_registers(1, 0, 1).await;
            assert!(matches!(result, Err(Error::Timeout { .. })), "in flight {in_flight}, request {i}: {result:?}");
            // Not made again before the last of them.
            let expected = u64::from(i + 1 == STALLED_AFTER_TIMEOUTS);
            assert_eq!(client.stats().stalled, expected, "in flight {in_flight}, request {i}");
        }
        assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [42], "in flight {in_flight}");
        let stats = client.stats();
        assert_eq!((stats.stalled, stats.connects), (1, 2), "in flight {in_flight}: {stats:?}");
    }
}

#[tokio::test]
async fn a_retry_after_half_a_reply_goes_on_the_new_connection_and_the_caller_gets_the_answer() {
    let addr = device(First::HalfReply).await;
    let config = ClientConfig { retries: 1, ..config(1) };
    let client = Client::connect(Transport::tcp(addr.to_string()), config).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [42]);
    assert_eq!(client.stats().stalled, 1);
}
