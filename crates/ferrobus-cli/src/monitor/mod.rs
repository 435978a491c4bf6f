//! `ferrobus monitor`: a terminal UI over the client. One pane per read definition (a grid
//! of cells, each with its format and alias, and a status line of counters), a traffic pane of
//! the PDUs sent and received with their decode, a trend chart for chosen cells, writes in
//! place checked by the cell's point (its type, range and access), pause and reset, and a
//! session file.
//!
//! The state ([`model`]), the drawing ([`view`]) and the keys ([`keys`]) take no IO and no
//! clock, so the screens are snapshot-tested on ratatui's `TestBackend`; this file is the IO:
//! the terminal (raw mode and the alternate screen, restored on exit, on a panic and on
//! SIGTERM), the key reader, the samples of a [`Poller`] (the polling of `ferrobus poll`; the
//! registers are taken from each sample's reply bytes, so a cell's format can change while it
//! runs) and the writes on the client (logged in the traffic pane).

mod keys;
mod model;
mod spec;
mod view;

#[cfg(test)]
mod tests;

use std::io::Write as _;
use std::time::Instant;

use clap::Args;
use ferrobus::Client;
use ferrobus_profile::Profile;
use ferrobus_tools::poll::{Event as PollEvent, Failure, FailureKind, Group, Layout, PollConfig, Poller, Sample};
use ratatui::Terminal;
use ratatui::backend::CrosstermBackend;
use ratatui::crossterm::event::{self, Event};
use ratatui::crossterm::{cursor, execute, terminal};

use crate::address::AddressArgs;
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use model::{App, Definition, Outcome, TrafficLine};

