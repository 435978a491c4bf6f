//! RTU receiver tests: every decoder case is fed whole, byte by byte, and with a second frame
//! in the same chunk, with and without garbage around it.

extern crate std;
use std::vec::Vec;

use super::*;
use crate::frame::{LineConfig, expire, feed};

/// 9600 8E1: t3.5 = 4.010417 ms.
fn codec(expect: Expect) -> RtuCodec {
    RtuCodec::new(LineTiming::new(&LineConfig::new(9600).unwrap()), expect)
}

/// SDP servo manual p.413: write 0x0BB8, 0x0000 to 0x0112 of unit 1.
const SDP_REQUEST: &[u8] = &[
    0x01, // unit
    0x10, // write multiple registers
    0x01, 0x12, // start address 0x0112
    0x00, 0x02, // two registers
    0x04, // byte count
    0x0B, 0xB8, // 0x0BB8 = 3000
    0x00, 0x00, // 0
    0xFC, 0xEB, // CRC, low byte first
];

/// Its response: start and quantity echoed.
const SDP_RESPONSE: &[u8] = &[
    0x01, // unit
    0x10, // write multiple registers
    0x01, 0x12, // start address
    0x00, 0x02, // quantity
    0xE0, 0x31, // CRC
];

/// 3G3RX p.4-168: read coils 7–12 of slave 8 (frame address 6).
const READ_COILS_REQUEST: &[u8] = &[
    0x08, // unit
    0x01, // read coils
    0x00, 0x06, // start (coil 7 in the manual's numbering)
    0x00, 0x06, // six coils
    0x5C, 0x90, // CRC
];

/// Its response: one byte of coil bits.
const READ_COILS_RESPONSE: &[u8] = &[
    0x08, // unit
    0x01, // read coils
    0x01, // byte count
    0x17, // coils 7..12 = 1,1,1,0,1,0
    0x12, 0x1A, // CRC
];

/// 3G3RX p.4-170: run command ON to slave 10 (the response is identical).
const WRITE_COIL: &[u8] = &[
    0x0A, // unit
    0x05, // write single coil
    0x00, 0x00, // coil 1
    0xFF, 0x00, // ON
    0x8D, 0x41, // CRC
];

/// An exception response: illegal data value to 0x08 from unit 1 (RKC manual).
const EXCEPTION: &[u8] = &[
    0x01, // unit
    0x88, // 0x08 | 0x80
    0x03, // illegal data value
    0x06, 0x01, // CRC
];

#[derive(Debug, PartialEq, Eq, Clone)]
enum Ev {
    Frame(Vec<u8>, Direction),
    Dropped(usize, DiscardReason),
}

fn frame(bytes: &[u8], direction: Direction) -> Ev {
    Ev::Frame(bytes.to_vec(), direction)
}

