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

use std::collections::HashMap;
use std::io::Read as _;
use std::path::{Path, PathBuf};

use serde_yaml_ng::value::{Tag, TaggedValue};
use serde_yaml_ng::{Mapping, Value};
use yaml_rust2::parser::{Event, Parser, Tag as YamlTag};
use yaml_rust2::scanner::{ScanError, TScalarStyle};

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

/// A container being built.
struct Frame {
    kind: Kind,
    /// Its anchor (0: none).
    anchor: usize,
    tag: Option<YamlTag>,
    /// What its place in the tree adds to its parent's (`.sensors`, `[0]`): the place
    /// (`modbus[0].sensors`) is made from these only for what is listed.
    segment: String,
    /// Nodes in it, itself included.
    nodes: usize,
}

enum Kind {
    Seq(Vec<Value>),
    Map {
        own: Mapping,
        /// The key read, waiting for its value: the key, whether it is `<<`, its line.
        key: Option<(Value, bool, usize)>,
        /// What `<<` keys merge, in the order of precedence from lowest.
        merged: Vec<Mapping>,
    },
}

impl Frame {
    /// The node built: its value (merges applied, the map's own keys last), nodes, anchor.
    fn close(self) -> (Value, usize, usize) {
        let value = match self.kind {
            Kind::Seq(items) => Value::Sequence(items),
            Kind::Map { own, merged, .. } => {
                let mut map = Mapping::new();
                for (k, v) in merged.into_iter().flatten().chain(own) {
                    map.insert(k, v);
                }
                Value::Mapping(map)
            }
        };
        (tagged(value, self.tag.as_ref()), self.nodes, self.anchor)
    }

    /// The place and the field of the node that comes next in it, the frame's place being
    /// `here`.
    fn next(&self, here: &str) -> (String, String) {
        match &self.kind {
            Kind::Seq(items) => (format!("{here}[{}]", items.len()), String::new()),
            Kind::Map { key: Some((key_value, _, _)), .. } => (here.to_string(), key(key_value)),
            Kind::Map { .. } => (here.to_string(), "key".to_string()),
        }
    }

    /// What the place of a node that comes next in it adds to `here`, the frame's place.
    fn child(&self, here: &str) -> String {
        match (&self.kind, self.next(here).1) {
            (Kind::Seq(items), _) => format!("[{}]", items.len()),
            (_, field) if here.is_empty() => super::shown(&field),
            (_, field) => format!(".{}", super::shown(&field)),
        }
    }
}

/// The place in the tree of the last of `frames`, below `base`.
fn place_of(base: &str, frames: &[Frame]) -> String {
    frames.iter().fold(base.to_string(), |place, frame| place + &frame.segment)
}

/// A place for a message: the tree's root is `top`.
fn at(place: &str) -> &str {
    if place.is_empty() { "top" } else { place }
}

