//! The manuals' example frames, sent as raw bytes to a simulated drive through the real slave
//! engine: the replies must match byte for byte, and the drive must refuse what it would
//! refuse with the codes it would use.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use ferrobus_proto::crc::crc16_wire;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming};
use ferrobus_proto::master::MAX_TX_LEN;
use ferrobus_proto::slave::{Slave, SlaveConfig};
use ferrobus_proto::time::Instant;
use ferrobus_sim::{Device, Faults, Profile, Sim, SimClock};

/// A line with simulated devices on it, and a clock the test moves.
struct Line {
    slave: Slave<RtuCodec>,
    sim: Sim,
    now_ms: Arc<AtomicU64>,
}

impl Line {
    fn new(devices: &[(u8, &str)]) -> Self {
        Line::with(devices.iter().map(|(u, p)| (*u, Profile::load(p).unwrap())).collect())
    }

    fn with(devices: Vec<(u8, Profile)>) -> Self {
        let now_ms = Arc::new(AtomicU64::new(0));
        let clock: SimClock = {
            let now_ms = Arc::clone(&now_ms);
            Arc::new(move || Duration::from_millis(now_ms.load(Ordering::SeqCst)))
        };
        let mut sim = Sim::new(clock, 1);
        for (unit, profile) in devices {
            sim.add(unit, Device::new(profile), Faults::default());
        }
        let timing = LineTiming::new(&LineConfig::new(9600).unwrap());
        let config = SlaveConfig { units: sim.unit_set(), response_wait: Duration::ZERO };
        Line { slave: Slave::new(RtuCodec::new(timing, Expect::Both), config), sim, now_ms }
    }

    /// Sends `frame` at the current time and returns the reply with its delay after the
    /// request, or `None` if the drive stays silent.
    #[track_caller]
    fn send(&mut self, frame: &[u8]) -> Option<(Vec<u8>, Duration)> {
        let t0 = Instant::from_millis(self.now_ms.load(Ordering::SeqCst));
        // A slave takes no frame while its event queue is full: poll it, as a driver does.
        while self.slave.poll_event().is_some() {}
        self.slave.on_bytes(t0, frame, &mut self.sim);
        let mut out = [0u8; MAX_TX_LEN];
        let reply = loop {
            let Some(due) = self.slave.poll_timeout() else { break None };
            self.slave.handle_timeout(due, &mut self.sim);
            if let Some(n) = self.slave.poll_transmit(due, &mut out) {
                break Some((out[..n].to_vec(), due.saturating_duration_since(t0)));
            }
        };
        // Leave the line quiet for a while before the next request.
        self.advance(Duration::from_millis(100));
        reply
    }

    #[track_caller]
    fn reply(&mut self, frame: &[u8]) -> Vec<u8> {
        self.send(frame).expect("a reply").0
    }

    fn advance(&self, d: Duration) {
        self.now_ms.fetch_add(u64::try_from(d.as_millis()).unwrap(), Ordering::SeqCst);
    }
}

/// `unit`, `pdu`, CRC.
fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = vec![unit];
    frame.extend_from_slice(pdu);
    frame.extend_from_slice(&crc16_wire(&frame));
    frame
}

#[test]
fn sdp_servo_seed_example_write_is_answered_byte_for_byte() {
    let mut line = Line::new(&[(1, "sdp-servo")]);
    // SDP manual p.413: write 0BB8H, 0000H to 0112H of device 01H.
    let request = [0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00, 0xFC, 0xEB];
    assert_eq!(line.reply(&request), [0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0xE0, 0x31]);
    // Read back: the two words as written.
    assert_eq!(line.reply(&rtu(1, &[0x03, 0x01, 0x12, 0x00, 0x02])), rtu(1, &[0x03, 0x04, 0x0B, 0xB8, 0x00, 0x00]));
}

