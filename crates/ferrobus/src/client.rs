//! The client: a cheap, cloneable handle to one bus.
//!
//! Every clone talks to the same driver task, which puts one request on the bus at a time, in
//! the order they come: many tasks can poll many devices through one port. (On Modbus/TCP,
//! [`ClientConfig::in_flight`] lets several be outstanding on the connection at once, matched
//! by transaction id.) Each request has a
//! timeout and a number of retries (from the client's defaults, or [`Client::with_timeout`]
//! and [`Client::with_retries`]); unit 0 on a serial line is a broadcast and returns as soon
//! as the turnaround delay has passed.
//!
//! ```no_run
//! # async fn demo() -> Result<(), ferrobus::Error> {
//! use ferrobus::{Client, ClientConfig, SerialConfig, Transport};
//! use ferrobus_proto::frame::LineConfig;
//!
//! let line = LineConfig::new(9600).expect("a baud rate");
//! let client = Client::connect(Transport::rtu(SerialConfig::new("/dev/ttyUSB0", line)), ClientConfig::default()).await?;
//! let status = client.read_holding_registers(1, 0x0002, 2).await?;
//! client.write_single_coil(1, 0x0000, true).await?;
//! # Ok(()) }
//! ```

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use ferrobus_proto::codes::{DiagnosticCode, ReadDeviceIdCode};
use ferrobus_proto::master::pipeline::MAX_IN_FLIGHT;
use ferrobus_proto::master::{Master, MasterConfig};
use ferrobus_proto::pdu::{
    Bits, CommEventCounter, Custom, Diagnostic, FileRecordReads, FileRecordRef, FileRecordWrite, FileRecordWrites,
    MAX_PDU_LEN, MaskWrite, MeiRequest, MeiResponse, NoData, ReadBits, ReadDeviceId, ReadFifo, ReadRegisters,
    ReadWriteRegisters, Registers, Request, Response, WriteCoil, WriteCoils, WriteRegister, WriteRegisters,
};
use ferrobus_proto::{FunctionCode, PduError};
use tokio::sync::{mpsc, oneshot, watch};

pub use crate::driver::{ClientStats, STALLED_AFTER_TIMEOUTS};
use crate::driver::{Command, Driver, Pipelined, Reply, parse_reply};
use crate::error::Error;
use crate::port::{Framing, Transport};
use crate::pump::{Codec, Role};

pub use crate::config::{Backoff, ClientConfig, RequestOptions};

/// A device identification, read object by object until the device says no more follow.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct DeviceInfo {
    /// The device's conformity level (0x01–0x03, 0x81–0x83).
    pub conformity: u8,
    /// The objects, by id.
    pub objects: Vec<(u8, Vec<u8>)>,
}

/// A comm event log (0x0C).
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct EventLog {
    /// 0xFFFF while the device is busy.
    pub status: u16,
    /// The comm event counter.
    pub event_count: u16,
    /// The bus message count.
    pub message_count: u16,
    /// The events, most recent first.
    pub events: Vec<u8>,
}

/// A handle to one bus. Clone it freely.
#[derive(Clone, Debug)]
pub struct Client {
    commands: mpsc::Sender<Command>,
    options: RequestOptions,
    framing: Framing,
    /// Requests the connection carries at once: 1 but on a pipelined Modbus/TCP connection.
    in_flight: usize,
    stats: Arc<Mutex<ClientStats>>,
    hold: watch::Receiver<Option<tokio::time::Instant>>,
}

/// When a client's driver lets its port go ([`Client::release`]): at once, unless a reply is
/// still on its way on a line whose replies carry no transaction id (RTU, ASCII).
///
/// A command interrupted while its request is on the line does not take its reply; but the
/// reply still comes, and over RTU or ASCII a program that opened the port next would take
/// it for the reply to its own request of the same shape. The driver therefore keeps the
/// port, reading, until that reply has come and been dropped or its late window has passed,
/// also once every client has gone; an application that is about to exit waits for it here.
#[derive(Clone, Debug)]
pub struct Release {
    hold: watch::Receiver<Option<tokio::time::Instant>>,
}

impl Release {
    /// How much longer the port may be held for a reply in flight or owed, at most; `None`
    /// if no reply is coming.
    pub fn pending(&self) -> Option<Duration> {
        let until = (*self.hold.borrow())?;
        let left = until.saturating_duration_since(tokio::time::Instant::now());
        (!left.is_zero()).then_some(left)
    }

