//! `ferrobus --device PROFILE get NAME...`: named values, read in the fewest transactions the
//! device allows, shown scaled with their unit.
//!
//! Names are the profile's codes (`d001`), labels (`output frequency`), globs over either
//! (`d0*`) and groups (`--group monitor`). The points of each table are read by the profile
//! crate's planner within the device's per-request limits. A request the device refuses with
//! an exception is read again point by point, so that only the points it refuses fail; each
//! failure is shown with the profile's meaning of the exception, and the exit code is 1.

use std::collections::HashMap;

use clap::Args;
use ferrobus::Client;
use ferrobus_profile::{Extent, Point, Profile, Table, Value, plan};
use serde_json::{Value as Json, json};

use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `get NAME...`.
#[derive(Args, Debug)]
#[command(after_help = "NAME is a code (d001), a label (\"output frequency\"), or a glob over either (d0*), \
     case-insensitive; `ferrobus profile show PROFILE` lists them.")]
pub(crate) struct GetArgs {
    /// What to read: codes, labels or globs
    #[arg(value_name = "NAME")]
    pub(crate) names: Vec<String>,

    /// Also every point of this group (monitor, basic, ...); may be repeated
    #[arg(long, value_name = "GROUP")]
    pub(crate) group: Vec<String>,

    /// Show the raw register value beside the scaled one
    #[arg(long)]
    pub(crate) raw: bool,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// The points `names` and `groups` select, in the order asked, each once; an unknown name or
/// group is a usage error.
pub(crate) fn select<'p>(
    profile: &'p Profile,
    names: &[String],
    groups: &[String],
) -> Result<Vec<&'p Point>, CliError> {
    let mut chosen: Vec<&Point> = Vec::new();
    let mut add = |points: Vec<&'p Point>| {
        for p in points {
            if !chosen.iter().any(|c| c.table == p.table && c.address == p.address) {
                chosen.push(p);
            }
        }
    };
    for name in names {
        let mut found = profile.find(name);
        if found.len() > 1 {
            // A glob or a shared label reads what can be read; a write-only point named alone
            // is reported as such.
            found.retain(|p| p.readable());
        }
        if found.is_empty() {
            return Err(CliError::Usage(format!(
                "{} has no parameter {name:?}: give a code, a label or a glob (`ferrobus profile show {}` lists them)",
                profile.origin, profile.origin
            )));
        }
        add(found);
    }
    for group in groups {
        let mut found = profile.group(group);
        let known_group = !found.is_empty();
        found.retain(|p| p.readable());
        if !known_group {
            let known = profile.groups();
            return Err(CliError::Usage(format!(
                "{} has no group {group:?}{}",
                profile.origin,
                if known.is_empty() { String::new() } else { format!(": its groups are {}", known.join(", ")) }
            )));
        }
        add(found);
    }
    if chosen.is_empty() {
        return Err(CliError::Usage("name at least one parameter, or a --group".into()));
    }
    Ok(chosen)
}

/// An exception in the profile's words: `exception 0x21 (data outside the inverter's range)`.
pub(crate) fn exception_words(profile: &Profile, error: &ferrobus::Error) -> String {
    match error.exception() {
        Some(code) => {
            // The profile's words; else the spec's name; else what the profile's [exceptions]
            // say a vendor code stands for.
            let e = &profile.exceptions;
            let vendor = if code.value() == e.out_of_range {
                Some("the value is out of the device's range")
            } else if code.value() == e.not_allowed {
                Some("not allowed in the device's present state")
            } else if code.value() == e.read_only {
                Some("read-only")
            } else {
                None
            };
            let meaning = profile.exception_meaning(code.value()).or(code.name()).or(vendor);
            match meaning {
                Some(meaning) => format!("exception {:#04x} ({meaning})", code.value()),
                None => format!("exception {:#04x}", code.value()),
            }
        }
        None => error.to_string(),
    }
}

/// What reading one point gave.
pub(crate) type Outcome = Result<Value, String>;

