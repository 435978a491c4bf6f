//! A backup written to `FILE` so that a good backup is never lost (`ferrobus backup -o FILE`).
//!
//! The new backup goes to a temporary file beside `FILE` (same directory, so the rename is
//! atomic), synced to disk, then renamed over `FILE`; a crash or a full disk leaves `FILE` as
//! it was. The previous `FILE` is kept as `FILE.bak`. One rule protects a good backup from a
//! bad read: a new backup with more unread parameters than the `FILE` it would replace (a
//! complete one first of all) does not replace it unless forced; it is written to
//! `FILE.incomplete` instead, so that neither is lost.

use std::ffi::OsString;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use super::file::{Backup, State};

/// Why a backup could not be saved; nothing is half-written then.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SaveError {
    /// The path names no file (a directory, `..`).
    #[error("{path}: name a file, not a directory")]
    NotAFile {
        /// The path given.
        path: PathBuf,
    },
    /// A file could not be read or written.
    #[error("{what}: {source}")]
    Io {
        /// The file, and what was being done with it.
        what: String,
        /// Why.
        source: std::io::Error,
    },
}

/// What became of the new backup.
#[derive(Clone, PartialEq, Eq, Debug)]
pub enum Saved {
    /// It is `FILE` now; the previous `FILE`, if there was one, is in `previous`.
    Replaced {
        /// `FILE.bak`, when `FILE` existed.
        previous: Option<PathBuf>,
    },
    /// `FILE` held a better backup and was kept; the new one is in `new`.
    KeptPrevious {
        /// `FILE.incomplete`.
        new: PathBuf,
        /// The parameters `FILE` holds, and how many of them it could not read.
        previous: Completeness,
    },
}

/// How complete a backup is: its parameters and how many of them hold no value.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Completeness {
    /// Parameters recorded.
    pub parameters: usize,
    /// Of them, not read.
    pub unread: usize,
}

impl Completeness {
    /// Of a backup.
    pub fn of(backup: &Backup) -> Completeness {
        let unread = backup.entries.iter().filter(|e| matches!(e.state, State::Failed(_))).count();
        Completeness { parameters: backup.entries.len(), unread }
    }

    /// Parameters with a value.
    pub fn read(self) -> usize {
        self.parameters.saturating_sub(self.unread)
    }
}

/// What `FILE` holds before the new backup is written.
enum Previous {
    /// Nothing: there is no such file.
    Nothing,
    /// A file that is not a backup.
    Other,
    /// A backup, this complete.
    Backup(Completeness),
}

/// Writes `backup` to `path` by the rules of the module doc; `force` lets an incomplete
/// backup replace a better one.
pub fn save(path: &Path, backup: &Backup, force: bool) -> Result<Saved, SaveError> {
    let new = Completeness::of(backup);
    let text = backup.render();
    let previous = match previous(path)? {
        Previous::Backup(old) if new.unread > old.unread && !force => {
            let aside = sibling(path, ".incomplete")?;
            write_atomically(&aside, text.as_bytes())?;
            return Ok(Saved::KeptPrevious { new: aside, previous: old });
        }
        Previous::Nothing => None,
        Previous::Other | Previous::Backup(_) => {
            let bak = sibling(path, ".bak")?;
            let old = std::fs::read(path).map_err(|source| output_error(path, source))?;
            write_atomically(&bak, &old)?;
            Some(bak)
        }
    };
    write_atomically(path, text.as_bytes())?;
    Ok(Saved::Replaced { previous })
}

/// What `path` holds now.
fn previous(path: &Path) -> Result<Previous, SaveError> {
    match std::fs::read_to_string(path) {
        Ok(text) => Ok(match Backup::parse(&text, &path.display().to_string()) {
            Ok(backup) => Previous::Backup(Completeness::of(&backup)),
            Err(_) => Previous::Other,
        }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Previous::Nothing),
        // Not text: not a backup, but kept as FILE.bak all the same.
        Err(e) if e.kind() == std::io::ErrorKind::InvalidData => Ok(Previous::Other),
        Err(source) => Err(SaveError::Io {
            what: format!("{} (it exists but cannot be read, so it cannot be kept as .bak)", path.display()),
            source,
        }),
    }
}

/// `path` with `suffix` after its file name: `drive.toml.bak`.
pub fn sibling(path: &Path, suffix: &str) -> Result<PathBuf, SaveError> {
    let Some(name) = path.file_name() else { return Err(SaveError::NotAFile { path: path.to_path_buf() }) };
    let mut name = OsString::from(name);
    name.push(suffix);
    Ok(path.with_file_name(name))
}

