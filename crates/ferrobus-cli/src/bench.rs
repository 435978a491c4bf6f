//! `ferrobus bench`: FC03 reads back to back through [`ferrobus::Client`], timed.
//!
//! The measurement is the one the peer fixtures' `bench` mode makes (tests/peers/README.md), so
//! that bench/peers.sh can put ferrobus beside libmodbus, pymodbus and tokio-modbus: N reads of
//! Q holding registers from address A, one after the other; each timed with the monotonic clock
//! from the call to its result; p50 and p99 as nearest-rank percentiles over all N, failures
//! included; `errors` counts the reads that failed or returned the wrong number of registers;
//! user and system CPU time of the whole process (every thread, start-up included) at the end.

use std::time::{Duration, Instant};

use clap::Args;

use crate::connect::ConnectArgs;
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output;

/// Long help of `ferrobus bench`.
const BENCH_HELP: &str = "\
Performs --count FC03 reads of --quantity holding registers from --address, back to back, on
the connection given by the global options (--port/--tcp/--rtu-tcp, --unit, --timeout, --t35,
--baud, --parity ...), and reports the rate, the latency and the CPU time used.

With --json it prints one line, the same object as the peer fixtures' bench mode:
  {\"transactions\":N,\"errors\":E,\"seconds\":S,\"tps\":T,\"p50_us\":P50,\"p99_us\":P99,\"user_s\":U,\"sys_s\":Y}
- seconds: wall time of the N reads (opening the port is not counted); tps = N / seconds
- p50_us, p99_us: nearest-rank percentiles of the per-read latency, failed reads included
- errors: reads that failed (timeout, exception, bad reply, IO) or returned the wrong count
- user_s, sys_s: CPU time of the whole process, all threads, start-up included: the run time
  of its threads (/proc/self/task/*/schedstat, in ns) split into user and system in the ratio
  of /proc/self/stat's clock ticks, as getrusage() reports it

Every read is made whatever the previous ones answered, until more than half of --count have
failed: the run is then no measurement, bench stops, reports the reads made, and exits with
the code of the first failure (3 for a timeout, 4 for the port, see ferrobus --help). It
stops too when no read has got through for --give-up (10 s unless given; at least 3 reads
failed in a row): the server or the device is gone. It then reports the reads made and exits
with the code of the last failure (4 for a connection refused or reset). Otherwise the exit
code is 0. No retries unless --retries is given. A lost port is reopened with a growing wait
between attempts.
Ctrl-C or SIGTERM stops the run: the summary (or JSON) of the reads completed is printed,
and the exit code is 130.

Examples:
  ferrobus --port /dev/pts/3 --baud 115200 --parity none bench --count 1000
  ferrobus --port /dev/pts/3 --t35 0ms bench --count 20000 --json     (a pty without a wire)
  ferrobus --tcp 127.0.0.1:1502 bench --count 10000 --quantity 125";

/// `bench [--count N] [--address A] [--quantity Q] [--json]`.
#[derive(Args, Debug)]
#[command(after_help = BENCH_HELP)]
pub(crate) struct BenchArgs {
    /// Number of FC03 reads
    #[arg(long, short = 'c', default_value_t = 1000, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) count: u32,

    /// First holding register, wire address (0-based; decimal or 0x hex)
    #[arg(long, short = 'a', default_value = "0", value_parser = parse_address)]
    pub(crate) address: u16,

    /// Registers per read (1-125)
    #[arg(long, short = 'q', default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=125))]
    pub(crate) quantity: u16,

    /// Print one line of JSON (the peer fixtures' bench format) instead of a summary
    #[arg(long)]
    pub(crate) json: bool,

    /// Stop when no read has got through for this long (at least 3 failed in a row): the
    /// server is gone
    #[arg(long, value_name = "DURATION", default_value = "10s", value_parser = crate::connect::parse_duration)]
    pub(crate) give_up: Duration,
}

/// Failed reads in a row fewer than this never stop a run, however long they took.
const GIVE_UP_READS: u32 = 3;

/// The reads that failed in a row since the last that got through, and when the first of them
/// was sent: when they have gone on for long enough, the server is gone.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
struct Streak {
    failures: u32,
    since: Option<Instant>,
}

impl Streak {
    /// A read sent at `sent` failed.
    fn failed(&mut self, sent: Instant) {
        self.failures = self.failures.saturating_add(1);
        self.since.get_or_insert(sent);
    }

    /// A read got through.
    fn succeeded(&mut self) {
        *self = Streak::default();
    }

    /// How long no read has got through at `now`, once at least [`GIVE_UP_READS`] failed in a
    /// row and for `bound` or longer; none while the run should go on.
    fn gone_for(&self, now: Instant, bound: Duration) -> Option<Duration> {
        let failing = now.saturating_duration_since(self.since?);
        (self.failures >= GIVE_UP_READS && failing >= bound).then_some(failing)
    }
}

/// What a run measured.
#[derive(Clone, PartialEq, Debug)]
struct Outcome {
    transactions: u32,
    errors: u32,
    elapsed: Duration,
    /// Latency of each read, sorted.
    latencies: Vec<Duration>,
    cpu: CpuTimes,
}

/// User and system CPU time of the process.
#[derive(Clone, Copy, PartialEq, Debug, Default)]
struct CpuTimes {
    user: Duration,
    system: Duration,
}

/// Runs `ferrobus bench`.
pub(crate) async fn run(connection: &ConnectArgs, args: &BenchArgs) -> Result<(), CliError> {
    connection.refuse_broadcast_read()?;
    if u32::from(args.address) + u32::from(args.quantity) > 0x1_0000 {
        return Err(CliError::Usage(format!(
            "--address {} + --quantity {} runs past register 65535",
            args.address, args.quantity
        )));
    }
    let mut interrupt = Interrupt::listen()?;
    let session = interrupt.unless(connection.open()).await.ok_or(CliError::Interrupted)??;
    let (client, unit) = (&session.client, session.unit);
    let expected = usize::from(args.quantity);
    let mut latencies = Vec::with_capacity(usize::try_from(args.count).unwrap_or(0));
    let mut errors = 0u32;
    let mut first_error = None;
    let (mut streak, mut last_error, mut gone) = (Streak::default(), None, None);
    tracing::info!(unit, count = args.count, address = args.address, quantity = args.quantity, "bench");
    let start = Instant::now();
    let mut interrupted = false;
    // More failures than this and the run has failed, however the rest goes.
    let most = args.count / 2;
    for _ in 0..args.count {
        let sent = Instant::now();
        let Some(result) = interrupt.unless(client.read_holding_registers(unit, args.address, args.quantity)).await
        else {
            interrupted = true;
            break;
        };
        latencies.push(sent.elapsed());
        let failure = match result {
            Ok(values) if values.len() == expected => None,
            Ok(values) => {
                tracing::debug!(got = values.len(), expected, "wrong number of registers");
                Some(CliError::BadData(format!("{} registers instead of {expected}", values.len())))
            }
            Err(error) => {
                tracing::debug!("read failed: {error}");
                Some(CliError::from(error))
            }
        };
        let Some(failure) = failure else {
            streak.succeeded();
            continue;
        };
        errors += 1;
        streak.failed(sent);
        if first_error.is_none() {
            first_error = Some(failure);
        } else {
            last_error = Some(failure);
        }
        gone = streak.gone_for(Instant::now(), args.give_up);
        if errors > most || gone.is_some() {
            break;
        }
    }
    let elapsed = start.elapsed();
    let done = u32::try_from(latencies.len()).unwrap_or(u32::MAX);
    latencies.sort_unstable();
    // Interrupted, the figures are those of the reads completed.
    let outcome = Outcome { transactions: done, errors, elapsed, latencies, cpu: cpu_times() };
    if args.json {
        output::print(&output::json_line(&outcome.json()))?;
    } else {
        output::print(&format!("{}\n", outcome.summary(&session.target.to_string(), unit, args)))?;
    }
    if interrupted {
        eprintln!("bench: interrupted after {done} of {} reads; the figures are those of the {done}", args.count);
        return Err(CliError::Interrupted);
    }
    if let Some(failing) = gone {
        eprintln!(
            "bench: stopped after {done} of {} reads: none has got through for {:.1} s ({} failed in a row); \
             the server or the device is gone",
            args.count,
            failing.as_secs_f64(),
            streak.failures
        );
        return Err(last_error.or(first_error).unwrap_or_else(|| CliError::Usage("no read got through".into())));
    }
    match first_error {
        Some(error) if errors > most => {
            if !args.json && errors < args.count {
                eprintln!(
                    "bench: stopped after {done} of {} reads: {errors} failed, more than half of them",
                    args.count
                );
            }
            Err(error)
        }
        Some(error) => {
            if !args.json {
                let first = crate::exit::report(&error, Some(&session.target), unit).message;
                eprintln!("bench: {errors} of {} reads failed; the first: {first}", args.count);
            }
            Ok(())
        }
        None => Ok(()),
    }
}

impl Outcome {
    fn tps(&self) -> f64 {
        let seconds = self.elapsed.as_secs_f64();
        if seconds > 0.0 { f64::from(self.transactions) / seconds } else { 0.0 }
    }

    /// The peer fixtures' bench object, with their rounding.
    fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "transactions": self.transactions,
            "errors": self.errors,
            "seconds": round(self.elapsed.as_secs_f64(), 6),
            "tps": round(self.tps(), 1),
            "p50_us": round(micros(percentile(&self.latencies, 50)), 1),
            "p99_us": round(micros(percentile(&self.latencies, 99)), 1),
            "user_s": round(self.cpu.user.as_secs_f64(), 6),
            "sys_s": round(self.cpu.system.as_secs_f64(), 6),
        })
    }

    /// One line for people.
    fn summary(&self, target: &str, unit: u8, args: &BenchArgs) -> String {
        let cpu = self.cpu.user + self.cpu.system;
        let per_read = cpu.as_secs_f64() * 1e6 / f64::from(self.transactions.max(1));
        format!(
            "bench: {} FC03 reads of {} registers at {} from unit {unit} on {target}: {:.1} transactions/s, \
             latency p50 {:.1} µs, p99 {:.1} µs, {} errors, {:.3} s; CPU {:.2} s user + {:.2} s sys = {per_read:.1} µs per read",
            self.transactions,
            args.quantity,
            args.address,
            self.tps(),
            micros(percentile(&self.latencies, 50)),
            micros(percentile(&self.latencies, 99)),
            self.errors,
            self.elapsed.as_secs_f64(),
            self.cpu.user.as_secs_f64(),
            self.cpu.system.as_secs_f64(),
        )
    }
}

/// The nearest-rank percentile `p` (1–100) of sorted values: the smallest value with at least
/// p % of the values at or below it.
fn percentile(sorted: &[Duration], p: usize) -> Duration {
    let n = sorted.len();
    let rank = (p * n).div_ceil(100).clamp(1, n.max(1));
    sorted.get(rank - 1).copied().unwrap_or_default()
}

fn micros(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn round(value: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (value * scale).round() / scale
}

/// `0x` hexadecimal or decimal, 0–65535.
fn parse_address(text: &str) -> Result<u16, String> {
    ferrobus::text::number(text, u64::from(u16::MAX))
        .ok()
        .and_then(|n| u16::try_from(n).ok())
        .ok_or_else(|| format!("'{}' is not a register address from 0 to 65535 (decimal or 0x hex)", text.trim()))
}

/// User and system CPU time of the whole process; zero where it cannot be read (not Linux).
///
/// /proc/self/stat splits the time into user and system but counts it in clock ticks (10 ms);
/// /proc/self/task/*/schedstat counts the run time of each live thread in nanoseconds. The
/// precise total is split in the ratio of the ticks, as getrusage() does.
fn cpu_times() -> CpuTimes {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return CpuTimes::default() };
    let hz = clock_ticks();
    let Some(coarse) = parse_stat(&stat, hz) else { return CpuTimes::default() };
    refine(coarse, run_time_of_threads(), Duration::from_secs(1) / u32::try_from(hz).unwrap_or(100))
}

/// The sum of the run times of the process's live threads (field 1 of their schedstat).
fn run_time_of_threads() -> Option<Duration> {
    let mut total = Duration::ZERO;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        total += Duration::from_nanos(stat.split_whitespace().next()?.parse().ok()?);
    }
    Some(total)
}

