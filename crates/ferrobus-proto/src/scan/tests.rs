//! Tests of the scan decisions, on explicit time.

extern crate std;

use std::string::{String, ToString};
use std::vec::Vec;

use super::*;
use crate::frame::rtu::encode_pdu;

fn line(baud: u32, format: CharFormat) -> LineConfig {
    format.apply(LineConfig::new(baud).unwrap())
}

#[test]
fn formats_parse_in_either_case_and_nothing_else() {
    assert_eq!(CharFormat::parse("8E1"), Some(CharFormat::E1));
    assert_eq!(CharFormat::parse("8o1"), Some(CharFormat::O1));
    assert_eq!(CharFormat::parse("8n2"), Some(CharFormat::N2));
    assert_eq!(CharFormat::parse("8N1"), Some(CharFormat::N1));
    for bad in ["", "8E2", "7E1", "8X1", "8E1 ", "E1", "8N11"] {
        assert_eq!(CharFormat::parse(bad), None, "{bad:?}");
    }
    for format in CharFormat::ALL {
        assert_eq!(CharFormat::parse(format.name()), Some(format));
        assert_eq!(CharFormat::of(&line(9600, format)), Some(format));
    }
    let seven = line(9600, CharFormat::E1).with_data_bits(crate::frame::DataBits::Seven);
    assert_eq!(CharFormat::of(&seven), None);
}

#[test]
fn the_sweep_tries_19200_8e1_then_9600_8e1_then_8n1_then_the_rest() {
    let mut lines = Vec::new();
    for baud in [115_200, 1_200, 9_600, 38_400, 19_200, 14_400] {
        for format in CharFormat::ALL {
            lines.push(line(baud, format));
        }
    }
    lines.sort_by_key(rank);
    let names: Vec<String> = lines.iter().map(ToString::to_string).collect();
    let head: Vec<&str> = names.iter().take(8).map(String::as_str).collect();
    assert_eq!(
        head,
        ["19200 8E1", "9600 8E1", "19200 8N1", "9600 8N1", "19200 8N2", "19200 8O1", "9600 8N2", "9600 8O1"]
    );
    // The common rates before the uncommon ones, which go from the lowest.
    let order: Vec<u32> = lines.iter().map(LineConfig::baud).collect();
    let first = |baud: u32| order.iter().position(|&b| b == baud).unwrap();
    assert!(first(38_400) < first(115_200) && first(115_200) < first(1_200) && first(1_200) < first(14_400));
}

#[test]
fn the_probe_is_one_register_at_address_0_by_default_and_never_a_write() {
    let probe = Probe::default();
    assert_eq!(probe.request().unwrap(), Request::ReadHoldingRegisters(ReadRegisters::new(0, 1).unwrap()));
    assert_eq!((probe.request_len(), probe.reply_len()), (8, 7));
    let coils = Probe { function: ProbeFunction::Coils, address: 0xFFFF };
    assert_eq!(coils.request().unwrap(), Request::ReadCoils(ReadBits::new(0xFFFF, 1).unwrap()));
    assert_eq!(coils.reply_len(), 6);
    for code in 0..=u8::MAX {
        let function = ProbeFunction::from_code(code);
        assert_eq!(function.is_some(), (1..=4).contains(&code), "0x{code:02X}");
        if let Some(function) = function {
            assert_eq!(function.code(), code);
        }
    }
}

#[test]
fn the_timeout_is_the_first_byte_wait_plus_the_expected_reply_on_the_wire() {
    let timing = LineTiming::new(&line(19_200, CharFormat::E1));
    let probe = Probe::default();
    let t = ProbeTiming::new(&timing, &probe, DEFAULT_FIRST_BYTE);
    // 7 characters of 11 bits at 19200 baud: seven times the character time (572.917 µs, rounded up to the nanosecond).
    assert_eq!(t.reply, Duration::from_nanos(4_010_419));
    assert_eq!(t.timeout(), Duration::from_nanos(104_010_419));
    // One silent probe: 8 characters of request (4.583 ms), t3.5 (2.005 ms), the timeout.
    let silent = t.silent_probe(&timing, &probe);
    assert_eq!(silent, timing.transmit_time(8) + timing.t3_5() + t.timeout());
    assert_eq!(silent.as_micros(), 110_598);
    // 8N2 is 11 bits too; 8N1 is 10.
    let n1 = ProbeTiming::new(&LineTiming::new(&line(9_600, CharFormat::N1)), &probe, Duration::ZERO);
    assert_eq!(n1.reply, Duration::from_nanos(7_291_669));
}

