//! Hex input, as people type it: `03 00 00 00 02`, `030000 0002`, `0x03,0x00`, `03:00`.
//!
//! Arguments are split at spaces, commas and colons; each piece may carry a `0x` prefix and
//! must have an even number of hex digits. Errors say where the problem is: which argument
//! and which character of it.

use std::fmt;

/// Why hex input could not be read.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(crate) enum HexError {
    /// No bytes at all.
    Empty,
    /// A character that is not a hex digit.
    BadDigit {
        /// The character.
        found: char,
        /// 1-based argument number.
        arg: usize,
        /// 1-based character position inside the argument.
        column: usize,
    },
    /// A group of digits with an odd count: a byte is two digits.
    OddDigits {
        /// The group as typed.
        group: String,
        /// 1-based argument number.
        arg: usize,
        /// 1-based character position of the group inside the argument.
        column: usize,
    },
}

impl fmt::Display for HexError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HexError::Empty => f.write_str("no hex bytes given"),
            HexError::BadDigit { found, arg, column } => {
                write!(f, "'{found}' (argument {arg}, character {column}) is not a hex digit")
            }
            HexError::OddDigits { group, arg, column } => write!(
                f,
                "'{group}' (argument {arg}, character {column}) has an odd number of hex digits; \
                 write each byte as two digits, e.g. 03"
            ),
        }
    }
}

impl std::error::Error for HexError {}

/// Parses hex bytes from command-line arguments.
pub(crate) fn parse_args<S: AsRef<str>>(args: &[S]) -> Result<Vec<u8>, HexError> {
    let mut out = Vec::new();
    for (index, arg) in args.iter().enumerate() {
        parse_arg(arg.as_ref(), index + 1, &mut out)?;
    }
    if out.is_empty() {
        return Err(HexError::Empty);
    }
    Ok(out)
}

/// Parses one argument, appending its bytes to `out`.
fn parse_arg(arg: &str, arg_no: usize, out: &mut Vec<u8>) -> Result<(), HexError> {
    let chars: Vec<char> = arg.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        if matches!(chars[i], ' ' | '\t' | ',' | ':' | '\n' | '\r') {
            i += 1;
            continue;
        }
        let start = i;
        let mut digits_from = i;
        if chars[i] == '0' && matches!(chars.get(i + 1), Some('x' | 'X')) {
            digits_from = i + 2;
        }
        let mut end = digits_from;
        while end < chars.len() && !matches!(chars[end], ' ' | '\t' | ',' | ':' | '\n' | '\r') {
            end += 1;
        }
        let group = &chars[digits_from..end];
        if let Some(pos) = group.iter().position(|c| !c.is_ascii_hexdigit()) {
            return Err(HexError::BadDigit { found: group[pos], arg: arg_no, column: digits_from + pos + 1 });
        }
        if group.len() % 2 == 1 || group.is_empty() {
            return Err(HexError::OddDigits {
                group: chars[start..end].iter().collect(),
                arg: arg_no,
                column: start + 1,
            });
        }
        for pair in group.chunks_exact(2) {
            let text: String = pair.iter().collect();
            // Both characters are hex digits, checked above.
            out.push(u8::from_str_radix(&text, 16).unwrap_or_default());
        }
        i = end;
    }
    Ok(())
}

/// `01 10 01 12`: bytes as upper-case hex separated by spaces.
pub(crate) fn format(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spaces_commas_prefixes_and_runs_all_give_the_same_bytes() {
        let want = vec![0x03, 0x00, 0x00, 0x00, 0x02];
        assert_eq!(parse_args(&["03", "00", "00", "00", "02"]).unwrap(), want);
        assert_eq!(parse_args(&["030000", "0002"]).unwrap(), want);
        assert_eq!(parse_args(&["0x03,0x00,0x00", "0x0002"]).unwrap(), want);
        assert_eq!(parse_args(&["03 00 00 00 02"]).unwrap(), want);
        assert_eq!(parse_args(&["03:00:00:00:02"]).unwrap(), want);
        assert_eq!(parse_args(&["0a0B"]).unwrap(), vec![0x0A, 0x0B]);
    }

    #[test]
    fn odd_digit_counts_and_bad_digits_name_their_position() {
        let e = parse_args(&["03", "000"]).unwrap_err();
        assert_eq!(e, HexError::OddDigits { group: "000".into(), arg: 2, column: 1 });
        let e = parse_args(&["03 0G"]).unwrap_err();
        assert_eq!(e, HexError::BadDigit { found: 'G', arg: 1, column: 5 });
        assert!(e.to_string().contains("argument 1, character 5"));
        assert_eq!(parse_args(&["0x"]).unwrap_err(), HexError::OddDigits { group: "0x".into(), arg: 1, column: 1 });
        assert_eq!(parse_args::<&str>(&[]).unwrap_err(), HexError::Empty);
        assert_eq!(parse_args(&[" , "]).unwrap_err(), HexError::Empty);
    }

    #[test]
    fn multibyte_characters_do_not_panic() {
        assert!(matches!(parse_args(&["0é"]), Err(HexError::BadDigit { found: 'é', .. })));
        assert!(parse_args(&["ü"]).is_err());
    }

    #[test]
    fn format_is_upper_case_with_spaces() {
        assert_eq!(format(&[0x01, 0xE0, 0x3f]), "01 E0 3F");
        assert_eq!(format(&[]), "");
    }
}
