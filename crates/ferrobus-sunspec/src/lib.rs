//! # ferrobus-sunspec: SunSpec devices, discovered and named
//!
//! SunSpec devices (solar inverters, meters, batteries) describe themselves in their holding
//! registers: "SunS" at 40000 (or 0, or 50000), then a chain of models, each an id, a length
//! and its points, ended by id 0xFFFF. This crate reads that chain over a
//! [`ferrobus::Client`] and turns the models it knows into a [`ferrobus_profile::Profile`] of
//! named points, which `get`, `poll` and `backup` read like any other device.
//!
//! ```text
//!   model_<ID>.json ──build.rs (FERROBUS_SUNSPEC_MODELS, or pysunspec2)──▶ Definitions::builtin()
//!   --sunspec-models PATH ──Definitions::load──▶ more (or replacing) definitions
//!   Client ──discover(client, unit, defs, limit)──▶ Discovery { base, models: [Found] }
//!   Discovery ──profile(discovery, defs, origin, limit)──▶ Profile (`inverter_three_phase.W`)
//! ```
//!
//! The model definitions are the SunSpec Alliance's published JSON model files, as the
//! pysunspec2 package ships them (`sunspec2/models/json/model_<ID>.json`, Apache-2.0); none
//! is in this repository. `build.rs` embeds the files of the directory (or the one file)
//! `FERROBUS_SUNSPEC_MODELS` names at build time, else those of the pysunspec2 that `python3`
//! imports. Built without either, the crate still builds, and [`Definitions::builtin`] is
//! empty ([`NONE_BUILT_IN`] says what to do).

mod def;
mod discover;
mod layout;
mod profile;

use std::collections::BTreeMap;
use std::path::Path;

pub use def::{Count, DefError, GroupDef, ModelDef, PointDef, PointType, ScaleFactor};
pub use discover::{BASES, DiscoverError, Discovery, END, Found, MARKER, discover};
pub use layout::{Layout, Placed, SfAt, layout};
pub use profile::{not_implemented, not_implemented_value, profile, profile_data};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/models.rs"));
}

/// What to do when no model definition is known.
pub const NONE_BUILT_IN: &str =
    "no SunSpec model definitions built in: pip install pysunspec2 and rebuild, or give --sunspec-models DIR";

/// The environment variable naming model files at build time, and more at run time.
pub const MODELS_ENV: &str = "FERROBUS_SUNSPEC_MODELS";

/// The model definitions known: the built-in ones, and those loaded at run time.
#[derive(Clone, Debug, Default)]
pub struct Definitions {
    models: BTreeMap<u16, ModelDef>,
}

/// Why model files given at run time could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    /// The path could not be read.
    #[error("SunSpec models {path}: {source}")]
    Read {
        /// The path.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A directory without `model_*.json` files.
    #[error("SunSpec models {path}: no model_*.json files there")]
    Empty {
        /// The directory.
        path: String,
    },
    /// A file that is not a usable model definition.
    #[error(transparent)]
    Def(#[from] DefError),
}

impl Definitions {
    /// The definitions embedded at build time (none if the build found none).
    pub fn builtin() -> Definitions {
        let mut models = BTreeMap::new();
        for (id, name, text) in embedded::EMBEDDED {
            // build.rs checked each with the same reader; a failure here cannot happen.
            match ModelDef::parse(text, name) {
                Ok(model) => {
                    models.insert(*id, model);
                }
                Err(e) => tracing::warn!(%e, "embedded SunSpec model skipped"),
            }
        }
        Definitions { models }
    }

    /// Where the built-in definitions came from at build time.
    pub fn built_from() -> &'static str {
        embedded::EMBEDDED_FROM
    }

    /// The built-in definitions and those of `path` (or else of [`MODELS_ENV`] at run time,
    /// if set); an error when the result is empty, saying what to do.
    pub fn with(path: Option<&Path>) -> Result<Definitions, String> {
        let mut defs = Definitions::builtin();
        let env = std::env::var_os(MODELS_ENV);
        if let Some(path) = path.or(env.as_deref().map(Path::new)) {
            defs.load(path).map_err(|e| e.to_string())?;
        }
        if defs.is_empty() {
            return Err(NONE_BUILT_IN.to_string());
        }
        Ok(defs)
    }

    /// Adds the definitions of `path` (a directory of `model_*.json`, or one file), replacing
    /// those of the same id; how many were read.
    pub fn load(&mut self, path: &Path) -> Result<usize, LoadError> {
        let shown = path.display().to_string();
        let read = |p: &Path| {
            std::fs::read_to_string(p).map_err(|source| LoadError::Read { path: p.display().to_string(), source })
        };
        let files = if path.is_dir() {
            let mut files: Vec<_> = std::fs::read_dir(path)
                .map_err(|source| LoadError::Read { path: shown.clone(), source })?
                .filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with("model_") && n.to_ascii_lowercase().ends_with(".json"))
                })
                .collect();
            files.sort();
            if files.is_empty() {
                return Err(LoadError::Empty { path: shown });
            }
            files
        } else {
            vec![path.to_path_buf()]
        };
        for file in &files {
            let model = ModelDef::parse(&read(file)?, &file.display().to_string())?;
            self.models.insert(model.id, model);
        }
        Ok(files.len())
    }

    /// Adds one definition, replacing that of the same id.
    pub fn insert(&mut self, model: ModelDef) {
        self.models.insert(model.id, model);
    }

    /// The definition of model `id`.
    pub fn get(&self, id: u16) -> Option<&ModelDef> {
        self.models.get(&id)
    }

    /// How many are known.
    pub fn len(&self) -> usize {
        self.models.len()
    }

    /// Whether none is known.
    pub fn is_empty(&self) -> bool {
        self.models.is_empty()
    }
}

#[cfg(test)]
mod tests;
