//! No two source files of a crate depend on each other, directly or round a loop: each file's
//! `crate::…` paths name the modules it uses, and the graph of top-level modules has no cycle
//! (issue 10: `client.rs` ↔ `driver.rs`, `cli/connect.rs` ↔ `cli/exit.rs`).
//!
//! Reads the workspace's sources; builds nothing.

mod sources;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use sources::{code, rust_files};

/// Cycles known and owned elsewhere, each as its sorted modules. When one is broken, this test
/// fails until it is taken off the list, so that it cannot come back unseen. None is known now.
const KNOWN: &[(&str, &[&str])] = &[];

const CRATES: [&str; 8] = [
    "ferrobus-proto",
    "ferrobus-profile",
    "ferrobus",
    "ferrobus-tools",
    "ferrobus-sim",
    "ferrobus-sunspec",
    "ferrobus-bridge",
    "ferrobus-cli",
];

fn ident(s: &str) -> &str {
    let end = s.find(|c: char| !(c.is_alphanumeric() || c == '_')).unwrap_or(s.len());
    &s[..end]
}

/// The top-level modules `code` names through `crate::`, grouped imports included.
fn uses(code: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for (at, _) in code.match_indices("crate::") {
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 0usize;
            let mut start = 0;
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => {
                        found.insert(ident(group[start..i].trim()).to_string());
                        break;
                    }
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        found.insert(ident(group[start..i].trim()).to_string());
                        start = i + 1;
                    }
                    _ => {}
                }
            }
        } else {
            found.insert(ident(rest).to_string());
        }
    }
    found.remove("");
    found.remove("self");
    found
}

/// Each top-level module of the crate and the modules it uses.
fn graph(krate: &str) -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(krate).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in files {
        let rel = file.strip_prefix(&src).unwrap();
        let first = rel.components().next().unwrap().as_os_str().to_string_lossy().into_owned();
        let module = first.strip_suffix(".rs").unwrap_or(&first).to_string();
        if module == "lib" || module == "main" {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        let mut used = uses(&code(&text));
        used.remove(&module);
        graph.entry(module).or_default().extend(used);
    }
    graph
}

/// The strongly connected groups of more than one module: each is a cycle of files.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> BTreeSet<Vec<String>> {
    let reach = |from: &str| {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.to_string()];
        while let Some(m) = todo.pop() {
            for next in graph.get(&m).into_iter().flatten() {
                if graph.contains_key(next) && seen.insert(next.clone()) {
                    todo.push(next.clone());
                }
            }
        }
        seen
    };
    let reaches: BTreeMap<&String, BTreeSet<String>> = graph.keys().map(|m| (m, reach(m))).collect();
    let mut out = BTreeSet::new();
    for (m, r) in &reaches {
        let group: Vec<String> =
            graph.keys().filter(|n| *n == *m || (r.contains(*n) && reaches[n].contains(*m))).cloned().collect();
        if group.len() > 1 {
            out.insert(group);
        }
    }
    out
}

#[test]
fn no_two_source_files_of_a_crate_depend_on_each_other_but_the_known_cycles() {
    let mut unexpected = Vec::new();
    let mut gone = Vec::new();
    for krate in CRATES {
        let found = cycles(&graph(krate));
        let known: BTreeSet<Vec<String>> = KNOWN
            .iter()
            .filter(|(k, _)| *k == krate)
            .map(|(_, m)| m.iter().map(ToString::to_string).collect())
            .collect();
        unexpected.extend(found.difference(&known).map(|c| format!("{krate}: {}", c.join(" <-> "))));
        gone.extend(known.difference(&found).map(|c| format!("{krate}: {}", c.join(" <-> "))));
    }
    assert!(unexpected.is_empty(), "files that depend on each other: {unexpected:?}");
    assert!(gone.is_empty(), "these known cycles are broken now: take them off KNOWN: {gone:?}");
}

#[test]
fn the_scanner_sees_plain_grouped_and_nested_imports_and_skips_comments() {
    let text = "use crate::a::B;\nuse crate::{c, d::{E, F}, self};\n// crate::g\nlet x = crate::h::i();";
    let found: Vec<String> = uses(&code(text)).into_iter().collect();
    assert_eq!(found, ["a", "c", "d", "h"]);
    let two: BTreeMap<String, BTreeSet<String>> = [
        ("x".to_string(), ["y".to_string()].into()),
        ("y".to_string(), ["x".to_string()].into()),
        ("z".to_string(), ["x".to_string()].into()),
    ]
    .into();
    assert_eq!(cycles(&two), [vec!["x".to_string(), "y".to_string()]].into());
}
