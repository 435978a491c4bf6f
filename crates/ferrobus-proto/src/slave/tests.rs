//! Slave engine tests with explicit time: who it answers, when, and with what.

extern crate std;
use std::vec::Vec;

use super::*;
use crate::crc::crc16_wire;
use crate::frame::ascii::AsciiCodec;
use crate::frame::mbap::MbapCodec;
use crate::frame::rtu::RtuCodec;
use crate::frame::{Expect, LineConfig, LineTiming};
use crate::pdu::{Bits, MaskWrite, Registers};

/// A small device: 100 of each table, two files of 100 records, a FIFO, identification.
struct Device {
    coils: [bool; 100],
    discrete: [bool; 100],
    holding: [u16; 100],
    input: [u16; 100],
    files: [[u16; 100]; 2],
    fifo: Vec<u16>,
    objects: Vec<(u8, Vec<u8>)>,
    waits: [(u8, Duration); 1],
    admission: Option<Admission>,
    writes: Vec<(u8, u16, u16)>,
}

impl Device {
    fn new() -> Self {
        let mut holding = [0u16; 100];
        for (i, r) in holding.iter_mut().enumerate() {
            *r = u16::try_from(i).unwrap() * 7 + 3;
        }
        Device {
            coils: core::array::from_fn(|i| i % 3 == 0),
            discrete: core::array::from_fn(|i| i % 5 == 0),
            holding,
            input: core::array::from_fn(|i| 0x1000 + u16::try_from(i).unwrap()),
            files: [[0x0F01; 100], [0x0F02; 100]],
            fifo: std::vec![0x01B8, 0x1284],
            objects: std::vec![(0, b"ferrobus".to_vec()), (1, b"FB-1".to_vec()), (2, b"1.0".to_vec())],
            waits: [(9, Duration::from_millis(50))],
            admission: None,
            writes: Vec::new(),
        }
    }
}

fn range<T>(table: &mut [T], start: u16, len: usize) -> Result<&mut [T], ExceptionCode> {
    let start = usize::from(start);
    table.get_mut(start..start + len).ok_or(ExceptionCode::IllegalDataAddress)
}

impl Handler for Device {
    fn admit(&mut self, _: u8, broadcast: bool, request: &Request<'_>) -> Admission {
        if let Some(a) = self.admission {
            return a;
        }
        if broadcast && !request.function().is_write() { Admission::Ignore } else { Admission::Serve }
    }
    fn response_wait(&self, unit: u8) -> Option<Duration> {
        self.waits.iter().find(|(u, _)| *u == unit).map(|(_, w)| *w)
    }
    fn read_coils(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(range(&mut self.coils, start, out.len())?);
        Ok(())
    }
    fn read_discrete_inputs(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(range(&mut self.discrete, start, out.len())?);
        Ok(())
    }
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(range(&mut self.holding, start, out.len())?);
        Ok(())
    }
    fn read_input_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(range(&mut self.input, start, out.len())?);
        Ok(())
    }
    fn write_single_coil(&mut self, _: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        range(&mut self.coils, address, 1)?[0] = value;
        Ok(())
    }
    fn write_single_register(&mut self, unit: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        range(&mut self.holding, address, 1)?[0] = value;
        self.writes.push((unit, address, value));
        Ok(())
    }
    fn write_multiple_coils(&mut self, _: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        values.copy_to(range(&mut self.coils, start, values.len())?);
        Ok(())
    }
    fn write_multiple_registers(&mut self, unit: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        values.copy_to(range(&mut self.holding, start, values.len())?);
        for (i, v) in values.iter().enumerate() {
            self.writes.push((unit, start + u16::try_from(i).unwrap(), v));
        }
        Ok(())
    }
    fn read_exception_status(&mut self, _: u8) -> Result<u8, ExceptionCode> {
        Ok(0x6D)
    }
    fn report_server_id(&mut self, _: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        out[..3].copy_from_slice(&[0x42, 0xFF, 0x01]);
        Ok(3)
    }
    fn read_file_record(&mut self, _: u8, file: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        let file = self.files.get_mut(usize::from(file).wrapping_sub(1)).ok_or(ExceptionCode::IllegalDataAddress)?;
        out.copy_from_slice(range(file, record, out.len())?);
        Ok(())
    }
    fn write_file_record(&mut self, _: u8, file: u16, record: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        let file = self.files.get_mut(usize::from(file).wrapping_sub(1)).ok_or(ExceptionCode::IllegalDataAddress)?;
        values.copy_to(range(file, record, values.len())?);
        Ok(())
    }
    fn read_fifo_queue(&mut self, _: u8, address: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        if address != 0x04DE {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        out[..self.fifo.len()].copy_from_slice(&self.fifo);
        Ok(self.fifo.len())
    }
    fn device_object(&mut self, _: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        let (_, value) = self.objects.iter().find(|(i, _)| *i == id)?;
        out[..value.len()].copy_from_slice(value);
        Some(value.len())
    }
    fn custom(&mut self, _: u8, function: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        if function != 0x41 {
            return Err(ExceptionCode::IllegalFunction);
        }
        out[..data.len()].copy_from_slice(data);
        out[data.len()] = 0x99;
        Ok(data.len() + 1)
    }
}

fn timing_9600() -> LineTiming {
    LineTiming::new(&LineConfig::new(9600).unwrap())
}

fn rtu_slave(config: SlaveConfig) -> Slave<RtuCodec> {
    Slave::new(RtuCodec::new(timing_9600(), Expect::Both), config)
}

/// `unit`, `pdu`, CRC.
fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = std::vec![unit];
    frame.extend_from_slice(pdu);
    frame.extend_from_slice(&crc16_wire(&frame));
    frame
}

/// Feeds `frame` at `at`, then returns the reply the slave sends, if any, with when it is due.
#[track_caller]
fn exchange<F: Framing>(
    slave: &mut Slave<F>,
    device: &mut Device,
    at: Instant,
    frame: &[u8],
) -> Option<(Vec<u8>, Instant)> {
    let mut taken = 0;
    loop {
        taken += slave.on_bytes(at, &frame[taken..], device);
        if taken == frame.len() {
            break;
        }
        // Blocked: make room as a driver does (the events of a long input are not looked at).
        while slave.poll_event().is_some() {}
    }
    let mut out = [0xA5u8; MAX_TX_LEN];
    // Step through the deadlines: the end of a frame of unknown length, then the reply.
    loop {
        if slave.is_blocked() {
            while slave.poll_event().is_some() {}
        }
        let due = slave.poll_timeout()?;
        if due > at {
            let early = due.saturating_sub(Duration::from_nanos(1));
            assert!(slave.poll_transmit(early, &mut out).is_none(), "nothing goes out before it is due");
        }
        slave.handle_timeout(due, device);
        if let Some(n) = slave.poll_transmit(due, &mut out) {
            return Some((out[..n].to_vec(), due));
        }
    }
}

/// The reply PDU to `pdu` sent to unit 1 of a fresh 9600-baud slave.
#[track_caller]
fn reply_pdu(pdu: &[u8]) -> Vec<u8> {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let (frame, _) = exchange(&mut slave, &mut Device::new(), Instant::ZERO, &rtu(1, pdu)).expect("a reply");
    assert_eq!(frame[0], 1, "the reply comes from the unit asked");
    assert!(crate::crc::crc_ok(&frame));
    frame[1..frame.len() - 2].to_vec()
}

// ---- Timing ----------------------------------------------------------------------------

