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
//! **The UInt divergence.** The specification carries UInt8, UInt16 and UInt32 in the
//! payload's `int_value` (protobuf uint32) and we do by default ([`convert::UintEncoding::Spec`]);
//! Eclipse Tahu and Ignition have long written UInt32 in `long_value`, and Tahu's JavaScript
//! codec (1.0.3) reads it only there, showing ours as null. [`convert::UintEncoding::LongValue`]
//! (the plant's `uint_encoding`) writes UInt8/16/32 there; commands are accepted in either field
//! whatever the switch says.
//!
//! Two conventions the specification leaves open: a signed value is written as two's
//! complement of its own width (Int16 −5 is `int_value` 65531, which pysparkplug and Tahu both
//! read; a 32-bit sign extension pysparkplug refuses), and a metric's engineering unit is the
//! String property `engUnit` ([`convert::ENG_UNIT`], Tahu's and Ignition's key).

pub mod convert;
pub mod payload;
pub mod topic;