    /// Waits until no reply is coming any more: it has come, its window has passed, or the
    /// driver has ended.
    pub async fn settled(mut self) {
        loop {
            let Some(until) = *self.hold.borrow_and_update() else { return };
            tokio::select! {
                () = tokio::time::sleep_until(until) => return,
                changed = self.hold.changed() => if changed.is_err() { return },
            }
        }
    }

    /// Waits until the driver has ended, its port let go: every clone of its client dropped
    /// and no reply owed any more. What a program waits on before it opens the same port
    /// again; [`Release::settled`] does not wait for a driver still in use.
    pub async fn ended(mut self) {
        while self.hold.changed().await.is_ok() {}
    }
}

impl Client {
    /// Opens the transport (so that a wrong port or an unreachable host fails here, with a
    /// clear error) and starts the driver on the current tokio runtime.
    pub async fn connect(transport: Transport, config: ClientConfig) -> Result<Client, Error> {
        let port = transport.open(config.connect_timeout).await?;
        Ok(Self::start(transport, config, Some(port)))
    }

    /// Starts the driver without opening the transport: it is opened on the first request.
    pub fn spawn(transport: Transport, config: ClientConfig) -> Client {
        Self::start(transport, config, None)
    }

    fn start(transport: Transport, config: ClientConfig, port: Option<crate::port::BoxPort>) -> Client {
        let (tx, rx) = mpsc::channel(config.queue.max(1));
        let options = RequestOptions { timeout: config.timeout, retries: config.retries };
        let framing = transport.framing();
        let in_flight = if framing == Framing::Mbap { config.in_flight.clamp(1, MAX_IN_FLIGHT) } else { 1 };
        let watched = if in_flight > 1 {
            let driver = Pipelined::new(transport, config, port);
            let watched = (driver.stats(), driver.hold());
            tokio::spawn(driver.run(rx));
            watched
        } else {
            let master = MasterConfig {
                response_timeout: config.timeout,
                turnaround_delay: config.turnaround_delay,
                echo_suppression: config.echo_suppression,
                ..MasterConfig::default()
            };
            let codec = Codec::for_transport(&transport, Role::Client);
            let driver = Driver::new(Master::new(codec, master), transport, config, port);
            let watched = (driver.stats(), driver.hold());
            tokio::spawn(driver.run(rx));
            watched
        };
        let (stats, hold) = watched;
        Client { commands: tx, options, framing, in_flight, stats, hold }
    }

    /// When the driver lets its port go: wait on it before the program exits, so that a reply
    /// still on its way reaches nobody ([`Release`]). It does not keep the driver running.
    pub fn release(&self) -> Release {
        Release { hold: self.hold.clone() }
    }

    /// The same client with another timeout for its requests.
    #[must_use]
    pub fn with_timeout(&self, timeout: Duration) -> Client {
        Client { options: RequestOptions { timeout, ..self.options }, ..self.clone() }
    }

    /// The same client with another number of retries.
    #[must_use]
    pub fn with_retries(&self, retries: u32) -> Client {
        Client { options: RequestOptions { retries, ..self.options }, ..self.clone() }
    }

    /// The timeout and retries of this handle's requests.
    pub fn options(&self) -> RequestOptions {
        self.options
    }

    /// How many requests the connection carries at once: [`ClientConfig::in_flight`] on
    /// Modbus/TCP (at most [`MAX_IN_FLIGHT`]), 1 on every other framing. A caller with that
    /// many requests under way keeps the connection full; more only wait in the queue.
    pub fn in_flight(&self) -> usize {
        self.in_flight
    }

