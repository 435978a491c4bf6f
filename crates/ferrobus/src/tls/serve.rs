//! Modbus/TCP Security served by the TCP server: the handshake, then the role checked on
//! every request the engine hands out, before the handler sees it.

use std::io;
use std::sync::Arc;

use ferrobus_proto::slave::Handler;
use tokio::net::TcpListener;

use super::{ServerTls, handshake};
use crate::server::{ServerOptions, Shared, TcpServeConfig, serve_transport};

/// Serves Modbus/TCP Security (mbaps) on `listener`, within `serve`'s limits, as
/// [`serve_tcp_with`](crate::server::serve_tcp_with) serves Modbus/TCP:
/// each connection first completes a TLS handshake with `tls` (a client certificate
/// required; a refused handshake is logged and counted in [`TcpCounts::tls_refused`](crate::server::TcpCounts::tls_refused)), then
/// every request is checked against `tls`'s policy for the client's role, a denied one
/// answered with exception 01 (the [`RoleCheck`](super::RoleCheck) as the session's
/// [`ServerOptions::authorize`] filter, counted in
/// [`TcpCounts::denied`](crate::server::TcpCounts::denied)). A connection in its handshake
/// counts towards the connection limit and towards its source's handshakes
/// ([`ServerTls::with_max_handshakes_per_source`]); the handshake must finish within `tls`'s
/// handshake timeout ([`HANDSHAKE_TIMEOUT`](super::HANDSHAKE_TIMEOUT) unless set).
pub async fn serve_tls_with<H, O>(
    listener: TcpListener,
    serve: TcpServeConfig,
    handler: Shared<H>,
    options: O,
    tls: ServerTls,
) -> io::Result<()>
where
    H: Handler + Send + 'static,
    O: Fn() -> ServerOptions + Send + Sync + 'static,
{
    let TcpServeConfig { transport, slave: config, limits } = serve;
    let options = Arc::new(options);
    let connection = limits.connection;
    let stats = Arc::clone(&limits.stats);
    crate::server::accept_handshaking(
        listener,
        &limits,
        tls.max_handshakes_per_source(),
        move |stream, peer, in_progress| {
            let transport = transport.clone();
            let mut handler = handler.clone();
            let options = Arc::clone(&options);
            let (tls, stats) = (tls.clone(), Arc::clone(&stats));
            async move {
                let tracker = in_progress.tracker();
                let Some((stream, check)) = handshake(&tls, stream, peer, &stats, in_progress).await else {
                    return Ok(());
                };
                let mut options = options();
                options.authorize = Some(Box::new(check));
                options.connection = options.connection.or(Some(connection));
                serve_transport(&transport, Box::new(tracker.track(stream)), config, &mut handler, &mut options).await
            }
        },
    )
    .await
}
