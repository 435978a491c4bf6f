//! `bridge` on SIGHUP: the plant file read again and checked, the bridge running on
//! throughout (its broker away: it keeps retrying). A mistake is logged at error level at its
//! place; the same file changes nothing; an added device is applied (the line it is on is
//! started again with it) and what was done is logged; a new edge node id is refused by name.
//! Throughout, `/status.json` sums up the plant as applied last and counts the reloads; a
//! refused one's errors are among its recent warnings, escaped.

use crate::gateway_lines::{Proc, dir, status_after};

/// The shipped demo plant (a simulated 3G3RX and servo on one virtual line), its broker at a
/// port where none listens.
fn plant() -> String {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/bridge/demo.toml");
    std::fs::read_to_string(demo).unwrap().replace("127.0.0.1:1883", "127.0.0.1:1")
}

#[test]
fn sighup_checks_the_plant_file_again_and_applies_it_while_the_bridge_runs_on() {
    let dir = dir("bridge-reload");
    let file = dir.join("plant.toml");
    let plant = plant();
    std::fs::write(&file, &plant).unwrap();
    let path = file.to_str().unwrap();
    let args = ["-v", "--config", path, "bridge", "--metrics", "127.0.0.1:0", "--duration", "120s"];
    let mut bridge = Proc::ferrobus(&args, false);
    let page = bridge.until("bridge: status on http://");
    let page = page.split("http://").nth(1).unwrap().split('/').next().unwrap().to_string();
    bridge.until("bridge: polling 2 devices on 1 line");
    let summary = |status: &serde_json::Value| status["summary"].as_str().unwrap().to_string();
    let (status, row) = status_after(&page, 0);
    let at_start = summary(&status);
    assert!(at_start.starts_with(&format!("{path}: 1 line, 2 devices, ")), "{at_start}");
    assert_eq!(row, ["0", "0", "never", "-", "never"]);

    // A mistake: a profile whose name (an escape in TOML) holds an ESC.
    std::fs::write(&file, plant.replacen(r#""omron-3g3rx""#, r#""omron\u001b[31m""#, 1)).unwrap();
    bridge.signal("HUP");
    let refused = bridge.until("reload refused");
    assert!(refused.contains("ERROR") && refused.contains(&format!("{path}:")), "{refused}");
    let (status, row) = status_after(&page, 1);
    assert_eq!(summary(&status), at_start, "a refused reload leaves the summary");
    assert_eq!(row[..4], ["1", "1", "never", "-"]);
    assert!(row[4].ends_with(" (why: the recent warnings)"), "{row:?}");
    let recent: Vec<&str> = status["recent"].as_array().unwrap().iter().map(|r| r["text"].as_str().unwrap()).collect();
    let why = format!("reload refused, the running plant stays: {path}:");
    let named = recent.iter().find(|r| r.contains(&why)).unwrap_or_else(|| panic!("{recent:?}"));
    assert!(named.contains(r#"profile "omron\u{1b}[31m""#) && !named.contains('\u{1b}'), "escaped: {named}");

    std::fs::write(&file, &plant).unwrap();
    bridge.signal("HUP");
    let same = bridge.until("reload:");
    assert!(same.contains("reload: 0 devices added, 0 changed, 0 removed, 2 unchanged;"), "{same}");
    let (status, row) = status_after(&page, 2);
    assert_eq!(summary(&status), at_start);
    assert_eq!(row[..2], ["2", "1"]);
    assert!(row[2].starts_with("20") && row[2].ends_with('Z'), "when it was applied: {row:?}");

    let added = "\n[[line.device]]\nid = \"second\"\nunit = 3\nprofile = \"omron-3g3rx\"\nevery = \"1s\"\npoints = [\"d001\"]\n";
    std::fs::write(&file, format!("{plant}{added}")).unwrap();
    bridge.signal("HUP");
    let applied = bridge.until("reload: 1 device");
    assert!(applied.contains("reload: 1 device added, 0 changed, 0 removed, 2 unchanged;"), "{applied}");
    let (status, row) = status_after(&page, 3);
    let three = summary(&status);
    assert!(three.starts_with(&format!("{path}: 1 line, 3 devices, ")), "the plant as applied: {three}");
    assert!(three.ends_with(at_start.split_once("; ").unwrap().1), "the same mode and broker: {three}");
    assert_eq!(row[..2], ["3", "1"]);
    assert!(row[3].starts_with("1 device added, 0 changed, 0 removed, 2 unchanged;"), "{row:?}");

    std::fs::write(&file, plant.replace("\"demo-edge\"", "\"other\"")).unwrap();
    bridge.signal("HUP");
    let fixed = bridge.until("reload refused");
    assert!(fixed.contains("[sparkplug] edge_node_id cannot change while the bridge runs"), "{fixed}");
    let (status, row) = status_after(&page, 4);
    assert_eq!(summary(&status), three, "the refused plant is not the one running");
    assert_eq!(row[1], "2");

    let end = bridge.stop().join("\n");
    assert!(end.contains("bridge: reload: 4 files checked, 2 refused"), "{end}");
}

/// `--demo` drives its inverter through the client of the line as started: it holds because
/// the demo's plant is never read again. SIGHUP says so and changes nothing, the page has no
/// `Reloads` table, and the demo's writes after it still reach the drive.
#[test]
fn sighup_in_the_demo_reads_no_file_and_the_demo_drives_its_inverter_on() {
    let args = ["bridge", "--demo", "--broker", "127.0.0.1:1", "--metrics", "127.0.0.1:0", "--duration", "120s"];
    let mut bridge = Proc::ferrobus(&args, false);
    let page = bridge.until("bridge: status on http://");
    let page = page.split("http://").nth(1).unwrap().split('/').next().unwrap().to_string();
    bridge.until("bridge: polling 2 devices on 1 line");
    bridge.signal("HUP");
    let warned = bridge.until("SIGHUP");
    assert!(warned.contains("the bridge runs the demo's plant, so there is no file to read again"), "{warned}");
    let status = crate::gateway_lines::status_json(&page);
    assert!(status["summary"].as_str().unwrap().starts_with("examples/bridge/demo.toml: 1 line, 2 devices, "));
    let titles: Vec<&str> = status["tables"].as_array().unwrap().iter().map(|t| t["title"].as_str().unwrap()).collect();
    assert!(!titles.contains(&"Reloads"), "{titles:?}");
    // The births never come (no broker): the demo starts after 5 s, on the line as started.
    let set = bridge.until("demo: inverter F001 = 60 Hz");
    assert!(set.ends_with("demo: inverter F001 = 60 Hz"), "the write went through: {set}");
    let run = bridge.until("demo: inverter run");
    assert!(run.ends_with("run: the output frequency ramps to F001"), "{run}");
    bridge.stop();
}