#[test]
fn at_9600_8e1_with_a_20_ms_wait_the_reply_goes_out_at_24_011_ms_not_24_010() {
    let mut slave = rtu_slave(SlaveConfig { response_wait: Duration::from_millis(20), ..SlaveConfig::unit(1) });
    let mut device = Device::new();
    slave.on_bytes(Instant::ZERO, &rtu(1, &[0x03, 0x00, 0x00, 0x00, 0x02]), &mut device);
    let mut out = [0u8; MAX_TX_LEN];
    // t3.5 = 3.5 × 11 / 9600 s = 4.010417 ms (rounded up), plus 20 ms.
    assert_eq!(slave.poll_timeout(), Some(Instant::from_nanos(24_010_417)));
    assert_eq!(slave.poll_transmit(Instant::from_micros(24_010), &mut out), None);
    assert_eq!(slave.poll_transmit(Instant::from_micros(24_011), &mut out), Some(9));
    assert_eq!(&out[..9], rtu(1, &[0x03, 0x04, 0x00, 0x03, 0x00, 0x0A]).as_slice());
    assert_eq!(slave.poll_transmit(Instant::from_millis(30), &mut out), None, "sent once");
}

#[test]
fn without_a_wait_the_reply_is_due_t3_5_after_the_request() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let (_, due) =
        exchange(&mut slave, &mut Device::new(), Instant::from_millis(7), &rtu(1, &[0x03, 0, 0, 0, 1])).unwrap();
    assert_eq!(due, Instant::from_nanos(7_000_000 + 4_010_417));
}

#[test]
fn a_units_own_response_wait_overrides_the_engines() {
    let config = SlaveConfig { units: [1, 9].into_iter().collect(), response_wait: Duration::from_millis(5) };
    let mut slave = rtu_slave(config);
    let mut device = Device::new();
    let (_, due) = exchange(&mut slave, &mut device, Instant::ZERO, &rtu(9, &[0x03, 0, 0, 0, 1])).unwrap();
    assert_eq!(due, Instant::from_nanos(54_010_417));
    let (_, due) = exchange(&mut slave, &mut device, Instant::from_secs(1), &rtu(1, &[0x03, 0, 0, 0, 1])).unwrap();
    assert_eq!(due, Instant::from_nanos(1_009_010_417));
}

#[test]
fn a_request_arriving_in_pieces_is_answered_t3_5_after_its_last_piece() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let mut device = Device::new();
    let frame = rtu(1, &[0x03, 0, 0, 0, 1]);
    slave.on_bytes(Instant::ZERO, &frame[..5], &mut device);
    let (_, due) = exchange(&mut slave, &mut device, Instant::from_millis(2), &frame[5..]).unwrap();
    assert_eq!(due, Instant::from_nanos(2_000_000 + 4_010_417));
}

// ---- Who is answered -------------------------------------------------------------------

#[test]
fn silent_on_a_bad_crc_and_the_error_is_counted() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let mut frame = rtu(1, &[0x03, 0, 0, 0, 1]);
    frame[7] ^= 0xFF;
    assert_eq!(exchange(&mut slave, &mut Device::new(), Instant::ZERO, &frame), None);
    assert_eq!(slave.counters().bus_comm_errors, 1);
    assert_eq!(slave.counters().bus_messages, 0);
}

#[test]
fn silent_on_another_units_request_but_it_counts_as_a_bus_message() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    assert_eq!(exchange(&mut slave, &mut Device::new(), Instant::ZERO, &rtu(2, &[0x03, 0, 0, 0, 1])), None);
    assert_eq!(slave.counters().bus_messages, 1);
    assert_eq!(slave.counters().server_messages, 0);
    assert_eq!(
        slave.poll_event(),
        Some(SlaveEvent::Ignored { unit: 2, function: FunctionCode::ReadHoldingRegisters, why: Ignored::OtherUnit })
    );
}

#[test]
fn another_slaves_response_on_the_bus_is_neither_answered_nor_an_error() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    // Unit 2 answering a read of two registers: a layout only a response has.
    let response = rtu(2, &[0x03, 0x04, 0x00, 0x01, 0x00, 0x02]);
    assert_eq!(exchange(&mut slave, &mut Device::new(), Instant::ZERO, &response), None);
    assert_eq!(slave.counters().bus_comm_errors, 0);
    assert_eq!(slave.counters().bus_messages, 1);
}

#[test]
fn a_broadcast_write_is_executed_on_every_unit_and_never_answered() {
    let mut slave = rtu_slave(SlaveConfig { units: [1, 2].into_iter().collect(), ..SlaveConfig::unit(1) });
    let mut device = Device::new();
    assert_eq!(exchange(&mut slave, &mut device, Instant::ZERO, &rtu(0, &[0x06, 0x00, 0x05, 0x12, 0x34])), None);
    assert_eq!(device.writes, [(1, 5, 0x1234), (2, 5, 0x1234)]);
    assert_eq!(device.holding[5], 0x1234);
    assert_eq!(slave.counters().server_no_response, 1);
    assert!(matches!(
        slave.poll_event(),
        Some(SlaveEvent::Request { unit: 0, disposition: Disposition::Executed, .. })
    ));
}

#[test]
fn a_broadcast_read_write_multiple_registers_is_a_write_executed_on_every_unit_and_never_answered() {
    let mut slave = rtu_slave(SlaveConfig { units: [1, 2].into_iter().collect(), ..SlaveConfig::unit(1) });
    let mut device = Device::new();
    // 0x17: read 1 from 0x0000, write 1 at 0x0005 (2 bytes: 0x1234).
    let pdu = [0x17, 0x00, 0x00, 0x00, 0x01, 0x00, 0x05, 0x00, 0x01, 0x02, 0x12, 0x34];
    assert_eq!(exchange(&mut slave, &mut device, Instant::ZERO, &rtu(0, &pdu)), None);
    assert_eq!(device.writes, [(1, 5, 0x1234), (2, 5, 0x1234)]);
    assert_eq!(slave.counters().server_no_response, 1);
}

#[test]
fn a_broadcast_read_is_neither_executed_nor_answered() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    assert_eq!(exchange(&mut slave, &mut Device::new(), Instant::ZERO, &rtu(0, &[0x03, 0, 0, 0, 1])), None);
    assert!(matches!(slave.poll_event(), Some(SlaveEvent::Request { disposition: Disposition::Silent, .. })));
}

#[test]
fn a_request_while_a_reply_is_pending_gets_no_answer() {
    let mut slave = rtu_slave(SlaveConfig { response_wait: Duration::from_millis(100), ..SlaveConfig::unit(1) });
    let mut device = Device::new();
    slave.on_bytes(Instant::ZERO, &rtu(1, &[0x03, 0, 0, 0, 1]), &mut device);
    slave.on_bytes(Instant::from_millis(10), &rtu(1, &[0x03, 0, 1, 0, 1]), &mut device);
    let mut out = [0u8; MAX_TX_LEN];
    let n = slave.poll_transmit(Instant::from_millis(200), &mut out).unwrap();
    assert_eq!(&out[..n], rtu(1, &[0x03, 0x02, 0x00, 0x03]).as_slice(), "the first request's reply");
    assert_eq!(slave.poll_transmit(Instant::from_millis(300), &mut out), None);
    assert_eq!(slave.counters().server_no_response, 1);
}

// ---- Exceptions --------------------------------------------------------------------------

