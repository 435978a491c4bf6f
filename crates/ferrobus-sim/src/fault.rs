//! Fault injection, per unit: what goes wrong, and how often.
//!
//! Written on the command line as `drop=10%,delay=50ms,corrupt=0.05,exception=0x06,silent,trip=5s`
//! (any subset, in any order), or in a profile's `faults` string with the same keys. A
//! specification with a matcher (`fc`, `addr`, `share`) or a reply action (`no-reply`, `short`,
//! `malformed`, `unit`, `tid`, `trickle`) is a [`Rule`] aimed at some requests instead.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

pub use crate::parse::{parse_duration, parse_share};

use crate::rule::{RULE_KEYS, Rule};

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
    /// Faults aimed at some requests, tried in order.
    pub rules: Vec<Rule>,
}

impl Faults {
    /// Whether any fault is set.
    pub fn any(&self) -> bool {
        *self != Faults::default()
    }

    /// Adds `other` to these: its rules after these', and its unit-wide faults where it sets
    /// them.
    pub fn merge(&mut self, other: Faults) {
        let Faults { drop, delay, corrupt, exception, silent, trip_after, rules } = other;
        if drop > 0.0 {
            self.drop = drop;
        }
        if !delay.is_zero() {
            self.delay = delay;
        }
        if corrupt > 0.0 {
            self.corrupt = corrupt;
        }
        self.exception = exception.or(self.exception);
        self.silent |= silent;
        self.trip_after = trip_after.or(self.trip_after);
        self.rules.extend(rules);
    }
}

/// Why a fault specification could not be read.
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[error("fault {spec:?}: {problem} (expected e.g. {example})")]
pub struct FaultError {
    spec: String,
    problem: String,
    example: &'static str,
}

const UNIT_EXAMPLE: &str = "drop=10%,delay=50ms,corrupt=0.05,exception=0x06,silent,trip=5s";
const RULE_EXAMPLE: &str = "fc=0x03,addr=0x1000-0x100F,share=50%,exception=0x06";

/// A code byte, decimal or 0x hex, by the one grammar ([`ferrobus::text::number`]).
fn code(value: &str) -> Option<u8> {
    ferrobus::text::number(value, u64::from(u8::MAX)).ok().and_then(|n| u8::try_from(n).ok())
}

impl FromStr for Faults {
    type Err = FaultError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let err = |problem: String| FaultError { spec: spec.to_string(), problem, example: UNIT_EXAMPLE };
        let keys = spec.split(',').map(|p| p.split_once('=').map_or(p, |(k, _)| k).trim());
        if keys.clone().any(|k| RULE_KEYS.contains(&k)) {
            let rule = spec.parse::<Rule>().map_err(|problem| FaultError { example: RULE_EXAMPLE, ..err(problem) })?;
            return Ok(Faults { rules: vec![rule], ..Faults::default() });
        }
        let mut faults = Faults::default();
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part.split_once('=').map_or((part, None), |(k, v)| (k.trim(), Some(v.trim())));
            if matches!(key, "silent" | "trip") {
                match (key, value) {
                    ("silent", None) => faults.silent = true,
                    ("trip", None) => faults.trip_after = Some(Duration::ZERO),
                    ("trip", Some(v)) => {
                        faults.trip_after = Some(parse_duration(v).map_err(|e| err(e.to_string()))?);
                    }
                    _ => return Err(err(format!("{key} takes no value"))),
                }
                continue;
            }
            if !matches!(key, "drop" | "corrupt" | "delay" | "exception") {
                return Err(err(format!("unknown fault {key:?}")));
            }
            let value = value.ok_or_else(|| err(format!("{key} needs a value")))?;
            let invalid = |what: &str| err(format!("{key}: {what}"));
            match key {
                "drop" => faults.drop = parse_share(value).map_err(|e| invalid(&e.to_string()))?,
                "corrupt" => faults.corrupt = parse_share(value).map_err(|e| invalid(&e.to_string()))?,
                "delay" => faults.delay = parse_duration(value).map_err(|e| invalid(&e.to_string()))?,
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
        parts.extend(self.rules.iter().map(Rule::to_string));
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
        assert!(e.to_string().starts_with("fault \"drop=150%\": drop: '150%' is not between 0 and 1"), "{e}");
        assert!("explode".parse::<Faults>().unwrap_err().to_string().contains("unknown fault \"explode\""));
        assert!("delay".parse::<Faults>().unwrap_err().to_string().contains("delay needs a value"));
        assert!("exception=0".parse::<Faults>().is_err());
        assert_eq!("".parse::<Faults>().unwrap(), Faults::default());
    }

    #[test]
    fn a_specification_with_a_matcher_or_a_reply_action_is_a_rule() {
        let f: Faults = "fc=3,addr=0x10-0x1F,share=50%,exception=6".parse().unwrap();
        assert_eq!(f.rules.len(), 1);
        assert_eq!(Faults { rules: Vec::new(), ..f.clone() }, Faults::default());
        assert_eq!(f.to_string(), "exception 0x06 for 50% of 0x03 at 0x0010-0x001F");
        assert_eq!("trickle=2ms".parse::<Faults>().unwrap().rules.len(), 1);
        // Without a matcher, exception and delay stay the unit's own faults.
        assert_eq!("exception=6".parse::<Faults>().unwrap().exception, Some(6));
        let e = "fc=3".parse::<Faults>().unwrap_err().to_string();
        assert!(e.ends_with("(expected e.g. fc=0x03,addr=0x1000-0x100F,share=50%,exception=0x06)"), "{e}");
    }

    #[test]
    fn merged_faults_keep_every_rule_in_order() {
        let mut f: Faults = "drop=10%".parse().unwrap();
        f.merge("fc=3,no-reply".parse().unwrap());
        f.merge("fc=4,short".parse().unwrap());
        f.merge("delay=5ms".parse().unwrap());
        assert!((f.drop - 0.1).abs() < 1e-12);
        assert_eq!(f.delay, Duration::from_millis(5));
        let functions: Vec<_> = f.rules.iter().map(|r| r.function).collect();
        assert_eq!(functions, [Some(3), Some(4)]);
    }

    #[test]
    fn durations_take_the_one_grammar() {
        for (typed, want) in ferrobus::text::DURATION_EXAMPLES {
            assert_eq!(parse_duration(typed), Ok(want), "{typed}");
            assert_eq!(format!("delay={typed}").parse::<Faults>().unwrap().delay, want, "delay={typed}");
        }
        assert!(parse_duration("-1s").is_err());
        assert!(parse_duration("soon").unwrap_err().to_string().contains("'soon' is not a duration"));
        assert!(parse_duration("8761h").is_err());
        assert_eq!(parse_share("5%"), Ok(0.05));
        assert!(parse_share("150%").is_err());
    }
}
