//! `backup`, `diff`, `restore`: a drive's parameters saved to a file, compared with the
//! device or another file, and written back.
//!
//! The backup file's format, the values in it, the profile it pins and the comparison are the
//! library's (`ferrobus_tools::backup`, whose doc describes the format); here are the commands.
//!
//! A backup saves what the profile marks `backup` (by default its read-write registers); the
//! reads follow the profile's read plan ([`ferrobus_profile::plan`]), so the 3G3RX's 4 registers per request are
//! filled across neighbouring parameters. Restore writes only what differs, dependencies
//! first, and refuses before sending anything when a value is read-only, out of range, or
//! run-locked while the drive runs (see [`restore`]).
//!
//! `backup -o FILE` never replaces a good file with a worse one, nor leaves it half-written
//! (see [`save`]); Ctrl-C stops the reads or writes of any of the three and they say what was
//! done; `diff --defaults` compares with the profile's factory defaults (see [`defaults`]).

pub(crate) mod defaults;
pub(crate) mod device;
pub(crate) mod diff;
pub(crate) mod restore;

// The file format, the values, the profile and the comparison are the library's.
pub(crate) use ferrobus_tools::backup::{entries, file, param, save, view};

use std::path::{Path, PathBuf};

use clap::Args;
use ferrobus_profile::Point;

use self::file::{Backup, Header};
use self::view::View;
use crate::connect::{ConnectArgs, Session};
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output;

/// `backup [-o FILE] [--force]`.
#[derive(Args, Debug)]
#[command(after_help = "Needs --device PROFILE. Writes every readable parameter the profile marks for backup \
                        (by default its read-write registers) with the device's identification, the time, the \
                        unit and the connection; a parameter that cannot be read is recorded with the reason \
                        and the exit code is 7.\n\nWith -o FILE the backup is written to a temporary file and \
                        renamed, so FILE is never half-written; the previous FILE is kept as FILE.bak. A backup \
                        with more unread parameters than FILE holds does not replace it: it goes to \
                        FILE.incomplete (--force replaces FILE all the same). Ctrl-C stops the reads; what was \
                        read is saved by the same rule and the command exits 130.\n\nExample:\n  ferrobus \
                        --port /dev/ttyUSB0 --device omron-3g3rx --unit 7 backup -o drive-07.toml")]
pub(crate) struct BackupArgs {
    /// Write the backup to FILE instead of stdout (the previous FILE is kept as FILE.bak)
    #[arg(long, short = 'o', value_name = "FILE")]
    pub(crate) output: Option<PathBuf>,

    /// Replace FILE even with a backup that could read fewer parameters than FILE holds
    #[arg(long, requires = "output")]
    pub(crate) force: bool,
}

/// The profile named by `--device`.
pub(crate) fn profile(connection: &ConnectArgs, command: &str) -> Result<View, CliError> {
    let Some(name) = &connection.device else {
        return Err(CliError::Usage(format!(
            "{command} needs the device's profile: --device NAME (omron-3g3rx, sdp-servo, generic, sunspec-inverter), --device sunspec (discovered) or --device FILE"
        )));
    };
    if name == crate::sunspec::DEVICE {
        // The profile `--device sunspec` discovered (an error if this command does not discover).
        let profile = connection.require_profile(command)?;
        return Ok(View { name: name.clone(), hash: None, profile });
    }
    View::load(name).map_err(|e| CliError::Usage(e.to_string()))
}

/// Runs `backup`.
pub(crate) async fn run(connection: &ConnectArgs, args: &BackupArgs) -> Result<(), CliError> {
    let view = profile(connection, "backup")?;
    connection.refuse_broadcast_read()?;
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let (identification, objects) =
        interrupt.unless(identify(&session, &view)).await.ok_or(CliError::Interrupted)??;
    let params = view.backed_up();
    let readings = device::read(&session, &view, &params, &mut interrupt).await;
    let backup = backup_of(&session, &view, identification, objects, &params, &readings);
    let (read, unread) = readings.split(&params);
    if read.is_empty()
        && let Some(error) = readings.stopped
    {
        return Err(error.into());
    }
    let saved = if let Some(path) = &args.output {
        Some((save::save(path, &backup, args.force).map_err(saving)?, path))
    } else {
        output::print(&backup.render())?;
        None
    };
    eprintln!(
        "backup: {} of {} parameters of unit {} in {} requests (the plan's {}), {:.1} ms",
        read.len(),
        backup.entries.len(),
        session.unit,
        readings.requests,
        readings.planned,
        readings.elapsed.as_secs_f64() * 1e3
    );
    if let Some((saved, path)) = saved {
        tell(&saved, path, &backup);
    }
    if readings.interrupted {
        eprintln!(
            "backup: interrupted: {} of {} parameters read; not read: {}",
            read.len(),
            params.len(),
            unread.join(", ")
        );
        return Err(CliError::Interrupted);
    }
    if unread.is_empty() {
        return Ok(());
    }
    Err(CliError::Incomplete(format!(
        "{} parameter{} could not be read ({}); the backup records why",
        unread.len(),
        if unread.len() == 1 { "" } else { "s" },
        unread.join(", ")
    )))
}

/// A failed save as the command's error: the file and why, or a path that names no file.
fn saving(error: save::SaveError) -> CliError {
    match error {
        save::SaveError::NotAFile { path } => {
            CliError::Usage(format!("-o {}: name a file, not a directory", path.display()))
        }
        save::SaveError::Io { what, source } => CliError::Output { what, source },
        other => CliError::Usage(other.to_string()),
    }
}

/// Says where the backup went when it did not simply become `path`.
fn tell(saved: &save::Saved, path: &Path, backup: &Backup) {
    let new = save::Completeness::of(backup);
    match saved {
        save::Saved::Replaced { previous: None } => {}
        save::Saved::Replaced { previous: Some(bak) } => {
            eprintln!("backup: the previous {} is kept as {}", path.display(), bak.display());
        }
        save::Saved::KeptPrevious { new: aside, previous } => eprintln!(
            "backup: kept {}: it holds {} of {} parameters, the new backup only {} of {}; the new backup is in {} \
             (--force replaces {} with it)",
            path.display(),
            previous.read(),
            previous.parameters,
            new.read(),
            new.parameters,
            aside.display(),
            path.display()
        ),
    }
}

/// The backup of what `readings` found of `params`, with its header.
pub(crate) fn backup_of(
    session: &Session,
    view: &View,
    identification: String,
    objects: Vec<(String, String)>,
    params: &[&Point],
    readings: &device::Readings,
) -> Backup {
    let (entries, _) = entries(params, readings);
    let header = Header {
        profile: view.name.clone(),
        profile_hash: view.hash.clone(),
        device: view.device().to_string(),
        time: file::now_utc(),
        unit: session.unit,
        connection: session.target.to_string(),
        identification,
    };
    Backup { header, identification: objects, entries }
}

/// How the device identifies itself ([`ferrobus_tools::backup::device::identify`]); no reply ends
/// the backup.
async fn identify(session: &Session, view: &View) -> Result<(String, Vec<(String, String)>), CliError> {
    Ok(ferrobus_tools::backup::device::identify(device::target(session), view).await?)
}
