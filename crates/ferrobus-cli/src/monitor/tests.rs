//! The monitor's screens on ratatui's `TestBackend`, as insta snapshots (80×24 and 120×40),
//! and the keys' effects on the state.

use std::time::Duration;

use ferrobus_profile::{Order, Profile, Table, Value, WireWrite};
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

use super::keys::{self, Action};
use super::model::{App, Definition, Format, Mode, Outcome, TrafficLine};
use super::{MonitorArgs, spec, view};

fn render(app: &App, width: u16, height: u16) -> String {
    let mut terminal = Terminal::new(TestBackend::new(width, height)).unwrap();
    terminal.draw(|frame| view::draw(frame, app)).unwrap();
    terminal.backend().to_string()
}

fn key(app: &mut App, code: KeyCode) -> Action {
    keys::handle(app, KeyEvent::new(code, KeyModifiers::NONE))
}

/// Two panes with data, failures of each kind, traffic and a trended cell.
fn busy() -> App {
    let mut holding = Definition::raw(1, Table::Holding, 0x0000, 10, Duration::from_millis(500));
    let mut input = Definition::raw(2, Table::Input, 0x0100, 4, Duration::from_secs(1));
    for (i, value) in [1200u16, 1210, 1230, 1225].iter().enumerate() {
        let mut registers: Vec<u16> = (0..10).map(|r| r * 100).collect();
        registers[0] = *value;
        registers[4] = 0x4049; // f32 3.14159 in ABCD over 4..6
        registers[5] = 0x0FD0;
        registers[6] = 0xFFFF;
        holding.record(Outcome::Registers(registers), Duration::from_micros(3200 + 100 * i as u64));
    }
    holding.record(Outcome::Timeout("no reply from unit 1 within 1000 ms (1 attempt)".into()), Duration::ZERO);
    input.record(Outcome::Registers(vec![7, 8, 9, 10]), Duration::from_micros(2100));
    input.record(Outcome::Crc("no valid reply from unit 2: bad CRC".into()), Duration::ZERO);
    input.record(
        Outcome::Exception("unit 2 answered 0x04 with exception 02 illegal data address".into()),
        Duration::from_micros(1900),
    );
    holding.cells[0].alias = "speed".into();
    holding.cells[4].set_format(Format::F32(Order::Abcd));
    holding.cells[6].set_format(Format::I16);
    holding.cells[7].set_format(Format::Hex);
    holding.cells[8].set_format(Format::Binary);
    let mut app = App::new("tcp 127.0.0.1:5020".into(), vec![holding, input]);
    app.traffic.push(TrafficLine {
        at: Duration::from_millis(1500),
        direction: "Tx",
        unit: 1,
        bytes: vec![0x03, 0x00, 0x00, 0x00, 0x0A],
        decode: "read holding 0x0000 ×10".into(),
    });
    app.traffic.push(TrafficLine {
        at: Duration::from_millis(1503),
        direction: "Rx",
        unit: 1,
        bytes: vec![0x03, 0x14, 0x04, 0xB0],
        decode: "10 registers".into(),
    });
    app.traffic.push(TrafficLine {
        at: Duration::from_millis(2503),
        direction: "--",
        unit: 1,
        bytes: vec![],
        decode: "no reply from unit 1 within 1000 ms (1 attempt)".into(),
    });
    app
}

fn with_trend(mut app: App) -> App {
    app.toggle_trend();
    for (t, v) in [(0.0, 1200.0), (0.5, 1210.0), (1.0, 1230.0), (1.5, 1225.0)] {
        if let Some(trend) = app.trends.first_mut() {
            trend.samples.push_back((t, v));
        }
    }
    app
}

#[test]
fn the_busy_screen_at_80x24() {
    insta::assert_snapshot!(render(&busy(), 80, 24));
}

#[test]
fn the_busy_screen_with_a_trend_at_120x40() {
    insta::assert_snapshot!(render(&with_trend(busy()), 120, 40));
}

