//! Roles mapped to rights (MB-TCP-Security v36 R-24–R-31): which units, function codes and
//! addresses each role may use, read from a TOML file the user writes; checked on every
//! request.
//!
//! ```toml
//! # Each [role.NAME] gives the rights of the certificates whose role is NAME.
//! [role.operator]
//! access = "read-write"          # "read" (the default) or "read-write"
//! units = ["1-10", 17]           # default: every unit
//! functions = [3, 4, 6, 16]      # default: every function the access allows
//! addresses = ["0-0x00FF"]       # default: every address
//!
//! [role.viewer]
//! access = "read"
//!
//! # Certificates without a role extension (the NULL role); without this section they may
//! # do nothing.
//! [null-role]
//! access = "read"
//! units = [1]
//! ```
//!
//! A role that is not in the file may do nothing. `access = "read"` allows the function
//! codes that change nothing in a device ([`READ_FUNCTIONS`]); everything else, 0x08
//! Diagnostics (which can restart a device's communications) and 0x17 Read/Write Multiple
//! Registers included, needs `"read-write"`. `addresses` applies to every table (coils,
//! inputs, registers): every address a request touches must lie in one of the ranges; a
//! request without addresses (0x07, 0x08, 0x11, 0x2B...) is not limited by them. A request
//! outside its role's rights gets exception 01 Illegal Function (R-31).

use std::collections::HashMap;
use std::fmt;
use std::ops::{Range, RangeInclusive};
use std::path::Path;

use ferrobus_profile::source::{self, Located, Place};
use ferrobus_proto::FunctionCode;
use ferrobus_proto::pdu::{AddressRange, Request};
use serde::Deserialize;
use toml::Spanned;

use super::Role;
use crate::text::Item;

/// The function codes `access = "read"` allows: reads of data, status, counters, logs and
/// identification (0x01 0x02 0x03 0x04 0x07 0x0B 0x0C 0x11 0x14 0x18 0x2B).
pub const READ_FUNCTIONS: [u8; 11] = [0x01, 0x02, 0x03, 0x04, 0x07, 0x0B, 0x0C, 0x11, 0x14, 0x18, 0x2B];

/// What one role may do.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Rights {
    write: bool,
    units: Option<Vec<RangeInclusive<u8>>>,
    functions: Option<Vec<u8>>,
    addresses: Option<Vec<AddressRange>>,
}

impl Rights {
    /// Reads of every unit, function and address.
    pub fn read_only() -> Self {
        Rights { write: false, units: None, functions: None, addresses: None }
    }

    /// Everything.
    pub fn read_write() -> Self {
        Rights { write: true, ..Rights::read_only() }
    }

    /// Only these units.
    #[must_use]
    pub fn with_units(mut self, units: impl IntoIterator<Item = RangeInclusive<u8>>) -> Self {
        self.units = Some(units.into_iter().collect());
        self
    }

    /// Only these function codes (within what the access allows).
    #[must_use]
    pub fn with_functions(mut self, codes: impl IntoIterator<Item = u8>) -> Self {
        self.functions = Some(codes.into_iter().collect());
        self
    }

    /// Only these addresses, in every table.
    #[must_use]
    pub fn with_addresses(mut self, ranges: impl IntoIterator<Item = AddressRange>) -> Self {
        self.addresses = Some(ranges.into_iter().collect());
        self
    }

    /// Why `request` to `unit` is outside these rights, if it is.
    pub fn check(&self, unit: u8, request: &Request<'_>) -> Result<(), Denied> {
        let function = request.function();
        if self.units.as_ref().is_some_and(|units| !units.iter().any(|r| r.contains(&unit))) {
            return Err(Denied::Unit(unit));
        }
        if self.functions.as_ref().is_some_and(|codes| !codes.contains(&function.value())) {
            return Err(Denied::Function(function));
        }
        if !self.write && !READ_FUNCTIONS.contains(&function.value()) {
            return Err(Denied::ReadOnly(function));
        }
        if let Some(allowed) = &self.addresses {
            for touched in request.address_ranges().into_iter().flatten() {
                if !allowed.iter().any(|a| a.first() <= touched.first() && touched.last() <= a.last()) {
                    return Err(Denied::Addresses(touched));
                }
            }
        }
        Ok(())
    }
}

