//! Checking a parsed profile: addresses inside the space, no overlaps, types with their
//! keys, ranges, enumerations and bit fields that fit, references that exist; every problem
//! with the line of the entry or field at fault.

use serde::Deserialize;

use crate::model::{Profile, RegisterDef, ValueType};

/// The line (from 1) of byte `offset` in `text`.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    text.get(..offset).unwrap_or(text).matches('\n').count().saturating_add(1)
}

/// The line of `field` in the entry whose header is at `span` of `text` (up to the next
/// header), else the header's line.
fn field_line(text: &str, span: &std::ops::Range<usize>, field: &str) -> usize {
    let header = line_of(text, span.start);
    let body = text.get(span.end..).unwrap_or_default().lines().skip(1);
    for (n, line) in (header.saturating_add(1)..).zip(body) {
        let line = line.trim_start();
        if line.starts_with('[') {
            break;
        }
        if line.strip_prefix(field).is_some_and(|rest| rest.trim_start().starts_with('=')) {
            return n;
        }
    }
    header
}

/// Where each entry of a profile starts, read by a second pass over the same text.
#[derive(Default, Deserialize)]
pub(crate) struct Spans {
    #[serde(default)]
    coils: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    discrete_inputs: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    registers: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    inputs: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    span: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    pub(crate) fault_rule: Vec<toml::Spanned<toml::Table>>,
    pub(crate) faults: Option<toml::Spanned<String>>,
    state: Option<toml::Spanned<toml::Table>>,
}

/// A problem with the entry at a line.
type Problem = (Option<usize>, String);

impl Profile {
    #[allow(clippy::too_many_lines)]
    pub(crate) fn validate(&self, text: &str, spans: &Spans) -> Result<(), Problem> {
        let lines = |entries: &[toml::Spanned<toml::Table>]| -> Vec<Option<usize>> {
            entries.iter().map(|e| Some(line_of(text, e.span().start))).collect()
        };
        if self.comm.response_wait_ms > 60_000 {
            return Err((None, format!("response_wait_ms = {} is more than a minute", self.comm.response_wait_ms)));
        }
        let base = u64::from(self.addressing.base);
        for (kind, entries, spans) in
            [("registers", &self.registers, &spans.registers), ("inputs", &self.inputs, &spans.inputs)]
        {
            let lines = lines(spans);
            let at = |i: usize, field: &str| spans.get(i).map(|e| field_line(text, &e.span(), field));
            for (i, r) in entries.iter().enumerate() {
                let entry = format!("[[{kind}]] {} ({})", r.number, r.name);
                check_register(r, &entry, base, &|field| at(i, field))?;
            }
            let extents =
                entries.iter().map(|r| (r.number, u64::from(r.count) * u64::from(r.width()), r.name.as_str()));
            no_overlaps(kind, extents, &lines)?;
        }
        for (kind, entries, spans) in
            [("coils", &self.coils, &spans.coils), ("discrete_inputs", &self.discrete_inputs, &spans.discrete_inputs)]
        {
            let lines = lines(spans);
            for (i, b) in entries.iter().enumerate() {
                if u64::from(b.number) < base || u64::from(b.number) + u64::from(b.count) > 0x1_0000 + base {
                    let at = lines.get(i).copied().flatten();
                    return Err((
                        at,
                        format!("[[{kind}]] {} ({}): number and count run outside the address space", b.number, b.name),
                    ));
                }
            }
            no_overlaps(kind, entries.iter().map(|b| (b.number, u64::from(b.count), b.name.as_str())), &lines)?;
        }
        for t in
            [self.tables.coils, self.tables.discrete_inputs, self.tables.holding_registers, self.tables.input_registers]
                .into_iter()
                .flatten()
        {
            if t > 0x1_0000 {
                return Err((None, format!("[tables]: a table of {t} items is larger than the address space")));
            }
        }
        let span_lines = lines(&spans.span);
        for (i, s) in self.span.iter().enumerate() {
            let at = span_lines.get(i).copied().flatten();
            if s.first > s.last {
                return Err((
                    at,
                    format!("[[span]] {}: first = {} is above last = {}", s.table.name(), s.first, s.last),
                ));
            }
            if u64::from(s.first) < base || u64::from(s.last) >= 0x1_0000 + base {
                return Err((
                    at,
                    format!("[[span]] {} {}-{}: outside the address space", s.table.name(), s.first, s.last),
                ));
            }
        }
        self.check_references(text, spans)
    }

