//! The client role: `script` (the line contract) and `bench`.
//!
//! tokio-modbus's async client has no timeout of its own: every call is
//! wrapped in `tokio::time::timeout`. After a timeout the same context is
//! kept (as libmodbus and pymodbus do); a late answer to the abandoned request
//! would then surface as a header-mismatch error on the next command, after
//! which the connection (or serial port) is reopened.

use std::{borrow::Cow, time::Duration, time::Instant};

use tokio::io::{AsyncBufReadExt as _, BufReader};
use tokio_modbus::{
    client::{rtu, tcp, Context},
    prelude::{Client as _, ReadCode, Reader as _, SlaveContext as _, Writer as _},
    ExceptionCode, ExceptionResponse, ProtocolError, Request, Response, Slave,
};

use crate::{
    args::{parse_num, BenchOpts, Common, Transport},
    server::open_serial,
};

/// The outcome of one request, before formatting.
type Outcome<T> = Result<Result<T, ExceptionCode>, String>;

/// A connected (or reconnectable) tokio-modbus client context.
struct Peer {
    common: Common,
    ctx: Option<Context>,
    unit: u8,
    timeout: Duration,
}

impl Peer {
    async fn connect(common: &Common, unit: u8) -> Result<Context, String> {
        let slave = Slave(unit);
        match &common.transport {
            Transport::Rtu(opts) => {
                let serial = open_serial(opts).map_err(|e| format!("cannot open {}: {e}", opts.path))?;
                Ok(rtu::attach_slave(serial, slave))
            }
            Transport::Tcp(host_port) => {
                let addr = tokio::net::lookup_host(host_port.as_str())
                    .await
                    .map_err(|e| format!("cannot resolve {host_port}: {e}"))?
                    .next()
                    .ok_or_else(|| format!("cannot resolve {host_port}"))?;
                tcp::connect_slave(addr, slave).await.map_err(|e| format!("cannot connect to {addr}: {e}"))
            }
        }
    }

    /// The context, reconnecting first if an earlier transport error dropped it.
    async fn ctx(&mut self) -> Result<&mut Context, String> {
        if self.ctx.is_none() {
            self.ctx = Some(Self::connect(&self.common, self.unit).await?);
        }
        self.ctx.as_mut().ok_or_else(|| "not connected".to_string())
    }

    /// Runs one tokio-modbus call with the timeout, mapping the nested result.
    async fn run<T, F>(&mut self, f: F) -> Outcome<T>
    where
        F: for<'c> FnOnce(
            &'c mut Context,
        )
            -> std::pin::Pin<Box<dyn std::future::Future<Output = tokio_modbus::Result<T>> + Send + 'c>>,
    {
        let timeout = self.timeout;
        let ctx = self.ctx().await.map_err(|e| format!("connect: {e}"))?;
        let Ok(result) = tokio::time::timeout(timeout, f(ctx)).await else {
            return Err("timeout".to_string());
        };
        match result {
            Ok(inner) => Ok(inner),
            // tokio-modbus 0.17 compares FunctionCode::Custom(0x18) with the
            // exception's FunctionCode::ReadFifoQueue and calls that a mismatch:
            // an exception to a custom request for 07/08/0B/0C/14/15/18 never
            // reaches the caller as an exception. Same byte on the wire: unwrap it.
            Err(tokio_modbus::Error::Protocol(ProtocolError::FunctionCodeMismatch {
                request,
                result: Err(ExceptionResponse { function, exception }),
            })) if request.value() == function.value() => Ok(Err(exception)),
            Err(e) => {
                // Any other error leaves the stream in an unknown state: after a
                // decode error tokio-util's Framed yields None once (the next
                // call would fail with a bogus error), and on TCP a reply that
                // was not consumed makes every later call read the previous
                // reply (header mismatch). Start afresh with the next command.
                self.ctx = None;
                Err(format!("error {e}"))
            }
        }
    }
}

/// Formats an outcome: `ok ...`, `exception N`, `timeout` or `error ...`.
fn line<T>(outcome: Outcome<T>, fmt: impl FnOnce(T) -> String) -> String {
    match outcome {
        Ok(Ok(v)) => fmt(v),
        Ok(Err(code)) => format!("exception {}", u8::from(code)),
        Err(e) => e, // already "timeout" or "error ..."
    }
}

fn ok_list<I: IntoIterator<Item = String>>(items: I) -> String {
    let mut s = String::from("ok");
    for item in items {
        s.push(' ');
        s.push_str(&item);
    }
    s
}