fn record(out: &mut Vec<Ev>) -> impl FnMut(RxEvent<'_>) + '_ {
    |ev| match ev {
        RxEvent::Frame(adu) => {
            let mut bytes = std::vec![adu.header.unit];
            bytes.extend_from_slice(adu.pdu);
            bytes.extend_from_slice(&crate::crc::crc16_wire(&bytes));
            out.push(Ev::Frame(bytes, adu.direction));
        }
        RxEvent::Discarded { bytes, reason, .. } => out.push(Ev::Dropped(bytes, reason)),
    }
}

/// Feeds `chunks` at their times (µs), then lets the line fall silent, and returns every event.
#[track_caller]
fn run(codec: &mut RtuCodec, chunks: &[(u64, &[u8])]) -> Vec<Ev> {
    let mut out = Vec::new();
    let mut last = Instant::ZERO;
    for &(t, bytes) in chunks {
        let now = Instant::from_micros(t);
        while let Some(deadline) = codec.poll_timeout().filter(|d| *d <= now) {
            expire(codec, deadline, record(&mut out));
        }
        feed(codec, now, bytes, record(&mut out));
        last = now;
    }
    while let Some(deadline) = codec.poll_timeout() {
        assert!(deadline >= last, "deadlines never go backwards");
        expire(codec, deadline, record(&mut out));
        last = deadline;
    }
    out
}

/// The same bytes as one chunk, byte by byte (1 µs apart), and in chunks of three.
#[track_caller]
fn run_all_ways(expect: Expect, input: &[u8]) -> Vec<Ev> {
    let whole = run(&mut codec(expect), &[(0, input)]);
    let bytes: Vec<(u64, &[u8])> = input.chunks(1).zip(0..).map(|(b, t)| (t, b)).collect();
    assert_eq!(run(&mut codec(expect), &bytes), whole, "byte by byte");
    let threes: Vec<(u64, &[u8])> = input.chunks(3).zip(0..).map(|(b, t)| (t, b)).collect();
    assert_eq!(run(&mut codec(expect), &threes), whole, "in threes");
    whole
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

#[test]
fn golden_frames_complete_by_length_with_their_direction() {
    let cases = [
        (SDP_REQUEST, Direction::Request),
        (SDP_RESPONSE, Direction::Response),
        (READ_COILS_REQUEST, Direction::Request),
        (READ_COILS_RESPONSE, Direction::Response),
        (WRITE_COIL, Direction::Either),
        (EXCEPTION, Direction::Response),
    ];
    for (bytes, direction) in cases {
        assert_eq!(run_all_ways(Expect::Both, bytes), [frame(bytes, direction)], "{bytes:02X?}");
    }
}

#[test]
fn a_frame_completes_on_its_last_byte_without_waiting_for_silence() {
    let mut c = codec(Expect::Both);
    let (head, last) = SDP_REQUEST.split_at(SDP_REQUEST.len() - 1);
    feed(&mut c, Instant::ZERO, head, |_| panic!("incomplete"));
    assert_eq!(c.poll_timeout(), Some(Instant::from_nanos(4_010_417)), "waiting for the rest, at most t3.5");
    let mut got = Vec::new();
    feed(&mut c, Instant::from_micros(1), last, record(&mut got));
    assert_eq!(got, [frame(SDP_REQUEST, Direction::Request)]);
    assert_eq!(c.poll_timeout(), None, "nothing left to time");
}

#[test]
fn two_frames_in_one_chunk_are_two_frames() {
    let input = cat(&[READ_COILS_REQUEST, READ_COILS_RESPONSE, SDP_REQUEST, SDP_RESPONSE]);
    assert_eq!(
        run_all_ways(Expect::Both, &input),
        [
            frame(READ_COILS_REQUEST, Direction::Request),
            frame(READ_COILS_RESPONSE, Direction::Response),
            frame(SDP_REQUEST, Direction::Request),
            frame(SDP_RESPONSE, Direction::Response),
        ]
    );
}

#[test]
fn garbage_before_and_between_frames_costs_only_the_garbage() {
    let input = cat(&[&[0xFF, 0x00, 0x13], SDP_REQUEST, &[0x55, 0xAA], READ_COILS_RESPONSE]);
    let events = run_all_ways(Expect::Both, &input);
    assert_eq!(
        events,
        [
            Ev::Dropped(3, DiscardReason::Noise),
            frame(SDP_REQUEST, Direction::Request),
            // 55 AA reads as an exception response from unit 0x55 whose CRC fails.
            Ev::Dropped(2, DiscardReason::ChecksumMismatch),
            frame(READ_COILS_RESPONSE, Direction::Response),
        ]
    );
}

#[test]
fn a_bad_crc_is_dropped_counted_and_the_next_frame_still_found() {
    let mut bad = SDP_REQUEST.to_vec();
    bad[8] ^= 0x40;
    let input = cat(&[&bad, SDP_RESPONSE]);
    let mut c = codec(Expect::Both);
    let events = run(&mut c, &[(0, &input)]);
    assert_eq!(events.last(), Some(&frame(SDP_RESPONSE, Direction::Response)));
    assert_eq!(events.len(), 2);
    assert!(matches!(events[0], Ev::Dropped(13, DiscardReason::ChecksumMismatch)), "{events:?}");
    assert_eq!(c.stats().checksum_errors, 1);
    assert_eq!(c.stats().frames, 1);
    assert_eq!(c.stats().discarded_bytes, 13);
    assert_eq!(run_all_ways(Expect::Both, &input), events);
}

#[test]
fn a_frame_cut_short_by_silence_is_dropped_and_the_next_one_found() {
    let mut c = codec(Expect::Both);
    let events = run(&mut c, &[(0, &SDP_REQUEST[..7]), (10_000, SDP_RESPONSE)]);
    assert_eq!(events, [Ev::Dropped(7, DiscardReason::TooShort), frame(SDP_RESPONSE, Direction::Response)]);
}

#[test]
fn a_longer_incomplete_timeout_keeps_a_frame_split_by_usb_latency_whole() {
    let mut c = codec(Expect::Both).with_incomplete_timeout(Duration::from_millis(20));
    let events = run(&mut c, &[(0, &SDP_REQUEST[..7]), (16_000, &SDP_REQUEST[7..])]);
    assert_eq!(events, [frame(SDP_REQUEST, Direction::Request)]);
}

#[test]
fn custom_function_codes_end_at_the_silent_interval() {
    let mut custom = std::vec![0x05, 0x41, 0x01, 0x02, 0x03];
    custom.extend_from_slice(&crate::crc::crc16_wire(&custom));
    let mut c = codec(Expect::Both);
    let mut got = Vec::new();
    feed(&mut c, Instant::ZERO, &custom, record(&mut got));
    assert!(got.is_empty(), "no length is known for 0x41");
    let gap = Instant::from_nanos(4_010_417);
    assert_eq!(c.poll_timeout(), Some(gap));
    expire(&mut c, Instant::from_nanos(4_010_416), record(&mut got));
    assert!(got.is_empty(), "one nanosecond before t3.5, still waiting");
    expire(&mut c, gap, record(&mut got));
    assert_eq!(got, [frame(&custom, Direction::Either)]);
    assert_eq!(run_all_ways(Expect::Both, &custom), [frame(&custom, Direction::Either)]);
}

#[test]
fn a_long_loopback_ends_at_the_gap_and_a_short_one_by_length() {
    let mut long = std::vec![0x01, 0x08, 0x00, 0x00, 0x12, 0x34, 0x56, 0x78];
    long.extend_from_slice(&crate::crc::crc16_wire(&long));
    assert_eq!(run_all_ways(Expect::Both, &long), [frame(&long, Direction::Either)]);
    let mut short = std::vec![0x01, 0x08, 0x00, 0x00, 0x1F, 0x34];
    short.extend_from_slice(&crate::crc::crc16_wire(&short));
    let mut c = codec(Expect::Both);
    let mut got = Vec::new();
    feed(&mut c, Instant::ZERO, &short, record(&mut got));
    assert_eq!(got, [frame(&short, Direction::Either)], "complete at once");
}

#[test]
fn expecting_only_requests_reads_a_response_as_noise() {
    let events = run_all_ways(Expect::Requests, READ_COILS_RESPONSE);
    assert_eq!(events, [Ev::Dropped(6, DiscardReason::TooShort)]);
    let events = run_all_ways(Expect::Responses, READ_COILS_REQUEST);
    assert!(events.iter().all(|e| matches!(e, Ev::Dropped(..))), "{events:?}");
}

#[test]
fn endless_noise_never_grows_past_one_frame_and_never_ends_the_receiver() {
    let noise: Vec<u8> = (0..5000u32).map(|i| i.wrapping_mul(2_654_435_761).to_be_bytes()[1]).collect();
    let mut c = codec(Expect::Both);
    let mut events = Vec::new();
    for chunk in noise.chunks(97) {
        feed(&mut c, Instant::ZERO, chunk, record(&mut events));
        assert!(c.len - c.start <= MAX_ADU_LEN + 1);
    }
    feed(&mut c, Instant::ZERO, SDP_REQUEST, record(&mut events));
    expire(&mut c, Instant::from_secs(1), record(&mut events));
    assert_eq!(events.last(), Some(&frame(SDP_REQUEST, Direction::Request)));
}

#[test]
fn strict_t1_5_drops_a_frame_with_a_gap_inside() {
    let mut c = codec(Expect::Both).with_strict_t1_5(true);
    // 1.8 ms > t1.5 (1.719 ms) between bytes 6 and 7.
    let events = run(&mut c, &[(0, &SDP_REQUEST[..6]), (1_800, &SDP_REQUEST[6..])]);
    // The six bytes before the gap, then the seven after it, which start no frame.
    assert_eq!(events, [Ev::Dropped(13, DiscardReason::InterCharacterGap)]);
    assert!(!events.contains(&frame(SDP_REQUEST, Direction::Request)));
    let mut c = codec(Expect::Both).with_strict_t1_5(true);
    let events = run(&mut c, &[(0, &SDP_REQUEST[..6]), (1_700, &SDP_REQUEST[6..])]);
    assert_eq!(events, [frame(SDP_REQUEST, Direction::Request)]);
}

#[test]
fn encoders_reproduce_the_seed_frames() {
    use crate::pdu::{Registers, WriteRegisters, WrittenRegisters};
    let values = [0x0BB8, 0x0000];
    let request =
        Request::WriteMultipleRegisters(WriteRegisters::new(0x0112, Registers::from_values(&values)).unwrap());
    let mut out = [0xA5u8; MAX_ADU_LEN + 1];
    let n = encode_request(1, &request, &mut out).unwrap();
    assert_eq!(&out[..n], SDP_REQUEST);
    assert_eq!(out[n], 0xA5);
    let response = Response::WriteMultipleRegisters(WrittenRegisters::new(0x0112, 2).unwrap());
    let n = encode_response(1, &response, &mut out).unwrap();
    assert_eq!(&out[..n], SDP_RESPONSE);
    assert_eq!(encode_pdu(1, &[0x03], &mut [0u8; 3]), Err(BufferTooSmall { needed: 4, available: 3 }));
}

#[test]
fn frame_view_checks_length_and_crc() {
    let f = RtuFrame::new_checked(SDP_RESPONSE).unwrap();
    assert_eq!(f.unit(), 1);
    assert_eq!(f.pdu(), &SDP_RESPONSE[1..6]);
    assert_eq!(RtuFrame::new_checked(&SDP_RESPONSE[..3]), Err(DiscardReason::TooShort));
    assert_eq!(RtuFrame::new_checked(&[0u8; 257]), Err(DiscardReason::TooLong));
    assert_eq!(RtuFrame::new_checked(&SDP_REQUEST[..12]), Err(DiscardReason::ChecksumMismatch));
}

#[test]
fn a_frame_of_256_bytes_is_the_largest_accepted() {
    use crate::pdu::{BitValues, Bits};
    let bits = [0x55u8; 250];
    let response = Response::ReadCoils(BitValues::new(Bits::from_wire(&bits, 2000).unwrap()).unwrap());
    let mut out = [0u8; MAX_ADU_LEN];
    let n = encode_response(7, &response, &mut out).unwrap();
    assert_eq!(n, 255);
    assert_eq!(run_all_ways(Expect::Responses, &out[..n]), [frame(&out[..n], Direction::Response)]);
}

#[test]
fn an_unpaced_stream_finds_frames_by_length_and_ends_unknown_ones_at_the_frame_gap() {
    let mut c = RtuCodec::new(LineTiming::unpaced(), Expect::Both).with_frame_gap(Duration::from_millis(50));
    assert_eq!(c.inter_frame_gap(), Duration::ZERO, "nothing to wait before transmitting");
    let mut got = Vec::new();
    feed(&mut c, Instant::ZERO, &SDP_REQUEST[..5], record(&mut got));
    assert_eq!(c.poll_timeout(), Some(Instant::from_millis(50)), "a split frame waits for its rest");
    feed(&mut c, Instant::from_millis(10), &SDP_REQUEST[5..], record(&mut got));
    assert_eq!(got, [frame(SDP_REQUEST, Direction::Request)]);
    let mut custom = std::vec![0x05, 0x41, 0x01];
    custom.extend_from_slice(&crate::crc::crc16_wire(&custom));
    feed(&mut c, Instant::from_millis(20), &custom, record(&mut got));
    assert_eq!(c.poll_timeout(), Some(Instant::from_millis(70)));
    expire(&mut c, Instant::from_millis(70), record(&mut got));
    assert_eq!(got.last(), Some(&frame(&custom, Direction::Either)));
}

mod chunking {
    use proptest::prelude::*;

    use super::*;

    const FRAMES: [&[u8]; 6] =
        [SDP_REQUEST, SDP_RESPONSE, READ_COILS_REQUEST, READ_COILS_RESPONSE, WRITE_COIL, EXCEPTION];

    fn chunked(input: &[u8], size: usize) -> Vec<(u64, &[u8])> {
        input.chunks(size).zip(0..).map(|(b, t)| (t, b)).collect()
    }

    proptest! {
        /// Bytes are taken in runs up to the next point where a verdict can change; that must
        /// be invisible: any mix of frames and noise gives the same events however it comes.
        #[test]
        fn chunking_never_changes_what_is_found(
            parts in prop::collection::vec(
                prop_oneof![
                    (0..FRAMES.len()).prop_map(|i| FRAMES[i].to_vec()),
                    prop::collection::vec(any::<u8>(), 1..40),
                ],
                1..8,
            ),
        ) {
            let input = parts.concat();
            let whole = run(&mut codec(Expect::Both), &[(0, &input)]);
            prop_assert_eq!(&run(&mut codec(Expect::Both), &chunked(&input, 1)), &whole, "byte by byte");
            prop_assert_eq!(&run(&mut codec(Expect::Both), &chunked(&input, 7)), &whole, "in sevens");
            let accounted: usize = whole
                .iter()
                .map(|e| match e {
                    Ev::Frame(b, _) => b.len(),
                    Ev::Dropped(n, _) => *n,
                })
                .sum();
            prop_assert_eq!(accounted, input.len(), "every byte is a frame's or a discard's");
        }
    }
}

#[test]
fn a_discarded_run_carries_the_address_and_function_code_it_began_with() {
    let mut bad = SDP_RESPONSE.to_vec();
    bad[7] ^= 0x5A; // the CRC's high byte
    let mut c = codec(Expect::Responses);
    let mut heads = Vec::new();
    let mut on = |e: RxEvent<'_>| {
        if let RxEvent::Discarded { reason, head, .. } = e {
            heads.push((reason, head));
        }
    };
    feed(&mut c, Instant::ZERO, &bad, &mut on);
    expire(&mut c, Instant::from_millis(10), &mut on);
    assert_eq!(heads, [(DiscardReason::ChecksumMismatch, Some((0x01, 0x10)))]);
    // A lone byte is too short to name anything.
    let mut c = codec(Expect::Responses);
    let mut heads = Vec::new();
    let mut on = |e: RxEvent<'_>| {
        if let RxEvent::Discarded { head, .. } = e {
            heads.push(head);
        }
    };
    feed(&mut c, Instant::ZERO, &[0xFF], &mut on);
    expire(&mut c, Instant::from_millis(10), &mut on);
    assert_eq!(heads, [None]);
}

