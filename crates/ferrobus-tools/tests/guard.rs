//! The write guard with its reading, against a server engine on an in-memory line (paused
//! clock): a run-locked point is refused while the running coil is on, after reading only that
//! coil; accepted when it is off; a point that may change while running costs no read; a value
//! out of range costs no read; a running point that cannot be read refuses the write; a write by
//! address is run-locked by the points it touches; the poller's write goes through the guard.

// The transport crate's test support: one in-memory unit, MBAP by hand, its devices.
#[path = "../../ferrobus/tests/support/mod.rs"]
mod support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use ferrobus::server::Shared;
use ferrobus::{Client, ClientConfig};
use ferrobus_profile::{Profile, Refusal, RunState, Table, Value, Write};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::slave::Handler;
use ferrobus_tools::guard::{check_span, check_write, run_state};
use ferrobus_tools::poll::{Cell, Group, PollConfig, Poller, WriteError};

const PROFILE: &str = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
    [state]\nrunning = { point = 'running', values = [1] }\n\
    [[coils]]\nnumber=0\nname='running'\n\
    [[registers]]\nnumber=0\nname='F001'\naccess='rw'\nmax=100\n\
    [[registers]]\nnumber=1\nname='A003'\naccess='rw'\nmax=100\nwhile_running=false\n";

/// The running coil, and the requests seen as (function, start).
#[derive(Default)]
struct Drive {
    running: bool,
    refuse_coils: bool,
    seen: Vec<(u8, u16)>,
}

impl Handler for Drive {
    fn read_coils(&mut self, _: u8, start: u16, out: &mut [bool]) -> Result<(), ExceptionCode> {
        self.seen.push((0x01, start));
        if self.refuse_coils {
            return Err(ExceptionCode::ServerDeviceFailure);
        }
        out.fill(false);
        if start == 0
            && let Some(first) = out.first_mut()
        {
            *first = self.running;
        }
        Ok(())
    }
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.seen.push((0x03, start));
        out.fill(0);
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, _: u16) -> Result<(), ExceptionCode> {
        self.seen.push((0x06, address));
        Ok(())
    }
}

async fn client(drive: &Arc<Mutex<Drive>>) -> Client {
    let transport = support::in_memory("in-memory drive", Shared(Arc::clone(drive)));
    let config = ClientConfig { timeout: Duration::from_millis(50), backoff: None, ..ClientConfig::default() };
    Client::connect(transport, config).await.unwrap()
}

fn seen(drive: &Arc<Mutex<Drive>>) -> Vec<(u8, u16)> {
    std::mem::take(&mut drive.lock().unwrap().seen)
}

async fn guard(client: &Client, profile: &Profile, code: &str, raw: i128) -> Result<(), Refusal> {
    let point = profile.point(code).unwrap();
    let raw = Value::Int(raw);
    let typed = point.show(&raw);
    check_write(client, 1, profile, &Write { point, raw: &raw, typed: &typed }).await
}

#[tokio::test(start_paused = true)]
async fn a_run_locked_point_is_refused_while_the_running_coil_is_on_after_reading_only_it() {
    let profile = Profile::parse(PROFILE, "guard.toml").unwrap();
    let drive = Arc::new(Mutex::new(Drive { running: true, ..Drive::default() }));
    let client = client(&drive).await;
    let refusal = guard(&client, &profile, "A003", 50).await.unwrap_err();
    assert_eq!(refusal.to_string(), "A003 cannot change while the drive runs (running = 1); stop it first");
    assert_eq!(seen(&drive), [(0x01, 0)], "one read of the running coil");
    // The same refusal as the profile's own guard given that reading.
    let point = profile.point("A003").unwrap();
    let raw = Value::Int(50);
    let typed = point.show(&raw);
    let state = run_state(&client, 1, &profile, point).await;
    assert_eq!(state, RunState::Read(Value::Bool(true)));
    assert_eq!(profile.guard_write(&Write { point, raw: &raw, typed: &typed }, &state), Err(refusal));

    drive.lock().unwrap().running = false;
    seen(&drive);
    assert_eq!(guard(&client, &profile, "A003", 50).await, Ok(()), "stopped");
    assert_eq!(seen(&drive), [(0x01, 0)]);
}

