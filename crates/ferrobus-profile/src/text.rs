//! The small languages people type, decided once: durations, sizes, numbers and lists of
//! numbers. The command line, the simulator's fault specifications and profiles, poll
//! sessions and the bridge's configuration all call these, so one input means one value
//! everywhere.
//!
//! - A **duration** is a decimal number and a unit: `ns`, `us` (or `µs`), `ms`, `s`, `min`
//!   (or `m`), `h`, spaces allowed between them, case ignored (`250ms`, `1.5s`, `2min`,
//!   `1h`). A plain number is milliseconds (`250`). At most a year. The value is exact
//!   (decimal arithmetic, no float): `0.1s` is 100 ms.
//! - A **size** is a whole number of bytes and an optional unit, case ignored: `B`; `k`/`kB`,
//!   `M`/`MB`, `G`/`GB` are powers of 1000 (SI); `KiB`, `MiB`, `GiB` powers of 1024
//!   (IEC). `10MB` is 10 000 000 bytes, `10MiB` 10 485 760.
//! - A **number** is decimal or `0x` hex (`247`, `0xF7`); `_` may group digits.
//! - A **list** is numbers and inclusive ranges separated by commas: `1-10,0x20,247`.
//!
//! - An **integer** is a raw value, maybe negative: decimal, `0x` hex or `0b` binary
//!   (`-5`, `0x8000`, `0b1010`); `_` may group digits.
//!
//! The grammar lives here, below the transport, so that a profile's keys and an imported
//! map's cells are read with it too; `ferrobus::text` is this module.
//!
//! Errors carry what was typed, escaped as every message of this crate escapes what it quotes
//! ([`source::bounded`](crate::source::bounded)), and say what is accepted.

use std::ops::RangeInclusive;
use std::time::Duration;

use crate::source::bounded as escape;

/// What a duration's units accept, for messages and help texts.
pub const DURATION_UNITS: &str = "ns, us, ms, s, min (or m) or h; a plain number is milliseconds";

/// What a size's units accept, for messages and help texts.
pub const SIZE_UNITS: &str =
    "B, kB, MB, GB (powers of 1000) or KiB, MiB, GiB (powers of 1024); a plain number is bytes";

/// Durations as typed, with their values: the grammar's examples, which the test of every
/// user of [`duration`] (the CLI, the simulator, poll sessions, the bridge's plant file)
/// runs, so that each shows it reads durations the one way.
pub const DURATION_EXAMPLES: [(&str, Duration); 5] = [
    ("250", Duration::from_millis(250)),
    ("1.5s", Duration::from_millis(1500)),
    ("2min", Duration::from_secs(120)),
    ("1h", Duration::from_secs(3600)),
    ("250us", Duration::from_micros(250)),
];

/// The longest duration [`duration`] takes: 365 days.
pub const MAX_DURATION: Duration = Duration::from_secs(365 * 24 * 3600);

/// Why typed text is not the value asked for. Each carries the text as typed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TextError {
    /// No number where a duration's number goes.
    #[error("'{}' is not a duration: write a number and a unit, {DURATION_UNITS} (e.g. 250ms, 1.5s, 2min)", escape(.text))]
    NotADuration {
        /// What was typed.
        text: String,
    },
    /// A duration with a unit that is none of [`DURATION_UNITS`].
    #[error("'{}' is not a duration: unknown unit '{}'; use {DURATION_UNITS}", escape(.text), escape(.unit))]
    DurationUnit {
        /// What was typed.
        text: String,
        /// The unit.
        unit: String,
    },
    /// A duration above [`MAX_DURATION`].
    #[error("'{}' is longer than a year", escape(.text))]
    DurationTooLong {
        /// What was typed.
        text: String,
    },
    /// No whole number where a size's number goes.
    #[error("'{}' is not a size: write a whole number and {SIZE_UNITS} (e.g. 500kB, 10MiB)", escape(.text))]
    NotASize {
        /// What was typed.
        text: String,
    },
    /// A size with a unit that is none of [`SIZE_UNITS`].
    #[error("'{}' is not a size: unknown unit '{}'; use {SIZE_UNITS}", escape(.text), escape(.unit))]
    SizeUnit {
        /// What was typed.
        text: String,
        /// The unit.
        unit: String,
    },
    /// A size past 2^64 − 1 bytes.
    #[error("'{}' is too large a size", escape(.text))]
    SizeTooLarge {
        /// What was typed.
        text: String,
    },
    /// Not a decimal or `0x` hex number.
    #[error("'{}' is not a number: write it in decimal or 0x hex (247, 0xF7)", escape(.text))]
    NotANumber {
        /// What was typed.
        text: String,
    },
    /// A number above the most the option takes.
    #[error("{value} is above {max}, the most it may be")]
    TooLarge {
        /// The number.
        value: u64,
        /// The most it may be.
        max: u64,
    },
    /// A range whose first number is above its last.
    #[error("'{}': {first} is above {last}; write a range low-high", escape(.text))]
    Backwards {
        /// The range as typed.
        text: String,
        /// Its first number.
        first: u64,
        /// Its last number.
        last: u64,
    },
    /// An empty list or an empty item (`1,,3`).
    #[error("'{}' has an empty item: write numbers and ranges separated by commas (1-10,0x20,247)", escape(.text))]
    EmptyItem {
        /// The list as typed.
        text: String,
    },
}

