//! The role a client certificate carries (MB-TCP-Security v36 §6, R-21–R-23, R-65).
//!
//! The role is the certificate extension [`ROLE_OID`], whose value is one DER `UTF8String`
//! (tag 0x0C); the whole string is the role. A certificate without the extension has the
//! NULL role ([`Role::Null`]), which the authorization step is given like any other. A value
//! in another encoding (an OCTET STRING or a PrintableString, as some examples write it), a
//! malformed one, or more than one role extension is an error: such a certificate is refused.

use std::fmt;

use x509_parser::prelude::{FromDer, X509Certificate};

use crate::log::escape;

/// The role extension's OID, 1.3.6.1.4.1.50316.802.1 (R-21).
pub const ROLE_OID: &str = "1.3.6.1.4.1.50316.802.1";

/// The DER tag of a `UTF8String` (R-22).
const UTF8_STRING: u8 = 0x0C;

/// The role a client is authorized as.
#[derive(Clone, PartialEq, Eq, Hash, Debug)]
pub enum Role {
    /// The certificate has no role extension (R-23).
    Null,
    /// The role named by the extension.
    Named(String),
}

impl fmt::Display for Role {
    /// The role as log lines name it: the name is the certificate's text, so it is escaped
    /// ([`escape`]): a role cannot end the line and forge the next.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Role::Null => f.write_str("the NULL role"),
            Role::Named(name) => write!(f, "role '{}'", escape(name)),
        }
    }
}

/// Why a certificate's role is refused.
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RoleError {
    /// The certificate itself does not parse.
    #[error("the client certificate does not parse: {0}")]
    Certificate(String),
    /// More than one role extension (R-65: exactly one role).
    #[error("the client certificate has {0} role extensions ({ROLE_OID}); exactly one is allowed")]
    Several(usize),
    /// The value is not a `UTF8String`.
    #[error("the role extension ({ROLE_OID}) holds ASN.1 tag 0x{0:02X}, not a UTF8String (0x0C)")]
    NotUtf8String(u8),
    /// The value is not one whole DER element.
    #[error("the role extension ({ROLE_OID}) is not one well-formed DER UTF8String")]
    Malformed,
    /// The string's bytes are not UTF-8.
    #[error("the role extension ({ROLE_OID}) is a UTF8String whose bytes are not UTF-8")]
    InvalidUtf8,
    /// The string is empty.
    #[error("the role extension ({ROLE_OID}) is an empty string")]
    Empty,
}

/// The role of the DER certificate `der`.
pub fn role_of(der: &[u8]) -> Result<Role, RoleError> {
    let (_, cert) = X509Certificate::from_der(der).map_err(|e| RoleError::Certificate(e.to_string()))?;
    let mut roles = cert.extensions().iter().filter(|ext| ext.oid.to_id_string() == ROLE_OID);
    let Some(first) = roles.next() else { return Ok(Role::Null) };
    let others = roles.count();
    if others > 0 {
        return Err(RoleError::Several(others.saturating_add(1)));
    }
    parse_utf8_string(first.value).map(Role::Named)
}

/// The text of the DER `UTF8String` that is the whole of `value`.
pub fn parse_utf8_string(value: &[u8]) -> Result<String, RoleError> {
    let (&tag, rest) = value.split_first().ok_or(RoleError::Malformed)?;
    if tag != UTF8_STRING {
        return Err(RoleError::NotUtf8String(tag));
    }
    let (&first, rest) = rest.split_first().ok_or(RoleError::Malformed)?;
    let (len, content) = match first {
        0..=0x7F => (usize::from(first), rest),
        0x81 => {
            let (&n, content) = rest.split_first().ok_or(RoleError::Malformed)?;
            // DER: the long form only for lengths the short form cannot hold.
            if n < 0x80 {
                return Err(RoleError::Malformed);
            }
            (usize::from(n), content)
        }
        0x82 => {
            let (bytes, content) = rest.split_at_checked(2).ok_or(RoleError::Malformed)?;
            let n = bytes.iter().fold(0usize, |n, &b| (n << 8) | usize::from(b));
            if n < 0x100 {
                return Err(RoleError::Malformed);
            }
            (n, content)
        }
        _ => return Err(RoleError::Malformed),
    };
    if content.len() != len {
        return Err(RoleError::Malformed);
    }
    let text = std::str::from_utf8(content).map_err(|_| RoleError::InvalidUtf8)?;
    if text.is_empty() {
        return Err(RoleError::Empty);
    }
    Ok(text.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_utf8_string_is_the_role() {
        // 0C 08 "Operator", as `openssl asn1parse` shows rcgen's extension.
        assert_eq!(parse_utf8_string(b"\x0C\x08Operator"), Ok("Operator".to_string()));
    }

    #[test]
    fn a_long_form_length_is_read() {
        let mut value = vec![0x0C, 0x81, 0x80];
        value.extend(std::iter::repeat_n(b'r', 0x80));
        assert_eq!(parse_utf8_string(&value).map(|s| s.len()), Ok(0x80));
        let mut value = vec![0x0C, 0x82, 0x01, 0x00];
        value.extend(std::iter::repeat_n(b'r', 0x100));
        assert_eq!(parse_utf8_string(&value).map(|s| s.len()), Ok(0x100));
    }

    #[test]
    fn other_encodings_and_broken_values_are_refused() {
        // An OCTET STRING, a PrintableString.
        assert_eq!(parse_utf8_string(b"\x04\x08Operator"), Err(RoleError::NotUtf8String(0x04)));
        assert_eq!(parse_utf8_string(b"\x13\x08Operator"), Err(RoleError::NotUtf8String(0x13)));
        // Too short, too long, truncated, not minimal, indefinite, empty, not UTF-8.
        assert_eq!(parse_utf8_string(b"\x0C\x09Operator"), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b"\x0C\x07Operator"), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b""), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b"\x0C"), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b"\x0C\x81"), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b"\x0C\x82\x01"), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b"\x0C\x81\x02ab"), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b"\x0C\x80"), Err(RoleError::Malformed));
        assert_eq!(parse_utf8_string(b"\x0C\x00"), Err(RoleError::Empty));
        assert_eq!(parse_utf8_string(b"\x0C\x02\xC3\x28"), Err(RoleError::InvalidUtf8));
    }

    #[test]
    fn a_role_is_shown_escaped_on_one_line() {
        let role = Role::Named("admin\n2026-12-03T00:00:00Z INFO forged\0".to_string());
        assert_eq!(role.to_string(), r"role 'admin\n2026-12-03T00:00:00Z INFO forged\0'");
    }

    #[test]
    fn garbage_is_not_a_certificate() {
        assert!(matches!(role_of(b"\x30\x03\x02\x01\x00"), Err(RoleError::Certificate(_))));
        assert!(matches!(role_of(b""), Err(RoleError::Certificate(_))));
    }
}
