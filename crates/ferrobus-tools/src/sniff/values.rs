//! What a bus's own master reads and writes, as named values: a paired read reply, or an
//! acknowledged write, decoded through a device's profile as a poll decodes its reply.
//!
//! ```text
//!   BusEvent ──Pairing::take──▶ Heard { unit, table, start, items, time }
//!                                  │ Heard::group(profile): every point it holds wholly
//!                                  └ Heard::sample(index, seq, group) ──▶ poll::Sample (Group::readings)
//! ```
//!
//! - A read (0x01, 0x02, 0x03, 0x04) is heard in its reply, paired by the core's sniffer
//!   with the request it answers: the request gives the table, the start and the count, the
//!   reply the items. A write (0x05, 0x06, 0x0F, 0x10) is heard in its request once the
//!   device has acknowledged it (the reply echoes the address, and the start and count): the
//!   items are what the master wrote.
//! - An exception, a frame with a bad CRC, a reply paired with no request, a request never
//!   answered and a broadcast (nothing acknowledges it) give nothing.
//! - A point is decoded only if every one of its registers (or its bit) is in the range heard:
//!   a point only partly covered is left out. The decoding is the poller's
//!   ([`Group::readings`]): scaling, word order, enumerations, units, and a value the profile
//!   marks as not implemented shown as [`ferrobus_profile::NOT_IMPLEMENTED`], never as a
//!   reading.
//! - The time of a value is the reply's end on the wire, as the listener stamped it.
//!
//! Nothing here does IO: the events come from a [`super::Listener`], or a test.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use ferrobus_profile::{Profile, Table};
use ferrobus_proto::FunctionCode;
use ferrobus_proto::Instant;
use ferrobus_proto::pdu::{Request, Response};
use ferrobus_proto::sniff::Role;

use super::BusEvent;
use crate::poll::{Cell, Group, Sample, Traffic, items};

/// What a device's memory was seen to hold: the items of a read reply, or of a write the
/// device acknowledged.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Heard {
    /// The unit that answered.
    pub unit: u8,
    /// The table.
    pub table: Table,
    /// The first wire address.
    pub start: u16,
    /// The items from `start`: registers, or bits as 0 and 1.
    pub items: Vec<u16>,
    /// Whether they were written by the master (and acknowledged) rather than read.
    pub written: bool,
    /// When the reply ended on the wire.
    pub time: SystemTime,
    /// From the request's end to the reply's.
    pub response_time: Duration,
    /// The request and the reply, each as unit and PDU.
    pub traffic: Traffic,
}

/// The last request heard, waiting for its reply.
#[derive(Clone, Debug)]
struct Asked {
    /// The ADU, CRC included.
    bytes: Vec<u8>,
    /// When it ended on the wire.
    end: Instant,
}

/// Turns the sniffer's events into what the devices' memory holds: keeps the last request
/// and takes its reply.
#[derive(Clone, Debug, Default)]
pub struct Pairing {
    asked: Option<Asked>,
}

impl Pairing {
    /// A pairing that has heard nothing.
    pub fn new() -> Self {
        Pairing::default()
    }

    /// Takes the next event, in the order heard; a reply that completes a read or a write
    /// gives what it says the device holds.
    pub fn take(&mut self, event: &BusEvent) -> Option<Heard> {
        match event {
            BusEvent::Frame { bytes, role: Role::Request, crc_ok, time, .. } => {
                self.asked = crc_ok.then(|| Asked { bytes: bytes.clone(), end: time.end });
                None
            }
            BusEvent::Frame { bytes, role: Role::Response, crc_ok, time, response_time } => {
                let asked = self.asked.take()?;
                let response_time = (*response_time).filter(|_| *crc_ok)?;
                // The core paired this reply with the request that ended response_time before it.
                if time.end.saturating_duration_since(asked.end) != response_time {
                    return None;
                }
                let mut heard = heard(&asked.bytes, bytes)?;
                heard.time = UNIX_EPOCH + Duration::from_nanos(time.end.as_nanos());
                heard.response_time = response_time;
                Some(heard)
            }
            BusEvent::Unanswered { .. } => {
                self.asked = None;
                None
            }
            BusEvent::Fragment { .. } => None,
        }
    }
}

/// Unit and PDU of an ADU: without its CRC.
fn unit_pdu(adu: &[u8]) -> Option<(u8, &[u8])> {
    let (&unit, rest) = adu.split_first()?;
    Some((unit, rest.get(..rest.len().checked_sub(2)?)?))
}

