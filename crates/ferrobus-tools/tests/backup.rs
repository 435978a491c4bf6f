//! The library's backup reads against a server engine on an in-memory line (paused clock): the
//! profile's read plan, a request the device refuses read again point by point so that only the
//! refused parameter is marked, a stop between two requests that marks the rest not read, and a
//! backup rendered from the readings that parses back the same; a restore in dependency order
//! whose refused write stops only what depends on it.

// The transport crate's test support: one in-memory unit, MBAP by hand, its devices.
#[path = "../../ferrobus/tests/support/mod.rs"]
mod support;

use std::future::Future;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ferrobus::server::Shared;
use ferrobus::{Client, ClientConfig};
use ferrobus_profile::{Profile, Value};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::slave::Handler;
use ferrobus_tools::backup::device::{self, INTERRUPTED};
use ferrobus_tools::backup::restore::{self, Item, Outcome};
use ferrobus_tools::backup::{Backup, Entry, Header, State, Target, Unwatched, View, Watch, param};

/// Four parameters at 0..4, read at most 4 registers a request; P2 is refused.
const PROFILE: &str = "[device]\nname='d'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
    [limits]\nread_registers=4\n\
    [[registers]]\nnumber=0\nname='P0'\naccess='rw'\n\
    [[registers]]\nnumber=1\nname='P1'\naccess='rw'\n\
    [[registers]]\nnumber=2\nname='P2'\naccess='rw'\n\
    [[registers]]\nnumber=3\nname='P3'\naccess='rw'\nunit='Hz'\nscale=0.1\n";

/// Registers 0..4 = 10, 11, 12, 13; any read that covers register 2 is refused, and so is a
/// write to register 1.
#[derive(Default)]
struct Drive {
    reads: Vec<(u16, usize)>,
    writes: Vec<(u16, u16)>,
}

impl Handler for Drive {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        self.reads.push((start, out.len()));
        let from = usize::from(start);
        if (from..from + out.len()).contains(&2) {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        for (i, word) in out.iter_mut().enumerate() {
            *word = u16::try_from(10 + from + i).unwrap();
        }
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        if address == 1 {
            return Err(ExceptionCode::IllegalDataValue);
        }
        self.writes.push((address, value));
        Ok(())
    }
}

async fn client(drive: &Arc<Mutex<Drive>>) -> Client {
    let transport = support::in_memory("in-memory drive", Shared(Arc::clone(drive)));
    let config = ClientConfig { timeout: Duration::from_millis(50), backoff: None, ..ClientConfig::default() };
    Client::connect(transport, config).await.unwrap()
}

fn view() -> View {
    View { name: "d.toml".into(), hash: None, profile: Profile::parse(PROFILE, "d.toml").unwrap() }
}

#[tokio::test(start_paused = true)]
async fn a_refused_request_is_read_again_point_by_point_and_only_the_refused_parameter_is_marked() {
    let drive = Arc::new(Mutex::new(Drive::default()));
    let client = client(&drive).await;
    let view = view();
    let params: Vec<_> = view.profile.points().iter().collect();
    let readings = device::read(Target { client: &client, unit: 1 }, &view, &params, &mut Unwatched).await;
    assert_eq!(drive.lock().unwrap().reads, [(0, 4), (0, 1), (1, 1), (2, 1), (3, 1)], "one planned read, then each");
    assert_eq!((readings.planned, readings.requests), (1, 5));
    assert_eq!(readings.values["P0"], Ok(vec![10]));
    assert_eq!(readings.values["P3"], Ok(vec![13]));
    let refused = readings.values["P2"].as_ref().unwrap_err();
    assert!(refused.starts_with("exception 0x02"), "{refused}");
    assert_eq!(readings.split(&params), (vec!["P0", "P1", "P3"], vec!["P2"]));
    assert!(readings.stopped.is_none() && !readings.interrupted);

    // The readings make a backup that renders and parses back the same.
    let entries: Vec<Entry> = params
        .iter()
        .map(|p| {
            let state = match &readings.values[&p.code] {
                Ok(words) => {
                    let raw = param::decode(p, words).unwrap();
                    State::Value { raw: param::to_toml(&raw), shown: p.show(&raw) }
                }
                Err(why) => State::Failed(why.clone()),
            };
            Entry { code: p.code.clone(), label: String::new(), line: 0, state }
        })
        .collect();
    let header = Header {
        profile: view.name.clone(),
        profile_hash: None,
        device: "d".into(),
        time: "2026-12-03T00:00:00Z".into(),
        unit: 1,
        connection: "in-memory".into(),
        identification: "none".into(),
    };
    let backup = Backup { header, identification: Vec::new(), entries };
    let back = Backup::parse(&backup.render(), "b.toml").unwrap();
    assert_eq!(back.header, backup.header);
    assert_eq!(
        back.entry("P3").map(|e| &e.state),
        Some(&State::Value { raw: toml::Value::Integer(13), shown: "1.3 Hz".into() })
    );
    assert!(matches!(back.entry("P2").map(|e| &e.state), Some(State::Failed(_))));
}

