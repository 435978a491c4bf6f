//! Serving a data request through a [`Handler`]: one arm per function code, each calling the
//! handler once and emitting the response PDU.

use super::Handler;
use crate::codes::{ExceptionCode, ReadDeviceIdCode, conformity};
use crate::cursor::Writer;
use crate::error::PduError;
use crate::pdu::{
    BitValues, Bits, Custom, DeviceIdentification, DeviceObjects, ExceptionStatus, FifoValues, FileRecordReads,
    FileSubResponses, MAX_DATA_LEN, MAX_PDU_LEN, MeiRequest, MeiResponse, RawMei, ReadBits, ReadDeviceId,
    ReadRegisters, RegisterValues, Registers, Request, Response, ServerId, WrittenCoils, WrittenRegisters,
};

/// Exceptions for a response that cannot be built: the request asked for more than fits.
fn too_big(_: PduError) -> ExceptionCode {
    ExceptionCode::IllegalDataValue
}

/// Emits `response` into `out`; returns the PDU length.
fn emit(response: &Response<'_>, out: &mut [u8; MAX_PDU_LEN]) -> Result<usize, ExceptionCode> {
    response.emit(out).map_err(|_| ExceptionCode::ServerDeviceFailure)
}

/// Serves `request` for `unit` (any function but 0x08, 0x0B and 0x0C, which the engine serves
/// itself) and writes the response PDU into `out`.
pub(super) fn serve<H: Handler + ?Sized>(
    handler: &mut H,
    unit: u8,
    request: &Request<'_>,
    out: &mut [u8; MAX_PDU_LEN],
) -> Result<usize, ExceptionCode> {
    match request {
        Request::ReadCoils(q) => {
            read_bits(*q, out, BitTable::Coils, |start, bits| handler.read_coils(unit, start, bits))
        }
        Request::ReadDiscreteInputs(q) => {
            read_bits(*q, out, BitTable::DiscreteInputs, |start, bits| handler.read_discrete_inputs(unit, start, bits))
        }
        Request::ReadHoldingRegisters(q) => read_registers(*q, out, RegisterTable::Holding, |start, regs| {
            handler.read_holding_registers(unit, start, regs)
        }),
        Request::ReadInputRegisters(q) => {
            read_registers(*q, out, RegisterTable::Input, |start, regs| handler.read_input_registers(unit, start, regs))
        }
        Request::WriteSingleCoil(q) => {
            handler.write_single_coil(unit, q.address, q.value)?;
            emit(&Response::WriteSingleCoil(*q), out)
        }
        Request::WriteSingleRegister(q) => {
            handler.write_single_register(unit, q.address, q.value)?;
            emit(&Response::WriteSingleRegister(*q), out)
        }
        Request::WriteMultipleCoils(q) => {
            handler.write_multiple_coils(unit, q.start(), q.values())?;
            let written = WrittenCoils::new(q.start(), q.quantity()).map_err(too_big)?;
            emit(&Response::WriteMultipleCoils(written), out)
        }
        Request::WriteMultipleRegisters(q) => {
            handler.write_multiple_registers(unit, q.start(), q.values())?;
            let written = WrittenRegisters::new(q.start(), q.quantity()).map_err(too_big)?;
            emit(&Response::WriteMultipleRegisters(written), out)
        }
        Request::MaskWriteRegister(q) => {
            handler.mask_write_register(unit, *q)?;
            emit(&Response::MaskWriteRegister(*q), out)
        }
        Request::ReadWriteMultipleRegisters(q) => {
            let mut regs = [0u16; ReadRegisters::MAX as usize];
            let read = regs.get_mut(..usize::from(q.read().quantity())).ok_or(ExceptionCode::IllegalDataValue)?;
            handler.read_write_multiple_registers(unit, q, read)?;
            let values = RegisterValues::new(Registers::from_values(read)).map_err(too_big)?;
            emit(&Response::ReadWriteMultipleRegisters(values), out)
        }
        Request::ReadExceptionStatus(_) => {
            let status = handler.read_exception_status(unit)?;
            emit(&Response::ReadExceptionStatus(ExceptionStatus { status }), out)
        }
        Request::ReportServerId(_) => {
            let mut data = [0u8; ServerId::MAX];
            let n = handler.report_server_id(unit, &mut data)?;
            let id = ServerId::new(data.get(..n).ok_or(ExceptionCode::ServerDeviceFailure)?)
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
            emit(&Response::ReportServerId(id), out)
        }
        Request::ReadFileRecord(q) => read_file_record(handler, unit, q, out),
        Request::WriteFileRecord(q) => {
            for sub in q.iter() {
                handler.write_file_record(unit, sub.file, sub.record, sub.data)?;
            }
            emit(&Response::WriteFileRecord(*q), out)
        }
        Request::ReadFifoQueue(q) => {
            let mut values = [0u16; FifoValues::MAX];
            let n = handler.read_fifo_queue(unit, q.address, &mut values)?;
            let regs = values.get(..n).ok_or(ExceptionCode::IllegalDataValue)?;
            let fifo = FifoValues::new(Registers::from_values(regs)).map_err(too_big)?;
            emit(&Response::ReadFifoQueue(fifo), out)
        }
        Request::EncapsulatedInterface(MeiRequest::ReadDeviceId(q)) => read_device_id(handler, unit, *q, out),
        Request::EncapsulatedInterface(MeiRequest::Other(raw)) => {
            let mut data = [0u8; MAX_DATA_LEN - 1];
            let n = handler.encapsulated(unit, raw.mei_type().value(), raw.data(), &mut data)?;
            let reply = RawMei::new(raw.mei_type(), data.get(..n).ok_or(ExceptionCode::ServerDeviceFailure)?)
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
            emit(&Response::EncapsulatedInterface(MeiResponse::Other(reply)), out)
        }
        Request::Custom(c) => {
            let mut data = [0u8; MAX_DATA_LEN];
            let n = handler.custom(unit, c.function(), c.data(), &mut data)?;
            let reply = Custom::new(c.function(), data.get(..n).ok_or(ExceptionCode::ServerDeviceFailure)?)
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
            emit(&Response::Custom(reply), out)
        }
        // Served by the engine from its own counters.
        Request::Diagnostics(_) | Request::GetCommEventCounter(_) | Request::GetCommEventLog(_) => {
            Err(ExceptionCode::IllegalFunction)
        }
    }
}