#[test]
fn sdp_servo_limits_and_refusals() {
    let mut line = Line::new(&[(1, "sdp-servo")]);
    // "The maximum allowable data in one single access is 10": 11 is exception 03.
    assert_eq!(line.reply(&rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x0B])), rtu(1, &[0x83, 0x03]));
    assert_eq!(line.reply(&rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x0A]))[2], 20);
    // No 0x08, no 0x01, no 0x05: exception 01 (a "ping" by loop-back fails on this drive).
    assert_eq!(line.reply(&rtu(1, &[0x08, 0x00, 0x00, 0x12, 0x34])), rtu(1, &[0x88, 0x01]));
    assert_eq!(line.reply(&rtu(1, &[0x05, 0x00, 0x00, 0xFF, 0x00])), rtu(1, &[0x85, 0x01]));
    // The speed command is limited to ±6000 r/min: 7000 is out of range (0x03 on this drive).
    assert_eq!(
        line.reply(&rtu(1, &[0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x1B, 0x58, 0x00, 0x00])),
        rtu(1, &[0x90, 0x03])
    );
}

#[test]
fn sdp_servo_runs_when_switched_on() {
    let mut line = Line::new(&[(3, "sdp-servo")]);
    // 3000 r/min, low word first; servo on.
    line.reply(&rtu(3, &[0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00]));
    line.reply(&rtu(3, &[0x06, 0x02, 0x00, 0x00, 0x01]));
    line.advance(Duration::from_secs(1));
    // Motor speed, input registers 0–1, low word first: 3000 = 0x0BB8.
    assert_eq!(line.reply(&rtu(3, &[0x04, 0x00, 0x00, 0x00, 0x02])), rtu(3, &[0x04, 0x04, 0x0B, 0xB8, 0x00, 0x00]));
}

#[test]
fn omron_3g3rx_example_frames_are_answered_as_the_manual_shows() {
    let mut line = Line::new(&[(1, "omron-3g3rx"), (5, "omron-3g3rx"), (8, "omron-3g3rx"), (10, "omron-3g3rx")]);
    // p.4-168: read coils 7–12 of slave 8; the terminals are 1,1,1,0,1,0 (0x17).
    line.sim.device(8).unwrap().memory_mut().write_bits(6, [true, true, true, false, true, false]);
    assert_eq!(line.reply(&[0x08, 0x01, 0x00, 0x06, 0x00, 0x06, 0x5C, 0x90]), [0x08, 0x01, 0x01, 0x17, 0x12, 0x1A]);
    // p.4-170: run command ON to slave 10 — "returns the query without a change".
    let run = [0x0A, 0x05, 0x00, 0x00, 0xFF, 0x00, 0x8D, 0x41];
    assert_eq!(line.reply(&run), run);
    // p.4-171: write A003 (1203h) = 50 to slave 5: echoed.
    let a003 = [0x05, 0x06, 0x12, 0x02, 0x00, 0x32, 0xAD, 0x23];
    assert_eq!(line.reply(&a003), a003);
    // p.4-169: read 0012h–0013h (trip 1 factor and status) of slave 5: no trip yet.
    assert_eq!(line.reply(&[0x05, 0x03, 0x00, 0x11, 0x00, 0x02, 0x95, 0x8A]), rtu(5, &[0x03, 0x04, 0, 0, 0, 0]));
    // Write 6 coils from coil 7 to slave 5, with the manual's word-padded byte count.
    let coils = [0x05, 0x0F, 0x00, 0x06, 0x00, 0x06, 0x02, 0x17, 0x00, 0xDB, 0x3E];
    assert_eq!(line.reply(&coils), [0x05, 0x0F, 0x00, 0x06, 0x00, 0x06, 0x34, 0x4C]);
    // p.4-173: F002 = 3000.00 s (300000 = 0x000493E0), high word first, to slave 1.
    let f002 = [0x01, 0x10, 0x11, 0x02, 0x00, 0x02, 0x04, 0x00, 0x04, 0x93, 0xE0, 0x9E, 0x9F];
    assert_eq!(line.reply(&f002), [0x01, 0x10, 0x11, 0x02, 0x00, 0x02, 0xE5, 0x34]);
    assert_eq!(line.sim.device(1).unwrap().memory().get("F002"), 300_000);
}

