//! What a Unix path names, for reopening only the same device (see [`Identity`]).

use std::os::unix::fs::MetadataExt;
use std::path::Path;

use super::tty::is_pty_path;
use crate::identity::Identity;

/// What `path` names now. `None` when it cannot be told (the path is gone).
pub(crate) fn identify(path: &Path) -> Option<Identity> {
    let link = std::fs::symlink_metadata(path).ok()?;
    if link.file_type().is_symlink() {
        return Some(Identity::Named);
    }
    let real = std::fs::canonicalize(path).ok()?;
    if is_pty_path(&real) {
        return Some(Identity::Pty(real));
    }
    if let Some(hardware) = real.file_name().and_then(|name| sysfs_identity(&Path::new("/sys/class/tty").join(name))) {
        return Some(Identity::Hardware(hardware));
    }
    Some(Identity::Node(link.rdev()))
}

/// The identity of the tty whose sysfs class directory is `class` (`/sys/class/tty/ttyUSB0`):
/// USB ids and serial number from the USB device above it, else its device-tree path.
fn sysfs_identity(class: &Path) -> Option<String> {
    let device = std::fs::canonicalize(class.join("device")).ok()?;
    for dir in device.ancestors().take(8) {
        let read = |name: &str| std::fs::read_to_string(dir.join(name)).ok().map(|s| s.trim().to_owned());
        if let (Some(vendor), Some(product)) = (read("idVendor"), read("idProduct")) {
            let at = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            // The interface matters too: a dual-port adapter has one serial number for two ttys.
            let interface = device
                .ancestors()
                .find(|d| d.parent() == Some(dir))
                .and_then(|d| d.file_name())
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let interface = interface.rsplit(':').next().unwrap_or_default().to_owned();
            return Some(match read("serial") {
                Some(serial) => format!("USB {vendor}:{product} serial {serial} interface {interface}"),
                None => format!("USB {vendor}:{product} (no serial number) on USB port {at} interface {interface}"),
            });
        }
    }
    Some(format!("the device at {}", device.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_symlink_to_a_pty_is_named_and_the_pty_itself_is_a_pty() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let _inside = runtime.enter();
        let pty = crate::Pty::open().unwrap();
        assert_eq!(identify(&pty.path), Some(Identity::Pty(pty.path.clone())));
        let dir = std::env::temp_dir().join(format!("ferrobus-identity-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir(&dir).unwrap();
        let link = dir.join("line");
        std::os::unix::fs::symlink(&pty.path, &link).unwrap();
        assert_eq!(identify(&link), Some(Identity::Named));
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(identify(Path::new("/dev/ferrobus-no-such-port")), None);
    }
}
