//! The Modbus/TCP server with its cap filled from many addresses (all of 127/8 is loopback,
//! and a client bound to 127.0.0.N is another host as far as the per-source limit goes): a
//! new client is served, the connection least worth keeping closed to make room (one never
//! answered, then the one idle longest, from the source holding the most first), and a
//! client that polls keeps its session. (The gateway's front end, which shares the accept
//! loop, is the tools crate's `tcp_line` test.)

mod support;

use support::sources::{MAX, PER_SOURCE, closed, connect_from, polled, server, until};

#[tokio::test]
async fn with_the_cap_filled_by_idle_connections_from_eleven_addresses_a_new_client_is_served_and_a_poller_kept() {
    let (server, stats) = server().await;
    // An operator, answered once.
    let mut operator = connect_from(200, server).await;
    assert!(polled(&mut operator, 1).await);
    // 11 addresses, 2 connections each (their share), that never send a request: 22 against
    // the 19 slots left.
    let mut flood = Vec::new();
    for host in 10..21 {
        for _ in 0..PER_SOURCE {
            flood.push(connect_from(host, server).await);
        }
    }
    let counts = until(&stats, |c| c.accepted == 23).await;
    assert_eq!((counts.refused, counts.refused_source, counts.evicted_unanswered), (0, 0, 3), "{counts:?}");
    // The three closed to make room were never answered, the oldest of a source holding two
    // each time: the first of 127.0.0.10, of .11 and of .12 (flood[0], [2], [4]).
    for i in [0, 2, 4] {
        assert!(closed(&mut flood[i]).await, "flood[{i}]");
    }
    // A new client gets in, and so does the operator's next poll; the first of .13 made room.
    let mut newcomer = connect_from(100, server).await;
    assert!(polled(&mut newcomer, 1).await);
    assert!(polled(&mut operator, 2).await);
    assert!(closed(&mut flood[6]).await);
    let counts = until(&stats, |c| c.open == MAX as u64).await;
    assert_eq!((counts.evicted_unanswered, counts.evicted_idle, counts.refused), (4, 0, 0), "{counts:?}");

    // Now every flooding connection left is answered once, in order, and stays idle: each
    // next newcomer closes the one idle longest of a source holding two (the first of .14,
    // then of .15, ...), never the operator, who polls.
    for i in [1, 3, 5].into_iter().chain(7..flood.len()) {
        assert!(polled(&mut flood[i], u16::try_from(i).unwrap()).await, "flood[{i}]");
    }
    let mut lates = Vec::new();
    for (i, host) in (101..108).enumerate() {
        assert!(polled(&mut operator, 10 + u16::try_from(i).unwrap()).await);
        let mut late = connect_from(host, server).await;
        assert!(polled(&mut late, 1).await, "newcomer {i}");
        lates.push(late);
        assert!(closed(&mut flood[8 + 2 * i]).await, "the one idle longest, newcomer {i}");
    }
    assert!(polled(&mut operator, 99).await);
    assert!(polled(&mut newcomer, 2).await);
    let counts = until(&stats, |c| c.open == MAX as u64).await;
    assert_eq!((counts.evicted_unanswered, counts.evicted_idle, counts.refused), (4, 7, 0), "{counts:?}");
}

#[tokio::test]
async fn a_source_holding_many_loses_one_before_a_source_holding_one() {
    let (server, stats) = server().await;
    // 10 sources hold one idle, answered connection each, opened first; then 5 sources fill
    // the rest with two each, also answered.
    let mut single = Vec::new();
    for host in 10..20 {
        let mut stream = connect_from(host, server).await;
        assert!(polled(&mut stream, 1).await);
        single.push(stream);
    }
    let mut double = Vec::new();
    for host in 30..35 {
        for _ in 0..PER_SOURCE {
            let mut stream = connect_from(host, server).await;
            assert!(polled(&mut stream, 1).await);
            double.push(stream);
        }
    }
    // The singles are idle longest, yet a newcomer closes a double source's first.
    let mut newcomer = connect_from(100, server).await;
    assert!(polled(&mut newcomer, 1).await);
    assert!(closed(&mut double[0]).await);
    for stream in &mut single {
        assert!(polled(stream, 2).await);
    }
    assert_eq!(until(&stats, |c| c.evicted_idle == 1).await.refused, 0);
}
