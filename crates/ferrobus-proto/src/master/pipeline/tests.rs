//! Pipeline tests with explicit time: many requests in flight, replies matched by transaction
//! id in any order, timeouts of one request among many, late replies, transaction ids.

extern crate std;
use std::collections::HashMap;
use std::string::ToString;
use std::vec::Vec;

use super::*;
use crate::codes::ExceptionCode;
use crate::error::{DiscardReason, PduError};
use crate::pdu::{Diagnostic, ReadBits, ReadRegisters, Response, WriteRegister};

const TIMEOUT: Duration = Duration::from_secs(1);

fn ms(n: u64) -> Instant {
    Instant::from_millis(n)
}

fn pipeline(in_flight: usize) -> Pipeline {
    Pipeline::new(MbapCodec::new(), in_flight)
}

fn read_holding(start: u16, quantity: u16) -> Request<'static> {
    Request::ReadHoldingRegisters(ReadRegisters::new(start, quantity).unwrap())
}

/// An MBAP frame: transaction id, protocol id 0, length (unit and PDU), unit, PDU.
fn mbap(transaction: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = transaction.to_be_bytes().to_vec();
    frame.extend_from_slice(&[0x00, 0x00]);
    frame.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    frame.push(unit);
    frame.extend_from_slice(pdu);
    frame
}

/// The PDU of a 0x03 reply carrying `values`.
fn registers(values: &[u16]) -> Vec<u8> {
    let mut pdu = std::vec![0x03, u8::try_from(values.len() * 2).unwrap()];
    for v in values {
        pdu.extend_from_slice(&v.to_be_bytes());
    }
    pdu
}

/// Every frame due at `now`, one per call, as a driver collects them.
fn transmit_all(p: &mut Pipeline, now: Instant) -> Vec<Vec<u8>> {
    let mut frames = Vec::new();
    let mut buf = [0xA5u8; MAX_ADU_LEN];
    while let Some(n) = p.poll_transmit(now, &mut buf) {
        assert_eq!(buf.get(n).copied().unwrap_or(0xA5), 0xA5, "written past the frame");
        frames.push(buf[..n].to_vec());
        buf = [0xA5; MAX_ADU_LEN];
    }
    frames
}

/// The completion, as an owned summary.
#[derive(Debug, PartialEq)]
enum Done {
    Registers(Vec<u16>),
    Bits(Vec<bool>),
    Other(FunctionCode),
    Raw(Vec<u8>),
    Exception(ExceptionCode),
    Sent,
    Failed(MasterError),
}

fn summary(c: Completion<'_>) -> Done {
    match c {
        Completion::Response(Response::ReadHoldingRegisters(r)) => Done::Registers(r.values().iter().collect()),
        Completion::Response(Response::ReadCoils(r)) => Done::Bits(r.values().iter().collect()),
        Completion::Response(r) => Done::Other(r.function()),
        Completion::Raw(pdu) => Done::Raw(pdu.to_vec()),
        Completion::Exception(e) => Done::Exception(e),
        Completion::Sent => Done::Sent,
        Completion::Failed(e) => Done::Failed(e),
    }
}

/// Every completion waiting, in order.
fn events(p: &mut Pipeline) -> Vec<(Ticket, Done)> {
    let mut done = Vec::new();
    while let Some((ticket, completion)) = p.poll_event() {
        done.push((ticket, summary(completion)));
    }
    done
}

/// Submits a read of register `i` from `unit` for each `i` in `0..n`, and transmits them.
fn in_flight(p: &mut Pipeline, n: u16, unit: u8) -> Vec<Ticket> {
    let tickets: Vec<Ticket> = (0..n).map(|i| p.submit(ms(0), unit, &read_holding(i, 1), TIMEOUT).unwrap()).collect();
    assert_eq!(transmit_all(p, ms(0)).len(), usize::from(n));
    tickets
}

// ---- Many in flight ------------------------------------------------------------------------

#[test]
fn sixteen_requests_in_flight_answered_in_reverse_and_shuffled_order_each_get_their_own_reply() {
    // Reverse, then every 7th (7 is prime to 16, so all of them).
    let orders: [Vec<usize>; 2] = [(0..16).rev().collect(), (0..16).map(|i| i * 7 % 16).collect()];
    for order in orders {
        let mut p = pipeline(MAX_IN_FLIGHT);
        let tickets = in_flight(&mut p, 16, 1);
        assert_eq!(p.outstanding(), 16);
        assert!(!p.has_room());
        for (k, &i) in order.iter().enumerate() {
            // Reply i carries 0x1000 + i, the value of register i.
            let value = 0x1000 + u16::try_from(i).unwrap();
            p.on_bytes(ms(10 + k as u64), &mbap(tickets[i].transaction(), 1, &registers(&[value])));
        }
        let done = events(&mut p);
        let ended: Vec<Ticket> = done.iter().map(|(t, _)| *t).collect();
        let expected: Vec<Ticket> = order.iter().map(|&i| tickets[i]).collect();
        assert_eq!(ended, expected, "completions in the order the replies came");
        for (ticket, done) in done {
            let i = tickets.iter().position(|t| *t == ticket).unwrap();
            assert_eq!(done, Done::Registers(std::vec![0x1000 + u16::try_from(i).unwrap()]), "{ticket:?}");
        }
        assert_eq!(p.outstanding(), 0);
        let stats = p.stats();
        assert_eq!((stats.requests, stats.responses, stats.ignored_frames), (16, 16, 0));
    }
}

