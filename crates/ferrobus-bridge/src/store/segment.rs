//! One segment file: its header (magic and read position) and its length-prefixed records,
//! checked with CRC-32 (ISO-HDLC, the one of zip and Ethernet). The layout is described in the
//! [module doc](super); this file only encodes, decodes and scans it, without keeping state.

use std::fs::File;
use std::io::{self, BufReader, ErrorKind, Read, Seek, SeekFrom};

/// The first eight bytes of every segment file: what it is, and the format's version.
pub(super) const MAGIC: [u8; 8] = *b"FBSTORE\x01";
/// The header: the magic, then two read-position slots of 16 bytes.
const HEADER: usize = 40;
/// The bytes in front of each record: its length and its CRC.
const FRAME: usize = 8;
/// [`HEADER`] as an offset.
pub(super) const HEADER_LEN: u64 = HEADER as u64;
/// [`FRAME`] as an offset.
pub(super) const FRAME_LEN: u64 = FRAME as u64;

const SLOT_LEN: usize = 16;
const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The read position written in a header slot: where the first record not yet popped starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Position {
    /// The offset of that record in the file (`HEADER_LEN` when nothing was popped).
    pub(super) start: u64,
    /// Counts the writes of the position; the slot written is `generation % 2`.
    pub(super) generation: u32,
}

impl Position {
    /// Where a new segment is read from.
    pub(super) const FRESH: Position = Position { start: HEADER_LEN, generation: 0 };

    /// The header slot this position goes to: its offset in the file and its bytes.
    pub(super) fn slot(self) -> (u64, [u8; SLOT_LEN]) {
        let mut bytes = [0; SLOT_LEN];
        bytes[..8].copy_from_slice(&self.start.to_le_bytes());
        bytes[8..12].copy_from_slice(&self.generation.to_le_bytes());
        let crc = CRC32.checksum(&bytes[..12]);
        bytes[12..].copy_from_slice(&crc.to_le_bytes());
        let offset = MAGIC.len() as u64 + u64::from(self.generation % 2) * SLOT_LEN as u64;
        (offset, bytes)
    }

    /// The position in one slot, if its CRC holds.
    fn from_slot(bytes: &[u8]) -> Option<Position> {
        let start = u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?);
        let generation = u32::from_le_bytes(bytes.get(8..12)?.try_into().ok()?);
        let crc = u32::from_le_bytes(bytes.get(12..16)?.try_into().ok()?);
        (CRC32.checksum(bytes.get(..12)?) == crc).then_some(Position { start, generation })
    }
}

/// The header of a new segment: the magic, slot 0 holding `Position::FRESH`, slot 1 empty.
pub(super) fn header() -> [u8; HEADER] {
    let mut bytes = [0; HEADER];
    bytes[..MAGIC.len()].copy_from_slice(&MAGIC);
    let (_, slot) = Position::FRESH.slot();
    bytes[MAGIC.len()..MAGIC.len() + SLOT_LEN].copy_from_slice(&slot);
    bytes
}

/// The length and CRC in front of `record`; `None` if it is longer than a `u32` can say.
pub(super) fn frame(record: &[u8]) -> Option<[u8; FRAME]> {
    let len = u32::try_from(record.len()).ok()?.to_le_bytes();
    let mut frame = [0; FRAME];
    frame[..4].copy_from_slice(&len);
    frame[4..].copy_from_slice(&record_crc(len, record).to_le_bytes());
    Some(frame)
}

/// The CRC of a record: over its length field and its bytes, so a damaged length is caught too.
fn record_crc(len: [u8; 4], record: &[u8]) -> u32 {
    let mut digest = CRC32.digest();
    digest.update(&len);
    digest.update(record);
    digest.finalize()
}

/// Reads the record at the reader's position, of a segment whose records end at `end`.
///
/// `Ok(Err(detail))` is damage: a length past `end`, a short file or a CRC that does not match.
/// `Err` is the system's error reading the file.
pub(super) fn read_record(reader: &mut impl Read, at: u64, end: u64) -> io::Result<Result<Vec<u8>, String>> {
    let mut frame = [0; FRAME];
    match reader.read_exact(&mut frame) {
        Err(e) if e.kind() == ErrorKind::UnexpectedEof => {
            return Ok(Err("the file ends inside a record's length".into()));
        }
        other => other?,
    }
    let len = [frame[0], frame[1], frame[2], frame[3]];
    let crc = u32::from_le_bytes([frame[4], frame[5], frame[6], frame[7]]);
    let room = end.saturating_sub(at.saturating_add(FRAME_LEN));
    let size = u32::from_le_bytes(len);
    if u64::from(size) > room {
        return Ok(Err(format!("a record of {size} bytes where only {room} bytes are left")));
    }
    let mut record = vec![0; size as usize];
    match reader.read_exact(&mut record) {
        Err(e) if e.kind() == ErrorKind::UnexpectedEof => {
            return Ok(Err(format!("the file ends inside a record of {size} bytes")));
        }
        other => other?,
    }
    let found = record_crc(len, &record);
    if found != crc {
        return Ok(Err(format!("CRC {found:#010x} of a record of {size} bytes, its frame says {crc:#010x}")));
    }
    Ok(Ok(record))
}

/// What a scan found in a segment file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Scan {
    /// The read position: the first record not popped.
    pub(super) start: Position,
    /// The records from `start` on.
    pub(super) records: u64,
    /// Where the last whole record ends: the file's length once its damage is cut away (or
    /// the file's length when `start` is past it).
    pub(super) end: u64,
    /// The damage found: its offset and what it was (the file is good up to `end`).
    pub(super) damage: Option<(u64, String)>,
    /// Neither header slot holds its CRC: the file is read from its first record.
    pub(super) position_lost: bool,
}

/// Reads a segment file from its read position on, checking every record, to find how many
/// records are left and where the good part ends. The records before the position (popped) are
/// not read: damage there does not matter any more.
pub(super) fn scan(file: File) -> io::Result<Scan> {
    let len = file.metadata()?.len();
    let mut reader = BufReader::new(file);
    let mut head = [0; HEADER];
    if len < HEADER_LEN {
        return Ok(unreadable(format!("{len} bytes, shorter than a header")));
    }
    reader.read_exact(&mut head)?;
    if head[..MAGIC.len()] != MAGIC {
        return Ok(unreadable(format!("not a segment: it starts with {:02x?}", &head[..MAGIC.len()])));
    }
    let slots = head[MAGIC.len()..].chunks(SLOT_LEN);
    let written = slots.filter_map(Position::from_slot).max_by_key(|p| p.generation);
    let mut scan = Scan {
        start: written.unwrap_or(Position::FRESH),
        records: 0,
        end: HEADER_LEN,
        damage: None,
        position_lost: written.is_none(),
    };
    if scan.start.start > len {
        // Every record was popped (the file lost its tail after the position was written).
        scan.end = len;
        return Ok(scan);
    }
    if scan.start.start > HEADER_LEN {
        reader.seek(SeekFrom::Start(scan.start.start))?;
        scan.end = scan.start.start;
    }
    while scan.end < len {
        match read_record(&mut reader, scan.end, len)? {
            Ok(record) => {
                scan.end += FRAME_LEN + record.len() as u64;
                scan.records += 1;
            }
            Err(detail) => {
                scan.damage = Some((scan.end, detail));
                break;
            }
        }
    }
    Ok(scan)
}

/// The scan of a file with no usable header: nothing in it can be read.
fn unreadable(detail: String) -> Scan {
    Scan { start: Position::FRESH, records: 0, end: 0, damage: Some((0, detail)), position_lost: false }
}
