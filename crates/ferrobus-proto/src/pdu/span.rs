//! The addresses a request touches: what a fault rule, a log line or an access check matches
//! a request by. Function codes without addresses (diagnostics, identification, file records
//! by file and record) touch none.

use super::Request;

/// An inclusive range of item addresses (coils, inputs or registers, by the function code).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct AddressRange {
    first: u16,
    last: u16,
}

impl AddressRange {
    /// `first` to `last` inclusive, if `first <= last`.
    pub const fn new(first: u16, last: u16) -> Option<Self> {
        if first <= last { Some(AddressRange { first, last }) } else { None }
    }

    /// `quantity` items from `start`, if there is at least one and they fit below 0x10000.
    pub fn from_quantity(start: u16, quantity: u16) -> Option<Self> {
        let last = start.checked_add(quantity.checked_sub(1)?)?;
        Some(AddressRange { first: start, last })
    }

    /// The first address.
    pub const fn first(&self) -> u16 {
        self.first
    }

    /// The last address.
    pub const fn last(&self) -> u16 {
        self.last
    }

    /// Whether the two ranges share an address.
    pub const fn overlaps(&self, other: &AddressRange) -> bool {
        self.first <= other.last && other.first <= self.last
    }
}

impl Request<'_> {
    /// The addresses the request touches: one range, or two for 0x17 (the read, then the
    /// write), or none for function codes without addresses.
    pub fn address_ranges(&self) -> [Option<AddressRange>; 2] {
        let one = |start: u16, quantity: u16| [AddressRange::from_quantity(start, quantity), None];
        let single = |address: u16| [Some(AddressRange { first: address, last: address }), None];
        let len = |n: usize| u16::try_from(n).unwrap_or(u16::MAX);
        match self {
            Request::ReadCoils(r) | Request::ReadDiscreteInputs(r) => one(r.start(), r.quantity()),
            Request::ReadHoldingRegisters(r) | Request::ReadInputRegisters(r) => one(r.start(), r.quantity()),
            Request::WriteSingleCoil(w) => single(w.address),
            Request::WriteSingleRegister(w) => single(w.address),
            Request::WriteMultipleCoils(w) => one(w.start(), w.quantity()),
            Request::WriteMultipleRegisters(w) => one(w.start(), w.quantity()),
            Request::MaskWriteRegister(m) => single(m.address),
            Request::ReadWriteMultipleRegisters(rw) => [
                AddressRange::from_quantity(rw.read().start(), rw.read().quantity()),
                AddressRange::from_quantity(rw.write_start(), len(rw.values().len())),
            ],
            Request::ReadFifoQueue(f) => single(f.address),
            _ => [None, None],
        }
    }

    /// Whether the request touches an address in `range`.
    pub fn touches(&self, range: &AddressRange) -> bool {
        self.address_ranges().iter().flatten().any(|r| r.overlaps(range))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn range(first: u16, last: u16) -> AddressRange {
        AddressRange::new(first, last).unwrap()
    }

    #[test]
    fn a_read_touches_start_to_start_plus_quantity_minus_one() {
        // 01 03 1000 0010: 16 holding registers from 0x1000.
        let pdu = [0x03, 0x10, 0x00, 0x00, 0x10];
        let request = Request::parse(&pdu).unwrap();
        assert_eq!(request.address_ranges(), [Some(range(0x1000, 0x100F)), None]);
        assert!(request.touches(&range(0x100F, 0x2000)));
        assert!(request.touches(&range(0x0000, 0x1000)));
        assert!(!request.touches(&range(0x1010, 0x1010)));
        assert!(!request.touches(&range(0x0000, 0x0FFF)));
    }

    #[test]
    fn single_writes_mask_write_and_fifo_touch_one_address() {
        for pdu in [
            &[0x05, 0x00, 0x07, 0xFF, 0x00][..],
            &[0x06, 0x00, 0x07, 0x12, 0x34],
            &[0x16, 0x00, 0x07, 0x00, 0xF2, 0x00, 0x25],
            &[0x18, 0x00, 0x07],
        ] {
            let request = Request::parse(pdu).unwrap();
            assert_eq!(request.address_ranges(), [Some(range(7, 7)), None], "{pdu:02X?}");
        }
    }

    #[test]
    fn multiple_writes_touch_their_quantity() {
        let coils = Request::parse(&[0x0F, 0x00, 0x13, 0x00, 0x0A, 0x02, 0xCD, 0x01]).unwrap();
        assert_eq!(coils.address_ranges(), [Some(range(0x13, 0x1C)), None]);
        let registers = Request::parse(&[0x10, 0xFF, 0xFE, 0x00, 0x02, 0x04, 0, 1, 0, 2]).unwrap();
        assert_eq!(registers.address_ranges(), [Some(range(0xFFFE, 0xFFFF)), None]);
    }

    #[test]
    fn read_write_registers_touch_the_read_and_the_write() {
        // Read 6 from 3, write 3 from 14 (§6.17's example).
        let pdu = [0x17, 0x00, 0x03, 0x00, 0x06, 0x00, 0x0E, 0x00, 0x03, 0x06, 0, 0xFF, 0, 0xFF, 0, 0xFF];
        let request = Request::parse(&pdu).unwrap();
        assert_eq!(request.address_ranges(), [Some(range(3, 8)), Some(range(14, 16))]);
        assert!(request.touches(&range(16, 20)));
        assert!(!request.touches(&range(9, 13)));
    }

    #[test]
    fn requests_without_addresses_touch_nothing() {
        for pdu in [&[0x07][..], &[0x11], &[0x08, 0x00, 0x00, 0x12, 0x34], &[0x2B, 0x0E, 0x01, 0x00]] {
            let request = Request::parse(pdu).unwrap();
            assert_eq!(request.address_ranges(), [None, None], "{pdu:02X?}");
            assert!(!request.touches(&range(0, u16::MAX)));
        }
    }

    #[test]
    fn ranges_are_checked_when_made() {
        assert_eq!(AddressRange::new(5, 4), None);
        assert_eq!(AddressRange::from_quantity(0, 0), None);
        assert_eq!(AddressRange::from_quantity(0xFFFF, 2), None);
        assert_eq!(AddressRange::from_quantity(0xFFFF, 1), Some(range(0xFFFF, 0xFFFF)));
        assert!(range(0, 0).overlaps(&range(0, 0)));
        assert!(!range(0, 0).overlaps(&range(1, 1)));
    }
}
