//! The session file: what `ferrobus poll --session F` polls and `ferrobus monitor` saves and
//! loads. TOML:
//!
//! ```toml
//! # Raw ranges: one read request each, at their own rate.
//! [[read]]
//! name = "drive 3 status"   # optional; else "u3 holding 0x1000"
//! unit = 3
//! table = "holding"         # holding, input, coils, discrete
//! address = 0x1000          # wire address of the first item
//! count = 4                 # items (default 1)
//! format = "u16"            # u16 i16 hex binary u32 i32 f32 f64 (default u16)
//! order = "ABCD"            # multi-register order: ABCD CDAB BADC DCBA (default ABCD)
//! every = "100ms"           # period: us, ms, s, min (default 1s)
//! [[read.cell]]             # optional: a name or another format for one cell
//! address = 0x1002
//! alias = "speed"
//! format = "i32"
//! order = "CDAB"            # optional: this cell's own order (else the read's)
//! trend = true              # optional: monitor charts it (poll ignores it)
//!
//! # Named points of a device profile, in the planner's fewest requests.
//! [[points]]
//! unit = 1
//! device = "omron-3g3rx"    # a built-in profile or a profile file
//! names = ["d001", "d002"]  # codes, labels or globs
//! groups = ["monitor"]      # the profile's groups
//! every = "500ms"
//! trends = ["d001"]         # optional: points monitor charts (poll ignores it)
//! ```

use std::path::Path;
use std::time::Duration;

use ferrobus_profile::source::{self, Located, ReadError};
use ferrobus_profile::{Order, Profile, Table};
use serde::{Deserialize, Serialize};

use super::{Format, Group, GroupError, Layout};

/// A session: raw ranges and profile points.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Session {
    /// Raw ranges.
    #[serde(default, rename = "read", skip_serializing_if = "Vec::is_empty")]
    pub reads: Vec<ReadDef>,
    /// Profile points.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub points: Vec<PointsDef>,
}

/// `[[read]]`: a raw range.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadDef {
    /// Its name; else made from the unit, table and address.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The unit.
    pub unit: u8,
    /// `holding`, `input`, `coils` or `discrete`.
    pub table: String,
    /// The wire address of the first item.
    pub address: u16,
    /// Items read.
    #[serde(default = "one")]
    pub count: u16,
    /// The cells' format (`u16` unless given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub format: Option<String>,
    /// The order of multi-register cells (`ABCD` unless given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub order: Option<String>,
    /// The period (`1s` unless given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub every: Option<String>,
    /// Cells with a name or another format.
    #[serde(default, rename = "cell", skip_serializing_if = "Vec::is_empty")]
    pub cells: Vec<CellDef>,
}

/// `[[read.cell]]`: one cell's alias or format.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellDef {
    /// Its wire address.
    pub address: u16,
    /// Its name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alias: Option<String>,
    /// Its format.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub format: Option<String>,
    /// Its own order of registers (`ABCD` ...), if not the read's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub order: Option<String>,
    /// Whether `monitor` charts it (its trends); `poll` ignores it.
    #[serde(default, skip_serializing_if = "is_false")]
    pub trend: bool,
}

/// `[[points]]`: named points of a profile.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointsDef {
    /// The unit.
    pub unit: u8,
    /// A built-in profile's name or a profile file's path.
    pub device: String,
    /// Codes, labels or globs.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub names: Vec<String>,
    /// The profile's groups.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<String>,
    /// The period (`1s` unless given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub every: Option<String>,
    /// Codes of the points `monitor` charts (its trends); `poll` ignores them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub trends: Vec<String>,
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a reference
fn is_false(b: &bool) -> bool {
    !*b
}

fn one() -> u16 {
    1
}

/// Why a session file cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SessionError {
    /// It could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// It is not a valid session: `file:line:col: message (in `excerpt`)`, a few hundred bytes
    /// at most however long the line ([`ferrobus_profile::source`]).
    #[error("{}", mistake.in_file(origin))]
    Parse {
        /// The file.
        origin: String,
        /// Where and what.
        mistake: Located,
    },
    /// A definition names something that does not exist or does not fit (what the file says
    /// is cut to a few hundred bytes).
    #[error("{origin}: {what}: {}", source::bounded(problem))]
    Invalid {
        /// The file.
        origin: String,
        /// The definition (`read 2`, `points 1`).
        what: String,
        /// What is wrong.
        problem: String,
    },
}

impl Session {
    /// Reads and parses a session file.
    pub fn load(path: &Path) -> Result<Session, SessionError> {
        let shown = path.display().to_string();
        let text = source::read(path).map_err(|e| match e {
            ReadError::Io(source) => SessionError::Io { path: shown.clone(), source },
            not_text @ ReadError::NotText(_) => {
                SessionError::Parse { origin: shown.clone(), mistake: not_text.located() }
            }
        })?;
        Session::parse(&text, &shown)
    }

