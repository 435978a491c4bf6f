//! Master engine tests with explicit time: gaps before transmitting, matching replies,
//! timeouts, broadcast, echo.

extern crate std;
use std::string::ToString;
use std::vec::Vec;

use super::*;
use crate::crc::crc16_wire;
use crate::frame::mbap::MbapCodec;
use crate::frame::rtu::RtuCodec;
use crate::frame::{Expect, LineConfig, LineTiming};
use crate::pdu::{Bits, ReadBits, ReadRegisters, Registers, WriteRegister, WriteRegisters};

/// t3.5 at 9600 8E1.
const T3_5: u64 = 4_010_417;
/// One character at 9600 8E1.
const CHAR: u64 = 1_145_834;

fn master(config: MasterConfig) -> Master<RtuCodec> {
    let timing = LineTiming::new(&LineConfig::new(9600).unwrap());
    Master::new(RtuCodec::new(timing, Expect::Both), config)
}

fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = std::vec![unit];
    frame.extend_from_slice(pdu);
    frame.extend_from_slice(&crc16_wire(&frame));
    frame
}

fn read_holding(start: u16, quantity: u16) -> Request<'static> {
    Request::ReadHoldingRegisters(ReadRegisters::new(start, quantity).unwrap())
}

fn ns(n: u64) -> Instant {
    Instant::from_nanos(n)
}

/// Transmits the queued request at `now`, asserting that it goes out then.
#[track_caller]
fn transmit(m: &mut Master<RtuCodec>, now: Instant) -> Vec<u8> {
    let mut buf = [0u8; MAX_TX_LEN];
    let n = m.poll_transmit(now, &mut buf).expect("the request goes out");
    buf[..n].to_vec()
}

/// The completion, as an owned summary.
#[derive(Debug, PartialEq)]
enum Done {
    Registers(Vec<u16>),
    Bits(Vec<bool>),
    Other(FunctionCode),
    Exception(ExceptionCode),
    Broadcast,
    Failed(MasterError),
}

#[track_caller]
fn done(m: &mut Master<RtuCodec>) -> Option<Done> {
    Some(match m.poll_event()? {
        Completion::Response(Response::ReadHoldingRegisters(r)) => Done::Registers(r.values().iter().collect()),
        Completion::Response(Response::ReadCoils(r)) => Done::Bits(r.values().iter().collect()),
        Completion::Response(r) => Done::Other(r.function()),
        Completion::Exception(e) => Done::Exception(e),
        Completion::Sent => Done::Broadcast,
        Completion::Raw(pdu) => Done::Other(FunctionCode::from_u8(pdu[0])),
        Completion::Failed(e) => Done::Failed(e),
    })
}

// ---- Gaps ---------------------------------------------------------------------------------

#[test]
fn a_request_waits_for_t3_5_of_silence_after_the_last_byte_heard() {
    let mut m = master(MasterConfig::default());
    m.on_bytes(ns(1_000_000), &[0x00, 0x11]); // someone else talking
    m.submit(ns(2_000_000), 1, &read_holding(0, 1)).unwrap();
    assert_eq!(m.poll_timeout(), Some(ns(1_000_000 + T3_5)));
    let mut buf = [0u8; MAX_TX_LEN];
    assert_eq!(m.poll_transmit(ns(1_000_000 + T3_5 - 1), &mut buf), None);
    assert_eq!(transmit(&mut m, ns(1_000_000 + T3_5)), rtu(1, &[0x03, 0, 0, 0, 1]));
}

#[test]
fn bytes_heard_while_queued_push_the_request_back() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    m.on_bytes(ns(0), &[0xFF]);
    m.on_bytes(ns(3_000_000), &[0xFF]);
    let mut buf = [0u8; MAX_TX_LEN];
    assert_eq!(m.poll_transmit(ns(3_000_000 + T3_5 - 1), &mut buf), None);
    assert!(m.poll_transmit(ns(3_000_000 + T3_5), &mut buf).is_some());
}

#[test]
fn on_a_quiet_line_the_first_request_goes_out_at_once() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(5), 1, &read_holding(0, 1)).unwrap();
    assert_eq!(m.poll_timeout(), Some(ns(5)));
    transmit(&mut m, ns(5));
}

#[test]
fn the_next_request_waits_t3_5_after_the_reply_and_after_our_own_frame() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(20_000_000), &rtu(1, &[0x03, 0x02, 0x12, 0x34]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![0x1234])));
    m.submit(ns(20_000_001), 1, &read_holding(0, 1)).unwrap();
    assert_eq!(m.poll_timeout(), Some(ns(20_000_000 + T3_5)));
    // A broadcast occupies the line for its own 8 characters, then the turnaround.
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 0, &Request::WriteSingleRegister(WriteRegister { address: 1, value: 2 })).unwrap();
    transmit(&mut m, ns(0));
    assert_eq!(m.poll_timeout(), Some(ns(8 * CHAR + 100_000_000)));
}

// ---- Replies -----------------------------------------------------------------------------

#[test]
fn only_the_asked_units_reply_with_the_asked_function_ends_the_wait() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 5, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(15_000_000), &rtu(6, &[0x03, 0x02, 0xDE, 0xAD])); // another unit
    m.on_bytes(ns(25_000_000), &rtu(5, &[0x04, 0x02, 0xDE, 0xAD])); // another function
    m.on_bytes(ns(35_000_000), &rtu(5, &[0x03, 0, 0, 0, 1])); // a request (another master, an echo)
    assert_eq!(done(&mut m), None);
    m.on_bytes(ns(45_000_000), &rtu(5, &[0x03, 0x02, 0x00, 0x2A]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![42])));
    assert_eq!(m.stats().ignored_frames, 3);
    assert_eq!(m.stats().responses, 1);
}