#[test]
fn the_confirmation_of_a_write_at_80x24() {
    let mut app = busy();
    key(&mut app, KeyCode::Char('e'));
    for c in "4660".chars() {
        key(&mut app, KeyCode::Char(c));
    }
    key(&mut app, KeyCode::Enter);
    assert_eq!(
        app.mode,
        Mode::Confirm {
            text: "4660".into(),
            raw: Value::Int(0x1234),
            request: WireWrite::Register { address: 0, value: 0x1234 }
        }
    );
    insta::assert_snapshot!(render(&app, 80, 24));
    assert_eq!(
        key(&mut app, KeyCode::Char('y')),
        Action::Write(keys::Asked {
            pane: 0,
            cell: 0,
            raw: Value::Int(0x1234),
            text: "4660".into(),
            request: WireWrite::Register { address: 0, value: 0x1234 }
        })
    );
}

#[test]
fn the_80x24_screen_shows_every_pane_status_the_keys_and_the_traffic() {
    let screen = render(&busy(), 80, 24);
    assert!(screen.contains("Tx 5  Err 1 (timeout 1, CRC 0, exception 0, other 0)  last 3.5 ms"), "{screen}");
    assert!(screen.contains("Tx 3  Err 2 (timeout 0, CRC 1, exception 1, other 0)  last 1.9 ms"), "{screen}");
    assert!(screen.contains("q quit"), "{screen}");
    assert!(screen.contains("03 00 00 00 0A"), "{screen}");
}

#[test]
fn cells_show_each_format() {
    let app = busy();
    let pane = &app.panes[0];
    let shown: Vec<String> = pane.cells.iter().map(|c| c.show(pane).unwrap()).collect();
    assert_eq!(shown[0], "1225");
    assert_eq!(shown[4], "3.14159");
    assert_eq!(shown[6], "-1");
    assert_eq!(shown[7], "0x02bc");
    assert_eq!(shown[8], "0000 0011 0010 0000");
}

#[test]
fn the_four_orders_decode_the_same_float_from_their_own_layouts() {
    // 1.5f32 = 0x3FC00000: ABCD 3FC0 0000, CDAB 0000 3FC0, BADC C03F 0000, DCBA 0000 C03F.
    for (order, words) in [
        (Order::Abcd, [0x3FC0, 0x0000]),
        (Order::Cdab, [0x0000, 0x3FC0]),
        (Order::Badc, [0xC03F, 0x0000]),
        (Order::Dcba, [0x0000, 0xC03F]),
    ] {
        let mut pane = Definition::raw(1, Table::Holding, 0, 2, Duration::from_secs(1));
        pane.record(Outcome::Registers(words.to_vec()), Duration::ZERO);
        pane.cells[0].set_format(Format::F32(order));
        assert_eq!(pane.cells[0].show(&pane).as_deref(), Some("1.5"), "{order:?}");
    }
    let mut pane = Definition::raw(1, Table::Holding, 0, 4, Duration::from_secs(1));
    pane.record(Outcome::Registers(vec![0x0000, 0x0000, 0x0000, 0xF83F]), Duration::ZERO); // 1.5f64 in DCBA
    pane.cells[0].set_format(Format::F64(Order::Dcba));
    assert_eq!(pane.cells[0].show(&pane).as_deref(), Some("1.5"));
}

#[test]
fn f_cycles_the_formats_and_o_the_orders() {
    let mut app = busy();
    app.cell = 1;
    let mut seen = Vec::new();
    for _ in 0..8 {
        key(&mut app, KeyCode::Char('f'));
        seen.push(app.panes[0].cells[1].format.name());
    }
    assert_eq!(seen, ["i16", "hex", "bin", "u32:ABCD", "i32:ABCD", "f32:ABCD", "f64:ABCD", "u16"]);
    app.panes[0].cells[1].set_format(Format::U32(Order::Abcd));
    let orders: Vec<String> = (0..4)
        .map(|_| {
            key(&mut app, KeyCode::Char('o'));
            app.panes[0].cells[1].format.name()
        })
        .collect();
    assert_eq!(orders, ["u32:CDAB", "u32:BADC", "u32:DCBA", "u32:ABCD"]);
}

