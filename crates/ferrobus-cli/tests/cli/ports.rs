//! `ferrobus ports`: a fake sysfs tree (Linux) for the USB attributes and the by-id link, and
//! the real system with a pty open, which is no serial port.

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

#[cfg(target_os = "linux")]
use crate::config::Scratch;
use crate::server::{ferrobus, stderr, stdout};

/// An FTDI adapter at ttyUSB0 as Linux 6 lays it out, its by-id link, and a virtual console.
#[cfg(target_os = "linux")]
fn fake_sysfs(root: &std::path::Path) {
    use std::os::unix::fs::symlink;
    let sys = root.join("sys");
    let link = |target: &std::path::Path, at: &std::path::Path| {
        std::fs::create_dir_all(at.parent().unwrap()).unwrap();
        symlink(target, at).unwrap();
    };
    let usb = sys.join("devices/pci0000:00/0000:00:14.0/usb1/1-2");
    std::fs::create_dir_all(&usb).unwrap();
    for (file, text) in [
        ("idVendor", "0403\n"),
        ("idProduct", "6001\n"),
        ("manufacturer", "FTDI\n"),
        ("product", "FT232R USB UART\n"),
        ("serial", "A10K1234\n"),
    ] {
        std::fs::write(usb.join(file), text).unwrap();
    }
    link(&sys.join("bus/usb"), &usb.join("subsystem"));
    let interface = usb.join("1-2:1.0");
    link(&sys.join("bus/usb"), &interface.join("subsystem"));
    link(&sys.join("bus/usb/drivers/ftdi_sio"), &interface.join("driver"));
    let port = interface.join("ttyUSB0");
    link(&sys.join("bus/usb-serial"), &port.join("subsystem"));
    let class = port.join("tty/ttyUSB0");
    link(&port, &class.join("device"));
    link(&class, &sys.join("class/tty/ttyUSB0"));
    let console = sys.join("devices/virtual/tty/tty0");
    std::fs::create_dir_all(&console).unwrap();
    link(&console, &sys.join("class/tty/tty0"));
    link(
        std::path::Path::new("../../ttyUSB0"),
        &root.join("dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"),
    );
}

#[cfg(target_os = "linux")]
#[test]
fn ports_json_gives_the_usb_ids_strings_and_by_id_path_from_sysfs() {
    let root = Scratch::new("ports-json");
    fake_sysfs(&root.0);
    let out = ferrobus().args(["ports", "--json", "--root", root.0.to_str().unwrap()]).assert().success();
    let doc: Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(
        doc,
        serde_json::json!({"ports": [{
            "path": "/dev/ttyUSB0", "kind": "usb", "driver": "ftdi_sio", "vid": 0x0403, "pid": 0x6001,
            "manufacturer": "FTDI", "product": "FT232R USB UART", "serial_number": "A10K1234",
            "by_id": "/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0",
        }]})
    );
}

#[cfg(target_os = "linux")]
#[test]
fn ports_table_shows_vid_pid_in_hex_and_the_by_id_path() {
    let root = Scratch::new("ports-table");
    fake_sysfs(&root.0);
    let out = ferrobus().args(["ports", "--root", root.0.to_str().unwrap()]).assert().success();
    let text = stdout(&out);
    let mut lines = text.lines();
    assert!(lines.next().unwrap().starts_with("PORT "), "{text}");
    let row = lines.next().unwrap();
    for cell in ["/dev/ttyUSB0", "usb", "0403:6001", "FTDI", "FT232R USB UART", "A10K1234", "ftdi_sio"] {
        assert!(row.contains(cell), "{cell} in {row}");
    }
    assert!(row.ends_with("/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"), "{row}");
    assert_eq!(lines.next(), None);
}

#[cfg(target_os = "linux")]
#[test]
fn no_ports_is_said_on_stderr_and_an_empty_list_in_json() {
    let root = Scratch::new("ports-empty");
    std::fs::create_dir_all(root.0.join("sys/class/tty")).unwrap();
    let out = ferrobus().args(["ports", "--root", root.0.to_str().unwrap()]).assert().success();
    assert_eq!(stdout(&out), "");
    assert_eq!(stderr(&out), "no serial ports found\n");
    let out = ferrobus().args(["ports", "--json", "--root", root.0.to_str().unwrap()]).assert().success();
    assert_eq!(serde_json::from_str::<Value>(&stdout(&out)).unwrap(), serde_json::json!({"ports": []}));
}

#[cfg(target_os = "linux")]
#[test]
fn a_root_without_sysfs_is_an_error_naming_what_failed() {
    let root = Scratch::new("ports-nosys");
    let out = ferrobus().args(["ports", "--root", root.0.to_str().unwrap()]).assert().code(2);
    assert!(stderr(&out).starts_with("error: cannot list the serial ports: "), "{}", stderr(&out));
}

#[test]
fn the_real_system_lists_its_ports_and_an_open_pty_is_not_one() {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let pty = runtime.block_on(async { ferrobus::Pty::open() }).unwrap();
    let out = ferrobus().args(["ports", "--json"]).assert().success();
    let doc: Value = serde_json::from_str(&stdout(&out)).unwrap();
    let paths: Vec<&str> = doc["ports"].as_array().unwrap().iter().map(|p| p["path"].as_str().unwrap()).collect();
    let pty_path = pty.path.display().to_string();
    assert!(!paths.contains(&pty_path.as_str()), "{pty_path} in {paths:?}");
    assert!(paths.iter().all(|p| p.starts_with("/dev/tty") || p.starts_with("/dev/cu.")), "{paths:?}");
}

#[test]
fn ports_refuses_connection_options_it_would_ignore() {
    let out = ferrobus().args(["ports", "--baud", "9600"]).assert().code(2);
    assert!(stderr(&out).contains("--baud is not used by `ports`"), "{}", stderr(&out));
}
