//! What an OS error means, asked by its Windows error code (a Win32 error or a Winsock one:
//! `raw_os_error` gives either).

use std::io;

/// Winsock: too many open sockets.
const WSAEMFILE: i32 = 10024;
/// Winsock: no buffer space available.
const WSAENOBUFS: i32 = 10055;
/// Win32: the system cannot open the file (too many open handles).
const ERROR_TOO_MANY_OPEN_FILES: i32 = 4;

/// Whether `e` says no socket can be made now: too many are open (WSAEMFILE,
/// ERROR_TOO_MANY_OPEN_FILES) or Winsock has no buffer space for one (WSAENOBUFS).
pub(crate) fn out_of_sockets(e: &io::Error) -> bool {
    matches!(e.raw_os_error(), Some(WSAEMFILE | WSAENOBUFS | ERROR_TOO_MANY_OPEN_FILES))
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
    fn a_connection_reset_or_aborted_or_the_unix_numbers_are_not_out_of_sockets() {
        // WSAECONNRESET, WSAECONNABORTED, WSAEINTR; and EMFILE's and ENFILE's Unix numbers,
        // which are other errors here.
        for code in [10054, 10053, 10004, 24, 23] {
            assert!(!out_of_sockets(&io::Error::from_raw_os_error(code)), "{code}");
        }
    }
}