fn ok_unit(_: ()) -> String {
    "ok".to_string()
}

struct Usage(&'static str);

fn u16_arg(tok: &str) -> Result<u16, ()> {
    parse_num(tok, 0, 65535).and_then(|v| u16::try_from(v).ok()).ok_or(())
}

fn u8_arg(tok: &str, lo: u64, hi: u64) -> Result<u8, ()> {
    parse_num(tok, lo, hi).and_then(|v| u8::try_from(v).ok()).ok_or(())
}

fn words(toks: &[&str]) -> Result<Vec<u16>, ()> {
    toks.iter().map(|t| u16_arg(t)).collect()
}

fn coils(toks: &[&str]) -> Result<Vec<bool>, ()> {
    toks.iter().map(|t| u8_arg(t, 0, 1).map(|b| b == 1)).collect()
}

/// Unwraps a `Response::Custom` with the expected function code.
fn custom(resp: Response, fc: u8) -> Result<Vec<u8>, String> {
    match resp {
        Response::Custom(code, data) if code == fc => Ok(data.to_vec()),
        other => Err(format!("error unexpected response {other:?}")),
    }
}

/// Executes one script command; returns the result line.
#[allow(clippy::too_many_lines)] // one arm per command reads best
async fn command(peer: &mut Peer, tok: &[&str]) -> String {
    let (cmd, a) = (tok[0], &tok[1..]);
    let usage = |u: Usage| format!("error usage: {}", u.0);
    macro_rules! args {
        ($cond:expr, $text:expr) => {
            if !$cond {
                return usage(Usage($text));
            }
        };
    }
    macro_rules! arg {
        ($e:expr, $text:expr) => {
            match $e {
                Ok(v) => v,
                Err(()) => return usage(Usage($text)),
            }
        };
    }

    match cmd {
        "unit" => {
            args!(a.len() == 1, "unit U");
            let unit = arg!(u8_arg(a[0], 0, 255), "unit U");
            peer.unit = unit;
            if let Some(ctx) = peer.ctx.as_mut() {
                ctx.set_slave(Slave(unit));
            }
            "ok".into()
        }
        "sleep" => {
            args!(a.len() == 1, "sleep MS");
            let ms = arg!(parse_num(a[0], 0, 60000).ok_or(()), "sleep MS");
            tokio::time::sleep(Duration::from_millis(ms)).await;
            "ok".into()
        }
        "read_holding" | "read_input" => {
            const U: &str = "read_holding|read_input ADDR COUNT";
            args!(a.len() == 2, U);
            let (addr, cnt) = (arg!(u16_arg(a[0]), U), arg!(u16_arg(a[1]), U));
            let holding = cmd == "read_holding";
            let r = peer
                .run(|c| if holding { c.read_holding_registers(addr, cnt) } else { c.read_input_registers(addr, cnt) })
                .await;
            line(r, |v| ok_list(v.iter().map(u16::to_string)))
        }
        "read_coils" | "read_discrete" => {
            const U: &str = "read_coils|read_discrete ADDR COUNT";
            args!(a.len() == 2, U);
            let (addr, cnt) = (arg!(u16_arg(a[0]), U), arg!(u16_arg(a[1]), U));
            let is_coils = cmd == "read_coils";
            let r =
                peer.run(|c| if is_coils { c.read_coils(addr, cnt) } else { c.read_discrete_inputs(addr, cnt) }).await;
            line(r, |v| ok_list(v.iter().map(|b| u8::from(*b).to_string())))
        }
        "write_coil" => {
            const U: &str = "write_coil ADDR 0|1";
            args!(a.len() == 2, U);
            let (addr, v) = (arg!(u16_arg(a[0]), U), arg!(u8_arg(a[1], 0, 1), U));
            line(peer.run(|c| c.write_single_coil(addr, v == 1)).await, ok_unit)
        }
        "write_register" => {
            const U: &str = "write_register ADDR VALUE";
            args!(a.len() == 2, U);
            let (addr, v) = (arg!(u16_arg(a[0]), U), arg!(u16_arg(a[1]), U));
            line(peer.run(|c| c.write_single_register(addr, v)).await, ok_unit)
        }
        "write_coils" => {
            const U: &str = "write_coils ADDR 0|1 [0|1 ...]";
            args!(a.len() >= 2, U);
            let (addr, bits) = (arg!(u16_arg(a[0]), U), arg!(coils(&a[1..]), U));
            line(peer.run(|c| Box::pin(async move { c.write_multiple_coils(addr, &bits).await })).await, ok_unit)
        }
        "write_registers" => {
            const U: &str = "write_registers ADDR VALUE [VALUE ...]";
            args!(a.len() >= 2, U);
            let (addr, vals) = (arg!(u16_arg(a[0]), U), arg!(words(&a[1..]), U));
            line(peer.run(|c| Box::pin(async move { c.write_multiple_registers(addr, &vals).await })).await, ok_unit)
        }
        "mask_write" => {
            const U: &str = "mask_write ADDR AND OR";
            args!(a.len() == 3, U);
            let (addr, and, or) = (arg!(u16_arg(a[0]), U), arg!(u16_arg(a[1]), U), arg!(u16_arg(a[2]), U));
            line(peer.run(|c| c.masked_write_register(addr, and, or)).await, ok_unit)
        }
        "write_read" => {
            const U: &str = "write_read READ_ADDR READ_COUNT WRITE_ADDR VALUE [VALUE ...]";
            args!(a.len() >= 4, U);
            let (ra, rn, wa) = (arg!(u16_arg(a[0]), U), arg!(u16_arg(a[1]), U), arg!(u16_arg(a[2]), U));
            let vals = arg!(words(&a[3..]), U);
            let r =
                peer.run(|c| Box::pin(async move { c.read_write_multiple_registers(ra, rn, wa, &vals).await })).await;
            line(r, |v| ok_list(v.iter().map(u16::to_string)))
        }
        "report_slave_id" => {
            args!(a.is_empty(), "report_slave_id");
            let r = peer.run(|c| c.call(Request::ReportServerId)).await;
            line(r, |resp| match resp {
                // tokio-modbus splits the payload; put it back together byte for byte.
                Response::ReportServerId(id, run, data) => {
                    let mut bytes = vec![id, if run { 0xFF } else { 0x00 }];
                    bytes.extend(data);
                    ok_list(bytes.iter().map(|b| format!("{b:02x}")))
                }
                other => format!("error unexpected response {other:?}"),
            })
        }
        "read_exception_status" => {
            args!(a.is_empty(), "read_exception_status");
            let r = peer.run(|c| c.call(Request::Custom(0x07, Cow::Borrowed(&[])))).await;
            line(r, |resp| match custom(resp, 0x07) {
                Ok(d) if d.len() == 1 => format!("ok {}", d[0]),
                Ok(d) => format!("error bad FC 07 payload {d:02x?}"),
                Err(e) => e,
            })
        }
        "diag" => {
            // FC 08 is not in tokio-modbus's typed API: sent as a custom request.
            const U: &str = "diag SUBFUNCTION VALUE";
            args!(a.len() == 2, U);
            let (sub, v) = (arg!(u16_arg(a[0]), U), arg!(u16_arg(a[1]), U));
            let mut pdu = sub.to_be_bytes().to_vec();
            pdu.extend(v.to_be_bytes());
            let r = peer.run(|c| c.call(Request::Custom(0x08, Cow::Owned(pdu)))).await;
            line(r, |resp| match custom(resp, 0x08) {
                Ok(d) if d.len() >= 2 && d.len() % 2 == 0 => {
                    ok_list(d.chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]]).to_string()))
                }
                Ok(d) => format!("error bad FC 08 payload {d:02x?}"),
                Err(e) => e,
            })
        }
        "read_device_id" => {
            const U: &str = "read_device_id READ_CODE(1..4) OBJECT_ID";
            args!(a.len() == 2, U);
            let code = arg!(u8_arg(a[0], 1, 4).map(ReadCode::try_from_value), U);
            let Some(code) = code else { return usage(Usage(U)) };
            let object = arg!(u8_arg(a[1], 0, 255), U);
            let r = peer.run(|c| c.read_device_identification(code, object)).await;
            line(r, |resp| {
                ok_list(resp.device_id_objects.iter().map(|o| {
                    use std::fmt::Write as _;
                    let mut item = format!("{:02x}=", o.id);
                    for b in &o.value {
                        let _ = write!(item, "{b:02x}"); // writing to a String cannot fail
                    }
                    item
                }))
            })
        }
        "read_fifo" => {
            const U: &str = "read_fifo ADDR";
            args!(a.len() == 1, U);
            let addr = arg!(u16_arg(a[0]), U);
            let r = peer.run(|c| c.call(Request::Custom(0x18, Cow::Owned(addr.to_be_bytes().to_vec())))).await;
            line(r, |resp| match custom(resp, 0x18) {
                // byte count (2), FIFO count (2), values
                Ok(d) if d.len() >= 4 && d.len() % 2 == 0 => {
                    let count = usize::from(u16::from_be_bytes([d[2], d[3]]));
                    if d.len() == 4 + 2 * count {
                        ok_list(d[4..].chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]]).to_string()))
                    } else {
                        format!("error bad FC 18 payload {d:02x?}")
                    }
                }
                Ok(d) => format!("error bad FC 18 payload {d:02x?}"),
                Err(e) => e,
            })
        }
        "read_file" | "write_file" => format!("error unsupported by tokio-modbus client: {cmd}"),
        other => format!("error unknown command: {other}"),
    }
}

