//! The ASCII and MBAP receivers on the same arbitrary list of (gap, chunk) pairs, driven like
//! an IO layer drives them. `drive_receiver` checks the receiver contract (PDU 1–253 bytes,
//! deadlines never before the last `now`, stats equal to the events handed out, no spinning);
//! here, in addition: the bytes accounted for (frames + discards) never exceed the bytes fed,
//! and an ASCII frame takes at least its minimal encoding.
//!
//! (MBAP cannot be held to "everything is accounted for": it reports bytes skipped before a
//! bad header only when the next good frame completes, so a stream that stays broken shows
//! no discards at all. See the fuzz report.)
#![no_main]

use core::time::Duration;

use arbitrary::Arbitrary;
use ferrobus_proto::frame::ascii::AsciiCodec;
use ferrobus_proto::frame::mbap::{self, MbapCodec};
use ferrobus_proto::frame::{Direction, Framing};
use ferrobus_proto::pdu::MAX_PDU_LEN;
use ferrobus_proto_fuzz::{Step, drive_receiver, line_9600_8e1};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
struct Input {
    /// ASCII inter-character timeout in units of 16 µs (0 keeps the default, one second).
    char_timeout: u16,
    /// ASCII end-of-frame character other than LF, if any (as 0x08/0x03 sets it).
    delimiter: Option<u8>,
    steps: Vec<Step>,
}

fuzz_target!(|input: Input| {
    let mut ascii = AsciiCodec::new(line_9600_8e1());
    if input.char_timeout != 0 {
        ascii = ascii.with_char_timeout(Duration::from_micros(16 * u64::from(input.char_timeout)));
    }
    if let Some(delimiter) = input.delimiter {
        ascii.set_delimiter(delimiter);
    }
    let tally = drive_receiver(&mut ascii, &input.steps, MAX_PDU_LEN, |adu, _| {
        assert_eq!(adu.direction, Direction::Either);
        assert_eq!(adu.header.transaction, 0);
    });
    // ':' + hex(unit, PDU, LRC) + CR + delimiter.
    let min_chars = 2 * tally.pdu_bytes + 7 * u64::from(tally.frames);
    assert!(min_chars + tally.discarded <= tally.fed, "ASCII accounts for more than it got: {tally:?}");
    assert_eq!(ascii.poll_timeout(), None, "ASCII still waiting after the final timeouts");

    let mut tcp = MbapCodec::new();
    let tally = drive_receiver(&mut tcp, &input.steps, MAX_PDU_LEN, |adu, _| {
        assert_eq!(adu.direction, Direction::Either);
    });
    let accounted = tally.pdu_bytes + mbap::HEADER_LEN as u64 * u64::from(tally.frames) + tally.discarded;
    assert!(accounted <= tally.fed, "MBAP accounts for more than it got: {tally:?}");
});
