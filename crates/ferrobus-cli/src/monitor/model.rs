//! The monitor's state: read definitions (panes) with their cells, counters, the traffic log
//! and the trends. No IO and no clock: times are handed in, so the screens can be tested.

use std::collections::VecDeque;
use std::time::Duration;

use ferrobus_profile::{Access, Order, Point, Table, Value, ValueType, WireWrite, WriteRules};

/// How many traffic lines are kept.
pub(crate) const TRAFFIC_KEPT: usize = 500;
/// How many samples a trend keeps.
pub(crate) const TREND_KEPT: usize = 120;

/// How one cell shows its registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Format {
    /// The profile point's own type, scaling, unit and meanings.
    Named,
    /// One register, unsigned.
    U16,
    /// One register, signed.
    I16,
    /// One register in hex.
    Hex,
    /// One register in binary.
    Binary,
    /// Two registers, unsigned, in an order.
    U32(Order),
    /// Two registers, signed.
    I32(Order),
    /// Two registers, IEEE 754 single.
    F32(Order),
    /// Four registers, IEEE 754 double.
    F64(Order),
}

impl Format {
    /// The formats `f` cycles through for a raw register.
    const CYCLE: [Format; 8] = [
        Format::U16,
        Format::I16,
        Format::Hex,
        Format::Binary,
        Format::U32(Order::Abcd),
        Format::I32(Order::Abcd),
        Format::F32(Order::Abcd),
        Format::F64(Order::Abcd),
    ];

    /// The order of a multi-register format.
    pub(crate) fn order(self) -> Option<Order> {
        match self {
            Format::U32(o) | Format::I32(o) | Format::F32(o) | Format::F64(o) => Some(o),
            _ => None,
        }
    }

    /// The same format in another order (single-register formats have none).
    pub(crate) fn with_order(self, order: Order) -> Format {
        match self {
            Format::U32(_) => Format::U32(order),
            Format::I32(_) => Format::I32(order),
            Format::F32(_) => Format::F32(order),
            Format::F64(_) => Format::F64(order),
            other => other,
        }
    }

    /// The next format of the cycle (a named point's own format is not in it).
    pub(crate) fn next(self) -> Format {
        let order = self.order().unwrap_or_default();
        let at = Format::CYCLE.iter().position(|f| f.with_order(order) == self);
        let next = at.map_or(0, |i| (i + 1) % Format::CYCLE.len());
        Format::CYCLE.get(next).copied().unwrap_or(Format::U16).with_order(order)
    }

    /// The next of the four orders, for a multi-register format.
    pub(crate) fn next_order(self) -> Format {
        let Some(order) = self.order() else { return self };
        let at = Order::ALL.iter().position(|o| *o == order).unwrap_or(0);
        self.with_order(Order::ALL.get((at + 1) % Order::ALL.len()).copied().unwrap_or_default())
    }

    /// The short name shown in the grid and the session file: `u16`, `f32:CDAB`.
    pub(crate) fn name(self) -> String {
        let (ty, order) = match self {
            Format::Named => return "named".into(),
            Format::U16 => return "u16".into(),
            Format::I16 => return "i16".into(),
            Format::Hex => return "hex".into(),
            Format::Binary => return "bin".into(),
            Format::U32(o) => ("u32", o),
            Format::I32(o) => ("i32", o),
            Format::F32(o) => ("f32", o),
            Format::F64(o) => ("f64", o),
        };
        format!("{ty}:{}", order.name())
    }

