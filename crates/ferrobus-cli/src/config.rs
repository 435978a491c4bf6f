//! Saved connections and defaults: the settings file, its precedence, and `ferrobus config show`.
//!
//! The file is TOML, at `$XDG_CONFIG_HOME/ferrobus/config.toml` (else `~/.config/ferrobus/config.toml`)
//! on Linux and the platform's config directory elsewhere (`~/Library/Application Support/ferrobus`,
//! `%APPDATA%\ferrobus`), or wherever `--config FILE` says:
//!
//! ```toml
//! [defaults]
//! timeout = "500ms"
//!
//! [connection.line-a]
//! port = "/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"
//! baud = 9600
//! parity = "even"
//! unit = 1
//! ```
//!
//! A key is a connection option's long name (`data-bits`, or `data_bits`), its value what the
//! option takes (a string or a number; `true` for a flag; a list for `unit`, which `sim` takes
//! more than once). Every option of [`ConnectArgs`] is a key, found by clap's own definition, so a
//! new connection option is a key without a line here; each value goes through that option's
//! own parser, so the file is checked exactly as the command line is.
//!
//! Precedence, highest first: the command line, `[connection.NAME]` chosen with `--conn NAME`,
//! `[defaults]`, the built-in default. A setting is also dropped where a higher layer set one it
//! conflicts with (a `--tcp` on the command line drops the connection's `port`). The chosen
//! settings are handed to clap as if typed before the command, so each command reads its options
//! as it always has; `-v` logs where each came from.

use std::collections::BTreeMap;
use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};

use clap::parser::ValueSource;
use clap::{ArgAction, ArgMatches, Args, CommandFactory};
use clap_complete::engine::{ArgValueCompleter, CompletionCandidate};
use serde::Deserialize;
use serde_json::json;
use toml::Spanned;

use ferrobus_profile::source::{self, Located, ReadError};

use crate::Cli;
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `--config FILE` and `--conn NAME`.
#[derive(Args, Clone, Debug, Default)]
#[command(next_help_heading = "Connection")]
pub(crate) struct ConfigArgs {
    /// Settings file for --conn and [defaults] (default: the platform's config dir, e.g. ~/.config/ferrobus/config.toml)
    #[arg(long, global = true, value_name = "FILE")]
    pub(crate) config: Option<PathBuf>,

    /// A saved connection: the settings of [connection.NAME] in the settings file
    #[arg(long, global = true, value_name = "NAME", add = ArgValueCompleter::new(complete_connection))]
    pub(crate) conn: Option<String>,
}

/// `config show`.
#[derive(Args, Debug)]
pub(crate) struct ConfigCommandArgs {
    /// What to do with the settings.
    #[command(subcommand)]
    action: ConfigAction,
}

/// The `config` actions.
#[derive(clap::Subcommand, Debug)]
enum ConfigAction {
    /// The effective connection settings, each with where it came from, and the saved connections
    Show {
        /// The output format.
        #[command(flatten)]
        output: OutputArgs,
    },
}

/// Where a setting came from.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(crate) enum Source {
    /// The command line.
    Flag,
    /// `[connection.NAME]` in the file.
    Connection { name: String, file: PathBuf },
    /// `[defaults]` in the file.
    Defaults { file: PathBuf },
    /// The option's built-in default.
    BuiltIn,
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Source::Flag => f.write_str("flag"),
            Source::Connection { name, file } => write!(f, "connection {name} in {}", file.display()),
            Source::Defaults { file } => write!(f, "defaults in {}", file.display()),
            Source::BuiltIn => f.write_str("built-in"),
        }
    }
}

/// One effective connection setting.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(crate) struct Setting {
    /// The option's long name (the file's key).
    pub(crate) key: String,
    /// Its value as clap holds it.
    pub(crate) value: String,
    /// Where it came from.
    pub(crate) source: Source,
}

/// The settings file that was looked at, and the effective settings.
#[derive(Clone, Debug, Default)]
pub(crate) struct Layered {
    /// The file looked at, and whether it was there.
    pub(crate) file: Option<(PathBuf, bool)>,
    /// The saved connections' names in the file.
    pub(crate) connections: Vec<String>,
    /// The connection chosen with `--conn`.
    pub(crate) conn: Option<String>,
    /// Every connection option that has a value, in `--help` order.
    pub(crate) settings: Vec<Setting>,
}

