//! Checking a parsed profile: addresses inside the space, no overlaps, types with their
//! keys, ranges, enumerations and bit fields that fit, references that exist; every problem,
//! not only the first, each with the place of the entry or field at fault.

pub(crate) mod text;

use std::collections::HashMap;
use std::ops::Range;

use toml::de::DeTable;

use crate::model::{Profile, RegisterDef, ValueType, parse_key};
use crate::source::Place;

/// The byte offset of `field` in the entry whose header is at `span` of `text` (up to the
/// next header), else the header's.
fn field_offset(text: &str, span: &Range<usize>, field: &str) -> usize {
    let mut offset = span.end;
    for (n, line) in text.get(span.end..).unwrap_or_default().split_inclusive('\n').enumerate() {
        let here = offset;
        offset = offset.saturating_add(line.len());
        if n == 0 {
            continue; // the rest of the header's line
        }
        let key = line.trim_start();
        if key.starts_with('[') {
            break;
        }
        if key.strip_prefix(field).is_some_and(|rest| rest.trim_start().starts_with('=')) {
            return here.saturating_add(line.len().saturating_sub(key.len()));
        }
    }
    span.start
}

/// A problem, with the byte offset of the entry or field at fault when known.
pub(crate) type Problem = (Option<usize>, String);

/// The lists of entries, each an array of tables.
pub(crate) const LISTS: [&str; 7] =
    ["coils", "discrete_inputs", "registers", "inputs", "span", "exception_meaning", "fault_rule"];

/// Where each entry that was read lies in the text (the span the TOML reader gives its table),
/// in the order of the profile's lists: the reader finds them, the checks place problems by them.
#[derive(Default)]
pub(crate) struct Spans {
    pub(crate) coils: Vec<Range<usize>>,
    pub(crate) discrete_inputs: Vec<Range<usize>>,
    pub(crate) registers: Vec<Range<usize>>,
    pub(crate) inputs: Vec<Range<usize>>,
    pub(crate) span: Vec<Range<usize>>,
    pub(crate) fault_rule: Vec<Range<usize>>,
    pub(crate) faults: Option<Range<usize>>,
    pub(crate) state: Option<Range<usize>>,
    /// The names of the entries that could not be read: a reference to one of them is not a
    /// second mistake.
    pub(crate) unread_names: Vec<String>,
}

/// What an entry of list `kind` is called in a message, as the checks call it:
/// `[[registers]] 3 (F001)` by its number and name, `[[registers]] entry 3 (F001)` (counted
/// from 1) when its number cannot be read.
pub(crate) fn entry_name(kind: &str, index: usize, table: Option<&DeTable<'_>>) -> String {
    let name = table
        .and_then(|t| t.get("name"))
        .and_then(|v| v.get_ref().as_str())
        .map(|n| format!(" ({})", crate::source::bounded(&n.chars().take(64).collect::<String>())))
        .unwrap_or_default();
    let number = table
        .and_then(|t| t.get("number"))
        .and_then(|v| v.get_ref().as_integer())
        .and_then(|n| u32::from_str_radix(&n.as_str().replace('_', ""), n.radix()).ok());
    match number {
        Some(number) => format!("[[{kind}]] {number}{name}"),
        None => format!("[[{kind}]] entry {}{name}", index.saturating_add(1)),
    }
}

