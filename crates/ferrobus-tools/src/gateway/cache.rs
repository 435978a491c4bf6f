//! The read cache (`--cache-max-age`): replies to reads (0x01-0x04) kept for a bounded age,
//! so that many pollers of the same values load the bus once.
//!
//! An entry is keyed by the unit and the request PDU exactly (same start, same quantity).
//! A write that succeeds drops every cached read of its unit whose table and addresses it
//! touches (coils for 0x05/0x0F, holding registers for 0x06/0x10/0x16/0x17), so that a read
//! after the write's reply never sees the value from before it. Discrete inputs and input
//! registers change on their own and are only bounded by the age.

use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use ferrobus_proto::pdu::{AddressRange, Request};

/// The cache of one gateway.
pub(crate) struct Cache {
    max_age: Duration,
    entries: Mutex<HashMap<(u8, Vec<u8>), Entry>>,
}

struct Entry {
    /// The read's function code (its table) and addresses.
    function: u8,
    range: AddressRange,
    reply: Vec<u8>,
    at: tokio::time::Instant,
}

/// The bound on the entries kept: past it, expired ones are swept before a new one goes in,
/// and if all are fresh the new one is not kept.
const MAX_ENTRIES: usize = 4096;

impl Cache {
    pub(crate) fn new(max_age: Duration) -> Self {
        Cache { max_age, entries: Mutex::new(HashMap::new()) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<(u8, Vec<u8>), Entry>> {
        self.entries.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The cached reply to `pdu` for `unit`, if one is younger than the bound.
    pub(crate) fn get(&self, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        if !is_read(pdu) {
            return None;
        }
        let entries = self.lock();
        let entry = entries.get(&(unit, pdu.to_vec()))?;
        (entry.at.elapsed() < self.max_age).then(|| entry.reply.clone())
    }

    /// Notes that `pdu` to `unit` was answered with `reply` (not an exception): a read is
    /// kept, a write drops what it touches.
    pub(crate) fn update(&self, unit: u8, pdu: &[u8], reply: &[u8]) {
        let Ok(request) = Request::parse(pdu) else { return };
        let Some(&function) = pdu.first() else { return };
        if is_read(pdu) {
            let Some(range) = request.address_ranges()[0] else { return };
            let mut entries = self.lock();
            if entries.len() >= MAX_ENTRIES {
                let max_age = self.max_age;
                entries.retain(|_, e| e.at.elapsed() < max_age);
                if entries.len() >= MAX_ENTRIES {
                    return;
                }
            }
            let entry = Entry { function, range, reply: reply.to_vec(), at: tokio::time::Instant::now() };
            entries.insert((unit, pdu.to_vec()), entry);
            return;
        }
        let table = match function {
            0x05 | 0x0F => 0x01,
            0x06 | 0x10 | 0x16 | 0x17 => 0x03,
            _ => return,
        };
        // 0x17 reads and writes: its write range is the second.
        let ranges = request.address_ranges();
        let written = if function == 0x17 { ranges[1] } else { ranges[0] };
        let Some(written) = written else { return };
        self.lock().retain(|(u, _), e| !(*u == unit && e.function == table && e.range.overlaps(&written)));
    }
}

fn is_read(pdu: &[u8]) -> bool {
    matches!(pdu.first(), Some(0x01..=0x04))
}

#[cfg(test)]
mod tests {
    use super::*;

    const READ_0_10: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x0A];
    const REPLY: [u8; 4] = [0x03, 0x02, 0x12, 0x34];

    #[tokio::test(start_paused = true)]
    async fn a_read_is_answered_from_the_cache_until_it_is_as_old_as_the_bound() {
        let cache = Cache::new(Duration::from_millis(100));
        assert_eq!(cache.get(1, &READ_0_10), None);
        cache.update(1, &READ_0_10, &REPLY);
        assert_eq!(cache.get(1, &READ_0_10).as_deref(), Some(&REPLY[..]));
        assert_eq!(cache.get(2, &READ_0_10), None, "another unit");
        tokio::time::advance(Duration::from_millis(99)).await;
        assert!(cache.get(1, &READ_0_10).is_some());
        tokio::time::advance(Duration::from_millis(1)).await;
        assert_eq!(cache.get(1, &READ_0_10), None);
    }

    #[tokio::test(start_paused = true)]
    async fn a_write_drops_the_cached_reads_it_touches_and_no_others() {
        let cache = Cache::new(Duration::from_secs(10));
        let coils = [0x01, 0x00, 0x00, 0x00, 0x0A];
        let far = [0x03, 0x00, 0x20, 0x00, 0x01];
        for pdu in [READ_0_10, coils, far] {
            cache.update(1, &pdu, &REPLY);
        }
        // FC06 to register 9: inside 0..=9 of the holding registers, not coils, not 0x20.
        cache.update(1, &[0x06, 0x00, 0x09, 0x00, 0x01], &[0x06, 0x00, 0x09, 0x00, 0x01]);
        assert_eq!(cache.get(1, &READ_0_10), None);
        assert!(cache.get(1, &coils).is_some());
        assert!(cache.get(1, &far).is_some());
        // FC05 to coil 3 drops the coil read.
        cache.update(1, &[0x05, 0x00, 0x03, 0xFF, 0x00], &[0x05, 0x00, 0x03, 0xFF, 0x00]);
        assert_eq!(cache.get(1, &coils), None);
        assert!(cache.get(1, &far).is_some());
    }
}
