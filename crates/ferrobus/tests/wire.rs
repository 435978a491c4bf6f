//! The virtual line's wire model on explicit time: what each endpoint receives and exactly
//! when, collisions, the t3.5 rule, faults from the seed, and the UART model for endpoints at
//! other settings. Nothing here reads a clock.

use std::time::Duration;

use ferrobus::wire::{Delivery, LineFaults, LineOptions, OnError, Receiver, Wire, heard};
use ferrobus_proto::Instant;
use ferrobus_proto::frame::{LineConfig, Parity};

/// 9600 8E1: a character is 11 bits, 1 145 834 ns; t1.5 1 718 750 ns; t3.5 4 010 417 ns.
fn line_9600() -> LineOptions {
    LineOptions::new(at_9600())
}

/// 9600 8E1.
fn at_9600() -> LineConfig {
    LineConfig::new(9600).unwrap()
}

const C: Duration = Duration::from_nanos(1_145_834);
const T0: Instant = Instant::from_millis(1000);

fn at(d: Duration) -> Instant {
    T0.saturating_add(d)
}

fn ns(n: u64) -> Duration {
    Duration::from_nanos(n)
}

/// A wire at `options` from `T0` with endpoints a, b, c (ids 0, 1, 2).
fn wire(options: LineOptions) -> Wire {
    let mut wire = Wire::new(options, T0);
    for name in ["a", "b", "c"] {
        wire.attach(name);
    }
    wire
}

#[test]
fn characters_reach_every_other_endpoint_when_their_last_bit_has_left_the_wire_and_not_a_nanosecond_before() {
    let mut w = wire(line_9600());
    assert_eq!(w.timing().char_time(), C);
    let sent: Vec<u8> = (1..=10).collect();
    w.send(0, &sent, T0);
    let end = at(C * 10);
    assert_eq!(w.next_wake(), Some(end), "woken once, at the end of the run");
    assert_eq!(w.advance(at(C).saturating_sub(ns(1))), [], "nothing before the first character has left");
    let got = w.advance(end.saturating_sub(ns(1)));
    let delivery = |to, bytes: &[u8], at| Delivery { to, bytes: bytes.to_vec(), at, tx: at_9600() };
    assert_eq!(
        got,
        [delivery(1, &sent[..9], at(C * 9)), delivery(2, &sent[..9], at(C * 9))],
        "b and c, not the sender"
    );
    assert_eq!(w.advance(end), [delivery(1, &sent[9..], end), delivery(2, &sent[9..], end)]);
    assert_eq!(w.next_wake(), None);
    assert_eq!(w.advance(at(Duration::from_secs(1))), []);
    let stats = w.stats();
    assert_eq!((stats.characters, stats.endpoints[0].characters, stats.collisions), (10, 10, 0));
}

#[test]
fn with_echo_the_sender_hears_itself_at_the_same_instant() {
    let mut w = wire(LineOptions { echo: true, ..line_9600() });
    w.send(1, &[7, 8], T0);
    let got = w.advance(at(C * 2));
    assert_eq!(got.iter().map(|d| (d.to, d.at)).collect::<Vec<_>>(), [(0, at(C * 2)), (1, at(C * 2)), (2, at(C * 2))]);
}

#[test]
fn a_write_while_the_sender_is_still_transmitting_follows_its_last_character() {
    let mut w = wire(line_9600());
    w.send(0, &[1, 2, 3], T0);
    w.send(0, &[4, 5], at(C));
    let got = w.advance(at(C * 5));
    assert_eq!(
        got[0],
        Delivery { to: 1, bytes: vec![1, 2, 3, 4, 5], at: at(C * 5), tx: at_9600() },
        "one run, back to back"
    );
    assert_eq!(w.stats().endpoints[0].gap_violations, 0);
}

#[test]
fn two_senders_overlapping_by_half_a_character_garble_exactly_the_characters_that_overlap() {
    let mut w = wire(line_9600());
    w.send(0, &[0x11; 8], T0);
    // b starts at 2.5 character times: its characters 0..=5 overlap a's 2..=7.
    w.send(1, &[0x22; 8], at(C * 5 / 2));
    let end = at(C * 21 / 2);
    assert_eq!(w.next_wake(), Some(end), "one run: the wire is busy throughout");
    let got = w.advance(end);
    let heard_by_c = &got.iter().find(|d| d.to == 2).unwrap().bytes;
    assert_eq!(heard_by_c.len(), 16);
    assert_eq!(heard_by_c[..2], [0x11, 0x11], "before b began");
    assert_eq!(heard_by_c[14..], [0x22, 0x22], "after a ended");
    assert_eq!(w.stats().collisions, 12, "6 of a's and 6 of b's");
}

