//! The disk part of the store: a queue of segment files in one directory, appended at the tail,
//! read and deleted at the head, with the read position kept in the head segment's header.

use std::collections::VecDeque;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufReader, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::StoreError;
use super::segment::{self, FRAME_LEN, HEADER_LEN, Position};

/// The number of the first segment in an empty directory: high enough that a close can put the
/// memory's records in a segment numbered below the head's about four billion times.
const FIRST_NUMBER: u64 = 1 << 32;
/// The largest segment started: a drained segment is deleted whole, so the space of records
/// already popped comes back in steps of at most this.
const MAX_SEGMENT: u64 = 16 << 20;

/// One segment file.
#[derive(Debug)]
struct Segment {
    number: u64,
    path: PathBuf,
    /// Where its first record not yet popped starts, as last written in its header.
    position: Position,
    /// Its records not yet popped.
    records: u64,
    /// Its length: where its last whole record ends.
    end: u64,
}

/// The open head segment: a buffered reader and a handle to rewrite the read position.
#[derive(Debug)]
struct Reader {
    number: u64,
    file: BufReader<File>,
    /// The offset the reader is at.
    at: u64,
    header: File,
}

/// What the disk part counted since it was opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct DiskCounters {
    /// Records found by `open`.
    pub(super) recovered: u64,
    /// Damaged parts cut away (at `open`, or found while reading).
    pub(super) truncated: u64,
    /// Records known to be lost with a damaged part found while reading.
    pub(super) lost: u64,
    /// Read positions that could not be written (those records may be delivered again).
    pub(super) position_errors: u64,
}

/// The disk part: segments in `dir`, their bytes bounded by `bound`.
#[derive(Debug)]
pub(super) struct Disk {
    dir: PathBuf,
    bound: u64,
    /// A segment at least this long is closed and a new one started.
    target: u64,
    segments: VecDeque<Segment>,
    next_number: u64,
    /// The segments' bytes (headers and records already popped of the head included).
    bytes: u64,
    records: u64,
    /// Appends to the last segment; `None`: the next record starts a new segment.
    writer: Option<BufWriter<File>>,
    reader: Option<Reader>,
    /// The head's first record, once read.
    front: Option<Vec<u8>>,
    pub(super) counters: DiskCounters,
}

/// An `io::Error` with the path it happened on.
fn io_error(path: &Path) -> impl FnOnce(io::Error) -> StoreError + '_ {
    move |source| StoreError::Io { path: path.to_path_buf(), source }
}

/// The name of segment `number`: sixteen hex digits, so the names sort as the numbers do.
fn file_name(number: u64) -> String {
    format!("{number:016x}.seg")
}

/// The number of a segment file's name; `None` for any other file.
fn number_of(name: &str) -> Option<u64> {
    let digits = name.strip_suffix(".seg")?;
    if digits.len() != 16 {
        return None;
    }
    u64::from_str_radix(digits, 16).ok()
}

/// Removes a file the store is done with; a failure is only worth a warning.
fn remove(path: &Path) {
    if let Err(e) = fs::remove_file(path) {
        tracing::warn!(path = %path.display(), error = %e, "store: cannot delete a consumed segment");
    }
}

impl Disk {
    /// Opens `dir` (creating it), recovering the segments a previous run left.
    pub(super) fn open(dir: PathBuf, bound: u64) -> Result<Disk, StoreError> {
        fs::create_dir_all(&dir).map_err(io_error(&dir))?;
        let mut numbers = Vec::new();
        for entry in fs::read_dir(&dir).map_err(io_error(&dir))? {
            let entry = entry.map_err(io_error(&dir))?;
            if let Some(number) = entry.file_name().to_str().and_then(number_of) {
                numbers.push(number);
            }
        }
        numbers.sort_unstable();
        let mut disk = Disk {
            target: (bound / 16).clamp(1, MAX_SEGMENT),
            next_number: numbers.last().map_or(FIRST_NUMBER, |n| n.saturating_add(1)),
            dir,
            bound,
            segments: VecDeque::new(),
            bytes: 0,
            records: 0,
            writer: None,
            reader: None,
            front: None,
            counters: DiskCounters::default(),
        };
        for number in numbers {
            disk.recover(number)?;
        }
        disk.counters.recovered = disk.records;
        Ok(disk)
    }

