//! `--metrics ADDR:PORT`, shared by the long-running commands: the status endpoint
//! (`/metrics`, `/healthz`, `/status.json`, `/`) of [`ferrobus_tools::status`], and the log
//! layer that keeps the recent warnings for its page.

use std::sync::Arc;

use clap::Args;
use ferrobus_tools::status::{RECENT, Source};
use tokio::net::TcpListener;
use tracing::field::{Field, Visit};
use tracing_subscriber::layer::{Context, Layer};

use crate::exit::CliError;

/// The status endpoint's option.
#[derive(Args, Clone, Debug, Default)]
#[command(next_help_heading = "Status endpoint")]
pub(crate) struct MetricsArgs {
    /// Serve OpenMetrics at /metrics, /healthz and a live status page at / on ADDR:PORT
    /// (a PORT alone binds 127.0.0.1)
    #[arg(long, value_name = "ADDR:PORT")]
    metrics: Option<String>,
}

impl MetricsArgs {
    /// Whether `--metrics` was given.
    pub(crate) fn given(&self) -> bool {
        self.metrics.is_some()
    }

    /// Binds the endpoint's address, if one was given; a port alone is on loopback.
    pub(crate) async fn bind(&self) -> Result<Option<TcpListener>, CliError> {
        let Some(given) = self.metrics.as_deref() else { return Ok(None) };
        let address = address(given)?;
        let listener = TcpListener::bind(&address)
            .await
            .map_err(|e| ferrobus::Error::io(format!("--metrics: listening on {address}"), e))?;
        Ok(Some(listener))
    }
}

/// `9100` → `127.0.0.1:9100`; `ADDR:PORT` as given.
fn address(given: &str) -> Result<String, CliError> {
    if let Ok(port) = given.parse::<u16>() {
        return Ok(format!("127.0.0.1:{port}"));
    }
    match given.rsplit_once(':') {
        Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok() => Ok(given.to_string()),
        _ => Err(CliError::Usage(format!(
            "--metrics '{}': give ADDR:PORT (127.0.0.1:9100, [::1]:9100) or a PORT alone",
            ferrobus::log::escape(given)
        ))),
    }
}

/// Serves `source` on `listener` in the background, saying where on stderr.
pub(crate) fn spawn(listener: TcpListener, source: Arc<dyn Source>, command: &str) {
    if let Ok(at) = listener.local_addr() {
        eprintln!("{command}: status on http://{at}/ (metrics at /metrics, health at /healthz)");
    }
    tokio::spawn(async move {
        if let Err(e) = ferrobus_tools::status::serve(listener, source).await {
            tracing::warn!("the status endpoint stopped: {e}");
        }
    });
}

/// Keeps each warning and error the log writes, for the status page.
pub(crate) struct RecentWarnings;

impl<S: tracing::Subscriber> Layer<S> for RecentWarnings {
    fn on_event(&self, event: &tracing::Event<'_>, _: Context<'_, S>) {
        if *event.metadata().level() > tracing::Level::WARN {
            return;
        }
        let mut text = Message(String::new());
        event.record(&mut text);
        RECENT.push(format!("{} {}", event.metadata().level(), text.0));
    }
}

/// An event's message and fields, as the log shows them.
struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        use std::fmt::Write as _;
        let sep = if self.0.is_empty() { "" } else { " " };
        let _ = if field.name() == "message" {
            write!(self.0, "{sep}{value:?}")
        } else {
            write!(self.0, "{sep}{}={value:?}", field.name())
        };
    }
}

#[cfg(test)]
mod tests {
    use super::address;

    #[test]
    fn a_port_alone_is_on_loopback_and_an_address_is_taken_as_given() {
        assert_eq!(address("9100").unwrap(), "127.0.0.1:9100");
        assert_eq!(address("0.0.0.0:9100").unwrap(), "0.0.0.0:9100");
        assert_eq!(address("[::1]:9100").unwrap(), "[::1]:9100");
        for bad in ["", "host", ":9100", "host:port", "1.2.3.4:70000"] {
            assert!(address(bad).is_err(), "{bad}");
        }
    }
}
