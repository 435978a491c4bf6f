//! Reading a profile's TOML: the document is parsed once, then every section and every entry
//! of the entry lists (`[[registers]]`, `[[coils]]`, ...) is read on its own, so that a type
//! error in one entry does not hide the mistakes of the others.
//!
//! A syntax error stops the reading (the TOML reader cannot go on past one); everything else —
//! a field of the wrong type, an unknown key, a missing field, a string with a control
//! character or past its length ([`crate::check::text`]) — is collected with the byte span
//! the reader gives, and the entries read well are checked further ([`Profile::validate`]).

use std::ops::Range;

use serde::de::DeserializeOwned;
use toml::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use crate::check::Problem;
use crate::model::{BitDef, ExceptionMeaning, Profile, RegisterDef, SpanDef};

/// The lists of entries, each an array of tables.
pub(crate) const LISTS: [&str; 7] =
    ["coils", "discrete_inputs", "registers", "inputs", "span", "exception_meaning", "fault_rule"];

/// The sections that are one table or one value.
const SECTIONS: [&str; 11] =
    ["device", "addressing", "comm", "limits", "exceptions", "tables", "model", "state", "files", "fifo", "faults"];

/// Where each entry that was read lies in the text (the span the TOML reader gives its table),
/// in the order of the profile's lists.
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