impl Layered {
    /// Logs where each setting came from (shown with `-v`).
    pub(crate) fn log(&self) {
        match &self.file {
            Some((path, true)) => tracing::info!("settings file {}", path.display()),
            Some((path, false)) => tracing::info!("no settings file at {}", path.display()),
            None => tracing::info!("no settings file: the platform has no config directory"),
        }
        for setting in &self.settings {
            tracing::info!("{} = {} ({})", setting.key, setting.value, setting.source);
        }
    }
}

/// The default settings file: `ferrobus/config.toml` in the platform's config directory.
pub(crate) fn default_path() -> Option<PathBuf> {
    dirs::config_dir().map(|dir| dir.join("ferrobus").join("config.toml"))
}

/// A value as the file holds it, with where it is.
type Value = Spanned<toml::Value>;
/// A table of settings as the file holds it.
type Table = BTreeMap<Spanned<String>, Value>;

/// The file's shape. Unknown tables are errors, with their line.
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileShape {
    #[serde(default)]
    defaults: Table,
    #[serde(default)]
    connection: BTreeMap<Spanned<String>, Spanned<Table>>,
}

/// A connection option as clap defines it.
struct OptionDef {
    id: String,
    long: String,
    flag: bool,
    many: bool,
}

/// The connection options: every argument of [`ConnectArgs`].
fn connection_options() -> Vec<OptionDef> {
    ConnectArgs::augment_args(clap::Command::new("connection"))
        .get_arguments()
        .filter_map(|arg| {
            let long = arg.get_long()?.to_string();
            Some(OptionDef {
                id: arg.get_id().to_string(),
                long,
                flag: matches!(arg.get_action(), ArgAction::SetTrue),
                many: matches!(arg.get_action(), ArgAction::Append),
            })
        })
        .collect()
}

/// A parsed settings file: each table's settings as command-line values.
#[derive(Debug)]
struct File {
    path: PathBuf,
    defaults: BTreeMap<String, Vec<String>>,
    connections: BTreeMap<String, BTreeMap<String, Vec<String>>>,
}

impl File {
    /// Reads and checks a settings file.
    fn read(path: &Path) -> Result<File, CliError> {
        let text = source::read(path).map_err(|e| match e {
            ReadError::Io(e) => CliError::Usage(format!("cannot read the settings file {}: {e}", path.display())),
            ReadError::NotText(e) => CliError::Usage(format!("settings file {}:{e}", path.display())),
        })?;
        File::parse(path, &text)
    }

    /// Parses and checks the text of a settings file.
    fn parse(path: &Path, text: &str) -> Result<File, CliError> {
        let shown = path.display().to_string();
        let shape: FileShape = toml::from_str(text)
            .map_err(|e| CliError::Usage(format!("settings file {}", Located::toml(text, &e).in_file(&shown))))?;
        let options = connection_options();
        let command = Cli::command();
        let at = |span: std::ops::Range<usize>, table: &str, what: String| {
            CliError::Usage(Located::new(text, Some(span), &format!("{table}: {what}")).in_file(&shown))
        };
        let table = |name: &str, table: &Table| -> Result<BTreeMap<String, Vec<String>>, CliError> {
            let mut out = BTreeMap::new();
            // In the file's order, so that an error points at the later of two settings.
            let mut entries: Vec<_> = table.iter().collect();
            entries.sort_by_key(|(key, _)| key.span().start);
            for (key, value) in entries {
                let typed = key.get_ref().replace('_', "-");
                let Some(option) = options.iter().find(|o| o.long == typed) else {
                    let known: Vec<&str> = options.iter().map(|o| o.long.as_str()).collect();
                    return Err(at(
                        key.span(),
                        name,
                        format!("unknown setting '{}' (settings are: {})", key.get_ref(), known.join(", ")),
                    ));
                };
                if out.contains_key(&option.id) {
                    return Err(at(key.span(), name, format!("'{}' is given twice", option.long)));
                }
                if let Some(other) =
                    options.iter().find(|o| out.contains_key(&o.id) && conflict(&command, &o.id, &option.id))
                {
                    return Err(at(
                        key.span(),
                        name,
                        format!("'{}' and '{}' cannot both be set (one bus per connection)", other.long, option.long),
                    ));
                }
                let values = values(option, value.get_ref()).map_err(|what| at(value.span(), name, what))?;
                for v in values.iter().filter(|_| !option.flag) {
                    check_value(&option.long, v).map_err(|what| at(value.span(), name, what))?;
                }
                out.insert(option.id.clone(), values);
            }
            Ok(out)
        };
        let defaults = table("[defaults]", &shape.defaults)?;
        let mut connections = BTreeMap::new();
        for (name, settings) in &shape.connection {
            let title = format!("[connection.{}]", name.get_ref());
            connections.insert(name.get_ref().clone(), table(&title, settings.get_ref())?);
        }
        Ok(File { path: path.to_path_buf(), defaults, connections })
    }
}

