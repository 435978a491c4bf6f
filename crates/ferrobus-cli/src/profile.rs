//! `ferrobus profile list | show NAME | check FILE`: the device profiles, offline.

use clap::{Args, Subcommand};
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
}

/// Runs `profile`.
pub(crate) fn run(args: &ProfileArgs) -> Result<(), CliError> {
    let format = args.output.format();
    match &args.action {
        Action::List => list(format),
        Action::Show { name, group } => show(name, group.as_deref(), format),
        Action::Check { file } => check(file, format),
    }
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
    if points.is_empty() {
        if let Some(g) = group {
            return Err(CliError::Usage(format!(
                "{name} has no group {g:?}: its groups are {}",
                profile.groups().join(", ")
            )));
        }
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
    let shown = if format == Format::Json {
        output::print(&output::json_line(&json!({ "file": file, "ok": false, "mistakes": mistakes })))
    } else {
        let mut lines = mistakes.join("\n");
        lines.push('\n');
        output::write_to(&mut std::io::stderr(), "stderr", &lines)
    };
    if let Err(e) = shown {
        return e;
    }
    let n = mistakes.len();
    CliError::Usage(format!("{file}: {n} mistake{}", if n == 1 { "" } else { "s" }))
}