#[test]
fn malformed_and_unsupported_requests_get_the_spec_exceptions() {
    // A quantity of zero: 03. Past the end of the map: 02 (from the handler).
    assert_eq!(reply_pdu(&[0x03, 0x00, 0x00, 0x00, 0x00]), [0x83, 0x03]);
    assert_eq!(reply_pdu(&[0x03, 0x00, 0x63, 0x00, 0x02]), [0x83, 0x02]);
    // A coil value that is neither FF00 nor 0000: 03.
    assert_eq!(reply_pdu(&[0x05, 0x00, 0x01, 0x12, 0x34]), [0x85, 0x03]);
    // A custom code the device does not know: 01.
    assert_eq!(reply_pdu(&[0x42, 0x01]), [0xC2, 0x01]);
    // Read/write with a write byte count that disagrees with the quantity: 03.
    assert_eq!(reply_pdu(&[0x17, 0, 0, 0, 1, 0, 0, 0, 1, 0x04, 0, 0, 0, 0]), [0x97, 0x03]);
}

#[test]
fn a_write_whose_byte_count_disagrees_with_its_quantity_gets_exception_03_over_rtu() {
    // From the issue: quantity 0, byte count 0, six data bytes, the CRC right over all of it.
    let frame = [0x11, 0x10, 0x01, 0x60, 0x00, 0x00, 0x00, 0x02, 0x2B, 0x00, 0x01, 0x00, 0x64, 0x8C, 0x88];
    let mut slave = rtu_slave(SlaveConfig::unit(0x11));
    let (reply, _) = exchange(&mut slave, &mut Device::new(), Instant::ZERO, &frame).expect("an exception reply");
    assert_eq!(reply, rtu(0x11, &[0x90, 0x03]));
    assert_eq!(slave.counters().bus_comm_errors, 0, "not a checksum error");
    assert_eq!(slave.counters().bus_messages, 1);
}

#[test]
fn the_handler_can_refuse_with_a_vendor_code_or_stay_silent() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let mut device = Device { admission: Some(Admission::Refuse(ExceptionCode::Vendor(0x22))), ..Device::new() };
    let (frame, _) = exchange(&mut slave, &mut device, Instant::ZERO, &rtu(1, &[0x06, 0, 1, 0, 2])).unwrap();
    assert_eq!(frame, rtu(1, &[0x86, 0x22]));
    assert!(device.writes.is_empty(), "refused requests are not served");
    assert_eq!(slave.counters().bus_exceptions, 1);
    device.admission = Some(Admission::Ignore);
    assert_eq!(exchange(&mut slave, &mut device, Instant::from_millis(100), &rtu(1, &[0x06, 0, 1, 0, 2])), None);
}

// ---- Every function code through the handler ---------------------------------------------

#[test]
fn reads_return_the_handlers_data() {
    assert_eq!(reply_pdu(&[0x01, 0x00, 0x00, 0x00, 0x0A]), [0x01, 0x02, 0b0100_1001, 0b0000_0010]);
    assert_eq!(reply_pdu(&[0x02, 0x00, 0x00, 0x00, 0x06]), [0x02, 0x01, 0b0010_0001]);
    assert_eq!(reply_pdu(&[0x03, 0x00, 0x01, 0x00, 0x02]), [0x03, 0x04, 0x00, 0x0A, 0x00, 0x11]);
    assert_eq!(reply_pdu(&[0x04, 0x00, 0x02, 0x00, 0x01]), [0x04, 0x02, 0x10, 0x02]);
    assert_eq!(reply_pdu(&[0x07]), [0x07, 0x6D]);
    assert_eq!(reply_pdu(&[0x11]), [0x11, 0x03, 0x42, 0xFF, 0x01]);
    assert_eq!(reply_pdu(&[0x18, 0x04, 0xDE]), [0x18, 0x00, 0x06, 0x00, 0x02, 0x01, 0xB8, 0x12, 0x84]);
    assert_eq!(
        reply_pdu(&[0x14, 0x0E, 0x06, 0x00, 0x01, 0x00, 0x00, 0x00, 0x01, 0x06, 0x00, 0x02, 0x00, 0x05, 0x00, 0x02]),
        [0x14, 0x0A, 0x03, 0x06, 0x0F, 0x01, 0x05, 0x06, 0x0F, 0x02, 0x0F, 0x02]
    );
    assert_eq!(reply_pdu(&[0x41, 0x01, 0x02]), [0x41, 0x01, 0x02, 0x99]);
}

#[test]
fn writes_echo_the_request_and_change_the_data() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let mut device = Device::new();
    let mut t = Instant::ZERO;
    let mut send = |pdu: &[u8], device: &mut Device| {
        t = t.saturating_add(Duration::from_millis(100));
        let (frame, _) = exchange(&mut slave, device, t, &rtu(1, pdu)).unwrap();
        frame[1..frame.len() - 2].to_vec()
    };
    assert_eq!(send(&[0x05, 0x00, 0x01, 0xFF, 0x00], &mut device), [0x05, 0x00, 0x01, 0xFF, 0x00]);
    assert!(device.coils[1]);
    assert_eq!(send(&[0x06, 0x00, 0x02, 0xAB, 0xCD], &mut device), [0x06, 0x00, 0x02, 0xAB, 0xCD]);
    assert_eq!(device.holding[2], 0xABCD);
    assert_eq!(send(&[0x0F, 0x00, 0x10, 0x00, 0x03, 0x01, 0b101], &mut device), [0x0F, 0x00, 0x10, 0x00, 0x03]);
    assert_eq!(device.coils[16..19], [true, false, true]);
    assert_eq!(
        send(&[0x10, 0x00, 0x20, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00], &mut device),
        [0x10, 0x00, 0x20, 0x00, 0x02]
    );
    assert_eq!(device.holding[32..34], [3000, 0]);
    // Mask write (§6.16 example): current 0x12, AND 0xF2, OR 0x25 → 0x17.
    device.holding[4] = 0x12;
    assert_eq!(
        send(&[0x16, 0x00, 0x04, 0x00, 0xF2, 0x00, 0x25], &mut device),
        [0x16, 0x00, 0x04, 0x00, 0xF2, 0x00, 0x25]
    );
    assert_eq!(device.holding[4], MaskWrite { address: 4, and_mask: 0xF2, or_mask: 0x25 }.apply(0x12));
    assert_eq!(device.holding[4], 0x17);
    // Read/write: the write comes first, so the read sees it.
    assert_eq!(
        send(&[0x17, 0x00, 0x40, 0x00, 0x01, 0x00, 0x40, 0x00, 0x01, 0x02, 0x55, 0xAA], &mut device),
        [0x17, 0x02, 0x55, 0xAA]
    );
    // Read/write at two places: read 2 from 0x0010, write 1 (0x1234) at 0x0041; each start
    // goes where it belongs.
    assert_eq!(
        send(&[0x17, 0x00, 0x10, 0x00, 0x02, 0x00, 0x41, 0x00, 0x01, 0x02, 0x12, 0x34], &mut device),
        [0x17, 0x04, 0x00, 0x73, 0x00, 0x7A]
    );
    assert_eq!(device.holding[0x41], 0x1234);
    assert_eq!(device.holding[0x10], 0x10 * 7 + 3, "the read start is not written");
    let write_file = [0x15, 0x0D, 0x06, 0x00, 0x02, 0x00, 0x07, 0x00, 0x03, 0x06, 0xAF, 0x04, 0xBE, 0x10, 0x0D];
    assert_eq!(send(&write_file, &mut device), write_file);
    assert_eq!(device.files[1][7..10], [0x06AF, 0x04BE, 0x100D]);
}

