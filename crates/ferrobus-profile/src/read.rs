//! Reading a profile: a built-in one by name or a file by path ([`Profile::load`]), or its text
//! ([`Profile::parse`]), into the model's sections and entries, checked, with its points
//! resolved; a profile built as data is checked the same way ([`Profile::build`]).
//!
//! The document is parsed once, then every section and every entry of the entry lists
//! (`[[registers]]`, `[[coils]]`, ...) is read on its own, so that a type error in one entry
//! does not hide the mistakes of the others.
//!
//! A syntax error stops the reading (the TOML reader cannot go on past one); everything else —
//! a field of the wrong type, an unknown key, a missing field, a string with a control
//! character or past its length ([`crate::check::text`]) — is collected with the byte span
//! the reader gives, and the entries read well are checked further ([`Profile::validate`]).
//!
//! A profile is refused when its entries of one kind overlap (two registers sharing an
//! address, a 32-bit value covering the next register), and every error names the file, the
//! line and column, and the entry and field at fault ([`crate::source`]);
//! [`Profile::parse_all`] lists every mistake of a file at once.

use std::ops::Range;
use std::path::Path;

use serde::de::DeserializeOwned;
use toml::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use crate::check::{LISTS, Problem, Spans, entry_name};
use crate::model::{BUILTIN, BitDef, ExceptionMeaning, Profile, ProfileError, RegisterDef, SpanDef};
use crate::point;
use crate::source::{self, Located, Place, ReadError};

/// The sections that are one table or one value.
const SECTIONS: [&str; 11] =
    ["device", "addressing", "comm", "limits", "exceptions", "tables", "model", "state", "files", "fifo", "faults"];

/// A profile read from TOML, with the mistakes found on the way.
struct Read {
    /// The profile, unless a section it cannot do without (`[device]`) could not be read.
    profile: Option<Profile>,
    /// Where its entries are.
    spans: Spans,
    /// Every mistake found while reading, with its byte offset.
    mistakes: Vec<Problem>,
}

