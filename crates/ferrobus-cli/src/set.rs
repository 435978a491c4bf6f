//! `ferrobus --device PROFILE set NAME VALUE`: one parameter, in its unit, checked before
//! anything is sent, written, read back and shown.
//!
//! The value is parsed by the profile (`45Hz`, `12.5s`, `60.00`, `0x10` raw, `modbus` by its
//! meaning) and converted by the point's scale; then it is written as every writer writes a
//! point (`ferrobus_tools::write::write_point`): the profile's guard checks its range and access
//! and, for a parameter that cannot change while the drive runs, reads the profile's `[state]
//! running` point first; only then is the value sent, FC05 for a coil, FC06 for one register
//! (FC10 when the device lacks FC06), FC10 for a value of several registers, never split; and
//! it is read back. What needs no bus (the value, the request's width) is checked before the
//! bus is opened.

use clap::Args;
use ferrobus_profile::{Point, Profile, Refusal, Write};
use ferrobus_tools::guard::ReadFailure;
use ferrobus_tools::write::{WriteError, Written};
use serde_json::json;

use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::get::{exception_words, point_json, raw_text};
use crate::interrupt::Interrupt;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `set NAME VALUE`.
#[derive(Args, Debug)]
#[command(after_help = "VALUE is in the parameter's unit, with or without it (45Hz, 45 Hz, 45), a raw \
     integer in hex or binary (0x10), or an enumeration's meaning (modbus).")]
pub(crate) struct SetArgs {
    /// The parameter: a code (F001) or a label
    pub(crate) name: String,

    /// The value, in the parameter's unit or raw (a negative one as is: set P1 -3)
    #[arg(allow_hyphen_values = true)]
    pub(crate) value: String,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// The one point `name` names.
fn one_point<'p>(profile: &'p Profile, name: &str) -> Result<&'p Point, CliError> {
    match profile.find(name).as_slice() {
        [] => Err(CliError::Usage(format!(
            "{} has no parameter {name:?} (`ferrobus profile show {}` lists them)",
            profile.origin, profile.origin
        ))),
        [one] => Ok(one),
        many => Err(CliError::Usage(format!(
            "{name:?} names {} parameters ({}): set one at a time",
            many.len(),
            many.iter().map(|p| p.code.as_str()).collect::<Vec<_>>().join(", ")
        ))),
    }
}

/// Runs `set`.
pub(crate) async fn run(connection: &ConnectArgs, args: &SetArgs) -> Result<(), CliError> {
    let profile = connection.require_profile("set")?;
    let point = one_point(&profile, &args.name)?;
    let raw = point.parse(&args.value).map_err(|e| CliError::Usage(format!("not sent: {e}")))?;
    let write = Write { point, raw: &raw, typed: &args.value };
    profile.check_value(&write).map_err(|e| refused(&e))?;
    point.wire_write(&raw, &profile.write_rules()).map_err(|e| refused(&e))?;
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let (client, unit) = (&session.client, session.unit);
    tracing::info!(unit, address = point.address, "writing {}", point.code);
    let written = ferrobus_tools::write::write_point(client, unit, Some(&profile), &write, true);
    let outcome = match interrupt.unless(written).await.ok_or(CliError::Interrupted)? {
        Ok(Written { read_back: Some(back), .. }) => back.map_err(|e| read_failure(&profile, &e)),
        Ok(Written { read_back: None, .. }) => {
            let text = format!("{} = {}: written, not read back\n", point.code, point.show(&raw));
            return output::print(&text);
        }
        Err(WriteError::Refused(refusal)) => return Err(refused(&refusal)),
        Err(WriteError::Value(e)) => return Err(CliError::Usage(format!("not sent: {e}"))),
        Err(WriteError::Bus(error)) if error.exception().is_some() => {
            return Err(CliError::Refused(format!(
                "the device refused {} = {}: {}",
                point.code,
                args.value.trim(),
                exception_words(&profile, &error)
            )));
        }
        Err(WriteError::Bus(error)) => return Err(error.into()),
        Err(other) => return Err(CliError::Usage(format!("not sent: {other}"))),
    };
    if let Ok(back) = &outcome
        && *back != raw
    {
        eprintln!(
            "set: {} reads back {}, not the {} written (the device may round or limit it)",
            point.code,
            point.show(back),
            point.show(&raw)
        );
    }
    let text = match args.output.format() {
        Format::Json => output::json_line(&json!({
            "device": profile.origin,
            "unit": unit,
            "written": point_json(point, &Ok(raw.clone())),
            "read_back": point_json(point, &outcome),
        })),
        format => {
            let mut rows = Rows::new(&[
                ("code", Align::Left),
                ("label", Align::Left),
                ("value", Align::Left),
                ("raw", Align::Left),
            ]);
            match &outcome {
                Ok(back) => {
                    rows.push(vec![point.code.clone(), point.label.clone(), point.show(back), raw_text(point, back)]);
                }
                Err(error) => rows.push(vec![
                    point.code.clone(),
                    point.label.clone(),
                    format!("written {}; reading it back failed: {error}", point.show(&raw)),
                    String::new(),
                ]),
            }
            rows.render(format)
        }
    };
    output::print(&text)?;
    match outcome {
        Ok(_) => Ok(()),
        Err(error) => {
            Err(CliError::Refused(format!("{} was written, but reading it back failed: {error}", point.code)))
        }
    }
}

/// A read-back's failure in the user's words: an exception with the profile's meaning.
fn read_failure(profile: &Profile, failure: &ReadFailure) -> String {
    match failure {
        ReadFailure::Bus(error) if error.exception().is_some() => exception_words(profile, error),
        other => other.to_string(),
    }
}

/// The guard's refusal as the command's error (`set` has no `--force`).
fn refused(refusal: &Refusal) -> CliError {
    crate::run_lock::refused(refusal, None)
}
