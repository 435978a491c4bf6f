//! Errors as the user sees them, and the exit codes scripts rely on.
//!
//! Every failure ends as a [`CliError`], which keeps the library's typed error, and is
//! rendered once, in [`report`], with what to check next. The codes:
//!
//! | code | meaning |
//! |---|---|
//! | 0 | success |
//! | 1 | the device answered with an exception |
//! | 2 | usage error (bad option, value, address or count) |
//! | 3 | timeout: no reply |
//! | 4 | IO error opening or using the port; the port is held by another process |
//! | 5 | bad reply (malformed, or not answering the request); `crc --check` on a bad CRC |
//! | 6 | output error: stdout or an output file could not be written (e.g. disk full); or stderr, by a command that otherwise succeeded |
//! | 7 | incomplete: some parameters could not be read or written (backup, restore; the output says which) |
//! | 130 | interrupted (Ctrl-C or SIGTERM), after writing what was done |
//! | 141 | stdout was closed by its reader (`| head`): the command ends quietly, as if by SIGPIPE |

use std::io;
use std::time::Duration;

use ferrobus::Error;
use ferrobus::port::PortFault;
use ferrobus_proto::master::HeardInstead;
use ferrobus_proto::{ExceptionCode, FunctionCode, PduError};
use ferrobus_tools::gateway::GatewayError;

use crate::target::Target;

/// The exit codes, as listed in `ferrobus --help`.
pub(crate) const EXIT_CODES_HELP: &str = "\
Exit codes:
  0  success
  1  the device answered with an exception (e.g. 0x02 Illegal Data Address)
     (diff: the device and the file, or the two files, differ)
  2  usage error: bad option, value, address or count
  3  timeout: no reply from the device
  4  IO error opening or using the port or connection, or the port is in use by another process
  5  bad reply: malformed, or not answering the request (also: crc --check on a bad CRC)
  6  output error: stdout or an output file could not be written (e.g. disk full);
     or stderr, by a command that otherwise succeeded (a failure keeps its own code)
  7  incomplete: some parameters could not be read or written (backup, diff, restore say which)
  130  interrupted by Ctrl-C (SIGINT) or SIGTERM, after writing what was done
  141  stdout closed by its reader (e.g. `| head -1`): ends quietly, as if by SIGPIPE";

/// Why the process exits, as a code.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[repr(u8)]
pub(crate) enum Exit {
    /// 0.
    Success = 0,
    /// 1: the device answered with an exception.
    Exception = 1,
    /// 2: the command line is wrong.
    Usage = 2,
    /// 3: no reply.
    Timeout = 3,
    /// 4: the port or connection failed.
    Io = 4,
    /// 5: a reply came but was wrong.
    BadReply = 5,
    /// 6: stdout or an output file could not be written.
    Output = 6,
    /// 7: some parameters could not be read or written; the output says which.
    Incomplete = 7,
    /// 130 (128 + SIGINT): interrupted, after writing what was done.
    Interrupted = 130,
    /// 141 (128 + SIGPIPE): the reader of stdout went away.
    BrokenPipe = 141,
}

impl From<Exit> for std::process::ExitCode {
    fn from(exit: Exit) -> Self {
        std::process::ExitCode::from(exit as u8)
    }
}

/// Everything a command can fail with.
#[derive(Debug)]
pub(crate) enum CliError {
    /// An error from the library: exception, timeout, IO, bad reply, invalid request.
    Modbus {
        /// The error.
        error: Error,
    },
    /// A request that the spec does not allow, refused before it was sent.
    Pdu(PduError),
    /// Something on the command line that cannot work.
    Usage(String),
    /// None of --port, --tcp, --rtu-tcp.
    MissingTarget,
    /// The gateway's routes send a unit to a line it does not have.
    Routing {
        /// The unit, as clients address it.
        unit: u8,
        /// The line it was routed to.
        line: usize,
        /// How many lines there are.
        lines: usize,
    },
    /// The TCP connection did not open in time.
    ConnectTimeout {
        /// What was being opened.
        target: String,
        /// How long we waited.
        waited: Duration,
    },
    /// A reply that parsed but is wrong (an echo that differs), or a frame with a bad CRC.
    BadData(String),
    /// Writing the results failed: stdout (a full disk, a closed pipe) or an output file.
    Output {
        /// What was being written: "stdout", or the file.
        what: String,
        /// Why it failed.
        source: io::Error,
    },
    /// SIGINT or SIGTERM came; what was done has been written.
    Interrupted,
    /// `diff` found differences (exit 1, like diff(1)); they have been listed.
    Differ,
    /// Some parameters could not be read or written; what was done has been listed.
    Incomplete(String),
    /// The device refused some of the work with exceptions, each already explained (in the
    /// profile's words); the message sums them up.
    Refused(String),
}

