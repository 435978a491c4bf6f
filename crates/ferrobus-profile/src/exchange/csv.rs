//! Register lists as CSV: ours (the columns [`export_csv`] writes), and the vendor variants of
//! the same facts under other column names (`Register`, `Data Type`, `Factor`, `R/W`, ...).
//!
//! The header is the first line that is not blank and not a `#` comment; its delimiter (`,`,
//! `;` or a tab, whichever it has most of) is the file's. Only the address column is needed: a
//! row without a name is named after its table and address, a row without a table is a holding
//! register, without a type a u16 (a bit in the bit tables), without an access read/write in
//! the writable tables (coils, holding registers) and read-only in the others.
//! A column of no meaning in a profile is listed once, with how many rows had a value in it.
//!
//! Meters' manuals (Eastron, Carlo Gavazzi, ABB) and the lists made from them number registers
//! Modicon-style: 30001 is input register 0, 40001 holding register 0. A file whose every
//! address is such a number is read so (with a note) unless `--first-address` says how it
//! numbers; an address column headed as hex (`Address (hex)`, `Start reg (Hex)`) is read as
//! hex, `0x` or not. Without a name column, a row is named after its description.

use std::collections::HashMap;

use super::{Draft, Entry, ImportError};
use crate::model::{Access, Order, Profile, Table, ValueType};
use crate::{Point, Value};

/// The columns [`export_csv`] writes, in its order; the import takes them and their aliases.
const COLUMNS: [&str; 18] = [
    "name",
    "table",
    "address",
    "type",
    "length",
    "order",
    "scale",
    "offset",
    "unit",
    "access",
    "min",
    "max",
    "group",
    "label",
    "description",
    "values",
    "bits",
    "default",
];

/// Other names of each column, as vendors' lists and other tools write them (compared in
/// lower case with blanks, `_`, `-`, `.` and `/` removed).
const ALIASES: &[(&str, &[&str])] = &[
    (
        "name",
        &[
            "code",
            "tag",
            "tagname",
            "parameter",
            "parametername",
            "param",
            "point",
            "signal",
            "variable",
            "registername",
            "measurement",
            // ABB's meter lists: the quantity measured ("Active import"); the registers are "Size".
            "quantity",
        ],
    ),
    (
        "table",
        &[
            "registertype",
            "area",
            "objecttype",
            "kind",
            "function",
            "fc",
            "functioncode",
            "modbusfc",
            "modbusfunction",
            "inputtype",
        ],
    ),
    (
        "address",
        &[
            "addr",
            "register",
            "reg",
            "registeraddress",
            "modbusaddress",
            "modbusaddr",
            "modbusregister",
            "modbusregisteraddress",
            "registernumber",
            "registerno",
            "regno",
            "regaddress",
            "startaddress",
            "startingaddress",
            "startreg",
            "startregister",
            "start",
            "number",
            "no",
        ],
    ),
    ("type", &["datatype", "valuetype", "format", "dataformat", "dtype", "encoding"]),
    (
        "length",
        &[
            "registers",
            "words",
            "size",
            "len",
            "lengthwords",
            "numberofregisters",
            "noofregisters",
            "registercount",
            "wordcount",
        ],
    ),
    ("order", &["wordorder", "byteorder", "endian", "endianness", "swap"]),
    ("scale", &["factor", "multiplier", "gain", "scaling", "resolution", "res", "scalefactor"]),
    ("unit", &["units", "uom", "engunit", "engineeringunit", "engineeringunits", "unitofmeasurement"]),
    ("access", &["rw", "mode", "permission", "permissions", "readwrite"]),
    ("min", &["minimum", "minvalue", "low", "rangemin"]),
    ("max", &["maximum", "maxvalue", "high", "rangemax"]),
    ("group", &["category", "section"]),
    ("label", &["title", "displayname", "caption"]),
    ("description", &["desc", "comment", "comments", "notes", "note", "remark", "remarks", "meaning", "details"]),
    ("values", &["enum", "enumeration", "options", "states"]),
    ("bits", &["bitfield", "flags"]),
    ("default", &["defaultvalue", "factorydefault", "initial", "init"]),
];

