//! `ferrobus write`: coils (FC05, FC0F) and registers (FC06, FC10).
//!
//! Each request prints one line on stdout saying what went where with which function code.
//! A 32-bit value takes two registers and so always goes with FC10; long writes are split at
//! value boundaries like reads.

use clap::{Args, Subcommand};
use ferrobus_proto::pdu::{WriteCoils, WriteRegisters};
use ferrobus_proto::{FunctionCode, PduError};

use crate::address::{ADDRESS_HELP, Address, AddressArgs, Table, per_request, quantity, split};
use crate::connect::{ConnectArgs, Session};
use crate::exit::CliError;
use crate::output;
use crate::run_lock::{self, Span};
use crate::value::{ValueArgs, ValueType, parse_coil};

/// The spec's most coils per FC0F request (§6.11), from the core.
const MAX_WRITE_COILS: usize = WriteCoils::MAX as usize;
/// The spec's most registers per FC10 request (§6.12), from the core.
const MAX_WRITE_REGISTERS: usize = WriteRegisters::MAX as usize;

/// `write coil|coils|register|registers`.
#[derive(Args, Debug)]
pub(crate) struct WriteArgs {
    /// What to write.
    #[command(subcommand)]
    pub(crate) what: WriteCommand,

    /// Write even where the --device profile says the value cannot change while the drive runs
    /// and the drive runs (or cannot say whether it does)
    #[arg(long, global = true)]
    pub(crate) force: bool,
}

/// The write commands.
#[derive(Subcommand, Debug)]
pub(crate) enum WriteCommand {
    /// Set one coil: on/off, 1/0, true/false (FC05)
    #[command(after_help = ADDRESS_HELP)]
    Coil {
        /// Coil address (see below)
        address: String,
        /// on/off, 1/0, true/false
        value: String,
        /// Address style.
        #[command(flatten)]
        address_args: AddressArgs,
    },
    /// Set consecutive coils (FC0F)
    #[command(after_help = ADDRESS_HELP)]
    Coils {
        /// First coil address (see below)
        address: String,
        /// on/off, 1/0, true/false, one per coil
        #[arg(required = true, num_args = 1..)]
        values: Vec<String>,
        /// Most coils per request [default: 1968; the 3G3RX takes 32]
        #[arg(long = "max-per-request", value_name = "N")]
        max_per_request: Option<u16>,
        /// Address style.
        #[command(flatten)]
        address_args: AddressArgs,
    },
    /// Write one register (FC06; FC10 with --multiple or a 32-bit --type)
    #[command(after_help = ADDRESS_HELP)]
    Register {
        /// Register address (see below)
        address: String,
        /// The value: decimal, 0x hex, negative for i16/i32, a float for f32
        #[arg(allow_negative_numbers = true)]
        value: String,
        /// Use FC10 even for one register (devices without FC06, e.g. the SDP servos)
        #[arg(long)]
        multiple: bool,
        /// Address style.
        #[command(flatten)]
        address_args: AddressArgs,
        /// Value types.
        #[command(flatten)]
        values: ValueArgs,
    },
    /// Write consecutive registers (FC10)
    #[command(after_help = ADDRESS_HELP)]
    Registers {
        /// First register address (see below)
        address: String,
        /// The values, typed by --type
        #[arg(required = true, num_args = 1.., allow_negative_numbers = true)]
        value: Vec<String>,
        /// Most registers per request; longer writes are split between values [default: 123]
        #[arg(long = "max-per-request", value_name = "N")]
        max_per_request: Option<u16>,
        /// Address style.
        #[command(flatten)]
        address_args: AddressArgs,
        /// Value types.
        #[command(flatten)]
        values: ValueArgs,
    },
}

/// `at 16 (0x0010), number 17`: an address as the user will recognise it.
pub(crate) fn describe_address(address: Address, wire: u16) -> String {
    match address.reference(wire) {
        Some(reference) => format!("{wire} (0x{wire:04X}) = {reference}"),
        None => format!("{wire} (0x{wire:04X})"),
    }
}

/// The line printed after a write request.
fn report(session: &Session, function: FunctionCode, what: &str, address: Address, start: u16, data: &str) -> String {
    let at = describe_address(address, start);
    if session.is_broadcast() {
        format!("broadcast: FC{:02X} sent {what} at {at}: {data} (no reply expected)\n", function.value())
    } else {
        format!("unit {}: FC{:02X} wrote {what} at {at}: {data}\n", session.unit, function.value())
    }
}

fn plural(n: usize, one: &str) -> String {
    if n == 1 { format!("1 {one}") } else { format!("{n} {one}s") }
}

fn hex_words(registers: &[u16]) -> String {
    registers.iter().map(|r| format!("0x{r:04X}")).collect::<Vec<_>>().join(" ")
}

fn on_off(bits: &[bool]) -> String {
    bits.iter().map(|&b| if b { "ON" } else { "OFF" }).collect::<Vec<_>>().join(" ")
}

impl WriteArgs {
    /// How the address is numbered (`--one-based`, `--modicon`).
    pub(crate) fn address_args(&self) -> AddressArgs {
        match &self.what {
            WriteCommand::Coil { address_args, .. }
            | WriteCommand::Coils { address_args, .. }
            | WriteCommand::Register { address_args, .. }
            | WriteCommand::Registers { address_args, .. } => *address_args,
        }
    }
}

