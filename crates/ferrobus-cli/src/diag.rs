//! `ferrobus diag`: serial line diagnostics (FC08 sub-functions, FC0B, FC0C).
//!
//! Spec: MODBUS Application Protocol V1.1b3 §6.8–6.10. Most drives answer only the echo
//! (sub-function 00); the Hitachi/Omron inverters say so in their manuals.

use clap::{Args, Subcommand, ValueEnum};
use ferrobus_proto::codes::DiagnosticCode;
use ferrobus_proto::slave::event;
use serde_json::json;

use crate::connect::{ConnectArgs, Session};
use crate::exit::CliError;
use crate::hex;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `diag SUBCOMMAND`.
#[derive(Args, Debug)]
pub(crate) struct DiagArgs {
    /// Which diagnostic.
    #[command(subcommand)]
    pub(crate) what: DiagCommand,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// The diagnostics.
#[derive(Subcommand, Debug)]
pub(crate) enum DiagCommand {
    /// Loopback: the device echoes the data (FC08/00)
    Echo {
        /// Data to echo, in hex
        #[arg(long, default_value = "A537")]
        data: String,
    },
    /// Restart communications; the only way out of listen-only mode (FC08/01). A device in
    /// listen-only mode restarts without replying: silence is checked with an echo (FC08/00)
    Restart {
        /// Also clear the comm event log
        #[arg(long = "clear-log")]
        clear_log: bool,
    },
    /// The 16-bit diagnostic register (FC08/02)
    Register,
    /// Change the ASCII end-of-frame character (default LF) (FC08/03)
    Delimiter {
        /// The new delimiter: one character, \n, \r, or 0xNN
        #[arg(long)]
        delimiter: String,
    },
    /// Force listen-only mode: the device stops answering until `diag restart` (FC08/04)
    ListenOnly,
    /// Clear the counters and the diagnostic register (FC08/0A)
    Clear,
    /// One counter (FC08/0B-12)
    Counter {
        /// Which counter: bus-messages (0B), comm-errors (0C), exceptions (0D), server-messages (0E),
        /// no-response (0F), nak (10), busy (11), overruns (12)
        #[arg(value_enum, hide_possible_values = true)]
        which: Counter,
    },
    /// All counters FC08/0B-12, as a table, as of the first read: the tool's own later reads,
    /// which the device counts too, are taken out
    Counters,
    /// Clear the overrun counter and flag (FC08/14)
    ClearOverrun,
    /// Any sub-function, with optional data (FC08/xx)
    Sub {
        /// Sub-function code, e.g. 0x0B
        code: String,
        /// Data in hex [default: 0000]
        #[arg(long)]
        data: Option<String>,
    },
    /// The comm event counter and status (FC0B)
    EventCounter,
    /// The comm event log, each event decoded (FC0C)
    EventLog,
}

/// The counters of sub-functions 0x0B–0x12.
#[derive(ValueEnum, Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Counter {
    // 0B: messages seen on the bus.
    BusMessages,
    // 0C: CRC errors seen on the bus.
    CommErrors,
    // 0D: exception replies sent.
    Exceptions,
    // 0E: messages addressed to the device.
    ServerMessages,
    // 0F: messages the device did not answer.
    NoResponse,
    // 10: negative acknowledgements sent.
    Nak,
    // 11: busy replies sent.
    Busy,
    // 12: messages lost to character overrun.
    Overruns,
}

impl Counter {
    const ALL: [Counter; 8] = [
        Counter::BusMessages,
        Counter::CommErrors,
        Counter::Exceptions,
        Counter::ServerMessages,
        Counter::NoResponse,
        Counter::Nak,
        Counter::Busy,
        Counter::Overruns,
    ];

    fn code(self) -> DiagnosticCode {
        match self {
            Counter::BusMessages => DiagnosticCode::BusMessageCount,
            Counter::CommErrors => DiagnosticCode::BusCommErrorCount,
            Counter::Exceptions => DiagnosticCode::BusExceptionErrorCount,
            Counter::ServerMessages => DiagnosticCode::ServerMessageCount,
            Counter::NoResponse => DiagnosticCode::ServerNoResponseCount,
            Counter::Nak => DiagnosticCode::ServerNakCount,
            Counter::Busy => DiagnosticCode::ServerBusyCount,
            Counter::Overruns => DiagnosticCode::BusCharacterOverrunCount,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Counter::BusMessages => "bus-messages",
            Counter::CommErrors => "comm-errors",
            Counter::Exceptions => "exceptions",
            Counter::ServerMessages => "server-messages",
            Counter::NoResponse => "no-response",
            Counter::Nak => "nak",
            Counter::Busy => "busy",
            Counter::Overruns => "overruns",
        }
    }
}

