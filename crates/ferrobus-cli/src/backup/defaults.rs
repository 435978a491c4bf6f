//! `diff --defaults [FILE]`: what was changed from the factory default, as vendor tools show
//! it — the device's parameters (or a backup's) whose value differs from the `default` the
//! profile gives, with name, value, default and unit. A parameter whose default the profile
//! does not know is not compared; how many there are is said. Exit 0 when none differs, 1
//! when some do, 7 when some could not be read.

use serde_json::{Value as Json, json};

use ferrobus_profile::{Point, Value};

use super::diff::toml_json;
use super::file::{Backup, State};
use super::param;
use super::view::View;
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output::{self, Align, Format, Rows};

/// A parameter that differs from its default.
struct Changed<'v> {
    point: &'v Point,
    value: Value,
    default: &'v Value,
}

/// What the comparison found.
struct Found<'v> {
    /// Parameters whose value is not the default, in the profile's order.
    changed: Vec<Changed<'v>>,
    /// Parameters compared (a default known, a value read).
    compared: usize,
    /// The codes of the parameters whose default the profile does not know.
    unknown: Vec<&'v str>,
    /// The codes of the parameters with a default but no value (not read), and why.
    unread: Vec<(&'v str, String)>,
}

/// Runs `diff --defaults` on the device, or on `file` when given.
pub(crate) async fn run(
    connection: &ConnectArgs,
    file: Option<&std::path::Path>,
    format: Format,
) -> Result<(), CliError> {
    if let Some(path) = file {
        return of_file(connection, path, format);
    }
    let view = super::profile(connection, "diff --defaults")?;
    connection.refuse_broadcast_read()?;
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let (known, unknown) = split(&view);
    let readings = super::device::read(&session, &view, &known, &mut interrupt).await;
    if readings.interrupted {
        return Err(CliError::Interrupted);
    }
    if readings.values.values().all(Result::is_err)
        && let Some(error) = readings.stopped
    {
        return Err(error.into());
    }
    let values = known.iter().map(|p| {
        let value = match readings.values.get(&p.code) {
            Some(Ok(words)) => param::decode(p, words).map_err(|e| e.to_string()),
            Some(Err(why)) => Err(why.clone()),
            None => Err("not read".into()),
        };
        (*p, value)
    });
    finish(&compare(values, unknown), &format!("unit {}", session.unit), format)
}

/// `diff --defaults FILE`: the backup against the defaults of `--device`, or else of the
/// profile the file names.
fn of_file(connection: &ConnectArgs, path: &std::path::Path, format: Format) -> Result<(), CliError> {
    let backup = super::diff::load(path)?;
    let view = if connection.device.is_some() {
        super::profile(connection, "diff --defaults")?
    } else {
        View::load(&backup.header.profile).map_err(|e| {
            CliError::Usage(format!("{}: its profile does not load ({e}); name one with --device", path.display()))
        })?
    };
    finish(&of_backup(&view, &backup), &path.display().to_string(), format)
}

/// The parameters the profile backs up, split into those whose default it knows and the
/// codes of the others.
fn split(view: &View) -> (Vec<&Point>, Vec<&str>) {
    let (known, unknown): (Vec<&Point>, Vec<&Point>) =
        view.backed_up().into_iter().partition(|p| p.factory_default.is_some());
    (known, unknown.into_iter().map(|p| p.code.as_str()).collect())
}

/// The backup's parameters against the profile's defaults (parameters the profile lacks are
/// left out).
fn of_backup<'v>(view: &'v View, backup: &Backup) -> Found<'v> {
    let mut unknown = Vec::new();
    let mut values = Vec::new();
    for entry in &backup.entries {
        let Some(point) = view.find(&entry.code) else { continue };
        if point.factory_default.is_none() {
            unknown.push(point.code.as_str());
            continue;
        }
        let value = match &entry.state {
            State::Value { raw, .. } => param::from_toml(point, raw).map_err(|e| e.to_string()),
            State::Failed(why) => Err(format!("the backup holds no value: {why}")),
        };
        values.push((point, value));
    }
    compare(values.into_iter(), unknown)
}

