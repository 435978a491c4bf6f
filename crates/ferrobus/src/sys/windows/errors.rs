//! What an OS error means, asked by its Windows error code (a Win32 error or a Winsock one:
//! `raw_os_error` gives either).

use std::io;

use crate::sys::PortFault;

/// Winsock: too many open sockets.
const WSAEMFILE: i32 = 10024;
/// Winsock: no buffer space available.
const WSAENOBUFS: i32 = 10055;
/// Win32: the system cannot open the file (too many open handles).
const ERROR_TOO_MANY_OPEN_FILES: i32 = 4;
/// Win32: access is denied; opening a COM port another program has open.
const ERROR_ACCESS_DENIED: i32 = 5;
/// Win32: the device does not recognize the command; a USB adapter unplugged under a read.
const ERROR_BAD_COMMAND: i32 = 22;
/// Win32: a device attached to the system is not functioning.
const ERROR_GEN_FAILURE: i32 = 31;
/// Win32: the device is not connected.
const ERROR_DEVICE_NOT_CONNECTED: i32 = 1167;

/// Whether `e` says no socket can be made now: too many are open (WSAEMFILE,
/// ERROR_TOO_MANY_OPEN_FILES) or Winsock has no buffer space for one (WSAENOBUFS).
pub(crate) fn out_of_sockets(e: &io::Error) -> bool {
    matches!(e.raw_os_error(), Some(WSAEMFILE | WSAENOBUFS | ERROR_TOO_MANY_OPEN_FILES))
}

/// What a COM port's error `e` means: access denied is another program's having it (a COM
/// port is one program's at a time); a command not recognized, a device not functioning or
/// not connected is an adapter gone.
pub(crate) fn port_fault(e: &io::Error) -> Option<PortFault> {
    match e.raw_os_error()? {
        ERROR_ACCESS_DENIED => Some(PortFault::Busy),
        ERROR_BAD_COMMAND | ERROR_GEN_FAILURE | ERROR_DEVICE_NOT_CONNECTED => Some(PortFault::Gone),
        _ => None,
    }
}

/// The error accepting gives when too many sockets are open (WSAEMFILE).
#[cfg(test)]
pub(crate) fn descriptor_table_full() -> io::Error {
    io::Error::from_raw_os_error(WSAEMFILE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_many_sockets_or_handles_or_no_buffer_space_is_out_of_sockets() {
        for code in [10024, 10055, 4] {
            assert!(out_of_sockets(&io::Error::from_raw_os_error(code)), "{code}");
        }
        assert!(out_of_sockets(&descriptor_table_full()));
    }

    #[test]
    fn access_denied_is_busy_and_an_unplugged_adapters_errors_are_gone_but_unix_numbers_are_not() {
        let cases = [
            (5, Some(PortFault::Busy)),
            (22, Some(PortFault::Gone)),
            (31, Some(PortFault::Gone)),
            (1167, Some(PortFault::Gone)),
            // ERROR_FILE_NOT_FOUND: its kind says it; EBUSY's and ENOTTY's numbers are other errors here.
            (2, None),
            (16, None),
            (25, None),
        ];
        for (code, fault) in cases {
            assert_eq!(PortFault::of(&io::Error::from_raw_os_error(code)), fault, "{code}");
        }
    }

    #[test]
    fn a_connection_reset_or_aborted_or_the_unix_numbers_are_not_out_of_sockets() {
        // WSAECONNRESET, WSAECONNABORTED, WSAEINTR; and EMFILE's and ENFILE's Unix numbers,
        // which are other errors here.
        for code in [10054, 10053, 10004, 24, 23] {
            assert!(!out_of_sockets(&io::Error::from_raw_os_error(code)), "{code}");
        }
    }
}
