//! `ferrobus read`: FC01–FC04, split into as many requests as the device takes.

use clap::Args;
use ferrobus_proto::PduError;

use crate::address::{ADDRESS_HELP, AddressArgs, Table, per_request, quantity, split};
use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output::{self, Format, OutputArgs, ReadData};
use crate::value::{ValueArgs, ValueType};

/// `read TABLE ADDRESS`.
#[derive(Args, Debug)]
#[command(after_help = ADDRESS_HELP)]
pub(crate) struct ReadArgs {
    /// Which table: coils (FC01), discrete (FC02), holding (FC03), input (FC04)
    #[arg(value_enum, hide_possible_values = true)]
    pub(crate) table: Table,

    /// First address (see below)
    pub(crate) address: String,

    /// Number of values: bits, registers, or 32-bit values with --type u32/i32/f32
    #[arg(long, short = 'c', default_value_t = 1)]
    pub(crate) count: u32,

    /// Most registers (or bits) per request; longer reads are split, never inside a 32-bit
    /// value [default: 125 registers, 2000 bits; the 3G3RX takes 4]
    #[arg(long = "max-per-request", value_name = "N")]
    pub(crate) max_per_request: Option<u16>,

    /// Address style.
    #[command(flatten)]
    pub(crate) address_args: AddressArgs,

    /// Value types.
    #[command(flatten)]
    pub(crate) values: ValueArgs,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// Runs `read`.
pub(crate) async fn run(connection: &ConnectArgs, args: &ReadArgs) -> Result<(), CliError> {
    connection.refuse_broadcast_read()?;
    let (address, values) = match connection.named(&args.address, args.table, args.values)? {
        Some(named) => named,
        None => (connection.address(&args.address, args.table, args.address_args)?, connection.values(args.values)?),
    };
    let table = args.table;
    if table.is_bits() && values.kind != ValueType::U16 {
        return Err(CliError::Usage(format!("--type applies to registers, not to {table}")));
    }
    let width = values.kind.width();
    let items = usize::try_from(args.count).unwrap_or(usize::MAX).saturating_mul(width);
    if items == 0 {
        return Err(PduError::QuantityOutOfRange { quantity: 0, min: 1, max: table.max_read() }.into());
    }
    address.check_span(items)?;
    let max_per_request = connection.max_per_request(args.max_per_request, table, false)?;
    let max = per_request(max_per_request, table.max_read(), width, values.kind)?;
    let pieces = split(address.wire, items, width, max);
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let client = &session.client;
    let unit = session.unit;
    let format = args.output.format();
    let function = table.read_function().value();
    if table.is_bits() {
        let (bits, requests, interrupted) = gather(&pieces, items, &mut interrupt, |start, n| async move {
            tracing::info!(unit, start, n, "reading {table}");
            match table {
                Table::Coils => client.read_coils(unit, start, n).await,
                _ => client.read_discrete_inputs(unit, start, n).await,
            }
        })
        .await?;
        let text = match format {
            Format::Json => {
                output::json_line(&output::read_json(unit, function, address, ReadData::Bits(&bits), requests))
            }
            other => output::bit_rows(address, address.wire, &bits).render(other),
        };
        output::print(&text)?;
        return finish(interrupted, bits.len(), items, table);
    }
    let (registers, requests, interrupted) = gather(&pieces, items, &mut interrupt, |start, n| async move {
        tracing::info!(unit, start, n, "reading {table} registers");
        match table {
            Table::Holding => client.read_holding_registers(unit, start, n).await,
            _ => client.read_input_registers(unit, start, n).await,
        }
    })
    .await?;
    let text = match format {
        Format::Json => output::json_line(&output::read_json(
            unit,
            function,
            address,
            ReadData::Registers(&registers, values),
            requests,
        )),
        other => output::register_rows(address, address.wire, &registers, values).render(other),
    };
    output::print(&text)?;
    finish(interrupted, registers.len(), items, table)
}

/// Reads each of `pieces` (start, count) with `read`, in order, until all are read or a signal
/// comes: the items read (room for `capacity`), the requests made, and whether it was cut short.
async fn gather<T, R: Future<Output = Result<Vec<T>, ferrobus::Error>>>(
    pieces: &[(u16, usize)],
    capacity: usize,
    interrupt: &mut Interrupt,
    mut read: impl FnMut(u16, u16) -> R,
) -> Result<(Vec<T>, usize, bool), CliError> {
    let mut items = Vec::with_capacity(capacity);
    for (requests, &(start, n)) in pieces.iter().enumerate() {
        let Some(got) = interrupt.unless(read(start, quantity(n))).await else {
            return Ok((items, requests, true));
        };
        items.extend(got?);
    }
    Ok((items, pieces.len(), false))
}

/// After the output: [`CliError::Interrupted`] with a note of how much was read, if a signal
/// cut the read short.
fn finish(interrupted: bool, done: usize, asked: usize, table: Table) -> Result<(), CliError> {
    if !interrupted {
        return Ok(());
    }
    eprintln!("read: interrupted after {done} of {asked} {}s; the output holds those read", table.item());
    Err(CliError::Interrupted)
}
