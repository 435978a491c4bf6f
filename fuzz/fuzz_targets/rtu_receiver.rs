//! The RTU receiver on an arbitrary list of (gap, chunk) pairs at 9600 8E1, driven like an IO
//! layer drives it (`frame::feed`, and `frame::expire` whenever `poll_timeout` falls before
//! the next chunk). Besides the contract checked by `drive_receiver` (PDU 1–253 bytes, so the
//! whole frame is at most 256; deadlines never before the last `now`; stats equal to the
//! events handed out; no spinning on timeouts), every byte must be accounted for once the line
//! has gone silent: each one ends up in exactly one frame (unit + PDU + CRC) or one discard.
#![no_main]

use core::time::Duration;

use arbitrary::Arbitrary;
use ferrobus_proto::frame::rtu::{MAX_ADU_LEN, RtuCodec};
use ferrobus_proto::frame::{Direction, Expect, Framing};
use ferrobus_proto::pdu::MAX_PDU_LEN;
use ferrobus_proto_fuzz::{Step, drive_receiver, line_9600_8e1};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
struct Input {
    /// Drop a partial frame on a gap longer than t1.5.
    strict_t1_5: bool,
    /// 0: requests, 1: responses, otherwise both (the sniffer's setting, the most paths).
    expect: u8,
    /// Extra wait for the rest of a frame of known length, in units of 64 µs (0: t3.5).
    incomplete_extra: u8,
    steps: Vec<Step>,
}

fuzz_target!(|input: Input| {
    let expect = match input.expect {
        0 => Expect::Requests,
        1 => Expect::Responses,
        _ => Expect::Both,
    };
    let timing = line_9600_8e1();
    let incomplete = timing.t3_5() + Duration::from_micros(64 * u64::from(input.incomplete_extra));
    let mut codec =
        RtuCodec::new(timing, expect).with_strict_t1_5(input.strict_t1_5).with_incomplete_timeout(incomplete);

    let tally = drive_receiver(&mut codec, &input.steps, MAX_PDU_LEN, |adu, _| {
        assert!(1 + adu.pdu.len() + 2 <= MAX_ADU_LEN);
        assert_eq!(adu.header.transaction, 0);
        match (expect, adu.direction) {
            (Expect::Requests, Direction::Request) | (Expect::Responses, Direction::Response) | (Expect::Both, _) => {}
            (e, d) => panic!("receiver expecting {e:?} delivered a frame it calls {d:?}"),
        }
    });

    // The line is silent now and every timeout has been handled: nothing may be left over.
    assert_eq!(codec.poll_timeout(), None);
    let accounted = tally.pdu_bytes + 3 * u64::from(tally.frames) + tally.discarded;
    assert_eq!(accounted, tally.fed, "bytes lost or counted twice: {tally:?}, stats {:?}", codec.stats());
});