/// Reads `points` of unit `unit` in the planner's fewest requests per table: each point's
/// raw value, or the device's refusal in the profile's words. Errors other than exceptions
/// (silence, a broken reply, the port) end the read. Returns the outcomes in the order of
/// `points`, and the requests made.
pub(crate) async fn read_points(
    client: &Client,
    unit: u8,
    profile: &Profile,
    points: &[&Point],
    interrupt: &mut Interrupt,
) -> Result<(Vec<Outcome>, usize), CliError> {
    let mut raw: HashMap<(Table, u16), Outcome> = HashMap::new();
    let mut requests = 0usize;
    for table in Table::ALL {
        let wanted: Vec<Extent> = points
            .iter()
            .filter(|p| p.table == table && p.readable())
            .map(|p| Extent { start: p.address, width: p.width })
            .collect();
        if wanted.is_empty() {
            continue;
        }
        let plan = plan(&wanted, &profile.mapped(table), &profile.spans(table), profile.read_limit(table))
            .map_err(|e| CliError::Usage(format!("{}: {e}", profile.origin)))?;
        for request in plan {
            let inside: Vec<&&Point> = points
                .iter()
                .filter(|p| p.table == table && p.readable())
                .filter(|p| request.start <= p.address && p.end() <= request.end())
                .collect();
            requests += 1;
            match read_span(client, unit, table, request.start, request.count, interrupt).await? {
                Ok(items) => {
                    for p in inside {
                        raw.insert((table, p.address), decode(p, request.start, &items));
                    }
                }
                Err(error) if error.exception().is_some() && inside.len() > 1 => {
                    // Which of them does the device refuse? Each on its own.
                    for p in inside {
                        requests += 1;
                        let outcome = match read_span(client, unit, table, p.address, p.width, interrupt).await? {
                            Ok(items) => decode(p, p.address, &items),
                            Err(error) if error.exception().is_some() => Err(exception_words(profile, &error)),
                            Err(error) => return Err(error.into()),
                        };
                        raw.insert((table, p.address), outcome);
                    }
                }
                Err(error) if error.exception().is_some() => {
                    for p in inside {
                        raw.insert((table, p.address), Err(exception_words(profile, &error)));
                    }
                }
                Err(error) => return Err(error.into()),
            }
        }
    }
    let outcomes = points
        .iter()
        .map(|p| {
            if p.readable() {
                raw.remove(&(p.table, p.address)).unwrap_or_else(|| Err("not read".into()))
            } else {
                Err("write-only: the device does not read it back".into())
            }
        })
        .collect();
    Ok((outcomes, requests))
}

/// Items as registers (bits as 0 and 1).
enum Items {
    Registers(Vec<u16>),
    Bits(Vec<bool>),
}

async fn read_span(
    client: &Client,
    unit: u8,
    table: Table,
    start: u16,
    count: u16,
    interrupt: &mut Interrupt,
) -> Result<Result<Items, ferrobus::Error>, CliError> {
    tracing::info!(unit, start, count, "reading {table:?}");
    let read = async {
        match table {
            Table::Coils => client.read_coils(unit, start, count).await.map(Items::Bits),
            Table::DiscreteInputs => client.read_discrete_inputs(unit, start, count).await.map(Items::Bits),
            Table::Holding => client.read_holding_registers(unit, start, count).await.map(Items::Registers),
            Table::Input => client.read_input_registers(unit, start, count).await.map(Items::Registers),
        }
    };
    interrupt.unless(read).await.ok_or(CliError::Interrupted)
}

/// Point `p`'s value out of items read from `start`.
fn decode(p: &Point, start: u16, items: &Items) -> Outcome {
    let from = usize::from(p.address.saturating_sub(start));
    let to = from.saturating_add(usize::from(p.width));
    match items {
        Items::Bits(bits) => bits.get(from).map(|b| Value::Bool(*b)).ok_or_else(|| "the reply was short".to_string()),
        Items::Registers(words) => match words.get(from..to) {
            Some(words) => p.decode(words).map_err(|e| e.to_string()),
            None => Err("the reply was short".to_string()),
        },
    }
}

/// The raw value as the register holds it: decimal, and hex for integers.
pub(crate) fn raw_text(p: &Point, raw: &Value) -> String {
    match raw {
        Value::Int(n) if *n >= 0 => format!("{n} ({n:#0width$x})", width = usize::from(p.width) * 4 + 2),
        other => other.to_string(),
    }
}

/// One point as a JSON object: `value` as shown (`50.00 Hz`, `run`), `engineering` the number
/// at the point's resolution, `meaning` an enumeration's or a bit field's (else null), `unit`,
/// `raw`; `implemented` false, and `value`, `engineering` and `meaning` null, for a value by
/// which the device says it does not implement the point.
pub(crate) fn point_json(p: &Point, outcome: &Outcome) -> Json {
    let mut doc = json!({
        "code": p.code,
        "label": p.label,
        "table": p.table.name(),
        "number": p.number,
        "address": p.address,
    });
    match outcome {
        Ok(raw) => {
            // A value the device does not implement is no value: null, with `implemented` false.
            doc["value"] = if p.implemented(raw) { p.show(raw).into() } else { Json::Null };
            doc["implemented"] = p.implemented(raw).into();
            doc["engineering"] = output::number_json(p, raw);
            doc["meaning"] = p.meaning(raw).map_or(Json::Null, Json::from);
            doc["unit"] = p.unit.clone().map_or(Json::Null, Json::from);
            doc["raw"] = output::raw_json(raw);
        }
        Err(error) => doc["error"] = error.clone().into(),
    }
    doc
}

