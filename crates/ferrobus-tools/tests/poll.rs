//! The poller against a server engine on an in-memory line, on tokio's paused clock: the rate
//! kept from the start over many periods, overruns on a line too slow for the period, every
//! failure a sample with its kind and counted, pause, reset and the write-through; the
//! session file.

// The transport crate's test support: one in-memory unit, MBAP by hand, its devices.
#[path = "../../ferrobus/tests/support/mod.rs"]
mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ferrobus::server::Shared;
use ferrobus::{Client, ClientConfig, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::slave::Handler;
use ferrobus_tools::poll::session::Session;
use ferrobus_tools::poll::{
    Event, FailureKind, Format, Group, Layout, PollConfig, Poller, RawRange, Sample, Table, Value, WriteError,
};

/// 100 holding registers; reads of register 50 are refused while `refuse` is set.
struct Device {
    registers: Vec<u16>,
    refuse: Arc<AtomicBool>,
}

impl Handler for Device {
    fn read_holding_registers(&mut self, _: u8, start: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        let from = usize::from(start);
        let to = from + out.len();
        if self.refuse.load(Ordering::SeqCst) && (from..to).contains(&50) {
            return Err(ExceptionCode::ServerDeviceFailure);
        }
        out.copy_from_slice(self.registers.get(from..to).ok_or(ExceptionCode::IllegalDataAddress)?);
        Ok(())
    }
    fn write_single_register(&mut self, _: u8, address: u16, value: u16) -> Result<(), ExceptionCode> {
        *self.registers.get_mut(usize::from(address)).ok_or(ExceptionCode::IllegalDataAddress)? = value;
        Ok(())
    }
    fn write_multiple_registers(
        &mut self,
        _: u8,
        start: u16,
        values: ferrobus_proto::pdu::Registers<'_>,
    ) -> Result<(), ExceptionCode> {
        let from = usize::from(start);
        let to = from + values.len();
        values.copy_to(self.registers.get_mut(from..to).ok_or(ExceptionCode::IllegalDataAddress)?);
        Ok(())
    }
}

use support::timing;

/// A transport to a server engine answering unit 1.
fn transport(refuse: Arc<AtomicBool>) -> Transport {
    support::in_memory("in-memory bus", Shared::new(Device { registers: (0..100).collect(), refuse }))
}

async fn client(refuse: &Arc<AtomicBool>) -> Client {
    let config = ClientConfig { timeout: Duration::from_millis(50), backoff: None, ..ClientConfig::default() };
    Client::connect(transport(Arc::clone(refuse)), config).await.unwrap()
}

fn group(name: &str, unit: u8, start: u16, count: u16, every_ms: u64) -> Group {
    let range = RawRange { unit, table: Table::Holding, start, count, every: Duration::from_millis(every_ms) };
    Group::raw(name, range, &Layout::default()).unwrap()
}

async fn samples(poller: &mut Poller, n: usize) -> Vec<Sample> {
    let mut out = Vec::new();
    while out.len() < n {
        match poller.next().await.expect("the poller runs") {
            Event::Sample(s) => out.push(s),
            Event::Overload(o) => panic!("no overload expected: {}", o.detail),
        }
    }
    out
}

#[tokio::test(start_paused = true)]
async fn the_rate_is_kept_from_the_start_without_drift_over_a_thousand_periods() {
    let refuse = Arc::new(AtomicBool::new(false));
    let mut poller = Poller::start(client(&refuse).await, vec![group("g", 1, 0, 4, 10)], PollConfig::default());
    let got = samples(&mut poller, 1000).await;
    for (k, s) in got.iter().enumerate() {
        let k = u32::try_from(k).unwrap();
        assert_eq!(s.seq, u64::from(k));
        assert_eq!(s.due, Duration::from_millis(10) * k, "poll {k} due on the grid from the start");
        assert!(s.started >= s.due, "poll {k} never early");
        assert!(
            s.started.checked_sub(s.due).unwrap() < Duration::from_millis(10),
            "poll {k} started within its period"
        );
        assert!(!s.overrun);
        let values: Vec<&Value> = s.result.as_ref().unwrap().iter().map(|r| r.raw.as_ref().unwrap()).collect();
        assert_eq!(values, [&Value::Int(0), &Value::Int(1), &Value::Int(2), &Value::Int(3)]);
    }
    let c = &poller.handle().counters()[0];
    assert_eq!((c.polls, c.ok, c.failed(), c.overruns), (1000, 1000, 0, 0));
    // Unit, function, start, count out; unit, function, byte count, 8 data bytes back.
    assert_eq!(got[0].traffic.tx, [1, 0x03, 0, 0, 0, 4]);
    assert_eq!(got[0].traffic.rx.as_deref(), Some(&[1, 0x03, 8, 0, 0, 0, 1, 0, 2, 0, 3][..]));
    assert_eq!((c.tx_bytes, c.rx_bytes), (6000, 11_000));
}

/// Over a pipelined Modbus/TCP connection the poller has as many groups under way as the
/// connection carries, never two polls of one group: a device that holds every request until
/// no more come sees the three groups together in each round (one at a time would stall it
/// at the first), though each is overdue while it waits and four may be in flight.
#[tokio::test]
async fn a_pipelined_connection_gets_every_due_group_at_once_and_never_one_group_twice() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let device = tokio::spawn(async move {
        let (mut stream, _) = listener.accept().await.unwrap();
        let mut rounds = Vec::new();
        for _ in 0..3 {
            let mut held = vec![support::pipelined::asked(&mut stream).await];
            while let Ok(asked) =
                tokio::time::timeout(Duration::from_millis(200), support::pipelined::asked(&mut stream)).await
            {
                held.push(asked);
            }
            let mut registers: Vec<u16> = held.iter().map(|a| a.register).collect();
            registers.sort_unstable();
            rounds.push(registers);
            for asked in held.into_iter().rev() {
                support::pipelined::answer(&mut stream, asked).await;
            }
        }
        rounds
    });
    let config = support::pipelined::pipelined(4, Duration::from_secs(5), 0);
    let client = Client::connect(Transport::tcp(addr.to_string()), config).await.unwrap();
    assert_eq!(client.in_flight(), 4);
    let groups = vec![group("a", 1, 10, 1, 10), group("b", 1, 11, 1, 10), group("c", 1, 12, 1, 10)];
    let mut poller = Poller::start(client, groups, PollConfig::default());
    let (mut got, mut overloads) = (Vec::new(), 0);
    while got.len() < 9 {
        match poller.next().await.expect("the poller runs") {
            Event::Sample(s) => got.push(s),
            Event::Overload(o) => overloads += usize::from(o.seen),
        }
    }
    poller.handle().stop();
    assert_eq!(overloads, 1, "the overruns are said once");
    assert_eq!(device.await.unwrap(), [[10, 11, 12]; 3], "each round: every group once, together");
    for s in &got {
        let register = 10 + u16::try_from(s.group).unwrap();
        let values: Vec<&Value> = s.result.as_ref().unwrap().iter().map(|r| r.raw.as_ref().unwrap()).collect();
        assert_eq!(values, [&Value::Int(i128::from(support::pipelined::value(register)))], "group {}", s.group);
        assert!(s.overrun, "held past the next deadline");
    }
    for group in 0..3 {
        let seqs: Vec<u64> = got.iter().filter(|s| s.group == group).map(|s| s.seq).collect();
        assert_eq!(seqs, [0, 1, 2], "group {group}");
    }
}

