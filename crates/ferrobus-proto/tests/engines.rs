//! Master and slaves on one simulated RS-485 line, through the public API only: every byte
//! arrives at every other node one character time after the previous one, and time jumps
//! from one deadline to the next (a discrete-event simulation in the style of quinn-proto's
//! test `Pair`). Checks every function code end to end, the timing rules on the wire, and a
//! multidrop bus.

use std::collections::BTreeMap;
use std::time::Duration;

use ferrobus_proto::codes::{DiagnosticCode, ExceptionCode, ReadDeviceIdCode};
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming};
use ferrobus_proto::master::{Completion, MAX_TX_LEN, Master, MasterConfig};
use ferrobus_proto::pdu::{
    Bits, Custom, Diagnostic, FileRecordReads, FileRecordRef, FileRecordWrite, FileRecordWrites, MaskWrite, MeiRequest,
    NoData, ReadBits, ReadDeviceId, ReadFifo, ReadRegisters, ReadWriteRegisters, Registers, Request, Response,
    WriteCoil, WriteCoils, WriteRegister, WriteRegisters,
};
use ferrobus_proto::slave::{Handler, Slave, SlaveConfig};
use ferrobus_proto::time::Instant;

/// A device with 1000 registers and coils, three identification objects and a FIFO.
struct Memory {
    coils: Vec<bool>,
    registers: Vec<u16>,
    files: Vec<u16>,
}

impl Memory {
    fn new() -> Self {
        Memory {
            coils: (0..1000).map(|i| i % 3 == 0).collect(),
            registers: (0..1000u16).map(|i| i.wrapping_mul(7).wrapping_add(3)).collect(),
            files: vec![0; 1000],
        }
    }
}

fn slice<T>(v: &mut [T], start: u16, n: usize) -> Result<&mut [T], ExceptionCode> {
    v.get_mut(usize::from(start)..usize::from(start) + n).ok_or(ExceptionCode::IllegalDataAddress)
}

impl Handler for Memory {
    fn read_coils(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(slice(&mut self.coils, start, out.len())?);
        Ok(())
    }
    fn read_discrete_inputs(&mut self, u: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.read_coils(u, start, out)
    }
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(slice(&mut self.registers, start, out.len())?);
        Ok(())
    }
    fn read_input_registers(&mut self, u: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.read_holding_registers(u, start, out)
    }
    fn write_single_coil(&mut self, _: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        slice(&mut self.coils, address, 1)?[0] = value;
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        slice(&mut self.registers, address, 1)?[0] = value;
        Ok(())
    }
    fn write_multiple_coils(&mut self, _: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        values.copy_to(slice(&mut self.coils, start, values.len())?);
        Ok(())
    }
    fn write_multiple_registers(&mut self, _: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        values.copy_to(slice(&mut self.registers, start, values.len())?);
        Ok(())
    }
    fn read_exception_status(&mut self, _: u8) -> Result<u8, ExceptionCode> {
        Ok(0x55)
    }
    fn report_server_id(&mut self, unit: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        out[..2].copy_from_slice(&[unit, 0xFF]);
        Ok(2)
    }
    fn read_file_record(&mut self, _: u8, _: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.copy_from_slice(slice(&mut self.files, record, out.len())?);
        Ok(())
    }
    fn write_file_record(&mut self, _: u8, _: u16, record: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        values.copy_to(slice(&mut self.files, record, values.len())?);
        Ok(())
    }
    fn read_fifo_queue(&mut self, _: u8, _: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        out[..3].copy_from_slice(&[10, 20, 30]);
        Ok(3)
    }
    fn device_object(&mut self, _: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        let value: &[u8] = match id {
            0 => b"ferrobus",
            1 => b"SIM",
            2 => b"0.1",
            _ => return None,
        };
        out[..value.len()].copy_from_slice(value);
        Some(value.len())
    }
    fn custom(&mut self, _: u8, _: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        out[..data.len()].copy_from_slice(data);
        out[..data.len()].reverse();
        Ok(data.len())
    }
}

/// A byte on the wire: who sent it and when its last bit was on the line.
#[derive(Clone, Copy, Debug)]
struct WireByte {
    from: usize,
    at: Instant,
    byte: u8,
}

/// One master (node 0) and slaves (nodes 1..) on a line.
struct Line {
    timing: LineTiming,
    now: Instant,
    master: Master<RtuCodec>,
    slaves: Vec<(Slave<RtuCodec>, Memory)>,
    /// Bytes in flight, by arrival time (ties keep order).
    in_flight: BTreeMap<(Instant, u64), WireByte>,
    seq: u64,
    /// Every byte that crossed the line, in order.
    log: Vec<WireByte>,
}