/// What request `asked` and its reply `reply` (ADUs with good CRCs) say the device holds.
fn heard(asked: &[u8], reply: &[u8]) -> Option<Heard> {
    let (unit, request_pdu) = unit_pdu(asked)?;
    let (replier, reply_pdu) = unit_pdu(reply)?;
    let function = *reply_pdu.first()?;
    if replier != unit || function & FunctionCode::EXCEPTION_BIT != 0 || request_pdu.first() != Some(&function) {
        return None;
    }
    let request = Request::parse(request_pdu).ok()?;
    let response = Response::parse(reply_pdu).ok()?;
    let read = |table: Table, start: u16, count: u16| Some((table, start, items(reply_pdu, count)?, false));
    let (table, start, items, written) = match (request, response) {
        (Request::ReadCoils(r), _) => read(Table::Coils, r.start(), r.quantity())?,
        (Request::ReadDiscreteInputs(r), _) => read(Table::DiscreteInputs, r.start(), r.quantity())?,
        (Request::ReadHoldingRegisters(r), _) => read(Table::Holding, r.start(), r.quantity())?,
        (Request::ReadInputRegisters(r), _) => read(Table::Input, r.start(), r.quantity())?,
        (Request::WriteSingleCoil(w), Response::WriteSingleCoil(echo)) if echo.address == w.address => {
            (Table::Coils, w.address, vec![u16::from(w.value)], true)
        }
        (Request::WriteSingleRegister(w), Response::WriteSingleRegister(echo)) if echo.address == w.address => {
            (Table::Holding, w.address, vec![w.value], true)
        }
        // A multiple write is acknowledged with its start and count.
        (Request::WriteMultipleCoils(w), Response::WriteMultipleCoils(echo)) => {
            let bits = w.values().iter().take(usize::from(w.quantity())).map(u16::from).collect();
            let echoed = (echo.start(), echo.quantity()) == (w.start(), w.quantity());
            echoed.then_some((Table::Coils, w.start(), bits, true))?
        }
        (Request::WriteMultipleRegisters(w), Response::WriteMultipleRegisters(echo)) => {
            let echoed = (echo.start(), echo.quantity()) == (w.start(), w.quantity());
            echoed.then(|| (Table::Holding, w.start(), w.values().iter().collect(), true))?
        }
        _ => return None,
    };
    let with_unit = |pdu: &[u8]| std::iter::once(unit).chain(pdu.iter().copied()).collect::<Vec<u8>>();
    Some(Heard {
        unit,
        table,
        start,
        items,
        written,
        time: UNIX_EPOCH,
        response_time: Duration::ZERO,
        traffic: Traffic { tx: with_unit(request_pdu), rx: Some(with_unit(reply_pdu)) },
    })
}

impl Heard {
    /// How many items were heard.
    pub fn count(&self) -> u16 {
        u16::try_from(self.items.len()).unwrap_or(u16::MAX)
    }

    /// Whether the items heard hold every register (or the bit) of `cell` (of `table`).
    fn holds(&self, table: Table, cell: &Cell) -> bool {
        let end = u32::from(self.start) + u32::from(self.count());
        table == self.table && cell.point.address >= self.start && cell.point.end() <= end
    }

    /// The group of every point of `profile` the items hold wholly (the readable ones of a
    /// read, any of a write), each once, named as the planner names its groups (`u1
    /// d001..d030`); `None` when they hold none.
    pub fn group(&self, profile: &Profile) -> Option<Group> {
        let mut cells: Vec<Cell> = Vec::new();
        for point in profile.points() {
            let cell = Cell::point(point);
            let fresh = !cells.iter().any(|c| c.point.address == point.address);
            if fresh && self.holds(point.table, &cell) && (self.written || point.readable()) {
                cells.push(cell);
            }
        }
        if cells.is_empty() {
            return None;
        }
        let name = crate::poll::name_of(self.unit, self.table, self.start, &cells);
        Some(Group {
            name,
            unit: self.unit,
            table: self.table,
            start: self.start,
            count: self.count(),
            every: Duration::ZERO,
            cells,
        })
    }

    /// What the items say of `group`'s cells, as a poll of it (number `index`, its `seq`th)
    /// would: the readings of the cells they hold wholly, each with its index in the group;
    /// `None` for a group of another unit or table, or none of whose cells they hold. Nothing
    /// was scheduled: `due` and `started` are zero, and it is never an overrun.
    pub fn sample(&self, index: usize, seq: u64, group: &Group) -> Option<Sample> {
        if group.unit != self.unit {
            return None;
        }
        let (at, cells): (Vec<usize>, Vec<Cell>) = group
            .cells
            .iter()
            .enumerate()
            .filter(|(_, c)| self.holds(group.table, c))
            .map(|(i, c)| (i, c.clone()))
            .unzip();
        if cells.is_empty() {
            return None;
        }
        let held = Group { start: self.start, count: self.count(), cells, ..group.clone() };
        let mut readings = held.readings(&self.items);
        for reading in &mut readings {
            reading.cell = at.get(reading.cell).copied().unwrap_or(reading.cell);
        }
        Some(Sample {
            group: index,
            seq,
            time: self.time,
            due: Duration::ZERO,
            started: Duration::ZERO,
            response_time: self.response_time,
            overrun: false,
            result: Ok(readings),
            traffic: self.traffic.clone(),
        })
    }
}

#[cfg(test)]
#[path = "values_tests.rs"]
mod tests;
