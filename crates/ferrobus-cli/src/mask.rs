//! `ferrobus mask`: FC16 Mask Write Register.
//!
//! The device computes `(current AND and) OR (or AND NOT and)`: bits set in AND are kept,
//! the others are taken from OR. To set bit 3 only: `mask ADDR 0xFFF7 0x0008`.

use clap::Args;
use ferrobus_proto::FunctionCode;

use crate::address::{ADDRESS_HELP, AddressArgs, Table};
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::output;
use crate::run_lock::{self, Span};
use crate::value::{ValueType, WordOrder, encode};
use crate::write::describe_address;

/// `mask ADDRESS AND OR`.
#[derive(Args, Debug)]
#[command(after_help = ADDRESS_HELP)]
pub(crate) struct MaskArgs {
    /// Holding register address (see below)
    pub(crate) address: String,
    /// AND mask: bits to keep (hex 0x.., binary 0b.. or decimal)
    pub(crate) and_mask: String,
    /// OR mask: values of the bits not kept
    pub(crate) or_mask: String,
    /// Address style.
    #[command(flatten)]
    pub(crate) address_args: AddressArgs,
    /// Write even where the --device profile says the register cannot change while the drive
    /// runs and the drive runs (or cannot say whether it does)
    #[arg(long)]
    pub(crate) force: bool,
}

fn mask(text: &str) -> Result<u16, CliError> {
    Ok(encode(ValueType::U16, WordOrder::Abcd, text)?.first().copied().unwrap_or_default())
}

/// Runs `mask`.
pub(crate) async fn run(connection: &ConnectArgs, args: &MaskArgs) -> Result<(), CliError> {
    let address = connection.address(&args.address, Table::Holding, args.address_args)?;
    let and_mask = mask(&args.and_mask)?;
    let or_mask = mask(&args.or_mask)?;
    let session = connection.open().await?;
    run_lock::check(connection, &session, Span::registers(address.wire, 1), args.force, "mask").await?;
    session.client.mask_write_register(session.unit, address.wire, and_mask, or_mask).await?;
    let who = if session.is_broadcast() { "broadcast".to_string() } else { format!("unit {}", session.unit) };
    output::print(&format!(
        "{who}: FC{:02X} masked register at {}: AND 0x{and_mask:04X} OR 0x{or_mask:04X}\n",
        FunctionCode::MaskWriteRegister.value(),
        describe_address(address, address.wire),
    ))?;
    Ok(())
}
