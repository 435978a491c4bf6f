//! What the two YAML readers share: reading a file into a tree with the place of a mistake,
//! as Home Assistant's loader reads it, and reading the scalars of a tree whose shape the
//! file's author chose.
//!
//! The text is read event by event (yaml-rust2's parser) into serde_yaml_ng's [`Value`]:
//!
//! - scalars resolve as YAML 1.1 plain scalars do (`~`/`null`, `true`/`False`, `0x1F`,
//!   `1e3`, `.inf`); a quoted or block scalar, or one tagged `!!str`, is text;
//! - merge keys apply: `<<: *a`, `<<: [*a, *b]` (the first of the list wins), and two `<<`
//!   keys in one map, which Home Assistant's loader accepts (the later wins); the map's own
//!   keys win over all of them;
//! - a key written twice in one map keeps its last value, as Home Assistant does, and the
//!   earlier one is listed as not mapped;
//! - `!include FILE`, `!include_dir_list`, `!include_dir_named`, `!include_dir_merge_list`
//!   and `!include_dir_merge_named` read files relative to the including file, inside the
//!   directory of the map ([`super::ImportOptions::dir`]); `!secret NAME` is looked up in the
//!   `secrets.yaml` of the including file's directory, then of its parents up to the map's
//!   directory, as Home Assistant looks it up. A tag that cannot be resolved (no directory
//!   given, no such file, no such secret, `!env_var`) is listed as not mapped with what it
//!   names, and stays in the tree as a tagged value that no reader takes for a number.
//!   These tags are Home Assistant's: in an evcc file they stay as written.
//!
//! Bounds, each refused with a message that names the file and the line: containers nested
//! deeper than [`DEPTH_MAX`] (counted as they open, so a file of `[[[[…` is refused within
//! its first few hundred bytes, whatever its size: the scanner's own bound of 256 flow levels,
//! met first when it scans ahead, reads as ours), aliases and anchors that copy more than
//! [`EXPANSION_MAX`] nodes (a "billion laughs" file), includes nested deeper than [`INCLUDE_DEPTH_MAX`] or in a cycle,
//! a file larger than [`super::MAP_MAX`], more than [`FILES_MAX`] files or [`BYTES_MAX`]
//! bytes read in all.

mod load;
mod scalar;
mod tags;

use std::collections::HashMap;
use std::path::PathBuf;

use serde_yaml_ng::{Mapping, Value};

use super::{Draft, ImportError, MAP_MAX};

/// How deep containers may nest, over a file and the files it includes.
pub(super) const DEPTH_MAX: usize = 64;

/// How many nodes aliases may add to the tree (and anchors copy), over an import.
pub(super) const EXPANSION_MAX: usize = 200_000;

/// How deep includes may nest (`!include` in an included file, ...).
pub(super) const INCLUDE_DEPTH_MAX: usize = 16;

/// How many files an import may read beside the map (includes, `secrets.yaml`).
pub(super) const FILES_MAX: usize = 1024;

/// How many bytes an import may read beside the map.
pub(super) const BYTES_MAX: u64 = 4 * MAP_MAX;

/// The tags of Home Assistant's loader; one that could not be resolved is listed as not
/// mapped when it is read, and readers skip it.
const HA_TAGS: &[&str] = &[
    "include",
    "include_dir_list",
    "include_dir_named",
    "include_dir_merge_list",
    "include_dir_merge_named",
    "secret",
    "env_var",
    "input",
];

/// Parses `text`, the map itself, resolving includes and secrets from
/// [`super::ImportOptions::dir`] (none without it) in a Home Assistant map; a mistake names
/// its file, line and column.
pub(super) fn parse(text: &str, draft: &mut Draft) -> Result<Value, ImportError> {
    let top = draft.options.dir.as_ref().map(|dir| std::fs::canonicalize(dir).unwrap_or_else(|_| dir.clone()));
    // Home Assistant's tags are Home Assistant's: an evcc file's are left as written.
    let resolve = draft.format == super::Format::HaYaml;
    let mut loader =
        Loader { draft, top: top.clone(), stack: Vec::new(), expanded: 0, files: 0, bytes: 0, secrets: HashMap::new() };
    let doc = Doc { name: String::new(), dir: top, resolve };
    loader.document(text, &doc, 0, "").map(|(tree, _)| tree)
}

