//! Every arrow between the workspace's crates points down: each crate has a layer, and it
//! depends (for its library or its tests) only on crates of lower layers. The transport
//! library a user embeds, `ferrobus`, sits below every tool, so that embedding a client or a
//! server compiles no gateway, poller or scanner.
//!
//! ```text
//!   5  ferrobus-cli
//!   4  ferrobus-bridge  ferrobus-sunspec (its tests read a simulated device)
//!   3  ferrobus-tools   ferrobus-sim
//!   2  ferrobus         (client, server, pump, ports, tls)
//!   1  ferrobus-profile
//!   0  ferrobus-proto
//! ```
//!
//! Reads the manifests; builds nothing.

use std::collections::BTreeMap;
use std::path::Path;

/// Each crate and its layer. A crate joining the workspace joins this list, or the test fails.
const LAYERS: [(&str, u8); 8] = [
    ("ferrobus-proto", 0),
    ("ferrobus-profile", 1),
    ("ferrobus", 2),
    ("ferrobus-tools", 3),
    ("ferrobus-sim", 3),
    ("ferrobus-sunspec", 4),
    ("ferrobus-bridge", 4),
    ("ferrobus-cli", 5),
];

fn workspace() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

fn manifest(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    text.parse().unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The workspace crates `krate` depends on, in any dependency table, with the table's name.
fn arrows(krate: &str) -> Vec<(String, &'static str)> {
    let manifest = manifest(&workspace().join("crates").join(krate).join("Cargo.toml"));
    let mut out = Vec::new();
    for table in ["dependencies", "dev-dependencies", "build-dependencies"] {
        let Some(deps) = manifest.get(table).and_then(toml::Value::as_table) else { continue };
        out.extend(deps.keys().filter(|name| name.starts_with("ferrobus")).map(|name| (name.clone(), table)));
    }
    out
}

#[test]
fn every_crate_of_the_workspace_has_a_layer() {
    let root = manifest(&workspace().join("Cargo.toml"));
    let members: Vec<String> = root["workspace"]["members"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap().trim_start_matches("crates/").to_string())
        .collect();
    let mut layered: Vec<&str> = LAYERS.iter().map(|(name, _)| *name).collect();
    let mut members: Vec<&str> = members.iter().map(String::as_str).collect();
    layered.sort_unstable();
    members.sort_unstable();
    assert_eq!(members, layered, "the workspace's members and the crates given a layer");
}

#[test]
fn every_dependency_between_the_workspace_crates_points_to_a_lower_layer() {
    let layer: BTreeMap<&str, u8> = LAYERS.into_iter().collect();
    let mut upward = Vec::new();
    for (krate, at) in LAYERS {
        for (dep, table) in arrows(krate) {
            match layer.get(dep.as_str()) {
                Some(&to) if to < at => {}
                Some(&to) => upward.push(format!("{krate} (layer {at}) -> {dep} (layer {to}) in [{table}]")),
                None => upward.push(format!("{krate} -> {dep}: a crate with no layer")),
            }
        }
    }
    assert!(upward.is_empty(), "arrows that do not point down: {upward:#?}");
}

#[test]
fn the_transport_library_depends_on_the_core_and_the_profiles_only_and_the_command_line_on_the_tools() {
    let transport: Vec<String> = arrows("ferrobus").into_iter().map(|(dep, _)| dep).collect();
    let extra: Vec<&String> =
        transport.iter().filter(|d| !["ferrobus-proto", "ferrobus-profile"].contains(&d.as_str())).collect();
    assert!(extra.is_empty(), "the transport library depends on {extra:?}");
    let cli: Vec<String> = arrows("ferrobus-cli").into_iter().map(|(dep, _)| dep).collect();
    assert!(cli.iter().any(|d| d == "ferrobus-tools"), "{cli:?}");
}