impl Profile {
    /// Every problem of the profile parsed from `text`, in the file's sections' order.
    pub(crate) fn validate(&self, text: &str, spans: &Spans) -> Vec<Problem> {
        let mut problems = Vec::new();
        let starts =
            |entries: &[Range<usize>]| -> Vec<Option<usize>> { entries.iter().map(|e| Some(e.start)).collect() };
        if self.comm.response_wait_ms > 60_000 {
            problems.push((None, format!("response_wait_ms = {} is more than a minute", self.comm.response_wait_ms)));
        }
        let base = u64::from(self.addressing.base);
        for (kind, entries, spans) in
            [("registers", &self.registers, &spans.registers), ("inputs", &self.inputs, &spans.inputs)]
        {
            let at = |i: usize, field: &str| spans.get(i).map(|e| field_offset(text, e, field));
            for (i, r) in entries.iter().enumerate() {
                let entry = format!("[[{kind}]] {} ({})", r.number, r.name);
                check_register(r, &entry, base, &|field| at(i, field), &mut problems);
            }
            let extents =
                entries.iter().map(|r| (r.number, u64::from(r.count) * u64::from(r.width()), r.name.as_str()));
            no_overlaps(text, kind, extents, &starts(spans), &mut problems);
        }
        for (kind, entries, spans) in
            [("coils", &self.coils, &spans.coils), ("discrete_inputs", &self.discrete_inputs, &spans.discrete_inputs)]
        {
            let starts = starts(spans);
            for (i, b) in entries.iter().enumerate() {
                if u64::from(b.number) < base || u64::from(b.number) + u64::from(b.count) > 0x1_0000 + base {
                    problems.push((
                        starts.get(i).copied().flatten(),
                        format!("[[{kind}]] {} ({}): number and count run outside the address space", b.number, b.name),
                    ));
                }
            }
            let extents = entries.iter().map(|b| (b.number, u64::from(b.count), b.name.as_str()));
            no_overlaps(text, kind, extents, &starts, &mut problems);
        }
        for t in
            [self.tables.coils, self.tables.discrete_inputs, self.tables.holding_registers, self.tables.input_registers]
                .into_iter()
                .flatten()
        {
            if t > 0x1_0000 {
                problems.push((None, format!("[tables]: a table of {t} items is larger than the address space")));
            }
        }
        let span_starts = starts(&spans.span);
        for (i, s) in self.span.iter().enumerate() {
            let at = span_starts.get(i).copied().flatten();
            if s.first > s.last {
                problems
                    .push((at, format!("[[span]] {}: first = {} is above last = {}", s.table.name(), s.first, s.last)));
            } else if u64::from(s.first) < base || u64::from(s.last) >= 0x1_0000 + base {
                problems.push((
                    at,
                    format!("[[span]] {} {}-{}: outside the address space", s.table.name(), s.first, s.last),
                ));
            }
        }
        self.check_references(text, spans, &mut problems);
        self.one_code_each(text, spans, &mut problems);
        problems
    }

    /// `depends_on` and `[state] running` name points that exist.
    fn check_references(&self, text: &str, spans: &Spans, problems: &mut Vec<Problem>) {
        let names: Vec<&str> = self
            .coils
            .iter()
            .chain(&self.discrete_inputs)
            .map(|b| b.name.as_str())
            .chain(self.registers.iter().chain(&self.inputs).map(|r| r.name.as_str()))
            .chain(spans.unread_names.iter().map(String::as_str))
            .collect();
        for (kind, entries, spans) in
            [("registers", &self.registers, &spans.registers), ("inputs", &self.inputs, &spans.inputs)]
        {
            for (i, r) in entries.iter().enumerate() {
                for missing in r.depends_on.iter().filter(|d| !names.contains(&d.as_str())) {
                    problems.push((
                        spans.get(i).map(|e| field_offset(text, e, "depends_on")),
                        format!(
                            "[[{kind}]] {} ({}): depends_on names {missing:?}, which the profile does not have",
                            r.number, r.name
                        ),
                    ));
                }
            }
        }
        if let Some(running) = &self.state.running
            && !names.contains(&running.point.as_str())
        {
            problems.push((
                spans.state.as_ref().map(|s| field_offset(text, s, "running")),
                format!("[state] running: point {:?} is not in the profile", running.point),
            ));
        }
    }
}

/// An entry for [`Profile::one_code_each`]: its list, number, name, count and start.
type Entry<'a> = (&'a str, u32, &'a str, u32, Option<usize>);

