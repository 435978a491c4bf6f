//! Several requests in flight on one Modbus/TCP connection (`ClientConfig::in_flight`): the
//! client's pipelined driver against a device that holds requests back and answers them out
//! of order ([`support::pipelined`]). Each caller gets the reply to its own request, a timeout
//! ends only its own, a late reply goes to nobody, and a connection lost under the requests in
//! flight sends those with retries again. (The gateway's pipelined line is the tools crate's
//! `tcp_line` test.)

use std::time::Duration;

use ferrobus::{Client, Error, Transport};
use tokio::net::TcpListener;

mod support;

use support::pipelined::{Asked, answer, asked, hold_and_answer_backwards, pipelined, value};

#[tokio::test]
async fn requests_go_out_without_waiting_for_replies_and_each_caller_gets_the_reply_to_its_own() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        // 12 requests, 4 at a time: the device hears 4 before it has answered any.
        let mut seen = Vec::new();
        for _ in 0..3 {
            seen.extend(hold_and_answer_backwards(&mut device, 4).await);
        }
        seen
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(4, Duration::from_secs(10), 0)).await.unwrap();
    let reads: Vec<_> = (0..12u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { (r, client.read_holding_registers(1, 100 + r, 1).await) })
        })
        .collect();
    for read in reads {
        let (r, result) = read.await.unwrap();
        assert_eq!(result.unwrap(), [value(100 + r)], "register {}", 100 + r);
    }
    let seen = device.await.unwrap();
    assert_eq!(seen.len(), 12);
    let stats = client.stats().master;
    assert_eq!((stats.requests, stats.responses, stats.timeouts, stats.ignored_frames), (12, 12, 0, 0), "{stats:?}");
}

#[tokio::test]
async fn a_timeout_ends_only_its_own_request_and_its_late_reply_is_handed_to_nobody() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let (timed_out, timed_out_rx) = tokio::sync::oneshot::channel::<()>();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        let mut three = Vec::new();
        for _ in 0..3 {
            three.push(asked(&mut device).await);
        }
        // Register 1's request is answered only after the client gave up on it; the two
        // others at once.
        let (slow, rest): (Vec<Asked>, Vec<Asked>) = three.into_iter().partition(|a| a.register == 1);
        for a in rest {
            answer(&mut device, a).await;
        }
        timed_out_rx.await.unwrap();
        // The late reply comes just before the answer to the next request: only the next
        // request's own reply may end it.
        let next = asked(&mut device).await;
        answer(&mut device, slow[0]).await;
        answer(&mut device, next).await;
        device
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(3, Duration::from_millis(300), 0)).await.unwrap();
    let reads: Vec<_> = (1..=3u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { (r, client.read_holding_registers(1, r, 1).await) })
        })
        .collect();
    for read in reads {
        match read.await.unwrap() {
            (1, Err(Error::Timeout { heard: None, attempts: 1, .. })) => {}
            (1, other) => panic!("register 1 was never answered in time: {other:?}"),
            (r, result) => assert_eq!(result.unwrap(), [value(r)], "register {r}"),
        }
    }
    timed_out.send(()).unwrap();
    assert_eq!(client.read_holding_registers(1, 9, 1).await.unwrap(), [value(9)], "its own reply, not the late one");
    let _device = device.await.unwrap();
    let stats = client.stats().master;
    assert_eq!((stats.responses, stats.timeouts, stats.late_replies), (3, 1, 1), "{stats:?}");
}

#[tokio::test]
async fn a_connection_lost_under_requests_in_flight_sends_those_with_retries_again_and_fails_the_others() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let device = tokio::spawn(async move {
        // Hears 4 requests and drops the connection without a word; then serves the next.
        let (mut first, _) = listener.accept().await.unwrap();
        let mut lost = Vec::new();
        for _ in 0..4 {
            lost.push(asked(&mut first).await.register);
        }
        drop(first);
        let (mut second, _) = listener.accept().await.unwrap();
        let again = hold_and_answer_backwards(&mut second, 4).await;
        let mut again: Vec<u16> = again.iter().map(|a| a.register).collect();
        lost.sort_unstable();
        again.sort_unstable();
        assert_eq!(lost, again, "the same requests, sent again");
        second
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(4, Duration::from_secs(10), 1)).await.unwrap();
    let reads: Vec<_> = (0..4u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { (r, client.read_holding_registers(1, r, 1).await) })
        })
        .collect();
    for read in reads {
        let (r, result) = read.await.unwrap();
        assert_eq!(result.unwrap(), [value(r)], "register {r}, on the second connection");
    }
    let _device = device.await.unwrap();
    let stats = client.stats();
    assert_eq!((stats.connects, stats.disconnects), (2, 1), "{stats:?}");

    // Without retries, a loss fails every request in flight with the IO error.
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        for _ in 0..3 {
            asked(&mut device).await;
        }
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(4, Duration::from_secs(10), 0)).await.unwrap();
    let reads: Vec<_> = (0..3u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { client.read_holding_registers(1, r, 1).await })
        })
        .collect();
    device.await.unwrap();
    for read in reads {
        let result = read.await.unwrap();
        assert!(matches!(result, Err(Error::Io { .. })), "{result:?}");
    }
}
