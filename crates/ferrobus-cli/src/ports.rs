//! `ferrobus ports`: the serial ports the OS knows, with what identifies each adapter.
//!
//! Linux reads sysfs itself ([`linux`]): `/sys/class/tty/*` with a `device` (virtual consoles
//! and ptys have none; a `ttyS` placeholder of the 8250 driver with no UART behind it says
//! `type` 0), the USB device's `idVendor`, `idProduct`, `manufacturer`, `product` and `serial`
//! found above it, and the stable `/dev/serial/by-id/` link that points at it. That is what
//! libudev would report for these fields, without linking libudev: the binary stays one static
//! file that cross-builds for a Raspberry Pi with no target libudev, and the tests point the
//! reader at a fake tree. macOS (IOKit) and Windows (SetupAPI) use the `serialport` crate's
//! enumeration ([`other`]).

use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use crate::exit::CliError;
use crate::output::{self, Align, Format, OutputArgs, Rows};

#[cfg(target_os = "linux")]
mod linux;
#[cfg(not(target_os = "linux"))]
mod other;

/// `ports [--json|--csv]`.
#[derive(Args, Debug)]
pub(crate) struct PortsArgs {
    /// The output format.
    #[command(flatten)]
    output: OutputArgs,

    /// Read sysfs and /dev under this directory instead of / (Linux; for tests)
    #[arg(long, hide = true, value_name = "DIR")]
    root: Option<PathBuf>,
}

/// One serial port.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub(crate) struct Port {
    /// The device path (`/dev/ttyUSB0`, `COM3`).
    pub(crate) path: String,
    /// What is behind it: `usb`, `pci`, `platform`, `bluetooth` or `unknown`.
    pub(crate) kind: String,
    /// The kernel driver (Linux), e.g. `ftdi_sio`, `cdc_acm`.
    pub(crate) driver: Option<String>,
    /// USB vendor id.
    pub(crate) vid: Option<u16>,
    /// USB product id.
    pub(crate) pid: Option<u16>,
    /// USB manufacturer string.
    pub(crate) manufacturer: Option<String>,
    /// USB product string.
    pub(crate) product: Option<String>,
    /// USB serial number.
    pub(crate) serial_number: Option<String>,
    /// The stable `/dev/serial/by-id/` link (Linux).
    pub(crate) by_id: Option<String>,
}

/// Runs `ports`.
pub(crate) fn run(args: &PortsArgs) -> Result<(), CliError> {
    let ports = list(args.root.as_deref())?;
    let text = match args.output.format() {
        Format::Json => {
            let ports: Vec<_> = ports
                .iter()
                .map(|p| {
                    json!({
                        "path": p.path, "kind": p.kind, "driver": p.driver,
                        "vid": p.vid, "pid": p.pid,
                        "manufacturer": p.manufacturer, "product": p.product,
                        "serial_number": p.serial_number, "by_id": p.by_id,
                    })
                })
                .collect();
            format!("{:#}\n", json!({ "ports": ports }))
        }
        format => {
            if ports.is_empty() && format == Format::Table {
                eprintln!("no serial ports found");
                return Ok(());
            }
            let mut rows = Rows::new(&[
                ("PORT", Align::Left),
                ("KIND", Align::Left),
                ("VID:PID", Align::Left),
                ("MANUFACTURER", Align::Left),
                ("PRODUCT", Align::Left),
                ("SERIAL", Align::Left),
                ("DRIVER", Align::Left),
                ("BY-ID", Align::Left),
            ]);
            let text = |s: &Option<String>| s.clone().unwrap_or_default();
            for p in &ports {
                let ids = match (p.vid, p.pid) {
                    (Some(vid), Some(pid)) => format!("{vid:04x}:{pid:04x}"),
                    _ => String::new(),
                };
                rows.push(vec![
                    p.path.clone(),
                    p.kind.clone(),
                    ids,
                    text(&p.manufacturer),
                    text(&p.product),
                    text(&p.serial_number),
                    text(&p.driver),
                    text(&p.by_id),
                ]);
            }
            rows.render(format)
        }
    };
    output::print(&text)
}

/// The ports, sorted by path.
#[cfg(target_os = "linux")]
fn list(root: Option<&std::path::Path>) -> Result<Vec<Port>, CliError> {
    let root = root.unwrap_or(std::path::Path::new("/"));
    linux::ports(root).map_err(|e| CliError::Usage(format!("cannot list the serial ports: {e}")))
}

/// The ports, sorted by path.
#[cfg(not(target_os = "linux"))]
fn list(root: Option<&std::path::Path>) -> Result<Vec<Port>, CliError> {
    if root.is_some() {
        return Err(CliError::Usage("--root reads a Linux sysfs tree; this is not Linux".into()));
    }
    other::ports().map_err(|e| CliError::Usage(format!("cannot list the serial ports: {e}")))
}
