//! `ferrobus profile list | show NAME | check FILE | import MAP | export PROFILE`: the device
//! profiles, offline.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand, ValueEnum};
use ferrobus_profile::exchange::{self, ImportError, ImportOptions};
use ferrobus_profile::{BUILTIN, Point, Profile, Value, ValueType};
use serde_json::json;

use crate::exit::CliError;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `profile ...`.
#[derive(Args, Debug)]
pub(crate) struct ProfileArgs {
    /// What to do.
    #[command(subcommand)]
    pub(crate) action: Action,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// The `profile` actions.
#[derive(Subcommand, Debug)]
pub(crate) enum Action {
    /// The built-in profiles
    List,
    /// A profile's parameter table
    Show {
        /// A built-in name or a TOML file
        #[arg(value_name = "PROFILE")]
        name: String,
        /// Only this group
        #[arg(long)]
        group: Option<String>,
    },
    /// Check a profile file: every mistake with its file and line
    Check {
        /// The TOML file (or a built-in name)
        #[arg(value_name = "FILE")]
        file: String,
    },
    /// Turn a device map of another tool into a profile: a vendor's CSV register list, or the
    /// YAML of a Home Assistant or evcc configuration. What could not be mapped is listed on
    /// stderr; the profile written passes `profile check`. Formats: docs/device-maps.md
    Import {
        /// The map file
        #[arg(value_name = "FILE")]
        file: PathBuf,
        /// What the file is
        #[arg(long = "from", value_enum, value_name = "FORMAT")]
        from: MapFormat,
        /// Write the profile to this file instead of stdout (an existing file is kept unless
        /// --force)
        #[arg(long, short = 'o', value_name = "PROFILE.toml")]
        output: Option<PathBuf>,
        /// Replace the --output file if it exists
        #[arg(long, requires = "output")]
        force: bool,
        /// The profile's device name [default: the file's name]
        #[arg(long, value_name = "NAME")]
        name: Option<String>,
        /// Only the entries of this unit (Home Assistant's slave, evcc's id): needed when the
        /// file describes several devices
        #[arg(long = "only-unit", value_name = "UNIT")]
        only_unit: Option<u8>,
        /// Only the entries of the evcc device of this name (a meter's or charger's `name:`):
        /// needed when the file describes several, one profile each; it names the profile
        #[arg(long = "only-device", value_name = "NAME")]
        only_device: Option<String>,
        /// The number the CSV gives the first register (1 for a manual's register numbers);
        /// subtracted from every CSV address. Unless given, a file whose every address is a
        /// Modicon number (30001, 40001, ...) is read as one (with a note), any other from 0
        #[arg(long = "first-address", value_name = "N")]
        first_address: Option<u16>,
    },
    /// Write a profile as a CSV register list (one row per point, the columns `import --from
    /// csv` reads back)
    Export {
        /// A built-in name or a TOML file
        #[arg(value_name = "PROFILE")]
        name: String,
        /// The format written
        #[arg(long = "to", value_enum, value_name = "FORMAT", default_value_t = ExportFormat::Csv)]
        to: ExportFormat,
        /// Write to this file instead of stdout (an existing file is kept unless --force)
        #[arg(long, short = 'o', value_name = "FILE")]
        output: Option<PathBuf>,
        /// Replace the --output file if it exists
        #[arg(long, requires = "output")]
        force: bool,
    },
}

/// What `profile import` reads.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub(crate) enum MapFormat {
    /// A register list as CSV (ours, or a vendor's columns)
    Csv,
    /// A Home Assistant `modbus:` configuration
    HaYaml,
    /// An evcc configuration (its `source: modbus` blocks)
    EvccYaml,
}

/// What `profile export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum ExportFormat {
    /// A register list as CSV
    Csv,
}