    /// Parses [`Format::name`]'s text (the order defaults to ABCD).
    pub(crate) fn parse(text: &str) -> Result<Format, String> {
        let (ty, order) = match text.split_once(':') {
            Some((ty, order)) => (
                ty,
                Order::from_name(order)
                    .ok_or_else(|| format!("'{order}' is not an order: use ABCD, CDAB, BADC or DCBA"))?,
            ),
            None => (text, Order::Abcd),
        };
        let single =
            |f: Format| if text.contains(':') { Err(format!("{ty} is one register: it has no order")) } else { Ok(f) };
        match ty.to_ascii_lowercase().as_str() {
            "named" => single(Format::Named),
            "u16" => single(Format::U16),
            "i16" => single(Format::I16),
            "hex" => single(Format::Hex),
            "bin" | "binary" => single(Format::Binary),
            "u32" => Ok(Format::U32(order)),
            "i32" => Ok(Format::I32(order)),
            "f32" => Ok(Format::F32(order)),
            "f64" => Ok(Format::F64(order)),
            _ => Err(format!(
                "'{ty}' is not a format: use u16, i16, hex, bin, u32, i32, f32 or f64 (with :ABCD, :CDAB, :BADC or :DCBA)"
            )),
        }
    }

    /// The value type the profile's codec decodes this format with.
    fn value_type(self) -> ValueType {
        match self {
            Format::Named | Format::U16 | Format::Hex | Format::Binary => ValueType::U16,
            Format::I16 => ValueType::I16,
            Format::U32(_) => ValueType::U32,
            Format::I32(_) => ValueType::I32,
            Format::F32(_) => ValueType::F32,
            Format::F64(_) => ValueType::F64,
        }
    }
}

/// A point for a raw register or bit: what the profile's codec needs to decode, show, parse
/// and check a write of it (any value of its type, read/write where the table allows).
pub(crate) fn raw_point(table: Table, address: u16, format: Format) -> Point {
    Point {
        order: format.order().unwrap_or_default(),
        access: if matches!(table, Table::Coils | Table::Holding) { Access::Rw } else { Access::Ro },
        ..Point::raw(table, address, format.value_type())
    }
}

/// One cell of a grid: a value at an address, its format and alias.
#[derive(Clone, Debug)]
pub(crate) struct Cell {
    /// What the codec decodes it as (a profile's point, or [`raw_point`]).
    pub(crate) point: Point,
    /// How it is shown.
    pub(crate) format: Format,
    /// A name the user gave it (a profile point's label or code by default).
    pub(crate) alias: String,
    /// Whether its values go to the trend chart.
    pub(crate) trended: bool,
}

impl Cell {
    /// The offset of its first register or bit in `pane`'s data.
    pub(crate) fn offset(&self, pane: &Definition) -> Option<usize> {
        usize::from(self.point.address).checked_sub(usize::from(pane.address))
    }

    /// The text of the cell from the pane's last data, or `None` before the first good read.
    pub(crate) fn show(&self, pane: &Definition) -> Option<String> {
        let raw = self.raw(pane)?;
        Some(match (self.format, &raw) {
            (Format::Hex, Value::Int(n)) => format!("{n:#06x}"),
            (Format::Binary, Value::Int(n)) => {
                let n = u16::try_from(*n).unwrap_or(0);
                format!("{:04b} {:04b} {:04b} {:04b}", n >> 12, (n >> 8) & 0xF, (n >> 4) & 0xF, n & 0xF)
            }
            // The shortest text that reads back as the same f32, not its f64's digits.
            #[allow(clippy::cast_possible_truncation)]
            (Format::F32(_), Value::Float(x)) => format!("{}", *x as f32),
            _ => self.point.show(&raw),
        })
    }

    /// The raw value from the pane's data.
    pub(crate) fn raw(&self, pane: &Definition) -> Option<Value> {
        let start = self.offset(pane)?;
        let end = start.checked_add(usize::from(self.point.width))?;
        if !pane.seen.get(start..end)?.iter().all(|s| *s) {
            return None;
        }
        if self.point.value_type == ValueType::Bit {
            return pane.bits.get(start).map(|b| Value::Bool(*b));
        }
        let words = pane.registers.get(start..end)?;
        self.point.decode(words).ok()
    }

    /// The engineering value for the trend.
    pub(crate) fn number(&self, pane: &Definition) -> Option<f64> {
        let raw = self.raw(pane)?;
        match raw {
            Value::Bool(b) => Some(f64::from(u8::from(b))),
            other => self.point.engineering(&other),
        }
    }

