//! `ferrobus bridge` end to end: the binary against a real mosquitto, simulated drives as
//! separate processes, and every message checked by tools nobody here wrote (pysparkplug
//! through tests/peers/sparkplug/verify.py, `protoc --decode_raw`).
//!
//! - [`spb`]: the recorder, the checker, the publisher and protoc, as the tests call them;
//! - [`checker`]: the checker proven first, on sessions built with pysparkplug, clean and broken.
//!
//! Each test starts its own broker on a free port and leaves a directory
//! `target/interop/bridge/<test>/` with the recording, verify.py's summary and the bridge's
//! output, which its failure message names.

mod checker;
mod spb;