/// A file value as the command-line values of `option`: none for a flag set to false.
fn values(option: &OptionDef, value: &toml::Value) -> Result<Vec<String>, String> {
    let scalar = |value: &toml::Value| match value {
        toml::Value::String(s) => Ok(s.clone()),
        toml::Value::Integer(i) => Ok(i.to_string()),
        toml::Value::Float(f) => Ok(f.to_string()),
        other => Err(format!("'{}' takes a string or a number, not a {}", option.long, other.type_str())),
    };
    match value {
        _ if option.flag => match value {
            toml::Value::Boolean(true) => Ok(vec!["true".into()]),
            toml::Value::Boolean(false) => Ok(Vec::new()),
            other => Err(format!("'{}' is a flag: true or false, not a {}", option.long, other.type_str())),
        },
        toml::Value::Array(items) if option.many => items.iter().map(scalar).collect(),
        toml::Value::Array(_) => Err(format!("'{}' takes one value, not a list", option.long)),
        value => Ok(vec![scalar(value)?]),
    }
}

/// Checks a value with the option's own parser: the connection options alone are given
/// `--long=value`, so that only the value is judged, not what else a command line holds.
fn check_value(long: &str, value: &str) -> Result<(), String> {
    let alone = ConnectArgs::augment_args(clap::Command::new("ferrobus").no_binary_name(true));
    alone.try_get_matches_from([format!("--{long}={value}")]).map(drop).map_err(|e| {
        let text = e.to_string();
        // clap's usage lines are for the command line; the first line says what is wrong.
        let first = text.lines().next().unwrap_or_default();
        first.strip_prefix("error: ").unwrap_or(first).to_string()
    })
}

/// Whether the command line gave `id` (on the top level or any subcommand: the connection
/// options are global).
fn given(matches: &ArgMatches, id: &str) -> bool {
    let mut m = Some(matches);
    while let Some(here) = m {
        if here.try_get_raw(id).is_ok_and(|v| v.is_some()) && here.value_source(id) == Some(ValueSource::CommandLine) {
            return true;
        }
        m = here.subcommand().map(|(_, sub)| sub);
    }
    false
}

/// Whether two options conflict (either way round).
fn conflict(command: &clap::Command, a: &str, b: &str) -> bool {
    let find = |id: &str| command.get_arguments().find(|x| x.get_id() == id);
    let (Some(arg_a), Some(arg_b)) = (find(a), find(b)) else { return false };
    command.get_arg_conflicts_with(arg_a).iter().any(|x| x.get_id() == b)
        || command.get_arg_conflicts_with(arg_b).iter().any(|x| x.get_id() == a)
}

/// The commands that use no connection setting: the file is not read for them.
const WITHOUT_CONNECTION: [&str; 6] = ["crc", "demo", "completions", "man", "ports", "help"];

/// The settings file to read (`--config FILE`, else the default one if it is there) and its
/// settings; the path is the one looked at, there or not.
fn find_file(explicit: Option<&PathBuf>) -> Result<(Option<PathBuf>, Option<File>), CliError> {
    Ok(match (explicit, default_path()) {
        (Some(path), _) => (Some(path.clone()), Some(File::read(path)?)),
        (None, Some(path)) if path.exists() => {
            let file = File::read(&path)?;
            (Some(path), Some(file))
        }
        (None, path) => (path, None),
    })
}

