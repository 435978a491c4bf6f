//! The server driver: runs the core slave engine over a port, or over every connection a TCP
//! listener accepts.
//!
//! Like the client's driver it knows no Modbus: it feeds bytes with their arrival time,
//! sleeps until the engine's next deadline ([`Timer::Precise`] on serial lines, so that a
//! reply due at t3.5 + wait is not a millisecond late), writes the reply the engine hands
//! it, and reports what happened. A [`ReplyFilter`] may drop, delay or alter replies on
//! their way out: the simulator's fault injection.

use std::collections::VecDeque;
use std::io;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use ferrobus_proto::frame::{Framing, LineTiming};
use ferrobus_proto::master::MAX_TX_LEN;
use ferrobus_proto::pdu::{AddressRange, Bits, MaskWrite, Registers, Request};
use ferrobus_proto::slave::{Admission, Disposition, Handler, Slave, SlaveConfig, SlaveEvent};
use ferrobus_proto::{ExceptionCode, FunctionCode};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

use crate::clock::Clock;
use crate::port::{BoxPort, Rs485, Transport};
use crate::timer::Timer;

/// What happens to a reply on its way out.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Fate {
    /// Send it now.
    Send,
    /// Send it this much later.
    Delay(Duration),
    /// Send it now, one byte at a time with `gap` between bytes (a slow or stuttering
    /// device; on a serial line a gap past t1.5 breaks the frame).
    Trickle {
        /// The pause after each byte but the last.
        gap: Duration,
    },
    /// Never send it.
    Drop,
}

/// What a reply answers: the request as the engine reported it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Answering {
    /// The unit the request was for.
    pub unit: u8,
    /// Its function code.
    pub function: FunctionCode,
    /// The addresses it touches.
    pub addresses: [Option<AddressRange>; 2],
}

impl Answering {
    /// What a reply to the request of `event` answers, if `event` is a request that gets one.
    pub fn of(event: &SlaveEvent) -> Option<Answering> {
        match *event {
            SlaveEvent::Request {
                unit,
                function,
                addresses,
                disposition: Disposition::Replied(_) | Disposition::Refused(..),
                ..
            } => Some(Answering { unit, function, addresses }),
            _ => None,
        }
    }
}

/// Decides the fate of each reply, and may change its bytes.
pub trait ReplyFilter: Send {
    /// `frame` is the reply as framed for the wire; the filter may change it, its length
    /// included. `answering` is the request it answers, when the engine reported one (the
    /// replies of one connection are matched to its requests in order).
    fn filter(&mut self, answering: Option<&Answering>, frame: &mut Vec<u8>) -> Fate;
}

/// What a server saw and did, for logs and monitors.
#[derive(Clone, PartialEq, Eq, Debug)]
pub enum ServerEvent {
    /// The engine's report of a request or a frame on the bus.
    Slave {
        /// The report.
        event: SlaveEvent,
        /// When it was made.
        at: tokio::time::Instant,
    },
    /// A reply went out.
    Sent {
        /// The frame.
        frame: Vec<u8>,
        /// When the engine had it due.
        due: tokio::time::Instant,
        /// When its write began: the reply's start as far as the server decides it. The
        /// write itself (the kernel's, and with RTS direction control the frame's whole
        /// transmission) comes after.
        at: tokio::time::Instant,
    },
    /// A reply was dropped by the filter.
    Dropped {
        /// The frame.
        frame: Vec<u8>,
    },
}

/// A handler shared by several engines (one per TCP connection) or with the program (a
/// simulator's model that also runs on its own).
pub struct Shared<H>(pub Arc<Mutex<H>>);

impl<H> Clone for Shared<H> {
    fn clone(&self) -> Self {
        Shared(Arc::clone(&self.0))
    }
}

impl<H> Shared<H> {
    /// Shares `handler`.
    pub fn new(handler: H) -> Self {
        Shared(Arc::new(Mutex::new(handler)))
    }

