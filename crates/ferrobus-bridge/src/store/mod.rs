//! Store and forward: the records the edge node could not publish while the broker was away,
//! kept in order until they are replayed.
//!
//! A [`Store`] is a bounded FIFO of opaque records (`Vec<u8>`): first in memory up to
//! [`StoreConfig::memory`] bytes, then in segment files in [`StoreConfig::dir`] up to
//! [`StoreConfig::disk`] bytes. The order is strict across the two: memory holds the oldest
//! records, and once a record went to disk every new one goes to disk behind it until the disk
//! part is drained. When both bounds are reached the *new* record is refused
//! ([`Pushed::Dropped`]) and counted in [`Store::dropped`]; the caller logs it. Nothing is lost
//! silently. Without a directory the store lives in memory only.
//!
//! # On disk
//!
//! ```text
//!   DIR/0000000100000000.seg   segments, numbered in hex (sixteen digits, so names sort)
//!   DIR/0000000100000001.seg   the tail, appended to
//!
//!   segment = header, record*
//!   header  = "FBSTORE" 0x01                      magic and format version (8 bytes)
//!             slot 0, slot 1                      the read position, 16 bytes each:
//!               start u64 LE                        offset of the first record not yet popped
//!               generation u32 LE                   +1 per pop; written to slot generation % 2
//!               crc32 u32 LE                        over start and generation
//!   record  = len u32 LE, crc32 u32 LE, len bytes  crc32 over len's 4 bytes and the bytes
//! ```
//!
//! CRC-32 is the ISO-HDLC one (zip, Ethernet). A pop rewrites one slot of the head segment's
//! header in place, the two slots taking turns, so a torn write leaves the other one, a record
//! behind: a restart delivers again at most the last record popped. A segment whose records
//! are all popped is deleted; a new segment is started when the tail reaches a sixteenth of
//! `disk` (at most 16 MiB), so the space of popped records comes back in those steps. `disk`
//! bounds the bytes of the segment files, headers and popped records of the head included.
//!
//! [`Store::open`] reads every segment from its read position on, checking each record: a
//! torn or corrupt tail (power loss, kill -9 mid-write, a damaged disk) is cut away with a
//! warning (`tracing`) and counted in [`StoreStats::truncated`]; a record found damaged later,
//! while reading, drops the rest of its segment once ([`StoreError::Corrupt`], counted in
//! [`StoreStats::lost`]). Neither panics nor repeats.
//!
//! Writes go through a buffered writer flushed after each push, so a killed process loses
//! nothing the store put on disk. There is **no fsync** per record: a power loss may lose the
//! last records the OS had not yet written, and deliver again records whose pops it had not.
//!
//! Records in memory are volatile: [`Store::close`] (or dropping the store) writes them to a
//! new segment numbered below the head, in front of the disk's records; a killed process
//! loses them. With a directory, `disk` bounds the files after that close too: the room the
//! memory's records will take there (a header, and each record with its frame) is kept free
//! on disk while they are held, so a record goes to memory only if it would fit on disk as
//! well, and to disk only if the memory's segment still fits beside it. The memory part is
//! then a fast front of what the disk bounds, and a clean stop never writes past the bound.
//! The first segment of an empty directory is numbered 2^32, leaving room below.
//!
//! A failed write (a full disk, a directory that became unwritable) is [`StoreError::Io`]
//! naming the path; that record is not stored, the failed bytes are cut away, and the store
//! stays usable: memory still takes records while the disk part is empty, and the next disk
//! write starts a new segment. All IO is blocking and small (a `write` per push to disk, a
//! seek and a 16-byte write per pop from disk); one directory belongs to one store at a time.

mod disk;
mod segment;
#[cfg(test)]
mod tests;

use std::collections::VecDeque;
use std::io;
use std::path::PathBuf;

use disk::Disk;
use segment::{FRAME_LEN, HEADER_LEN};

/// The bounds of a [`Store`] and where its disk part lives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoreConfig {
    /// The bytes of records kept in memory before the disk is used.
    pub memory: usize,
    /// The directory of the segment files (created if missing); `None`: memory only.
    pub dir: Option<PathBuf>,
    /// The bytes the segment files may take.
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
    /// Bytes of the segment files (what [`StoreConfig::disk`] bounds).
    pub disk_bytes: u64,
    /// Records refused since `open`: both bounds were reached.
    pub dropped: u64,
    /// Records not stored since `open` because writing them failed ([`StoreError::Io`]).
    pub failed: u64,
    /// Records of a previous run found on disk by `open`.
    pub recovered: u64,
    /// Damaged parts of segment files cut away: torn or corrupt tails at `open`, damaged
    /// records found while reading.
    pub truncated: u64,
    /// Records known to be lost with a damaged part found while reading.
    pub lost: u64,
    /// Read positions that could not be written: after a restart those records may be
    /// delivered again.
    pub position_errors: u64,
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
    /// A segment file holds something that is not a record; the rest of it was dropped.
    #[error("{}: at byte {offset}: {detail}", path.display())]
    Corrupt {
        /// The segment file.
        path: PathBuf,
        /// Where the bad bytes start.
        offset: u64,
        /// What was found.
        detail: String,
    },
}

/// A bounded FIFO of opaque records: memory first, then disk segments (see the
/// [module doc](self)).
#[derive(Debug)]
pub struct Store {
    memory: VecDeque<Vec<u8>>,
    memory_bytes: usize,
    memory_bound: usize,
    disk: Option<Disk>,
    dropped: u64,
    failed: u64,
}