/// From the issue: 0x10 to unit 0x11 with quantity 0 and byte count 0 but six data bytes. The
/// CRC is right over all 15 bytes and wrong over the 9 the byte count implies.
const COUNT_DISAGREES: &[u8] = &[
    0x11, // unit
    0x10, // write multiple registers
    0x01, 0x60, // start address
    0x00, 0x00, // quantity 0
    0x00, // byte count 0
    0x02, 0x2B, 0x00, 0x01, 0x00, 0x64, // six data bytes nobody counted
    0x8C, 0x88, // CRC over all of it
];

#[test]
fn a_frame_whose_crc_fails_at_its_length_but_agrees_at_the_gap_is_the_silence_delimited_frame() {
    assert_eq!(run_all_ways(Expect::Requests, COUNT_DISAGREES), [frame(COUNT_DISAGREES, Direction::Request)]);
    // Both layouts of 0x10 are contradicted; the slave's setting cannot tell which.
    assert_eq!(run_all_ways(Expect::Both, COUNT_DISAGREES), [frame(COUNT_DISAGREES, Direction::Either)]);
    let mut c = codec(Expect::Requests);
    let _ = run(&mut c, &[(0, COUNT_DISAGREES)]);
    assert_eq!(c.stats().frames, 1);
    assert_eq!(c.stats().checksum_errors, 0, "not counted as a checksum error");
    assert_eq!(c.stats().discarded_bytes, 0);
}