/// The `script` mode: one result line per command line on stdin.
pub async fn script(common: Common, timeout: Duration) -> i32 {
    use std::io::Write as _;
    let unit = common.unit;
    let ctx = match Peer::connect(&common, unit).await {
        Ok(ctx) => ctx,
        Err(e) => {
            eprintln!("tokio-modbus-peer: {e}");
            return 1;
        }
    };
    let mut peer = Peer { common, ctx: Some(ctx), unit, timeout };
    let mut lines = BufReader::new(tokio::io::stdin()).lines();
    loop {
        let text = match lines.next_line().await {
            Ok(Some(text)) => text,
            Ok(None) => break,
            Err(e) => {
                // e.g. invalid UTF-8: report it as this line's result and go on.
                println!("error {e}");
                continue;
            }
        };
        let tok: Vec<&str> = text.split_whitespace().collect();
        if tok.is_empty() || tok[0].starts_with('#') {
            continue;
        }
        let result = command(&mut peer, &tok).await;
        let mut out = std::io::stdout().lock();
        if writeln!(out, "{result}").and_then(|()| out.flush()).is_err() {
            return 0; // nobody is listening any more
        }
    }
    if let Some(mut ctx) = peer.ctx.take() {
        let _ = ctx.disconnect().await;
    }
    0
}