/// Splits `text` into its leading number (digits and `.`) and the unit after it, trimmed.
fn number_and_unit(text: &str) -> (&str, &str) {
    let split = text.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(text.len());
    let (number, unit) = text.split_at(split);
    (number, unit.trim())
}

/// A duration as the [module](self) describes it.
///
/// ```
/// use std::time::Duration;
/// use ferrobus_profile::text::duration;
/// assert_eq!(duration("1.5s"), Ok(Duration::from_millis(1500)));
/// assert_eq!(duration("250"), Ok(Duration::from_millis(250)));
/// assert_eq!(duration("2 min"), Ok(Duration::from_secs(120)));
/// assert!(duration("-1s").is_err());
/// ```
pub fn duration(text: &str) -> Result<Duration, TextError> {
    let typed = text.trim();
    let (number, unit) = number_and_unit(typed);
    let nanos_per: u128 = match unit.to_lowercase().as_str() {
        "ns" => 1,
        "us" | "µs" => 1_000,
        "" | "ms" => 1_000_000,
        "s" => 1_000_000_000,
        "m" | "min" => 60_000_000_000,
        "h" => 3_600_000_000_000,
        _ if number.is_empty() => return Err(TextError::NotADuration { text: typed.to_string() }),
        _ => return Err(TextError::DurationUnit { text: typed.to_string(), unit: unit.to_string() }),
    };
    let not_one = || TextError::NotADuration { text: typed.to_string() };
    let (whole, fraction) = number.split_once('.').unwrap_or((number, ""));
    if whole.is_empty() && fraction.is_empty() || fraction.contains('.') {
        return Err(not_one());
    }
    let too_long = || TextError::DurationTooLong { text: typed.to_string() };
    // Only digits here: a whole part that does not parse is past 2^128.
    let whole: u128 = if whole.is_empty() { 0 } else { whole.parse().map_err(|_| too_long())? };
    // Past 18 digits a fraction is below a nanosecond of any unit.
    let digits = fraction.get(..fraction.len().min(18)).unwrap_or(fraction);
    let part: u128 = if digits.is_empty() { 0 } else { digits.parse().map_err(|_| not_one())? };
    let scale = 10u128.pow(u32::try_from(digits.len()).unwrap_or(0));
    let nanos = whole
        .checked_mul(nanos_per)
        .and_then(|n| n.checked_add(part.checked_mul(nanos_per)? / scale))
        .ok_or_else(too_long)?;
    let secs = u64::try_from(nanos / 1_000_000_000).map_err(|_| too_long())?;
    let sub = u32::try_from(nanos % 1_000_000_000).unwrap_or(0);
    let value = Duration::new(secs, sub);
    if value > MAX_DURATION {
        return Err(too_long());
    }
    Ok(value)
}

/// A size in bytes as the [module](self) describes it.
///
/// ```
/// use ferrobus_profile::text::size;
/// assert_eq!(size("10MB"), Ok(10_000_000));
/// assert_eq!(size("10MiB"), Ok(10 << 20));
/// assert_eq!(size("500k"), Ok(500_000));
/// assert_eq!(size("4096"), Ok(4096));
/// ```
pub fn size(text: &str) -> Result<u64, TextError> {
    let typed = text.trim();
    let (number, unit) = number_and_unit(typed);
    let per: u64 = match unit.to_lowercase().as_str() {
        "" | "b" => 1,
        "k" | "kb" => 1_000,
        "m" | "mb" => 1_000_000,
        "g" | "gb" => 1_000_000_000,
        "kib" => 1 << 10,
        "mib" => 1 << 20,
        "gib" => 1 << 30,
        _ if number.is_empty() => return Err(TextError::NotASize { text: typed.to_string() }),
        _ => return Err(TextError::SizeUnit { text: typed.to_string(), unit: unit.to_string() }),
    };
    if number.is_empty() || number.contains('.') {
        return Err(TextError::NotASize { text: typed.to_string() });
    }
    let too_large = || TextError::SizeTooLarge { text: typed.to_string() };
    let value: u64 = number.parse().map_err(|_| too_large())?;
    value.checked_mul(per).ok_or_else(too_large)
}