impl Loader<'_> {
    /// Reads `text` (the file `doc`), its containers nested `depth` deep already, its root
    /// at tree place `path`.
    fn document(&mut self, text: &str, doc: &Doc, depth: usize, path: &str) -> Result<(Value, usize), ImportError> {
        let named = |message: String| {
            if doc.name.is_empty() { message } else { format!("{}: {message}", super::shown(&doc.name)) }
        };
        let mut parser = Parser::new_from_str(text);
        let mut stack: Vec<Frame> = Vec::new();
        let mut anchors: HashMap<usize, (Value, usize)> = HashMap::new();
        let mut root: Option<(Value, usize)> = None;
        let mut documents = 0;
        loop {
            let (event, mark) = parser.next_token().map_err(|e| self.scan_error(&e, doc))?;
            let line = mark.line();
            let seq = matches!(event, Event::SequenceStart(..));
            // A node read whole: its value, nodes and anchor.
            let done: (Value, usize, usize, bool) = match event {
                Event::StreamStart | Event::Nothing | Event::DocumentEnd => continue,
                Event::StreamEnd => break,
                Event::DocumentStart => {
                    documents += 1;
                    if documents > 1 {
                        return Err(self.draft.malformed(named(format!(
                            "a second YAML document at line {line}: a map is one document"
                        ))));
                    }
                    continue;
                }
                Event::SequenceStart(anchor, tag) | Event::MappingStart(anchor, tag) => {
                    if depth + stack.len() >= DEPTH_MAX {
                        return Err(self
                            .draft
                            .malformed(named(format!("nested deeper than {DEPTH_MAX} at line {line}: refused"))));
                    }
                    // The root's place is `path`; a child's adds to its parent's.
                    let segment = match stack.last() {
                        None => String::new(),
                        Some(parent) => parent.child(if stack.len() == 1 && path.is_empty() { "" } else { "." }),
                    };
                    let kind = if seq {
                        Kind::Seq(Vec::new())
                    } else {
                        Kind::Map { own: Mapping::new(), key: None, merged: Vec::new() }
                    };
                    stack.push(Frame { kind, anchor, tag, segment, nodes: 1 });
                    continue;
                }
                Event::SequenceEnd | Event::MappingEnd => {
                    let Some(frame) = stack.pop() else { continue };
                    let (value, nodes, anchor) = frame.close();
                    (value, nodes, anchor, false)
                }
                Event::Alias(id) => {
                    let Some((value, nodes)) = anchors.get(&id) else {
                        return Err(self
                            .draft
                            .malformed(named(format!("an alias at line {line} to a node that holds it: refused"))));
                    };
                    let (value, nodes) = (value.clone(), *nodes);
                    self.copied(nodes, line, doc)?;
                    (value, nodes, 0, false)
                }
                Event::Scalar(text, style, anchor, tag) => {
                    let is_key = matches!(stack.last(), Some(Frame { kind: Kind::Map { key: None, .. }, .. }));
                    let ha_tag = tag.as_ref().is_some_and(|t| t.handle == "!" && HA_TAGS.contains(&t.suffix.as_str()));
                    if is_key || !ha_tag {
                        // A key is never a file's or a secret's; a plain `<<` (or `!!merge <<`) merges.
                        let merge_tag =
                            tag.as_ref().is_none_or(|t| t.handle == "tag:yaml.org,2002:" && t.suffix == "merge");
                        let merge = is_key && style == TScalarStyle::Plain && merge_tag && text == "<<";
                        (scalar(text, style, tag.as_ref()), 1, anchor, merge)
                    } else {
                        // Its place, made only for a tag of Home Assistant's.
                        let here = place_of(path, &stack);
                        let (place, field) =
                            stack.last().map_or_else(|| (here.clone(), String::new()), |f| f.next(&here));
                        let child = stack.last().map_or_else(|| here.clone(), |f| here.clone() + &f.child(&here));
                        let (value, nodes) = self.tagged_scalar(
                            text,
                            style,
                            tag.as_ref(),
                            doc,
                            depth + stack.len(),
                            &place,
                            &field,
                            &child,
                        )?;
                        (value, nodes, anchor, false)
                    }
                }
            };
            let (value, nodes, anchor, merge) = done;
            if anchor != 0 {
                // An anchor's copy counts: anchors nested in anchors would copy the file
                // once per level.
                if nodes > 1 {
                    self.copied(nodes, line, doc)?;
                }
                anchors.insert(anchor, (value.clone(), nodes));
            }
            let Some(mut frame) = stack.pop() else {
                root = Some((value, nodes));
                continue;
            };
            self.put(&mut frame, (&stack, path), (value, nodes, merge), line, doc);
            stack.push(frame);
        }
        Ok(root.unwrap_or((Value::Null, 1)))
    }

    /// Counts `nodes` copied by an alias or an anchor at `line`, refused past [`EXPANSION_MAX`].
    fn copied(&mut self, nodes: usize, line: usize, doc: &Doc) -> Result<(), ImportError> {
        self.expanded = self.expanded.saturating_add(nodes);
        if self.expanded <= EXPANSION_MAX {
            return Ok(());
        }
        let message = format!("aliases expand to more than {EXPANSION_MAX} nodes (at line {line}): refused");
        Err(self.draft.malformed(if doc.name.is_empty() {
            message
        } else {
            format!("{}: {message}", super::shown(&doc.name))
        }))
    }

    /// The error for a text the YAML scanner refuses, with its line and column.
    fn scan_error(&self, e: &ScanError, doc: &Doc) -> ImportError {
        let m = e.marker();
        // The scanner's own bound on flow nesting (deeper than ours, met first when it scans
        // ahead of the events).
        let message = if e.info() == "recursion limit exceeded" {
            format!("nested deeper than {DEPTH_MAX} at line {}: refused", m.line())
        } else {
            format!("not YAML: {} at line {} column {}", super::bounded(e.info(), 200), m.line(), m.col() + 1)
        };
        self.draft.malformed(if doc.name.is_empty() {
            message
        } else {
            format!("{}: {message}", super::shown(&doc.name))
        })
    }

    /// Puts the node `value` of `nodes` nodes (`merge`: a `<<` key), read at `line`, in `frame`: an item, a key, a
    /// key's value, or what a `<<` merges.
    fn put(
        &mut self,
        frame: &mut Frame,
        (parents, base): (&[Frame], &str),
        (value, nodes, merge): (Value, usize, bool),
        line: usize,
        doc: &Doc,
    ) {
        let Frame { kind, segment, nodes: count, .. } = frame;
        *count = count.saturating_add(nodes);
        // The frame's place, made only for what is listed.
        let path = || place_of(base, parents) + segment;
        match kind {
            Kind::Seq(items) => items.push(value),
            Kind::Map { key: pending @ None, .. } => *pending = Some((value, merge, line)),
            Kind::Map { own, key: pending, merged } => {
                let Some((k, merge, key_line)) = pending.take() else { return };
                if merge {
                    match value {
                        Value::Mapping(map) => merged.push(map),
                        Value::Sequence(items) if items.iter().all(Value::is_mapping) => {
                            merged.extend(items.into_iter().rev().filter_map(|v| match v {
                                Value::Mapping(m) => Some(m),
                                _ => None,
                            }));
                        }
                        other if unresolved(&other) => {}
                        other => {
                            let why = format!("line {key_line}: `<<` merges a map or a list of maps: left out");
                            self.draft.unmapped(at(&path()), "<<", &shown(&other), &why);
                        }
                    }
                } else if let Some(old) = own.insert(k.clone(), value) {
                    let mut why = format!(
                        "the key is written again at line {key_line}: the last is kept, as Home Assistant keeps it"
                    );
                    if !doc.name.is_empty() {
                        why = format!("{}: {why}", super::shown(&doc.name));
                    }
                    self.draft.unmapped(at(&path()), &key(&k), &shown(&old), &why);
                }
            }
        }
    }

    /// A scalar that is a value, its tag resolved: the value and its nodes. `place` and
    /// `field` say where it is for a listing, `child` is the tree place of what it includes,
    /// `depth` how deep it is.
    #[allow(clippy::too_many_arguments)] // the scalar's four parts and its three places
    fn tagged_scalar(
        &mut self,
        text: String,
        style: TScalarStyle,
        tag: Option<&YamlTag>,
        doc: &Doc,
        depth: usize,
        place: &str,
        field: &str,
        child: &str,
    ) -> Result<(Value, usize), ImportError> {
        let Some(name) = tag.filter(|t| t.handle == "!").map(|t| t.suffix.clone()) else {
            return Ok((scalar(text, style, tag), 1));
        };
        if !HA_TAGS.contains(&name.as_str()) {
            return Ok((scalar(text, style, tag), 1));
        }
        let arg = text.trim().to_string();
        let left = |value: String| {
            Value::Tagged(Box::new(TaggedValue { tag: Tag::new(name.clone()), value: Value::String(value) }))
        };
        if !doc.resolve {
            return Ok((left(arg), 1));
        }
        let outcome = match name.as_str() {
            "secret" => self.secret(&arg, doc),
            "env_var" | "input" => Err(format!(
                "Home Assistant's {} of its own host: not read",
                if name == "input" { "blueprint input" } else { "environment variable" }
            )),
            "include" => self.include(&arg, doc, depth, child),
            _ => self.include_dir(&name, &arg, doc, depth, child),
        };
        match outcome {
            Ok(Ok(found)) => {
                if name == "secret" {
                    if let Value::String(text) = &found.0 {
                        self.draft.secret_texts.insert(text.clone(), format!("!secret {arg}"));
                    }
                    let field = if field.is_empty() { "!secret" } else { field };
                    // A bare hub's readers call the root `hub`.
                    for place in if place.is_empty() { vec!["top", "hub"] } else { vec![place] } {
                        self.draft.secret_at.insert((place.to_string(), field.to_string()), format!("!secret {arg}"));
                    }
                }
                Ok(found)
            }
            Ok(Err(error)) => Err(error),
            Err(why) => {
                let field = if field.is_empty() { format!("!{name}") } else { field.to_string() };
                let named = if doc.name.is_empty() { why } else { format!("{} (in {})", why, super::shown(&doc.name)) };
                self.draft.unmapped(at(place), &field, &format!("!{name} {arg}"), &named);
                Ok((left(arg), 1))
            }
        }
    }
}

