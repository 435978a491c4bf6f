//! The number forms that fault specifications, profiles and the command line share: shares
//! (`5%`, `0.05`) and durations (`50ms`, `1.5s`).

use std::time::Duration;

/// A share from 0 to 1, written `0.05` or `5%`.
pub fn parse_share(text: &str) -> Result<f64, String> {
    let text = text.trim();
    let value = match text.strip_suffix('%') {
        Some(pct) => pct.trim().parse::<f64>().map(|v| v / 100.0),
        None => text.parse::<f64>(),
    }
    .map_err(|_| format!("'{text}' is not a share (e.g. 0.05 or 5%)"))?;
    if (0.0..=1.0).contains(&value) { Ok(value) } else { Err(format!("'{text}' is not between 0 and 1 (0% and 100%)")) }
}

/// A duration written `50ms`, `1.5s`, `250us`, `2min`, or a plain number of milliseconds; at
/// most an hour.
pub fn parse_duration(text: &str) -> Result<Duration, String> {
    let text = text.trim();
    let split = text.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(text.len());
    let (number, unit) = text.split_at(split);
    let value: f64 = number.parse().map_err(|_| format!("'{text}' is not a duration (e.g. 500ms, 1.5s, 2s)"))?;
    let seconds = match unit.trim() {
        "" | "ms" => value / 1e3,
        "s" => value,
        "us" | "µs" => value / 1e6,
        "ns" => value / 1e9,
        "m" | "min" => value * 60.0,
        other => return Err(format!("unknown unit '{other}' in '{text}'; use ns, us, ms, s or min")),
    };
    if seconds > 3600.0 {
        return Err(format!("'{text}' is longer than an hour"));
    }
    Duration::try_from_secs_f64(seconds).map_err(|_| format!("'{text}' is not a duration"))
}
