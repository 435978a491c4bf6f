//! Serial ports on Linux, from sysfs (see the parent module for why not libudev).
//!
//! For each `ROOT/sys/class/tty/NAME` with a `device` link: the device directory it resolves
//! to, and above it (a few levels up at most) the USB device with `idVendor`; the first
//! ancestor's subsystem that is a bus (`usb`, `pci`, `pnp`, `platform`, ...) is the kind, and the
//! first driver bound above the serial core is the driver. `ROOT/dev/serial/by-id/*` links are
//! matched by the name they point at.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use super::Port;

/// How many directories above a tty's device the USB device may be (usb-serial: the port, the
/// interface, the device).
const ANCESTORS: usize = 6;

/// Subsystems of the serial core itself, passed over when looking for the bus and the driver.
const SERIAL_CORE: [&str; 4] = ["serial-base", "tty", "usb-serial", "serial"];

/// The serial ports under `root` (`/` on a real system), sorted by path.
pub(super) fn ports(root: &Path) -> io::Result<Vec<Port>> {
    let class = root.join("sys/class/tty");
    let by_id = by_id_links(&root.join("dev/serial/by-id"));
    let mut ports = Vec::new();
    for entry in fs::read_dir(&class)? {
        let entry = entry?;
        let tty = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        // Virtual consoles, ptys and the console have no device.
        let Ok(device) = fs::canonicalize(tty.join("device")) else { continue };
        // The 8250 driver makes ttyS0-ttySn whether or not a UART is there: type 0 is none.
        if read_trimmed(&tty.join("type")).is_some_and(|t| t == "0") {
            continue;
        }
        let mut port = describe(&device);
        port.path = format!("/dev/{name}");
        port.by_id = by_id.iter().find(|(_, target)| *target == name).map(|(link, _)| link.clone());
        ports.push(port);
    }
    ports.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(ports)
}

/// What the device directory of a tty and its ancestors say.
fn describe(device: &Path) -> Port {
    let mut port = Port::default();
    let mut bus = None;
    for dir in device.ancestors().take(ANCESTORS) {
        let subsystem = link_name(&dir.join("subsystem"));
        let core = subsystem.as_deref().is_some_and(|s| SERIAL_CORE.contains(&s));
        if port.driver.is_none() && !core {
            port.driver = link_name(&dir.join("driver"));
        }
        if bus.is_none() && !core {
            bus.clone_from(&subsystem);
        }
        if let Some(vid) = read_hex(&dir.join("idVendor")) {
            port.vid = Some(vid);
            port.pid = read_hex(&dir.join("idProduct"));
            port.manufacturer = read_trimmed(&dir.join("manufacturer"));
            port.product = read_trimmed(&dir.join("product"));
            port.serial_number = read_trimmed(&dir.join("serial"));
            bus = Some("usb".into());
            break;
        }
    }
    port.kind = bus.unwrap_or_else(|| "unknown".into());
    port
}

/// `(link path, name of the tty it points at)` for each link in `dir` (none if there is no dir).
fn by_id_links(dir: &Path) -> Vec<(String, String)> {
    let Ok(entries) = fs::read_dir(dir) else { return Vec::new() };
    let mut links: Vec<(String, String)> = entries
        .filter_map(Result::ok)
        .filter_map(|entry| {
            let target = fs::read_link(entry.path()).ok()?;
            let name = target.file_name()?.to_string_lossy().into_owned();
            let link = PathBuf::from("/dev/serial/by-id").join(entry.file_name());
            Some((link.to_string_lossy().into_owned(), name))
        })
        .collect();
    links.sort();
    links
}

/// The last component of a symlink's target (`driver` -> `ftdi_sio`).
fn link_name(path: &Path) -> Option<String> {
    fs::read_link(path).ok()?.file_name().map(|n| n.to_string_lossy().into_owned())
}

/// A sysfs attribute without its newline; none if missing, unreadable or empty.
fn read_trimmed(path: &Path) -> Option<String> {
    let text = fs::read_to_string(path).ok()?;
    let text = text.trim();
    (!text.is_empty()).then(|| text.to_string())
}