/// What resolving a tag gives: the tree, or a hard error (`Ok(Err)`), or why it is left
/// unresolved (`Err`).
type Resolved = Result<Result<(Value, usize), ImportError>, String>;

impl Loader<'_> {
    /// The place of `path` for a message: from the map's directory when inside it.
    fn rel(&self, path: &Path) -> String {
        let shown = self.top.as_ref().and_then(|top| path.strip_prefix(top).ok()).unwrap_or(path);
        shown.display().to_string()
    }

    /// `path` made canonical, if it is inside the map's directory.
    fn inside(&self, path: &Path) -> Result<PathBuf, String> {
        let Some(top) = &self.top else {
            return Err("the map was given without its directory: not read".to_string());
        };
        let real = std::fs::canonicalize(path).map_err(|e| format!("cannot read it: {e}"))?;
        if real.starts_with(top) {
            Ok(real)
        } else {
            Err(format!("outside the map's directory {}: not read", top.display()))
        }
    }

    /// The text of the file `path` (canonical), counted against the bounds.
    fn read(&mut self, path: &Path) -> Result<String, ImportError> {
        let name = super::shown(&self.rel(path));
        self.files += 1;
        if self.files > FILES_MAX {
            return Err(self.draft.malformed(format!("{name}: more than {FILES_MAX} files included: refused")));
        }
        let mut bytes = Vec::new();
        let read = std::fs::File::open(path).and_then(|f| f.take(MAP_MAX + 1).read_to_end(&mut bytes));
        if let Err(e) = read {
            return Err(self.draft.malformed(format!("{name}: cannot read it: {e}")));
        }
        let len = bytes.len() as u64;
        if len > MAP_MAX {
            return Err(self
                .draft
                .malformed(format!("{name}: larger than the {} MiB a map file may be: refused", MAP_MAX >> 20)));
        }
        self.bytes = self.bytes.saturating_add(len);
        if self.bytes > BYTES_MAX {
            return Err(self
                .draft
                .malformed(format!("{name}: the files included hold more than {} MiB: refused", BYTES_MAX >> 20)));
        }
        String::from_utf8(bytes).map_err(|e| {
            let at = e.utf8_error().valid_up_to();
            self.draft.malformed(format!("{name}: not UTF-8 text (byte {at})"))
        })
    }

    /// The tree of the file `path` (canonical), read at `depth` and tree place `child`.
    fn file(&mut self, path: &Path, depth: usize, child: &str) -> Result<(Value, usize), ImportError> {
        if self.stack.iter().any(|p| p == path) {
            let chain: Vec<String> =
                self.stack.iter().chain([&path.to_path_buf()]).map(|p| super::shown(&self.rel(p))).collect();
            return Err(self.draft.malformed(format!("an include cycle: {}: refused", chain.join(" includes "))));
        }
        if self.stack.len() >= INCLUDE_DEPTH_MAX {
            let name = super::shown(&self.rel(path));
            return Err(self
                .draft
                .malformed(format!("{name}: includes nested deeper than {INCLUDE_DEPTH_MAX}: refused")));
        }
        let text = self.read(path)?;
        let doc = Doc { name: self.rel(path), dir: path.parent().map(Path::to_path_buf), resolve: true };
        self.stack.push(path.to_path_buf());
        let tree = self.document(&text, &doc, depth, child);
        self.stack.pop();
        tree
    }

    /// `!include FILE`.
    fn include(&mut self, file: &str, doc: &Doc, depth: usize, child: &str) -> Resolved {
        let Some(dir) = &doc.dir else {
            return Err("the map was given without its directory: the file is not read".to_string());
        };
        let path = self.inside(&dir.join(file))?;
        Ok(self.file(&path, depth, child))
    }

    /// `!include_dir_list DIR` and the other three (`kind`): the `.yaml` files under `DIR`
    /// (but `secrets.yaml` and hidden ones), in the order of their paths.
    fn include_dir(&mut self, kind: &str, name: &str, doc: &Doc, depth: usize, child: &str) -> Resolved {
        let Some(dir) = &doc.dir else {
            return Err("the map was given without its directory: the files are not read".to_string());
        };
        let root = self.inside(&dir.join(name))?;
        let mut files = Vec::new();
        let mut dirs = vec![root];
        while let Some(dir) = dirs.pop() {
            let list = std::fs::read_dir(&dir).map_err(|e| format!("cannot read {}: {e}", self.rel(&dir)))?;
            for entry in list.flatten() {
                let file_name = entry.file_name().to_string_lossy().into_owned();
                let Ok(kind) = entry.file_type() else { continue };
                if file_name.starts_with('.') {
                    continue;
                }
                if kind.is_dir() {
                    dirs.push(entry.path());
                } else if has_yaml_extension(&file_name) && file_name != "secrets.yaml" {
                    files.push(self.inside(&entry.path())?);
                }
                if files.len() + dirs.len() > FILES_MAX {
                    return Err(format!("more than {FILES_MAX} files: not read"));
                }
            }
        }
        files.sort();
        let (mut list, mut map, mut nodes) = (Vec::new(), Mapping::new(), 1usize);
        for (i, path) in files.iter().enumerate() {
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let value = match kind {
                "include_dir_list" => self.file(path, depth + 1, &format!("{child}[{i}]")),
                "include_dir_named" => self.file(path, depth + 1, &format!("{child}.{}", super::shown(&stem))),
                _ => self.file(path, depth, child),
            };
            let (value, n) = match value {
                Ok(found) => found,
                Err(e) => return Ok(Err(e)),
            };
            nodes = nodes.saturating_add(n);
            match (kind, value) {
                ("include_dir_list", value) => list.push(value),
                ("include_dir_named", value) => {
                    map.insert(Value::String(stem), value);
                }
                ("include_dir_merge_list", Value::Sequence(items)) => list.extend(items),
                ("include_dir_merge_named", Value::Mapping(more)) => map.extend(more),
                (_, other) => {
                    let why = format!(
                        "!{kind} takes a {} from each file: left out",
                        if kind.ends_with("list") { "list" } else { "map" }
                    );
                    self.draft.unmapped(at(child), &self.rel(path), &shown(&other), &why);
                }
            }
        }
        let tree = if kind.ends_with("list") { Value::Sequence(list) } else { Value::Mapping(map) };
        Ok(Ok((tree, nodes)))
    }

    /// `!secret NAME`: from the `secrets.yaml` of the including file's directory, or of its
    /// parents up to the map's directory.
    fn secret(&mut self, name: &str, doc: &Doc) -> Resolved {
        let (Some(dir), Some(top)) = (doc.dir.clone(), self.top.clone()) else {
            return Err(
                "the map was given without its directory: no secrets.yaml to look it up in, the value is unknown"
                    .to_string(),
            );
        };
        let mut looked = Vec::new();
        let mut here = Some(dir.as_path());
        while let Some(d) = here {
            let file = d.join("secrets.yaml");
            if file.is_file() {
                if !self.secrets.contains_key(&file) {
                    let text = match self.read(&file) {
                        Ok(text) => text,
                        Err(e) => return Ok(Err(e)),
                    };
                    let doc = Doc { name: self.rel(&file), dir: None, resolve: false };
                    let tree = match self.document(&text, &doc, 0, "") {
                        Ok((tree, _)) => tree,
                        Err(e) => return Ok(Err(e)),
                    };
                    let map = match tree {
                        Value::Mapping(map) => map,
                        _ => Mapping::new(),
                    };
                    self.secrets.insert(file.clone(), map);
                }
                if let Some(value) = self.secrets.get(&file).and_then(|m| m.get(name)).cloned() {
                    let nodes = count(&value);
                    self.expanded = self.expanded.saturating_add(nodes);
                    if self.expanded > EXPANSION_MAX {
                        let why = format!("secrets and aliases expand to more than {EXPANSION_MAX} nodes: refused");
                        return Ok(Err(self.draft.malformed(why)));
                    }
                    return Ok(Ok((value, nodes)));
                }
                looked.push(self.rel(&file));
            }
            if d == top || !d.starts_with(&top) {
                break;
            }
            here = d.parent();
        }
        Err(if looked.is_empty() {
            "no secrets.yaml in the file's directory or its parents up to the map's: the value is unknown".to_string()
        } else {
            format!("no secret of this name in {}: the value is unknown", looked.join(", "))
        })
    }
}

