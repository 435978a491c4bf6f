//! The virtual RS-485 line's adapter, in real time: the wire model (tested on explicit time
//! in `wire.rs`) runs on tokio's clock, characters are never early, collisions garble,
//! broken gaps are counted against the endpoint that broke them, faults are drawn from the
//! seed, ptys reach the line, and a client and a server on the line keep every gap. How late
//! a delivery is, is a figure (printed here, measured by the benchmarks), not asserted.
#![cfg(unix)] // its endpoints are ptys

use std::time::Duration;

use ferrobus::line::{Line, LineFaults, LineOptions};
use ferrobus::server::{ServerOptions, serve};
use ferrobus::{Client, ClientConfig, Timer};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, Parity};
use ferrobus_proto::slave::{Handler, Slave, SlaveConfig};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

fn line_9600() -> LineOptions {
    LineOptions::new(LineConfig::new(9600).unwrap())
}

/// Reads until `n` bytes have come or `within` has passed: for what should come, a bound
/// (10 s) that only a stall of seconds misses; for what should not, how long to listen.
async fn read_n(port: &mut (impl AsyncReadExt + Unpin), n: usize, within: Duration) -> Vec<u8> {
    let mut got = Vec::new();
    let _ = tokio::time::timeout(within, async {
        let mut buf = [0u8; 256];
        while got.len() < n {
            match port.read(&mut buf).await {
                Ok(k) if k > 0 => got.extend_from_slice(&buf[..k]),
                _ => return,
            }
        }
    })
    .await;
    got
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn characters_are_never_early_and_reach_every_other_endpoint() {
    let line = Line::start(line_9600());
    let mut a = line.endpoint("a").await.unwrap();
    let mut b = line.endpoint("b").await.unwrap();
    let mut c = line.endpoint("c").await.unwrap();
    let start = Instant::now();
    a.write_all(&[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]).await.unwrap();
    assert_eq!(read_n(&mut b, 10, Duration::from_secs(10)).await, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
    let took = start.elapsed();
    // 10 characters of 11 bits at 9600 baud: 11.458 ms on the wire. Never early; how late
    // is a figure.
    assert!(took >= Duration::from_micros(11_458), "{took:?}");
    eprintln!("10 characters at 9600 8E1 read after {took:?} (11.458 ms on the wire)");
    assert_eq!(read_n(&mut c, 10, Duration::from_secs(10)).await.len(), 10);
    assert!(read_n(&mut a, 1, Duration::from_millis(30)).await.is_empty(), "no echo by default");
    let stats = line.stats();
    assert_eq!(stats.characters, 10);
    assert_eq!(stats.endpoints[0].characters, 10);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_endpoints_talking_at_once_collide_and_both_frames_are_garbled() {
    let line = Line::start(line_9600());
    let mut a = line.endpoint("a").await.unwrap();
    let mut b = line.endpoint("b").await.unwrap();
    let mut c = line.endpoint("c").await.unwrap();
    a.write_all(&[0x11; 8]).await.unwrap();
    b.write_all(&[0x22; 8]).await.unwrap();
    let heard = read_n(&mut c, 16, Duration::from_secs(10)).await;
    assert!(line.stats().collisions > 0, "{:?}", line.stats());
    assert!(heard.windows(8).all(|w| w != [0x11; 8] && w != [0x22; 8]), "{heard:02X?}");
}

/// At 1200 baud, whose t3.5 (32 ms) a loaded machine does not let pass between a read and
/// the answer written at once; the exact rule is tested on explicit time in `wire.rs`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frame_begun_before_t3_5_of_silence_counts_against_its_sender() {
    let line = Line::start(LineOptions::new(LineConfig::new(1200).unwrap()));
    let mut a = line.endpoint("master").await.unwrap();
    let mut b = line.endpoint("hasty slave").await.unwrap();
    a.write_all(&[1; 8]).await.unwrap();
    assert_eq!(read_n(&mut b, 8, Duration::from_secs(10)).await.len(), 8);
    // Answer at once: t3.5 is 32.08 ms at 1200 baud.
    b.write_all(&[2; 5]).await.unwrap();
    assert_eq!(read_n(&mut a, 5, Duration::from_secs(10)).await.len(), 5);
    // Then the master waits 40 ms before its next frame: within the rule.
    tokio::time::sleep(Duration::from_millis(40)).await;
    a.write_all(&[3; 8]).await.unwrap();
    assert_eq!(read_n(&mut b, 8, Duration::from_secs(10)).await.len(), 8);
    let stats = line.stats();
    assert_eq!(stats.endpoints[0].gap_violations, 0);
    assert_eq!(stats.endpoints[1].gap_violations, 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn faults_are_drawn_from_the_seed_and_a_dead_endpoint_hears_nothing() {
    let faults = LineFaults { corrupt_rate: 0.2, drop_rate: 0.1, ..LineFaults::default() };
    let options = LineOptions { faults, paced: false, seed: 42, ..line_9600() };
    let mut runs = Vec::new();
    for _ in 0..2 {
        let line = Line::start(options);
        let mut a = line.endpoint("a").await.unwrap();
        let mut b = line.endpoint("b").await.unwrap();
        let sent: Vec<u8> = (0..200u8).collect();
        a.write_all(&sent).await.unwrap();
        // Unpaced: what is left of the 200 comes in one delivery, counted before it is sent.
        let got = read_n(&mut b, 1, Duration::from_secs(10)).await;
        let stats = line.stats();
        assert_eq!(got.len() as u64, 200 - stats.dropped);
        assert!(stats.corrupted > 10 && stats.dropped > 5, "{stats:?}");
        runs.push(got);
    }
    assert_eq!(runs[0], runs[1], "the same seed, the same faults");

    let line = Line::start(LineOptions { paced: false, ..line_9600() });
    let mut a = line.endpoint("a").await.unwrap();
    let mut b = line.endpoint("b").await.unwrap();
    line.set_dead(b.id(), true);
    a.write_all(&[1, 2, 3]).await.unwrap();
    b.write_all(&[4, 5, 6]).await.unwrap();
    assert!(read_n(&mut b, 1, Duration::from_millis(50)).await.is_empty());
    assert!(read_n(&mut a, 1, Duration::from_millis(50)).await.is_empty(), "a dead endpoint is mute too");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn another_program_reaches_the_line_through_a_pty() {
    let line = Line::start(LineOptions { paced: false, ..line_9600() });
    let path = line.pty().await.unwrap();
    let mut inside = line.endpoint("inside").await.unwrap();
    let line_config = LineConfig::new(9600).unwrap().with_parity(Parity::None);
    let mut outside = ferrobus::port::open_serial(&ferrobus::SerialConfig::new(&path, line_config)).unwrap();
    outside.write_all(&[0xAB, 0xCD]).await.unwrap();
    assert_eq!(read_n(&mut inside, 2, Duration::from_secs(10)).await, [0xAB, 0xCD]);
    inside.write_all(&[0x01]).await.unwrap();
    let mut buf = [0u8; 1];
    tokio::time::timeout(Duration::from_secs(10), outside.read(&mut buf)).await.unwrap().unwrap();
    assert_eq!(buf, [0x01]);
    assert_eq!(line.stats().endpoints[0].name, path.display().to_string());
}

/// Holding registers that read back their address.
struct Echo;

impl Handler for Echo {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        for (i, r) in out.iter_mut().enumerate() {
            *r = start.wrapping_add(u16::try_from(i).unwrap_or(0));
        }
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_and_a_server_on_the_line_keep_every_gap() {
    let config = LineConfig::new(19_200).unwrap();
    let line = Line::start(LineOptions::new(config));
    let timing = line.timing();
    let server_port = line.endpoint("server").await.unwrap();
    tokio::spawn(async move {
        let slave = Slave::new(RtuCodec::new(timing, Expect::Both), SlaveConfig::unit(1));
        serve(slave, Box::new(server_port), &mut Echo, &mut ServerOptions::new(timing, Timer::Spin)).await
    });
    let client = Client::connect(line.transport("client"), ClientConfig::default()).await.unwrap();
    let start = Instant::now();
    for i in 0..20 {
        assert_eq!(client.read_holding_registers(1, i, 10).await.unwrap()[0], i);
    }
    let elapsed = start.elapsed();
    let stats = line.stats();
    assert_eq!(stats.endpoints.iter().map(|e| e.gap_violations).sum::<u64>(), 0, "{stats:?}");
    assert_eq!(stats.frames, 40);
    assert_eq!(stats.collisions, 0);
    // The theoretical time: (8 + 25) characters and two t3.5 per transaction. Never faster
    // than the wire allows — which is that, but the silence after the last reply — and the
    // share of the theoretical rate is a figure (the benchmark measures it).
    let ideal = (timing.char_time() * 33 + timing.t3_5() * 2) * 20;
    let floor = ideal.saturating_sub(timing.t3_5());
    assert!(elapsed >= floor, "{elapsed:?}: faster than the wire allows ({floor:?})");
    eprintln!(
        "20 transactions in {elapsed:?}: {:.1}% of the theoretical rate",
        100.0 * ideal.as_secs_f64() / elapsed.as_secs_f64()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pty_endpoint_at_the_wrong_baud_rate_gets_garbage_and_one_at_the_right_settings_clean_bytes() {
    let line = Line::start(LineOptions { paced: false, ..line_9600() });
    let (right, wrong) = (line.pty().await.unwrap(), line.pty().await.unwrap());
    let mut inside = line.endpoint("inside").await.unwrap();
    // 9600 8E1 is the line's (the pty refuses the parity; the line takes it as held).
    let open = |path, baud| {
        ferrobus::port::open_serial(&ferrobus::SerialConfig::new(path, LineConfig::new(baud).unwrap())).unwrap()
    };
    let mut right = open(&right, 9600);
    let mut wrong = open(&wrong, 38_400);
    let request = [0x01, 0x03, 0x00, 0x00, 0x00, 0x01, 0x84, 0x0A];
    inside.write_all(&request).await.unwrap();
    assert_eq!(read_n(&mut right, 8, Duration::from_secs(10)).await, request, "clean at the line's settings");
    // What it is given comes in one delivery, however many bytes the UART model made of it.
    let garbage = read_n(&mut wrong, 1, Duration::from_secs(10)).await;
    assert_ne!(garbage, request, "at 38400 on a 9600 line");
    assert!(!garbage.is_empty(), "a fast receiver sees something: every start bit");
    // And what it sends reaches the line garbled: 38400 characters are a quarter as long.
    wrong.write_all(&request).await.unwrap();
    let heard = read_n(&mut inside, 1, Duration::from_secs(10)).await;
    assert_ne!(heard, request, "a 38400 transmitter on a 9600 line");
    right.write_all(&request).await.unwrap();
    let mut clean = read_n(&mut inside, 8, Duration::from_secs(10)).await;
    // The garbled bytes may come before; the clean request is what follows them.
    clean = clean.split_off(clean.len().saturating_sub(8));
    assert_eq!(clean, request, "the right endpoint's request arrives clean");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pty_tap_hears_both_sides_says_when_each_run_ended_and_transmits_nothing() {
    let line = Line::start(line_9600());
    let mut a = line.endpoint("master").await.unwrap();
    let mut b = line.endpoint("slave").await.unwrap();
    let mut tap = line.tap().await.unwrap();
    let line_config = LineConfig::new(9600).unwrap().with_parity(Parity::None);
    let mut sniffer = ferrobus::port::open_serial(&ferrobus::SerialConfig::new(&tap.path, line_config)).unwrap();
    let sent = Instant::now();
    a.write_all(&[0x01, 0x03, 0x00, 0x00]).await.unwrap();
    assert_eq!(read_n(&mut b, 4, Duration::from_secs(10)).await.len(), 4);
    b.write_all(&[0x01, 0x83]).await.unwrap();
    assert_eq!(read_n(&mut sniffer, 6, Duration::from_secs(10)).await, [0x01, 0x03, 0x00, 0x00, 0x01, 0x83]);
    assert_eq!(read_n(&mut a, 2, Duration::from_secs(10)).await, [0x01, 0x83]);
    // What a sniffer writes on the tap never reaches the line.
    sniffer.write_all(&[0xEE; 3]).await.unwrap();
    assert!(read_n(&mut a, 1, Duration::from_millis(50)).await.is_empty());
    let first = tap.heard.recv().await.unwrap();
    let second = tap.heard.recv().await.unwrap();
    assert_eq!((first.bytes, second.bytes), (vec![0x01, 0x03, 0x00, 0x00], vec![0x01, 0x83]));
    // Four characters of 1.146 ms: the run ended on the wire no earlier than 4.583 ms after
    // the write, and reached the tap's pty no earlier than that.
    assert!(first.end.duration_since(sent) >= Duration::from_micros(4583), "{:?}", first.end - sent);
    assert!(first.written >= first.end);
    let stats = line.stats();
    let e = &stats.endpoints[2];
    assert!(e.tap && e.characters == 0, "{e:?}");
    assert_eq!(e.refused, 3);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pty_tap_whose_sniffer_falls_behind_a_full_pty_buffer_still_hears_every_run_whole_and_in_order() {
    // 120 kB through the tap before its sniffer reads a byte: more than a Linux pty buffers
    // (64 kB and the line discipline's 4 kB), so the line's writes to it stop being taken and
    // the rest waits for room.
    let line = Line::start(LineOptions { paced: false, ..line_9600() });
    let mut a = line.endpoint("a").await.unwrap();
    let mut tap = line.tap().await.unwrap();
    let line_config = LineConfig::new(9600).unwrap().with_parity(Parity::None);
    let mut sniffer = ferrobus::port::open_serial(&ferrobus::SerialConfig::new(&tap.path, line_config)).unwrap();
    let runs: Vec<Vec<u8>> =
        (0..120u32).map(|i| (0..1000u32).map(|j| ((i * 1000 + j) % 251) as u8).collect()).collect();
    for run in &runs {
        a.write_all(run).await.unwrap();
    }
    let got = read_n(&mut sniffer, 120_000, Duration::from_secs(20)).await;
    assert_eq!(got.len(), 120_000);
    assert!(got == runs.concat(), "every byte, in order");
    for run in &runs {
        let heard = tap.heard.recv().await.unwrap();
        assert!(&heard.bytes == run && heard.written >= heard.end, "the runs recorded in order");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_in_process_tap_hears_the_line_and_its_writes_never_reach_it() {
    let line = Line::start(LineOptions { paced: false, ..line_9600() });
    let mut a = line.endpoint("a").await.unwrap();
    let mut b = line.endpoint("b").await.unwrap();
    let mut tap = line.tap_endpoint("tap").await.unwrap();
    tap.write_all(&[0xEE; 4]).await.unwrap();
    a.write_all(&[0x11, 0x22]).await.unwrap();
    assert_eq!(read_n(&mut tap, 2, Duration::from_secs(10)).await, [0x11, 0x22]);
    assert_eq!(read_n(&mut b, 3, Duration::from_millis(50)).await, [0x11, 0x22], "only a's bytes");
    let stats = line.stats();
    assert_eq!((stats.endpoints[tap.id()].refused, stats.characters), (4, 2));
}
