//! What an OS error means, asked by its errno (through rustix: the numbers differ between
//! Unixes, ENOBUFS is 105 on Linux and 55 on macOS).

use std::io;

use rustix::io::Errno;

use crate::sys::PortFault;

/// Whether `e` says no socket can be made now: the process's descriptor table is full
/// (EMFILE), the system's is (ENFILE), or the kernel has no memory for one (ENOBUFS,
/// ENOMEM; accept(2) gives either).
pub(crate) fn out_of_sockets(e: &io::Error) -> bool {
    matches!(Errno::from_io_error(e), Some(Errno::MFILE | Errno::NFILE | Errno::NOBUFS | Errno::NOMEM))
}

/// What a serial port's error `e` means: EBUSY another program has it, ENOTTY it is no
/// terminal, EIO / ENXIO / ENODEV it went away (what reading an unplugged USB adapter gives).
pub(crate) fn port_fault(e: &io::Error) -> Option<PortFault> {
    match Errno::from_io_error(e)? {
        Errno::BUSY => Some(PortFault::Busy),
        Errno::NOTTY => Some(PortFault::NotSerial),
        Errno::IO | Errno::NXIO | Errno::NODEV => Some(PortFault::Gone),
        _ => None,
    }
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
    fn busy_not_a_tty_and_an_unplugged_adapters_errors_are_their_port_faults() {
        let cases = [
            (Errno::BUSY, Some(PortFault::Busy)),
            (Errno::NOTTY, Some(PortFault::NotSerial)),
            (Errno::IO, Some(PortFault::Gone)),
            (Errno::NXIO, Some(PortFault::Gone)),
            (Errno::NODEV, Some(PortFault::Gone)),
            (Errno::ACCESS, None),
            (Errno::INVAL, None),
        ];
        for (e, fault) in cases {
            assert_eq!(PortFault::of(&errno(e)), fault, "{e:?}");
        }
        assert_eq!(PortFault::of(&io::ErrorKind::UnexpectedEof.into()), None, "no code: nothing more");
    }

    #[test]
    fn a_connection_aborted_an_interrupted_call_or_a_bad_argument_is_not_out_of_sockets() {
        for e in [Errno::CONNABORTED, Errno::INTR, Errno::AGAIN, Errno::PERM, Errno::INVAL] {
            assert!(!out_of_sockets(&errno(e)), "{e:?}");
        }
    }
}