/// A header cell as compared: lower case, without blanks, `_-./` and brackets.
fn folded(cell: &str) -> String {
    cell.chars().filter(|c| !c.is_whitespace() && !"_-./()[]".contains(*c)).flat_map(char::to_lowercase).collect()
}

/// The column a header cell names, if any, and whether it says its numbers are hex (an
/// address column headed `Address (hex)`, `Hex address`).
fn column_of(cell: &str) -> Option<(&'static str, bool)> {
    let cell = folded(cell);
    let named = |cell: &str| {
        COLUMNS
            .iter()
            .copied()
            .find(|c| *c == cell)
            .or_else(|| ALIASES.iter().find(|(_, aliases)| aliases.contains(&cell)).map(|(column, _)| *column))
    };
    if let Some(column) = named(&cell) {
        return Some((column, false));
    }
    let plain = cell.replacen("hex", "", 1);
    named(&plain).filter(|column| plain != cell && *column == "address").map(|column| (column, true))
}

/// How a file numbers its registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Numbering {
    /// Addresses from this number (the first register's).
    From(u16),
    /// Addresses as hex numbers, from 0.
    Hex,
    /// Modicon register numbers: the first digit the table, the rest from 1.
    Modicon,
}

/// A Modicon register number: five digits (six for the 65536 registers of a table), the first
/// the table's (0 coils, 1 discrete inputs, 3 input registers, 4 holding registers), the rest
/// the register's from 1 — the table and the frame's address.
fn modicon(text: &str) -> Option<(Table, u16)> {
    let text = text.trim();
    if !matches!(text.len(), 5 | 6) || !text.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let table = match text.as_bytes().first()? {
        b'0' => Table::Coils,
        b'1' => Table::DiscreteInputs,
        b'3' => Table::Input,
        b'4' => Table::Holding,
        _ => return None,
    };
    let register: u32 = text.get(1..)?.parse().ok()?;
    let last = if text.len() == 5 { 9999 } else { 0x1_0000 };
    let address = u16::try_from(register.checked_sub(1)?).ok()?;
    (register <= last).then_some((table, address))
}

/// Whether `addresses` (a file's address cells) are Modicon register numbers: every one is,
/// all of one length, and one at least is not a coil's (`00001`-style numbers alone may be
/// plain numbers padded with zeros).
fn all_modicon<'a>(mut addresses: impl Iterator<Item = &'a str>) -> bool {
    let mut length = None;
    let mut registers = false;
    let all = addresses.all(|text| {
        let text = text.trim();
        let Some((table, _)) = modicon(text) else { return false };
        registers |= table != Table::Coils;
        *length.get_or_insert(text.len()) == text.len()
    });
    all && registers
}

