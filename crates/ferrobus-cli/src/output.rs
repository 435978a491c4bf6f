//! Output: aligned tables for people, `--csv` and `--json` for scripts.
//!
//! Results go to stdout and nothing else does; notes and errors go to stderr. The columns of
//! a table and of its CSV are the same, so a script can switch between them.

use clap::Args;
use serde_json::{Value, json};

use crate::address::{Address, Style};
use crate::exit::CliError;
use crate::value::{Decoded, ValueArgs, ValueType};

/// The output format options.
#[derive(Args, Clone, Copy, Debug, Default)]
#[command(next_help_heading = "Output")]
pub(crate) struct OutputArgs {
    /// One JSON document on stdout
    #[arg(long, global = true, conflicts_with = "csv")]
    pub(crate) json: bool,

    /// CSV with a header row on stdout
    #[arg(long, global = true)]
    pub(crate) csv: bool,
}

/// The format chosen.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Format {
    /// An aligned table.
    Table,
    /// One JSON document.
    Json,
    /// CSV with a header row.
    Csv,
}

impl OutputArgs {
    /// The format chosen.
    pub(crate) fn format(self) -> Format {
        if self.json {
            Format::Json
        } else if self.csv {
            Format::Csv
        } else {
            Format::Table
        }
    }
}

/// How a column is aligned in a table.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Align {
    /// Text.
    Left,
    /// Numbers.
    Right,
}

/// Rows of text under a header.
#[derive(Clone, Debug, Default)]
pub(crate) struct Rows {
    headers: Vec<(String, Align)>,
    rows: Vec<Vec<String>>,
}

impl Rows {
    /// Rows with these columns.
    pub(crate) fn new(headers: &[(&str, Align)]) -> Self {
        Rows { headers: headers.iter().map(|(h, a)| ((*h).to_string(), *a)).collect(), rows: Vec::new() }
    }

    /// Adds a row (one cell per column), each cell [`printable`]: a table's cells come from
    /// devices, profiles and files.
    pub(crate) fn push(&mut self, row: Vec<String>) {
        self.rows.push(row.into_iter().map(|cell| printable(&cell).into_owned()).collect());
    }

    /// The table with aligned columns, two spaces apart, no trailing spaces.
    pub(crate) fn table(&self) -> String {
        let mut widths: Vec<usize> = self.headers.iter().map(|(h, _)| h.chars().count()).collect();
        for row in &self.rows {
            for (w, cell) in widths.iter_mut().zip(row) {
                *w = (*w).max(cell.chars().count());
            }
        }
        let mut out = String::new();
        let header: Vec<String> = self.headers.iter().map(|(h, _)| h.clone()).collect();
        for row in std::iter::once(&header).chain(&self.rows) {
            let mut line = String::new();
            for (i, ((cell, width), (_, align))) in row.iter().zip(&widths).zip(&self.headers).enumerate() {
                if i > 0 {
                    line.push_str("  ");
                }
                let pad = width.saturating_sub(cell.chars().count());
                match align {
                    Align::Right => {
                        line.push_str(&" ".repeat(pad));
                        line.push_str(cell);
                    }
                    Align::Left => {
                        line.push_str(cell);
                        line.push_str(&" ".repeat(pad));
                    }
                }
            }
            out.push_str(line.trim_end());
            out.push('\n');
        }
        out
    }

    /// CSV (RFC 4180): a header row, then the rows, CRLF-free.
    pub(crate) fn csv(&self) -> String {
        let mut out = String::new();
        let header: Vec<String> = self.headers.iter().map(|(h, _)| h.clone()).collect();
        for row in std::iter::once(&header).chain(&self.rows) {
            let cells: Vec<String> = row.iter().map(|c| csv_field(c)).collect();
            out.push_str(&cells.join(","));
            out.push('\n');
        }
        out
    }

    /// The rows in `format` (JSON is built by the caller).
    pub(crate) fn render(&self, format: Format) -> String {
        match format {
            Format::Csv => self.csv(),
            _ => self.table(),
        }
    }
}

/// A CSV field, [`printable`], quoted if it holds a comma, a quote or a line break (RFC 4180).
pub(crate) fn csv_field(cell: &str) -> String {
    let cell = printable(cell);
    if cell.contains([',', '"', '\n', '\r']) { format!("\"{}\"", cell.replace('"', "\"\"")) } else { cell.into_owned() }
}