/// `monitor [DEFINITION...]`.
#[derive(Args, Debug)]
#[command(after_help = "DEFINITION is [UNIT:]TABLE:ADDRESS[:COUNT][@RATE] (TABLE = coils, discrete, holding, input; \
    RATE like 250ms or 2s, default 1s), e.g. holding:0x1000:8@250ms or 3:input:0:4, or the two words TABLE ADDRESS \
    with --count (poll's form: holding 0x1000 --count 8); with --device, a point's code or label, a glob (F0*) or \
    group:NAME, with @RATE. ADDRESS is numbered as read and write number it: a wire address, or with --one-based, \
    --modicon or the --device profile's numbering (the 3G3RX's from 1); a range longer than the device takes in \
    one request (the profile's limit) is read in several.\n\n\
    Keys: q quit, Tab next pane, arrows move, e edit (then Enter, then y to write), f format, o word/byte \
    order, a alias, t trend, p pause polling, r reset counters, Space pause traffic, PgUp/PgDn scroll \
    traffic, s save the session.")]
pub(crate) struct MonitorArgs {
    /// What to watch: each definition is a pane
    #[arg(value_name = "DEFINITION")]
    pub(crate) watch: Vec<String>,

    /// A session file (the one `poll --session` takes): loaded at start if it exists and no
    /// DEFINITION is given (what to watch, formats, aliases); written by the `s` key
    #[arg(long, value_name = "FILE")]
    pub(crate) session: Option<String>,

    /// A cell's format: ADDRESS=FORMAT (u16, i16, hex, bin, u32, i32, f32, f64; the wider ones
    /// with :ABCD, :CDAB, :BADC or :DCBA), in every pane that shows ADDRESS
    #[arg(long = "format", value_name = "ADDRESS=FORMAT")]
    pub(crate) formats: Vec<String>,

    /// A cell's alias: ADDRESS=NAME
    #[arg(long = "alias", value_name = "ADDRESS=NAME")]
    pub(crate) aliases: Vec<String>,

    /// Items of each definition written as the two words TABLE ADDRESS (poll's form)
    #[arg(long, value_name = "N")]
    pub(crate) count: Option<u16>,

    /// How ADDRESS is numbered.
    #[command(flatten)]
    pub(crate) address_args: AddressArgs,
}

/// The definitions of the command line, each in one word: `TABLE ADDRESS[@RATE]` (two words,
/// poll's form) becomes `TABLE:ADDRESS[:COUNT][@RATE]` with `--count`.
fn definitions(args: &MonitorArgs) -> Result<Vec<String>, CliError> {
    let mut out = Vec::new();
    let mut words = args.watch.iter();
    while let Some(word) = words.next() {
        if crate::address::Table::from_name(word).is_none() {
            out.push(word.clone());
            continue;
        }
        let address = words.next().ok_or_else(|| CliError::Usage(format!("{word} needs an ADDRESS after it")))?;
        let (address, rate) = address.split_once('@').map_or((address.as_str(), None), |(a, r)| (a, Some(r)));
        let count = args.count.map(|n| format!(":{n}")).unwrap_or_default();
        let rate = rate.map(|r| format!("@{r}")).unwrap_or_default();
        out.push(format!("{word}:{address}{count}{rate}"));
    }
    Ok(out)
}

/// Applies `--format` and `--alias`.
fn apply_options(args: &MonitorArgs, panes: &mut [Definition]) -> Result<(), CliError> {
    let split = |text: &str, what: &str, panes: &[Definition]| -> Result<(u16, String), CliError> {
        let (address, value) = text
            .split_once('=')
            .ok_or_else(|| CliError::Usage(format!("--{what} '{text}': use ADDRESS={}", what.to_uppercase())))?;
        let a = address.trim();
        let address = ferrobus::text::number(a, u64::from(u16::MAX))
            .map(|n| u16::try_from(n).unwrap_or(u16::MAX))
            .map_err(|_| CliError::Usage(format!("--{what} '{text}': '{a}' is not an address 0 to 65535")))?;
        let cells = panes.iter().flat_map(|p| p.cells.iter()).filter(|c| c.point.address == address).count();
        if cells == 0 {
            return Err(CliError::Usage(format!("--{what} '{text}': no pane shows address {address:#06x}")));
        }
        Ok((address, value.trim().to_string()))
    };
    for text in &args.formats {
        let (address, format) = split(text, "format", panes)?;
        let format = model::Format::parse(&format).map_err(|e| CliError::Usage(format!("--format '{text}': {e}")))?;
        for cell in panes.iter_mut().flat_map(|p| p.cells.iter_mut()).filter(|c| c.point.address == address) {
            cell.set_format(format);
        }
    }
    for text in &args.aliases {
        let (address, alias) = split(text, "alias", panes)?;
        for cell in panes.iter_mut().flat_map(|p| p.cells.iter_mut()).filter(|c| c.point.address == address) {
            cell.alias.clone_from(&alias);
        }
    }
    Ok(())
}

/// Splits each raw pane's read into the requests the device takes (the `--device` profile's
/// limit, else the spec's); the profile's panes are the planner's already.
fn within_limits(connection: &ConnectArgs, panes: &mut [Definition]) -> Result<(), CliError> {
    for pane in panes.iter_mut().filter(|p| p.cells.iter().all(|c| c.format != model::Format::Named)) {
        let table = crate::address::Table::from(pane.table);
        pane.reads = connection.read_pieces(pane.address, usize::from(pane.count), 1, table, None)?;
    }
    Ok(())
}

/// Runs `monitor`.
pub(crate) async fn run(connection: &ConnectArgs, args: &MonitorArgs) -> Result<(), CliError> {
    let profile = connection.profile()?;
    let unit = connection.unit()?;
    let mut panes = Vec::new();
    let number = |address: &str, table| connection.address(address, table, args.address_args).map(|a| a.wire);
    for definition in definitions(args)? {
        panes.extend(spec::parse_numbered(&definition, unit, profile.as_ref(), &number)?);
    }
    if let Some(path) = &args.session {
        let path = std::path::Path::new(path);
        if args.watch.is_empty() && path.exists() {
            let session = ferrobus_tools::poll::session::Session::load(path)
                .map_err(|e| CliError::Usage(format!("the session file: {e}")))?;
            panes = spec::panes_of(&session, &path.display().to_string())?;
        }
    }
    if panes.is_empty() {
        return Err(CliError::Usage(
            "give what to watch: one or more definitions like holding:0:10@500ms, or --session FILE".into(),
        ));
    }
    apply_options(args, &mut panes)?;
    within_limits(connection, &mut panes)?;
    if !std::io::IsTerminal::is_terminal(&std::io::stdout()) {
        return Err(CliError::Usage("monitor needs a terminal: for a log, use `ferrobus read` in a loop".into()));
    }
    // One poller group per read request of each pane (a pane of profile points may take
    // several: the planner's); `reads` maps a group back to its pane and range.
    let mut groups = Vec::new();
    let mut reads = Vec::new();
    for (index, p) in panes.iter().enumerate() {
        for &(start, count) in &p.reads {
            let name = format!("unit {} {} {start:#06x} ×{count}", p.unit, p.table_name());
            let range = ferrobus_tools::poll::RawRange { unit: p.unit, table: p.table, start, count, every: p.every };
            let group = Group::raw(&name, range, &Layout::default()).map_err(|e| CliError::Usage(e.to_string()))?;
            groups.push(group);
            reads.push(Read { pane: index, start, count });
        }
    }
    let session_client = connection.open().await?;
    let target = session_client.target.to_string();
    // The wire time of a cycle can be predicted on an RTU serial line only (as `poll` does).
    let line = matches!(session_client.target, crate::target::Target::Serial { ascii: false, .. })
        .then(|| *connection.transport(&session_client.target).timing());
    let poller = Poller::start(session_client.client.clone(), groups, PollConfig { line, raw_only: false });
    let mut app = App::new(target, panes);
    app.rules = profile.as_ref().map_or(ferrobus_profile::WriteRules::SPEC, ferrobus_profile::Profile::write_rules);
    let saving = SaveTo { path: args.session.clone(), device: connection.device.clone() };
    let mut screen = Screen::enter().map_err(|e| io_error("setting up the terminal", e))?;
    let bus = Bus { client: &session_client.client, profile: profile.as_ref() };
    let result = event_loop(&mut screen.terminal, &mut app, &bus, poller, &reads, &saving).await;
    drop(screen);
    result
}

/// The read request of one poller group: its pane and range.
#[derive(Clone, Copy, Debug)]
struct Read {
    pane: usize,
    start: u16,
    count: u16,
}

/// What a write goes through: the client, and the `--device` profile whose write guard it
/// passes first.
struct Bus<'a> {
    client: &'a Client,
    profile: Option<&'a Profile>,
}

