//! `diff FILE` (the device against a backup) and `diff A B` (two backups): each difference with
//! its code, label and both values in the profile's unit; exit 0 when equal, 1 when they
//! differ, as diff(1) does, another code for an error.

use std::path::{Path, PathBuf};

use clap::Args;
use serde_json::{Value, json};

use ferrobus_profile::Point;
use ferrobus_profile::source::ReadError;

use super::file::Backup;
use super::param::shown_toml;
use super::view::View;
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output::{self, Align, Format, OutputArgs, Rows};
use ferrobus_tools::backup::{Difference, Side, compare};

/// `diff FILE [OTHER]`, `diff --defaults [FILE]`.
#[derive(Args, Debug)]
#[command(after_help = "With one file: the device (--device PROFILE and a bus) against the backup. With two: the \
                        two backups, offline. With --defaults: the device (or the backup FILE, offline) against \
                        the profile's defaults: what was changed from the factory default, with value, default \
                        and unit; parameters whose default the profile does not give are counted, not \
                        compared. Exit 0 when equal, 1 when they differ, 7 when some parameters could not be \
                        read, another code for an error.\n\nExamples:\n  ferrobus --port /dev/ttyUSB0 --device \
                        omron-3g3rx diff drive-07.toml\n  ferrobus diff drive-07.toml drive-08.toml\n  ferrobus \
                        --port /dev/ttyUSB0 --device omron-3g3rx diff --defaults")]
pub(crate) struct DiffArgs {
    /// A backup file
    #[arg(required_unless_present = "defaults")]
    pub(crate) file: Option<PathBuf>,

    /// A second backup file, to compare with the first instead of the device
    #[arg(conflicts_with = "defaults")]
    pub(crate) other: Option<PathBuf>,

    /// Compare with the profile's defaults: what differs from the factory setting
    #[arg(long)]
    pub(crate) defaults: bool,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// One side of a comparison as JSON.
fn side_json(side: &Side) -> Value {
    match side {
        Side::Value(raw, shown) => json!({ "raw": toml_json(raw), "value": shown }),
        Side::Failed(why) => json!({ "error": why }),
        Side::Absent => Value::Null,
    }
}

/// A raw TOML value as JSON.
pub(crate) fn toml_json(raw: &toml::Value) -> Value {
    match raw {
        toml::Value::Integer(n) => json!(n),
        toml::Value::Float(f) => json!(f),
        toml::Value::Boolean(b) => json!(b),
        other => json!(shown_toml(other).trim_matches('"')),
    }
}

/// Reads a backup file, with its path in every error.
pub(crate) fn load(path: &Path) -> Result<Backup, CliError> {
    let shown = path.display().to_string();
    let text = ferrobus_profile::source::read(path).map_err(|e| match e {
        ReadError::Io(e) => CliError::Usage(format!("cannot read {shown}: {e}")),
        not_text @ ReadError::NotText(_) => CliError::Usage(not_text.located().in_file(&shown)),
    })?;
    Backup::parse(&text, &shown).map_err(|e| CliError::Usage(e.to_string()))
}

/// Runs `diff FILE [OTHER]` (`diff --defaults` is [`super::defaults::run`]).
pub(crate) async fn run(connection: &ConnectArgs, args: &DiffArgs) -> Result<(), CliError> {
    let Some(file) = &args.file else {
        return Err(CliError::Usage("diff needs a backup FILE, or --defaults".into()));
    };
    let a = load(file)?;
    let a_name = file.display().to_string();
    if let Some(other) = &args.other {
        let b = load(other)?;
        if a.header.profile != b.header.profile {
            eprintln!(
                "note: {a_name} is of profile {}, {} of profile {}",
                a.header.profile,
                other.display(),
                b.header.profile
            );
        }
        // Labels and units come from --device, or else from the first file's profile if it loads.
        let view = match &connection.device {
            Some(_) => Some(super::profile(connection, "diff")?),
            None => View::load(&a.header.profile).ok(),
        };
        let differences = compare(view.as_ref(), &a, &b);
        return finish(&differences, &a_name, &other.display().to_string(), args.output.format(), a.entries.len(), 0);
    }
    let view = super::profile(connection, "diff")?;
    if a.header.profile != view.name {
        eprintln!("note: {a_name} was made with profile {}; comparing with --device {}", a.header.profile, view.name);
    }
    connection.refuse_broadcast_read()?;
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    // The device's values of the parameters in the file, and of those the profile backs up.
    let mut params: Vec<&Point> = a.entries.iter().filter_map(|e| view.find(&e.code)).collect();
    for p in view.backed_up() {
        if !params.iter().any(|q| q.code == p.code) {
            params.push(p);
        }
    }
    let mut readings = super::device::read(&session, &view, &params, &mut interrupt).await;
    if readings.interrupted {
        return Err(CliError::Interrupted);
    }
    if readings.values.values().all(Result::is_err)
        && let Some(error) = readings.stopped.take()
    {
        return Err(error.into());
    }
    let (entries, failed) = super::entries(&params, &readings);
    let device = Backup { header: a.header.clone(), identification: Vec::new(), entries };
    let differences = compare(Some(&view), &a, &device);
    finish(&differences, &a_name, &format!("unit {}", session.unit), args.output.format(), params.len(), failed)
}

/// Prints the differences; the outcome as an exit code.
fn finish(
    differences: &[Difference],
    a: &str,
    b: &str,
    format: Format,
    compared: usize,
    unread: usize,
) -> Result<(), CliError> {
    let text = match format {
        Format::Json => output::json_line(&json!({
            "a": a,
            "b": b,
            "compared": compared,
            "equal": differences.is_empty(),
            "differences": differences.iter().map(|d| json!({
                "code": d.code,
                "label": d.label,
                "a": side_json(&d.a),
                "b": side_json(&d.b),
            })).collect::<Vec<_>>(),
        })),
        other => {
            let mut rows =
                Rows::new(&[("code", Align::Left), ("label", Align::Left), (a, Align::Left), (b, Align::Left)]);
            for d in differences {
                rows.push(vec![d.code.clone(), d.label.clone(), d.a.shown(), d.b.shown()]);
            }
            if other == Format::Table && differences.is_empty() {
                format!("{a} and {b} agree on all {compared} parameters\n")
            } else {
                rows.render(other)
            }
        }
    };
    output::print(&text)?;
    if unread > 0 {
        return Err(CliError::Incomplete(format!(
            "{unread} parameter{} could not be read from {b}: the comparison is incomplete",
            if unread == 1 { "" } else { "s" }
        )));
    }
    if differences.is_empty() { Ok(()) } else { Err(CliError::Differ) }
}
