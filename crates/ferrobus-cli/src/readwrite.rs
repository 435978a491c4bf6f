//! `ferrobus readwrite`: FC17, a write then a read in one transaction.

use clap::Args;
use ferrobus_proto::FunctionCode;

use crate::address::{ADDRESS_HELP, AddressArgs, Table};
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::output::{self, Format, OutputArgs, ReadData};
use crate::run_lock::{self, Span};
use crate::value::ValueArgs;

/// `readwrite --read ADDRESS --count N --write ADDRESS VALUE...`.
#[derive(Args, Debug)]
#[command(after_help = ADDRESS_HELP)]
pub(crate) struct ReadWriteArgs {
    /// First holding register to read (see below)
    #[arg(long, value_name = "ADDRESS")]
    pub(crate) read: String,

    /// Values to read (registers, or 32-bit values with --type u32/i32/f32)
    #[arg(long, short = 'c', default_value_t = 1)]
    pub(crate) count: u16,

    /// First holding register to write, then the values (written before the read)
    #[arg(long, num_args = 2.., value_names = ["ADDRESS", "VALUE"], allow_negative_numbers = true, required = true)]
    pub(crate) write: Vec<String>,

    /// Address style (both addresses).
    #[command(flatten)]
    pub(crate) address_args: AddressArgs,

    /// Value types (both directions).
    #[command(flatten)]
    pub(crate) values: ValueArgs,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,

    /// Write even where the --device profile says a register cannot change while the drive
    /// runs and the drive runs (or cannot say whether it does)
    #[arg(long)]
    pub(crate) force: bool,
}

/// Runs `readwrite`.
pub(crate) async fn run(connection: &ConnectArgs, args: &ReadWriteArgs) -> Result<(), CliError> {
    connection.refuse_broadcast_read()?;
    let read = connection.address(&args.read, Table::Holding, args.address_args)?;
    let (write_at, texts) =
        args.write.split_first().ok_or_else(|| CliError::Usage("--write needs an address".into()))?;
    let write = connection.address(write_at, Table::Holding, args.address_args)?;
    let registers = args.values.encode_all(texts)?;
    let count = usize::from(args.count) * args.values.kind.width();
    read.check_span(count)?;
    write.check_span(registers.len())?;
    let read_count = u16::try_from(count).unwrap_or(u16::MAX);
    let session = connection.open().await?;
    let span = Span::registers(write.wire, registers.len());
    run_lock::check(connection, &session, span, args.force, "readwrite").await?;
    let got = session
        .client
        .read_write_multiple_registers(session.unit, read.wire, read_count, write.wire, &registers)
        .await?;
    let text = match args.output.format() {
        Format::Json => {
            let mut doc = output::read_json(
                session.unit,
                FunctionCode::ReadWriteMultipleRegisters.value(),
                read,
                ReadData::Registers(&got, args.values),
                1,
            );
            doc["write_start"] = write.wire.into();
            doc["written"] = registers.into();
            output::json_line(&doc)
        }
        other => output::register_rows(read, read.wire, &got, args.values).render(other),
    };
    output::print(&text)?;
    Ok(())
}
