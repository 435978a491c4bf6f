//! `ferrobus demo`: a tour with no hardware and no configuration.
//!
//! A simulated Omron 3G3RX inverter sits on a virtual RS-485 line inside this process, with
//! real character timing; the real client drives it the way a commissioning engineer would:
//! check the link, identify, set the ramp and the frequency, run, watch the output frequency
//! ramp, stop — meeting the drive's limits and vendor exceptions on the way.

use std::time::Duration;

use clap::Args;
use ferrobus::line::{Line, LineOptions};
use ferrobus::server::{ServerOptions, Shared, serve};
use ferrobus::{Client, ClientConfig, Error, Timer};
use ferrobus_proto::codes::{DiagnosticCode, ReadDeviceIdCode};
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig};
use ferrobus_proto::slave::{Slave, SlaveConfig};
use ferrobus_sim::{Device, Faults, Profile, Sim, tokio_clock};

use crate::exit::CliError;
use crate::output;

/// `println!` to stdout, checked: a failed write ends the demo with its error.
macro_rules! say {
    () => {
        output::print("\n")?
    };
    ($($arg:tt)*) => {
        output::print(&format!("{}\n", format_args!($($arg)*)))?
    };
}

/// Arguments of `ferrobus demo`.
#[derive(Args, Clone, Debug)]
pub(crate) struct DemoArgs {
    /// Baud rate of the virtual line (8E1)
    #[arg(long = "line-baud", default_value_t = 19_200, value_parser = clap::value_parser!(u32).range(1200..=115_200))]
    baud: u32,
}

/// The drive's unit address.
const UNIT: u8 = 1;

/// The data of the loop-back test.
const LOOPBACK: [u8; 2] = [0x12, 0x34];

/// Frame addresses on the 3G3RX (the manual's register number − 1).
mod reg {
    /// F001, output frequency setting (32-bit, 0.01 Hz).
    pub(super) const F001: u16 = 0x0000;
    /// Inverter status A and B.
    pub(super) const STATUS: u16 = 0x0002;
    /// d001, output frequency monitor (32-bit, 0.01 Hz), and d002, output current (0.01 A).
    pub(super) const D001: u16 = 0x1000;
    /// F002, acceleration time 1 (32-bit, 0.01 s).
    pub(super) const F002: u16 = 0x1102;
    /// F003, deceleration time 1 (32-bit, 0.01 s).
    pub(super) const F003: u16 = 0x1104;
    /// A003, base frequency (Hz).
    pub(super) const A003: u16 = 0x1202;
    /// Coil 1, the run command.
    pub(super) const RUN: u16 = 0x0000;
}

fn words(value: u32) -> [u16; 2] {
    let [a, b, c, d] = value.to_be_bytes();
    [u16::from_be_bytes([a, b]), u16::from_be_bytes([c, d])]
}

fn join(words: &[u16]) -> u32 {
    match words {
        [hi, lo, ..] => (u32::from(*hi) << 16) | u32::from(*lo),
        _ => 0,
    }
}

fn status_a(code: u16) -> &'static str {
    match code {
        0 => "initial",
        2 => "stopped",
        3 => "running",
        4 => "free-run stop",
        8 => "tripped",
        _ => "other",
    }
}

