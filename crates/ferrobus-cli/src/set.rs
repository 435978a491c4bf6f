//! `ferrobus --device PROFILE set NAME VALUE`: one parameter, in its unit, checked before
//! anything is sent, written, read back and shown.
//!
//! The value is parsed by the profile (`45Hz`, `12.5s`, `60.00`, `0x10` raw, `modbus` by its
//! meaning) and converted by the point's scale; then the profile's write guard (the one every
//! writer applies, `ferrobus::guard::check_write`) checks its range and access and, for a
//! parameter that cannot change while the drive runs, reads the profile's `[state] running`
//! point first. Only then is the value written: FC05 for a coil, FC06 for one register
//! (FC10 when the device lacks FC06), FC10 for a value of several registers, never split.

use clap::Args;
use ferrobus_profile::{Point, Profile, Refusal, RunState, Table, Value, Write};
use serde_json::json;

use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::get::{exception_words, point_json, raw_text, read_points};
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
    let words = match &raw {
        Value::Bool(_) => Vec::new(),
        other => point.encode(other).map_err(|e| CliError::Usage(format!("not sent: {e}")))?,
    };
    let limit = usize::from(profile.write_limit(point.table));
    if words.len() > limit {
        return Err(CliError::Usage(format!(
            "not sent: {} takes {} registers, more than the {limit} {} writes in one request",
            point.code,
            words.len(),
            profile.device.name
        )));
    }
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let (client, unit) = (&session.client, session.unit);
    let broadcast = session.is_broadcast();
    guard(&session, &profile, &write, &mut interrupt).await?;
    let sixteen = profile.comm.functions.as_ref().is_none_or(|f| f.contains(&0x06));
    tracing::info!(unit, address = point.address, ?words, "writing {}", point.code);
    let write = async {
        match (&raw, words.as_slice()) {
            (Value::Bool(on), _) => client.write_single_coil(unit, point.address, *on).await,
            (_, [one]) if sixteen => client.write_single_register(unit, point.address, *one).await,
            (_, words) => client.write_multiple_registers(unit, point.address, words).await,
        }
    };
    match interrupt.unless(write).await.ok_or(CliError::Interrupted)? {
        Ok(()) => {}
        Err(error) if error.exception().is_some() => {
            return Err(CliError::Refused(format!(
                "the device refused {} = {}: {}",
                point.code,
                args.value.trim(),
                exception_words(&profile, &error)
            )));
        }
        Err(error) => return Err(error.into()),
    }
    if broadcast || !point.readable() || point.table != Table::Holding && point.table != Table::Coils {
        let text = format!("{} = {}: written, not read back\n", point.code, point.show(&raw));
        return output::print(&text);
    }
    let (outcomes, _) = read_points(client, unit, &profile, &[point], &mut interrupt).await?;
    let outcome = outcomes.into_iter().next().unwrap_or_else(|| Err("not read".into()));
    if let Ok(back) = &outcome {
        if *back != raw {
            eprintln!(
                "set: {} reads back {}, not the {} written (the device may round or limit it)",
                point.code,
                point.show(back),
                point.show(&raw)
            );
        }
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

/// The profile's write guard for `write`, with the drive's run state read first when the
/// point is run-locked (a broadcast cannot read it, so the guard refuses such a point).
async fn guard(
    session: &crate::connect::Session,
    profile: &Profile,
    write: &Write<'_>,
    interrupt: &mut Interrupt,
) -> Result<(), CliError> {
    if session.is_broadcast() {
        let state =
            if profile.run_state_point(write.point).is_some() { RunState::Broadcast } else { RunState::NotRead };
        return profile.guard_write(write, &state).map_err(|e| refused(&e));
    }
    let check = ferrobus::guard::check_write(&session.client, session.unit, profile, write);
    interrupt.unless(check).await.ok_or(CliError::Interrupted)?.map_err(|e| refused(&e))
}

/// The guard's refusal as the command's error (`set` has no `--force`).
fn refused(refusal: &Refusal) -> CliError {
    crate::run_lock::refused(refusal, None)
}