/// Each value against its point's default, through the registers both encode to.
fn compare<'v>(values: impl Iterator<Item = (&'v Point, Result<Value, String>)>, unknown: Vec<&'v str>) -> Found<'v> {
    let mut found = Found { changed: Vec::new(), compared: 0, unknown, unread: Vec::new() };
    for (point, value) in values {
        let Some(default) = &point.factory_default else { continue };
        match value {
            Ok(value) => {
                found.compared += 1;
                if param::encode(point, &value).ok() != param::encode(point, default).ok() {
                    found.changed.push(Changed { point, value, default });
                }
            }
            Err(why) => found.unread.push((point.code.as_str(), why)),
        }
    }
    found
}

/// A value without its unit (the unit has its own column): an enumeration's meaning, else the
/// number at the point's resolution.
fn bare(point: &Point, raw: &Value) -> String {
    point.meaning(raw).unwrap_or_else(|| point.number(raw))
}

/// Prints what differs and what was not compared; the outcome as an exit code.
fn finish(found: &Found<'_>, what: &str, format: Format) -> Result<(), CliError> {
    let text = match format {
        Format::Json => output::json_line(&json!({
            "source": what,
            "compared": found.compared,
            "equal": found.changed.is_empty(),
            "changed": found.changed.iter().map(|c| json!({
                "code": c.point.code,
                "label": param::label(c.point),
                "value": { "raw": toml_json(&param::to_toml(&c.value)), "value": c.point.show(&c.value) },
                "default": { "raw": toml_json(&param::to_toml(c.default)), "value": c.point.show(c.default) },
                "unit": c.point.unit.clone().map_or(Json::Null, Json::from),
            })).collect::<Vec<_>>(),
            "no_default": found.unknown,
            "unread": found.unread.iter().map(|(code, why)| json!({ "code": code, "error": why })).collect::<Vec<_>>(),
        })),
        other => {
            let mut rows = Rows::new(&[
                ("code", Align::Left),
                ("label", Align::Left),
                ("value", Align::Right),
                ("default", Align::Right),
                ("unit", Align::Left),
            ]);
            for c in &found.changed {
                rows.push(vec![
                    c.point.code.clone(),
                    param::label(c.point).to_string(),
                    bare(c.point, &c.value),
                    bare(c.point, c.default),
                    c.point.unit.clone().unwrap_or_default(),
                ]);
            }
            if other == Format::Table && found.changed.is_empty() {
                format!("{what}: all {} parameters with a known default are at it\n", found.compared)
            } else {
                rows.render(other)
            }
        }
    };
    output::print(&text)?;
    if format == Format::Table {
        let unknown = found.unknown.len();
        eprintln!(
            "diff --defaults: {} of {} parameters of {what} differ from the profile's default{}",
            found.changed.len(),
            found.compared,
            if unknown == 0 {
                String::new()
            } else {
                format!(
                    "; {unknown} more ha{} no default in the profile and {} not compared (--json lists them)",
                    if unknown == 1 { "s" } else { "ve" },
                    if unknown == 1 { "was" } else { "were" }
                )
            }
        );
    }
    if !found.unread.is_empty() {
        let codes: Vec<&str> = found.unread.iter().map(|(code, _)| *code).collect();
        let first = found.unread.first().map(|(_, why)| why.as_str()).unwrap_or_default();
        return Err(CliError::Incomplete(format!(
            "{} parameter{} with a default could not be compared ({}): {first}",
            codes.len(),
            if codes.len() == 1 { "" } else { "s" },
            codes.join(", ")
        )));
    }
    if found.changed.is_empty() { Ok(()) } else { Err(CliError::Differ) }
}
