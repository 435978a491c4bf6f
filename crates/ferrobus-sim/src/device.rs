//! One simulated device: a profile's rules over its memory and its model.
//!
//! Before a request is served, [`Device::admit`] applies the profile: function codes the device
//! lacks get exception 01, more items than it takes per request exception 03, broadcasts it
//! does not execute are ignored. The data methods then apply the map: unmapped addresses get
//! 02, writes to read-only items, values out of range and writes the model forbids in its
//! present state get the profile's vendor codes (0x22, 0x21 on the 3G3RX).

use std::time::Duration;

use ferrobus_proto::pdu::{Bits, MeiRequest, Registers, Request};
use ferrobus_proto::slave::Admission;
use ferrobus_proto::{ExceptionCode, FunctionCode};

use crate::memory::{Denial, Memory, Table};
use crate::model::{self, Model};
use crate::profile::Profile;

/// A simulated device.
pub struct Device {
    profile: Profile,
    memory: Memory,
    model: Option<Box<dyn Model>>,
    files: Vec<Vec<u16>>,
    /// Device time: the model is advanced to it before each request.
    now: Duration,
}

impl Device {
    /// A device at its start values.
    pub fn new(profile: Profile) -> Self {
        let mut memory = Memory::new(&profile);
        let model = profile.model.as_ref().map(|m| model::build(m, &mut memory));
        let files =
            profile.files.map(|f| vec![vec![0u16; usize::from(f.records)]; usize::from(f.count)]).unwrap_or_default();
        Device { profile, memory, model, files, now: Duration::ZERO }
    }

    /// The profile.
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// The memory (for monitors, tests and the demo).
    pub fn memory(&self) -> &Memory {
        &self.memory
    }

    /// The memory, to change values from outside the bus.
    pub fn memory_mut(&mut self) -> &mut Memory {
        &mut self.memory
    }

    /// Advances the model to device time `now` (time never goes backwards).
    pub fn advance_to(&mut self, now: Duration) {
        let dt = now.saturating_sub(self.now);
        self.now = self.now.max(now);
        if let Some(model) = self.model.as_mut() {
            model.advance(&mut self.memory, dt);
        }
    }

    /// Trips the drive (fault injection).
    pub fn trip(&mut self, code: u16) {
        if let Some(model) = self.model.as_mut() {
            model.trip(&mut self.memory, code);
        }
    }

    /// A one-line state summary.
    pub fn summary(&self) -> String {
        match &self.model {
            Some(model) => model.summary(&self.memory),
            None => "no model".to_string(),
        }
    }

    /// The wait before replying, on top of t3.5.
    pub fn response_wait(&self) -> Duration {
        Duration::from_millis(u64::from(self.profile.comm.response_wait_ms))
    }

    /// The exception code the profile answers a denial with.
    fn exception(&self, denial: Denial) -> ExceptionCode {
        let e = &self.profile.exceptions;
        ExceptionCode::from_u8(match denial {
            Denial::Unmapped => 0x02,
            Denial::ReadOnly => e.read_only,
            Denial::OutOfRange => e.out_of_range,
            Denial::NotAllowed => e.not_allowed,
        })
    }

    fn supports(&self, function: FunctionCode) -> bool {
        match &self.profile.comm.functions {
            Some(list) => list.contains(&function.value()),
            None => function.is_public(),
        }
    }

    /// Applies the profile's rules before a request is served.
    pub fn admit(&self, broadcast: bool, request: &Request<'_>) -> Admission {
        let function = request.function();
        let comm = &self.profile.comm;
        if broadcast {
            let allowed = match request {
                Request::Diagnostics(_) => comm.broadcast_diagnostics,
                r if !r.function().is_write() => comm.broadcast_reads,
                _ => true,
            };
            if !allowed || !self.supports(function) {
                return Admission::Ignore;
            }
        }
        if !self.supports(function) {
            return Admission::Refuse(ExceptionCode::IllegalFunction);
        }
        let identification =
            matches!(request, Request::ReportServerId(_) | Request::EncapsulatedInterface(MeiRequest::ReadDeviceId(_)));
        if identification && !self.profile.device.identification {
            return Admission::Refuse(ExceptionCode::IllegalFunction);
        }
        if let Request::Diagnostics(d) = request {
            let sub = d.sub_function().value();
            if comm.diagnostics.as_ref().is_some_and(|list| !list.contains(&sub)) {
                return Admission::Refuse(ExceptionCode::IllegalFunction);
            }
        }
        if self.over_limit(request) { Admission::Refuse(ExceptionCode::IllegalDataValue) } else { Admission::Serve }
    }

    /// Whether the request carries more items than the device takes in one request.
    fn over_limit(&self, request: &Request<'_>) -> bool {
        let limits = &self.profile.limits;
        let over = |n: usize, limit: Option<u16>| limit.is_some_and(|l| n > usize::from(l));
        match request {
            Request::ReadCoils(q) | Request::ReadDiscreteInputs(q) => {
                over(usize::from(q.quantity()), limits.read_coils)
            }
            Request::WriteMultipleCoils(q) => over(q.values().len(), limits.write_coils),
            Request::ReadHoldingRegisters(q) | Request::ReadInputRegisters(q) => {
                over(usize::from(q.quantity()), limits.read_registers)
            }
            Request::WriteMultipleRegisters(q) => over(q.values().len(), limits.write_registers),
            Request::ReadWriteMultipleRegisters(q) => {
                over(usize::from(q.read().quantity()), limits.read_registers)
                    || over(q.values().len(), limits.write_registers)
            }
            _ => false,
        }
    }

