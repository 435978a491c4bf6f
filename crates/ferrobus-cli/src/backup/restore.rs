//! `restore FILE`: what differs between a backup and the device, written back.
//!
//! A dry run by default: it reads the device and lists what it would write. `--apply` writes
//! only what differs, one parameter per request (so a refusal is pinned to one parameter),
//! dependencies first (the profile's `depends_on`, a topological order that otherwise keeps
//! the profile's), then reads every parameter of the file back and compares.
//!
//! Nothing is sent, not even a read, when the file holds a value its parameter cannot take
//! (out of `min`..=`max`, not of its type, wider than one write request). Nothing is written
//! when a differing parameter is read-only, or run-locked (`while_running = false`) while the
//! drive runs — the profile's write guard, the one every writer applies, says so for each —:
//! restore does not stop the drive itself — stopping a motor under load is the
//! operator's decision, and the profile says how to tell that the drive runs, not how to stop
//! it safely — so it names the parameters and asks for the drive to be stopped. A file of
//! another profile is refused unless `--force`, which restores the parameters both share.

use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use super::device::{self, Watched};
use super::diff::load;
use ferrobus_profile::Point;
use ferrobus_tools::backup::restore::{self as plan, Item, Outcome};

use super::param;
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `restore FILE [--apply] [--force]`.
#[derive(Args, Debug)]
#[command(after_help = "Needs --device PROFILE. A dry run unless --apply: lists what differs and would be \
                        written. --apply writes only that, dependencies first, refusing before any write a \
                        read-only or out-of-range value or a run-locked parameter while the drive runs, then \
                        reads everything back. On a partial failure it lists what was written and verified and \
                        what was not, and why (exit 7).\n\nExample:\n  ferrobus --port /dev/ttyUSB0 --device \
                        omron-3g3rx restore drive-07.toml --apply")]
pub(crate) struct RestoreArgs {
    /// The backup file
    pub(crate) file: PathBuf,

    /// Write what differs (without it, only list it)
    #[arg(long)]
    pub(crate) apply: bool,