impl From<Error> for CliError {
    fn from(error: Error) -> Self {
        match error {
            Error::InvalidRequest(e) => CliError::Pdu(e),
            error => CliError::Modbus { error },
        }
    }
}

/// A routing mistake is the settings' (exit 2); a line that cannot be opened, the port's.
impl From<GatewayError> for CliError {
    fn from(error: GatewayError) -> Self {
        match error {
            GatewayError::Routing { unit, line, lines } => CliError::Routing { unit, line, lines },
            GatewayError::Io { source, .. } => source.into(),
            // A kind of failure this build does not know yet: as the library tells it.
            other => CliError::Modbus { error: Error::io("starting the gateway", io::Error::other(other.to_string())) },
        }
    }
}

impl From<PduError> for CliError {
    fn from(e: PduError) -> Self {
        CliError::Pdu(e)
    }
}

impl CliError {
    /// The exit code.
    pub(crate) fn exit(&self) -> Exit {
        match self {
            CliError::Modbus { error } => match error {
                Error::Exception { .. } => Exit::Exception,
                Error::Timeout { .. } | Error::Backoff { .. } | Error::NoReply { .. } => Exit::Timeout,
                Error::BadReply { .. } => Exit::BadReply,
                Error::InvalidRequest(_) | Error::BroadcastRead { .. } => Exit::Usage,
                // Io, NotSameDevice, Closed, and any kind of failure this build does not know
                // yet: the port's or the connection's.
                _ => Exit::Io,
            },
            CliError::Pdu(_) | CliError::Usage(_) | CliError::MissingTarget | CliError::Routing { .. } => Exit::Usage,
            CliError::ConnectTimeout { .. } => Exit::Io,
            CliError::BadData(_) => Exit::BadReply,
            CliError::Output { source, .. } if source.kind() == io::ErrorKind::BrokenPipe => Exit::BrokenPipe,
            CliError::Output { .. } => Exit::Output,
            CliError::Interrupted => Exit::Interrupted,
            CliError::Differ | CliError::Refused(_) => Exit::Exception,
            CliError::Incomplete(_) => Exit::Incomplete,
        }
    }
}

/// The message and the hints for an error.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(crate) struct Report {
    /// One line saying what went wrong.
    pub(crate) message: String,
    /// What to check, one item per line.
    pub(crate) hints: Vec<String>,
}

impl Report {
    /// Prints the report to stderr; an empty message prints nothing.
    pub(crate) fn print(&self) {
        if self.message.is_empty() {
            return;
        }
        eprintln!("error: {}", self.message);
        match self.hints.as_slice() {
            [] => {}
            [one] => eprintln!("hint: {one}"),
            many => {
                eprintln!("check:");
                for hint in many {
                    eprintln!("  - {hint}");
                }
            }
        }
    }
}

/// How the command's addresses were numbered: the hint for an address the device refused
/// (exception 02) says what to change in that mode, not in another.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub(crate) enum Numbering {
    /// Plain wire addresses.
    #[default]
    Wire,
    /// `--one-based`: a manual's register numbers.
    OneBased,
    /// The `--device` profile (named here) numbers its registers from 1.
    Device(String),
    /// `--modicon`: Modicon references.
    Modicon,
}

/// The report for `error`; `target` and `unit` (if a bus was named) sharpen the hints, the
/// addresses taken as wire addresses.
pub(crate) fn report(error: &CliError, target: Option<&Target>, unit: u8) -> Report {
    report_numbered(error, target, unit, &Numbering::Wire)
}

/// [`report`], for a command whose addresses were numbered as `numbering` says.
pub(crate) fn report_numbered(error: &CliError, target: Option<&Target>, unit: u8, numbering: &Numbering) -> Report {
    match error {
        CliError::Modbus { error } => modbus_report(error, target, unit, numbering),
        CliError::Pdu(e) => Report { message: format!("invalid request: {}", pdu_words(e)), hints: Vec::new() },
        CliError::Usage(message)
        | CliError::BadData(message)
        | CliError::Incomplete(message)
        | CliError::Refused(message) => Report { message: message.clone(), hints: Vec::new() },
        CliError::MissingTarget => Report {
            message: "no bus given: use one of --port PATH, --tcp HOST[:PORT] or --rtu-tcp HOST:PORT".into(),
            hints: Vec::new(),
        },
        CliError::Routing { unit, line, lines } => Report {
            message: format!("unit {unit} is routed to line {line}, but there are {lines} lines (numbered from 0)"),
            hints: vec![format!(
                "lines are numbered from 0 in the order given (--port, then each --line; or the [[line]]s of \
                 --lines-file): route unit {unit} to one of 0-{}",
                lines.saturating_sub(1)
            )],
        },
        CliError::ConnectTimeout { target, waited } => Report {
            message: format!("connecting to {target} timed out after {} ms", waited.as_millis()),
            hints: vec!["check that the host is reachable (ping) and the port is right (Modbus/TCP: 502)".into()],
        },
        // The reader of a pipe went away (`| head`): nothing to say, as tools killed by SIGPIPE.
        CliError::Output { source, .. } if source.kind() == io::ErrorKind::BrokenPipe => {
            Report { message: String::new(), hints: Vec::new() }
        }
        CliError::Output { what, source } => Report {
            message: format!("cannot write {what}: {source}"),
            hints: match source.kind() {
                io::ErrorKind::StorageFull => vec!["the disk is full: free some space or write elsewhere".into()],
                _ => Vec::new(),
            },
        },
        CliError::Interrupted => Report { message: "interrupted".into(), hints: Vec::new() },
        CliError::Differ => Report { message: String::new(), hints: Vec::new() },
    }
}