/// Reads the CSV `text` into `draft`.
pub(super) fn read(text: &str, draft: &mut Draft) -> Result<(), ImportError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let header_line =
        text.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#')).ok_or_else(|| {
            draft.malformed("no header line: the first line names the columns (name,table,address,...)")
        })?;
    let delimiter =
        [b',', b';', b'\t'].into_iter().max_by_key(|d| header_line.bytes().filter(|b| b == d).count()).unwrap_or(b',');
    let mut reader = reader_for(text, delimiter);
    let headers = reader.headers().map_err(|e| draft.malformed(format!("the header line: {e}")))?.clone();
    let mut columns: HashMap<&'static str, usize> = HashMap::new();
    let mut ignored: Vec<(usize, String)> = Vec::new();
    let mut hex = false;
    for (i, cell) in headers.iter().enumerate() {
        match column_of(cell) {
            Some((column, in_hex)) if !columns.contains_key(column) => {
                columns.insert(column, i);
                hex |= in_hex;
            }
            Some((column, _)) => {
                let why = format!("a second {column} column: the first one is read");
                draft.unmapped("header", cell, "", &why);
            }
            None if cell.is_empty() => {}
            None => ignored.push((i, cell.to_string())),
        }
    }
    let Some(&address_column) = columns.get("address") else {
        return Err(draft.malformed(format!(
            "the header line {:?} has no address column (address, register, addr, ...)",
            super::shown(header_line)
        )));
    };
    let numbering = match draft.options.base {
        Some(base) => Numbering::From(base),
        None if hex => Numbering::Hex,
        None => {
            // A second reader over the same text: the numbering is the whole file's.
            let mut again = reader_for(text, delimiter);
            let records: Vec<_> = again.records().filter_map(Result::ok).collect();
            let cells = records.iter().filter_map(|r| r.get(address_column)).filter(|a| !a.is_empty());
            if all_modicon(cells) {
                draft.notes.push(
                    "Every address is a Modicon register number: 30001 is read as input register 0, 40001 as \
                     holding register 0 (10001 a discrete input, 00001 a coil); --first-address N reads them as \
                     numbers from N instead."
                        .to_string(),
                );
                Numbering::Modicon
            } else {
                Numbering::From(0)
            }
        }
    };
    let mut ignored_counts = vec![0usize; ignored.len()];
    for (n, record) in reader.records().enumerate() {
        let record = record.map_err(|e| draft.malformed(format!("row {}: {e}", n + 1)))?;
        let line = record.position().map_or(n + 2, |p| usize::try_from(p.line()).unwrap_or(usize::MAX));
        let place = format!("line {line}");
        if record.iter().all(str::is_empty) {
            continue;
        }
        for (k, (i, _)) in ignored.iter().enumerate() {
            if record.get(*i).is_some_and(|v| !v.is_empty()) {
                ignored_counts[k] += 1;
            }
        }
        let cell = |column: &str| columns.get(column).and_then(|i| record.get(*i)).filter(|v| !v.is_empty());
        row(&cell, &place, numbering, draft);
    }
    for ((_, name), count) in ignored.iter().zip(ignored_counts) {
        let why = format!("no such column in a profile ({count} rows have a value in it)");
        draft.unmapped("header", name, "", &why);
    }
    Ok(())
}

/// A CSV reader of `text`, its header first.
fn reader_for(text: &str, delimiter: u8) -> ::csv::Reader<&[u8]> {
    ::csv::ReaderBuilder::new()
        .delimiter(delimiter)
        .comment(Some(b'#'))
        .flexible(true)
        .trim(::csv::Trim::All)
        .from_reader(text.as_bytes())
}

