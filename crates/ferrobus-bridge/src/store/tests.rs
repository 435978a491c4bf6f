//! The store's unit tests: the segment format, the order across memory and disk, recovery, and
//! a property test of push, pop, close and crash against a model.

use std::collections::VecDeque;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

use proptest::prelude::*;

use super::segment::{self, FRAME_LEN, HEADER_LEN, Position};
use super::{Pushed, Store, StoreConfig, StoreError};

/// A fresh directory under the system's temp dir, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("ferrobus-store-unit-{name}-{}-{n}", std::process::id()));
        let _ = fs::remove_dir_all(&path);
        TempDir(path)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

fn config(memory: usize, dir: &Path, disk: u64) -> StoreConfig {
    StoreConfig { memory, dir: Some(dir.to_path_buf()), disk }
}

/// A record that says which it is: `i` as 4 bytes, then `pad` bytes.
fn record(i: u32, pad: usize) -> Vec<u8> {
    let mut r = i.to_le_bytes().to_vec();
    r.resize(4 + pad, 0xA5);
    r
}

/// Pops every record, in order.
fn drain(store: &mut Store) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    while let Some(r) = store.front().unwrap() {
        store.pop().unwrap();
        out.push(r);
    }
    out
}

/// What a killed process leaves: the records in memory are gone, the files stay as written.
fn crash(mut store: Store) {
    store.memory.clear();
    store.memory_bytes = 0;
    drop(store);
}

/// The bytes of the segment files in `dir`, as the file system has them.
fn bytes_on_disk(dir: &Path) -> u64 {
    segments(dir).iter().map(|p| fs::metadata(p).map_or(0, |m| m.len())).sum()
}

fn segments(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<_> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "seg"))
        .collect();
    files.sort();
    files
}

#[test]
fn a_record_reads_back_through_its_frame() {
    let frame = segment::frame(b"abc").unwrap();
    let mut bytes = frame.to_vec();
    bytes.extend_from_slice(b"abc");
    let end = bytes.len() as u64;
    let got = segment::read_record(&mut bytes.as_slice(), 0, end).unwrap();
    assert_eq!(got, Ok(b"abc".to_vec()));
}

#[test]
fn a_damaged_length_fails_the_crc_even_when_it_fits() {
    let mut bytes = segment::frame(b"abcd").unwrap().to_vec();
    bytes.extend_from_slice(b"abcd");
    bytes[0] = 3;
    let got = segment::read_record(&mut bytes.as_slice(), 0, 100).unwrap();
    assert!(got.unwrap_err().contains("CRC"));
}

#[test]
fn a_length_past_the_end_is_damage_without_reading_it() {
    let mut bytes = segment::frame(&[0; 1000]).unwrap().to_vec();
    bytes.extend_from_slice(&[0; 10]);
    let got = segment::read_record(&mut bytes.as_slice(), 0, 18).unwrap();
    assert_eq!(got, Err("a record of 1000 bytes where only 10 bytes are left".into()));
}

#[test]
fn the_newer_header_slot_wins_and_a_torn_one_falls_back() {
    let a = Position { start: 60, generation: 7 };
    let b = Position { start: 80, generation: 8 };
    let (offset_a, slot_a) = a.slot();
    let (offset_b, slot_b) = b.slot();
    let (offset_a, offset_b) = (usize::try_from(offset_a).unwrap(), usize::try_from(offset_b).unwrap());
    assert_ne!(offset_a, offset_b);
    assert_eq!(offset_b + 16, offset_a);
    let mut header = segment::header();
    header[offset_b..offset_b + 16].copy_from_slice(&slot_b);
    header[offset_a..offset_a + 16].copy_from_slice(&slot_a);
    let mut file = header.to_vec();
    file.extend_from_slice(&[0; 80]);
    let dir = TempDir::new("slots");
    fs::create_dir_all(&dir.0).unwrap();
    let path = dir.0.join("x.seg");
    fs::write(&path, &file).unwrap();
    let scan = segment::scan(fs::File::open(&path).unwrap()).unwrap();
    assert_eq!(scan.start.generation, 8);
    file[offset_b + 3] ^= 1;
    fs::write(&path, &file).unwrap();
    let scan = segment::scan(fs::File::open(&path).unwrap()).unwrap();
    assert_eq!(scan.start.generation, 7);
    assert!(!scan.position_lost);
}

