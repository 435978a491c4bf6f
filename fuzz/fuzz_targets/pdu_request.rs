//! `Request::parse` on arbitrary bytes. On success the request must emit the bytes it was
//! parsed from, into a 253-byte buffer pre-filled with 0xA5 whose tail stays untouched (the
//! normalisations allowed, both of 0x0F: a word-padded byte count comes back as the spec's,
//! padding bits as zeros);
//! `encoded_len` must agree, parsing the output must give the same value, and the RTU length
//! predictor must not contradict the parser (it may not know the length, but if it claims
//! to, the claim must be this PDU's length).
#![no_main]

use ferrobus_proto::pdu::{MAX_PDU_LEN, Request, WireLen};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(request) = Request::parse(data) else { return };
    assert!(!data.is_empty() && data.len() <= MAX_PDU_LEN);

    let mut out = [0xA5u8; MAX_PDU_LEN];
    let n = request.emit(&mut out).expect("a parsed request fits in 253 bytes");
    // The normalisations allowed, both of 0x0F: the Hitachi/Omron word-padded byte count (one
    // byte more than the coils need) is re-emitted as the spec's, and the unused high bits of
    // the last coil byte go out as zeros.
    let mut canonical = data.to_vec();
    if let Request::WriteMultipleCoils(q) = request {
        let bytes = q.values().byte_len();
        if data.len() == 6 + bytes + 1 {
            canonical[5] -= 1;
            canonical.pop();
        }
        let used = q.quantity() % 8;
        if used != 0 {
            canonical[5 + bytes] &= (1u8 << used) - 1;
        }
    }
    assert_eq!(&out[..n], canonical.as_slice(), "emit(parse(x)) != x for {request:?}");
    assert!(out[n..].iter().all(|&b| b == 0xA5), "emit wrote past its length");
    assert_eq!(request.encoded_len(), n, "encoded_len disagrees with emit for {request:?}");
    assert_eq!(Request::parse(&out[..n]), Ok(request));
    assert_eq!(request.function().value(), data[0]);

    // Too small a buffer fails cleanly.
    let mut short = [0u8; MAX_PDU_LEN];
    assert!(request.emit(&mut short[..n - 1]).is_err());

    let body = &data[1..];
    match Request::wire_len(data[0], body) {
        WireLen::Known(len) => assert_eq!(len, body.len(), "wire_len claims another length for {request:?}"),
        WireLen::NeedMore => panic!("wire_len wants more bytes than a whole request: {request:?}"),
        WireLen::Probable(_) | WireLen::Unknown => {}
    }
    // The predictor must also agree on every prefix: it may not claim a shorter frame.
    for cut in 0..body.len() {
        if let WireLen::Known(len) = Request::wire_len(data[0], &body[..cut]) {
            assert_eq!(len, body.len(), "wire_len on {cut} bytes of {request:?}");
        }
    }
    let _ = std::format!("{request} {request:?}");
});