/// Runs `ferrobus demo`.
pub(crate) async fn run(args: &DemoArgs) -> Result<(), CliError> {
    let config = LineConfig::new(args.baud).ok_or_else(|| CliError::Usage("a baud rate above 0".into()))?;
    let line = Line::start(LineOptions::new(config));
    let timing = line.timing();

    let mut sim = Sim::new(tokio_clock(), 1);
    let profile = Profile::load("omron-3g3rx").map_err(|e| CliError::Usage(e.to_string()))?;
    sim.add(UNIT, Device::new(profile), Faults::default());
    let units = sim.unit_set();
    let sim = Shared::new(sim);
    let drive_port = line.endpoint("3G3RX").await.map_err(|e| Error::io("attaching the drive", e))?;
    let mut handler = sim.clone();
    tokio::spawn(async move {
        let slave =
            Slave::new(RtuCodec::new(timing, Expect::Both), SlaveConfig { units, response_wait: Duration::ZERO });
        serve(slave, Box::new(drive_port), &mut handler, &mut ServerOptions::new(timing, Timer::Spin)).await
    });
    let client = Client::connect(line.transport("client"), ClientConfig::default()).await?;

    say!("ferrobus demo: a simulated Omron 3G3RX inverter, unit {UNIT}, on a virtual RS-485 line");
    say!(
        "at {config} — every character takes {:.0} µs on the wire, frames are {:.2} ms of silence apart.\n",
        timing.char_time().as_secs_f64() * 1e6,
        timing.t3_5().as_secs_f64() * 1e3
    );

    step("1. Is anyone there? A loop-back test (FC08, sub-function 0000h), as the 3G3RX manual suggests.")?;
    let started = tokio::time::Instant::now();
    let echo = client.diagnostics(UNIT, DiagnosticCode::ReturnQueryData, &LOOPBACK).await?;
    say!("   {} in {:.1} ms\n", echo_words(&LOOPBACK, &echo), started.elapsed().as_secs_f64() * 1e3);

    step("2. Who is it? Device identification (FC2B/0E):")?;
    match client.read_device_identification(UNIT, ReadDeviceIdCode::Basic, 0).await {
        Err(Error::Exception { code, .. }) => {
            say!("   exception {code}: the 3G3RX does not implement it, as its manual says.");
            let status = client.read_holding_registers(UNIT, reg::STATUS, 2).await?;
            say!("   Its status registers (0003h, 0004h) answer instead: {}\n", status_a(status[0]));
        }
        other => say!("   {other:?}\n"),
    }

    step("3. The 3G3RX takes at most 4 registers per request. Asking for 5:")?;
    if let Err(e) = client.read_holding_registers(UNIT, reg::F001, 5).await {
        say!("   {e}\n   (ferrobus read --max-per-request 4 splits such reads, never inside a 32-bit value)\n");
    }

    step(
        "4. Ramp times (F002, F003: 32-bit, high word first, in 0.01 s, from 0 to the maximum frequency A004, 60 Hz):",
    )?;
    client.write_multiple_registers(UNIT, reg::F002, &words(300)).await?;
    client.write_multiple_registers(UNIT, reg::F003, &words(225)).await?;
    say!("   F002 = 3.00 s, F003 = 2.25 s: 20 Hz/s up, 26.7 Hz/s down\n");

    step("5. A frequency of 500.00 Hz is beyond the drive's range:")?;
    if let Err(e) = client.write_multiple_registers(UNIT, reg::F001, &words(50_000)).await {
        say!("   {e}: the 3G3RX's vendor code for \"out of range\"\n");
    }
    client.write_multiple_registers(UNIT, reg::F001, &words(6_000)).await?;
    say!("   F001 = 60.00 Hz accepted\n");

    step("6. Run (coil 0001h ON) and watch the output frequency d001 ramp:")?;
    client.write_single_coil(UNIT, reg::RUN, true).await?;
    watch(&client, 14).await?;

    step("7. While running, the base frequency A003 cannot change:")?;
    if let Err(e) = client.write_single_register(UNIT, reg::A003, 50).await {
        say!("   {e}: the 3G3RX's code for \"not allowed in this state\"\n");
    }

    step("8. Stop (coil 0001h OFF): the output ramps down with F003.")?;
    client.write_single_coil(UNIT, reg::RUN, false).await?;
    watch(&client, 11).await?;

    let stats = line.stats();
    let broken: u64 = stats.endpoints.iter().map(|e| e.gap_violations).sum();
    say!(
        "The line carried {} frames ({} characters); t3.5 broken {broken} times, {} collisions.",
        stats.frames,
        stats.characters,
        stats.collisions
    );
    say!("\nOn a real drive, the same steps from the command line:");
    say!("  ferrobus --port /dev/ttyUSB0 --baud 19200 --unit 1 diag echo");
    say!("  ferrobus --port /dev/ttyUSB0 --unit 1 write registers --one-based 0x0001 6000 --type u32");
    say!("  ferrobus --port /dev/ttyUSB0 --unit 1 write coil --one-based 1 on");
    say!("  ferrobus --port /dev/ttyUSB0 --unit 1 read holding --one-based 0x1001 --type u32");
    if cfg!(unix) {
        say!("and `ferrobus sim --profile omron-3g3rx --pty` puts this simulated drive on a pty for your own tools.");
    } else {
        say!(
            "and `ferrobus sim --profile omron-3g3rx --tcp 127.0.0.1:5020` serves this simulated drive to your own tools."
        );
    }
    Ok(())
}

/// What the loop-back test sent and got back, in hex (the manual writes 1234h).
fn echo_words(sent: &[u8], echoed: &[u8]) -> String {
    let hex = |bytes: &[u8]| match bytes {
        [] => "nothing".to_string(),
        _ => bytes.iter().map(|b| format!("0x{b:02X}")).collect::<Vec<_>>().join(" "),
    };
    format!("sent {}, echoed {}", hex(sent), hex(echoed))
}

fn step(text: &str) -> Result<(), CliError> {
    say!("{text}");
    Ok(())
}

/// Prints the output frequency and current `samples` times, 250 ms apart, with a bar.
async fn watch(client: &Client, samples: u32) -> Result<(), CliError> {
    for _ in 0..samples {
        let monitor = client.read_holding_registers(UNIT, reg::D001, 3).await?;
        let centi_hz = join(&monitor);
        let (hz, amps) = (f64::from(centi_hz) / 100.0, f64::from(monitor[2]) / 100.0);
        let status = client.read_holding_registers(UNIT, reg::STATUS, 1).await?;
        // One block per 2 Hz.
        let bar = "█".repeat(usize::try_from(centi_hz / 200).unwrap_or(0));
        say!("   {hz:6.2} Hz {amps:6.2} A  {:<8} {bar}", status_a(status[0]));
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    say!();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_loop_back_bytes_are_shown_in_hex_with_a_prefix() {
        assert_eq!(echo_words(&[0x12, 0x34], &[0x12, 0x34]), "sent 0x12 0x34, echoed 0x12 0x34");
        assert_eq!(echo_words(&[0x12], &[]), "sent 0x12, echoed nothing");
    }
}
