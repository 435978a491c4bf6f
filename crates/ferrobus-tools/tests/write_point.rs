//! One way to write a point, whoever writes it: `write::write_point`, `PollHandle::write` and
//! `PollHandle::write_raw` (the bridge's path) against a server engine on an in-memory line
//! (paused clock) whose device answers neither FC05 nor FC06, as its profile's `functions` say:
//! each writer sends a coil as FC0F and one register as FC10, reads back what `write_point`
//! is asked to, and refuses a value wider than the device's per-request limit with nothing sent.
//! Without the profile, the spec's functions go out (FC06), and this device refuses them.

// The transport crate's test support: one in-memory unit, MBAP by hand, its devices.
#[path = "../../ferrobus/tests/support/mod.rs"]
mod support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use ferrobus::server::Shared;
use ferrobus::{Client, ClientConfig, Error};
use ferrobus_profile::{Profile, Refusal, Table, Value, WireWrite, Write};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::pdu::{Bits, Registers};
use ferrobus_proto::slave::Handler;
use ferrobus_tools::poll::{Cell, Group, PollConfig, Poller, WriteError};
use ferrobus_tools::write::write_point;

const PROFILE: &str = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
    [comm]\nfunctions = [0x01, 0x03, 0x0F, 0x10]\n\
    [limits]\nwrite_registers = 2\n\
    [[coils]]\nnumber=0\nname='run'\naccess='rw'\n\
    [[registers]]\nnumber=0\nname='F001'\naccess='rw'\n\
    [[registers]]\nnumber=1\nname='target'\ntype='u32'\naccess='rw'\n\
    [[registers]]\nnumber=3\nname='wide'\ntype='f64'\naccess='rw'\n";

/// A device with FC01, FC03, FC0F and FC10 only (the others get exception 01), and the
/// requests it was sent as (function, start).
#[derive(Default)]
struct Device {
    coils: [bool; 8],
    registers: [u16; 8],
    seen: Vec<(u8, u16)>,
}

impl Handler for Device {
    fn read_coils(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = *self.coils.get(usize::from(start) + i).ok_or(ExceptionCode::IllegalDataAddress)?;
        }
        Ok(())
    }
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = *self.registers.get(usize::from(start) + i).ok_or(ExceptionCode::IllegalDataAddress)?;
        }
        Ok(())
    }
    fn write_multiple_coils(&mut self, _: u8, start: u16, values: Bits<'_>) -> Result<(), ExceptionCode> {
        self.seen.push((0x0F, start));
        for (i, on) in values.iter().enumerate() {
            *self.coils.get_mut(usize::from(start) + i).ok_or(ExceptionCode::IllegalDataAddress)? = on;
        }
        Ok(())
    }
    fn write_multiple_registers(&mut self, _: u8, start: u16, values: Registers<'_>) -> Result<(), ExceptionCode> {
        self.seen.push((0x10, start));
        for (i, value) in values.iter().enumerate() {
            *self.registers.get_mut(usize::from(start) + i).ok_or(ExceptionCode::IllegalDataAddress)? = value;
        }
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, _: u16) -> Result<(), ExceptionCode> {
        self.seen.push((0x06, address));
        Err(ExceptionCode::IllegalFunction)
    }
}

async fn client(device: &Arc<Mutex<Device>>) -> Client {
    let transport = support::in_memory("in-memory device", Shared(Arc::clone(device)));
    let config = ClientConfig { timeout: Duration::from_millis(50), backoff: None, ..ClientConfig::default() };
    Client::connect(transport, config).await.unwrap()
}

fn seen(device: &Arc<Mutex<Device>>) -> Vec<(u8, u16)> {
    std::mem::take(&mut device.lock().unwrap().seen)
}

async fn write(
    client: &Client,
    profile: &Profile,
    code: &str,
    text: &str,
) -> Result<ferrobus_tools::write::Written, WriteError> {
    let point = profile.point(code).unwrap();
    let raw = point.prepare_write(text).unwrap();
    write_point(client, 1, Some(profile), &Write { point, raw: &raw, typed: text }, true).await
}

#[tokio::test(start_paused = true)]
async fn write_point_sends_what_the_device_takes_and_reads_it_back() {
    let profile = Profile::parse(PROFILE, "write.toml").unwrap();
    let device = Arc::new(Mutex::new(Device::default()));
    let client = client(&device).await;

    let word = write(&client, &profile, "F001", "42").await.unwrap();
    assert_eq!(word.request, WireWrite::Registers { address: 0, values: vec![42] }, "FC10, the device has no FC06");
    assert_eq!(word.read_back.unwrap().unwrap(), Value::Int(42));
    let coil = write(&client, &profile, "run", "1").await.unwrap();
    assert_eq!(coil.request, WireWrite::OneOfCoils { address: 0, on: true }, "FC0F, the device has no FC05");
    assert_eq!(coil.read_back.unwrap().unwrap(), Value::Bool(true));
    let long = write(&client, &profile, "target", "70000").await.unwrap();
    assert_eq!(long.request, WireWrite::Registers { address: 1, values: vec![1, 4464] }, "one request, never split");
    assert_eq!(seen(&device), [(0x10, 0), (0x0F, 0), (0x10, 1)]);

    let wide = write(&client, &profile, "wide", "1.5").await.unwrap_err();
    assert!(matches!(wide, WriteError::Refused(Refusal::TooWide { items: 4, limit: 2, .. })), "{wide}");
    assert_eq!(wide.to_string(), "wide takes 4 registers, more than the 2 the device writes in one request");
    assert_eq!(seen(&device), [], "nothing sent");
}

#[tokio::test(start_paused = true)]
async fn the_poll_handles_writes_take_the_same_path_and_without_a_profile_the_specs() {
    let profile = Profile::parse(PROFILE, "write.toml").unwrap();
    let device = Arc::new(Mutex::new(Device::default()));
    let point = profile.point("F001").unwrap().clone();
    let cell = Cell { name: point.code.clone(), point, format: None };
    let group = Group {
        name: "g".into(),
        unit: 1,
        table: Table::Holding,
        start: 0,
        count: 1,
        every: Duration::from_secs(60),
        cells: vec![cell],
    };
    let poller = Poller::start(client(&device).await, vec![group], PollConfig::default());
    let handle = poller.handle();
    handle.pause();

    assert_eq!(handle.write(Some(&profile), 0, 0, "7").await.unwrap(), Value::Int(7));
    handle.write_raw(Some(&profile), 0, 0, &Value::Int(8)).await.unwrap();
    assert_eq!(seen(&device), [(0x10, 0), (0x10, 0)], "PollHandle::write and write_raw: FC10");
    assert_eq!(device.lock().unwrap().registers[0], 8);

    let spec = handle.write_raw(None, 0, 0, &Value::Int(9)).await.unwrap_err();
    assert!(matches!(&spec, WriteError::Bus(Error::Exception { code: ExceptionCode::IllegalFunction, .. })), "{spec}");
    assert_eq!(seen(&device), [(0x06, 0)], "no profile: the spec's FC06, which this device refuses");
    handle.stop();
}
