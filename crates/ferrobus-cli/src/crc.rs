//! `ferrobus crc`: checksums and framing, offline.
//!
//! CRC-16/MODBUS goes on the wire low byte first (MODBUS over Serial Line V1.02 §2.5.1.2):
//! `01 10 01 12 00 02` has CRC 0x31E0, sent as `E0 31`. The ASCII frame carries the LRC
//! instead, the two's complement of the byte sum (§2.5.2.2).

use clap::Args;
use ferrobus_proto::crc::{crc16, crc16_wire};
use ferrobus_proto::frame::ascii::lrc;

use crate::exit::CliError;
use crate::hex;
use crate::output;

/// `crc HEX... [--check]`.
#[derive(Args, Debug)]
pub(crate) struct CrcArgs {
    /// Bytes in hex: unit address and PDU (or a whole RTU frame with --check)
    #[arg(required = true, num_args = 1..)]
    pub(crate) bytes: Vec<String>,

    /// The input is a whole RTU frame: check its last two bytes (exit 5 if wrong)
    #[arg(long)]
    pub(crate) check: bool,
}

/// Runs `crc`.
pub(crate) fn run(args: &CrcArgs) -> Result<(), CliError> {
    let bytes = hex::parse_args(&args.bytes).map_err(|e| CliError::Usage(e.to_string()))?;
    if args.check {
        return check(&bytes);
    }
    let crc = crc16(&bytes);
    let wire = crc16_wire(&bytes);
    let mut frame = bytes.clone();
    frame.extend(wire);
    let lrc = lrc(&bytes);
    let ascii = hex::format(&bytes).replace(' ', "") + &format!("{lrc:02X}");
    output::print(&format!(
        "CRC-16/MODBUS  0x{crc:04X}\n\
         wire bytes     {}  (low byte first)\n\
         RTU frame      {}\n\
         LRC            0x{lrc:02X}\n\
         ASCII frame    :{ascii}\\r\\n\n",
        hex::format(&wire),
        hex::format(&frame),
    ))?;
    Ok(())
}

fn check(frame: &[u8]) -> Result<(), CliError> {
    let Some((body, found)) = frame.split_last_chunk::<2>().filter(|(body, _)| !body.is_empty()) else {
        return Err(CliError::Usage("--check needs a whole RTU frame: at least one byte and the two CRC bytes".into()));
    };
    let expected = crc16_wire(body);
    if *found == expected {
        output::print(&format!("CRC OK: {} (0x{:04X})\n", hex::format(found), crc16(body)))?;
        return Ok(());
    }
    Err(CliError::BadData(format!(
        "CRC wrong: the frame ends with {}, expected {} (0x{:04X}); the correct frame is {} {}",
        hex::format(found),
        hex::format(&expected),
        crc16(body),
        hex::format(body),
        hex::format(&expected),
    )))
}
