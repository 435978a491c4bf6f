//! `ferrobus line`: a virtual RS-485 bus of pty endpoints, with real wire timing.
//!
//! Prints one pty path per line on stdout, then carries bytes between them — paced at the
//! character time, colliding when two talk at once, with the faults asked for — until
//! interrupted (Ctrl-C or SIGTERM, its normal end: exit 0) or `--duration` is over. On exit it
//! prints what it saw: characters, frames, collisions, faults, and for each endpoint the frames
//! it began before the line had been silent for t3.5.
//!
//! With `--tap`, one more pty is printed last: a tap, for `ferrobus sniff`, that hears
//! everything on the line and transmits nothing. `--tap-record FILE` writes what it heard, one
//! JSON line per run of characters with the instant its last character left the wire: the
//! reference the sniffer's timestamps are measured against (`bench/sniff.sh`).

use std::time::Duration;

use clap::Args;
use ferrobus::line::{Line, LineFaults, LineOptions, WireStats};

use crate::connect::{ConnectArgs, parse_duration};
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output;

/// Arguments of `ferrobus line`.
#[derive(Args, Clone, Debug)]
pub(crate) struct LineArgs {
    /// Number of pty endpoints on the bus
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(2..=32))]
    drops: u8,

    /// Deliver every byte at once, without character timing (a software-overhead bench)
    #[arg(long)]
    unpaced: bool,

    /// Every endpoint hears its own transmission too
    #[arg(long)]
    echo: bool,

    /// Chance that a bit is flipped, e.g. 1e-4
    #[arg(long = "bit-errors", value_name = "RATE", default_value_t = 0.0, value_parser = rate)]
    bit_errors: f64,

    /// Chance that a character is replaced, e.g. 1%
    #[arg(long, value_name = "RATE", default_value_t = 0.0, value_parser = rate)]
    corrupt: f64,

    /// Chance that a character is lost, e.g. 0.5%
    #[arg(long, value_name = "RATE", default_value_t = 0.0, value_parser = rate)]
    lose: f64,

    /// Chance that a gap opens before a character inside a frame, and how long: RATE:DURATION
    #[arg(long, value_name = "RATE:DURATION", value_parser = stretch)]
    stretch: Option<(f64, Duration)>,

    /// Noise bursts per second, and their longest length in characters: RATE[:LEN]
    #[arg(long, value_name = "RATE[:LEN]", value_parser = noise)]
    noise: Option<(f64, usize)>,

    /// Make endpoint N (0-based, below --drops) dead: it neither sends nor hears
    #[arg(long, value_name = "N")]
    dead: Vec<usize>,

    /// Seed of the fault generator
    #[arg(long, default_value_t = 1)]
    seed: u64,

    /// Stop after this long; default: run until interrupted
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    duration: Option<Duration>,

    /// Also write the statistics as JSON to this file on exit (created at the start)
    #[arg(long = "stats-json", value_name = "FILE")]
    stats_json: Option<std::path::PathBuf>,

    /// Add a tap: one more pty, printed last, that hears everything and transmits nothing
    /// (for `ferrobus sniff`; what is written to it is dropped and counted)
    #[arg(long)]
    tap: bool,

    /// Write what the tap heard to FILE: one JSON line per run of characters, with when its
    /// last character left the wire (end_ns, nanoseconds since the Unix epoch), when the line's
    /// write of it to the tap's pty returned (written_ns) and its bytes
    #[arg(long = "tap-record", value_name = "FILE", requires = "tap")]
    tap_record: Option<std::path::PathBuf>,
}

use ferrobus_sim::fault::parse_share as rate;

fn stretch(text: &str) -> Result<(f64, Duration), String> {
    let (r, d) = text.split_once(':').ok_or_else(|| format!("'{text}': expected RATE:DURATION, e.g. 1%:3ms"))?;
    Ok((rate(r).map_err(|e| e.to_string())?, parse_duration(d)?))
}

fn noise(text: &str) -> Result<(f64, usize), String> {
    let (r, len) = text.split_once(':').unwrap_or((text, "8"));
    let per_second: f64 = r.trim().parse().map_err(|_| format!("'{r}' is not a number of bursts per second"))?;
    let len: usize = len.trim().parse().map_err(|_| format!("'{len}' is not a burst length"))?;
    if per_second < 0.0 || len == 0 || len > 256 {
        return Err(format!("'{text}': a rate of 0 or more bursts per second, of 1 to 256 characters"));
    }
    Ok((per_second, len))
}

