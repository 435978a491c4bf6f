//! `Response::parse` on arbitrary bytes. On success the response must emit exactly the bytes
//! it was parsed from (into a 253-byte buffer pre-filled with 0xA5, whose tail stays
//! untouched), `encoded_len` must agree, parsing the output must give the same value, and the
//! RTU length predictor must not contradict the parser.
#![no_main]

use ferrobus_proto::pdu::{MAX_PDU_LEN, Response, WireLen};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(response) = Response::parse(data) else { return };
    assert!(!data.is_empty() && data.len() <= MAX_PDU_LEN);

    let mut out = [0xA5u8; MAX_PDU_LEN];
    let n = response.emit(&mut out).expect("a parsed response fits in 253 bytes");
    assert_eq!(&out[..n], data, "emit(parse(x)) != x for {response:?}");
    assert!(out[n..].iter().all(|&b| b == 0xA5), "emit wrote past its length");
    assert_eq!(response.encoded_len(), n, "encoded_len disagrees with emit for {response:?}");
    assert_eq!(Response::parse(&out[..n]), Ok(response));
    assert_eq!(response.function().value(), data[0] & 0x7F);
    assert_eq!(response.exception().is_some(), data[0] & 0x80 != 0);

    // Too small a buffer fails cleanly.
    let mut short = [0u8; MAX_PDU_LEN];
    assert!(response.emit(&mut short[..n - 1]).is_err());

    let body = &data[1..];
    match Response::wire_len(data[0], body) {
        WireLen::Known(len) => assert_eq!(len, body.len(), "wire_len claims another length for {response:?}"),
        WireLen::NeedMore => panic!("wire_len wants more bytes than a whole response: {response:?}"),
        WireLen::Probable(_) | WireLen::Unknown => {}
    }
    for cut in 0..body.len() {
        if let WireLen::Known(len) = Response::wire_len(data[0], &body[..cut]) {
            assert_eq!(len, body.len(), "wire_len on {cut} bytes of {response:?}");
        }
    }
    let _ = std::format!("{response:?} {}", response.function());
});
