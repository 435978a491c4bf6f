//! `sniff --device PROFILE[:UNIT]`: the bus's own master's traffic as named values, written
//! as `poll` writes its records. The pairing and the decoding are the library's
//! ([`ferrobus_tools::sniff::Pairing`], [`ferrobus_tools::sniff::Heard`]); the CSV and JSON
//! lines are `poll`'s own writer ([`crate::poll::records`]), so their columns and fields are
//! poll's; the table is one line per value, as it is heard.

use std::collections::HashMap;

use ferrobus_profile::Profile;
use ferrobus_tools::sniff::{BusEvent, Pairing};

use crate::exit::CliError;
use crate::output;
use crate::poll::{CSV_HEADER, Style, records};

/// The most a unit may be (247; 0 is a broadcast, which nothing answers).
const MAX_UNIT: u8 = 247;

/// The devices watched on the bus and how their values are written.
pub(super) struct Watch {
    profile: Profile,
    units: Vec<u8>,
    style: Style,
    pairing: Pairing,
    /// Per group name, the values written of it so far (its records' `seq`).
    seqs: HashMap<String, u64>,
}

/// `PROFILE[:UNIT]`: the profile's name or path and the unit, if one is given after the last
/// colon (a Windows path's `C:` is no unit).
pub(super) fn device_unit(given: &str) -> Result<(&str, Option<u8>), CliError> {
    let Some((profile, unit)) = given.rsplit_once(':') else { return Ok((given, None)) };
    if unit.is_empty() || !unit.chars().all(|c| c.is_ascii_digit()) {
        return Ok((given, None));
    }
    match unit.parse::<u8>() {
        Ok(u @ 1..=MAX_UNIT) if !profile.is_empty() => Ok((profile, Some(u))),
        _ => Err(CliError::Usage(format!(
            "--device {}: the unit after the colon is 1 to {MAX_UNIT} (0 is a broadcast, which no device answers)",
            ferrobus::log::escape(given)
        ))),
    }
}

impl Watch {
    /// The `--device` given to sniff: its profile, and the unit after its colon, else `units`
    /// (the `--unit` filter) if given, else unit 1.
    pub(super) fn new(given: &str, units: &[u8], style: Style) -> Result<Watch, CliError> {
        let (name, unit) = device_unit(given)?;
        let profile = crate::connect::load_profile(name)?;
        let units = match (unit, units) {
            (Some(u), _) => vec![u],
            (None, []) => vec![1],
            (None, units) => units.to_vec(),
        };
        if units.contains(&0) {
            return Err(CliError::Usage("--device: unit 0 is a broadcast, which no device answers".into()));
        }
        Ok(Watch { profile, units, style, pairing: Pairing::new(), seqs: HashMap::new() })
    }

    /// What is written before the first value: the CSV header, or the table's.
    pub(super) fn header(&self) -> String {
        match self.style {
            Style::Csv => CSV_HEADER.to_string(),
            Style::Table => table_line(&["time", "unit", "group", "point", "value"]),
            Style::Jsonl => String::new(),
        }
    }

    /// Takes an event heard; a reply or an acknowledged write of a watched unit holding some
    /// of the profile's points is written, one record as a poll of it writes.
    pub(super) fn take(&mut self, event: &BusEvent) -> Result<(), CliError> {
        let Some(heard) = self.pairing.take(event) else { return Ok(()) };
        if !self.units.contains(&heard.unit) {
            return Ok(());
        }
        let Some(group) = heard.group(&self.profile) else { return Ok(()) };
        let seq = self.seqs.entry(group.name.clone()).or_default();
        let Some(sample) = heard.sample(0, *seq, &group) else { return Ok(()) };
        *seq = seq.saturating_add(1);
        let text = match self.style {
            Style::Table => {
                let since = sample.time.duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
                let time = super::show::clock_time(u64::try_from(since.as_nanos()).unwrap_or(u64::MAX));
                let unit = group.unit.to_string();
                let readings = sample.result.as_deref().unwrap_or_default();
                readings
                    .iter()
                    .filter_map(|r| {
                        let cell = group.cells.get(r.cell)?;
                        Some(table_line(&[&time, &unit, &group.name, &cell.name, &output::printable(&r.shown)]))
                    })
                    .collect()
            }
            style => records(&sample, &group, style, &[]),
        };
        output::print(&text)
    }
}

/// A line of the table: time, unit, group, point, value, each column wide enough for most.
fn table_line(fields: &[&str]) -> String {
    match fields {
        [time, unit, group, point, value] => format!("{time:<15}  {unit:>4}  {group:<24}  {point:<10}  {value}\n"),
        _ => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_unit_follows_the_last_colon_and_a_path_or_a_name_alone_has_none() {
        assert_eq!(device_unit("omron-3g3rx:3").ok(), Some(("omron-3g3rx", Some(3))));
        assert_eq!(device_unit("omron-3g3rx").ok(), Some(("omron-3g3rx", None)));
        assert_eq!(device_unit(r"C:\drives\rx.toml").ok(), Some((r"C:\drives\rx.toml", None)));
        assert_eq!(device_unit(r"C:\drives\rx.toml:7").ok(), Some((r"C:\drives\rx.toml", Some(7))));
        for bad in ["omron-3g3rx:0", "omron-3g3rx:248", "omron-3g3rx:999", ":3"] {
            assert!(matches!(device_unit(bad), Err(CliError::Usage(m)) if m.contains("1 to 247")), "{bad}");
        }
    }
}
