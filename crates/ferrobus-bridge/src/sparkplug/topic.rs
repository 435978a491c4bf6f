//! Sparkplug B topics: `spBv1.0/<group_id>/<message type>/<edge_node_id>[/<device_id>]` for an
//! edge node's and its devices' messages, `spBv1.0/STATE/<host_id>` for a host application's
//! state (a retained JSON `{"online":true,"timestamp":...}`), and the checks an id must pass to
//! be one level of a topic.

use std::fmt;
use std::str::FromStr;

/// The first level of every Sparkplug B 3.0 topic.
pub const NAMESPACE: &str = "spBv1.0";

/// The message types of an edge node and its devices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MessageType {
    /// The edge node's birth certificate.
    NBirth,
    /// The edge node's data.
    NData,
    /// A command to the edge node.
    NCmd,
    /// The edge node's death certificate (its MQTT Will).
    NDeath,
    /// A device's birth certificate.
    DBirth,
    /// A device's data.
    DData,
    /// A command to a device.
    DCmd,
    /// A device's death certificate.
    DDeath,
}

impl MessageType {
    /// Every message type.
    pub const ALL: [MessageType; 8] = [
        MessageType::NBirth,
        MessageType::NData,
        MessageType::NCmd,
        MessageType::NDeath,
        MessageType::DBirth,
        MessageType::DData,
        MessageType::DCmd,
        MessageType::DDeath,
    ];

    /// Its topic level: `NBIRTH`, `DDATA`, ...
    pub const fn as_str(self) -> &'static str {
        match self {
            MessageType::NBirth => "NBIRTH",
            MessageType::NData => "NDATA",
            MessageType::NCmd => "NCMD",
            MessageType::NDeath => "NDEATH",
            MessageType::DBirth => "DBIRTH",
            MessageType::DData => "DDATA",
            MessageType::DCmd => "DCMD",
            MessageType::DDeath => "DDEATH",
        }
    }

    /// Whether it is a device's message (its topic has a device id).
    pub const fn is_device(self) -> bool {
        matches!(self, MessageType::DBirth | MessageType::DData | MessageType::DCmd | MessageType::DDeath)
    }
}

impl fmt::Display for MessageType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A topic level that is no Sparkplug message type.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not a Sparkplug message type (NBIRTH, NDATA, NCMD, NDEATH, DBIRTH, DDATA, DCMD, DDEATH)")]
pub struct UnknownMessageType(pub String);

impl FromStr for MessageType {
    type Err = UnknownMessageType;

    fn from_str(level: &str) -> Result<MessageType, UnknownMessageType> {
        MessageType::ALL
            .into_iter()
            .find(|kind| kind.as_str() == level)
            .ok_or_else(|| UnknownMessageType(level.to_owned()))
    }
}

/// An edge node's or device's topic.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Topic {
    /// The group id.
    pub group: String,
    /// The message type.
    pub kind: MessageType,
    /// The edge node id.
    pub node: String,
    /// The device id, for a device's message.
    pub device: Option<String>,
}

impl Topic {
    /// The topic of an edge node's message.
    pub fn node(group: &str, kind: MessageType, node: &str) -> Topic {
        Topic { group: group.to_owned(), kind, node: node.to_owned(), device: None }
    }

    /// The topic of a device's message.
    pub fn device(group: &str, kind: MessageType, node: &str, device: &str) -> Topic {
        Topic { group: group.to_owned(), kind, node: node.to_owned(), device: Some(device.to_owned()) }
    }

    /// The topic of that name, if it is an edge node's (`spBv1.0/G/NBIRTH/N`) or a device's
    /// (`spBv1.0/G/DDATA/N/D`): the right namespace, a known message type, non-empty ids,
    /// a device id exactly when the type is a device's.
    pub fn parse(topic: &str) -> Option<Topic> {
        let mut levels = topic.split('/');
        if levels.next()? != NAMESPACE {
            return None;
        }
        let group = levels.next()?;
        let kind: MessageType = levels.next()?.parse().ok()?;
        let node = levels.next()?;
        let device = levels.next();
        if levels.next().is_some() || kind.is_device() != device.is_some() {
            return None;
        }
        let ids_ok = [Some(group), Some(node), device].into_iter().flatten().all(|id| !id.is_empty());
        ids_ok.then(|| Topic {
            group: group.to_owned(),
            kind,
            node: node.to_owned(),
            device: device.map(str::to_owned),
        })
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{NAMESPACE}/{}/{}/{}", self.group, self.kind, self.node)?;
        match &self.device {
            Some(device) => write!(f, "/{device}"),
            None => Ok(()),
        }
    }
}

