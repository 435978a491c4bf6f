//! Where in a text file a mistake is, said in a bounded number of bytes.
//!
//! Every reader of a file a user writes (profiles, the gateway's roles file, saved
//! connections) reports a mistake as `file:line:col: message (in `excerpt`)`. The pieces are
//! made here, once:
//!
//! - [`Place`]: the line and column (both from 1, the column in characters) of a byte offset;
//! - [`excerpt`]: a window of the line around that column, at most [`WINDOW`] characters
//!   either side, control characters escaped, `…` where the line goes on;
//! - [`bounded`]: a message cut to [`MESSAGE_MAX`] characters, escaped likewise (a TOML
//!   reader's message quotes the value at fault, which may be the whole 100 MB line);
//! - [`text`]: the bytes of a file as text, or the line and column of the first byte that is
//!   not UTF-8 (a binary file is told apart from a text file with one bad byte);
//! - [`Located`]: the three together, displayed as above.
//!
//! Nothing here echoes more than a few hundred bytes of the file, whatever its size.

use std::fmt;
use std::ops::Range;

/// Characters of a line shown on either side of the column at fault.
pub const WINDOW: usize = 40;

/// Characters of a message shown before it is cut.
pub const MESSAGE_MAX: usize = 600;

/// A line and a column, both from 1; the column counts characters, not bytes.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Place {
    /// The line, from 1.
    pub line: usize,
    /// The column, from 1, in characters.
    pub column: usize,
}

impl Place {
    /// The place of byte `offset` of `text` (the end of the text if past it, the start of
    /// its character if inside one).
    pub fn of(text: &str, offset: usize) -> Place {
        let offset = char_boundary(text, offset);
        let before = text.get(..offset).unwrap_or(text);
        let start = line_start(text, offset);
        let line = before.bytes().filter(|&b| b == b'\n').count().saturating_add(1);
        let column = before.get(start..).map_or(0, |s| s.chars().count()).saturating_add(1);
        Place { line, column }
    }
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.column)
    }
}

/// The largest char boundary of `text` at or below `offset`.
fn char_boundary(text: &str, offset: usize) -> usize {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset = offset.saturating_sub(1);
    }
    offset
}

/// The byte where the line holding byte `offset` starts.
fn line_start(text: &str, offset: usize) -> usize {
    text.get(..offset).and_then(|s| s.rfind('\n')).map_or(0, |i| i.saturating_add(1))
}

/// The byte where the line holding byte `offset` ends (before its `\r\n` or `\n`).
fn line_end(text: &str, offset: usize) -> usize {
    let end = text.get(offset..).and_then(|s| s.find('\n')).map_or(text.len(), |i| offset.saturating_add(i));
    if text.get(..end).is_some_and(|s| s.ends_with('\r')) { end.saturating_sub(1) } else { end }
}

/// Up to [`WINDOW`] characters either side of byte `offset`, on its line, trimmed, escaped,
/// with `…` where the line was cut; empty for a blank line.
pub fn excerpt(text: &str, offset: usize) -> String {
    let offset = char_boundary(text, offset);
    let (start, end) = (line_start(text, offset), line_end(text, offset));
    let before = text.get(start..offset).unwrap_or_default();
    let after = text.get(offset..end.max(offset)).unwrap_or_default();
    let from = before.char_indices().rev().nth(WINDOW.saturating_sub(1)).map_or(0, |(i, _)| i);
    let to = after.char_indices().nth(WINDOW).map_or(after.len(), |(i, _)| i);
    let (head, tail) = (before.get(from..).unwrap_or_default(), after.get(..to).unwrap_or_default());
    let window = format!("{head}{tail}");
    let (cut_before, cut_after) = (from > 0, to < after.len());
    // A side that was cut keeps its spaces: they are part of what is shown.
    let window = match (cut_before, cut_after) {
        (false, false) => window.trim(),
        (true, false) => window.trim_end(),
        (false, true) => window.trim_start(),
        (true, true) => window.as_str(),
    };
    let mut shown = String::new();
    if cut_before {
        shown.push('…');
    }
    escape_into(&mut shown, window);
    if cut_after {
        shown.push('…');
    }
    shown
}