/// A request error in plain words.
pub(crate) fn pdu_words(e: &PduError) -> String {
    match *e {
        PduError::QuantityOutOfRange { quantity, min, max } => {
            format!("a count of {quantity} is out of range: one request carries {min} to {max}")
        }
        PduError::AddressOverflow { start, quantity } => {
            format!("{quantity} items from address {start} run past the last address, 65535")
        }
        PduError::TooLong { len } => format!("the request would be {len} bytes; a Modbus PDU holds at most 253"),
        other => other.to_string(),
    }
}

fn modbus_report(error: &Error, target: Option<&Target>, unit: u8, numbering: &Numbering) -> Report {
    let on = target.map(|t| format!(" on {t}")).unwrap_or_default();
    match error {
        Error::Exception { function, code, .. } => {
            Report { message: error.to_string(), hints: exception_hints(*function, *code, target, numbering) }
        }
        Error::Timeout { heard: Some(heard), .. } => {
            Report { message: format!("{error}{on}"), hints: heard_hints(heard, target, unit) }
        }
        Error::Timeout { .. } | Error::Backoff { .. } => {
            Report { message: format!("{error}{on}"), hints: timeout_hints(target, unit) }
        }
        Error::BadReply { .. } => {
            let mut hints = vec![
                "another master on the bus, two devices with the same address, or a wrong baud rate garbling frames"
                    .to_string(),
            ];
            if let Some(Target::Serial { ascii: false, .. }) = target {
                hints.push("USB adapters split frames: try --low-latency or a longer --t35".into());
            }
            hints.push("`ferrobus raw` shows the reply bytes as they came".into());
            Report { message: format!("{error}{on}"), hints }
        }
        Error::Io { source, .. } => Report { message: error.to_string(), hints: io_hint(source, target) },
        Error::InvalidRequest(e) => Report { message: format!("invalid request: {}", pdu_words(e)), hints: Vec::new() },
        Error::NotSameDevice { .. } => Report {
            message: error.to_string(),
            hints: vec![
                "a stable name is reopened whatever it leads to: /dev/serial/by-id/..., a udev rule's name, \
                         socat's link="
                    .into(),
            ],
        },
        Error::PortBusy { holder, .. } => Report {
            message: error.to_string(),
            hints: vec![match holder {
                Some(holder) => format!(
                    "one master per port: stop process {} first (two programs on one port take each other's replies)",
                    holder.pid
                ),
                None => "one master per port: close the program that has it open (a terminal, another ferrobus, a \
                         vendor tool); two programs on one port take each other's replies"
                    .into(),
            }],
        },
        Error::BroadcastRead { .. } => {
            Report { message: error.to_string(), hints: vec!["address one device: --unit 1-247".into()] }
        }
        _ => Report { message: error.to_string(), hints: Vec::new() },
    }
}

/// What a timeout usually means on a drive bus.
fn timeout_hints(target: Option<&Target>, unit: u8) -> Vec<String> {
    let mut hints = Vec::new();
    if let Some(Target::Serial { line, .. }) = target {
        hints.push(format!("the unit address: --unit {unit} must match the device's station number"));
        hints.push(format!("baud rate and parity: this is {line}; the device must use the same (e.g. 8E1 vs 8N1)"));
        hints.push("wiring: swap A and B if unsure; common ground".into());
        hints.push("termination: 120 ohm at both ends of a long line".into());
    } else {
        hints.push(format!(
            "the unit id: --unit {unit}; a gateway passes it on as the serial address (some devices want 255 or 0)"
        ));
        hints.push("behind a gateway: its baud rate and parity (e.g. 8E1 vs 8N1), wiring A/B, termination".into());
    }
    hints.push("the device's response wait time (3G3RX C078, up to 1000 ms): raise --timeout above it".into());
    hints
}

