//! The device's data: four tables of the whole 16-bit address space, and the named items a
//! profile lays over them.
//!
//! Every address either belongs to an item — a named coil, a register, a 32-bit pair, a plain
//! table — or to nothing, and then reading or writing it is exception 02. Writes are checked
//! whole before any value changes: a request that fails changes nothing.
//!
//! Addresses are `u16` on the wire and `usize` or `u32` while they are computed; the profile
//! was checked to stay inside the 65536 addresses, and requests are too (a quantity cannot run
//! past 0xFFFF), so narrowing them back cannot truncate.
#![allow(clippy::cast_possible_truncation)]

use std::collections::HashMap;

use crate::profile::{Access, Point, Profile, Value};

pub use crate::profile::Table;

/// Why an access is denied; the device turns it into its exception code.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Denial {
    /// No item at the address (exception 02).
    Unmapped,
    /// The item is read-only.
    ReadOnly,
    /// The value is outside the item's range.
    OutOfRange,
    /// Not allowed in the device's present state (e.g. while running).
    NotAllowed,
}

/// One named item.
#[derive(Clone, Debug)]
pub struct Item {
    /// Its table.
    pub table: Table,
    /// Wire address of its first register or bit.
    pub address: u16,
    /// Registers per item: 1, 2, 4 or a string's length (1 for bits).
    pub size: u16,
    /// Name (unique within the profile, or shared by a run of plain registers).
    pub name: String,
    /// Description.
    pub description: String,
    /// Access.
    pub access: Access,
    /// Whether it may change while the drive runs.
    pub while_running: bool,
    /// The profile's point, for its type, order and range (none for a plain table).
    pub point: Option<Point>,
}

impl Item {
    /// Decodes the value from its registers (`words` in address order): an integer as is, a
    /// float rounded, text as 0.
    pub fn decode(&self, words: &[u16]) -> i64 {
        match &self.point {
            #[allow(clippy::cast_possible_truncation)]
            Some(point) => match point.decode(words.get(..usize::from(self.size)).unwrap_or(words)) {
                Ok(Value::Int(n)) => i64::try_from(n).unwrap_or(if n < 0 { i64::MIN } else { i64::MAX }),
                Ok(Value::Float(x)) => x.round() as i64,
                Ok(Value::Bool(b)) => i64::from(b),
                Ok(Value::Text(_)) | Err(_) => 0,
            },
            None => i64::from(words.first().copied().unwrap_or_default()),
        }
    }

    /// Encodes an integer value into its registers, in address order (a float item takes it
    /// as a float; out of the type's range it is clamped).
    pub fn encode(&self, value: i64) -> Vec<u16> {
        let Some(point) = &self.point else { return vec![value.cast_unsigned() as u16] };
        #[allow(clippy::cast_precision_loss)]
        let v = if point.value_type.is_float() { Value::Float(value as f64) } else { Value::Int(i128::from(value)) };
        let (lo, hi) = point.value_type.integer_range();
        let v = match v {
            Value::Int(n) if point.value_type.is_integer() => Value::Int(n.clamp(lo, hi)),
            other => other,
        };
        point.encode(&v).unwrap_or_else(|_| vec![0; usize::from(self.size)])
    }

    /// Encodes the point's start value.
    fn encode_default(&self) -> Vec<u16> {
        match &self.point {
            Some(point) => point.encode(&point.default).unwrap_or_else(|_| vec![0; usize::from(self.size)]),
            None => vec![0],
        }
    }

    fn in_range(&self, words: &[u16]) -> bool {
        let Some(point) = &self.point else { return true };
        let Ok(value) = point.decode(words) else { return false };
        let Some(x) = value.as_f64() else { return true };
        point.min.is_none_or(|m| x >= m) && point.max.is_none_or(|m| x <= m)
    }
}

const NONE: u32 = u32::MAX;

/// A table's values and which item owns each address.
#[derive(Clone, Debug)]
struct Space<T> {
    values: Vec<T>,
    owner: Vec<u32>,
}

impl<T: Copy + Default> Space<T> {
    fn new() -> Self {
        Space { values: vec![T::default(); 0x1_0000], owner: vec![NONE; 0x1_0000] }
    }
}

