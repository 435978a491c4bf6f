//! Addresses as typed: wire addresses, a manual's 1-based numbers, Modicon references.
//!
//! The frame carries a 0-based address (the "wire address"). Drive manuals number registers
//! from 1 and the frame carries number − 1 (reference §4.6: "the holding register start
//! address is 0011h, which is smaller by 1 than the register number 0012h"). PLC tools use
//! Modicon references, where the leading digit names the table: 0xxxx coils, 1xxxx discrete
//! inputs, 3xxxx input registers, 4xxxx holding registers, each 1-based (5 digits up to
//! 9999, 6 digits up to 65536).
//!
//! A plain number is always a wire address: SunSpec devices, for one, keep their registers at
//! wire 40000 and up. A Modicon reference needs `--modicon`; a plain number that reads as a
//! reference to the command's table (40001 for holding registers) is taken as a wire address,
//! with a warning that names the other reading.

use std::fmt;

use clap::{Args, ValueEnum};
use ferrobus_proto::FunctionCode;
use ferrobus_proto::pdu::{ReadBits, ReadRegisters};

use crate::exit::CliError;

/// The one-line explanation shown in `--help`.
pub(crate) const ADDRESS_HELP: &str = "ADDRESS is the wire address (0-based, as on the bus; decimal or 0x hex); \
     use --one-based for a manual's register numbers, or --modicon for a Modicon reference like 40001 \
     (= holding register 1, wire 0)";

/// A Modbus data table.
#[derive(ValueEnum, Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Table {
    // Coils: read/write bits (FC01, FC05, FC0F).
    Coils,
    // Discrete inputs: read-only bits (FC02).
    Discrete,
    // Holding registers: read/write words (FC03, FC06, FC10).
    Holding,
    // Input registers: read-only words (FC04).
    Input,
}

impl Table {
    /// Whether the table holds bits.
    pub(crate) fn is_bits(self) -> bool {
        matches!(self, Table::Coils | Table::Discrete)
    }

    /// The function code that reads it.
    pub(crate) fn read_function(self) -> FunctionCode {
        match self {
            Table::Coils => FunctionCode::ReadCoils,
            Table::Discrete => FunctionCode::ReadDiscreteInputs,
            Table::Holding => FunctionCode::ReadHoldingRegisters,
            Table::Input => FunctionCode::ReadInputRegisters,
        }
    }

    /// The spec's most items per read request (§6.1–6.4), from the core.
    pub(crate) fn max_read(self) -> usize {
        usize::from(if self.is_bits() { ReadBits::MAX } else { ReadRegisters::MAX })
    }

    /// The leading digit of a Modicon reference.
    fn modicon_digit(self) -> u32 {
        match self {
            Table::Coils => 0,
            Table::Discrete => 1,
            Table::Input => 3,
            Table::Holding => 4,
        }
    }

    fn from_modicon_digit(digit: u32) -> Option<Table> {
        match digit {
            0 => Some(Table::Coils),
            1 => Some(Table::Discrete),
            3 => Some(Table::Input),
            4 => Some(Table::Holding),
            _ => None,
        }
    }

    /// The name used on the command line and in JSON.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Table::Coils => "coils",
            Table::Discrete => "discrete",
            Table::Holding => "holding",
            Table::Input => "input",
        }
    }

    /// One item, in words.
    pub(crate) fn item(self) -> &'static str {
        match self {
            Table::Coils => "coil",
            Table::Discrete => "discrete input",
            Table::Holding => "holding register",
            Table::Input => "input register",
        }
    }
}

impl Table {
    /// A table by the name a user types: coils (or coil), discrete, holding, input, in any case.
    pub(crate) fn from_name(name: &str) -> Option<Table> {
        match name.trim().to_ascii_lowercase().as_str() {
            "coils" | "coil" => Some(Table::Coils),
            "discrete" => Some(Table::Discrete),
            "holding" => Some(Table::Holding),
            "input" => Some(Table::Input),
            _ => None,
        }
    }
}

