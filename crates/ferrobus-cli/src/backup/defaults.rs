//! `diff --defaults [FILE]`: what was changed from the factory default, as vendor tools show
//! it — the device's parameters (or a backup's) whose value differs from the `default` the
//! profile gives, with name, value, default and unit. A parameter whose default the profile
//! does not know is not compared; how many there are is said. Exit 0 when none differs, 1
//! when some do, 7 when some could not be read.

use serde_json::{Value as Json, json};

use ferrobus_profile::{Point, Value};
use ferrobus_tools::backup::defaults::{Found, compare, of_backup, split};

use super::diff::toml_json;
use super::param;
use super::view::View;
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output::{self, Align, Format, Rows};

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