#[test]
fn a_reply_in_pieces_and_behind_noise_is_found() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 2)).unwrap();
    transmit(&mut m, ns(0));
    let reply = rtu(1, &[0x03, 0x04, 0x00, 0x01, 0x00, 0x02]);
    m.on_bytes(ns(10_000_000), &[0x00]);
    m.on_bytes(ns(10_500_000), &reply[..4]);
    m.on_bytes(ns(11_000_000), &reply[4..]);
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![1, 2])));
}

#[test]
fn an_exception_is_a_result_not_a_failure() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(10_000_000), &rtu(1, &[0x83, 0x21]));
    assert_eq!(done(&mut m), Some(Done::Exception(ExceptionCode::Vendor(0x21))));
    assert_eq!(m.stats().exceptions, 1);
    assert!(m.is_idle());
}

#[test]
fn a_reply_that_does_not_answer_the_request_fails_it() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 2)).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(10_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x01]));
    assert_eq!(
        done(&mut m),
        Some(Done::Failed(MasterError::Mismatch { field: "register count", expected: 2, received: 1 }))
    );
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &Request::WriteSingleRegister(WriteRegister { address: 7, value: 9 })).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(10_000_000), &rtu(1, &[0x06, 0x00, 0x07, 0x00, 0x08]));
    assert_eq!(done(&mut m), Some(Done::Failed(MasterError::Mismatch { field: "value", expected: 9, received: 8 })));
    assert_eq!(m.stats().bad_replies, 1);
}

#[test]
fn a_malformed_reply_fails_the_request_with_the_parse_error() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    // Byte count 3: the frame is complete by its length, but 3 bytes are not registers.
    m.on_bytes(ns(10_000_000), &rtu(1, &[0x03, 0x03, 0x00, 0x01, 0x02]));
    assert_eq!(
        done(&mut m),
        Some(Done::Failed(MasterError::BadResponse(PduError::ByteCountMismatch { declared: 3, expected: 4 })))
    );
}

#[test]
fn coil_replies_carry_exactly_the_bits_asked_for() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 8, &Request::ReadCoils(ReadBits::new(6, 6).unwrap())).unwrap();
    assert_eq!(transmit(&mut m, ns(0)), [0x08, 0x01, 0x00, 0x06, 0x00, 0x06, 0x5C, 0x90]);
    // 3G3RX p.4-168: coils 7..12 = 1,1,1,0,1,0 in one byte 0x17.
    m.on_bytes(ns(10_000_000), &[0x08, 0x01, 0x01, 0x17, 0x12, 0x1A]);
    assert_eq!(done(&mut m), Some(Done::Bits(std::vec![true, true, true, false, true, false])));
}

// ---- Timeouts ----------------------------------------------------------------------------

#[test]
fn no_reply_times_out_exactly_the_timeout_after_the_request_left() {
    let config = MasterConfig { response_timeout: Duration::from_millis(200), ..MasterConfig::default() };
    let mut m = master(config);
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    let left = 8 * CHAR;
    assert_eq!(m.poll_timeout(), Some(ns(left + 200_000_000)));
    m.handle_timeout(ns(left + 199_999_999));
    assert_eq!(done(&mut m), None);
    m.handle_timeout(ns(left + 200_000_000));
    assert_eq!(
        done(&mut m),
        Some(Done::Failed(MasterError::Timeout { waited: Duration::from_millis(200), heard: None }))
    );
    assert_eq!(m.stats().timeouts, 1);
    assert!(m.is_idle());
}

#[test]
fn a_reply_still_arriving_at_the_deadline_is_given_time_to_finish() {
    let config = MasterConfig { response_timeout: Duration::from_millis(20), ..MasterConfig::default() };
    let mut m = master(config);
    m.submit(ns(0), 1, &read_holding(0, 2)).unwrap();
    transmit(&mut m, ns(0));
    let deadline = 8 * CHAR + 20_000_000;
    let reply = rtu(1, &[0x03, 0x04, 0x00, 0x01, 0x00, 0x02]);
    m.on_bytes(ns(deadline - 1_000_000), &reply[..5]);
    m.handle_timeout(ns(deadline));
    assert_eq!(done(&mut m), None, "still receiving");
    m.on_bytes(ns(deadline + 2_000_000), &reply[5..]);
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![1, 2])));
}

// ---- Broadcast ---------------------------------------------------------------------------

#[test]
fn a_broadcast_awaits_no_reply_only_the_turnaround_delay() {
    let mut m = master(MasterConfig::default());
    let values = [1, 2];
    let write = Request::WriteMultipleRegisters(WriteRegisters::new(0, Registers::from_values(&values)).unwrap());
    m.submit(ns(0), 0, &write).unwrap();
    let frame = transmit(&mut m, ns(0));
    let until = frame.len() as u64 * CHAR + 100_000_000;
    assert_eq!(m.poll_timeout(), Some(ns(until)));
    m.handle_timeout(ns(until - 1));
    assert_eq!(done(&mut m), None);
    m.handle_timeout(ns(until));
    assert_eq!(done(&mut m), Some(Done::Broadcast));
    assert_eq!(m.stats().broadcasts, 1);
    assert_eq!(m.stats().requests, 0);
}

// ---- Echo --------------------------------------------------------------------------------

#[test]
fn with_echo_suppression_our_own_write_coming_back_is_not_taken_for_the_reply() {
    let config = MasterConfig { echo_suppression: true, ..MasterConfig::default() };
    let mut m = master(config);
    let write = Request::WriteSingleRegister(WriteRegister { address: 1, value: 0x1234 });
    m.submit(ns(0), 1, &write).unwrap();
    let frame = transmit(&mut m, ns(0));
    // The echo arrives in two pieces, then a reply that differs (the device refuses).
    m.on_bytes(ns(5_000_000), &frame[..3]);
    m.on_bytes(ns(9_000_000), &frame[3..]);
    assert_eq!(done(&mut m), None);
    m.on_bytes(ns(30_000_000), &rtu(1, &[0x86, 0x02]));
    assert_eq!(done(&mut m), Some(Done::Exception(ExceptionCode::IllegalDataAddress)));
    assert_eq!(m.stats().echo_bytes, 8);
}