impl From<Table> for ferrobus_profile::Table {
    fn from(table: Table) -> Self {
        match table {
            Table::Coils => ferrobus_profile::Table::Coils,
            Table::Discrete => ferrobus_profile::Table::DiscreteInputs,
            Table::Holding => ferrobus_profile::Table::Holding,
            Table::Input => ferrobus_profile::Table::Input,
        }
    }
}

impl From<ferrobus_profile::Table> for Table {
    fn from(table: ferrobus_profile::Table) -> Self {
        match table {
            ferrobus_profile::Table::Coils => Table::Coils,
            ferrobus_profile::Table::DiscreteInputs => Table::Discrete,
            ferrobus_profile::Table::Holding => Table::Holding,
            ferrobus_profile::Table::Input => Table::Input,
        }
    }
}

/// A raw range written as one word, `[UNIT:]TABLE:ADDRESS[:COUNT]` (`holding:0x1000:8`,
/// `3:input:0`): its parts as typed, the address still to be numbered
/// ([`crate::connect::ConnectArgs::address`]). `poll` and `monitor` both take it, beside the
/// two words `TABLE ADDRESS` with `--count`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct RangeWord<'a> {
    /// The unit, if the word names one.
    pub(crate) unit: Option<u8>,
    /// The table.
    pub(crate) table: Table,
    /// The address as typed.
    pub(crate) address: &'a str,
    /// The count, if the word gives one.
    pub(crate) count: Option<u16>,
}

impl<'a> RangeWord<'a> {
    /// The range `word` writes; `None` when it writes none (a point's name, `group:NAME`), an
    /// error when it starts like one but is wrong.
    pub(crate) fn parse(word: &'a str) -> Option<Result<RangeWord<'a>, CliError>> {
        let parts: Vec<&str> = word.split(':').collect();
        match parts.as_slice() {
            [unit, table, rest @ ..] if Table::from_name(unit).is_none() => {
                Table::from_name(table).map(|table| Self::checked(word, Some(unit), table, rest))
            }
            [table, rest @ ..] => Table::from_name(table).map(|table| Self::checked(word, None, table, rest)),
            [] => None,
        }
    }

    /// The range of `word`, whose unit (if any), table and the parts after the table are given.
    fn checked(word: &'a str, unit: Option<&str>, table: Table, rest: &[&'a str]) -> Result<RangeWord<'a>, CliError> {
        let usage = |why: String| CliError::Usage(format!("'{word}': {why}; write [UNIT:]TABLE:ADDRESS[:COUNT]"));
        let unit = match unit {
            None => None,
            Some(u) => Some(
                number(u)
                    .and_then(|u| u8::try_from(u).ok())
                    .filter(|u| (1..=247).contains(u))
                    .ok_or_else(|| usage(format!("the unit '{u}' is not 1 to 247")))?,
            ),
        };
        let (address, count) = match rest {
            [address] => (*address, None),
            [address, count] => (*address, Some(*count)),
            [] => return Err(usage("no address".into())),
            _ => return Err(usage("too many parts".into())),
        };
        let count = match count {
            None => None,
            Some(c) => Some(
                number(c)
                    .and_then(|c| u16::try_from(c).ok())
                    .filter(|c| *c > 0)
                    .ok_or_else(|| usage(format!("the count '{c}' is not 1 to 65535")))?,
            ),
        };
        Ok(RangeWord { unit, table, address, count })
    }
}

/// A decimal or `0x` hex number, by the one grammar ([`ferrobus::text::number`]).
fn number(text: &str) -> Option<u32> {
    ferrobus::text::number(text, u64::from(u32::MAX)).ok().and_then(|n| u32::try_from(n).ok())
}

impl fmt::Display for Table {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The `--one-based` and `--modicon` options of the commands that take addresses.
#[derive(Args, Clone, Copy, Debug, Default)]
pub(crate) struct AddressArgs {
    /// ADDRESS is a manual's 1-based register number (frame address = number - 1)
    #[arg(long = "one-based", short = '1')]
    pub(crate) one_based: bool,

