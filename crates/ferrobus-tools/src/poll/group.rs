//! What a poller reads: groups (one read request each, at one rate) of cells (one value each).

use std::time::Duration;

use ferrobus_profile::{Extent, Order, Point, Profile, Table, Value, ValueType, plan};

/// How a raw cell's registers are read and shown.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub enum Format {
    /// One register, unsigned.
    #[default]
    U16,
    /// One register, two's complement.
    I16,
    /// One register in hex (`0x01F4`).
    Hex,
    /// One register in binary (`0b0000000111110100`).
    Binary,
    /// Two registers, unsigned.
    U32,
    /// Two registers, two's complement.
    I32,
    /// Two registers, IEEE 754 single.
    F32,
    /// Four registers, IEEE 754 double.
    F64,
    /// A coil or discrete input (the only format of the bit tables).
    Bit,
}

impl Format {
    /// Every format, by name.
    pub const ALL: [Format; 9] = [
        Format::U16,
        Format::I16,
        Format::Hex,
        Format::Binary,
        Format::U32,
        Format::I32,
        Format::F32,
        Format::F64,
        Format::Bit,
    ];

    /// Its name (`u16`, `hex`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            Format::U16 => "u16",
            Format::I16 => "i16",
            Format::Hex => "hex",
            Format::Binary => "binary",
            Format::U32 => "u32",
            Format::I32 => "i32",
            Format::F32 => "f32",
            Format::F64 => "f64",
            Format::Bit => "bit",
        }
    }

    /// The format named `name` (case-insensitive).
    pub fn from_name(name: &str) -> Option<Format> {
        Format::ALL.into_iter().find(|f| f.name().eq_ignore_ascii_case(name.trim()))
    }

    /// The value type its registers are decoded as.
    pub const fn value_type(self) -> ValueType {
        match self {
            Format::U16 | Format::Hex | Format::Binary => ValueType::U16,
            Format::I16 => ValueType::I16,
            Format::U32 => ValueType::U32,
            Format::I32 => ValueType::I32,
            Format::F32 => ValueType::F32,
            Format::F64 => ValueType::F64,
            Format::Bit => ValueType::Bit,
        }
    }

    /// Registers (or bits) a value takes.
    pub const fn width(self) -> u16 {
        self.value_type().registers()
    }
}

/// One value of a group: a raw cell in a format, or a profile's point.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// What it is called in records and on screen: the alias, the point's code, or the
    /// address (`0x1000`).
    pub name: String,
    /// The point it decodes as: the profile's, or one made for a raw cell (its code is
    /// `name`, no unit, scale 1).
    pub point: Point,
    /// For a raw cell, its format (hex and binary are shown as such); `None` for a profile's
    /// point, shown as the profile says.
    pub format: Option<Format>,
}

impl Cell {
    /// A raw cell at wire `address` of `table` in `format` (`order` for multi-register ones),
    /// writable if the table is.
    pub fn raw(table: Table, address: u16, format: Format, order: Order, alias: Option<&str>) -> Cell {
        let format = if table.is_bits() { Format::Bit } else { format };
        let name = alias.map_or_else(|| format!("{address:#06x}"), str::to_string);
        let point = Point { code: name.clone(), order, ..Point::raw(table, address, format.value_type()) };
        Cell { name, point, format: Some(format) }
    }

    /// A profile's point, named by its code.
    pub fn point(point: &Point) -> Cell {
        Cell { name: point.code.clone(), point: point.clone(), format: None }
    }

    /// The raw value as shown: hex and binary as such, else as the profile shows it (scaled,
    /// with its unit, an enumeration's meaning).
    pub fn show(&self, raw: &Value) -> String {
        match (self.format, raw) {
            (Some(Format::Hex), Value::Int(n)) => format!("{n:#06x}"),
            (Some(Format::Binary), Value::Int(n)) => format!("{n:#018b}"),
            _ => self.point.show(raw),
        }
    }

    /// The engineering value (raw × scale + offset) of a numeric raw value.
    pub fn scaled(&self, raw: &Value) -> Option<f64> {
        match raw {
            Value::Bool(b) => Some(if *b { 1.0 } else { 0.0 }),
            _ => self.point.engineering(raw),
        }
    }