/// An event byte of the comm event log in words (§6.10).
pub(crate) fn describe_event(byte: u8) -> String {
    let kind = match event::kind(byte) {
        event::Kind::Receive => "receive",
        event::Kind::Send => "send",
        event::Kind::EnteredListenOnly => return "entered listen-only".into(),
        event::Kind::Restart => return "restart".into(),
        event::Kind::Unknown => return "unknown event".into(),
    };
    let words: Vec<&str> = event::flags(byte).collect();
    if words.is_empty() { kind.to_string() } else { format!("{kind}: {}", words.join(", ")) }
}

/// A byte from `c`, `\n`, `\r`, `\t` or `0xNN`.
fn delimiter_byte(text: &str) -> Result<u8, CliError> {
    let byte = match text {
        "\\n" => Some(b'\n'),
        "\\r" => Some(b'\r'),
        "\\t" => Some(b'\t'),
        t if t.starts_with("0x") || t.starts_with("0X") => {
            ferrobus::text::number(t, u64::from(u8::MAX)).ok().and_then(|n| u8::try_from(n).ok())
        }
        t if t.len() == 1 && t.is_ascii() => t.bytes().next(),
        _ => None,
    };
    byte.ok_or_else(|| CliError::Usage(format!("delimiter '{text}' must be one ASCII character, \\n, \\r or 0xNN")))
}

fn sub_code(text: &str) -> Result<DiagnosticCode, CliError> {
    ferrobus::text::number(text, u64::from(u16::MAX))
        .ok()
        .and_then(|n| u16::try_from(n).ok())
        .map(DiagnosticCode::from_u16)
        .ok_or_else(|| CliError::Usage(format!("sub-function '{text}' must be 0-65535 (decimal or 0x hex)")))
}

/// Runs `diag`.
pub(crate) async fn run(connection: &ConnectArgs, args: &DiagArgs) -> Result<(), CliError> {
    if !matches!(args.what, DiagCommand::ListenOnly | DiagCommand::Restart { .. }) {
        connection.refuse_broadcast_read()?;
    }
    // Every input is checked before the bus is opened.
    let data = match &args.what {
        DiagCommand::Echo { data } | DiagCommand::Sub { data: Some(data), .. } => {
            hex::parse_args(&[data]).map_err(|e| CliError::Usage(format!("--data: {e}")))?
        }
        _ => vec![0, 0],
    };
    let delimiter = match &args.what {
        DiagCommand::Delimiter { delimiter } => delimiter_byte(delimiter)?,
        _ => b'\n',
    };
    let sub = match &args.what {
        DiagCommand::Sub { code, .. } => sub_code(code)?,
        _ => DiagnosticCode::ReturnQueryData,
    };
    let session = &connection.open().await?;
    let client = &session.client;
    let unit = session.unit;
    let format = args.output.format();
    let text = match &args.what {
        DiagCommand::Echo { .. } => {
            let echoed = client.diagnostics(unit, DiagnosticCode::ReturnQueryData, &data).await?;
            if echoed != data {
                return Err(CliError::BadData(format!(
                    "unit {unit} echoed {} instead of {}",
                    hex::format(&echoed),
                    hex::format(&data)
                )));
            }
            let said = format!("echo OK (FC08/00): {}", hex::format(&echoed));
            Outcome::new(unit, DiagnosticCode::ReturnQueryData, said, Some(echoed)).render(format)
        }
        DiagCommand::Restart { clear_log } => restart(session, *clear_log).await?.render(format),
        DiagCommand::Register => {
            let sub = DiagnosticCode::ReturnDiagnosticRegister;
            let v = client.diagnostic_word(unit, sub, 0).await?;
            Outcome::word(unit, sub, format!("diagnostic register 0x{v:04X} (0b{v:016b})"), v).render(format)
        }
        DiagCommand::Delimiter { .. } => {
            let sub = DiagnosticCode::ChangeAsciiDelimiter;
            let reply = client.diagnostics(unit, sub, &[delimiter, 0]).await?;
            let said = format!("ASCII delimiter set to 0x{delimiter:02X} (FC08/03)");
            Outcome::new(unit, sub, said, Some(reply)).render(format)
        }
        DiagCommand::ListenOnly => {
            eprintln!(
                "warning: unit {unit} will stop answering (this tool included) until `ferrobus diag restart` \
                 or a power cycle"
            );
            let sub = DiagnosticCode::ForceListenOnly;
            client.diagnostics(unit, sub, &[0, 0]).await?;
            Outcome::new(unit, sub, "listen-only mode forced (FC08/04); no reply expected".into(), None).render(format)
        }
        DiagCommand::Clear => {
            let sub = DiagnosticCode::ClearCounters;
            let v = client.diagnostic_word(unit, sub, 0).await?;
            Outcome::word(unit, sub, "counters and diagnostic register cleared (FC08/0A)".into(), v).render(format)
        }
        DiagCommand::Counter { which } => {
            let v = client.diagnostic_word(unit, which.code(), 0).await?;
            Outcome::word(unit, which.code(), format!("{}: {v}", which.code()), v).render(format)
        }
        DiagCommand::Counters => counters(session, format).await?,
        DiagCommand::ClearOverrun => {
            let sub = DiagnosticCode::ClearOverrunCounter;
            let v = client.diagnostic_word(unit, sub, 0).await?;
            Outcome::word(unit, sub, "overrun counter and flag cleared (FC08/14)".into(), v).render(format)
        }
        DiagCommand::Sub { .. } => {
            let reply = client.diagnostics(unit, sub, &data).await?;
            let said = match *reply.as_slice() {
                [hi, lo] => format!("{sub}: {} (word {})", hex::format(&reply), u16::from_be_bytes([hi, lo])),
                _ => format!("{sub}: {}", hex::format(&reply)),
            };
            Outcome::new(unit, sub, said, Some(reply)).render(format)
        }
        DiagCommand::EventCounter => event_counter(session, format).await?,
        DiagCommand::EventLog => event_log(session, format).await?,
    };
    output::print(&text)?;
    Ok(())
}