#[test]
fn any_valid_frame_of_the_unit_proves_presence_and_broken_bytes_are_leads() {
    use crate::master::HeardInstead as M;
    assert_eq!(Answer::from_heard(None), Answer::Silence);
    let bad = Answer::from_heard(Some(M::BadChecksum { head: Some((5, 0x03)), expected: (5, 0x03) }));
    assert_eq!(bad, Answer::Lead(Lead::BadChecksum { head: Some((5, 0x03)) }));
    let garbage = Answer::from_heard(Some(M::Garbage { bytes: 3, reason: DiscardReason::Noise }));
    assert_eq!(garbage, Answer::Lead(Lead::Garbage { bytes: 3, reason: DiscardReason::Noise }));
    let other = Answer::from_heard(Some(M::OtherUnit { unit: 9, function: 0x03 }));
    assert_eq!(other, Answer::OtherTraffic { unit: 9, function: 0x03 });
    let wrong = Answer::from_heard(Some(M::WrongFunction { function: 0x04, expected: 0x03 }));
    assert_eq!(wrong, Answer::Mismatch);
    for present in [Answer::Reply, Answer::Exception(ExceptionCode::IllegalDataAddress), Answer::Mismatch] {
        assert!(present.proves_presence() && !present.is_lead(), "{present:?}");
    }
    for absent in [Answer::Silence, bad, garbage, other] {
        assert!(!absent.proves_presence(), "{absent:?}");
    }
    assert!(bad.is_lead() && garbage.is_lead() && !other.is_lead() && !Answer::Silence.is_lead());
}

/// A frame of `pdu` from `unit`, fed to `listener` one byte per character time from `at`;
/// returns the instant after its last byte.
fn send(listener: &mut Survey, timing: &LineTiming, at: Instant, unit: u8, pdu: &[u8], corrupt: bool) -> Instant {
    let mut frame = [0u8; 256];
    let n = encode_pdu(unit, pdu, &mut frame).unwrap();
    if corrupt {
        frame[n - 1] ^= 0x01;
    }
    let mut now = at;
    for byte in &frame[..n] {
        now = now.checked_add(timing.char_time()).unwrap();
        listener.on_bytes(now, core::slice::from_ref(byte));
    }
    now
}

fn settle(listener: &mut Survey, after: Instant) {
    while let Some(due) = listener.poll_timeout() {
        assert!(due >= after, "a timeout in the past: {due:?} < {after:?}");
        listener.handle_timeout(due);
    }
}

#[test]
fn a_listener_that_hears_crc_valid_requests_and_replies_reports_another_master_and_its_units() {
    let timing = LineTiming::new(&line(19_200, CharFormat::E1));
    let mut listener = Survey::new(timing);
    let gap = timing.t3_5();
    let mut now = send(&mut listener, &timing, Instant::ZERO, 7, &[0x03, 0x00, 0x00, 0x00, 0x01], false);
    now = send(&mut listener, &timing, now.checked_add(gap).unwrap(), 7, &[0x03, 0x02, 0x00, 0x2A], false);
    now = send(&mut listener, &timing, now.checked_add(gap).unwrap(), 12, &[0x04, 0x00, 0x10, 0x00, 0x02], false);
    settle(&mut listener, now);
    let LineActivity::Traffic { units, requests, responses, either } = listener.heard() else {
        panic!("{:?}", listener.heard());
    };
    assert_eq!(units.iter().collect::<Vec<_>>(), [7, 12]);
    assert_eq!((requests, responses, either), (2, 1, 0));
}

#[test]
fn a_listener_that_hears_only_bad_crcs_reports_noise_and_silence_is_quiet() {
    let timing = LineTiming::new(&line(9_600, CharFormat::E1));
    let mut listener = Survey::new(timing);
    assert_eq!(listener.heard(), LineActivity::Quiet);
    let now = send(&mut listener, &timing, Instant::from_millis(5), 3, &[0x03, 0x00, 0x00, 0x00, 0x01], true);
    settle(&mut listener, now);
    assert_eq!(listener.heard(), LineActivity::Noise { bad_checksums: 1, bytes: 8 });
    // Then one good frame: traffic wins.
    let later = now.checked_add(timing.t3_5()).unwrap();
    let end = send(&mut listener, &timing, later, 3, &[0x03, 0x00, 0x00, 0x00, 0x01], false);
    settle(&mut listener, end);
    assert!(matches!(listener.heard(), LineActivity::Traffic { requests: 1, .. }), "{:?}", listener.heard());
}

#[test]
fn a_listener_decides_a_frame_of_unknown_length_only_after_the_silence() {
    let timing = LineTiming::new(&line(19_200, CharFormat::E1));
    let mut listener = Survey::new(timing);
    // 0x41 is a user-defined function code: its length is known only from the silence.
    let end = send(&mut listener, &timing, Instant::ZERO, 2, &[0x41, 0x01], false);
    assert_eq!(listener.heard(), LineActivity::Quiet);
    let due = listener.poll_timeout().unwrap();
    assert!(due >= end.checked_add(timing.t3_5()).unwrap());
    listener.handle_timeout(due);
    assert!(matches!(listener.heard(), LineActivity::Traffic { .. }), "{:?}", listener.heard());
}