/// What to check when something came instead of the reply: the checklist for what it was.
fn heard_hints(heard: &HeardInstead, target: Option<&Target>, unit: u8) -> Vec<String> {
    let trace = "-vvv traces every byte sent and received".to_string();
    let mut hints = Vec::new();
    match heard {
        // Bytes damaged on the way: the line, not the device.
        HeardInstead::BadChecksum { .. } | HeardInstead::Garbage { .. } => match target {
            Some(Target::Tcp(_) | Target::Mbaps(_)) => {
                hints.push(
                    "what came is not Modbus/TCP: is this an RTU-over-TCP gateway (--rtu-tcp), or another protocol \
                     on this port?"
                        .into(),
                );
            }
            Some(Target::Serial { line, ascii, .. }) => {
                hints.push("noise: shielded twisted pair, common ground, away from motor and power cables".into());
                hints.push("termination: 120 ohm at both ends of a long line, and only there".into());
                hints.push(format!(
                    "baud rate and parity: this is {line}; a device set otherwise (e.g. 8E1 vs 8N1) garbles every frame"
                ));
                if !ascii && matches!(heard, HeardInstead::Garbage { .. }) {
                    hints.push("USB adapters split frames: try --low-latency or a longer --t35".into());
                }
            }
            Some(Target::RtuTcp(_)) | None => {
                hints.push(
                    "noise or termination on the serial line, or a baud rate or parity mismatch (e.g. 8E1 vs 8N1) \
                     between the gateway and the device"
                        .into(),
                );
            }
        },
        HeardInstead::OtherUnit { unit: other, .. } => {
            hints.push(format!(
                "unit {other} answered while unit {unit} was asked: is the device at address {other} (--unit {other})? \
                 Two devices with one address, or another master on the bus, look the same"
            ));
            if !matches!(target, Some(Target::Serial { .. })) {
                hints.push("some gateways answer under another unit id (0 or 255)".into());
            }
        }
        HeardInstead::OtherTransaction { .. } => {
            hints.push(
                "a late reply to an earlier request: the device answers after --timeout, raise it; or a gateway \
                 that does not echo transaction ids"
                    .into(),
            );
        }
        HeardInstead::TooEarly { .. } => {
            hints.push(
                "a reply was already on its way when the request left: a stale reply to an earlier request (an \
                 interrupted command, another master on the line), dropped; try again"
                    .into(),
            );
        }
        HeardInstead::Suspect { .. } => {
            hints.push(
                "the unit usually answers far sooner: a reply this late is most likely one to an earlier request \
                 that timed out, dropped. If the device is now this slow, raise --timeout (and --late-window)"
                    .into(),
            );
        }
        HeardInstead::WrongFunction { .. } => {
            hints.push(
                "the unit is talking but did not answer this request: it may not support the function or the \
                 quantity asked, or the reply is a late one to an earlier request"
                    .into(),
            );
        }
    }
    hints.push(trace);
    hints
}

/// What an exception usually means; over TCP a gateway or server in between may have
/// answered it, and its hint names the setting there that lets the request through (a hint
/// that suggests another request is given only where that request may be let through).
fn exception_hints(
    function: FunctionCode,
    code: ExceptionCode,
    target: Option<&Target>,
    numbering: &Numbering,
) -> Vec<String> {
    match (code.value(), target) {
        (0x01, Some(Target::Mbaps(_))) => vec![refused_by_role(function)],
        (0x01, Some(Target::Tcp(_) | Target::RtuTcp(_))) => {
            let mut hints: Vec<String> = exception_hint(function, code, numbering).into_iter().collect();
            hints.push(refused_by_gateway(function));
            hints
        }
        (0x0A, Some(Target::Tcp(_) | Target::RtuTcp(_) | Target::Mbaps(_))) => vec![
            "a gateway has no path to the unit: check --unit and the gateway's line to it (a serial line or a \
             Modbus/TCP device); `ferrobus gateway` answers 0x0A too for a unit outside its --route or \
             --allow-units: add the unit there"
                .into(),
        ],
        _ => exception_hint(function, code, numbering).into_iter().collect(),
    }
}

/// Exception 01 over Modbus/TCP may be a gateway's rule: the settings of `ferrobus gateway`
/// that let the request through.
fn refused_by_gateway(function: FunctionCode) -> String {
    let code = function.value();
    let settings = if changes_data(function) {
        format!("run it without --read-only, and with {code} in --allow-functions if it has one")
    } else {
        format!("add {code} to its --allow-functions")
    };
    format!("or a gateway in front of the device keeps function {code} out (`ferrobus gateway`: {settings})")
}

/// Whether a role needs write access for `function`, and a read-only gateway refuses it:
/// the writes (0x17 among them) and 0x08 (some sub-functions restart or silence).
fn changes_data(function: FunctionCode) -> bool {
    function.is_write() || function == FunctionCode::Diagnostics
}