/// A poller of raw values only hands out what the group decodes, unscaled and unshown, and
/// the same raw values as one that shows them.
#[tokio::test(start_paused = true)]
async fn a_raw_only_poller_hands_out_the_raw_values_without_showing_them() {
    let refuse = Arc::new(AtomicBool::new(false));
    let mut raw = Poller::start(
        client(&refuse).await,
        vec![group("g", 1, 4, 2, 10)],
        PollConfig { raw_only: true, ..PollConfig::default() },
    );
    let mut shown = Poller::start(client(&refuse).await, vec![group("g", 1, 4, 2, 10)], PollConfig::default());
    let (raw, shown) = (samples(&mut raw, 1).await, samples(&mut shown, 1).await);
    let (raw, shown) = (raw[0].result.as_ref().unwrap(), shown[0].result.as_ref().unwrap());
    for (r, s) in raw.iter().zip(shown) {
        assert_eq!((r.cell, &r.raw), (s.cell, &s.raw));
        assert_eq!((r.scaled, r.shown.as_str()), (None, ""), "raw only");
        assert!(!s.shown.is_empty(), "shown: {s:?}");
    }
    assert_eq!(raw.iter().map(|r| r.raw.clone().unwrap()).collect::<Vec<_>>(), [Value::Int(4), Value::Int(5)]);
}

