//! `ferrobus completions SHELL`: the shell's completion script.
//!
//! The script is clap_complete's dynamic one: at each Tab the shell runs
//! `FERROBUS_COMPLETE=SHELL ferrobus -- WORDS...`, and ferrobus answers from its own command
//! definition (see [`command`]), so new commands and options complete without a new script,
//! and values that live outside the definition complete too: `--conn` offers the saved
//! connections of the settings file, `--device` the built-in profiles and then files. This
//! works in bash, zsh, fish, elvish and PowerShell alike.

use clap::{Args, CommandFactory, ValueEnum};
use clap_complete::engine::{ArgValueCompleter, CompletionCandidate, PathCompleter, ValueCompleter};
use clap_complete::env::Shells;

use crate::Cli;
use crate::exit::CliError;

/// The environment variable that asks ferrobus for completions instead of running a command.
pub(crate) const VAR: &str = "FERROBUS_COMPLETE";

/// `completions SHELL [--completer PROGRAM]`.
#[derive(Args, Debug)]
pub(crate) struct CompletionsArgs {
    /// The shell
    #[arg(value_enum)]
    shell: Shell,

    /// The program the script runs to complete (default: ferrobus, found on PATH)
    #[arg(long, value_name = "PROGRAM", default_value = "ferrobus")]
    completer: String,
}

/// The shells clap_complete writes for.
#[derive(ValueEnum, Clone, Copy, Debug)]
enum Shell {
    // GNU bash 4.4 and later (older ones without sorting).
    Bash,
    // Z shell.
    Zsh,
    // fish.
    Fish,
    // PowerShell.
    Powershell,
    // elvish.
    Elvish,
}

/// The command definition the completions are made from: the CLI's, with completers for the
/// values clap does not know (saved connections carry theirs in [`crate::config`]).
pub(crate) fn command() -> clap::Command {
    Cli::command().mut_arg("device", |arg| arg.add(ArgValueCompleter::new(complete_device)))
}

/// Runs `completions`.
pub(crate) fn run(args: &CompletionsArgs) -> Result<(), CliError> {
    let name = match args.shell {
        Shell::Bash => "bash",
        Shell::Zsh => "zsh",
        Shell::Fish => "fish",
        Shell::Powershell => "powershell",
        Shell::Elvish => "elvish",
    };
    let shells = Shells::builtins();
    let Some(shell) = shells.completer(name) else {
        return Err(CliError::Usage(format!("clap_complete has no {name} completer")));
    };
    let mut script = Vec::new();
    shell
        .write_registration(VAR, "ferrobus", "ferrobus", &args.completer, &mut script)
        .map_err(|source| CliError::Output { what: "the completion script".into(), source })?;
    crate::output::print(&String::from_utf8_lossy(&script))
}

/// The built-in profile names that start with what was typed, then files.
fn complete_device(current: &std::ffi::OsStr) -> Vec<CompletionCandidate> {
    let typed = current.to_string_lossy();
    let mut candidates: Vec<CompletionCandidate> = ferrobus_sim::profile::BUILTIN
        .iter()
        .filter(|(name, _)| name.starts_with(typed.as_ref()))
        .map(|(name, _)| CompletionCandidate::new(*name).help(Some("built-in profile".into())))
        .collect();
    candidates.extend(PathCompleter::file().complete(current));
    candidates
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_completes_the_built_in_profiles_by_prefix() {
        let names: Vec<String> =
            complete_device("omr".as_ref()).iter().map(|c| c.get_value().to_string_lossy().into_owned()).collect();
        assert_eq!(names, ["omron-3g3rx"]);
    }

    #[test]
    fn the_completion_command_keeps_the_definition_consistent() {
        command().debug_assert();
    }
}