#[test]
fn the_silence_delimited_frame_is_taken_at_the_gap_and_ends_with_its_last_byte() {
    let mut c = codec(Expect::Requests);
    feed(&mut c, Instant::from_micros(100), COUNT_DISAGREES, |ev| panic!("nothing before the gap: {ev:?}"));
    let gap = Instant::from_micros(100).saturating_add(Duration::from_nanos(4_010_417));
    assert_eq!(c.poll_timeout(), Some(gap), "t3.5 after the last byte");
    let mut ends = Vec::new();
    expire(&mut c, gap, |ev| match ev {
        RxEvent::Frame(adu) => ends.push((adu.header.unit, adu.pdu.len(), adu.end)),
        RxEvent::Discarded { .. } => panic!("not noise: {ev:?}"),
    });
    assert_eq!(ends, [(0x11, 12, Instant::from_micros(100))]);
}

#[test]
fn a_silence_delimited_run_that_fails_its_crc_too_is_one_checksum_error() {
    let mut bad = COUNT_DISAGREES.to_vec();
    bad[9] ^= 0x01;
    let mut c = codec(Expect::Requests);
    assert_eq!(run(&mut c, &[(0, &bad)]), [Ev::Dropped(15, DiscardReason::ChecksumMismatch)]);
    assert_eq!(c.stats().checksum_errors, 1);
    assert_eq!(c.stats().frames, 0);
}

