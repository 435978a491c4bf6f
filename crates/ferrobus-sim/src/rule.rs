//! Fault rules aimed at requests: for a function code and an address range, and a share of
//! the requests that match, one misbehaviour — as the slave simulators integrators test
//! masters, gateways and SCADA drivers against offer them.
//!
//! Written `fc=0x03,addr=0x1000-0x100F,share=50%,exception=0x06`: the matchers `fc` (one
//! function code, `0x03` or `3`), `addr` (addresses as the frame carries them, from 0: `100`,
//! `0x1000-0x100F`; a request matches if it touches one) and `share` (of the matching
//! requests, default 100%), then exactly one action:
//!
//! | action            | what the master sees                                             |
//! |-------------------|------------------------------------------------------------------|
//! | `exception=0x06`  | this exception code (any, vendor codes too), the request not run  |
//! | `no-reply`        | nothing: the request is not run                                  |
//! | `delay=200ms`     | the reply this much later than due                               |
//! | `short` `short=3` | the reply's first half (or first 3 bytes), no valid checksum      |
//! | `malformed`       | the reply's PDU without its last byte, under a valid checksum    |
//! | `unit=7`          | the reply from unit 7                                            |
//! | `tid=+1` `tid=9`  | the reply under another transaction id (Modbus/TCP only)         |
//! | `trickle=5ms`     | the reply byte by byte, 5 ms apart                               |
//!
//! `exception` and `no-reply` are decided when the request arrives; the others when its reply
//! leaves. Rules are tried in order: of each kind, the first that matches and wins its share
//! applies.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use ferrobus_proto::pdu::AddressRange;

use crate::parse::{parse_duration, parse_share};

/// The keys that make a fault specification a rule.
pub(crate) const RULE_KEYS: &[&str] =
    &["fc", "addr", "share", "no-reply", "short", "malformed", "unit", "tid", "trickle"];

/// A fault aimed at some requests.
#[derive(Clone, PartialEq, Debug)]
pub struct Rule {
    /// The function code matched; `None`: every one.
    pub function: Option<u8>,
    /// The addresses matched; `None`: every request, with addresses or without.
    pub addresses: Option<AddressRange>,
    /// The share of matching requests it applies to (0 to 1).
    pub share: f64,
    /// What it does.
    pub action: Action,
}

/// What a rule does to a request or its reply.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Action {
    /// Refuse with this exception code.
    Exception(u8),
    /// Neither run the request nor answer.
    NoReply,
    /// Send the reply this much later.
    Delay(Duration),
    /// Send only the first bytes of the framed reply: this many, or half of it when `None`.
    Short(Option<usize>),
    /// Send the PDU without its last byte, framed with a valid checksum.
    Malformed,
    /// Send the reply as from this unit.
    Unit(u8),
    /// Send the reply under another transaction id.
    Transaction(TransactionId),
    /// Send the reply one byte at a time, this far apart.
    Trickle(Duration),
}

impl Action {
    /// Whether the action is taken when the request arrives (else when its reply leaves).
    pub fn on_request(&self) -> bool {
        matches!(self, Action::Exception(_) | Action::NoReply)
    }
}

/// The transaction id a rule gives a reply.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum TransactionId {
    /// The request's, plus this much (wrapping).
    Offset(u16),
    /// This one.
    Fixed(u16),
}

impl TransactionId {
    /// The id for a reply to a request with `id`.
    pub fn apply(self, id: u16) -> u16 {
        match self {
            TransactionId::Offset(by) => id.wrapping_add(by),
            TransactionId::Fixed(to) => to,
        }
    }
}

impl Rule {
    /// Whether the rule is aimed at a request with `function` touching `addresses`.
    pub fn matches(&self, function: u8, addresses: &[Option<AddressRange>; 2]) -> bool {
        self.function.is_none_or(|f| f == function)
            && self.addresses.is_none_or(|range| addresses.iter().flatten().any(|a| a.overlaps(&range)))
    }
}

/// A number written `0x1A` or `26`, by the one grammar ([`ferrobus::text::number`]).
pub(crate) fn number<T: TryFrom<u32>>(text: &str) -> Option<T> {
    let value = ferrobus::text::number(text, u64::from(u32::MAX)).ok()?;
    T::try_from(u32::try_from(value).ok()?).ok()
}