/// All of a device's data.
#[derive(Clone, Debug)]
pub struct Memory {
    coils: Space<bool>,
    discrete: Space<bool>,
    holding: Space<u16>,
    input: Space<u16>,
    items: Vec<Item>,
    by_name: HashMap<String, usize>,
    /// Where unmapped addresses read as 0: `(table, first, last)` wire addresses.
    spans: Vec<(Table, u16, u16)>,
}

impl Memory {
    /// The data of a device described by `profile`, at its start values.
    pub fn new(profile: &Profile) -> Self {
        let mut m = Memory {
            coils: Space::new(),
            discrete: Space::new(),
            holding: Space::new(),
            input: Space::new(),
            items: Vec::new(),
            by_name: HashMap::new(),
            spans: Vec::new(),
        };
        let tables = [
            (Table::Coils, profile.tables.coils),
            (Table::DiscreteInputs, profile.tables.discrete_inputs),
            (Table::Holding, profile.tables.holding_registers),
            (Table::Input, profile.tables.input_registers),
        ];
        for (table, size) in tables {
            if let Some(size) = size {
                // A discrete input or input register is read-only on the bus, but the plain
                // tables of the generic device let a program set them.
                let access = Access::Rw;
                let item = m.push_item(Item::plain(table, "table", access));
                for a in 0..size.min(0x1_0000) {
                    m.own(table, a, item);
                }
            }
        }
        for point in profile.points() {
            m.add_point(point);
        }
        m.spans = Table::ALL.iter().flat_map(|&t| profile.spans(t).into_iter().map(move |(a, b)| (t, a, b))).collect();
        m
    }

    fn push_item(&mut self, item: Item) -> u32 {
        self.items.push(item);
        u32::try_from(self.items.len() - 1).unwrap_or(NONE)
    }

    fn own(&mut self, table: Table, address: u32, item: u32) {
        let slot = match table {
            Table::Coils => self.coils.owner.get_mut(address as usize),
            Table::DiscreteInputs => self.discrete.owner.get_mut(address as usize),
            Table::Holding => self.holding.owner.get_mut(address as usize),
            Table::Input => self.input.owner.get_mut(address as usize),
        };
        if let Some(slot) = slot {
            *slot = item;
        }
    }

    fn add_point(&mut self, point: &Point) {
        let item = Item {
            table: point.table,
            address: point.address,
            size: point.width,
            name: point.code.clone(),
            description: point.description.clone(),
            access: point.access,
            while_running: point.while_running,
            point: Some(point.clone()),
        };
        let words = item.encode_default();
        let (table, address, size) = (item.table, u32::from(item.address), u32::from(item.size));
        let index = self.push_item(item);
        self.by_name.insert(point.code.clone(), index as usize);
        if table.is_bits() {
            self.own(table, address, index);
            self.set_bit_raw(table, address as u16, point.default == Value::Bool(true));
            return;
        }
        for (w, word) in (0..size).zip(words) {
            self.own(table, address + w, index);
            if let Some(v) = self.words_mut(table).get_mut((address + w) as usize) {
                *v = word;
            }
        }
    }

    /// Whether unmapped `address` of `table` lies in a span (and reads as 0).
    fn in_span(&self, table: Table, address: u16) -> bool {
        self.spans.iter().any(|&(t, first, last)| t == table && (first..=last).contains(&address))
    }

    fn words(&self, table: Table) -> &Space<u16> {
        if table == Table::Input { &self.input } else { &self.holding }
    }

    fn words_mut(&mut self, table: Table) -> &mut Vec<u16> {
        if table == Table::Input { &mut self.input.values } else { &mut self.holding.values }
    }

    fn bits(&self, table: Table) -> &Space<bool> {
        if table == Table::DiscreteInputs { &self.discrete } else { &self.coils }
    }

    fn bits_mut(&mut self, table: Table) -> &mut Space<bool> {
        if table == Table::DiscreteInputs { &mut self.discrete } else { &mut self.coils }
    }

