//! `ferrobus man`: manual pages in roff, made from the command definition (clap_mangen).
//!
//! Without `--dir`, ferrobus(1) goes to stdout (`ferrobus man | man -l -`); with `--dir DIR`,
//! ferrobus.1 and one page per command (ferrobus-read.1, ferrobus-diag-echo.1, ...) are written
//! there, as the Debian package installs them.
//!
//! clap_mangen's sections are used as they are, but for the text after the options (examples,
//! the exit codes, bench's JSON format): that is laid out by hand for a terminal, so its
//! indented lines (examples, tables) and its `- ` list items keep their lines (`.nf`) instead of
//! being filled into the paragraph, where a long example line would not fit (groff: "cannot
//! adjust line"); prose is filled as usual.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, CommandFactory};
use clap_mangen::Man;
use clap_mangen::roff::{Roff, roman};

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
    let mut command = Cli::command().disable_help_subcommand(true);
    command.build();
    if let Some(dir) = &args.dir {
        return write_pages(&command, "ferrobus", dir)
            .map_err(|source| CliError::Output { what: format!("the man pages into {}", dir.display()), source });
    }
    let mut page = Vec::new();
    render(&command, &mut page).map_err(|source| CliError::Output { what: "the man page".into(), source })?;
    crate::output::print(&String::from_utf8_lossy(&page))
}

/// Writes the page of `command` (named `name`.1) and of each of its visible subcommands.
fn write_pages(command: &clap::Command, name: &str, dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut file = std::fs::File::create(dir.join(format!("{name}.1")))?;
    render(command, &mut file)?;
    file.flush()?;
    for sub in command.get_subcommands().filter(|s| !s.is_hide_set()) {
        let sub_name = format!("{name}-{}", sub.get_name());
        let sub = sub.clone().display_name(sub_name.clone());
        write_pages(&sub, &sub_name, dir)?;
    }
    Ok(())
}

/// One page: clap_mangen's sections, and the text after the options kept line by line.
fn render(command: &clap::Command, out: &mut dyn Write) -> std::io::Result<()> {
    let man = Man::new(command.clone());
    man.render_title(out)?;
    man.render_name_section(out)?;
    man.render_synopsis_section(out)?;
    man.render_description_section(out)?;
    if command.get_arguments().any(|a| !a.is_hide_set()) {
        man.render_options_section(out)?;
    }
    if command.get_subcommands().any(|s| !s.is_hide_set()) {
        man.render_subcommands_section(out)?;
    }
    if let Some(after) = command.get_after_long_help().or_else(|| command.get_after_help()) {
        let mut roff = Roff::new();
        roff.control("SH", ["NOTES"]);
        let mut kept = false;
        for line in after.to_string().lines() {
            let keep = line.starts_with(' ') || line.starts_with("- ");
            if keep != kept {
                roff.control(if keep { "nf" } else { "fi" }, []);
                kept = keep;
            }
            if line.trim().is_empty() {
                roff.control("sp", []);
            } else {
                roff.text([roman(line)]);
            }
        }
        if kept {
            roff.control("fi", []);
        }
        out.write_all(roff.to_roff().as_bytes())?;
    }
    if command.get_version().is_some() {
        man.render_version_section(out)?;
    }
    Ok(())
}
