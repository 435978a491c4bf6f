//! Embeds the SunSpec model definitions: the `model_<ID>.json` files of
//! `FERROBUS_SUNSPEC_MODELS` (a directory of them, or one file), else of the installed
//! pysunspec2 package (`sunspec2/models/json/`, found by asking `python3`, or `$PYTHON`).
//! Each file is checked with the crate's own reader (`src/def.rs`); a file that does not read
//! fails the build, naming it. With none found the build succeeds with a warning, and the
//! crate says so at run time; it is built again when Python's package directories change
//! (`pip install pysunspec2`).

#![allow(missing_docs, unreachable_pub, dead_code, clippy::pedantic)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "src/def.rs"]
mod def;

fn main() {
    println!("cargo:rerun-if-env-changed=FERROBUS_SUNSPEC_MODELS");
    println!("cargo:rerun-if-env-changed=PYTHON");
    println!("cargo:rerun-if-changed=src/def.rs");
    println!("cargo:rerun-if-changed=build.rs");
    let (files, from) = match std::env::var_os("FERROBUS_SUNSPEC_MODELS") {
        Some(path) => {
            let path = PathBuf::from(path);
            (model_files(&path), format!("FERROBUS_SUNSPEC_MODELS={}", path.display()))
        }
        None => match pysunspec2_models() {
            Some(dir) => (model_files(&dir), format!("pysunspec2 at {}", dir.display())),
            None => {
                // Built again once pysunspec2 is installed: `pip install` changes the
                // directories Python imports packages from.
                for dir in python_package_dirs() {
                    println!("cargo:rerun-if-changed={}", dir.display());
                }
                (Vec::new(), "nowhere".to_string())
            }
        },
    };
    let mut code = String::from("/// The embedded model files: (id, file name, text).\n");
    let _ = writeln!(code, "pub(crate) const EMBEDDED_FROM: &str = {from:?};");
    code.push_str("pub(crate) static EMBEDDED: &[(u16, &str, &str)] = &[\n");
    let mut ids = Vec::new();
    for file in &files {
        println!("cargo:rerun-if-changed={}", file.display());
        let text = match std::fs::read_to_string(file) {
            Ok(text) => text,
            Err(e) => panic!("SunSpec model file {}: {e}", file.display()),
        };
        let model = match def::ModelDef::parse(&text, &file.display().to_string()) {
            Ok(model) => model,
            Err(e) => panic!("{e}"),
        };
        if ids.contains(&model.id) {
            panic!("SunSpec model {} is defined twice (again in {})", model.id, file.display());
        }
        ids.push(model.id);
        let name = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let _ = writeln!(code, "    ({}, {name:?}, include_str!({:?})),", model.id, file.display().to_string());
    }
    code.push_str("];\n");
    if files.is_empty() {
        println!(
            "cargo:warning=no SunSpec model definitions found ({from}): pip install pysunspec2 (the next build \
             takes them), or set FERROBUS_SUNSPEC_MODELS=DIR; the crate builds without them"
        );
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR")).join("models.rs");
    std::fs::write(&out, code).expect("writing OUT_DIR/models.rs");
}

/// The `model_*.json` files of `path` (a directory), or `path` itself (a file), sorted.
fn model_files(path: &Path) -> Vec<PathBuf> {
    if path.is_file() {
        return vec![path.to_path_buf()];
    }
    println!("cargo:rerun-if-changed={}", path.display());
    let Ok(entries) = std::fs::read_dir(path) else {
        println!("cargo:warning=FERROBUS_SUNSPEC_MODELS: {} is neither a file nor a directory", path.display());
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("model_") && n.ends_with(".json"))
        })
        .collect();
    files.sort();
    files
}

/// What `python3` (or `$PYTHON`) prints running `code`, if it runs and succeeds.
fn python(code: &str) -> Option<String> {
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".to_string());
    let output = Command::new(python).args(["-c", code]).output().ok()?;
    if !output.status.success() {
        return None;
    }
    String::from_utf8(output.stdout).ok()
}

/// `sunspec2/models/json` of the pysunspec2 package `python3` imports, if any.
fn pysunspec2_models() -> Option<PathBuf> {
    let package = python("import sunspec2, os; print(os.path.dirname(sunspec2.__file__))")?;
    let dir = PathBuf::from(package.trim()).join("models").join("json");
    dir.is_dir().then_some(dir)
}

/// The directories `python3` imports installed packages from (site-packages, the user's
/// too) that exist: where `pip install pysunspec2` puts it.
fn python_package_dirs() -> Vec<PathBuf> {
    let code = "import site; print('\\n'.join(site.getsitepackages() + [site.getusersitepackages()]))";
    python(code).map_or_else(Vec::new, |text| text.lines().map(PathBuf::from).filter(|d| d.is_dir()).collect())
}