/// Stops the reads once `after` parameters have their outcome.
struct StopAfter {
    after: u64,
    done: u64,
}

impl Watch for StopAfter {
    fn stop(&mut self) -> impl Future<Output = ()> {
        let stop = self.done >= self.after;
        async move {
            if !stop {
                std::future::pending::<()>().await;
            }
        }
    }

    fn progress(&mut self, done: u64) {
        self.done += done;
    }
}

#[tokio::test(start_paused = true)]
async fn a_stop_between_two_requests_sends_nothing_more_and_marks_the_rest_not_read() {
    let text = PROFILE.replace("[[registers]]\nnumber=2\nname='P2'", "[[inputs]]\nnumber=2\nname='P2'");
    let view = View { name: "d.toml".into(), hash: None, profile: Profile::parse(&text, "d.toml").unwrap() };
    let drive = Arc::new(Mutex::new(Drive::default()));
    let client = client(&drive).await;
    let params: Vec<_> = view.profile.points().iter().filter(|p| p.code != "P2").collect();
    // P2 is an input register now: the holding reads are P0..P1 and P3 (the planner does not
    // read across an unmapped register); the stop comes after the first.
    let mut watch = StopAfter { after: 1, done: 0 };
    let readings = device::read(Target { client: &client, unit: 1 }, &view, &params, &mut watch).await;
    assert_eq!(drive.lock().unwrap().reads, [(0, 2)], "nothing sent past the stop");
    assert!(readings.interrupted);
    assert_eq!((readings.values["P0"].clone(), readings.values["P1"].clone()), (Ok(vec![10]), Ok(vec![11])));
    assert_eq!(readings.values["P3"], Err(INTERRUPTED.to_string()));
}

#[tokio::test(start_paused = true)]
async fn a_refused_write_stops_only_what_depends_on_it_and_the_order_puts_dependencies_first() {
    let text = PROFILE
        .replace("name='P0'", "name='P0'\ndepends_on=['P3']")
        .replace("name='P2'", "name='P2'\ndepends_on=['P1']");
    let view = View { name: "d.toml".into(), hash: None, profile: Profile::parse(&text, "d.toml").unwrap() };
    let drive = Arc::new(Mutex::new(Drive::default()));
    let client = client(&drive).await;
    let mut items: Vec<Item<'_>> = view
        .profile
        .points()
        .iter()
        .map(|param| Item {
            param,
            raw: Value::Int(7),
            words: vec![7],
            before: String::new(),
            outcome: Outcome::Pending,
        })
        .collect();
    restore::order(&mut items).unwrap();
    let codes: Vec<&str> = items.iter().map(|i| i.param.code.as_str()).collect();
    assert_eq!(codes, ["P1", "P2", "P3", "P0"], "P3 before P0, P1 before P2");
    let stopped = restore::apply(Target { client: &client, unit: 1 }, &view, &mut items, &mut Unwatched).await;
    assert!(!stopped);
    assert_eq!(drive.lock().unwrap().writes, [(3, 7), (0, 7)], "P3 and P0 written; P1 refused, P2 not tried");
    let outcome = |code: &str| items.iter().find(|i| i.param.code == code).map(|i| i.outcome.clone()).unwrap();
    assert!(
        matches!(outcome("P1"), Outcome::NotWritten(why) if why.starts_with("exception 0x03")),
        "{:?}",
        outcome("P1")
    );
    assert_eq!(outcome("P2"), Outcome::NotWritten("it depends on P1, which was not written".into()));
    assert_eq!((outcome("P3"), outcome("P0")), (Outcome::Pending, Outcome::Pending), "written, to be verified");
    let p3 = items.iter().find(|i| i.param.code == "P3").unwrap();
    assert_eq!(restore::verify(p3, Some(&Ok(vec![7]))), Outcome::Verified);
    assert!(matches!(restore::verify(p3, Some(&Ok(vec![8]))), Outcome::Unverified(_)));
}