    /// The item at `address` of `table`.
    pub fn item_at(&self, table: Table, address: u16) -> Option<&Item> {
        let owner = match table {
            Table::Coils | Table::DiscreteInputs => self.bits(table).owner.get(usize::from(address)),
            Table::Holding | Table::Input => self.words(table).owner.get(usize::from(address)),
        };
        owner.copied().filter(|&o| o != NONE).and_then(|o| self.items.get(o as usize))
    }

    /// Every named item, in profile order.
    pub fn items(&self) -> &[Item] {
        &self.items
    }

    /// Reads bits; every address must belong to an item.
    pub fn read_bits(&self, table: Table, start: u16, out: &mut [bool]) -> Result<(), Denial> {
        let space = self.bits(table);
        for (i, slot) in out.iter_mut().enumerate() {
            let a = usize::from(start) + i;
            if space.owner.get(a).is_none_or(|&o| o == NONE) {
                if self.in_span(table, a as u16) {
                    *slot = false;
                    continue;
                }
                return Err(Denial::Unmapped);
            }
            let wo = self.item_at(table, a as u16).is_some_and(|it| it.access == Access::Wo);
            *slot = !wo && space.values.get(a).copied().unwrap_or_default();
        }
        Ok(())
    }

    /// Reads registers; every address must belong to an item.
    pub fn read_registers(&self, table: Table, start: u16, out: &mut [u16]) -> Result<(), Denial> {
        let space = self.words(table);
        for (i, slot) in out.iter_mut().enumerate() {
            let a = usize::from(start) + i;
            let Some(item) = self.item_at(table, a as u16) else {
                if self.in_span(table, a as u16) {
                    *slot = 0;
                    continue;
                }
                return Err(Denial::Unmapped);
            };
            *slot = if item.access == Access::Wo { 0 } else { space.values.get(a).copied().unwrap_or_default() };
        }
        Ok(())
    }

    /// Checks a write of coils from `start` without changing anything.
    pub fn check_write_bits(&self, start: u16, count: usize) -> Result<(), Denial> {
        for i in 0..count {
            let a = (usize::from(start) + i) as u16;
            match self.item_at(Table::Coils, a) {
                None => return Err(Denial::Unmapped),
                Some(item) if item.access == Access::Ro => return Err(Denial::ReadOnly),
                Some(_) => {}
            }
        }
        Ok(())
    }

    /// Writes coils (after [`Memory::check_write_bits`]).
    pub fn write_bits(&mut self, start: u16, values: impl IntoIterator<Item = bool>) {
        for (i, v) in values.into_iter().enumerate() {
            self.set_bit_raw(Table::Coils, (usize::from(start) + i) as u16, v);
        }
    }

    /// The items a register write touches, with the raw value each would have afterwards,
    /// checked for access and range. Nothing changes.
    pub fn check_write_registers(&self, start: u16, values: &[u16]) -> Result<Vec<(usize, i64)>, Denial> {
        let mut touched: Vec<(usize, i64)> = Vec::new();
        let mut a = usize::from(start);
        let end = a + values.len();
        while a < end {
            let owner = self.holding.owner.get(a).copied().unwrap_or(NONE);
            let Some(item) = self.items.get(owner as usize) else { return Err(Denial::Unmapped) };
            if item.access == Access::Ro {
                return Err(Denial::ReadOnly);
            }
            // The item's registers after the write: new values where written, old elsewhere
            // (a write of one half of a pair keeps the other half). A plain table is one item
            // owning many addresses, each its own register.
            let first = if item.point.is_none() { a } else { usize::from(item.address) };
            let words: Vec<u16> = (first..first + usize::from(item.size))
                .map(|addr| {
                    if (usize::from(start)..end).contains(&addr) {
                        values.get(addr - usize::from(start)).copied().unwrap_or_default()
                    } else {
                        self.holding.values.get(addr).copied().unwrap_or_default()
                    }
                })
                .collect();
            if !item.in_range(&words) {
                return Err(Denial::OutOfRange);
            }
            let value = item.decode(&words);
            touched.push((owner as usize, value));
            // Past the item, and never in place whatever the map says.
            a = (first + usize::from(item.size)).max(a + 1);
        }
        Ok(touched)
    }