/// What a single FC08 request found: a sentence for people, a record for scripts.
struct Outcome {
    unit: u8,
    sub: DiagnosticCode,
    /// What happened, after `unit N: `.
    said: String,
    /// The reply's data field; `None` when no reply comes (listen-only).
    reply: Option<Vec<u8>>,
}

impl Outcome {
    fn new(unit: u8, sub: DiagnosticCode, said: String, reply: Option<Vec<u8>>) -> Self {
        Outcome { unit, sub, said, reply }
    }

    fn word(unit: u8, sub: DiagnosticCode, said: String, word: u16) -> Self {
        Outcome::new(unit, sub, said, Some(word.to_be_bytes().to_vec()))
    }

    /// The reply as one word, when it is one.
    fn reply_word(&self) -> Option<u16> {
        match self.reply.as_deref() {
            Some(&[hi, lo]) => Some(u16::from_be_bytes([hi, lo])),
            _ => None,
        }
    }

    fn render(&self, format: Format) -> String {
        let name = self.sub.name().unwrap_or_default();
        let reply = self.reply.as_deref().map(hex::format);
        match format {
            Format::Table => format!("unit {}: {}\n", self.unit, self.said),
            Format::Json => output::json_line(&json!({
                "unit": self.unit, "function": 0x08, "sub": self.sub.value(), "name": name,
                "reply": reply, "word": self.reply_word(), "result": self.said,
            })),
            Format::Csv => {
                let mut rows = Rows::new(&[
                    ("unit", Align::Right),
                    ("function", Align::Right),
                    ("sub", Align::Right),
                    ("name", Align::Left),
                    ("reply", Align::Left),
                    ("word", Align::Right),
                    ("result", Align::Left),
                ]);
                rows.push(vec![
                    self.unit.to_string(),
                    "8".into(),
                    self.sub.value().to_string(),
                    name.to_string(),
                    reply.unwrap_or_default(),
                    self.reply_word().map(|w| w.to_string()).unwrap_or_default(),
                    self.said.clone(),
                ]);
                rows.csv()
            }
        }
    }
}