/// A sysfs attribute in hex (`idVendor` is `0403`).
fn read_hex(path: &Path) -> Option<u16> {
    u16::from_str_radix(&read_trimmed(path)?, 16).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;

    /// A scratch directory removed at the end of the test.
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(name: &str) -> Scratch {
            let dir = std::env::temp_dir().join(format!("ferrobus-ports-{name}-{}", std::process::id()));
            let _ = fs::remove_dir_all(&dir);
            fs::create_dir_all(&dir).unwrap();
            Scratch(dir)
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    fn write(path: &Path, text: &str) {
        fs::create_dir_all(path.parent().unwrap()).unwrap();
        fs::write(path, text).unwrap();
    }

    /// A sysfs tree as Linux 6 lays it out: an FTDI adapter on USB (ttyUSB0), a 16550A on PNP
    /// (ttyS0), an 8250 placeholder with no UART (ttyS1), a virtual console and ptmx.
    pub(crate) fn fake_tree(root: &Path) {
        let sys = root.join("sys");
        let link = |target: &Path, at: &Path| {
            fs::create_dir_all(at.parent().unwrap()).unwrap();
            symlink(target, at).unwrap();
        };
        let usb = sys.join("devices/pci0000:00/0000:00:14.0/usb1/1-2");
        for (file, text) in [
            ("idVendor", "0403\n"),
            ("idProduct", "6001\n"),
            ("manufacturer", "FTDI\n"),
            ("product", "FT232R USB UART\n"),
            ("serial", "A10K1234\n"),
        ] {
            write(&usb.join(file), text);
        }
        link(&sys.join("bus/usb"), &usb.join("subsystem"));
        let interface = usb.join("1-2:1.0");
        link(&sys.join("bus/usb"), &interface.join("subsystem"));
        link(&sys.join("bus/usb/drivers/ftdi_sio"), &interface.join("driver"));
        let port = interface.join("ttyUSB0");
        link(&sys.join("bus/usb-serial"), &port.join("subsystem"));
        link(&sys.join("bus/usb-serial/drivers/ftdi_sio"), &port.join("driver"));
        let class = port.join("tty/ttyUSB0");
        link(&port, &class.join("device"));
        link(&class, &sys.join("class/tty/ttyUSB0"));

        let pnp = sys.join("devices/pnp0/00:00");
        link(&sys.join("bus/pnp"), &pnp.join("subsystem"));
        link(&sys.join("bus/pnp/drivers/serial"), &pnp.join("driver"));
        link(&sys.join("bus/serial-base"), &pnp.join("00:00:0/subsystem"));
        let uart = pnp.join("00:00:0/00:00:0.0");
        link(&sys.join("bus/serial-base"), &uart.join("subsystem"));
        link(&sys.join("bus/serial-base/drivers/port"), &uart.join("driver"));
        let class = uart.join("tty/ttyS0");
        write(&class.join("type"), "4\n");
        link(&uart, &class.join("device"));
        link(&class, &sys.join("class/tty/ttyS0"));

        let placeholder = sys.join("devices/platform/serial8250/serial8250:0/serial8250:0.1");
        link(&sys.join("bus/serial-base"), &placeholder.join("subsystem"));
        let class = placeholder.join("tty/ttyS1");
        write(&class.join("type"), "0\n");
        link(&placeholder, &class.join("device"));
        link(&class, &sys.join("class/tty/ttyS1"));

        for virtual_tty in ["tty0", "ptmx"] {
            let class = sys.join("devices/virtual/tty").join(virtual_tty);
            write(&class.join("dev"), "4:0\n");
            link(&class, &sys.join("class/tty").join(virtual_tty));
        }
        link(Path::new("../../ttyUSB0"), &root.join("dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"));
    }

    #[test]
    fn a_usb_adapter_is_found_with_its_ids_strings_driver_and_by_id_link() {
        let root = Scratch::new("usb");
        let root = &root.0;
        fake_tree(root);
        let ports = ports(root).unwrap();
        let usb = ports.iter().find(|p| p.path == "/dev/ttyUSB0").unwrap();
        assert_eq!(usb.kind, "usb");
        assert_eq!((usb.vid, usb.pid), (Some(0x0403), Some(0x6001)));
        assert_eq!(usb.manufacturer.as_deref(), Some("FTDI"));
        assert_eq!(usb.product.as_deref(), Some("FT232R USB UART"));
        assert_eq!(usb.serial_number.as_deref(), Some("A10K1234"));
        assert_eq!(usb.driver.as_deref(), Some("ftdi_sio"));
        assert_eq!(usb.by_id.as_deref(), Some("/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"));
    }

    #[test]
    fn consoles_ptys_and_empty_8250_placeholders_are_not_ports() {
        let root = Scratch::new("skip");
        let root = &root.0;
        fake_tree(root);
        let paths: Vec<String> = ports(root).unwrap().into_iter().map(|p| p.path).collect();
        assert_eq!(paths, ["/dev/ttyS0", "/dev/ttyUSB0"]);
    }

    #[test]
    fn a_uart_without_usb_has_its_bus_as_kind_and_no_ids() {
        let root = Scratch::new("uart");
        let root = &root.0;
        fake_tree(root);
        let ports = ports(root).unwrap();
        let uart = ports.iter().find(|p| p.path == "/dev/ttyS0").unwrap();
        assert_eq!(uart.kind, "pnp");
        assert_eq!(uart.driver.as_deref(), Some("serial"));
        assert_eq!((uart.vid, uart.by_id.as_ref()), (None, None));
    }

    #[test]
    fn garbage_in_an_attribute_is_left_out_not_fatal() {
        let root = Scratch::new("garbage");
        let root = &root.0;
        fake_tree(root);
        let usb = root.join("sys/devices/pci0000:00/0000:00:14.0/usb1/1-2");
        write(&usb.join("idVendor"), "zz\n");
        let ports = ports(root).unwrap();
        let port = ports.iter().find(|p| p.path == "/dev/ttyUSB0").unwrap();
        assert_eq!(port.vid, None);
        // The interface above the port is still on the USB bus.
        assert_eq!(port.kind, "usb");
    }

    #[test]
    fn a_missing_sysfs_is_an_error() {
        let root = Scratch::new("none");
        assert!(ports(&root.0).is_err());
    }

    #[test]
    fn the_real_system_lists_without_error_and_never_a_pty() {
        let ports = ports(Path::new("/")).unwrap();
        assert!(ports.iter().all(|p| !p.path.starts_with("/dev/pts/") && p.path != "/dev/ptmx"), "{ports:?}");
    }
}
