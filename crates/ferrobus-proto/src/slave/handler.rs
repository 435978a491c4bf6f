//! The one trait through which a slave serves data.

use core::time::Duration;

use crate::codes::ExceptionCode;
use crate::pdu::{Bits, MaskWrite, ReadWriteRegisters, Registers, Request};

/// What the slave does with a request, as decided by [`Handler::admit`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Admission {
    /// Serve it.
    Serve,
    /// Answer with this exception without serving it (an unsupported function, more items
    /// than the device takes in one request, a state that forbids it).
    Refuse(ExceptionCode),
    /// Stay silent, as if the request had never come (a device that does not answer some
    /// broadcasts, a simulated fault).
    Ignore,
}

/// Serves the data of one or more units. Every method has a default: data access answers
/// exception 01 (Illegal Function) until it is implemented, so a handler implements only what
/// its device has.
///
/// The slave engine calls [`Handler::admit`] first, then exactly one data method per request
/// (0x14 calls [`Handler::read_file_record`] once per sub-request). It serves 0x08
/// Diagnostics, 0x0B and 0x0C itself, from its own counters, after `admit`. Output slices are
/// sized to the request, so a handler fills every element or returns an exception.
///
/// `unit` is the address the request was sent to. A broadcast (unit 0) is handed to the
/// handler once for every unit the slave serves, with that unit.
#[allow(unused_variables)]
pub trait Handler {
    /// Decides whether to serve a request for `unit`; `broadcast` if it was sent to all. The
    /// default serves everything but broadcasts of reads, which the spec does not define and
    /// which no device answers anyway.
    fn admit(&mut self, unit: u8, broadcast: bool, request: &Request<'_>) -> Admission {
        if broadcast && !request.function().is_write() { Admission::Ignore } else { Admission::Serve }
    }

    /// How long `unit` waits before it replies, on top of the t3.5 silent interval (the
    /// 3G3RX's C078). `None` takes the engine's [`SlaveConfig::response_wait`](super::SlaveConfig).
    fn response_wait(&self, unit: u8) -> Option<Duration> {
        None
    }

    /// 0x01: fills `out` with the coils from `start`.
    fn read_coils(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x02: fills `out` with the discrete inputs from `start`.
    fn read_discrete_inputs(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x03: fills `out` with the holding registers from `start`.
    fn read_holding_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x04: fills `out` with the input registers from `start`.
    fn read_input_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x05: sets one coil.
    fn write_single_coil(&mut self, unit: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x06: sets one holding register.
    fn write_single_register(&mut self, unit: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x0F: sets coils from `start`.
    fn write_multiple_coils(&mut self, unit: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x10: sets holding registers from `start`.
    fn write_multiple_registers(&mut self, unit: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x16: by default, reads the register, applies the masks and writes it back through the
    /// two methods above.
    fn mask_write_register(&mut self, unit: u8, mask: MaskWrite) -> Result<(), ExceptionCode> {
        let mut current = [0u16];
        self.read_holding_registers(unit, mask.address, &mut current)?;
        let [value] = current;
        self.write_single_register(unit, mask.address, mask.apply(value))
    }

    /// 0x17: `out` is sized to `request.read()`. By default, writes through
    /// [`Handler::write_multiple_registers`], then reads through
    /// [`Handler::read_holding_registers`] — the write comes first (§6.17).
    fn read_write_multiple_registers(
        &mut self,
        unit: u8,
        request: &ReadWriteRegisters<'_>,
        out: &mut [u16],
    ) -> Result<(), ExceptionCode> {
        self.write_multiple_registers(unit, request.write_start(), request.values())?;
        self.read_holding_registers(unit, request.read().start(), out)
    }

    /// 0x07: the eight exception status bits.
    fn read_exception_status(&mut self, unit: u8) -> Result<u8, ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x11: writes the server id, run indicator and any additional data into `out` (at most
    /// 251 bytes) and returns the length.
    fn report_server_id(&mut self, unit: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x14, once per sub-request: fills `out` from `record` of `file`.
    fn read_file_record(&mut self, unit: u8, file: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x15, once per sub-request: writes `values` from `record` of `file`.
    fn write_file_record(
        &mut self,
        unit: u8,
        file: u16,
        record: u16,
        values: Registers<'_>,
    ) -> Result<(), ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x18: writes the queue behind the FIFO pointer `address` into `out`, oldest first, and
    /// returns how many values there are (at most 31).
    fn read_fifo_queue(&mut self, unit: u8, address: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// 0x2B/0x0E: copies the value of device identification object `id` into `out` (255
    /// bytes: longer values are cut) and returns its length, or `None` if the device does not
    /// have it. Objects 0x00–0x02 (vendor, product code, revision) are mandatory: a device
    /// without object 0x00 answers 0x2B/0x0E with exception 01.
    fn device_object(&mut self, unit: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        None
    }

    /// 0x2B with an MEI type other than 0x0E: writes the response data after the MEI type
    /// into `out` and returns its length.
    fn encapsulated(&mut self, unit: u8, mei_type: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }

    /// A function code the spec does not define: writes the response data after the function
    /// code into `out` (at most 252 bytes) and returns its length.
    fn custom(&mut self, unit: u8, function: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        Err(ExceptionCode::IllegalFunction)
    }
}
