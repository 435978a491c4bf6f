//! The authorization step: a filter that checks each request against the client's role
//! before the handler or the gateway's line sees it (MB-TCP-Security v36 §6, R-31). The TLS
//! server and the TLS gateway front run it the same way, as their [`Authorize`].

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use ferrobus_proto::ExceptionCode;
use ferrobus_proto::pdu::Request;

use super::{Policy, Role};
use crate::server::Authorize;

/// One client's authorization: its role, the policy, and where denials are logged and
/// counted.
#[derive(Clone, Debug)]
pub struct RoleCheck {
    role: Role,
    policy: Arc<Policy>,
    peer: Option<SocketAddr>,
    denied: Arc<AtomicU64>,
}

impl RoleCheck {
    /// `policy`'s check for `role`.
    pub fn new(role: Role, policy: Arc<Policy>) -> Self {
        RoleCheck { role, policy, peer: None, denied: Arc::default() }
    }

    /// Names the client in the log lines of denied requests.
    #[must_use]
    pub fn with_peer(mut self, peer: SocketAddr) -> Self {
        self.peer = Some(peer);
        self
    }

    /// Counts denied requests in `counter` (shared with whoever reports it).
    #[must_use]
    pub fn counting(mut self, counter: Arc<AtomicU64>) -> Self {
        self.denied = counter;
        self
    }

    /// The client's role.
    pub fn role(&self) -> &Role {
        &self.role
    }

    /// Requests denied so far (by this check and any sharing its counter).
    pub fn denied(&self) -> u64 {
        self.denied.load(Ordering::Relaxed)
    }

    /// Whether the client may send `request` to `unit`; a denial is counted and logged.
    pub fn allows(&self, unit: u8, request: &Request<'_>) -> bool {
        let Err(why) = self.policy.check(&self.role, unit, request) else { return true };
        self.denied.fetch_add(1, Ordering::Relaxed);
        let peer = self.peer.map(|p| p.to_string()).unwrap_or_default();
        tracing::warn!(%peer, "denied {} to unit {unit} for {}: {why}; answered exception 01", request.function(), self.role);
        false
    }
}

/// The authorization step for a TLS client, of the server and of the gateway alike: the
/// PDU parsed, then checked; a denied request gets exception 01, one that does not parse the
/// exception a server would answer it with (it could not be checked, so it is not served or
/// forwarded). A broadcast refused gets nothing (the server's session drops it).
impl Authorize for RoleCheck {
    fn authorize(&mut self, unit: u8, pdu: &[u8]) -> Result<(), ExceptionCode> {
        let request = Request::parse(pdu).map_err(ferrobus_proto::PduError::exception_code)?;
        if self.allows(unit, &request) { Ok(()) } else { Err(ExceptionCode::IllegalFunction) }
    }
}