#[test]
fn memory_only_keeps_fifo_order_and_drops_the_new_record_over_the_bound() {
    let mut store = Store::open(StoreConfig { memory: 10, dir: None, disk: 1000 }).unwrap();
    assert_eq!(store.push(record(1, 0)).unwrap(), Pushed::Memory);
    assert_eq!(store.push(record(2, 0)).unwrap(), Pushed::Memory);
    assert_eq!(store.push(record(3, 0)).unwrap(), Pushed::Dropped);
    assert_eq!((store.len(), store.dropped()), (2, 1));
    assert_eq!(drain(&mut store), [record(1, 0), record(2, 0)]);
    assert!(store.is_empty());
    store.pop().unwrap();
}

#[test]
fn once_a_record_is_on_disk_new_ones_follow_it_there_until_it_is_drained() {
    let dir = TempDir::new("order");
    let mut store = Store::open(config(10, &dir.0, 10_000)).unwrap();
    assert_eq!(store.push(record(1, 2)).unwrap(), Pushed::Memory);
    assert_eq!(store.push(record(2, 2)).unwrap(), Pushed::Disk);
    store.pop().unwrap();
    // Memory has room again, but record 2 waits on disk: 3 goes behind it.
    assert_eq!(store.push(record(3, 0)).unwrap(), Pushed::Disk);
    assert_eq!(drain(&mut store), [record(2, 2), record(3, 0)]);
    assert!(segments(&dir.0).is_empty(), "a drained disk part leaves no file");
    assert_eq!(store.push(record(4, 0)).unwrap(), Pushed::Memory);
    assert_eq!(store.stats().disk_bytes, 0);
}

#[test]
fn over_both_bounds_the_new_record_is_dropped_and_counted() {
    let dir = TempDir::new("bounds");
    // Segments of a sixteenth of the bound: each record starts its own.
    let disk = 2 * (HEADER_LEN + FRAME_LEN + 4);
    let mut store = Store::open(config(4, &dir.0, disk)).unwrap();
    let pushed: Vec<_> = (0..5).map(|i| store.push(record(i, 0)).unwrap()).collect();
    // Record 0 in memory keeps a segment's room free on disk for the close: one more fits.
    assert_eq!(pushed, [Pushed::Memory, Pushed::Disk, Pushed::Dropped, Pushed::Dropped, Pushed::Dropped]);
    assert_eq!(store.dropped(), 3);
    assert_eq!(store.stats().disk_bytes, disk / 2);
    assert_eq!(drain(&mut store), [record(0, 0), record(1, 0)]);
}

#[test]
fn segments_roll_and_are_deleted_once_read() {
    let dir = TempDir::new("roll");
    // Segments of 100 bytes: the header and two records of 20 bytes (28 with their frames).
    let mut store = Store::open(config(0, &dir.0, 1600)).unwrap();
    for i in 0..6 {
        assert_eq!(store.push(record(i, 16)).unwrap(), Pushed::Disk);
    }
    assert_eq!(segments(&dir.0).len(), 3);
    store.pop().unwrap();
    store.pop().unwrap();
    assert_eq!(segments(&dir.0).len(), 2);
    assert_eq!(store.stats().disk_bytes, 2 * (HEADER_LEN + 2 * 28));
}

#[test]
fn a_clean_stop_with_memory_and_disk_full_leaves_the_files_within_the_disk_bound() {
    let dir = TempDir::new("full-close");
    // 1 KiB of memory, 4 KiB of disk: records of 100 bytes until both refuse them.
    let disk = 4096;
    let mut store = Store::open(config(1024, &dir.0, disk)).unwrap();
    let mut pushed = Vec::new();
    for i in 0..100 {
        pushed.push(store.push(record(i, 96)).unwrap());
    }
    assert!(pushed.contains(&Pushed::Memory) && pushed.contains(&Pushed::Disk), "{pushed:?}");
    assert_eq!(pushed.last(), Some(&Pushed::Dropped), "the store is full");
    let kept = store.len();
    store.close().unwrap();
    let bytes = bytes_on_disk(&dir.0);
    assert!(bytes <= disk, "{bytes} bytes of segment files after the stop, over the bound of {disk}");
    let mut store = Store::open(config(1024, &dir.0, disk)).unwrap();
    assert_eq!(store.stats().recovered, kept, "every record kept is on disk");
    let want: Vec<_> = (0..100).map(|i| record(i, 96)).take(usize::try_from(kept).unwrap()).collect();
    assert_eq!(drain(&mut store), want, "in order, the newest dropped");
}