#[test]
fn without_echo_suppression_a_read_requests_echo_is_ignored_as_a_request() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    let frame = transmit(&mut m, ns(0));
    m.on_bytes(ns(9_200_000), &frame);
    m.on_bytes(ns(20_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x07]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![7])));
}

// ---- API ---------------------------------------------------------------------------------

#[test]
fn one_request_at_a_time_until_its_completion_is_polled() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    assert_eq!(m.submit(ns(0), 1, &read_holding(0, 1)), Err(SubmitError::Busy));
    transmit(&mut m, ns(0));
    m.on_bytes(ns(10_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x07]));
    assert_eq!(m.submit(ns(10_000_000), 1, &read_holding(0, 1)), Err(SubmitError::Busy), "completion not polled");
    done(&mut m);
    assert!(m.submit(ns(10_000_000), 1, &read_holding(0, 1)).is_ok());
    m.abort();
    assert!(m.is_idle());
}

#[test]
fn a_transmit_buffer_too_small_fails_the_request_instead_of_panicking() {
    let mut m = master(MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    assert_eq!(m.poll_transmit(ns(0), &mut [0u8; 4]), None);
    assert!(matches!(done(&mut m), Some(Done::Failed(MasterError::TransmitBuffer(_)))));
}

#[test]
fn over_mbap_replies_match_by_transaction_and_unit_0_is_an_ordinary_unit() {
    let mut m = Master::new(MbapCodec::new(), MasterConfig::default());
    m.submit(ns(0), 0, &read_holding(0, 1)).unwrap();
    let mut buf = [0u8; MAX_TX_LEN];
    let n = m.poll_transmit(ns(0), &mut buf).unwrap();
    assert_eq!(&buf[..n], &[0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x00, 0x03, 0x00, 0x00, 0x00, 0x01]);
    assert_eq!(m.poll_timeout(), Some(ns(1_000_000_000)), "a unit-0 request awaits its reply on TCP");
    // A stale reply from transaction 0 is ignored; transaction 1 is ours.
    m.on_bytes(ns(1_000), &[0x00, 0x00, 0x00, 0x00, 0x00, 0x05, 0x00, 0x03, 0x02, 0x00, 0x09]);
    m.on_bytes(ns(2_000), &[0x00, 0x01, 0x00, 0x00, 0x00, 0x05, 0x00, 0x03, 0x02, 0x00, 0x07]);
    match m.poll_event() {
        Some(Completion::Response(Response::ReadHoldingRegisters(r))) => assert_eq!(r.values().get(0), Some(7)),
        other => panic!("{other:?}"),
    }
    assert_eq!(m.stats().ignored_frames, 1);
}

#[test]
fn a_timeout_names_the_function_code_the_unit_sent_instead_of_a_reply() {
    // pymodbus answers a read of 126 registers with 80 01: ignored, as any frame with another
    // function code is, but a timeout that says so tells a confused device from a silent one.
    let mut m = Master::new(MbapCodec::new(), MasterConfig::default());
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    let mut buf = [0u8; MAX_TX_LEN];
    m.poll_transmit(ns(0), &mut buf).unwrap();
    m.on_bytes(ns(1_000), &[0x00, 0x01, 0x00, 0x00, 0x00, 0x03, 0x01, 0x80, 0x01]);
    assert!(m.poll_event().is_none(), "ignored, not accepted");
    m.handle_timeout(ns(1_000_000_000));
    match m.poll_event() {
        Some(Completion::Failed(
            e @ MasterError::Timeout {
                heard: Some(HeardInstead::WrongFunction { function: 0x80, expected: 0x03 }), ..
            },
        )) => {
            assert_eq!(
                e.to_string(),
                "no valid reply within 1000 ms: the unit sent a frame with function code 0x80 instead of 0x03, ignored"
            );
        }
        other => panic!("{other:?}"),
    }
    // The next request starts with a clean slate.
    m.submit(ns(1_000_000_000), 1, &read_holding(0, 1)).unwrap();
    m.poll_transmit(ns(1_000_000_000), &mut buf).unwrap();
    m.handle_timeout(ns(2_000_000_000));
    assert!(matches!(m.poll_event(), Some(Completion::Failed(MasterError::Timeout { heard: None, .. }))));
}

#[test]
fn written_coils_are_checked_against_the_echoed_range() {
    let mut m = master(MasterConfig::default());
    let bits = [true, false, true];
    let write = Request::WriteMultipleCoils(crate::pdu::WriteCoils::new(6, Bits::from_values(&bits)).unwrap());
    m.submit(ns(0), 5, &write).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(20_000_000), &rtu(5, &[0x0F, 0x00, 0x06, 0x00, 0x03]));
    assert_eq!(done(&mut m), Some(Done::Other(FunctionCode::WriteMultipleCoils)));
}

#[test]
fn force_listen_only_is_not_answered_so_it_is_not_awaited() {
    use crate::pdu::Diagnostic;
    let mut m = master(MasterConfig::default());
    let request = Request::Diagnostics(Diagnostic::with_word(DiagnosticCode::ForceListenOnly, 0));
    m.submit(ns(0), 1, &request).unwrap();
    transmit(&mut m, ns(0));
    assert_eq!(m.poll_timeout(), Some(ns(8 * CHAR + 100_000_000)), "the turnaround, not the response timeout");
    m.handle_timeout(ns(8 * CHAR + 100_000_000));
    assert_eq!(done(&mut m), Some(Done::Broadcast));
}