/// Whether a file's name ends in `.yaml`, as Home Assistant's `*.yaml` matches it (in that
/// case only).
#[allow(clippy::case_sensitive_file_extension_comparisons)] // Home Assistant's own comparison
fn has_yaml_extension(name: &str) -> bool {
    name.ends_with(".yaml")
}

/// The nodes of `value`.
fn count(value: &Value) -> usize {
    match value {
        Value::Sequence(items) => items.iter().map(count).fold(1, usize::saturating_add),
        Value::Mapping(map) => {
            map.iter().map(|(k, v)| count(k).saturating_add(count(v))).fold(1, usize::saturating_add)
        }
        Value::Tagged(tagged) => count(&tagged.value),
        _ => 1,
    }
}

/// `value` with the tag a container was written with (none for the standard `!!` ones).
fn tagged(value: Value, tag: Option<&YamlTag>) -> Value {
    match tag {
        Some(tag) if tag.handle != "tag:yaml.org,2002:" => match tag_of(tag) {
            Some(tag) => Value::Tagged(Box::new(TaggedValue { tag, value })),
            None => value,
        },
        _ => value,
    }
}

/// serde_yaml_ng's tag for a tag as written (none for the empty `!`).
fn tag_of(tag: &YamlTag) -> Option<Tag> {
    let text = if tag.handle == "!" { format!("!{}", tag.suffix) } else { format!("{}{}", tag.handle, tag.suffix) };
    (!text.is_empty() && text != "!").then(|| Tag::new(text))
}