/// One row, its cells by column, its addresses numbered by `numbering`.
fn row<'a>(cell: &dyn Fn(&str) -> Option<&'a str>, place: &str, numbering: Numbering, draft: &mut Draft) {
    let table = match cell("table") {
        None => Table::Holding,
        Some(text) => {
            let Some(table) = table_of(text) else {
                let why = "not a table (coils, discrete, holding, input, or 0x/1x/4x/3x, FC 1-4): row skipped";
                draft.unmapped(place, "table", text, why);
                return;
            };
            table
        }
    };
    let Some(address_text) = cell("address") else {
        draft.unmapped(place, "address", "", "no address: row skipped");
        return;
    };
    let Some((table, address)) = address_of(address_text, table, cell("table"), place, numbering, draft) else {
        return;
    };
    let Ok(address) = u16::try_from(address) else {
        draft.unmapped(place, "address", address_text, "beyond the address space (65535): row skipped");
        return;
    };
    let default_name = format!("{}_{address}", table.name());
    // Without a name column, the description names the row (a manual's "Parameter" list).
    let described = cell("name").is_none() && cell("description").is_some();
    let name = cell("name").or(cell("description").filter(|_| described)).unwrap_or(&default_name);
    let mut entry = Entry::new(table, address, name, place.to_string());
    entry.access = if matches!(table, Table::Coils | Table::Holding) { Access::Rw } else { Access::Ro };
    shape(cell, &mut entry, place, draft);
    if let Some(text) = cell("scale") {
        match scale_of(text) {
            Some(scale) if !super::is(scale, 0.0) => entry.scale = Some(scale).filter(|s| !super::is(*s, 1.0)),
            _ => draft.unmapped(place, "scale", text, "not a scale (0.1, 1/10, x10): left 1"),
        }
    }
    for (column, field) in [("offset", &mut entry.offset), ("min", &mut entry.min), ("max", &mut entry.max)] {
        if let Some(text) = cell(column) {
            match real(text) {
                Some(value) => *field = Some(value),
                None => draft.unmapped(place, column, text, "not a number"),
            }
        }
    }
    entry.offset = entry.offset.filter(|o| !super::is(*o, 0.0));
    entry.unit = cell("unit").map(str::to_string);
    if let Some(text) = cell("access") {
        match access_of(text) {
            Some(access) => entry.access = access,
            None => {
                draft.unmapped(place, "access", text, "not an access (ro, rw, wo, R, R/W, W): left as the table's");
            }
        }
    }
    entry.group = cell("group").map(str::to_string);
    if let Some(label) = cell("label") {
        entry.label = Some(label.to_string());
    }
    if !described {
        entry.description = cell("description").unwrap_or_default().to_string();
    }
    for (column, bits) in [("values", false), ("bits", true)] {
        if let Some(text) = cell(column) {
            match pairs(text, bits) {
                Some(list) if bits => entry.bits = list,
                Some(list) => entry.values = list,
                None => {
                    let form = if bits { "BIT=MEANING; ... (bits 0-63)" } else { "VALUE=MEANING; ..." };
                    draft.unmapped(place, column, text, &format!("not a list of {form}"));
                }
            }
        }
    }
    if let Some(text) = cell("default") {
        entry.default = default_of(text, entry.value_type);
        if entry.default.is_none() {
            let why = format!("not a value of a {}", entry.value_type.name());
            draft.unmapped(place, "default", text, &why);
        }
    }
    draft.add(entry);
}

/// The table and address of a row's `address_text` as the file numbers them, its `table` the
/// row's (from `table_cell`, if it has one); an address that cannot be read is listed.
fn address_of(
    address_text: &str,
    table: Table,
    table_cell: Option<&str>,
    place: &str,
    numbering: Numbering,
    draft: &mut Draft,
) -> Option<(Table, u32)> {
    Some(match numbering {
        Numbering::Modicon => {
            // Every address is one: the check read the whole file.
            let (numbered, address) = modicon(address_text)?;
            if let Some(given) = table_cell.filter(|_| numbered != table) {
                let why = format!("the Modicon number {address_text} is a {}: read as one", numbered.name());
                draft.unmapped(place, "table", given, &why);
            }
            (numbered, u32::from(address))
        }
        Numbering::Hex => {
            let Some(address) = hex_number(address_text) else {
                draft.unmapped(place, "address", address_text, "not a hex address (the column says hex): row skipped");
                return None;
            };
            (table, address)
        }
        Numbering::From(base) => {
            let Some(address) = number(address_text).and_then(|a| a.checked_sub(u32::from(base))) else {
                let why = if base > 0 {
                    format!("not an address of {base} or more (the first address): row skipped")
                } else {
                    "not an address (0-65535, decimal or 0x hex): row skipped".to_string()
                };
                draft.unmapped(place, "address", address_text, &why);
                return None;
            };
            (table, address)
        }
    })
}