/// Where `s` saves.
struct SaveTo {
    path: Option<String>,
    device: Option<String>,
}

fn io_error(what: &str, source: std::io::Error) -> CliError {
    CliError::Output { what: what.to_string(), source }
}

/// The terminal in raw mode on the alternate screen; dropping it restores the terminal, and a
/// panic hook does the same before the panic's message is printed.
struct Screen {
    terminal: Terminal<CrosstermBackend<std::io::Stdout>>,
}

/// Leaves raw mode and the alternate screen and shows the cursor (each step tried even if
/// one fails: this runs on the way out).
fn restore() {
    let _ = terminal::disable_raw_mode();
    let _ = execute!(std::io::stdout(), terminal::LeaveAlternateScreen, cursor::Show);
    let _ = std::io::stdout().flush();
}

impl Screen {
    fn enter() -> std::io::Result<Screen> {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            restore();
            previous(info);
        }));
        terminal::enable_raw_mode()?;
        let mut stdout = std::io::stdout();
        if let Err(e) = execute!(stdout, terminal::EnterAlternateScreen, cursor::Hide) {
            restore();
            return Err(e);
        }
        match Terminal::new(CrosstermBackend::new(stdout)) {
            Ok(terminal) => Ok(Screen { terminal }),
            Err(e) => {
                restore();
                Err(e)
            }
        }
    }
}

impl Drop for Screen {
    fn drop(&mut self) {
        restore();
    }
}

/// Resolves when SIGTERM (or SIGHUP, the terminal closing) comes; on Windows, never (a
/// console's close ends the process, and Ctrl-C is a key in raw mode).
#[cfg(unix)]
async fn terminated() {
    use tokio::signal::unix::{SignalKind, signal};
    let (Ok(mut term), Ok(mut hup)) = (signal(SignalKind::terminate()), signal(SignalKind::hangup())) else {
        return std::future::pending().await;
    };
    tokio::select! {
        _ = term.recv() => {}
        _ = hup.recv() => {}
    }
}

#[cfg(not(unix))]
async fn terminated() {
    std::future::pending::<()>().await;
}

/// Keys from a thread that blocks on the terminal.
fn key_reader() -> tokio::sync::mpsc::Receiver<std::io::Result<Event>> {
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    std::thread::spawn(move || {
        loop {
            let event = event::read();
            let failed = event.is_err();
            if tx.blocking_send(event).is_err() || failed {
                return;
            }
        }
    });
    rx
}

