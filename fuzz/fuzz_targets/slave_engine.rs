//! The slave engine (`Slave<RtuCodec>`, 9600 8E1, units 1 and 2, an in-memory handler that
//! implements every data method) fed an arbitrary list of (gap, chunk) pairs, with timeouts
//! handled as an IO layer would and `poll_transmit`/`poll_event` drained at every instant
//! visited. Asserted:
//!
//! - no panic, and no spinning on a deadline that is already due;
//! - every transmitted frame is at most 256 bytes, has a correct CRC (the engine checksums
//!   with the real CRC even under `cfg(fuzzing)`), is addressed from unit 1 or 2, and carries
//!   a response PDU that parses, to the function of the request that asked for it;
//! - a reply goes out no earlier than the `poll_timeout()` that announced it, no earlier than
//!   the instant the `SlaveEvent::Request` said it was due, and that instant is at least t3.5
//!   plus the unit's response wait after the request's last byte.
#![no_main]

use core::time::Duration;

use arbitrary::Arbitrary;
use ferrobus_proto::crc::crc16;
use ferrobus_proto::frame::Expect;
use ferrobus_proto::frame::rtu::{MAX_ADU_LEN, RtuCodec, RtuFrame};
use ferrobus_proto::master::MAX_TX_LEN;
use ferrobus_proto::pdu::Response;
use ferrobus_proto::slave::{Disposition, Slave, SlaveConfig, SlaveEvent, UnitSet};
use ferrobus_proto::time::Instant;
use ferrobus_proto::{ExceptionCode, FunctionCode};
use ferrobus_proto_fuzz::{MAX_TIMEOUTS_PER_WAIT, MemoryHandler, Step, line_9600_8e1};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
struct Input {
    strict_t1_5: bool,
    /// Also deliver frames that look like responses (the engine must ignore them).
    expect_both: bool,
    /// The engine's response wait (unit 1), in units of 64 µs.
    wait: u8,
    /// Unit 2's own response wait, in units of 64 µs.
    unit2_wait: u8,
    steps: Vec<Step>,
}

/// A reply the slave has announced and not sent yet.
#[derive(Clone, Copy, Debug)]
struct Due {
    unit: u8,
    function: FunctionCode,
    at: Instant,
    exception: Option<ExceptionCode>,
}

struct Harness {
    slave: Slave<RtuCodec>,
    handler: MemoryHandler,
    t3_5: Duration,
    wait: Duration,
    t: Instant,
    /// What the last `SlaveEvent::Request` with a reply announced; `None` once sent.
    due: Option<Due>,
    /// Events were dropped: the announcement may have been lost with them.
    lost_track: bool,
    /// `dropped_events()` when last looked at.
    dropped: u32,
    sent: u32,
}

impl Harness {
    /// Transmits what is due at `self.t` and drains events, checking both.
    fn poll(&mut self) {
        self.drain_events();
        let announced = self.slave.poll_timeout();
        let mut buf = [0xA5u8; MAX_TX_LEN];
        if let Some(n) = self.slave.poll_transmit(self.t, &mut buf) {
            self.check_transmit(&buf[..n], announced);
        }
        assert!(self.slave.poll_transmit(self.t, &mut buf).is_none(), "a reply was transmitted twice");
        self.drain_events();
    }

    fn check_transmit(&mut self, frame: &[u8], announced: Option<Instant>) {
        let now = self.t;
        self.sent += 1;
        assert!(frame.len() <= MAX_ADU_LEN, "transmitted {} bytes", frame.len());
        assert!(announced.is_some_and(|a| a <= now), "transmitted at {now}, announced {announced:?}");
        assert_eq!(crc16(frame), 0, "bad CRC on transmitted {frame:02X?}");
        let rtu = RtuFrame::new_checked(frame).expect("transmitted frame is a valid RTU frame");
        assert!(matches!(rtu.unit(), 1 | 2), "transmitted for unit {}", rtu.unit());
        let response = Response::parse(rtu.pdu())
            .unwrap_or_else(|e| panic!("transmitted PDU does not parse ({e:?}): {:02X?}", rtu.pdu()));
        if self.lost_track {
            self.due = None;
            self.lost_track = false;
            return;
        }
        let due = self.due.take().unwrap_or_else(|| panic!("transmitted {frame:02X?} without a request asking"));
        assert!(now >= due.at, "reply due at {} sent at {now}", due.at);
        assert_eq!(rtu.unit(), due.unit, "reply for another unit than the request's");
        assert_eq!(response.function(), due.function, "reply with another function than the request's");
        assert_eq!(response.exception().map(|e| e.code()), due.exception);
    }

