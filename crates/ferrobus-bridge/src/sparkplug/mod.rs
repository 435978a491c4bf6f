//! Sparkplug B 3.0: the payload, the topics, and values to and from metrics.
//!
//! Sparkplug B is the Eclipse Foundation's specification of MQTT for industrial devices: an
//! edge node announces itself and its devices with birth certificates (NBIRTH, DBIRTH) that
//! name and type every metric and give it an alias, then publishes changes by exception
//! (NDATA, DDATA: aliases only, a `seq` 0–255 per message), takes commands (NCMD, DCMD), and
//! dies with a death certificate (NDEATH, its MQTT Will, carrying the session's `bdSeq`).
//! Here the edge node is the bridge, its devices are the plant's Modbus devices, and their
//! metrics are the profiles' points.
//!
//! - [`payload`]: the protobuf payload as prost message types, written from the
//!   specification, so no protoc and no schema file enter the build.
//! - [`topic`]: `spBv1.0/<group>/<type>/<edge node>[/<device>]`, host STATE, id checks.
//! - [`convert`]: a point's datatype, its raw values as metric values, and a command's metric
//!   value back to a raw value.
//!
//! **The integer divergence.** The specification carries UInt8, UInt16 and UInt32 in the
//! payload's `int_value` (protobuf uint32) and we do by default ([`convert::UintEncoding::Spec`]),
//! with a signed Int8/16 as two's complement of its own width (Int16 −5 is 65531), the only form
//! pysparkplug reads. Eclipse Tahu and Ignition have long written UInt32 in `long_value` and
//! Int8/16 sign-extended to 32 bits, and Tahu's JavaScript codec (1.0.3) reads only that: ours
//! shows there as a null UInt32 and a large positive Int16 (`tests/tahu.rs` pins it down).
//! [`convert::UintEncoding::LongValue`] (the plant's `uint_in_long_value`) writes Tahu's way;
//! commands are accepted in every one of these forms whatever the switch says.
//!
//! A metric's engineering unit is the String property `engUnit` ([`convert::ENG_UNIT`],
//! Tahu's and Ignition's key), a convention the specification leaves open.

pub mod convert;
pub mod payload;
pub mod topic;
