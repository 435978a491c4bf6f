//! The authorization step: a handler that checks each request against the client's role
//! before the handler behind it sees it (MB-TCP-Security v36 §6, R-31).

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use ferrobus_proto::ExceptionCode;
use ferrobus_proto::pdu::{Bits, MaskWrite, ReadWriteRegisters, Registers, Request};
use ferrobus_proto::slave::{Admission, Handler};

use super::{Policy, Role};

/// One client's authorization: its role, the policy, and where denials are logged and
/// counted.
#[derive(Clone, Debug)]
pub struct RoleCheck {
    role: Role,
    policy: Arc<Policy>,
    peer: Option<SocketAddr>,
    denied: Arc<AtomicU64>,
}

impl RoleCheck {
    /// `policy`'s check for `role`.
    pub fn new(role: Role, policy: Arc<Policy>) -> Self {
        RoleCheck { role, policy, peer: None, denied: Arc::default() }
    }

    /// Names the client in the log lines of denied requests.
    #[must_use]
    pub fn with_peer(mut self, peer: SocketAddr) -> Self {
        self.peer = Some(peer);
        self
    }

    /// Counts denied requests in `counter` (shared with whoever reports it).
    #[must_use]
    pub fn counting(mut self, counter: Arc<AtomicU64>) -> Self {
        self.denied = counter;
        self
    }

    /// The client's role.
    pub fn role(&self) -> &Role {
        &self.role
    }

    /// Requests denied so far (by this check and any sharing its counter).
    pub fn denied(&self) -> u64 {
        self.denied.load(Ordering::Relaxed)
    }

    /// Whether the client may send `request` to `unit`; a denial is counted and logged.
    pub fn allows(&self, unit: u8, request: &Request<'_>) -> bool {
        let Err(why) = self.policy.check(&self.role, unit, request) else { return true };
        self.denied.fetch_add(1, Ordering::Relaxed);
        let peer = self.peer.map(|p| p.to_string()).unwrap_or_default();
        tracing::warn!(%peer, "denied {} to unit {unit} for {}: {why}; answered exception 01", request.function(), self.role);
        false
    }
}

/// The gateway's authorization step for a TLS client: the PDU parsed, then checked; a
/// denied request gets exception 01, one that does not parse the exception a server would
/// answer it with (it could not be checked, so it is not forwarded).
impl crate::gateway::Authorize for RoleCheck {
    fn authorize(&mut self, unit: u8, pdu: &[u8]) -> Result<(), ExceptionCode> {
        let request = Request::parse(pdu).map_err(ferrobus_proto::PduError::exception_code)?;
        if self.allows(unit, &request) { Ok(()) } else { Err(ExceptionCode::IllegalFunction) }
    }
}

/// `inner`, for one client: every request is checked by a [`RoleCheck`] first
/// ([`Handler::admit`] runs before any data method, for every request, broadcasts too); a
/// denied one is answered with exception 01 Illegal Function and logged.
pub struct Authorized<H> {
    inner: H,
    check: RoleCheck,
}

impl<H> Authorized<H> {
    /// `inner` behind `check`.
    pub fn new(inner: H, check: RoleCheck) -> Self {
        Authorized { inner, check }
    }

    /// The check.
    pub fn check(&self) -> &RoleCheck {
        &self.check
    }
}

impl<H: Handler> Handler for Authorized<H> {
    fn admit(&mut self, unit: u8, broadcast: bool, request: &Request<'_>) -> Admission {
        if !self.check.allows(unit, request) {
            // A broadcast gets no reply: it is dropped.
            return if broadcast { Admission::Ignore } else { Admission::Refuse(ExceptionCode::IllegalFunction) };
        }
        self.inner.admit(unit, broadcast, request)
    }
    fn response_wait(&self, unit: u8) -> Option<Duration> {
        self.inner.response_wait(unit)
    }
    fn read_coils(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.inner.read_coils(unit, start, out)
    }
    fn read_discrete_inputs(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.inner.read_discrete_inputs(unit, start, out)
    }
    fn read_holding_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.inner.read_holding_registers(unit, start, out)
    }
    fn read_input_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.inner.read_input_registers(unit, start, out)
    }
    fn write_single_coil(&mut self, unit: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        self.inner.write_single_coil(unit, address, value)
    }
    fn write_single_register(&mut self, unit: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        self.inner.write_single_register(unit, address, value)
    }
    fn write_multiple_coils(&mut self, unit: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        self.inner.write_multiple_coils(unit, start, values)
    }
    fn write_multiple_registers(&mut self, unit: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        self.inner.write_multiple_registers(unit, start, values)
    }
    fn mask_write_register(&mut self, unit: u8, mask: MaskWrite) -> Result<(), ExceptionCode> {
        self.inner.mask_write_register(unit, mask)
    }
    fn read_write_multiple_registers(
        &mut self,
        unit: u8,
        request: &ReadWriteRegisters<'_>,
        out: &mut [u16],
    ) -> Result<(), ExceptionCode> {
        self.inner.read_write_multiple_registers(unit, request, out)
    }
    fn read_exception_status(&mut self, unit: u8) -> Result<u8, ExceptionCode> {
        self.inner.read_exception_status(unit)
    }
    fn report_server_id(&mut self, unit: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.inner.report_server_id(unit, out)
    }
    fn read_file_record(&mut self, unit: u8, file: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.inner.read_file_record(unit, file, record, out)
    }
    fn write_file_record(
        &mut self,
        unit: u8,
        file: u16,
        record: u16,
        values: Registers<'_>,
    ) -> Result<(), ExceptionCode> {
        self.inner.write_file_record(unit, file, record, values)
    }
    fn read_fifo_queue(&mut self, unit: u8, address: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        self.inner.read_fifo_queue(unit, address, out)
    }
    fn device_object(&mut self, unit: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        self.inner.device_object(unit, id, out)
    }
    fn encapsulated(&mut self, unit: u8, mei_type: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.inner.encapsulated(unit, mei_type, data, out)
    }
    fn custom(&mut self, unit: u8, function: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.inner.custom(unit, function, data, out)
    }
}