/// The bit table a read addresses.
#[derive(Clone, Copy)]
enum BitTable {
    /// 0x01: coils, written by the master.
    Coils,
    /// 0x02: discrete inputs, read-only.
    DiscreteInputs,
}

/// The register table a read addresses.
#[derive(Clone, Copy)]
enum RegisterTable {
    /// 0x03: holding registers, written by the master.
    Holding,
    /// 0x04: input registers, read-only.
    Input,
}

/// 0x14: one handler call per sub-request, the registers of all of them in one buffer.
fn read_file_record<H: Handler + ?Sized>(
    handler: &mut H,
    unit: u8,
    q: &FileRecordReads<'_>,
    out: &mut [u8; MAX_PDU_LEN],
) -> Result<usize, ExceptionCode> {
    // Validated at parse: at most 35 sub-requests whose responses fit in 245 bytes.
    let mut regs = [0u16; MAX_DATA_LEN / 2];
    let mut spans = [(0usize, 0usize); 35];
    let mut at = 0usize;
    for (sub, span) in q.iter().zip(spans.iter_mut()) {
        let len = usize::from(sub.length);
        let end = at.checked_add(len).ok_or(ExceptionCode::IllegalDataValue)?;
        let dst = regs.get_mut(at..end).ok_or(ExceptionCode::IllegalDataValue)?;
        handler.read_file_record(unit, sub.file, sub.record, dst)?;
        *span = (at, end);
        at = end;
    }
    let mut records = [Registers::EMPTY; 35];
    for (slot, &(a, b)) in records.iter_mut().zip(spans.iter()).take(q.len()) {
        *slot = Registers::from_values(regs.get(a..b).unwrap_or_default());
    }
    let subs = FileSubResponses::new(records.get(..q.len()).unwrap_or_default()).map_err(too_big)?;
    emit(&Response::ReadFileRecord(subs), out)
}

