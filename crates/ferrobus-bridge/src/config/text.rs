//! The small languages inside the file's strings: durations (`250ms`), sizes (`4MiB`) and
//! `host:port`.

use std::time::Duration;

/// A duration by the project's one grammar ([`ferrobus::text::duration`]): a number and
/// `ns`, `us`, `ms`, `s`, `min` (or `m`), `h` (`250ms`, `1.5s`, `2m`); a plain number is
/// milliseconds.
pub(super) fn duration(s: &str) -> Result<Duration, String> {
    ferrobus::text::duration(s).map_err(|e| e.to_string())
}

/// A size in bytes by the project's one grammar ([`ferrobus::text::size`]): `kB`, `MB`, `GB`
/// are powers of 1000, `KiB`, `MiB`, `GiB` powers of 1024, a plain number is bytes.
pub(super) fn size(s: &str) -> Result<u64, String> {
    ferrobus::text::size(s).map_err(|e| e.to_string())
}

/// `host:port`, `host` (then `default_port`), `[v6]:port` or `[v6]`.
pub(super) fn host_port(s: &str, default_port: u16) -> Result<(String, u16), String> {
    let s = s.trim();
    let bad =
        |why: &str| format!("{s:?} is not an address: {why}; write host:port (\"broker.local:1883\", \"[::1]:1883\")");
    if s.contains("://") {
        return Err(bad("give no scheme"));
    }
    let (host, port) = if let Some(rest) = s.strip_prefix('[') {
        let (host, after) = rest.split_once(']').ok_or_else(|| bad("the [ of an IPv6 address is not closed"))?;
        match after {
            "" => (host, None),
            _ => (host, Some(after.strip_prefix(':').ok_or_else(|| bad("a : must follow the ]"))?)),
        }
    } else {
        match s.rsplit_once(':') {
            Some((host, _)) if host.contains(':') => return Err(bad("an IPv6 address goes in brackets")),
            Some((host, port)) => (host, Some(port)),
            None => (s, None),
        }
    };
    if host.is_empty() || host.contains(char::is_whitespace) {
        return Err(bad("the host is empty or has spaces"));
    }
    let port = match port {
        None => default_port,
        Some(p) => match p.parse::<u16>() {
            Ok(0) | Err(_) => return Err(bad("the port is not 1 to 65535")),
            Ok(p) => p,
        },
    };
    Ok((host.to_string(), port))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_are_the_one_grammar() {
        for (typed, want) in ferrobus::text::DURATION_EXAMPLES {
            assert_eq!(duration(typed), Ok(want), "{typed}");
        }
        assert_eq!(duration("2m"), Ok(Duration::from_secs(120)));
        assert!(duration("fast").unwrap_err().contains("ms, s, min (or m) or h"));
        assert!(duration("1..5s").is_err());
    }

    #[test]
    fn sizes_are_the_one_grammar_si_and_iec() {
        // The inputs every user of ferrobus::text::size is tested with (poll --rotate-size too).
        for (typed, want) in [("500k", 500_000), ("10MB", 10_000_000), ("10MiB", 10 << 20), ("64KiB", 65_536)] {
            assert_eq!(size(typed), Ok(want), "{typed}");
        }
        assert_eq!(size("1GiB"), Ok(1 << 30));
        assert_eq!(size("512"), Ok(512));
        assert!(size("4 megs").unwrap_err().contains("KiB"));
        assert!(size("99999999999999999999GiB").is_err());
    }

    #[test]
    fn addresses() {
        assert_eq!(host_port("broker:1884", 1883), Ok(("broker".into(), 1884)));
        assert_eq!(host_port("broker", 8883), Ok(("broker".into(), 8883)));
        assert_eq!(host_port("[::1]:1883", 1), Ok(("::1".into(), 1883)));
        assert_eq!(host_port("[::1]", 1883), Ok(("::1".into(), 1883)));
        assert!(host_port("mqtt://broker", 1883).is_err());
        assert!(host_port("broker:0", 1883).is_err());
        assert!(host_port("::1", 1883).is_err());
        assert!(host_port(":1883", 1883).is_err());
    }
}