    /// 0x01 / 0x02.
    pub fn read_bits(&self, table: Table, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.memory.read_bits(table, start, out).map_err(|d| self.exception(d))
    }

    /// 0x03 / 0x04.
    pub fn read_registers(&self, table: Table, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.memory.read_registers(table, start, out).map_err(|d| self.exception(d))
    }

    /// 0x05 / 0x0F.
    pub fn write_coils(&mut self, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        self.memory.check_write_bits(start, values.len()).map_err(|d| self.exception(d))?;
        if let Some(model) = &self.model {
            for i in 0..values.len() {
                let address = u16::try_from(usize::from(start) + i).unwrap_or(u16::MAX);
                if let Some(item) = self.memory.item_at(Table::Coils, address) {
                    model
                        .check_write(item, i64::from(values.get(i).unwrap_or_default()))
                        .map_err(|d| self.exception(d))?;
                }
            }
        }
        self.memory.write_bits(start, values.iter());
        self.settle();
        Ok(())
    }

    /// 0x06 / 0x10 and the write of 0x16, 0x17.
    pub fn write_registers(&mut self, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        let words: Vec<u16> = values.iter().collect();
        let touched = self.memory.check_write_registers(start, &words).map_err(|d| self.exception(d))?;
        if let Some(model) = &self.model {
            for (index, value) in &touched {
                if let Some(item) = self.memory.item_by_index(*index) {
                    model.check_write(item, *value).map_err(|d| self.exception(d))?;
                }
            }
        }
        self.memory.write_registers(start, &words);
        self.settle();
        Ok(())
    }

    /// Lets the model react to a write at once (a trip coil, a momentary reset).
    fn settle(&mut self) {
        if let Some(model) = self.model.as_mut() {
            model.advance(&mut self.memory, Duration::ZERO);
        }
    }

    /// 0x11: the server id, the run indicator (0xFF ON) and the product code.
    pub fn server_id(&self, out: &mut [u8]) -> usize {
        let device = &self.profile.device;
        let id = device.server_id.as_deref().unwrap_or(&device.product_code).as_bytes();
        let mut bytes = id.to_vec();
        bytes.push(0xFF);
        bytes.extend_from_slice(device.revision.as_bytes());
        let n = bytes.len().min(out.len());
        out[..n].copy_from_slice(&bytes[..n]);
        n
    }

    /// 0x2B/0x0E: object `id`.
    pub fn device_object(&self, id: u8) -> Option<&[u8]> {
        let d = &self.profile.device;
        let text = match id {
            0x00 => Some(d.vendor.as_str()),
            0x01 => Some(d.product_code.as_str()),
            0x02 => Some(d.revision.as_str()),
            0x03 => d.vendor_url.as_deref(),
            0x04 => d.product_name.as_deref(),
            0x05 => d.model_name.as_deref(),
            0x06 => d.user_application_name.as_deref(),
            _ => None,
        };
        text.map(str::as_bytes)
    }

    /// 0x14, one sub-request.
    pub fn read_file(&self, file: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        let records = self.file(file)?;
        let start = usize::from(record);
        let src = records.get(start..start + out.len()).ok_or(ExceptionCode::IllegalDataAddress)?;
        out.copy_from_slice(src);
        Ok(())
    }

    /// 0x15, one sub-request.
    pub fn write_file(&mut self, file: u16, record: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        self.file(file)?;
        let records = self.files.get_mut(usize::from(file) - 1).ok_or(ExceptionCode::IllegalDataAddress)?;
        let start = usize::from(record);
        let dst = records.get_mut(start..start + values.len()).ok_or(ExceptionCode::IllegalDataAddress)?;
        values.copy_to(dst);
        Ok(())
    }

    fn file(&self, file: u16) -> Result<&Vec<u16>, ExceptionCode> {
        // Files are numbered from 1 (§6.14).
        usize::from(file).checked_sub(1).and_then(|i| self.files.get(i)).ok_or(ExceptionCode::IllegalDataAddress)
    }

    /// 0x18: the count at the pointer address, the values after it.
    pub fn read_fifo(&self, address: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        let fifo = self.profile.fifo.ok_or(ExceptionCode::IllegalFunction)?;
        if address != fifo.address {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        let count = usize::from(self.memory.peek(Table::Holding, address));
        if count > out.len() {
            return Err(ExceptionCode::IllegalDataValue);
        }
        for (i, slot) in out.iter_mut().enumerate().take(count) {
            *slot = self
                .memory
                .peek(Table::Holding, address.wrapping_add(1).wrapping_add(u16::try_from(i).unwrap_or(u16::MAX)));
        }
        Ok(count)
    }
}