#[test]
fn completions_come_in_the_order_the_requests_ended_timeouts_by_deadline() {
    let mut p = pipeline(4);
    let slow = p.submit(ms(0), 1, &read_holding(0, 1), Duration::from_millis(300)).unwrap();
    let fast = p.submit(ms(0), 1, &read_holding(1, 1), Duration::from_millis(100)).unwrap();
    let middle = p.submit(ms(0), 1, &read_holding(2, 1), Duration::from_millis(200)).unwrap();
    let answered = p.submit(ms(0), 1, &read_holding(3, 1), TIMEOUT).unwrap();
    transmit_all(&mut p, ms(0));
    assert_eq!(p.poll_timeout(), Some(ms(100)), "the earliest deadline");
    p.on_bytes(ms(50), &mbap(answered.transaction(), 1, &registers(&[4])));
    // Handled late: the three due at once end in the order of their deadlines.
    p.handle_timeout(ms(400));
    let ended: Vec<Ticket> = events(&mut p).into_iter().map(|(t, _)| t).collect();
    assert_eq!(ended, [answered, fast, middle, slow]);
}

// ---- Slots and the limit ----------------------------------------------------------------

#[test]
fn submit_past_the_limit_is_refused_as_full_and_a_slot_is_reused_only_after_its_completion_is_polled() {
    assert_eq!((pipeline(0).limit(), pipeline(100).limit(), pipeline(5).limit()), (1, MAX_IN_FLIGHT, 5));
    let mut p = pipeline(2);
    let first = p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    let second = p.submit(ms(0), 1, &read_holding(1, 1), TIMEOUT).unwrap();
    assert_eq!((first.slot(), second.slot()), (0, 1));
    let full = p.submit(ms(0), 1, &read_holding(2, 1), TIMEOUT);
    assert_eq!(full, Err(SubmitError::Full { limit: 2 }));
    assert_eq!(full.unwrap_err().to_string(), "2 requests are outstanding, the most this connection keeps in flight");
    assert_eq!(p.submit_raw(ms(0), 1, &[0x03], TIMEOUT), Err(SubmitError::Full { limit: 2 }));
    transmit_all(&mut p, ms(0));
    p.on_bytes(ms(10), &mbap(first.transaction(), 1, &registers(&[7])));
    assert_eq!(p.outstanding(), 2, "ended, but not polled yet");
    assert_eq!(p.submit(ms(10), 1, &read_holding(2, 1), TIMEOUT), Err(SubmitError::Full { limit: 2 }));
    assert_eq!(events(&mut p), [(first, Done::Registers(std::vec![7]))]);
    assert!(p.has_room());
    let third = p.submit(ms(10), 1, &read_holding(2, 1), TIMEOUT).unwrap();
    assert_eq!(third.slot(), first.slot(), "the slot freed by polling");
    assert_ne!(third, first, "a new ticket: another transaction id");
    assert_eq!(third.transaction(), 3);
}

// ---- Transmission -----------------------------------------------------------------------

#[test]
fn frames_go_out_one_per_call_in_submission_order_each_under_its_own_id_with_the_pdu_submitted() {
    let mut p = pipeline(4);
    p.submit(ms(0), 0x11, &read_holding(0x006B, 3), TIMEOUT).unwrap();
    p.submit(ms(0), 0x00, &Request::WriteSingleRegister(WriteRegister { address: 1, value: 3 }), TIMEOUT).unwrap();
    p.submit_raw(ms(0), 0xFF, &[0x41, 0x01, 0x02], TIMEOUT).unwrap();
    assert_eq!(p.poll_timeout(), Some(ms(0)), "queued requests are due at once");
    let mut buf = [0xA5u8; MAX_ADU_LEN];
    let n = p.poll_transmit(ms(0), &mut buf).unwrap();
    #[rustfmt::skip]
    assert_eq!(&buf[..=n], [
        0x00, 0x01, // transaction id 1
        0x00, 0x00, // protocol id
        0x00, 0x06, // length: unit + 5 PDU bytes
        0x11, // unit id
        0x03, 0x00, 0x6B, 0x00, 0x03, // the PDU submitted
        0xA5, // untouched
    ]);
    let n = p.poll_transmit(ms(0), &mut buf).unwrap();
    assert_eq!(&buf[..n], mbap(2, 0x00, &[0x06, 0x00, 0x01, 0x00, 0x03]));
    let n = p.poll_transmit(ms(0), &mut buf).unwrap();
    assert_eq!(&buf[..n], mbap(3, 0xFF, &[0x41, 0x01, 0x02]));
    assert_eq!(p.poll_transmit(ms(0), &mut buf), None);
    assert_eq!(p.stats().requests, 3);
    assert_eq!(p.poll_timeout(), Some(ms(1_000)), "each awaits its reply from its transmission");
}

#[test]
fn a_request_goes_out_no_sooner_than_it_was_submitted_and_its_timeout_runs_from_then() {
    let mut p = pipeline(2);
    p.submit(ms(10), 1, &read_holding(0, 1), Duration::from_millis(100)).unwrap();
    assert!(transmit_all(&mut p, ms(9)).is_empty());
    assert_eq!(transmit_all(&mut p, ms(25)).len(), 1);
    assert_eq!(p.poll_timeout(), Some(ms(125)));
    p.handle_timeout(ms(124));
    assert!(events(&mut p).is_empty());
    p.handle_timeout(ms(125));
    assert_eq!(
        events(&mut p).pop().map(|(_, d)| d),
        Some(Done::Failed(MasterError::Timeout { waited: Duration::from_millis(100), heard: None }))
    );
    assert_eq!(p.poll_timeout(), None);
}

#[test]
fn a_frame_too_big_for_the_buffer_fails_its_request_and_the_next_one_goes_out() {
    let mut p = pipeline(2);
    let big = p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    let small = p.submit_raw(ms(0), 1, &[0x11], TIMEOUT).unwrap();
    let mut buf = [0u8; 8];
    assert_eq!(p.poll_transmit(ms(0), &mut buf), Some(8), "the raw request's frame fits");
    assert_eq!(&buf, &mbap(small.transaction(), 1, &[0x11])[..]);
    assert_eq!(
        events(&mut p),
        [(big, Done::Failed(MasterError::TransmitBuffer(BufferTooSmall { needed: 12, available: 8 })))]
    );
    assert_eq!((p.stats().requests, p.stats().bad_replies), (1, 1));
}