impl Line {
    fn new(baud: u32, slaves: &[SlaveConfig]) -> Self {
        let timing = LineTiming::new(&LineConfig::new(baud).unwrap());
        Line {
            timing,
            now: Instant::ZERO,
            master: Master::new(RtuCodec::new(timing, Expect::Both), MasterConfig::default()),
            slaves: slaves
                .iter()
                .map(|c| (Slave::new(RtuCodec::new(timing, Expect::Both), *c), Memory::new()))
                .collect(),
            in_flight: BTreeMap::new(),
            seq: 0,
            log: Vec::new(),
        }
    }

    /// Puts `bytes` from `from` on the line, one character time apart, starting now.
    fn send(&mut self, from: usize, bytes: &[u8]) {
        let char_time = self.timing.char_time();
        let start = self.in_flight.values().map(|b| b.at).max().unwrap_or(self.now).max(self.now);
        for (i, &byte) in bytes.iter().enumerate() {
            let at = start.saturating_add(char_time * (u32::try_from(i).unwrap() + 1));
            self.seq += 1;
            self.in_flight.insert((at, self.seq), WireByte { from, at, byte });
        }
    }

    /// Runs until the master has a completion, and returns a summary of it.
    fn run(&mut self) -> String {
        let mut buf = [0u8; MAX_TX_LEN];
        for _ in 0..100_000 {
            if let Some(n) = self.master.poll_transmit(self.now, &mut buf) {
                self.send(0, &buf[..n]);
            }
            for i in 0..self.slaves.len() {
                if let Some(n) = self.slaves[i].0.poll_transmit(self.now, &mut buf) {
                    self.send(i + 1, &buf[..n]);
                }
            }
            if let Some(done) = self.master.poll_event() {
                return summary(done);
            }
            // A slave takes no more bytes while its events wait: poll them, as a driver does.
            for (slave, _) in &mut self.slaves {
                while slave.poll_event().is_some() {}
            }
            // Jump to the next thing that happens: a byte arriving or a deadline.
            let next_byte = self.in_flight.keys().next().map(|k| k.0);
            let deadlines = std::iter::once(self.master.poll_timeout())
                .chain(self.slaves.iter().map(|(s, _)| s.poll_timeout()))
                .flatten();
            let next = deadlines.chain(next_byte).min().expect("something must be pending");
            assert!(next >= self.now, "time never goes backwards");
            self.now = next;
            while let Some(entry) = self.in_flight.first_entry() {
                if entry.key().0 > self.now {
                    break;
                }
                let wb = entry.remove();
                self.log.push(wb);
                if wb.from != 0 {
                    self.master.on_bytes(wb.at, &[wb.byte]);
                }
                for (i, (slave, memory)) in self.slaves.iter_mut().enumerate() {
                    if wb.from != i + 1 {
                        slave.on_bytes(wb.at, &[wb.byte], memory);
                    }
                }
            }
            self.master.handle_timeout(self.now);
            for (slave, memory) in &mut self.slaves {
                slave.handle_timeout(self.now, memory);
            }
        }
        panic!("no completion");
    }

    fn request(&mut self, unit: u8, request: &Request<'_>) -> String {
        self.master.submit(self.now, unit, request).unwrap();
        self.run()
    }

    /// The frames on the line, split where a new sender starts, with their first and last
    /// byte times.
    fn frames(&self) -> Vec<(usize, Instant, Instant, Vec<u8>)> {
        let mut frames: Vec<(usize, Instant, Instant, Vec<u8>)> = Vec::new();
        for b in &self.log {
            let char_gap = self.timing.char_time() * 2;
            match frames.last_mut() {
                Some(f) if f.0 == b.from && b.at.saturating_duration_since(f.2) < char_gap => {
                    f.2 = b.at;
                    f.3.push(b.byte);
                }
                _ => frames.push((b.from, b.at, b.at, vec![b.byte])),
            }
        }
        frames
    }
}

fn summary(done: Completion<'_>) -> String {
    match done {
        Completion::Response(r) => format!("{r:?}"),
        Completion::Exception(e) => format!("exception {e}"),
        Completion::Sent => "broadcast".into(),
        Completion::Raw(pdu) => format!("raw {pdu:02X?}"),
        Completion::Failed(e) => format!("failed: {e}"),
    }
}