/// The topic of a host application's state: `spBv1.0/STATE/<host_id>`.
pub fn state_topic(host_id: &str) -> String {
    format!("{NAMESPACE}/STATE/{host_id}")
}

/// The host id of a STATE topic, if it is one.
pub fn parse_state_topic(topic: &str) -> Option<&str> {
    let host = topic.strip_prefix(NAMESPACE)?.strip_prefix("/STATE/")?;
    (!host.is_empty() && !host.contains('/')).then_some(host)
}

/// A host application's state, as its STATE message says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HostState {
    /// Whether the host is online.
    pub online: bool,
    /// When the host's session began (milliseconds since the Unix epoch), if given.
    pub timestamp: Option<u64>,
}

impl HostState {
    /// Its JSON payload: `{"online":true,"timestamp":1700000000000}`.
    pub fn to_json(&self) -> Vec<u8> {
        let mut json = serde_json::json!({ "online": self.online });
        if let Some(timestamp) = self.timestamp {
            json["timestamp"] = timestamp.into();
        }
        json.to_string().into_bytes()
    }
}

/// The host state of a STATE message's JSON payload `{"online":true,"timestamp":...}`; None
/// when it is not JSON, not an object, or has no boolean `online`.
pub fn parse_state(payload: &[u8]) -> Option<HostState> {
    let json: serde_json::Value = serde_json::from_slice(payload).ok()?;
    let online = json.get("online")?.as_bool()?;
    let timestamp = json.get("timestamp").and_then(serde_json::Value::as_u64);
    Some(HostState { online, timestamp })
}

/// Why a string cannot be a Sparkplug id.
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IdError {
    /// The id is empty.
    #[error("{what} id is empty; Sparkplug ids are one non-empty topic level")]
    Empty {
        /// Which id: group, edge node, device, host.
        what: String,
    },
    /// The id holds a character a topic level cannot.
    #[error("{what} id {id:?} contains '{character}', {}", IdError::reason(*.character))]
    Forbidden {
        /// Which id: group, edge node, device, host.
        what: String,
        /// The id.
        id: String,
        /// The character: `/`, `+` or `#`.
        character: char,
    },
}

impl IdError {
    /// Why `c` cannot be in a topic level.
    fn reason(c: char) -> &'static str {
        match c {
            '/' => "which separates topic levels",
            '+' => "which is MQTT's single-level wildcard",
            _ => "which is MQTT's multi-level wildcard",
        }
    }
}

