//! The server role: the shared data map behind a `tokio_modbus::server::Service`.
//!
//! tokio-modbus leaves every protocol decision to the service: it answers
//! every unit id, checks no quantity and no address. This service applies the
//! Modbus spec limits itself (exception 03 for a bad quantity, 02 for an
//! address past the map) and answers unit U only.
//!
//! Quirks of tokio-modbus 0.17.0 this file works around (see README.md):
//! - The RTU server's `serve_forever` returns on the first undecodable input
//!   (more than 20 bytes of noise in one go, an unknown function code, a
//!   request whose PDU fails to decode) and drops the port with it. The loop
//!   below reopens the port and serves on.
//! - Decoding FC 0F with a quantity larger than 8 x byte count panics inside
//!   tokio-modbus (index out of bounds). Serving runs in a spawned task, so a
//!   panic ends one RTU session (reopened) or one TCP connection, not the
//!   process.

use std::{
    net::{Ipv4Addr, SocketAddr},
    ops::Range,
    sync::{Arc, Mutex},
    time::Duration,
};

use tokio::net::TcpListener;
use tokio_modbus::{
    bytes::Bytes,
    prelude::{ConformityLevel, DeviceIdObject, ReadCode, ReadDeviceIdentificationResponse},
    server::{
        rtu::Server as RtuServer,
        tcp::{accept_tcp_connection, Server as TcpServer},
        Service,
    },
    ExceptionCode, Request, Response, SlaveRequest,
};

use crate::args::{Common, SerialOpts, Transport};

/// Holding and input registers: addresses 0..999.
const REGISTERS: usize = 1000;
/// Coils and discrete inputs: addresses 0..1999.
const BITS: usize = 2000;

/// FC 11 additional data and FC 2B/0E objects.
const VENDOR: &str = "tokio-modbus";
const PRODUCT_CODE: &str = "TM";
/// The tokio-modbus release this crate is locked to (keep in step with Cargo.toml).
const REVISION: &str = "0.17";

/// The shared data map of tests/peers/README.md.
#[derive(Debug)]
struct DataMap {
    holding: Vec<u16>,
    input: Vec<u16>,
    coils: Vec<bool>,
    discrete: Vec<bool>,
}

type Answer = Result<Response, ExceptionCode>;

/// `addr..addr+qty` if `qty` is within `1..=max` (else 03) and the range fits the table (else 02).
fn span(addr: u16, qty: usize, max: usize, len: usize) -> Result<Range<usize>, ExceptionCode> {
    if qty == 0 || qty > max {
        return Err(ExceptionCode::IllegalDataValue);
    }
    let start = usize::from(addr);
    let end = start + qty;
    if end > len {
        return Err(ExceptionCode::IllegalDataAddress);
    }
    Ok(start..end)
}

impl DataMap {
    fn new() -> Self {
        #[allow(clippy::cast_possible_truncation)] // masked to 16 bits
        Self {
            holding: (0..REGISTERS).map(|i| ((i * 7 + 3) & 0xFFFF) as u16).collect(),
            input: (0..REGISTERS).map(|i| ((0x1000 + i) & 0xFFFF) as u16).collect(),
            coils: (0..BITS).map(|i| i % 3 == 0).collect(),
            discrete: (0..BITS).map(|i| i % 5 == 0).collect(),
        }
    }