#[test]
fn characters_that_only_touch_do_not_collide() {
    let mut w = wire(line_9600());
    w.send(0, &[1; 4], T0);
    w.send(1, &[2; 4], at(C * 4));
    let got = w.advance(at(C * 8));
    assert_eq!(w.stats().collisions, 0);
    assert_eq!(got.iter().find(|d| d.to == 2).unwrap().bytes, [1, 1, 1, 1, 2, 2, 2, 2]);
    assert_eq!(w.stats().endpoints[1].gap_violations, 1, "no silence at all before b's frame");
}

#[test]
fn a_frame_begun_a_nanosecond_before_t3_5_of_silence_counts_against_its_sender_and_one_at_t3_5_does_not() {
    let mut w = wire(line_9600());
    let t3_5 = w.timing().t3_5();
    assert_eq!(t3_5, ns(4_010_417));
    w.send(0, &[1; 8], T0);
    let request_end = at(C * 8);
    w.send(1, &[2; 5], request_end.saturating_add(t3_5).saturating_sub(ns(1)));
    assert_eq!(w.stats().endpoints[1].gap_violations, 1);
    let reply_end = request_end.saturating_add(t3_5).saturating_sub(ns(1)).saturating_add(C * 5);
    w.send(0, &[3; 8], reply_end.saturating_add(t3_5));
    assert_eq!(w.stats().endpoints[0].gap_violations, 0, "exactly t3.5 of silence keeps the rule");
}

#[test]
fn a_write_within_t1_5_of_the_senders_last_character_continues_its_frame() {
    let mut w = wire(line_9600());
    let t1_5 = w.timing().t1_5();
    w.send(0, &[1; 4], T0);
    w.send(0, &[1; 4], at(C * 4).saturating_add(t1_5).saturating_sub(ns(1)));
    assert_eq!(w.stats().endpoints[0].gap_violations, 0);
    // A gap inside a frame ends the run: b gets the two parts at their own ends.
    let got = w.advance(at(Duration::from_millis(20)));
    let to_b: Vec<Instant> = got.iter().filter(|d| d.to == 1).map(|d| d.at).collect();
    assert_eq!(to_b, [at(C * 4), at(C * 8).saturating_add(t1_5).saturating_sub(ns(1))]);
}

#[test]
fn an_unpaced_wire_delivers_at_the_instant_of_the_write() {
    let mut w = wire(LineOptions { paced: false, ..line_9600() });
    assert_eq!(w.timing().char_time(), Duration::ZERO);
    w.send(0, &[1, 2, 3], at(ns(5)));
    assert_eq!(
        w.advance(at(ns(5))),
        [
            Delivery { to: 1, bytes: vec![1, 2, 3], at: at(ns(5)), tx: at_9600() },
            Delivery { to: 2, bytes: vec![1, 2, 3], at: at(ns(5)), tx: at_9600() },
        ]
    );
}

#[test]
fn the_sniffer_counts_a_request_as_one_frame() {
    let mut w = wire(line_9600());
    w.send(0, &[0x01, 0x03, 0x00, 0x00, 0x00, 0x01, 0x84, 0x0A], T0);
    w.advance(at(C * 8));
    w.advance(at(C * 8 + Duration::from_millis(5)));
    assert_eq!((w.stats().frames, w.stats().discards), (1, 0), "{:?}", w.stats());
}

/// b's deliveries from 200 characters a sends on a faulty wire seeded `seed`.
fn faulty_run(seed: u64) -> (Vec<u8>, u64, u64) {
    let faults = LineFaults { corrupt_rate: 0.2, drop_rate: 0.1, ..LineFaults::default() };
    let mut w = wire(LineOptions { faults, seed, ..line_9600() });
    let sent: Vec<u8> = (0..200u8).collect();
    w.send(0, &sent, T0);
    let got: Vec<u8> = w.advance(at(C * 200)).into_iter().filter(|d| d.to == 1).flat_map(|d| d.bytes).collect();
    (got, w.stats().dropped, w.stats().corrupted)
}

