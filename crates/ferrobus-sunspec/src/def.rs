//! SunSpec model definitions: the SunSpec Alliance's JSON model files (`model_<ID>.json`, as
//! pysunspec2 ships them), read and checked.
//!
//! A model file is `{"id": N, "group": {...}}`. A group has a `name`, `points` and `groups`
//! (repeating groups, with a `count`: a number, 0 for "as many as fill the model's length",
//! or the name of a `count` point; none is one instance). A point has a `name`, a `type`
//! (`uint16`, `int16`, `acc32`, `float32`, `string`, `enum16`, `bitfield32`, `sunssf`,
//! `pad`, ...), a `size` in registers, and optionally `sf` (the scale factor point naming
//! 10^sf), `units`, `access` (`R` or `RW`), `mandatory` (`M`) and `symbols` (the meanings of
//! an enumeration's values or a bit field's bits).
//!
//! The top group's first two points are the model's header, `ID` and `L` (the length in
//! registers after the header). Checking refuses what a device map could not be built from:
//! an unknown type, a size that does not fit the type, a scale factor or a count that names no
//! point; every error names the model and the point.
//!
//! This file is also compiled into the crate's `build.rs`, which checks the files it embeds
//! with it: it uses nothing but std, serde, serde_json and thiserror.

use serde::Deserialize;

/// One model definition.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelDef {
    /// The model id (1 common, 103 three-phase inverter, 203 meter, ...).
    pub id: u16,
    /// The top group: the header (`ID`, `L`), the fixed points and the repeating groups.
    pub group: GroupDef,
}

/// A group of points: the model's top group, or a repeating group in it.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupDef {
    /// The name (`common`, `inverter_three_phase`, `module`).
    pub name: String,
    /// A human name.
    pub label: Option<String>,
    /// The points, in register order.
    pub points: Vec<PointDef>,
    /// The groups that follow the points, in register order.
    pub groups: Vec<GroupDef>,
    /// How many times the group repeats.
    pub count: Count,
}

/// How many times a group repeats.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Count {
    /// Once (the top group, or a group written without a count).
    One,
    /// As many as fill the rest of the model's length (`"count": 0`).
    Fill,
    /// A fixed number.
    Fixed(u16),
    /// The value of the `count` point of this name in the enclosing group.
    Point(String),
}

/// One point of a group.
#[derive(Clone, Debug, PartialEq)]
pub struct PointDef {
    /// The name (`W`, `Mn`, `A_SF`).
    pub name: String,
    /// A human name.
    pub label: Option<String>,
    /// What it is.
    pub desc: Option<String>,
    /// The type.
    pub kind: PointType,
    /// Registers.
    pub size: u16,
    /// The scale factor: value = raw × 10^sf.
    pub sf: Option<ScaleFactor>,
    /// The unit (`W`, `Wh`, `A`).
    pub units: Option<String>,
    /// Whether it may be written (`"access": "RW"`).
    pub writable: bool,
    /// Whether every device must give it (`"mandatory": "M"`).
    pub mandatory: bool,
    /// An enumeration's values or a bit field's bits: (value or bit, name).
    pub symbols: Vec<(i64, String)>,
}

/// Where a point's scale factor comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ScaleFactor {
    /// The `sunssf` point of this name (in the point's group or an enclosing one).
    Point(String),
    /// A fixed power of ten.
    Fixed(i8),
}

/// A point's type, as the model files name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointType {
    /// `uint16`.
    Uint16,
    /// `int16`.
    Int16,
    /// `uint32`.
    Uint32,
    /// `int32`.
    Int32,
    /// `uint64`.
    Uint64,
    /// `int64`.
    Int64,
    /// `acc16`: an accumulator.
    Acc16,
    /// `acc32`: an accumulator.
    Acc32,
    /// `acc64`: an accumulator.
    Acc64,
    /// `float32`.
    Float32,
    /// `float64`.
    Float64,
    /// `enum16`: an enumeration.
    Enum16,
    /// `enum32`: an enumeration.
    Enum32,
    /// `bitfield16`.
    Bitfield16,
    /// `bitfield32`.
    Bitfield32,
    /// `bitfield64`.
    Bitfield64,
    /// A scale factor: a power of ten, an int16.
    Sunssf,
    /// A count of repeating groups (uint16).
    Count,
    /// Text, two characters a register.
    String,
    /// A register that holds nothing (alignment).
    Pad,
    /// An IPv4 address (uint32).
    Ipaddr,
    /// An IPv6 address (8 registers).
    Ipv6addr,
    /// A MAC address (4 registers).
    Eui48,
}

