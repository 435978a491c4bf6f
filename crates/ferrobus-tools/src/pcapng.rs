//! Capture files of an RTU line that Wireshark and tshark decode as Modbus RTU with no setup
//! beyond one preference: pcapng (draft-ietf-opsawg-pcapng), one interface of link type 252
//! (`LINKTYPE_WIRESHARK_UPPER_PDU`, "exported PDU").
//!
//! Each frame is an Enhanced Packet Block whose data is a list of exported-PDU tags
//! (wireshark's `wsutil/exported_pdu_tlvs.h`: 2-byte big-endian type and length, the value,
//! an end tag) and then the frame as heard, CRC included, good or bad:
//!
//! - tag 12, the dissector name `mbrtu`;
//! - tags 24, 25, 26: port type UDP, source and destination port: a request goes from port
//!   50000 to port [`RTU_PORT`] (5020), a response from 5020 to 50000. The `mbrtu` dissector
//!   tells a query from a response by these ports only (not by the direction flags), and
//!   without them has to guess, which it cannot for the echoes of 0x05, 0x06 and others.
//!
//! The interface has nanosecond timestamps (`if_tsresol` = 9); a frame's timestamp is when its
//! last character ended. The block's `epb_flags` say the direction for people (a request
//! outbound from the master, a response inbound), and a comment (`opt_comment`) says what was
//! wrong on the line: a bad CRC, a short silence before the frame, a gap inside it. Bytes that
//! are not a frame (noise, a frame cut short) are written with the `data` dissector and a
//! comment saying what they are.
//!
//! Decode a file with
//! `tshark -r cap.pcapng -o mbrtu.crc_verification:TRUE -o mbrtu.tcp.port:5020`.
//! Every block is written whole with one `write_all`, and flushed when asked
//! ([`PcapngWriter::flush_each`]), so that a reader on a pipe (`| tshark -i -`) gets each
//! frame as it comes.

use std::io::{self, Write};

/// The port a request goes to, and a response comes from.
pub const RTU_PORT: u32 = 5020;

/// The port a request comes from, and a response goes to.
pub const MASTER_PORT: u32 = 50_000;

/// `LINKTYPE_WIRESHARK_UPPER_PDU`.
pub const LINKTYPE_UPPER_PDU: u16 = 252;

const SHB: u32 = 0x0A0D_0D0A;
const IDB: u32 = 0x0000_0001;
const EPB: u32 = 0x0000_0006;
const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;

const OPT_END: u16 = 0;
const OPT_COMMENT: u16 = 1;
const SHB_USERAPPL: u16 = 4;
const IF_NAME: u16 = 2;
const IF_DESCRIPTION: u16 = 3;
const IF_TSRESOL: u16 = 9;
const EPB_FLAGS: u16 = 2;

const TAG_END: u16 = 0;
const TAG_DISSECTOR_NAME: u16 = 12;
const TAG_DISSECTOR_TABLE_NAME: u16 = 14;
const TAG_DISSECTOR_TABLE_VALUE: u16 = 32;
const TAG_PORT_TYPE: u16 = 24;
const TAG_SRC_PORT: u16 = 25;
const TAG_DST_PORT: u16 = 26;
const PORT_TYPE_UDP: u32 = 3;

/// `epb_flags` bits 0–1: inbound.
const INBOUND: u32 = 0b01;
/// `epb_flags` bits 0–1: outbound.
const OUTBOUND: u32 = 0b10;

/// What a packet holds.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Content {
    /// A request frame, from the master.
    Request,
    /// A response frame, from a slave.
    Response,
    /// Bytes that are not a frame: noise, a frame cut short.
    Other,
}

/// One packet: what was heard, when, and what was wrong with it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Packet<'a> {
    /// Nanoseconds since the Unix epoch at which its last character ended.
    pub timestamp_ns: u64,
    /// The bytes, CRC included.
    pub bytes: &'a [u8],
    /// Request, response or neither.
    pub content: Content,
    /// What was wrong on the line, for `frame.comment`.
    pub comment: Option<&'a str>,
}

