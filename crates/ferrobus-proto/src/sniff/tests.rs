//! The sniffer on explicit time at 9600 8E1 (a character is 1.145833 ms, t1.5 1.71875 ms,
//! t3.5 4.010417 ms): every exchange fed whole, byte by byte, and as two frames in one chunk.

extern crate std;

use core::time::Duration;
use std::vec;
use std::vec::Vec;

use super::*;
use crate::frame::LineConfig;
use crate::frame::rtu::encode_pdu;

/// What an event said, owned.
#[derive(Clone, PartialEq, Debug)]
enum Seen {
    Frame { adu: Vec<u8>, role: Role, crc_ok: bool, time: WireTime, reply: Option<Reply> },
    Fragment { bytes: Vec<u8>, kind: FragmentKind, time: WireTime },
    Unanswered(Unanswered),
}

fn own(event: SniffEvent<'_>) -> Seen {
    match event {
        SniffEvent::Frame(f) => {
            Seen::Frame { adu: f.adu().to_vec(), role: f.role, crc_ok: f.crc_ok, time: f.time, reply: f.reply }
        }
        SniffEvent::Fragment(f) => Seen::Fragment { bytes: f.bytes.to_vec(), kind: f.kind, time: f.time },
        SniffEvent::Unanswered(u) => Seen::Unanswered(u),
    }
}

fn timing() -> LineTiming {
    LineTiming::new(&LineConfig::new(9600).unwrap())
}

fn char_time() -> Duration {
    timing().char_time()
}

fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut out = [0xA5u8; 256];
    let n = encode_pdu(unit, pdu, &mut out).unwrap();
    out[..n].to_vec()
}

/// How the bytes reach the sniffer.
#[derive(Clone, Copy, Debug)]
enum Delivery {
    /// Each frame in one chunk, when its last byte has ended.
    Whole,
    /// Each byte when it has ended.
    ByteByByte,
}

/// Frames on the wire: each starts `gap` after the previous one ended (the first at 10 ms).
fn on_wire(frames: &[(&[u8], Duration)]) -> Vec<(Vec<u8>, Instant, Instant)> {
    let mut at = Instant::from_millis(10);
    let mut out = Vec::new();
    for (bytes, gap) in frames {
        let start = at.saturating_add(*gap);
        let end = start.saturating_add(timing().transmit_time(bytes.len()));
        out.push((bytes.to_vec(), start, end));
        at = end;
    }
    out
}

/// Sniffs `frames` delivered as `delivery`, expiring the timeouts as they come, then to the end.
fn sniff(frames: &[(&[u8], Duration)], delivery: Delivery) -> Vec<Seen> {
    let mut sniffer = Sniffer::new(timing());
    let mut seen = Vec::new();
    let mut chunks: Vec<(Vec<u8>, Instant)> = Vec::new();
    for (bytes, start, end) in on_wire(frames) {
        match delivery {
            Delivery::Whole => chunks.push((bytes, end)),
            Delivery::ByteByByte => {
                for (i, b) in bytes.iter().enumerate() {
                    chunks.push((vec![*b], start.saturating_add(timing().transmit_time(i + 1))));
                }
            }
        }
    }
    for (bytes, at) in chunks {
        while let Some(deadline) = sniffer.poll_timeout().filter(|d| *d <= at) {
            sniffer.expire(deadline, |e| seen.push(own(e)));
        }
        sniffer.feed(at, &bytes, |e| seen.push(own(e)));
    }
    while let Some(deadline) = sniffer.poll_timeout() {
        sniffer.expire(deadline, |e| seen.push(own(e)));
    }
    sniffer.finish(|e| seen.push(own(e)));
    seen
}

fn frames(seen: &[Seen]) -> Vec<(Vec<u8>, Role, bool)> {
    seen.iter()
        .filter_map(|s| match s {
            Seen::Frame { adu, role, crc_ok, .. } => Some((adu.clone(), *role, *crc_ok)),
            _ => None,
        })
        .collect()
}

fn ms(x: f64) -> Duration {
    Duration::from_secs_f64(x / 1e3)
}