#[test]
fn a_raw_request_is_sent_as_is_and_its_reply_returned_unparsed() {
    let mut m = master(MasterConfig::default());
    // Quantity 0 is invalid; a raw request goes out anyway.
    m.submit_raw(ns(0), 1, &[0x03, 0x00, 0x00, 0x00, 0x00]).unwrap();
    assert_eq!(transmit(&mut m, ns(0)), rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x00]));
    m.on_bytes(ns(10_000_000), &rtu(1, &[0x83, 0x03]));
    assert_eq!(done(&mut m), Some(Done::Exception(ExceptionCode::IllegalDataValue)));
    m.submit_raw(ns(20_000_000), 1, &[0x03, 0x00, 0x00, 0x00, 0x01]).unwrap();
    transmit(&mut m, ns(20_000_000));
    m.on_bytes(ns(30_000_000), &rtu(1, &[0x03, 0x02, 0xAB, 0xCD]));
    match m.poll_event() {
        Some(Completion::Raw(pdu)) => assert_eq!(pdu, [0x03, 0x02, 0xAB, 0xCD]),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        m.submit_raw(ns(40_000_000), 1, &[]),
        Err(SubmitError::Encode(BufferTooSmall { needed: 1, available: 253 }))
    );
}

// ---- What a timeout heard ----------------------------------------------------------------