/// Runs `write`.
pub(crate) async fn run(connection: &ConnectArgs, args: &WriteArgs) -> Result<(), CliError> {
    match &args.what {
        WriteCommand::Coil { address, value, address_args } => {
            let address = match connection.named(address, Table::Coils, ValueArgs::default())? {
                Some((named, _)) => named,
                None => connection.address(address, Table::Coils, *address_args)?,
            };
            let value = parse_coil(value)?;
            let session = &connection.open().await?;
            run_lock::check(connection, session, Span::coils(address.wire, 1), args.force, "write").await?;
            session.client.write_single_coil(session.unit, address.wire, value).await?;
            let line = report(session, FunctionCode::WriteSingleCoil, "coil", address, address.wire, &on_off(&[value]));
            output::print(&line)?;
            Ok(())
        }
        WriteCommand::Coils { address, values, max_per_request, address_args } => {
            let address = connection.address(address, Table::Coils, *address_args)?;
            let bits = values.iter().map(|v| parse_coil(v)).collect::<Result<Vec<_>, _>>()?;
            address.check_span(bits.len())?;
            let max_per_request = connection.max_per_request(*max_per_request, Table::Coils, true)?;
            let max = per_request(max_per_request, MAX_WRITE_COILS, 1, ValueType::U16)?;
            let session = &connection.open().await?;
            run_lock::check(connection, session, Span::coils(address.wire, bits.len()), args.force, "write").await?;
            for (start, n) in split(address.wire, bits.len(), 1, max) {
                let from = usize::from(start - address.wire);
                let chunk = &bits[from..from + n];
                session.client.write_multiple_coils(session.unit, start, chunk).await?;
                let what = plural(n, "coil");
                output::print(&report(
                    session,
                    FunctionCode::WriteMultipleCoils,
                    &what,
                    address,
                    start,
                    &on_off(chunk),
                ))?;
            }
            Ok(())
        }
        WriteCommand::Register { address, value, multiple, values, address_args } => {
            let (address, values) = match connection.named(address, Table::Holding, *values)? {
                Some(named) => named,
                None => (connection.address(address, Table::Holding, *address_args)?, connection.values(*values)?),
            };
            let values = &values;
            let registers = values.encode_all(std::slice::from_ref(value))?;
            address.check_span(registers.len())?;
            let session = &connection.open().await?;
            let span = Span::registers(address.wire, registers.len());
            run_lock::check(connection, session, span, args.force, "write").await?;
            if registers.len() == 1 && !multiple {
                session.client.write_single_register(session.unit, address.wire, registers[0]).await?;
                let data = shown(*values, &registers);
                let line = report(session, FunctionCode::WriteSingleRegister, "register", address, address.wire, &data);
                output::print(&line)?;
                return Ok(());
            }
            write_registers(session, address, &registers, *values, MAX_WRITE_REGISTERS).await
        }
        WriteCommand::Registers { address, value, max_per_request, values, address_args } => {
            let (address, values) = match connection.named(address, Table::Holding, *values)? {
                Some(named) => named,
                None => (connection.address(address, Table::Holding, *address_args)?, connection.values(*values)?),
            };
            let values = &values;
            let registers = values.encode_all(value)?;
            address.check_span(registers.len())?;
            let max_per_request = connection.max_per_request(*max_per_request, Table::Holding, true)?;
            let max = per_request(max_per_request, MAX_WRITE_REGISTERS, values.kind.width(), values.kind)?;
            let session = &connection.open().await?;
            let span = Span::registers(address.wire, registers.len());
            run_lock::check(connection, session, span, args.force, "write").await?;
            write_registers(session, address, &registers, *values, max).await
        }
    }
}

/// The registers written, as on the wire and as the values they are: `0x0004 0x93E0 (u32
/// 300000)`, `0x0032 (u16 50)`.
fn shown(values: ValueArgs, registers: &[u16]) -> String {
    let decoded: Vec<String> = values.decode_all(registers).iter().map(ToString::to_string).collect();
    format!("{} ({} {})", hex_words(registers), values.kind.name(), decoded.join(" "))
}

/// FC10, split at value boundaries into requests of at most `max` registers.
async fn write_registers(
    session: &Session,
    address: Address,
    registers: &[u16],
    values: ValueArgs,
    max: usize,
) -> Result<(), CliError> {
    if registers.is_empty() {
        return Err(PduError::QuantityOutOfRange { quantity: 0, min: 1, max: MAX_WRITE_REGISTERS }.into());
    }
    for (start, n) in split(address.wire, registers.len(), values.kind.width(), max) {
        let from = usize::from(start - address.wire);
        let chunk = &registers[from..from + n];
        tracing::info!(unit = session.unit, start, n = quantity(n), "writing registers");
        session.client.write_multiple_registers(session.unit, start, chunk).await?;
        let data = shown(values, chunk);
        let what = plural(n, "register");
        output::print(&report(session, FunctionCode::WriteMultipleRegisters, &what, address, start, &data))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_write_limits_are_the_specs_1968_coils_and_123_registers() {
        assert_eq!(MAX_WRITE_COILS, 0x07B0);
        assert_eq!(MAX_WRITE_REGISTERS, 0x007B);
    }
}