    /// Writes registers (after [`Memory::check_write_registers`]).
    pub fn write_registers(&mut self, start: u16, values: &[u16]) {
        for (i, v) in values.iter().enumerate() {
            if let Some(slot) = self.holding.values.get_mut(usize::from(start) + i) {
                *slot = *v;
            }
        }
    }

    /// The item named `name`.
    pub fn item(&self, name: &str) -> Option<&Item> {
        self.by_name.get(name).and_then(|&i| self.items.get(i))
    }

    /// The index of the item named `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.by_name.get(name).copied()
    }

    /// The item at `index`.
    pub fn item_by_index(&self, index: usize) -> Option<&Item> {
        self.items.get(index)
    }

    /// The raw value of a named register or bit (0 if the profile has none by that name).
    pub fn get(&self, name: &str) -> i64 {
        let Some(item) = self.item(name) else { return 0 };
        match item.table {
            Table::Coils | Table::DiscreteInputs => {
                i64::from(self.bits(item.table).values.get(usize::from(item.address)).copied().unwrap_or_default())
            }
            Table::Holding | Table::Input => {
                let a = usize::from(item.address);
                let space = &self.words(item.table).values;
                let words: Vec<u16> =
                    (a..a + usize::from(item.size)).map(|i| space.get(i).copied().unwrap_or_default()).collect();
                item.decode(&words)
            }
        }
    }

    /// Sets a named register or bit, whatever its access (the device's own outputs).
    pub fn set(&mut self, name: &str, value: i64) {
        let Some(item) = self.item(name) else { return };
        let (table, address, size, words) =
            (item.table, usize::from(item.address), usize::from(item.size), item.encode(value));
        match table {
            Table::Coils | Table::DiscreteInputs => self.set_bit_raw(table, address as u16, value != 0),
            Table::Holding | Table::Input => {
                let space = self.words_mut(table);
                for (slot, word) in space.iter_mut().skip(address).zip(words).take(size) {
                    *slot = word;
                }
            }
        }
    }

    fn set_bit_raw(&mut self, table: Table, address: u16, value: bool) {
        if let Some(slot) = self.bits_mut(table).values.get_mut(usize::from(address)) {
            *slot = value;
        }
    }

    /// Sets any register of `table`, mapped or not (the FIFO, tests).
    pub fn poke(&mut self, table: Table, address: u16, value: u16) {
        if let Some(slot) = self.words_mut(table).get_mut(usize::from(address)) {
            *slot = value;
        }
    }

    /// Reads any register of `table`, mapped or not.
    pub fn peek(&self, table: Table, address: u16) -> u16 {
        self.words(table).values.get(usize::from(address)).copied().unwrap_or_default()
    }
}

