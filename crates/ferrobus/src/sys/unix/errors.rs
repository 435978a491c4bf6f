//! What an OS error means, asked by its errno (through rustix: the numbers differ between
//! Unixes, ENOBUFS is 105 on Linux and 55 on macOS).

use std::io;

use rustix::io::Errno;

/// Whether `e` says no socket can be made now: the process's descriptor table is full
/// (EMFILE), the system's is (ENFILE), or the kernel has no memory for one (ENOBUFS,
/// ENOMEM; accept(2) gives either).
pub(crate) fn out_of_sockets(e: &io::Error) -> bool {
    matches!(Errno::from_io_error(e), Some(Errno::MFILE | Errno::NFILE | Errno::NOBUFS | Errno::NOMEM))
}

/// The error accepting gives when the process's descriptor table is full (EMFILE).
#[cfg(test)]
pub(crate) fn descriptor_table_full() -> io::Error {
    io::Error::from_raw_os_error(Errno::MFILE.raw_os_error())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn errno(e: Errno) -> io::Error {
        io::Error::from_raw_os_error(e.raw_os_error())
    }

    #[test]
    fn a_full_descriptor_table_or_no_memory_for_a_socket_is_out_of_sockets() {
        for e in [Errno::MFILE, Errno::NFILE, Errno::NOBUFS, Errno::NOMEM] {
            assert!(out_of_sockets(&errno(e)), "{e:?}");
        }
        assert!(out_of_sockets(&descriptor_table_full()));
    }

    #[test]
    fn a_connection_aborted_an_interrupted_call_or_a_bad_argument_is_not_out_of_sockets() {
        for e in [Errno::CONNABORTED, Errno::INTR, Errno::AGAIN, Errno::PERM, Errno::INVAL] {
            assert!(!out_of_sockets(&errno(e)), "{e:?}");
        }
    }
}