// ---- Timeouts and late replies ----------------------------------------------------------

#[test]
fn one_request_times_out_while_the_others_are_answered_and_its_late_reply_goes_to_no_one() {
    let mut p = pipeline(4);
    let t = in_flight(&mut p, 3, 1);
    p.on_bytes(ms(100), &mbap(t[0].transaction(), 1, &registers(&[10])));
    p.on_bytes(ms(200), &mbap(t[2].transaction(), 1, &registers(&[12])));
    p.handle_timeout(ms(1_000));
    assert_eq!(
        events(&mut p),
        [
            (t[0], Done::Registers(std::vec![10])),
            (t[2], Done::Registers(std::vec![12])),
            (t[1], Done::Failed(MasterError::Timeout { waited: TIMEOUT, heard: None })),
        ]
    );
    // The next request is in flight when the late reply comes: it is dropped, not taken.
    let next = p.submit(ms(1_000), 1, &read_holding(1, 1), TIMEOUT).unwrap();
    assert_eq!(next.transaction(), 4, "a new id, not the one that timed out");
    transmit_all(&mut p, ms(1_000));
    p.on_bytes(ms(1_100), &mbap(t[1].transaction(), 1, &registers(&[0xDEAD])));
    assert!(events(&mut p).is_empty(), "the late reply was taken");
    let stats = p.stats();
    assert_eq!((stats.late_replies, stats.ignored_frames, stats.timeouts), (1, 1, 1));
    // Its id is forgotten: a second copy is just a frame under an unknown id, and named.
    p.on_bytes(ms(1_200), &mbap(t[1].transaction(), 1, &registers(&[0xDEAD])));
    assert_eq!((p.stats().late_replies, p.stats().ignored_frames), (1, 2));
    p.on_bytes(ms(1_300), &mbap(next.transaction(), 1, &registers(&[11])));
    assert_eq!(events(&mut p), [(next, Done::Registers(std::vec![11]))]);
}

#[test]
fn a_late_reply_from_another_unit_than_the_request_that_timed_out_is_not_taken_for_it() {
    let mut p = pipeline(2);
    let t = in_flight(&mut p, 1, 1);
    p.handle_timeout(ms(1_000));
    events(&mut p);
    let other = p.submit(ms(1_000), 2, &read_holding(0, 1), TIMEOUT).unwrap();
    transmit_all(&mut p, ms(1_000));
    p.on_bytes(ms(1_100), &mbap(t[0].transaction(), 2, &registers(&[1])));
    assert_eq!(p.stats().late_replies, 0);
    p.handle_timeout(ms(2_000));
    let heard = Some(HeardInstead::OtherTransaction { transaction: t[0].transaction(), expected: other.transaction() });
    assert_eq!(events(&mut p), [(other, Done::Failed(MasterError::Timeout { waited: TIMEOUT, heard }))]);
    // The right unit's late reply is still recognised.
    p.on_bytes(ms(2_100), &mbap(t[0].transaction(), 1, &registers(&[1])));
    assert_eq!(p.stats().late_replies, 1);
}

#[test]
fn a_reply_under_an_unknown_id_is_ignored_and_named_in_the_timeout_of_each_request_to_that_unit() {
    let mut p = pipeline(4);
    let one = p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    let also_one = p.submit(ms(0), 1, &read_holding(1, 1), TIMEOUT).unwrap();
    let two = p.submit(ms(0), 2, &read_holding(0, 1), TIMEOUT).unwrap();
    transmit_all(&mut p, ms(0));
    p.on_bytes(ms(10), &mbap(99, 1, &registers(&[5])));
    assert!(events(&mut p).is_empty());
    assert_eq!(p.stats().ignored_frames, 1);
    p.handle_timeout(ms(1_000));
    let named = |expected: Ticket| {
        let heard = Some(HeardInstead::OtherTransaction { transaction: 99, expected: expected.transaction() });
        Done::Failed(MasterError::Timeout { waited: TIMEOUT, heard })
    };
    assert_eq!(
        events(&mut p),
        [
            (one, named(one)),
            (also_one, named(also_one)),
            (two, Done::Failed(MasterError::Timeout { waited: TIMEOUT, heard: None })),
        ]
    );
}

#[test]
fn bytes_that_make_no_frame_are_named_by_every_request_awaiting_a_reply() {
    let mut p = pipeline(4);
    let t = [
        p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap(),
        p.submit(ms(0), 2, &read_holding(0, 1), TIMEOUT).unwrap(),
    ];
    transmit_all(&mut p, ms(0));
    // Protocol id 0x1234: a bad header, skipped byte by byte by the lenient receiver.
    p.on_bytes(ms(10), &[0x00, 0x07, 0x12, 0x34, 0x00, 0x05, 0x01, 0xFF]);
    p.handle_timeout(ms(1_000));
    for (ticket, done) in events(&mut p) {
        assert!(t.contains(&ticket));
        let Done::Failed(MasterError::Timeout { heard: Some(HeardInstead::Garbage { reason, .. }), .. }) = done else {
            panic!("{done:?}")
        };
        assert_eq!(reason, DiscardReason::BadHeader);
    }
}

// ---- Matching under the right id --------------------------------------------------------

