//! `ferrobus raw`: send any PDU, show the reply bytes and what they mean.

use clap::Args;
use ferrobus::Error;
use ferrobus_proto::FunctionCode;
use ferrobus_proto::pdu::{MAX_PDU_LEN, Request, Response};

use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::hex;
use crate::output;
use crate::run_lock::{self, Span};

/// `raw HEX...`.
#[derive(Args, Debug)]
pub(crate) struct RawArgs {
    /// The PDU in hex, function code first: `03 00 00 00 02` or `030000 0002`
    #[arg(required = true, num_args = 1..)]
    pub(crate) bytes: Vec<String>,

    /// Send a write even where the --device profile says what it writes cannot change while the
    /// drive runs and the drive runs (or cannot say whether it does)
    #[arg(long)]
    pub(crate) force: bool,
}

/// Runs `raw`.
pub(crate) async fn run(connection: &ConnectArgs, args: &RawArgs) -> Result<(), CliError> {
    let pdu = hex::parse_args(&args.bytes).map_err(|e| CliError::Usage(e.to_string()))?;
    if pdu.len() > MAX_PDU_LEN {
        return Err(ferrobus_proto::PduError::TooLong { len: pdu.len() }.into());
    }
    let function = FunctionCode::from_u8(pdu[0]);
    let session = connection.open().await?;
    match Request::parse(&pdu) {
        Ok(request) => {
            if let Some(span) = Span::of_request(&request) {
                run_lock::check(connection, &session, span, args.force, "raw").await?;
            }
            output::print(&format!("request  {}  ({})\n", hex::format(&pdu), request.function()))?;
        }
        Err(e) => {
            eprintln!("note: not a valid {function} request ({e}); sending it as is");
            output::print(&format!("request  {}\n", hex::format(&pdu)))?;
        }
    }
    match session.client.raw(session.unit, &pdu).await {
        Ok(Some(reply)) => {
            let decoded = match Response::parse(&reply) {
                Ok(response) => format!("{response:?}"),
                Err(e) => format!("(not a valid response: {e})"),
            };
            output::print(&format!("reply    {}\ndecoded  {decoded}\n", hex::format(&reply)))?;
            Ok(())
        }
        Ok(None) => {
            output::print("sent; no reply expected (broadcast or listen-only)\n")?;
            Ok(())
        }
        Err(Error::Exception { unit, function, code }) => {
            let bytes = [function.value() | FunctionCode::EXCEPTION_BIT, code.value()];
            output::print(&format!("reply    {}\n", hex::format(&bytes)))?;
            Err(Error::Exception { unit, function, code }.into())
        }
        Err(e) => Err(e.into()),
    }
}
