//! Home Assistant's tags: `!include FILE`, the four `!include_dir_*`, `!secret NAME`, and the
//! files they read, inside the map's directory and within the bounds on files and bytes.

use std::io::Read as _;
use std::path::{Path, PathBuf};

use serde_yaml_ng::{Mapping, Value};

use super::load::at;
use super::{
    BYTES_MAX, Doc, EXPANSION_MAX, FILES_MAX, INCLUDE_DEPTH_MAX, ImportError, Loader, MAP_MAX, Resolved, shown,
};

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
        let name = crate::exchange::shown(&self.rel(path));
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
                self.stack.iter().chain([&path.to_path_buf()]).map(|p| crate::exchange::shown(&self.rel(p))).collect();
            return Err(self.draft.malformed(format!("an include cycle: {}: refused", chain.join(" includes "))));
        }
        if self.stack.len() >= INCLUDE_DEPTH_MAX {
            let name = crate::exchange::shown(&self.rel(path));
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
    pub(super) fn include(&mut self, file: &str, doc: &Doc, depth: usize, child: &str) -> Resolved {
        let Some(dir) = &doc.dir else {
            return Err("the map was given without its directory: the file is not read".to_string());
        };
        let path = self.inside(&dir.join(file))?;
        Ok(self.file(&path, depth, child))
    }

    /// `!include_dir_list DIR` and the other three (`kind`): the `.yaml` files under `DIR`
    /// (but `secrets.yaml` and hidden ones), in the order of their paths.
    pub(super) fn include_dir(&mut self, kind: &str, name: &str, doc: &Doc, depth: usize, child: &str) -> Resolved {
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
                "include_dir_named" => {
                    self.file(path, depth + 1, &format!("{child}.{}", crate::exchange::shown(&stem)))
                }
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
    pub(super) fn secret(&mut self, name: &str, doc: &Doc) -> Resolved {
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