/// Sends a read of one register to `unit` at t = 0, feeds `heard` at 20 ms, and returns what
/// the timeout 300 ms after the request left says it heard.
#[track_caller]
fn heard_after(unit: u8, heard: &[&[u8]]) -> (Option<HeardInstead>, std::string::String) {
    let config = MasterConfig { response_timeout: Duration::from_millis(300), ..MasterConfig::default() };
    let mut m = master(config);
    m.submit(ns(0), unit, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    for (i, bytes) in (0u64..).zip(heard) {
        m.on_bytes(ns(20_000_000 + i * 50_000_000), bytes);
        m.handle_timeout(ns(20_000_000 + i * 50_000_000 + T3_5));
        assert_eq!(done(&mut m), None, "nothing heard ends the wait");
    }
    m.handle_timeout(ns(8 * CHAR + 300_000_000));
    match done(&mut m) {
        Some(Done::Failed(e @ MasterError::Timeout { heard, .. })) => (heard, e.to_string()),
        other => panic!("expected a timeout, got {other:?}"),
    }
}

fn bad_crc(mut frame: Vec<u8>) -> Vec<u8> {
    if let Some(b) = frame.last_mut() {
        *b ^= 0x5A;
    }
    frame
}

#[test]
fn silence_times_out_with_nothing_heard() {
    assert_eq!(heard_after(2, &[]), (None, "no reply within 300 ms".into()));
}

#[test]
fn a_reply_with_a_bad_crc_times_out_saying_the_unit_answered_with_a_wrong_checksum() {
    let (heard, text) = heard_after(2, &[&bad_crc(rtu(2, &[0x03, 0x02, 0x00, 0x07]))]);
    assert_eq!(heard, Some(HeardInstead::BadChecksum { head: Some((2, 0x03)), expected: (2, 0x03) }));
    assert_eq!(
        text,
        "no valid reply within 300 ms: unit 2 answered, but the checksum was wrong (function code 0x03, as asked)"
    );
    assert!(heard.is_some_and(|h| h.is_damage()));
}

#[test]
fn a_bad_crc_over_a_damaged_function_code_names_the_code_seen_and_the_one_expected() {
    let mut frame = rtu(2, &[0x03, 0x02, 0x00, 0x07]);
    frame[1] = 0x1E;
    let (heard, text) = heard_after(2, &[&frame]);
    assert_eq!(heard, Some(HeardInstead::BadChecksum { head: Some((2, 0x1E)), expected: (2, 0x03) }));
    assert!(
        text.ends_with("unit 2 answered, but the checksum was wrong (function code 0x1E, expected 0x03)"),
        "{text}"
    );
}

#[test]
fn bytes_that_make_no_frame_time_out_as_garbage_not_silence() {
    let (heard, text) = heard_after(2, &[&[0xFF]]);
    assert_eq!(heard, Some(HeardInstead::Garbage { bytes: 1, reason: DiscardReason::TooShort }));
    assert_eq!(text, "no valid reply within 300 ms: 1 byte came that made no frame (frame too short)");
}

#[test]
fn a_frame_from_another_unit_times_out_naming_that_unit() {
    let (heard, text) = heard_after(2, &[&rtu(3, &[0x03, 0x02, 0x00, 0x07])]);
    assert_eq!(heard, Some(HeardInstead::OtherUnit { unit: 3, function: 0x03 }));
    assert!(text.ends_with("unit 3 sent a frame (function code 0x03) instead, ignored"), "{text}");
}

#[test]
fn what_tells_most_about_the_unit_asked_is_kept_over_later_lesser_things() {
    let reply = bad_crc(rtu(2, &[0x03, 0x02, 0x00, 0x07]));
    let other = rtu(3, &[0x03, 0x02, 0x00, 0x07]);
    let ours = HeardInstead::BadChecksum { head: Some((2, 0x03)), expected: (2, 0x03) };
    assert_eq!(heard_after(2, &[&reply, &other, &[0xFF]]).0, Some(ours));
    // Garbage outweighs another unit's traffic; the latest of equal weight is kept.
    let garbage = HeardInstead::Garbage { bytes: 1, reason: DiscardReason::TooShort };
    assert_eq!(heard_after(2, &[&other, &[0xFF]]).0, Some(garbage));
    assert_eq!(
        heard_after(2, &[&other, &rtu(4, &[0x03, 0x02, 0x00, 0x07])]).0,
        Some(HeardInstead::OtherUnit { unit: 4, function: 0x03 })
    );
    // A valid frame from the unit with another code outweighs a broken one.
    let wrong = HeardInstead::WrongFunction { function: 0x04, expected: 0x03 };
    assert_eq!(heard_after(2, &[&rtu(2, &[0x04, 0x02, 0x00, 0x07]), &reply]).0, Some(wrong));
}

#[test]
fn a_tcp_reply_under_another_transaction_id_times_out_naming_both_ids() {
    let config = MasterConfig { response_timeout: Duration::from_millis(300), ..MasterConfig::default() };
    let mut m = Master::new(MbapCodec::new(), config);
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    let mut buf = [0u8; MAX_TX_LEN];
    let n = m.poll_transmit(ns(0), &mut buf).unwrap();
    assert_eq!(&buf[..2], [0x00, 0x01], "the request's transaction id is 1 ({:02X?})", &buf[..n]);
    // The right unit and function code, under transaction 7.
    m.on_bytes(ns(1_000_000), &[0x00, 0x07, 0x00, 0x00, 0x00, 0x05, 0x01, 0x03, 0x02, 0x00, 0x2A]);
    assert!(m.poll_event().is_none(), "ignored, not accepted");
    m.handle_timeout(ns(300_000_000));
    match m.poll_event() {
        Some(Completion::Failed(
            e @ MasterError::Timeout {
                heard: Some(HeardInstead::OtherTransaction { transaction: 7, expected: 1 }), ..
            },
        )) => assert_eq!(
            e.to_string(),
            "no valid reply within 300 ms: a reply came under transaction id 7, not 1, ignored"
        ),
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_ascii_reply_with_a_bad_lrc_names_the_unit_and_function_code_it_carried() {
    use crate::frame::ascii::{AsciiCodec, encode_pdu};
    let timing = LineTiming::new(&LineConfig::new(9600).unwrap());
    let config = MasterConfig { response_timeout: Duration::from_millis(300), ..MasterConfig::default() };
    let mut m = Master::new(AsciiCodec::new(timing), config);
    m.submit(ns(0), 5, &read_holding(0, 1)).unwrap();
    let mut buf = [0u8; MAX_TX_LEN];
    let sent = m.poll_transmit(ns(0), &mut buf).unwrap();
    let mut reply = [0u8; 64];
    let n = encode_pdu(5, &[0x03, 0x02, 0x00, 0x07], &mut reply).unwrap();
    // `… L L CR LF`: another LRC.
    reply[n - 4] = if reply[n - 4] == b'0' { b'1' } else { b'0' };
    m.on_bytes(ns(20_000_000), &reply[..n]);
    m.handle_timeout(ns(sent as u64 * CHAR + 300_000_000));
    match m.poll_event() {
        Some(Completion::Failed(MasterError::Timeout { heard, .. })) => {
            assert_eq!(heard, Some(HeardInstead::BadChecksum { head: Some((5, 0x03)), expected: (5, 0x03) }));
        }
        other => panic!("{other:?}"),
    }
}

// ---- Late replies: owed to a request that timed out ---------------------------------------

/// A master with a 100 ms timeout and a 200 ms late window.
fn late_master() -> Master<RtuCodec> {
    let config = MasterConfig {
        response_timeout: Duration::from_millis(100),
        late_window: Duration::from_millis(200),
        ..MasterConfig::default()
    };
    master(config)
}

/// The instant the read of one register sent at `at` times out (8 characters, then 100 ms).
fn timeout_of(at: u64) -> u64 {
    at + 8 * CHAR + 100_000_000
}

/// Sends a read of one register to unit 1 at t = 0 and lets it time out.
#[track_caller]
fn timed_out_read(m: &mut Master<RtuCodec>) {
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(m, ns(0));
    m.handle_timeout(ns(timeout_of(0)));
    assert!(matches!(done(m), Some(Done::Failed(MasterError::Timeout { .. }))));
}

/// A master whose read of one register to unit 1 timed out, with the next such read queued
/// at the timeout `t`: a reply is owed.
fn owing() -> (Master<RtuCodec>, u64) {
    let mut m = late_master();
    timed_out_read(&mut m);
    let t = timeout_of(0);
    m.submit(ns(t), 1, &read_holding(0, 1)).unwrap();
    (m, t)
}

/// Feeds `frame` at `at` whole, byte by byte 1 µs apart, or after another unit's frame in
/// one chunk; returns the instant its last byte came.
fn feed_as(m: &mut Master<RtuCodec>, at: u64, frame: &[u8], how: Feed) -> u64 {
    match how {
        Feed::Whole => {
            m.on_bytes(ns(at), frame);
            at
        }
        Feed::ByteByByte => {
            for (i, b) in (0u64..).zip(frame) {
                m.on_bytes(ns(at + i * 1_000), &[*b]);
            }
            at + (frame.len() as u64 - 1) * 1_000
        }
        Feed::BehindAnother => {
            let mut chunk = rtu(9, &[0x03, 0x02, 0x55, 0x55]);
            chunk.extend_from_slice(frame);
            m.on_bytes(ns(at), &chunk);
            at
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Feed {
    Whole,
    ByteByByte,
    BehindAnother,
}

const FEEDS: [Feed; 3] = [Feed::Whole, Feed::ByteByByte, Feed::BehindAnother];

#[test]
fn a_reply_after_the_timeout_is_dropped_as_late_and_never_taken_for_the_next_same_shape_request() {
    for how in FEEDS {
        let mut m = late_master();
        timed_out_read(&mut m);
        // The next request, same unit, function and length, is queued at once...
        let t = timeout_of(0);
        m.submit(ns(t), 1, &read_holding(0, 1)).unwrap();
        let mut buf = [0u8; MAX_TX_LEN];
        assert_eq!(m.poll_transmit(ns(t), &mut buf), None, "{how:?}: the line opened with a reply owed");
        assert!(m.owes_reply(ns(t)));
        // ...and the late reply (value 0xDEAD) comes 50 ms later, while the line is closed.
        let end = feed_as(&mut m, t + 50_000_000, &rtu(1, &[0x03, 0x02, 0xDE, 0xAD]), how);
        assert_eq!(m.stats().late_replies, 1, "{how:?}: the late reply was not counted");
        assert!(!m.owes_reply(ns(end)), "{how:?}");
        // The line opens t3.5 after it, and the next request gets its own reply.
        assert_eq!(m.poll_timeout(), Some(ns(end + T3_5)), "{how:?}");
        assert_eq!(m.poll_transmit(ns(end + T3_5 - 1), &mut buf), None, "{how:?}");
        assert!(m.poll_transmit(ns(end + T3_5), &mut buf).is_some(), "{how:?}");
        m.on_bytes(ns(end + T3_5 + 20_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x07]));
        assert_eq!(done(&mut m), Some(Done::Registers(std::vec![7])), "{how:?}");
    }
}

#[test]
fn with_no_late_reply_the_line_opens_once_the_late_window_has_passed_in_silence() {
    let (mut m, t) = owing();
    assert_eq!(m.poll_timeout(), Some(ns(t + 200_000_000)), "the late window, from the timeout");
    let mut buf = [0u8; MAX_TX_LEN];
    assert_eq!(m.poll_transmit(ns(t + 200_000_000 - 1), &mut buf), None);
    assert!(m.poll_transmit(ns(t + 200_000_000), &mut buf).is_some());
    assert_eq!(m.stats().late_replies, 0);
}

#[test]
fn another_units_frame_or_another_length_does_not_settle_the_owed_reply() {
    let (mut m, t) = owing();
    m.on_bytes(ns(t + 10_000_000), &rtu(2, &[0x03, 0x02, 0x00, 0x01])); // another unit
    m.on_bytes(ns(t + 20_000_000), &rtu(1, &[0x03, 0x04, 0, 1, 0, 2])); // two registers, not one
    m.on_bytes(ns(t + 30_000_000), &rtu(1, &[0x04, 0x02, 0x00, 0x01])); // another function
    assert!(m.owes_reply(ns(t + 30_000_000)), "a frame that is not the owed reply settled it");
    assert_eq!(m.stats().late_replies, 0);
    assert_eq!(m.poll_timeout(), Some(ns(t + 200_000_000)));
    // The owed unit's exception is its reply.
    m.on_bytes(ns(t + 40_000_000), &rtu(1, &[0x83, 0x02]));
    assert_eq!((m.owes_reply(ns(t + 40_000_000)), m.stats().late_replies), (false, 1));
}

#[test]
fn a_retry_waits_for_the_reply_owed_to_the_attempt_before_so_it_gets_its_own() {
    // A device that answers 150 ms after each request, against a 100 ms timeout: each late
    // reply is dropped, the retry goes out after it, and no attempt takes another's reply.
    let mut m = late_master();
    timed_out_read(&mut m);
    // The retry, submitted at once, waits; the first attempt's reply (value 1) comes.
    let t = timeout_of(0);
    m.submit(ns(t), 1, &read_holding(0, 1)).unwrap();
    m.on_bytes(ns(150_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x01]));
    let retry_at = 150_000_000 + T3_5;
    assert_eq!(transmit(&mut m, ns(retry_at)), rtu(1, &[0x03, 0, 0, 0, 1]));
    m.handle_timeout(ns(timeout_of(retry_at)));
    assert!(matches!(done(&mut m), Some(Done::Failed(MasterError::Timeout { heard: None, .. }))));
    // The next job: the retry's reply (value 2) is owed, and dropped when it comes.
    let next = timeout_of(retry_at);
    m.submit(ns(next), 1, &read_holding(0, 1)).unwrap();
    m.on_bytes(ns(retry_at + 150_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x02]));
    transmit(&mut m, ns(retry_at + 150_000_000 + T3_5));
    m.on_bytes(ns(retry_at + 160_000_000 + T3_5), &rtu(1, &[0x03, 0x02, 0x00, 0x03]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![3])));
    assert_eq!(m.stats().late_replies, 2);
}

#[test]
fn a_late_reply_with_a_bad_crc_settles_the_owed_reply_too() {
    let (mut m, t) = owing();
    m.on_bytes(ns(t + 10_000_000), &bad_crc(rtu(1, &[0x03, 0x02, 0x00, 0x01])));
    m.handle_timeout(ns(t + 10_000_000 + T3_5));
    assert_eq!(m.stats().late_replies, 1);
    assert!(!m.owes_reply(ns(t + 10_000_000 + T3_5)));
}

#[test]
fn a_timeout_after_a_damaged_reply_owes_nothing() {
    let mut m = late_master();
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(20_000_000), &bad_crc(rtu(1, &[0x03, 0x02, 0x00, 0x07])));
    m.handle_timeout(ns(20_000_000 + T3_5));
    m.handle_timeout(ns(timeout_of(0)));
    assert!(matches!(done(&mut m), Some(Done::Failed(MasterError::Timeout { heard: Some(_), .. }))));
    assert!(!m.owes_reply(ns(timeout_of(0))), "the unit's reply came, damaged: none is owed");
}

// ---- Replies sooner than any slave may answer ---------------------------------------------

/// A master on a wire: no reply may begin before the request has left (8 characters).
fn line_master() -> Master<RtuCodec> {
    let config = MasterConfig {
        response_timeout: Duration::from_millis(100),
        min_reply_delay: Some(Duration::ZERO),
        ..MasterConfig::default()
    };
    master(config)
}

#[test]
fn a_reply_that_begins_before_the_request_has_left_is_dropped_as_stale_and_named_in_the_timeout() {
    for how in FEEDS {
        let mut m = line_master();
        m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
        transmit(&mut m, ns(0));
        // A stale reply already in the port: 49 µs after the request began.
        feed_as(&mut m, 49_000, &rtu(1, &[0x03, 0x02, 0x0C, 0xE4]), how);
        assert_eq!(done(&mut m), None, "{how:?}: the stale reply was taken");
        assert_eq!(m.stats().early_replies, 1, "{how:?}");
        m.handle_timeout(ns(timeout_of(0)));
        let Some(Done::Failed(e @ MasterError::Timeout { heard, .. })) = done(&mut m) else {
            panic!("{how:?}: no timeout")
        };
        let earliest = Duration::from_nanos(8 * CHAR);
        assert_eq!(heard, Some(HeardInstead::TooEarly { after: Duration::from_micros(49), earliest }), "{how:?}");
        assert!(
            e.to_string().ends_with(
                "a reply 49 µs after the request, earlier than any slave can answer (not before 9166 µs): a stale \
                 reply, ignored"
            ),
            "{how:?}: {e}"
        );
    }
}

#[test]
fn a_reply_that_begins_as_the_request_has_left_is_accepted_as_a_prompt_device_sends_it() {
    for how in FEEDS {
        let mut m = line_master();
        m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
        transmit(&mut m, ns(0));
        feed_as(&mut m, 8 * CHAR, &rtu(1, &[0x03, 0x02, 0x00, 0x2A]), how);
        assert_eq!(done(&mut m), Some(Done::Registers(std::vec![42])), "{how:?}");
        assert_eq!(m.stats().early_replies, 0, "{how:?}");
    }
}

#[test]
fn with_t3_5_as_the_minimum_delay_a_reply_before_that_silence_is_stale_and_the_true_one_after_it_is_taken() {
    let config = MasterConfig { min_reply_delay: Some(Duration::from_nanos(T3_5)), ..MasterConfig::default() };
    let mut m = master(config);
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(8 * CHAR + T3_5 - 1), &rtu(1, &[0x03, 0x02, 0x0C, 0xE4]));
    assert_eq!((done(&mut m), m.stats().early_replies), (None, 1));
    m.on_bytes(ns(8 * CHAR + T3_5 + 10_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x2A]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![42])));
}