/// `message` with control characters escaped, cut after [`MESSAGE_MAX`] characters with `…`.
pub fn bounded(message: &str) -> String {
    let message = message.trim();
    let cut = message.char_indices().nth(MESSAGE_MAX).map(|(i, _)| i);
    let mut shown = String::new();
    escape_into(&mut shown, cut.and_then(|i| message.get(..i)).unwrap_or(message));
    if cut.is_some() {
        shown.push('…');
    }
    shown
}

/// Appends `text` with every control character (newlines, NUL, escape sequences) and every
/// bidirectional override written as an escape, so that it cannot forge or reorder a line.
fn escape_into(out: &mut String, text: &str) {
    for c in text.chars() {
        let bidi = matches!(c, '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}');
        if c.is_control() || bidi {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
}

/// A file's bytes that are not UTF-8 text: where the first bad byte is.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct NotText {
    /// The place of the first byte that is not part of a UTF-8 character.
    pub place: Place,
    /// That byte.
    pub byte: u8,
    /// Whether the bytes look binary (a NUL before the bad byte, or the bad byte at the start).
    pub binary: bool,
}

impl NotText {
    /// What is wrong, without the place.
    fn what(&self) -> String {
        let binary = if self.binary { " (this looks like a binary file, not a TOML text file)" } else { "" };
        format!("byte 0x{:02X} is not UTF-8 text{binary}", self.byte)
    }
}

impl fmt::Display for NotText {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.place, self.what())
    }
}

impl std::error::Error for NotText {}

/// `bytes` as text, or where the first byte that is not UTF-8 is.
pub fn text(bytes: &[u8]) -> Result<&str, NotText> {
    std::str::from_utf8(bytes).map_err(|e| not_text(bytes, e.valid_up_to()))
}

/// Where the UTF-8 of `bytes` stops being valid, at byte `at`.
fn not_text(bytes: &[u8], at: usize) -> NotText {
    let good = bytes.get(..at).and_then(|b| std::str::from_utf8(b).ok()).unwrap_or_default();
    NotText {
        place: Place::of(good, good.len()),
        byte: bytes.get(at).copied().unwrap_or_default(),
        binary: at == 0 || good.contains('\0'),
    }
}

/// A mistake at a place in a text: its place, an excerpt of the line there and a bounded
/// message; displayed `line:col: message (in `excerpt`)`, to follow a file's name.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Located {
    /// Where, if the reader said.
    pub place: Option<Place>,
    /// The line around the place (see [`excerpt`]); empty if none.
    pub excerpt: String,
    /// What is wrong (see [`bounded`]).
    pub message: String,
}

impl Located {
    /// The mistake `message` at byte `span.start` of `text` (or nowhere in particular).
    pub fn new(text: &str, span: Option<Range<usize>>, message: &str) -> Located {
        let place = span.as_ref().map(|s| Place::of(text, s.start));
        let excerpt = span.map(|s| excerpt(text, s.start)).unwrap_or_default();
        Located { place, excerpt, message: bounded(message) }
    }

    /// The mistake a TOML reader found in `text`.
    pub fn toml(text: &str, error: &toml::de::Error) -> Located {
        Located::new(text, error.span(), error.message())
    }

    /// The mistake `message` at `place`, with no excerpt (the text is gone).
    pub fn at(place: Option<Place>, message: &str) -> Located {
        Located { place, excerpt: String::new(), message: bounded(message) }
    }

    /// `file:line:col: message (in `excerpt`)`, or `file: message` without a place.
    pub fn in_file(&self, file: &str) -> String {
        let separator = if self.place.is_some() { ":" } else { ": " };
        format!("{file}{separator}{self}")
    }
}

