//! Windows: COM ports through serial2-tokio. There are no ptys: what needs one (a simulator on
//! a pty, the virtual line) is Unix-only, and says so.

mod errors;
mod serial;

use std::path::Path;

#[cfg(test)]
pub(crate) use errors::descriptor_table_full;
pub(crate) use errors::{out_of_sockets, port_fault};
pub use serial::{TtyPort, open_serial};

use crate::identity::Identity;

/// What `path` names now: Windows gives a COM name to an adapter and keeps it for that adapter
/// (in the registry, by its USB serial number or port), so the name is the device.
#[expect(clippy::unnecessary_wraps, reason = "the signature of every platform's: a Unix path can be gone")]
pub(crate) fn identify(_path: &Path) -> Option<Identity> {
    Some(Identity::Named)
}