    /// Executes one request addressed to us.
    fn handle(&mut self, unit: u8, req: Request<'_>) -> Answer {
        match req {
            Request::ReadCoils(a, q) => Ok(Response::ReadCoils(self.coils[span(a, q.into(), 2000, BITS)?].to_vec())),
            Request::ReadDiscreteInputs(a, q) => {
                Ok(Response::ReadDiscreteInputs(self.discrete[span(a, q.into(), 2000, BITS)?].to_vec()))
            }
            Request::ReadHoldingRegisters(a, q) => {
                Ok(Response::ReadHoldingRegisters(self.holding[span(a, q.into(), 125, REGISTERS)?].to_vec()))
            }
            Request::ReadInputRegisters(a, q) => {
                Ok(Response::ReadInputRegisters(self.input[span(a, q.into(), 125, REGISTERS)?].to_vec()))
            }
            Request::WriteSingleCoil(a, v) => {
                self.coils[span(a, 1, 1, BITS)?.start] = v;
                Ok(Response::WriteSingleCoil(a, v))
            }
            Request::WriteSingleRegister(a, v) => {
                self.holding[span(a, 1, 1, REGISTERS)?.start] = v;
                Ok(Response::WriteSingleRegister(a, v))
            }
            Request::WriteMultipleCoils(a, values) => {
                let r = span(a, values.len(), 1968, BITS)?;
                self.coils[r].copy_from_slice(&values);
                #[allow(clippy::cast_possible_truncation)] // <= 1968
                Ok(Response::WriteMultipleCoils(a, values.len() as u16))
            }
            Request::WriteMultipleRegisters(a, values) => {
                let r = span(a, values.len(), 123, REGISTERS)?;
                self.holding[r].copy_from_slice(&values);
                #[allow(clippy::cast_possible_truncation)] // <= 123
                Ok(Response::WriteMultipleRegisters(a, values.len() as u16))
            }
            Request::MaskWriteRegister(a, and, or) => {
                let i = span(a, 1, 1, REGISTERS)?.start;
                // Spec 6.16: (current AND and_mask) OR (or_mask AND NOT and_mask).
                self.holding[i] = (self.holding[i] & and) | (or & !and);
                Ok(Response::MaskWriteRegister(a, and, or))
            }
            Request::ReadWriteMultipleRegisters(ra, rq, wa, values) => {
                // Validate both halves before touching anything; the write goes first.
                let read = span(ra, rq.into(), 125, REGISTERS)?;
                let write = span(wa, values.len(), 121, REGISTERS)?;
                self.holding[write].copy_from_slice(&values);
                Ok(Response::ReadWriteMultipleRegisters(self.holding[read].to_vec()))
            }
            Request::ReportServerId => Ok(Response::ReportServerId(unit, true, VENDOR.as_bytes().to_vec())),
            Request::ReadDeviceIdentification(code, object) => device_identification(code, object),
            Request::Custom(0x07, data) if data.is_empty() => {
                // Read Exception Status: no exception outputs here.
                Ok(Response::Custom(0x07, Bytes::from_static(&[0x00])))
            }
            Request::Custom(0x08, data) if data.len() == 4 && data[..2] == [0, 0] => {
                // Diagnostics sub-function 00 (Return Query Data): echo.
                Ok(Response::Custom(0x08, Bytes::from(data.into_owned())))
            }
            // Other diagnostics sub-functions, 0B, 0C, 14, 15, 18 and vendor codes.
            Request::Custom(..) => Err(ExceptionCode::IllegalFunction),
        }
    }

    /// True for requests that change state (executed when broadcast on RTU).
    fn is_write(req: &Request<'_>) -> bool {
        matches!(
            req,
            Request::WriteSingleCoil(..)
                | Request::WriteSingleRegister(..)
                | Request::WriteMultipleCoils(..)
                | Request::WriteMultipleRegisters(..)
                | Request::MaskWriteRegister(..)
        )
    }
}

/// FC 2B/0E with the three basic objects; conformity 0x81 (basic, stream and individual access).
fn device_identification(code: ReadCode, object: u8) -> Answer {
    let objects: [(u8, &str); 3] = [(0x00, VENDOR), (0x01, PRODUCT_CODE), (0x02, REVISION)];
    let pick = |from: usize| -> Vec<DeviceIdObject> {
        objects[from..]
            .iter()
            .map(|(id, v)| DeviceIdObject { id: *id, value: Bytes::from_static(v.as_bytes()) })
            .collect()
    };
    let device_id_objects = match code {
        // Individual access: that object or exception 02.
        ReadCode::Specific => {
            let i = usize::from(object);
            if i >= objects.len() {
                return Err(ExceptionCode::IllegalDataAddress);
            }
            vec![pick(i).remove(0)]
        }
        // Stream access: an unknown start object reads as object 0 (spec 6.21).
        ReadCode::Basic | ReadCode::Regular | ReadCode::Extended => {
            pick(if usize::from(object) < objects.len() { usize::from(object) } else { 0 })
        }
    };
    Ok(Response::ReadDeviceIdentification(ReadDeviceIdentificationResponse {
        read_code: code,
        conformity_level: ConformityLevel::BasicIdentification,
        more_follows: false,
        next_object_id: 0,
        device_id_objects,
    }))
}

/// The service handed to tokio-modbus; cheap to clone (one per connection).
#[derive(Debug, Clone)]
struct PeerService {
    unit: u8,
    /// RTU: execute broadcast (unit 0) writes without answering. TCP: ignore unit 0.
    broadcast_writes: bool,
    map: Arc<Mutex<DataMap>>,
    debug: bool,
}