    /// Restore a file made with another profile: the parameters both share
    #[arg(long)]
    pub(crate) force: bool,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// Runs `restore`.
pub(crate) async fn run(connection: &ConnectArgs, args: &RestoreArgs) -> Result<(), CliError> {
    let backup = load(&args.file)?;
    let file = args.file.display().to_string();
    let view = super::profile(connection, "restore")?;
    let other_profile =
        backup.header.profile != view.name || (view.hash.is_some() && backup.header.profile_hash != view.hash);
    if other_profile && !args.force {
        return Err(CliError::Usage(format!(
            "{file} was made with profile {}{}, not --device {}: refusing to restore it (--force restores the \
             parameters the two profiles share)",
            backup.header.profile,
            backup.header.profile_hash.as_ref().map(|h| format!(" ({h})")).unwrap_or_default(),
            view.name
        )));
    }
    let checked = plan::checked(&backup, &view, &file, args.force).map_err(|e| CliError::Usage(e.to_string()))?;
    for note in &checked.notes {
        eprintln!("note: {note}");
    }
    let candidates = checked.candidates;
    connection.refuse_broadcast_read()?;
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let running_param = view.running();
    let mut to_read: Vec<&Point> = candidates.iter().map(|(p, _, _)| *p).collect();
    if let Some((p, _)) = running_param
        && !to_read.iter().any(|q| q.code == p.code)
    {
        to_read.push(p);
    }
    let before = device::read(&session, &view, &to_read, &mut interrupt).await;
    if before.interrupted {
        eprintln!("restore: interrupted while reading the device first: nothing was written");
        return Err(CliError::Interrupted);
    }
    if let Some(error) = before.stopped {
        return Err(error.into());
    }
    let mut items = plan::differing(candidates, &before, &file).map_err(|e| CliError::Usage(e.to_string()))?;
    plan::order(&mut items).map_err(|e| CliError::Usage(e.to_string()))?;
    let format = args.output.format();
    if !args.apply {
        let text = render(&items, format, "dry run", &file);
        output::print(&text)?;
        if format == Format::Table {
            let n = items.iter().filter(|i| i.outcome == Outcome::Pending).count();
            eprintln!(
                "restore: dry run: {n} parameter{} would be written, in this order; --apply writes them",
                plural(n)
            );
        }
        if let Err(why) = plan::guard(&items, &view.profile, running_param, &before) {
            eprintln!("note: --apply would refuse now: {why}");
        }
        return Ok(());
    }
    plan::guard(&items, &view.profile, running_param, &before)
        .map_err(|why| CliError::Incomplete(format!("{why}; nothing was written")))?;
    let pending = items.iter().filter(|i| i.outcome == Outcome::Pending).count();
    let mut watched = Watched::new(&mut interrupt, pending, "parameters written");
    let interrupted = plan::apply(device::target(&session), &view, &mut items, &mut watched).await;
    watched.finish();
    let what = plan::ReadBack { view: &view, backup: &backup, interrupted };
    let mut watched = Watched::new(&mut interrupt, what.points(&items).len(), "parameters read");
    let drifted = plan::read_back(device::target(&session), what, &mut items, &mut watched).await;
    watched.finish();
    conclude(&items, &drifted, format, &file, interrupted)
}

/// Prints the outcome; an error naming what was and was not written unless all is verified
/// (after an interruption, exit 130 with the same lists).
fn conclude(
    items: &[Item<'_>],
    drifted: &[String],
    format: Format,
    file: &str,
    interrupted: bool,
) -> Result<(), CliError> {
    let text = render(items, format, if interrupted { "interrupted" } else { "applied" }, file);
    output::print(&text)?;
    let verified: Vec<&str> =
        items.iter().filter(|i| i.outcome == Outcome::Verified).map(|i| i.param.code.as_str()).collect();
    let written_unverified: Vec<&str> =
        items.iter().filter(|i| matches!(i.outcome, Outcome::Unverified(_))).map(|i| i.param.code.as_str()).collect();
    let not_written: Vec<&str> =
        items.iter().filter(|i| matches!(i.outcome, Outcome::NotWritten(_))).map(|i| i.param.code.as_str()).collect();
    eprintln!(
        "restore: {}{} written and verified{}{}",
        if interrupted { "interrupted: " } else { "" },
        verified.len(),
        if written_unverified.is_empty() {
            String::new()
        } else {
            format!(", {} written but not verified ({})", written_unverified.len(), written_unverified.join(", "))
        },
        if not_written.is_empty() {
            String::new()
        } else {
            format!(", {} not written ({})", not_written.len(), not_written.join(", "))
        },
    );
    for note in drifted {
        eprintln!("note: not in the restore, yet differs after it: {note}");
    }
    if written_unverified.is_empty() && not_written.is_empty() && drifted.is_empty() && !interrupted {
        return Ok(());
    }
    let lists = format!(
        "written and verified: {}; written but not verified: {}; not written: {}{}",
        list(&verified),
        list(&written_unverified),
        list(&not_written),
        if drifted.is_empty() { String::new() } else { format!("; differing after it: {}", drifted.len()) }
    );
    if interrupted {
        eprintln!("restore: interrupted, so incomplete: {lists}");
        return Err(CliError::Interrupted);
    }
    Err(CliError::Incomplete(format!("the restore is incomplete: {lists}")))
}

fn list(codes: &[&str]) -> String {
    if codes.is_empty() { "none".into() } else { codes.join(", ") }
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

/// The plan or the outcome as a table, CSV or JSON.
fn render(items: &[Item<'_>], format: Format, stage: &str, file: &str) -> String {
    let result = |o: &Outcome| match o {
        Outcome::Pending => {
            if stage == "dry run" {
                "would write".to_string()
            } else {
                "written".to_string()
            }
        }
        Outcome::InFlight => "interrupted while being written".into(),
        Outcome::Verified => "written, verified".into(),
        Outcome::Unverified(why) => why.clone(),
        Outcome::NotWritten(why) => format!("not written: {why}"),
    };
    if format == Format::Json {
        return output::json_line(&json!({
            "file": file,
            "stage": stage,
            "parameters": items.iter().map(|i| json!({
                "code": i.param.code,
                "label": param::label(i.param),
                "device": i.before,
                "file": i.param.show(&i.raw),
                "result": result(&i.outcome),
                "written": matches!(i.outcome, Outcome::Verified | Outcome::Unverified(_)),
                "verified": i.outcome == Outcome::Verified,
            })).collect::<Vec<_>>(),
        }));
    }
    let mut rows = Rows::new(&[
        ("code", Align::Left),
        ("label", Align::Left),
        ("device", Align::Left),
        ("file", Align::Left),
        ("result", Align::Left),
    ]);
    for i in items {
        rows.push(vec![
            i.param.code.clone(),
            param::label(i.param).to_string(),
            i.before.clone(),
            i.param.show(&i.raw),
            result(&i.outcome),
        ]);
    }
    if format == Format::Table && items.is_empty() {
        return format!("the device agrees with {file}: nothing to write\n");
    }
    rows.render(format)
}