    /// Shows the cell in `format` instead (a raw register's point follows it).
    pub(crate) fn set_format(&mut self, format: Format) {
        if self.format == Format::Named || self.point.value_type == ValueType::Bit {
            return;
        }
        self.format = format;
        let table = self.point.table;
        let address = self.point.address;
        self.point = raw_point(table, address, format);
    }
}

/// Failures by kind, as the status line counts them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Counters {
    /// Requests sent.
    pub(crate) tx: u64,
    /// Good replies.
    pub(crate) ok: u64,
    /// No reply in time (silence, or bytes that made no reply).
    pub(crate) timeouts: u64,
    /// A reply with a bad CRC (or LRC) and nothing better.
    pub(crate) crc: u64,
    /// An exception reply.
    pub(crate) exceptions: u64,
    /// Anything else: a lost port, a malformed reply.
    pub(crate) other: u64,
}

impl Counters {
    /// All failures.
    pub(crate) fn errors(&self) -> u64 {
        self.timeouts.saturating_add(self.crc).saturating_add(self.exceptions).saturating_add(self.other)
    }
}

/// What a poll came to.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Outcome {
    /// Registers read.
    Registers(Vec<u16>),
    /// Bits read.
    Bits(Vec<bool>),
    /// No reply in time.
    Timeout(String),
    /// A bad checksum was all that came.
    Crc(String),
    /// An exception reply, with its code's name.
    Exception(String),
    /// Anything else.
    Other(String),
}

/// One read definition: a pane.
#[derive(Clone, Debug)]
pub(crate) struct Definition {
    /// The unit asked.
    pub(crate) unit: u8,
    /// The table read.
    pub(crate) table: Table,
    /// The first address read.
    pub(crate) address: u16,
    /// Registers or bits the pane covers.
    pub(crate) count: u16,
    /// The read requests that fill it, (first address, count) each: the range itself for a
    /// raw pane, the planner's reads for profile points.
    pub(crate) reads: Vec<(u16, u16)>,
    /// How often.
    pub(crate) every: Duration,
    /// The cells shown.
    pub(crate) cells: Vec<Cell>,
    /// The last registers read (holding, input).
    pub(crate) registers: Vec<u16>,
    /// The last bits read (coils, discrete).
    pub(crate) bits: Vec<bool>,
    /// Which of the pane's items a good reply has filled.
    pub(crate) seen: Vec<bool>,
    /// The counters.
    pub(crate) counters: Counters,
    /// The last response time.
    pub(crate) last_response: Option<Duration>,
    /// The last failure, for the status line.
    pub(crate) last_error: Option<String>,
}

impl Definition {
    /// A raw definition: one u16 cell per register (one per bit).
    pub(crate) fn raw(unit: u8, table: Table, address: u16, count: u16, every: Duration) -> Definition {
        let cells = (0..count)
            .filter_map(|i| address.checked_add(i))
            .map(|a| Cell {
                point: raw_point(table, a, Format::U16),
                format: Format::U16,
                alias: String::new(),
                trended: false,
            })
            .collect();
        Definition::with_cells(unit, table, address, count, every, cells)
    }

    /// A definition over `cells` (all in `table`, within `address .. address + count`).
    pub(crate) fn with_cells(
        unit: u8,
        table: Table,
        address: u16,
        count: u16,
        every: Duration,
        cells: Vec<Cell>,
    ) -> Definition {
        Definition {
            unit,
            table,
            address,
            count,
            reads: vec![(address, count)],
            every,
            cells,
            registers: Vec::new(),
            bits: Vec::new(),
            seen: Vec::new(),
            counters: Counters::default(),
            last_response: None,
            last_error: None,
        }
    }

    /// Whether it reads bits.
    pub(crate) fn is_bits(&self) -> bool {
        matches!(self.table, Table::Coils | Table::DiscreteInputs)
    }