/// The cells that say what a register holds: `type`, `length`, `order`.
fn shape<'a>(cell: &dyn Fn(&str) -> Option<&'a str>, entry: &mut Entry, place: &str, draft: &mut Draft) {
    let table = entry.table;
    if let Some(text) = cell("type") {
        match type_of(text) {
            Some(ValueType::Bit) if !table.is_bits() => {
                draft.unmapped(place, "type", text, "a bit is a coil or discrete input: read as u16");
            }
            Some(value_type) => entry.value_type = value_type,
            None => draft.unmapped(
                place,
                "type",
                text,
                "not a type (u16, i16, u32, i32, u64, i64, f32, f64, string): read as u16",
            ),
        }
    }
    // A type without its width ("Unsigned", "Signed") takes it from the registers the row gives.
    let widthless = cell("type").map(folded).filter(|t| ["unsigned", "signed", "uint", "int"].contains(&t.as_str()));
    if let (Some(kind), Some(length)) = (widthless, cell("length").and_then(|l| l.parse::<u16>().ok())) {
        let signed = kind != "unsigned" && kind != "uint";
        entry.value_type = match (length, signed) {
            (2, false) => ValueType::U32,
            (2, true) => ValueType::I32,
            (4, false) => ValueType::U64,
            (4, true) => ValueType::I64,
            _ => entry.value_type,
        };
    }
    if let Some(text) = cell("length") {
        match text.parse::<u16>() {
            Ok(length) if entry.value_type == ValueType::String && length > 0 => entry.length = Some(length),
            Ok(length) if length == entry.value_type.registers() => {}
            _ if entry.value_type == ValueType::String => {
                draft.unmapped(place, "length", text, "not a number of registers: the string is given 1");
            }
            _ => {
                let why = format!("a {} takes {} registers", entry.value_type.name(), entry.value_type.registers());
                draft.unmapped(place, "length", text, &why);
            }
        }
    }
    if entry.value_type == ValueType::String && entry.length.is_none() {
        entry.length = Some(1);
    }
    if let Some(text) = cell("order") {
        match order_of(text) {
            Some(order) if entry.value_type.registers() > 1 => entry.order = Some(order),
            Some(Order::Abcd) => {}
            Some(_) => draft.unmapped(place, "order", text, "a value of one register has no word order"),
            None => draft.unmapped(
                place,
                "order",
                text,
                "not a word order (ABCD, CDAB, BADC, DCBA, big-endian, word-swapped); ambiguous names such as \
                 little-endian are not guessed",
            ),
        }
    }
}

/// A table by any of its names.
fn table_of(text: &str) -> Option<Table> {
    Some(match folded(text).as_str() {
        "coils" | "coil" | "0x" | "0" | "1" | "01" | "fc1" | "fc01" | "co" | "do" | "digitaloutput" => Table::Coils,
        "discrete" | "discreteinput" | "discreteinputs" | "di" | "1x" | "2" | "02" | "fc2" | "fc02"
        | "digitalinput" | "inputstatus" => Table::DiscreteInputs,
        "holding" | "holdingregister" | "holdingregisters" | "hr" | "4x" | "3" | "03" | "fc3" | "fc03" | "holdings" => {
            Table::Holding
        }
        "input" | "inputregister" | "inputregisters" | "ir" | "3x" | "4" | "04" | "fc4" | "fc04" => Table::Input,
        _ => return None,
    })
}

/// A value type by any of its names.
fn type_of(text: &str) -> Option<ValueType> {
    Some(match folded(text).as_str() {
        "u16" | "uint16" | "uint" | "unsigned" | "unsigned16" | "word" | "ushort" => ValueType::U16,
        "i16" | "int16" | "int" | "signed" | "signed16" | "sint16" | "s16" | "short" => ValueType::I16,
        "u32" | "uint32" | "unsigned32" | "dword" | "udint" | "ulong" => ValueType::U32,
        "i32" | "int32" | "signed32" | "sint32" | "s32" | "dint" | "long" => ValueType::I32,
        "u64" | "uint64" | "unsigned64" | "ulint" | "lword" => ValueType::U64,
        "i64" | "int64" | "signed64" | "sint64" | "s64" | "lint" => ValueType::I64,
        "f32" | "float" | "float32" | "real" | "single" | "ieee754" | "ieee754float" | "32bitfloat" | "float32bit"
        | "floatingpoint" => ValueType::F32,
        "f64" | "double" | "float64" | "lreal" => ValueType::F64,
        "string" | "str" | "ascii" | "char" | "text" => ValueType::String,
        "bit" | "bool" | "boolean" => ValueType::Bit,
        _ => return None,
    })
}

