//! The bus a command talks to, as the connection options name it: a serial port with its line
//! settings, Modbus/TCP, or RTU over TCP. Apart from `connect` (which builds it) and `exit`
//! (which words hints by it), so that neither depends on the other.

use std::fmt;

use ferrobus_proto::frame::LineConfig;

/// Which kind of bus the options name.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(crate) enum Target {
    /// A serial port and its line settings.
    Serial {
        /// The path.
        path: String,
        /// Baud, data bits, parity, stop bits.
        line: LineConfig,
        /// ASCII framing instead of RTU.
        ascii: bool,
    },
    /// Modbus/TCP to `host:port`.
    Tcp(String),
    /// Modbus/TCP Security (`--tls`) to `host:port`: the server may refuse a request for the
    /// role in our certificate.
    Mbaps(String),
    /// RTU over TCP to `host:port`.
    RtuTcp(String),
}

impl fmt::Display for Target {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Target::Serial { path, line, ascii } => {
                write!(f, "{path} at {line} ({})", if *ascii { "ASCII" } else { "RTU" })
            }
            Target::Tcp(addr) => write!(f, "{addr} (Modbus/TCP)"),
            Target::Mbaps(addr) => write!(f, "{addr} (Modbus/TCP Security)"),
            Target::RtuTcp(addr) => write!(f, "{addr} (RTU over TCP)"),
        }
    }
}