/// Why a request was denied.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[non_exhaustive]
pub enum Denied {
    /// The role has no rights at all (no section for it).
    NoRights,
    /// The unit is not among the role's.
    Unit(u8),
    /// The function code is not among the role's.
    Function(FunctionCode),
    /// The role may only read, and this function writes (or may change the device).
    ReadOnly(FunctionCode),
    /// These addresses are outside the role's.
    Addresses(AddressRange),
}

impl fmt::Display for Denied {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Denied::NoRights => f.write_str("the roles file gives it no rights"),
            Denied::Unit(unit) => write!(f, "unit {unit} is not among its units"),
            Denied::Function(code) => write!(f, "function {code} is not among its functions"),
            Denied::ReadOnly(code) => write!(f, "it may only read, and {code} is not a read"),
            Denied::Addresses(r) => write!(f, "addresses {}-{} are outside its addresses", r.first(), r.last()),
        }
    }
}

/// The rights of every role: the roles-to-rights database.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct Policy {
    roles: HashMap<String, Rights>,
    null: Option<Rights>,
    /// The rights of a named role without its own section.
    others: Option<Rights>,
}

impl Policy {
    /// A policy where no role may do anything (add rights with [`Policy::with_role`]).
    pub fn deny_all() -> Self {
        Policy::default()
    }

    /// Any client with a trusted certificate, whatever its role, may do anything: the policy
    /// of a server run without a roles file.
    pub fn allow_all() -> Self {
        Policy { roles: HashMap::new(), null: Some(Rights::read_write()), others: Some(Rights::read_write()) }
    }

    /// Gives `role` these rights.
    #[must_use]
    pub fn with_role(mut self, role: &Role, rights: Rights) -> Self {
        match role {
            Role::Null => self.null = Some(rights),
            Role::Named(name) => {
                self.roles.insert(name.clone(), rights);
            }
        }
        self
    }

    /// The rights of `role`: its section's, or for a named role without one those of
    /// [`Policy::allow_all`]'s catch-all, if the policy has it.
    pub fn rights(&self, role: &Role) -> Option<&Rights> {
        match role {
            Role::Null => self.null.as_ref(),
            Role::Named(name) => self.roles.get(name).or(self.others.as_ref()),
        }
    }

    /// Whether `role` may send `request` to `unit`.
    pub fn check(&self, role: &Role, unit: u8, request: &Request<'_>) -> Result<(), Denied> {
        self.rights(role).ok_or(Denied::NoRights)?.check(unit, request)
    }

    /// Reads a roles file.
    pub fn load(path: &Path) -> Result<Policy, PolicyError> {
        let text = source::read(path).map_err(|e| PolicyError::from(e.located()).in_file(path))?;
        Policy::parse(&text).map_err(|e| e.in_file(path))
    }

    /// Parses the text of a roles file.
    pub fn parse(text: &str) -> Result<Policy, PolicyError> {
        let at = |span: Option<Range<usize>>, message: String| PolicyError::from(Located::new(text, span, &message));
        let file: File = toml::from_str(text).map_err(|e| PolicyError::from(Located::toml(text, &e)))?;
        let mut policy = Policy::deny_all();
        for (name, section) in file.role {
            if name.is_empty() {
                return Err(at(None, "a role name is empty".to_string()));
            }
            let rights = section.rights().map_err(|(span, message)| at(Some(span), message))?;
            policy.roles.insert(name, rights);
        }
        if let Some(section) = file.null_role {
            policy.null = Some(section.rights().map_err(|(span, message)| at(Some(span), message))?);
        }
        Ok(policy)
    }
}