    /// ADDRESS is a Modicon reference: table digit (0 coils, 1 discrete, 3 input, 4 holding),
    /// then the 1-based number: 40001 or 400001 = holding register 1 = wire 0
    #[arg(long, conflicts_with = "one_based")]
    pub(crate) modicon: bool,
}

/// How an address was written, so that output can show it the same way.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Style {
    /// A wire address.
    Wire,
    /// A 1-based number (`--one-based`).
    OneBased,
    /// A 1-based number typed in hex (`--one-based 0x1001`), shown in hex.
    OneBasedHex,
    /// A Modicon reference with this many digits (5 or 6).
    Modicon(u8),
}

/// An address resolved to the wire.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct Address {
    /// The address in the frame.
    pub(crate) wire: u16,
    /// The table it is in.
    pub(crate) table: Table,
    /// How it was written.
    pub(crate) style: Style,
}

impl Address {
    /// Resolves `text` for `table`. A plain number that could be meant as a Modicon reference
    /// is taken as a wire address, with a warning on stderr (see [`modicon_lookalike`]).
    pub(crate) fn parse(text: &str, table: Table, args: AddressArgs) -> Result<Address, CliError> {
        let address = Self::resolve(text, table, args)?;
        if let Some(warning) = modicon_lookalike(text, address) {
            eprintln!("warning: {warning}");
        }
        Ok(address)
    }

    fn resolve(text: &str, table: Table, args: AddressArgs) -> Result<Address, CliError> {
        let cleaned: String = text.trim().chars().filter(|&c| c != '_').collect();
        if cleaned.starts_with('-') {
            return Err(CliError::Usage(format!(
                "'{text}' is not an address: addresses are 0 to 65535 (register numbers, with --one-based, 1 to 65536)"
            )));
        }
        let bad = || CliError::Usage(format!("'{text}' is not an address: use decimal or 0x hex"));
        let typed_hex = cleaned.starts_with("0x") || cleaned.starts_with("0X");
        // The number by the one grammar; the count of decimal digits tells a Modicon reference.
        let value = number(&cleaned).ok_or_else(bad)?;
        let digits = (!typed_hex).then_some(cleaned.len());
        if args.modicon {
            return match modicon(value, digits) {
                Some(address) => address.matching(table, text),
                None => Err(CliError::Usage(format!(
                    "with --modicon, '{text}' is not a Modicon reference: write the table digit (0 coils, \
                     1 discrete, 3 input, 4 holding), then the 1-based number in 4 or 5 digits: 40001, 400001"
                ))),
            };
        }
        if args.one_based {
            return match value {
                0 => Err(CliError::Usage(
                    "with --one-based, register numbers start at 1 (frame address = number - 1); 0 is not one".into(),
                )),
                1..=65536 => {
                    let style = if typed_hex { Style::OneBasedHex } else { Style::OneBased };
                    Ok(Address { wire: u16::try_from(value - 1).unwrap_or(u16::MAX), table, style })
                }
                _ => Err(CliError::Usage(format!("register number {text} is out of range (1-65536)"))),
            };
        }
        match u16::try_from(value) {
            Ok(wire) => Ok(Address { wire, table, style: Style::Wire }),
            Err(_) if modicon(value, digits).is_some() => Err(CliError::Usage(format!(
                "address {text} is out of range (0-65535); for a Modicon reference add --modicon"
            ))),
            Err(_) => Err(CliError::Usage(format!("address {text} is out of range (0-65535)"))),
        }
    }

    fn matching(self, table: Table, text: &str) -> Result<Address, CliError> {
        if self.table == table {
            return Ok(self);
        }
        let as_wire = match text.trim().parse::<u16>() {
            Ok(wire) => format!("; without --modicon it is wire address {wire}"),
            Err(_) => String::new(),
        };
        Err(CliError::Usage(format!(
            "{text} is a Modicon reference to {} {}, but the command addresses {}{as_wire}",
            self.table.item(),
            u32::from(self.wire) + 1,
            table.name(),
        )))
    }

    /// How `wire` (an address of the same request) is written in this address's style: the
    /// 1-based number or the Modicon reference; `None` for plain wire addresses.
    pub(crate) fn reference(self, wire: u16) -> Option<String> {
        let number = u32::from(wire) + 1;
        let digit = self.table.modicon_digit();
        match self.style {
            Style::Wire => None,
            Style::OneBased => Some(number.to_string()),
            Style::OneBasedHex => Some(format!("0x{number:04X}")),
            Style::Modicon(5) if number <= 9999 => Some(format!("{digit}{number:04}")),
            Style::Modicon(_) => Some(format!("{digit}{number:05}")),
        }
    }

