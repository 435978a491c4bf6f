//! The command that needs Unix ptys, where there are none (Windows): `line` parses whatever
//! it is given and says what to use instead. (`demo` runs its virtual line in-process, and
//! `sim --pty` is refused by `sim`.)

/// What to use instead of a pty on this platform.
pub(crate) const INSTEAD: &str = "on Windows, run the simulator over TCP (`ferrobus sim --tcp 127.0.0.1:5020`, \
     then `ferrobus --tcp 127.0.0.1:5020 ...`) or on one end of a com0com virtual COM pair \
     (`ferrobus sim --port COM10`, the client on COM11)";

/// `ferrobus line` without ptys.
pub(crate) mod line {
    use clap::Args;

    use crate::connect::ConnectArgs;
    use crate::exit::CliError;

    /// Arguments of `ferrobus line`: taken as given, never used.
    #[derive(Args, Clone, Debug)]
    pub(crate) struct LineArgs {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        ignored: Vec<String>,
    }

    /// Refuses: the virtual line is made of ptys.
    #[expect(clippy::unused_async, reason = "the same signature as on Unix")]
    pub(crate) async fn run(_: &ConnectArgs, _: &LineArgs) -> Result<(), CliError> {
        Err(CliError::Usage(format!("ferrobus line needs Unix ptys (Linux, macOS); {}", super::INSTEAD)))
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use crate::Cli;
    use crate::exit::CliError;

    /// What `ferrobus ARGS...` refuses with.
    fn refusal(args: &[&str]) -> String {
        let cli = Cli::try_parse_from(args).unwrap();
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        match runtime.block_on(crate::dispatch(&cli)) {
            Err(CliError::Usage(message)) => message,
            other => panic!("{args:?}: expected a usage error, got {other:?}"),
        }
    }

    #[test]
    fn line_and_sim_pty_say_they_need_a_unix_pty_and_what_to_use_instead() {
        for (args, what) in [
            (&["ferrobus", "line", "--drops", "3"][..], "ferrobus line needs Unix ptys"),
            (&["ferrobus", "sim", "--pty", "--profile", "generic"][..], "--pty needs a Unix pty"),
        ] {
            let message = refusal(args);
            assert!(message.starts_with(what), "{args:?}: {message}");
            assert!(message.contains("ferrobus sim --tcp 127.0.0.1:5020") && message.contains("com0com"), "{message}");
        }
    }
}
