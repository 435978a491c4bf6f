//! SunSpec devices: `scan --sunspec` lists a device's model chain, `--device sunspec` makes
//! its models the profile of `get`, `poll` and `backup`.
//!
//! Both are thin over [`ferrobus_sunspec`]: open the bus, [`ferrobus_sunspec::discover`],
//! then print the models or build the profile. `--sunspec-models PATH` (or
//! `FERROBUS_SUNSPEC_MODELS` at run time) adds model definitions to the built-in ones.

use std::path::Path;
use std::sync::Arc;

use ferrobus_sunspec::{Definitions, Discovery};
use serde_json::json;

use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::output::{self, Align, Format, Rows};

/// The `--device` name that discovers the profile.
pub(crate) use crate::connect::SUNSPEC as DEVICE;

/// The model definitions: built-in plus `--sunspec-models`.
pub(crate) fn definitions(connection: &ConnectArgs) -> Result<Definitions, CliError> {
    Definitions::with(connection.sunspec_models.as_deref()).map_err(CliError::Usage)
}

/// Opens the bus and walks the unit's model chain.
async fn walk(connection: &ConnectArgs, defs: &Definitions) -> Result<(Discovery, String), CliError> {
    let session = connection.open().await?;
    let limit = connection.max_per_request(None, crate::address::Table::Holding, false).ok().flatten().unwrap_or(125);
    let found = ferrobus_sunspec::discover(&session.client, session.unit, defs, limit)
        .await
        .map_err(|e| CliError::Usage(format!("{} unit {}: {e}", session.target, session.unit)))?;
    Ok((found, format!("sunspec at {} unit {}", session.target, session.unit)))
}

/// `connection` with its `--device sunspec` discovered into a profile; `connection` itself for
/// any other device.
pub(crate) async fn resolve(connection: &ConnectArgs) -> Result<ConnectArgs, CliError> {
    let mut resolved = connection.clone();
    if connection.device.as_deref() != Some(DEVICE) {
        return Ok(resolved);
    }
    let defs = definitions(connection)?;
    let (found, origin) = walk(connection, &defs).await?;
    let profile = ferrobus_sunspec::profile(&found, &defs, &origin, 125).map_err(|e| CliError::Usage(e.to_string()))?;
    if profile.points().is_empty() {
        return Err(CliError::Usage(format!(
            "{origin}: none of the models found ({}) has a definition that fits: `ferrobus scan --sunspec` lists them",
            found.models.iter().map(|m| m.id.to_string()).collect::<Vec<_>>().join(", ")
        )));
    }
    resolved.sunspec = Some(Arc::new(profile));
    Ok(resolved)
}

/// `scan --sunspec` over TCP: the unit's models, as a table or `--json`; with `save`, their
/// profile written there too.
pub(crate) async fn scan(connection: &ConnectArgs, format: Format, save_to: Option<&Path>) -> Result<(), CliError> {
    let defs = definitions(connection)?;
    let (found, origin) = walk(connection, &defs).await?;
    if let Some(path) = save_to {
        let limit =
            connection.max_per_request(None, crate::address::Table::Holding, false).ok().flatten().unwrap_or(125);
        save(&found, &defs, &origin, limit, path)?;
    }
    let text = match format {
        Format::Json => {
            output::json_line(&json!({ "device": origin, "base": found.base, "models": models_json(&found) }))
        }
        Format::Csv => model_rows(&found).csv(),
        Format::Table => {
            format!(
                "{origin}: \"SunS\" at {}, {} models\n{}",
                found.base,
                found.models.len(),
                model_rows(&found).table()
            )
        }
    };
    output::print(&text)
}

/// Writes the profile of `found` to a new file at `path` (checked first: the profile
/// `--device sunspec` would make, written as every profile is) and says so on stderr.
pub(crate) fn save(
    found: &Discovery,
    defs: &Definitions,
    origin: &str,
    limit: u16,
    path: &Path,
) -> Result<(), CliError> {
    let profile = ferrobus_sunspec::profile(found, defs, origin, limit).map_err(|e| CliError::Usage(e.to_string()))?;
    let text = profile.to_toml();
    let header = format!(
        "# Written by `ferrobus scan --sunspec --save-profile` from {origin}: the models found then, their\n\
         # scale factors as read then. A device whose scale factors change needs a new scan.\n\n"
    );
    output::write_file(path, &format!("{header}{text}"), false, "remove it, or save to another file")?;
    let what = format!("{}: {} points of {} models\n", path.display(), profile.points().len(), found.models.len());
    output::write_to(&mut std::io::stderr(), "stderr", &format!("scan: profile saved to {what}"))
}

/// What the definition says of a model found: `ok`, `no definition`, or what differs.
fn fit(m: &ferrobus_sunspec::Found) -> String {
    match &m.fits {
        None => "no definition".to_string(),
        Some(Ok(())) => "ok".to_string(),
        Some(Err(why)) => why.clone(),
    }
}

/// The models of `found` as JSON objects: id, name, start, length, fits, problem.
pub(crate) fn models_json(found: &Discovery) -> Vec<serde_json::Value> {
    found
        .models
        .iter()
        .map(|m| {
            json!({
                "id": m.id,
                "name": m.name,
                "start": m.start,
                "length": m.length,
                "fits": m.fits.as_ref().map(Result::is_ok),
                "problem": m.fits.as_ref().and_then(|f| f.as_ref().err()),
            })
        })
        .collect()
}

/// The columns of a model found, as [`model_cells`] fills them.
pub(crate) const MODEL_COLUMNS: [(&str, Align); 5] = [
    ("model", Align::Right),
    ("name", Align::Left),
    ("start", Align::Right),
    ("length", Align::Right),
    ("definition", Align::Left),
];

/// The models of `found` as rows: model, name, start, length, definition.
pub(crate) fn model_rows(found: &Discovery) -> Rows {
    let mut rows = Rows::new(&MODEL_COLUMNS);
    for m in &found.models {
        rows.push(model_cells(m));
    }
    rows
}

/// One model's cells of [`model_rows`].
pub(crate) fn model_cells(m: &ferrobus_sunspec::Found) -> Vec<String> {
    vec![
        m.id.to_string(),
        m.name.clone().unwrap_or_else(|| "?".into()),
        m.start.to_string(),
        m.length.to_string(),
        fit(m),
    ]
}