/// A roles file that could not be used, with where: `file:line:col: message (in `excerpt`)`,
/// a few hundred bytes at most however long the line ([`ferrobus_profile::source`]).
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[error("{}", Located { place: self.line.zip(self.column).map(|(line, column)| Place { line, column }), excerpt: self.text.clone(), message: self.message.clone() }.in_file(&self.file))]
pub struct PolicyError {
    /// The file (`roles` when parsed from text).
    pub file: String,
    /// The line at fault (from 1), when known.
    pub line: Option<usize>,
    /// The column at fault (from 1, in characters), when known.
    pub column: Option<usize>,
    /// An excerpt of that line around the column, escaped.
    pub text: String,
    /// What is wrong.
    pub message: String,
}

impl From<Located> for PolicyError {
    fn from(mistake: Located) -> Self {
        PolicyError {
            file: "roles".to_string(),
            line: mistake.place.map(|p| p.line),
            column: mistake.place.map(|p| p.column),
            text: mistake.excerpt,
            message: mistake.message,
        }
    }
}

impl PolicyError {
    fn in_file(mut self, path: &Path) -> Self {
        self.file = path.display().to_string();
        self
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    role: HashMap<String, Section>,
    #[serde(rename = "null-role")]
    null_role: Option<Section>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Section {
    access: Option<Spanned<String>>,
    units: Option<Vec<Spanned<Item>>>,
    functions: Option<Vec<Spanned<Item>>>,
    addresses: Option<Vec<Spanned<Item>>>,
}

type Problem = (Range<usize>, String);

impl Section {
    fn rights(self) -> Result<Rights, Problem> {
        let write = match self.access {
            None => false,
            Some(access) => match access.get_ref().as_str() {
                "read" => false,
                "read-write" => true,
                other => {
                    return Err((access.span(), format!("access is \"read\" or \"read-write\", not \"{other}\"")));
                }
            },
        };
        let units = self.units.map(|items| ranges(items, "unit", u64::from(u8::MAX))).transpose()?.map(|rs| {
            rs.into_iter()
                .map(|(a, b)| u8::try_from(a).unwrap_or(u8::MAX)..=u8::try_from(b).unwrap_or(u8::MAX))
                .collect()
        });
        let functions = self
            .functions
            .map(|items| {
                let mut codes = Vec::new();
                for (first, last) in ranges(items, "function code", 0x7F)? {
                    codes.extend((first..=last).filter_map(|c| u8::try_from(c).ok()));
                }
                Ok::<_, Problem>(codes)
            })
            .transpose()?;
        let addresses = self
            .addresses
            .map(|items| ranges(items, "register or coil address", u64::from(u16::MAX)))
            .transpose()?
            .map(|rs| {
                rs.into_iter()
                    .filter_map(|(a, b)| AddressRange::new(u16::try_from(a).ok()?, u16::try_from(b).ok()?))
                    .collect()
            });
        Ok(Rights { write, units, functions, addresses })
    }
}

/// The inclusive ranges `items` give, each within 0..=`max`.
fn ranges(items: Vec<Spanned<Item>>, what: &str, max: u64) -> Result<Vec<(u64, u64)>, Problem> {
    let mut out = Vec::with_capacity(items.len());
    for item in items {
        let span = item.span();
        let bad = |why: String| (span.clone(), why);
        let (first, last) = match item.into_inner() {
            Item::Number(n) => {
                let n = u64::try_from(n).map_err(|_| bad(format!("{what} {n} is negative")))?;
                (n, n)
            }
            Item::Text(text) => {
                let (a, b) = text.split_once('-').unwrap_or((&text, &text));
                let number = |s: &str| {
                    parse_number(s.trim()).ok_or_else(|| bad(format!("'{text}' is neither a {what} nor a range A-B")))
                };
                (number(a)?, number(b)?)
            }
        };
        if first > last {
            return Err(bad(format!("the range {first}-{last} ends before it begins")));
        }
        if last > max {
            return Err(bad(format!("{what} {last} is past the highest, {max}")));
        }
        out.push((first, last));
    }
    Ok(out)
}

/// A number by the one number grammar ([`crate::text::number`]: decimal or 0x hex).
fn parse_number(text: &str) -> Option<u64> {
    crate::text::number(text, u64::MAX).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(pdu: &[u8]) -> Request<'_> {
        Request::parse(pdu).unwrap()
    }

    const READ_3_AT_0X10: [u8; 5] = [0x03, 0x00, 0x10, 0x00, 0x03];
    const WRITE_6_AT_0X10: [u8; 5] = [0x06, 0x00, 0x10, 0x12, 0x34];

    #[test]
    fn a_read_role_reads_and_may_not_write() {
        let policy = Policy::parse("[role.viewer]\naccess = \"read\"\n").unwrap();
        let viewer = Role::Named("viewer".into());
        assert_eq!(policy.check(&viewer, 1, &request(&READ_3_AT_0X10)), Ok(()));
        assert_eq!(
            policy.check(&viewer, 1, &request(&WRITE_6_AT_0X10)),
            Err(Denied::ReadOnly(FunctionCode::WriteSingleRegister))
        );
        // Diagnostics and read/write registers need write access.
        assert!(policy.check(&viewer, 1, &request(&[0x08, 0x00, 0x00, 0x12, 0x34])).is_err());
    }

    #[test]
    fn units_functions_and_addresses_limit_a_role() {
        let text = "[role.op]\naccess = \"read-write\"\nunits = [\"1-3\", 9]\nfunctions = [3, \"5-6\"]\n\
                    addresses = [\"0x10-0x11\", 0x20]\n";
        let policy = Policy::parse(text).unwrap();
        let op = Role::Named("op".into());
        assert_eq!(policy.check(&op, 4, &request(&WRITE_6_AT_0X10)), Err(Denied::Unit(4)));
        assert_eq!(policy.check(&op, 9, &request(&WRITE_6_AT_0X10)), Ok(()));
        assert_eq!(
            policy.check(&op, 1, &request(&[0x04, 0x00, 0x10, 0x00, 0x01])),
            Err(Denied::Function(FunctionCode::ReadInputRegisters))
        );
        // 0x10..=0x12: the last one is outside.
        assert_eq!(
            policy.check(&op, 1, &request(&READ_3_AT_0X10)),
            Err(Denied::Addresses(AddressRange::new(0x10, 0x12).unwrap()))
        );
        assert_eq!(policy.check(&op, 1, &request(&[0x03, 0x00, 0x10, 0x00, 0x02])), Ok(()));
        assert_eq!(policy.check(&op, 1, &request(&[0x05, 0x00, 0x20, 0xFF, 0x00])), Ok(()));
    }

    #[test]
    fn roles_not_in_the_file_and_the_null_role_get_nothing_unless_given() {
        let policy = Policy::parse("[role.viewer]\n").unwrap();
        let read = request(&READ_3_AT_0X10);
        assert_eq!(policy.check(&Role::Named("admin".into()), 1, &read), Err(Denied::NoRights));
        assert_eq!(policy.check(&Role::Null, 1, &read), Err(Denied::NoRights));
        let policy = Policy::parse("[null-role]\nunits = [1]\n").unwrap();
        assert_eq!(policy.check(&Role::Null, 1, &read), Ok(()));
        assert_eq!(policy.check(&Role::Null, 2, &read), Err(Denied::Unit(2)));
    }

    #[test]
    fn rights_built_in_code_match_the_same_rights_parsed() {
        let built = Rights::read_write()
            .with_units([1..=3, 9..=9])
            .with_functions([3, 5, 6])
            .with_addresses([AddressRange::new(0x10, 0x11).unwrap(), AddressRange::new(0x20, 0x20).unwrap()]);
        let text = "[role.op]\naccess = \"read-write\"\nunits = [\"1-3\", 9]\nfunctions = [3, \"5-6\"]\n\
                    addresses = [\"0x10-0x11\", 0x20]\n";
        let parsed = Policy::parse(text).unwrap();
        assert_eq!(parsed.rights(&Role::Named("op".into())), Some(&built));
        let policy = Policy::deny_all().with_role(&Role::Named("op".into()), built);
        assert_eq!(policy, parsed);
    }

    #[test]
    fn allow_all_lets_every_role_do_everything() {
        let policy = Policy::allow_all();
        for role in [Role::Null, Role::Named("anyone".into())] {
            assert_eq!(policy.check(&role, 7, &request(&WRITE_6_AT_0X10)), Ok(()));
        }
    }

    #[test]
    fn errors_name_the_line_and_what_is_wrong() {
        let cases = [
            ("[role.a]\naccess = \"write\"\n", 2, "access is \"read\" or \"read-write\", not \"write\""),
            ("[role.a]\n\nunits = [1, 300]\n", 3, "unit 300 is past the highest, 255"),
            ("[role.a]\nfunctions = [\"6-5\"]\n", 2, "the range 6-5 ends before it begins"),
            ("[role.a]\naddresses = [\"low\"]\n", 2, "'low' is neither a register or coil address nor a range A-B"),
            ("[role.a]\nunits = [-1]\n", 2, "unit -1 is negative"),
            ("[role.a]\nacces = \"read\"\n", 2, "unknown field `acces`"),
            ("[roles.a]\n", 1, "unknown field `roles`"),
            ("[role.a\n", 1, ""),
        ];
        for (text, line, message) in cases {
            let error = Policy::parse(text).unwrap_err();
            assert_eq!(error.line, Some(line), "{text:?}: {error}");
            assert!(error.message.contains(message), "{text:?}: {error}");
            assert!(error.to_string().starts_with(&format!("roles:{line}:")), "{error}");
        }
    }

    #[test]
    fn a_mistake_on_a_10_mb_line_is_told_in_a_few_hundred_bytes_with_its_column() {
        let text = format!("[role.a]\naccess = \"{}\"\n", "w".repeat(10 << 20));
        let error = Policy::parse(&text).unwrap_err();
        let shown = error.to_string();
        assert!(shown.len() < 2_000, "{} bytes", shown.len());
        assert!(shown.starts_with("roles:2:") && shown.contains('…'), "{}", shown.get(..300).unwrap_or(&shown));
    }

    #[test]
    fn a_roles_file_that_is_not_utf8_is_refused_with_its_line_and_column() {
        let path = std::env::temp_dir().join(format!("ferrobus-roles-binary-{}.toml", std::process::id()));
        std::fs::write(&path, b"[role.a]\naccess = \"r\xffead\"\n").unwrap();
        let error = Policy::load(&path).unwrap_err();
        let _ = std::fs::remove_file(&path);
        assert_eq!(error.to_string(), format!("{}:2:12: byte 0xFF is not UTF-8 text", path.display()));
    }

    #[test]
    fn the_documented_example_parses_to_what_it_says() {
        let text = "[role.operator]\naccess = \"read-write\"\nunits = [\"1-10\", 17]\nfunctions = [3, 4, 6, 16]\n\
                    addresses = [\"0-0x00FF\"]\n[role.viewer]\n[null-role]\naccess = \"read\"\nunits = [1]\n";
        let policy = Policy::parse(text).unwrap();
        let operator = Role::Named("operator".into());
        assert_eq!(policy.check(&operator, 17, &request(&WRITE_6_AT_0X10)), Ok(()));
        assert_eq!(policy.check(&operator, 11, &request(&WRITE_6_AT_0X10)), Err(Denied::Unit(11)));
        let viewer = Role::Named("viewer".into());
        assert_eq!(policy.check(&viewer, 200, &request(&READ_3_AT_0X10)), Ok(()));
        assert!(policy.check(&viewer, 200, &request(&WRITE_6_AT_0X10)).is_err());
        assert_eq!(policy.check(&Role::Null, 1, &request(&READ_3_AT_0X10)), Ok(()));
        assert_eq!(policy.check(&Role::Null, 2, &request(&READ_3_AT_0X10)), Err(Denied::Unit(2)));
    }

    #[test]
    fn a_missing_file_is_named() {
        let error = Policy::load(Path::new("/nonexistent/roles.toml")).unwrap_err();
        assert!(error.to_string().starts_with("/nonexistent/roles.toml: cannot read it: "), "{error}");
    }
}