fn rusage_seconds() -> (f64, f64) {
    // SAFETY: getrusage only writes into the zeroed struct we pass.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &raw mut ru) } != 0 {
        return (0.0, 0.0);
    }
    #[allow(clippy::cast_precision_loss)]
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    (tv(ru.ru_utime), tv(ru.ru_stime))
}

/// Nearest-rank percentile of sorted nanoseconds, in microseconds.
#[allow(clippy::cast_precision_loss, clippy::cast_possible_truncation, clippy::cast_sign_loss)]
fn percentile_us(sorted: &[u64], p: u64) -> f64 {
    let n = sorted.len() as u64;
    let rank = (p * n).div_ceil(100).clamp(1, n);
    sorted[(rank - 1) as usize] as f64 / 1000.0
}

/// The `bench` mode: N FC03 reads back to back, one JSON line.
pub async fn bench(common: Common, timeout: Duration, opts: BenchOpts) -> i32 {
    let unit = common.unit;
    let ctx = match Peer::connect(&common, unit).await {
        Ok(ctx) => ctx,
        Err(e) => {
            eprintln!("tokio-modbus-peer: {e}");
            return 1;
        }
    };
    let mut peer = Peer { common, ctx: Some(ctx), unit, timeout };
    let (addr, qty) = (opts.address, opts.quantity);
    let mut lat: Vec<u64> = Vec::with_capacity(usize::try_from(opts.count).unwrap_or(0));
    let mut errors: u64 = 0;
    let start = Instant::now(); // CLOCK_MONOTONIC on Linux
    for _ in 0..opts.count {
        let t0 = Instant::now();
        let r = peer.run(|c| c.read_holding_registers(addr, qty)).await;
        lat.push(u64::try_from(t0.elapsed().as_nanos()).unwrap_or(u64::MAX));
        if !matches!(r, Ok(Ok(ref v)) if v.len() == usize::from(qty)) {
            errors += 1;
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let (user, sys) = rusage_seconds();
    lat.sort_unstable();
    #[allow(clippy::cast_precision_loss)]
    let tps = if seconds > 0.0 { opts.count as f64 / seconds } else { 0.0 };
    println!(
        "{{\"transactions\":{},\"errors\":{errors},\"seconds\":{seconds:.6},\"tps\":{tps:.1},\
         \"p50_us\":{:.1},\"p99_us\":{:.1},\"user_s\":{user:.6},\"sys_s\":{sys:.6}}}",
        opts.count,
        percentile_us(&lat, 50),
        percentile_us(&lat, 99),
    );
    if let Some(mut ctx) = peer.ctx.take() {
        let _ = ctx.disconnect().await;
    }
    0
}