/// `text` from outside (a device's string register, a profile's label or unit, a file) as it
/// may reach a terminal: when it holds a control character, a line separator or a
/// bidirectional control, spelled out as a log line spells it ([`ferrobus::log::escape`]:
/// `\u{1b}`, `\n`, backslashes doubled); as it is otherwise.
pub(crate) fn printable(text: &str) -> std::borrow::Cow<'_, str> {
    let escaped = ferrobus::log::escape(text).to_string();
    // The escape adds one character per backslash and more per character it spells out.
    if escaped.len() == text.len() + text.matches('\\').count() {
        std::borrow::Cow::Borrowed(text)
    } else {
        std::borrow::Cow::Owned(escaped)
    }
}

/// The header of the reference column, if the address style has one.
fn ref_header(address: Address) -> Option<&'static str> {
    match address.style {
        Style::Wire => None,
        Style::OneBased | Style::OneBasedHex => Some("number"),
        Style::Modicon(_) => Some("ref"),
    }
}

/// The address cells of a row: wire decimal, wire hex, and the reference if any.
fn address_cells(address: Address, wire: u16) -> Vec<String> {
    let mut cells = vec![wire.to_string(), format!("0x{wire:04X}")];
    cells.extend(address.reference(wire));
    cells
}

fn address_headers(address: Address) -> Vec<(&'static str, Align)> {
    let mut headers = vec![("address", Align::Right), ("addr_hex", Align::Left)];
    headers.extend(ref_header(address).map(|h| (h, Align::Right)));
    headers
}

/// Rows for registers read from `start`: one per register, or one per 32-bit value with
/// both registers shown.
pub(crate) fn register_rows(address: Address, start: u16, registers: &[u16], values: ValueArgs) -> Rows {
    let kind = values.kind;
    let typed = !matches!(kind, ValueType::U16 | ValueType::Hex);
    let mut headers = address_headers(address);
    headers.extend([("hex", Align::Left), ("dec", Align::Right)]);
    if typed {
        headers.push((kind.name(), Align::Right));
    }
    let mut rows = Rows::new(&headers);
    let width = kind.width();
    for (i, (regs, decoded)) in registers.chunks_exact(width).zip(values.decode_all(registers)).enumerate() {
        let wire = u16::try_from(usize::from(start) + i * width).unwrap_or(u16::MAX);
        let mut row = address_cells(address, wire);
        row.push(regs.iter().map(|r| format!("0x{r:04X}")).collect::<Vec<_>>().join(" "));
        row.push(regs.iter().map(u16::to_string).collect::<Vec<_>>().join(" "));
        if typed {
            row.push(decoded.to_string());
        }
        rows.push(row);
    }
    rows
}

/// Rows for bits read from `start`: 0/1 and ON/OFF.
pub(crate) fn bit_rows(address: Address, start: u16, bits: &[bool]) -> Rows {
    let mut headers = address_headers(address);
    headers.extend([("value", Align::Right), ("state", Align::Left)]);
    let mut rows = Rows::new(&headers);
    for (i, &bit) in bits.iter().enumerate() {
        let wire = u16::try_from(usize::from(start) + i).unwrap_or(u16::MAX);
        let mut row = address_cells(address, wire);
        row.push(u8::from(bit).to_string());
        row.push(if bit { "ON" } else { "OFF" }.to_string());
        rows.push(row);
    }
    rows
}

/// The data of a read, for JSON.
#[derive(Clone, Copy, Debug)]
pub(crate) enum ReadData<'a> {
    /// Register values.
    Registers(&'a [u16], ValueArgs),
    /// Bits.
    Bits(&'a [bool]),
}

/// The JSON document of a read: unit, function, start, values (and decoded values for typed
/// registers), and how many requests it took.
pub(crate) fn read_json(unit: u8, function: u8, address: Address, data: ReadData<'_>, requests: usize) -> Value {
    let mut doc = json!({
        "unit": unit,
        "function": function,
        "table": address.table.name(),
        "start": address.wire,
        "requests": requests,
    });
    if let Some(reference) = address.reference(address.wire) {
        doc["start_ref"] = reference.into();
    }
    match data {
        ReadData::Registers(registers, values) => {
            doc["count"] = registers.len().into();
            doc["values"] = registers.to_vec().into();
            if values.kind != ValueType::U16 {
                doc["type"] = values.kind.name().into();
                if values.kind.width() == 2 {
                    doc["word_order"] = values.order().name().into();
                }
                doc["decoded"] = values.decode_all(registers).into_iter().map(Decoded::to_json).collect();
            }
        }
        ReadData::Bits(bits) => {
            doc["count"] = bits.len().into();
            doc["values"] = bits.to_vec().into();
        }
    }
    doc
}

/// Writes `text` to stdout and flushes it. A failure (a full disk, a closed pipe) is an
/// error: [`CliError::Output`], whose exit code tells a closed pipe (141, quietly) from the rest.
pub(crate) fn print(text: &str) -> Result<(), CliError> {
    write_to(&mut std::io::stdout().lock(), "stdout", text)
}

/// Writes `text` to `out` and flushes it; `what` names `out` in the error.
pub(crate) fn write_to(out: &mut impl std::io::Write, what: &str, text: &str) -> Result<(), CliError> {
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|source| CliError::Output { what: what.to_string(), source })
}