    /// The table's name.
    pub(crate) fn table_name(&self) -> &'static str {
        match self.table {
            Table::Coils => "coils",
            Table::DiscreteInputs => "discrete",
            Table::Holding => "holding",
            Table::Input => "input",
        }
    }

    /// Counts a poll's outcome of the read over the whole pane and keeps its data.
    #[cfg(test)]
    pub(crate) fn record(&mut self, outcome: Outcome, response: Duration) {
        self.record_at(self.address, outcome, response);
    }

    /// Counts a poll's outcome of the read from `start` and keeps its data in its place.
    pub(crate) fn record_at(&mut self, start: u16, outcome: Outcome, response: Duration) {
        let from = usize::from(start.saturating_sub(self.address));
        let size = usize::from(self.count);
        let c = &mut self.counters;
        c.tx = c.tx.saturating_add(1);
        match outcome {
            Outcome::Registers(r) => {
                c.ok = c.ok.saturating_add(1);
                self.registers.resize(size, 0);
                self.seen.resize(size, false);
                for (i, word) in r.into_iter().enumerate() {
                    let at = from.saturating_add(i);
                    if let (Some(slot), Some(seen)) = (self.registers.get_mut(at), self.seen.get_mut(at)) {
                        *slot = word;
                        *seen = true;
                    }
                }
                self.last_response = Some(response);
            }
            Outcome::Bits(b) => {
                c.ok = c.ok.saturating_add(1);
                self.bits.resize(size, false);
                self.seen.resize(size, false);
                for (i, bit) in b.into_iter().enumerate() {
                    let at = from.saturating_add(i);
                    if let (Some(slot), Some(seen)) = (self.bits.get_mut(at), self.seen.get_mut(at)) {
                        *slot = bit;
                        *seen = true;
                    }
                }
                self.last_response = Some(response);
            }
            Outcome::Timeout(e) => {
                c.timeouts = c.timeouts.saturating_add(1);
                self.last_error = Some(e);
            }
            Outcome::Crc(e) => {
                c.crc = c.crc.saturating_add(1);
                self.last_error = Some(e);
            }
            Outcome::Exception(e) => {
                c.exceptions = c.exceptions.saturating_add(1);
                self.last_error = Some(e);
                self.last_response = Some(response);
            }
            Outcome::Other(e) => {
                c.other = c.other.saturating_add(1);
                self.last_error = Some(e);
            }
        }
    }
}

/// One line of the traffic pane.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct TrafficLine {
    /// Time since the monitor started.
    pub(crate) at: Duration,
    /// `Tx`, `Rx` or `--` (nothing came).
    pub(crate) direction: &'static str,
    /// The unit.
    pub(crate) unit: u8,
    /// The PDU bytes (function code first).
    pub(crate) bytes: Vec<u8>,
    /// What they mean.
    pub(crate) decode: String,
}

/// The traffic pane's log: the last [`TRAFFIC_KEPT`] lines, a pause and a scroll position.
#[derive(Clone, Debug, Default)]
pub(crate) struct Traffic {
    /// The lines, oldest first.
    pub(crate) lines: VecDeque<TrafficLine>,
    /// While paused, new lines are not added (the count of those dropped is kept).
    pub(crate) paused: bool,
    /// Lines not shown because the pane was paused.
    pub(crate) missed: u64,
    /// How many lines up from the newest the view is scrolled.
    pub(crate) scroll: usize,
}

impl Traffic {
    /// Adds a line unless paused.
    pub(crate) fn push(&mut self, line: TrafficLine) {
        if self.paused {
            self.missed = self.missed.saturating_add(1);
            return;
        }
        if self.lines.len() >= TRAFFIC_KEPT {
            self.lines.pop_front();
        }
        self.lines.push_back(line);
    }
}

/// A cell's samples for the trend chart.
#[derive(Clone, Debug)]
pub(crate) struct Trend {
    /// The pane and cell.
    pub(crate) pane: usize,
    /// The cell in the pane.
    pub(crate) cell: usize,
    /// (seconds since start, value), oldest first.
    pub(crate) samples: VecDeque<(f64, f64)>,
}