/// Runs `ferrobus line`.
pub(crate) async fn run(connection: &ConnectArgs, args: &LineArgs) -> Result<(), CliError> {
    if let Some(&dead) = args.dead.iter().find(|&&n| n >= usize::from(args.drops)) {
        return Err(CliError::Usage(format!(
            "--dead {dead}: there are {} drops, numbered 0 to {}",
            args.drops,
            args.drops.saturating_sub(1)
        )));
    }
    // The statistics file is opened now, so that a path that cannot be written fails at once,
    // not after hours of running.
    let mut stats_file = match &args.stats_json {
        Some(path) => Some((
            std::fs::File::create(path)
                .map_err(|source| CliError::Output { what: path.display().to_string(), source })?,
            path.display().to_string(),
        )),
        None => None,
    };
    let mut interrupt = Interrupt::listen()?;
    let (stretch_rate, stretch_by) = args.stretch.unwrap_or((0.0, Duration::ZERO));
    let (noise_per_second, noise_len) = args.noise.unwrap_or((0.0, 0));
    let options = LineOptions {
        config: connection.line(),
        paced: !args.unpaced,
        echo: args.echo,
        faults: LineFaults {
            bit_error_rate: args.bit_errors,
            corrupt_rate: args.corrupt,
            drop_rate: args.lose,
            stretch_rate,
            stretch_by,
            noise_per_second,
            noise_len,
        },
        seed: args.seed,
    };
    let line = Line::start(options);
    for index in 0..args.drops {
        let path = line.pty().await.map_err(|e| ferrobus::Error::io("making a pty", e))?;
        output::print(&format!("{}\n", path.display()))?;
        if args.dead.contains(&usize::from(index)) {
            line.set_dead(usize::from(index), true);
        }
    }
    if args.tap {
        let tap = line.tap().await.map_err(|e| ferrobus::Error::io("making the tap's pty", e))?;
        output::print(&format!("{}\n", tap.path.display()))?;
        if let Some(file) = &args.tap_record {
            record_tap(file, tap.heard)?;
        }
    }
    let timing = line.timing();
    eprintln!(
        "line: {} drops at {}{}: character {:.1} µs, t3.5 {:.1} µs; Ctrl-C or SIGTERM prints the statistics",
        args.drops,
        connection.line(),
        if args.unpaced { ", unpaced" } else { "" },
        timing.char_time().as_secs_f64() * 1e6,
        timing.t3_5().as_secs_f64() * 1e6
    );
    match args.duration {
        Some(d) => tokio::select! {
            () = tokio::time::sleep(d) => {}
            () = interrupt.wait() => {}
        },
        None => interrupt.wait().await,
    }
    let stats = line.stats();
    print_stats(&stats);
    if let Some((file, what)) = &mut stats_file {
        output::write_to(file, what, &stats_json(&stats).to_string())?;
    }
    Ok(())
}

/// Writes what the tap hears to `path` as it comes, one JSON line per run, until the line
/// stops. The file is created now, so that a path that cannot be written fails at once.
fn record_tap(
    path: &std::path::Path,
    mut heard: tokio::sync::mpsc::UnboundedReceiver<ferrobus::line::TapRun>,
) -> Result<(), CliError> {
    let what = path.display().to_string();
    let mut file = std::fs::File::create(path).map_err(|source| CliError::Output { what: what.clone(), source })?;
    let clock = ferrobus_tools::sniff::WallClock::now();
    tokio::spawn(async move {
        while let Some(run) = heard.recv().await {
            let doc = serde_json::json!({
                "end_ns": clock.unix(run.end).as_nanos(),
                "written_ns": clock.unix(run.written).as_nanos(),
                "bytes": crate::hex::format(&run.bytes),
            });
            if let Err(e) = output::write_to(&mut file, &what, &output::json_line(&doc)) {
                tracing::warn!("tap record: {e:?}");
                return;
            }
        }
    });
    Ok(())
}

fn print_stats(s: &WireStats) {
    eprintln!(
        "line: {} characters, {} frames, {} discards, {} collisions; faults: {} bit errors, {} corrupted, {} lost, {} gaps stretched, {} noise characters",
        s.characters, s.frames, s.discards, s.collisions, s.bit_errors, s.corrupted, s.dropped, s.stretched, s.noise
    );
    for (i, e) in s.endpoints.iter().enumerate() {
        if e.tap {
            eprintln!("line: endpoint {i} {}: tap, {} characters written to it refused", e.name, e.refused);
            continue;
        }
        eprintln!(
            "line: endpoint {i} {}: {} characters sent, {} frames begun less than t3.5 after the line was busy{}",
            e.name,
            e.characters,
            e.gap_violations,
            if e.dead { " (dead)" } else { "" }
        );
    }
}

fn stats_json(s: &WireStats) -> serde_json::Value {
    serde_json::json!({
        "characters": s.characters, "frames": s.frames, "discards": s.discards, "collisions": s.collisions,
        "bit_errors": s.bit_errors, "corrupted": s.corrupted, "dropped": s.dropped, "stretched": s.stretched,
        "noise": s.noise,
        "endpoints": s.endpoints.iter().map(|e| serde_json::json!({
            "name": e.name, "characters": e.characters, "gap_violations": e.gap_violations, "dead": e.dead,
            "tap": e.tap, "refused": e.refused,
        })).collect::<Vec<_>>(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_and_fault_specs_parse_and_refuse_nonsense() {
        assert_eq!(rate("1%"), Ok(0.01));
        assert_eq!(rate("0.25"), Ok(0.25));
        assert!(rate("150%").is_err() && rate("often").is_err());
        assert_eq!(stretch("2%:3ms"), Ok((0.02, Duration::from_millis(3))));
        assert!(stretch("2%").is_err());
        assert_eq!(noise("0.5"), Ok((0.5, 8)));
        assert_eq!(noise("2:4"), Ok((2.0, 4)));
        assert!(noise("2:0").is_err());
    }
}