/// A scalar: text if quoted, a block or `!!str`, else resolved as a plain scalar; a tag of
/// the file's own kept.
fn scalar(text: String, style: TScalarStyle, tag: Option<&YamlTag>) -> Value {
    match tag {
        Some(tag) if tag.handle == "tag:yaml.org,2002:" => match tag.suffix.as_str() {
            "str" | "binary" | "timestamp" => Value::String(text),
            _ => plain(text),
        },
        Some(tag) => match tag_of(tag) {
            Some(t) => Value::Tagged(Box::new(TaggedValue { tag: t, value: scalar(text, style, None) })),
            None => Value::String(text),
        },
        None if style == TScalarStyle::Plain => plain(text),
        None => Value::String(text),
    }
}

/// A plain scalar as serde_yaml_ng resolves it: null, a boolean, an integer (decimal, `0x`,
/// `0o`, `0b`), a finite float or `.inf`/`.nan`, else text.
fn plain(text: String) -> Value {
    match text.as_str() {
        "" | "~" | "null" | "Null" | "NULL" => return Value::Null,
        "true" | "True" | "TRUE" => return Value::Bool(true),
        "false" | "False" | "FALSE" => return Value::Bool(false),
        _ => {}
    }
    if let Some(n) = unsigned_int(&text) {
        return Value::Number(n.into());
    }
    if let Some(n) = negative_int(&text) {
        return Value::Number(n.into());
    }
    if !leading_zero(&text) {
        if let Some(f) = float(&text) {
            return Value::Number(f.into());
        }
    }
    Value::String(text)
}