    /// `depends_on` and `[state] running` name points that exist.
    fn check_references(&self, text: &str, spans: &Spans) -> Result<(), Problem> {
        let names: Vec<&str> = self
            .coils
            .iter()
            .chain(&self.discrete_inputs)
            .map(|b| b.name.as_str())
            .chain(self.registers.iter().chain(&self.inputs).map(|r| r.name.as_str()))
            .collect();
        for (kind, entries, spans) in
            [("registers", &self.registers, &spans.registers), ("inputs", &self.inputs, &spans.inputs)]
        {
            for (i, r) in entries.iter().enumerate() {
                if let Some(missing) = r.depends_on.iter().find(|d| !names.contains(&d.as_str())) {
                    let line = spans.get(i).map(|e| field_line(text, &e.span(), "depends_on"));
                    return Err((
                        line,
                        format!(
                            "[[{kind}]] {} ({}): depends_on names {missing:?}, which the profile does not have",
                            r.number, r.name
                        ),
                    ));
                }
            }
        }
        if let Some(running) = &self.state.running {
            if !names.contains(&running.point.as_str()) {
                let line = spans.state.as_ref().map(|s| field_line(text, &s.span(), "running"));
                return Err((line, format!("[state] running: point {:?} is not in the profile", running.point)));
            }
        }
        Ok(())
    }
}

/// A raw integer written in a profile key: decimal, `0x` hex or `0b` binary, maybe negative.
pub(crate) fn parse_key(key: &str) -> Option<i128> {
    let key = key.trim();
    let (negative, digits) = key.strip_prefix('-').map_or((false, key), |rest| (true, rest));
    let value = if let Some(hex) = digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
        i128::from_str_radix(hex, 16).ok()?
    } else if let Some(bin) = digits.strip_prefix("0b").or_else(|| digits.strip_prefix("0B")) {
        i128::from_str_radix(bin, 2).ok()?
    } else {
        digits.parse::<i128>().ok()?
    };
    Some(if negative { -value } else { value })
}