fn read_bits(
    q: ReadBits,
    out: &mut [u8; MAX_PDU_LEN],
    table: BitTable,
    read: impl FnOnce(u16, &mut [bool]) -> Result<(), ExceptionCode>,
) -> Result<usize, ExceptionCode> {
    let mut bits = [false; ReadBits::MAX as usize];
    let bits = bits.get_mut(..usize::from(q.quantity())).ok_or(ExceptionCode::IllegalDataValue)?;
    read(q.start(), bits)?;
    let values = BitValues::new(Bits::from_values(bits)).map_err(too_big)?;
    emit(
        &match table {
            BitTable::Coils => Response::ReadCoils(values),
            BitTable::DiscreteInputs => Response::ReadDiscreteInputs(values),
        },
        out,
    )
}

fn read_registers(
    q: ReadRegisters,
    out: &mut [u8; MAX_PDU_LEN],
    table: RegisterTable,
    read: impl FnOnce(u16, &mut [u16]) -> Result<(), ExceptionCode>,
) -> Result<usize, ExceptionCode> {
    let mut regs = [0u16; ReadRegisters::MAX as usize];
    let regs = regs.get_mut(..usize::from(q.quantity())).ok_or(ExceptionCode::IllegalDataValue)?;
    read(q.start(), regs)?;
    let values = RegisterValues::new(Registers::from_values(regs)).map_err(too_big)?;
    emit(
        &match table {
            RegisterTable::Holding => Response::ReadHoldingRegisters(values),
            RegisterTable::Input => Response::ReadInputRegisters(values),
        },
        out,
    )
}

/// 0x2B/0x0E (§6.21): a stream of the objects of one category from `object_id` on (from the
/// first, if the device has no such object), as many as fit, with "more follows"; or one
/// specific object (exception 02 if the device lacks it).
fn read_device_id<H: Handler + ?Sized>(
    handler: &mut H,
    unit: u8,
    q: ReadDeviceId,
    out: &mut [u8; MAX_PDU_LEN],
) -> Result<usize, ExceptionCode> {
    let mut value = [0u8; 255];
    let mut has = |id: u8| handler.device_object(unit, id, &mut value).is_some();
    if !has(0x00) {
        return Err(ExceptionCode::IllegalFunction);
    }
    // Conformity: the highest category the device has objects in, with bit 7 set because
    // individual access (code 04) is always supported.
    let mut reaches = |c: ReadDeviceIdCode| (c.first_object()..=c.last_object()).any(&mut has);
    let category = if reaches(ReadDeviceIdCode::Extended) {
        ReadDeviceIdCode::Extended
    } else if reaches(ReadDeviceIdCode::Regular) {
        ReadDeviceIdCode::Regular
    } else {
        ReadDeviceIdCode::Basic
    };
    let level = conformity::level(category, true);
    let (first, last) = match q.code() {
        ReadDeviceIdCode::Specific => {
            if !has(q.object_id()) {
                return Err(ExceptionCode::IllegalDataAddress);
            }
            (q.object_id(), q.object_id())
        }
        code => {
            let last = code.last_object();
            let first = if q.object_id() <= last && has(q.object_id()) { q.object_id() } else { 0 };
            (first, last)
        }
    };
    let mut objects = [0u8; DeviceIdentification::MAX_OBJECT_BYTES];
    let mut w = Writer::new(&mut objects);
    let mut count = 0u8;
    let mut next = None;
    for id in first..=last {
        let Some(n) = handler.device_object(unit, id, &mut value) else { continue };
        // A handler claiming more than the buffer holds gets what it wrote.
        let value = value.get(..n.min(value.len())).unwrap_or_default();
        let fits = w.position().saturating_add(2).saturating_add(value.len()) <= DeviceIdentification::MAX_OBJECT_BYTES;
        if !fits {
            next = Some(id);
            break;
        }
        let _ =
            w.u8(id).and_then(|()| w.u8(u8::try_from(value.len()).unwrap_or(u8::MAX))).and_then(|()| w.bytes(value));
        count = count.saturating_add(1);
    }
    let used = w.position();
    let objects = DeviceObjects::from_wire(objects.get(..used).unwrap_or_default(), count);
    let reply = DeviceIdentification::new(q.code(), level, next.is_some(), next.unwrap_or(0), objects)
        .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
    emit(&Response::EncapsulatedInterface(MeiResponse::ReadDeviceId(reply)), out)
}
