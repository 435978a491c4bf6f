//! What backup, diff and restore need to know of a device profile, taken from the profile
//! once: the parameters, the per-request limits, which addresses answer a read, how to tell
//! that the drive runs, and the device's words for its exception codes.

use ferrobus_sim::profile::{self as model, Profile};

use super::param::{Access, Kind, Order, Param, Table};

/// How the device identifies itself, as the profile says.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Identification {
    /// FC2B/0E Read Device Identification.
    DeviceId,
    /// FC11 Report Server ID.
    ServerId,
    /// Neither.
    None,
}

/// A profile as the backup commands use it.
#[derive(Clone, Debug)]
pub(crate) struct View {
    /// The name it was loaded by: a built-in name or a file's path.
    pub(crate) name: String,
    /// The device's name (`[device] name`).
    pub(crate) device: String,
    /// `sha256:…` of the file, for a profile that is not built in.
    pub(crate) hash: Option<String>,
    /// Every parameter, in the profile's order.
    pub(crate) params: Vec<Param>,
    /// Registers per read request.
    pub(crate) read_registers: u16,
    /// Registers per write request.
    pub(crate) write_registers: u16,
    /// Bits per read request.
    pub(crate) read_bits: u16,
    /// Addresses that answer a read though no parameter lives there: (table, first, last).
    pub(crate) spans: Vec<(Table, u16, u16)>,
    /// How the device identifies itself.
    pub(crate) identification: Identification,
    /// The point that tells whether the drive runs, and its raw values that mean running.
    pub(crate) running: Option<(String, Vec<i64>)>,
    /// The device's own meaning of exception codes.
    pub(crate) exception_meanings: Vec<(u8, String)>,
}

impl View {
    /// Loads a built-in profile by name or a profile file.
    pub(crate) fn load(name: &str) -> Result<View, String> {
        let profile = Profile::load(name).map_err(|e| e.to_string())?;
        let hash = if model::BUILTIN.iter().any(|(n, _)| *n == name) {
            None
        } else {
            let bytes = std::fs::read(name).map_err(|e| format!("cannot read profile {name}: {e}"))?;
            Some(format!("sha256:{}", super::sha256::hex(&bytes)))
        };
        Ok(View::from_profile(name, hash, &profile))
    }

    fn from_profile(name: &str, hash: Option<String>, profile: &Profile) -> View {
        let base = u32::from(profile.addressing.base);
        let wire = |number: u32| u16::try_from(number.saturating_sub(base)).unwrap_or(u16::MAX);
        let mut params = Vec::new();
        for (table, defs) in [(Table::Holding, &profile.registers), (Table::Input, &profile.inputs)] {
            for def in defs {
                for item in 0..def.count {
                    let number = def.number.saturating_add(item.saturating_mul(def.size));
                    let kind = match (def.size, def.signed) {
                        (2, true) => Kind::I32,
                        (2, false) => Kind::U32,
                        (_, true) => Kind::I16,
                        (_, false) => Kind::U16,
                    };
                    let access = access(def.access);
                    params.push(Param {
                        code: item_name(&def.name, def.count, item),
                        label: def.description.clone(),
                        table,
                        wire: wire(number),
                        width: u16::try_from(def.size).unwrap_or(1),
                        kind,
                        order: if def.word_order == model::WordOrder::LowFirst { Order::Cdab } else { Order::Abcd },
                        scale: def.scale.unwrap_or(1.0),
                        offset: 0.0,
                        unit: def.unit.clone(),
                        min: def.min,
                        max: def.max,
                        access,
                        while_running: def.while_running,
                        depends_on: Vec::new(),
                        backup: access == Access::Rw && table == Table::Holding,
                        values: Vec::new(),
                    });
                }
            }
        }
        for (table, defs) in [(Table::Coils, &profile.coils), (Table::Discrete, &profile.discrete_inputs)] {
            for def in defs {
                for item in 0..def.count {
                    params.push(Param {
                        code: item_name(&def.name, def.count, item),
                        label: def.description.clone(),
                        table,
                        wire: wire(def.number.saturating_add(item)),
                        width: 1,
                        kind: Kind::Bit,
                        order: Order::Abcd,
                        scale: 1.0,
                        offset: 0.0,
                        unit: None,
                        min: None,
                        max: None,
                        access: access(def.access),
                        while_running: true,
                        depends_on: Vec::new(),
                        // Coils are commands (run, reset), not settings.
                        backup: false,
                        values: Vec::new(),
                    });
                }
            }
        }
        let limits = &profile.limits;
        let running =
            profile.coils.iter().find(|c| c.name == "running" && c.count == 1).map(|c| (c.name.clone(), vec![1]));
        View {
            name: name.to_string(),
            device: profile.device.name.clone(),
            hash,
            params,
            read_registers: limits.read_registers.unwrap_or(125).clamp(1, 125),
            write_registers: limits.write_registers.unwrap_or(123).clamp(1, 123),
            read_bits: limits.read_coils.unwrap_or(2000).clamp(1, 2000),
            spans: Vec::new(),
            identification: if profile.device.identification {
                Identification::DeviceId
            } else if profile.device.server_id.is_some() {
                Identification::ServerId
            } else {
                Identification::None
            },
            running,
            exception_meanings: vec![
                (profile.exceptions.out_of_range, "data outside the device's range".into()),
                (profile.exceptions.not_allowed, "the device restricts execution".into()),
            ],
        }
    }

    /// The parameter called `code` (case-insensitively).
    pub(crate) fn find(&self, code: &str) -> Option<&Param> {
        self.params.iter().find(|p| p.code.eq_ignore_ascii_case(code))
    }

    /// The parameters a backup saves, in the profile's order.
    pub(crate) fn backed_up(&self) -> Vec<&Param> {
        self.params.iter().filter(|p| p.backup && p.access != Access::Wo).collect()
    }

    /// The device's meaning of an exception code, if the profile gives one.
    pub(crate) fn meaning(&self, code: u8) -> Option<&str> {
        self.exception_meanings.iter().find(|(c, _)| *c == code).map(|(_, m)| m.as_str())
    }

    /// Whether a read of `address` in `table` is answered: a parameter lives there, or a span
    /// covers it.
    pub(crate) fn answers(&self, table: Table, address: u16) -> bool {
        self.params.iter().any(|p| {
            p.table == table && address >= p.wire && u32::from(address) < u32::from(p.wire) + u32::from(p.width)
        }) || self.spans.iter().any(|(t, first, last)| *t == table && (*first..=*last).contains(&address))
    }
}

/// `name`, or `name1`… for an item of a run of `count`.
fn item_name(name: &str, count: u32, item: u32) -> String {
    if count > 1 { format!("{name}{}", item.saturating_add(1)) } else { name.to_string() }
}

fn access(access: model::Access) -> Access {
    match access {
        model::Access::Ro => Access::Ro,
        model::Access::Rw => Access::Rw,
        model::Access::Wo => Access::Wo,
    }
}