#[allow(clippy::too_many_lines)]
fn check_register(r: &RegisterDef, entry: &str, base: u64, at: &dyn Fn(&str) -> Option<usize>) -> Result<(), Problem> {
    let ty = r.value_type;
    match (ty, r.length) {
        (ValueType::String, None | Some(0)) => {
            return Err((at("length"), format!("{entry}: a string needs length = its registers (1 or more)")));
        }
        (ValueType::String, Some(_)) | (_, None) => {}
        (_, Some(_)) => return Err((at("length"), format!("{entry}: length is for type = \"string\" only"))),
    }
    if r.order.is_some() && ty.registers() == 1 && ty != ValueType::String {
        return Err((
            at("order"),
            format!("{entry}: order is for values of more than one register, not {}", ty.name()),
        ));
    }
    if r.count == 0 {
        return Err((at("count"), format!("{entry}: count = 0 describes nothing")));
    }
    if u64::from(r.number) < base {
        return Err((at("number"), format!("{entry}: number is below the base {base}")));
    }
    if u64::from(r.number) + u64::from(r.count) * u64::from(r.width()) > 0x1_0000 + base {
        return Err((at("count"), format!("{entry}: count = {} runs past the address space", r.count)));
    }
    for (field, value) in [("scale", r.scale), ("offset", r.offset), ("min", r.min), ("max", r.max)] {
        if value.is_some_and(|v| !v.is_finite()) {
            return Err((at(field), format!("{entry}: {field} must be a finite number")));
        }
    }
    if r.scale == Some(0.0) {
        return Err((at("scale"), format!("{entry}: scale = 0 would make every value the same")));
    }
    if let (Some(min), Some(max)) = (r.min, r.max) {
        if min > max {
            return Err((at("max"), format!("{entry}: min = {min} is above max = {max}")));
        }
    }
    if ty == ValueType::String && (r.min.is_some() || r.max.is_some() || r.scale.is_some() || r.offset.is_some()) {
        return Err((at("type"), format!("{entry}: a string has no min, max, scale or offset")));
    }
    if ty.is_integer() {
        let (lo, hi) = ty.integer_range();
        #[allow(clippy::cast_precision_loss)]
        let (lo, hi) = (lo as f64, hi as f64);
        for (field, value) in [("min", r.min), ("max", r.max)] {
            if let Some(v) = value.filter(|v| *v < lo || *v > hi || v.fract() != 0.0) {
                return Err((at(field), format!("{entry}: {field} = {v} is not a raw {} value", ty.name())));
            }
        }
    }
    if !r.values.is_empty() && !ty.is_integer() {
        return Err((
            at("values"),
            format!("{entry}: values (an enumeration) needs an integer type, not {}", ty.name()),
        ));
    }
    for key in r.values.keys() {
        let (lo, hi) = ty.integer_range();
        if parse_key(key).is_none_or(|k| k < lo || k > hi) {
            return Err((at("values"), format!("{entry}: values key {key:?} is not a raw {} value", ty.name())));
        }
    }
    if !r.bits.is_empty() && !ty.is_integer() {
        return Err((at("bits"), format!("{entry}: bits (a bit field) needs an integer type, not {}", ty.name())));
    }
    let bit_count = i128::from(ty.registers()) * 16;
    for key in r.bits.keys() {
        if parse_key(key).is_none_or(|k| k < 0 || k >= bit_count) {
            return Err((at("bits"), format!("{entry}: bits key {key:?} is not a bit from 0 to {}", bit_count - 1)));
        }
    }
    if let Some(default) = &r.default {
        let fits = match (ty, default) {
            (ValueType::String, toml::Value::String(s)) => s.len() <= usize::from(r.width()) * 2 && s.is_ascii(),
            (t, toml::Value::Integer(n)) if t.is_integer() => {
                let (lo, hi) = t.integer_range();
                (lo..=hi).contains(&i128::from(*n))
            }
            (t, toml::Value::Integer(_) | toml::Value::Float(_)) => t.is_float(),
            _ => false,
        };
        if !fits {
            return Err((at("default"), format!("{entry}: default = {default} is not a {} value", ty.name())));
        }
    }
    Ok(())
}

/// Checks that no two entries of `kind` — `(number, items, name)`, at `lines` — share an
/// address; names the later one and the line of the earlier one.
fn no_overlaps<'a>(
    kind: &str,
    entries: impl Iterator<Item = (u32, u64, &'a str)>,
    lines: &[Option<usize>],
) -> Result<(), Problem> {
    let mut sorted: Vec<(u64, u64, &str, usize)> =
        entries.enumerate().map(|(i, (n, items, name))| (u64::from(n), items, name, i)).collect();
    sorted.sort_by_key(|&(start, _, _, i)| (start, i));
    // The entry reaching furthest so far: where it ends, and which it is.
    let mut reach: Option<(u64, usize)> = None;
    for (k, &(start, items, _, _)) in sorted.iter().enumerate() {
        if items == 0 {
            continue;
        }
        if let Some((_, owner)) = reach.filter(|&(end, _)| start < end) {
            let (Some(a), Some(b)) = (sorted.get(owner), sorted.get(k)) else { break };
            // Name the entry written later, and the line of the one written first.
            let (first, later) = if a.3 < b.3 { (a, b) } else { (b, a) };
            let what = if a.0 == b.0 { "is at the same number as" } else { "overlaps" };
            let line = |i: usize| lines.get(i).copied().flatten();
            let earlier = line(first.3).map_or(String::new(), |l| format!(" on line {l}"));
            return Err((
                line(later.3),
                format!("[[{kind}]] {} ({}) {what} {} ({}){earlier}", later.0, later.2, first.0, first.2),
            ));
        }
        let end = start.saturating_add(items);
        if reach.is_none_or(|(furthest, _)| end > furthest) {
            reach = Some((end, k));
        }
    }
    Ok(())
}
