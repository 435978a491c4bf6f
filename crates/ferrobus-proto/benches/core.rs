//! Criterion benchmarks of the protocol core: the costs a driver pays per frame.
//!
//! - `crc16/256B`: CRC-16/MODBUS over the largest RTU frame.
//! - `fc03/request encode+decode`, `fc03/response encode+decode`: emit and parse a read of
//!   125 registers (the largest) and its 253-byte response.
//! - `rtu/receive 125-register response`: a whole 255-byte response frame pushed through the
//!   RTU receiver (length prediction after every byte, then the CRC) and polled out.
//! - `engine/master+slave round trip`: one 0x03 transaction of 10 registers between a master
//!   and a slave engine in memory, with explicit time: submit, transmit, the slave's receive,
//!   its reply at t3.5, the master's receive and completion.
//!
//! Run: `cargo bench -p ferrobus-proto --bench core` (add `-- --warm-up-time 1
//! --measurement-time 3` for a quick run). The goal for the first three is under 100 ns each.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::crc::crc16;
use ferrobus_proto::frame::rtu::{self, RtuCodec};
use ferrobus_proto::frame::{Expect, Framing, LineConfig, LineTiming, RxEvent};
use ferrobus_proto::master::{Completion, MAX_TX_LEN, Master, MasterConfig};
use ferrobus_proto::pdu::{MAX_PDU_LEN, ReadRegisters, RegisterValues, Registers, Request, Response};
use ferrobus_proto::slave::{Handler, Slave, SlaveConfig};
use ferrobus_proto::time::Instant;

/// 125 register values, the most one response carries.
fn values_125() -> [u16; 125] {
    core::array::from_fn(|i| u16::try_from(i).expect("i < 125").wrapping_mul(0x0101))
}

fn crc(c: &mut Criterion) {
    let data: [u8; 256] = core::array::from_fn(|i| u8::try_from(i).expect("i < 256"));
    let mut group = c.benchmark_group("crc16");
    group.throughput(Throughput::Bytes(256));
    group.bench_function("256B", |b| b.iter(|| crc16(black_box(&data))));
    group.finish();
}

fn fc03(c: &mut Criterion) {
    let mut group = c.benchmark_group("fc03");

    let request = Request::ReadHoldingRegisters(ReadRegisters::new(0, 125).expect("125 registers"));
    let mut buf = [0u8; MAX_PDU_LEN];
    group.bench_function("request encode+decode", |b| {
        b.iter(|| {
            let n = black_box(&request).emit(&mut buf).expect("fits");
            let parsed = Request::parse(black_box(&buf[..n])).expect("parses");
            black_box(parsed);
        });
    });

    let values = values_125();
    let response =
        Response::ReadHoldingRegisters(RegisterValues::new(Registers::from_values(&values)).expect("125 registers"));
    group.bench_function("response encode+decode", |b| {
        b.iter(|| {
            let n = black_box(&response).emit(&mut buf).expect("fits");
            let parsed = Response::parse(black_box(&buf[..n])).expect("parses");
            black_box(parsed);
        });
    });
    group.finish();
}

fn rtu_receive(c: &mut Criterion) {
    let values = values_125();
    let response =
        Response::ReadHoldingRegisters(RegisterValues::new(Registers::from_values(&values)).expect("125 registers"));
    let mut adu = [0u8; rtu::MAX_ADU_LEN];
    let n = rtu::encode_response(1, &response, &mut adu).expect("fits");
    assert_eq!(n, 255, "unit, fc, byte count, 250 data bytes, CRC");
    let frame = &adu[..n];

    let timing = LineTiming::new(&LineConfig::default());
    let mut codec = RtuCodec::new(timing, Expect::Responses);
    let now = Instant::ZERO;
    let mut group = c.benchmark_group("rtu");
    group.throughput(Throughput::Bytes(255));
    group.bench_function("receive 125-register response", |b| {
        b.iter(|| {
            // The previous frame is released by this push; a frame of known length completes
            // at its last byte, without waiting for the gap.
            let consumed = codec.push(now, black_box(frame));
            debug_assert_eq!(consumed, frame.len());
            match codec.poll_event() {
                Some(RxEvent::Frame(adu)) => black_box(adu.pdu.len()),
                other => panic!("expected the frame, got {other:?}"),
            }
        });
    });
    group.finish();
}

/// Holding registers 0–15 hold their own address.
struct Registers16;

impl Handler for Registers16 {
    fn read_holding_registers(&mut self, _unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        let end = usize::from(start) + out.len();
        if end > 16 {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        for (slot, address) in out.iter_mut().zip(start..) {
            *slot = address;
        }
        Ok(())
    }
}

fn engine(c: &mut Criterion) {
    let timing = LineTiming::new(&LineConfig::default());
    let mut master = Master::new(RtuCodec::new(timing, Expect::Responses), MasterConfig::default());
    let mut slave = Slave::new(RtuCodec::new(timing, Expect::Requests), SlaveConfig::unit(1));
    let mut handler = Registers16;
    let request = Request::ReadHoldingRegisters(ReadRegisters::new(0, 10).expect("10 registers"));
    let mut tx = [0u8; MAX_TX_LEN];
    let mut now = Instant::ZERO;

    let mut group = c.benchmark_group("engine");
    group.bench_function("master+slave round trip", |b| {
        b.iter(|| {
            master.submit(now, 1, black_box(&request)).expect("idle");
            // The master waits for t3.5 of silence after the previous reply.
            now = now.max(master.poll_timeout().expect("a queued request has a deadline"));
            let n = master.poll_transmit(now, &mut tx).expect("due");
            slave.on_bytes(now, black_box(&tx[..n]), &mut handler);
            now = slave.poll_timeout().expect("a reply is due");
            let m = slave.poll_transmit(now, &mut tx).expect("due");
            // The slave takes no frame while its event queue is full.
            while slave.poll_event().is_some() {}
            master.on_bytes(now, black_box(&tx[..m]));
            match master.poll_event() {
                Some(Completion::Response(Response::ReadHoldingRegisters(r))) => black_box(r.values().len()),
                other => panic!("expected the registers, got {other:?}"),
            }
        });
    });
    group.finish();
}

criterion_group!(benches, crc, fc03, rtu_receive, engine);
criterion_main!(benches);
