//! Serial ports on macOS (IOKit) and Windows (SetupAPI), through the `serialport` crate.

use super::Port;

/// The ports the OS knows, sorted by name.
pub(super) fn ports() -> Result<Vec<Port>, serialport::Error> {
    let mut ports: Vec<Port> = serialport::available_ports()?
        .into_iter()
        .map(|info| {
            let mut port = Port { path: info.port_name, ..Port::default() };
            match info.port_type {
                serialport::SerialPortType::UsbPort(usb) => {
                    port.kind = "usb".into();
                    port.vid = Some(usb.vid);
                    port.pid = Some(usb.pid);
                    port.manufacturer = usb.manufacturer;
                    port.product = usb.product;
                    port.serial_number = usb.serial_number;
                }
                serialport::SerialPortType::PciPort => port.kind = "pci".into(),
                serialport::SerialPortType::BluetoothPort => port.kind = "bluetooth".into(),
                serialport::SerialPortType::Unknown => port.kind = "unknown".into(),
            }
            port
        })
        .collect();
    ports.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(ports)
}