#[test]
fn close_saves_the_memory_records_in_front_of_the_disk_ones() {
    let dir = TempDir::new("close");
    let mut store = Store::open(config(20, &dir.0, 10_000)).unwrap();
    for i in 0..6 {
        store.push(record(i, 4)).unwrap();
    }
    store.pop().unwrap();
    assert_eq!(store.stats().memory_records, 1);
    store.close().unwrap();
    let mut store = Store::open(config(20, &dir.0, 10_000)).unwrap();
    assert_eq!(store.stats().recovered, 5);
    store.push(record(6, 4)).unwrap();
    let want: Vec<_> = (1..7).map(|i| record(i, 4)).collect();
    assert_eq!(drain(&mut store), want);
}

#[test]
fn a_crash_after_partial_consumption_neither_replays_nor_loses_disk_records() {
    let dir = TempDir::new("partial");
    let mut store = Store::open(config(0, &dir.0, 10_000)).unwrap();
    for i in 0..5 {
        store.push(record(i, 2)).unwrap();
    }
    store.pop().unwrap();
    store.pop().unwrap();
    assert_eq!(store.front().unwrap(), Some(record(2, 2)));
    crash(store);
    let mut store = Store::open(config(0, &dir.0, 10_000)).unwrap();
    assert_eq!(store.stats().recovered, 3);
    assert_eq!(drain(&mut store), [record(2, 2), record(3, 2), record(4, 2)]);
}

#[test]
fn a_torn_tail_is_cut_away_and_counted() {
    let dir = TempDir::new("torn");
    let mut store = Store::open(config(0, &dir.0, 10_000)).unwrap();
    for i in 0..3 {
        store.push(record(i, 10)).unwrap();
    }
    crash(store);
    let seg = segments(&dir.0).remove(0);
    let len = fs::metadata(&seg).unwrap().len();
    fs::OpenOptions::new().write(true).open(&seg).unwrap().set_len(len - 3).unwrap();
    let mut store = Store::open(config(0, &dir.0, 10_000)).unwrap();
    let stats = store.stats();
    assert_eq!((stats.recovered, stats.truncated), (2, 1));
    assert_eq!(fs::metadata(&seg).unwrap().len(), len - FRAME_LEN - 14);
    store.push(record(9, 0)).unwrap();
    assert_eq!(drain(&mut store), [record(0, 10), record(1, 10), record(9, 0)]);
}

#[test]
fn damage_found_while_reading_drops_its_segment_once() {
    let dir = TempDir::new("rot");
    let mut store = Store::open(config(0, &dir.0, 1600)).unwrap();
    for i in 0..4 {
        store.push(record(i, 16)).unwrap();
    }
    let first = segments(&dir.0).remove(0);
    let mut bytes = fs::read(&first).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0xFF;
    fs::write(&first, &bytes).unwrap();
    assert_eq!(store.front().unwrap(), Some(record(0, 16)));
    store.pop().unwrap();
    match store.front() {
        Err(StoreError::Corrupt { path, offset, .. }) => {
            assert_eq!(path, first);
            assert_eq!(offset, HEADER_LEN + 28);
        }
        other => panic!("expected the damage, got {other:?}"),
    }
    assert_eq!(store.stats().lost, 1);
    assert_eq!(drain(&mut store), [record(2, 16), record(3, 16)]);
}

#[test]
fn a_directory_that_cannot_be_created_is_an_error_naming_it() {
    let dir = TempDir::new("blocked");
    fs::create_dir_all(&dir.0).unwrap();
    let file = dir.0.join("file");
    fs::write(&file, b"not a directory").unwrap();
    let wanted = file.join("store");
    match Store::open(config(0, &wanted, 1000)) {
        Err(StoreError::Io { path, .. }) => assert_eq!(path, wanted),
        other => panic!("expected an IO error, got {other:?}"),
    }
}

