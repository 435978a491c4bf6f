//! A store record: what would have been published while the broker was away, written so that
//! it means the same after a restart of the bridge (the store keeps records on disk).
//!
//! ```text
//!   "FBe" | version 1 | kind | id length (u16, big endian) | id (UTF-8) | body
//!   kind b'S': id = the device id, body = a Sparkplug Payload whose metrics carry names,
//!              datatypes, values and timestamps (no aliases: those belong to a session)
//!   kind b'P': id = the plain-mode topic, body = its JSON message
//! ```

/// The record's first bytes.
const MAGIC: &[u8; 3] = b"FBe";
/// The record layout's version.
const VERSION: u8 = 1;

/// A decoded store record.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum Record {
    /// A Sparkplug device's data, by metric name.
    Sparkplug {
        /// The device id.
        device: String,
        /// The encoded Payload.
        payload: Vec<u8>,
    },
    /// A plain-mode message.
    Plain {
        /// The topic.
        topic: String,
        /// The JSON message.
        payload: Vec<u8>,
    },
}

impl Record {
    /// The record's bytes.
    pub(crate) fn encode(&self) -> Vec<u8> {
        let (kind, id, body) = match self {
            Record::Sparkplug { device, payload } => (b'S', device, payload),
            Record::Plain { topic, payload } => (b'P', topic, payload),
        };
        // An id longer than 64 KiB is cut at a character boundary (ids are short names).
        let mut end = id.len().min(usize::from(u16::MAX));
        while !id.is_char_boundary(end) {
            end -= 1;
        }
        let id = id.get(..end).unwrap_or_default();
        let len = u16::try_from(id.len()).unwrap_or(u16::MAX);
        let mut out = Vec::with_capacity(MAGIC.len() + 4 + id.len() + body.len());
        out.extend_from_slice(MAGIC);
        out.push(VERSION);
        out.push(kind);
        out.extend_from_slice(&len.to_be_bytes());
        out.extend_from_slice(id.as_bytes());
        out.extend_from_slice(body);
        out
    }

    /// The record in `bytes`, or what is wrong with them.
    pub(crate) fn decode(bytes: &[u8]) -> Result<Record, String> {
        let head =
            bytes.get(..MAGIC.len() + 4).ok_or_else(|| format!("{} bytes, too short for a record", bytes.len()))?;
        let (magic, rest) = head.split_at(MAGIC.len());
        if magic != MAGIC {
            return Err(format!("starts with {magic:02x?}, not a ferrobus edge record"));
        }
        let [version, kind, hi, lo] = [rest[0], rest[1], rest[2], rest[3]];
        if version != VERSION {
            return Err(format!("record version {version}; this bridge reads version {VERSION}"));
        }
        let len = usize::from(u16::from_be_bytes([hi, lo]));
        let from = MAGIC.len() + 4;
        let id = bytes
            .get(from..from + len)
            .ok_or_else(|| format!("the id takes {len} bytes, {} are left", bytes.len() - from))?;
        let id = std::str::from_utf8(id).map_err(|e| format!("the id is not UTF-8: {e}"))?.to_string();
        let body = bytes.get(from + len..).unwrap_or_default().to_vec();
        match kind {
            b'S' => Ok(Record::Sparkplug { device: id, payload: body }),
            b'P' => Ok(Record::Plain { topic: id, payload: body }),
            other => Err(format!("record kind {other:#04x}, neither Sparkplug (S) nor plain (P)")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip() {
        for record in [
            Record::Sparkplug { device: "drive1".into(), payload: vec![1, 2, 3] },
            Record::Plain { topic: "plant/drive1/F001".into(), payload: b"{}".to_vec() },
            Record::Plain { topic: String::new(), payload: Vec::new() },
        ] {
            assert_eq!(Record::decode(&record.encode()), Ok(record));
        }
    }

    #[test]
    fn foreign_or_cut_bytes_are_refused_with_what_was_seen() {
        let good = Record::Sparkplug { device: "drive1".into(), payload: vec![9] }.encode();
        for cut in 0..9 {
            assert!(Record::decode(&good[..cut]).is_err(), "{cut} bytes");
        }
        let mut other = good.clone();
        other[0] = b'X';
        assert!(Record::decode(&other).unwrap_err().contains("not a ferrobus edge record"));
        let mut version = good.clone();
        version[3] = 7;
        assert!(Record::decode(&version).unwrap_err().contains("version 7"));
        let mut kind = good;
        kind[4] = b'Z';
        assert!(Record::decode(&kind).unwrap_err().contains("0x5a"));
    }
}