#[test]
fn every_function_code_round_trips_between_master_and_slave() {
    let mut line = Line::new(19_200, &[SlaveConfig::unit(1)]);
    let coils = [true, false, true, true];
    let regs = [0x0BB8, 0x0000];
    let file_refs = [FileRecordRef { file: 4, record: 1, length: 2 }];
    let file_data = [0x1111, 0x2222];
    let file_writes = [FileRecordWrite { file: 4, record: 1, data: Registers::from_values(&file_data) }];
    let requests: Vec<(Request<'_>, &str)> = vec![
        (Request::ReadCoils(ReadBits::new(0, 5).unwrap()), "ReadCoils(BitValues { values: [10010] })"),
        (Request::ReadDiscreteInputs(ReadBits::new(3, 2).unwrap()), "ReadDiscreteInputs(BitValues { values: [10] })"),
        (
            Request::ReadHoldingRegisters(ReadRegisters::new(1, 2).unwrap()),
            "ReadHoldingRegisters(RegisterValues { values: [10, 17] })",
        ),
        (
            Request::ReadInputRegisters(ReadRegisters::new(0, 1).unwrap()),
            "ReadInputRegisters(RegisterValues { values: [3] })",
        ),
        (
            Request::WriteSingleCoil(WriteCoil { address: 1, value: true }),
            "WriteSingleCoil(WriteCoil { address: 1, value: true })",
        ),
        (
            Request::WriteSingleRegister(WriteRegister { address: 2, value: 99 }),
            "WriteSingleRegister(WriteRegister { address: 2, value: 99 })",
        ),
        (Request::ReadExceptionStatus(NoData), "ReadExceptionStatus(ExceptionStatus { status: 85 })"),
        (
            Request::Diagnostics(Diagnostic::with_data(DiagnosticCode::ReturnQueryData, &[0xA5, 0x37]).unwrap()),
            "Diagnostics(Diagnostic { sub_function: ReturnQueryData, data: [165, 55] })",
        ),
        (
            Request::Diagnostics(Diagnostic::with_word(DiagnosticCode::BusMessageCount, 0)),
            "Diagnostics(Diagnostic { sub_function: BusMessageCount, data: [0, 9] })",
        ),
        (Request::GetCommEventCounter(NoData), "GetCommEventCounter(CommEventCounter { status: 0, event_count: 9 })"),
        (
            Request::WriteMultipleCoils(WriteCoils::new(10, Bits::from_values(&coils)).unwrap()),
            "WriteMultipleCoils(WrittenCoils { start: 10, quantity: 4 })",
        ),
        (
            Request::WriteMultipleRegisters(WriteRegisters::new(0x0112, Registers::from_values(&regs)).unwrap()),
            "WriteMultipleRegisters(WrittenRegisters { start: 274, quantity: 2 })",
        ),
        (Request::ReportServerId(NoData), "ReportServerId(ServerId { data: [1, 255] })"),
        (Request::WriteFileRecord(FileRecordWrites::new(&file_writes).unwrap()), "WriteFileRecord([FileRecordWrite"),
        (Request::ReadFileRecord(FileRecordReads::new(&file_refs).unwrap()), "ReadFileRecord([[4369, 8738]])"),
        (
            Request::MaskWriteRegister(MaskWrite { address: 2, and_mask: 0x00F0, or_mask: 0x0005 }),
            "MaskWriteRegister(MaskWrite { address: 2, and_mask: 240, or_mask: 5 })",
        ),
        (
            Request::ReadWriteMultipleRegisters(
                ReadWriteRegisters::new(2, 1, 3, Registers::from_values(&[7])).unwrap(),
            ),
            "ReadWriteMultipleRegisters(RegisterValues { values: [101] })",
        ),
        (Request::ReadFifoQueue(ReadFifo { address: 0 }), "ReadFifoQueue(FifoValues { values: [10, 20, 30] })"),
        (
            Request::EncapsulatedInterface(MeiRequest::ReadDeviceId(
                ReadDeviceId::new(ReadDeviceIdCode::Basic, 0).unwrap(),
            )),
            "EncapsulatedInterface(ReadDeviceId(DeviceIdentification { code: Basic, conformity: 129",
        ),
        (Request::Custom(Custom::new(0x41, &[1, 2, 3]).unwrap()), "Custom(Custom { function: 65, data: [3, 2, 1] })"),
        (Request::ReadHoldingRegisters(ReadRegisters::new(999, 2).unwrap()), "exception 0x02 Illegal Data Address"),
    ];
    for (request, expected) in &requests {
        let got = line.request(1, request);
        assert!(got.starts_with(expected), "{request}: got {got}, expected {expected}");
    }
    // The mask write above: (99 & 0xF0) | (0x05 & !0xF0) = 0x65 = 101, read back by 0x17.
}