async fn event_loop(
    terminal: &mut Terminal<CrosstermBackend<std::io::Stdout>>,
    app: &mut App,
    bus: &Bus<'_>,
    mut poller: Poller,
    reads: &[Read],
    saving: &SaveTo,
) -> Result<(), CliError> {
    let start = Instant::now();
    let handle = poller.handle();
    let mut keys = key_reader();
    let mut stop = std::pin::pin!(terminated());
    loop {
        terminal.draw(|frame| view::draw(frame, app)).map_err(|e| io_error("drawing the screen", e))?;
        if app.quit {
            handle.stop();
            return Ok(());
        }
        tokio::select! {
            key = keys.recv() => match key {
                Some(Ok(Event::Key(key))) => {
                    #[cfg(debug_assertions)]
                    test_panic(key);
                    let was_paused = app.paused;
                    let action = keys::handle(app, key);
                    match (was_paused, app.paused) {
                        (false, true) => handle.pause(),
                        (true, false) => handle.resume(),
                        _ => {}
                    }
                    match action {
                        keys::Action::None => {}
                        keys::Action::Save => save(app, saving),
                        keys::Action::Reset => handle.reset(),
                        keys::Action::Write(asked) => {
                            write(app, bus, start, &asked).await;
                            // Read again at once: a resume polls every group now.
                            if !app.paused {
                                handle.pause();
                                handle.resume();
                            }
                        }
                    }
                }
                Some(Ok(_)) => {}
                Some(Err(e)) => return Err(io_error("reading the keyboard", e)),
                None => return Ok(()),
            },
            event = poller.next() => match event {
                Some(PollEvent::Sample(sample)) => {
                    if let Some(read) = reads.get(sample.group) {
                        take(app, start, *read, &sample);
                    }
                }
                Some(PollEvent::Overload(overload)) => app.message = Some(overload.detail),
                None => return Ok(()),
            },
            () = &mut stop => {
                handle.stop();
                return Ok(());
            }
        }
    }
}

/// Debug builds only (never in a release): with `FERROBUS_MONITOR_TEST_PANIC` set, the `!`
/// key panics, so a test can see the panic hook restore the terminal.
#[cfg(debug_assertions)]
#[allow(clippy::manual_assert)] // a panic on purpose, not an assertion
fn test_panic(key: event::KeyEvent) {
    if key.code == event::KeyCode::Char('!') && std::env::var_os("FERROBUS_MONITOR_TEST_PANIC").is_some() {
        panic!("FERROBUS_MONITOR_TEST_PANIC is set: the monitor panics as the test asked");
    }
}

/// A poll's sample into its pane, the traffic pane and the trends.
fn take(app: &mut App, start: Instant, read: Read, sample: &Sample) {
    let Some(pane) = app.panes.get_mut(read.pane) else { return };
    let unit = pane.unit;
    let pdu = |bytes: &[u8]| bytes.get(1..).unwrap_or_default().to_vec();
    let request = pdu(&sample.traffic.tx);
    let at = sample.started.min(start.elapsed());
    let decode = format!("read {} {:#06x} ×{}", pane.table_name(), read.start, read.count);
    let outcome = match (&sample.result, &sample.traffic.rx) {
        (Ok(_), Some(rx)) => read_reply(pane.is_bits(), read.count, &pdu(rx)),
        (Ok(_), None) => Outcome::Other("no reply".into()),
        (Err(failure), _) => outcome_of(failure),
    };
    let reply = sample.traffic.rx.as_deref().map(pdu).unwrap_or_default();
    let direction = if reply.is_empty() { "--" } else { "Rx" };
    let answer = describe(&outcome);
    pane.record_at(read.start, outcome, sample.response_time);
    app.traffic.push(TrafficLine { at, direction: "Tx", unit, bytes: request, decode });
    let ended = at.saturating_add(sample.response_time);
    app.traffic.push(TrafficLine { at: ended, direction, unit, bytes: reply, decode: answer });
    app.sample(read.pane, ended);
}

fn save(app: &mut App, saving: &SaveTo) {
    let Some(path) = &saving.path else {
        app.message = Some("no --session FILE was given: nothing to save to".into());
        return;
    };
    let session = spec::session_of(saving.device.as_deref(), &app.panes);
    app.message = Some(match session.save(std::path::Path::new(path)) {
        Ok(()) => format!("session saved to {path}"),
        Err(e) => format!("not saved: {e}"),
    });
}