#[test]
fn device_identification_streams_and_reads_single_objects() {
    // Basic stream from object 0: three objects, no more follow, conformity 0x81.
    let mut expected = std::vec![0x2B, 0x0E, 0x01, 0x81, 0x00, 0x00, 0x03];
    expected.extend_from_slice(&[0x00, 8]);
    expected.extend_from_slice(b"ferrobus");
    expected.extend_from_slice(&[0x01, 4]);
    expected.extend_from_slice(b"FB-1");
    expected.extend_from_slice(&[0x02, 3]);
    expected.extend_from_slice(b"1.0");
    assert_eq!(reply_pdu(&[0x2B, 0x0E, 0x01, 0x00]), expected);
    // One specific object; a missing one is exception 02.
    assert_eq!(
        reply_pdu(&[0x2B, 0x0E, 0x04, 0x01]),
        [0x2B, 0x0E, 0x04, 0x81, 0x00, 0x00, 0x01, 0x01, 4, b'F', b'B', b'-', b'1']
    );
    assert_eq!(reply_pdu(&[0x2B, 0x0E, 0x04, 0x05]), [0xAB, 0x02]);
    // An invalid read code is exception 03; another MEI type is the handler's (01 here).
    assert_eq!(reply_pdu(&[0x2B, 0x0E, 0x05, 0x00]), [0xAB, 0x03]);
    assert_eq!(reply_pdu(&[0x2B, 0x0D, 0x00]), [0xAB, 0x01]);
}

#[test]
fn device_identification_that_does_not_fit_says_more_follows() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let mut device = Device::new();
    device.objects = (0..6u8).map(|id| (id, std::vec![b'x'; 100])).collect();
    let (frame, _) = exchange(&mut slave, &mut device, Instant::ZERO, &rtu(1, &[0x2B, 0x0E, 0x02, 0x00])).unwrap();
    let pdu = &frame[1..frame.len() - 2];
    // conformity 0x82 (regular objects), more follows, next object 2, two objects.
    assert_eq!(&pdu[..7], &[0x2B, 0x0E, 0x02, 0x82, 0xFF, 0x02, 0x02]);
    let (frame, _) =
        exchange(&mut slave, &mut device, Instant::from_millis(100), &rtu(1, &[0x2B, 0x0E, 0x02, 0x02])).unwrap();
    assert_eq!(&frame[1..8], &[0x2B, 0x0E, 0x02, 0x82, 0xFF, 0x04, 0x02]);
}

#[test]
fn a_device_without_identification_answers_illegal_function() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let mut device = Device { objects: Vec::new(), ..Device::new() };
    let (frame, _) = exchange(&mut slave, &mut device, Instant::ZERO, &rtu(1, &[0x2B, 0x0E, 0x01, 0x00])).unwrap();
    assert_eq!(frame, rtu(1, &[0xAB, 0x01]));
}

// ---- Diagnostics, counters, event log, listen-only ---------------------------------------

/// Sends `pdu` to unit 1 at 100 ms intervals and returns the reply PDU, if any.
struct Bench {
    slave: Slave<RtuCodec>,
    device: Device,
    t: Instant,
}

impl Bench {
    fn new() -> Self {
        Bench { slave: rtu_slave(SlaveConfig::unit(1)), device: Device::new(), t: Instant::ZERO }
    }

    #[track_caller]
    fn send(&mut self, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        self.raw(&rtu(unit, pdu))
    }

    #[track_caller]
    fn raw(&mut self, bytes: &[u8]) -> Option<Vec<u8>> {
        self.t = self.t.saturating_add(Duration::from_millis(100));
        let (frame, _) = exchange(&mut self.slave, &mut self.device, self.t, bytes)?;
        Some(frame[1..frame.len() - 2].to_vec())
    }

    #[track_caller]
    fn counter(&mut self, sub: u8) -> u16 {
        let reply = self.send(1, &[0x08, 0x00, sub, 0x00, 0x00]).expect("a counter");
        assert_eq!(&reply[..3], &[0x08, 0x00, sub]);
        u16::from_be_bytes([reply[3], reply[4]])
    }
}

#[test]
fn return_query_data_echoes_any_data() {
    let mut b = Bench::new();
    assert_eq!(b.send(1, &[0x08, 0x00, 0x00, 0xA5, 0x37]), Some(std::vec![0x08, 0x00, 0x00, 0xA5, 0x37]));
    assert_eq!(b.send(1, &[0x08, 0x00, 0x00, 1, 2, 3, 4, 5]), Some(std::vec![0x08, 0x00, 0x00, 1, 2, 3, 4, 5]));
}

#[test]
fn counters_count_what_the_spec_says_and_clear_on_0a() {
    let mut b = Bench::new();
    b.send(1, &[0x03, 0, 0, 0, 1]); // served
    b.send(2, &[0x03, 0, 0, 0, 1]); // another unit
    b.send(1, &[0x03, 0, 0, 0, 0]); // exception 03
    b.send(0, &[0x06, 0, 1, 0, 1]); // broadcast: no response
    let mut bad = rtu(1, &[0x03, 0, 0, 0, 1]);
    bad[3] ^= 1;
    b.raw(&bad); // CRC error
    b.raw(&[0x55; 300]); // overrun: noise longer than any frame
    assert_eq!(b.counter(0x0B), 5, "bus messages: every good frame, this request included");
    assert_eq!(b.counter(0x0C), 1, "CRC errors");
    assert_eq!(b.counter(0x0D), 1, "exceptions sent");
    assert_eq!(b.counter(0x0E), 7, "messages for this slave or broadcast, the counter polls included");
    assert_eq!(b.counter(0x0F), 1, "no response: the broadcast");
    assert_eq!(b.counter(0x10), 0, "NAK");
    assert_eq!(b.counter(0x11), 0, "busy");
    assert!(b.counter(0x12) >= 1, "overruns");
    assert_eq!(b.send(1, &[0x08, 0x00, 0x0A, 0x00, 0x00]), Some(std::vec![0x08, 0x00, 0x0A, 0x00, 0x00]));
    assert_eq!(b.counter(0x0C), 0);
    assert_eq!(b.counter(0x0B), 2, "counting starts again after the clear");
    assert_eq!(b.send(1, &[0x08, 0x00, 0x14, 0x00, 0x00]), Some(std::vec![0x08, 0x00, 0x14, 0x00, 0x00]));
    assert_eq!(b.counter(0x12), 0);
}

#[test]
fn listen_only_silences_everything_until_restart() {
    let mut b = Bench::new();
    assert_eq!(b.send(1, &[0x08, 0x00, 0x04, 0x00, 0x00]), None, "entering listen-only is not answered");
    assert!(b.slave.is_listen_only());
    assert_eq!(b.send(1, &[0x03, 0, 0, 0, 1]), None);
    assert_eq!(b.send(1, &[0x06, 0, 1, 0, 9]), None);
    assert_eq!(b.device.holding[1], 10, "nor executed");
    assert_eq!(b.send(1, &[0x08, 0x00, 0x0B, 0x00, 0x00]), None, "not even diagnostics");
    assert_eq!(b.send(1, &[0x08, 0x00, 0x01, 0x00, 0x00]), None, "restart leaves listen-only without a reply");
    assert!(!b.slave.is_listen_only());
    assert_eq!(b.send(1, &[0x03, 0, 0, 0, 1]), Some(std::vec![0x03, 0x02, 0x00, 0x03]));
}

#[test]
fn restart_replies_then_clears_counters_and_with_ff00_the_log() {
    let mut b = Bench::new();
    b.send(1, &[0x03, 0, 0, 0, 1]);
    assert_eq!(b.send(1, &[0x08, 0x00, 0x01, 0xFF, 0x00]), Some(std::vec![0x08, 0x00, 0x01, 0xFF, 0x00]));
    let mut saw_restart = false;
    while let Some(e) = b.slave.poll_event() {
        saw_restart |= e == SlaveEvent::Restart { clear_log: true };
    }
    assert!(saw_restart);
    assert_eq!(b.slave.event_log().len(), 2, "the restart event and the send event of its reply");
    assert_eq!(b.counter(0x0B), 1);
    assert_eq!(b.send(1, &[0x08, 0x00, 0x01, 0x12, 0x34]), Some(std::vec![0x88, 0x03]), "data must be 0000 or FF00");
}

