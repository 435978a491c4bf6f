//! The options that make a server speak Modbus/TCP Security (mbaps): `--tls-cert`,
//! `--tls-key`, `--tls-ca` and `--roles`, shared by `sim` and `gateway`.

use std::path::PathBuf;

use clap::Args;
use ferrobus::tls::{Policy, ServerTls};

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

    /// The rights of each role named in client certificates (TOML; see README); without it
    /// every trusted client may do everything
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    pub(crate) roles: Option<PathBuf>,
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
        let tls = ServerTls::from_pem_files(cert, key, ca).map_err(|e| CliError::Usage(e.to_string()))?;
        let Some(roles) = &self.roles else { return Ok(Some(tls)) };
        let policy = Policy::load(roles).map_err(|e| CliError::Usage(format!("roles file {e}")))?;
        Ok(Some(tls.with_policy(policy)))
    }
}
