//! Building the tree from the parser's events: containers on a stack, anchors and aliases,
//! merge keys, a key written twice, and the bounds on nesting and copies.

use std::collections::HashMap;

use serde_yaml_ng::value::{Tag, TaggedValue};
use serde_yaml_ng::{Mapping, Value};
use yaml_rust2::parser::{Event, Parser, Tag as YamlTag};
use yaml_rust2::scanner::{ScanError, TScalarStyle};

use super::scalar::{scalar, tagged};
use super::{DEPTH_MAX, Doc, EXPANSION_MAX, HA_TAGS, ImportError, Loader, key, shown, unresolved};

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
            (_, field) if here.is_empty() => crate::exchange::shown(&field),
            (_, field) => format!(".{}", crate::exchange::shown(&field)),
        }
    }
}

/// The place in the tree of the last of `frames`, below `base`.
fn place_of(base: &str, frames: &[Frame]) -> String {
    frames.iter().fold(base.to_string(), |place, frame| place + &frame.segment)
}

/// A place for a message: the tree's root is `top`.
pub(super) fn at(place: &str) -> &str {
    if place.is_empty() { "top" } else { place }
}

impl Loader<'_> {
    /// Reads `text` (the file `doc`), its containers nested `depth` deep already, its root
    /// at tree place `path`.
    pub(super) fn document(
        &mut self,
        text: &str,
        doc: &Doc,
        depth: usize,
        path: &str,
    ) -> Result<(Value, usize), ImportError> {
        let named = |message: String| {
            if doc.name.is_empty() { message } else { format!("{}: {message}", crate::exchange::shown(&doc.name)) }
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
            format!("{}: {message}", crate::exchange::shown(&doc.name))
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
            format!("not YAML: {} at line {} column {}", crate::exchange::bounded(e.info(), 200), m.line(), m.col() + 1)
        };
        self.draft.malformed(if doc.name.is_empty() {
            message
        } else {
            format!("{}: {message}", crate::exchange::shown(&doc.name))
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
                        // A secrets.yaml is not listed: its values are secrets.
                        other if unresolved(&other) || !doc.resolve => {}
                        other => {
                            let why = format!("line {key_line}: `<<` merges a map or a list of maps: left out");
                            self.draft.unmapped(at(&path()), "<<", &shown(&other), &why);
                        }
                    }
                } else if let Some(old) = own.insert(k.clone(), value).filter(|_| doc.resolve) {
                    let mut why = format!(
                        "the key is written again at line {key_line}: the last is kept, as Home Assistant keeps it"
                    );
                    if !doc.name.is_empty() {
                        why = format!("{}: {why}", crate::exchange::shown(&doc.name));
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
                let named = if doc.name.is_empty() {
                    why
                } else {
                    format!("{} (in {})", why, crate::exchange::shown(&doc.name))
                };
                self.draft.unmapped(at(place), &field, &format!("!{name} {arg}"), &named);
                Ok((left(arg), 1))
            }
        }
    }
}