    /// Checks that `count` items from here stay within the 65536 addresses.
    pub(crate) fn check_span(self, count: usize) -> Result<(), CliError> {
        if usize::from(self.wire) + count > 0x1_0000 {
            return Err(CliError::Usage(format!(
                "{count} {}s from address {} run past the last address, 65535",
                self.table.item(),
                self.wire
            )));
        }
        Ok(())
    }
}

/// The warning for a plain decimal wire address that also reads as a Modicon reference to
/// the same table (40001 for holding registers, 00001 for coils), naming both readings.
pub(crate) fn modicon_lookalike(text: &str, address: Address) -> Option<String> {
    if address.style != Style::Wire {
        return None;
    }
    let cleaned: String = text.trim().chars().filter(|&c| c != '_').collect();
    if !cleaned.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let reference = modicon(cleaned.parse().ok()?, Some(cleaned.len())).filter(|r| r.table == address.table)?;
    Some(format!(
        "{text} is taken as wire address {} (0x{:04X}); for the Modicon reference to {} {} (wire {}) add --modicon",
        address.wire,
        address.wire,
        reference.table.item(),
        u32::from(reference.wire) + 1,
        reference.wire,
    ))
}

/// A Modicon reference, if `value` written with `digits` digits is one.
fn modicon(value: u32, digits: Option<usize>) -> Option<Address> {
    let (scale, max, width) = match digits? {
        5 => (10_000, 9_999, 5),
        6 => (100_000, 65_536, 6),
        _ => return None,
    };
    let table = Table::from_modicon_digit(value / scale)?;
    let offset = value % scale;
    if offset == 0 || offset > max {
        return None;
    }
    Some(Address { wire: u16::try_from(offset - 1).ok()?, table, style: Style::Modicon(width) })
}

/// Splits `total` items from `start` into requests of at most `max` items, cutting only at
/// multiples of `width` (a 32-bit value is never split across two requests). Returns
/// (start, count) pairs. `max` must be at least `width`.
pub(crate) fn split(start: u16, total: usize, width: usize, max: usize) -> Vec<(u16, usize)> {
    let per = (max / width.max(1)).max(1) * width.max(1);
    let mut out = Vec::new();
    let mut done = 0;
    while done < total {
        let n = per.min(total - done);
        let at = usize::from(start) + done;
        out.push((u16::try_from(at).unwrap_or(u16::MAX), n));
        done += n;
    }
    out
}

/// The per-request limit: `--max-per-request` or the spec's, checked against the spec and
/// the value width.
pub(crate) fn per_request(
    max: Option<u16>,
    spec_max: usize,
    width: usize,
    kind: crate::value::ValueType,
) -> Result<usize, CliError> {
    let Some(max) = max else { return Ok(spec_max) };
    let max = usize::from(max);
    if max > spec_max {
        return Err(CliError::Usage(format!("--max-per-request {max} is above the spec's {spec_max} per request")));
    }
    if max < width {
        return Err(CliError::Usage(format!(
            "--max-per-request {max} cannot hold one {} value ({width} registers)",
            kind.name()
        )));
    }
    Ok(max)
}