#[test]
fn a_frame_found_inside_the_run_wins_over_the_silence_delimited_run() {
    // A bad frame then a good one without a gap: the good one is found by length at once, and
    // the run before it is noise even if, by chance, the CRC over both agreed.
    let mut bad = SDP_REQUEST.to_vec();
    bad[8] ^= 0x40;
    let input = cat(&[&bad, READ_COILS_REQUEST]);
    assert_eq!(
        run_all_ways(Expect::Requests, &input),
        [Ev::Dropped(13, DiscardReason::ChecksumMismatch), frame(READ_COILS_REQUEST, Direction::Request)]
    );
}

#[test]
fn the_silence_delimited_frame_needs_a_clean_start_and_the_next_frame_after_the_gap_is_found() {
    // One byte of noise before it: the run does not start after a frame or a gap.
    let noisy = cat(&[&[0x00], COUNT_DISAGREES]);
    let events = run_all_ways(Expect::Requests, &noisy);
    assert!(events.iter().all(|e| matches!(e, Ev::Dropped(..))), "{events:?}");
    assert_eq!(events.iter().map(|e| if let Ev::Dropped(n, _) = e { *n } else { 0 }).sum::<usize>(), 16);
    // After the gap, the next frame is found as usual.
    let mut c = codec(Expect::Requests);
    let events = run(&mut c, &[(0, COUNT_DISAGREES), (10_000, READ_COILS_REQUEST)]);
    assert_eq!(events, [frame(COUNT_DISAGREES, Direction::Request), frame(READ_COILS_REQUEST, Direction::Request)]);
}

#[test]
fn a_corrupted_crc_is_discarded_as_a_checksum_mismatch_with_unit_and_pdu_kept() {
    let mut frame = SDP_RESPONSE.to_vec();
    assert!(corrupt_crc(&mut frame));
    assert_eq!(frame[..frame.len() - 2], SDP_RESPONSE[..SDP_RESPONSE.len() - 2]);
    assert_eq!(RtuFrame::new_checked(&frame).err(), Some(DiscardReason::ChecksumMismatch));
    // Not a whole good frame: left alone.
    let mut short = std::vec![0x01, 0x03];
    assert!(!corrupt_crc(&mut short));
    assert_eq!(short, [0x01, 0x03]);
    let mut bad = frame.clone();
    assert!(!corrupt_crc(&mut bad));
    assert_eq!(bad, frame);
}