#[test]
fn under_the_right_id_a_frame_from_another_unit_or_with_another_function_is_ignored_and_named() {
    let mut p = pipeline(2);
    let t = in_flight(&mut p, 1, 5);
    let id = t[0].transaction();
    p.on_bytes(ms(10), &mbap(id, 6, &registers(&[1]))); // another unit
    p.on_bytes(ms(20), &mbap(id, 5, &[0x04, 0x02, 0x00, 0x01])); // another function
    assert!(events(&mut p).is_empty());
    assert_eq!(p.stats().ignored_frames, 2);
    p.on_bytes(ms(30), &mbap(id, 5, &registers(&[42])));
    assert_eq!(events(&mut p), [(t[0], Done::Registers(std::vec![42]))]);
    // Timed out instead, the wrong function (a frame from the unit asked) is what is named.
    let mut p = pipeline(2);
    let t = in_flight(&mut p, 1, 5);
    let id = t[0].transaction();
    p.on_bytes(ms(10), &mbap(id, 5, &[0x04, 0x02, 0x00, 0x01]));
    p.on_bytes(ms(20), &mbap(id, 6, &registers(&[1])));
    p.handle_timeout(ms(1_000));
    let heard = Some(HeardInstead::WrongFunction { function: 0x04, expected: 0x03 });
    assert_eq!(events(&mut p), [(t[0], Done::Failed(MasterError::Timeout { waited: TIMEOUT, heard }))]);
    // Only another unit's frame: that is named.
    let mut p = pipeline(2);
    let t = in_flight(&mut p, 1, 5);
    p.on_bytes(ms(20), &mbap(t[0].transaction(), 6, &registers(&[1])));
    p.handle_timeout(ms(1_000));
    let heard = Some(HeardInstead::OtherUnit { unit: 6, function: 0x03 });
    assert_eq!(events(&mut p), [(t[0], Done::Failed(MasterError::Timeout { waited: TIMEOUT, heard }))]);
}

#[test]
fn a_reply_that_does_not_answer_its_request_fails_only_that_request() {
    let mut p = pipeline(4);
    let t = [
        p.submit(ms(0), 1, &read_holding(0, 2), TIMEOUT).unwrap(),
        p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap(),
        p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap(),
        p.submit(ms(0), 1, &Request::WriteSingleRegister(WriteRegister { address: 7, value: 9 }), TIMEOUT).unwrap(),
    ];
    transmit_all(&mut p, ms(0));
    p.on_bytes(ms(10), &mbap(t[0].transaction(), 1, &registers(&[1]))); // one register of two
    p.on_bytes(ms(11), &mbap(t[1].transaction(), 1, &[0x03, 0x03, 0x00, 0x01, 0x02])); // byte count 3
    p.on_bytes(ms(12), &mbap(t[2].transaction(), 1, &registers(&[3])));
    p.on_bytes(ms(13), &mbap(t[3].transaction(), 1, &[0x06, 0x00, 0x07, 0x00, 0x08])); // another value
    assert_eq!(
        events(&mut p),
        [
            (t[0], Done::Failed(MasterError::Mismatch { field: "register count", expected: 2, received: 1 })),
            (t[1], Done::Failed(MasterError::BadResponse(PduError::ByteCountMismatch { declared: 3, expected: 4 }))),
            (t[2], Done::Registers(std::vec![3])),
            (t[3], Done::Failed(MasterError::Mismatch { field: "value", expected: 9, received: 8 })),
        ]
    );
    assert_eq!((p.stats().bad_replies, p.stats().responses), (3, 1));
}

#[test]
fn several_replies_in_one_chunk_and_one_split_across_chunks_are_all_found() {
    for chunk in [1, 5, 11, 1000] {
        let mut p = pipeline(4);
        let t = in_flight(&mut p, 3, 1);
        let stream: Vec<u8> = [2usize, 0, 1]
            .iter()
            .flat_map(|&i| mbap(t[i].transaction(), 1, &registers(&[u16::try_from(i).unwrap()])))
            .collect();
        for (k, piece) in (0u64..).zip(stream.chunks(chunk)) {
            p.on_bytes(ms(10 + k), piece);
        }
        let done = events(&mut p);
        assert_eq!(
            done,
            [
                (t[2], Done::Registers(std::vec![2])),
                (t[0], Done::Registers(std::vec![0])),
                (t[1], Done::Registers(std::vec![1])),
            ],
            "in chunks of {chunk}"
        );
    }
}

// ---- Kinds of request -------------------------------------------------------------------

#[test]
fn raw_requests_get_their_reply_unparsed_and_an_exception_as_an_exception() {
    let mut p = pipeline(4);
    // Quantity 0 is invalid; a raw request goes out anyway.
    let invalid = p.submit_raw(ms(0), 1, &[0x03, 0x00, 0x00, 0x00, 0x00], TIMEOUT).unwrap();
    let custom = p.submit_raw(ms(0), 1, &[0x41, 0xAA], TIMEOUT).unwrap();
    assert_eq!(transmit_all(&mut p, ms(0))[0], mbap(1, 1, &[0x03, 0x00, 0x00, 0x00, 0x00]));
    p.on_bytes(ms(10), &mbap(custom.transaction(), 1, &[0x41, 0xBB, 0xCC]));
    p.on_bytes(ms(11), &mbap(invalid.transaction(), 1, &[0x83, 0x03]));
    assert_eq!(
        events(&mut p),
        [(custom, Done::Raw(std::vec![0x41, 0xBB, 0xCC])), (invalid, Done::Exception(ExceptionCode::IllegalDataValue))]
    );
    assert_eq!(
        p.submit_raw(ms(20), 1, &[], TIMEOUT),
        Err(SubmitError::Encode(BufferTooSmall { needed: 1, available: MAX_PDU_LEN }))
    );
    assert_eq!(
        p.submit_raw(ms(20), 1, &[0x41; MAX_PDU_LEN + 1], TIMEOUT),
        Err(SubmitError::Encode(BufferTooSmall { needed: MAX_PDU_LEN + 1, available: MAX_PDU_LEN }))
    );
    assert_eq!(p.outstanding(), 0, "a refused request holds no slot");
}

#[test]
fn an_exception_ends_only_its_request_as_a_result_not_a_failure() {
    let mut p = pipeline(2);
    let t = in_flight(&mut p, 2, 1);
    p.on_bytes(ms(10), &mbap(t[1].transaction(), 1, &[0x83, 0x02]));
    p.on_bytes(ms(20), &mbap(t[0].transaction(), 1, &registers(&[1])));
    assert_eq!(
        events(&mut p),
        [(t[1], Done::Exception(ExceptionCode::IllegalDataAddress)), (t[0], Done::Registers(std::vec![1]))]
    );
    assert_eq!((p.stats().exceptions, p.stats().responses, p.stats().bad_replies), (1, 1, 0));
}

