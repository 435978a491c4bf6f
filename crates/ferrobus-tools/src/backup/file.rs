//! The backup file: TOML, written by hand so that each parameter's label is a comment above
//! it and the order is the profile's, read back with serde (errors name the file and line).
//! The format is described in the module doc of [`super`]. A file that is not a backup of
//! this format is a [`BackupError`] naming the file and the line.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use ferrobus_profile::source;
use serde::Deserialize;

/// Why a text is not a backup this build reads: each names the file and, where there is
/// one, the line.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BackupError {
    /// Not TOML of a backup's shape (a missing field, a value of the wrong kind, ...).
    #[error("{origin}{}: not a backup file: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    NotBackup {
        /// The file.
        origin: String,
        /// The line, when the parser knows it.
        line: Option<usize>,
        /// The parser's message (bounded).
        message: String,
    },
    /// Another format version.
    #[error("{origin}:{line}: backup format {found} is not the format {FORMAT} this ferrobus reads")]
    Format {
        /// The file.
        origin: String,
        /// The line of `format`.
        line: usize,
        /// The version it gives.
        found: u32,
    },
    /// A parameter's entry that is neither a value nor an error, or a `raw` of the wrong kind.
    #[error("{origin}:{line}: {code}: {problem}")]
    Entry {
        /// The file.
        origin: String,
        /// The entry's line.
        line: usize,
        /// The parameter.
        code: String,
        /// What is wrong with it.
        problem: &'static str,
    },
}

/// The format version this build writes and reads.
pub const FORMAT: u32 = 1;

/// The header of a backup: what was saved, from where, when.
#[derive(Clone, PartialEq, Debug)]
pub struct Header {
    /// The profile: a built-in name or the path of the profile file.
    pub profile: String,
    /// `sha256:…` of the profile file, for one that is not built in.
    pub profile_hash: Option<String>,
    /// The device's name in the profile.
    pub device: String,
    /// When, ISO-8601 UTC.
    pub time: String,
    /// The unit read.
    pub unit: u8,
    /// The bus it was read over.
    pub connection: String,
    /// How the device identified itself, or why it did not.
    pub identification: String,
}

/// One parameter's entry.
#[derive(Clone, PartialEq, Debug)]
pub struct Entry {
    /// Its code.
    pub code: String,
    /// Its label (written as a comment; not read back).
    pub label: String,
    /// The line it is on, in a file read back (0 for one not read from a file).
    pub line: usize,
    /// Its value, or why there is none.
    pub state: State,
}

/// A parameter's value in a backup, or the reason it could not be read.
#[derive(Clone, PartialEq, Debug)]
pub enum State {
    /// The raw value, and as the profile shows it.
    Value {
        /// The raw value.
        raw: toml::Value,
        /// In the profile's unit.
        shown: String,
    },
    /// It could not be read: why.
    Failed(String),
}

/// A whole backup.
#[derive(Clone, PartialEq, Debug)]
pub struct Backup {
    /// The header.
    pub header: Header,
    /// The identification objects read from the device, by name.
    pub identification: Vec<(String, String)>,
    /// The parameters, in the profile's order.
    pub entries: Vec<Entry>,
}

impl Backup {
    /// The entry of `code` (case-insensitively).
    pub fn entry(&self, code: &str) -> Option<&Entry> {
        self.entries.iter().find(|e| e.code.eq_ignore_ascii_case(code))
    }

    /// The file's text.
    pub fn render(&self) -> String {
        let h = &self.header;
        let mut out = String::new();
        let _ = writeln!(out, "# ferrobus backup of unit {} ({}), profile {}", h.unit, h.device, h.profile);
        out.push_str(
            "# Each parameter: its raw value as the device holds it and that value in the profile's unit\n\
             # (only `raw` is read back). Compare: ferrobus --device PROFILE ... diff FILE;\n\
             # write back what differs: ferrobus --device PROFILE ... restore FILE --apply.\n\n[backup]\n",
        );
        let _ = writeln!(out, "format = {FORMAT}");
        let _ = writeln!(out, "profile = {}", quoted(&h.profile));
        if let Some(hash) = &h.profile_hash {
            let _ = writeln!(out, "profile_hash = {}", quoted(hash));
        }
        for (key, value) in [
            ("device", &h.device),
            ("time", &h.time),
            ("connection", &h.connection),
            ("identification", &h.identification),
        ] {
            let _ = writeln!(out, "{key} = {}", quoted(value));
        }
        let _ = writeln!(out, "unit = {}", h.unit);
        if !self.identification.is_empty() {
            out.push_str("\n[identification]\n");
            for (name, value) in &self.identification {
                let _ = writeln!(out, "{} = {}", key(name), quoted(value));
            }
        }
        out.push_str("\n[parameters]\n");
        for entry in &self.entries {
            let label = entry.label.split_whitespace().collect::<Vec<_>>().join(" ");
            if !label.is_empty() {
                let _ = writeln!(out, "# {label}");
            }
            let _ = match &entry.state {
                State::Value { raw, shown } => {
                    writeln!(out, "{} = {{ raw = {raw}, value = {} }}", key(&entry.code), quoted(shown))
                }
                State::Failed(why) => writeln!(out, "{} = {{ error = {} }}", key(&entry.code), quoted(why)),
            };
        }
        out
    }

