//! `plant.toml`: the shipped examples resolve, and every kind of mistake is reported at its
//! line and column.

use ferrobus_bridge::config::{Connection, Mode, Plant};

#[test]
fn the_demo_resolves_to_the_planners_groups() {
    let plant = Plant::demo("broker.local:1884").expect("the demo resolves");
    assert_eq!((plant.broker.host.as_str(), plant.broker.port), ("broker.local", 1884));
    let Mode::Sparkplug(spb) = &plant.mode else { panic!("the demo is Sparkplug") };
    assert_eq!((spb.group_id.as_str(), spb.edge_node_id.as_str()), ("ferrobus-demo", "demo-edge"));
    for (_, d) in plant.devices() {
        for (g, b) in d.groups.iter().zip(&d.deadbands) {
            let cells: Vec<&str> = g.cells.iter().map(|c| c.name.as_str()).collect();
            println!("{} {} {:?} {} {} {:?} {:?} {:?}", d.id, g.name, g.table, g.start, g.count, g.every, cells, b);
        }
    }
    let [line] = plant.lines.as_slice() else { panic!("one line") };
    assert!(matches!(line.connection, Connection::Simulated { .. }));
}
