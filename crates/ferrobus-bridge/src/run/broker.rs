//! The MQTT options of a plant's broker: client id, credentials, keep-alive, and TLS with the
//! rustls configuration that `ferrobus::tls::ClientTls` makes from PEM files (ring provider,
//! the same versions as Modbus/TCP Security).

use ferrobus::tls::ClientTls;
use rumqttc::{MqttOptions, TlsConfiguration, Transport};

use crate::config::{Broker, BrokerTls};

use super::RunError;

/// The options to connect to `broker` with (the Will is the session's business).
pub(super) fn options(broker: &Broker) -> Result<MqttOptions, RunError> {
    let mut options = MqttOptions::new(broker.client_id.clone(), broker.host.clone(), broker.port);
    options.set_keep_alive(broker.keep_alive.max(std::time::Duration::from_secs(1)));
    if let Some(username) = &broker.username {
        options.set_credentials(username.clone(), broker.password.clone().unwrap_or_default());
    }
    if let Some(tls) = &broker.tls {
        options.set_transport(transport(tls)?);
    }
    Ok(options)
}

/// TLS to the broker, trusting `tls.ca`, showing `tls.cert` and `tls.key` if given; the
/// broker's certificate must name `tls.server_name`, else the host connected to.
fn transport(tls: &BrokerTls) -> Result<Transport, RunError> {
    let identity = match (&tls.cert, &tls.key) {
        (Some(cert), Some(key)) => Some((cert.as_path(), key.as_path())),
        (None, None) => None,
        _ => return Err(RunError::Tls("a client certificate needs its key, and a key its certificate".into())),
    };
    let client = match &tls.server_name {
        Some(name) => ClientTls::from_pem_files_naming(&tls.ca, identity, name),
        None => ClientTls::from_pem_files(&tls.ca, identity),
    }
    .map_err(|e| RunError::Tls(e.to_string()))?;
    Ok(Transport::tls_with_config(TlsConfiguration::Rustls(client.rustls_config())))
}

/// `host:port` of the broker, for messages.
pub(super) fn describe(broker: &Broker) -> String {
    let scheme = if broker.tls.is_some() { "mqtts" } else { "mqtt" };
    if broker.host.contains(':') {
        format!("{scheme}://[{}]:{}", broker.host, broker.port)
    } else {
        format!("{scheme}://{}:{}", broker.host, broker.port)
    }
}
