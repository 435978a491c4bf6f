//! Points: the profile's entries resolved to one value each, at a wire address, and the ways
//! to find them (code, label, glob, group).

use crate::model::{Access, Order, Point, Profile, Table, ValueType, parse_key};

impl Point {
    /// A point no profile describes: `value_type` at wire `address` of `table` (a bit for the
    /// bit tables), named by its address (`0x1000`), in order ABCD, unscaled, with no unit,
    /// range or meaning, read/write where the table allows, zero at start. Set the fields that
    /// differ with struct update syntax.
    pub fn raw(table: Table, address: u16, value_type: ValueType) -> Point {
        let bits = table.is_bits();
        let value_type = if bits { ValueType::Bit } else { value_type };
        Point {
            table,
            address,
            number: u32::from(address),
            code: format!("{address:#06x}"),
            label: String::new(),
            description: String::new(),
            value_type,
            order: Order::default(),
            width: value_type.registers(),
            unit: None,
            scale: 1.0,
            offset: 0.0,
            min: None,
            max: None,
            access: Access::Rw,
            while_running: true,
            group: None,
            values: Vec::new(),
            bits: Vec::new(),
            depends_on: Vec::new(),
            backup: false,
            source: None,
            confirmed: true,
            default: if bits { crate::Value::Bool(false) } else { crate::Value::Int(0) },
            factory_default: None,
            not_implemented: None,
            implemented: true,
        }
    }

    /// Whether a client may read it (write-only points read as zero).
    pub fn readable(&self) -> bool {
        self.access != Access::Wo
    }

    /// Whether a client may write it: read/write or write-only, and in a writable table.
    pub fn writable(&self) -> bool {
        self.access != Access::Ro && matches!(self.table, Table::Coils | Table::Holding)
    }

    /// The wire address just past it.
    pub fn end(&self) -> u32 {
        u32::from(self.address) + u32::from(self.width)
    }

    /// Whether `pattern` names it: its code or its label (case-insensitive; spaces, dashes
    /// and underscores alike), or a glob over either (`*` any run, `?` one character).
    pub fn matches(&self, pattern: &str) -> bool {
        let pattern = fold(pattern);
        [fold(&self.code), fold(&self.label)].iter().any(|name| !name.is_empty() && glob(&pattern, name))
    }
}

/// Lower case, with spaces, dashes and underscores as one `-`.
fn fold(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.trim().chars() {
        if matches!(c, ' ' | '-' | '_') {
            if !out.ends_with('-') {
                out.push('-');
            }
        } else {
            out.extend(c.to_lowercase());
        }
    }
    out
}

/// Whether `pattern` (with `*` and `?`) matches all of `text`.
fn glob(pattern: &str, text: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pattern.chars().collect(), text.chars().collect());
    // The classic two-pointer match with one backtrack point for the last `*`.
    let (mut pi, mut ti, mut star, mut mark) = (0usize, 0usize, None::<usize>, 0usize);
    while ti < t.len() {
        match p.get(pi) {
            Some('*') => {
                star = Some(pi);
                mark = ti;
                pi += 1;
            }
            Some(&c) if c == '?' || Some(&c) == t.get(ti) => {
                pi += 1;
                ti += 1;
            }
            _ => match star {
                Some(s) => {
                    pi = s + 1;
                    mark += 1;
                    ti = mark;
                }
                None => return false,
            },
        }
    }
    p.get(pi..).is_some_and(|rest| rest.iter().all(|&c| c == '*'))
}