/// A number, decimal or `0x` hex, at most `max`.
///
/// ```
/// use ferrobus_profile::text::number;
/// assert_eq!(number("0xF7", 255), Ok(247));
/// assert_eq!(number("1_000", u64::MAX), Ok(1000));
/// assert!(number("256", 255).is_err());
/// ```
pub fn number(text: &str, max: u64) -> Result<u64, TextError> {
    let typed = text.trim();
    let not_one = || TextError::NotANumber { text: typed.to_string() };
    let digits: String = typed.chars().filter(|&c| c != '_').collect();
    let (radix, body) = match digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
        Some(hex) => (16, hex),
        None => (10, digits.as_str()),
    };
    if body.is_empty() || body.starts_with(['+', '-']) || typed.starts_with('_') {
        return Err(not_one());
    }
    let value = u64::from_str_radix(body, radix).map_err(|e| match e.kind() {
        std::num::IntErrorKind::PosOverflow => TextError::TooLarge { value: u64::MAX, max },
        _ => not_one(),
    })?;
    if value > max {
        return Err(TextError::TooLarge { value, max });
    }
    Ok(value)
}

/// A list of numbers and inclusive ranges, each at most `max`: `1-10,0x20,247`. The items
/// come back in the order written, ranges as `first..=last`, a lone number as `n..=n`.
///
/// ```
/// use ferrobus_profile::text::list;
/// assert_eq!(list("1-3,0x20,247", 247), Ok(vec![1..=3, 32..=32, 247..=247]));
/// assert!(list("5-2", 247).is_err());
/// ```
pub fn list(text: &str, max: u64) -> Result<Vec<RangeInclusive<u64>>, TextError> {
    let typed = text.trim();
    let mut out = Vec::new();
    for item in typed.split(',') {
        let item = item.trim();
        if item.is_empty() {
            return Err(TextError::EmptyItem { text: typed.to_string() });
        }
        let (first, last) = if let Some((a, b)) = item.split_once('-') {
            (number(a, max)?, number(b, max)?)
        } else {
            let n = number(item, max)?;
            (n, n)
        };
        if first > last {
            return Err(TextError::Backwards { text: item.to_string(), first, last });
        }
        out.push(first..=last);
    }
    Ok(out)
}

/// How an [`integer`] was written: in hex or binary it names raw bits, in decimal a value.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Radix {
    /// Decimal.
    Decimal,
    /// `0x` hex.
    Hex,
    /// `0b` binary.
    Binary,
}

/// An integer, maybe negative: decimal, `0x` hex or `0b` binary, `_` grouping digits, a
/// leading `+` allowed; at most 40 digits. `None` for anything else.
///
/// ```
/// use ferrobus_profile::text::{Radix, integer};
/// assert_eq!(integer("-5"), Some((-5, Radix::Decimal)));
/// assert_eq!(integer("0x8000"), Some((0x8000, Radix::Hex)));
/// assert_eq!(integer("0b1010_1010"), Some((0xAA, Radix::Binary)));
/// assert_eq!(integer("0x"), None);
/// ```
pub fn integer(text: &str) -> Option<(i128, Radix)> {
    let cleaned: String = text.trim().chars().filter(|&c| c != '_').collect();
    let (negative, body) = match cleaned.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, cleaned.strip_prefix('+').unwrap_or(&cleaned)),
    };
    let (radix, digits) = if let Some(h) = body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        (Radix::Hex, h)
    } else if let Some(b) = body.strip_prefix("0b").or_else(|| body.strip_prefix("0B")) {
        (Radix::Binary, b)
    } else {
        (Radix::Decimal, body)
    };
    if digits.is_empty() || digits.len() > 40 || digits.starts_with(['+', '-']) {
        return None;
    }
    let base = match radix {
        Radix::Decimal => 10,
        Radix::Hex => 16,
        Radix::Binary => 2,
    };
    let value = i128::from_str_radix(digits, base).ok()?;
    Some((if negative { -value } else { value }, radix))
}