#[test]
fn force_listen_only_completes_as_sent_once_transmitted_and_unit_0_is_awaited_like_any_unit() {
    let mut p = pipeline(2);
    let listen = Request::Diagnostics(Diagnostic::with_word(DiagnosticCode::ForceListenOnly, 0));
    let quiet = p.submit(ms(0), 1, &listen, TIMEOUT).unwrap();
    let zero = p.submit(ms(0), 0, &read_holding(0, 1), TIMEOUT).unwrap();
    assert!(events(&mut p).is_empty(), "nothing completes before it is transmitted");
    transmit_all(&mut p, ms(0));
    assert_eq!(events(&mut p), [(quiet, Done::Sent)]);
    assert_eq!(p.poll_timeout(), Some(ms(1_000)), "unit 0 awaits its reply on TCP");
    p.on_bytes(ms(5), &mbap(zero.transaction(), 0, &registers(&[9])));
    assert_eq!(events(&mut p), [(zero, Done::Registers(std::vec![9]))]);
    let stats = p.stats();
    assert_eq!((stats.requests, stats.responses, stats.broadcasts), (2, 1, 0));
}

#[test]
fn bit_reads_are_trimmed_to_the_quantity_asked() {
    let mut p = pipeline(2);
    let coils = p.submit(ms(0), 8, &Request::ReadCoils(ReadBits::new(6, 6).unwrap()), TIMEOUT).unwrap();
    transmit_all(&mut p, ms(0));
    // 3G3RX p.4-168: coils 7..12 = 1,1,1,0,1,0 in one byte 0x17.
    p.on_bytes(ms(10), &mbap(coils.transaction(), 8, &[0x01, 0x01, 0x17]));
    assert_eq!(events(&mut p), [(coils, Done::Bits(std::vec![true, true, true, false, true, false]))]);
}

// ---- Transaction ids --------------------------------------------------------------------

#[test]
fn transaction_ids_wrap_from_0xffff_to_0_skipping_one_still_in_flight() {
    // Request 1 stays in flight while 65 535 others come and go: after 0xFFFF and 0, the
    // next id is 2.
    let mut p = pipeline(2);
    let long = p.submit(ms(0), 1, &read_holding(0, 1), Duration::from_secs(1_000_000)).unwrap();
    assert_eq!(long.transaction(), 1);
    transmit_all(&mut p, ms(0));
    let mut buf = [0u8; MAX_ADU_LEN];
    for expected in (2..=0xFFFF).chain([0, 2]) {
        let ticket = p.submit_raw(ms(1), 1, &[0x41], TIMEOUT).unwrap();
        assert_eq!(ticket.transaction(), expected);
        p.poll_transmit(ms(1), &mut buf).unwrap();
        p.on_bytes(ms(1), &mbap(expected, 1, &[0x41]));
        let (done, completion) = p.poll_event().unwrap();
        assert_eq!((done, completion), (ticket, Completion::Raw(&[0x41])));
    }
    p.on_bytes(ms(2), &mbap(1, 1, &registers(&[1])));
    assert_eq!(events(&mut p), [(long, Done::Registers(std::vec![1]))]);
}