impl Profile {
    /// No two entries share a name and no two points a code (a run's NAME1, NAME2, ...), in
    /// any case: `get`, `set`, a backup and the bridge find a point by its code, whatever its
    /// case. Each mistake names both entries, the later one first.
    fn one_code_each(&self, text: &str, spans: &Spans, problems: &mut Vec<Problem>) {
        let mut entries: Vec<Entry<'_>> = Vec::new();
        for (kind, list, spans) in
            [("coils", &self.coils, &spans.coils), ("discrete_inputs", &self.discrete_inputs, &spans.discrete_inputs)]
        {
            entries.extend(
                list.iter()
                    .enumerate()
                    .map(|(i, b)| (kind, b.number, b.name.as_str(), b.count, spans.get(i).map(|s| s.start))),
            );
        }
        for (kind, list, spans) in
            [("registers", &self.registers, &spans.registers), ("inputs", &self.inputs, &spans.inputs)]
        {
            entries.extend(
                list.iter()
                    .enumerate()
                    .map(|(i, r)| (kind, r.number, r.name.as_str(), r.count, spans.get(i).map(|s| s.start))),
            );
        }
        let name_of = |e: &Entry<'_>| {
            let line = e.4.map_or(String::new(), |at| format!(" on line {}", Place::of(text, at).line));
            format!("[[{}]] {} ({}){line}", e.0, e.1, e.2)
        };
        let mut names: HashMap<String, usize> = HashMap::new();
        let mut codes: HashMap<String, usize> = HashMap::new();
        for (n, entry) in entries.iter().enumerate() {
            let (kind, number, name, count, at) = *entry;
            if let Some(first) = names.get(&name.to_lowercase()).and_then(|&f| entries.get(f)) {
                problems
                    .push((at, format!("[[{kind}]] {number} ({name}): the name is also that of {}", name_of(first))));
                continue;
            }
            names.insert(name.to_lowercase(), n);
            if count > 0x1_0000 {
                continue; // refused for running past the address space
            }
            let mine: Vec<String> = (0..count).map(|i| crate::point::run_name(name, count, i).to_lowercase()).collect();
            if let Some((code, first)) =
                mine.iter().find_map(|code| codes.get(code).and_then(|&f| entries.get(f)).map(|first| (code, first)))
            {
                let code = (0..count)
                    .map(|i| crate::point::run_name(name, count, i))
                    .find(|c| c.to_lowercase() == *code)
                    .unwrap_or_default();
                problems.push((
                    at,
                    format!(
                        "[[{kind}]] {number} ({name}): its point {code} has the code of a point of {}",
                        name_of(first)
                    ),
                ));
                continue;
            }
            for code in mine {
                codes.entry(code).or_insert(n);
            }
        }
    }
}