/// Runs `profile`.
pub(crate) fn run(args: &ProfileArgs) -> Result<(), CliError> {
    let format = args.output.format();
    match &args.action {
        Action::List => list(format),
        Action::Show { name, group } => show(name, group.as_deref(), format),
        Action::Check { file } => check(file, format),
        Action::Import { file, from, output, force, name, only_unit, only_device, first_address } => {
            // A YAML map's `!include` and `!secret` are read from the map's directory.
            let dir = file.parent().map(|d| if d.as_os_str().is_empty() { Path::new(".") } else { d }.to_path_buf());
            let options = ImportOptions {
                name: name.clone(),
                unit: *only_unit,
                device: only_device.clone(),
                base: *first_address,
                dir,
            };
            import(file, *from, &options, output.as_deref(), *force, format)
        }
        Action::Export { name, to: ExportFormat::Csv, output, force } => {
            let profile = crate::connect::load_profile(name)?;
            let text = exchange::export_csv(&profile);
            match output {
                Some(path) => output::write_file(path, &text, *force, "give --force to replace it"),
                None => output::print(&text),
            }
        }
    }
}

/// `profile import`: the profile to `output` (or stdout), the unmapped list and a summary on
/// stderr (with `--json`, one document on stdout instead).
fn import(
    file: &Path,
    from: MapFormat,
    options: &ImportOptions,
    output: Option<&Path>,
    force: bool,
    format: Format,
) -> Result<(), CliError> {
    let shown = file.display().to_string();
    if std::fs::metadata(file).is_ok_and(|m| m.len() > exchange::MAP_MAX) {
        let why = format!("{shown}: larger than the {} MiB a map file may be: refused", exchange::MAP_MAX >> 20);
        return Err(CliError::Usage(why));
    }
    let text = ferrobus_profile::source::read(file).map_err(|e| match e {
        ferrobus_profile::source::ReadError::Io(e) => CliError::Usage(format!("{shown}: {e}")),
        ferrobus_profile::source::ReadError::NotText(e) => CliError::Usage(format!("{shown}:{e}")),
    })?;
    let from = match from {
        MapFormat::Csv => exchange::Format::Csv,
        MapFormat::HaYaml => exchange::Format::HaYaml,
        MapFormat::EvccYaml => exchange::Format::EvccYaml,
    };
    let imported = match exchange::import(&text, &shown, from, options) {
        Ok(imported) => imported,
        Err(ImportError::Nothing { list, .. }) if !list.is_empty() && format != Format::Json => {
            output::write_to(&mut std::io::stderr(), "stderr", &not_mapped(&list))?;
            return Err(CliError::Usage(format!("{shown}: no entry could be mapped to a profile point")));
        }
        Err(e) => return Err(CliError::Usage(e.to_string())),
    };
    if let Some(path) = output {
        output::write_file(path, &imported.toml, force, "give --force to replace it")?;
    }
    let n = imported.unmapped.len();
    if format == Format::Json {
        let doc = json!({
            "file": shown, "from": from.name(), "points": imported.points, "notes": imported.notes,
            "profile": output.map_or_else(|| json!(imported.toml), |p| json!(p.display().to_string())),
            "unmapped": imported.unmapped.iter().map(|u| json!({
                "place": u.place, "field": u.field, "value": u.value, "why": u.why,
            })).collect::<Vec<_>>(),
        });
        return output::print(&output::json_line(&doc));
    }
    if output.is_none() {
        output::print(&imported.toml)?;
    }
    let mut report = not_mapped(&imported.unmapped);
    for note in &imported.notes {
        let _ = writeln!(report, "note: {note}");
    }
    let _ = writeln!(
        report,
        "{shown}: {} point{} imported{}; {n} thing{} not mapped{}",
        imported.points,
        if imported.points == 1 { "" } else { "s" },
        output.map(|p| format!(" into {}", p.display())).unwrap_or_default(),
        if n == 1 { "" } else { "s" },
        if n == 0 { "" } else { " (listed above)" },
    );
    output::write_to(&mut std::io::stderr(), "stderr", &report)
}

/// The most `not mapped: ...` lines a report shows; the rest are counted by field.
const SHOWN_UNMAPPED: usize = 100;