    /// Scans segment `number`, cuts a damaged tail away and keeps it if records are left.
    fn recover(&mut self, number: u64) -> Result<(), StoreError> {
        let path = self.dir.join(file_name(number));
        let file = File::open(&path).map_err(io_error(&path))?;
        let scan = segment::scan(file).map_err(io_error(&path))?;
        let shown = path.display();
        if scan.position_lost {
            tracing::warn!(path = %shown, "store: no read position in the header holds its CRC; reading the segment from its first record");
        }
        if let Some((offset, detail)) = &scan.damage {
            self.counters.truncated += 1;
            tracing::warn!(path = %shown, offset, detail = %detail, "store: a damaged segment tail was cut away");
            if scan.records > 0 {
                let cut = OpenOptions::new().write(true).open(&path).and_then(|f| f.set_len(scan.end));
                if let Err(e) = cut {
                    tracing::warn!(path = %shown, error = %e, "store: cannot truncate the damaged tail; it is skipped");
                }
            }
        }
        if scan.records == 0 {
            remove(&path);
            return Ok(());
        }
        self.records += scan.records;
        self.bytes += scan.end;
        self.segments.push_back(Segment { number, path, position: scan.start, records: scan.records, end: scan.end });
        Ok(())
    }

    /// The records on disk.
    pub(super) fn records(&self) -> u64 {
        self.records
    }

    /// The bytes of the segment files.
    pub(super) fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Whether `bytes` more fit the bound.
    pub(super) fn has_room(&self, bytes: u64) -> bool {
        self.bytes.saturating_add(bytes) <= self.bound
    }

    /// Appends `record` behind every other, keeping `reserved` bytes free (the memory's
    /// records, written at close); `Ok(false)` when the bound leaves no room for it.
    pub(super) fn append(&mut self, record: &[u8], reserved: u64) -> Result<bool, StoreError> {
        let Some(frame) = segment::frame(record) else {
            return Ok(false);
        };
        let size = FRAME_LEN + record.len() as u64;
        let tail_end = self.segments.back().map_or(0, |tail| tail.end);
        let start_new = self.writer.is_none() || tail_end + size > self.target;
        let needed = if start_new { HEADER_LEN + size } else { size };
        if !self.has_room(needed.saturating_add(reserved)) {
            return Ok(false);
        }
        if start_new {
            self.writer = None;
            self.start_segment(&frame, record)?;
        } else {
            self.write_tail(&frame, record)?;
        }
        self.records += 1;
        self.bytes += needed;
        Ok(true)
    }

    /// Starts a new segment at the tail holding `record`.
    fn start_segment(&mut self, frame: &[u8], record: &[u8]) -> Result<(), StoreError> {
        let number = self.next_number;
        self.next_number = number.saturating_add(1);
        let (path, writer) = self.create(number, &[(frame, record)])?;
        self.writer = Some(writer);
        self.segments.push_back(Segment {
            number,
            path,
            position: Position::FRESH,
            records: 1,
            end: HEADER_LEN + FRAME_LEN + record.len() as u64,
        });
        Ok(())
    }

    /// Creates segment `number` holding `records` (frame and bytes), flushed.
    fn create(&self, number: u64, records: &[(&[u8], &[u8])]) -> Result<(PathBuf, BufWriter<File>), StoreError> {
        let path = self.dir.join(file_name(number));
        let file = OpenOptions::new().write(true).create_new(true).open(&path).map_err(io_error(&path))?;
        let mut writer = BufWriter::new(file);
        let mut written = writer.write_all(&segment::header());
        for (frame, record) in records {
            written = written.and_then(|()| writer.write_all(frame)).and_then(|()| writer.write_all(record));
        }
        if let Err(e) = written.and_then(|()| writer.flush()) {
            drop(writer.into_parts());
            remove(&path);
            return Err(io_error(&path)(e));
        }
        Ok((path, writer))
    }

    /// Appends `record` to the tail segment; on an error the segment is cut back and closed.
    fn write_tail(&mut self, frame: &[u8], record: &[u8]) -> Result<(), StoreError> {
        let (Some(writer), Some(tail)) = (self.writer.as_mut(), self.segments.back_mut()) else {
            return Ok(());
        };
        let written = writer.write_all(frame).and_then(|()| writer.write_all(record)).and_then(|()| writer.flush());
        if let Err(e) = written {
            if let Some(writer) = self.writer.take() {
                let (file, _unwritten) = writer.into_parts();
                if let Err(cut) = file.set_len(tail.end) {
                    tracing::warn!(path = %tail.path.display(), error = %cut, "store: cannot cut a failed write away; the next open will");
                }
            }
            return Err(io_error(&tail.path)(e));
        }
        tail.records += 1;
        tail.end += FRAME_LEN + record.len() as u64;
        Ok(())
    }

    /// The oldest record on disk, read once and kept until it is popped.
    ///
    /// A damaged record is an error once: the rest of its segment is dropped (counted in
    /// `lost`) and the next call reads the next segment.
    pub(super) fn front(&mut self) -> Result<Option<&[u8]>, StoreError> {
        if self.front.is_none() {
            self.front = self.read_front()?;
        }
        Ok(self.front.as_deref())
    }