/// One value read as `T`, or the reader's mistake (with its place) said of `what`.
fn one<T: DeserializeOwned>(value: Spanned<DeValue<'_>>, what: &str) -> Result<T, Problem> {
    let span = value.span();
    T::deserialize(ValueDeserializer::from(value)).map_err(|e| {
        let at = e.span().filter(|s| s.start > 0 || s.end > 0).unwrap_or(span);
        (Some(at.start), format!("{what}: {}", with_migration_hint(e.message())))
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
fn read(text: &str) -> Result<Read, toml::de::Error> {
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
    /// Checks a profile built as data ([`Profile::new`]) and resolves its points, naming it
    /// `origin` in messages. It is checked as its file would be, by the one reader of
    /// profiles: written with [`Profile::to_toml`] and read back, so that no check is written
    /// twice; every mistake is returned, placed in that text.
    pub fn build(self, origin: &str) -> Result<Profile, Vec<ProfileError>> {
        Profile::parse_all(&self.to_toml(), origin)
    }

    /// A built-in profile by name.
    pub fn builtin(name: &str) -> Result<Profile, ProfileError> {
        match BUILTIN.iter().find(|(n, _)| *n == name) {
            Some((name, text)) => Profile::parse(text, name),
            None => Err(ProfileError::Unknown { name: name.to_string() }),
        }
    }

    /// A built-in profile by name, or a profile file by path.
    pub fn load(name_or_path: &str) -> Result<Profile, ProfileError> {
        if BUILTIN.iter().any(|(n, _)| *n == name_or_path) {
            return Profile::builtin(name_or_path);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            let looks_like_a_path = name_or_path.contains(['/', '\\'])
                || name_or_path.starts_with('.')
                || path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml"));
            return Err(if looks_like_a_path {
                ProfileError::NoSuchFile { path: name_or_path.to_string() }
            } else {
                ProfileError::Unknown { name: name_or_path.to_string() }
            });
        }
        let shown = path.display().to_string();
        let text = source::read(path).map_err(|e| match e {
            ReadError::Io(source) => ProfileError::Read { path: shown.clone(), source },
            ReadError::NotText(error) => ProfileError::NotText { path: shown.clone(), error },
        })?;
        Profile::parse(&text, &shown)
    }

    /// A built-in profile by name, or a profile file by path, with every mistake of the file
    /// (see [`Profile::parse_all`]).
    pub fn load_all(name_or_path: &str) -> Result<Profile, Vec<ProfileError>> {
        let path = Path::new(name_or_path);
        if BUILTIN.iter().any(|(n, _)| *n == name_or_path) || !path.exists() {
            return Profile::load(name_or_path).map_err(|e| vec![e]);
        }
        let shown = path.display().to_string();
        match source::read(path) {
            Ok(text) => Profile::parse_all(&text, &shown),
            Err(ReadError::Io(source)) => Err(vec![ProfileError::Read { path: shown, source }]),
            Err(ReadError::NotText(error)) => Err(vec![ProfileError::NotText { path: shown, error }]),
        }
    }

    /// Parses and checks a profile; `origin` names it in errors, with the place at fault. The
    /// first mistake of the file (see [`Profile::parse_all`] for every one).
    pub fn parse(text: &str, origin: &str) -> Result<Profile, ProfileError> {
        Profile::parse_all(text, origin).map_err(|mut mistakes| mistakes.swap_remove(0))
    }

    /// Parses and checks a profile, with every mistake of the file when it has any, in the
    /// file's order: the TOML reader stops at its first, the checks of a well-formed file
    /// find them all. Never an empty list.
    pub fn parse_all(text: &str, origin: &str) -> Result<Profile, Vec<ProfileError>> {
        let read = read(text).map_err(|e| {
            let mut mistake = Located::toml(text, &e);
            mistake.message = with_migration_hint(&mistake.message);
            vec![ProfileError::Parse { origin: origin.to_string(), mistake }]
        })?;
        let spans = read.spans;
        // The reader's mistakes, then the checks' of the entries it read: all in the file's order.
        let mut mistakes: Vec<(Option<usize>, String, bool)> =
            read.mistakes.into_iter().map(|(at, message)| (at, message, true)).collect();
        let mut profile = read.profile;
        if let Some(profile) = profile.as_mut() {
            profile.origin = origin.to_string();
            profile.faults_place = spans.faults.as_ref().map(|f| Place::of(text, f.start));
            profile.fault_rule_places = spans.fault_rule.iter().map(|e| Some(Place::of(text, e.start))).collect();
            mistakes.extend(profile.validate(text, &spans).into_iter().map(|(at, message)| (at, message, false)));
        }
        match profile {
            Some(mut profile) if mistakes.is_empty() => {
                profile.points = point::resolve(&profile);
                Ok(profile)
            }
            _ => {
                mistakes.sort_by_key(|(at, _, _)| at.unwrap_or(0));
                Err(mistakes
                    .into_iter()
                    .map(|(at, message, parse)| {
                        let mistake = Located::new(text, at.map(|a| a..a), &message);
                        let origin = origin.to_string();
                        if parse {
                            ProfileError::Parse { origin, mistake }
                        } else {
                            ProfileError::Invalid { origin, mistake }
                        }
                    })
                    .collect())
            }
        }
    }

    /// The profile of a document whose entry lists were taken out (they are read one by one).
    fn deserialize_rest(root: Spanned<DeValue<'_>>) -> Result<Profile, Problem> {
        one::<Profile>(root, "the profile")
    }
}

/// A TOML reader's message, with the new keys named when it refuses an old one.
fn with_migration_hint(message: &str) -> String {
    let old =
        ["`size`", "`signed`", "`word_order`"].iter().any(|key| message.starts_with(&format!("unknown field {key}")));
    if old {
        format!(
            "{message} (size, signed and word_order are now type and order: type = \"u32\" or \"i32\", \
             order = \"ABCD\" for high-first or \"CDAB\" for low-first)"
        )
    } else {
        message.to_string()
    }
}

#[cfg(test)]
mod tests;