#[test]
fn without_a_minimum_reply_delay_a_prompt_reply_is_accepted() {
    // TCP, RTU over TCP and ptys: nothing bounds how soon a reply may come.
    let mut m = late_master();
    m.submit(ns(0), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(0));
    m.on_bytes(ns(49_000), &rtu(1, &[0x03, 0x02, 0x0C, 0xE4]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![0x0CE4])));
}

#[test]
fn a_unit_silent_through_its_late_window_owes_no_reply_on_its_next_timeouts_until_it_is_heard() {
    let mut m = late_master();
    timed_out_read(&mut m);
    // The window passes in silence: the unit is dead, not slow.
    let t = timeout_of(0) + 200_000_000;
    m.submit(ns(timeout_of(0)), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(t));
    m.handle_timeout(ns(timeout_of(t)));
    assert!(matches!(done(&mut m), Some(Done::Failed(MasterError::Timeout { .. }))));
    assert!(!m.owes_reply(ns(timeout_of(t))), "a silent unit's timeout owes a reply");
    // Once it is heard again it is slow, not silent: its next timeout owes a reply.
    let u = timeout_of(t);
    m.submit(ns(u), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(u));
    m.on_bytes(ns(u + 10_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x05]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![5])));
    let v = u + 10_000_000 + T3_5;
    m.submit(ns(v), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(v));
    m.handle_timeout(ns(timeout_of(v)));
    done(&mut m);
    assert!(m.owes_reply(ns(timeout_of(v))));
}