#[test]
fn faults_are_drawn_from_the_seed_the_same_seed_the_same_faults() {
    let (got, dropped, corrupted) = faulty_run(42);
    assert_eq!(got.len() as u64, 200 - dropped);
    assert!(corrupted > 10 && dropped > 5, "{dropped} dropped, {corrupted} corrupted");
    assert_eq!(faulty_run(42), (got.clone(), dropped, corrupted));
    assert_ne!(faulty_run(43).0, got, "another seed, other faults");
}

#[test]
fn a_dead_endpoint_neither_hears_nor_sends_and_alive_again_does_both() {
    let mut w = wire(line_9600());
    w.set_dead(1, true);
    w.send(0, &[1, 2, 3], T0);
    w.send(1, &[4, 5, 6], T0);
    let got = w.advance(at(Duration::from_millis(10)));
    assert_eq!(got, [Delivery { to: 2, bytes: vec![1, 2, 3], at: at(C * 3), tx: at_9600() }]);
    assert!(w.stats().endpoints[1].dead);
    w.set_dead(1, false);
    w.send(1, &[4], at(Duration::from_millis(20)));
    let to = |d: &Delivery| d.to;
    assert_eq!(w.advance(at(Duration::from_millis(30))).iter().map(to).collect::<Vec<_>>(), [0, 2]);
    w.set_dead(99, true);
    w.send(99, &[1], at(Duration::from_millis(40)));
    assert_eq!(w.next_wake(), None, "an unknown endpoint sends nothing");
}

#[test]
fn a_stretched_gap_splits_the_run_and_each_part_arrives_at_its_own_end() {
    // A chance above 1 is taken as 1: every gap is stretched, and nothing panics.
    let faults = LineFaults { stretch_rate: 2.0, stretch_by: Duration::from_millis(1), ..LineFaults::default() };
    let mut w = wire(LineOptions { faults, ..line_9600() });
    w.send(0, &[1, 2, 3], T0);
    let got = w.advance(at(Duration::from_millis(10)));
    let ms = Duration::from_millis(1);
    let to_b: Vec<(Vec<u8>, Instant)> = got.into_iter().filter(|d| d.to == 1).map(|d| (d.bytes, d.at)).collect();
    assert_eq!(to_b, [(vec![1], at(C)), (vec![2], at(C * 2 + ms)), (vec![3], at(C * 3 + ms * 2))]);
    assert_eq!(w.stats().stretched, 2);
    // A chance that is not a number is taken as 0.
    let faults = LineFaults { stretch_rate: f64::NAN, drop_rate: f64::NAN, ..faults };
    let mut w = wire(LineOptions { faults, ..line_9600() });
    w.send(0, &[1, 2, 3], T0);
    assert_eq!(w.advance(at(C * 3))[0].bytes, [1, 2, 3]);
}

#[test]
fn noise_bursts_come_at_times_drawn_from_the_seed_and_reach_every_endpoint() {
    let faults = LineFaults { noise_per_second: 50.0, noise_len: 4, ..LineFaults::default() };
    let run = || {
        let mut w = wire(LineOptions { faults, seed: 9, ..line_9600() });
        let mut got = Vec::new();
        // Woken whenever the wire asks, as the adapter does.
        while let Some(t) = w.next_wake().filter(|t| *t <= at(Duration::from_secs(1))) {
            got.extend(w.advance(t));
        }
        (got, w.stats().clone())
    };
    let (got, stats) = run();
    assert!(stats.noise >= 10, "{stats:?}");
    let to_a: u64 = got.iter().filter(|d| d.to == 0).map(|d| d.bytes.len() as u64).sum();
    // Every noise character reaches a, but the last burst's, which may still be on the wire.
    assert!(to_a <= stats.noise && to_a + 4 >= stats.noise, "{to_a} of {}", stats.noise);
    assert!(got.iter().all(|d| d.at > T0 && d.at <= at(Duration::from_secs(1))));
    assert_eq!(run().0, got, "the same seed, the same bursts at the same instants");
}