impl Store {
    /// Opens a store, recovering a previous run's records from `config.dir`, in order, in
    /// front of any new one. A directory that cannot be created or read is an error.
    pub fn open(config: StoreConfig) -> Result<Store, StoreError> {
        let disk = match config.dir {
            Some(dir) => Some(Disk::open(dir, config.disk)?),
            None => None,
        };
        Ok(Store { memory: VecDeque::new(), memory_bytes: 0, memory_bound: config.memory, disk, dropped: 0, failed: 0 })
    }

    /// Appends a record behind every other: in memory while it has room and nothing is on
    /// disk (and, with a directory, the disk could take it at close), else on disk. Over both
    /// bounds the record is refused and counted ([`Pushed::Dropped`]); a failed write is an
    /// error and the record is not stored.
    pub fn push(&mut self, record: Vec<u8>) -> Result<Pushed, StoreError> {
        let disk_empty = self.disk.as_ref().is_none_or(|d| d.records() == 0);
        let fits = self.memory_bytes.saturating_add(record.len()) <= self.memory_bound;
        let saved = self.saved_len(Some(record.len()));
        let savable = self.disk.as_ref().is_none_or(|d| d.has_room(saved));
        if disk_empty && fits && savable && u32::try_from(record.len()).is_ok() {
            self.memory_bytes += record.len();
            self.memory.push_back(record);
            return Ok(Pushed::Memory);
        }
        let reserved = self.saved_len(None);
        let stored = match self.disk.as_mut().map(|disk| disk.append(&record, reserved)) {
            Some(Ok(true)) => Pushed::Disk,
            None | Some(Ok(false)) => Pushed::Dropped,
            Some(Err(e)) => {
                self.failed += 1;
                return Err(e);
            }
        };
        if stored == Pushed::Dropped {
            self.dropped += 1;
        }
        Ok(stored)
    }

    /// The oldest record, not removed.
    ///
    /// [`StoreError::Corrupt`]: the oldest disk records were damaged and are dropped (the
    /// next call goes on with the next segment); [`StoreError::Io`]: reading failed, nothing
    /// changed.
    pub fn front(&mut self) -> Result<Option<Vec<u8>>, StoreError> {
        if let Some(record) = self.memory.front() {
            return Ok(Some(record.clone()));
        }
        match self.disk.as_mut() {
            Some(disk) => Ok(disk.front()?.map(<[u8]>::to_vec)),
            None => Ok(None),
        }
    }

    /// Removes the oldest record (once it was sent); nothing if the store is empty.
    ///
    /// The errors are [`Store::front`]'s: an error means no record was removed (a damaged one
    /// may have been dropped).
    pub fn pop(&mut self) -> Result<(), StoreError> {
        if let Some(record) = self.memory.pop_front() {
            self.memory_bytes -= record.len();
            return Ok(());
        }
        match self.disk.as_mut() {
            Some(disk) => disk.pop(),
            None => Ok(()),
        }
    }

    /// The records held.
    pub fn len(&self) -> u64 {
        self.memory.len() as u64 + self.disk.as_ref().map_or(0, Disk::records)
    }

    /// Whether no record is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The records refused since `open`: both bounds were reached.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Records and bytes in memory and on disk, and the counters.
    pub fn stats(&self) -> StoreStats {
        let counters = self.disk.as_ref().map(|d| d.counters).unwrap_or_default();
        StoreStats {
            memory_records: self.memory.len() as u64,
            memory_bytes: self.memory_bytes as u64,
            disk_records: self.disk.as_ref().map_or(0, Disk::records),
            disk_bytes: self.disk.as_ref().map_or(0, Disk::bytes),
            dropped: self.dropped,
            failed: self.failed,
            recovered: counters.recovered,
            truncated: counters.truncated,
            lost: counters.lost,
            position_errors: counters.position_errors,
        }
    }

    /// Closes the store, writing the records in memory to disk in front of the disk's (the
    /// next `open` recovers them all, in order). Without a directory they are gone.
    ///
    /// Dropping the store does the same, logging a failure instead of returning it.
    pub fn close(mut self) -> Result<(), StoreError> {
        self.save_memory()
    }

    /// The bytes the memory's records take as a segment on disk at close, with one more record
    /// of `extra` bytes if given (0 when there is nothing to write).
    fn saved_len(&self, extra: Option<usize>) -> u64 {
        let records = self.memory.len() + usize::from(extra.is_some());
        if records == 0 {
            return 0;
        }
        let bytes = self.memory_bytes.saturating_add(extra.unwrap_or(0)) as u64;
        HEADER_LEN.saturating_add(FRAME_LEN.saturating_mul(records as u64)).saturating_add(bytes)
    }

    /// Writes the records in memory to a segment in front of the disk's, and forgets them.
    fn save_memory(&mut self) -> Result<(), StoreError> {
        let Some(disk) = self.disk.as_mut() else {
            return Ok(());
        };
        if self.memory.is_empty() {
            return Ok(());
        }
        disk.prepend(&self.memory)?;
        self.memory.clear();
        self.memory_bytes = 0;
        Ok(())
    }
}

impl Drop for Store {
    fn drop(&mut self) {
        let records = self.memory.len();
        if let Err(e) = self.save_memory() {
            tracing::warn!(error = %e, records, "store: the records in memory could not be saved");
        }
    }
}