/// Whether `id` can be a group, edge node, device or host id (`what` names which, for the
/// message): not empty, and none of `/` (a topic level's separator), `+` and `#` (MQTT's
/// wildcards).
///
/// # Errors
/// Says which id and why, e.g. `device id "pump/1" contains '/', which separates topic levels`.
pub fn check_id(what: &str, id: &str) -> Result<(), IdError> {
    if id.is_empty() {
        return Err(IdError::Empty { what: what.to_string() });
    }
    match id.chars().find(|c| matches!(c, '/' | '+' | '#')) {
        Some(character) => Err(IdError::Forbidden { what: what.to_string(), id: id.to_string(), character }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn node_and_device_topics_read_as_the_specification_writes_them() {
        let node = Topic::node("plant", MessageType::NBirth, "bridge1");
        assert_eq!(node.to_string(), "spBv1.0/plant/NBIRTH/bridge1");
        let device = Topic::device("plant", MessageType::DData, "bridge1", "drive1");
        assert_eq!(device.to_string(), "spBv1.0/plant/DDATA/bridge1/drive1");
        assert_eq!(Topic::parse("spBv1.0/plant/NBIRTH/bridge1"), Some(node));
        assert_eq!(Topic::parse("spBv1.0/plant/DDATA/bridge1/drive1"), Some(device));
    }

    #[test]
    fn other_topics_are_not_sparkplug_ones() {
        for topic in [
            "spBv1.0/STATE/scada",
            "spAv1.0/plant/NBIRTH/bridge1",
            "spBv1.0/plant/NBIRTH",
            "spBv1.0/plant/NBIRTH/bridge1/drive1",
            "spBv1.0/plant/DDATA/bridge1",
            "spBv1.0/plant/DDATA/bridge1/drive1/extra",
            "spBv1.0/plant/DDATA/bridge1/",
            "spBv1.0//NDATA/bridge1",
            "spBv1.0/plant/NDATA/",
            "spBv1.0/plant/nbirth/bridge1",
            "spBv1.0/plant/NRESET/bridge1",
            "",
        ] {
            assert_eq!(Topic::parse(topic), None, "{topic}");
        }
    }

    #[test]
    fn message_types_read_back() {
        for kind in MessageType::ALL {
            assert_eq!(kind.as_str().parse::<MessageType>(), Ok(kind));
            assert_eq!(kind.is_device(), kind.as_str().starts_with('D'));
        }
        let error = "STATE".parse::<MessageType>().unwrap_err().to_string();
        assert!(error.contains("\"STATE\" is not a Sparkplug message type"), "{error}");
    }

    #[test]
    fn the_host_state_topic() {
        assert_eq!(state_topic("scada"), "spBv1.0/STATE/scada");
        assert_eq!(parse_state_topic("spBv1.0/STATE/scada"), Some("scada"));
        assert_eq!(parse_state_topic("spBv1.0/STATE/"), None);
        assert_eq!(parse_state_topic("spBv1.0/STATE/a/b"), None);
        assert_eq!(parse_state_topic("spBv1.0/plant/NBIRTH/bridge1"), None);
    }

    #[test]
    fn the_host_state_json() {
        let online = HostState { online: true, timestamp: Some(1_700_000_000_000) };
        assert_eq!(parse_state(br#"{"online":true,"timestamp":1700000000000}"#), Some(online));
        assert_eq!(parse_state(&online.to_json()), Some(online));
        assert_eq!(String::from_utf8_lossy(&online.to_json()), r#"{"online":true,"timestamp":1700000000000}"#);
        let offline = HostState { online: false, timestamp: None };
        assert_eq!(parse_state(br#"{ "online" : false }"#), Some(offline));
        assert_eq!(parse_state(&offline.to_json()), Some(offline));
        for bad in [&b"ONLINE"[..], b"", b"{}", br#"{"online":"true"}"#, b"[true]", b"\xff\xfe", br#"{"online":1}"#] {
            assert_eq!(parse_state(bad), None, "{}", String::from_utf8_lossy(bad));
        }
    }

    #[test]
    fn ids_are_one_topic_level() {
        assert_eq!(check_id("group", "plant-1"), Ok(()));
        assert_eq!(check_id("device", "Drive 1.ä"), Ok(()));
        let said = |what, id| check_id(what, id).unwrap_err().to_string();
        assert_eq!(
            check_id("device", "pump/1"),
            Err(IdError::Forbidden { what: "device".into(), id: "pump/1".into(), character: '/' })
        );
        assert_eq!(check_id("group", ""), Err(IdError::Empty { what: "group".into() }));
        assert_eq!(said("group", ""), "group id is empty; Sparkplug ids are one non-empty topic level");
        assert_eq!(said("device", "pump/1"), "device id \"pump/1\" contains '/', which separates topic levels");
        assert_eq!(
            said("edge node", "a+b"),
            "edge node id \"a+b\" contains '+', which is MQTT's single-level wildcard"
        );
        assert_eq!(said("host", "#"), "host id \"#\" contains '#', which is MQTT's multi-level wildcard");
    }

    fn id() -> impl Strategy<Value = String> {
        "[^/+#]{1,8}"
    }

    proptest! {
        #[test]
        fn a_topic_of_valid_ids_reads_back(
            group in id(), node in id(), device in id(), kind in 0usize..8,
        ) {
            let kind = MessageType::ALL.get(kind).copied().unwrap_or(MessageType::NData);
            let topic = if kind.is_device() {
                Topic::device(&group, kind, &node, &device)
            } else {
                Topic::node(&group, kind, &node)
            };
            prop_assert!(check_id("group", &group).is_ok());
            prop_assert_eq!(Topic::parse(&topic.to_string()), Some(topic));
        }
    }
}