#[allow(clippy::too_many_lines)]
/// Pushes every problem of register entry `r` (named `entry`; `at` finds a field's place).
fn check_register(
    r: &RegisterDef,
    entry: &str,
    base: u64,
    at: &dyn Fn(&str) -> Option<usize>,
    problems: &mut Vec<Problem>,
) {
    let mut problem = |field: &str, message: String| problems.push((at(field), format!("{entry}: {message}")));
    let ty = r.value_type;
    match (ty, r.length) {
        (ValueType::String, None | Some(0)) => {
            problem("length", "a string needs length = its registers (1 or more)".into());
        }
        (ValueType::String, Some(_)) | (_, None) => {}
        (_, Some(_)) => problem("length", "length is for type = \"string\" only".into()),
    }
    if r.order.is_some() && ty.registers() == 1 && ty != ValueType::String {
        problem("order", format!("order is for values of more than one register, not {}", ty.name()));
    }
    if r.count == 0 {
        problem("count", "count = 0 describes nothing".into());
    }
    if u64::from(r.number) < base {
        problem("number", format!("number is below the base {base}"));
    }
    if u64::from(r.number) + u64::from(r.count) * u64::from(r.width()) > 0x1_0000 + base {
        problem("count", format!("count = {} runs past the address space", r.count));
    }
    for (field, value) in [("scale", r.scale), ("offset", r.offset), ("min", r.min), ("max", r.max)] {
        if value.is_some_and(|v| !v.is_finite()) {
            problem(field, format!("{field} must be a finite number"));
        }
    }
    if r.scale == Some(0.0) {
        problem("scale", "scale = 0 would make every value the same".into());
    }
    if let (Some(min), Some(max)) = (r.min, r.max)
        && min > max
    {
        problem("max", format!("min = {min} is above max = {max}"));
    }
    if ty == ValueType::String && (r.min.is_some() || r.max.is_some() || r.scale.is_some() || r.offset.is_some()) {
        problem("type", "a string has no min, max, scale or offset".into());
    }
    if ty.is_integer() {
        let (lo, hi) = ty.integer_range();
        #[allow(clippy::cast_precision_loss)]
        let (lo, hi) = (lo as f64, hi as f64);
        for (field, value) in [("min", r.min), ("max", r.max)] {
            if let Some(v) = value.filter(|v| *v < lo || *v > hi || v.fract() != 0.0) {
                problem(field, format!("{field} = {v} is not a raw {} value", ty.name()));
            }
        }
    }
    if !r.values.is_empty() && !ty.is_integer() {
        problem("values", format!("values (an enumeration) needs an integer type, not {}", ty.name()));
    }
    for key in r.values.keys() {
        let (lo, hi) = ty.integer_range();
        if parse_key(key).is_none_or(|k| k < lo || k > hi) {
            problem("values", format!("values key {key:?} is not a raw {} value", ty.name()));
        }
    }
    if !r.bits.is_empty() && !ty.is_integer() {
        problem("bits", format!("bits (a bit field) needs an integer type, not {}", ty.name()));
    }
    let bit_count = i128::from(ty.registers()) * 16;
    for key in r.bits.keys() {
        if parse_key(key).is_none_or(|k| k < 0 || k >= bit_count) {
            problem("bits", format!("bits key {key:?} is not a bit from 0 to {}", bit_count - 1));
        }
    }
    let fits = |value: &toml::Value| match (ty, value) {
        (ValueType::String, toml::Value::String(s)) => s.len() <= usize::from(r.width()) * 2 && s.is_ascii(),
        (t, toml::Value::Integer(n)) if t.is_integer() => {
            let (lo, hi) = t.integer_range();
            (lo..=hi).contains(&i128::from(*n))
        }
        (t, toml::Value::Integer(_) | toml::Value::Float(_)) => t.is_float(),
        _ => false,
    };
    // A not-implemented u64 (0xFFFFFFFFFFFFFFFF) is past TOML's integers: it may be written as text.
    let raw_text = |value: &toml::Value| match value {
        toml::Value::String(s) if ty.is_integer() => {
            let (lo, hi) = ty.integer_range();
            parse_key(s).is_some_and(|n| (lo..=hi).contains(&n))
        }
        _ => false,
    };
    for (field, value) in [("default", &r.default), ("not_implemented", &r.not_implemented)] {
        let fits = |v: &toml::Value| fits(v) || (field == "not_implemented" && raw_text(v));
        if let Some(value) = value.as_ref().filter(|v| !fits(v)) {
            problem(field, format!("{field} = {value} is not a {} value", ty.name()));
        }
    }
}

/// Pushes a problem for each entry of `kind` — `(number, items, name)`, starting at byte
/// `starts` of `text` — that shares an address with an earlier one; names the later entry and
/// the line of the earlier one.
fn no_overlaps<'a>(
    text: &str,
    kind: &str,
    entries: impl Iterator<Item = (u32, u64, &'a str)>,
    starts: &[Option<usize>],
    problems: &mut Vec<Problem>,
) {
    let mut sorted: Vec<(u64, u64, &str, usize)> =
        entries.enumerate().map(|(i, (n, items, name))| (u64::from(n), items, name, i)).collect();
    sorted.sort_by_key(|&(start, _, _, i)| (start, i));
    let start_of = |i: usize| starts.get(i).copied().flatten();
    // The entry reaching furthest so far: where it ends, and which it is.
    let mut reach: Option<(u64, usize)> = None;
    for (k, &(start, items, _, _)) in sorted.iter().enumerate() {
        if items == 0 {
            continue;
        }
        if let Some((_, owner)) = reach.filter(|&(end, _)| start < end)
            && let (Some(a), Some(b)) = (sorted.get(owner), sorted.get(k))
        {
            // Name the entry written later, and the line of the one written first.
            let (first, later) = if a.3 < b.3 { (a, b) } else { (b, a) };
            let what = if a.0 == b.0 { "is at the same number as" } else { "overlaps" };
            let earlier =
                start_of(first.3).map_or(String::new(), |at| format!(" on line {}", Place::of(text, at).line));
            problems.push((
                start_of(later.3),
                format!("[[{kind}]] {} ({}) {what} {} ({}){earlier}", later.0, later.2, first.0, first.2),
            ));
        }
        let end = start.saturating_add(items);
        if reach.is_none_or(|(furthest, _)| end > furthest) {
            reach = Some((end, k));
        }
    }
}
