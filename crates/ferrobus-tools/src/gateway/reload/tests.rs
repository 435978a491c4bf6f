use super::{Fate, Plan, plan};
use crate::gateway::config::{LineDefaults, LinesFile, parse};

fn file(text: &str) -> LinesFile {
    parse("gw.toml", text, &LineDefaults::default()).unwrap()
}

const RUNNING: &str = r#"
[[line]]
port = "/dev/ttyA"
units = [1]

[[line]]
port = "/dev/ttyB"
baud = 9600
units = [2]

[[line]]
tcp = "10.0.0.7"
units = [3]
"#;

#[test]
fn the_same_file_is_an_empty_plan() {
    let plan = plan(&file(RUNNING), &file(RUNNING));
    assert!(plan.is_empty(), "{plan:?}");
    assert_eq!(plan.to_string(), "0 lines added, 0 changed, 0 removed, 3 unchanged; routes unchanged");
}

#[test]
fn a_line_is_known_by_its_port_not_its_place_and_an_added_line_is_added() {
    // ttyB first now, the tcp device's default port written out, and a new line.
    let new = r#"
[[line]]
port = "/dev/ttyB"
baud = 9600
units = [2]

[[line]]
tcp = "10.0.0.7:502"
units = [3]

[[line]]
port = "/dev/ttyA"
units = [1]

[[line]]
port = "/dev/ttyC"
units = [4]
"#;
    let plan = plan(&file(RUNNING), &file(new));
    let expected =
        vec![Fate::Unchanged { was: 1 }, Fate::Unchanged { was: 2 }, Fate::Unchanged { was: 0 }, Fate::Added];
    assert_eq!(plan, Plan { lines: expected, removed: vec![], routes_changed: true });
    assert_eq!(plan.to_string(), "1 line added, 0 changed, 0 removed, 3 unchanged; routes changed");
}

#[test]
fn a_setting_changed_changes_the_line_and_a_line_left_out_is_removed() {
    let new = r#"
[[line]]
port = "/dev/ttyA"
units = [1]

[[line]]
port = "/dev/ttyB"
baud = 19200
units = [2]
"#;
    let plan = plan(&file(RUNNING), &file(new));
    assert_eq!(plan.lines, [Fate::Unchanged { was: 0 }, Fate::Changed { was: 1 }]);
    assert_eq!(plan.removed, [2]);
    assert!(plan.routes_changed, "unit 3 goes nowhere now");
    assert_eq!(plan.to_string(), "0 lines added, 1 changed, 1 removed, 1 unchanged; routes changed");
}

#[test]
fn units_moved_change_the_routes_and_no_line() {
    let new = RUNNING.replace("units = [1]", "units = [1, \"10-12\"]").replace("units = [3]", "renumber = { 3 = 1 }");
    let plan = plan(&file(RUNNING), &file(&new));
    assert_eq!(plan.lines, [Fate::Unchanged { was: 0 }, Fate::Unchanged { was: 1 }, Fate::Unchanged { was: 2 }]);
    assert!(plan.routes_changed && plan.removed.is_empty());
}

#[test]
fn a_default_made_explicit_is_no_change_and_a_response_wait_is_one() {
    // 19200 8E1 is the default: saying it changes nothing; a response wait lengthens the
    // timeout, which the line runs with.
    let same = RUNNING.replacen("port = \"/dev/ttyA\"", "port = \"/dev/ttyA\"\nbaud = 19200\nparity = \"even\"", 1);
    assert!(plan(&file(RUNNING), &file(&same)).is_empty());
    let waits = RUNNING.replacen("port = \"/dev/ttyA\"", "port = \"/dev/ttyA\"\nresponse-wait = \"20ms\"", 1);
    assert_eq!(plan(&file(RUNNING), &file(&waits)).lines[0], Fate::Changed { was: 0 });
}

#[test]
fn a_serial_line_turned_into_rtu_over_tcp_is_one_removed_and_one_added() {
    let new = RUNNING.replace("port = \"/dev/ttyB\"\nbaud = 9600", "rtu-tcp = \"10.0.0.8:4001\"");
    let plan = plan(&file(RUNNING), &file(&new));
    assert_eq!(plan.lines, [Fate::Unchanged { was: 0 }, Fate::Added, Fate::Unchanged { was: 2 }]);
    assert_eq!(plan.removed, [1]);
}
