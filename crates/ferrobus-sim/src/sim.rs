//! The simulator: several devices on one line, each at its unit address, served through one
//! [`Handler`] — and the faults injected into their replies.

use std::collections::BTreeMap;
use std::time::Duration;

use ferrobus::Framing;
use ferrobus::server::{Answering, Fate, ReplyFilter, Shared};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::pdu::{AddressRange, Bits, MaskWrite, Registers, Request};
use ferrobus_proto::slave::{Admission, Handler, UnitSet};
use rand::rngs::SmallRng;
use rand::{RngExt, SeedableRng};

use crate::clock::SimClock;
use crate::device::Device;
use crate::fault::Faults;
use crate::memory::Table;
use crate::reframe::{corrupt_checksum, reframe, unit_of};
use crate::rule::Action;
use crate::ticker::{Ticker, TickerError};

/// One unit on the line.
pub struct Unit {
    /// The device.
    pub device: Device,
    /// What goes wrong with it.
    pub faults: Faults,
    tripped: bool,
}

/// What answers a request to a unit no device is at (the engine must pass such units on:
/// its [`UnitSet`] holds them).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Unserved {
    /// Nothing: the request goes unanswered, as on a serial line.
    #[default]
    Silent,
    /// The device at this unit, as if addressed itself (`--any-unit`, or unit 0 and 0xFF of
    /// a single device over Modbus/TCP).
    Device(u8),
    /// This exception, as a gateway answers for a unit behind it that does not respond
    /// (0x0B, Gateway Target Device Failed to Respond).
    Refuse(ExceptionCode),
}

/// Devices by unit address.
pub struct Sim {
    units: BTreeMap<u8, Unit>,
    /// Units answered by another unit's device, and what answers the rest.
    aliases: BTreeMap<u8, u8>,
    unserved: Unserved,
    clock: SimClock,
    rng: SmallRng,
    /// Points that count periods of the wall clock, on every unit.
    tickers: Vec<Ticker>,
}

impl Sim {
    /// An empty line with `clock`; `seed` makes fault injection repeatable.
    pub fn new(clock: SimClock, seed: u64) -> Self {
        Sim {
            units: BTreeMap::new(),
            aliases: BTreeMap::new(),
            unserved: Unserved::Silent,
            clock,
            rng: SmallRng::seed_from_u64(seed),
            tickers: Vec::new(),
        }
    }

    /// Has requests to `unit` answered by the device at `device` (unit 0 and 0xFF of a single
    /// device over Modbus/TCP).
    pub fn alias(&mut self, unit: u8, device: u8) {
        self.aliases.insert(unit, device);
    }

    /// Sets what answers a unit no device (or alias) is at.
    pub fn set_unserved(&mut self, unserved: Unserved) {
        self.unserved = unserved;
    }

    /// The unit whose device answers requests to `unit`, if any.
    pub fn resolve(&self, unit: u8) -> Option<u8> {
        if self.units.contains_key(&unit) {
            return Some(unit);
        }
        let ((Some(&target), _) | (None, Unserved::Device(target))) = (self.aliases.get(&unit), self.unserved) else {
            return None;
        };
        self.units.contains_key(&target).then_some(target)
    }

    /// Puts `device` at `unit`.
    pub fn add(&mut self, unit: u8, device: Device, faults: Faults) {
        self.units.insert(unit, Unit { device, faults, tripped: false });
    }

    /// Makes `ticker`'s point of every unit count its periods (see [`crate::ticker`]); refused,
    /// naming the unit, if a unit's profile has no integer register by that name. Add the
    /// units first.
    pub fn add_ticker(&mut self, ticker: Ticker) -> Result<(), TickerError> {
        for (unit, u) in &self.units {
            ticker.check(u.device.memory()).map_err(|e| TickerError::Unit { unit: *unit, error: Box::new(e) })?;
        }
        self.tickers.push(ticker);
        Ok(())
    }

    /// The unit addresses served.
    pub fn unit_set(&self) -> UnitSet {
        self.units.keys().copied().collect()
    }

    /// The units.
    pub fn units(&self) -> impl Iterator<Item = (u8, &Unit)> {
        self.units.iter().map(|(u, d)| (*u, d))
    }

