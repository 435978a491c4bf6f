//! Tests of the poller on paused time.