    /// Reads a backup file's text; `origin` (the path) names it in errors, with the line.
    pub fn parse(text: &str, origin: &str) -> Result<Backup, BackupError> {
        let doc: Doc = toml::from_str(text).map_err(|e| BackupError::NotBackup {
            origin: origin.to_string(),
            line: e.span().map(|s| line_of(text, s.start)),
            message: source::bounded(e.message().trim()),
        })?;
        let header = doc.backup.into_inner();
        if header.format != FORMAT {
            return Err(BackupError::Format {
                origin: origin.to_string(),
                line: line_of(text, text.find("format").unwrap_or(0)),
                found: header.format,
            });
        }
        let mut entries = Vec::new();
        for (code, spanned) in doc.parameters {
            let line = line_of(text, spanned.span().start);
            let entry = spanned.into_inner();
            let problem =
                |problem| BackupError::Entry { origin: origin.to_string(), line, code: code.clone(), problem };
            let state = match (entry.raw, entry.error) {
                (Some(raw), None) => State::Value { raw, shown: entry.value.unwrap_or_default() },
                (None, Some(why)) => State::Failed(why),
                (Some(_), Some(_)) => return Err(problem("both `raw` and `error`")),
                (None, None) => return Err(problem("neither `raw` nor `error`")),
            };
            if let State::Value {
                raw: toml::Value::Array(_) | toml::Value::Table(_) | toml::Value::Datetime(_), ..
            } = &state
            {
                return Err(problem("`raw` must be a number, a string or true/false"));
            }
            entries.push(Entry { code, label: String::new(), line, state });
        }
        entries.sort_by_key(|e| e.line);
        Ok(Backup {
            header: Header {
                profile: header.profile,
                profile_hash: header.profile_hash,
                device: header.device,
                time: header.time,
                unit: header.unit,
                connection: header.connection,
                identification: header.identification,
            },
            identification: doc.identification.into_iter().collect(),
            entries,
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Doc {
    backup: toml::Spanned<HeaderDoc>,
    #[serde(default)]
    identification: BTreeMap<String, String>,
    #[serde(default)]
    parameters: BTreeMap<String, toml::Spanned<EntryDoc>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HeaderDoc {
    format: u32,
    profile: String,
    profile_hash: Option<String>,
    device: String,
    time: String,
    unit: u8,
    connection: String,
    identification: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EntryDoc {
    raw: Option<toml::Value>,
    value: Option<String>,
    error: Option<String>,
}

/// The 1-based line of byte `offset`.
fn line_of(text: &str, offset: usize) -> usize {
    source::Place::of(text, offset).line
}

/// A TOML string.
fn quoted(text: &str) -> String {
    toml::Value::String(text.to_string()).to_string()
}

/// A TOML key: bare if it can be, quoted otherwise.
fn key(name: &str) -> String {
    let bare = !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if bare { name.to_string() } else { quoted(name) }
}

/// Now, ISO-8601 UTC to the second.
pub fn now_utc() -> String {
    crate::poll::iso8601(std::time::SystemTime::now())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Backup {
        Backup {
            header: Header {
                profile: "omron-3g3rx".into(),
                profile_hash: None,
                device: "Omron 3G3RX inverter".into(),
                time: "2026-12-01T22:00:00Z".into(),
                unit: 7,
                connection: "/dev/ttyUSB0 at 19200 8E1 (RTU)".into(),
                identification: "none: the profile says the device has no identification".into(),
            },
            identification: Vec::new(),
            entries: vec![
                Entry {
                    code: "F002".into(),
                    label: "Acceleration time 1".into(),
                    line: 0,
                    state: State::Value { raw: toml::Value::Integer(1000), shown: "10.00 s".into() },
                },
                Entry {
                    code: "odd name".into(),
                    label: "two\nlines".into(),
                    line: 0,
                    state: State::Failed("exception 0x02 (Illegal Data Address)".into()),
                },
            ],
        }
    }

    #[test]
    fn a_rendered_backup_reads_back_the_same_with_its_lines() {
        let backup = sample();
        let text = backup.render();
        assert!(text.contains("# Acceleration time 1\nF002 = { raw = 1000, value = \"10.00 s\" }\n"), "{text}");
        assert!(text.contains("# two lines\n\"odd name\" = { error = "), "{text}");
        let back = Backup::parse(&text, "b.toml").unwrap();
        assert_eq!(back.header, backup.header);
        let codes: Vec<_> = back.entries.iter().map(|e| (e.code.as_str(), e.state.clone())).collect();
        assert_eq!(codes, [("F002", backup.entries[0].state.clone()), ("odd name", backup.entries[1].state.clone())]);
        let f002_line = text.lines().position(|l| l.starts_with("F002")).unwrap() + 1;
        assert_eq!(back.entries[0].line, f002_line);
    }

    #[test]
    fn a_broken_backup_is_refused_with_its_file_and_line() {
        let text = sample().render().replace("raw = 1000", "raw = ");
        let err = Backup::parse(&text, "b.toml").unwrap_err().to_string();
        let line = text.lines().position(|l| l.starts_with("F002")).unwrap() + 1;
        assert!(err.starts_with(&format!("b.toml:{line}: not a backup file")), "{err}");
        let both = sample().render().replace("raw = 1000,", "raw = 1000, error = \"x\",");
        assert!(Backup::parse(&both, "b.toml").unwrap_err().to_string().ends_with("F002: both `raw` and `error`"));
        let later = sample().render().replace("format = 1", "format = 9");
        let later = Backup::parse(&later, "b.toml").unwrap_err();
        assert!(matches!(later, BackupError::Format { found: 9, .. }), "{later}");
        assert!(later.to_string().contains("backup format 9 is not the format 1"));
        let err = Backup::parse("[backup]\nformat = 1\n", "c.toml").unwrap_err().to_string();
        assert!(err.starts_with("c.toml:") && err.contains("missing field"), "{err}");
    }
}
