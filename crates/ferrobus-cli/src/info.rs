//! `ferrobus info`: device identification (FC2B/0E) or the server id (FC11).
//!
//! Spec: MODBUS Application Protocol V1.1b3 §6.21 and §6.13. The basic objects come first;
//! the device's conformity level says whether regular (0x03–0x7F) and extended (0x80–0xFF)
//! objects exist, and each category is read to its end, following "more follows". A device
//! without FC2B (exception 01) is asked for FC11 instead.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use clap::Args;
use ferrobus::Error;
use ferrobus_proto::codes::{ReadDeviceIdCode, conformity, device_object};
use ferrobus_proto::{ExceptionCode, FunctionCode};
use serde_json::json;

use crate::connect::{ConnectArgs, Session};
use crate::exit::CliError;
use crate::hex;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `info [--server-id]`.
#[derive(Args, Debug)]
pub(crate) struct InfoArgs {
    /// Ask for the server id (FC11) instead of the identification objects
    #[arg(long = "server-id")]
    pub(crate) server_id: bool,

    /// Output format.
    #[command(flatten)]
    pub(crate) output: OutputArgs,
}

/// Runs `info`.
pub(crate) async fn run(connection: &ConnectArgs, args: &InfoArgs) -> Result<(), CliError> {
    connection.refuse_broadcast_read()?;
    let session = &connection.open().await?;
    let format = args.output.format();
    if args.server_id {
        return server_id(session, format).await;
    }
    let client = &session.client;
    let unit = session.unit;
    let basic = match client.read_device_identification(unit, ReadDeviceIdCode::Basic, 0).await {
        Ok(info) => info,
        Err(Error::Exception { code: ExceptionCode::IllegalFunction, .. }) => {
            eprintln!(
                "note: unit {unit} does not support FC2B/0E device identification (exception 0x01 Illegal \
                 Function); trying FC11 Report Server ID"
            );
            return server_id(session, format).await;
        }
        Err(e) => return Err(e.into()),
    };
    let conformity = basic.conformity;
    let mut objects: BTreeMap<u8, Vec<u8>> = BTreeMap::new();
    keep(&mut objects, basic.objects, 0x00, 0x02);
    let level = conformity & 0x7F;
    for (code, first, last, name) in
        [(ReadDeviceIdCode::Regular, 0x03, 0x7F, "regular"), (ReadDeviceIdCode::Extended, 0x80, 0xFF, "extended")]
    {
        if level < code.value() {
            continue;
        }
        match client.read_device_identification(unit, code, first).await {
            Ok(info) => keep(&mut objects, info.objects, first, last),
            Err(Error::Exception { code: exception, .. }) => {
                eprintln!("note: unit {unit} refused the {name} objects with exception {exception}");
            }
            Err(e) => return Err(e.into()),
        }
    }
    let text = match format {
        Format::Json => {
            let list: Vec<_> = objects
                .iter()
                .map(|(&id, value)| {
                    let mut o = json!({ "id": id, "name": object_name(id), "hex": hex::format(value) });
                    if let Some(text) = as_text(value) {
                        o["value"] = text.into();
                    }
                    o
                })
                .collect();
            output::json_line(&json!({
                "unit": unit,
                "function": FunctionCode::EncapsulatedInterface.value(),
                "conformity": conformity,
                "objects": list,
            }))
        }
        other => {
            let mut rows = Rows::new(&[("id", Align::Left), ("name", Align::Left), ("value", Align::Left)]);
            for (&id, value) in &objects {
                let shown = as_text(value).unwrap_or_else(|| format!("[hex] {}", hex::format(value)));
                rows.push(vec![format!("0x{id:02X}"), object_name(id), shown]);
            }
            let body = rows.render(other);
            if other == Format::Csv {
                body
            } else {
                format!("unit {unit}: conformity 0x{conformity:02X} ({})\n{body}", describe_conformity(conformity))
            }
        }
    };
    output::print(&text)?;
    Ok(())
}