#[test]
fn an_infinite_noise_rate_makes_at_most_one_burst_per_character_time() {
    let faults = LineFaults { noise_per_second: f64::INFINITY, noise_len: 1, ..LineFaults::default() };
    let mut w = wire(LineOptions { faults, ..line_9600() });
    w.advance(at(C * 100));
    assert_eq!(w.stats().noise, 100, "a burst each character time, from the first");
}

/// A read request, 01 03 00 00 00 01 84 0A.
const REQUEST: [u8; 8] = [0x01, 0x03, 0x00, 0x00, 0x00, 0x01, 0x84, 0x0A];

#[test]
fn an_endpoint_at_the_wrong_baud_rate_sends_and_hears_garbage_and_one_at_the_wires_settings_clean_bytes() {
    let mut w = wire(line_9600());
    let wire_config = w.options().config;
    let right = Receiver { config: wire_config, on_error: OnError::Keep };
    let fast = LineConfig::new(38_400).unwrap();
    assert_eq!(w.heard_by(right, &REQUEST), REQUEST);
    let garbage = w.heard_by(Receiver { config: fast, on_error: OnError::Keep }, &REQUEST);
    assert!(!garbage.is_empty() && garbage != REQUEST, "{garbage:02X?}");
    w.send_at(0, fast, &REQUEST, T0);
    w.send_at(2, wire_config, &REQUEST, at(Duration::from_millis(100)));
    // b is at the wire's settings.
    let to_b: Vec<Vec<u8>> = w
        .advance(at(Duration::from_millis(200)))
        .into_iter()
        .filter(|d| d.to == 1)
        .map(|d| d.heard_by(right))
        .collect();
    assert_eq!(to_b.len(), 2);
    assert_ne!(to_b[0], REQUEST, "a 38400 transmitter on a 9600 line");
    assert_eq!(to_b[1], REQUEST, "one at the line's settings");
}

#[test]
fn characters_in_error_are_delivered_as_the_receiver_says() {
    // Even parity sent, odd expected: every character has a parity error.
    let even = LineConfig::new(9600).unwrap().with_parity(Parity::Even);
    let odd = even.with_parity(Parity::Odd);
    let rx = |on_error| Receiver { config: odd, on_error };
    assert_eq!(heard(even, rx(OnError::Keep), &[0x01, 0x03]), [0x01, 0x03]);
    assert_eq!(heard(even, rx(OnError::Drop), &[0x01, 0x03]), []);
    assert_eq!(heard(even, rx(OnError::Mark), &[0x01, 0x03]), [0xFF, 0x00, 0x01, 0xFF, 0x00, 0x03]);
    assert_eq!(heard(even, rx(OnError::Zero), &[0x01, 0x03]), [0x00, 0x00]);
    assert_eq!(heard(even, Receiver { config: even, on_error: OnError::Drop }, &[0x01]), [0x01], "clean: kept");
}

#[test]
fn a_tap_hears_every_endpoint_at_the_instant_the_others_do_and_what_it_sends_is_refused_and_counted() {
    let mut w = wire(line_9600());
    let tap = w.attach_tap("tap");
    w.send(0, &[1, 2], T0);
    w.send(tap, &[0xEE; 5], T0);
    w.send(1, &[3], at(C * 10));
    let got: Vec<Delivery> = w.advance(at(C * 20)).into_iter().filter(|d| d.to == tap).collect();
    let delivery = |bytes: &[u8], at| Delivery { to: tap, bytes: bytes.to_vec(), at, tx: at_9600() };
    assert_eq!(got, [delivery(&[1, 2], at(C * 2)), delivery(&[3], at(C * 11))]);
    let stats = w.stats();
    assert_eq!(stats.characters, 3, "nothing of the tap's went on the wire");
    let e = &stats.endpoints[tap];
    assert_eq!((e.tap, e.refused, e.characters), (true, 5, 0));
    assert!(!stats.endpoints[0].tap);
}

/// 19200 8E1: a character is 572 917 ns.
fn at_19200() -> LineConfig {
    LineConfig::new(19_200).unwrap()
}

/// A response to [`REQUEST`], 01 03 02 00 2A 39 9B.
const RESPONSE: [u8; 7] = [0x01, 0x03, 0x02, 0x00, 0x2A, 0x39, 0x9B];

