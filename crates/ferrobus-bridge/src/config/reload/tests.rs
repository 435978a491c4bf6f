use std::path::Path;

use super::{Fate, Fixed, Plan, plan};
use crate::config::Plant;

/// Two simulated lines: a 3G3RX and a servo on the first, another 3G3RX on the second (the
/// running plant of the runtime's reload tests too).
pub(crate) const RUNNING: &str = r#"
[broker]
address = "127.0.0.1:1883"

[sparkplug]
group_id = "plant"
edge_node_id = "edge"

[[line]]
name = "a"
simulated = true

[[line.device]]
id = "inverter"
unit = 1
profile = "omron-3g3rx"
every = "1s"
points = ["d001", "d002"]

[[line.device]]
id = "servo"
unit = 2
profile = "sdp-servo"
every = "1s"
groups = ["monitor"]

[[line]]
name = "b"
simulated = true

[[line.device]]
id = "meter"
unit = 3
profile = "omron-3g3rx"
every = "1s"
points = ["d003"]
"#;

pub(crate) fn plant(text: &str) -> Plant {
    Plant::parse(text, "plant.toml", Path::new(".")).unwrap()
}

fn plan_to(text: &str) -> Result<Plan, Fixed> {
    plan(&plant(RUNNING), &plant(text))
}

#[test]
fn the_same_plant_changes_nothing() {
    let plan = plan_to(RUNNING).unwrap();
    assert!(plan.is_empty(), "{plan:?}");
    assert_eq!(
        plan.to_string(),
        "0 devices added, 0 changed, 0 removed, 3 unchanged; 0 lines added, 0 changed, 0 removed, 2 unchanged; broker \
         unchanged"
    );
}

#[test]
fn a_device_added_is_added_and_the_others_stay_unchanged() {
    let new = format!(
        "{RUNNING}\n[[line.device]]\nid = \"meter2\"\nunit = 4\nprofile = \"omron-3g3rx\"\nevery = \"1s\"\npoints = [\"d003\"]\n"
    );
    let plan = plan_to(&new).unwrap();
    let unchanged = |was| Fate::Unchanged { was };
    assert_eq!(plan.devices, [unchanged(0), unchanged(1), unchanged(2), Fate::Added]);
    assert_eq!(plan.lines, [unchanged(0), unchanged(1)]);
    assert!(!plan.reconnect && plan.removed_devices.is_empty());
    assert!(plan.to_string().starts_with("1 device added, 0 changed, 0 removed, 3 unchanged;"), "{plan}");
}

#[test]
fn a_device_whose_points_changed_is_changed_and_one_left_out_is_removed() {
    let new = RUNNING.replace(r#"points = ["d001", "d002"]"#, r#"points = ["d001"]"#);
    let start = new.find("[[line.device]]\nid = \"servo\"").unwrap();
    let end = new.find("[[line]]\nname = \"b\"").unwrap();
    let new = format!("{}{}", &new[..start], &new[end..]);
    let plan = plan_to(&new).unwrap();
    assert_eq!(plan.devices, [Fate::Changed { was: 0 }, Fate::Unchanged { was: 2 }]);
    assert_eq!(plan.removed_devices, [1]);
    assert_eq!(
        plan.lines,
        [Fate::Unchanged { was: 0 }, Fate::Unchanged { was: 1 }],
        "a line's devices are not its settings"
    );
}

#[test]
fn a_line_setting_changes_the_line_and_a_device_moved_to_another_line_is_changed() {
    let new = RUNNING.replacen("name = \"b\"\nsimulated = true", "name = \"b\"\nsimulated = true\nbaud = 9600", 1);
    let plan = plan_to(&new).unwrap();
    assert_eq!(plan.lines, [Fate::Unchanged { was: 0 }, Fate::Changed { was: 1 }]);
    // The device itself is the same: its line's settings do not rebirth it.
    assert_eq!(plan.devices[2], Fate::Unchanged { was: 2 });
    let moved = RUNNING.replace("name = \"b\"", "name = \"c\"");
    let plan = plan_to(&moved).unwrap();
    assert_eq!(plan.lines, [Fate::Unchanged { was: 0 }, Fate::Added]);
    assert_eq!(plan.removed_lines, [1]);
    assert_eq!(plan.devices[2], Fate::Changed { was: 2 });
}

#[test]
fn a_broker_setting_reconnects() {
    let plan = plan_to(&RUNNING.replace("127.0.0.1:1883", "127.0.0.1:1884")).unwrap();
    assert!(plan.reconnect && !plan.is_empty());
    assert!(plan.to_string().ends_with("; broker session made again"), "{plan}");
}

#[test]
fn the_edge_nodes_identity_the_mode_and_the_store_are_refused_by_name() {
    let renamed = RUNNING.replace("group_id = \"plant\"", "group_id = \"plant2\"").replace("\"edge\"", "\"edge2\"");
    let fixed = plan_to(&format!("{renamed}\n[store]\nmemory = \"1MiB\"\n")).unwrap_err();
    assert_eq!(fixed, Fixed(vec!["[sparkplug] group_id", "[sparkplug] edge_node_id", "[store]"]));
    assert_eq!(
        fixed.to_string(),
        "[sparkplug] group_id, [sparkplug] edge_node_id, [store] cannot change while the bridge runs (restart it to \
         change them); the running plant stays"
    );
    let plain =
        RUNNING.replace("[sparkplug]\ngroup_id = \"plant\"\nedge_node_id = \"edge\"", "[plain]\nprefix = \"plant\"");
    assert_eq!(plan_to(&plain).unwrap_err(), Fixed(vec!["the mode ([sparkplug] or [plain])"]));
}
