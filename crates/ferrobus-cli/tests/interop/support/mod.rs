//! Helpers shared by the interop tests: what they need and how they skip ([`env`]), child
//! processes that die with their test ([`process`]), pty pairs and raw frames ([`serial`]), a
//! raw Modbus/TCP client ([`mbap`]), the `ferrobus` binary as a client ([`cli`]), and the peers
//! and the simulator ([`peers`]).
//! An MQTT broker of the test's own: [`mosquitto`].

pub(crate) mod cli;
pub(crate) mod env;
pub(crate) mod mbap;
pub(crate) mod mosquitto;
pub(crate) mod peers;
pub(crate) mod process;
pub(crate) mod serial;

pub(crate) use cli::{Ferrobus, Link, Parity, bits, ferrobus, words};
pub(crate) use env::{Need, require, require_alone};
pub(crate) use peers::{Over, Stack, check_script, mbpoll, peer_server, sim, sim_pty};
pub(crate) use serial::{RawPort, SocatPair, TempDir, hex, show, with_crc};
