//! The options that make a server speak Modbus/TCP Security (mbaps): `--tls-cert`,
//! `--tls-key`, `--tls-ca` and `--roles`, and the handshake's bounds, shared by `sim` and
//! `gateway`.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use ferrobus::tls::{Policy, ServerTls};

use crate::connect::parse_duration;
use crate::exit::CliError;

/// Options of an mbaps server.
#[derive(Args, Clone, Debug, Default)]
#[command(next_help_heading = "Modbus/TCP Security (mbaps, port 802)")]
pub(crate) struct ServerTlsArgs {
    /// Serve Modbus/TCP Security with this certificate (PEM, its chain); needs --tls-key and
    /// --tls-ca
    #[arg(long = "tls-cert", value_name = "FILE", requires_all = ["tls_key", "tls_ca"])]
    pub(crate) tls_cert: Option<PathBuf>,

    /// The private key of --tls-cert (PEM, unencrypted)
    #[arg(long = "tls-key", value_name = "FILE", requires = "tls_cert")]
    pub(crate) tls_key: Option<PathBuf>,

    /// The CA certificate(s) that clients' certificates must be issued by (PEM); a client
    /// without a certificate is refused at the handshake
    #[arg(long = "tls-ca", value_name = "FILE", requires = "tls_cert")]
    pub(crate) tls_ca: Option<PathBuf>,

    /// The rights of each role named in client certificates (TOML; see docs/tls.md); without it
    /// every trusted client may do everything
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    pub(crate) roles: Option<PathBuf>,

    /// Close a connection whose TLS handshake is not finished this long after it was accepted
    #[arg(long = "tls-handshake-timeout", value_name = "DURATION", default_value = "5s",
          value_parser = parse_handshake_timeout)]
    pub(crate) handshake_timeout: Duration,

    /// TLS handshakes one client address (an IPv6 /64) may have in progress at once; past it a
    /// new connection from there is closed at once, so one host cannot lock the others out
    #[arg(long = "tls-max-handshakes-per-source", value_name = "N", default_value_t = 16,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) max_handshakes_per_source: u32,
}

/// A handshake timeout: a duration above zero (a handshake that may last for ever holds its
/// connection slot for ever).
fn parse_handshake_timeout(text: &str) -> Result<Duration, String> {
    let timeout = parse_duration(text)?;
    if timeout.is_zero() {
        return Err("a handshake needs some time: give a duration above 0, such as 5s".into());
    }
    Ok(timeout)
}

impl ServerTlsArgs {
    /// Whether mbaps is asked for.
    pub(crate) fn enabled(&self) -> bool {
        self.tls_cert.is_some()
    }

    /// The server's TLS setup, if asked for: its certificate, key, client CA and roles file
    /// read now, so that a bad file is an error (naming it, and the line) before anything is
    /// served.
    pub(crate) fn load(&self) -> Result<Option<ServerTls>, CliError> {
        let (Some(cert), Some(key), Some(ca)) = (&self.tls_cert, &self.tls_key, &self.tls_ca) else { return Ok(None) };
        let tls = ServerTls::from_pem_files(cert, key, ca)
            .map_err(|e| CliError::Usage(e.to_string()))?
            .with_handshake_timeout(self.handshake_timeout)
            .with_max_handshakes_per_source(usize::try_from(self.max_handshakes_per_source).unwrap_or(usize::MAX));
        let Some(roles) = &self.roles else { return Ok(Some(tls)) };
        let policy = Policy::load(roles).map_err(|e| CliError::Usage(format!("roles file {e}")))?;
        Ok(Some(tls.with_policy(policy)))
    }
}