/// The profile's entries as points (after the profile was checked).
pub(crate) fn resolve(profile: &Profile) -> Vec<Point> {
    let base = u32::from(profile.addressing.base);
    let mut points = Vec::new();
    for (table, defs) in [(Table::Coils, &profile.coils), (Table::DiscreteInputs, &profile.discrete_inputs)] {
        for def in defs {
            for i in 0..def.count {
                let number = def.number.saturating_add(i);
                points.push(Point {
                    table,
                    address: u16::try_from(number.saturating_sub(base)).unwrap_or(u16::MAX),
                    number,
                    code: run_name(&def.name, def.count, i),
                    label: def.label.clone().unwrap_or_default(),
                    description: def.description.clone(),
                    value_type: ValueType::Bit,
                    order: Order::Abcd,
                    width: 1,
                    unit: None,
                    scale: 1.0,
                    offset: 0.0,
                    min: None,
                    max: None,
                    access: def.access,
                    while_running: true,
                    group: def.group.clone(),
                    values: Vec::new(),
                    bits: Vec::new(),
                    depends_on: Vec::new(),
                    backup: def.backup.unwrap_or(def.access == Access::Rw && table == Table::Coils),
                    source: def.source.clone(),
                    confirmed: def.confirmed,
                    default: crate::Value::Bool(def.default.unwrap_or(false)),
                    factory_default: def.default.map(crate::Value::Bool),
                    not_implemented: None,
                    implemented: true,
                });
            }
        }
    }
    for (table, defs) in [(Table::Holding, &profile.registers), (Table::Input, &profile.inputs)] {
        for def in defs {
            let width = def.width();
            for i in 0..def.count {
                let number = def.number.saturating_add(i.saturating_mul(u32::from(width)));
                let mut values: Vec<(i128, String)> =
                    def.values.iter().filter_map(|(k, v)| Some((parse_key(k)?, v.clone()))).collect();
                values.sort_by_key(|(k, _)| *k);
                let mut bits: Vec<(u8, String)> =
                    def.bits.iter().filter_map(|(k, v)| Some((u8::try_from(parse_key(k)?).ok()?, v.clone()))).collect();
                bits.sort_by_key(|(k, _)| *k);
                points.push(Point {
                    table,
                    address: u16::try_from(number.saturating_sub(base)).unwrap_or(u16::MAX),
                    number,
                    code: run_name(&def.name, def.count, i),
                    label: def.label.clone().unwrap_or_default(),
                    description: def.description.clone(),
                    value_type: def.value_type,
                    order: def.order.unwrap_or(profile.addressing.order),
                    width,
                    unit: def.unit.clone(),
                    scale: def.scale.unwrap_or(1.0),
                    offset: def.offset.unwrap_or(0.0),
                    min: def.min,
                    max: def.max,
                    access: def.access,
                    while_running: def.while_running,
                    group: def.group.clone(),
                    values,
                    bits,
                    depends_on: def.depends_on.clone(),
                    backup: def.backup.unwrap_or(def.access == Access::Rw && table == Table::Holding),
                    source: def.source.clone(),
                    confirmed: def.confirmed,
                    default: crate::codec::default_value(def.value_type, def.default.as_ref()),
                    factory_default: def
                        .default
                        .as_ref()
                        .map(|given| crate::codec::default_value(def.value_type, Some(given))),
                    not_implemented: def.not_implemented.as_ref().map(|given| match given {
                        toml::Value::String(text) if def.value_type.is_integer() => {
                            crate::Value::Int(parse_key(text).unwrap_or_default())
                        }
                        given => crate::codec::default_value(def.value_type, Some(given)),
                    }),
                    implemented: def.implemented,
                });
            }
        }
    }
    points
}

pub(crate) fn run_name(name: &str, count: u32, i: u32) -> String {
    if count == 1 { name.to_string() } else { format!("{name}{}", i.saturating_add(1)) }
}

impl Profile {
    /// The points `pattern` names (see [`Point::matches`]), in profile order; an exact code
    /// match alone when there is one.
    pub fn find(&self, pattern: &str) -> Vec<&Point> {
        let exact: Vec<&Point> = self.points().iter().filter(|p| p.code.eq_ignore_ascii_case(pattern.trim())).collect();
        if !exact.is_empty() {
            return exact;
        }
        self.points().iter().filter(|p| p.matches(pattern)).collect()
    }

    /// The point whose code is `code` (case-insensitive).
    pub fn point(&self, code: &str) -> Option<&Point> {
        self.points().iter().find(|p| p.code.eq_ignore_ascii_case(code.trim()))
    }

    /// The points of group `group` (case-insensitive), in profile order.
    pub fn group(&self, group: &str) -> Vec<&Point> {
        self.points().iter().filter(|p| p.group.as_deref().is_some_and(|g| g.eq_ignore_ascii_case(group))).collect()
    }

    /// The groups the profile names, in order of first appearance.
    pub fn groups(&self) -> Vec<&str> {
        let mut groups: Vec<&str> = Vec::new();
        for g in self.points().iter().filter_map(|p| p.group.as_deref()) {
            if !groups.contains(&g) {
                groups.push(g);
            }
        }
        groups
    }