/// Digits after a leading zero (`0123`): text in YAML 1.2, as serde_yaml_ng reads it.
fn leading_zero(text: &str) -> bool {
    let digits = text.strip_prefix(['-', '+']).unwrap_or(text);
    digits.len() > 1 && digits.starts_with('0') && digits.bytes().all(|b| b.is_ascii_digit())
}

/// A non-negative integer: `+`, then `0x`, `0o`, `0b` or decimal digits.
fn unsigned_int(text: &str) -> Option<u64> {
    let digits = text.strip_prefix('+').unwrap_or(text);
    for (prefix, radix) in [("0x", 16), ("0o", 8), ("0b", 2)] {
        if let Some(rest) = digits.strip_prefix(prefix) {
            if rest.starts_with(['+', '-']) {
                return None;
            }
            if let Ok(n) = u64::from_str_radix(rest, radix) {
                return Some(n);
            }
        }
    }
    if digits.starts_with(['+', '-']) || leading_zero(text) {
        return None;
    }
    digits.parse().ok()
}

/// A negative integer: `-`, then `0x`, `0o`, `0b` or decimal digits.
fn negative_int(text: &str) -> Option<i64> {
    let rest = text.strip_prefix('-')?;
    for (prefix, radix) in [("0x", 16), ("0o", 8), ("0b", 2)] {
        if let Some(digits) = rest.strip_prefix(prefix) {
            if let Ok(n) = i64::from_str_radix(&format!("-{digits}"), radix) {
                return Some(n);
            }
        }
    }
    if leading_zero(text) {
        return None;
    }
    text.parse().ok()
}

/// A float: `.inf`, `-.inf`, `.nan` (in their cases), or a finite number.
fn float(text: &str) -> Option<f64> {
    let unsigned = match text.strip_prefix('+') {
        Some(rest) if rest.starts_with(['+', '-']) => return None,
        Some(rest) => rest,
        None => text,
    };
    match (unsigned, text) {
        (".inf" | ".Inf" | ".INF", _) => return Some(f64::INFINITY),
        (_, "-.inf" | "-.Inf" | "-.INF") => return Some(f64::NEG_INFINITY),
        (_, ".nan" | ".NaN" | ".NAN") => return Some(f64::NAN),
        _ => {}
    }
    unsigned.parse::<f64>().ok().filter(|f| f.is_finite())
}

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
        Value::String(s) => {
            let s = s.trim();
            match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
                Some(hex) => u64::from_str_radix(hex, 16).ok(),
                None => s.parse().ok(),
            }
        }
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