#[test]
fn the_seed_frames_cross_the_line_byte_for_byte() {
    let mut line = Line::new(9600, &[SlaveConfig::unit(1)]);
    let regs = [0x0BB8, 0x0000];
    let reply = line.request(
        1,
        &Request::WriteMultipleRegisters(WriteRegisters::new(0x0112, Registers::from_values(&regs)).unwrap()),
    );
    assert_eq!(reply, "WriteMultipleRegisters(WrittenRegisters { start: 274, quantity: 2 })");
    let frames = line.frames();
    assert_eq!(frames[0].3, [0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00, 0xFC, 0xEB]);
    assert_eq!(frames[1].3, [0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0xE0, 0x31]);
}

#[test]
fn on_the_wire_every_gap_between_frames_is_at_least_t3_5_and_the_slave_adds_its_wait() {
    let wait = Duration::from_millis(20);
    let mut line = Line::new(9600, &[SlaveConfig { response_wait: wait, ..SlaveConfig::unit(1) }]);
    for i in 0..5 {
        let reply = line.request(1, &Request::ReadHoldingRegisters(ReadRegisters::new(i, 10).unwrap()));
        assert!(reply.starts_with("ReadHoldingRegisters"), "{reply}");
    }
    let t3_5 = line.timing.t3_5();
    let char_time = line.timing.char_time();
    let frames = line.frames();
    assert_eq!(frames.len(), 10);
    for pair in frames.windows(2) {
        let (prev, next) = (&pair[0], &pair[1]);
        // Byte times mark the end of a character; the next frame's first character starts
        // one character time before its time stamp.
        let silence = next.1.saturating_duration_since(prev.2).checked_sub(char_time).unwrap();
        if next.0 == 0 {
            assert!(silence >= t3_5, "master broke the gap: {silence:?}");
            assert!(silence < t3_5 + Duration::from_micros(1), "master waited too long: {silence:?}");
        } else {
            assert!(silence >= t3_5 + wait, "slave replied early: {silence:?}");
            assert!(silence < t3_5 + wait + Duration::from_micros(1), "slave replied late: {silence:?}");
        }
    }
}

#[test]
fn on_a_multidrop_bus_each_slave_answers_only_itself_and_all_execute_a_broadcast() {
    let mut line = Line::new(19_200, &[SlaveConfig::unit(1), SlaveConfig::unit(2), SlaveConfig::unit(3)]);
    for unit in 1..=3u8 {
        let reply = line.request(unit, &Request::ReportServerId(NoData));
        assert_eq!(reply, format!("ReportServerId(ServerId {{ data: [{unit}, 255] }})"));
    }
    assert_eq!(line.request(9, &Request::ReportServerId(NoData)), "failed: no reply within 1000 ms");
    let reply = line.request(0, &Request::WriteSingleRegister(WriteRegister { address: 5, value: 0xBEEF }));
    assert_eq!(reply, "broadcast");
    for (_, memory) in &line.slaves {
        assert_eq!(memory.registers[5], 0xBEEF);
    }
    for (slave, _) in &line.slaves {
        let c = slave.counters();
        assert_eq!(c.bus_comm_errors, 0, "other slaves' replies are not errors");
        assert_eq!(c.bus_messages, 7, "5 requests and the 2 other slaves' replies: a slave does not hear itself");
    }
}

#[test]
fn the_master_reads_every_response_type_the_slave_can_send() {
    // Replies parsed by the master are exactly what the slave emitted.
    let mut line = Line::new(115_200, &[SlaveConfig::unit(7)]);
    let reply = line.request(7, &Request::ReadHoldingRegisters(ReadRegisters::new(0, 125).unwrap()));
    let expected: Vec<u16> = (0..125u16).map(|i| i * 7 + 3).collect();
    assert_eq!(reply, format!("ReadHoldingRegisters(RegisterValues {{ values: {expected:?} }})"));
    let reply = line.request(7, &Request::ReadCoils(ReadBits::new(0, 2000).unwrap_or_else(|e| panic!("{e}"))));
    assert!(reply.starts_with("exception 0x02"), "{reply}");
    let reply = line.request(7, &Request::ReadCoils(ReadBits::new(0, 1000).unwrap()));
    assert!(reply.starts_with("ReadCoils(BitValues { values: [100100"), "{reply}");
    let _ = Response::parse(&[0x03, 0x02, 0x00, 0x01]).unwrap();
}