/// Adds the objects within `first..=last` (a device may restart a stream from object 0).
fn keep(into: &mut BTreeMap<u8, Vec<u8>>, objects: Vec<(u8, Vec<u8>)>, first: u8, last: u8) {
    for (id, value) in objects {
        if (first..=last).contains(&id) {
            into.entry(id).or_insert(value);
        }
    }
}

fn object_name(id: u8) -> String {
    match device_object::name(id) {
        Some(name) => name.to_string(),
        None if id >= 0x80 => "(extended)".to_string(),
        None => "(reserved)".to_string(),
    }
}

fn describe_conformity(level: u8) -> String {
    let category = match conformity::category(level) {
        Some(category) => category.name().unwrap_or("unknown level"),
        None => "unknown level",
    };
    let access =
        if conformity::individual_access(level) { "stream and individual access" } else { "stream access only" };
    format!("{category}, {access}")
}

/// The value as text, if it is printable UTF-8.
fn as_text(value: &[u8]) -> Option<String> {
    let text = std::str::from_utf8(value).ok()?;
    text.chars().all(|c| !c.is_control()).then(|| text.to_string())
}

/// Printable ASCII, `.` for anything else.
fn ascii(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| if b.is_ascii_graphic() || b == b' ' { char::from(b) } else { '.' }).collect()
}

async fn server_id(session: &Session, format: Format) -> Result<(), CliError> {
    let unit = session.unit;
    let data = session.client.report_server_id(unit).await?;
    let text = match format {
        Format::Json => output::json_line(&json!({
            "unit": unit,
            "function": FunctionCode::ReportServerId.value(),
            "data": hex::format(&data),
            "ascii": ascii(&data),
        })),
        Format::Csv => {
            let mut rows = Rows::new(&[("offset", Align::Left), ("hex", Align::Left), ("ascii", Align::Left)]);
            for (i, line) in data.chunks(16).enumerate() {
                rows.push(vec![format!("{:04X}", i * 16), hex::format(line), ascii(line)]);
            }
            rows.csv()
        }
        Format::Table => {
            let mut out =
                format!("unit {unit}: server id, run indicator and device data, {} bytes (FC11)\n", data.len());
            for (i, line) in data.chunks(16).enumerate() {
                let _ = writeln!(out, "{:04X}  {:<47}  |{}|", i * 16, hex::format(line), ascii(line));
            }
            // The server id's length is device-specific; most devices use one byte.
            if let [id, run @ (0x00 | 0xFF), ..] = data.as_slice() {
                let state = if *run == 0xFF { "ON" } else { "OFF" };
                let _ = writeln!(out, "if the server id is one byte: id 0x{id:02X}, run indicator {state}");
            }
            out
        }
    };
    output::print(&text)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objects_have_standard_names_and_text_or_hex() {
        assert_eq!(object_name(0x00), "VendorName");
        assert_eq!(object_name(0x06), "UserApplicationName");
        assert_eq!(object_name(0x07), "(reserved)");
        assert_eq!(object_name(0x80), "(extended)");
        assert_eq!(as_text(b"ferrobus").as_deref(), Some("ferrobus"));
        assert_eq!(as_text(&[0x00, 0xFF]), None);
        assert_eq!(ascii(b"ab\x00\xFF"), "ab..");
        assert_eq!(describe_conformity(0x83), "extended, stream and individual access");
    }

    #[test]
    fn a_restarted_stream_does_not_duplicate_objects() {
        let mut all = BTreeMap::new();
        keep(&mut all, vec![(0, b"a".to_vec()), (3, b"b".to_vec())], 0, 2);
        keep(&mut all, vec![(0, b"x".to_vec()), (3, b"b".to_vec())], 3, 0x7F);
        assert_eq!(all.len(), 2);
        assert_eq!(all[&0], b"a");
    }
}