#[test]
fn unknown_sub_functions_are_illegal_function_and_bad_data_illegal_value() {
    let mut b = Bench::new();
    assert_eq!(b.send(1, &[0x08, 0x00, 0x13, 0x00, 0x00]), Some(std::vec![0x88, 0x01]));
    assert_eq!(b.send(1, &[0x08, 0x00, 0x0B, 0x00, 0x01]), Some(std::vec![0x88, 0x03]));
    // A counter request without its data word is shorter than its function code says: the
    // receiver takes it for a frame cut short, and nothing answers it.
    assert_eq!(b.send(1, &[0x08, 0x00, 0x0B]), None);
    assert_eq!(b.send(1, &[0x08, 0x00, 0x02, 0x00, 0x00]), Some(std::vec![0x08, 0x00, 0x02, 0x00, 0x00]));
}

#[test]
fn comm_event_counter_counts_successes_only_and_the_log_lists_them_newest_first() {
    let mut b = Bench::new();
    b.send(1, &[0x03, 0, 0, 0, 1]);
    b.send(1, &[0x03, 0, 0, 0, 0]); // exception: not counted
    b.send(0, &[0x06, 0, 1, 0, 1]); // executed broadcast: counted
    assert_eq!(b.send(1, &[0x0B]), Some(std::vec![0x0B, 0x00, 0x00, 0x00, 0x02]));
    assert_eq!(b.send(1, &[0x0B]), Some(std::vec![0x0B, 0x00, 0x00, 0x00, 0x02]), "polling the counter is not counted");
    let log = b.send(1, &[0x0C]).unwrap();
    // Status 0, event count 2, message count 6 (every frame, this one included), 10 events.
    assert_eq!(&log[..8], &[0x0C, 6 + 10, 0x00, 0x00, 0x00, 0x02, 0x00, 0x06]);
    // Newest first: receive of this 0x0C; send and receive of each 0x0B poll; the broadcast's
    // receive (0x40 flag, no send); the exception's send (read exception) and receive; the
    // first read's send and receive.
    assert_eq!(&log[8..], &[0x80, 0x40, 0x80, 0x40, 0x80, 0xC0, 0x41, 0x80, 0x40, 0x80]);
}

// ---- Other framings ---------------------------------------------------------------------

#[test]
fn over_mbap_the_transaction_is_echoed_unit_0_is_a_unit_and_there_is_no_gap() {
    let mut slave = Slave::new(MbapCodec::new(), SlaveConfig::unit(0));
    let mut device = Device::new();
    let request = [0x12, 0x34, 0x00, 0x00, 0x00, 0x06, 0x00, 0x03, 0x00, 0x00, 0x00, 0x01];
    let (frame, due) = exchange(&mut slave, &mut device, Instant::from_millis(3), &request).unwrap();
    assert_eq!(due, Instant::from_millis(3), "no silent interval on TCP");
    assert_eq!(frame, [0x12, 0x34, 0x00, 0x00, 0x00, 0x05, 0x00, 0x03, 0x02, 0x00, 0x03]);
}

#[test]
fn over_ascii_a_request_is_answered_in_ascii_and_the_input_delimiter_can_change() {
    let mut slave = Slave::new(AsciiCodec::new(timing_9600()), SlaveConfig::unit(1));
    let mut device = Device::new();
    let (frame, _) = exchange(&mut slave, &mut device, Instant::from_millis(10), b":010300000001FB\r\n").unwrap();
    assert_eq!(frame, b":0103020003F7\r\n");
    // 0x08/0x03: requests now end in CR '!' (0x21); replies keep CR LF.
    let (frame, _) = exchange(&mut slave, &mut device, Instant::from_millis(50), b":010800032100D3\r\n").unwrap();
    assert_eq!(frame, b":010800032100D3\r\n");
    let (frame, _) = exchange(&mut slave, &mut device, Instant::from_millis(100), b":010300000001FB\r!").unwrap();
    assert_eq!(frame, b":0103020003F7\r\n");
    assert_eq!(exchange(&mut slave, &mut device, Instant::from_millis(150), b":010300000001FB\r\n"), None);
}

// ---- Several requests at once -------------------------------------------------------------

/// An MBAP request: transaction `t`, unit `unit`, `pdu`.
fn mbap(t: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = Vec::new();
    frame.extend_from_slice(&t.to_be_bytes());
    frame.extend_from_slice(&[0, 0]);
    frame.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    frame.push(unit);
    frame.extend_from_slice(pdu);
    frame
}

/// Feeds `input` as a driver does: what the engine does not take is kept and handed in
/// again after the replies due at `at` are sent and the events polled. Returns the replies and
/// the events, in order.
fn drive_pipelined<F: Framing>(
    slave: &mut Slave<F>,
    device: &mut Device,
    at: Instant,
    input: &[u8],
) -> (Vec<Vec<u8>>, Vec<SlaveEvent>) {
    let mut out = [0xA5u8; MAX_TX_LEN];
    let (mut replies, mut events) = (Vec::new(), Vec::new());
    let mut taken = 0;
    let mut blocked_calls = 0;
    loop {
        taken += slave.on_bytes(at, &input[taken..], device);
        if slave.is_blocked() {
            blocked_calls += 1;
        }
        while let Some(n) = slave.poll_transmit(at, &mut out) {
            replies.push(out[..n].to_vec());
        }
        events.extend(core::iter::from_fn(|| slave.poll_event()));
        if taken == input.len() && !slave.is_blocked() && slave.pending_replies() == 0 {
            slave.on_bytes(at, &[], device);
            let before = events.len();
            events.extend(core::iter::from_fn(|| slave.poll_event()));
            if slave.pending_replies() == 0 && events.len() == before {
                break;
            }
        }
        assert!(blocked_calls < 1000, "the engine makes progress");
    }
    (replies, events)
}

#[test]
fn twenty_pipelined_mbap_requests_get_twenty_replies_in_order_each_with_its_transaction() {
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    let mut device = Device::new();
    let input: Vec<u8> =
        (0..20u16).flat_map(|t| mbap(0x0100 + t, 1, &[0x03, 0, u8::try_from(t).unwrap(), 0, 1])).collect();
    // More than the reply queue: the engine takes part of the input and blocks.
    let first = slave.on_bytes(Instant::ZERO, &input, &mut device);
    // The receiver may hold the rest (it buffers one ADU's worth); none of it is lost.
    assert!(slave.is_blocked(), "{first} of {} bytes taken, the queue full", input.len());
    assert!((1..=REPLY_QUEUE).contains(&slave.pending_replies()));
    let (replies, events) = drive_pipelined(&mut slave, &mut device, Instant::ZERO, &input[first..]);
    assert_eq!(replies.len(), 20, "every request answered");
    for (t, reply) in (0..20u16).zip(&replies) {
        let [hi, lo] = device.holding[usize::from(t)].to_be_bytes();
        assert_eq!(reply, &mbap(0x0100 + t, 1, &[0x03, 0x02, hi, lo]), "reply {t}");
    }
    let requests =
        events.iter().filter(|e| matches!(e, SlaveEvent::Request { disposition: Disposition::Replied(_), .. })).count();
    assert_eq!(requests, 20, "one event per request, none dropped");
    assert_eq!(slave.dropped_events(), 0);
    assert_eq!(slave.counters().server_no_response, 0);
}

