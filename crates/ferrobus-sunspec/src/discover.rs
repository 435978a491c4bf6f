//! Discovery: find "SunS" and walk the chain of models.
//!
//! The marker `SunS` (0x5375 0x6E53) is looked for at holding register 40000, then 0, then
//! 50000 (wire addresses). After it each model starts with its id and its length L (the
//! registers after those two); the chain ends at id 0xFFFF. Each model is read whole, in
//! requests of at most the read limit (125 registers, or the device's), ending each request on
//! a point boundary of the model's definition (a single point longer than the limit, such as a
//! 150-register string, cannot be kept whole). A length running past register 65535, a read
//! error, or more models than the address space can hold stop the walk with an error saying what
//! was seen.

use ferrobus::Client;

use crate::Definitions;
use crate::layout::layout;

/// The marker's two registers: "SunS".
pub const MARKER: [u16; 2] = [0x5375, 0x6E53];
/// Where the marker is looked for, in this order (wire addresses).
pub const BASES: [u16; 3] = [40000, 0, 50000];
/// The id that ends the chain.
pub const END: u16 = 0xFFFF;

/// One model found on a device.
#[derive(Clone, Debug, PartialEq)]
pub struct Found {
    /// The model id.
    pub id: u16,
    /// L: its registers after the id and the length.
    pub length: u16,
    /// The wire address of its id register.
    pub start: u16,
    /// The definition's name (`common`), when the definition is known.
    pub name: Option<String>,
    /// Whether L fits the definition: `None` without a definition, else `Ok` or what differs.
    pub fits: Option<Result<(), String>>,
    /// Its registers, from the id register on (2 + L of them).
    pub registers: Vec<u16>,
}

/// What discovery found: the base and the models, in chain order.
#[derive(Clone, Debug, PartialEq)]
pub struct Discovery {
    /// The wire address of "SunS".
    pub base: u16,
    /// The models.
    pub models: Vec<Found>,
}

/// Why discovery failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DiscoverError {
    /// "SunS" is at none of the bases.
    #[error("not a SunSpec device: no \"SunS\" at 40000, 0 or 50000 ({})", seen.join("; "))]
    NoMarker {
        /// What each base gave: `40000: 0x0000 0x0000`, `0: exception 0x02 ...`.
        seen: Vec<String>,
    },
    /// A model's length runs past register 65535.
    #[error("model {id} at {start} has length {length}, which runs past register 65535")]
    PastEnd {
        /// The id read.
        id: u16,
        /// Its address.
        start: u16,
        /// The length read.
        length: u16,
    },
    /// The chain runs to the end of the address space without an end marker.
    #[error("no end marker (0xFFFF): the chain after \"SunS\" at {base} runs to register 65535 ({models} models)")]
    NoEnd {
        /// The base.
        base: u16,
        /// Models read.
        models: usize,
    },
    /// A read answered with fewer registers than asked for.
    #[error("reading {count} registers at {address} ({what}): {got} came back")]
    Short {
        /// The address.
        address: u16,
        /// How many were asked for.
        count: u16,
        /// How many came.
        got: usize,
        /// What was being read.
        what: String,
    },
    /// A read failed.
    #[error("reading {count} registers at {address} ({what}): {error}")]
    Read {
        /// The address.
        address: u16,
        /// How many.
        count: u16,
        /// What was being read: `the header after model 1`, `model 103`.
        what: String,
        /// The client's error.
        error: ferrobus::Error,
    },
}

/// Finds "SunS" on `unit` and reads every model of the chain, in requests of at most `limit`
/// registers (clamped to 1..=125).
pub async fn discover(client: &Client, unit: u8, defs: &Definitions, limit: u16) -> Result<Discovery, DiscoverError> {
    let limit = limit.clamp(1, 125);
    let mut seen = Vec::new();
    let mut base = None;
    for at in BASES {
        match client.read_holding_registers(unit, at, 2).await {
            Ok(regs) if regs == MARKER => {
                base = Some(at);
                break;
            }
            Ok(regs) => {
                seen.push(format!("{at}: {}", regs.iter().map(|r| format!("0x{r:04X}")).collect::<Vec<_>>().join(" ")));
            }
            Err(error) => seen.push(format!("{at}: {error}")),
        }
    }
    let Some(base) = base else { return Err(DiscoverError::NoMarker { seen }) };
    tracing::debug!(base, "SunS found");
    let mut models: Vec<Found> = Vec::new();
    let mut at = u32::from(base) + 2;
    loop {
        let Ok(address) = u16::try_from(at) else {
            return Err(DiscoverError::NoEnd { base, models: models.len() });
        };
        if at + 2 > 65536 {
            return Err(DiscoverError::NoEnd { base, models: models.len() });
        }
        let what = || match models.last() {
            Some(m) => format!("the header after model {} at {}", m.id, m.start),
            None => format!("the first model header after \"SunS\" at {base}"),
        };
        let header = read(client, unit, address, 2, &what).await?;
        let [id, length] = header[..] else {
            return Err(DiscoverError::NoEnd { base, models: models.len() });
        };
        if id == END {
            break;
        }
        let end = at + 2 + u32::from(length);
        if end > 65536 {
            return Err(DiscoverError::PastEnd { id, start: address, length });
        }
        let def = defs.get(id);
        let mut registers = header.clone();
        while registers.len() < usize::from(length) + 2 {
            let done = u32::try_from(registers.len()).unwrap_or(u32::MAX);
            let left = end - at - done;
            let mut count = left.min(u32::from(limit));
            if let Some(def) = def {
                // End the request where a point ends, if one ends within the limit.
                let placed = layout(def, length, &registers);
                let boundary = placed
                    .points
                    .iter()
                    .map(|p| p.offset + u32::from(p.def.size))
                    .filter(|e| *e > done && *e <= done + count)
                    .max();
                if let Some(e) = boundary {
                    count = e - done;
                }
            }
            let from = u16::try_from(at + done).unwrap_or(u16::MAX);
            let count = u16::try_from(count).unwrap_or(limit);
            let what = || format!("model {id} at {address}");
            registers.extend(read(client, unit, from, count, &what).await?);
        }
        let fits = def.map(|d| match layout(d, length, &registers) {
            l if l.complete && l.mismatch.is_none() => Ok(()),
            l => Err(l.mismatch.unwrap_or_else(|| "a repeating group's count is not readable".into())),
        });
        tracing::debug!(id, start = address, length, "model found");
        models.push(Found { id, length, start: address, name: def.map(|d| d.name().to_string()), fits, registers });
        at = end;
    }
    Ok(Discovery { base, models })
}

async fn read(
    client: &Client,
    unit: u8,
    address: u16,
    count: u16,
    what: &dyn Fn() -> String,
) -> Result<Vec<u16>, DiscoverError> {
    match client.read_holding_registers(unit, address, count).await {
        Ok(regs) if regs.len() == usize::from(count) => Ok(regs),
        Ok(regs) => Err(DiscoverError::Short { address, count, got: regs.len(), what: what() }),
        Err(error) => Err(DiscoverError::Read { address, count, what: what(), error }),
    }
}