    /// Its unit of measure, if any.
    pub fn unit(&self) -> Option<&str> {
        self.point.unit.as_deref()
    }
}

/// One read request at one rate: `count` items of `table` from `start` of unit `unit`, every
/// `every`, and the cells they hold.
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    /// Its name in records and on screen.
    pub name: String,
    /// The unit asked.
    pub unit: u8,
    /// The table read.
    pub table: Table,
    /// The first wire address read.
    pub start: u16,
    /// Items read (registers or bits).
    pub count: u16,
    /// The period.
    pub every: Duration,
    /// The cells, each inside `start .. start + count`.
    pub cells: Vec<Cell>,
}

/// Why a group cannot be made.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GroupError {
    /// The range is empty, runs past 0xFFFF, or is more than one request may read.
    #[error("{what}: {problem}")]
    Range {
        /// The group.
        what: String,
        /// What is wrong.
        problem: String,
    },
    /// A profile has no point by that name or group.
    #[error("{profile} has no {what} {name:?}")]
    NoSuchPoint {
        /// The profile.
        profile: String,
        /// `parameter` or `group`.
        what: &'static str,
        /// The name asked.
        name: String,
    },
    /// The planner could not cover the points.
    #[error("{profile}: {problem}")]
    Plan {
        /// The profile.
        profile: String,
        /// The planner's words.
        problem: String,
    },
}

/// The most items one read request may carry (0x03/0x04; 0x01/0x02 take 2000 bits).
pub const fn max_count(table: Table) -> u16 {
    if table.is_bits() { 2000 } else { 125 }
}

/// A raw range to poll: `count` items of `table` from `start` at `unit`, every `every`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RawRange {
    /// The unit read.
    pub unit: u8,
    /// The table read.
    pub table: Table,
    /// The first address.
    pub start: u16,
    /// How many items (registers or bits).
    pub count: u16,
    /// The period.
    pub every: Duration,
}

impl Default for RawRange {
    /// One holding register at 0 of unit 1, every second.
    fn default() -> Self {
        RawRange { unit: 1, table: Table::Holding, start: 0, count: 1, every: Duration::from_secs(1) }
    }
}

impl Group {
    /// A raw range, called `name`, cut into cells as `layout` says (the bit tables take one
    /// bit a cell).
    pub fn raw(name: &str, range: RawRange, layout: &Layout) -> Result<Group, GroupError> {
        let RawRange { unit, table, start, count, every } = range;
        let range = |problem: String| GroupError::Range { what: name.to_string(), problem };
        if count == 0 || count > max_count(table) {
            return Err(range(format!("a count of {count}; one request reads 1 to {}", max_count(table))));
        }
        let end = u32::from(start) + u32::from(count);
        if end > 0x1_0000 {
            return Err(range(format!("{count} items from {start:#06x} run past 0xFFFF")));
        }
        let mut cells = Vec::new();
        let mut address = u32::from(start);
        while address < end {
            let Ok(at) = u16::try_from(address) else { break };
            let format = layout.formats.iter().find(|(a, _)| *a == at).map_or(layout.format, |(_, f)| *f);
            let alias = layout.aliases.iter().find(|(a, _)| *a == at).map(|(_, n)| n.as_str());
            let order = layout.orders.iter().find(|(a, _)| *a == at).map_or(layout.order, |(_, o)| *o);
            let cell = Cell::raw(table, at, format, order, alias);
            let next = address + u32::from(cell.point.width);
            if next > end {
                return Err(range(format!(
                    "the {} at {at:#06x} takes {} registers, past the end of the range ({:#06x})",
                    format.name(),
                    cell.point.width,
                    end - 1
                )));
            }
            cells.push(cell);
            address = next;
        }
        let given = layout
            .aliases
            .iter()
            .map(|(a, _)| *a)
            .chain(layout.formats.iter().map(|(a, _)| *a))
            .chain(layout.orders.iter().map(|(a, _)| *a));
        for at in given {
            if !cells.iter().any(|c| c.point.address == at) {
                return Err(range(format!("no cell starts at {at:#06x} (an alias, format or order is given for it)")));
            }
        }
        Ok(Group { name: name.to_string(), unit, table, start, count, every, cells })
    }