impl PointType {
    /// Every type, with its name in the model files.
    pub const ALL: [(PointType, &'static str); 23] = [
        (PointType::Uint16, "uint16"),
        (PointType::Int16, "int16"),
        (PointType::Uint32, "uint32"),
        (PointType::Int32, "int32"),
        (PointType::Uint64, "uint64"),
        (PointType::Int64, "int64"),
        (PointType::Acc16, "acc16"),
        (PointType::Acc32, "acc32"),
        (PointType::Acc64, "acc64"),
        (PointType::Float32, "float32"),
        (PointType::Float64, "float64"),
        (PointType::Enum16, "enum16"),
        (PointType::Enum32, "enum32"),
        (PointType::Bitfield16, "bitfield16"),
        (PointType::Bitfield32, "bitfield32"),
        (PointType::Bitfield64, "bitfield64"),
        (PointType::Sunssf, "sunssf"),
        (PointType::Count, "count"),
        (PointType::String, "string"),
        (PointType::Pad, "pad"),
        (PointType::Ipaddr, "ipaddr"),
        (PointType::Ipv6addr, "ipv6addr"),
        (PointType::Eui48, "eui48"),
    ];

    /// The type of a model file's name.
    pub fn from_name(name: &str) -> Option<PointType> {
        PointType::ALL.iter().find(|(_, n)| *n == name).map(|(t, _)| *t)
    }

    /// The name in the model files.
    pub fn name(self) -> &'static str {
        PointType::ALL.iter().find(|(t, _)| *t == self).map_or("?", |(_, n)| n)
    }

    /// Registers of a value of the type; `None` for a string (its `size` says).
    pub const fn registers(self) -> Option<u16> {
        Some(match self {
            PointType::Uint16
            | PointType::Int16
            | PointType::Acc16
            | PointType::Enum16
            | PointType::Bitfield16
            | PointType::Sunssf
            | PointType::Count
            | PointType::Pad => 1,
            PointType::Uint32
            | PointType::Int32
            | PointType::Acc32
            | PointType::Float32
            | PointType::Enum32
            | PointType::Bitfield32
            | PointType::Ipaddr => 2,
            PointType::Uint64
            | PointType::Int64
            | PointType::Acc64
            | PointType::Float64
            | PointType::Bitfield64
            | PointType::Eui48 => 4,
            PointType::Ipv6addr => 8,
            PointType::String => return None,
        })
    }
}

/// Why a model file was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum DefError {
    /// Not JSON, or not the shape of a model file.
    #[error("{origin}: not a SunSpec model file: {reason}")]
    Json {
        /// The file (or the embedded model).
        origin: String,
        /// serde_json's words, with line and column.
        reason: String,
    },
    /// A point or group that a device map cannot be built from.
    #[error("{origin}: model {model}, {place}: {problem}")]
    Invalid {
        /// The file (or the embedded model).
        origin: String,
        /// The model's id.
        model: u16,
        /// The group and point at fault: `group inverter, point W`.
        place: String,
        /// What is wrong, with what was seen.
        problem: String,
    },
}

#[derive(Deserialize)]
struct RawModel {
    id: u16,
    group: RawGroup,
}

#[derive(Deserialize)]
struct RawGroup {
    name: String,
    label: Option<String>,
    #[serde(default)]
    points: Vec<RawPoint>,
    #[serde(default)]
    groups: Vec<RawGroup>,
    count: Option<serde_json::Value>,
}

#[derive(Deserialize)]
struct RawPoint {
    name: String,
    label: Option<String>,
    desc: Option<String>,
    #[serde(rename = "type")]
    kind: String,
    size: u16,
    sf: Option<serde_json::Value>,
    units: Option<String>,
    access: Option<String>,
    mandatory: Option<String>,
    #[serde(default)]
    symbols: Vec<RawSymbol>,
}

#[derive(Deserialize)]
struct RawSymbol {
    name: String,
    value: i64,
}

impl ModelDef {
    /// Reads and checks one model file's text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<ModelDef, DefError> {
        let raw: RawModel = serde_json::from_str(text)
            .map_err(|e| DefError::Json { origin: origin.to_string(), reason: e.to_string() })?;
        let id = raw.id;
        let invalid = |place: String, problem: String| DefError::Invalid {
            origin: origin.to_string(),
            model: id,
            place,
            problem,
        };
        let group = convert_group(raw.group, true, &invalid)?;
        let model = ModelDef { id, group };
        model.check(&invalid)?;
        Ok(model)
    }

    /// The model's name: its top group's name (`common`, `inverter_three_phase`).
    pub fn name(&self) -> &str {
        &self.group.name
    }

    /// Registers after the header (`ID`, `L`) of the fixed part: what `L` is for a model
    /// without repeating groups.
    pub fn fixed_length(&self) -> u32 {
        self.group.fixed_registers().saturating_sub(2)
    }

    fn check(&self, invalid: &dyn Fn(String, String) -> DefError) -> Result<(), DefError> {
        let header: Vec<(&str, PointType)> =
            self.group.points.iter().take(2).map(|p| (p.name.as_str(), p.kind)).collect();
        if header != [("ID", PointType::Uint16), ("L", PointType::Uint16)] {
            return Err(invalid(
                format!("group {}", self.group.name),
                format!("the first two points must be ID and L (uint16), not {header:?}"),
            ));
        }
        let mut scope = Vec::new();
        check_group(&self.group, &mut scope, invalid)
    }
}

impl GroupDef {
    /// Registers of one instance of the group's points (not its groups).
    pub fn fixed_registers(&self) -> u32 {
        self.points.iter().map(|p| u32::from(p.size)).sum()
    }