/// A raw value of a profile as JSON: a bit as a boolean, an integer as a number (`null` past
/// 64 bits), a float as a number (`null` when it is not one), a text as a string.
pub(crate) fn raw_json(raw: &ferrobus_profile::Value) -> Value {
    match raw {
        ferrobus_profile::Value::Bool(b) => Value::from(*b),
        ferrobus_profile::Value::Int(n) => {
            i64::try_from(*n).map(Value::from).or_else(|_| u64::try_from(*n).map(Value::from)).unwrap_or(Value::Null)
        }
        ferrobus_profile::Value::Float(x) => Value::from(*x),
        ferrobus_profile::Value::Text(s) => Value::from(s.clone()),
    }
}

/// A point's value as a JSON number, as [`ferrobus_profile::Point::number`] writes it: at the
/// point's resolution (34.98, not 34.980000000000004), an unscaled integer as an integer, a
/// bit as 0 or 1; `null` for a text (or a float that is not a number).
pub(crate) fn number_json(point: &ferrobus_profile::Point, raw: &ferrobus_profile::Value) -> Value {
    if matches!(raw, ferrobus_profile::Value::Text(_)) {
        return Value::Null;
    }
    serde_json::from_str::<serde_json::Number>(&point.number(raw)).map_or(Value::Null, Value::Number)
}

/// A JSON document on one line, as printed.
pub(crate) fn json_line(doc: &Value) -> String {
    format!("{doc}\n")
}

/// Writes `text` to `path`, a new file, or over the one there with `force`; a failure names
/// the file, and a file kept says `if_kept` (how to replace it).
pub(crate) fn write_file(path: &std::path::Path, text: &str, force: bool, if_kept: &str) -> Result<(), CliError> {
    let what = path.display().to_string();
    let mut open = std::fs::OpenOptions::new();
    open.write(true);
    if force {
        open.create(true).truncate(true);
    } else {
        open.create_new(true);
    }
    let mut file = open.open(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::AlreadyExists {
            CliError::Usage(format!("{what} exists and is kept: {if_kept}"))
        } else {
            CliError::Output { what: what.clone(), source }
        }
    })?;
    std::io::Write::write_all(&mut file, text.as_bytes())
        .and_then(|()| file.sync_all())
        .map_err(|source| CliError::Output { what, source })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::address::Table;

    #[test]
    fn csv_quotes_only_what_needs_it() {
        assert_eq!(csv_field("plain"), "plain");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
    }

    #[test]
    fn control_characters_in_cells_are_spelled_out_in_tables_and_csv() {
        let mut rows = Rows::new(&[("code", Align::Left), ("unit", Align::Left)]);
        rows.push(vec!["red\u{1b}[31m".into(), "\0°C\u{202e}".into()]);
        rows.push(vec!["C:\\dir".into(), "a\tb".into()]);
        assert_eq!(rows.table(), "code           unit\nred\\u{1b}[31m  \\0°C\\u{202e}\nC:\\dir         a\\tb\n");
        assert_eq!(csv_field("line\nbreak"), "line\\nbreak");
        assert_eq!(printable("plain °C \\ path"), "plain °C \\ path", "nothing to spell out: as it is");
    }

    #[test]
    fn tables_align_numbers_right_and_text_left() {
        let mut rows = Rows::new(&[("n", Align::Right), ("name", Align::Left)]);
        rows.push(vec!["1".into(), "a".into()]);
        rows.push(vec!["100".into(), "bb".into()]);
        assert_eq!(rows.table(), "  n  name\n  1  a\n100  bb\n");
        assert_eq!(rows.csv(), "n,name\n1,a\n100,bb\n");
    }

    #[test]
    fn thirty_two_bit_rows_show_both_registers() {
        let address = Address { wire: 0x10, table: Table::Holding, style: Style::OneBased };
        let values = ValueArgs { kind: ValueType::U32, ..Default::default() };
        let rows = register_rows(address, 0x10, &[0x0004, 0x93E0], values);
        let csv = rows.csv();
        assert_eq!(csv, "address,addr_hex,number,hex,dec,u32\n16,0x0010,17,0x0004 0x93E0,4 37856,300000\n");
    }
}
