//! Text from outside, made safe to log.
//!
//! A log line is one line: a value that came from a wire, a file or a peer (a certificate's
//! role or subject, an MQTT metric name, a host name as a client gave it) must not be able to
//! end it and forge the next (`admin\n2026-12-03T00:00:00Z INFO forged`), hide part of it
//! (`\r`, a terminal's escape sequences) or reorder it on screen (Unicode's bidirectional
//! controls). [`escape`] writes such a value with every character of those kinds spelled out
//! the way Rust writes them in a string literal (`\n`, `\r`, `\t`, `\0`, `\u{1b}`, `\u{202e}`)
//! and a backslash doubled, so that the escaped text reads back unambiguously: a role that
//! really is the two characters `\n` is logged as `\\n`. Everything else, non-ASCII letters
//! included, is written as it is. [`escape_bytes`] does the same for bytes that need not be
//! UTF-8, writing each byte of an invalid sequence as `\xNN`.
//!
//! Both return a value that implements [`Display`](fmt::Display): nothing is allocated, and
//! they fit anywhere a value is formatted —
//! `tracing::warn!(role = %escape(name), "refused")` or `format!("role '{}'", escape(name))`.

use std::fmt::{self, Write};

/// `text`, escaped for a log line when formatted (see the [module](self)).
///
/// ```
/// use ferrobus::log::escape;
/// assert_eq!(escape("admin\n2026 INFO forged").to_string(), r"admin\n2026 INFO forged");
/// assert_eq!(escape("a\\b\0\u{1b}[2J").to_string(), r"a\\b\0\u{1b}[2J");
/// assert_eq!(escape("Betreiber für Pumpe 3").to_string(), "Betreiber für Pumpe 3");
/// ```
pub fn escape(text: &str) -> Escaped<'_> {
    Escaped(text.as_bytes())
}

/// `bytes`, escaped for a log line when formatted: as [`escape`] for the parts that are
/// UTF-8, each byte of an invalid sequence as `\xNN`.
///
/// ```
/// use ferrobus::log::escape_bytes;
/// assert_eq!(escape_bytes(b"pump\xff\n").to_string(), r"pump\xff\n");
/// ```
pub fn escape_bytes(bytes: &[u8]) -> Escaped<'_> {
    Escaped(bytes)
}

/// Text or bytes from outside that format escaped: made by [`escape`] and [`escape_bytes`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Escaped<'a>(&'a [u8]);

/// Bytes as upper-case hex pairs, as the frame trace (`-vvv`) writes every frame.
///
/// ```
/// use ferrobus::log::Hex;
/// assert_eq!(Hex(&[0x01, 0x83, 0x0b]).to_string(), "01 83 0B");
/// ```
pub struct Hex<'a>(pub &'a [u8]);

impl fmt::Display for Hex<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, b) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

impl fmt::Display for Escaped<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for chunk in self.0.utf8_chunks() {
            for c in chunk.valid().chars() {
                write_char(f, c)?;
            }
            for byte in chunk.invalid() {
                write!(f, "\\x{byte:02x}")?;
            }
        }
        Ok(())
    }
}

/// Writes `c`, spelled out if it could break, hide or reorder a log line.
fn write_char(f: &mut fmt::Formatter<'_>, c: char) -> fmt::Result {
    if c == '\\' {
        f.write_str("\\\\")
    } else if needs_escape(c) {
        // `\n`, `\r`, `\t`, `\0`, and `\u{…}` for the rest.
        write!(f, "{}", c.escape_debug())
    } else {
        f.write_char(c)
    }
}

/// Whether `c` is a control character (C0, DEL, C1), a line or paragraph separator, or one
/// of Unicode's bidirectional controls.
fn needs_escape(c: char) -> bool {
    c.is_control()
        || matches!(c,
            '\u{2028}' | '\u{2029}'            // line and paragraph separators
            | '\u{200E}' | '\u{200F}' | '\u{061C}' // left-to-right, right-to-left, Arabic marks
            | '\u{202A}'..='\u{202E}'          // embeddings and overrides
            | '\u{2066}'..='\u{2069}') // isolates
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_forged_line_stays_on_one_line() {
        let escaped = escape("admin\n2026-12-03T00:00:00Z INFO forged").to_string();
        assert_eq!(escaped, r"admin\n2026-12-03T00:00:00Z INFO forged");
        assert!(!escaped.contains('\n'));
    }

    #[test]
    fn every_control_character_is_spelled_out() {
        for c in (0u32..0x20).chain(0x7F..0xA0).filter_map(char::from_u32) {
            let escaped = escape(c.encode_utf8(&mut [0; 4])).to_string();
            assert!(escaped.starts_with('\\') && escaped.chars().all(|c| !c.is_control()), "{c:?} gave {escaped:?}");
        }
        assert_eq!(escape("\r\t\0\u{7f}\u{85}").to_string(), r"\r\t\0\u{7f}\u{85}");
    }

    #[test]
    fn separators_and_bidirectional_controls_are_spelled_out() {
        assert_eq!(escape("a\u{2028}b\u{2029}").to_string(), r"a\u{2028}b\u{2029}");
        assert_eq!(escape("\u{202e}txt.exe\u{2066}").to_string(), r"\u{202e}txt.exe\u{2066}");
    }

    #[test]
    fn a_backslash_is_doubled_so_the_escapes_read_back_unambiguously() {
        assert_eq!(escape(r"a\nb").to_string(), r"a\\nb");
        assert_ne!(escape(r"a\nb").to_string(), escape("a\nb").to_string());
    }

    #[test]
    fn printable_text_is_left_as_it_is() {
        let text = "Operator 3G3RX: Drehzahl für Pumpe 1 — ✓ 日本語";
        assert_eq!(escape(text).to_string(), text);
    }

    #[test]
    fn invalid_utf8_bytes_are_written_in_hex() {
        assert_eq!(escape_bytes(b"ok\xC3\x28\xFF\0end").to_string(), r"ok\xc3(\xff\0end");
        assert_eq!(escape_bytes("für".as_bytes()).to_string(), "für");
    }
}