// ---- Owed replies per unit, and replies far outside a unit's habit -----------------------

#[test]
fn a_request_to_another_unit_goes_out_while_a_reply_is_owed_and_the_owed_reply_cannot_answer_it() {
    let (mut m, t) = owing();
    m.abort();
    // Unit 2 need not wait for unit 1's late reply...
    m.submit(ns(t), 2, &read_holding(0, 1)).unwrap();
    assert_eq!(transmit(&mut m, ns(t + T3_5)), rtu(2, &[0x03, 0, 0, 0, 1]));
    // ...which comes during unit 2's wait: dropped as late, never taken for unit 2's.
    m.on_bytes(ns(t + 20_000_000), &rtu(1, &[0x03, 0x02, 0xDE, 0xAD]));
    assert_eq!(done(&mut m), None);
    assert_eq!((m.stats().late_replies, m.owes_reply(ns(t + 20_000_000))), (1, false));
    m.on_bytes(ns(t + 30_000_000), &rtu(2, &[0x03, 0x02, 0x00, 0x02]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![2])));
}

#[test]
fn a_request_to_a_unit_owed_a_reply_still_waits_for_it_after_requests_to_others() {
    let (mut m, t) = owing();
    m.abort();
    m.submit(ns(t), 2, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(t + T3_5));
    m.on_bytes(ns(t + 10_000_000), &rtu(2, &[0x03, 0x02, 0x00, 0x02]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![2])));
    // Unit 1 is still owed its reply: its next request waits for the late window.
    m.submit(ns(t + 20_000_000), 1, &read_holding(0, 1)).unwrap();
    assert_eq!(m.poll_timeout(), Some(ns(t + 200_000_000)));
    let mut buf = [0u8; MAX_TX_LEN];
    assert_eq!(m.poll_transmit(ns(t + 200_000_000 - 1), &mut buf), None);
    assert!(m.poll_transmit(ns(t + 200_000_000), &mut buf).is_some());
}