#[test]
fn omron_3g3rx_refuses_as_the_manual_says() {
    let mut line = Line::new(&[(1, "omron-3g3rx")]);
    // 4 registers per message at most; more than 32 coils or none: exception 03.
    assert_eq!(line.reply(&rtu(1, &[0x03, 0x10, 0x00, 0x00, 0x05])), rtu(1, &[0x83, 0x03]));
    assert_eq!(line.reply(&rtu(1, &[0x01, 0x00, 0x00, 0x00, 0x21])), rtu(1, &[0x81, 0x03]));
    // Unsupported function codes: 01. Device identification too.
    assert_eq!(line.reply(&rtu(1, &[0x04, 0x00, 0x00, 0x00, 0x01])), rtu(1, &[0x84, 0x01]));
    assert_eq!(line.reply(&rtu(1, &[0x2B, 0x0E, 0x01, 0x00])), rtu(1, &[0xAB, 0x01]));
    // Loop-back (sub-function 0000h) only.
    assert_eq!(line.reply(&rtu(1, &[0x08, 0x00, 0x00, 0x12, 0x34])), rtu(1, &[0x08, 0x00, 0x00, 0x12, 0x34]));
    assert_eq!(line.reply(&rtu(1, &[0x08, 0x00, 0x0B, 0x00, 0x00])), rtu(1, &[0x88, 0x01]));
    // F001 above 400.00 Hz: 21h, data outside the inverter's range.
    assert_eq!(
        line.reply(&rtu(1, &[0x10, 0x00, 0x00, 0x00, 0x02, 0x04, 0x00, 0x00, 0x9C, 0x41])),
        rtu(1, &[0x90, 0x21])
    );
    // A read-only register: 22h.
    assert_eq!(line.reply(&rtu(1, &[0x06, 0x00, 0x02, 0x00, 0x03])), rtu(1, &[0x86, 0x22]));
    // Past the map: 02.
    assert_eq!(line.reply(&rtu(1, &[0x03, 0x00, 0x04, 0x00, 0x01])), rtu(1, &[0x83, 0x02]));
    // While running, A003 (base frequency) cannot change: 22h. F001 can.
    line.reply(&rtu(1, &[0x10, 0x00, 0x00, 0x00, 0x02, 0x04, 0x00, 0x00, 0x13, 0x88]));
    line.reply(&rtu(1, &[0x05, 0x00, 0x00, 0xFF, 0x00]));
    line.advance(Duration::from_millis(500));
    assert_eq!(line.reply(&rtu(1, &[0x06, 0x12, 0x02, 0x00, 0x32])), rtu(1, &[0x86, 0x22]));
    assert_eq!(line.reply(&rtu(1, &[0x06, 0x00, 0x01, 0x07, 0xD0])), rtu(1, &[0x06, 0x00, 0x01, 0x07, 0xD0]));
}

#[test]
fn omron_3g3rx_broadcast_writes_run_but_reads_and_loopback_do_not() {
    let mut line = Line::new(&[(1, "omron-3g3rx"), (2, "omron-3g3rx")]);
    assert_eq!(line.send(&rtu(0, &[0x06, 0x12, 0x02, 0x00, 0x32])), None);
    assert_eq!(line.sim.device(1).unwrap().memory().get("A003"), 50);
    assert_eq!(line.sim.device(2).unwrap().memory().get("A003"), 50);
    assert_eq!(line.send(&rtu(0, &[0x03, 0x00, 0x00, 0x00, 0x01])), None);
    assert_eq!(line.send(&rtu(0, &[0x08, 0x00, 0x00, 0x12, 0x34])), None);
    // Another unit's request is not answered either.
    assert_eq!(line.send(&rtu(3, &[0x03, 0x00, 0x00, 0x00, 0x01])), None);
}