/// A word order by its names, and the unambiguous descriptions of them.
fn order_of(text: &str) -> Option<Order> {
    Order::from_name(text).or_else(|| {
        Some(match folded(text).as_str() {
            "big" | "bigendian" | "be" | "msbfirst" | "highfirst" | "none" | "normal" => Order::Abcd,
            "wordswap" | "wordswapped" | "swapped" | "lowfirst" | "word" => Order::Cdab,
            "byteswap" | "byteswapped" | "byte" => Order::Badc,
            "wordbyteswap" | "wordbyte" | "byteandwordswapped" => Order::Dcba,
            _ => return None,
        })
    })
}

/// An access by any of its names.
fn access_of(text: &str) -> Option<Access> {
    Some(match folded(text).as_str() {
        "ro" | "r" | "read" | "readonly" => Access::Ro,
        "rw" | "wr" | "readwrite" | "writeread" => Access::Rw,
        "wo" | "w" | "write" | "writeonly" => Access::Wo,
        _ => return None,
    })
}

/// A non-negative integer: the one grammar of numbers ([`crate::text::number`]: decimal or
/// `0x` hex), or the `h`-suffixed hex of vendor sheets.
fn number(text: &str) -> Option<u32> {
    let text = text.trim();
    if let Some(hex) = text.strip_suffix(['h', 'H']) {
        return u32::from_str_radix(hex, 16).ok();
    }
    let value = crate::text::number(text, u64::from(u32::MAX)).ok()?;
    u32::try_from(value).ok()
}

/// A non-negative hex integer, with or without `0x` or an `h` suffix.
fn hex_number(text: &str) -> Option<u32> {
    let text = text.trim();
    let digits = text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")).unwrap_or(text);
    let digits = digits.strip_suffix(['h', 'H']).unwrap_or(digits);
    u32::from_str_radix(digits, 16).ok()
}

/// A finite number; a decimal comma (`0,1`) is read as a point.
fn real(text: &str) -> Option<f64> {
    let text = text.trim();
    let value: f64 = text.parse().or_else(|_| text.replace(',', ".").parse()).ok()?;
    value.is_finite().then_some(value)
}

/// A scale: `0.1`, `1/10`, `x10`, `×0.01`, `/100`, or one followed by its unit as a
/// resolution column gives it (`0,01 kWh`); finite.
fn scale_of(text: &str) -> Option<f64> {
    let scale = quotient(text).or_else(|| {
        let (number, unit) = text.trim().split_once(char::is_whitespace)?;
        unit.trim().chars().all(|c| c.is_alphabetic() || "%°/²³·".contains(c)).then(|| quotient(number))?
    });
    scale.filter(|s| s.is_finite())
}

/// What [`scale_of`] reads, before the check that it is finite (`1/1e-320` is not).
fn quotient(text: &str) -> Option<f64> {
    let text = text.trim();
    let text = text.strip_prefix(['x', 'X', '×', '*']).unwrap_or(text).trim();
    if let Some(divisor) = text.strip_prefix('/') {
        return real(divisor).filter(|d| *d != 0.0).map(|d| 1.0 / d);
    }
    if let Some((n, d)) = text.split_once('/') {
        let (n, d) = (real(n)?, real(d)?);
        return (d != 0.0).then(|| n / d);
    }
    real(text)
}

