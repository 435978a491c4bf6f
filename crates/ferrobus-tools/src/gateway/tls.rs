//! The gateway's front end over Modbus/TCP Security: each connection's TLS handshake, then
//! the gateway's own rules and the client's role checked on every request.

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;

use tokio::net::TcpListener;

use crate::gateway::{Authorize, Chain, FrontConfig, Gateway};
use ferrobus::tls::{ServerTls, handshake};

impl Gateway {
    /// Serves Modbus/TCP Security on `listener` as `front` says, as [`Gateway::serve_tcp`]
    /// serves Modbus/TCP:
    /// each connection completes a TLS handshake with `tls` first (a client certificate
    /// required; a refused handshake is logged and counted in
    /// [`TcpCounts::tls_refused`](ferrobus::server::TcpCounts::tls_refused)), then every request
    /// passes the [`Authorize`] that `authorize` makes for its peer (the gateway's rules) and
    /// then the client's role against `tls`'s policy (a denial: exception 01, logged, counted
    /// in [`TcpCounts::denied`](ferrobus::server::TcpCounts::denied)). A connection in its
    /// handshake counts towards its source's handshakes
    /// ([`ServerTls::with_max_handshakes_per_source`]) until it finishes or times out. Runs until
    /// dropped.
    pub async fn serve_tls<A>(
        &self,
        listener: TcpListener,
        front: FrontConfig,
        authorize: A,
        tls: ServerTls,
    ) -> io::Result<()>
    where
        A: Fn(SocketAddr) -> Box<dyn Authorize> + Send + Sync + 'static,
    {
        let FrontConfig { inbound, limits } = front;
        let connection = limits.connection;
        let authorize = Arc::new(authorize);
        let stats = Arc::clone(&limits.stats);
        ferrobus::server::accept_handshaking(
            listener,
            &limits,
            tls.max_handshakes_per_source(),
            |stream, peer, in_progress| {
                let gateway = self.clone();
                let authorize = Arc::clone(&authorize);
                let (tls, stats) = (tls.clone(), Arc::clone(&stats));
                async move {
                    let tracker = in_progress.tracker();
                    let Some((stream, check)) = handshake(&tls, stream, peer, &stats, in_progress).await else {
                        return Ok(());
                    };
                    let mut chain = Chain(vec![authorize(peer), Box::new(check)]);
                    gateway
                        .serve_connection(tracker.track(stream), &peer.to_string(), inbound, &mut chain, connection)
                        .await
                }
            },
        )
        .await
    }
}
