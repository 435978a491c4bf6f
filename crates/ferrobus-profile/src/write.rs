//! How a value of a point goes on the wire: the function and the request, decided once for
//! every writer (`set`, `restore`, `monitor`, the bridge, poll's writes).
//!
//! ```text
//!   Profile::plan_write(write, state)
//!     ├─ guard_write(write, state)      access, range, the run lock       ──▶ Refusal
//!     └─ point.wire_write(raw, rules)   the one request for the value     ──▶ WireWrite
//!          coil       FC05, or FC0F of one coil when the device lacks FC05
//!          register   FC06 for one word (FC10 when the device lacks FC06), FC10 for several,
//!                     never split: wider than the device's per-request limit is refused
//! ```
//!
//! A value is never split across requests: half a 32-bit value written is a wrong value on the
//! device until the other half lands, and a refusal of the second leaves it there.
//! [`WriteRules`] are what the device takes ([`Profile::write_rules`]: its `functions` and its
//! write limits), or the spec's ([`WriteRules::SPEC`]) for a point no profile describes.

use ferrobus_proto::pdu::{Bits, Registers, Request, WriteCoil, WriteCoils, WriteRegister, WriteRegisters};
use ferrobus_proto::{FunctionCode, PduError};

use crate::codec::ValueError;
use crate::guard::{Refusal, RunState, Write};
use crate::model::{Point, Profile, Table, Value};

/// What a device takes in its writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteRules {
    /// Coils: FC05 and FC0F.
    pub coil: Takes,
    /// Holding registers: FC06 and FC10.
    pub register: Takes,
    /// The most registers one FC10 carries.
    pub registers: u16,
    /// The most coils one FC0F carries.
    pub coils: u16,
}

/// Which of a table's two write functions a device answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Takes {
    /// The single write (FC05, FC06).
    pub single: bool,
    /// The multiple write (FC0F, FC10).
    pub multiple: bool,
}

impl WriteRules {
    /// Every write function, and the spec's limits (123 registers, 1968 coils).
    pub const SPEC: WriteRules = WriteRules {
        coil: Takes { single: true, multiple: true },
        register: Takes { single: true, multiple: true },
        registers: 123,
        coils: 1968,
    };
}

/// The one request that writes a value to a point.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WireWrite {
    /// FC05.
    Coil {
        /// The coil's wire address.
        address: u16,
        /// On or off.
        on: bool,
    },
    /// FC0F of one coil (a device without FC05).
    OneOfCoils {
        /// The coil's wire address.
        address: u16,
        /// On or off.
        on: bool,
    },
    /// FC06.
    Register {
        /// The register's wire address.
        address: u16,
        /// Its new value.
        value: u16,
    },
    /// FC10: every register of the value, in one request.
    Registers {
        /// The first register's wire address.
        address: u16,
        /// The registers, in the point's word order.
        values: Vec<u16>,
    },
}

impl WireWrite {
    /// The function code it is sent with.
    pub fn function(&self) -> FunctionCode {
        match self {
            WireWrite::Coil { .. } => FunctionCode::WriteSingleCoil,
            WireWrite::OneOfCoils { .. } => FunctionCode::WriteMultipleCoils,
            WireWrite::Register { .. } => FunctionCode::WriteSingleRegister,
            WireWrite::Registers { .. } => FunctionCode::WriteMultipleRegisters,
        }
    }

    /// The first wire address written.
    pub fn address(&self) -> u16 {
        match self {
            WireWrite::Coil { address, .. }
            | WireWrite::OneOfCoils { address, .. }
            | WireWrite::Register { address, .. }
            | WireWrite::Registers { address, .. } => *address,
        }
    }