#[test]
fn sixty_frames_in_one_chunk_report_sixty_events_and_drop_none() {
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    let mut device = Device::new();
    // Other units: each frame is one event and no reply, so only the event queue can fill.
    let input: Vec<u8> = (0..60u16).flat_map(|t| mbap(t, 7, &[0x03, 0, 0, 0, 1])).collect();
    const { assert!(60 > 2 * EVENT_QUEUE, "more frames than the event queue and the receiver hold") };
    let first = slave.on_bytes(Instant::ZERO, &input, &mut device);
    assert!(first < input.len(), "the event queue fills: the engine stops taking bytes");
    let mut events: Vec<SlaveEvent> = core::iter::from_fn(|| slave.poll_event()).collect();
    let (replies, more) = drive_pipelined(&mut slave, &mut device, Instant::ZERO, &input[first..]);
    events.extend(more);
    assert!(replies.is_empty());
    assert_eq!(events.len(), 60);
    assert!(events.iter().all(|e| matches!(e, SlaveEvent::Ignored { unit: 7, why: Ignored::OtherUnit, .. })));
    assert_eq!(slave.dropped_events(), 0);
    assert_eq!(slave.counters().bus_messages, 60);
}

#[test]
fn twelve_rtu_frames_in_one_read_are_all_counted_and_a_serial_line_still_takes_one_at_a_time() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    let mut device = Device::new();
    // Other units' requests: no reply is pending, each frame is an event.
    let input: Vec<u8> = (0..12).flat_map(|_| rtu(2, &[0x03, 0, 0, 0, 1])).collect();
    let (_, events) = drive_pipelined(&mut slave, &mut device, Instant::ZERO, &input);
    let later = Instant::from_millis(100);
    slave.handle_timeout(later, &mut device);
    let count = events.len() + core::iter::from_fn(|| slave.poll_event()).count();
    assert_eq!(count, 12, "every frame reported");
    assert_eq!(slave.dropped_events(), 0);
    // Two requests to us back to back: the second is not answered (one at a time).
    let two = [rtu(1, &[0x03, 0, 0, 0, 1]), rtu(1, &[0x03, 0, 1, 0, 1])].concat();
    slave.on_bytes(later, &two, &mut device);
    assert!(!slave.is_blocked(), "a serial line never blocks on replies");
    assert_eq!(slave.pending_replies(), 1);
    assert_eq!(slave.counters().server_no_response, 1);
}

#[test]
fn over_mbap_function_code_0x00_gets_exception_01_like_any_unknown_code() {
    // (The RTU receiver never frames a code 0x00: it is noise it resyncs on.)
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    let (frame, _) = exchange(&mut slave, &mut Device::new(), Instant::ZERO, &mbap(5, 1, &[0x00])).unwrap();
    assert_eq!(frame, mbap(5, 1, &[0x80, 0x01]));
}

// ---- Deferred: requests out, responses in ------------------------------------------------

/// The reply due at `at`, checking that nothing went out a nanosecond before.
#[track_caller]
fn sent_at<F: Framing>(slave: &mut Slave<F>, at: Instant) -> Vec<u8> {
    let mut out = [0xA5u8; MAX_TX_LEN];
    if at > Instant::ZERO {
        assert_eq!(slave.poll_transmit(at.saturating_sub(Duration::from_nanos(1)), &mut out), None, "sent early");
    }
    let n = slave.poll_transmit(at, &mut out).expect("a reply due");
    out[..n].to_vec()
}

#[test]
fn a_deferred_request_is_handed_out_once_and_its_answer_goes_out_no_earlier_than_t3_5_plus_the_wait() {
    let wait = Duration::from_millis(20);
    let mut slave = rtu_slave(SlaveConfig { response_wait: wait, ..SlaveConfig::unit(1) });
    let request = rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]);
    assert_eq!(slave.receive(Instant::ZERO, &request), request.len());
    let got = slave.poll_request().expect("the request handed out");
    assert_eq!((got.unit, got.broadcast, got.pdu), (1, false, &[0x03, 0x00, 0x10, 0x00, 0x01][..]));
    let id = got.id;
    assert!(slave.poll_request().is_none(), "a request is handed out once");
    let mut out = [0u8; MAX_TX_LEN];
    assert_eq!(slave.poll_transmit(Instant::from_secs(1), &mut out), None, "nothing is sent before the answer");
    // Answered early: the reply still waits for t3.5 + the wait after the request's end.
    slave.respond(id, &[0x03, 0x02, 0x12, 0x34]).unwrap();
    let end = match slave.poll_event() {
        Some(SlaveEvent::Request { end, disposition: Disposition::Replied(due), .. }) => {
            assert_eq!(due, end.saturating_add(timing_9600().t3_5() + wait));
            end
        }
        other => panic!("not the request's report: {other:?}"),
    };
    assert_eq!(sent_at(&mut slave, end.saturating_add(timing_9600().t3_5() + wait)), rtu(1, &[0x03, 0x02, 0x12, 0x34]));
    // Answered late: it goes out at once.
    slave.receive(Instant::from_secs(2), &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let id = slave.poll_request().unwrap().id;
    assert_eq!(slave.reply_due(), None);
    slave.refuse(id, ExceptionCode::ServerDeviceBusy).unwrap();
    assert_eq!(
        slave.poll_transmit(Instant::from_secs(3), &mut out).map(|n| out[..n].to_vec()),
        Some(rtu(1, &[0x83, 0x06]))
    );
    assert_eq!(slave.counters().server_busy, 1);
}

#[test]
fn deferred_mbap_replies_go_out_in_request_order_whatever_order_they_are_answered_in() {
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    let input: Vec<u8> = (0..3u16).flat_map(|t| mbap(t, 1, &[0x03, 0, u8::try_from(t).unwrap(), 0, 1])).collect();
    assert_eq!(slave.receive(Instant::ZERO, &input), input.len());
    let handed: Vec<(RequestId, u16)> =
        core::iter::from_fn(|| slave.poll_request().map(|r| (r.id, r.transaction))).collect();
    assert_eq!(handed.iter().map(|&(_, t)| t).collect::<Vec<_>>(), [0, 1, 2], "each with its transaction id");
    let ids: Vec<RequestId> = handed.iter().map(|&(id, _)| id).collect();
    let mut out = [0u8; MAX_TX_LEN];
    slave.respond(ids[2], &[0x03, 0x02, 0, 2]).unwrap();
    slave.respond(ids[1], &[0x03, 0x02, 0, 1]).unwrap();
    assert_eq!(slave.poll_transmit(Instant::ZERO, &mut out), None, "the first request's reply holds back the rest");
    slave.respond(ids[0], &[0x03, 0x02, 0, 0]).unwrap();
    let sent: Vec<Vec<u8>> =
        core::iter::from_fn(|| slave.poll_transmit(Instant::ZERO, &mut out).map(|n| out[..n].to_vec())).collect();
    assert_eq!(
        sent,
        [mbap(0, 1, &[0x03, 0x02, 0, 0]), mbap(1, 1, &[0x03, 0x02, 0, 1]), mbap(2, 1, &[0x03, 0x02, 0, 2])]
    );
    assert_eq!(slave.pending_replies(), 0);
}