    /// Locks it (a handler that panicked is still used: its data is plain values).
    pub fn lock(&self) -> MutexGuard<'_, H> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl<H: Handler> Handler for Shared<H> {
    fn admit(&mut self, unit: u8, broadcast: bool, request: &Request<'_>) -> Admission {
        self.lock().admit(unit, broadcast, request)
    }
    fn response_wait(&self, unit: u8) -> Option<Duration> {
        self.lock().response_wait(unit)
    }
    fn read_coils(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.lock().read_coils(unit, start, out)
    }
    fn read_discrete_inputs(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.lock().read_discrete_inputs(unit, start, out)
    }
    fn read_holding_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.lock().read_holding_registers(unit, start, out)
    }
    fn read_input_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.lock().read_input_registers(unit, start, out)
    }
    fn write_single_coil(&mut self, unit: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        self.lock().write_single_coil(unit, address, value)
    }
    fn write_single_register(&mut self, unit: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        self.lock().write_single_register(unit, address, value)
    }
    fn write_multiple_coils(&mut self, unit: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        self.lock().write_multiple_coils(unit, start, values)
    }
    fn write_multiple_registers(&mut self, unit: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        self.lock().write_multiple_registers(unit, start, values)
    }
    fn mask_write_register(&mut self, unit: u8, mask: MaskWrite) -> Result<(), ExceptionCode> {
        self.lock().mask_write_register(unit, mask)
    }
    fn read_write_multiple_registers(
        &mut self,
        unit: u8,
        write_start: u16,
        values: Registers<'_>,
        read_start: u16,
        out: &mut [u16],
    ) -> Result<(), ExceptionCode> {
        self.lock().read_write_multiple_registers(unit, write_start, values, read_start, out)
    }
    fn read_exception_status(&mut self, unit: u8) -> Result<u8, ExceptionCode> {
        self.lock().read_exception_status(unit)
    }
    fn report_server_id(&mut self, unit: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.lock().report_server_id(unit, out)
    }
    fn read_file_record(&mut self, unit: u8, file: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.lock().read_file_record(unit, file, record, out)
    }
    fn write_file_record(
        &mut self,
        unit: u8,
        file: u16,
        record: u16,
        values: Registers<'_>,
    ) -> Result<(), ExceptionCode> {
        self.lock().write_file_record(unit, file, record, values)
    }
    fn read_fifo_queue(&mut self, unit: u8, address: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        self.lock().read_fifo_queue(unit, address, out)
    }
    fn device_object(&mut self, unit: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        self.lock().device_object(unit, id, out)
    }
    fn encapsulated(&mut self, unit: u8, mei_type: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.lock().encapsulated(unit, mei_type, data, out)
    }
    fn custom(&mut self, unit: u8, function: u8, data: &[u8], out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.lock().custom(unit, function, data, out)
    }
}

/// How a server runs, besides its engine.
pub struct ServerOptions {
    /// How deadlines are waited for.
    pub timer: Timer,
    /// RS-485 direction control (RTS is raised around each reply when [`Rs485::Rts`]).
    pub rs485: Rs485,
    /// The line timing (for how long RTS stays up).
    pub timing: LineTiming,
    /// Fault injection on replies.
    pub filter: Option<Box<dyn ReplyFilter>>,
    /// Called with every event.
    pub observer: Option<Box<dyn FnMut(ServerEvent) + Send>>,
}

impl ServerOptions {
    /// Options for a line with `timing`, waiting with `timer`: no direction control, no
    /// filter, no observer.
    pub fn new(timing: LineTiming, timer: Timer) -> Self {
        ServerOptions { timer, rs485: Rs485::Auto, timing, filter: None, observer: None }
    }

    /// Options fitting `transport`: its timer, RS-485 mode and timing.
    pub fn for_transport(transport: &Transport) -> Self {
        ServerOptions {
            timer: transport.timer(),
            rs485: transport.rs485(),
            timing: *transport.timing(),
            filter: None,
            observer: None,
        }
    }

    fn observe(&mut self, event: ServerEvent) {
        if let Some(observer) = self.observer.as_mut() {
            observer(event);
        }
    }
}

/// The most requests remembered for replies not yet sent (a peer that pipelines more, with
/// replies the engine never sends, cannot grow the queue).
const ANSWERING_MAX: usize = 64;