/// 0x08/0x01. A device in listen-only mode leaves it on this request without replying (§6.8.1);
/// one not in listen-only mode answers. The tool cannot know which it was, so silence is
/// expected and checked with an echo (0x08/0x00): an answer there means the restart worked.
async fn restart(session: &Session, clear_log: bool) -> Result<Outcome, CliError> {
    let (client, unit) = (&session.client, session.unit);
    let word: u16 = if clear_log { 0xFF00 } else { 0x0000 };
    let sub = DiagnosticCode::RestartCommunications;
    let log = if clear_log { "; event log cleared" } else { "" };
    match client.diagnostics(unit, sub, &word.to_be_bytes()).await {
        Ok(reply) => {
            return Ok(Outcome::new(unit, sub, format!("communications restarted (FC08/01){log}"), Some(reply)));
        }
        // Silence, not a broken reply: what a device in listen-only mode does.
        Err(ferrobus::Error::Timeout { heard: None, .. }) => {}
        Err(e) => return Err(e.into()),
    }
    eprintln!(
        "note: unit {unit} did not answer the restart (FC08/01), as a device in listen-only mode does; \
         checking that it answers an echo (FC08/00) now"
    );
    let probe = [0xA5, 0x37];
    let answer = match client.diagnostics(unit, DiagnosticCode::ReturnQueryData, &probe).await {
        Ok(echoed) if echoed == probe => "it answers the echo (FC08/00) now".to_string(),
        Ok(echoed) => {
            return Err(CliError::BadData(format!(
                "unit {unit} did not answer the restart (FC08/01), and echoed {} instead of {} to the echo \
                 (FC08/00) after it",
                hex::format(&echoed),
                hex::format(&probe)
            )));
        }
        // Refused, but listening: out of listen-only mode all the same.
        Err(ferrobus::Error::Exception { code, .. }) => {
            format!("it answers again (the echo, FC08/00, with exception {code})")
        }
        // The note above says what this error follows.
        Err(e) => return Err(e.into()),
    };
    let said = format!("communications restarted (FC08/01){log}: no reply, as expected in listen-only mode; {answer}");
    Ok(Outcome::new(unit, sub, said, None))
}

/// What the tool's own reads add to each counter: the counters come from eight requests, each
/// of which the device counts, so each is reported as it stood when the first read arrived.
#[derive(Default)]
struct OwnReads {
    /// Reads the device answered so far (normally or with an exception). Read number `i`
    /// counts `i` more of them in a message count than the first read did, whether the device
    /// counts a request on arrival (then the first includes itself) or after answering it.
    answered: u16,
    /// Exception replies to our reads so far, in all, and with 06 (busy) and 07 (NAK).
    exceptions: u16,
    busy: u16,
    nak: u16,
}

impl OwnReads {
    /// How many of our own requests `counter`, read now, has counted since the first read
    /// arrived.
    fn in_count(&self, counter: Counter) -> u16 {
        match counter {
            Counter::BusMessages | Counter::ServerMessages => self.answered,
            Counter::Exceptions => self.exceptions,
            Counter::Busy => self.busy,
            Counter::Nak => self.nak,
            Counter::CommErrors | Counter::NoResponse | Counter::Overruns => 0,
        }
    }

    fn record(&mut self, refused: Option<u8>) {
        self.answered = self.answered.saturating_add(1);
        if let Some(code) = refused {
            self.exceptions = self.exceptions.saturating_add(1);
            match code {
                0x06 => self.busy = self.busy.saturating_add(1),
                0x07 => self.nak = self.nak.saturating_add(1),
                _ => {}
            }
        }
    }
}

/// What the table says below the counts.
const AS_OF_FIRST_READ: &str = "counts as of the first read (0x0B); the tool's own later reads are taken out";

/// Reads every counter; one the device refuses shows its exception (many drives answer only
/// the echo), and only if it refuses them all is that an error. The counts are made one
/// snapshot: see [`OwnReads`].
async fn counters(session: &Session, format: Format) -> Result<String, CliError> {
    let mut rows = Rows::new(&[("sub", Align::Left), ("counter", Align::Left), ("count", Align::Right)]);
    let mut doc = json!({ "unit": session.unit, "function": 0x08, "counters": {}, "as_of": AS_OF_FIRST_READ });
    let mut refused = None;
    let mut own = OwnReads::default();
    for counter in Counter::ALL {
        let code = counter.code();
        let (cell, value) = match session.client.diagnostic_word(session.unit, code, 0).await {
            Ok(v) => {
                let v = v.saturating_sub(own.in_count(counter));
                own.record(None);
                (v.to_string(), v.into())
            }
            Err(e @ ferrobus::Error::Exception { code: exception, .. }) => {
                own.record(Some(exception.value()));
                refused.get_or_insert(e);
                (format!("exception {exception}"), serde_json::Value::Null)
            }
            Err(e) => return Err(e.into()),
        };
        rows.push(vec![format!("0x{:02X}", code.value()), code.name().unwrap_or_default().to_string(), cell]);
        doc["counters"][counter.name()] = value;
    }
    if let (Some(e), true) =
        (refused, doc["counters"].as_object().is_some_and(|c| c.values().all(serde_json::Value::is_null)))
    {
        return Err(e.into());
    }
    Ok(match format {
        Format::Json => output::json_line(&doc),
        Format::Table => format!("{}({AS_OF_FIRST_READ})\n", rows.render(Format::Table)),
        Format::Csv => rows.render(Format::Csv),
    })
}