/// Exception 01 from a Modbus/TCP Security server: most often the role in our certificate
/// may not make the request (MB-TCP-Security R-31). No other request is suggested: the same
/// role would be refused it too.
fn refused_by_role(function: FunctionCode) -> String {
    let access = if changes_data(function) { "access = \"read-write\", " } else { "" };
    format!(
        "a Modbus/TCP Security server answers 01 to what the role in your certificate may not do: use a certificate \
         whose role the server's roles file (--roles) gives {access}function {} and this unit and address, or have \
         that role's entry allow them (the server's log names the role and the request it denied)",
        function.value()
    )
}

fn exception_hint(function: FunctionCode, code: ExceptionCode, numbering: &Numbering) -> Option<String> {
    let hint = match code.value() {
        0x02 => return Some(illegal_address_hint(numbering)),
        0x01 if function == FunctionCode::WriteSingleRegister => {
            "the device does not support FC06; try --multiple to write with FC10 (as the SDP servos need)"
        }
        0x01 => "the device does not support this function code",
        0x03 => return Some(illegal_value_hint(function)),
        0x04 => "the device failed while executing the request",
        0x05 | 0x06 => "the device is busy with a long operation; retry later",
        0x0A => {
            "a gateway has no path to the unit: check --unit and the gateway's line to it (a serial line or a \
                 Modbus/TCP device)"
        }
        0x0B => {
            "the device behind a gateway did not answer it: check --unit, and that the device is on and reachable \
                 from the gateway (on a serial line: wiring, baud rate and parity; over Modbus/TCP: its address)"
        }
        0x21 => "Hitachi/Omron inverters: value out of the inverter's range",
        0x22 => "Hitachi/Omron inverters: not allowed in this state (e.g. while running, or a read-only register)",
        0x23 => "Hitachi/Omron inverters: the parameter is read-only",
        0x25 => "Hitachi/Omron inverters: the parameter belongs to the other mode (VT/CT)",
        0x26 => "Hitachi/Omron inverters: busy saving to EEPROM or initialising; retry",
        0x27 => "Hitachi inverters: only half of a 2-register parameter was accessed; use both (--type u32)",
        _ => return None,
    };
    Some(hint.to_string())
}

/// Exception 02: the address, or address + count, is not on the device; what may be wrong
/// depends on how the addresses were numbered.
fn illegal_address_hint(numbering: &Numbering) -> String {
    const NOT_ON: &str = "the address, or address + count, is not on the device";
    match numbering {
        Numbering::Wire => {
            format!("{NOT_ON}; if the manual numbers registers from 1, add --one-based (frame address = number - 1)")
        }
        Numbering::OneBased => format!(
            "{NOT_ON}; with --one-based the frame address is the number - 1: check the number in the manual, or \
             leave --one-based out if it is a wire address"
        ),
        Numbering::Device(device) => format!(
            "{NOT_ON}; addresses are numbered from 1 as the {device} profile says (frame address = number - 1): \
             check the number in the manual, or name the parameter (`ferrobus profile show` lists them)"
        ),
        Numbering::Modicon => format!(
            "{NOT_ON}; with --modicon the reference's digits after the table digit are the 1-based number: check it \
             in the device's register map"
        ),
    }
}

/// Exception 03 means a count for a read and a value (or a count) for a write: the hint
/// depends on what was asked, with the 3G3RX's limit for that function.
fn illegal_value_hint(function: FunctionCode) -> String {
    match function {
        FunctionCode::ReadCoils | FunctionCode::ReadDiscreteInputs => {
            "the device refused the count: some read only a few bits per request (3G3RX: 32 coils) - try \
             --max-per-request"
        }
        FunctionCode::ReadHoldingRegisters | FunctionCode::ReadInputRegisters => {
            "the device refused the count: some read only a few registers per request (3G3RX: 4) - try \
             --max-per-request"
        }
        FunctionCode::WriteSingleCoil | FunctionCode::WriteSingleRegister | FunctionCode::MaskWriteRegister => {
            "the device refused the value: out of the parameter's range or format (check its limits in the manual)"
        }
        FunctionCode::WriteMultipleCoils => {
            "the device refused a value or the count: some write only a few coils per request (3G3RX: 32) - try \
             --max-per-request"
        }
        FunctionCode::WriteMultipleRegisters | FunctionCode::ReadWriteMultipleRegisters => {
            "the device refused a value or the count: check the values against the parameter's range; some take \
             only a few registers per request (3G3RX: 4) - try --max-per-request"
        }
        FunctionCode::Diagnostics => {
            "the device refused the sub-function's data (many drives answer only 08/00, the echo)"
        }
        _ => "the device refused a value or a count in the request",
    }
    .to_string()
}

