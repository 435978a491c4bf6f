//! IO failures back off, on tokio's paused clock: a dead port is tried a few times a second,
//! not in a busy loop, the attempts never closer than the backoff says; and retries span a
//! short loss of the port.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use ferrobus::port::{BoxPort, ConnectWith, Connecting};
use ferrobus::{Client, ClientConfig, Error, Framing, Transport};
use ferrobus_proto::frame::{LineConfig, LineTiming};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

/// When each open was attempted, and from when on opens succeed.
#[derive(Default)]
struct Port {
    attempts: Vec<Instant>,
    back_at: Option<Instant>,
}

/// A port that opens once (the client's first open), is then lost at once, and opens again
/// only from `back_at` on. A successful open gives a line whose other end answers every FC03
/// request for one register of unit 1 with the value 7.
fn transport(port: &Arc<Mutex<Port>>) -> Transport {
    let port = Arc::clone(port);
    let connector = ConnectWith::new("flaky port", move || -> Connecting {
        let now = Instant::now();
        let first = {
            let mut port = port.lock().unwrap();
            port.attempts.push(now);
            port.attempts.len() == 1
        };
        let open = first || port.lock().unwrap().back_at.is_some_and(|at| now >= at);
        Box::pin(async move {
            if !open {
                return Err(std::io::Error::new(std::io::ErrorKind::NotFound, "unplugged"));
            }
            let (ours, mut theirs) = tokio::io::duplex(256);
            if first {
                // Lost as soon as it is used.
                drop(theirs);
            } else {
                tokio::spawn(async move {
                    let mut request = [0u8; 8];
                    while theirs.read_exact(&mut request).await.is_ok() {
                        // 01 03 02 00 07, CRC.
                        let _ = theirs.write_all(&[0x01, 0x03, 0x02, 0x00, 0x07, 0xF9, 0x86]).await;
                    }
                });
            }
            Ok(Box::new(ours) as BoxPort)
        })
    });
    Transport::custom(Framing::Rtu, LineTiming::new(&LineConfig::new(19_200).unwrap()), connector)
}

fn config(retries: u32) -> ClientConfig {
    ClientConfig { timeout: Duration::from_millis(100), retries, backoff: None, ..ClientConfig::default() }
}

#[tokio::test(start_paused = true)]
async fn a_dead_port_is_tried_a_few_times_a_second_with_growing_gaps() {
    let port = Arc::new(Mutex::new(Port::default()));
    let client = Client::connect(transport(&port), config(0)).await.unwrap();
    let start = Instant::now();
    let mut failed = 0;
    // Bounded: without a backoff the paused clock would never reach 5 s.
    while start.elapsed() < Duration::from_secs(5) && failed < 1000 {
        let result = client.read_holding_registers(1, 0, 1).await;
        assert!(matches!(result, Err(Error::Io { .. })), "{result:?}");
        failed += 1;
    }
    let attempts = port.lock().unwrap().attempts.clone();
    let gaps: Vec<Duration> = attempts.windows(2).skip(1).map(|w| w[1] - w[0]).collect();
    eprintln!("{failed} failed requests in 5 s; reopen gaps {gaps:?}");
    // 10, 20, 40, ... 320 ms, then 500 ms: 5 s hold 6 + about 9 attempts.
    assert!(failed <= 16, "{failed} requests failed in 5 s: no backoff");
    for (i, gap) in gaps.iter().enumerate() {
        let due = Duration::from_millis(10 << i.min(6)).min(Duration::from_millis(500));
        assert!(*gap >= due, "attempt {} came {gap:?} after the one before, before its backoff {due:?}", i + 3);
    }
}

#[tokio::test(start_paused = true)]
async fn retries_ride_out_a_port_lost_for_300_ms() {
    let port = Arc::new(Mutex::new(Port::default()));
    let client = Client::connect(transport(&port), config(10)).await.unwrap();
    port.lock().unwrap().back_at = Some(Instant::now() + Duration::from_millis(300));
    assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [7], "answered once the port was back");
    let after = Instant::now();
    assert!(after - port.lock().unwrap().attempts[0] >= Duration::from_millis(300), "not before it was back");
    // Back to normal: the next request goes out at once.
    assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [7]);
}

#[tokio::test(start_paused = true)]
async fn without_retries_an_io_failure_is_returned_within_the_first_backoff() {
    let port = Arc::new(Mutex::new(Port::default()));
    let client = Client::connect(transport(&port), config(0)).await.unwrap();
    let start = Instant::now();
    let result = client.read_holding_registers(1, 0, 1).await;
    assert!(matches!(result, Err(Error::Io { .. })), "{result:?}");
    // The loss seen while idle already counts: the one reopen waits 10 ms, and no more.
    assert!(start.elapsed() <= Duration::from_millis(10), "returned after {:?}", start.elapsed());
    let attempts = port.lock().unwrap().attempts.len();
    assert!(attempts <= 2, "{attempts} opens: one reopen at most");
}