/// A pcapng stream being written: a section header and one interface, then packets.
#[derive(Debug)]
pub struct PcapngWriter<W: Write> {
    out: W,
    flush_each: bool,
}

impl<W: Write> PcapngWriter<W> {
    /// Writes the section header and the interface (`name`, e.g. `ttyUSB0`, and
    /// `description`, e.g. `RS-485 9600 8E1`) to `out`.
    pub fn new(mut out: W, name: &str, description: &str) -> io::Result<Self> {
        let mut shb = Vec::new();
        put_u32(&mut shb, BYTE_ORDER_MAGIC);
        put_u16(&mut shb, 1);
        put_u16(&mut shb, 0);
        // Section length: not given.
        shb.extend_from_slice(&u64::MAX.to_le_bytes());
        put_option(&mut shb, SHB_USERAPPL, concat!("ferrobus ", env!("CARGO_PKG_VERSION")).as_bytes());
        put_option(&mut shb, OPT_END, &[]);
        out.write_all(&block(SHB, &shb))?;
        let mut idb = Vec::new();
        put_u16(&mut idb, LINKTYPE_UPPER_PDU);
        put_u16(&mut idb, 0);
        // Snap length: no limit.
        put_u32(&mut idb, 0);
        put_option(&mut idb, IF_NAME, name.as_bytes());
        put_option(&mut idb, IF_DESCRIPTION, description.as_bytes());
        put_option(&mut idb, IF_TSRESOL, &[9]);
        put_option(&mut idb, OPT_END, &[]);
        out.write_all(&block(IDB, &idb))?;
        out.flush()?;
        Ok(PcapngWriter { out, flush_each: false })
    }

    /// Flushes after every packet (for a pipe to a live reader); off by default.
    #[must_use]
    pub fn flush_each(mut self, on: bool) -> Self {
        self.flush_each = on;
        self
    }

    /// Writes one packet.
    pub fn write(&mut self, packet: &Packet<'_>) -> io::Result<()> {
        let data = exported_pdu(packet);
        let len = u32::try_from(data.len()).map_err(|_| io::Error::other("packet too long for pcapng"))?;
        let mut epb = Vec::with_capacity(data.len().saturating_add(64));
        put_u32(&mut epb, 0);
        // The timestamp's high word, then its low word.
        put_u32(&mut epb, u32::try_from(packet.timestamp_ns >> 32).unwrap_or(u32::MAX));
        put_u32(&mut epb, u32::try_from(packet.timestamp_ns & 0xFFFF_FFFF).unwrap_or(u32::MAX));
        put_u32(&mut epb, len);
        put_u32(&mut epb, len);
        epb.extend_from_slice(&data);
        pad(&mut epb);
        match packet.content {
            Content::Request => put_option(&mut epb, EPB_FLAGS, &OUTBOUND.to_le_bytes()),
            Content::Response => put_option(&mut epb, EPB_FLAGS, &INBOUND.to_le_bytes()),
            Content::Other => {}
        }
        if let Some(comment) = packet.comment {
            put_option(&mut epb, OPT_COMMENT, comment.as_bytes());
        }
        put_option(&mut epb, OPT_END, &[]);
        self.out.write_all(&block(EPB, &epb))?;
        if self.flush_each {
            self.out.flush()?;
        }
        Ok(())
    }

    /// Flushes what is buffered.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// The stream written to.
    pub fn into_inner(self) -> W {
        self.out
    }
}