#[test]
fn with_as_many_units_owed_a_reply_as_it_keeps_a_request_to_yet_another_waits_for_the_first() {
    // A late window long enough for every unit's to be open at once.
    let config = MasterConfig { late_window: Duration::from_secs(1), ..*late_master().config() };
    let mut m = master(config);
    let mut at = 0;
    let mut first_until = None;
    for unit in 1..=u8::try_from(MAX_OWED).unwrap() {
        m.submit(ns(at), unit, &read_holding(0, 1)).unwrap();
        transmit(&mut m, ns(at));
        at = timeout_of(at);
        m.handle_timeout(ns(at));
        assert!(matches!(done(&mut m), Some(Done::Failed(MasterError::Timeout { .. }))));
        first_until.get_or_insert(at + 1_000_000_000);
        at += T3_5;
    }
    m.submit(ns(at), 9, &read_holding(0, 1)).unwrap();
    assert_eq!(m.poll_timeout(), first_until.map(ns), "unit 1's window is the first to end");
    // Unit 1's late reply settles its slot, and the line opens after the gap.
    m.on_bytes(ns(at + 1_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x01]));
    let mut buf = [0u8; MAX_TX_LEN];
    assert!(m.poll_transmit(ns(at + 1_000_000 + T3_5), &mut buf).is_some());
    assert_eq!(m.stats().late_replies, 1);
}

/// A master whose unit 1 has answered 20 reads 5 ms after each, then timed out on one whose
/// late window passed in silence; returns it with the next read to unit 1 just sent, and when.
fn in_doubt() -> (Master<RtuCodec>, u64) {
    let mut m = late_master();
    let mut at = 0;
    for value in 0..20 {
        m.submit(ns(at), 1, &read_holding(0, 1)).unwrap();
        transmit(&mut m, ns(at));
        let reply_at = at + 8 * CHAR + 5_000_000;
        m.on_bytes(ns(reply_at), &rtu(1, &[0x03, 0x02, 0x00, value]));
        assert_eq!(done(&mut m), Some(Done::Registers(std::vec![u16::from(value)])));
        at = reply_at + T3_5;
    }
    m.submit(ns(at), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(at));
    m.handle_timeout(ns(timeout_of(at)));
    assert!(matches!(done(&mut m), Some(Done::Failed(MasterError::Timeout { .. }))));
    let next = timeout_of(at) + 200_000_000;
    m.submit(ns(timeout_of(at)), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(next));
    (m, next)
}

#[test]
fn a_reply_far_later_than_the_unit_answers_after_its_owed_reply_never_came_is_dropped_as_that_reply() {
    let (mut m, sent) = in_doubt();
    // The timed-out read's reply, 3.1 s after it: 100 ms into this read's wait.
    m.on_bytes(ns(sent + 8 * CHAR + 100_000_000), &rtu(1, &[0x03, 0x02, 0xDE, 0xAD]));
    assert_eq!(done(&mut m), None, "the late reply was taken for this read's");
    assert_eq!(m.stats().suspect_replies, 1);
    m.handle_timeout(ns(timeout_of(sent)));
    let Some(Done::Failed(e @ MasterError::Timeout { heard, .. })) = done(&mut m) else { panic!("no timeout") };
    let usual = Duration::from_millis(8);
    assert_eq!(heard, Some(HeardInstead::Suspect { after: Duration::from_millis(100), usual }));
    assert!(e.to_string().contains("a reply 100 ms after the request, where the unit answers within 8 ms"), "{e}");
}

#[test]
fn a_reply_in_the_units_habit_after_its_owed_reply_never_came_is_taken() {
    let (mut m, sent) = in_doubt();
    m.on_bytes(ns(sent + 8 * CHAR + 6_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x2A]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![42])));
    assert_eq!(m.stats().suspect_replies, 0);
}

#[test]
fn a_slow_reply_from_a_unit_in_no_doubt_is_taken() {
    let (mut m, _) = in_doubt();
    m.on_bytes(ns(timeout_of(0)), &[]);
    m.abort();
    // Heard again (this reply), the unit is in no doubt: its next slow reply is its own.
    let at = 100_000_000_000;
    m.submit(ns(at), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(at));
    m.on_bytes(ns(at + 8 * CHAR + 5_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x01]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![1])));
    m.submit(ns(at + 50_000_000), 1, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(at + 50_000_000));
    m.on_bytes(ns(at + 50_000_000 + 8 * CHAR + 90_000_000), &rtu(1, &[0x03, 0x02, 0x00, 0x02]));
    assert_eq!(done(&mut m), Some(Done::Registers(std::vec![2])));
}

#[test]
fn once_a_request_beside_another_units_owed_reply_gets_none_every_request_waits_for_every_owed_reply() {
    // Units behind one responder (a multi-unit device): busy with unit 1's late reply, it does
    // not hear unit 2's request.
    let (mut m, t) = owing();
    m.abort();
    m.submit(ns(t), 2, &read_holding(0, 1)).unwrap();
    transmit(&mut m, ns(t + T3_5));
    m.on_bytes(ns(t + 20_000_000), &rtu(1, &[0x03, 0x02, 0xDE, 0xAD]));
    m.handle_timeout(ns(timeout_of(t + T3_5)));
    assert!(matches!(done(&mut m), Some(Done::Failed(MasterError::Timeout { .. }))));
    // Unit 2's timeout owes a reply now; unit 3's request waits for it, as every request does
    // on this line from now on.
    let u = timeout_of(t + T3_5);
    m.submit(ns(u), 3, &read_holding(0, 1)).unwrap();
    assert_eq!(m.poll_timeout(), Some(ns(u + 200_000_000)));
    let mut buf = [0u8; MAX_TX_LEN];
    assert_eq!(m.poll_transmit(ns(u + 200_000_000 - 1), &mut buf), None);
    assert!(m.poll_transmit(ns(u + 200_000_000), &mut buf).is_some());
}
