//! What "the same serial device" means when a lost port is reopened.
//!
//! A path names a device only as long as nobody else gets the name. When a port is lost and
//! reopened, the path may by then lead to another device: Linux gives a vanished pty's number
//! to the next pty made, and `/dev/ttyUSB0` to whichever adapter is plugged in first. So the
//! first open records what the path named, and every reopen must find the same:
//!
//! - **A symlink** (`/dev/serial/by-id/...`, `/dev/serial/by-path/...`, a socat `link=`, a udev
//!   rule's name) is a name someone chose for a device: whatever it leads to is that device,
//!   and it is reopened.
//! - **A raw pty** (`/dev/pts/N`): nothing but the number identifies it, and the number is
//!   reused. A pty that went away does not come back, so it is never reopened.
//! - **A device in sysfs** (`/dev/ttyUSB0`, `/dev/ttyACM0`, `/dev/ttyS0`): the USB vendor,
//!   product and serial number (without a serial number, the USB port it is plugged into), or
//!   for a port that is not USB, its place in the device tree. Reopened only if it matches.
//! - **Anything else**: its device number.

//!
//! On Windows a COM port's name is given to an adapter by Windows and kept for it, so a COM
//! port is a named device. Finding the identity is platform code ([`sys`](crate::sys)).

use std::fmt;
use std::path::PathBuf;

/// What a port's path named when it was first opened.
#[derive(Clone, PartialEq, Eq, Debug)]
#[cfg_attr(not(unix), allow(dead_code, reason = "ptys, sysfs and device numbers are Unix's"))]
pub(crate) enum Identity {
    /// A symlink: a name chosen for the device.
    Named,
    /// A raw pty: identified by a reusable number alone.
    Pty(PathBuf),
    /// A device in sysfs, described (USB ids and serial number, or the device-tree path).
    Hardware(String),
    /// Another device file: its device number.
    Node(u64),
}

impl fmt::Display for Identity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Identity::Named => f.write_str("a named link"),
            Identity::Pty(path) => write!(f, "the pty {}", path.display()),
            Identity::Hardware(what) => f.write_str(what),
            Identity::Node(rdev) => write!(f, "device number {rdev:#x}"),
        }
    }
}

impl Identity {
    /// Whether a port first opened as `self` may be reopened where the path now names `now`;
    /// if not, why, for the error.
    pub(crate) fn reopen_check(&self, now: Option<&Identity>) -> Result<(), String> {
        match (self, now) {
            (Identity::Named, _) => Ok(()),
            (Identity::Pty(path), _) => Err(format!(
                "{} was a pty, and a pty that went away never comes back: its number goes to the next pty made, \
                 so it is not reopened (give the pty a name, e.g. socat's link=, to have it reopened)",
                path.display()
            )),
            (first, Some(now)) if first == now => Ok(()),
            (first, Some(now)) => Err(format!("it was {first} when first opened, and it is {now} now")),
            (first, None) => Err(format!("it was {first} when first opened, and it cannot be identified now")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_symlink_is_reopened_wherever_it_leads() {
        assert_eq!(Identity::Named.reopen_check(Some(&Identity::Pty("/dev/pts/3".into()))), Ok(()));
        assert_eq!(Identity::Named.reopen_check(None), Ok(()));
    }

    #[test]
    fn a_raw_pty_is_never_reopened_even_under_the_same_number() {
        let pty = Identity::Pty("/dev/pts/7".into());
        let refused = pty.reopen_check(Some(&pty)).unwrap_err();
        assert!(refused.contains("/dev/pts/7 was a pty") && refused.contains("not reopened"), "{refused}");
    }

    #[test]
    fn hardware_is_reopened_only_when_it_is_the_same() {
        let first = Identity::Hardware("USB 0403:6001 serial A1 interface 0".into());
        assert_eq!(first.reopen_check(Some(&first.clone())), Ok(()));
        let other = Identity::Hardware("USB 0403:6001 serial B2 interface 0".into());
        let refused = first.reopen_check(Some(&other)).unwrap_err();
        assert_eq!(
            refused,
            "it was USB 0403:6001 serial A1 interface 0 when first opened, and it is USB 0403:6001 serial B2 interface 0 now"
        );
        assert!(Identity::Node(0x0400).reopen_check(Some(&Identity::Node(0x0401))).is_err());
    }
}