/// A packet's data: the exported-PDU tags, then its bytes.
fn exported_pdu(packet: &Packet<'_>) -> Vec<u8> {
    let mut data = Vec::with_capacity(packet.bytes.len().saturating_add(48));
    let (dissector, ports): (&[u8], _) = match packet.content {
        Content::Request => (b"mbrtu", Some((MASTER_PORT, RTU_PORT))),
        Content::Response => (b"mbrtu", Some((RTU_PORT, MASTER_PORT))),
        Content::Other => (b"data", None),
    };
    // A string value may carry NULs at its end, counted in its length: padded to 32 bits.
    let padded = |s: &[u8]| {
        let mut v = s.to_vec();
        pad(&mut v);
        v
    };
    if ports.is_some() && packet.bytes.first() == Some(&0) {
        // The `mbrtu` dissector refuses unit 0; the one on UDP ports takes it.
        put_tag(&mut data, TAG_DISSECTOR_TABLE_NAME, &padded(b"udp.port"));
        put_tag(&mut data, TAG_DISSECTOR_TABLE_VALUE, &RTU_PORT.to_be_bytes());
    } else {
        put_tag(&mut data, TAG_DISSECTOR_NAME, &padded(dissector));
    }
    if let Some((src, dst)) = ports {
        put_tag(&mut data, TAG_PORT_TYPE, &PORT_TYPE_UDP.to_be_bytes());
        put_tag(&mut data, TAG_SRC_PORT, &src.to_be_bytes());
        put_tag(&mut data, TAG_DST_PORT, &dst.to_be_bytes());
    }
    put_tag(&mut data, TAG_END, &[]);
    data.extend_from_slice(packet.bytes);
    data
}

/// An exported-PDU tag: type and length big-endian, then the value.
fn put_tag(out: &mut Vec<u8>, tag: u16, value: &[u8]) {
    out.extend_from_slice(&tag.to_be_bytes());
    out.extend_from_slice(&u16::try_from(value.len()).unwrap_or(u16::MAX).to_be_bytes());
    out.extend_from_slice(value);
}

/// A block: type, total length, body, total length again.
fn block(kind: u32, body: &[u8]) -> Vec<u8> {
    let total = u32::try_from(body.len().saturating_add(12)).unwrap_or(u32::MAX);
    let mut out = Vec::with_capacity(body.len().saturating_add(12));
    put_u32(&mut out, kind);
    put_u32(&mut out, total);
    out.extend_from_slice(body);
    put_u32(&mut out, total);
    out
}

/// A pcapng option: code and length (little-endian, as the section), the value padded to 32
/// bits.
fn put_option(out: &mut Vec<u8>, code: u16, value: &[u8]) {
    put_u16(out, code);
    put_u16(out, u16::try_from(value.len()).unwrap_or(u16::MAX));
    out.extend_from_slice(value);
    pad(out);
}

fn pad(out: &mut Vec<u8>) {
    while !out.len().is_multiple_of(4) {
        out.push(0);
    }
}