    fn read_front(&mut self) -> Result<Option<Vec<u8>>, StoreError> {
        let Some(head) = self.segments.front() else {
            return Ok(None);
        };
        let start = head.position.start;
        let mut reader = match self.reader.take() {
            Some(reader) if reader.number == head.number => reader,
            _ => Reader::open(head).map_err(io_error(&head.path))?,
        };
        if reader.at != start {
            reader.file.seek(SeekFrom::Start(start)).map_err(io_error(&head.path))?;
            reader.at = start;
        }
        match segment::read_record(&mut reader.file, start, head.end) {
            Ok(Ok(record)) => {
                reader.at = start + FRAME_LEN + record.len() as u64;
                self.reader = Some(reader);
                Ok(Some(record))
            }
            Ok(Err(detail)) => Err(self.drop_damaged_head(start, detail)),
            Err(e) => Err(io_error(&head.path)(e)),
        }
    }

    /// Drops the head segment, found damaged at `offset` while reading.
    fn drop_damaged_head(&mut self, offset: u64, detail: String) -> StoreError {
        self.reader = None;
        let Some(head) = self.segments.pop_front() else {
            return StoreError::Corrupt { path: self.dir.clone(), offset, detail };
        };
        tracing::warn!(path = %head.path.display(), offset, detail = %detail, lost = head.records, "store: a damaged segment was dropped");
        self.counters.truncated += 1;
        self.counters.lost += head.records;
        self.forget(&head);
        StoreError::Corrupt { path: head.path, offset, detail }
    }

    /// Removes the oldest record on disk (nothing if there is none).
    pub(super) fn pop(&mut self) -> Result<(), StoreError> {
        if self.front.is_none() {
            self.front = self.read_front()?;
        }
        let (Some(record), Some(head)) = (self.front.take(), self.segments.front_mut()) else {
            return Ok(());
        };
        head.position.start += FRAME_LEN + record.len() as u64;
        head.position.generation = head.position.generation.wrapping_add(1);
        head.records -= 1;
        self.records -= 1;
        let position = head.position;
        let done = head.records == 0;
        self.write_position(position);
        if done {
            self.reader = None;
            if let Some(head) = self.segments.pop_front() {
                self.forget(&head);
            }
        }
        Ok(())
    }

    /// Writes the head's read position into its header (not synced: the OS writes it).
    fn write_position(&mut self, position: Position) {
        let Some(reader) = self.reader.as_mut() else {
            return;
        };
        let (offset, slot) = position.slot();
        let written = (&reader.header).seek(SeekFrom::Start(offset)).and_then(|_| (&reader.header).write_all(&slot));
        if let Err(e) = written {
            self.counters.position_errors += 1;
            let path = self.segments.front().map(|head| head.path.display());
            tracing::warn!(path = %path.map(|p| p.to_string()).unwrap_or_default(), error = %e, "store: cannot write the read position; a restart may deliver records again");
        }
    }

    /// Deletes a segment taken off the queue, closing the tail's writer if it was the last.
    fn forget(&mut self, segment: &Segment) {
        if self.segments.is_empty() {
            self.writer = None;
        }
        self.records -= segment.records;
        self.bytes -= segment.end;
        remove(&segment.path);
    }

    /// Puts `records` in a new segment in front of every other (the memory's records, at close).
    pub(super) fn prepend(&mut self, records: &VecDeque<Vec<u8>>) -> Result<(), StoreError> {
        let number = if let Some(head) = self.segments.front() {
            head.number
                .checked_sub(1)
                .ok_or_else(|| io_error(&self.dir)(io::Error::other("no segment number is left below the head")))?
        } else {
            let number = self.next_number;
            self.next_number = number.saturating_add(1);
            number
        };
        let frames: Vec<_> = records.iter().filter_map(|r| Some((segment::frame(r)?, r.as_slice()))).collect();
        let refs: Vec<(&[u8], &[u8])> = frames.iter().map(|(f, r)| (&f[..], *r)).collect();
        let (path, writer) = self.create(number, &refs)?;
        drop(writer);
        let end = HEADER_LEN + refs.iter().map(|(f, r)| (f.len() + r.len()) as u64).sum::<u64>();
        self.records += refs.len() as u64;
        self.bytes += end;
        self.front = None;
        self.segments.push_front(Segment { number, path, position: Position::FRESH, records: refs.len() as u64, end });
        Ok(())
    }
}

impl Reader {
    /// Opens `segment` to read it and to rewrite its read position.
    fn open(segment: &Segment) -> io::Result<Reader> {
        let file = File::open(&segment.path)?;
        let header = OpenOptions::new().write(true).open(&segment.path)?;
        Ok(Reader { number: segment.number, file: BufReader::new(file), at: 0, header })
    }
}