    /// Named points of a profile: the fewest read requests that cover them (the profile's
    /// planner, within its per-request limits), one group each, all every `every`. Names are
    /// codes, labels or globs; `groups` adds every readable point of a profile group.
    pub fn points<'p>(
        profile: &'p Profile,
        unit: u8,
        names: &[String],
        groups: &[String],
        every: Duration,
    ) -> Result<Vec<Group>, GroupError> {
        let mut chosen: Vec<&'p Point> = Vec::new();
        let mut add = |found: Vec<&'p Point>| {
            for p in found {
                if p.readable() && !chosen.iter().any(|c| c.table == p.table && c.address == p.address) {
                    chosen.push(p);
                }
            }
        };
        for name in names {
            let found = profile.find(name);
            if found.is_empty() {
                return Err(GroupError::NoSuchPoint {
                    profile: profile.origin.clone(),
                    what: "parameter",
                    name: name.clone(),
                });
            }
            add(found);
        }
        for group in groups {
            let found = profile.group(group);
            if found.is_empty() {
                return Err(GroupError::NoSuchPoint {
                    profile: profile.origin.clone(),
                    what: "group",
                    name: group.clone(),
                });
            }
            add(found);
        }
        let mut out = Vec::new();
        for table in Table::ALL {
            let wanted: Vec<Extent> = chosen
                .iter()
                .filter(|p| p.table == table)
                .map(|p| Extent { start: p.address, width: p.width })
                .collect();
            if wanted.is_empty() {
                continue;
            }
            let requests = plan(&wanted, &profile.mapped(table), &profile.spans(table), profile.read_limit(table))
                .map_err(|e| GroupError::Plan { profile: profile.origin.clone(), problem: e.to_string() })?;
            for request in requests {
                let cells: Vec<Cell> = chosen
                    .iter()
                    .filter(|p| p.table == table && p.address >= request.start && p.end() <= request.end())
                    .map(|p| Cell::point(p))
                    .collect();
                let name = name_of(unit, table, request.start, &cells);
                out.push(Group { name, unit, table, start: request.start, count: request.count, every, cells });
            }
        }
        Ok(out)
    }

    /// Decodes the items a read returned (registers or bits as 0/1, `count` of them) into
    /// each cell's raw value.
    pub fn decode(&self, items: &[u16]) -> Vec<Result<Value, String>> {
        self.decoded(items).collect()
    }

    /// [`Group::decode`], value by value.
    pub(crate) fn decoded<'a>(&'a self, items: &'a [u16]) -> impl Iterator<Item = Result<Value, String>> + 'a {
        self.cells.iter().map(move |cell| {
            let from = usize::from(cell.point.address.saturating_sub(self.start));
            let to = from.saturating_add(usize::from(cell.point.width));
            let words = items
                .get(from..to)
                .ok_or_else(|| format!("the reply held {} items, {} needs {from}..{to}", items.len(), cell.name))?;
            if cell.point.value_type == ValueType::Bit {
                return Ok(Value::Bool(words.first().is_some_and(|w| *w != 0)));
            }
            cell.point.decode(words).map_err(|e| e.to_string())
        })
    }
}

/// A group's name from its cells: `u1 d001` for one, `u1 d001..d003` for several, the table
/// and start for none.
pub(crate) fn name_of(unit: u8, table: Table, start: u16, cells: &[Cell]) -> String {
    match cells {
        [one] => format!("u{unit} {}", one.name),
        [first, .., last] => format!("u{unit} {}..{}", first.name, last.name),
        [] => format!("u{unit} {}@{start:#06x}", table.name()),
    }
}

/// How a raw range is cut into cells.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Layout {
    /// The format of every cell not in `formats`.
    pub format: Format,
    /// The order of multi-register cells.
    pub order: Order,
    /// Cells by wire address with another order.
    pub orders: Vec<(u16, Order)>,
    /// Cells by wire address with another format.
    pub formats: Vec<(u16, Format)>,
    /// Names of cells by wire address.
    pub aliases: Vec<(u16, String)>,
}