fn put_u16(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn u32_at(bytes: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
    }

    /// Splits a stream into its blocks (type, body), checking both length fields.
    fn blocks(bytes: &[u8]) -> Vec<(u32, Vec<u8>)> {
        let mut out = Vec::new();
        let mut at = 0;
        while at < bytes.len() {
            let (kind, total) = (u32_at(bytes, at), u32_at(bytes, at + 4) as usize);
            assert_eq!(total % 4, 0, "block at {at} is not 32-bit aligned");
            assert_eq!(u32_at(bytes, at + total - 4) as usize, total, "trailing length of the block at {at}");
            out.push((kind, bytes[at + 8..at + total - 4].to_vec()));
            at += total;
        }
        out
    }

    #[test]
    fn a_capture_is_a_section_an_upper_pdu_interface_in_nanoseconds_and_one_block_per_packet() {
        let mut w = PcapngWriter::new(Vec::new(), "ttyUSB0", "RS-485 9600 8E1").unwrap();
        let frame = [0x01, 0x06, 0x00, 0x05, 0x12, 0x34, 0x95, 0x3A];
        let at = 1_700_000_000_012_000_123u64;
        w.write(&Packet { timestamp_ns: at, bytes: &frame, content: Content::Request, comment: Some("CRC error") })
            .unwrap();
        let out = w.into_inner();
        let blocks = blocks(&out);
        assert_eq!(blocks.iter().map(|b| b.0).collect::<Vec<_>>(), [SHB, IDB, EPB]);
        assert_eq!(u32_at(&blocks[0].1, 0), BYTE_ORDER_MAGIC);
        let idb = &blocks[1].1;
        assert_eq!(u16::from_le_bytes([idb[0], idb[1]]), 252);
        // if_name, if_description, then if_tsresol = 9.
        let tsresol = [IF_TSRESOL.to_le_bytes(), 1u16.to_le_bytes()].concat();
        let found = idb.windows(5).position(|w| w[..4] == tsresol[..]).unwrap();
        assert_eq!(idb[found + 4], 9);
        let epb = &blocks[2].1;
        assert_eq!(u64::from(u32_at(epb, 4)) << 32 | u64::from(u32_at(epb, 8)), at);
        let len = u32_at(epb, 12) as usize;
        let data = &epb[20..20 + len];
        let tags: &[u8] = &[
            0, 12, 0, 8, b'm', b'b', b'r', b't', b'u', 0, 0, 0, // the dissector
            0, 24, 0, 4, 0, 0, 0, 3, // UDP
            0, 25, 0, 4, 0, 0, 0xC3, 0x50, // from 50000
            0, 26, 0, 4, 0, 0, 0x13, 0x9C, // to 5020
            0, 0, 0, 0, // end
        ];
        assert_eq!(&data[..tags.len()], tags);
        assert_eq!(&data[tags.len()..], frame);
        let options = &epb[20 + len.next_multiple_of(4)..];
        assert_eq!(&options[..8], [2, 0, 4, 0, 0b10, 0, 0, 0], "epb_flags: outbound");
        assert_eq!(&options[8..12], [1, 0, 9, 0], "a 9-byte comment");
        assert_eq!(&options[12..21], b"CRC error");
    }

    #[test]
    fn a_response_goes_from_the_rtu_port_inbound_and_noise_to_the_data_dissector_without_ports() {
        let mut w = PcapngWriter::new(Vec::new(), "tap", "line").unwrap();
        w.write(&Packet {
            timestamp_ns: 1,
            bytes: &[1, 0x83, 2, 0xC0, 0xF1],
            content: Content::Response,
            comment: None,
        })
        .unwrap();
        w.write(&Packet { timestamp_ns: 2, bytes: &[0xFF], content: Content::Other, comment: Some("noise") }).unwrap();
        let blocks = blocks(&w.into_inner());
        let response = &blocks[2].1;
        assert_eq!(&response[20 + 20..20 + 36], [0, 25, 0, 4, 0, 0, 0x13, 0x9C, 0, 26, 0, 4, 0, 0, 0xC3, 0x50]);
        let noise = &blocks[3].1;
        assert_eq!(&noise[20..32], [0, 12, 0, 4, b'd', b'a', b't', b'a', 0, 0, 0, 0]);
        assert_eq!(noise[32], 0xFF);
    }

    #[test]
    fn a_broadcast_goes_through_the_udp_port_table_whose_rtu_dissector_takes_unit_0() {
        let mut w = PcapngWriter::new(Vec::new(), "tap", "line").unwrap();
        let broadcast = [0, 0x06, 0, 5, 0, 7, 0xD9, 0xD8];
        w.write(&Packet { timestamp_ns: 1, bytes: &broadcast, content: Content::Request, comment: None }).unwrap();
        let blocks = blocks(&w.into_inner());
        let epb = &blocks[2].1;
        let tags: &[u8] = &[
            0, 14, 0, 8, b'u', b'd', b'p', b'.', b'p', b'o', b'r', b't', // the table
            0, 32, 0, 4, 0, 0, 0x13, 0x9C, // its key: 5020
            0, 24, 0, 4, 0, 0, 0, 3, // then the ports, as for any request
        ];
        assert_eq!(&epb[20..20 + tags.len()], tags);
    }
}