    /// The most items of `table` one read request may carry (the spec's limit when the
    /// profile names none).
    pub fn read_limit(&self, table: Table) -> u16 {
        if table.is_bits() { self.limits.read_coils.unwrap_or(2000) } else { self.limits.read_registers.unwrap_or(125) }
    }

    /// The most items of `table` one write request may carry (FC0F and FC10).
    pub fn write_limit(&self, table: Table) -> u16 {
        if table.is_bits() {
            self.limits.write_coils.unwrap_or(1968)
        } else {
            self.limits.write_registers.unwrap_or(123)
        }
    }

    /// The spans of `table`, as wire addresses `(first, last)`.
    pub fn spans(&self, table: Table) -> Vec<(u16, u16)> {
        let base = u32::from(self.addressing.base);
        let wire = |n: u32| u16::try_from(n.saturating_sub(base)).unwrap_or(u16::MAX);
        self.span.iter().filter(|s| s.table == table).map(|s| (wire(s.first), wire(s.last))).collect()
    }

    /// Every address of `table` that belongs to an entry or a plain table, as extents
    /// `(start, width)`.
    pub fn mapped(&self, table: Table) -> Vec<crate::Extent> {
        let plain = match table {
            Table::Coils => self.tables.coils,
            Table::DiscreteInputs => self.tables.discrete_inputs,
            Table::Holding => self.tables.holding_registers,
            Table::Input => self.tables.input_registers,
        };
        let mut extents: Vec<crate::Extent> = Vec::new();
        if let Some(size) = plain.filter(|s| *s > 0) {
            // A plain table of up to 65536 items, in extents of at most 0xFFFF.
            let size = size.min(0x1_0000);
            let first = size.min(0xFFFF);
            extents.push(crate::Extent { start: 0, width: u16::try_from(first).unwrap_or(u16::MAX) });
            if size > first {
                extents.push(crate::Extent { start: 0xFFFF, width: 1 });
            }
        }
        extents.extend(
            self.points()
                .iter()
                .filter(|p| p.table == table)
                .map(|p| crate::Extent { start: p.address, width: p.width }),
        );
        extents
    }

    /// The profile's meaning of exception `code`, if it gives one.
    pub fn exception_meaning(&self, code: u8) -> Option<&str> {
        self.exception_meaning.iter().find(|e| e.code == code).map(|e| e.meaning.as_str())
    }

    /// The default order of multi-register values.
    pub fn order(&self) -> Order {
        self.addressing.order
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs_match_whole_names_with_stars_and_question_marks() {
        assert!(glob("d0*", "d001"));
        assert!(glob("*", ""));
        assert!(glob("d??1", "d001"));
        assert!(!glob("d0*", "f001"));
        assert!(glob("*freq*", "output-frequency"));
        assert!(!glob("d00", "d001"));
        assert!(glob("a*b*c", "axxbyyc"));
        assert!(!glob("a*b*c", "axxbyy"));
    }

    #[test]
    fn a_default_is_known_only_where_the_profile_gives_one() {
        let text = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
                    [[registers]]\nnumber=0\nname='given'\ndefault=7\n\
                    [[registers]]\nnumber=1\nname='zero'\n\
                    [[coils]]\nnumber=0\nname='off'\ndefault=false\n\
                    [[coils]]\nnumber=1\nname='unsaid'\n";
        let profile = Profile::parse(text, "x.toml").unwrap();
        let known = |code: &str| profile.point(code).map(|p| (p.default.clone(), p.factory_default.clone()));
        assert_eq!(known("given"), Some((crate::Value::Int(7), Some(crate::Value::Int(7)))));
        assert_eq!(known("zero"), Some((crate::Value::Int(0), None)));
        assert_eq!(known("off"), Some((crate::Value::Bool(false), Some(crate::Value::Bool(false)))));
        assert_eq!(known("unsaid"), Some((crate::Value::Bool(false), None)));
    }

    #[test]
    fn labels_match_with_spaces_dashes_or_underscores_in_any_case() {
        assert_eq!(fold(" Output  Frequency "), "output-frequency");
        assert_eq!(fold("output_frequency"), fold("output-frequency"));
    }
}
