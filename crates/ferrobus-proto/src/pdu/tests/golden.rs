//! Golden PDUs: a request and a response for every function code, annotated byte by byte,
//! declared in `golden/access.rs`, `golden/serial.rs` and `golden/extended.rs`.
//!
//! Where a manual or the spec prints a frame, the PDU is that frame without its unit address
//! and CRC (sources in `reference/modbus-and-drives.md` §4.10 and §6, and the spec's examples
//! in MODBUS Application Protocol V1.1b3 §6). Each golden becomes a module with one test per
//! check of `tests.rs`; the value it is compared with is always built by the constructors.

use super::*;
use crate::codes::ExceptionCode;

/// Declares the goldens: `name: Request|Response [bytes] => value, |p| { field checks }`.
/// Each becomes a module of tests, and `all()` lists them.
macro_rules! goldens {
    ($(
        $(#[$meta:meta])*
        $name:ident: $dir:ident [$($byte:expr),+ $(,)?] => $value:expr,
        |$p:ident| $check:block
    )+) => {
        $(
            $(#[$meta])*
            mod $name {
                use super::*;

                pub(super) fn golden() -> Golden {
                    Golden { name: stringify!($name), pdu: vec![$($byte),+], value: Pdu::$dir($value) }
                }

                fn check_fields($p: &$dir<'_>) $check

                #[test]
                fn parses_to_its_value_with_the_expected_fields() {
                    let g = golden();
                    match assert_parses_to(g.value, &g.pdu) {
                        Pdu::$dir(parsed) => check_fields(&parsed),
                        other => panic!("{other:?}"),
                    }
                    match g.value {
                        Pdu::$dir(built) => check_fields(&built),
                        other => panic!("{other:?}"),
                    }
                }

                #[test]
                fn emit_writes_exactly_these_bytes_and_nothing_after() {
                    let g = golden();
                    assert_emits(g.value, &g.pdu);
                    assert_emits(assert_parses_to(g.value, &g.pdu), &g.pdu);
                }

                #[test]
                fn emit_into_every_shorter_buffer_is_buffer_too_small() {
                    let g = golden();
                    assert_short_buffers_fail(g.value, &g.pdu);
                    assert_short_buffers_fail(assert_parses_to(g.value, &g.pdu), &g.pdu);
                }

                #[test]
                fn every_strict_prefix_is_truncated_unless_the_layout_is_open() {
                    let g = golden();
                    assert_prefixes(g.value.dir(), &g.pdu);
                }

                #[test]
                fn one_extra_byte_is_trailing_unless_the_layout_is_open() {
                    let g = golden();
                    assert_extra_byte(g.value.dir(), &g.pdu);
                }

                #[test]
                fn wire_len_never_contradicts_the_body_length() {
                    let g = golden();
                    assert_wire_len(g.value.dir(), &g.pdu);
                }
            }
        )+

        /// Every golden above.
        pub(super) fn all() -> Vec<Golden> {
            vec![$($name::golden()),+]
        }
    };
}

mod access;
mod extended;
mod serial;

/// Every golden of the three files.
fn all() -> Vec<Golden> {
    [access::all(), serial::all(), extended::all()].into_iter().flatten().collect()
}

// ── Tables that apply the same checks to families of PDUs ───────────────────────────────────

#[test]
fn diagnostic_counter_sub_functions_0a_to_12_and_14_are_goldens_too() {
    use DiagnosticCode::*;
    let counters = [
        (ClearCounters, 0x0000_u16), // the echo of its data
        (BusMessageCount, 0x0123),
        (BusCommErrorCount, 0x0002),
        (BusExceptionErrorCount, 0x0003),
        (ServerMessageCount, 0x0120),
        (ServerNoResponseCount, 0x0004),
        (ServerNakCount, 0x0000),
        (ServerBusyCount, 0x0001),
        (BusCharacterOverrunCount, 0x0005),
        (ClearOverrunCounter, 0x0000), // the echo of its data
    ];
    let subs: Vec<u16> = counters.iter().map(|(code, _)| code.value()).collect();
    assert_eq!(subs, [0x0A, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x14]);
    for (code, count) in counters {
        let [sub_hi, sub_lo] = code.value().to_be_bytes();
        let [count_hi, count_lo] = count.to_be_bytes();
        #[rustfmt::skip]
        let request = [
            0x08,           // function code: 0x08 Diagnostics
            sub_hi, sub_lo, // sub-function
            0x00, 0x00,     // data: 0x0000
        ];
        #[rustfmt::skip]
        let response = [
            0x08,               // function code: 0x08 Diagnostics
            sub_hi, sub_lo,     // sub-function, echoed
            count_hi, count_lo, // the counter (or the echoed 0x0000)
        ];
        assert_golden(Pdu::Request(Request::Diagnostics(Diagnostic::with_word(code, 0))), &request);
        assert_golden(Pdu::Response(Response::Diagnostics(Diagnostic::with_word(code, count))), &response);
        let d = body!(Response::parse(&response).unwrap(), Response::Diagnostics);
        assert_eq!((d.sub_function(), d.word()), (code, Some(count)));
    }
}

#[test]
fn the_goldens_cover_every_function_code_both_ways_plus_custom_codes_and_exceptions() {
    let goldens = all();
    let has =
        |dir: Dir, wanted: &dyn Fn(&Pdu<'_>) -> bool| goldens.iter().any(|g| g.value.dir() == dir && wanted(&g.value));
    for &code in FunctionCode::ALL {
        let normal = |p: &Pdu<'_>| p.function() == code && !matches!(p, Pdu::Response(Response::Exception(_)));
        assert!(has(Dir::Request, &normal), "no request golden for {code}");
        assert!(has(Dir::Response, &normal), "no response golden for {code}");
    }
    assert!(has(Dir::Request, &|p| matches!(p, Pdu::Request(Request::Custom(_)))));
    assert!(has(Dir::Response, &|p| matches!(p, Pdu::Response(Response::Custom(_)))));
    for code in [
        ExceptionCode::Vendor(0x21),
        ExceptionCode::GatewayPathUnavailable,
        ExceptionCode::GatewayTargetDeviceFailedToRespond,
    ] {
        assert!(
            has(Dir::Response, &|p| matches!(p, Pdu::Response(Response::Exception(e)) if e.code() == code)),
            "{code}"
        );
    }
    let mut names: Vec<&str> = goldens.iter().map(|g| g.name).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), goldens.len(), "golden names are unique");
}

#[test]
fn pdus_display_their_function_code() {
    use std::string::ToString;
    let request = Request::parse(&[0x03, 0x00, 0x11, 0x00, 0x06]).unwrap();
    assert_eq!(request.to_string(), "0x03 Read Holding Registers");
    let e = Response::parse(&[0x86, 0x21]).unwrap().exception().unwrap();
    assert_eq!(e.to_string(), "exception 0x21 (vendor-specific) to 0x06 Write Single Register");
    let custom = Request::parse(&[0x41]).unwrap();
    assert_eq!(custom.to_string(), "0x41 (custom)");
}