/// `coarse` with its total replaced by `precise`, when `precise` accounts for all of it (up to
/// a tick: a thread that has exited is missing from the live threads' sum).
fn refine(coarse: CpuTimes, precise: Option<Duration>, tick: Duration) -> CpuTimes {
    let total = coarse.user + coarse.system;
    let Some(precise) = precise.filter(|p| *p + tick >= total) else { return coarse };
    if total.is_zero() {
        return CpuTimes { user: precise, system: Duration::ZERO };
    }
    let user = precise.mul_f64(coarse.user.as_secs_f64() / total.as_secs_f64());
    CpuTimes { user, system: precise.saturating_sub(user) }
}

/// utime and stime (fields 14 and 15) of a /proc/PID/stat line, in ticks of `hz`.
fn parse_stat(stat: &str, hz: u64) -> Option<CpuTimes> {
    // The command name (field 2) is in parentheses and may hold spaces or ')': fields are
    // counted from the last ')'. The field after it is field 3, the state.
    let rest = stat.get(stat.rfind(')')? + 1..)?;
    let mut fields = rest.split_whitespace().skip(11);
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    let ticks = |t: u64| Duration::from_secs(t / hz) + Duration::from_nanos((t % hz) * 1_000_000_000 / hz);
    (hz > 0).then(|| CpuTimes { user: ticks(utime), system: ticks(stime) })
}