/// The settings of `[connection.NAME]` for `--conn NAME`: an error if there is no such
/// connection or no file.
fn chosen_connection<'f>(
    conn: Option<&str>,
    path: Option<&Path>,
    file: Option<&'f File>,
) -> Result<Option<&'f BTreeMap<String, Vec<String>>>, CliError> {
    let Some(name) = conn else { return Ok(None) };
    let Some(file) = file else {
        return Err(CliError::Usage(match path {
            Some(path) => format!(
                "--conn {name}: there is no settings file at {} (write one, or name it with --config FILE)",
                path.display()
            ),
            None => format!("--conn {name}: this platform has no config directory; name the file with --config FILE"),
        }));
    };
    file.connections.get(name).map(Some).ok_or_else(|| {
        let names: Vec<&str> = file.connections.keys().map(String::as_str).collect();
        CliError::Usage(format!(
            "no connection '{name}' in {}: it has {}",
            file.path.display(),
            if names.is_empty() { "none".to_string() } else { names.join(", ") }
        ))
    })
}

/// The file's settings put under the command line's, as new arguments for clap; and where
/// each effective setting came from. `args` is the command line, its program name first.
pub(crate) fn layer(matches: ArgMatches, args: Vec<OsString>) -> Result<(ArgMatches, Layered), CliError> {
    if let Some(name) = matches.subcommand_name().filter(|name| WITHOUT_CONNECTION.contains(name)) {
        if let Some(option) = ["config", "conn"].into_iter().find(|id| given(&matches, id)) {
            return Err(CliError::Usage(format!(
                "--{option} is not used by `{name}`: it reads no connection settings; leave it out"
            )));
        }
        return Ok((matches, Layered::default()));
    }
    // `bridge --config FILE` is the plant file: the bridge reads no connection settings.
    if matches.subcommand_name() == Some("bridge") {
        if given(&matches, "conn") {
            return Err(CliError::Usage(
                "--conn is not used by `bridge`: each line of the plant file has its own settings; leave it out".into(),
            ));
        }
        return Ok((matches, Layered::default()));
    }
    let conn = matches.get_one::<String>("conn").cloned();
    let (path, file) = find_file(matches.get_one::<PathBuf>("config"))?;
    let chosen = chosen_connection(conn.as_deref(), path.as_deref(), file.as_ref())?;
    let command = Cli::command();
    let options = connection_options();
    let mut set: Vec<&str> = options.iter().filter(|o| given(&matches, &o.id)).map(|o| o.id.as_str()).collect();
    let mut sources: BTreeMap<&str, Source> = set.iter().map(|id| (*id, Source::Flag)).collect();
    let mut extra: Vec<OsString> = Vec::new();
    let empty = BTreeMap::new();
    let layers = [
        (
            chosen.unwrap_or(&empty),
            conn.as_ref()
                .zip(file.as_ref())
                .map(|(name, file)| Source::Connection { name: name.clone(), file: file.path.clone() }),
        ),
        (
            file.as_ref().map_or(&empty, |f| &f.defaults),
            file.as_ref().map(|f| Source::Defaults { file: f.path.clone() }),
        ),
    ];
    for (table, source) in layers {
        let Some(source) = source else { continue };
        let mut here = Vec::new();
        for option in &options {
            let Some(values) = table.get(&option.id) else { continue };
            if set.iter().any(|id| *id == option.id || conflict(&command, id, &option.id)) {
                continue;
            }
            for value in values {
                extra.push(if option.flag {
                    format!("--{}", option.long).into()
                } else {
                    format!("--{}={value}", option.long).into()
                });
            }
            sources.insert(&option.id, source.clone());
            here.push(option.id.as_str());
        }
        set.extend(here);
    }
    let matches = if extra.is_empty() {
        matches
    } else {
        let mut typed = args.into_iter();
        let program = typed.next();
        command.try_get_matches_from(program.into_iter().chain(extra).chain(typed)).map_err(|e| {
            CliError::Usage(format!(
                "the settings file's values do not fit the command line: {}",
                e.to_string().trim_end()
            ))
        })?
    };
    refuse_unused(&matches, &sources, &options)?;
    let settings = options
        .iter()
        .filter_map(|option| {
            let raw: Vec<String> =
                matches.try_get_raw(&option.id).ok().flatten()?.map(|v| v.to_string_lossy().into_owned()).collect();
            let source = sources.get(option.id.as_str()).cloned().unwrap_or(Source::BuiltIn);
            Some(Setting { key: option.long.clone(), value: raw.join(", "), source })
        })
        .collect();
    let layered = Layered {
        file: path.map(|p| {
            let found = file.is_some();
            (p, found)
        }),
        connections: file.as_ref().map(|f| f.connections.keys().cloned().collect()).unwrap_or_default(),
        conn,
        settings,
    };
    Ok((matches, layered))
}

