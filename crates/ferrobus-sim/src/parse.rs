//! The number forms that fault specifications, profiles and the command line share: shares
//! (`5%`, `0.05`) and durations (`50ms`, `1.5s`; the grammar is [`ferrobus::text`]'s).

use std::time::Duration;

use ferrobus::log::escape;
use ferrobus::text::TextError;

/// Why a share is refused. Each carries the text as typed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ShareError {
    /// Neither a number nor a percentage.
    #[error("'{}' is not a share (e.g. 0.05 or 5%)", escape(.text))]
    NotAShare {
        /// What was typed.
        text: String,
    },
    /// Below 0 or above 1.
    #[error("'{}' is not between 0 and 1 (0% and 100%)", escape(.text))]
    OutOfRange {
        /// What was typed.
        text: String,
    },
}

/// A share from 0 to 1, written `0.05` or `5%`.
pub fn parse_share(text: &str) -> Result<f64, ShareError> {
    let text = text.trim();
    let value = match text.strip_suffix('%') {
        Some(pct) => pct.trim().parse::<f64>().map(|v| v / 100.0),
        None => text.parse::<f64>(),
    }
    .map_err(|_| ShareError::NotAShare { text: text.to_string() })?;
    if (0.0..=1.0).contains(&value) { Ok(value) } else { Err(ShareError::OutOfRange { text: text.to_string() }) }
}

/// A duration by the project's one grammar ([`ferrobus::text::duration`]): `50ms`, `1.5s`,
/// `250us`, `2min`, `1h`, or a plain number of milliseconds; at most a year.
pub fn parse_duration(text: &str) -> Result<Duration, TextError> {
    ferrobus::text::duration(text)
}