#[test]
fn transaction_ids_skip_those_in_flight_and_those_that_recently_timed_out() {
    let mut p = pipeline(4);
    p.set_last_transaction(0xFFFC);
    let answered = p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    let timed_out = p.submit(ms(0), 1, &read_holding(0, 1), Duration::from_millis(10)).unwrap();
    let held = p.submit(ms(0), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    assert_eq!([answered, timed_out, held].map(Ticket::transaction), [0xFFFD, 0xFFFE, 0xFFFF]);
    transmit_all(&mut p, ms(0));
    p.on_bytes(ms(5), &mbap(0xFFFD, 1, &registers(&[1])));
    p.handle_timeout(ms(10));
    assert_eq!(events(&mut p).len(), 2, "one answered, one timed out");
    // 0xFFFD is free again; 0xFFFE timed out (its late reply may still come), 0xFFFF is in flight.
    p.set_last_transaction(0xFFFD);
    let next = p.submit(ms(10), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    assert_eq!(next.transaction(), 0);
    // Once the late reply has come, its id may be given again.
    p.on_bytes(ms(20), &mbap(0xFFFE, 1, &registers(&[2])));
    assert_eq!(p.stats().late_replies, 1);
    p.set_last_transaction(0xFFFD);
    assert_eq!(p.submit(ms(20), 1, &read_holding(0, 1), TIMEOUT).unwrap().transaction(), 0xFFFE);
}

/// `n` requests to unit 1 one after the other, each timing out (1 s) in turn from `from`;
/// returns their ids and the instant the last one timed out.
fn time_out_in_turn(p: &mut Pipeline, n: usize, from: u64) -> (Vec<u16>, u64) {
    let mut ids = Vec::new();
    let mut at = from;
    for _ in 0..n {
        let ticket = p.submit(ms(at), 1, &read_holding(0, 1), TIMEOUT).unwrap();
        transmit_all(p, ms(at));
        at += 1_000;
        p.handle_timeout(ms(at));
        assert!(matches!(events(p)[..], [(t, Done::Failed(MasterError::Timeout { .. }))] if t == ticket));
        ids.push(ticket.transaction());
    }
    (ids, at)
}

#[test]
fn a_timed_out_id_stays_out_of_use_for_its_late_window_whatever_the_timeouts_after_it() {
    let mut p = pipeline(4);
    p.set_late_window(Some(Duration::from_secs(60)));
    // Id 1 times out at 1 s, then 24 more in a row (ids 2..=25) until 25 s: inside its window.
    let (ids, at) = time_out_in_turn(&mut p, 25, 0);
    assert_eq!((ids[0], ids[24], at), (1, 25, 25_000));
    // The ids wrap round (a fast line, 65,536 requests within the window): the next request
    // does not take id 1, nor any of the 25, whose late replies may all still come.
    p.set_last_transaction(0);
    let next = p.submit(ms(at), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    assert_eq!(next.transaction(), 26);
    transmit_all(&mut p, ms(at));
    // Id 1's late reply comes, 30 s after its timeout: dropped, not handed to anyone.
    p.on_bytes(ms(31_000), &mbap(1, 1, &registers(&[0xDEAD])));
    assert!(events(&mut p).is_empty(), "the late reply was taken");
    assert_eq!(p.stats().late_replies, 1);
    p.on_bytes(ms(31_001), &mbap(26, 1, &registers(&[7])));
    assert_eq!(events(&mut p), [(next, Done::Registers(std::vec![7]))]);
}

#[test]
fn a_timed_out_id_is_given_again_once_its_window_has_passed_and_not_a_moment_before() {
    let mut p = pipeline(MAX_IN_FLIGHT);
    p.set_late_window(Some(Duration::from_secs(10)));
    // 20 timeouts: ids 1..=16 at 1 s (their windows end at 11 s), 17..=20 at 2 s (at 12 s).
    in_flight(&mut p, 16, 1);
    p.handle_timeout(ms(1_000));
    assert_eq!(events(&mut p).len(), 16);
    for _ in 0..4 {
        p.submit(ms(1_000), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    }
    transmit_all(&mut p, ms(1_000));
    p.handle_timeout(ms(2_000));
    assert_eq!(events(&mut p).len(), 4);
    p.set_last_transaction(0);
    let before = p.submit(ms(10_999), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    assert_eq!(before.transaction(), 21, "every one of the 20 is still out of use");
    p.set_last_transaction(0);
    let after = p.submit(ms(11_000), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    assert_eq!(after.transaction(), 1, "id 1's window has passed");
    // Past its window, a frame under id 2 is no late reply: an unknown id, ignored.
    transmit_all(&mut p, ms(11_000));
    p.on_bytes(ms(11_001), &mbap(2, 1, &registers(&[1])));
    assert_eq!((p.stats().late_replies, p.stats().ignored_frames), (0, 1));
    assert!(events(&mut p).is_empty());
}

#[test]
fn by_default_the_late_window_is_twice_the_requests_timeout() {
    let mut p = pipeline(1);
    let (ids, at) = time_out_in_turn(&mut p, 1, 0);
    assert_eq!((ids[0], at), (1, 1_000));
    p.set_last_transaction(0);
    let inside = p.submit(ms(2_999), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    assert_eq!(inside.transaction(), 2, "id 1's window ends at 3 s");
    p.abort();
    let mut p = pipeline(1);
    time_out_in_turn(&mut p, 1, 0);
    p.set_last_transaction(0);
    assert_eq!(p.submit(ms(3_000), 1, &read_holding(0, 1), TIMEOUT).unwrap().transaction(), 1);
}

#[test]
fn with_more_timeouts_in_one_window_than_it_remembers_the_id_whose_window_ends_soonest_is_forgotten() {
    let mut p = pipeline(1);
    p.set_late_window(Some(Duration::from_secs(100_000)));
    let (ids, _) = time_out_in_turn(&mut p, LATE_IDS + 1, 0);
    // Id 1 (the soonest to end) gave its place to the last; id 2 is still remembered.
    p.on_bytes(ms(300_000), &mbap(ids[1], 1, &registers(&[1])));
    p.on_bytes(ms(300_001), &mbap(ids[0], 1, &registers(&[1])));
    p.on_bytes(ms(300_002), &mbap(ids[LATE_IDS], 1, &registers(&[1])));
    assert_eq!((p.stats().late_replies, p.stats().ignored_frames), (2, 3));
}

// ---- Abort ------------------------------------------------------------------------------

#[test]
fn abort_drops_every_request_without_a_completion_and_frees_every_slot() {
    let mut p = pipeline(4);
    let t = in_flight(&mut p, 3, 1);
    p.on_bytes(ms(10), &mbap(t[0].transaction(), 1, &registers(&[1]))); // ended, not polled
    p.handle_timeout(ms(1_000)); // the other two time out, not polled
    p.submit(ms(1_000), 1, &read_holding(0, 1), TIMEOUT).unwrap(); // queued
    let half = mbap(9, 1, &registers(&[1]));
    p.on_bytes(ms(1_000), &half[..4]); // half a frame
    p.abort();
    assert_eq!((p.outstanding(), p.poll_timeout()), (0, None));
    assert!(events(&mut p).is_empty());
    assert!(transmit_all(&mut p, ms(1_000)).is_empty());
    // The late ids are forgotten, and the receiver starts afresh.
    p.on_bytes(ms(1_001), &mbap(t[1].transaction(), 1, &registers(&[1])));
    assert_eq!(p.stats().late_replies, 0);
    let fresh = p.submit(ms(1_001), 1, &read_holding(0, 1), TIMEOUT).unwrap();
    assert_eq!(fresh.slot(), 0);
    transmit_all(&mut p, ms(1_001));
    p.on_bytes(ms(1_002), &mbap(fresh.transaction(), 1, &registers(&[5])));
    assert_eq!(events(&mut p), [(fresh, Done::Registers(std::vec![5]))]);
}

// ---- Any interleaving -------------------------------------------------------------------

mod interleavings {
    use proptest::prelude::*;
    use proptest::sample::Index;

    use super::*;

    #[derive(Clone, Debug)]
    enum Op {
        /// Submits a request of kind `kind % 5` (a register read, a coil read, 0x08/0x04, a
        /// raw custom code) to `unit`.
        Submit {
            unit: u8,
            kind: u8,
            quantity: u16,
            timeout_ms: u64,
        },
        /// Queues a frame: under the id of a request picked by `pick` (or `id` if `random`),
        /// from its unit or the next one, with a plausible reply, an exception or any PDU.
        Reply {
            pick: Index,
            random: bool,
            id: u16,
            other_unit: bool,
            body: u8,
            data: Vec<u8>,
        },
        /// Queues bytes that are no frame.
        Garbage(Vec<u8>),
        /// After `gap_ms`, delivers `len` of the bytes queued.
        Deliver {
            gap_ms: u64,
            len: usize,
        },
        /// Handles the timeouts due within `ms`.
        Wait {
            ms: u64,
        },
        /// Polls the completions.
        Poll,
        Abort,
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            8 => (0u8..3, any::<u8>(), 1u16..20, 1u64..60)
                .prop_map(|(unit, kind, quantity, timeout_ms)| Op::Submit { unit, kind, quantity, timeout_ms }),
            12 => (any::<Index>(), prop::bool::weighted(0.2), any::<u16>(), prop::bool::weighted(0.2), any::<u8>(),
                  prop::collection::vec(any::<u8>(), 0..8))
                .prop_map(|(pick, random, id, other_unit, body, data)| Op::Reply { pick, random, id, other_unit, body, data }),
            2 => prop::collection::vec(any::<u8>(), 1..12).prop_map(Op::Garbage),
            8 => (0u64..30, 0usize..200).prop_map(|(gap_ms, len)| Op::Deliver { gap_ms, len }),
            4 => (0u64..80).prop_map(|ms| Op::Wait { ms }),
            4 => Just(Op::Poll),
            1 => Just(Op::Abort),
        ]
    }

    /// One submitted request, as the test sees it.
    #[derive(Debug)]
    struct Record {
        ticket: Ticket,
        unit: u8,
        pdu: Vec<u8>,
        raw: bool,
        /// How many frames the shadow receiver had logged when it went out.
        transmitted: Option<usize>,
        ended: bool,
        aborted: bool,
    }

    struct Run {
        p: Pipeline,
        shadow: MbapCodec,
        /// Every frame the shadow receiver found: id, unit, PDU.
        log: Vec<(u16, u8, Vec<u8>)>,
        sent: Vec<Record>,
        /// Indexes in `sent` of the tickets outstanding.
        live: HashMap<Ticket, usize>,
        /// Indexes in `sent` not transmitted yet, in submission order.
        queue: Vec<usize>,
        pending: Vec<u8>,
        t: Instant,
    }

    impl Run {
        fn check(&self) -> Result<(), TestCaseError> {
            prop_assert!(self.p.outstanding() <= self.p.limit());
            prop_assert_eq!(self.p.outstanding(), self.live.len());
            Ok(())
        }

        fn transmit(&mut self) -> Result<(), TestCaseError> {
            let mut buf = [0u8; MAX_ADU_LEN];
            while let Some(n) = self.p.poll_transmit(self.t, &mut buf) {
                let frame = &buf[..n];
                prop_assert!(!self.queue.is_empty(), "transmitted with nothing queued");
                let index = self.queue.remove(0);
                let sent = &mut self.sent[index];
                prop_assert_eq!(frame, &mbap(sent.ticket.transaction(), sent.unit, &sent.pdu)[..], "not in order");
                sent.transmitted = Some(self.log.len());
            }
            Ok(())
        }

        fn poll(&mut self) -> Result<(), TestCaseError> {
            while let Some((ticket, completion)) = self.p.poll_event() {
                let index = self.live.remove(&ticket);
                prop_assert!(index.is_some(), "{:?} completed twice or never submitted", ticket);
                let sent = &mut self.sent[index.unwrap_or_default()];
                prop_assert!(!sent.ended);
                sent.ended = true;
                let from = sent.transmitted;
                prop_assert!(from.is_some(), "{:?} before it went out", completion);
                let from = from.unwrap_or_default();
                let fc = sent.pdu[0];
                // The frame that ended it: the first after it went out under its id, from its
                // unit, with its function code or the exception form.
                let reply = self.log[from..]
                    .iter()
                    .find(|(id, unit, pdu)| *id == ticket.transaction() && *unit == sent.unit && pdu[0] & 0x7F == fc);
                match completion {
                    Completion::Response(response) => {
                        prop_assert!(!sent.raw);
                        prop_assert!(reply.is_some(), "a response without a frame under its id from its unit");
                        let reply = reply.map(|r| r.2.clone()).unwrap_or_default();
                        let mut out = [0u8; MAX_PDU_LEN];
                        let n = response.emit(&mut out).unwrap();
                        let mut want = reply.clone();
                        if let Response::ReadCoils(bits) = response {
                            // Trimmed to the quantity asked: the bits past it go out as zeros.
                            let quantity = u16::from_be_bytes([sent.pdu[3], sent.pdu[4]]);
                            prop_assert_eq!(bits.values().len(), usize::from(quantity));
                            want.truncate(n);
                            if !quantity.is_multiple_of(8) {
                                want[n - 1] &= (1u8 << (quantity % 8)) - 1;
                            }
                        }
                        prop_assert_eq!(&out[..n], &want[..], "the response is not its frame's");
                    }
                    Completion::Raw(pdu) => {
                        prop_assert!(sent.raw);
                        prop_assert_eq!(Some(pdu), reply.map(|r| &r.2[..]));
                    }
                    Completion::Exception(code) => {
                        let reply = reply.map(|r| r.2.clone()).unwrap_or_default();
                        prop_assert_eq!(reply.first().copied(), Some(fc | 0x80));
                        prop_assert_eq!(reply.get(1).copied(), Some(code.value()));
                    }
                    Completion::Sent => prop_assert_eq!(&sent.pdu[..], &[0x08, 0x00, 0x04, 0x00, 0x00][..]),
                    Completion::Failed(_) => {}
                }
            }
            Ok(())
        }

        /// Handles every timeout due by `until`, transmitting as a driver does.
        fn run_until(&mut self, until: Option<Instant>) -> Result<(), TestCaseError> {
            for round in 0.. {
                self.transmit()?;
                let Some(deadline) = self.p.poll_timeout() else { return Ok(()) };
                if until.is_some_and(|u| deadline > u) {
                    return Ok(());
                }
                prop_assert!(round < 100, "spinning at {:?}", deadline);
                self.t = self.t.max(deadline);
                self.p.handle_timeout(self.t);
            }
            Ok(())
        }

        fn submit(&mut self, unit: u8, kind: u8, quantity: u16, timeout: Duration) {
            let (request, raw) = match kind % 5 {
                0 | 1 => (Some(read_holding(0, quantity)), false),
                2 => (Some(Request::ReadCoils(ReadBits::new(0, quantity).unwrap())), false),
                3 => (Some(Request::Diagnostics(Diagnostic::with_word(DiagnosticCode::ForceListenOnly, 0))), false),
                _ => (None, true),
            };
            let mut pdu = [0u8; MAX_PDU_LEN];
            let len = request.map_or(2, |r| r.emit(&mut pdu).unwrap());
            if raw {
                pdu[..2].copy_from_slice(&[0x41, kind]);
            }
            let had_room = self.p.has_room();
            let result = match request {
                Some(r) => self.p.submit(self.t, unit, &r, timeout),
                None => self.p.submit_raw(self.t, unit, &pdu[..len], timeout),
            };
            match result {
                Ok(ticket) => {
                    assert!(had_room);
                    assert!(ticket.slot() < self.p.limit());
                    self.live.insert(ticket, self.sent.len());
                    self.queue.push(self.sent.len());
                    let pdu = pdu[..len].to_vec();
                    self.sent.push(Record { ticket, unit, pdu, raw, transmitted: None, ended: false, aborted: false });
                }
                Err(e) => {
                    assert!(!had_room);
                    assert_eq!(e, SubmitError::Full { limit: self.p.limit() });
                }
            }
        }

        fn reply(&mut self, pick: Index, random: bool, id: u16, other_unit: bool, body: u8, data: &[u8]) {
            let target = (!random && !self.sent.is_empty()).then(|| &self.sent[pick.index(self.sent.len())]);
            let (id, unit, fc, quantity) = match target {
                Some(s) => {
                    let quantity =
                        u16::from_be_bytes([s.pdu.get(3).copied().unwrap_or(0), s.pdu.get(4).copied().unwrap_or(1)]);
                    (s.ticket.transaction(), s.unit, s.pdu[0], usize::from(quantity))
                }
                None => (id, 1, 0x03, 1),
            };
            let unit = if other_unit { unit.wrapping_add(1) } else { unit };
            let pdu = match body % 4 {
                // What the request calls for, filled from `data`.
                0 | 1 => {
                    let mut pdu = std::vec![fc];
                    let len = match fc {
                        0x01 => quantity.div_ceil(8),
                        0x03 => quantity * 2,
                        _ => data.len(),
                    };
                    if matches!(fc, 0x01 | 0x03) {
                        pdu.push(u8::try_from(len).unwrap());
                    }
                    pdu.extend((0..len).map(|i| data.get(i % data.len().max(1)).copied().unwrap_or(0x5A)));
                    pdu
                }
                2 => std::vec![fc | 0x80, data.first().copied().unwrap_or(0x02)],
                _ if data.is_empty() => std::vec![0x00],
                _ => data.to_vec(),
            };
            self.pending.extend_from_slice(&mbap(id, unit, &pdu));
        }

        fn deliver(&mut self, len: usize) {
            let n = len.min(self.pending.len());
            let bytes: Vec<u8> = self.pending.drain(..n).collect();
            self.p.on_bytes(self.t, &bytes);
            let log = &mut self.log;
            feed(&mut self.shadow, self.t, &bytes, |event| {
                if let RxEvent::Frame(frame) = event {
                    log.push((frame.header.transaction, frame.header.unit, frame.pdu.to_vec()));
                }
            });
        }

        fn abort(&mut self) {
            self.p.abort();
            self.shadow.reset();
            self.pending.clear();
            for (_, index) in self.live.drain() {
                self.sent[index].aborted = true;
            }
            self.queue.clear();
        }
    }

    proptest! {
        /// Whatever comes in whatever order: no panic, never more outstanding than the limit,
        /// frames out in submission order, every request ends once (or is aborted), and a
        /// reply is only ever handed to the request whose id and unit it carries.
        #[test]
        fn any_interleaving_of_submits_bytes_and_timeouts_keeps_every_request_to_its_own_reply(
            limit in 1usize..6,
            ops in prop::collection::vec(op(), 0..60),
        ) {
            let mut run = Run {
                p: pipeline(limit),
                shadow: MbapCodec::new(),
                log: Vec::new(),
                sent: Vec::new(),
                live: HashMap::new(),
                queue: Vec::new(),
                pending: Vec::new(),
                t: Instant::ZERO,
            };
            for op in ops {
                match op {
                    Op::Submit { unit, kind, quantity, timeout_ms } => {
                        run.submit(unit, kind, quantity, Duration::from_millis(timeout_ms));
                    }
                    Op::Reply { pick, random, id, other_unit, body, data } => {
                        run.reply(pick, random, id, other_unit, body, &data);
                    }
                    Op::Garbage(bytes) => run.pending.extend_from_slice(&bytes),
                    Op::Deliver { gap_ms, len } => {
                        let at = run.t.saturating_add(Duration::from_millis(gap_ms));
                        run.run_until(Some(at))?;
                        run.t = at;
                        run.deliver(len);
                    }
                    Op::Wait { ms } => {
                        let at = run.t.saturating_add(Duration::from_millis(ms));
                        run.run_until(Some(at))?;
                        run.t = at;
                    }
                    Op::Poll => run.poll()?,
                    Op::Abort => run.abort(),
                }
                run.transmit()?;
                run.check()?;
            }
            let rest = run.pending.len();
            run.deliver(rest);
            run.run_until(None)?;
            run.poll()?;
            prop_assert_eq!(run.p.outstanding(), 0);
            for sent in &run.sent {
                prop_assert!(sent.ended != sent.aborted, "{:?} neither ended nor aborted, or both", sent);
            }
        }
    }
}