/// `KEY=MEANING` pairs separated by `;` (or `|`); keys are raw values (bit indices for `bits`).
fn pairs(text: &str, bits: bool) -> Option<Vec<(String, String)>> {
    let separator = if text.contains(';') { ';' } else { '|' };
    let mut out = Vec::new();
    for pair in text.split(separator).map(str::trim).filter(|p| !p.is_empty()) {
        let (key, meaning) = pair.split_once('=').or_else(|| pair.split_once(':'))?;
        let key = crate::model::parse_key(key)?;
        if bits && !(0..64).contains(&key) {
            return None;
        }
        out.push((key.to_string(), meaning.trim().to_string()));
    }
    (!out.is_empty()).then_some(out)
}

/// A default value of `value_type`.
fn default_of(text: &str, value_type: ValueType) -> Option<toml::Value> {
    match value_type {
        ValueType::Bit => match folded(text).as_str() {
            "1" | "on" | "true" | "yes" => Some(toml::Value::Boolean(true)),
            "0" | "off" | "false" | "no" => Some(toml::Value::Boolean(false)),
            _ => None,
        },
        ValueType::String => Some(toml::Value::String(text.to_string())),
        ValueType::F32 | ValueType::F64 => real(text).map(toml::Value::Float),
        _ => {
            let value = crate::model::parse_key(text)?;
            let (low, high) = value_type.integer_range();
            (low..=high).contains(&value).then(|| i64::try_from(value).ok().map(toml::Value::Integer))?
        }
    }
}

/// `profile` as CSV: a header of the columns the import reads (name, table, address, type,
/// length, order, scale, offset, unit, access, min, max, group, label, description, values,
/// bits, default), then one row per point in profile order (a run of `count` items gives
/// `count` rows). Addresses are the frame's. A scale of 1 and an offset of 0 are left empty,
/// and so are the cells a point has no use for (a word order of one register, a length of a
/// number, a type of a bit).
pub fn export_csv(profile: &Profile) -> String {
    let mut writer = ::csv::WriterBuilder::new().terminator(::csv::Terminator::Any(b'\n')).from_writer(Vec::new());
    // Writing to a Vec cannot fail; a record is the same width as the header.
    let _ = writer.write_record(COLUMNS);
    for point in profile.points() {
        let _ = writer.write_record(cells(point));
    }
    let bytes = writer.into_inner().unwrap_or_default();
    String::from_utf8(bytes).unwrap_or_default()
}

/// The cells of one point, in [`COLUMNS`]' order.
fn cells(p: &Point) -> [String; 18] {
    let bits = p.table.is_bits();
    let number = |v: f64| format!("{v:?}");
    let joined = |pairs: Vec<String>| pairs.join("; ");
    [
        p.code.clone(),
        p.table.name().to_string(),
        p.address.to_string(),
        if bits { String::new() } else { p.value_type.name().to_string() },
        if p.value_type == ValueType::String { p.width.to_string() } else { String::new() },
        if !bits && p.value_type.registers() > 1 { p.order.name().to_string() } else { String::new() },
        if super::is(p.scale, 1.0) { String::new() } else { number(p.scale) },
        if super::is(p.offset, 0.0) { String::new() } else { number(p.offset) },
        p.unit.clone().unwrap_or_default(),
        p.access.name().to_string(),
        p.min.map(number).unwrap_or_default(),
        p.max.map(number).unwrap_or_default(),
        p.group.clone().unwrap_or_default(),
        p.label.clone(),
        p.description.clone(),
        joined(p.values.iter().map(|(k, v)| format!("{k}={v}")).collect()),
        joined(p.bits.iter().map(|(k, v)| format!("{k}={v}")).collect()),
        match &p.factory_default {
            None => String::new(),
            Some(Value::Bool(b)) => u8::from(*b).to_string(),
            Some(Value::Int(n)) => n.to_string(),
            Some(Value::Float(x)) => number(*x),
            Some(Value::Text(t)) => t.clone(),
        },
    ]
}
