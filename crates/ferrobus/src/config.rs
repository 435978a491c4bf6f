//! The settings of a client and of each request: what the client hands its driver, kept apart
//! from both so that neither depends on the other for them.

use std::time::Duration;

use ferrobus_proto::master::MasterConfig;

/// How a unit that stops answering is skipped: the core's policy, which the driver asks.
pub use ferrobus_proto::retry::Backoff;

/// Settings of a client.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ClientConfig {
    /// How long to wait for each reply once the request has left.
    pub timeout: Duration,
    /// How many times to resend a request that got no usable reply: a timeout, a bad reply, or
    /// an IO failure (the port is then reopened, after a backoff that grows with each failure).
    pub retries: u32,
    /// The quiet time after a broadcast.
    pub turnaround_delay: Duration,
    /// Drop our own transmission when the adapter echoes it.
    pub echo_suppression: bool,
    /// Skip units that stop answering; `None` never skips.
    pub backoff: Option<Backoff>,
    /// Requests that may wait for the bus before `request` calls wait themselves.
    pub queue: usize,
    /// How long opening the port or connecting may take.
    pub connect_timeout: Duration,
    /// After a request timed out, how long past its timeout its late reply is still awaited
    /// (the line kept closed, the reply dropped when it comes) before the next request goes
    /// out; `None`: twice the request's own timeout, so that a reply up to three timeouts
    /// after its request is still recognised as late (a device that misses a 1 s timeout
    /// by a second is dropped, not handed to the next request) — at the price of a unit that
    /// falls silent costing one late window once (its later timeouts owe nothing until it is
    /// heard again). On serial framings: see the master engine's owed replies
    /// ([`ferrobus_proto::master`]). On a pipelined Modbus/TCP connection
    /// ([`in_flight`](Self::in_flight) past 1) nothing waits: a timed-out request's
    /// transaction id is kept out of use that long, its late reply dropped if it comes
    /// ([`Pipeline::set_late_window`](ferrobus_proto::master::pipeline::Pipeline::set_late_window)).
    pub late_window: Option<Duration>,
    /// On Modbus/TCP: how many requests may be outstanding on the connection at once, each
    /// matched to its reply by its transaction id (at most
    /// [`MAX_IN_FLIGHT`](ferrobus_proto::master::pipeline::MAX_IN_FLIGHT)). 1, the default,
    /// sends a request only once the last has ended. More hides the round trip for a device
    /// that reads its connection in order and answers every request (libmodbus's server
    /// does); a device that takes one request at a time and drops the rest wants 1 (pymodbus's
    /// server answers only the first of the requests that reach it together).
    /// Every other framing (RTU, ASCII, RTU over TCP) has no transaction id and keeps one
    /// request in flight whatever this says.
    pub in_flight: usize,
}

impl Default for ClientConfig {
    fn default() -> Self {
        let master = MasterConfig::default();
        ClientConfig {
            timeout: master.response_timeout,
            retries: 0,
            turnaround_delay: master.turnaround_delay,
            echo_suppression: false,
            backoff: Some(Backoff::default()),
            queue: 64,
            connect_timeout: Duration::from_secs(5),
            late_window: None,
            in_flight: 1,
        }
    }
}

/// The timeout and retries of a request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RequestOptions {
    /// How long to wait for the reply once the request has left.
    pub timeout: Duration,
    /// How many times to resend it.
    pub retries: u32,
}