#[tokio::test(start_paused = true)]
async fn groups_run_at_their_own_rates_and_units_are_told_apart() {
    let refuse = Arc::new(AtomicBool::new(false));
    let groups = vec![group("fast", 1, 0, 1, 50), group("slow", 1, 10, 2, 175), group("slower", 1, 20, 3, 500)];
    let mut poller = Poller::start(client(&refuse).await, groups, PollConfig::default());
    let got = samples(&mut poller, 150).await;
    let last_due = got.last().unwrap().due;
    for (index, every) in [(0usize, 50u64), (1, 175), (2, 500)] {
        let mine: Vec<&Sample> = got.iter().filter(|s| s.group == index).collect();
        for (k, s) in mine.iter().enumerate() {
            assert_eq!(s.due, Duration::from_millis(every) * u32::try_from(k).unwrap(), "group {index} poll {k}");
        }
        // Every slot up to the last one seen was polled, none skipped.
        let expected = last_due.as_millis() / u128::from(every);
        assert!(mine.len() as u128 >= expected, "group {index}: {} polls by {last_due:?}", mine.len());
    }
    assert!(got.iter().all(|s| s.result.is_ok() && !s.overrun));
}

#[tokio::test(start_paused = true)]
async fn every_failure_is_a_sample_with_its_kind_and_polling_goes_on() {
    let refuse = Arc::new(AtomicBool::new(true));
    let groups = vec![group("refused", 1, 50, 1, 200), group("silent", 9, 0, 1, 200)];
    let mut poller = Poller::start(client(&refuse).await, groups, PollConfig::default());
    let got = samples(&mut poller, 6).await;
    for s in &got {
        let f = s.result.as_ref().unwrap_err();
        if s.group == 0 {
            assert_eq!(f.kind, FailureKind::Exception);
            assert_eq!(f.exception, Some(0x04));
            assert!(f.diagnosis.contains("exception 0x04"), "{}", f.diagnosis);
            assert_eq!(s.traffic.rx.as_deref(), Some(&[1, 0x83, 0x04][..]));
        } else {
            assert_eq!(f.kind, FailureKind::Timeout);
            assert!(f.diagnosis.contains("no reply from unit 9"), "{}", f.diagnosis);
            assert_eq!(s.traffic.rx, None);
        }
    }
    refuse.store(false, Ordering::SeqCst);
    let more = samples(&mut poller, 4).await;
    assert!(more.iter().filter(|s| s.group == 0).all(|s| s.result.is_ok()), "the device answers again");
    let c = poller.handle().counters();
    assert_eq!(c[0].polls, c[0].ok + c[0].of(FailureKind::Exception));
    assert_eq!(c[0].of(FailureKind::Exception), 3);
    assert_eq!(c[1].of(FailureKind::Timeout), c[1].polls);
    assert_eq!(c[0].polls + c[1].polls, 10);
    let times = poller.handle().response_times();
    assert_eq!(times.iter().map(|t| t.unit).collect::<Vec<_>>(), [1], "unit 9 never answered: no times");
    assert_eq!(times[0].count, c[0].polls);
}

#[tokio::test(start_paused = true)]
async fn a_line_too_slow_for_the_period_is_said_once_with_the_arithmetic_then_polled_flat_out() {
    let refuse = Arc::new(AtomicBool::new(false));
    // 100 registers at 19200 baud: (8 + 205) characters × 573 µs + 2 × 1.75 ms ≈ 125.6 ms
    // on the wire, every 50 ms.
    let line = Some(timing());
    let mut poller = Poller::start(
        client(&refuse).await,
        vec![group("big", 1, 0, 100, 50)],
        PollConfig { line, ..PollConfig::default() },
    );
    let Some(Event::Overload(o)) = poller.next().await else { panic!("the overload is said first") };
    assert!(!o.seen);
    assert!(o.detail.contains("(8 + 205) characters"), "{}", o.detail);
    assert!(o.detail.contains("every 50.000 ms"), "{}", o.detail);
    // The in-memory line is faster than the arithmetic; the poller goes on at its rate and says
    // nothing more.
    let got = samples(&mut poller, 20).await;
    assert!(got.iter().all(|s| s.result.is_ok()));
}