async fn event_counter(session: &Session, format: Format) -> Result<String, CliError> {
    let unit = session.unit;
    let c = session.client.get_comm_event_counter(unit).await?;
    let status = if c.status == 0xFFFF { "busy" } else { "ready" };
    Ok(match format {
        Format::Json => output::json_line(&json!({
            "unit": unit, "function": 0x0B, "status": c.status, "event_count": c.event_count,
        })),
        Format::Csv => {
            let mut rows = Rows::new(&[
                ("unit", Align::Right),
                ("function", Align::Right),
                ("status", Align::Right),
                ("event_count", Align::Right),
            ]);
            rows.push(vec![unit.to_string(), "11".into(), c.status.to_string(), c.event_count.to_string()]);
            rows.csv()
        }
        Format::Table => format!("unit {unit}: status 0x{:04X} ({status}), event count {}\n", c.status, c.event_count),
    })
}

async fn event_log(session: &Session, format: Format) -> Result<String, CliError> {
    let log = session.client.get_comm_event_log(session.unit).await?;
    let status = if log.status == 0xFFFF { "busy" } else { "ready" };
    if format == Format::Json {
        let events: Vec<_> = log.events.iter().map(|&e| json!({ "byte": e, "event": describe_event(e) })).collect();
        return Ok(output::json_line(&json!({
            "unit": session.unit, "function": 0x0C, "status": log.status, "event_count": log.event_count,
            "message_count": log.message_count, "events": events,
        })));
    }
    let mut rows = Rows::new(&[("age", Align::Right), ("byte", Align::Left), ("event", Align::Left)]);
    for (age, &e) in log.events.iter().enumerate() {
        rows.push(vec![age.to_string(), format!("0x{e:02X}"), describe_event(e)]);
    }
    let body = rows.render(format);
    if format == Format::Csv {
        return Ok(body);
    }
    Ok(format!(
        "unit {}: status 0x{:04X} ({status}), event count {}, message count {}, {} event(s), most recent first\n{body}",
        session.unit,
        log.status,
        log.event_count,
        log.message_count,
        log.events.len(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_bytes_are_decoded_into_words() {
        assert_eq!(describe_event(0xC0), "receive: broadcast");
        assert_eq!(describe_event(0x80), "receive");
        assert_eq!(describe_event(0x41), "send: read exception");
        assert_eq!(describe_event(0x40), "send");
        assert_eq!(describe_event(0x04), "entered listen-only");
        assert_eq!(describe_event(0x00), "restart");
        assert_eq!(describe_event(0xA2), "receive: communication error, in listen-only mode");
        assert_eq!(describe_event(0x01), "unknown event");
    }

    #[test]
    fn own_reads_are_taken_out_whether_a_device_counts_a_request_on_arrival_or_after() {
        // Before the first read, 10 messages and 2 exceptions; our reads of 0C and 0D are
        // refused with 07 (NAK). Each device below reports what it counted when each read came.
        for counts_itself in [true, false] {
            let mut own = OwnReads::default();
            let mut seen = Vec::new();
            let (mut messages, mut exceptions, mut nak) = (10u16, 2u16, 0u16);
            for counter in Counter::ALL {
                if counts_itself {
                    messages += 1;
                }
                let raw = match counter {
                    Counter::BusMessages | Counter::ServerMessages => messages,
                    Counter::Exceptions => exceptions,
                    Counter::Nak => nak,
                    _ => 0,
                };
                seen.push(raw.saturating_sub(own.in_count(counter)));
                if !counts_itself {
                    messages += 1;
                }
                let refused = matches!(counter, Counter::CommErrors | Counter::Exceptions);
                if refused {
                    exceptions += 1;
                    nak += 1;
                }
                own.record(refused.then_some(0x07));
            }
            let first = if counts_itself { 11 } else { 10 };
            // bus, comm errors, exceptions, server, no response, NAK, busy, overruns
            assert_eq!(seen, [first, 0, 2, first, 0, 0, 0, 0], "counts itself: {counts_itself}");
        }
    }

    #[test]
    fn delimiters_and_sub_codes_parse() {
        assert_eq!(delimiter_byte("\\n").unwrap(), b'\n');
        assert_eq!(delimiter_byte("0x0D").unwrap(), 0x0D);
        assert_eq!(delimiter_byte(";").unwrap(), b';');
        assert!(delimiter_byte("ab").is_err());
        assert!(delimiter_byte("0xZZ").is_err());
        assert_eq!(sub_code("0x0B").unwrap(), DiagnosticCode::BusMessageCount);
        assert_eq!(sub_code("11").unwrap(), DiagnosticCode::BusMessageCount);
        assert!(sub_code("70000").is_err());
    }
}
