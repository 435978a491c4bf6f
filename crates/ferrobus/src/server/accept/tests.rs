//! The accept loop over loopback sockets: a source past its share of connections or of
//! handshakes is refused while another source gets in; a source's entry goes with its last
//! connection. 127.0.0.2 is another host as far as the limits go (all of 127/8 is loopback,
//! and the server on 127.0.0.1 sees a client bound to 127.0.0.2 as coming from there).

use std::net::SocketAddr;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpSocket;

use super::*;

const OTHER_HOST: &str = "127.0.0.2";
const THIS_HOST: &str = "127.0.0.1";

/// A connection to `server` from `source` (an address of the loopback).
async fn connect_from(source: &str, server: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(format!("{source}:0").parse().unwrap()).unwrap();
    socket.connect(server).await.unwrap()
}

/// Whether the server closed `stream` at once (EOF or a reset), as it closes a refused one.
async fn closed(stream: &mut TcpStream) -> bool {
    let mut byte = [0u8; 1];
    matches!(stream.read(&mut byte).await, Ok(0) | Err(_))
}

/// Whether `stream` is served: the server echoes the byte sent (the first byte ends the
/// connection's handshake).
async fn served(stream: &mut TcpStream) -> bool {
    if stream.write_all(b"x").await.is_err() {
        return false;
    }
    let mut byte = [0u8; 1];
    matches!(stream.read(&mut byte).await, Ok(1))
}

