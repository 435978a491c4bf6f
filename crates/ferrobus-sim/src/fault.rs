//! Fault injection, per unit: what goes wrong, and how often.
//!
//! Written on the command line as `drop=10%,delay=50ms,corrupt=0.05,exception=0x06,silent,trip=5s`
//! (any subset, in any order), or in a profile's `[faults]` table with the same keys.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

/// What goes wrong with one unit.
#[derive(Clone, PartialEq, Debug, Default)]
pub struct Faults {
    /// The share of replies lost on the way (0 to 1).
    pub drop: f64,
    /// Extra time before every reply.
    pub delay: Duration,
    /// The share of replies sent with a broken checksum (0 to 1).
    pub corrupt: f64,
    /// Answer every request with this exception code.
    pub exception: Option<u8>,
    /// Answer nothing at all.
    pub silent: bool,
    /// Trip the drive this long after the simulation starts.
    pub trip_after: Option<Duration>,
}

impl Faults {
    /// Whether any fault is set.
    pub fn any(&self) -> bool {
        *self != Faults::default()
    }
}

/// Why a fault specification could not be read.
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[error("fault {spec:?}: {problem} (expected e.g. drop=10%,delay=50ms,corrupt=0.05,exception=0x06,silent,trip=5s)")]
pub struct FaultError {
    spec: String,
    problem: String,
}

fn share(value: &str) -> Option<f64> {
    let v = match value.strip_suffix('%') {
        Some(pct) => pct.trim().parse::<f64>().ok()? / 100.0,
        None => value.parse::<f64>().ok()?,
    };
    (0.0..=1.0).contains(&v).then_some(v)
}

/// `50ms`, `1.5s`, `250us`, or a plain number of milliseconds.
pub fn parse_duration(value: &str) -> Option<Duration> {
    let value = value.trim();
    let (number, scale) = if let Some(v) = value.strip_suffix("ms") {
        (v, 1e-3)
    } else if let Some(v) = value.strip_suffix("us").or_else(|| value.strip_suffix("µs")) {
        (v, 1e-6)
    } else if let Some(v) = value.strip_suffix('s') {
        (v, 1.0)
    } else if let Some(v) = value.strip_suffix("min") {
        (v, 60.0)
    } else {
        (value, 1e-3)
    };
    let seconds = number.trim().parse::<f64>().ok()? * scale;
    (0.0..1e9).contains(&seconds).then(|| Duration::from_secs_f64(seconds))
}

fn code(value: &str) -> Option<u8> {
    match value.strip_prefix("0x").or_else(|| value.strip_prefix("0X")) {
        Some(hex) => u8::from_str_radix(hex, 16).ok(),
        None => value.parse().ok(),
    }
}

impl FromStr for Faults {
    type Err = FaultError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let err = |problem: String| FaultError { spec: spec.to_string(), problem };
        let mut faults = Faults::default();
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part.split_once('=').map_or((part, None), |(k, v)| (k.trim(), Some(v.trim())));
            if matches!(key, "silent" | "trip") {
                match (key, value) {
                    ("silent", None) => faults.silent = true,
                    ("trip", None) => faults.trip_after = Some(Duration::ZERO),
                    ("trip", Some(v)) => {
                        faults.trip_after =
                            Some(parse_duration(v).ok_or_else(|| err(format!("{part}: a duration like 5s")))?);
                    }
                    _ => return Err(err(format!("{key} takes no value"))),
                }
                continue;
            }
            if !matches!(key, "drop" | "corrupt" | "delay" | "exception") {
                return Err(err(format!("unknown fault {key:?}")));
            }
            let value = value.ok_or_else(|| err(format!("{key} needs a value")))?;
            let invalid = |what: &str| err(format!("{part}: {what}"));
            match key {
                "drop" => faults.drop = share(value).ok_or_else(|| invalid("a share from 0 to 1 or 0% to 100%"))?,
                "corrupt" => {
                    faults.corrupt = share(value).ok_or_else(|| invalid("a share from 0 to 1 or 0% to 100%"))?;
                }
                "delay" => faults.delay = parse_duration(value).ok_or_else(|| invalid("a duration like 50ms"))?,
                "exception" => {
                    faults.exception =
                        Some(code(value).filter(|c| *c != 0).ok_or_else(|| invalid("a code from 0x01 to 0xFF"))?);
                }
                _ => {}
            }
        }
        Ok(faults)
    }
}

impl fmt::Display for Faults {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut parts = Vec::new();
        if self.drop > 0.0 {
            parts.push(format!("drop {:.0}%", self.drop * 100.0));
        }
        if !self.delay.is_zero() {
            parts.push(format!("delay {:?}", self.delay));
        }
        if self.corrupt > 0.0 {
            parts.push(format!("corrupt {:.0}%", self.corrupt * 100.0));
        }
        if let Some(c) = self.exception {
            parts.push(format!("exception 0x{c:02X}"));
        }
        if self.silent {
            parts.push("silent".into());
        }
        if let Some(t) = self.trip_after {
            parts.push(format!("trip after {t:?}"));
        }
        f.write_str(&if parts.is_empty() { "none".to_string() } else { parts.join(", ") })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_specification_parses() {
        let f: Faults = "drop=10%, delay=50ms,corrupt=0.05,exception=0x06,silent,trip=5s".parse().unwrap();
        assert!((f.drop - 0.1).abs() < 1e-12);
        assert_eq!(f.delay, Duration::from_millis(50));
        assert!((f.corrupt - 0.05).abs() < 1e-12);
        assert_eq!(f.exception, Some(6));
        assert!(f.silent);
        assert_eq!(f.trip_after, Some(Duration::from_secs(5)));
        assert_eq!(f.to_string(), "drop 10%, delay 50ms, corrupt 5%, exception 0x06, silent, trip after 5s");
    }

    #[test]
    fn mistakes_say_what_was_expected() {
        let e = "drop=150%".parse::<Faults>().unwrap_err();
        assert!(e.to_string().starts_with("fault \"drop=150%\": drop=150%: a share from 0 to 1"), "{e}");
        assert!("explode".parse::<Faults>().unwrap_err().to_string().contains("unknown fault \"explode\""));
        assert!("delay".parse::<Faults>().unwrap_err().to_string().contains("delay needs a value"));
        assert!("exception=0".parse::<Faults>().is_err());
        assert_eq!("".parse::<Faults>().unwrap(), Faults::default());
    }

    #[test]
    fn durations_take_the_usual_units() {
        assert_eq!(parse_duration("1.5s"), Some(Duration::from_millis(1500)));
        assert_eq!(parse_duration("250us"), Some(Duration::from_micros(250)));
        assert_eq!(parse_duration("20"), Some(Duration::from_millis(20)));
        assert_eq!(parse_duration("-1s"), None);
        assert_eq!(parse_duration("soon"), None);
    }
}
