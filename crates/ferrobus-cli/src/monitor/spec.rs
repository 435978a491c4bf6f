//! What to watch: raw read definitions (`[UNIT:]TABLE:ADDRESS[:COUNT][@RATE]`), profile points
//! (a code, a glob or `group:NAME`, with `@RATE`), and the session file that saves them with
//! the cells' formats, aliases and trends.

use std::time::Duration;

use ferrobus_profile::{Point, Profile, Table};
use serde::{Deserialize, Serialize};

use super::model::{Cell, Definition, Format};
use crate::exit::CliError;

/// The rate of a definition that gives none.
pub(crate) const DEFAULT_EVERY: Duration = Duration::from_secs(1);

/// The most registers one read definition of a profile's points may span (FC03/FC04's 125).
const MAX_SPAN: u32 = 125;

fn number(text: &str, what: &str, spec: &str) -> Result<u32, CliError> {
    let t = text.trim();
    let parsed = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => t.parse(),
    };
    parsed.map_err(|_| CliError::Usage(format!("'{spec}': {what} '{t}' is not a number")))
}

fn table(name: &str) -> Option<Table> {
    match name.to_ascii_lowercase().as_str() {
        "coils" | "coil" => Some(Table::Coils),
        "discrete" => Some(Table::DiscreteInputs),
        "holding" => Some(Table::Holding),
        "input" => Some(Table::Input),
        _ => None,
    }
}

/// Splits `@RATE` off a definition.
fn rate(spec: &str) -> Result<(&str, Duration), CliError> {
    let Some((body, rate)) = spec.rsplit_once('@') else { return Ok((spec, DEFAULT_EVERY)) };
    let every = ferrobus_sim::fault::parse_duration(rate).map_err(|e| CliError::Usage(format!("'{spec}': {e}")))?;
    if every < Duration::from_millis(10) {
        return Err(CliError::Usage(format!("'{spec}': a rate under 10 ms is not a rate a screen can show")));
    }
    Ok((body, every))
}

/// Parses one definition: raw, or (with a profile) points by name, glob or `group:NAME`.
pub(crate) fn parse(spec: &str, default_unit: u8, profile: Option<&Profile>) -> Result<Vec<Definition>, CliError> {
    let (body, every) = rate(spec)?;
    let parts: Vec<&str> = body.split(':').collect();
    let (unit, rest) = match parts.as_slice() {
        [first, rest @ ..] if !rest.is_empty() && table(rest[0]).is_some() && table(first).is_none() => {
            let unit = number(first, "the unit", spec)?;
            let unit = u8::try_from(unit)
                .ok()
                .filter(|u| (1..=247).contains(u))
                .ok_or_else(|| CliError::Usage(format!("'{spec}': unit {unit} is not 1 to 247")))?;
            (unit, rest)
        }
        all => (default_unit, all),
    };
    if let [name, address, count @ ..] = rest {
        if let Some(table) = table(name) {
            let address = number(address, "the address", spec)?;
            let count = match count {
                [] => 1,
                [count] => number(count, "the count", spec)?,
                _ => return Err(CliError::Usage(format!("'{spec}': use [UNIT:]TABLE:ADDRESS[:COUNT][@RATE]"))),
            };
            let max = if matches!(table, Table::Coils | Table::DiscreteInputs) { 2000 } else { 125 };
            if count == 0 || count > max {
                return Err(CliError::Usage(format!("'{spec}': the count is 1 to {max} for {name}")));
            }
            let address = u16::try_from(address)
                .ok()
                .filter(|a| u32::from(*a) + count <= 65536)
                .ok_or_else(|| CliError::Usage(format!("'{spec}': the range passes the last address 0xFFFF")))?;
            let count = u16::try_from(count).unwrap_or(u16::MAX);
            return Ok(vec![Definition::raw(unit, table, address, count, every)]);
        }
    }
    let Some(profile) = profile else {
        return Err(CliError::Usage(format!(
            "'{spec}' is not a read definition ([UNIT:]TABLE:ADDRESS[:COUNT][@RATE], TABLE = coils, discrete, \
             holding or input); point names need --device"
        )));
    };
    let name = rest.join(":");
    let points: Vec<&Point> = match name.strip_prefix("group:") {
        Some(group) => profile.group(group),
        None => profile.find(&name),
    };
    let points: Vec<&Point> = points.into_iter().filter(|p| p.readable()).collect();
    if points.is_empty() {
        return Err(CliError::Usage(format!(
            "'{spec}': no readable point of {} is called that (see `ferrobus profile show`)",
            profile.device.name
        )));
    }
    points_to_panes(spec, unit, every, &points)
}

