//! `ferrobus man`: manual pages in roff, made from the command definition (clap_mangen).
//!
//! Without `--dir`, ferrobus(1) goes to stdout (`ferrobus man | man -l -`); with `--dir DIR`,
//! ferrobus.1 and one page per command (ferrobus-read.1, ...) are written there, as the
//! Debian package installs them.

use std::path::PathBuf;

use clap::{Args, CommandFactory};

use crate::Cli;
use crate::exit::CliError;

/// `man [--dir DIR]`.
#[derive(Args, Debug)]
pub(crate) struct ManArgs {
    /// Write ferrobus.1 and a page for each command into this directory
    #[arg(long, value_name = "DIR")]
    dir: Option<PathBuf>,
}

/// Runs `man`.
pub(crate) fn run(args: &ManArgs) -> Result<(), CliError> {
    let command = Cli::command();
    if let Some(dir) = &args.dir {
        return std::fs::create_dir_all(dir)
            .and_then(|()| clap_mangen::generate_to(command, dir))
            .map_err(|source| CliError::Output { what: format!("the man pages into {}", dir.display()), source });
    }
    let mut page = Vec::new();
    clap_mangen::Man::new(command)
        .render(&mut page)
        .map_err(|source| CliError::Output { what: "the man page".into(), source })?;
    crate::output::print(&String::from_utf8_lossy(&page))
}
