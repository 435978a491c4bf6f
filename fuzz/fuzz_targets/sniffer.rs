//! The passive sniffer on an arbitrary list of (gap, chunk) pairs at 9600 8E1, driven like
//! `ferrobus sniff` drives it (`feed`, and `expire` whenever `poll_timeout` falls before the
//! next chunk, then `finish`). Every byte fed must come out exactly once, in a frame or a
//! fragment, in the order it came; frames are 4 to 256 bytes; a wire time never ends before it
//! starts nor after the chunk that completed it arrived.
#![no_main]

use ferrobus_proto::Instant;
use ferrobus_proto::frame::rtu::{MAX_ADU_LEN, MIN_ADU_LEN};
use ferrobus_proto::sniff::{SniffEvent, Sniffer};
use ferrobus_proto_fuzz::{MAX_TIMEOUTS_PER_WAIT, Step, line_9600_8e1};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|steps: Vec<Step>| {
    let mut sniffer = Sniffer::new(line_9600_8e1());
    let mut fed: Vec<u8> = Vec::new();
    let mut out: Vec<u8> = Vec::new();
    let mut now = Instant::from_millis(1);
    let check = |event: SniffEvent<'_>, latest: Instant, out: &mut Vec<u8>| match event {
        SniffEvent::Frame(f) => {
            assert!((MIN_ADU_LEN..=MAX_ADU_LEN).contains(&f.adu().len()), "{f:?}");
            assert!(f.time.start <= f.time.end && f.time.end <= latest, "{f:?} at {latest:?}");
            out.extend_from_slice(f.adu());
        }
        SniffEvent::Fragment(f) => {
            assert!(!f.bytes.is_empty());
            assert!(f.time.start <= f.time.end && f.time.end <= latest, "{f:?} at {latest:?}");
            out.extend_from_slice(f.bytes);
        }
        SniffEvent::Unanswered(u) => assert!(u.request_end <= latest),
    };
    for step in &steps {
        let at = step.arrival(now);
        let mut waits = 0;
        while let Some(deadline) = sniffer.poll_timeout().filter(|d| *d <= at) {
            waits += 1;
            assert!(waits < MAX_TIMEOUTS_PER_WAIT, "the sniffer asks for a timeout again and again");
            sniffer.expire(deadline.max(now), |e| check(e, deadline.max(now), &mut out));
        }
        sniffer.feed(at, &step.bytes, |e| check(e, at, &mut out));
        fed.extend_from_slice(&step.bytes);
        now = at;
    }
    sniffer.finish(|e| check(e, Instant::from_nanos(u64::MAX), &mut out));
    assert_eq!(out, fed, "bytes lost, duplicated or reordered");
});
