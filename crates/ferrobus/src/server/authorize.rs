//! The authorization filter every request passes before it is answered: by a server (a TLS
//! client's role) and by the gateway's front (its rules, a role too), the same trait.

use ferrobus_proto::ExceptionCode;

/// Decides, per request, whether it is served (a server) or forwarded (the gateway).
pub trait Authorize: Send {
    /// `Ok(())` lets the request for `unit` (the unit as the client addressed it) with `pdu`
    /// (function code first) through; `Err(code)` answers it with exception `code`, and it
    /// goes no further.
    fn authorize(&mut self, unit: u8, pdu: &[u8]) -> Result<(), ExceptionCode>;
}

impl<F> Authorize for F
where
    F: FnMut(u8, &[u8]) -> Result<(), ExceptionCode> + Send,
{
    fn authorize(&mut self, unit: u8, pdu: &[u8]) -> Result<(), ExceptionCode> {
        self(unit, pdu)
    }
}