#[test]
fn deferred_mbap_requests_past_the_reply_queue_wait_in_the_receiver_until_answered() {
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    let input: Vec<u8> =
        (0..u16::try_from(REPLY_QUEUE).unwrap() + 4).flat_map(|t| mbap(t, 1, &[0x03, 0, 0, 0, 1])).collect();
    let taken = slave.receive(Instant::ZERO, &input);
    let first: Vec<RequestId> = core::iter::from_fn(|| slave.poll_request().map(|r| r.id)).collect();
    assert_eq!(first.len(), REPLY_QUEUE, "as many handed out as there are slots");
    assert!(slave.is_blocked(), "a full set of unanswered requests blocks the engine");
    assert_eq!(slave.receive(Instant::ZERO, &input[taken..]), 0, "no byte taken while blocked");
    for id in first {
        slave.respond(id, &[0x03, 0x02, 0, 0]).unwrap();
    }
    let mut out = [0u8; MAX_TX_LEN];
    while slave.poll_transmit(Instant::ZERO, &mut out).is_some() {}
    while slave.poll_event().is_some() {}
    let rest = slave.receive(Instant::ZERO, &input[taken..]);
    assert_eq!(taken + rest, input.len());
    assert_eq!(core::iter::from_fn(|| slave.poll_request().map(|r| r.id)).count(), 4);
}

#[test]
fn a_deferred_broadcast_is_handed_out_flagged_and_never_answered_whatever_the_response() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    slave.receive(Instant::ZERO, &rtu(0, &[0x06, 0x00, 0x05, 0x12, 0x34]));
    let got = slave.poll_request().unwrap();
    assert!(got.broadcast && got.unit == 0);
    let id = got.id;
    slave.respond(id, &[0x06, 0x00, 0x05, 0x12, 0x34]).unwrap();
    let mut out = [0u8; MAX_TX_LEN];
    assert_eq!(slave.poll_transmit(Instant::from_secs(1), &mut out), None, "a broadcast got a reply");
    assert_eq!(slave.reply_due(), None);
    assert!(matches!(
        slave.poll_event(),
        Some(SlaveEvent::Request { unit: 0, disposition: Disposition::Executed, .. })
    ));
    // The slot is free again: the next request is taken.
    slave.receive(Instant::from_millis(100), &rtu(1, &[0x03, 0, 0, 0, 1]));
    assert!(slave.poll_request().is_some(), "the line was left busy after the broadcast");
}

#[test]
fn an_unknown_or_answered_id_is_refused_and_a_bad_length_too() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    assert_eq!(slave.respond(RequestId(7), &[0x03, 0x02, 0, 0]), Err(AnswerError::Unknown(RequestId(7))));
    slave.receive(Instant::ZERO, &rtu(1, &[0x03, 0, 0, 0, 1]));
    let id = slave.poll_request().unwrap().id;
    assert_eq!(slave.respond(id, &[]), Err(AnswerError::BadLength(0)));
    assert_eq!(slave.respond(id, &[0u8; MAX_PDU_LEN + 1]), Err(AnswerError::BadLength(MAX_PDU_LEN + 1)));
    slave.respond(id, &[0x03, 0x02, 0, 0]).unwrap();
    assert_eq!(slave.respond(id, &[0x03, 0x02, 0, 0]), Err(AnswerError::Unknown(id)), "answered twice");
    assert_eq!(slave.ignore(id), Err(AnswerError::Unknown(id)));
    assert_eq!(slave.answer_with(id, &mut Device::new()), Err(AnswerError::Unknown(id)));
}

#[test]
fn a_request_whose_answer_never_comes_is_given_up_at_the_answer_limit_without_a_reply() {
    let mut slave = rtu_slave(SlaveConfig::unit(1));
    slave.set_answer_limit(Some(Duration::from_millis(500)));
    let request = rtu(1, &[0x03, 0, 0, 0, 1]);
    slave.receive(Instant::ZERO, &request);
    let id = slave.poll_request().unwrap().id;
    while slave.poll_event().is_some() {}
    // Step through the engine's deadlines: the request is dropped at the limit, not before.
    let limit = Instant::from_millis(500);
    loop {
        let at = slave.poll_timeout().expect("the engine wants to be woken at the limit");
        slave.wake(at.saturating_sub(Duration::from_nanos(1)));
        assert_eq!(slave.pending_replies(), 1, "given up before {at:?}");
        slave.wake(at);
        if slave.pending_replies() == 0 {
            assert_eq!(at, limit, "given up at {at:?}");
            break;
        }
    }
    assert!(matches!(slave.poll_event(), Some(SlaveEvent::Request { disposition: Disposition::Silent, .. })));
    assert_eq!(slave.counters().server_no_response, 1);
    assert_eq!(slave.respond(id, &[0x03, 0x02, 0, 0]), Err(AnswerError::Unknown(id)), "a stale id was taken");
    let mut out = [0u8; MAX_TX_LEN];
    assert_eq!(slave.poll_transmit(Instant::from_secs(10), &mut out), None);
    // The line is free for the next request.
    slave.receive(Instant::from_secs(1), &request);
    assert!(slave.poll_request().is_some());
}

#[test]
fn answer_with_is_the_same_dispatch_as_answering_at_once() {
    // The same request, answered at once by on_bytes and deferred through answer_with, gives
    // the same frame at the same instant.
    let request = rtu(9, &[0x03, 0x00, 0x02, 0x00, 0x02]);
    let config = SlaveConfig { units: [1, 9].into_iter().collect(), ..SlaveConfig::unit(1) };
    let mut at_once = rtu_slave(config);
    let (frame, due) = exchange(&mut at_once, &mut Device::new(), Instant::ZERO, &request).unwrap();
    let mut deferred = rtu_slave(config);
    deferred.receive(Instant::ZERO, &request);
    if deferred.pending_replies() == 0 {
        deferred.wake(deferred.poll_timeout().unwrap());
    }
    let id = deferred.poll_request().unwrap().id;
    deferred.answer_with(id, &mut Device::new()).unwrap();
    assert_eq!(sent_at(&mut deferred, due), frame, "unit 9's own wait, the same data");
}

#[test]
fn a_max_pending_bound_blocks_the_engine_at_that_many_requests_and_frees_it_with_a_reply() {
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    slave.set_connection_policy(ConnectionPolicy { max_pending: 3, ..ConnectionPolicy::NONE }, Instant::ZERO);
    let input: Vec<u8> = (0..5u16).flat_map(|t| mbap(t, 1, &[0x03, 0, 0, 0, 1])).collect();
    let taken = slave.receive(Instant::ZERO, &input);
    let ids: Vec<RequestId> = core::iter::from_fn(|| slave.poll_request().map(|r| r.id)).collect();
    assert_eq!(ids.len(), 3, "three handed out, the rest not framed");
    assert!(slave.is_blocked());
    slave.respond(ids[0], &[0x03, 0x02, 0, 0]).unwrap();
    let mut out = [0u8; MAX_TX_LEN];
    assert!(slave.poll_transmit(Instant::ZERO, &mut out).is_some());
    assert!(!slave.is_blocked(), "a reply sent makes room for one more");
    slave.receive(Instant::ZERO, &input[taken..]);
    assert_eq!(core::iter::from_fn(|| slave.poll_request().map(|r| r.id)).count(), 1, "one more, no more");
}