/// The `not mapped: ...` lines of `list`: the first [`SHOWN_UNMAPPED`], then how many more
/// of each field (`--json` lists them all).
fn not_mapped(list: &[exchange::Unmapped]) -> String {
    let mut lines = String::new();
    for u in list.iter().take(SHOWN_UNMAPPED) {
        let _ = writeln!(lines, "not mapped: {u}");
    }
    let rest = list.get(SHOWN_UNMAPPED..).unwrap_or_default();
    if !rest.is_empty() {
        let mut fields: Vec<(&str, usize)> = Vec::new();
        for u in rest {
            match fields.iter_mut().find(|(field, _)| *field == u.field) {
                Some((_, count)) => *count += 1,
                None => fields.push((&u.field, 1)),
            }
            if fields.len() > SHOWN_UNMAPPED {
                break;
            }
        }
        fields.sort_by_key(|(_, count)| std::cmp::Reverse(*count));
        let counted: usize = fields.iter().map(|(_, count)| count).sum();
        let mut by_field: Vec<String> =
            fields.iter().take(8).map(|(field, count)| format!("{count} {field}")).collect();
        if counted < rest.len() || fields.len() > 8 {
            by_field.push("...".to_string());
        }
        let _ =
            writeln!(lines, "not mapped: ... and {} more ({}; --json lists them all)", rest.len(), by_field.join(", "));
    }
    lines
}

fn list(format: Format) -> Result<(), CliError> {
    let mut profiles = Vec::new();
    for (name, _) in BUILTIN {
        profiles.push((*name, Profile::builtin(name).map_err(|e| CliError::Usage(e.to_string()))?));
    }
    let text = if format == Format::Json {
        output::json_line(&json!(profiles
            .iter()
            .map(|(name, p)| json!({ "name": name, "device": p.device.name, "vendor": p.device.vendor, "points": p.points().len() }))
            .collect::<Vec<_>>()))
    } else {
        let mut rows = Rows::new(&[
            ("name", Align::Left),
            ("device", Align::Left),
            ("vendor", Align::Left),
            ("points", Align::Right),
        ]);
        for (name, p) in &profiles {
            rows.push(vec![
                (*name).to_string(),
                p.device.name.clone(),
                p.device.vendor.clone(),
                p.points().len().to_string(),
            ]);
        }
        rows.render(format)
    };
    output::print(&text)
}

/// A not-implemented sentinel as JSON: as [`output::raw_json`], but a float's NaN (SunSpec's
/// sentinel of a float) is `"nan"`, not a `null` that would read as "none".
fn sentinel_json(raw: &Value) -> serde_json::Value {
    match raw {
        Value::Float(x) if x.is_nan() => serde_json::Value::from("nan"),
        other => output::raw_json(other),
    }
}

/// A point's range in engineering units: `0.00 Hz .. 400.00 Hz`, or its enumeration.
fn range(p: &Point) -> String {
    if !p.values.is_empty() {
        return p.values.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(" ");
    }
    let bound = |b: Option<f64>| {
        b.map(|b| {
            #[allow(clippy::cast_possible_truncation)]
            let raw = if p.value_type.is_float() { Value::Float(b) } else { Value::Int(b as i128) };
            p.show(&raw)
        })
    };
    match (bound(p.min), bound(p.max)) {
        (None, None) => String::new(),
        (lo, hi) => format!("{} .. {}", lo.unwrap_or_default(), hi.unwrap_or_default()),
    }
}