    /// Parses a session; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Session, SessionError> {
        toml::from_str(text)
            .map_err(|e| SessionError::Parse { origin: origin.to_string(), mistake: Located::toml(text, &e) })
    }

    /// The session as TOML.
    pub fn to_toml(&self) -> String {
        // Every field is a string, a number or a table of them: serialising cannot fail.
        toml::to_string(self).unwrap_or_default()
    }

    /// Writes the session to `path`.
    pub fn save(&self, path: &Path) -> Result<(), SessionError> {
        let text = format!("# ferrobus session (poll --session, monitor --session)\n{}", self.to_toml());
        std::fs::write(path, text).map_err(|source| SessionError::Io { path: path.display().to_string(), source })
    }

    /// The groups it defines, `[[read]]`s first; profiles are loaded with `load_profile`.
    pub fn groups(
        &self,
        origin: &str,
        mut load_profile: impl FnMut(&str) -> Result<Profile, String>,
    ) -> Result<Vec<Group>, SessionError> {
        let mut out = Vec::new();
        for (i, r) in self.reads.iter().enumerate() {
            let what = format!("read {}", i.saturating_add(1));
            out.push(r.group().map_err(|problem| SessionError::Invalid {
                origin: origin.to_string(),
                what,
                problem: problem.to_string(),
            })?);
        }
        for (i, p) in self.points.iter().enumerate() {
            let invalid = |problem: String| SessionError::Invalid {
                origin: origin.to_string(),
                what: format!("points {}", i.saturating_add(1)),
                problem,
            };
            let every = period(p.every.as_deref()).map_err(|e| invalid(e.to_string()))?;
            let profile = load_profile(&p.device).map_err(invalid)?;
            if p.names.is_empty() && p.groups.is_empty() {
                return Err(invalid("give names or groups".into()));
            }
            let groups =
                Group::points(&profile, p.unit, &p.names, &p.groups, every).map_err(|e| invalid(e.to_string()))?;
            out.extend(groups);
        }
        Ok(out)
    }
}

/// Why a value of a session definition was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DefError {
    /// No table by that name.
    #[error("table {name:?}: give holding, input, coils or discrete")]
    Table {
        /// The name, trimmed and lowercased.
        name: String,
    },
    /// No word order by that name.
    #[error("order {name:?}: give ABCD, CDAB, BADC or DCBA")]
    Order {
        /// The name given.
        name: String,
    },
    /// No format by that name.
    #[error("format {name:?}: give one of {}", Format::ALL.iter().map(|f| f.name()).collect::<Vec<_>>().join(", "))]
    Format {
        /// The name given.
        name: String,
    },
    /// A period that is not a duration (the one grammar, [`ferrobus::text::duration`]).
    #[error("period: {0}")]
    Period(ferrobus::text::TextError),
    /// A period of zero or of more than a day.
    #[error("period {text:?}: give more than 0 and at most a day")]
    PeriodRange {
        /// The period given.
        text: String,
    },
    /// The group cannot be made.
    #[error(transparent)]
    Group(#[from] GroupError),
}

impl ReadDef {
    /// The group it defines.
    pub fn group(&self) -> Result<Group, DefError> {
        let table = table_from_name(&self.table)?;
        let format = format_of(self.format.as_deref())?.unwrap_or_default();
        let order = order_of(self.order.as_deref())?.unwrap_or_default();
        let mut layout = Layout { format, order, ..Layout::default() };
        for c in &self.cells {
            if let Some(f) = format_of(c.format.as_deref())? {
                layout.formats.push((c.address, f));
            }
            if let Some(o) = order_of(c.order.as_deref())? {
                layout.orders.push((c.address, o));
            }
            if let Some(a) = &c.alias {
                layout.aliases.push((c.address, a.clone()));
            }
        }
        let every = period(self.every.as_deref())?;
        let name =
            self.name.clone().unwrap_or_else(|| format!("u{} {} {:#06x}", self.unit, table.name(), self.address));
        let range = super::RawRange { unit: self.unit, table, start: self.address, count: self.count, every };
        Ok(Group::raw(&name, range, &layout)?)
    }
}

/// A table by its name: `holding`, `input`, `coils`, `discrete` (and `discrete-inputs`).
pub fn table_from_name(name: &str) -> Result<Table, DefError> {
    match name.trim().to_ascii_lowercase().as_str() {
        "holding" => Ok(Table::Holding),
        "input" => Ok(Table::Input),
        "coils" | "coil" => Ok(Table::Coils),
        "discrete" | "discrete-inputs" => Ok(Table::DiscreteInputs),
        other => Err(DefError::Table { name: other.to_string() }),
    }
}

/// An order by name (`ABCD`, `CDAB`, `BADC`, `DCBA`).
pub fn order_of(name: Option<&str>) -> Result<Option<Order>, DefError> {
    name.map(|o| Order::from_name(o).ok_or_else(|| DefError::Order { name: o.to_string() })).transpose()
}

fn format_of(name: Option<&str>) -> Result<Option<Format>, DefError> {
    name.map(|n| Format::from_name(n).ok_or_else(|| DefError::Format { name: n.to_string() })).transpose()
}

/// A period by the one grammar of durations ([`ferrobus::text::duration`]: `250us`, `100ms`,
/// `2s`, `1min`; a plain number is milliseconds), above 0 and at most a day; `None` is 1 s.
pub fn period(text: Option<&str>) -> Result<Duration, DefError> {
    let Some(text) = text else { return Ok(Duration::from_secs(1)) };
    let period = ferrobus::text::duration(text).map_err(DefError::Period)?;
    if period.is_zero() || period > Duration::from_secs(86_400) {
        return Err(DefError::PeriodRange { text: text.to_string() });
    }
    Ok(period)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_period_is_the_one_duration_grammar_above_zero_and_at_most_a_day() {
        for (typed, want) in ferrobus::text::DURATION_EXAMPLES {
            assert_eq!(period(Some(typed)), Ok(want), "{typed}");
        }
        assert_eq!(period(None), Ok(Duration::from_secs(1)));
        assert!(period(Some("0ms")).unwrap_err().to_string().contains("more than 0"));
        assert!(period(Some("25h")).unwrap_err().to_string().contains("at most a day"));
        assert!(period(Some("10 parsecs")).unwrap_err().to_string().contains("unknown unit 'parsecs'"));
    }
}