#[tokio::test(start_paused = true)]
async fn a_free_point_or_a_value_out_of_range_costs_no_read() {
    let profile = Profile::parse(PROFILE, "guard.toml").unwrap();
    let drive = Arc::new(Mutex::new(Drive { running: true, ..Drive::default() }));
    let client = client(&drive).await;
    assert_eq!(guard(&client, &profile, "F001", 50).await, Ok(()), "F001 may change while running");
    let out = guard(&client, &profile, "A003", 101).await.unwrap_err();
    assert!(matches!(out, Refusal::Value(_)) && out.to_string().contains("out of range"), "{out}");
    assert_eq!(seen(&drive), [], "nothing read");
}

#[tokio::test(start_paused = true)]
async fn a_running_point_that_cannot_be_read_refuses_the_write() {
    let profile = Profile::parse(PROFILE, "guard.toml").unwrap();
    let drive = Arc::new(Mutex::new(Drive { refuse_coils: true, ..Drive::default() }));
    let client = client(&drive).await;
    let refusal = guard(&client, &profile, "A003", 50).await.unwrap_err();
    assert!(matches!(refusal, Refusal::Unreadable { .. }), "{refusal}");
    assert!(refusal.to_string().starts_with("A003 cannot change while the drive runs, and reading running failed: "));
}

#[tokio::test(start_paused = true)]
async fn a_write_by_address_over_a_run_locked_point_is_refused_while_running_and_costs_no_read_elsewhere() {
    let profile = Profile::parse(PROFILE, "guard.toml").unwrap();
    let drive = Arc::new(Mutex::new(Drive { running: true, ..Drive::default() }));
    let client = client(&drive).await;
    assert_eq!(check_span(&client, 1, &profile, Table::Holding, 0, 1).await, Ok(()), "F001 alone");
    assert_eq!(seen(&drive), [], "nothing run-locked touched, nothing read");
    let refusal = check_span(&client, 1, &profile, Table::Holding, 0, 2).await.unwrap_err();
    assert_eq!(refusal.to_string(), "A003 cannot change while the drive runs (running = 1); stop it first");
    assert_eq!(seen(&drive), [(0x01, 0)], "one read of the running coil");
    drive.lock().unwrap().running = false;
    assert_eq!(check_span(&client, 1, &profile, Table::Holding, 1, 1).await, Ok(()), "stopped");
}

#[tokio::test(start_paused = true)]
async fn a_poll_handle_write_through_a_profile_goes_through_its_guard() {
    let profile = Profile::parse(PROFILE, "guard.toml").unwrap();
    let drive = Arc::new(Mutex::new(Drive { running: true, ..Drive::default() }));
    let point = profile.point("A003").unwrap().clone();
    let cell = Cell { name: point.code.clone(), point, format: None };
    let group = Group {
        name: "g".into(),
        unit: 1,
        table: Table::Holding,
        start: 1,
        count: 1,
        every: Duration::from_secs(60),
        cells: vec![cell],
    };
    let poller = Poller::start(client(&drive).await, vec![group], PollConfig::default());
    let handle = poller.handle();
    handle.pause();
    let refused = handle.write(Some(&profile), 0, 0, "50").await.unwrap_err();
    assert!(matches!(refused, WriteError::Refused(Refusal::Running { .. })), "{refused}");
    assert_eq!(seen(&drive), [(0x01, 0)], "the running coil read, nothing written");
    drive.lock().unwrap().running = false;
    assert_eq!(handle.write(Some(&profile), 0, 0, "50").await.unwrap(), Value::Int(50), "stopped: written");
    assert_eq!(seen(&drive), [(0x01, 0), (0x06, 1)]);
    handle.stop();
}