impl Service for PeerService {
    type Request = SlaveRequest<'static>;
    /// `None` = send nothing.
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = std::future::Ready<Result<Option<Response>, ExceptionCode>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        let SlaveRequest { slave, request } = req;
        // A poisoned lock only means an earlier request panicked: the data is still usable.
        let mut map = self.map.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let answer = if slave == self.unit {
            map.handle(self.unit, request).map(Some)
        } else {
            if slave == 0 && self.broadcast_writes && DataMap::is_write(&request) {
                let _ = map.handle(self.unit, request);
            } else if self.debug {
                eprintln!("tokio-modbus-peer: ignoring request for unit {slave}");
            }
            Ok(None)
        };
        std::future::ready(answer)
    }
}

pub fn open_serial(opts: &SerialOpts) -> tokio_serial::Result<tokio_serial::SerialStream> {
    let builder = tokio_serial::new(&opts.path, opts.baud)
        .parity(opts.parity)
        .data_bits(opts.data_bits)
        .stop_bits(opts.stop_bits)
        .flow_control(tokio_serial::FlowControl::None);
    tokio_serial::SerialStream::open(&builder)
}

fn say_ready() {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    // If stdout is gone there is nobody to tell; keep serving anyway.
    let _ = writeln!(out, "READY");
    let _ = out.flush();
}

/// Runs the server role until a signal; returns the exit status.
pub async fn run(common: Common) -> i32 {
    let map = Arc::new(Mutex::new(DataMap::new()));
    match common.transport {
        Transport::Rtu(ref opts) => {
            let service = PeerService { unit: common.unit, broadcast_writes: true, map, debug: common.debug };
            serve_rtu(opts, service).await
        }
        Transport::Tcp(ref port) => {
            let service = PeerService { unit: common.unit, broadcast_writes: false, map, debug: common.debug };
            // args.rs has validated the port.
            let port: u16 = port.parse().unwrap_or(0);
            serve_tcp(port, service).await
        }
    }
}

async fn serve_rtu(opts: &SerialOpts, service: PeerService) -> i32 {
    let first = match open_serial(opts) {
        Ok(port) => port,
        Err(e) => {
            eprintln!("tokio-modbus-peer: cannot open {}: {e}", opts.path);
            return 1;
        }
    };
    say_ready();
    let mut port = Some(first);
    let mut reported = false;
    loop {
        let serial = match port.take() {
            Some(serial) => serial,
            None => match open_serial(opts) {
                Ok(serial) => {
                    reported = false;
                    serial
                }
                Err(e) => {
                    if !reported {
                        eprintln!("tokio-modbus-peer: cannot reopen {}: {e}; retrying every second", opts.path);
                        reported = true;
                    }
                    tokio::time::sleep(Duration::from_secs(1)).await;
                    continue;
                }
            },
        };
        let svc = service.clone();
        let session = tokio::spawn(async move { RtuServer::new(serial).serve_forever(svc).await });
        match session.await {
            Ok(Ok(())) => eprintln!("tokio-modbus-peer: {}: end of stream; reopening", opts.path),
            Ok(Err(e)) => eprintln!("tokio-modbus-peer: RTU session ended: {e}; reopening the port"),
            Err(e) => eprintln!("tokio-modbus-peer: RTU session panicked ({e}); reopening the port"),
        }
        // Never spin on a port that fails at once.
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

async fn serve_tcp(port: u16, service: PeerService) -> i32 {
    let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
    let listener = match TcpListener::bind(addr).await {
        Ok(l) => l,
        Err(e) => {
            eprintln!("tokio-modbus-peer: cannot listen on {addr}: {e}");
            return 1;
        }
    };
    let server = TcpServer::new(listener);
    say_ready();
    let debug = service.debug;
    let on_connected = move |stream, peer| {
        let svc = service.clone();
        async move { accept_tcp_connection(stream, peer, move |_| Ok(Some(svc.clone()))) }
    };
    let on_process_error = move |err: std::io::Error| {
        if debug {
            eprintln!("tokio-modbus-peer: connection closed: {err}");
        }
    };
    // serve() only returns if accept() itself fails.
    loop {
        if let Err(e) = server.serve(&on_connected, on_process_error).await {
            eprintln!("tokio-modbus-peer: accept failed: {e}; retrying");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
}