/// The number of items as a request quantity (every split piece is at most 65535).
pub(crate) fn quantity(n: usize) -> u16 {
    u16::try_from(n).unwrap_or(u16::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_range_word_gives_its_unit_table_address_and_count_and_names_are_no_range() {
        fn word(w: &str) -> Option<Result<RangeWord<'_>, String>> {
            RangeWord::parse(w).map(|r| r.map_err(|e| format!("{e:?}")))
        }
        fn range(unit: Option<u8>, table: Table, address: &str, count: Option<u16>) -> RangeWord<'_> {
            RangeWord { unit, table, address, count }
        }
        assert_eq!(word("holding:0x1000:8"), Some(Ok(range(None, Table::Holding, "0x1000", Some(8)))));
        assert_eq!(word("3:input:0"), Some(Ok(range(Some(3), Table::Input, "0", None))));
        assert_eq!(word("Coil:7:0x10"), Some(Ok(range(None, Table::Coils, "7", Some(16)))));
        assert_eq!(word("F002"), None);
        assert_eq!(word("group:basic"), None);
        assert_eq!(
            word("holding"),
            Some(Err("Usage(\"'holding': no address; write [UNIT:]TABLE:ADDRESS[:COUNT]\")".into()))
        );
        assert!(word("300:holding:0").unwrap().unwrap_err().contains("the unit '300' is not 1 to 247"));
        assert!(word("holding:0:0").unwrap().unwrap_err().contains("the count '0' is not 1 to 65535"));
        assert!(word("holding:0:1:2").unwrap().unwrap_err().contains("too many parts"));
    }

    #[test]
    fn the_read_limits_are_the_specs_2000_bits_and_125_registers() {
        assert_eq!(Table::Coils.max_read(), 0x07D0);
        assert_eq!(Table::Discrete.max_read(), 0x07D0);
        assert_eq!(Table::Holding.max_read(), 0x007D);
        assert_eq!(Table::Input.max_read(), 0x007D);
    }

    fn parse(text: &str, table: Table, one_based: bool) -> Result<Address, CliError> {
        Address::parse(text, table, AddressArgs { one_based, modicon: false })
    }

    fn reference(text: &str, table: Table) -> Result<Address, CliError> {
        Address::parse(text, table, AddressArgs { one_based: false, modicon: true })
    }

    fn usage(result: Result<Address, CliError>) -> String {
        match result {
            Err(CliError::Usage(msg)) => msg,
            other => panic!("expected a usage error, got {other:?}"),
        }
    }

    #[test]
    fn addresses_units_and_counts_take_the_one_number_grammar() {
        // The numbers scan --units takes (ferrobus::text::number): decimal, 0x hex, _ grouping.
        for (typed, want) in [("247", 247), ("0xF7", 247), ("0Xf7", 247), ("2_47", 247)] {
            assert_eq!(number(typed), Some(want), "{typed}");
            assert_eq!(parse(typed, Table::Holding, false).unwrap().wire, 247, "{typed}");
        }
        let word = RangeWord::parse("0x10:holding:0x20:0x4").unwrap().unwrap();
        assert_eq!((word.unit, word.address, word.count), (Some(16), "0x20", Some(4)));
        assert_eq!(number("-1"), None);
        assert_eq!(number("0x"), None);
    }

    #[test]
    fn wire_addresses_are_decimal_or_hex() {
        assert_eq!(parse("16", Table::Holding, false).unwrap().wire, 16);
        assert_eq!(parse("0x0011", Table::Holding, false).unwrap().wire, 0x11);
        assert_eq!(parse("65535", Table::Holding, false).unwrap().wire, 65535);
        assert!(parse("65536", Table::Holding, false).is_err());
        assert!(parse("70000", Table::Holding, false).is_err());
        assert!(parse("0x", Table::Holding, false).is_err());
        assert!(parse("", Table::Holding, false).is_err());
        assert!(parse("99999999999999", Table::Holding, false).is_err());
    }

    #[test]
    fn a_negative_address_is_refused_with_the_range() {
        let msg = usage(parse("-1", Table::Holding, false));
        assert_eq!(
            msg,
            "'-1' is not an address: addresses are 0 to 65535 (register numbers, with --one-based, 1 to 65536)"
        );
        assert!(parse("-5", Table::Holding, true).is_err());
    }

    #[test]
    fn one_based_numbers_are_one_more_than_the_wire() {
        let a = parse("18", Table::Holding, true).unwrap();
        assert_eq!((a.wire, a.style), (0x11, Style::OneBased));
        assert_eq!(a.reference(0x11).as_deref(), Some("18"));
        // The user's notation is kept: a number typed in hex is shown in hex.
        let hex = parse("0x0012", Table::Holding, true).unwrap();
        assert_eq!((hex.wire, hex.style), (0x11, Style::OneBasedHex));
        assert_eq!(hex.reference(0x11).as_deref(), Some("0x0012"));
        assert_eq!(hex.reference(0x1000).as_deref(), Some("0x1001"));
        assert_eq!(parse("65536", Table::Holding, true).unwrap().wire, 65535);
        assert!(parse("0", Table::Holding, true).is_err());
    }

    #[test]
    fn plain_numbers_in_the_modicon_ranges_are_wire_addresses() {
        // SunSpec: the "SunS" marker at wire 40000, its first model at 40002.
        for (text, wire) in [("40000", 40000), ("40001", 40001), ("40002", 40002), ("49999", 49999)] {
            let a = parse(text, Table::Holding, false).unwrap();
            assert_eq!((a.wire, a.style), (wire, Style::Wire), "{text}");
        }
        assert_eq!(parse("30002", Table::Input, false).unwrap().wire, 30002);
        assert_eq!(parse("00001", Table::Coils, false).unwrap().wire, 1);
        let msg = usage(parse("400001", Table::Holding, false));
        assert!(msg.contains("out of range (0-65535); for a Modicon reference add --modicon"), "{msg}");
    }

    #[test]
    fn a_plain_number_that_reads_as_a_reference_to_the_same_table_gets_a_warning() {
        let warn = |text: &str, table| modicon_lookalike(text, parse(text, table, false).unwrap());
        assert_eq!(
            warn("40001", Table::Holding).as_deref(),
            Some(
                "40001 is taken as wire address 40001 (0x9C41); for the Modicon reference to holding register 1 \
                 (wire 0) add --modicon"
            )
        );
        assert!(warn("00010", Table::Coils).unwrap().contains("coil 10 (wire 9)"));
        // Not a reference (offset 0), another table, hex, or not five or six digits: no warning.
        assert_eq!(warn("40000", Table::Holding), None);
        assert_eq!(warn("40001", Table::Input), None);
        assert_eq!(warn("0x9C41", Table::Holding), None);
        assert_eq!(warn("4001", Table::Holding), None);
        assert_eq!(modicon_lookalike("40001", parse("40001", Table::Holding, true).unwrap()), None);
    }

    #[test]
    fn modicon_references_name_table_and_number() {
        let a = reference("40001", Table::Holding).unwrap();
        assert_eq!((a.wire, a.style), (0, Style::Modicon(5)));
        assert_eq!(a.reference(1).as_deref(), Some("40002"));
        assert_eq!(reference("00001", Table::Coils).unwrap().wire, 0);
        assert_eq!(reference("10010", Table::Discrete).unwrap().wire, 9);
        assert_eq!(reference("30002", Table::Input).unwrap().wire, 1);
        let six = reference("465536", Table::Holding).unwrap();
        assert_eq!((six.wire, six.style), (65535, Style::Modicon(6)));
        assert_eq!(six.reference(65535).as_deref(), Some("465536"));
        assert_eq!(modicon_lookalike("40001", a), None);
    }

    #[test]
    fn with_modicon_anything_but_a_reference_is_refused() {
        for text in ["40000", "20001", "4001", "0x9C41", "1234567"] {
            let msg = usage(reference(text, Table::Holding));
            assert!(msg.contains(&format!("with --modicon, '{text}' is not a Modicon reference")), "{msg}");
        }
    }

    #[test]
    fn a_modicon_reference_to_another_table_is_refused() {
        let msg = usage(reference("40001", Table::Coils));
        assert!(msg.contains("holding register 1"), "{msg}");
        assert!(msg.contains("without --modicon it is wire address 40001"), "{msg}");
    }

    #[test]
    fn splits_cut_only_at_value_boundaries() {
        assert_eq!(split(0, 10, 2, 4), vec![(0, 4), (4, 4), (8, 2)]);
        assert_eq!(split(0, 10, 2, 5), vec![(0, 4), (4, 4), (8, 2)]);
        assert_eq!(split(100, 250, 1, 125), vec![(100, 125), (225, 125)]);
        assert_eq!(split(0, 0, 1, 125), vec![]);
        assert_eq!(split(65534, 2, 2, 125), vec![(65534, 2)]);
    }
}