    /// The request PDU's body, ready to send. Fails only for an FC10 that no request can carry
    /// (none that [`Point::wire_write`] makes).
    pub fn request(&self) -> Result<Request<'_>, PduError> {
        Ok(match self {
            WireWrite::Coil { address, on } => Request::WriteSingleCoil(WriteCoil { address: *address, value: *on }),
            WireWrite::OneOfCoils { address, on } => {
                let one: &'static [bool] = if *on { &[true] } else { &[false] };
                Request::WriteMultipleCoils(WriteCoils::new(*address, Bits::from_values(one))?)
            }
            WireWrite::Register { address, value } => {
                Request::WriteSingleRegister(WriteRegister { address: *address, value: *value })
            }
            WireWrite::Registers { address, values } => {
                Request::WriteMultipleRegisters(WriteRegisters::new(*address, Registers::from_values(values))?)
            }
        })
    }
}

impl Point {
    /// The one request that writes raw value `raw` to this point with a device's `rules`:
    /// a coil is on for `true` or any non-zero number; a register value is encoded in the
    /// point's type and word order and sent whole. Refused: a point of a read-only table, a
    /// value that does not fit the point's type, one wider than the device writes in one
    /// request, a table the device has no function to write. Range, access and the run lock
    /// are the guard's ([`Profile::plan_write`] applies both).
    pub fn wire_write(&self, raw: &Value, rules: &WriteRules) -> Result<WireWrite, Refusal> {
        let address = self.address;
        let none = |single: FunctionCode, multiple: FunctionCode| Refusal::NoFunction {
            code: self.code.clone(),
            single: single.value(),
            multiple: multiple.value(),
        };
        match self.table {
            Table::Coils => {
                let on = match raw {
                    Value::Bool(on) => *on,
                    other => other.as_int().is_some_and(|n| n != 0),
                };
                match (rules.coil.single, rules.coil.multiple) {
                    (true, _) => Ok(WireWrite::Coil { address, on }),
                    (false, true) => Ok(WireWrite::OneOfCoils { address, on }),
                    (false, false) => Err(none(FunctionCode::WriteSingleCoil, FunctionCode::WriteMultipleCoils)),
                }
            }
            Table::Holding => {
                let values = self.encode(raw)?;
                if values.len() > usize::from(rules.registers) {
                    return Err(Refusal::TooWide {
                        code: self.code.clone(),
                        items: values.len(),
                        limit: rules.registers,
                    });
                }
                match (values.as_slice(), rules.register.single, rules.register.multiple) {
                    ([value], true, _) => Ok(WireWrite::Register { address, value: *value }),
                    (_, _, true) => Ok(WireWrite::Registers { address, values }),
                    _ => Err(none(FunctionCode::WriteSingleRegister, FunctionCode::WriteMultipleRegisters)),
                }
            }
            Table::Input | Table::DiscreteInputs => Err(ValueError::ReadOnly { code: self.code.clone() }.into()),
        }
    }
}

impl Profile {
    /// What the device takes in its writes: the functions its `functions` list names (every one
    /// when it has none) and its write limits.
    pub fn write_rules(&self) -> WriteRules {
        let has = |f: FunctionCode| self.comm.functions.as_ref().is_none_or(|all| all.contains(&f.value()));
        WriteRules {
            coil: Takes { single: has(FunctionCode::WriteSingleCoil), multiple: has(FunctionCode::WriteMultipleCoils) },
            register: Takes {
                single: has(FunctionCode::WriteSingleRegister),
                multiple: has(FunctionCode::WriteMultipleRegisters),
            },
            registers: self.write_limit(Table::Holding),
            coils: self.write_limit(Table::Coils),
        }
    }