    fn drain_events(&mut self) {
        // The queue holds eight events; a chunk with many frames can overflow it, and the
        // announcement of the reply may be among those dropped.
        if self.slave.dropped_events() != self.dropped {
            self.dropped = self.slave.dropped_events();
            self.lost_track = true;
        }
        while let Some(event) = self.slave.poll_event() {
            if let SlaveEvent::Request { unit, function, end, disposition, .. } = event {
                assert!(unit == 0 || unit == 1 || unit == 2, "request event for unit {unit}");
                assert!(end <= self.t);
                let (at, exception) = match disposition {
                    Disposition::Replied(at) => (at, None),
                    Disposition::Refused(code, at) => (at, Some(code)),
                    Disposition::Executed | Disposition::Silent => continue,
                };
                assert_ne!(unit, 0, "a broadcast is never answered");
                let wait = if unit == 2 { self.handler.unit2_wait } else { self.wait };
                assert!(at >= end.saturating_add(self.t3_5).saturating_add(wait), "reply due too early: {event:?}");
                assert!(self.due.is_none() || self.lost_track, "a second reply announced before the first went out");
                self.due = Some(Due { unit, function, at, exception });
            }
        }
    }

    /// Handles every deadline up to `until` (all of them if `None`), polling at each.
    fn run_until(&mut self, until: Option<Instant>) {
        for round in 0.. {
            self.poll();
            let Some(deadline) = self.slave.poll_timeout() else { return };
            if until.is_some_and(|u| deadline > u) {
                return;
            }
            assert!(round < MAX_TIMEOUTS_PER_WAIT, "slave keeps asking for timeouts ({deadline}, now {})", self.t);
            self.t = self.t.max(deadline);
            self.slave.handle_timeout(self.t, &mut self.handler);
        }
    }
}

fuzz_target!(|input: Input| {
    let timing = line_9600_8e1();
    let expect = if input.expect_both { Expect::Both } else { Expect::Requests };
    let codec = RtuCodec::new(timing, expect).with_strict_t1_5(input.strict_t1_5);
    let wait = Duration::from_micros(64 * u64::from(input.wait));
    let config = SlaveConfig { units: UnitSet::from_iter([1, 2]), response_wait: wait };
    let mut h = Harness {
        slave: Slave::new(codec, config),
        handler: MemoryHandler::new(Duration::from_micros(64 * u64::from(input.unit2_wait))),
        t3_5: timing.t3_5(),
        wait,
        t: Instant::ZERO,
        due: None,
        lost_track: false,
        dropped: 0,
        sent: 0,
    };
    for step in &input.steps {
        let arrival = step.arrival(h.t);
        h.run_until(Some(arrival));
        h.t = arrival;
        // The engine takes no frame without room for its events: hand in the rest after polling.
        let mut taken = 0;
        loop {
            taken += h.slave.on_bytes(h.t, &step.bytes[taken..], &mut h.handler);
            h.poll();
            if taken >= step.bytes.len() {
                break;
            }
        }
    }
    h.run_until(None);
    assert!(h.due.is_none() || h.lost_track, "a reply was announced and never sent: {:?}", h.due);
    assert_eq!(h.slave.dropped_events(), 0, "an event was dropped");
    let _ = (h.sent, h.slave.counters(), h.slave.event_log(), h.slave.is_listen_only());
});
