//! The run lock for writes by address: `write`, `readwrite`, `mask` and `raw` name no point, but
//! with `--device` the profile knows which of the registers and coils they touch cannot change
//! while the drive runs. Before such a write the running point is read, as `set` reads it
//! ([`ferrobus_tools::guard::check_span`], the one rule); while the drive runs, or when whether it runs
//! cannot be told, the write is refused, and `--force` sends it anyway with a warning.
//!
//! A write that touches no run-locked point, or made without `--device`, reads nothing.

use ferrobus_profile::{Refusal, RunState, Table};
use ferrobus_proto::pdu::Request;

use crate::connect::{ConnectArgs, Session};
use crate::exit::CliError;

/// What a write by address touches: `count` items of `table` from `start`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Span {
    /// The table written.
    pub(crate) table: Table,
    /// The first address written.
    pub(crate) start: u16,
    /// How many coils or registers.
    pub(crate) count: usize,
}

impl Span {
    /// `count` holding registers from `start`.
    pub(crate) fn registers(start: u16, count: usize) -> Span {
        Span { table: Table::Holding, start, count }
    }

    /// `count` coils from `start`.
    pub(crate) fn coils(start: u16, count: usize) -> Span {
        Span { table: Table::Coils, start, count }
    }

    /// What a request PDU writes, if it writes (FC05, FC06, FC0F, FC10, FC16, FC17).
    pub(crate) fn of_request(request: &Request<'_>) -> Option<Span> {
        match request {
            Request::WriteSingleCoil(w) => Some(Span::coils(w.address, 1)),
            Request::WriteSingleRegister(w) => Some(Span::registers(w.address, 1)),
            Request::WriteMultipleCoils(w) => Some(Span::coils(w.start(), usize::from(w.quantity()))),
            Request::WriteMultipleRegisters(w) => Some(Span::registers(w.start(), usize::from(w.quantity()))),
            Request::MaskWriteRegister(w) => Some(Span::registers(w.address, 1)),
            Request::ReadWriteMultipleRegisters(w) => Some(Span::registers(w.write_start(), w.values().len())),
            _ => None,
        }
    }
}

/// Applies the `--device` profile's run lock to a write of `span` by `command`: `Ok` to send it
/// (nothing run-locked touched, the drive stopped, or `force`, said on stderr), else the
/// refusal, with nothing sent.
pub(crate) async fn check(
    connection: &ConnectArgs,
    session: &Session,
    span: Span,
    force: bool,
    command: &str,
) -> Result<(), CliError> {
    let Some(profile) = connection.profile()? else { return Ok(()) };
    let refusal = if session.is_broadcast() {
        let locked = profile.run_locked_in(span.table, span.start, span.count);
        profile.guard_span(&locked, &RunState::Broadcast)
    } else {
        ferrobus_tools::guard::check_span(&session.client, session.unit, &profile, span.table, span.start, span.count)
            .await
    };
    match refusal {
        Ok(()) => Ok(()),
        Err(refusal) if force => {
            eprintln!("{command}: {refusal}; written anyway (--force)");
            Ok(())
        }
        Err(refusal) => Err(refused(&refusal, Some("--force writes it anyway"))),
    }
}

/// The guard's refusal as the command's error: nothing was sent (exit 2), or, when the drive
/// could not be asked whether it runs, the device's part (exit 7, as for a refused request).
/// `hint` is how to write it anyway, if there is a way.
pub(crate) fn refused(refusal: &Refusal, hint: Option<&str>) -> CliError {
    let text = match hint {
        Some(hint) if refusal.is_run_lock() => format!("not sent: {refusal} ({hint})"),
        _ => format!("not sent: {refusal}"),
    };
    match refusal {
        Refusal::Unreadable { .. } => CliError::Refused(text),
        _ => CliError::Usage(text),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_writing_request_says_what_it_writes_and_a_read_nothing() {
        let span = |pdu: &[u8]| Span::of_request(&Request::parse(pdu).unwrap());
        assert_eq!(span(&[0x05, 0x00, 0x07, 0xFF, 0x00]), Some(Span::coils(7, 1)));
        assert_eq!(span(&[0x06, 0x12, 0x03, 0x00, 0x01]), Some(Span::registers(0x1203, 1)));
        assert_eq!(span(&[0x0F, 0x00, 0x02, 0x00, 0x03, 0x01, 0x05]), Some(Span::coils(2, 3)));
        assert_eq!(span(&[0x10, 0x00, 0x04, 0x00, 0x02, 0x04, 0, 1, 0, 2]), Some(Span::registers(4, 2)));
        assert_eq!(span(&[0x16, 0x00, 0x09, 0xFF, 0x00, 0x00, 0x01]), Some(Span::registers(9, 1)));
        let fc17 = [0x17, 0x00, 0x00, 0x00, 0x01, 0x00, 0x20, 0x00, 0x02, 0x04, 0, 1, 0, 2];
        assert_eq!(span(&fc17), Some(Span::registers(0x20, 2)));
        assert_eq!(span(&[0x03, 0x00, 0x00, 0x00, 0x02]), None);
    }
}