/// A tag of Home Assistant's loader left in the tree unresolved (already listed).
pub(super) fn unresolved(value: &Value) -> bool {
    matches!(value, Value::Tagged(tagged) if HA_TAGS.iter().any(|t| tagged.tag == *t))
}

/// What a file being read is.
struct Doc {
    /// Its name in messages: empty for the map (the origin names it), else its path from the
    /// map's directory.
    name: String,
    /// The directory its includes and secrets are found from, if any.
    dir: Option<PathBuf>,
    /// Whether its tags are resolved (not in a `secrets.yaml`).
    resolve: bool,
}

/// The state of one import's reading, over the map and every file it includes.
struct Loader<'d> {
    draft: &'d mut Draft,
    /// The map's directory (canonical): includes stay inside it, secrets are looked up to it.
    top: Option<PathBuf>,
    /// The files being included, outermost first (canonical), for cycles and depth.
    stack: Vec<PathBuf>,
    /// Nodes aliases added.
    expanded: usize,
    /// Files and bytes read beside the map.
    files: usize,
    bytes: u64,
    /// Each `secrets.yaml` read (canonical path), its map.
    secrets: HashMap<PathBuf, Mapping>,
}

/// What resolving a tag gives: the tree, or a hard error (`Ok(Err)`), or why it is left
/// unresolved (`Err`).
type Resolved = Result<Result<(Value, usize), ImportError>, String>;

/// A scalar as written, for a message (a tree is shown by its kind).
pub(super) fn shown(value: &Value) -> String {
    match value {
        Value::Null => "null".to_string(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => n.to_string(),
        Value::String(s) => s.clone(),
        Value::Sequence(items) => format!("a list of {}", items.len()),
        Value::Mapping(map) => format!("a map of {} keys", map.len()),
        Value::Tagged(tagged) => format!("{} {}", tagged.tag, shown(&tagged.value)),
    }
}

/// A key as text.
pub(super) fn key(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        other => shown(other),
    }
}

/// The text of a string, number or boolean.
pub(super) fn text(value: &Value) -> Option<String> {
    match value {
        Value::String(s) => Some(s.trim().to_string()),
        Value::Number(n) => Some(n.to_string()),
        Value::Bool(b) => Some(b.to_string()),
        _ => None,
    }
}

/// A non-negative integer: a YAML integer, or text of one (decimal or `0x` hex).
pub(super) fn unsigned(value: &Value) -> Option<u64> {
    match value {
        Value::Number(n) => n.as_u64(),
        Value::String(s) => crate::text::number(s, u64::MAX).ok(),
        _ => None,
    }
}

/// A finite number: a YAML number, or text of one.
pub(super) fn real(value: &Value) -> Option<f64> {
    let value = match value {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.trim().parse().ok(),
        _ => None,
    }?;
    value.is_finite().then_some(value)
}

/// A unit number (`slave`, `device_address`, evcc's `id`): 0-255.
pub(super) fn unit(value: &Value) -> Option<u8> {
    unsigned(value).and_then(|u| u8::try_from(u).ok())
}

/// The entries of `map` in the file's order, keys as text.
pub(super) fn entries(map: &Mapping) -> impl Iterator<Item = (String, &Value)> {
    map.iter().map(|(k, v)| (key(k), v))
}

/// The items of a list, or the one item a map is (YAML lets a list of one be written bare).
pub(super) fn items(value: &Value) -> Vec<&Value> {
    match value {
        Value::Sequence(items) => items.iter().collect(),
        Value::Null => Vec::new(),
        // An include that could not be read was listed when it was read.
        other if unresolved(other) => Vec::new(),
        other => vec![other],
    }
}

/// Lists every key of `map` that `known` does not name as not mapped, at `place`, for `why`.
pub(super) fn rest(map: &Mapping, known: &[&str], place: &str, why: &dyn Fn(&str) -> String, draft: &mut Draft) {
    for (k, v) in entries(map) {
        if !known.contains(&k.as_str()) {
            draft.unmapped(place, &k, &shown(v), &why(&k));
        }
    }
}