/// An option that the chosen bus does not use (`--tcp HOST --baud 9600`) is a mistake, not a
/// no-op: it is refused, with where it came from, if the command line gave it or a connection
/// gave it beside that bus. `[defaults]` are for every bus, and a connection's line settings
/// under a bus the command line gives instead are the connection's: those are left alone.
fn refuse_unused(
    matches: &ArgMatches,
    sources: &BTreeMap<&str, Source>,
    options: &[OptionDef],
) -> Result<(), CliError> {
    let Some(bus) = ["tcp", "rtu_tcp"].into_iter().find(|id| matches.try_get_raw(id).is_ok_and(|v| v.is_some())) else {
        return Ok(());
    };
    let (unused, why) = crate::connect::unused_by(bus);
    let bus_source = sources.get(bus);
    let named: Vec<String> = options
        .iter()
        .filter(|option| unused.contains(&option.id.as_str()))
        .filter_map(|option| match sources.get(option.id.as_str())? {
            Source::Flag => Some(format!("--{}", option.long)),
            source @ Source::Connection { .. } if Some(source) == bus_source => {
                Some(format!("{} (from {source})", option.long))
            }
            Source::Connection { .. } | Source::Defaults { .. } | Source::BuiltIn => None,
        })
        .collect();
    if named.is_empty() {
        return Ok(());
    }
    let (verb, them) = if named.len() == 1 { ("does", "it") } else { ("do", "them") };
    Err(CliError::Usage(format!("{why}: {} {verb} not apply to it; leave {them} out", named.join(", "))))
}

/// Runs `config show`.
pub(crate) fn run(layered: &Layered, args: &ConfigCommandArgs) -> Result<(), CliError> {
    let ConfigAction::Show { output } = &args.action;
    let mut rows = Rows::new(&[("SETTING", Align::Left), ("VALUE", Align::Left), ("SOURCE", Align::Left)]);
    for setting in &layered.settings {
        rows.push(vec![setting.key.clone(), setting.value.clone(), setting.source.to_string()]);
    }
    let file = layered.file.as_ref().map(|(path, found)| (path.display().to_string(), *found));
    match output.format() {
        Format::Json => {
            let settings: Vec<_> = layered
                .settings
                .iter()
                .map(|s| json!({"setting": s.key, "value": s.value, "source": s.source.to_string()}))
                .collect();
            let document = json!({
                "file": file.as_ref().map(|(path, _)| path),
                "file_found": file.as_ref().is_some_and(|(_, found)| *found),
                "connection": layered.conn,
                "connections": layered.connections,
                "settings": settings,
            });
            output::print(&format!("{document:#}\n"))
        }
        format => {
            if format == Format::Table {
                match &file {
                    Some((path, true)) => eprintln!("settings file: {path}"),
                    Some((path, false)) => eprintln!("settings file: {path} (none there: built-in defaults)"),
                    None => eprintln!("settings file: none (this platform has no config directory)"),
                }
                if !layered.connections.is_empty() {
                    eprintln!("saved connections: {}", layered.connections.join(", "));
                }
            }
            output::print(&rows.render(format))
        }
    }
}