#[test]
fn a_read_and_its_reply_are_a_request_and_a_paired_response_fed_whole_or_byte_by_byte() {
    let request = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02]);
    let reply = rtu(1, &[0x03, 0x04, 0x00, 0x2A, 0x00, 0x2B]);
    // 5 characters of silence before the reply (the slave's t3.5 plus a little).
    let wire = [(&request[..], Duration::ZERO), (&reply[..], char_time() * 5)];
    let placed = on_wire(&wire);
    for delivery in [Delivery::Whole, Delivery::ByteByByte] {
        let seen = sniff(&wire, delivery);
        assert_eq!(seen.len(), 2, "{delivery:?}: {seen:#?}");
        let Seen::Frame { role, crc_ok, time, reply: None, .. } = &seen[0] else { panic!("{seen:?}") };
        assert_eq!((*role, *crc_ok), (Role::Request, true), "{delivery:?}");
        assert_eq!((time.start, time.end), (placed[0].1, placed[0].2), "{delivery:?}: the request's wire time");
        assert_eq!(time.silence_before, None, "nothing was heard before it");
        let Seen::Frame { role, crc_ok, time, reply: Some(paired), .. } = &seen[1] else { panic!("{seen:?}") };
        assert_eq!((*role, *crc_ok), (Role::Response, true), "{delivery:?}");
        assert_eq!((time.start, time.end), (placed[1].1, placed[1].2), "{delivery:?}: the reply's wire time");
        assert_eq!(time.silence_before, Some(char_time() * 5), "{delivery:?}");
        assert!(!time.t3_5_violation && !time.t1_5_violation, "{delivery:?}: {time:?}");
        assert_eq!(paired.request_end, placed[0].2);
        assert_eq!(paired.response_time, placed[1].2.saturating_duration_since(placed[0].2));
    }
}

#[test]
fn two_frames_in_one_chunk_are_both_found_and_look_back_to_back() {
    let request = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02]);
    let reply = rtu(1, &[0x03, 0x04, 0x00, 0x2A, 0x00, 0x2B]);
    let mut sniffer = Sniffer::new(timing());
    let mut seen = Vec::new();
    let chunk: Vec<u8> = request.iter().chain(&reply).copied().collect();
    let at = Instant::from_millis(100);
    sniffer.feed(at, &chunk, |e| seen.push(own(e)));
    sniffer.finish(|e| seen.push(own(e)));
    assert_eq!(frames(&seen), [(request.clone(), Role::Request, true), (reply.clone(), Role::Response, true)]);
    let Seen::Frame { time, reply: Some(_), .. } = &seen[1] else { panic!("{seen:?}") };
    assert_eq!(time.end, at, "the chunk's last byte ended when it arrived");
    // The gap between them was inside the chunk, so it cannot be seen: reported as none.
    assert_eq!(time.silence_before, Some(Duration::ZERO));
    assert!(time.t3_5_violation);
    let Seen::Frame { time: first, .. } = &seen[0] else { panic!() };
    assert_eq!(first.end, at.saturating_sub(timing().transmit_time(reply.len())));
}

#[test]
fn a_gap_under_t3_5_before_a_frame_and_one_over_t1_5_inside_it_are_violations() {
    let request = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02]);
    let reply = rtu(1, &[0x03, 0x04, 0x00, 0x2A, 0x00, 0x2B]);
    let mut sniffer = Sniffer::new(timing());
    let mut seen = Vec::new();
    let c = char_time();
    let t0 = Instant::from_millis(10);
    let request_end = t0.saturating_add(c * 8);
    sniffer.feed(request_end, &request, |e| seen.push(own(e)));
    // The reply begins 2 characters after the request, byte by byte, and stops for 2
    // characters after its third byte.
    let mut end = request_end.saturating_add(c * 2);
    for (i, byte) in reply.iter().enumerate() {
        end = end.saturating_add(if i == 3 { c * 3 } else { c });
        sniffer.feed(end, &[*byte], |e| seen.push(own(e)));
    }
    sniffer.finish(|e| seen.push(own(e)));
    let Seen::Frame { role: Role::Response, time, .. } = &seen[1] else { panic!("{seen:?}") };
    assert_eq!(time.silence_before, Some(c * 2));
    assert_eq!(time.longest_gap, c * 2);
    assert!(time.t3_5_violation && time.t1_5_violation, "{time:?}");
}