fn parse_range(text: &str) -> Result<AddressRange, String> {
    let bad = || format!("'{text}' is not an address or a range (e.g. 100, 0x1000-0x100F)");
    let (first, last) = text.split_once('-').unwrap_or((text, text));
    let (first, last) = (number::<u16>(first).ok_or_else(bad)?, number::<u16>(last).ok_or_else(bad)?);
    AddressRange::new(first, last).ok_or_else(|| format!("'{text}' ends before it starts"))
}

impl FromStr for Rule {
    type Err = String;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let (mut function, mut addresses, mut share, mut action) = (None, None, 1.0, None);
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part.split_once('=').map_or((part, None), |(k, v)| (k.trim(), Some(v.trim())));
            let needs = || value.ok_or_else(|| format!("{key} needs a value"));
            let invalid = |what: String| format!("{key}: {what}");
            let this = match key {
                "fc" => {
                    let value = needs()?;
                    function = Some(
                        number::<u8>(value)
                            .filter(|c| (1..0x80).contains(c))
                            .ok_or_else(|| invalid(format!("'{value}' is not a function code (0x01 to 0x7F)")))?,
                    );
                    continue;
                }
                "addr" => {
                    addresses = Some(parse_range(needs()?).map_err(invalid)?);
                    continue;
                }
                "share" => {
                    share = parse_share(needs()?).map_err(|e| invalid(e.to_string()))?;
                    continue;
                }
                "exception" => {
                    let value = needs()?;
                    Action::Exception(
                        number::<u8>(value)
                            .filter(|c| *c != 0)
                            .ok_or_else(|| invalid(format!("'{value}' is not a code from 0x01 to 0xFF")))?,
                    )
                }
                "no-reply" | "silent" if value.is_none() => Action::NoReply,
                "malformed" if value.is_none() => Action::Malformed,
                "no-reply" | "silent" | "malformed" => return Err(format!("{key} takes no value")),
                "short" => Action::Short(match value {
                    None => None,
                    Some(v) => Some(
                        number::<usize>(v)
                            .filter(|n| *n > 0)
                            .ok_or_else(|| invalid(format!("'{v}' is not a number of bytes from 1")))?,
                    ),
                }),
                "delay" => Action::Delay(parse_duration(needs()?).map_err(|e| invalid(e.to_string()))?),
                "trickle" => Action::Trickle(parse_duration(needs()?).map_err(|e| invalid(e.to_string()))?),
                "unit" => {
                    let value = needs()?;
                    Action::Unit(
                        number::<u8>(value).ok_or_else(|| invalid(format!("'{value}' is not a unit (0 to 255)")))?,
                    )
                }
                "tid" => {
                    let value = needs()?;
                    let bad = || invalid(format!("'{value}' is not +N (the request's id plus N) or an id N"));
                    Action::Transaction(match value.strip_prefix('+') {
                        Some(by) => TransactionId::Offset(number(by).ok_or_else(bad)?),
                        None => TransactionId::Fixed(number(value).ok_or_else(bad)?),
                    })
                }
                "drop" | "corrupt" | "trip" => {
                    return Err(format!(
                        "{key} is a fault of the whole unit, not of a rule; give it in its own --fault"
                    ));
                }
                other => return Err(format!("unknown key {other:?}")),
            };
            if action.replace(this).is_some() {
                return Err("a rule takes one action; give another rule for another".into());
            }
        }
        let action = action
            .ok_or("a rule needs an action: exception, no-reply, delay, short, malformed, unit, tid or trickle")?;
        Ok(Rule { function, addresses, share, action })
    }
}