/// The kernel's USER_HZ, from the auxiliary vector (AT_CLKTCK), else the usual 100.
fn clock_ticks() -> u64 {
    std::fs::read("/proc/self/auxv").ok().and_then(|auxv| auxv_value(&auxv, AT_CLKTCK)).unwrap_or(100)
}

/// The auxiliary vector's entry type for the clock tick rate.
const AT_CLKTCK: u64 = 17;

/// The value of entry `key` in an auxiliary vector: pairs of native-endian words.
fn auxv_value(auxv: &[u8], key: u64) -> Option<u64> {
    const WORD: usize = std::mem::size_of::<usize>();
    let word = |bytes: &[u8]| -> Option<u64> {
        let bytes: [u8; WORD] = bytes.try_into().ok()?;
        u64::try_from(usize::from_ne_bytes(bytes)).ok()
    };
    auxv.chunks_exact(2 * WORD)
        .filter_map(|pair| Some((word(pair.get(..WORD)?)?, word(pair.get(WORD..)?)?)))
        .take_while(|&(k, _)| k != 0)
        .find_map(|(k, v)| (k == key && v > 0).then_some(v))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn us(values: &[u64]) -> Vec<Duration> {
        values.iter().map(|&v| Duration::from_micros(v)).collect()
    }

    #[test]
    fn a_streak_of_failures_says_gone_only_after_three_reads_and_the_bound_and_restarts_on_success() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let bound = Duration::from_secs(10);
        let mut streak = Streak::default();
        assert_eq!(streak.gone_for(at(60_000), bound), None, "no failure, nothing gone");
        streak.failed(at(0));
        streak.failed(at(5_000));
        assert_eq!(streak.gone_for(at(20_000), bound), None, "two failures are not enough, however long");
        streak.failed(at(9_000));
        assert_eq!(streak.gone_for(at(9_999), bound), None, "three failures, the bound not reached");
        assert_eq!(streak.gone_for(at(10_000), bound), Some(bound), "counted from the first failure's send");
        streak.succeeded();
        streak.failed(at(11_000));
        streak.failed(at(12_000));
        streak.failed(at(13_000));
        assert_eq!(streak.gone_for(at(20_999), bound), None, "a read got through at 10 s: counted again");
        assert_eq!(streak.gone_for(at(21_000), bound), Some(bound));
    }

    #[test]
    fn percentiles_are_nearest_rank_like_the_peer_fixtures() {
        let sorted = us(&(1..=100).collect::<Vec<_>>());
        assert_eq!(percentile(&sorted, 50), Duration::from_micros(50));
        assert_eq!(percentile(&sorted, 99), Duration::from_micros(99));
        let three = us(&[10, 20, 30]);
        assert_eq!(percentile(&three, 50), Duration::from_micros(20));
        assert_eq!(percentile(&three, 99), Duration::from_micros(30));
        assert_eq!(percentile(&us(&[7]), 99), Duration::from_micros(7));
        assert_eq!(percentile(&[], 50), Duration::ZERO);
    }

    #[test]
    fn the_json_object_has_the_peer_fields_in_their_order_and_rounding() {
        let outcome = Outcome {
            transactions: 4,
            errors: 1,
            elapsed: Duration::from_micros(2_000_001),
            latencies: us(&[100, 200, 300, 1_000]),
            cpu: CpuTimes { user: Duration::from_millis(30), system: Duration::from_millis(10) },
        };
        assert_eq!(
            outcome.json().to_string(),
            r#"{"transactions":4,"errors":1,"seconds":2.000001,"tps":2.0,"p50_us":200.0,"p99_us":1000.0,"user_s":0.03,"sys_s":0.01}"#
        );
    }

    #[test]
    fn stat_lines_give_user_and_system_time_even_with_odd_command_names() {
        let stat = "4242 (my prog) x) S 1 4242 4242 0 -1 4194560 500 0 0 0 123 45 0 0 20 0 3 0 99 0 0";
        let cpu = parse_stat(stat, 100).unwrap();
        assert_eq!(cpu.user, Duration::from_millis(1230));
        assert_eq!(cpu.system, Duration::from_millis(450));
        assert!(parse_stat("4242 (short) S 1", 100).is_none());
        assert!(parse_stat(stat, 0).is_none());
    }

    #[test]
    fn the_precise_total_is_split_in_the_ratio_of_the_ticks() {
        let ms = Duration::from_millis;
        let tick = ms(10);
        let coarse = CpuTimes { user: ms(30), system: ms(90) };
        assert_eq!(refine(coarse, Some(ms(128)), tick), CpuTimes { user: ms(32), system: ms(96) });
        assert_eq!(refine(coarse, None, tick), coarse);
        // A live-thread sum short of the ticks by more than a tick misses an exited thread.
        assert_eq!(refine(coarse, Some(ms(100)), tick), coarse);
        let none = CpuTimes::default();
        assert_eq!(refine(none, Some(ms(4)), tick), CpuTimes { user: ms(4), system: Duration::ZERO });
    }

    #[test]
    fn the_clock_tick_rate_is_read_from_the_auxiliary_vector() {
        let mut auxv = Vec::new();
        for (k, v) in [(6usize, 4096usize), (17, 250), (0, 0), (17, 1)] {
            auxv.extend_from_slice(&k.to_ne_bytes());
            auxv.extend_from_slice(&v.to_ne_bytes());
        }
        assert_eq!(auxv_value(&auxv, AT_CLKTCK), Some(250));
        assert_eq!(auxv_value(&auxv[..2 * std::mem::size_of::<usize>()], AT_CLKTCK), None);
        assert!(clock_ticks() > 0);
        assert!(cpu_times().user + cpu_times().system < Duration::from_secs(3600));
    }

    #[test]
    fn addresses_are_decimal_or_hex() {
        assert_eq!(parse_address("0"), Ok(0));
        assert_eq!(parse_address("0x1000"), Ok(0x1000));
        assert_eq!(parse_address("65535"), Ok(65535));
        assert!(parse_address("65536").is_err());
        assert!(parse_address("-1").is_err());
    }
}
