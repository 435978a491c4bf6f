//! The authorization step every request of a gateway connection passes before it is routed.
//!
//! Each connection holds one [`Authorize`]: it sees the unit and the request PDU (function
//! code first) and either lets the request through or names the exception that answers it
//! instead. [`Rules`] is the gateway's own: read-only mode and allowlists of units and
//! function codes. A Modbus/TCP Security policy (roles from the client's certificate) plugs
//! in the same way, per connection; [`Chain`] asks several in turn.
//!
//! The exceptions chosen: a function code the gateway does not let through (read-only mode,
//! the function allowlist) is 0x01 Illegal Function — to the client the gateway is the server,
//! and that function is not available through it; a unit outside the unit allowlist is 0x0A
//! Gateway Path Unavailable, the same answer as a unit in no routing table: the gateway has no
//! path to it for this client.

use ferrobus_proto::ExceptionCode;

pub use ferrobus::server::Authorize;

/// Lets everything through.
#[derive(Clone, Copy, Debug, Default)]
pub struct AllowAll;

impl Authorize for AllowAll {
    fn authorize(&mut self, _unit: u8, _pdu: &[u8]) -> Result<(), ExceptionCode> {
        Ok(())
    }
}

/// Asks each in turn; the first refusal answers.
#[derive(Default)]
pub struct Chain(pub Vec<Box<dyn Authorize>>);

impl Authorize for Chain {
    fn authorize(&mut self, unit: u8, pdu: &[u8]) -> Result<(), ExceptionCode> {
        self.0.iter_mut().try_for_each(|a| a.authorize(unit, pdu))
    }
}

/// The gateway's own rules: read-only mode and allowlists of units and function codes.
#[derive(Clone, Debug)]
pub struct Rules {
    read_only: bool,
    units: Option<Box<[bool; 256]>>,
    functions: Option<Box<[bool; 256]>>,
}

impl Default for Rules {
    /// Everything allowed.
    fn default() -> Self {
        Rules { read_only: false, units: None, functions: None }
    }
}

impl Rules {
    /// Everything allowed.
    pub fn new() -> Self {
        Self::default()
    }

    /// Refuses with 0x01 every request that may change the device: only reads (0x01-0x04,
    /// 0x07, 0x0B, 0x0C, 0x11, 0x14, 0x18, 0x2B) and the diagnostics that return data pass.
    #[must_use]
    pub fn read_only(mut self, read_only: bool) -> Self {
        self.read_only = read_only;
        self
    }

    /// Only these units (as the client addresses them) are let through; others get 0x0A.
    #[must_use]
    pub fn units(mut self, units: impl IntoIterator<Item = u8>) -> Self {
        self.units = Some(table(units));
        self
    }

    /// Only these function codes are let through; others get 0x01.
    #[must_use]
    pub fn functions(mut self, functions: impl IntoIterator<Item = u8>) -> Self {
        self.functions = Some(table(functions));
        self
    }

    /// Whether the rules let everything through.
    pub fn allows_all(&self) -> bool {
        !self.read_only && self.units.is_none() && self.functions.is_none()
    }
}

fn table(items: impl IntoIterator<Item = u8>) -> Box<[bool; 256]> {
    let mut table = Box::new([false; 256]);
    for item in items {
        if let Some(slot) = table.get_mut(usize::from(item)) {
            *slot = true;
        }
    }
    table
}

fn allowed(table: Option<&[bool; 256]>, item: u8) -> bool {
    table.is_none_or(|t| t.get(usize::from(item)).copied().unwrap_or(false))
}

impl Authorize for Rules {
    fn authorize(&mut self, unit: u8, pdu: &[u8]) -> Result<(), ExceptionCode> {
        if !allowed(self.units.as_deref(), unit) {
            return Err(ExceptionCode::GatewayPathUnavailable);
        }
        let function = pdu.first().copied().unwrap_or_default();
        if !allowed(self.functions.as_deref(), function) {
            return Err(ExceptionCode::IllegalFunction);
        }
        if self.read_only && !only_reads(pdu) {
            return Err(ExceptionCode::IllegalFunction);
        }
        Ok(())
    }
}

/// Whether `pdu` is known to change nothing on the device: the reads, and the diagnostics
/// that only return data. Everything else — writes, 0x17 (it writes too), the diagnostics
/// that restart, clear or silence, vendor codes nobody can vouch for — is not.
fn only_reads(pdu: &[u8]) -> bool {
    match pdu {
        [0x01..=0x04 | 0x07 | 0x0B | 0x0C | 0x11 | 0x14 | 0x18 | 0x2B, ..] => true,
        // 0x08: 0x0000 returns the query, 0x0002 the diagnostic register, 0x000B-0x0012 counters.
        [0x08, hi, lo, ..] => matches!(u16::from_be_bytes([*hi, *lo]), 0x0000 | 0x0002 | 0x000B..=0x0012),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_only_refuses_every_write_function_with_illegal_function_and_passes_reads() {
        let mut rules = Rules::new().read_only(true);
        for write in [0x05u8, 0x06, 0x0F, 0x10, 0x16, 0x17, 0x15, 0x41] {
            assert_eq!(rules.authorize(1, &[write, 0, 0]), Err(ExceptionCode::IllegalFunction), "{write:#04x}");
        }
        for read in [0x01u8, 0x02, 0x03, 0x04, 0x2B, 0x14, 0x18] {
            assert_eq!(rules.authorize(1, &[read, 0, 0]), Ok(()), "{read:#04x}");
        }
        // Diagnostics: echo and counters pass; restart (0x01), clear (0x0A), listen only (0x04) do not.
        for (sub, ok) in [(0x00u8, true), (0x0B, true), (0x12, true), (0x01, false), (0x04, false), (0x0A, false)] {
            assert_eq!(rules.authorize(1, &[0x08, 0, sub, 0, 0]).is_ok(), ok, "0x08/{sub:#04x}");
        }
    }

    #[test]
    fn a_unit_outside_the_allowlist_gets_path_unavailable_and_a_function_outside_illegal_function() {
        let mut rules = Rules::new().units([1, 2]).functions([3]);
        assert_eq!(rules.authorize(1, &[3, 0, 0, 0, 1]), Ok(()));
        assert_eq!(rules.authorize(3, &[3, 0, 0, 0, 1]), Err(ExceptionCode::GatewayPathUnavailable));
        assert_eq!(rules.authorize(2, &[4, 0, 0, 0, 1]), Err(ExceptionCode::IllegalFunction));
        assert_eq!(rules.authorize(2, &[]), Err(ExceptionCode::IllegalFunction));
    }

    #[test]
    fn a_chain_answers_with_the_first_refusal() {
        let mut chain = Chain(vec![
            Box::new(Rules::new().units([1])),
            Box::new(|_: u8, _: &[u8]| Err(ExceptionCode::IllegalDataAddress)),
        ]);
        assert_eq!(chain.authorize(2, &[3]), Err(ExceptionCode::GatewayPathUnavailable));
        assert_eq!(chain.authorize(1, &[3]), Err(ExceptionCode::IllegalDataAddress));
        assert_eq!(AllowAll.authorize(9, &[0x10]), Ok(()));
    }
}