/// Decodes a read reply (function code first) of `count` bits or registers: them, or what is
/// wrong.
fn read_reply(bits: bool, count: u16, reply: &[u8]) -> Outcome {
    let count = usize::from(count);
    let Some((&byte_count, data)) = reply.get(1..).and_then(<[u8]>::split_first) else {
        return Outcome::Other(format!("a reply of {} bytes is too short", reply.len()));
    };
    let want = if bits { count.div_ceil(8) } else { count * 2 };
    if usize::from(byte_count) != want || data.len() != want {
        return Outcome::Other(format!("the reply holds {} bytes of data, not {want}", data.len()));
    }
    if bits {
        Outcome::Bits((0..count).map(|i| data.get(i / 8).is_some_and(|b| b & (1 << (i % 8)) != 0)).collect())
    } else {
        Outcome::Registers(data.chunks_exact(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect())
    }
}

/// The failure by the status line's kinds.
fn outcome_of(failure: &Failure) -> Outcome {
    let text = failure.diagnosis.clone();
    match failure.kind {
        FailureKind::Timeout => Outcome::Timeout(text),
        FailureKind::Crc => Outcome::Crc(text),
        FailureKind::Exception => Outcome::Exception(text),
        _ => Outcome::Other(text),
    }
}

/// The decode of a reply or a failure, for the traffic pane.
fn describe(outcome: &Outcome) -> String {
    match outcome {
        Outcome::Registers(r) => format!("{} registers", r.len()),
        Outcome::Bits(b) => format!("{} bits", b.len()),
        Outcome::Timeout(e) | Outcome::Crc(e) | Outcome::Exception(e) | Outcome::Other(e) => e.clone(),
    }
}

/// Writes what the user confirmed, once the profile's write guard lets it (the one `set`,
/// `restore` and the bridge apply: range, access, and for a run-locked parameter the drive's
/// run state read first), in the request the confirmation showed ([`ferrobus_profile::Point::wire_write`]
/// with the device's functions and limit), sent as every writer sends it
/// ([`ferrobus_tools::write::send`]). A cell of a raw range over a profile's parameter is guarded
/// as that parameter.
async fn write(app: &mut App, bus: &Bus<'_>, start: Instant, asked: &keys::Asked) {
    let keys::Asked { pane, cell, raw, text, request } = asked;
    let (pane, client) = (*pane, bus.client);
    let Some(unit) = app.panes.get(pane).map(|p| p.unit) else { return };
    if let (Some(profile), Some(cell)) = (bus.profile, app.panes.get(pane).and_then(|p| p.cells.get(*cell))) {
        let point = profile
            .points()
            .iter()
            .find(|p| p.table == cell.point.table && p.address == cell.point.address)
            .unwrap_or(&cell.point);
        let write = ferrobus_profile::Write { point, raw, typed: text };
        if let Err(refusal) = ferrobus_tools::guard::check_write(client, unit, profile, &write).await {
            app.message = Some(format!("not written: {refusal}"));
            return;
        }
    }
    let (address, function) = (request.address(), request.function().value());
    let sent = request.request().ok().and_then(|pdu| {
        let mut bytes = vec![0; pdu.encoded_len()];
        let n = pdu.emit(&mut bytes).ok()?;
        bytes.truncate(n);
        Some(bytes)
    });
    let decode = format!("write {address:#06x}");
    app.traffic.push(TrafficLine {
        at: start.elapsed(),
        direction: "Tx",
        unit,
        bytes: sent.unwrap_or_default(),
        decode,
    });
    let result = ferrobus_tools::write::send(client, unit, request).await;
    let (bytes, decode) = match &result {
        Ok(Some(reply)) => (reply.clone(), "written".to_string()),
        Ok(None) => (Vec::new(), "sent".to_string()),
        Err(e @ ferrobus::Error::Exception { code, .. }) => (vec![function | 0x80, code.value()], e.to_string()),
        Err(e) => (Vec::new(), e.to_string()),
    };
    app.message = Some(match &result {
        Ok(_) => format!("wrote {address:#06x} on unit {unit}"),
        Err(e) => format!("not written: {e}"),
    });
    let direction = if bytes.is_empty() { "--" } else { "Rx" };
    app.traffic.push(TrafficLine { at: start.elapsed(), direction, unit, bytes, decode });
}