/// The counts once `done` holds (no time bound of its own: the test harness's is the bound).
async fn until(stats: &TcpStats, done: impl Fn(&TcpCounts) -> bool) -> TcpCounts {
    loop {
        let counts = stats.counts();
        if done(&counts) {
            return counts;
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}

fn limits(max: usize, per_source: usize) -> TcpLimits {
    TcpLimits { max_connections: max, max_per_source: per_source, ..Default::default() }
}

/// A server on 127.0.0.1 whose connections' handshake is the client's first byte (at most
/// `handshakes` in progress from one source); every byte is echoed, until EOF.
async fn echo_server(limits: &TcpLimits, handshakes: usize) -> SocketAddr {
    let listener = TcpListener::bind((THIS_HOST, 0)).await.unwrap();
    let addr = listener.local_addr().unwrap();
    let limits = limits.clone();
    tokio::spawn(async move {
        accept_handshaking(listener, &limits, handshakes, |mut stream, _peer, handshake| async move {
            let mut byte = [0u8; 1];
            if stream.read(&mut byte).await? == 0 {
                return Ok(());
            }
            drop(handshake);
            loop {
                stream.write_all(&byte).await?;
                if stream.read(&mut byte).await? == 0 {
                    return Ok(());
                }
            }
        })
        .await
    });
    addr
}

#[tokio::test]
async fn a_source_past_its_share_is_refused_and_another_source_still_gets_in() {
    let limits = limits(10, 3);
    let server = echo_server(&limits, 16).await;
    let mut theirs = Vec::new();
    for _ in 0..3 {
        let mut stream = connect_from(OTHER_HOST, server).await;
        assert!(served(&mut stream).await);
        theirs.push(stream);
    }
    for _ in 0..2 {
        assert!(closed(&mut connect_from(OTHER_HOST, server).await).await);
    }
    let mut ours = connect_from(THIS_HOST, server).await;
    assert!(served(&mut ours).await);
    let counts = limits.stats.counts();
    assert_eq!((counts.open, counts.sources, counts.refused_source, counts.refused), (4, 2, 2, 0), "{counts:?}");
}

#[tokio::test]
async fn a_source_past_its_handshakes_is_refused_while_other_sources_and_finished_handshakes_are_served() {
    let limits = limits(20, 10);
    let server = echo_server(&limits, 2).await;
    // Two handshakes from the other host that do not finish; a third is refused.
    let mut first = connect_from(OTHER_HOST, server).await;
    let _second = connect_from(OTHER_HOST, server).await;
    until(&limits.stats, |c| c.open == 2).await;
    assert!(closed(&mut connect_from(OTHER_HOST, server).await).await);
    assert_eq!(limits.stats.counts().refused_handshakes, 1);
    // This host gets in all along.
    let mut ours = connect_from(THIS_HOST, server).await;
    assert!(served(&mut ours).await);
    // Once one of the other host's handshakes finishes, it may begin another.
    assert!(served(&mut first).await);
    let mut third = connect_from(OTHER_HOST, server).await;
    assert!(served(&mut third).await);
    let counts = limits.stats.counts();
    assert_eq!((counts.open, counts.refused_handshakes, counts.refused_source), (4, 1, 0), "{counts:?}");
}

#[tokio::test]
async fn a_sources_entry_goes_with_its_last_connection() {
    let limits = limits(20, 10);
    let server = echo_server(&limits, 10).await;
    let mut streams = Vec::new();
    for source in [OTHER_HOST, OTHER_HOST, OTHER_HOST, THIS_HOST, THIS_HOST] {
        let mut stream = connect_from(source, server).await;
        // Handshakes finished for some, not for others: both are given back.
        if streams.len() % 2 == 0 {
            assert!(served(&mut stream).await);
        }
        streams.push(stream);
    }
    assert_eq!(until(&limits.stats, |c| c.open == 5).await.sources, 2);
    streams.truncate(2);
    let counts = until(&limits.stats, |c| c.open == 2).await;
    assert_eq!(counts.sources, 1, "{counts:?}");
    streams.clear();
    let counts = until(&limits.stats, |c| c.open == 0).await;
    assert_eq!(counts.sources, 0, "{counts:?}");
}

#[test]
fn an_ipv6_source_is_its_slash_64_and_a_mapped_ipv4_address_is_the_ipv4_one() {
    let of = |s: &str| Source::of(s.parse().unwrap());
    assert_eq!(of("[2001:db8:1:2:aaaa::1]:502"), of("[2001:db8:1:2:bbbb::9]:503"));
    assert_ne!(of("[2001:db8:1:2::1]:502"), of("[2001:db8:1:3::1]:502"));
    assert_eq!(of("[2001:db8:1:2:aaaa::1]:502").to_string(), "2001:db8:1:2::/64");
    assert_eq!(of("[::ffff:192.0.2.7]:502"), of("192.0.2.7:9"));
    assert_ne!(of("192.0.2.7:9"), of("192.0.2.8:9"));
}

#[tokio::test(start_paused = true)]
async fn refusals_are_logged_once_a_second_and_the_next_line_counts_the_others() {
    let mut throttle = Throttle::default();
    assert_eq!(throttle.pass(), Some(0));
    for _ in 0..3 {
        assert_eq!(throttle.pass(), None);
    }
    tokio::time::advance(REFUSALS_LOGGED_EVERY.saturating_sub(Duration::from_millis(1))).await;
    assert_eq!(throttle.pass(), None);
    tokio::time::advance(Duration::from_millis(1)).await;
    assert_eq!(throttle.pass(), Some(4));
    assert_eq!(throttle.pass(), None);
}

#[tokio::test(start_paused = true)]
async fn out_of_sockets_pauses_accepting_for_the_backoff_and_another_error_only_briefly() {
    let stats = TcpStats::default();
    let started = tokio::time::Instant::now();
    wait_out(&crate::sys::descriptor_table_full(), &stats).await;
    assert_eq!(started.elapsed(), ACCEPT_BACKOFF, "the platform's full descriptor table waits the backoff");
    let counts = stats.counts();
    assert_eq!((counts.descriptor_waits, counts.accept_errors), (1, 0));

    let started = tokio::time::Instant::now();
    wait_out(&io::Error::from(io::ErrorKind::ConnectionAborted), &stats).await;
    assert!(started.elapsed() < ACCEPT_BACKOFF, "{:?}", started.elapsed());
    let counts = stats.counts();
    assert_eq!((counts.descriptor_waits, counts.accept_errors), (1, 1));
}

#[test]
fn a_library_server_leaves_freed_memory_to_the_allocator_unless_the_application_asks() {
    assert!(!TcpLimits::default().release_memory_after_bursts, "the library's default: no malloc_trim");
}