fn show(name: &str, group: Option<&str>, format: Format) -> Result<(), CliError> {
    let profile = crate::connect::load_profile(name)?;
    let points: Vec<&Point> = match group {
        Some(g) => profile.group(g),
        None => profile.points().iter().collect(),
    };
    if points.is_empty()
        && let Some(g) = group
    {
        return Err(CliError::Usage(format!(
            "{name} has no group {g:?}: its groups are {}",
            profile.groups().join(", ")
        )));
    }
    let text = if format == Format::Json {
        output::json_line(&json!({
            "device": profile.device.name,
            "points": points.iter().map(|p| json!({
                "code": p.code, "label": p.label, "table": p.table.name(), "number": p.number,
                "address": p.address, "type": p.value_type.name(), "order": p.order.name(), "unit": p.unit,
                "scale": p.scale, "offset": p.offset, "min": p.min, "max": p.max, "access": p.access.name(),
                "while_running": p.while_running, "group": p.group, "description": p.description,
                "values": p.values.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
                "bits": p.bits.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
                "confirmed": p.confirmed, "source": p.source,
                "default": p.factory_default.as_ref().map_or(serde_json::Value::Null, output::raw_json),
                "not_implemented": p.not_implemented.as_ref().map_or(serde_json::Value::Null, sentinel_json),
                "implemented": p.implemented,
            })).collect::<Vec<_>>(),
        }))
    } else {
        let mut rows = Rows::new(&[
            ("code", Align::Left),
            ("label", Align::Left),
            ("table", Align::Left),
            ("number", Align::Right),
            ("type", Align::Left),
            ("access", Align::Left),
            ("unit", Align::Left),
            ("range", Align::Left),
            ("group", Align::Left),
        ]);
        for p in &points {
            let mut kind = p.value_type.name().to_string();
            if p.width > 1 && p.value_type != ValueType::String {
                kind = format!("{kind} {}", p.order.name());
            }
            let mut access = p.access.name().to_string();
            if !p.while_running {
                access.push_str(" stopped");
            }
            rows.push(vec![
                p.code.clone(),
                if p.label.is_empty() { p.description.clone() } else { p.label.clone() },
                p.table.name().to_string(),
                format!("{:#06x}", p.number),
                kind,
                access,
                p.unit.clone().unwrap_or_default(),
                range(p),
                p.group.clone().unwrap_or_default(),
            ]);
        }
        rows.render(format)
    };
    output::print(&text)
}

/// `profile check`: a summary of a sound profile, or every mistake of the file, one a line
/// (`file:line:col: what (in `excerpt`)`) on stderr and, with `--json`, as a list on
/// stdout; exit 2 either way when there is one.
fn check(file: &str, format: Format) -> Result<(), CliError> {
    // The simulator's reading too: its fault keys are part of the file.
    let profile = ferrobus_sim::profile::load_all(file).map_err(|mistakes| {
        let mistakes: Vec<String> = mistakes.iter().map(ToString::to_string).collect();
        refuse(file, &mistakes, format)
    })?;
    let count = |t: ferrobus_profile::Table| profile.points().iter().filter(|p| p.table == t).count();
    let (coils, discrete, holding, input) = (
        count(ferrobus_profile::Table::Coils),
        count(ferrobus_profile::Table::DiscreteInputs),
        count(ferrobus_profile::Table::Holding),
        count(ferrobus_profile::Table::Input),
    );
    let text = if format == Format::Json {
        output::json_line(&json!({
            "file": file, "ok": true, "device": profile.device.name,
            "coils": coils, "discrete_inputs": discrete, "holding_registers": holding, "input_registers": input,
        }))
    } else {
        format!(
            "{file}: ok: {} — {coils} coils, {discrete} discrete inputs, {holding} holding and {input} input register values\n",
            profile.device.name
        )
    };
    output::print(&text)
}

/// Shows every mistake of `file` and sums them up in the error.
fn refuse(file: &str, mistakes: &[String], format: Format) -> CliError {
    if format == Format::Json {
        if let Err(e) = output::print(&output::json_line(&json!({ "file": file, "ok": false, "mistakes": mistakes }))) {
            return e;
        }
    } else {
        // Through the crate's stderr: a full stderr leaves the exit code the mistakes' own.
        for mistake in mistakes {
            eprintln!("{mistake}");
        }
    }
    let n = mistakes.len();
    CliError::Usage(format!("{file}: {n} mistake{}", if n == 1 { "" } else { "s" }))
}