    /// The device at `unit`, advanced to now.
    pub fn device(&mut self, unit: u8) -> Option<&mut Device> {
        let now = (self.clock)();
        let unit = self.resolve(unit)?;
        let u = self.units.get_mut(&unit)?;
        u.device.advance_to(now);
        for ticker in &self.tickers {
            ticker.apply(u.device.memory_mut());
        }
        if let Some(after) = u.faults.trip_after
            && !u.tripped
            && now >= after
        {
            u.tripped = true;
            // E07, overvoltage: an arbitrary but recognisable trip.
            u.device.trip(7);
        }
        Some(&mut u.device)
    }

    fn with<T>(
        &mut self,
        unit: u8,
        f: impl FnOnce(&mut Device) -> Result<T, ExceptionCode>,
    ) -> Result<T, ExceptionCode> {
        // The engine only asks for units it serves; an unknown one is a device failure.
        self.device(unit).map_or(Err(ExceptionCode::ServerDeviceFailure), f)
    }

    /// Draws whether a reply from `unit` is dropped, and if not whether it is corrupted.
    fn draw(&mut self, unit: u8) -> (bool, bool) {
        let Some(u) = self.resolve(unit).and_then(|unit| self.units.get(&unit)) else { return (false, false) };
        let (drop, corrupt) = (u.faults.drop, u.faults.corrupt);
        // Shares are checked when parsed, but the fields are public: clamp, never panic.
        let dropped = drop > 0.0 && self.rng.random_bool(drop.clamp(0.0, 1.0));
        let corrupted = !dropped && corrupt > 0.0 && self.rng.random_bool(corrupt.clamp(0.0, 1.0));
        (dropped, corrupted)
    }

    /// Draws the first rule of `unit` for a request with `function` touching `addresses`
    /// that applies: among those taken when the request arrives if `on_request`, else among
    /// those taken when its reply leaves.
    fn draw_rule(
        &mut self,
        unit: u8,
        function: u8,
        addresses: &[Option<AddressRange>; 2],
        on_request: bool,
    ) -> Option<Action> {
        // A unit answered by another's device (0xFF over TCP, --any-unit) meets that device's rules.
        let unit = self.resolve(unit)?;
        let Sim { units, rng, .. } = self;
        let rules = &units.get(&unit)?.faults.rules;
        rules
            .iter()
            .filter(|r| r.action.on_request() == on_request && r.matches(function, addresses))
            // Shares are checked when parsed, but the fields are public: clamp, never panic.
            .find(|r| r.share >= 1.0 || (r.share > 0.0 && rng.random_bool(r.share.clamp(0.0, 1.0))))
            .map(|r| r.action)
    }
}

impl Handler for Sim {
    fn admit(&mut self, unit: u8, broadcast: bool, request: &Request<'_>) -> Admission {
        let Some(device) = self.device(unit) else {
            return match self.unserved {
                Unserved::Refuse(code) if !broadcast => Admission::Refuse(code),
                _ => Admission::Ignore,
            };
        };
        let admission = device.admit(broadcast, request);
        let Some(faults) = self.resolve(unit).and_then(|unit| self.units.get(&unit)).map(|u| &u.faults) else {
            return Admission::Ignore;
        };
        if faults.silent {
            return Admission::Ignore;
        }
        if let (Some(code), false) = (faults.exception, broadcast) {
            return Admission::Refuse(ExceptionCode::from_u8(code));
        }
        if !broadcast {
            match self.draw_rule(unit, request.function().value(), &request.address_ranges(), true) {
                Some(Action::Exception(code)) => return Admission::Refuse(ExceptionCode::from_u8(code)),
                Some(Action::NoReply) => return Admission::Ignore,
                _ => {}
            }
        }
        admission
    }

    fn response_wait(&self, unit: u8) -> Option<Duration> {
        let u = self.units.get(&self.resolve(unit)?)?;
        Some(u.device.response_wait() + u.faults.delay)
    }