/// Writes `bytes` to a temporary file beside `path`, syncs it and renames it to `path`: a
/// reader sees the old file or the new one, never a part.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), SaveError> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let temporary = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let written = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&temporary)
        .and_then(|mut file| file.write_all(bytes).and_then(|()| file.sync_all()))
        .and_then(|()| std::fs::rename(&temporary, path));
    written.map_err(|source| {
        let _ = std::fs::remove_file(&temporary);
        output_error(path, source)
    })
}

fn output_error(path: &Path, source: std::io::Error) -> SaveError {
    SaveError::Io { what: path.display().to_string(), source }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backup::file::{Entry, Header};
    use std::path::PathBuf;

    fn backup(unread: usize, of: usize) -> Backup {
        let entries = (0..of)
            .map(|i| Entry {
                code: format!("P{i:03}"),
                label: String::new(),
                line: 0,
                state: if i < unread {
                    State::Failed("no reply".into())
                } else {
                    State::Value { raw: toml::Value::Integer(i64::try_from(i).unwrap()), shown: i.to_string() }
                },
            })
            .collect();
        let header = Header {
            profile: "generic".into(),
            profile_hash: None,
            device: "t".into(),
            time: "2026-12-03T12:00:00Z".into(),
            unit: 1,
            connection: "test".into(),
            identification: "none".into(),
        };
        Backup { header, identification: Vec::new(), entries }
    }

    fn dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("ferrobus-save-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn leftovers(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        names.sort();
        names
    }

    #[test]
    fn an_incomplete_backup_never_replaces_a_complete_one_and_goes_beside_it() {
        let dir = dir("keep");
        let path = dir.join("drive.toml");
        let good = backup(0, 5).render();
        std::fs::write(&path, &good).unwrap();
        let saved = save(&path, &backup(4, 5), false).unwrap();
        let aside = dir.join("drive.toml.incomplete");
        assert_eq!(
            saved,
            Saved::KeptPrevious { new: aside.clone(), previous: Completeness { parameters: 5, unread: 0 } }
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), good, "the good file is untouched");
        assert_eq!(std::fs::read_to_string(&aside).unwrap(), backup(4, 5).render(), "the new data is not lost");
        assert_eq!(leftovers(&dir), ["drive.toml", "drive.toml.incomplete"], "no temporary file left");
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn force_or_a_better_backup_replaces_the_file_and_keeps_the_previous_as_bak() {
        let dir = dir("replace");
        let path = dir.join("drive.toml");
        let (first, second) = (backup(3, 5).render(), backup(1, 5).render());
        std::fs::write(&path, &first).unwrap();
        let bak = dir.join("drive.toml.bak");
        assert_eq!(save(&path, &backup(1, 5), false).unwrap(), Saved::Replaced { previous: Some(bak.clone()) });
        assert_eq!(std::fs::read_to_string(&path).unwrap(), second);
        assert_eq!(std::fs::read_to_string(&bak).unwrap(), first);
        // Worse than what is there, but forced.
        assert_eq!(save(&path, &backup(5, 5), true).unwrap(), Saved::Replaced { previous: Some(bak.clone()) });
        assert_eq!(std::fs::read_to_string(&bak).unwrap(), second);
        assert_eq!(leftovers(&dir), ["drive.toml", "drive.toml.bak"]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn a_new_file_is_written_even_incomplete_and_a_file_that_is_no_backup_is_kept_as_bak() {
        let dir = dir("new");
        let path = dir.join("drive.toml");
        assert_eq!(save(&path, &backup(2, 3), false).unwrap(), Saved::Replaced { previous: None });
        assert_eq!(leftovers(&dir), ["drive.toml"]);
        std::fs::write(&path, "notes, not a backup").unwrap();
        let saved = save(&path, &backup(2, 3), false).unwrap();
        assert_eq!(saved, Saved::Replaced { previous: Some(dir.join("drive.toml.bak")) });
        assert_eq!(std::fs::read_to_string(dir.join("drive.toml.bak")).unwrap(), "notes, not a backup");
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn a_failed_write_leaves_no_temporary_file_and_names_the_file() {
        let dir = dir("fail");
        let path = dir.join("missing").join("drive.toml");
        let err = save(&path, &backup(0, 1), false).unwrap_err();
        assert!(matches!(&err, SaveError::Io { what, .. } if what == &path.display().to_string()), "{err:?}");
        assert!(leftovers(&dir).is_empty());
        std::fs::remove_dir_all(dir).unwrap();
    }
}
