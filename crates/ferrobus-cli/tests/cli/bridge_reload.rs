//! `bridge` on SIGHUP: the plant file read again and checked, the bridge running on
//! throughout (its broker away: it keeps retrying). A mistake is logged at error level at its
//! place; the same file changes nothing; an added device is applied (the line it is on is
//! started again with it) and what was done is logged; a new edge node id is refused by name.

use crate::gateway_lines::{Proc, dir};

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
    let mut bridge = Proc::ferrobus(&["-v", "--config", path, "bridge", "--duration", "120s"], false);
    bridge.until("bridge: polling 2 devices on 1 line");

    std::fs::write(&file, plant.replace("unit = 1", "unit = 1\nunit = 2")).unwrap();
    bridge.signal("HUP");
    let refused = bridge.until("reload refused");
    assert!(refused.contains("ERROR") && refused.contains(&format!("{path}:")), "{refused}");

    std::fs::write(&file, &plant).unwrap();
    bridge.signal("HUP");
    let same = bridge.until("reload:");
    assert!(same.contains("reload: 0 devices added, 0 changed, 0 removed, 2 unchanged;"), "{same}");

    let added = "\n[[line.device]]\nid = \"second\"\nunit = 3\nprofile = \"omron-3g3rx\"\nevery = \"1s\"\npoints = [\"d001\"]\n";
    std::fs::write(&file, format!("{plant}{added}")).unwrap();
    bridge.signal("HUP");
    let applied = bridge.until("reload: 1 device");
    assert!(applied.contains("reload: 1 device added, 0 changed, 0 removed, 2 unchanged;"), "{applied}");

    std::fs::write(&file, plant.replace("\"demo-edge\"", "\"other\"")).unwrap();
    bridge.signal("HUP");
    let fixed = bridge.until("reload refused");
    assert!(fixed.contains("[sparkplug] edge_node_id cannot change while the bridge runs"), "{fixed}");

    let end = bridge.stop().join("\n");
    assert!(end.contains("bridge: reload: 4 files checked, 2 refused"), "{end}");
}