/// Why a text file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file system's error.
    #[error("cannot read it: {0}")]
    Io(#[from] std::io::Error),
    /// Bytes that are not UTF-8, at a place.
    #[error("{0}")]
    NotText(#[from] NotText),
}

impl ReadError {
    /// The error as a mistake at a place (the first bad byte), or at none.
    pub fn located(&self) -> Located {
        match self {
            ReadError::Io(_) => Located::at(None, &self.to_string()),
            ReadError::NotText(not_text) => Located::at(Some(not_text.place), &not_text.what()),
        }
    }
}

/// Reads a text file, checking that it is UTF-8 (see [`text`]).
pub fn read(path: &std::path::Path) -> Result<String, ReadError> {
    String::from_utf8(std::fs::read(path)?)
        .map_err(|e| ReadError::NotText(not_text(e.as_bytes(), e.utf8_error().valid_up_to())))
}

impl fmt::Display for Located {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(place) = self.place {
            write!(f, "{place}: ")?;
        }
        f.write_str(&self.message)?;
        if !self.excerpt.is_empty() {
            write!(f, " (in `{}`)", self.excerpt)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn places_count_lines_from_1_and_columns_in_characters() {
        let text = "a = 1\nbé = 2\n";
        assert_eq!(Place::of(text, 0), Place { line: 1, column: 1 });
        assert_eq!(Place::of(text, 6), Place { line: 2, column: 1 });
        assert_eq!(Place::of(text, text.rfind('=').unwrap()), Place { line: 2, column: 4 });
        assert_eq!(Place::of(text, 999), Place { line: 3, column: 1 });
        // Inside the é: its start.
        assert_eq!(Place::of(text, 8), Place { line: 2, column: 2 });
    }

    #[test]
    fn an_excerpt_of_a_10_mb_line_is_a_window_around_the_column_with_marks() {
        let line = format!("{}X{}", "a".repeat(5_000_000), "b".repeat(5_000_000));
        let at = line.find('X').unwrap();
        let shown = excerpt(&line, at);
        assert_eq!(shown, format!("…{}X{}…", "a".repeat(WINDOW), "b".repeat(WINDOW - 1)));
    }

    #[test]
    fn a_short_line_is_shown_whole_and_trimmed_without_marks() {
        let text = "first\n  count = 'x'  \r\nlast";
        assert_eq!(excerpt(text, text.find("'x'").unwrap()), "count = 'x'");
        assert_eq!(excerpt(text, 0), "first");
        assert_eq!(excerpt("\n\n", 1), "");
    }

    #[test]
    fn control_characters_and_bidi_overrides_are_escaped() {
        assert_eq!(excerpt("a\0b\u{1b}[2Jc\u{202E}d", 0), "a\\u{0}b\\u{1b}[2Jc\\u{202e}d");
        assert_eq!(bounded("bad\nforged: line"), "bad\\nforged: line");
    }

    #[test]
    fn a_long_message_is_cut_with_a_mark() {
        let message = format!("invalid type: string \"{}\"", "z".repeat(1_000_000));
        let shown = bounded(&message);
        assert_eq!(shown.chars().count(), MESSAGE_MAX + 1);
        assert!(shown.ends_with('…') && shown.starts_with("invalid type"), "{shown}");
    }

    #[test]
    fn bytes_that_are_not_utf8_are_placed_by_line_and_column() {
        let bad = NotText { place: Place { line: 2, column: 4 }, byte: 0xFF, binary: false };
        assert_eq!(text(b"ok\nab\xC3\xA9\xFFz"), Err(bad));
        assert_eq!(bad.to_string(), "2:4: byte 0xFF is not UTF-8 text");
        let binary = text(b"\x7fELF\x02\x01\x01\0\0\0\xE0").unwrap_err();
        assert!(binary.binary, "{binary}");
        assert_eq!(binary.place, Place { line: 1, column: 11 });
        assert_eq!(text(b"fine"), Ok("fine"));
    }

    #[test]
    fn a_located_mistake_reads_place_message_excerpt() {
        let text = "a = 1\nb = 'x'\n";
        let located = Located::new(text, Some(10..13), "expected an integer");
        assert_eq!(located.to_string(), "2:5: expected an integer (in `b = 'x'`)");
        assert_eq!(Located::new(text, None, "no [device]").to_string(), "no [device]");
        assert_eq!(located.in_file("f.toml"), "f.toml:2:5: expected an integer (in `b = 'x'`)");
        assert_eq!(Located::at(None, "no [device]").in_file("f.toml"), "f.toml: no [device]");
        let error = toml::from_str::<toml::Table>("a = = 1").unwrap_err();
        assert!(
            Located::toml("a = = 1", &error).to_string().starts_with("1:5: "),
            "{}",
            Located::toml("a = = 1", &error)
        );
    }
}