    /// Registers of one instance with one instance of each of its groups with a fixed count
    /// (the smallest a repeating group can be read as).
    pub fn registers_once(&self) -> u32 {
        self.fixed_registers() + self.groups.iter().map(GroupDef::registers_once).sum::<u32>()
    }
}

fn convert_group(raw: RawGroup, top: bool, invalid: &dyn Fn(String, String) -> DefError) -> Result<GroupDef, DefError> {
    let place = format!("group {}", raw.name);
    let count = match raw.count {
        None => Count::One,
        Some(serde_json::Value::Number(n)) => match n.as_u64() {
            Some(0) => Count::Fill,
            Some(n) => {
                Count::Fixed(u16::try_from(n).map_err(|_| invalid(place.clone(), format!("count {n} is over 65535")))?)
            }
            None => return Err(invalid(place, format!("count {n} is not a number of groups"))),
        },
        Some(serde_json::Value::String(name)) => Count::Point(name),
        Some(other) => return Err(invalid(place, format!("count {other} is neither a number nor a point name"))),
    };
    if top && count != Count::One {
        return Err(invalid(place, "the model's top group does not repeat".into()));
    }
    let points = raw.points.into_iter().map(|p| convert_point(p, &raw.name, invalid)).collect::<Result<Vec<_>, _>>()?;
    let groups = raw.groups.into_iter().map(|g| convert_group(g, false, invalid)).collect::<Result<Vec<_>, _>>()?;
    Ok(GroupDef { name: raw.name, label: raw.label, points, groups, count })
}

fn convert_point(
    raw: RawPoint,
    group: &str,
    invalid: &dyn Fn(String, String) -> DefError,
) -> Result<PointDef, DefError> {
    let place = format!("group {group}, point {}", raw.name);
    let Some(kind) = PointType::from_name(&raw.kind) else {
        return Err(invalid(
            place,
            format!(
                "type {:?} is not a SunSpec point type: one of {}",
                raw.kind,
                PointType::ALL.iter().map(|(_, n)| *n).collect::<Vec<_>>().join(", ")
            ),
        ));
    };
    match kind.registers() {
        Some(n) if n != raw.size => {
            return Err(invalid(place, format!("size {} does not fit type {} ({n} registers)", raw.size, kind.name())));
        }
        None if raw.size == 0 => return Err(invalid(place, "a string of size 0".into())),
        _ => {}
    }
    let sf = match raw.sf {
        None => None,
        Some(serde_json::Value::String(name)) => Some(ScaleFactor::Point(name)),
        Some(serde_json::Value::Number(n)) => match n.as_i64().and_then(|n| i8::try_from(n).ok()) {
            Some(n) if (-10..=10).contains(&n) => Some(ScaleFactor::Fixed(n)),
            _ => return Err(invalid(place, format!("sf {n} is not a power of ten from -10 to 10"))),
        },
        Some(other) => return Err(invalid(place, format!("sf {other} is neither a number nor a point name"))),
    };
    let writable = match raw.access.as_deref() {
        None | Some("R") => false,
        Some("RW") => true,
        Some(other) => return Err(invalid(place, format!("access {other:?} is neither R nor RW"))),
    };
    Ok(PointDef {
        name: raw.name,
        label: raw.label,
        desc: raw.desc,
        kind,
        size: raw.size,
        sf,
        units: raw.units,
        writable,
        mandatory: raw.mandatory.as_deref() == Some("M"),
        symbols: raw.symbols.into_iter().map(|s| (s.value, s.name)).collect(),
    })
}

/// Checks that every scale factor and count names a point of the right type in the group or
/// an enclosing one (`scope` holds the enclosing groups).
fn check_group<'d>(
    group: &'d GroupDef,
    scope: &mut Vec<&'d GroupDef>,
    invalid: &dyn Fn(String, String) -> DefError,
) -> Result<(), DefError> {
    scope.push(group);
    let find = |scope: &[&GroupDef], name: &str| {
        scope.iter().rev().find_map(|g| g.points.iter().find(|p| p.name == name)).map(|p| p.kind)
    };
    for p in &group.points {
        if let Some(ScaleFactor::Point(name)) = &p.sf {
            match find(scope, name) {
                Some(PointType::Sunssf) => {}
                Some(other) => {
                    return Err(invalid(
                        format!("group {}, point {}", group.name, p.name),
                        format!("sf names {name}, a {} point, not a sunssf", other.name()),
                    ));
                }
                None => {
                    return Err(invalid(
                        format!("group {}, point {}", group.name, p.name),
                        format!("sf names {name}, which the model does not have"),
                    ));
                }
            }
        }
    }
    for g in &group.groups {
        if let Count::Point(name) = &g.count
            && !matches!(find(scope, name), Some(PointType::Count | PointType::Uint16))
        {
            return Err(invalid(
                format!("group {}", g.name),
                format!("count names {name}, which is no count point before it"),
            ));
        }
        check_group(g, scope, invalid)?;
    }
    scope.pop();
    Ok(())
}