/// The saved connection names in the default settings file that start with what was typed
/// (for the shells' completion; a broken or missing file offers none).
fn complete_connection(current: &OsStr) -> Vec<CompletionCandidate> {
    let Some(current) = current.to_str() else { return Vec::new() };
    let Some(file) = default_path().and_then(|path| File::read(&path).ok()) else { return Vec::new() };
    file.connections.keys().filter(|name| name.starts_with(current)).map(CompletionCandidate::new).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<File, String> {
        File::parse(Path::new("c.toml"), text).map_err(|e| match e {
            CliError::Usage(message) => message,
            other => format!("{other:?}"),
        })
    }

    #[test]
    fn a_connection_and_the_defaults_are_read_as_command_line_values() {
        let file = parse(
            "[defaults]\ntimeout = \"500ms\"\n[connection.line-a]\nport = \"/dev/ttyUSB0\"\nbaud = 9600\n\
             parity = \"none\"\ndata_bits = 8\necho = true\nascii = false\nunit = [1, 2]\n",
        )
        .unwrap();
        assert_eq!(file.defaults["timeout"], ["500ms"]);
        let line = &file.connections["line-a"];
        assert_eq!(line["port"], ["/dev/ttyUSB0"]);
        assert_eq!(line["baud"], ["9600"]);
        assert_eq!(line["data_bits"], ["8"]);
        assert_eq!(line["echo"], ["true"]);
        assert!(line["ascii"].is_empty());
        assert_eq!(line["unit"], ["1", "2"]);
    }

    #[test]
    fn a_bad_value_names_the_file_line_column_table_and_setting() {
        let error = parse("[connection.a]\nport = \"/dev/x\"\nbaud = 0\n").unwrap_err();
        assert!(error.starts_with("c.toml:3:8: [connection.a]: "), "{error}");
        assert!(error.contains("--baud"), "{error}");
        let error = parse("[defaults]\nparity = \"mark\"\n").unwrap_err();
        assert!(error.starts_with("c.toml:2:10: [defaults]: "), "{error}");
        assert!(error.contains("mark"), "{error}");
    }

    #[test]
    fn an_unknown_setting_is_named_with_its_line_and_the_known_ones() {
        let error = parse("[defaults]\n\nbauds = 9600\n").unwrap_err();
        assert!(error.starts_with("c.toml:3:1: [defaults]: unknown setting 'bauds'"), "{error}");
        assert!(error.contains("baud, parity"), "{error}");
    }

    #[test]
    fn a_wrong_type_says_what_the_setting_takes() {
        assert!(
            parse("[defaults]\necho = 1\n").unwrap_err().contains("'echo' is a flag: true or false, not a integer")
        );
        assert!(parse("[defaults]\nbaud = [1]\n").unwrap_err().contains("'baud' takes one value, not a list"));
        assert!(parse("[defaults]\nport = true\n").unwrap_err().contains("'port' takes a string or a number"));
    }

    #[test]
    fn a_setting_given_twice_by_both_spellings_is_an_error() {
        let error = parse("[defaults]\ndata-bits = 8\ndata_bits = 8\n").unwrap_err();
        assert!(error.contains("'data-bits' is given twice"), "{error}");
    }

    #[test]
    fn a_toml_syntax_error_and_an_unknown_table_name_the_file_and_line() {
        let error = parse("[defaults]\nbaud = \n").unwrap_err();
        assert!(error.starts_with("settings file c.toml:2:8: "), "{error}");
        let error = parse("[conection.a]\nport = \"x\"\n").unwrap_err();
        assert!(error.starts_with("settings file c.toml:1:") && error.contains("conection"), "{error}");
    }

    #[test]
    fn a_mistake_on_a_10_mb_line_is_told_in_a_few_hundred_bytes() {
        let huge = "9".repeat(10 << 20);
        for text in [format!("[defaults]\nbaud = {huge}x\n"), format!("[defaults]\nparity = \"{huge}\"\n")] {
            let error = parse(&text).unwrap_err();
            assert!(error.len() < 2_000, "{} bytes: {}", error.len(), error.get(..200).unwrap_or(&error));
            assert!(error.contains(":2:") && error.contains('…'), "{error}");
        }
    }

    #[test]
    fn a_settings_file_that_is_not_utf8_is_refused_with_its_line_and_column() {
        let path = std::env::temp_dir().join(format!("ferrobus-settings-latin1-{}.toml", std::process::id()));
        std::fs::write(&path, b"[defaults]\nport = \"/dev/caf\xe9\"\n").unwrap();
        let error = match File::read(&path) {
            Err(CliError::Usage(e)) => e,
            other => panic!("{other:?}"),
        };
        let _ = std::fs::remove_file(&path);
        assert_eq!(error, format!("settings file {}:2:17: byte 0xE9 is not UTF-8 text", path.display()));
    }

    #[test]
    fn two_buses_in_one_table_are_an_error_at_the_second() {
        let error = parse("[connection.a]\nport = \"/dev/ttyUSB0\"\ntcp = \"plc\"\n").unwrap_err();
        assert!(error.starts_with("c.toml:3:1: [connection.a]: 'port' and 'tcp' cannot both be set"), "{error}");
    }

    #[test]
    fn port_and_tcp_conflict_either_way_round() {
        let command = Cli::command();
        assert!(conflict(&command, "tcp", "port"));
        assert!(conflict(&command, "port", "tcp"));
        assert!(!conflict(&command, "port", "baud"));
    }
}