/// One item of a list in a TOML file (the gateway's lines file, the TLS roles policy): a
/// number, `5`, or a text for the grammar, `"1-10"` or `"0x20"`.
#[derive(serde::Deserialize)]
#[serde(untagged)]
pub enum Item {
    /// A TOML integer.
    Number(i64),
    /// A TOML string.
    Text(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_take_every_unit_exactly_and_a_plain_number_is_milliseconds() {
        let ms = Duration::from_millis;
        for (typed, want) in [
            ("250ms", ms(250)),
            ("250", ms(250)),
            ("1.5s", ms(1500)),
            ("0.1s", ms(100)),
            ("2s", Duration::from_secs(2)),
            ("750us", Duration::from_micros(750)),
            ("750µs", Duration::from_micros(750)),
            ("40ns", Duration::from_nanos(40)),
            ("2m", Duration::from_secs(120)),
            ("2 min", Duration::from_secs(120)),
            ("1h", Duration::from_secs(3600)),
            ("5H", Duration::from_secs(5 * 3600)),
            (" 0 ", Duration::ZERO),
            ("8760h", MAX_DURATION),
            (".5s", ms(500)),
        ]
        .into_iter()
        .chain(DURATION_EXAMPLES)
        {
            assert_eq!(duration(typed), Ok(want), "{typed:?}");
        }
    }

    #[test]
    fn durations_refuse_signs_junk_unknown_units_and_more_than_a_year() {
        for typed in ["-1s", "fast", "", ".", "1.2.3s", "1..5s", "s"] {
            assert_eq!(duration(typed), Err(TextError::NotADuration { text: typed.trim().into() }), "{typed:?}");
        }
        assert_eq!(duration("5d"), Err(TextError::DurationUnit { text: "5d".into(), unit: "d".into() }));
        for typed in ["8761h", "99999999999999999999s", "999999999999999999999999999999999999999h"] {
            assert_eq!(duration(typed), Err(TextError::DurationTooLong { text: typed.into() }), "{typed:?}");
        }
        assert_eq!(
            duration("fast").unwrap_err().to_string(),
            "'fast' is not a duration: write a number and a unit, ns, us, ms, s, min (or m) or h; a plain number is \
             milliseconds (e.g. 250ms, 1.5s, 2min)"
        );
        assert_eq!(duration("1\nINFO").unwrap_err().to_string().lines().count(), 1, "escaped");
    }

    #[test]
    fn sizes_are_si_for_k_m_g_and_binary_for_kib_mib_gib() {
        for (typed, want) in [
            ("4096", 4096),
            ("512B", 512),
            ("500k", 500_000),
            ("500kB", 500_000),
            ("500KB", 500_000),
            ("10M", 10_000_000),
            ("10MB", 10_000_000),
            ("1GB", 1_000_000_000),
            ("64KiB", 64 << 10),
            ("4MiB", 4 << 20),
            ("4 mib", 4 << 20),
            ("1GiB", 1 << 30),
        ] {
            assert_eq!(size(typed), Ok(want), "{typed:?}");
        }
        assert_eq!(size("4 megs"), Err(TextError::SizeUnit { text: "4 megs".into(), unit: "megs".into() }));
        assert_eq!(size("1TB"), Err(TextError::SizeUnit { text: "1TB".into(), unit: "TB".into() }));
        assert_eq!(size("1.5MB"), Err(TextError::NotASize { text: "1.5MB".into() }));
        assert_eq!(size("big"), Err(TextError::NotASize { text: "big".into() }));
        assert_eq!(size("99999999999GiB"), Err(TextError::SizeTooLarge { text: "99999999999GiB".into() }));
        assert_eq!(
            size("99999999999999999999999"),
            Err(TextError::SizeTooLarge { text: "99999999999999999999999".into() })
        );
    }

    #[test]
    fn numbers_are_decimal_or_hex_and_lists_take_ranges() {
        assert_eq!(number("247", 247), Ok(247));
        assert_eq!(number("0x20", 247), Ok(32));
        assert_eq!(number("0XfF", 255), Ok(255));
        assert_eq!(number("248", 247), Err(TextError::TooLarge { value: 248, max: 247 }));
        assert_eq!(number("99999999999999999999999", 247), Err(TextError::TooLarge { value: u64::MAX, max: 247 }));
        for bad in ["", "0x", "-1", "+1", "ten", "1.5", "0b11"] {
            assert_eq!(number(bad, 247), Err(TextError::NotANumber { text: bad.into() }), "{bad:?}");
        }
        assert_eq!(list("1-10,0x20,247", 247), Ok(vec![1..=10, 0x20..=0x20, 247..=247]));
        assert_eq!(list(" 0x10 - 0x12 ", 247), Ok(vec![16..=18]));
        assert_eq!(list("10-1", 247), Err(TextError::Backwards { text: "10-1".into(), first: 10, last: 1 }));
        assert_eq!(list("1,,3", 247), Err(TextError::EmptyItem { text: "1,,3".into() }));
        assert_eq!(list("", 247), Err(TextError::EmptyItem { text: String::new() }));
        assert!(list("1-300", 247).is_err());
    }
}