/// Runs `get`.
pub(crate) async fn run(connection: &ConnectArgs, args: &GetArgs) -> Result<(), CliError> {
    let profile = connection.require_profile("get")?;
    connection.refuse_broadcast_read()?;
    let points = select(&profile, &args.names, &args.group)?;
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let (outcomes, requests) = read_points(&session.client, session.unit, &profile, &points, &mut interrupt).await?;
    let text = match args.output.format() {
        Format::Json => output::json_line(&json!({
            "device": profile.origin,
            "unit": session.unit,
            "requests": requests,
            "points": points.iter().zip(&outcomes).map(|(p, o)| point_json(p, o)).collect::<Vec<_>>(),
        })),
        format => {
            let mut headers = vec![("code", Align::Left), ("label", Align::Left), ("value", Align::Left)];
            if args.raw {
                headers.push(("raw", Align::Left));
            }
            let mut rows = Rows::new(&headers);
            for (p, outcome) in points.iter().zip(&outcomes) {
                let (value, raw) = match outcome {
                    // Not implemented: `n/a` for people, an empty field in CSV.
                    Ok(raw) if format == Format::Csv && !p.implemented(raw) => (String::new(), raw_text(p, raw)),
                    Ok(raw) => (p.show(raw), raw_text(p, raw)),
                    Err(error) => (format!("error: {error}"), String::new()),
                };
                let mut row = vec![p.code.clone(), p.label.clone(), value];
                if args.raw {
                    row.push(raw);
                }
                rows.push(row);
            }
            rows.render(format)
        }
    };
    output::print(&text)?;
    let failed: Vec<&str> =
        points.iter().zip(&outcomes).filter(|(_, o)| o.is_err()).map(|(p, _)| p.code.as_str()).collect();
    if failed.is_empty() {
        return Ok(());
    }
    Err(CliError::Refused(format!(
        "{} of {} parameters could not be read: {}",
        failed.len(),
        points.len(),
        failed.join(", ")
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferrobus_proto::{ExceptionCode, FunctionCode};

    fn refused(code: u8) -> ferrobus::Error {
        ferrobus::Error::Exception {
            unit: 1,
            function: FunctionCode::WriteSingleRegister,
            code: ExceptionCode::from_u8(code),
        }
    }

    #[test]
    fn an_exception_is_told_in_the_profiles_words_else_the_specs_else_by_its_exceptions_table() {
        let text = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
                    [exceptions]\nout_of_range=0x21\nnot_allowed=0x22\nread_only=0x22\n\
                    [[exception_meaning]]\ncode=0x23\nmeaning='the inverter is tripped'\n";
        let profile = Profile::parse(text, "x.toml").unwrap();
        assert_eq!(exception_words(&profile, &refused(0x23)), "exception 0x23 (the inverter is tripped)");
        assert_eq!(
            exception_words(&profile, &refused(0x21)),
            "exception 0x21 (the value is out of the device's range)"
        );
        assert_eq!(
            exception_words(&profile, &refused(0x22)),
            "exception 0x22 (not allowed in the device's present state)"
        );
        assert_eq!(exception_words(&profile, &refused(0x02)), "exception 0x02 (Illegal Data Address)");
        assert_eq!(exception_words(&profile, &refused(0x30)), "exception 0x30");
    }

    #[test]
    fn globs_and_groups_leave_write_only_points_out_and_a_name_alone_keeps_it() {
        let text = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
                    [[registers]]\nnumber=0\nname='cmd'\naccess='wo'\ngroup='g'\n\
                    [[registers]]\nnumber=1\nname='cnt'\ngroup='g'\n";
        let profile = Profile::parse(text, "x.toml").unwrap();
        let codes = |names: &[&str], groups: &[&str]| -> Vec<String> {
            let names: Vec<String> = names.iter().map(ToString::to_string).collect();
            let groups: Vec<String> = groups.iter().map(ToString::to_string).collect();
            select(&profile, &names, &groups).unwrap().iter().map(|p| p.code.clone()).collect()
        };
        assert_eq!(codes(&["c*"], &[]), ["cnt"]);
        assert_eq!(codes(&[], &["g"]), ["cnt"]);
        assert_eq!(codes(&["cmd"], &[]), ["cmd"]);
    }
}