/// The points as panes: by table, in address order, a new pane where the span would pass 125.
fn points_to_panes(spec: &str, unit: u8, every: Duration, points: &[&Point]) -> Result<Vec<Definition>, CliError> {
    let mut panes: Vec<Definition> = Vec::new();
    for table in [Table::Holding, Table::Input, Table::Coils, Table::DiscreteInputs] {
        let mut these: Vec<&Point> = points.iter().copied().filter(|p| p.table == table).collect();
        these.sort_by_key(|p| p.address);
        let limit = if matches!(table, Table::Coils | Table::DiscreteInputs) { 2000 } else { MAX_SPAN };
        let mut group: Vec<&Point> = Vec::new();
        for point in these {
            if point.end() - u32::from(point.address) > limit {
                return Err(CliError::Usage(format!("'{spec}': {} is wider than one read", point.code)));
            }
            let start = group.first().map_or(u32::from(point.address), |p| u32::from(p.address));
            if point.end() - start > limit {
                panes.push(pane_of(unit, table, every, &group));
                group.clear();
            }
            group.push(point);
        }
        if !group.is_empty() {
            panes.push(pane_of(unit, table, every, &group));
        }
    }
    Ok(panes)
}

fn pane_of(unit: u8, table: Table, every: Duration, points: &[&Point]) -> Definition {
    let start = points.first().map_or(0, |p| p.address);
    let end = points.iter().map(|p| p.end()).max().unwrap_or(u32::from(start));
    let count = u16::try_from(end - u32::from(start)).unwrap_or(u16::MAX);
    let cells = points
        .iter()
        .map(|p| Cell {
            point: (*p).clone(),
            format: Format::Named,
            alias: if p.label.is_empty() { p.code.clone() } else { p.label.clone() },
            trended: false,
        })
        .collect();
    Definition::with_cells(unit, table, start, count, every, cells)
}

/// The session file: what was watched and how it was shown.
#[derive(Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub(crate) struct Session {
    /// The `--device` profile, if points were watched.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) device: Option<String>,
    /// The definitions as typed.
    pub(crate) watch: Vec<String>,
    /// Cells whose format, alias or trend differ from the start.
    #[serde(default, rename = "cell", skip_serializing_if = "Vec::is_empty")]
    pub(crate) cells: Vec<CellSetting>,
}

/// One cell's settings in a session.
#[derive(Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub(crate) struct CellSetting {
    /// The pane (0-based, in the order of `watch`'s panes).
    pub(crate) pane: usize,
    /// The wire address.
    pub(crate) address: u16,
    /// The format (`u16`, `f32:CDAB`, `named`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) format: Option<String>,
    /// The alias.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) alias: Option<String>,
    /// Whether it is trended.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub(crate) trend: bool,
}

impl Session {
    /// Reads a session file.
    pub(crate) fn load(path: &str) -> Result<Session, CliError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| CliError::Usage(format!("cannot read the session file {path}: {e}")))?;
        toml::from_str(&text).map_err(|e| CliError::Usage(format!("the session file {path} is not valid: {e}")))
    }

    /// The session of the panes: `watch` and the cells' settings.
    pub(crate) fn of(device: Option<String>, watch: Vec<String>, panes: &[Definition]) -> Session {
        let mut cells = Vec::new();
        for (pane, def) in panes.iter().enumerate() {
            for cell in &def.cells {
                let format = (cell.format != Format::U16 && cell.format != Format::Named).then(|| cell.format.name());
                let named_alias = cell.format == Format::Named;
                let alias = (!cell.alias.is_empty() && !named_alias).then(|| cell.alias.clone());
                if format.is_some() || alias.is_some() || cell.trended {
                    cells.push(CellSetting { pane, address: cell.point.address, format, alias, trend: cell.trended });
                }
            }
        }
        Session { device, watch, cells }
    }

    /// Writes it to `path`.
    pub(crate) fn save(&self, path: &str) -> Result<(), String> {
        let text = toml::to_string(self).map_err(|e| e.to_string())?;
        std::fs::write(path, text).map_err(|e| format!("cannot write {path}: {e}"))
    }

    /// Applies the cells' settings to `panes`.
    pub(crate) fn apply(&self, panes: &mut [Definition]) -> Result<(), CliError> {
        for setting in &self.cells {
            let cell = panes
                .get_mut(setting.pane)
                .and_then(|p| p.cells.iter_mut().find(|c| c.point.address == setting.address))
                .ok_or_else(|| {
                    CliError::Usage(format!(
                        "the session's cell {:#06x} of pane {} is not in what it watches",
                        setting.address, setting.pane
                    ))
                })?;
            if let Some(format) = &setting.format {
                cell.set_format(Format::parse(format).map_err(CliError::Usage)?);
            }
            if let Some(alias) = &setting.alias {
                cell.alias.clone_from(alias);
            }
            cell.trended = setting.trend;
        }
        Ok(())
    }
}