impl fmt::Display for Rule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.action {
            Action::Exception(code) => write!(f, "exception 0x{code:02X}")?,
            Action::NoReply => f.write_str("no reply")?,
            Action::Delay(d) => write!(f, "delay {d:?}")?,
            Action::Short(None) => f.write_str("short (half)")?,
            Action::Short(Some(n)) => write!(f, "short ({n} bytes)")?,
            Action::Malformed => f.write_str("malformed")?,
            Action::Unit(u) => write!(f, "from unit {u}")?,
            Action::Transaction(TransactionId::Offset(by)) => write!(f, "transaction id +{by}")?,
            Action::Transaction(TransactionId::Fixed(id)) => write!(f, "transaction id {id}")?,
            Action::Trickle(gap) => write!(f, "byte by byte, {gap:?} apart")?,
        }
        if self.share < 1.0 {
            write!(f, " for {:.0}% of", self.share * 100.0)?;
        } else {
            f.write_str(" for")?;
        }
        match self.function {
            Some(fc) => write!(f, " 0x{fc:02X}")?,
            None => f.write_str(" every request")?,
        }
        if let Some(range) = self.addresses {
            write!(f, " at 0x{:04X}-0x{:04X}", range.first(), range.last())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn range(first: u16, last: u16) -> AddressRange {
        AddressRange::new(first, last).unwrap()
    }

    #[test]
    fn a_rule_with_every_matcher_parses() {
        let rule: Rule = "fc=0x03,addr=0x1000-0x100F,share=50%,exception=0x06".parse().unwrap();
        assert_eq!(
            rule,
            Rule {
                function: Some(3),
                addresses: Some(range(0x1000, 0x100F)),
                share: 0.5,
                action: Action::Exception(6)
            }
        );
        assert_eq!(rule.to_string(), "exception 0x06 for 50% of 0x03 at 0x1000-0x100F");
    }

    #[test]
    fn every_action_parses() {
        let cases = [
            ("no-reply", Action::NoReply),
            ("delay=200ms", Action::Delay(Duration::from_millis(200))),
            ("short", Action::Short(None)),
            ("short=3", Action::Short(Some(3))),
            ("malformed", Action::Malformed),
            ("unit=7", Action::Unit(7)),
            ("tid=+1", Action::Transaction(TransactionId::Offset(1))),
            ("tid=0x1234", Action::Transaction(TransactionId::Fixed(0x1234))),
            ("trickle=5ms", Action::Trickle(Duration::from_millis(5))),
            ("exception=0x21", Action::Exception(0x21)),
        ];
        for (spec, action) in cases {
            let rule: Rule = spec.parse().unwrap_or_else(|e| panic!("{spec}: {e}"));
            assert_eq!(rule, Rule { function: None, addresses: None, share: 1.0, action }, "{spec}");
        }
    }

    #[test]
    fn a_rule_matches_its_function_and_any_overlapping_address() {
        let rule: Rule = "fc=3,addr=100-109,no-reply".parse().unwrap();
        assert!(rule.matches(3, &[Some(range(109, 120)), None]));
        assert!(rule.matches(3, &[Some(range(90, 100)), None]));
        assert!(!rule.matches(3, &[Some(range(110, 120)), None]));
        assert!(!rule.matches(4, &[Some(range(100, 100)), None]));
        assert!(!rule.matches(3, &[None, None]));
        let any: Rule = "fc=0x11,no-reply".parse().unwrap();
        assert!(any.matches(0x11, &[None, None]));
        let second_range: Rule = "addr=14,no-reply".parse().unwrap();
        assert!(second_range.matches(0x17, &[Some(range(3, 8)), Some(range(14, 16))]));
    }

    #[test]
    fn rule_mistakes_say_what_was_wrong() {
        let error = |spec: &str| spec.parse::<Rule>().unwrap_err();
        assert_eq!(
            error("fc=3"),
            "a rule needs an action: exception, no-reply, delay, short, malformed, unit, tid or trickle"
        );
        assert_eq!(error("fc=0x80,no-reply"), "fc: '0x80' is not a function code (0x01 to 0x7F)");
        assert_eq!(error("addr=20-10,no-reply"), "addr: '20-10' ends before it starts");
        assert_eq!(error("addr=x,no-reply"), "addr: 'x' is not an address or a range (e.g. 100, 0x1000-0x100F)");
        assert_eq!(error("no-reply,short"), "a rule takes one action; give another rule for another");
        assert_eq!(
            error("fc=3,drop=10%"),
            "drop is a fault of the whole unit, not of a rule; give it in its own --fault"
        );
        assert_eq!(error("short=0"), "short: '0' is not a number of bytes from 1");
        assert_eq!(error("tid=-1"), "tid: '-1' is not +N (the request's id plus N) or an id N");
        assert_eq!(error("no-reply=1"), "no-reply takes no value");
        assert_eq!(error("explode"), "unknown key \"explode\"");
    }
}
