use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, FromArgMatches};
use ferrobus_tools::gateway::Route;
use ferrobus_tools::gateway::config::LinesFile;

use super::{Base, read};
use crate::connect::ConnectArgs;
use crate::exit::{CliError, Exit};

/// The connection options as `args` on the command line give them.
fn connection(args: &[&str]) -> ConnectArgs {
    let command = ConnectArgs::augment_args(clap::Command::new("test").no_binary_name(true));
    ConnectArgs::from_arg_matches(&command.try_get_matches_from(args).unwrap()).unwrap()
}

const BASE: Base = Base { backoff: None, queue: 64, late_guard: Duration::from_millis(100), in_flight: 1 };

/// `text` in a file of its own, removed when dropped.
struct File(PathBuf);

impl File {
    fn new(name: &str, text: &str) -> File {
        let path = std::env::temp_dir().join(format!("ferrobus-lines-{}-{name}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        File(path)
    }
}

impl Drop for File {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[test]
fn keys_not_in_a_line_come_from_the_command_line_and_the_line_beats_it() {
    let file = File::new("precedence", "[[line]]\nport = \"/dev/ttyA\"\nbaud = 9600\n");
    let args = connection(&[
        "--baud",
        "115200",
        "--parity",
        "none",
        "--timeout",
        "300ms",
        "--retries",
        "1",
        "--t35",
        "3ms",
        "--echo",
    ]);
    let LinesFile { lines, routes, .. } = read(&file.0, &args, BASE).unwrap();
    assert_eq!(lines[0].transport.describe(), "/dev/ttyA at 9600 8N1");
    assert_eq!(lines[0].transport.timing().t3_5(), Duration::from_millis(3));
    assert_eq!(lines[0].client.timeout, Duration::from_millis(300));
    assert_eq!(lines[0].client.retries, 1);
    assert!(lines[0].client.echo_suppression);
    // One line without units: units 1-247 under their own addresses, as with --port alone.
    assert_eq!(routes.get(1), Some(Route { line: 0, unit: 1 }));
    assert_eq!(routes.get(247), Some(Route { line: 0, unit: 247 }));
}

#[test]
fn the_gateways_queue_late_guard_and_backoff_go_to_every_line_unless_it_says_otherwise() {
    let text = "[[line]]\nport = \"/dev/ttyA\"\nunits = [1]\n[[line]]\nport = \"/dev/ttyB\"\nunits = [2]\nqueue = 3\n";
    let file = File::new("base", text);
    let backoff = ferrobus::Backoff { after: 3, initial: Duration::from_secs(5), max: Duration::from_secs(60) };
    let base = Base { backoff: Some(backoff), queue: 9, late_guard: Duration::from_millis(40), in_flight: 1 };
    let lines = read(&file.0, &connection(&[]), base).unwrap().lines;
    assert!(lines.iter().all(|l| l.client.backoff == Some(backoff)));
    assert_eq!((lines[0].queue, lines[1].queue), (9, 3));
    assert!(lines.iter().all(|l| l.late_guard == Duration::from_millis(40)));
}

#[test]
fn a_mistake_in_the_file_is_a_usage_error_with_the_librarys_place_and_message() {
    let file = File::new("mistake", "[[line]]\nport = \"/dev/ttyA\"\nbuad = 9600\n");
    let e = read(&file.0, &connection(&[]), BASE).unwrap_err();
    assert_eq!(e.exit(), Exit::Usage);
    let CliError::Usage(message) = e else { panic!("{e:?}") };
    assert!(message.starts_with(&format!("{}:3:1:", file.0.display())), "{message}");
    assert!(message.contains("buad"), "{message}");
    let missing = read(std::path::Path::new("/nonexistent/gw.toml"), &connection(&[]), BASE).unwrap_err();
    assert!(matches!(&missing, CliError::Usage(m) if m.starts_with("cannot read the lines file /nonexistent/gw.toml")));
}