#[test]
fn a_frame_with_a_bad_crc_is_a_frame_marked_bad_and_the_next_one_is_found() {
    let mut bad = rtu(1, &[0x06, 0x00, 0x05, 0x12, 0x34]);
    let last = bad.len() - 1;
    bad[last] ^= 0x5A;
    let good = rtu(2, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    let wire = [(&bad[..], Duration::ZERO), (&good[..], ms(10.0))];
    for delivery in [Delivery::Whole, Delivery::ByteByByte] {
        let seen = sniff(&wire, delivery);
        assert_eq!(frames(&seen), [(bad.clone(), Role::Request, false), (good.clone(), Role::Request, true)]);
        // The bad request waited, but its silence is expected: no "unanswered" for it.
        assert!(!seen.iter().any(|s| matches!(s, Seen::Unanswered(_))), "{delivery:?}: {seen:#?}");
    }
    // Both in one chunk: the bad one is still whole and marked bad.
    let mut sniffer = Sniffer::new(timing());
    let mut seen = Vec::new();
    let chunk: Vec<u8> = bad.iter().chain(&good).copied().collect();
    sniffer.feed(Instant::from_millis(50), &chunk, |e| seen.push(own(e)));
    sniffer.finish(|e| seen.push(own(e)));
    assert_eq!(frames(&seen), [(bad.clone(), Role::Request, false), (good, Role::Request, true)]);
}

#[test]
fn a_bad_crc_reply_is_a_response_paired_with_its_request() {
    let request = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    let mut reply = rtu(1, &[0x03, 0x02, 0x00, 0x07]);
    reply[4] ^= 0xFF;
    let seen = sniff(&[(&request[..], Duration::ZERO), (&reply[..], ms(5.0))], Delivery::Whole);
    let Seen::Frame { role: Role::Response, crc_ok: false, reply: Some(_), .. } = &seen[1] else { panic!("{seen:#?}") };
}

#[test]
fn a_frame_cut_short_by_silence_is_a_partial_frame_and_garbage_is_noise() {
    let request = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02]);
    let noise = [0xFFu8, 0x00, 0xFE];
    let next = rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]);
    let wire = [(&request[..5], Duration::ZERO), (&noise[..], ms(10.0)), (&next[..], ms(10.0))];
    for delivery in [Delivery::Whole, Delivery::ByteByByte] {
        let seen = sniff(&wire, delivery);
        assert_eq!(seen.len(), 3, "{delivery:?}: {seen:#?}");
        let Seen::Fragment { bytes, kind: FragmentKind::Partial { expected: Some(8) }, .. } = &seen[0] else {
            panic!("{delivery:?}: {seen:#?}")
        };
        assert_eq!(bytes[..], request[..5]);
        let Seen::Fragment { bytes, kind: FragmentKind::Noise, time } = &seen[1] else { panic!("{seen:#?}") };
        assert_eq!(bytes[..], noise);
        assert_eq!(time.silence_before, Some(ms(10.0)));
        assert_eq!(frames(&seen[2..]), [(next.clone(), Role::Request, true)]);
    }
}

#[test]
fn an_echoed_write_is_a_request_then_a_response_and_a_second_write_a_request_again() {
    let write = rtu(1, &[0x06, 0x00, 0x05, 0x12, 0x34]);
    let wire = [(&write[..], Duration::ZERO), (&write[..], ms(5.0)), (&write[..], ms(10.0))];
    for delivery in [Delivery::Whole, Delivery::ByteByByte] {
        let seen = sniff(&wire, delivery);
        let roles: Vec<Role> = frames(&seen).into_iter().map(|f| f.1).collect();
        assert_eq!(roles, [Role::Request, Role::Response, Role::Request], "{delivery:?}");
    }
}

#[test]
fn an_exception_answers_its_request_and_a_reply_from_another_unit_does_not() {
    let request = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    let stranger = rtu(2, &[0x83, 0x02]);
    let exception = rtu(1, &[0x83, 0x02]);
    let seen =
        sniff(&[(&request[..], Duration::ZERO), (&stranger[..], ms(5.0)), (&exception[..], ms(5.0))], Delivery::Whole);
    let Seen::Frame { role: Role::Response, reply: None, .. } = &seen[1] else { panic!("{seen:#?}") };
    let Seen::Frame { role: Role::Response, reply: Some(_), .. } = &seen[2] else { panic!("{seen:#?}") };
}