#[test]
fn the_inverter_ramps_its_output_after_run_as_the_registers_show() {
    let mut line = Line::new(&[(1, "omron-3g3rx")]);
    // F002 = 0.60 s (0 → A004, 60 Hz by default): 100 Hz/s. F001 = 50.00 Hz. Run.
    line.reply(&rtu(1, &[0x10, 0x11, 0x02, 0x00, 0x02, 0x04, 0x00, 0x00, 0x00, 0x3C]));
    line.reply(&rtu(1, &[0x10, 0x00, 0x00, 0x00, 0x02, 0x04, 0x00, 0x00, 0x13, 0x88]));
    line.reply(&rtu(1, &[0x05, 0x00, 0x00, 0xFF, 0x00]));
    // 100 ms of line time has passed since the run command (this request included): 10 Hz.
    let d001 = |line: &mut Line| {
        let reply = line.reply(&rtu(1, &[0x03, 0x10, 0x00, 0x00, 0x02]));
        u32::from_be_bytes([reply[3], reply[4], reply[5], reply[6]])
    };
    assert_eq!(d001(&mut line), 1000);
    line.advance(Duration::from_millis(300));
    assert_eq!(d001(&mut line), 5000, "at speed after 0.5 s");
    let status = line.reply(&rtu(1, &[0x03, 0x00, 0x02, 0x00, 0x02]));
    assert_eq!(&status[3..7], &[0x00, 0x03, 0x00, 0x01], "status A 3 (run), status B 1 (run)");
}

#[test]
fn a_communication_wait_time_delays_the_reply_by_exactly_that_much() {
    let mut profile = Profile::load("omron-3g3rx").unwrap();
    profile.comm.response_wait_ms = 20; // C078 = 20 ms
    let mut line = Line::with(vec![(1, profile)]);
    let (_, delay) = line.send(&rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02])).unwrap();
    // 9600 8E1: t3.5 = 4.010417 ms, rounded up; plus C078.
    assert_eq!(delay, Duration::from_nanos(24_010_417));
}

#[test]
fn injected_faults_silence_refuse_delay_and_trip_a_unit() {
    let clock: SimClock = Arc::new(|| Duration::from_secs(10));
    let mut sim = Sim::new(clock, 7);
    let rx = || Device::new(Profile::load("omron-3g3rx").unwrap());
    sim.add(1, rx(), "silent".parse().unwrap());
    sim.add(2, rx(), "exception=0x06".parse().unwrap());
    sim.add(3, rx(), "delay=50ms".parse().unwrap());
    sim.add(4, rx(), "trip=5s".parse().unwrap());
    let timing = LineTiming::new(&LineConfig::new(9600).unwrap());
    let config = SlaveConfig { units: sim.unit_set(), response_wait: Duration::ZERO };
    let mut line = Line { slave: Slave::new(RtuCodec::new(timing, Expect::Both), config), sim, now_ms: Arc::default() };
    assert_eq!(line.send(&rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x01])), None);
    assert_eq!(line.reply(&rtu(2, &[0x03, 0x00, 0x00, 0x00, 0x01])), rtu(2, &[0x83, 0x06]));
    let (_, delay) = line.send(&rtu(3, &[0x03, 0x00, 0x00, 0x00, 0x01])).unwrap();
    assert_eq!(delay, Duration::from_nanos(54_010_417));
    // Unit 4 tripped at 5 s (the clock says 10 s): status A 8, status B 2.
    assert_eq!(line.reply(&rtu(4, &[0x03, 0x00, 0x02, 0x00, 0x02])), rtu(4, &[0x03, 0x04, 0x00, 0x08, 0x00, 0x02]));
}