impl Item {
    fn plain(table: Table, name: &str, access: Access) -> Item {
        Item {
            table,
            address: 0,
            size: 1,
            name: name.to_string(),
            description: String::new(),
            access,
            while_running: true,
            point: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rx() -> Memory {
        Memory::new(&Profile::load("omron-3g3rx").unwrap())
    }

    #[test]
    fn manual_numbers_become_wire_addresses_one_less() {
        let m = rx();
        // F001 is registers 0001h/0002h in the manual: frame addresses 0 and 1.
        assert_eq!(m.item_at(Table::Holding, 0).unwrap().name, "F001");
        assert_eq!(m.item_at(Table::Holding, 1).unwrap().name, "F001");
        assert_eq!(m.item_at(Table::Holding, 0x1102).unwrap().name, "F002");
        assert_eq!(m.item_at(Table::Coils, 0).unwrap().name, "run");
        assert!(m.item_at(Table::Holding, 0x0004).is_none(), "0005h is not in the map");
    }

    #[test]
    fn a_32_bit_pair_is_checked_as_one_value() {
        let m = rx();
        // F001 = 40000 (0x9C40) is the maximum; 40001 is out of range.
        assert!(m.check_write_registers(0, &[0x0000, 0x9C40]).is_ok());
        assert_eq!(m.check_write_registers(0, &[0x0000, 0x9C41]), Err(Denial::OutOfRange));
        assert_eq!(m.check_write_registers(0, &[0x0001, 0x0000]), Err(Denial::OutOfRange), "the high word alone");
        assert_eq!(m.check_write_registers(2, &[1]), Err(Denial::ReadOnly), "status A");
        assert_eq!(m.check_write_registers(4, &[1]), Err(Denial::Unmapped));
    }

    #[test]
    fn word_order_is_per_item() {
        let m = Memory::new(&Profile::load("sdp-servo").unwrap());
        let item = m.item("speed-command").unwrap();
        assert_eq!(item.encode(3000), [0x0BB8, 0x0000], "low word first, as the manual's example");
        assert_eq!(item.decode(&[0xFC18, 0xFFFF]), -1000);
        let rx = rx();
        assert_eq!(rx.item("F002").unwrap().encode(300_000), [0x0004, 0x93E0], "3G3RX: high word first");
    }

    #[test]
    fn plain_tables_take_writes_anywhere_in_them() {
        // One item owns the whole table; each address is still its own register.
        let mut m = Memory::new(&Profile::load("generic").unwrap());
        let values: Vec<u16> = (0..123).collect();
        let touched = m.check_write_registers(100, &values).unwrap();
        assert_eq!(touched.len(), 123);
        m.write_registers(100, &values);
        assert_eq!((m.peek(Table::Holding, 100), m.peek(Table::Holding, 222)), (0, 122));
        assert_eq!(m.check_write_registers(0xFFFF, &[7]).map(|t| t.len()), Ok(1), "the last address");
    }

    #[test]
    fn unmapped_addresses_read_as_zero_inside_a_span_and_are_refused_outside() {
        let text = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n[addressing]\nbase=1\n\
                    [[registers]]\nnumber=0x1001\nname='a'\ndefault=7\n[[registers]]\nnumber=0x1004\nname='b'\n\
                    [[span]]\ntable='holding'\nfirst=0x1001\nlast=0x1005\n";
        let m = Memory::new(&Profile::parse(text, "span.toml").unwrap());
        let mut out = [9u16; 5];
        assert_eq!(m.read_registers(Table::Holding, 0x1000, &mut out), Ok(()));
        assert_eq!(out, [7, 0, 0, 0, 0], "0x1002, 0x1003 and 0x1005 are holes in the span");
        let mut past = [0u16; 6];
        assert_eq!(m.read_registers(Table::Holding, 0x1000, &mut past), Err(Denial::Unmapped), "0x1006 is outside");
        assert_eq!(m.read_registers(Table::Input, 0x1001, &mut [0u16; 1]), Err(Denial::Unmapped), "another table");
        assert_eq!(m.check_write_registers(0x1001, &[1]), Err(Denial::Unmapped), "a span is for reads only");
    }

    #[test]
    fn every_type_is_laid_out_in_its_order_and_checked_whole() {
        let text = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
                    [[registers]]\nnumber=0\nname='f'\ntype='f32'\norder='DCBA'\ndefault=1.5\nmin=0\nmax=2\naccess='rw'\n\
                    [[registers]]\nnumber=2\nname='q'\ntype='i64'\norder='CDAB'\ndefault=-2\naccess='rw'\n\
                    [[registers]]\nnumber=6\nname='s'\ntype='string'\nlength=2\ndefault='OK'\naccess='rw'\n";
        let m = Memory::new(&Profile::parse(text, "types.toml").unwrap());
        let mut out = [0u16; 8];
        m.read_registers(Table::Holding, 0, &mut out).unwrap();
        assert_eq!(out, [0x0000, 0xC03F, 0xFFFE, 0xFFFF, 0xFFFF, 0xFFFF, 0x4F4B, 0x0000]);
        assert_eq!(m.get("q"), -2);
        // 2.5 (0x4020_0000, DCBA: 0000h then 2040h) is above max = 2; 1.75 is not.
        assert_eq!(m.check_write_registers(0, &[0x0000, 0x2040]), Err(Denial::OutOfRange));
        assert!(m.check_write_registers(0, &[0x0000, 0xE03F]).is_ok());
    }

    #[test]
    fn named_items_start_at_their_defaults() {
        let m = rx();
        assert_eq!(m.get("F002"), 1000);
        assert_eq!(m.get("status-a"), 2);
        assert_eq!(m.get("ready"), 1);
        assert_eq!(m.get("no-such-thing"), 0);
    }
}