    /// The one plan of a write: the guard with `state` ([`Profile::guard_write`]), then the
    /// request that carries the value ([`Point::wire_write`] with [`Profile::write_rules`]).
    pub fn plan_write(&self, write: &Write<'_>, state: &RunState) -> Result<WireWrite, Refusal> {
        self.guard_write(write, state)?;
        write.point.wire_write(write.raw, &self.write_rules())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A device with a coil, a word, a 32-bit value and an input register; `extra` adds
    /// sections (its functions, its limits).
    fn profile(extra: &str) -> Profile {
        let text = format!(
            "[device]\nname = 't'\nvendor = 'v'\nproduct_code = 'p'\nrevision = '1'\n{extra}\n\
             [[coils]]\nnumber = 0\nname = 'RUN'\naccess = 'rw'\n\
             [[registers]]\nnumber = 1\nname = 'F'\naccess = 'rw'\n\
             [[registers]]\nnumber = 2\nname = 'L'\ntype = 'u32'\naccess = 'rw'\n\
             [[inputs]]\nnumber = 10\nname = 'I'\n"
        );
        Profile::parse(&text, "t.toml").unwrap_or_else(|e| panic!("{e}"))
    }

    fn plan(profile: &Profile, code: &str, raw: &Value) -> Result<WireWrite, Refusal> {
        let point = profile.point(code).expect("the point");
        profile.plan_write(&Write { point, raw, typed: "typed" }, &RunState::NotRead)
    }

    #[test]
    fn a_coil_is_fc05_a_word_fc06_and_a_wider_value_one_fc10() {
        let p = profile("");
        assert_eq!(plan(&p, "RUN", &Value::Bool(true)), Ok(WireWrite::Coil { address: 0, on: true }));
        assert_eq!(plan(&p, "RUN", &Value::Int(0)), Ok(WireWrite::Coil { address: 0, on: false }));
        assert_eq!(plan(&p, "F", &Value::Int(7)), Ok(WireWrite::Register { address: 1, value: 7 }));
        assert_eq!(
            plan(&p, "L", &Value::Int(0x0001_0002)),
            Ok(WireWrite::Registers { address: 2, values: vec![1, 2] })
        );
    }

    #[test]
    fn a_device_without_the_single_functions_gets_the_multiple_ones() {
        let p = profile("[comm]\nfunctions = [1, 3, 15, 16]");
        assert_eq!(plan(&p, "RUN", &Value::Bool(true)), Ok(WireWrite::OneOfCoils { address: 0, on: true }));
        assert_eq!(plan(&p, "F", &Value::Int(7)), Ok(WireWrite::Registers { address: 1, values: vec![7] }));
        let request = plan(&p, "RUN", &Value::Bool(true)).unwrap();
        assert_eq!(request.function(), FunctionCode::WriteMultipleCoils);
        assert!(matches!(request.request(), Ok(Request::WriteMultipleCoils(_))));
    }

    #[test]
    fn a_device_with_no_function_for_a_table_is_refused_naming_both() {
        let p = profile("[comm]\nfunctions = [1, 3]");
        let refusal = plan(&p, "F", &Value::Int(7)).unwrap_err();
        assert_eq!(refusal.to_string(), "F: the device answers neither 0x06 nor 0x10, the functions that write it");
    }

    #[test]
    fn a_value_wider_than_one_request_is_refused_never_split() {
        let p = profile("[limits]\nwrite_registers = 1");
        let refusal = plan(&p, "L", &Value::Int(1)).unwrap_err();
        assert_eq!(refusal.to_string(), "L takes 2 registers, more than the 1 the device writes in one request");
        assert_eq!(plan(&p, "F", &Value::Int(1)), Ok(WireWrite::Register { address: 1, value: 1 }));
    }

    #[test]
    fn a_read_only_point_and_a_value_out_of_its_type_are_refused() {
        let p = profile("");
        assert!(matches!(plan(&p, "I", &Value::Int(1)), Err(Refusal::Value(ValueError::ReadOnly { .. }))));
        let point = p.point("I").unwrap();
        assert!(point.wire_write(&Value::Int(1), &WriteRules::SPEC).is_err(), "an input register, raw too");
        let word = p.point("F").unwrap();
        assert!(matches!(word.wire_write(&Value::Int(70_000), &WriteRules::SPEC), Err(Refusal::Value(_))));
    }

    #[test]
    fn the_request_carries_what_the_plan_says() {
        let write = WireWrite::Registers { address: 0x1103, values: vec![0, 3000] };
        let request = write.request().unwrap();
        let mut pdu = [0u8; 16];
        let n = request.emit(&mut pdu).unwrap();
        assert_eq!(&pdu[..n], &[0x10, 0x11, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x0B, 0xB8]);
        assert_eq!(write.address(), 0x1103);
    }
}
