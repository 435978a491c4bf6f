//! The Modbus edge node of a plant: the devices on serial lines and Modbus/TCP published to an
//! MQTT broker as Sparkplug B 3.0 or as plain JSON, commands from the broker written back to
//! the devices through their profiles' checks, and nothing lost while the broker is away.
//!
//! ```text
//!   plant.toml ──▶ config ──▶ Plant (lines, devices, groups)
//!                                 │
//!   line ─▶ Poller ─┐             ▼
//!   line ─▶ Poller ─┼─▶ run ─▶ edge (Sparkplug B or plain: births, data by exception,
//!   line ─▶ Poller ─┘    │        deaths, commands)  ─▶ MQTT (rumqttc) ─▶ broker
//!                        └─▶ store (memory, then disk) while the broker is unreachable
//! ```
//!
//! - [`sparkplug`]: the Sparkplug B payload as prost message types, its topics, and values to
//!   and from metrics.
//! - [`store`]: the bounded store and forward queue.
//! - [`config`]: `plant.toml`, with `file:line` errors.
//! - [`edge`]: the edge node without IO: what each sample, connection and command publishes.
//! - [`run`]: the bridge itself: a poller per line, the MQTT session, the store.

pub mod config;
pub mod edge;
pub mod run;
pub mod sparkplug;
pub mod store;