#[test]
fn a_failed_write_is_an_error_and_the_memory_part_still_works() {
    let dir = TempDir::new("gone");
    let mut store = Store::open(config(8, &dir.0, 10_000)).unwrap();
    fs::remove_dir_all(&dir.0).unwrap();
    assert_eq!(store.push(record(1, 4)).unwrap(), Pushed::Memory);
    match store.push(record(2, 4)) {
        Err(StoreError::Io { path, .. }) => assert!(path.starts_with(&dir.0), "{path:?}"),
        other => panic!("expected an IO error, got {other:?}"),
    }
    assert_eq!((store.len(), store.stats().failed), (1, 1));
    assert_eq!(drain(&mut store), [record(1, 4)]);
    assert_eq!(store.push(record(3, 4)).unwrap(), Pushed::Memory);
    fs::create_dir_all(&dir.0).unwrap();
    assert_eq!(store.push(record(4, 4)).unwrap(), Pushed::Disk);
    assert_eq!(drain(&mut store), [record(3, 4), record(4, 4)]);
}

/// One step of the property test.
#[derive(Debug, Clone)]
enum Op {
    Push(usize),
    Pop,
    /// Close and open again.
    Reopen,
    /// Kill the process and open again: memory is lost, the files stay.
    Crash,
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        5 => (0usize..24).prop_map(Op::Push),
        3 => Just(Op::Pop),
        1 => Just(Op::Reopen),
        1 => Just(Op::Crash),
    ]
}

/// What the store should hold: each record and whether it is in memory.
#[derive(Default)]
struct Model {
    records: VecDeque<(Vec<u8>, bool)>,
    dropped: u64,
    delivered: Vec<u32>,
    lost_in_crash: Vec<u32>,
}

fn id(record: &[u8]) -> u32 {
    u32::from_le_bytes(record[..4].try_into().unwrap())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Any sequence keeps FIFO order; every record is delivered once, dropped (counted) or was
    /// in memory at a crash; reopening never replays.
    #[test]
    fn any_sequence_keeps_fifo_order_and_accounts_for_every_record(
        memory in 0usize..64,
        disk in prop_oneof![0u64..400, 400u64..3000],
        ops in proptest::collection::vec(op(), 1..80),
    ) {
        let dir = TempDir::new("prop");
        let config = config(memory, &dir.0, disk);
        let mut store = Store::open(config.clone()).unwrap();
        let mut model = Model::default();
        let mut next = 0u32;
        for op in ops {
            match op {
                Op::Push(pad) => {
                    let r = record(next, pad);
                    next += 1;
                    match store.push(r.clone()).unwrap() {
                        Pushed::Memory => model.records.push_back((r, true)),
                        Pushed::Disk => model.records.push_back((r, false)),
                        Pushed::Dropped => model.dropped += 1,
                    }
                }
                Op::Pop => {
                    let got = store.front().unwrap();
                    prop_assert_eq!(got.as_ref(), model.records.front().map(|(r, _)| r));
                    store.pop().unwrap();
                    if let Some((r, _)) = model.records.pop_front() {
                        model.delivered.push(id(&r));
                    }
                }
                Op::Reopen => {
                    store.close().unwrap();
                    prop_assert!(bytes_on_disk(&dir.0) <= disk, "a close wrote past the bound");
                    store = Store::open(config.clone()).unwrap();
                    for (_, in_memory) in &mut model.records {
                        *in_memory = false;
                    }
                    model.dropped = 0;
                }
                Op::Crash => {
                    crash(store);
                    store = Store::open(config.clone()).unwrap();
                    model.records.retain(|(r, in_memory)| {
                        if *in_memory {
                            model.lost_in_crash.push(id(r));
                        }
                        !*in_memory
                    });
                    model.dropped = 0;
                }
            }
            prop_assert_eq!(store.len(), model.records.len() as u64);
            prop_assert_eq!(store.dropped(), model.dropped);
            let stats = store.stats();
            prop_assert_eq!((stats.truncated, stats.lost), (0, 0));
            prop_assert!(stats.disk_bytes <= disk);
            prop_assert!(stats.memory_bytes <= memory as u64);
        }
        let rest = drain(&mut store);
        let want: Vec<_> = model.records.iter().map(|(r, _)| r.clone()).collect();
        prop_assert_eq!(rest, want);
        prop_assert!(model.delivered.windows(2).all(|w| w[0] < w[1]));
    }
}