/// Runs `slave` over `port`, serving through `handler`, until the port fails or closes.
/// Returns the engine (with its counters) and the error that ended it, if any.
pub async fn serve<F: Framing, H: Handler + Send>(
    mut slave: Slave<F>,
    mut port: BoxPort,
    handler: &mut H,
    options: &mut ServerOptions,
) -> (Slave<F>, io::Result<()>) {
    let clock = Clock::new();
    let mut sleeper = options.timer.sleeper();
    let mut rx = vec![0u8; 1024];
    let mut tx = [0u8; MAX_TX_LEN];
    // A reply held back by the filter: its bytes and when to send them.
    let mut delayed: Option<(Vec<u8>, tokio::time::Instant)> = None;
    // The requests whose replies have not gone out yet, oldest first.
    let mut answering: VecDeque<Answering> = VecDeque::new();
    loop {
        let now = clock.now();
        // Events first: a request is known before its reply leaves (on TCP, at once).
        while let Some(event) = slave.poll_event() {
            if let Some(request) = Answering::of(&event) {
                if answering.len() == ANSWERING_MAX {
                    answering.pop_front();
                }
                answering.push_back(request);
            }
            options.observe(ServerEvent::Slave { event, at: tokio::time::Instant::now() });
        }
        let due = slave.reply_due().map(|t| clock.to_tokio(t));
        if let Some(n) = slave.poll_transmit(now, &mut tx) {
            let due = due.unwrap_or_else(tokio::time::Instant::now);
            let mut frame = tx.get(..n).unwrap_or_default().to_vec();
            let request = answering.pop_front();
            let fate = options.filter.as_mut().map_or(Fate::Send, |f| f.filter(request.as_ref(), &mut frame));
            match fate {
                Fate::Send => {
                    let at = tokio::time::Instant::now();
                    if let Err(e) = write(&mut port, &frame, options.rs485, options.timing).await {
                        return (slave, Err(e));
                    }
                    options.observe(ServerEvent::Sent { frame, due, at });
                }
                Fate::Trickle { gap } => {
                    let at = tokio::time::Instant::now();
                    for (i, byte) in frame.iter().enumerate() {
                        if i > 0 {
                            tokio::time::sleep(gap).await;
                        }
                        if let Err(e) =
                            write(&mut port, std::slice::from_ref(byte), options.rs485, options.timing).await
                        {
                            return (slave, Err(e));
                        }
                    }
                    options.observe(ServerEvent::Sent { frame, due, at });
                }
                Fate::Delay(d) => delayed = Some((frame, tokio::time::Instant::now() + d)),
                Fate::Drop => options.observe(ServerEvent::Dropped { frame }),
            }
        }
        let engine = slave.poll_timeout().map(|t| clock.to_tokio(t));
        let deadline = match (&delayed, engine) {
            (Some((_, d)), Some(e)) => Some((*d).min(e)),
            (Some((_, d)), None) => Some(*d),
            (None, e) => e,
        };
        tokio::select! {
            read = port.read(&mut rx) => match read {
                Ok(0) => return (slave, Ok(())),
                Ok(n) => {
                    let at = port.last_arrival().map_or_else(|| clock.now(), |t| clock.from_tokio(t));
                    let bytes = rx.get(..n).unwrap_or_default();
                    tracing::trace!("rx {}", crate::driver::Hex(bytes));
                    slave.on_bytes(at, bytes, handler);
                }
                Err(e) => return (slave, Err(e)),
            },
            () = sleeper.sleep_until(deadline) => {
                slave.handle_timeout(clock.now(), handler);
                if let Some((frame, due)) = delayed.take_if(|(_, at)| *at <= tokio::time::Instant::now()) {
                    let at = tokio::time::Instant::now();
                    if let Err(e) = write(&mut port, &frame, options.rs485, options.timing).await {
                        return (slave, Err(e));
                    }
                    options.observe(ServerEvent::Sent { frame, due, at });
                }
            }
        }
    }
}

async fn write(port: &mut BoxPort, frame: &[u8], rs485: Rs485, timing: LineTiming) -> io::Result<()> {
    tracing::trace!("tx {}", crate::driver::Hex(frame));
    let rts = rs485 == Rs485::Rts;
    if rts {
        port.set_rts(true)?;
    }
    port.write_all(frame).await?;
    port.flush().await?;
    if rts {
        // The OS buffers the frame; hold RTS until its last character has left.
        tokio::time::sleep(timing.transmit_time(frame.len()).saturating_add(timing.char_time())).await;
        port.set_rts(false)?;
    }
    Ok(())
}

/// Runs a slave engine for `config` over `port` with the framing and timing of `transport`,
/// serving through `handler`, until the port fails or closes.
pub async fn serve_transport<H: Handler + Send>(
    transport: &Transport,
    port: BoxPort,
    config: SlaveConfig,
    handler: &mut H,
    options: &mut ServerOptions,
) -> io::Result<()> {
    match transport.framing() {
        crate::port::Framing::Mbap => {
            serve(Slave::new(Transport::mbap_codec(), config), port, handler, options).await.1
        }
        crate::port::Framing::Rtu => serve(Slave::new(transport.rtu_codec(), config), port, handler, options).await.1,
        crate::port::Framing::Ascii => {
            serve(Slave::new(transport.ascii_codec(), config), port, handler, options).await.1
        }
    }
}

/// Serves Modbus/TCP (or RTU over TCP, per `transport`'s framing) on `listener`: one engine
/// per connection, all sharing `handler`, each with the options `options` makes. Runs until the
/// listener fails.
pub async fn serve_tcp<H, O>(
    listener: TcpListener,
    transport: Transport,
    config: SlaveConfig,
    handler: Shared<H>,
    options: O,
) -> io::Result<()>
where
    H: Handler + Send + 'static,
    O: Fn() -> ServerOptions + Send + Sync + 'static,
{
    let options = Arc::new(options);
    loop {
        let (stream, peer) = listener.accept().await?;
        stream.set_nodelay(true)?;
        tracing::debug!(%peer, "connection accepted");
        let transport = transport.clone();
        let mut handler = handler.clone();
        let options = Arc::clone(&options);
        tokio::spawn(async move {
            let mut options = options();
            match serve_transport(&transport, Box::new(stream), config, &mut handler, &mut options).await {
                Ok(()) => tracing::debug!(%peer, "connection closed"),
                Err(e) => tracing::debug!(%peer, "connection failed: {e}"),
            }
        });
    }
}