    /// What the driver has seen on the bus so far, as of the end of the last request.
    pub fn stats(&self) -> ClientStats {
        *self.stats.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Whether the bus has a broadcast (unit 0 on the serial framings, RTU over TCP
    /// included); Modbus/TCP has none.
    pub fn has_broadcast(&self) -> bool {
        self.framing != Framing::Mbap
    }

    /// Whether a request to `unit` is a broadcast here: unit 0 on a serial framing (RTU,
    /// ASCII, RTU over TCP), which no device answers.
    pub fn is_broadcast(&self, unit: u8) -> bool {
        ferrobus_proto::codes::unit::is_broadcast(unit, self.framing != Framing::Mbap)
    }

    async fn send(&self, unit: u8, pdu: Vec<u8>, raw: bool) -> Result<Reply, Error> {
        let (reply, rx) = oneshot::channel();
        let command = Command { unit, pdu, raw, options: self.options, reply };
        self.commands.send(command).await.map_err(|_| Error::Closed)?;
        rx.await.map_err(|_| Error::Closed)?
    }

    /// Sends `request` to `unit` and returns the reply PDU (function code first), checked
    /// against the request; `None` for a request that gets no reply (a broadcast).
    pub async fn request(&self, unit: u8, request: &Request<'_>) -> Result<Option<Vec<u8>>, Error> {
        let mut pdu = vec![0u8; request.encoded_len()];
        let n =
            request.emit(&mut pdu).map_err(|_| Error::InvalidRequest(PduError::TooLong { len: MAX_PDU_LEN + 1 }))?;
        pdu.truncate(n);
        match self.send(unit, pdu, false).await? {
            Reply::Pdu(pdu) => Ok(Some(pdu)),
            Reply::Sent => Ok(None),
        }
    }

    /// Sends any PDU, valid or not, and returns the reply PDU unchecked: for probing devices.
    /// An exception reply is still [`Error::Exception`].
    pub async fn raw(&self, unit: u8, pdu: &[u8]) -> Result<Option<Vec<u8>>, Error> {
        if pdu.is_empty() || pdu.len() > MAX_PDU_LEN {
            return Err(Error::InvalidRequest(PduError::TooLong { len: pdu.len() }));
        }
        match self.send(unit, pdu.to_vec(), true).await? {
            Reply::Pdu(pdu) => Ok(Some(pdu)),
            Reply::Sent => Ok(None),
        }
    }

    /// Sends a request that must be answered and hands its parsed reply to `read`.
    async fn query<T>(
        &self,
        unit: u8,
        request: &Request<'_>,
        read: impl FnOnce(Response<'_>) -> Option<T>,
    ) -> Result<T, Error> {
        let function = request.function();
        if self.is_broadcast(unit) {
            return Err(Error::BroadcastRead { function });
        }
        let pdu = self.request(unit, request).await?.ok_or(Error::NoReply { unit, function })?;
        let response = parse_reply(unit, &pdu)?;
        let function = response.function();
        read(response).ok_or(Error::BadReply {
            unit,
            error: ferrobus_proto::master::MasterError::Mismatch {
                field: "function code",
                expected: u16::from(request.function().value()),
                received: u16::from(function.value()),
            },
        })
    }

    /// Sends a write; a broadcast returns once the turnaround has passed.
    async fn execute(&self, unit: u8, request: &Request<'_>) -> Result<(), Error> {
        self.request(unit, request).await.map(|_| ())
    }

    /// 0x01: `count` coils from `start`.
    pub async fn read_coils(&self, unit: u8, start: u16, count: u16) -> Result<Vec<bool>, Error> {
        let request = Request::ReadCoils(ReadBits::new(start, count)?);
        self.query(unit, &request, |r| match r {
            Response::ReadCoils(v) => Some(v.values().iter().take(usize::from(count)).collect()),
            _ => None,
        })
        .await
    }

    /// 0x02: `count` discrete inputs from `start`.
    pub async fn read_discrete_inputs(&self, unit: u8, start: u16, count: u16) -> Result<Vec<bool>, Error> {
        let request = Request::ReadDiscreteInputs(ReadBits::new(start, count)?);
        self.query(unit, &request, |r| match r {
            Response::ReadDiscreteInputs(v) => Some(v.values().iter().take(usize::from(count)).collect()),
            _ => None,
        })
        .await
    }

    /// 0x03: `count` holding registers from `start`.
    pub async fn read_holding_registers(&self, unit: u8, start: u16, count: u16) -> Result<Vec<u16>, Error> {
        let request = Request::ReadHoldingRegisters(ReadRegisters::new(start, count)?);
        self.query(unit, &request, |r| match r {
            Response::ReadHoldingRegisters(v) => Some(v.values().iter().collect()),
            _ => None,
        })
        .await
    }

    /// 0x04: `count` input registers from `start`.
    pub async fn read_input_registers(&self, unit: u8, start: u16, count: u16) -> Result<Vec<u16>, Error> {
        let request = Request::ReadInputRegisters(ReadRegisters::new(start, count)?);
        self.query(unit, &request, |r| match r {
            Response::ReadInputRegisters(v) => Some(v.values().iter().collect()),
            _ => None,
        })
        .await
    }

    /// 0x05: sets one coil.
    pub async fn write_single_coil(&self, unit: u8, address: u16, value: bool) -> Result<(), Error> {
        self.execute(unit, &Request::WriteSingleCoil(WriteCoil { address, value })).await
    }

    /// 0x06: sets one register.
    pub async fn write_single_register(&self, unit: u8, address: u16, value: u16) -> Result<(), Error> {
        self.execute(unit, &Request::WriteSingleRegister(WriteRegister { address, value })).await
    }

    /// 0x0F: sets coils from `start` (1–1968).
    pub async fn write_multiple_coils(&self, unit: u8, start: u16, values: &[bool]) -> Result<(), Error> {
        let request = Request::WriteMultipleCoils(WriteCoils::new(start, Bits::from_values(values))?);
        self.execute(unit, &request).await
    }

    /// 0x10: sets registers from `start` (1–123).
    pub async fn write_multiple_registers(&self, unit: u8, start: u16, values: &[u16]) -> Result<(), Error> {
        let request = Request::WriteMultipleRegisters(WriteRegisters::new(start, Registers::from_values(values))?);
        self.execute(unit, &request).await
    }

    /// 0x16: `register = (register AND and_mask) OR (or_mask AND NOT and_mask)`.
    pub async fn mask_write_register(&self, unit: u8, address: u16, and_mask: u16, or_mask: u16) -> Result<(), Error> {
        self.execute(unit, &Request::MaskWriteRegister(MaskWrite { address, and_mask, or_mask })).await
    }

    /// 0x17: writes `values` from `write_start`, then reads `read_count` from `read_start`.
    pub async fn read_write_multiple_registers(
        &self,
        unit: u8,
        read_start: u16,
        read_count: u16,
        write_start: u16,
        values: &[u16],
    ) -> Result<Vec<u16>, Error> {
        let request = Request::ReadWriteMultipleRegisters(ReadWriteRegisters::new(
            read_start,
            read_count,
            write_start,
            Registers::from_values(values),
        )?);
        self.query(unit, &request, |r| match r {
            Response::ReadWriteMultipleRegisters(v) => Some(v.values().iter().collect()),
            _ => None,
        })
        .await
    }

    /// 0x07: the eight exception status bits.
    pub async fn read_exception_status(&self, unit: u8) -> Result<u8, Error> {
        self.query(unit, &Request::ReadExceptionStatus(NoData), |r| match r {
            Response::ReadExceptionStatus(s) => Some(s.status),
            _ => None,
        })
        .await
    }

    /// 0x08: a diagnostics sub-function with its data; returns the data of the reply.
    /// 0x04 (Force Listen Only) gets no reply and returns empty data.
    pub async fn diagnostics(&self, unit: u8, sub: DiagnosticCode, data: &[u8]) -> Result<Vec<u8>, Error> {
        let request = Request::Diagnostics(Diagnostic::with_data(sub, data)?);
        let Some(pdu) = self.request(unit, &request).await? else { return Ok(Vec::new()) };
        match parse_reply(unit, &pdu)? {
            Response::Diagnostics(d) => Ok(d.data().to_vec()),
            other => Err(Error::BadReply {
                unit,
                error: ferrobus_proto::master::MasterError::Mismatch {
                    field: "function code",
                    expected: 0x08,
                    received: u16::from(other.function().value()),
                },
            }),
        }
    }

    /// 0x08 with a sub-function that returns a counter (0x0B–0x12), or any that takes a word.
    pub async fn diagnostic_word(&self, unit: u8, sub: DiagnosticCode, word: u16) -> Result<u16, Error> {
        let data = self.diagnostics(unit, sub, &word.to_be_bytes()).await?;
        match *data {
            [hi, lo] => Ok(u16::from_be_bytes([hi, lo])),
            _ => Err(Error::BadReply {
                unit,
                error: ferrobus_proto::master::MasterError::Mismatch {
                    field: "diagnostic data (bytes)",
                    expected: 2,
                    received: u16::try_from(data.len()).unwrap_or(u16::MAX),
                },
            }),
        }
    }

    /// 0x0B: the comm event counter and status.
    pub async fn get_comm_event_counter(&self, unit: u8) -> Result<CommEventCounter, Error> {
        self.query(unit, &Request::GetCommEventCounter(NoData), |r| match r {
            Response::GetCommEventCounter(c) => Some(c),
            _ => None,
        })
        .await
    }

    /// 0x0C: the comm event log.
    pub async fn get_comm_event_log(&self, unit: u8) -> Result<EventLog, Error> {
        self.query(unit, &Request::GetCommEventLog(NoData), |r| match r {
            Response::GetCommEventLog(l) => Some(EventLog {
                status: l.status(),
                event_count: l.event_count(),
                message_count: l.message_count(),
                events: l.events().to_vec(),
            }),
            _ => None,
        })
        .await
    }

    /// 0x11: the server id, run indicator and additional data, as the device sends them.
    pub async fn report_server_id(&self, unit: u8) -> Result<Vec<u8>, Error> {
        self.query(unit, &Request::ReportServerId(NoData), |r| match r {
            Response::ReportServerId(id) => Some(id.data().to_vec()),
            _ => None,
        })
        .await
    }

    /// 0x14: reads each of `refs`; one register list per sub-request.
    pub async fn read_file_record(&self, unit: u8, refs: &[FileRecordRef]) -> Result<Vec<Vec<u16>>, Error> {
        let request = Request::ReadFileRecord(FileRecordReads::new(refs)?);
        self.query(unit, &request, |r| match r {
            Response::ReadFileRecord(subs) => Some(subs.iter().map(|regs| regs.iter().collect()).collect()),
            _ => None,
        })
        .await
    }

    /// 0x15: writes `values` from `record` of `file`.
    pub async fn write_file_record(&self, unit: u8, file: u16, record: u16, values: &[u16]) -> Result<(), Error> {
        let writes = [FileRecordWrite { file, record, data: Registers::from_values(values) }];
        self.execute(unit, &Request::WriteFileRecord(FileRecordWrites::new(&writes)?)).await
    }

    /// 0x18: the FIFO queue behind the pointer register `address`.
    pub async fn read_fifo_queue(&self, unit: u8, address: u16) -> Result<Vec<u16>, Error> {
        self.query(unit, &Request::ReadFifoQueue(ReadFifo { address }), |r| match r {
            Response::ReadFifoQueue(f) => Some(f.values().iter().collect()),
            _ => None,
        })
        .await
    }

    /// 0x2B/0x0E: every object of the category `code` (basic, regular, extended), following
    /// "more follows" across as many transactions as the device needs; or, with
    /// [`ReadDeviceIdCode::Specific`], the one object `object_id`.
    pub async fn read_device_identification(
        &self,
        unit: u8,
        code: ReadDeviceIdCode,
        object_id: u8,
    ) -> Result<DeviceInfo, Error> {
        let mut info = DeviceInfo { conformity: 0, objects: Vec::new() };
        let mut next = object_id;
        // At most one transaction per object id: a device that keeps saying "more follows"
        // without moving on cannot hold us forever.
        for _ in 0..=u8::MAX {
            let request = Request::EncapsulatedInterface(MeiRequest::ReadDeviceId(ReadDeviceId::new(code, next)?));
            let (more, next_id) = self
                .query(unit, &request, |r| match r {
                    Response::EncapsulatedInterface(MeiResponse::ReadDeviceId(id)) => {
                        info.conformity = id.conformity();
                        info.objects.extend(id.objects().iter().map(|o| (o.id, o.value.to_vec())));
                        Some((id.more_follows(), id.next_object_id()))
                    }
                    _ => None,
                })
                .await?;
            if !more || code == ReadDeviceIdCode::Specific || next_id <= next {
                break;
            }
            next = next_id;
        }
        Ok(info)
    }

    /// A custom function code with its data; returns the reply's data.
    pub async fn custom(&self, unit: u8, function: u8, data: &[u8]) -> Result<Vec<u8>, Error> {
        let request = Request::Custom(Custom::new(function, data)?);
        self.query(unit, &request, |r| match r {
            Response::Custom(c) if c.function() == function => Some(c.data().to_vec()),
            _ => None,
        })
        .await
    }

    /// The function code of a request PDU, for messages.
    pub fn function_of(pdu: &[u8]) -> FunctionCode {
        FunctionCode::from_u8(pdu.first().copied().unwrap_or_default())
    }
}
