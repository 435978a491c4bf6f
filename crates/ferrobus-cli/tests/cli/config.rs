//! Saved connections and defaults: the settings file's place, `--config`, `--conn`, precedence
//! (flags over the connection over `[defaults]` over built-in), `-v` and `config show`, and the
//! errors for broken files.

use std::path::{Path, PathBuf};

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::server::{Server, ferrobus, stderr, stdout};

/// A scratch directory removed at the end of the test.
pub(crate) struct Scratch(pub(crate) PathBuf);

impl Scratch {
    pub(crate) fn new(name: &str) -> Scratch {
        let dir = std::env::temp_dir().join(format!("ferrobus-cli-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }

    /// Writes `text` to `name` in the directory and returns its path.
    pub(crate) fn file(&self, name: &str, text: &str) -> PathBuf {
        let path = self.0.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, text).unwrap();
        path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

const FILE: &str = "\
[defaults]
baud = 38400
parity = \"odd\"
retries = 2

[connection.line-a]
port = \"/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0\"
baud = 9600
unit = 5
device = \"omron-3g3rx\"

[connection.empty]
";

/// `config show --json` with `args` before it, the settings file's home at `xdg`.
fn show(xdg: &Path, args: &[&str]) -> Value {
    let out = ferrobus().env("XDG_CONFIG_HOME", xdg).args(args).args(["config", "show", "--json"]).assert().success();
    serde_json::from_str(&stdout(&out)).unwrap()
}

/// The value and the source of one setting, or `None` if it has no value.
fn setting(doc: &Value, key: &str) -> Option<(String, String)> {
    doc["settings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["setting"] == key)
        .map(|s| (s["value"].as_str().unwrap().to_string(), s["source"].as_str().unwrap().to_string()))
}

/// What [`setting`] returns for a setting with this value and source.
#[expect(clippy::unnecessary_wraps, reason = "compared with setting()'s Option")]
fn pair(value: &str, source: &str) -> Option<(String, String)> {
    Some((value.to_string(), source.to_string()))
}

#[test]
fn the_file_is_found_under_xdg_config_home_and_its_defaults_apply_without_conn() {
    let dir = Scratch::new("config-xdg");
    let path = dir.file("ferrobus/config.toml", FILE);
    let doc = show(&dir.0, &[]);
    assert_eq!(doc["file"], path.display().to_string());
    assert_eq!(doc["file_found"], true);
    assert_eq!(doc["connections"], serde_json::json!(["empty", "line-a"]));
    let defaults = format!("defaults in {}", path.display());
    assert_eq!(setting(&doc, "baud"), pair("38400", &defaults));
    assert_eq!(setting(&doc, "parity"), pair("odd", &defaults));
    assert_eq!(setting(&doc, "data-bits"), pair("8", "built-in"));
    assert_eq!(setting(&doc, "port"), None);
}

#[test]
fn without_xdg_config_home_the_file_is_in_home_dot_config() {
    let dir = Scratch::new("config-home");
    let path = dir.file(".config/ferrobus/config.toml", FILE);
    let out = ferrobus()
        .env_remove("XDG_CONFIG_HOME")
        .env("HOME", &dir.0)
        .args(["--conn", "line-a", "config", "show", "--json"])
        .assert()
        .success();
    let doc: Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(doc["file"], path.display().to_string());
    assert_eq!(setting(&doc, "baud"), pair("9600", &format!("connection line-a in {}", path.display())));
}

#[test]
fn flags_override_the_connection_which_overrides_the_defaults_which_override_built_ins() {
    let dir = Scratch::new("config-precedence");
    let path = dir.file("ferrobus/config.toml", FILE);
    let doc = show(&dir.0, &["--conn", "line-a", "--unit", "7", "--timeout", "250ms"]);
    let connection = format!("connection line-a in {}", path.display());
    let defaults = format!("defaults in {}", path.display());
    assert_eq!(doc["connection"], "line-a");
    assert_eq!(setting(&doc, "unit"), pair("7", "flag"));
    assert_eq!(setting(&doc, "timeout"), pair("250ms", "flag"));
    assert_eq!(setting(&doc, "baud"), pair("9600", &connection));
    assert_eq!(setting(&doc, "device"), pair("omron-3g3rx", &connection));
    assert_eq!(
        setting(&doc, "port"),
        pair("/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0", &connection)
    );
    assert_eq!(setting(&doc, "parity"), pair("odd", &defaults));
    assert_eq!(setting(&doc, "retries"), pair("2", &defaults));
    assert_eq!(setting(&doc, "stop-bits"), pair("1", "built-in"));
}

#[test]
fn a_bus_on_the_command_line_drops_the_connections_bus_but_keeps_its_line_settings() {
    let dir = Scratch::new("config-conflict");
    dir.file("ferrobus/config.toml", FILE);
    let doc = show(&dir.0, &["--conn", "line-a", "--tcp", "127.0.0.1:1502"]);
    assert_eq!(setting(&doc, "tcp"), pair("127.0.0.1:1502", "flag"));
    assert_eq!(setting(&doc, "port"), None);
    assert_eq!(setting(&doc, "baud").unwrap().0, "9600");
}

#[test]
fn options_given_after_the_command_override_the_file_too() {
    let dir = Scratch::new("config-after");
    dir.file("ferrobus/config.toml", FILE);
    let out = ferrobus()
        .env("XDG_CONFIG_HOME", &dir.0)
        .args(["config", "show", "--json", "--conn", "line-a", "--baud", "115200"])
        .assert()
        .success();
    let doc: Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(setting(&doc, "baud"), pair("115200", "flag"));
    assert_eq!(setting(&doc, "unit").unwrap().0, "5");
}

#[test]
fn a_saved_connection_reaches_the_device() {
    let server = Server::start();
    let dir = Scratch::new("config-reach");
    let [_, address] = server.target();
    let config =
        dir.file("plc.toml", &format!("[connection.plc]\ntcp = \"{address}\"\ntimeout = \"500ms\"\nunit = 1\n"));
    let out = ferrobus()
        .args(["--config", config.to_str().unwrap(), "--conn", "plc", "read", "holding", "0", "--count", "2", "--csv"])
        .assert()
        .success();
    assert_eq!(stdout(&out).lines().count(), 3, "a header and two registers: {}", stdout(&out));
    assert_eq!(server.take_requests().len(), 1);
}

#[test]
fn verbose_says_where_each_setting_came_from() {
    let dir = Scratch::new("config-verbose");
    let path = dir.file("ferrobus/config.toml", FILE);
    let out = ferrobus()
        .env("XDG_CONFIG_HOME", &dir.0)
        .env_remove("RUST_LOG")
        .args(["-v", "--conn", "line-a", "--stop-bits", "2", "config", "show"])
        .assert()
        .success();
    let err = stderr(&out);
    assert!(err.contains(&format!("settings file {}", path.display())), "{err}");
    assert!(err.contains(&format!("baud = 9600 (connection line-a in {})", path.display())), "{err}");
    assert!(err.contains(&format!("parity = odd (defaults in {})", path.display())), "{err}");
    assert!(err.contains("stop-bits = 2 (flag)"), "{err}");
    assert!(err.contains("data-bits = 8 (built-in)"), "{err}");
}

#[test]
fn config_show_prints_a_table_of_settings_and_sources() {
    let dir = Scratch::new("config-table");
    let path = dir.file("ferrobus/config.toml", FILE);
    let out = ferrobus().env("XDG_CONFIG_HOME", &dir.0).args(["--conn", "line-a", "config", "show"]).assert().success();
    let text = stdout(&out);
    assert!(text.starts_with("SETTING"), "{text}");
    let baud = text.lines().find(|l| l.starts_with("baud ")).unwrap();
    assert!(baud.contains("9600") && baud.ends_with(&format!("connection line-a in {}", path.display())), "{baud}");
    assert!(stderr(&out).contains("saved connections: empty, line-a"), "{}", stderr(&out));
}

#[test]
fn no_file_means_built_in_defaults() {
    let dir = Scratch::new("config-none");
    let doc = show(&dir.0, &[]);
    assert_eq!(doc["file_found"], false);
    assert_eq!(setting(&doc, "baud"), pair("19200", "built-in"));
}

/// Runs with `--config FILE` holding `text`; the exit code must be 2; returns stderr.
fn broken(text: &str, args: &[&str]) -> (String, PathBuf, Scratch) {
    let dir = Scratch::new(&format!("config-broken-{}", text.len()));
    let path = dir.file("broken.toml", text);
    let out = ferrobus().args(["--config", path.to_str().unwrap()]).args(args).assert().code(2);
    (stderr(&out), path, dir)
}

#[test]
fn a_bad_value_is_named_by_file_line_column_table_and_setting() {
    let (err, path, _dir) = broken(
        "[connection.a]\nport = \"/dev/ttyUSB0\"\nparity = \"mark\"\n",
        &["--conn", "a", "read", "holding", "0"],
    );
    assert!(
        err.starts_with(&format!("error: {}:3:10: [connection.a]: invalid value 'mark' for '--parity", path.display())),
        "{err}"
    );
}

#[test]
fn an_unknown_setting_is_named_with_its_line_and_the_settings_there_are() {
    let (err, path, _dir) = broken("[defaults]\nbaud = 9600\nspeed = 9600\n", &["config", "show"]);
    assert!(err.starts_with(&format!("error: {}:3:1: [defaults]: unknown setting 'speed'", path.display())), "{err}");
    assert!(err.contains("settings are: port, tcp, rtu-tcp"), "{err}");
}

#[test]
fn a_toml_syntax_error_names_the_file_and_line() {
    let (err, path, _dir) = broken("[defaults]\nbaud = 9600\ntimeout = 500ms\n", &["config", "show"]);
    assert!(err.contains(&format!("settings file {}:3:11: ", path.display())), "{err}");
}

#[test]
fn an_unknown_table_is_an_error_not_ignored() {
    let (err, path, _dir) = broken("[connections.a]\nport = \"/dev/ttyUSB0\"\n", &["config", "show"]);
    assert!(err.contains(&format!("{}:1:2: unknown field `connections`", path.display())), "{err}");
}

#[test]
fn a_broken_file_in_the_default_place_is_an_error_even_without_conn() {
    let dir = Scratch::new("config-broken-default");
    dir.file("ferrobus/config.toml", "[defaults]\nbaud = \"fast\"\n");
    let out = ferrobus().env("XDG_CONFIG_HOME", &dir.0).args(["config", "show"]).assert().code(2);
    assert!(stderr(&out).contains("[defaults]: invalid value 'fast' for '--baud"), "{}", stderr(&out));
    // Commands that use no connection setting do not read it, and refuse --conn.
    ferrobus().env("XDG_CONFIG_HOME", &dir.0).args(["crc", "01 03"]).assert().success();
    let out = ferrobus().env("XDG_CONFIG_HOME", &dir.0).args(["crc", "--conn", "a", "01 03"]).assert().code(2);
    assert!(stderr(&out).contains("--conn is not used by `crc`"), "{}", stderr(&out));
}

#[test]
fn an_unknown_connection_lists_the_saved_ones() {
    let dir = Scratch::new("config-unknown-conn");
    dir.file("ferrobus/config.toml", FILE);
    let out = ferrobus().env("XDG_CONFIG_HOME", &dir.0).args(["--conn", "line-b", "config", "show"]).assert().code(2);
    assert!(
        stderr(&out).contains("no connection 'line-b' in") && stderr(&out).contains("it has empty, line-a"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn conn_without_a_file_and_a_missing_config_file_are_errors() {
    let dir = Scratch::new("config-missing");
    let out = ferrobus().env("XDG_CONFIG_HOME", &dir.0).args(["--conn", "a", "config", "show"]).assert().code(2);
    assert!(stderr(&out).contains("--conn a: there is no settings file at"), "{}", stderr(&out));
    let missing = dir.0.join("nope.toml");
    let out = ferrobus().args(["--config", missing.to_str().unwrap(), "config", "show"]).assert().code(2);
    assert!(stderr(&out).contains(&format!("cannot read the settings file {}", missing.display())), "{}", stderr(&out));
}

#[test]
fn a_flag_set_false_in_a_connection_turns_off_the_defaults_true() {
    let dir = Scratch::new("config-flag");
    let path = dir.file("ferrobus/config.toml", "[defaults]\necho = true\n[connection.quiet]\necho = false\n");
    let doc = show(&dir.0, &[]);
    assert_eq!(setting(&doc, "echo"), pair("true", &format!("defaults in {}", path.display())));
    let doc = show(&dir.0, &["--conn", "quiet"]);
    assert_eq!(setting(&doc, "echo"), pair("false", &format!("connection quiet in {}", path.display())));
}

#[test]
fn an_option_the_bus_does_not_use_is_refused_unless_it_is_a_default_or_the_connections() {
    let dir = Scratch::new("config-unused");
    let refused = |args: &[&str]| {
        let out = ferrobus().env("XDG_CONFIG_HOME", &dir.0).args(args).args(["read", "holding", "0"]).assert().code(2);
        stderr(&out)
    };
    let err = refused(&["--tcp", "127.0.0.1:1", "--baud", "9600"]);
    assert!(err.contains("--tcp is Modbus/TCP") && err.contains("--baud does not apply to it; leave it out"), "{err}");
    let err = refused(&["--tcp", "127.0.0.1:1", "--echo", "--t35", "10ms"]);
    assert!(err.contains("--t35, --echo do not apply to it; leave them out"), "{err}");
    // RTU over TCP has RTU's gaps, but the serial line is the gateway's.
    let err = refused(&["--rtu-tcp", "127.0.0.1:1", "--t35", "10ms", "--parity", "none"]);
    assert!(err.contains("--rtu-tcp is a TCP connection") && err.contains(": --parity does not apply"), "{err}");
    // A connection that names a TCP bus and a baud rate is a mistake in the file.
    let path = dir.file(
        "ferrobus/config.toml",
        "[defaults]\nbaud = 9600\n[connection.plc]\ntcp = \"127.0.0.1:1\"\nrs485 = \"rts\"\n",
    );
    let err = refused(&["--conn", "plc"]);
    assert!(err.contains(&format!("rs485 (from connection plc in {}) does not apply", path.display())), "{err}");
    // The defaults' baud rate is for the serial lines: with --tcp it is left alone.
    let doc = show(&dir.0, &["--tcp", "127.0.0.1:1"]);
    assert_eq!(setting(&doc, "baud").unwrap().0, "9600");
}
