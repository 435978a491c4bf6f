//! The bdSeq kept across restarts: a one-line file `bdseq` holding the bdSeq of the last
//! CONNECT's Will, so that the next run's first CONNECT takes the next one, as Sparkplug asks
//! of an edge node that comes back (tck-id-payloads-ndeath-bdseq: every new CONNECT increments
//! it, 255 → 0).
//!
//! The file lives in the store's directory when one is configured (the plant's state is kept
//! together), else in the platform's state (or local data) directory under
//! `ferrobus/bridge/<group>-<edge node>/`. A missing file is a first run; an unreadable or
//! corrupt one is said and the count starts again at 0: a host sees a new bdSeq either way.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

/// The name of the file.
pub const FILE_NAME: &str = "bdseq";

/// Where the bdSeq of one edge node is kept.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BdSeqFile {
    path: PathBuf,
}

/// What reading the file found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Stored {
    /// The bdSeq of the last CONNECT.
    Last(u8),
    /// No file: the first run.
    None,
    /// A file that cannot be used, and why.
    Unusable(String),
}

impl BdSeqFile {
    /// The file at `path`.
    pub fn at(path: impl Into<PathBuf>) -> BdSeqFile {
        BdSeqFile { path: path.into() }
    }

    /// The file of edge node `node` of `group`: in `store_dir` if given, else in the
    /// platform's state directory; `None` if the platform has neither a state nor a data
    /// directory.
    pub fn locate(store_dir: Option<&Path>, group: &str, node: &str) -> Option<BdSeqFile> {
        if let Some(dir) = store_dir {
            return Some(BdSeqFile::at(dir.join(FILE_NAME)));
        }
        let base = dirs::state_dir().or_else(dirs::data_local_dir)?;
        Some(BdSeqFile::at(base.join("ferrobus").join("bridge").join(format!("{group}-{node}")).join(FILE_NAME)))
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The bdSeq it holds.
    pub fn read(&self) -> Stored {
        match fs::read_to_string(&self.path) {
            Ok(text) => parse(&text).map_or_else(
                || Stored::Unusable(format!("{}: {:?} is not a bdSeq (0-255)", self.path.display(), text.trim())),
                Stored::Last,
            ),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Stored::None,
            Err(e) => Stored::Unusable(format!("{}: {e}", self.path.display())),
        }
    }

    /// Keeps `bd_seq` (written to a temporary file, then renamed over the old one, so that a
    /// crash leaves the old value or the new one, never half a line).
    pub fn write(&self, bd_seq: u8) -> io::Result<()> {
        if let Some(dir) = self.path.parent() {
            fs::create_dir_all(dir)?;
        }
        let temporary = self.path.with_extension("tmp");
        fs::write(&temporary, format!("{bd_seq}\n"))?;
        fs::rename(&temporary, &self.path)
    }
}

/// The bdSeq of the next CONNECT after one whose Will carried `last`.
pub fn next(last: u8) -> u8 {
    last.wrapping_add(1)
}

fn parse(text: &str) -> Option<u8> {
    text.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temporary(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("ferrobus-bdseq-{}-{name}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_written_bd_seq_is_read_back_and_a_missing_file_is_a_first_run() {
        let dir = temporary("roundtrip");
        let file = BdSeqFile::at(dir.join("nested").join(FILE_NAME));
        assert_eq!(file.read(), Stored::None);
        file.write(41).unwrap();
        assert_eq!(file.read(), Stored::Last(41));
        file.write(255).unwrap();
        assert_eq!(file.read(), Stored::Last(255));
        assert!(!file.path().with_extension("tmp").exists(), "the temporary file was renamed");
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_corrupt_file_is_unusable_and_says_what_it_held() {
        let dir = temporary("corrupt");
        fs::create_dir_all(&dir).unwrap();
        let file = BdSeqFile::at(dir.join(FILE_NAME));
        for bad in ["256\n", "x", "", "-1"] {
            fs::write(file.path(), bad).unwrap();
            let Stored::Unusable(why) = file.read() else { panic!("{bad:?} is no bdSeq") };
            assert!(why.contains("is not a bdSeq"), "{why}");
        }
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_next_bd_seq_wraps_from_255_to_0() {
        assert_eq!(next(0), 1);
        assert_eq!(next(254), 255);
        assert_eq!(next(255), 0);
    }

    #[test]
    fn the_file_is_in_the_store_directory_when_there_is_one() {
        let file = BdSeqFile::locate(Some(Path::new("/var/lib/plant")), "G", "N").unwrap();
        assert_eq!(file.path(), Path::new("/var/lib/plant/bdseq"));
        if let Some(file) = BdSeqFile::locate(None, "plant", "edge1") {
            assert!(file.path().ends_with("ferrobus/bridge/plant-edge1/bdseq"), "{}", file.path().display());
        }
    }
}