#[test]
fn rtu_taken_as_a_stream_pipelines_and_hands_unit_0_out_as_a_unit() {
    let mut slave = rtu_slave(SlaveConfig { units: [0, 1].into_iter().collect(), ..SlaveConfig::unit(1) });
    slave.set_stream(true);
    let two = [rtu(1, &[0x03, 0, 0, 0, 1]), rtu(0, &[0x06, 0, 1, 0, 2])].concat();
    slave.receive(Instant::ZERO, &two);
    let first = slave.poll_request().map(|r| (r.id, r.unit, r.broadcast)).unwrap();
    let second = slave.poll_request().map(|r| (r.id, r.unit, r.broadcast)).expect("a second request taken at once");
    assert_eq!((first.1, first.2, second.1, second.2), (1, false, 0, false));
    slave.respond(second.0, &[0x06, 0, 1, 0, 2]).unwrap();
    slave.respond(first.0, &[0x03, 0x02, 0, 0]).unwrap();
    let due = slave.reply_due().expect("the first reply is due");
    assert_eq!(sent_at(&mut slave, due), rtu(1, &[0x03, 0x02, 0, 0]), "in request order");
    assert_eq!(slave.poll_transmit(due, &mut [0u8; MAX_TX_LEN]).map(|_| ()), Some(()), "unit 0 answered too");
}

/// A Modbus/TCP slave of unit 1 under `policy`, opened at 0.
fn tcp_slave(policy: ConnectionPolicy) -> Slave<MbapCodec> {
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    slave.set_connection_policy(policy, Instant::ZERO);
    slave
}

const SECOND: Duration = Duration::from_secs(1);

#[test]
fn an_idle_connection_closes_at_its_idle_time_after_the_last_byte_and_not_a_nanosecond_before() {
    let mut slave = tcp_slave(ConnectionPolicy { idle: Some(SECOND), ..ConnectionPolicy::NONE });
    assert_eq!(slave.poll_timeout(), Some(Instant::from_secs(1)), "quiet since it was opened");
    let read = mbap(1, 1, &[0x03, 0, 0, 0, 1]);
    slave.on_bytes(Instant::from_millis(400), &read, &mut Device::new());
    let due = slave.reply_due().unwrap();
    assert!(slave.poll_transmit(due, &mut [0u8; MAX_TX_LEN]).is_some());
    let at = due.checked_add(SECOND).unwrap();
    assert_eq!(slave.poll_timeout(), Some(at), "quiet from the reply on");
    slave.wake(Instant::from_nanos(at.as_nanos() - 1));
    assert_eq!(slave.closed(), None);
    slave.wake(at);
    assert_eq!(slave.closed(), Some(Closed::Idle(SECOND)));
    assert_eq!(slave.poll_timeout(), None, "a closed connection has no deadline left");
}

#[test]
fn a_connection_is_never_idle_while_a_request_waits_for_its_answer() {
    let mut slave = tcp_slave(ConnectionPolicy { idle: Some(SECOND), ..ConnectionPolicy::NONE });
    slave.set_answer_limit(None);
    slave.receive(Instant::ZERO, &mbap(1, 1, &[0x03, 0, 0, 0, 1]));
    let id = slave.poll_request().unwrap().id;
    assert_eq!(slave.poll_timeout(), None, "a slow device behind a gateway");
    slave.wake(Instant::from_secs(3600));
    assert_eq!(slave.closed(), None);
    slave.respond(id, &[0x03, 0x02, 0, 7]).unwrap();
    let at = Instant::from_secs(3601);
    assert!(slave.poll_transmit(at, &mut [0u8; MAX_TX_LEN]).is_some());
    assert_eq!(slave.poll_timeout(), Some(Instant::from_secs(3602)), "idle counts from the reply");
}

#[test]
fn a_frame_begun_and_not_finished_closes_at_its_frame_time_after_its_first_byte() {
    let policy = ConnectionPolicy { frame: Some(SECOND), ..ConnectionPolicy::NONE };
    let read = mbap(1, 1, &[0x03, 0, 0, 0, 1]);
    let mut slave = tcp_slave(policy);
    assert_eq!(slave.poll_timeout(), None, "no frame begun");
    slave.on_bytes(Instant::from_millis(100), &read[..3], &mut Device::new());
    slave.on_bytes(Instant::from_millis(900), &read[3..5], &mut Device::new());
    assert_eq!(slave.poll_timeout(), Some(Instant::from_millis(1100)), "from the first byte, not the last");
    slave.wake(Instant::from_millis(1100));
    assert_eq!(slave.closed(), Some(Closed::UnfinishedFrame(SECOND)));

    let mut finished = tcp_slave(policy);
    finished.on_bytes(Instant::from_millis(100), &read[..3], &mut Device::new());
    finished.on_bytes(Instant::from_millis(900), &read[3..], &mut Device::new());
    let due = finished.reply_due().unwrap();
    assert!(finished.poll_transmit(due, &mut [0u8; MAX_TX_LEN]).is_some());
    assert_eq!(finished.poll_timeout(), None, "the frame was finished");
    finished.wake(Instant::from_secs(60));
    assert_eq!(finished.closed(), None);
}

#[test]
fn a_frame_is_not_timed_while_the_engine_holds_the_client_back_and_is_from_when_it_reads_again() {
    let policy = ConnectionPolicy { frame: Some(SECOND), max_pending: 1, ..ConnectionPolicy::NONE };
    let mut slave = tcp_slave(policy);
    slave.set_answer_limit(None);
    let second = mbap(2, 1, &[0x03, 0, 0, 0, 1]);
    let input = [mbap(1, 1, &[0x03, 0, 0, 0, 1]).as_slice(), &second[..4]].concat();
    slave.receive(Instant::ZERO, &input);
    let id = slave.poll_request().unwrap().id;
    assert!(slave.is_blocked() && slave.framing().is_mid_frame(), "a half frame behind a request outstanding");
    slave.wake(Instant::from_secs(5));
    assert_eq!((slave.poll_timeout(), slave.closed()), (None, None), "nothing is read: nothing is timed");
    slave.respond(id, &[0x03, 0x02, 0, 7]).unwrap();
    assert!(slave.poll_transmit(Instant::from_secs(10), &mut [0u8; MAX_TX_LEN]).is_some());
    assert_eq!(slave.poll_timeout(), Some(Instant::from_secs(11)), "timed from when the engine reads again");
    slave.receive(Instant::from_millis(10_500), &second[4..]);
    assert_eq!(slave.poll_request().map(|r| r.transaction), Some(2));
    assert_eq!(slave.poll_timeout(), None, "finished in time");
}

#[test]
fn a_bad_mbap_header_closes_the_connection_after_the_replies_owed_before_it() {
    let mut slave = tcp_slave(ConnectionPolicy::TCP);
    let bad = [0u8, 9, 0, 7, 0, 6, 1, 3, 0, 0, 0, 1];
    let input = [mbap(1, 1, &[0x03, 0, 0, 0, 1]).as_slice(), &bad].concat();
    slave.on_bytes(Instant::ZERO, &input, &mut Device::new());
    assert_eq!(slave.closed(), Some(Closed::BadHeader));
    let due = slave.reply_due().expect("the request before it is still answered");
    assert!(slave.poll_transmit(due, &mut [0u8; MAX_TX_LEN]).is_some());
    assert_eq!(slave.poll_timeout(), None);
}

#[test]
fn without_a_policy_nothing_closes_a_connection() {
    let mut slave = Slave::new(MbapCodec::strict(), SlaveConfig::unit(1));
    assert_eq!(slave.connection_policy(), ConnectionPolicy::NONE);
    slave.receive(Instant::ZERO, &mbap(1, 1, &[0x03, 0, 0])[..5]);
    assert_eq!(slave.poll_timeout(), None);
    slave.wake(Instant::from_secs(u64::from(u32::MAX)));
    assert_eq!(slave.closed(), None);
    let huge = ConnectionPolicy { idle: Some(Duration::MAX), frame: Some(Duration::MAX), max_pending: 0 };
    let slave = tcp_slave(huge);
    assert_eq!(slave.connection_policy().max_pending, 1, "at least one request");
    assert_eq!(slave.poll_timeout(), None, "a time past representable time is no deadline");
}