#[test]
fn pause_reset_and_the_traffic_pause_keys_change_the_state() {
    let mut app = busy();
    key(&mut app, KeyCode::Char('p'));
    assert!(app.paused);
    assert!(render(&app, 80, 24).contains("PAUSED"));
    key(&mut app, KeyCode::Char('p'));
    assert!(!app.paused);
    key(&mut app, KeyCode::Char('r'));
    assert!(app.panes.iter().all(|p| p.counters.tx == 0 && p.counters.errors() == 0));
    key(&mut app, KeyCode::Char(' '));
    let before = app.traffic.lines.len();
    app.traffic.push(TrafficLine {
        at: Duration::ZERO,
        direction: "Tx",
        unit: 1,
        bytes: vec![3],
        decode: String::new(),
    });
    assert_eq!(app.traffic.lines.len(), before);
    assert!(render(&app, 80, 24).contains("paused, 1 not shown"));
    key(&mut app, KeyCode::PageUp);
    assert!(app.traffic.scroll > 0);
    assert_eq!(key(&mut app, KeyCode::Char('q')), Action::None);
    assert!(app.quit);
}

#[test]
fn a_write_out_of_the_points_range_is_refused_before_anything_is_sent() {
    let profile = Profile::builtin("omron-3g3rx").unwrap();
    let point = profile.points().iter().find(|p| p.writable() && p.max.is_some()).unwrap().clone();
    let too_big = point.max.unwrap() + 1.0;
    let mut pane = spec::parse(&point.code, 1, Some(&profile)).unwrap().remove(0);
    pane.record(Outcome::Registers(vec![0; usize::from(pane.count)]), Duration::ZERO);
    let mut app = App::new("t".into(), vec![pane]);
    key(&mut app, KeyCode::Char('e'));
    // A raw value past max, in the point's engineering units.
    let text = format!("{}", too_big * point.scale + point.offset);
    for c in text.chars() {
        key(&mut app, KeyCode::Char(c));
    }
    assert_eq!(key(&mut app, KeyCode::Enter), Action::None);
    assert_eq!(app.mode, Mode::Normal);
    let message = app.message.clone().unwrap();
    assert!(message.starts_with("not written:"), "{message}");
}

#[test]
fn read_only_tables_refuse_an_edit() {
    let mut app = busy();
    key(&mut app, KeyCode::Tab);
    key(&mut app, KeyCode::Char('e'));
    key(&mut app, KeyCode::Char('1'));
    key(&mut app, KeyCode::Enter);
    assert_eq!(app.mode, Mode::Normal);
    assert_eq!(app.message.as_deref(), Some("input are read-only"));
}

#[test]
fn definitions_parse_with_unit_count_and_rate_and_bad_ones_say_why() {
    let d = spec::parse("3:input:0x100:8@250ms", 1, None).unwrap().remove(0);
    assert_eq!((d.unit, d.table, d.address, d.count, d.every), (3, Table::Input, 0x100, 8, Duration::from_millis(250)));
    let d = spec::parse("holding:5", 7, None).unwrap().remove(0);
    assert_eq!((d.unit, d.address, d.count, d.every), (7, 5, 1, spec::DEFAULT_EVERY));
    let err = |s: &str| spec::parse(s, 1, None).err().map(|e| format!("{e:?}")).unwrap();
    assert!(err("holding:0:126").contains("1 to 125"), "{}", err("holding:0:126"));
    assert!(err("holding:0xFFFF:2").contains("passes the last address"));
    assert!(err("holding:x").contains("'x' is not a number"));
    assert!(err("speed").contains("need --device"));
    assert!(err("holding:0@1ms").contains("under 10 ms"));
}

#[test]
fn the_trend_bounds_come_from_the_data_not_from_zero() {
    assert_eq!(view::bounds([2900.0, 3020.0].into_iter()), Some([2888.0, 3032.0]));
    assert_eq!(view::bounds([5.0].into_iter()), Some([4.0, 6.0]));
    assert_eq!(view::bounds(std::iter::empty()), None);
}

