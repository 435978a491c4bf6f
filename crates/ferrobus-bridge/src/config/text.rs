//! The small languages inside the file's strings: durations (`250ms`), sizes (`4MiB`) and
//! `host:port`.

use std::time::Duration;

/// A duration: a number and a unit, `ms`, `s`, `m` or `h` (`250ms`, `1.5s`, `2m`).
pub(super) fn duration(s: &str) -> Result<Duration, String> {
    let s = s.trim();
    let split = s.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(s.len());
    let (number, unit) = s.split_at(split);
    let scale = match unit.trim() {
        "ms" => 0.001,
        "s" => 1.0,
        "m" | "min" => 60.0,
        "h" => 3600.0,
        _ => {
            return Err(format!(
                "{s:?} is not a duration; write a number and ms, s, m or h (\"250ms\", \"1s\", \"2m\")"
            ));
        }
    };
    let value: f64 =
        number.parse().map_err(|_| format!("{s:?} is not a duration; the number {number:?} is not one"))?;
    Duration::try_from_secs_f64(value * scale).map_err(|_| format!("{s:?} is not a duration this bridge can wait"))
}

/// A size in bytes: a whole number and `B`, `KiB`, `MiB`, `GiB` (or `KB`, `MB`, `GB` as
/// powers of 1000).
pub(super) fn size(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let split = s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
    let (number, unit) = s.split_at(split);
    let scale: u64 = match unit.trim() {
        "" | "B" => 1,
        "KiB" => 1 << 10,
        "MiB" => 1 << 20,
        "GiB" => 1 << 30,
        "KB" | "kB" => 1_000,
        "MB" => 1_000_000,
        "GB" => 1_000_000_000,
        _ => {
            return Err(format!(
                "{s:?} is not a size; write a whole number and B, KiB, MiB or GiB (\"64KiB\", \"4MiB\")"
            ));
        }
    };
    let value: u64 = number.parse().map_err(|_| format!("{s:?} is not a size; it starts with no whole number"))?;
    value.checked_mul(scale).ok_or_else(|| format!("{s:?} is too large a size"))
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
    fn durations() {
        assert_eq!(duration("250ms"), Ok(Duration::from_millis(250)));
        assert_eq!(duration("1s"), Ok(Duration::from_secs(1)));
        assert_eq!(duration("1.5s"), Ok(Duration::from_millis(1500)));
        assert_eq!(duration("2m"), Ok(Duration::from_secs(120)));
        assert_eq!(duration("1h"), Ok(Duration::from_secs(3600)));
        assert!(duration("250").unwrap_err().contains("ms, s, m or h"));
        assert!(duration("fast").is_err());
        assert!(duration("1..5s").is_err());
    }

    #[test]
    fn sizes() {
        assert_eq!(size("64KiB"), Ok(64 * 1024));
        assert_eq!(size("4MiB"), Ok(4 << 20));
        assert_eq!(size("1GiB"), Ok(1 << 30));
        assert_eq!(size("10MB"), Ok(10_000_000));
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