    fn read_coils(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.read_bits(Table::Coils, start, out))
    }
    fn read_discrete_inputs(&mut self, unit: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.read_bits(Table::DiscreteInputs, start, out))
    }
    fn read_holding_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.read_registers(Table::Holding, start, out))
    }
    fn read_input_registers(&mut self, unit: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.read_registers(Table::Input, start, out))
    }
    fn write_single_coil(&mut self, unit: u8, address: u16, value: bool) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.write_coils(address, Bits::from_values(&[value])))
    }
    fn write_single_register(&mut self, unit: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.write_registers(address, Registers::from_values(&[value])))
    }
    fn write_multiple_coils(&mut self, unit: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.write_coils(start, values))
    }
    fn write_multiple_registers(&mut self, unit: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.write_registers(start, values))
    }
    fn mask_write_register(&mut self, unit: u8, mask: MaskWrite) -> Result<(), ExceptionCode> {
        self.with(unit, |d| {
            let mut current = [0u16];
            d.read_registers(Table::Holding, mask.address, &mut current)?;
            d.write_registers(mask.address, Registers::from_values(&[mask.apply(current[0])]))
        })
    }
    fn read_exception_status(&mut self, unit: u8) -> Result<u8, ExceptionCode> {
        self.with(unit, |_| Ok(0))
    }
    fn report_server_id(&mut self, unit: u8, out: &mut [u8]) -> Result<usize, ExceptionCode> {
        self.with(unit, |d| Ok(d.server_id(out)))
    }
    fn read_file_record(&mut self, unit: u8, file: u16, record: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.read_file(file, record, out))
    }
    fn write_file_record(
        &mut self,
        unit: u8,
        file: u16,
        record: u16,
        values: Registers<'_>,
    ) -> Result<(), ExceptionCode> {
        self.with(unit, |d| d.write_file(file, record, values))
    }
    fn read_fifo_queue(&mut self, unit: u8, address: u16, out: &mut [u16; 31]) -> Result<usize, ExceptionCode> {
        self.with(unit, |d| d.read_fifo(address, out))
    }
    fn device_object(&mut self, unit: u8, id: u8, out: &mut [u8]) -> Option<usize> {
        let value = self.units.get(&self.resolve(unit)?)?.device.device_object(id)?;
        let n = value.len().min(out.len());
        out[..n].copy_from_slice(&value[..n]);
        Some(n)
    }
}

/// Injects each unit's reply faults (drops, broken checksums) and its rules' reply actions
/// (delays, short, malformed or re-addressed replies, trickles) on the way out.
pub struct FaultFilter {
    sim: Shared<Sim>,
    framing: Framing,
}

impl FaultFilter {
    /// A filter for replies framed with `framing` from the units of `sim`.
    pub fn new(sim: Shared<Sim>, framing: Framing) -> Self {
        FaultFilter { sim, framing }
    }
}

impl ReplyFilter for FaultFilter {
    fn filter(&mut self, answering: Option<&Answering>, frame: &mut Vec<u8>) -> Fate {
        let Some(unit) = answering.map(|a| a.unit).or_else(|| unit_of(self.framing, frame)) else { return Fate::Send };
        let (dropped, corrupted, action) = {
            let mut sim = self.sim.lock();
            let (dropped, corrupted) = sim.draw(unit);
            let action = match answering {
                Some(a) if !dropped => sim.draw_rule(unit, a.function.value(), &a.addresses, false),
                _ => None,
            };
            (dropped, corrupted, action)
        };
        if dropped {
            return Fate::Drop;
        }
        let framing = self.framing;
        let fate = match action {
            Some(Action::Delay(d)) => Fate::Delay(d),
            Some(Action::Trickle(gap)) => Fate::Trickle { gap },
            Some(Action::Short(keep)) => {
                frame.truncate(keep.unwrap_or(frame.len() / 2).max(1));
                Fate::Send
            }
            Some(Action::Malformed) => {
                reframe(framing, frame, |_, pdu| {
                    if pdu.len() > 1 {
                        pdu.pop();
                    }
                });
                Fate::Send
            }
            Some(Action::Unit(to)) => {
                reframe(framing, frame, |header, _| header.unit = to);
                Fate::Send
            }
            Some(Action::Transaction(id)) => {
                // Serial frames carry no transaction id; theirs go out unchanged.
                if framing == Framing::Mbap {
                    reframe(framing, frame, |header, _| header.transaction = id.apply(header.transaction));
                }
                Fate::Send
            }
            Some(Action::Exception(_) | Action::NoReply) | None => Fate::Send,
        };
        if corrupted {
            corrupt_checksum(framing, frame);
        }
        fate
    }
}