#[tokio::test(start_paused = true)]
async fn polls_that_overrun_are_counted_and_the_next_goes_at_once_on_the_original_grid() {
    let refuse = Arc::new(AtomicBool::new(false));
    // Unit 9 is silent: each poll takes the 50 ms timeout, against a 20 ms period.
    let mut poller = Poller::start(client(&refuse).await, vec![group("slow", 9, 0, 1, 20)], PollConfig::default());
    let Some(Event::Overload(o)) = poller.next().await else { panic!("the first overrun is said") };
    assert!(o.seen);
    assert!(o.detail.contains("was due at 0.000 ms and ended at 5"), "{}", o.detail);
    assert!(o.detail.contains("(period 20.000 ms; its own request took 5"), "{}", o.detail);
    let got = samples(&mut poller, 10).await;
    for pair in got.windows(2) {
        assert!(pair[1].due <= pair[1].started, "never early");
        assert_eq!(pair[1].due.as_nanos() % 20_000_000, 0, "still on the 20 ms grid: {:?}", pair[1].due);
    }
    let c = &poller.handle().counters()[0];
    assert_eq!(c.overruns, c.polls, "every poll overran");
    assert!(c.skipped >= c.polls, "each skipped at least one slot: {c:?}");
}

#[tokio::test(start_paused = true)]
async fn pause_stops_polling_reset_zeroes_the_counters_and_a_write_goes_through() {
    let refuse = Arc::new(AtomicBool::new(false));
    let layout = Layout { format: Format::U16, aliases: vec![(5, "speed".into())], ..Layout::default() };
    let g = Group::raw(
        "g",
        RawRange { start: 4, count: 2, every: Duration::from_millis(10), ..RawRange::default() },
        &layout,
    )
    .unwrap();
    assert_eq!(g.cells[1].name, "speed");
    let mut poller = Poller::start(client(&refuse).await, vec![g], PollConfig::default());
    let handle = poller.handle();
    samples(&mut poller, 3).await;
    handle.pause();
    while poller.try_next().is_some() {}
    let before = handle.counters()[0].polls;
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert_eq!(handle.counters()[0].polls, before, "no polls while paused");
    assert!(poller.try_next().is_none());
    handle.reset();
    assert_eq!(handle.counters()[0], ferrobus_tools::poll::Counters::default());
    assert_eq!(handle.write(None, 0, 1, "1234").await.unwrap(), Value::Int(1234));
    assert!(handle.write(None, 0, 1, "70000").await.is_err(), "a u16 cell takes no 70000");
    assert_eq!(handle.prepare_write(0, 1, "4321").unwrap(), Value::Int(4321), "prepared, not sent");
    assert!(handle.write_raw(None, 0, 1, &Value::Int(70_000)).await.is_err(), "a raw value must fit the type");
    assert!(matches!(
        handle.write_raw(None, 0, 9, &Value::Int(1)).await,
        Err(WriteError::NoSuchCell { group: 0, cell: 9 })
    ));
    handle.resume();
    let s = samples(&mut poller, 1).await.remove(0);
    assert_eq!(s.result.unwrap()[1].shown, "1234");
    assert_eq!(handle.counters()[0].polls, 1);
    handle.pause();
    while poller.try_next().is_some() {}
    handle.write_raw(None, 0, 0, &Value::Int(4321)).await.unwrap();
    handle.resume();
    let s = samples(&mut poller, 1).await.remove(0);
    assert_eq!(s.result.unwrap()[0].shown, "4321", "a raw write goes through as is");
    handle.stop();
    assert!(poller.next().await.is_none(), "stopped: the stream ends");
}