#[test]
fn a_request_without_a_reply_is_unanswered_when_the_next_comes_but_a_broadcast_waits_for_nothing() {
    let first = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    let broadcast = rtu(0, &[0x06, 0x00, 0x01, 0x00, 0x02]);
    let third = rtu(2, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    let placed = on_wire(&[(&first[..], Duration::ZERO), (&broadcast[..], ms(100.0)), (&third[..], ms(10.0))]);
    let seen =
        sniff(&[(&first[..], Duration::ZERO), (&broadcast[..], ms(100.0)), (&third[..], ms(10.0))], Delivery::Whole);
    let unanswered: Vec<&Unanswered> = seen
        .iter()
        .filter_map(|s| match s {
            Seen::Unanswered(u) => Some(u),
            _ => None,
        })
        .collect();
    assert_eq!(unanswered, [&Unanswered { unit: 1, function: 0x03, request_end: placed[0].2 }]);
    // Reported as the broadcast began, before it.
    assert!(matches!(seen[1], Seen::Unanswered(_)), "{seen:#?}");
    let Seen::Frame { role: Role::Request, .. } = &seen[2] else { panic!("{seen:#?}") };
}

#[test]
fn every_byte_of_a_long_noise_burst_is_reported_without_a_frame() {
    let mut sniffer = Sniffer::new(timing());
    let mut noise_bytes = 0usize;
    let mut frames_seen = 0usize;
    // 3000 bytes of 0xFF: no frame starts anywhere in them.
    let burst = [0xFFu8; 3000];
    sniffer.feed(Instant::from_secs(4), &burst, |e| match e {
        SniffEvent::Fragment(f) => noise_bytes += f.bytes.len(),
        _ => frames_seen += 1,
    });
    sniffer.finish(|e| match e {
        SniffEvent::Fragment(f) => noise_bytes += f.bytes.len(),
        _ => frames_seen += 1,
    });
    assert_eq!((noise_bytes, frames_seen), (3000, 0));
}

#[test]
fn a_frame_is_reported_once_at_its_length_without_waiting_for_the_silence() {
    let request = rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02]);
    let mut sniffer = Sniffer::new(timing());
    let mut seen = Vec::new();
    sniffer.feed(Instant::from_millis(20), &request, |e| seen.push(own(e)));
    assert_eq!(frames(&seen), [(request, Role::Request, true)]);
    assert_eq!(sniffer.poll_timeout(), None, "nothing is left to settle");
}

#[test]
fn the_frame_view_gives_unit_function_pdu_crc_and_the_parsed_pdu() {
    let reply = rtu(7, &[0x83, 0x02]);
    let mut sniffer = Sniffer::new(timing());
    let mut checked = false;
    sniffer.feed(Instant::from_millis(20), &reply, |e| {
        let SniffEvent::Frame(f) = e else { panic!("{e:?}") };
        assert_eq!((f.unit(), f.function(), f.pdu()), (7, 0x83, &[0x83, 0x02][..]));
        assert_eq!(f.crc(), u16::from_le_bytes([reply[3], reply[4]]));
        assert!(!f.is_broadcast());
        assert!(f.response().unwrap().exception().is_some());
        assert!(f.request().is_err());
        checked = true;
    });
    assert!(checked);
}

proptest::proptest! {
    /// Whatever comes, and however it is chunked and timed, every byte comes out once, in a
    /// frame or a fragment, in order (the `sniffer` fuzz target checks the same at length).
    #[test]
    fn every_byte_comes_out_once_in_order_in_a_frame_or_a_fragment(
        steps in proptest::collection::vec((0u16..6000, proptest::collection::vec(proptest::prelude::any::<u8>(), 0..40)), 0..40),
        frames in proptest::collection::vec(0usize..3, 0..40),
    ) {
        let mut sniffer = Sniffer::new(timing());
        let (mut fed, mut out) = (Vec::new(), Vec::new());
        let mut now = Instant::from_millis(1);
        let take = |e: SniffEvent<'_>, out: &mut Vec<u8>| match e {
            SniffEvent::Frame(f) => out.extend_from_slice(f.adu()),
            SniffEvent::Fragment(f) => out.extend_from_slice(f.bytes),
            SniffEvent::Unanswered(_) => {}
        };
        for (i, (gap, noise)) in steps.iter().enumerate() {
            // Noise, or a real frame now and then, so that both paths are taken.
            let bytes = match frames.get(i) {
                Some(1) => rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02]),
                Some(2) => rtu(1, &[0x03, 0x02, 0x00, 0x07]),
                _ => noise.clone(),
            };
            let at = now.saturating_add(Duration::from_micros(u64::from(*gap)));
            while let Some(deadline) = sniffer.poll_timeout().filter(|d| *d <= at) {
                sniffer.expire(deadline.max(now), |e| take(e, &mut out));
            }
            sniffer.feed(at, &bytes, |e| take(e, &mut out));
            fed.extend_from_slice(&bytes);
            now = at;
        }
        sniffer.finish(|e| take(e, &mut out));
        proptest::prop_assert_eq!(out, fed);
    }
}