#[test]
fn a_session_file_round_trips_formats_aliases_and_points_in_polls_format() {
    let mut raw = Definition::raw(3, Table::Holding, 0x10, 6, Duration::from_millis(250));
    raw.cells[0].alias = "speed".into();
    raw.cells[2].set_format(Format::F32(Order::Cdab));
    raw.cells[5].set_format(Format::Hex);
    let profile = Profile::builtin("omron-3g3rx").unwrap();
    let code = profile.points().iter().find(|p| p.readable() && p.table == Table::Holding).unwrap().code.clone();
    let mut panes = vec![raw];
    panes.extend(spec::parse(&format!("{code}@2s"), 1, Some(&profile)).unwrap());
    let session = spec::session_of(Some("omron-3g3rx"), &panes);
    let dir = std::env::temp_dir().join(format!("ferrobus-monitor-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("s.toml");
    session.save(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("[[read]]") && text.contains("[[points]]") && text.contains("order = \"CDAB\""), "{text}");
    let loaded = ferrobus_tools::poll::session::Session::load(&path).unwrap();
    assert_eq!(loaded, session);
    // The poll library reads the same file into its own groups.
    assert_eq!(loaded.groups("s.toml", |name| Profile::load(name).map_err(|e| e.to_string())).unwrap().len(), 2);
    let fresh = spec::panes_of(&loaded, "s.toml").unwrap();
    assert_eq!(fresh.len(), 2);
    let (a, b) = (&fresh[0], &fresh[1]);
    assert_eq!((a.unit, a.address, a.count, a.every), (3, 0x10, 6, Duration::from_millis(250)));
    assert_eq!(a.cells[0].alias, "speed");
    assert_eq!(a.cells[2].format, Format::F32(Order::Cdab));
    assert_eq!(a.cells[5].format, Format::Hex);
    assert_eq!(
        (b.every, b.cells[0].point.code.as_str(), b.cells[0].format),
        (Duration::from_secs(2), code.as_str(), Format::Named)
    );
    std::fs::write(&path, "[[read]]\nunit = 1\ntable = \"holding\"\naddress = 0\nformat = \"f16\"\n").unwrap();
    let loaded = ferrobus_tools::poll::session::Session::load(&path).unwrap();
    let err = format!("{:?}", spec::panes_of(&loaded, "s.toml").err().unwrap());
    assert!(err.contains("read 1") && err.contains("'f16' is not a format"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The redraw benchmark (bench/monitor.sh runs it, in release): 200 cells in two panes of 100
/// registers, every value changed before each frame, drawn 2,000 times on a 160×60 screen,
/// through ratatui's diff into crossterm's escape sequences (written to a sink). Prints the
/// median, p90, p99 and max per frame.
#[test]
#[ignore = "a benchmark: bench/monitor.sh"]
fn bench_redraw_of_a_200_cell_grid() {
    use ratatui::backend::CrosstermBackend;
    let panes = vec![
        Definition::raw(1, Table::Holding, 0, 100, Duration::from_millis(100)),
        Definition::raw(2, Table::Input, 0, 100, Duration::from_millis(100)),
    ];
    let mut app = with_trend(App::new("tcp 127.0.0.1:502".into(), panes));
    let mut terminal = Terminal::with_options(
        CrosstermBackend::new(std::io::sink()),
        ratatui::TerminalOptions { viewport: ratatui::Viewport::Fixed(ratatui::layout::Rect::new(0, 0, 160, 60)) },
    )
    .unwrap();
    let cells: usize = app.panes.iter().map(|p| p.cells.len()).sum();
    assert_eq!(cells, 200);
    let frames = 2000u16;
    let mut times = Vec::with_capacity(usize::from(frames));
    for frame in 0..frames {
        for pane in &mut app.panes {
            let registers = (0..100u16).map(|r| r.wrapping_mul(31).wrapping_add(frame)).collect();
            pane.record(Outcome::Registers(registers), Duration::from_millis(3));
        }
        app.sample(0, Duration::from_millis(u64::from(frame) * 100));
        app.traffic.push(TrafficLine {
            at: Duration::from_millis(u64::from(frame) * 100),
            direction: "Rx",
            unit: 1,
            bytes: vec![0x03, 0xC8, 0x00, 0x01],
            decode: "100 registers".into(),
        });
        let start = std::time::Instant::now();
        terminal.draw(|f| view::draw(f, &app)).unwrap();
        times.push(start.elapsed());
    }
    times.sort();
    let at = |q: usize| times[(times.len() - 1) * q / 100];
    println!(
        "redraw of {cells} cells at 160x60, {frames} frames: median {:?}, p90 {:?}, p99 {:?}, max {:?}",
        at(50),
        at(90),
        at(99),
        times[times.len() - 1]
    );
}

#[test]
fn a_pollers_samples_fill_the_pane_its_counters_by_kind_and_the_traffic() {
    use ferrobus_tools::poll::{Failure, FailureKind, Sample, Traffic};
    let mut app = App::new("t".into(), vec![Definition::raw(4, Table::Holding, 0x10, 2, Duration::from_secs(1))]);
    let sample = |result, rx: Option<Vec<u8>>| Sample {
        group: 0,
        seq: 0,
        time: std::time::SystemTime::UNIX_EPOCH,
        due: Duration::ZERO,
        started: Duration::ZERO,
        response_time: Duration::from_micros(2500),
        overrun: false,
        result,
        traffic: Traffic { tx: vec![4, 0x03, 0x00, 0x10, 0x00, 0x02], rx },
    };
    let start = std::time::Instant::now();
    let read = super::Read { pane: 0, start: 0x10, count: 2 };
    super::take(&mut app, start, read, &sample(Ok(Vec::new()), Some(vec![4, 0x03, 0x04, 0x12, 0x34, 0xAB, 0xCD])));
    let failure = |kind| Failure { kind, exception: None, diagnosis: format!("{kind:?} seen") };
    for kind in [FailureKind::Timeout, FailureKind::Crc, FailureKind::Crc, FailureKind::Exception, FailureKind::Port] {
        super::take(&mut app, start, read, &sample(Err(failure(kind)), None));
    }
    let pane = &app.panes[0];
    assert_eq!(pane.registers, [0x1234, 0xABCD]);
    let c = pane.counters;
    assert_eq!((c.tx, c.ok, c.timeouts, c.crc, c.exceptions, c.other), (6, 1, 1, 2, 1, 1));
    assert_eq!(pane.last_response, Some(Duration::from_micros(2500)));
    let lines: Vec<(&str, &[u8])> = app.traffic.lines.iter().take(2).map(|l| (l.direction, &l.bytes[..])).collect();
    assert_eq!(lines, [("Tx", &[0x03, 0x00, 0x10, 0x00, 0x02][..]), ("Rx", &[0x03, 0x04, 0x12, 0x34, 0xAB, 0xCD][..])]);
    assert_eq!(app.traffic.lines.back().map(|l| (l.direction, l.decode.as_str())), Some(("--", "Port seen")));
}

#[test]
fn a_pane_of_profile_points_shows_them_scaled_with_units_at_80x24() {
    let profile = Profile::builtin("omron-3g3rx").unwrap();
    let mut panes = spec::parse("d00*@200ms", 1, Some(&profile)).unwrap();
    for pane in &mut panes {
        // 50.00 Hz in d001's 0.01 Hz steps, the rest counting up.
        let registers = (0..pane.count).map(|i| if i == 1 { 5000 } else { i * 3 }).collect();
        pane.record(Outcome::Registers(registers), Duration::from_millis(9));
    }
    let app = App::new("tcp 127.0.0.1:5020".into(), panes);
    insta::assert_snapshot!(render(&app, 80, 24));
}

#[test]
fn left_and_right_move_a_cell_up_and_down_a_row_of_the_grid_as_drawn() {
    let mut app = busy();
    // Two columns at 80: the binary cell's 19 characters set the grid's width.
    assert!(
        render(&app, 80, 24)
            .contains("│ 0000 speed          1225           0001 u16             100                  │")
    );
    key(&mut app, KeyCode::Down);
    assert_eq!(app.cell, 2);
    key(&mut app, KeyCode::Right);
    assert_eq!(app.cell, 3);
    key(&mut app, KeyCode::Up);
    assert_eq!(app.cell, 1);
    key(&mut app, KeyCode::Left);
    key(&mut app, KeyCode::Left);
    assert_eq!(app.cell, 0);
    for _ in 0..10 {
        key(&mut app, KeyCode::Down);
    }
    assert_eq!(app.cell, 9, "the last cell, not past it");
    assert!(render(&app, 80, 24).contains("rows 4-5 of 5 (↑↓ scroll)"), "the grid scrolled to the selection");
}

#[test]
fn a_pane_of_points_far_apart_is_filled_by_the_planners_reads_never_across_an_unmapped_hole() {
    use ferrobus_profile::{Extent, plan};
    let profile = Profile::builtin("omron-3g3rx").unwrap();
    // d001 (0x1000, 2 registers), F002 and A003 are far apart; the 3G3RX maps no spans and
    // reads at most 4 registers a request.
    let mut panes = Vec::new();
    for spec in ["d001", "F002", "A003"] {
        panes.extend(spec::parse(spec, 1, Some(&profile)).unwrap());
    }
    let wanted = |codes: &[&str]| {
        let mut extents: Vec<Extent> =
            codes.iter().map(|c| profile.find(c)[0]).map(|p| Extent { start: p.address, width: p.width }).collect();
        extents.sort_by_key(|e| e.start);
        plan(&extents, &profile.mapped(Table::Holding), &profile.spans(Table::Holding), 4)
            .unwrap()
            .iter()
            .map(|r| (r.start, r.count))
            .collect::<Vec<_>>()
    };
    for (pane, code) in panes.iter().zip(["d001", "F002", "A003"]) {
        assert_eq!(pane.reads, wanted(&[code]), "{code}'s pane reads what the planner plans");
        assert_eq!(pane.cells.len(), 1);
    }
    // One definition of several points: one pane, its reads the planner's, each within the
    // limit and over mapped registers only.
    let mut pane = spec::parse("d00*", 1, Some(&profile)).unwrap().remove(0);
    let codes: Vec<String> = pane.cells.iter().map(|c| c.point.code.clone()).collect();
    let codes: Vec<&str> = codes.iter().map(String::as_str).collect();
    assert_eq!(pane.reads, wanted(&codes));
    assert!(pane.reads.len() > 1, "d00* needs more than one 4-register read: {:?}", pane.reads);
    let mapped = profile.mapped(Table::Holding);
    for &(start, count) in &pane.reads {
        assert!(count <= profile.read_limit(Table::Holding));
        for a in start..start + count {
            assert!(mapped.iter().any(|e| e.start <= a && a < e.start + e.width), "{a:#06x} is not mapped");
        }
    }
    // Each read fills its own cells: d001 shows 50.00 Hz from the first; the others wait.
    let (first, count) = pane.reads[0];
    let registers = (0..count).map(|i| if i == 1 { 5000 } else { 0 }).collect();
    pane.record_at(first, Outcome::Registers(registers), Duration::from_millis(1));
    assert_eq!(pane.cells[0].show(&pane).as_deref(), Some("50.00 Hz"));
    let last = pane.cells.last().unwrap();
    assert!(last.point.address >= pane.reads[1].0 && last.show(&pane).is_none(), "shown before its read");
}

#[test]
fn a_session_file_keeps_the_trends_and_each_cells_own_order_and_poll_reads_it() {
    let mut raw = Definition::raw(2, Table::Holding, 0x20, 4, Duration::from_millis(500));
    raw.cells[0].set_format(Format::F32(Order::Cdab));
    raw.cells[2].set_format(Format::U32(Order::Dcba));
    raw.cells[2].trended = true;
    let profile = Profile::builtin("omron-3g3rx").unwrap();
    let mut panes = vec![raw];
    panes.extend(spec::parse("d001", 1, Some(&profile)).unwrap());
    panes.extend(spec::parse("A003", 1, Some(&profile)).unwrap());
    panes[1].cells[0].trended = true;
    let session = spec::session_of(Some("omron-3g3rx"), &panes);
    let text = session.to_toml();
    assert!(text.contains("order = \"CDAB\"") && text.contains("order = \"DCBA\""), "{text}");
    assert!(text.contains("trend = true") && text.contains("trends = [\"d001\"]"), "{text}");
    let loaded = ferrobus_tools::poll::session::Session::parse(&text, "s.toml").unwrap();
    assert_eq!(loaded, session);
    let fresh = spec::panes_of(&loaded, "s.toml").unwrap();
    assert_eq!(fresh[0].cells[0].format, Format::F32(Order::Cdab));
    assert_eq!(fresh[0].cells[2].format, Format::U32(Order::Dcba), "the cell's own order, not the read's");
    let trended: Vec<(usize, u16)> = fresh
        .iter()
        .enumerate()
        .flat_map(|(i, p)| p.cells.iter().filter(|c| c.trended).map(move |c| (i, c.point.address)))
        .collect();
    assert_eq!(trended, [(0, 0x22), (1, 0x1000)]);
    assert_eq!(App::new("t".into(), fresh).trends.len(), 2, "the monitor charts them again");
    // poll reads the same file: each cell in its own order, the trends ignored.
    let groups = loaded.groups("s.toml", |name| Profile::load(name).map_err(|e| e.to_string())).unwrap();
    let orders: Vec<Order> = groups[0].cells.iter().map(|c| c.point.order).collect();
    assert_eq!(orders, [Order::Cdab, Order::Dcba]);
    assert_eq!(groups.len(), 3);
    // A trend of a point not watched is refused, naming it.
    let bad = text.replace("trends = [\"d001\"]", "trends = [\"F002\"]");
    let bad = ferrobus_tools::poll::session::Session::parse(&bad, "s.toml").unwrap();
    let err = format!("{:?}", spec::panes_of(&bad, "s.toml").err().unwrap());
    assert!(err.contains("points 1") && err.contains("\\\"F002\\\" is not one of the points watched"), "{err}");
}

/// The connection options of a command line (`--device omron-3g3rx`, ...).
fn connection(args: &[&str]) -> crate::connect::ConnectArgs {
    use clap::{Args as _, FromArgMatches as _};
    let command = crate::connect::ConnectArgs::augment_args(clap::Command::new("ferrobus"));
    let matches = command.try_get_matches_from(std::iter::once("ferrobus").chain(args.iter().copied())).unwrap();
    crate::connect::ConnectArgs::from_arg_matches(&matches).unwrap()
}

/// The `monitor` arguments of `words` (DEFINITIONs and options).
fn monitor_args(words: &[&str]) -> MonitorArgs {
    use clap::{Args as _, FromArgMatches as _};
    let command = MonitorArgs::augment_args(clap::Command::new("monitor"));
    let matches = command.try_get_matches_from(std::iter::once("monitor").chain(words.iter().copied())).unwrap();
    MonitorArgs::from_arg_matches(&matches).unwrap()
}

#[test]
fn monitor_takes_polls_two_word_form_with_count_beside_its_own() {
    let args = monitor_args(&["holding", "0x1000@250ms", "input:7:2", "coils", "3", "--count", "4"]);
    assert_eq!(super::definitions(&args).unwrap(), ["holding:0x1000:4@250ms", "input:7:2", "coils:3:4"]);
    let dangling = monitor_args(&["holding"]);
    assert!(format!("{:?}", super::definitions(&dangling).unwrap_err()).contains("holding needs an ADDRESS"));
}

#[test]
fn with_device_a_raw_pane_is_numbered_as_read_numbers_it_and_read_within_the_profiles_limit() {
    let rx = connection(&["--device", "omron-3g3rx"]);
    let args = monitor_args(&["holding:0x1001:8"]);
    let number = |address: &str, table| rx.address(address, table, args.address_args).map(|a| a.wire);
    let mut panes = spec::parse_numbered("holding:0x1001:8", 1, None, &number).unwrap();
    assert_eq!((panes[0].address, panes[0].count), (0x1000, 8), "one-based as the 3G3RX numbers");
    super::within_limits(&rx, &mut panes).unwrap();
    assert_eq!(panes[0].reads, [(0x1000, 4), (0x1004, 4)], "4 registers a request, the 3G3RX's limit");
    // Without --device: wire addresses and the spec's limit.
    let plain = connection(&[]);
    let number = |address: &str, table| plain.address(address, table, args.address_args).map(|a| a.wire);
    let mut panes = spec::parse_numbered("holding:0x1001:8", 1, None, &number).unwrap();
    super::within_limits(&plain, &mut panes).unwrap();
    assert_eq!(panes[0].reads, [(0x1001, 8)]);
}