/// A profile read from TOML, with the mistakes found on the way.
pub(crate) struct Read {
    /// The profile, unless a section it cannot do without (`[device]`) could not be read.
    pub(crate) profile: Option<Profile>,
    /// Where its entries are.
    pub(crate) spans: Spans,
    /// Every mistake found while reading, with its byte offset.
    pub(crate) mistakes: Vec<Problem>,
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

/// One value read as `T`, or the reader's mistake (with its place) said of `what`.
fn one<T: DeserializeOwned>(value: Spanned<DeValue<'_>>, what: &str) -> Result<T, Problem> {
    let span = value.span();
    T::deserialize(ValueDeserializer::from(value)).map_err(|e| {
        let at = e.span().filter(|s| s.start > 0 || s.end > 0).unwrap_or(span);
        (Some(at.start), format!("{what}: {}", crate::model::with_migration_hint(e.message())))
    })
}

/// The entries of list `kind` that read as `T`, with their spans; a mistake for each other.
fn list<T: DeserializeOwned>(
    value: Spanned<DeValue<'_>>,
    kind: &str,
    spans: &mut Vec<Range<usize>>,
    unread: &mut Vec<String>,
    mistakes: &mut Vec<Problem>,
) -> Vec<T> {
    let span = value.span();
    let DeValue::Array(items) = value.into_inner() else {
        mistakes.push((Some(span.start), format!("{kind}: expected a list of tables ([[{kind}]])")));
        return Vec::new();
    };
    let mut read = Vec::new();
    for (i, item) in items.into_iter().enumerate() {
        let what = entry_name(kind, i, item.get_ref().as_table());
        let item_span = item.span();
        let name = item.get_ref().as_table().and_then(|t| t.get("name")).and_then(|v| v.get_ref().as_str());
        let name = name.map(str::to_string);
        match one::<T>(item, &what) {
            Ok(entry) => {
                read.push(entry);
                spans.push(item_span);
            }
            Err(problem) => {
                unread.extend(name);
                mistakes.push(problem);
            }
        }
    }
    read
}

/// Reads the profile of `text`; `Err` for a syntax error (the reader's place and message).
pub(crate) fn read(text: &str) -> Result<Read, toml::de::Error> {
    let root = DeTable::parse(text)?;
    let root_span = root.span();
    let mut root = root.into_inner();
    let mut mistakes = crate::check::text::strings(&root);
    let mut spans = Spans::default();
    let mut take = |key: &str| root.remove(key);
    let (mut coils, mut discrete_inputs, mut registers, mut inputs) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut span, mut exception_meaning, mut fault_rule) = (Vec::new(), Vec::new(), Vec::new());
    let unread = &mut spans.unread_names;
    if let Some(v) = take("coils") {
        coils = list::<BitDef>(v, "coils", &mut spans.coils, unread, &mut mistakes);
    }
    if let Some(v) = take("discrete_inputs") {
        discrete_inputs = list::<BitDef>(v, "discrete_inputs", &mut spans.discrete_inputs, unread, &mut mistakes);
    }
    if let Some(v) = take("registers") {
        registers = list::<RegisterDef>(v, "registers", &mut spans.registers, unread, &mut mistakes);
    }
    if let Some(v) = take("inputs") {
        inputs = list::<RegisterDef>(v, "inputs", &mut spans.inputs, unread, &mut mistakes);
    }
    if let Some(v) = take("span") {
        span = list::<SpanDef>(v, "span", &mut spans.span, unread, &mut mistakes);
    }
    if let Some(v) = take("exception_meaning") {
        let mut ignored = Vec::new();
        exception_meaning = list::<ExceptionMeaning>(v, "exception_meaning", &mut ignored, unread, &mut mistakes);
    }
    if let Some(v) = take("fault_rule") {
        fault_rule = list::<toml::Table>(v, "fault_rule", &mut spans.fault_rule, unread, &mut mistakes);
    }
    spans.faults = root.get("faults").map(Spanned::span);
    spans.state = root.get("state").map(Spanned::span);
    // Each section on its own first, so that a mistake in one does not hide another's.
    let keys: Vec<(String, Range<usize>)> = root.keys().map(|k| (k.get_ref().to_string(), k.span())).collect();
    let mut device_read = true;
    for (key, key_span) in keys {
        if !SECTIONS.contains(&key.as_str()) {
            let known = SECTIONS.iter().chain(LISTS.iter()).copied().collect::<Vec<_>>().join(", ");
            mistakes.push((Some(key_span.start), format!("unknown section `{key}`, expected one of {known}")));
            root.remove(key.as_str());
            continue;
        }
        let Some(value) = root.get(key.as_str()).cloned() else { continue };
        let what = if key == "faults" { "faults".to_string() } else { format!("[{key}]") };
        if let Err(problem) = section(&key, value, &what) {
            mistakes.push(problem);
            root.remove(key.as_str());
            device_read &= key != "device";
        }
    }
    let profile = if device_read {
        match Profile::deserialize_rest(Spanned::new(root_span, DeValue::Table(root))) {
            Ok(mut profile) => {
                profile.coils = coils;
                profile.discrete_inputs = discrete_inputs;
                profile.registers = registers;
                profile.inputs = inputs;
                profile.span = span;
                profile.exception_meaning = exception_meaning;
                profile.fault_rule = fault_rule;
                Some(profile)
            }
            Err(problem) => {
                mistakes.push(problem);
                None
            }
        }
    } else {
        None
    };
    Ok(Read { profile, spans, mistakes })
}

/// Reads section `key` as its type, for its mistakes alone.
fn section(key: &str, value: Spanned<DeValue<'_>>, what: &str) -> Result<(), Problem> {
    use crate::model::{Addressing, Comm, DeviceSection, Exceptions, Fifo, Files, Limits, ModelSection, State, Tables};
    match key {
        "device" => one::<DeviceSection>(value, what).map(drop),
        "addressing" => one::<Addressing>(value, what).map(drop),
        "comm" => one::<Comm>(value, what).map(drop),
        "limits" => one::<Limits>(value, what).map(drop),
        "exceptions" => one::<Exceptions>(value, what).map(drop),
        "tables" => one::<Tables>(value, what).map(drop),
        "model" => one::<ModelSection>(value, what).map(drop),
        "state" => one::<State>(value, what).map(drop),
        "files" => one::<Files>(value, what).map(drop),
        "fifo" => one::<Fifo>(value, what).map(drop),
        "faults" => one::<String>(value, what).map(drop),
        _ => Ok(()),
    }
}

impl Profile {
    /// The profile of a document whose entry lists were taken out (they are read one by one).
    fn deserialize_rest(root: Spanned<DeValue<'_>>) -> Result<Profile, Problem> {
        one::<Profile>(root, "the profile")
    }
}