#[test]
fn a_session_round_trips_through_its_file_and_builds_its_groups() {
    let text = r#"
[[read]]
unit = 3
table = "holding"
address = 0x1000
count = 4
format = "hex"
every = "100ms"
[[read.cell]]
address = 0x1002
alias = "speed"
format = "i32"

[[points]]
unit = 1
device = "omron-3g3rx"
names = ["d001"]
every = "500ms"
"#;
    let session = Session::parse(text, "s.toml").unwrap();
    let dir = std::env::temp_dir().join(format!("ferrobus-poll-session-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("s.toml");
    session.save(&path).unwrap();
    assert_eq!(Session::load(&path).unwrap(), session);
    std::fs::remove_dir_all(&dir).unwrap();
    let groups =
        session.groups("s.toml", |name| ferrobus_profile::Profile::load(name).map_err(|e| e.to_string())).unwrap();
    assert_eq!(groups.len(), 2);
    let raw = &groups[0];
    assert_eq!((raw.unit, raw.start, raw.count, raw.every), (3, 0x1000, 4, Duration::from_millis(100)));
    let names: Vec<&str> = raw.cells.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["0x1000", "0x1001", "speed"]);
    assert_eq!(raw.cells[0].show(&Value::Int(0x1F4)), "0x01f4");
    assert_eq!(groups[1].cells[0].name, "d001");
    assert_eq!(groups[1].every, Duration::from_millis(500));
}

#[test]
fn a_cells_own_order_is_polled_in_that_order_and_the_monitors_trends_are_ignored() {
    let text = r#"
[[read]]
unit = 1
table = "holding"
address = 0
count = 4
format = "u32"
order = "CDAB"
[[read.cell]]
address = 2
order = "DCBA"
trend = true

[[points]]
unit = 1
device = "omron-3g3rx"
names = ["d001"]
trends = ["d001"]
"#;
    let session = Session::parse(text, "s.toml").unwrap();
    assert_eq!(Session::parse(&session.to_toml(), "again").unwrap(), session, "the new keys round-trip");
    let groups =
        session.groups("s.toml", |name| ferrobus_profile::Profile::load(name).map_err(|e| e.to_string())).unwrap();
    assert_eq!(groups.len(), 2);
    // 0x00010002 in CDAB is 0002 0001; in DCBA it is 0200 0100.
    let values = groups[0].decode(&[0x0002, 0x0001, 0x0200, 0x0100]);
    assert_eq!(values, [Ok(Value::Int(0x0001_0002)), Ok(Value::Int(0x0001_0002))]);
    let s = Session::parse(&text.replace("order = \"DCBA\"", "order = \"DXBA\""), "s").unwrap();
    let e = s.groups("s", |_| unreachable!()).unwrap_err();
    assert_eq!(e.to_string(), "s: read 1: order \"DXBA\": give ABCD, CDAB, BADC or DCBA");
}

#[test]
fn a_broken_session_names_the_file_the_line_and_the_definition() {
    let e = Session::parse("[[read]]\nunit = 3\ntable = \"holding\"\naddres = 1\n", "s.toml").unwrap_err();
    assert!(e.to_string().starts_with("s.toml:4:1: unknown field `addres`"), "{e}");
    assert!(e.to_string().ends_with("(in `addres = 1`)"), "{e}");
    let huge = format!("[[read]]\nunit = 3\ntable = \"{}\"\naddress = 1\n", "h".repeat(10 << 20));
    let e = Session::parse(&huge, "s.toml").unwrap().groups("s.toml", |_| unreachable!()).unwrap_err();
    assert!(e.to_string().len() < 1_000, "{} bytes", e.to_string().len());
    let s = Session::parse("[[read]]\nunit = 3\ntable = \"holdings\"\naddress = 1\n", "s.toml").unwrap();
    let e = s.groups("s.toml", |_| unreachable!()).unwrap_err();
    assert_eq!(e.to_string(), "s.toml: read 1: table \"holdings\": give holding, input, coils or discrete");
    let s = Session::parse("[[read]]\nunit = 3\ntable = \"holding\"\naddress = 0\ncount = 3\nformat = \"u32\"\n", "s")
        .unwrap();
    let e = s.groups("s", |_| unreachable!()).unwrap_err();
    assert!(e.to_string().contains("the u32 at 0x0002 takes 2 registers, past the end"), "{e}");
    let s =
        Session::parse("[[read]]\nunit = 3\ntable = \"holding\"\naddress = 0\nevery = \"10 parsecs\"\n", "s").unwrap();
    assert!(s.groups("s", |_| unreachable!()).unwrap_err().to_string().contains("unknown unit"));
}

#[test]
fn session_values_are_refused_with_typed_errors_that_say_what_they_take() {
    use ferrobus_tools::poll::session::{DefError, order_of, period, table_from_name};
    assert_eq!(table_from_name(" Coils"), Ok(Table::Coils));
    assert_eq!(table_from_name(" Holdings"), Err(DefError::Table { name: "holdings".into() }));
    assert_eq!(order_of(None), Ok(None));
    assert_eq!(order_of(Some("DXBA")), Err(DefError::Order { name: "DXBA".into() }));
    assert_eq!(period(None), Ok(Duration::from_secs(1)));
    assert_eq!(period(Some("250us")), Ok(Duration::from_micros(250)));
    assert_eq!(period(Some("5h")), Ok(Duration::from_secs(5 * 3600)));
    assert!(matches!(period(Some("fast")), Err(DefError::Period(_))));
    assert!(matches!(period(Some("5 parsecs")), Err(DefError::Period(_))));
    assert_eq!(period(Some("0ms")), Err(DefError::PeriodRange { text: "0ms".into() }));
    assert_eq!(period(Some("25h")), Err(DefError::PeriodRange { text: "25h".into() }));
    let refused = period(Some("5 parsecs")).unwrap_err().to_string();
    assert!(refused.starts_with("period: '5 parsecs' is not a duration: unknown unit 'parsecs'"), "{refused}");
}
