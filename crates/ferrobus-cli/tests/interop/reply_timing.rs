//! When the simulator's reply starts, measured from outside by a raw master on its pty.
//!
//! `ferrobus sim --profile omron-3g3rx --response-wait 20ms --pty --baud 9600` must not
//! start a reply before t3.5 + 20 ms after the request: 3.5 characters of 11 bits at 9600
//! baud (8E1) are 4.010417 ms, so 24.010417 ms. A pty delivers the request at once, so it is
//! timed from just before the write (a preempted test thread can then only make a reply look
//! late, never early) to the read of the first reply byte. Every reply must come at or after
//! the target; how late is a figure, not asserted (a loaded machine can delay any reply):
//! the percentiles go to stderr (`--nocapture` shows them), and `bench` measures lateness
//! under load. The test runs alone.
//!
//! Beside them it prints the pty's own floor: the same requests against an echo that sleeps as
//! the simulator does (a current-thread tokio runtime, the pty in its epoll) and answers by a
//! busy wait exactly the target after it read the request — as punctual as a program can be.
//! What the simulator adds to that floor is its own share.

use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};

use crate::support::{RawPort, hex, require_alone, show, sim_pty, with_crc};

/// Requests timed.
const SAMPLES: usize = 200;

/// t3.5 at 9600 baud, 11-bit characters: 3.5 × 11 / 9600 s.
const T3_5: Duration = Duration::from_nanos(4_010_417);

/// The 3G3RX's communication wait (C078) given to the simulator.
const WAIT: Duration = Duration::from_millis(20);

/// The `q`th percentile (nearest rank) of sorted `values`.
fn percentile(sorted: &[i64], q: usize) -> i64 {
    let rank = (sorted.len() * q).div_ceil(100).max(1);
    sorted[rank - 1]
}

#[test]
fn sim_reply_starts_no_earlier_than_t3_5_plus_the_response_wait() {
    let Some(_turn) = require_alone(&[]) else { return };
    let args = ["--profile", "omron-3g3rx", "--response-wait", "20ms", "--baud", "9600"];
    let (mut sim, pty) = sim_pty(&args);
    let port = RawPort::open(&pty, 9600);
    // FC03 of status A and B (frame 0002h-0003h): 2 (stop), 0 (stop).
    let request = with_crc(&hex("01 03 00 02 00 02"));
    let expected = with_crc(&hex("01 03 04 00 02 00 00"));
    let target = T3_5 + WAIT;

    let mut late_us = Vec::with_capacity(SAMPLES);
    let mut early = Vec::new();
    for i in 0..SAMPLES {
        let sent = port.send(&request);
        let (reply, first) = port.receive(expected.len());
        assert_eq!(reply, expected, "reply {i}: {} instead of {}", show(&reply), show(&expected));
        let delay = first.expect("a first byte").duration_since(sent);
        if delay < target {
            early.push(delay);
        }
        late_us.push(lateness_us(delay, target));
        // The master's silence before the next request: the rest of the reply's 9 characters
        // on a real line (10.3 ms), then t3.5.
        std::thread::sleep(Duration::from_millis(15));
    }
    late_us.sort_unstable();
    let (p50, p99, min, max) = (percentile(&late_us, 50), percentile(&late_us, 99), late_us[0], late_us[SAMPLES - 1]);
    eprintln!(
        "reply timing, 9600 8E1, response wait 20 ms: target t3.5 + wait = {:.3} ms; first reply byte minus \
         target over {SAMPLES} requests: p50 {p50} µs, p99 {p99} µs, min {min} µs, max {max} µs",
        target.as_secs_f64() * 1000.0
    );
    sim.terminate();
    if let Some(own) = sim.log().lines().find(|l| l.contains("reply start after its due time")) {
        eprintln!("the simulator's own figures:{}", own.trim_start_matches("  [err] sim:"));
    }
    let mut floor = echo_lateness(&request, target);
    floor.sort_unstable();
    eprintln!(
        "the pty's floor, an echo answering by a busy wait, lateness over {SAMPLES} requests: p50 {} µs, \
         p99 {} µs, min {} µs",
        percentile(&floor, 50),
        percentile(&floor, 99),
        floor[0]
    );
    assert!(early.is_empty(), "{} of {SAMPLES} replies started before {target:?}: {early:?}", early.len());
}

/// `delay` minus `target`, in µs.
fn lateness_us(delay: Duration, target: Duration) -> i64 {
    i64::try_from(delay.as_micros()).unwrap_or(i64::MAX) - i64::try_from(target.as_micros()).unwrap_or(0)
}

/// How late, in µs, echoes of `request` came back through a pty, against `target`: the echo
/// sleeps in a current-thread tokio runtime's epoll, as `ferrobus sim` does, and writes back
/// what it read `target` after reading it, busy-waiting the last 2 ms.
fn echo_lateness(request: &[u8], target: Duration) -> Vec<i64> {
    let (path_tx, path_rx) = std::sync::mpsc::channel();
    let echo = std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().expect("a runtime");
        runtime.block_on(async {
            let mut pty = ferrobus::Pty::open().expect("a pty");
            path_tx.send(pty.path.clone()).expect("the test waits for the path");
            let mut buf = [0u8; 64];
            // The pty outlives the test's end; the echo ends when requests stop coming.
            while let Ok(n @ 1..) =
                tokio::time::timeout(Duration::from_millis(500), pty.read(&mut buf)).await.unwrap_or(Ok(0))
            {
                // The echo is the runtime's only task: blocking its thread delays nothing else.
                let due = Instant::now() + target;
                std::thread::sleep(target.saturating_sub(Duration::from_millis(2)));
                while Instant::now() < due {
                    std::hint::spin_loop();
                }
                if pty.write_all(&buf[..n]).await.is_err() {
                    break;
                }
            }
        });
    });
    let path = path_rx.recv().expect("the echo's pty");
    let port = RawPort::open(&path, 9600);
    let mut late_us = Vec::with_capacity(SAMPLES);
    for _ in 0..SAMPLES {
        let sent = port.send(request);
        let (echoed, first) = port.receive(request.len());
        assert_eq!(echoed, request, "the echo");
        late_us.push(lateness_us(first.expect("a first byte").duration_since(sent), target));
        std::thread::sleep(Duration::from_millis(15));
    }
    drop(port);
    echo.join().expect("the echo thread");
    late_us
}