/// What the keyboard is doing.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Mode {
    /// Moving around.
    Normal,
    /// Typing a new value for the selected cell.
    Edit(String),
    /// Typing an alias for the selected cell.
    Alias(String),
    /// Asking to confirm the request that writes the text typed.
    Confirm {
        /// What the user typed.
        text: String,
        /// Its raw value, for the write guard.
        raw: Value,
        /// The request that writes it ([`Point::wire_write`] with [`App::rules`]).
        request: WireWrite,
    },
}

/// The whole monitor.
#[derive(Clone, Debug)]
pub(crate) struct App {
    /// The panes.
    pub(crate) panes: Vec<Definition>,
    /// The pane with the cursor.
    pub(crate) pane: usize,
    /// The cell with the cursor.
    pub(crate) cell: usize,
    /// Whether polling is paused.
    pub(crate) paused: bool,
    /// The traffic log.
    pub(crate) traffic: Traffic,
    /// The trended cells.
    pub(crate) trends: Vec<Trend>,
    /// The keyboard's mode.
    pub(crate) mode: Mode,
    /// A message for the user (a refused write, a saved session).
    pub(crate) message: Option<String>,
    /// What the bus is (`tcp 127.0.0.1:502`).
    pub(crate) target: String,
    /// Set by `q`.
    pub(crate) quit: bool,
    /// The columns of the focused pane's grid as last drawn (Up and Down move by a row).
    pub(crate) columns: std::cell::Cell<usize>,
    /// What the device takes in its writes: its profile's, or the spec's.
    pub(crate) rules: WriteRules,
}

impl App {
    /// A monitor over `panes`, writing with the spec's functions and limits until told the
    /// device's ([`App::rules`]).
    pub(crate) fn new(target: String, panes: Vec<Definition>) -> App {
        let trends = panes
            .iter()
            .enumerate()
            .flat_map(|(p, def)| {
                def.cells.iter().enumerate().filter(|(_, c)| c.trended).map(move |(cell, _)| Trend {
                    pane: p,
                    cell,
                    samples: VecDeque::new(),
                })
            })
            .collect();
        App {
            panes,
            pane: 0,
            cell: 0,
            paused: false,
            traffic: Traffic::default(),
            trends,
            mode: Mode::Normal,
            message: None,
            target,
            quit: false,
            columns: std::cell::Cell::new(1),
            rules: WriteRules::SPEC,
        }
    }

    /// The selected pane and cell.
    pub(crate) fn selected(&self) -> Option<(&Definition, &Cell)> {
        let pane = self.panes.get(self.pane)?;
        Some((pane, pane.cells.get(self.cell)?))
    }

    /// Resets every pane's counters.
    pub(crate) fn reset_counters(&mut self) {
        for pane in &mut self.panes {
            pane.counters = Counters::default();
            pane.last_response = None;
            pane.last_error = None;
        }
        self.traffic.missed = 0;
    }

    /// Adds the trended cells' values of pane `index` at `at`.
    pub(crate) fn sample(&mut self, index: usize, at: Duration) {
        let Some(pane) = self.panes.get(index) else { return };
        for trend in self.trends.iter_mut().filter(|t| t.pane == index) {
            let Some(value) = pane.cells.get(trend.cell).and_then(|c| c.number(pane)) else { continue };
            if trend.samples.len() >= TREND_KEPT {
                trend.samples.pop_front();
            }
            trend.samples.push_back((at.as_secs_f64(), value));
        }
    }

    /// Starts or stops trending the selected cell.
    pub(crate) fn toggle_trend(&mut self) {
        let (pane, cell) = (self.pane, self.cell);
        let Some(c) = self.panes.get_mut(pane).and_then(|p| p.cells.get_mut(cell)) else { return };
        c.trended = !c.trended;
        if c.trended {
            self.trends.push(Trend { pane, cell, samples: VecDeque::new() });
        } else {
            self.trends.retain(|t| (t.pane, t.cell) != (pane, cell));
        }
    }
}