#[test]
fn two_endpoints_at_9600_on_a_19200_line_exchange_a_frame_cleanly_and_in_9600s_time() {
    let mut w = wire(LineOptions::new(at_19200()));
    let slow = Receiver { config: at_9600(), on_error: OnError::Drop };
    w.send_at(0, at_9600(), &REQUEST, T0);
    let end = at(C * 8);
    assert_eq!(w.next_wake(), Some(end), "eight characters of 9600, not of 19200");
    let to_b: Vec<Delivery> = w.advance(end).into_iter().filter(|d| d.to == 1).collect();
    assert_eq!(to_b.len(), 1);
    assert_eq!((to_b[0].at, to_b[0].tx), (end, at_9600()));
    assert_eq!(to_b[0].heard_by(slow), REQUEST, "clean at the sender's settings");
    // b answers after its own t3.5 (4 ms at 9600): a hears it clean, 7 characters of 9600 later.
    let answer = end.saturating_add(Duration::from_millis(5));
    w.send_at(1, at_9600(), &RESPONSE, answer);
    let to_a: Vec<Delivery> = w.advance(answer.saturating_add(C * 7)).into_iter().filter(|d| d.to == 0).collect();
    assert_eq!(to_a.len(), 1);
    assert_eq!((to_a[0].heard_by(slow), to_a[0].at), (RESPONSE.to_vec(), answer.saturating_add(C * 7)));
    let stats = w.stats();
    assert_eq!((stats.collisions, stats.endpoints[0].gap_violations, stats.endpoints[1].gap_violations), (0, 0, 0));
}

#[test]
fn an_endpoint_at_the_lines_19200_hears_garbage_from_endpoints_at_9600() {
    let mut w = wire(LineOptions::new(at_19200()));
    w.send_at(0, at_9600(), &REQUEST, T0);
    let to_c: Vec<Delivery> = w.advance(at(C * 8)).into_iter().filter(|d| d.to == 2).collect();
    assert_eq!(to_c.len(), 1);
    let fast = to_c[0].heard_by(Receiver { config: at_19200(), on_error: OnError::Keep });
    assert!(fast != REQUEST, "a 19200 receiver of a 9600 frame: {fast:02X?}");
    // And so does the wire's own sniffer, at the line's settings: no frame.
    assert_eq!(w.stats().frames, 0);
    // A frame sent at the line's settings is heard clean and sniffed.
    w.send(0, &REQUEST, at(Duration::from_millis(50)));
    let to_c: Vec<Delivery> = w.advance(at(Duration::from_millis(100))).into_iter().filter(|d| d.to == 2).collect();
    assert_eq!(to_c[0].heard_by(Receiver { config: at_19200(), on_error: OnError::Keep }), REQUEST);
    assert_eq!(w.stats().frames, 1);
}

#[test]
fn a_9600_run_and_a_19200_run_that_overlap_collide() {
    // c's 19200 character starts three quarters into a's 9600 one: it would not overlap a
    // character of the line's own 19200 (half of C), it does overlap one of 9600.
    let mut w = wire(LineOptions::new(at_19200()));
    w.send_at(0, at_9600(), &[0x55], T0);
    w.send_at(2, at_19200(), &[0xAA], at(C * 3 / 4));
    w.advance(at(Duration::from_millis(10)));
    assert_eq!(w.stats().collisions, 2, "both characters garbled");
    // The other way round: a 9600 character begun inside a 19200 one.
    let mut w = wire(LineOptions::new(at_19200()));
    w.send_at(2, at_19200(), &[0xAA], T0);
    w.send_at(0, at_9600(), &[0x55], at(C / 4));
    w.advance(at(Duration::from_millis(10)));
    assert_eq!(w.stats().collisions, 2);
    // Back to back, they don't: the 19200 character begins as the 9600 one ends.
    let mut w = wire(LineOptions::new(at_19200()));
    w.send_at(0, at_9600(), &[0x55], T0);
    w.send_at(2, at_19200(), &[0xAA], at(C));
    let got = w.advance(at(Duration::from_millis(10)));
    assert_eq!(w.stats().collisions, 0);
    let to_b: Vec<(Vec<u8>, LineConfig)> = got.into_iter().filter(|d| d.to == 1).map(|d| (d.bytes, d.tx)).collect();
    assert_eq!(to_b, [(vec![0x55], at_9600()), (vec![0xAA], at_19200())], "one run per sender's settings");
}