/// What is done to one segment file while the store is not running.
#[derive(Debug, Clone)]
enum Damage {
    /// Cut the file to this share of its length (in thousandths).
    Truncate(u64),
    /// Flip one bit at this share of its length (in thousandths).
    Flip(u64, u8),
}

fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        (0u64..1000).prop_map(Damage::Truncate),
        ((0u64..1000), (0u8..8)).prop_map(|(at, bit)| Damage::Flip(at, bit)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Whatever is cut or flipped in a segment, `open` succeeds and what comes back is whole
    /// records, in order, at most one of them popped before.
    #[test]
    fn a_damaged_segment_opens_and_gives_whole_records_in_order(
        count in 1u32..40,
        pops in 0u32..40,
        file in 0usize..8,
        damage in damage(),
    ) {
        let dir = TempDir::new("damage");
        let config = config(0, &dir.0, 2400);
        let mut store = Store::open(config.clone()).unwrap();
        for i in 0..count {
            prop_assert_eq!(store.push(record(i, i as usize % 20)).unwrap(), Pushed::Disk);
        }
        let pops = pops.min(count);
        for _ in 0..pops {
            store.pop().unwrap();
        }
        crash(store);
        let files = segments(&dir.0);
        if let Some(path) = files.get(file % files.len().max(1)) {
            let mut bytes = fs::read(path).unwrap();
            let len = bytes.len() as u64;
            match damage {
                Damage::Truncate(share) => {
                    bytes.truncate(usize::try_from(len * share / 1000).unwrap());
                }
                Damage::Flip(share, bit) => {
                    bytes[usize::try_from(len * share / 1000).unwrap()] ^= 1 << bit;
                }
            }
            fs::write(path, &bytes).unwrap();
        }
        let mut store = Store::open(config).unwrap();
        let recovered = store.stats().recovered;
        let back = drain(&mut store);
        prop_assert_eq!(back.len() as u64, recovered);
        let ids: Vec<u32> = back.iter().map(|r| id(r)).collect();
        prop_assert!(ids.windows(2).all(|w| w[0] < w[1]), "in order: {:?}", ids);
        for (i, r) in ids.iter().zip(&back) {
            prop_assert_eq!(r, &record(*i, *i as usize % 20));
            prop_assert!(*i < count && *i + 1 >= pops, "record {} after {} pops", i, pops);
        }
    }
}

#[test]
fn damage_in_records_already_popped_does_not_matter() {
    let dir = TempDir::new("popped");
    let mut store = Store::open(config(0, &dir.0, 10_000)).unwrap();
    for i in 0..3 {
        store.push(record(i, 4)).unwrap();
    }
    store.pop().unwrap();
    crash(store);
    let seg = segments(&dir.0).remove(0);
    let mut bytes = fs::read(&seg).unwrap();
    bytes[usize::try_from(HEADER_LEN).unwrap() + 9] ^= 0xFF;
    fs::write(&seg, &bytes).unwrap();
    let mut store = Store::open(config(0, &dir.0, 10_000)).unwrap();
    assert_eq!(store.stats().truncated, 0);
    assert_eq!(drain(&mut store), [record(1, 4), record(2, 4)]);
}

#[test]
fn dropping_the_store_saves_memory_like_close_and_it_moves_between_tasks() {
    fn send<T: Send>(_: &T) {}
    let dir = TempDir::new("drop");
    let mut store = Store::open(config(100, &dir.0, 10_000)).unwrap();
    send(&store);
    store.push(record(1, 0)).unwrap();
    store.push(record(2, 0)).unwrap();
    drop(store);
    let mut store = Store::open(config(100, &dir.0, 10_000)).unwrap();
    assert_eq!(drain(&mut store), [record(1, 0), record(2, 0)]);
}