fn io_hint(source: &io::Error, target: Option<&Target>) -> Vec<String> {
    let path = match target {
        Some(Target::Serial { path, .. }) => Some(path.as_str()),
        _ => None,
    };
    // What the OS's code says of a port's trouble (its numbers differ: ferrobus asks).
    let fault = path.and_then(|_| PortFault::of(source));
    let hint = match (source.kind(), fault, path) {
        _ if source.get_ref().and_then(|e| e.downcast_ref::<ferrobus::TlsAnswer>()).is_some() => {
            "connect with --tls and --ca FILE (the CA of the server's certificate), and --cert FILE --key FILE: \
             an mbaps server requires a client certificate; a --tcp host without a port is then port 802"
                .to_string()
        }
        // First: Windows says a COM port another program has is access denied.
        (_, Some(PortFault::Busy), Some(path)) => format!("another program has the port open (fuser {path})"),
        (io::ErrorKind::PermissionDenied, _, _) => {
            "add yourself to the dialout group (sudo usermod -aG dialout $USER), then log in again".to_string()
        }
        (io::ErrorKind::NotFound, _, Some(_)) => {
            "check the path; is the adapter plugged in? (ls /dev/serial/by-id/)".to_string()
        }
        (_, Some(PortFault::NotSerial), Some(_)) => "this is not a serial port".to_string(),
        (io::ErrorKind::InvalidInput | io::ErrorKind::Other, _, Some(_)) => {
            "the port refused these settings: check that it supports the baud rate, data bits and parity \
             (a pty takes neither parity nor 7 data bits)"
                .to_string()
        }
        (io::ErrorKind::ConnectionRefused, _, _) => {
            "nothing listens there: check the host and port (Modbus/TCP uses 502) and that the server runs".to_string()
        }
        // EOF, or what reading an unplugged USB adapter gives (EIO on Linux).
        (io::ErrorKind::UnexpectedEof | io::ErrorKind::ConnectionReset, _, Some(_))
        | (_, Some(PortFault::Gone), Some(_)) => {
            "the port went away: was the adapter unplugged? (ls /dev/serial/by-id/)".to_string()
        }
        (io::ErrorKind::UnexpectedEof | io::ErrorKind::ConnectionReset, _, None) => {
            "the server closed the connection (it may take one client at a time)".to_string()
        }
        (io::ErrorKind::HostUnreachable | io::ErrorKind::NetworkUnreachable | io::ErrorKind::TimedOut, _, _) => {
            "check that the host is reachable (ping) and on the same network".to_string()
        }
        _ => return Vec::new(),
    };
    vec![hint]
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn exit_codes_follow_the_error_kind() {
        let exception = CliError::from(Error::Exception {
            unit: 1,
            function: FunctionCode::ReadHoldingRegisters,
            code: ExceptionCode::IllegalDataAddress,
        });
        assert_eq!(exception.exit(), Exit::Exception);
        let timeout =
            CliError::from(Error::Timeout { unit: 1, timeout: Duration::from_millis(5), attempts: 1, heard: None });
        assert_eq!(timeout.exit(), Exit::Timeout);
        let io = CliError::from(Error::Io { context: "x".into(), source: Arc::new(io::ErrorKind::NotFound.into()) });
        assert_eq!(io.exit(), Exit::Io);
        assert_eq!(CliError::from(PduError::Empty).exit(), Exit::Usage);
        assert_eq!(CliError::from(Error::InvalidRequest(PduError::Empty)).exit(), Exit::Usage);
        assert_eq!(CliError::BadData("x".into()).exit(), Exit::BadReply);
        let full = CliError::Output { what: "stdout".into(), source: io::ErrorKind::StorageFull.into() };
        assert_eq!(full.exit(), Exit::Output);
        let pipe = CliError::Output { what: "stdout".into(), source: io::ErrorKind::BrokenPipe.into() };
        assert_eq!(pipe.exit(), Exit::BrokenPipe);
        assert_eq!(CliError::Interrupted.exit(), Exit::Interrupted);
    }

    #[test]
    fn a_gateway_routing_mistake_is_a_usage_error_with_the_lines_named_and_a_port_failure_an_io_error() {
        let routing = CliError::from(GatewayError::Routing { unit: 7, line: 2, lines: 2 });
        assert_eq!(routing.exit(), Exit::Usage);
        let r = report(&routing, None, 1);
        assert_eq!(r.message, "unit 7 is routed to line 2, but there are 2 lines (numbered from 0)");
        assert!(r.hints[0].contains("route unit 7 to one of 0-1"), "{:?}", r.hints);
        let source =
            Error::Io { context: "opening /dev/ttyUSB0".into(), source: Arc::new(io::ErrorKind::NotFound.into()) };
        let port = CliError::from(GatewayError::Io { line: 0, source });
        assert_eq!(port.exit(), Exit::Io);
        let r = report(&port, Some(&serial()), 1);
        assert!(r.message.starts_with("opening /dev/ttyUSB0"), "{}", r.message);
        assert!(r.hints.iter().any(|h| h.contains("is the adapter plugged in")), "{:?}", r.hints);
    }

    #[test]
    fn a_closed_pipe_is_reported_with_no_message_and_a_full_disk_with_one() {
        let pipe = CliError::Output { what: "stdout".into(), source: io::ErrorKind::BrokenPipe.into() };
        assert_eq!(report(&pipe, None, 1).message, "");
        let full = CliError::Output { what: "stdout".into(), source: io::Error::from_raw_os_error(28) };
        let r = report(&full, None, 1);
        assert!(r.message.starts_with("cannot write stdout: No space left on device"), "{}", r.message);
        assert!(r.hints[0].contains("disk is full"), "{:?}", r.hints);
    }

    #[test]
    fn vendor_exceptions_get_the_inverter_hints() {
        let e = Error::Exception {
            unit: 1,
            function: FunctionCode::WriteSingleRegister,
            code: ExceptionCode::from_u8(0x21),
        };
        let r = report(&CliError::from(e), None, 1);
        assert!(r.message.contains("exception 0x21 (vendor-specific)"));
        assert!(r.hints[0].contains("value out of the inverter's range"));
    }

    fn serial() -> Target {
        let line = ferrobus_proto::frame::LineConfig::new(9600).unwrap();
        Target::Serial { path: "/dev/ttyUSB0".into(), line, ascii: false }
    }

    fn timeout(heard: Option<HeardInstead>) -> CliError {
        CliError::from(Error::Timeout { unit: 2, timeout: Duration::from_millis(300), attempts: 1, heard })
    }

    fn exception_hints_on(function: FunctionCode, code: u8, target: &Target) -> String {
        let e = Error::Exception { unit: 1, function, code: ExceptionCode::from_u8(code) };
        report(&CliError::from(e), Some(target), 1).hints.join("\n")
    }

    #[test]
    fn a_refusal_through_a_role_or_a_gateway_rule_names_the_setting_that_lets_it_through() {
        let fc06 = FunctionCode::WriteSingleRegister;
        let direct = exception_hints_on(fc06, 0x01, &serial());
        assert!(direct.contains("try --multiple"), "{direct}");
        // A role that may not write is refused FC10 as well: nothing but the role is offered.
        let mbaps = exception_hints_on(fc06, 0x01, &Target::Mbaps("127.0.0.1:802".into()));
        assert!(!mbaps.contains("--multiple"), "{mbaps}");
        assert!(mbaps.contains("access = \"read-write\", function 6"), "{mbaps}");
        let read = exception_hints_on(FunctionCode::ReadInputRegisters, 0x01, &Target::Mbaps("h:802".into()));
        assert!(read.contains("gives function 4 and this unit"), "{read}");
        let tcp = Target::Tcp("127.0.0.1:502".into());
        let gateway = exception_hints_on(fc06, 0x01, &tcp);
        assert!(gateway.contains("without --read-only, and with 6 in --allow-functions"), "{gateway}");
        let read = exception_hints_on(FunctionCode::ReadCoils, 0x01, &tcp);
        assert!(read.contains("add 1 to its --allow-functions") && !read.contains("--read-only"), "{read}");
        let path = exception_hints_on(FunctionCode::ReadCoils, 0x0A, &tcp);
        assert!(path.contains("--route or --allow-units"), "{path}");
        // The device behind a gateway may be on a serial line or on Modbus/TCP.
        assert!(path.contains("a serial line or a Modbus/TCP device"), "{path}");
        let silent = exception_hints_on(FunctionCode::ReadCoils, 0x0B, &tcp);
        assert!(silent.contains("did not answer") && silent.contains("over Modbus/TCP: its address"), "{silent}");
    }

    fn exception_03(function: FunctionCode) -> String {
        let e = Error::Exception { unit: 1, function, code: ExceptionCode::IllegalDataValue };
        report(&CliError::from(e), None, 1).hints.join("\n")
    }

    #[test]
    fn exception_03_hints_name_the_limit_of_the_function_asked_or_the_value() {
        assert!(exception_03(FunctionCode::ReadCoils).contains("3G3RX: 32 coils"));
        assert!(!exception_03(FunctionCode::ReadCoils).contains("registers"));
        assert!(exception_03(FunctionCode::ReadHoldingRegisters).contains("(3G3RX: 4)"));
        let single = exception_03(FunctionCode::WriteSingleRegister);
        assert!(single.contains("refused the value: out of the parameter's range"), "{single}");
        assert!(!single.contains("3G3RX") && !single.contains("--max-per-request"), "{single}");
        assert!(exception_03(FunctionCode::WriteMultipleCoils).contains("3G3RX: 32"));
        assert!(exception_03(FunctionCode::WriteMultipleRegisters).contains("range"));
        assert!(exception_03(FunctionCode::Diagnostics).contains("08/00"));
    }

    #[test]
    fn a_bad_checksum_gets_the_line_checklist_not_the_silence_one() {
        let heard = HeardInstead::BadChecksum { head: Some((2, 0x03)), expected: (2, 0x03) };
        let r = report(&timeout(Some(heard)), Some(&serial()), 2);
        assert_eq!(timeout(Some(heard)).exit(), Exit::Timeout);
        assert!(r.message.contains("unit 2 answered, but the checksum was wrong"), "{}", r.message);
        let hints = r.hints.join("\n");
        assert!(hints.contains("noise") && hints.contains("termination") && hints.contains("9600 8E1"), "{hints}");
        assert!(!hints.contains("swap A and B") && !hints.contains("C078"), "{hints}");
        // Silence keeps the wiring, unit and response-wait checklist.
        let hints = report(&timeout(None), Some(&serial()), 2).hints.join("\n");
        assert!(hints.contains("swap A and B") && hints.contains("--unit 2") && hints.contains("C078"), "{hints}");
    }

    #[test]
    fn what_came_instead_picks_the_hint() {
        let tcp = Target::Tcp("127.0.0.1:502".into());
        let garbage = HeardInstead::Garbage { bytes: 9, reason: ferrobus_proto::DiscardReason::BadHeader };
        let hints = report(&timeout(Some(garbage)), Some(&tcp), 2).hints.join("\n");
        assert!(hints.contains("--rtu-tcp") && !hints.contains("USB"), "{hints}");
        let other = HeardInstead::OtherUnit { unit: 3, function: 0x03 };
        let hints = report(&timeout(Some(other)), Some(&serial()), 2).hints.join("\n");
        assert!(hints.contains("unit 3 answered while unit 2 was asked") && hints.contains("--unit 3"), "{hints}");
        let late = HeardInstead::OtherTransaction { transaction: 4, expected: 5 };
        let hints = report(&timeout(Some(late)), Some(&tcp), 2).hints.join("\n");
        assert!(hints.contains("late reply") && hints.contains("transaction ids"), "{hints}");
        let wrong = HeardInstead::WrongFunction { function: 0x80, expected: 0x03 };
        assert!(report(&timeout(Some(wrong)), Some(&tcp), 2).hints[0].contains("did not answer this request"));
    }

    #[test]
    fn usb_and_connection_hints_only_for_their_transport() {
        let bad = || {
            CliError::from(Error::BadReply {
                unit: 1,
                error: ferrobus_proto::master::MasterError::Mismatch { field: "byte count", expected: 4, received: 2 },
            })
        };
        let tcp = Target::Tcp("127.0.0.1:502".into());
        assert!(!report(&bad(), Some(&tcp), 1).hints.join("\n").contains("USB"));
        assert!(report(&bad(), Some(&serial()), 1).hints.join("\n").contains("--low-latency"));
        let eof = || CliError::from(Error::io("reading from x", io::ErrorKind::UnexpectedEof.into()));
        let serial_hint = report(&eof(), Some(&serial()), 1).hints.join("\n");
        assert!(serial_hint.contains("adapter unplugged") && !serial_hint.contains("server"), "{serial_hint}");
        assert!(report(&eof(), Some(&tcp), 1).hints[0].contains("the server closed the connection"));
        // EIO on Unix, ERROR_BAD_COMMAND on Windows: the platform's code for an adapter gone.
        let gone = if cfg!(windows) { 22 } else { 5 };
        let eio = CliError::from(Error::io("reading from x", io::Error::from_raw_os_error(gone)));
        assert!(report(&eio, Some(&serial()), 1).hints[0].contains("adapter unplugged"));
    }

    #[test]
    fn a_port_another_program_has_gets_its_hint_by_the_platforms_code_and_not_the_dialout_one() {
        // EBUSY on Unix; ERROR_ACCESS_DENIED on Windows, whose kind is PermissionDenied.
        let busy = if cfg!(windows) { 5 } else { 16 };
        let e = CliError::from(Error::io("opening /dev/ttyUSB0", io::Error::from_raw_os_error(busy)));
        let hints = report(&e, Some(&serial()), 1).hints;
        assert!(hints[0].starts_with("another program has the port open"), "{hints:?}");
        assert!(!hints.join("\n").contains("dialout"), "{hints:?}");
        let tcp = Target::Tcp("127.0.0.1:502".into());
        assert!(report(&e, Some(&tcp), 1).hints.iter().all(|h| !h.contains("another program")), "a port's code only");
    }

    #[test]
    fn plain_words_for_counts() {
        let e = PduError::QuantityOutOfRange { quantity: 0, min: 1, max: 125 };
        assert_eq!(pdu_words(&e), "a count of 0 is out of range: one request carries 1 to 125");
    }
}
