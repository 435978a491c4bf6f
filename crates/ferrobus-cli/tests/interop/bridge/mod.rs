//! `ferrobus bridge` end to end: the binary against a real mosquitto, simulated drives as
//! separate processes (`ferrobus sim --tcp`), and every message checked by tools nobody here
//! wrote (pysparkplug through tests/peers/sparkplug/verify.py, `protoc --decode_raw`).
//!
//! - [`checker`]: the checker proven first, on sessions built with pysparkplug, clean and
//!   broken, and the broker harness's restart;
//! - [`sparkplug`]: births and data (two lines, TCP and RTU), NCMD Rebirth, SIGKILL and the Will,
//!   DCMD to F001, DDEATH and DBIRTH, a primary host's STATE;
//! - [`outage`]: the broker away for 30 s, the samples meanwhile delivered as historical;
//! - [`plain`]: plain JSON per point, writes on `.../set`, retained last values;
//! - [`discovery`]: plain mode's Home Assistant discovery configs, retained, checked against
//!   HA's documented schema, a sensor's state and a number's and a select's commands;
//! - [`guard`]: a DCMD and a plain `.../set` of a run-locked point, taken stopped, refused running;
//! - [`listen`]: a listen line on a `ferrobus line` tap, publishing what the bus's own master
//!   read, at its wire time, transmitting nothing, a `.../set` refused;
//! - [`reload`]: SIGHUP with a device added and one changed, applied without a new session
//!   (Sparkplug), and a device removed and one added with discovery (plain);
//! - [`cli`]: `--check` on a broken file and the shipped examples, and `--demo`;
//! - [`harness`] (drives, plant.toml, the bridge process) and [`spb`] (recorder, checker,
//!   publisher, protoc) are what they are made of.
//!
//! Each test starts its own broker on a free port and leaves a directory
//! `target/interop/bridge/<test>/` with the recording, verify.py's summary (`verify.json`),
//! the plant.toml and the bridge's output (`bridge.log`); a failure message names it.

mod checker;
mod cli;
mod discovery;
mod guard;
mod harness;
mod listen;
mod outage;
mod plain;
mod reload;
mod sparkplug;
mod spb;
